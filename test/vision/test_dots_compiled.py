"""Compiled passes of the dots stage (in card_kernels): numpy's results to the bit, in bounds."""

import subprocess
import sys

import cv2
import numba
import numpy as np
from pattern_locator.card.pattern import PatternConfig
from pattern_locator.sim.render import (card_pose_facing, CardPlacement, DotCardTexture,
                                        render_scene, RenderOptions)
from pattern_locator.vision import card_kernels, fit_kernels, spot_kernels
from pattern_locator.vision.camera import CameraModel
from pattern_locator.vision.detector import Detector
from pattern_locator.vision.dots import combed
from pattern_locator.vision.locate import CardLocator

CFG = PatternConfig()
VGA = CameraModel.from_focal(640, 480, 1000.0)


def _bilinear_numpy(table, u, v, step):
    """Look up the grid as numpy computes it (the kernel's specification)."""
    gx = np.clip((u + 0.5) / step - 0.5, 0, table.shape[1] - 1)
    gy = np.clip((v + 0.5) / step - 0.5, 0, table.shape[0] - 1)
    x0 = np.minimum(gx.astype(np.intp), max(table.shape[1] - 2, 0))
    y0 = np.minimum(gy.astype(np.intp), max(table.shape[0] - 2, 0))
    fx, fy = np.clip(gx - x0, 0.0, 1.0), np.clip(gy - y0, 0.0, 1.0)
    x1 = np.minimum(x0 + 1, table.shape[1] - 1)
    y1 = np.minimum(y0 + 1, table.shape[0] - 1)
    return ((1 - fy) * ((1 - fx) * table[y0, x0] + fx * table[y0, x1])
            + fy * ((1 - fx) * table[y1, x0] + fx * table[y1, x1]))


def test_grid_look_up_is_numpys_bilinear_to_the_bit():
    rng = np.random.default_rng(2)
    for _ in range(300):
        th, tw = rng.integers(1, 6, size=2)
        table = rng.uniform(0, 255, (th, tw)).astype(np.float32)
        step = int(rng.integers(1, 9))
        u = rng.uniform(-20, step * tw + 20, 30)
        v = rng.uniform(-20, step * th + 20, 30)
        u[::4] = np.round(u[::4])               # on cell centres and edges
        got = card_kernels.bilinear(table, u, v, step)
        assert np.array_equal(got, _bilinear_numpy(table, u, v, step))


def test_grid_look_up_keeps_non_finite_points_in_bounds():
    table = np.arange(12, dtype=np.float32).reshape(3, 4)
    u = np.array([np.nan, np.inf, -np.inf, 1e300, -1e300, 5.0])
    v = np.array([5.0, np.inf, -np.inf, -1e300, 1e300, np.nan])
    got = card_kernels.bilinear(table, u, v, 4)
    assert np.isnan(got[0]) and np.isnan(got[5])
    assert got[1:5].tolist() == [11.0, 0.0, 3.0, 8.0]


def _combed_numpy(image, tile_rows=16):
    g = (image[:, ::16, 1] if image.ndim == 3 else image[:, ::16]).astype(np.int16)
    h = (g.shape[0] - 4) // 2 * 2
    cols = g.shape[1] // 4 * 4
    if h < 2 * tile_rows or cols == 0:
        return False
    mid = g[2:2 + h]
    one = np.abs(2 * mid - g[1:1 + h] - g[3:3 + h])
    two = np.abs(2 * mid - g[0:h] - g[4:4 + h])
    rows = h // tile_rows * tile_rows
    t1, t2 = (c[:rows, :cols].reshape(rows // tile_rows, tile_rows, cols // 4, 4).sum(
        axis=(1, 3), dtype=np.int32) for c in (one, two))
    strong = (t1 > 6 * tile_rows * 4) & (t1 > 3 * t2)
    return int(np.count_nonzero(strong)) >= 2


def test_comb_test_counts_tiles_as_numpy_does():
    rng = np.random.default_rng(5)
    combs = 0
    for _ in range(400):
        h, w = rng.integers(1, 140), rng.integers(1, 240)
        image = (rng.integers(0, 256, (h, w, 3)) // rng.integers(1, 60)).astype(np.uint8)
        if rng.random() < 0.5:
            # One field darker: a comb wherever the scene has structure.
            image[1::2] //= 3
        tile = int(rng.integers(1, 20))
        expected = _combed_numpy(image, tile)
        assert combed(image, tile) == expected
        assert combed(np.ascontiguousarray(image[:, :, 1]), tile) == expected
        combs += expected
    assert 20 < combs < 380


def test_components_keep_what_the_dot_tests_keep():
    rng = np.random.default_rng(6)
    for _ in range(50):
        h, w = rng.integers(8, 60, size=2)
        mask = (rng.random((h, w)) < 0.3).astype(np.uint8) * 255
        _, _, stats, centroids = cv2.connectedComponentsWithStats(mask, connectivity=8)
        x, y, bw, bh, area = (stats[:, k] for k in range(5))
        max_area = float(rng.integers(1, 30))
        keep = ((area <= max_area) & (area * 4 >= bw * bh)
                & (np.maximum(bw, bh) <= 6 * np.minimum(bw, bh) + 2)
                & (x > 0) & (y > 0) & (x + bw < w) & (y + bh < h))
        keep[0] = False
        idx, u, v = card_kernels.dot_components(stats, centroids, 2, 10, 20, max_area, h, w)
        assert np.array_equal(idx, np.flatnonzero(keep))
        assert np.array_equal(u, 10 + 2.0 * (centroids[idx, 0] + 0.5) - 0.5)
        assert np.array_equal(v, 20 + 2.0 * (centroids[idx, 1] + 0.5) - 0.5)


def test_threshold_is_numpys_float32_arithmetic():
    rng = np.random.default_rng(8)
    for _ in range(200):
        shape = tuple(rng.integers(1, 20, size=2))
        white = rng.uniform(0, 255, shape).astype(np.float32)
        white[rng.random(shape) < 0.3] = rng.integers(0, 256)
        noise = rng.exponential(rng.uniform(0.1, 20.0), shape).astype(np.float32)
        keep, factor, least = rng.uniform(0.05, 0.7), rng.uniform(1.0, 20.0), int(rng.integers(60))
        margin = np.maximum(keep * white, np.minimum(factor * noise, 0.5 * white))
        expected = np.clip(np.where(white >= least, white - np.maximum(margin, 2.0), 0.0),
                           0, 255).astype(np.uint8)
        got = card_kernels.threshold(white, noise, np.float32(keep), np.float32(factor), least)
        assert np.array_equal(got, expected)


def test_faint_spots_leave_out_the_own_spot_and_big_ones():
    rng = np.random.default_rng(9)
    for _ in range(100):
        mask = (rng.random(tuple(rng.integers(3, 40, size=2))) < 0.3).astype(np.uint8) * 255
        n, labels, stats, centroids = cv2.connectedComponentsWithStats(mask, connectivity=8)
        own = int(rng.integers(0, n))
        max_area = float(rng.integers(1, 40))
        area = stats[1:, cv2.CC_STAT_AREA] * 4.0
        keep = area <= max_area
        if own > 0:
            keep[own - 1] = False
        xy, own_area = card_kernels.faint_components(stats, centroids, own, max_area, 2, 1.5, -2.5)
        assert np.array_equal(xy, centroids[1:][keep] * 2 + (1.5, -2.5))
        assert own_area == (area[own - 1] if own > 0 else 0.0)


def _faint_ring_numpy(small, u, v, reach, max_area, white, noise, radius, scale):
    """Look for a far centre's faint ring with OpenCV's calls, one blob at a time (the spec)."""
    h, w = small.shape[:2]
    x0, y0 = max(0, int((u - reach) / scale)), max(0, int((v - reach) / scale))
    x1, y1 = min(w, int((u + reach) / scale) + 2), min(h, int((v + reach) / scale) + 2)
    spots, own_area = np.zeros((0, 2)), 0.0
    if x1 - x0 >= 3 and y1 - y0 >= 3 and white >= 24:
        window = small[y0:y1, x0:x1]
        darkest = window if window.ndim == 2 else window.min(axis=2)
        margin = max(0.12 * white, 5.0 * noise / scale, 2.0)
        mask = cv2.compare(np.ascontiguousarray(darkest), white - margin, cv2.CMP_LT)
        _, labels, stats, centroids = cv2.connectedComponentsWithStatsWithAlgorithm(
            mask, 8, cv2.CV_32S, cv2.CCL_GRANA)
        own = int(labels[min(int(v / scale), y1 - 1) - y0, min(int(u / scale), x1 - 1) - x0])
        spots, own_area = card_kernels.faint_components(
            stats, centroids, own, max_area, scale, (x0 + 0.5) * scale - 0.5 - u,
            (y0 + 0.5) * scale - 0.5 - v)
    ring_like, n_ring = card_kernels.ring_of_spots(spots, radius, reach, 6)
    return ring_like, n_ring, own_area


def test_faint_rings_are_opencvs_components_blob_by_blob():
    rng = np.random.default_rng(21)
    rings = 0
    for trial in range(60):
        h, w = rng.integers(8, 90, size=2)
        # Pale spots on paper: some rings of them, some clutter.
        small = np.full((h, w, 3), 200, dtype=np.uint8)
        for _ in range(int(rng.integers(0, 40))):
            y, x = rng.integers(0, h), rng.integers(0, w)
            small[y:y + 2, x:x + 2] = rng.integers(120, 200, size=3)
        cy, cx = rng.uniform(0, h), rng.uniform(0, w)
        for a in np.linspace(0.0, 2 * np.pi, 8, endpoint=False):
            y, x = int(cy + 6 * np.sin(a)), int(cx + 6 * np.cos(a))
            small[max(y, 0):max(y + 2, 0), max(x, 0):max(x + 2, 0)] = 150
        small[int(cy):int(cy) + 3, int(cx):int(cx) + 3] = 60
        grey = trial % 3 == 0
        source = np.ascontiguousarray(small[:, :, 1]) if grey else small
        n = int(rng.integers(1, 8))
        u = np.append(2 * cx + 2, rng.uniform(-10, 2 * w + 10, n - 1))
        v = np.append(2 * cy + 2, rng.uniform(-10, 2 * h + 10, n - 1))
        reach = rng.uniform(0.5, 40.0, n)
        max_area = rng.uniform(1.0, 60.0, n)
        white = rng.uniform(10.0, 230.0, n)
        noise = rng.uniform(0.0, 6.0, n)
        radius = rng.uniform(0.5, 4.0, n)
        view = (source if source.ndim == 3 else source[:, :, None]).view()
        view.flags.writeable = False
        got = card_kernels.faint_rings(view, u, v, reach, max_area, white, noise, radius, 2,
                                       0.12, 24, 6)
        for k in range(n):
            expected = _faint_ring_numpy(source, u[k], v[k], reach[k], max_area[k], white[k],
                                         noise[k], radius[k], 2)
            assert (bool(got[0][k]), int(got[1][k]), float(got[2][k])) == \
                (bool(expected[0]), int(expected[1]), float(expected[2]))
        rings += int(np.count_nonzero(got[0]))
    assert rings > 0        # the rings drawn are found, not only rejections compared


def test_one_compiled_signature_per_kernel_after_detections():
    # Each argument-type combination compiles again (seconds): the dots
    # stage passes one, colour or grey, decimated or windowed.
    T = card_pose_facing(3.0, 30.0, 200.0, -20.0, (80.0, 60.0), VGA)
    image = render_scene(VGA, [CardPlacement(T, DotCardTexture(CFG, CFG.encode(2, 17, 3)))],
                         RenderOptions(noise_sigma=1.0, background='photo', seed=8)).image
    detector = Detector(CFG)
    assert detector.detect(image, VGA)
    assert detector.detect(np.ascontiguousarray(image[:, :, 1]), VGA)
    # A ROS image's buffer is read-only.
    frozen = image.copy()
    frozen.flags.writeable = False
    assert detector.detect(frozen, VGA)
    # And the pose's refinement, in the locator.
    assert CardLocator(CFG).locate(image, VGA)[0].T_camera_pattern is not None
    kernels = [card_kernels.bilinear, card_kernels.combed_tiles, card_kernels.dot_components,
               card_kernels.threshold, card_kernels.faint_components,
               card_kernels.faint_rings,
               card_kernels.label_components, card_kernels.blob_covariance,
               card_kernels.darkest_in, card_kernels.halve,
               spot_kernels.paper_noise, fit_kernels.fit_homography_points,
               fit_kernels.fit_homography_inliers, fit_kernels.planar_poses,
               fit_kernels.refine_exact, spot_kernels.measure,
               fit_kernels.refine_pose, fit_kernels.refine_pose_prior,
               fit_kernels.project_points,
               fit_kernels.circle_image_centres, fit_kernels.pose_jacobian,
               fit_kernels.point_residuals, fit_kernels.pose_covariance_matrix,
               fit_kernels.circle_axis_angle]
    assert all(isinstance(k, numba.core.registry.CPUDispatcher) for k in kernels)
    assert all(len(k.signatures) == 1 for k in kernels), \
        {k.__name__: k.signatures for k in kernels if len(k.signatures) != 1}


def test_component_labels_and_statistics_are_opencvs():
    rng = np.random.default_rng(11)
    masks = [(rng.random(rng.integers(1, 70, size=2)) < rng.uniform(0.0, 0.9)).astype(np.uint8)
             * 255 for _ in range(300)]
    # Blobs of many shapes (rings, bars, touching diagonals) on a clutter
    # image's scale, and the degenerate ones: empty, full, one row, one column.
    blobs = cv2.GaussianBlur(rng.random((180, 320)), (0, 0), 2.0)
    masks += [(blobs < np.quantile(blobs, q)).astype(np.uint8) * 255 for q in (0.05, 0.35, 0.7)]
    masks += [np.zeros((5, 9), np.uint8), np.full((6, 7), 255, np.uint8),
              np.eye(9, dtype=np.uint8), np.eye(9, dtype=np.uint8)[::-1].copy(),
              (rng.random((1, 50)) < 0.5).astype(np.uint8),
              (rng.random((50, 1)) < 0.5).astype(np.uint8)]
    for mask in masks:
        n, labels, stats, centroids = cv2.connectedComponentsWithStatsWithAlgorithm(
            mask, 8, cv2.CV_32S, cv2.CCL_GRANA)
        got_labels, got_stats, got_centroids = card_kernels.label_components(mask)
        assert got_stats.shape == (n, 5) and got_centroids.shape == (n, 2)
        assert np.array_equal(got_labels, labels)
        assert np.array_equal(got_stats[1:], stats[1:])
        assert np.array_equal(got_centroids[1:], centroids[1:])


def test_darkest_channel_of_a_window_is_numpys_minimum_clipped_to_the_image():
    rng = np.random.default_rng(12)
    image = rng.integers(0, 256, (37, 53, 3), dtype=np.uint8)
    image.flags.writeable = False
    for x0, y0, x1, y1 in [(0, 0, 53, 37), (5, 7, 20, 30), (-4, -3, 10, 8), (40, 30, 99, 99),
                           (10, 10, 10, 20), (60, 40, 70, 50)]:
        got = card_kernels.darkest_in(image, x0, y0, x1, y1)
        cx0, cy0 = min(max(x0, 0), 53), min(max(y0, 0), 37)
        cx1, cy1 = min(max(x1, cx0), 53), min(max(y1, cy0), 37)
        assert np.array_equal(got, image[cy0:cy1, cx0:cx1].min(axis=2))


def test_halved_frame_its_darkest_channel_and_comb_count_are_opencvs_and_combed_tiles():
    # The segmentation's one pass over the frame: OpenCV's area resize by
    # two, the minimum over B, G, R, and the comb test's tile count (as
    # combed_tiles, which stops counting at two). Odd sizes drop the last
    # row or column, as the crop before the resize did.
    rng = np.random.default_rng(21)
    combs = 0
    for h, w in [(16, 16), (17, 23), (48, 64), (97, 130), (240, 321), (300, 70)]:
        noise = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
        comb = noise // 4
        comb[::2] += 150                                 # the two fields apart
        bars = np.full((h, w, 3), 200, dtype=np.uint8)
        bars[rng.integers(0, h, 12)] = 10
        for image in (noise, comb, bars, np.full((h, w, 3), 255, dtype=np.uint8),
                      (rng.integers(0, 4, (h, w, 3)) + 126).astype(np.uint8)):
            view = image.view()
            view.flags.writeable = False
            h2, w2 = h // 2, w // 2
            expected = cv2.resize(np.ascontiguousarray(image[:2 * h2, :2 * w2]), (w2, h2),
                                  interpolation=cv2.INTER_AREA)
            for tile_rows in (16, 3, 0):
                small, darkest, tiles = card_kernels.halve(view, tile_rows)
                assert np.array_equal(small, expected)
                assert np.array_equal(darkest, expected.min(axis=2))
                assert tiles == (card_kernels.combed_tiles(view, tile_rows) if tile_rows else 0)
                combs += tiles >= 2
    assert combs >= 6       # combed frames counted, not only plain ones compared


def test_every_kernel_is_ready_at_import():
    # A kernel first compiled (or loaded) at a frame costs that frame
    # seconds: the first frames of a bench, of a node. In a fresh process,
    # importing the locator must leave nothing for the first location.
    script = """
import numba, numpy as np
from pattern_locator.card.pattern import PatternConfig
from pattern_locator.sim.render import (card_pose_facing, CardPlacement, DotCardTexture,
                                        render_scene, RenderOptions)
from pattern_locator.vision import card_kernels, fit_kernels, spot_kernels
from pattern_locator.vision.camera import CameraModel
from pattern_locator.vision.locate import CardLocator
def counts():
    return {(m.__name__, n): len(getattr(m, n).signatures)
            for m in (card_kernels, fit_kernels, spot_kernels) for n in dir(m)
            if isinstance(getattr(m, n), numba.core.registry.CPUDispatcher)}
cfg, cam = PatternConfig(), CameraModel.from_focal(640, 480, 1000.0)
T = card_pose_facing(2.5, 40.0, 120.0, 10.0, (60.0, -40.0), cam)
image = render_scene(cam, [CardPlacement(T, DotCardTexture(cfg, cfg.encode(1, 12, 4)))],
                     RenderOptions(noise_sigma=1.5, background='photo', seed=3)).image
locator = CardLocator(cfg)
before = counts()
assert locator.locate(image, cam)[0].T_camera_pattern is not None
after = counts()
print({k: (before[k], after[k]) for k in after if after[k] != before[k]})
"""
    result = subprocess.run([sys.executable, '-c', script], capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 0, result.stderr[-2000:]
    assert result.stdout.strip() == '{}', f'compiled at the first frame: {result.stdout}'
