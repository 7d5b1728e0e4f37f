"""Compiled passes of the centres stage against small per-pixel references, and odd windows."""

import cv2
import numpy as np
from pattern_locator.vision import spot_kernels
from pattern_locator.vision.centres import measure_spots, Paper, plane_layout
from pattern_locator.vision.detector_params import DetectorParams
from pattern_locator.vision.dots import segment
import pytest


def test_asymmetry_compares_each_pixel_with_its_reflection():
    rng = np.random.default_rng(3)
    s = 9
    weight = rng.uniform(0, 1, (s, s)).astype(np.float32)
    region = rng.uniform(0, 1, (s, s)) < 0.8
    sigma = np.float32(0.05)

    def at(x, y):
        return float(weight[y, x]) if 0 <= x < s and 0 <= y < s else 0.0

    # Centres on a pixel, half way, and near the edges.
    for c0, c1 in ((4.0, 4.0), (4.5, 3.25), (0.3, 7.9), (8.0, 0.0), (2.7, 5.1)):
        total = difference = count = 0.0
        for y in range(s):
            for x in range(s):
                px, py = 2 * c0 - x, 2 * c1 - y
                xn, yn = int(np.floor(px + 0.5)), int(np.floor(py + 0.5))
                if not (region[y, x] and 0 <= xn < s and 0 <= yn < s and region[yn, xn]):
                    continue
                x0, y0 = int(np.floor(px)), int(np.floor(py))
                fx, fy = px - x0, py - y0
                mirror = ((1 - fy) * ((1 - fx) * at(x0, y0) + fx * at(x0 + 1, y0))
                          + fy * ((1 - fx) * at(x0, y0 + 1) + fx * at(x0 + 1, y0 + 1)))
                total += weight[y, x] + mirror
                difference += abs(weight[y, x] - mirror)
                count += weight[y, x] > 0
        want = (difference - 1.13 * sigma * count) / max(total, 1e-6)
        rows = np.empty((s, s), dtype=np.float32)
        got = spot_kernels._asymmetry(weight, region, (0, s, 0, s), c0, c1, sigma, rows)
        assert got == pytest.approx(want, rel=1e-5, abs=1e-6)


def test_a_point_symmetric_spot_has_only_the_noise_as_asymmetry():
    y, x = np.mgrid[0:11, 0:11]
    weight = np.exp(-((x - 5.0) ** 2 + (y - 5.0) ** 2) / 6.0).astype(np.float32)
    region = np.ones((11, 11), dtype=bool)
    rows = np.empty((11, 11), dtype=np.float32)
    got = spot_kernels._asymmetry(weight, region, (0, 11, 0, 11), 5.0, 5.0, np.float32(0.0), rows)
    assert got == pytest.approx(0.0, abs=1e-7)


def test_flood_keeps_the_8_connected_region_of_the_start():
    rng = np.random.default_rng(5)
    for trial in range(20):
        dark = rng.uniform(0, 1, (15, 15)) < 0.45
        start = int(np.flatnonzero(dark.ravel())[trial])
        keep = ~dark
        spot_kernels._flood(dark, keep, start, np.empty(15 * 15, dtype=np.int64))
        _, labels = cv2.connectedComponents(dark.astype(np.uint8), connectivity=8)
        own = labels.ravel()[start]
        assert np.array_equal(keep, ~dark | (labels == own))


def test_box3_is_opencvs_blur_of_the_window_alone():
    a = np.random.default_rng(6).uniform(0, 1, (7, 7, 3)).astype(np.float32)
    want = cv2.blur(a, (3, 3), borderType=cv2.BORDER_REPLICATE)
    assert np.array_equal(spot_kernels.box3(a), want)


@pytest.mark.parametrize('seed', range(5))
def test_paper_pixels_are_those_clear_of_every_spot_and_inside_the_card(seed):
    # The per-pixel reference: each pixel's plane point against every spot's
    # edge and the card's edge, three window pixels of room (in the plane).
    rng = np.random.default_rng(seed)
    size, half = 31, 0.15
    points = rng.uniform(-0.12, 0.12, (21, 2))
    radii = rng.uniform(0.008, 0.025, 21)
    pred = rng.uniform(10, 20, 2)
    to_plane = rng.normal(0.0, 0.003, (2, 2))
    q0 = points[int(rng.integers(21))]
    in_image = rng.uniform(size=(size, size)) > 0.1
    k = np.arange(size, dtype=np.float64)
    qx = q0[0] + to_plane[0, 0] * (k[None, :] - pred[0]) + to_plane[0, 1] * (k[:, None] - pred[1])
    qy = q0[1] + to_plane[1, 0] * (k[None, :] - pred[0]) + to_plane[1, 1] * (k[:, None] - pred[1])
    room = 3.0 * np.sqrt(abs(np.linalg.det(to_plane)))
    ink = np.min(np.hypot(qx[..., None] - points[:, 0], qy[..., None] - points[:, 1]) - radii,
                 axis=-1)
    edge = half - np.maximum(np.abs(qx), np.abs(qy))
    want = (ink > room) & (edge > room) & in_image
    got = spot_kernels.paper_pixels(size, pred, to_plane, q0, points, radii, half, in_image)
    assert want.any() and (~want).any()
    assert np.array_equal(got, want)
    # Nothing is paper where the plane is not known.
    bad = to_plane.copy()
    bad[0, 0] = np.nan
    assert not spot_kernels.paper_pixels(size, pred, bad, q0, points, radii, half,
                                         in_image).any()


def test_spot_shapes_are_the_singular_value_decomposition():
    rng = np.random.default_rng(7)
    L = rng.normal(0, 100, (50, 2, 2))
    radii = rng.uniform(0.01, 0.02, 50)
    pred = np.zeros((50, 2))
    axes, major, minor, semi, inverse, fit = spot_kernels.spot_shapes(L, radii, 3.0, pred, 1e9)
    U, sv, _ = np.linalg.svd(L)
    assert fit
    assert np.allclose(major, sv[:, 0] * radii, rtol=1e-12)
    assert np.allclose(minor, sv[:, 1] * radii, rtol=1e-9)
    assert np.allclose(semi, np.column_stack([1.2 * major + 3.0, 1.2 * minor + 3.0]))
    # Axes up to their sign.
    assert np.allclose(np.abs(np.einsum('kia,kia->ka', axes, U)), 1.0, atol=1e-9)
    assert np.allclose(inverse, np.linalg.inv(L), rtol=1e-9)


@pytest.mark.parametrize('case', ['rank one', 'NaN', 'too big', 'prediction off'])
def test_spot_shapes_refuse_what_cannot_be_measured(case):
    L = np.tile(np.array([[50.0, 10.0], [-5.0, 40.0]]), (3, 1, 1))
    pred = np.zeros((3, 2))
    largest = 100.0
    if case == 'rank one':
        L[1] = [[50.0, 10.0], [100.0, 20.0]]
    elif case == 'NaN':
        L[2, 0, 1] = np.nan
    elif case == 'too big':
        largest = 1.0
    else:
        pred[0, 1] = np.inf
    assert not spot_kernels.spot_shapes(L, np.full(3, 0.02), 3.0, pred, largest)[-1]


def test_windows_round_halves_to_even_as_numpy():
    pred = np.array([[10.5, 11.5], [3.0, -2.5], [20.25, 7.75]])
    semi = np.array([[3.0, 2.0], [4.2, 1.0], [2.0, 2.0]])
    axes = np.tile(np.eye(2), (3, 1, 1))
    for scale in (1, 2):
        base, size, _, wpred, wsemi, to_plane = spot_kernels.windows(
            np.arange(3), scale, pred, axes, semi, 0.001 * axes)
        centre = (pred - (scale - 1) / 2) / scale
        half = int(np.ceil(semi[:, 0].max() / scale)) + 2
        assert size == 2 * half + 1
        assert np.array_equal(base, np.round(centre).astype(int) - half)
        assert np.allclose(wpred, centre - base)
        assert np.allclose(wsemi, semi / scale)
        assert np.allclose(to_plane, 0.001 * scale * axes)


def first_pass(image, base, size, pred, semi=(3.0, 2.0), axes=(2.0, 1.5)):
    """Run the first pass on windows at ``base`` (one spot per window, plane all its own)."""
    dot_image = segment(image, DetectorParams(field='frame'))
    k = len(base)
    eye = np.tile(np.eye(2), (k, 1, 1))
    out = [np.full((k, 2), np.nan), np.zeros(k, bool), np.zeros(k), np.zeros(k),
           np.zeros(k, bool)]
    result = spot_kernels.first_pass(
        dot_image.image, 1, np.asarray(base, np.int64), size, np.arange(k),
        eye.astype(np.float32), np.asarray(pred, float), np.tile(semi, (k, 1)),
        0.001 * eye.astype(np.float32), np.zeros(k, np.int64), np.zeros((k, 2)),
        np.zeros((1, 1), np.int16), 10.0, 100.0, np.full(k, float(axes[0])),
        np.full(k, float(axes[1])), 0.001 * eye,
        dot_image.white_at(*(np.asarray(pred, float) + base).T).astype(np.float32),
        np.float32(1.0), 2.2, 1.0, 0.12, *out, np.float32(np.inf), np.zeros(k, bool))
    return dot_image, result, out


def glossy_dot(added_per_px, centre=(40.3, 39.6), radius=5.0, size=81):
    """Draw a dot on paper under light added along x (linear light), encoded with gamma 2.2."""
    fine = 4
    ys, xs = np.mgrid[0:size * fine, 0:size * fine]
    x, y = (xs + 0.5) / fine - 0.5, (ys + 0.5) / fine - 0.5
    ink = np.hypot(x - centre[0], y - centre[1]) <= radius
    linear = np.where(ink, 0.05, 0.6) + added_per_px * (x - centre[0]) + 0.1
    linear = linear.reshape(size, fine, size, fine).mean(axis=(1, 3))
    grey = np.rint(255.0 * np.clip(linear, 0.0, 1.0) ** (1 / 2.2)).astype(np.uint8)
    return np.ascontiguousarray(np.dstack([grey] * 3))


@pytest.mark.parametrize('added', [0.004, 0.008, -0.006])
def test_a_dot_on_tilted_paper_is_centred_where_it_is(added):
    # Light added unevenly (a highlight's flank) is added to ink and paper
    # alike: the dot's darkness is taken below a plane fitted to its paper
    # ring, in linear light (_paper_tilt), so its centroid stays put.
    # Below a level white in the encoding its first centroid moved 0.8-1.3 px.
    image = glossy_dot(added)
    pred = np.array([[12.3, 11.6]])
    _, _, (points, valid, _, _, _) = first_pass(image, [[28, 28]], 25, pred,
                                                semi=(11.0, 11.0), axes=(5.0, 5.0))
    assert valid[0] and np.hypot(*(points[0] - (40.3, 39.6))) < 0.06


def test_flat_paper_and_an_object_beside_a_dot_tilt_nothing():
    # The same dot, in flat light, and with a dark object over a third of
    # the paper round it: no tilt (the object is no highlight), so the
    # first pass is what it was (its centroid pulled by the object, which
    # the last pass's tests then catch).
    flat = glossy_dot(0.0)
    touched = flat.copy()
    touched[:, 50:] = 40
    pred = np.array([[12.3, 11.6]])
    for image in (flat, touched):
        level = spot_kernels._paper_level(
            image, 28, 28, 25, np.eye(2, dtype=np.float32)[None], 0, 12.3, 11.6, 5.0, 5.0,
            np.float32(image[:, :49].max()), np.float32(1.0), np.empty(625, np.uint8),
            0.001 * np.eye(2, dtype=np.float32)[None], np.float32(0.0), np.float32(0.0),
            np.zeros((1, 1), np.int16), 0, np.float32(10.0), np.float32(100.0),
            np.empty((625, 3)), np.float32(np.inf))
        assert level[1] == 0.0 and level[2] == 0.0
    _, _, (points, _, _, _, _) = first_pass(flat, [[28, 28]], 25, pred, semi=(11.0, 11.0),
                                            axes=(5.0, 5.0))
    assert np.hypot(*(points[0] - (40.3, 39.6))) < 0.03


def test_windows_inside_and_across_the_border_hold_the_image_pixels():
    image = np.random.default_rng(4).integers(0, 256, (60, 80, 3), dtype=np.uint8)
    base = np.array([[15, 25], [-3, 50], [75, -2]])          # inside, left edge, corner
    size = 9
    dot_image, (pixels, in_image, *_), (points, valid, _, _, inside) = first_pass(
        image, base, size, np.full((3, 2), 4.0))
    for i in range(3):
        for y in range(size):
            for x in range(size):
                u, v = base[i, 0] + x, base[i, 1] + y
                assert in_image[i, y, x] == (0 <= u < 80 and 0 <= v < 60)
                # Beyond the border: the nearest pixel of the image.
                assert np.array_equal(pixels[i, y, x],
                                      dot_image.image[min(max(v, 0), 59), min(max(u, 0), 79)])
    # A window cut by the border is no dot.
    assert inside.tolist() == [True, False, False]
    assert not valid[1] and not valid[2]


def test_a_one_pixel_window_and_one_far_off_the_image_are_measured_safely():
    image = np.full((40, 50, 3), 200, dtype=np.uint8)
    image[20, 25] = 0
    _, result, (points, valid, peak, _, inside) = first_pass(
        image, np.array([[25, 20], [10 ** 6, -10 ** 6]]), 1, np.zeros((2, 2)), semi=(0.5, 0.5))
    pixels, in_image = result[0], result[1]
    assert pixels[0, 0, 0].tolist() == [0, 0, 0] and in_image[0, 0, 0]
    assert points[0].tolist() == [25.0, 20.0] and inside[0] and peak[0] > 0
    assert not in_image[1].any() and not inside[1] and not valid[1]


def test_a_degenerate_homography_measures_nothing():
    image = np.full((120, 160, 3), 200, dtype=np.uint8)
    dot_image = segment(image, DetectorParams(field='frame'))
    layout = plane_layout(np.array([[0.0, 0.0], [0.05, 0.0]]), np.array([0.01, 0.01]), 0.1)
    H = np.array([[1000.0, 0.0, 80.0], [2000.0, 0.0, 60.0], [0.0, 0.0, 1.0]])   # rank 2
    spots = measure_spots(dot_image, None, H, layout, np.arange(2), Paper(np.full(3, 200.0), 1.0))
    assert not spots.valid.any() and np.isnan(spots.points).all()


def test_a_far_cards_colours_take_their_direction_from_sums_and_strength_from_peaks():
    peaks = np.array([[0.6, 0.6, 0.3], [0.5, 0.5, 0.5], [0.4, 0.2, 0.4], [0.3, 0.2, 0.1]])
    sums = np.array([[12.0, 12.0, 3.0], [9.0, 9.0, 9.5], [8.0, 2.0, 8.0], [0.0, 0.0, 0.0]])
    readable = np.array([True, True, False, True])
    out = np.full((4, 3), np.nan)
    spot_kernels.small_card_colours(peaks, sums, readable, out)
    assert np.allclose(out[0], [0.6, 0.6, 0.15])
    assert np.allclose(out[1], [0.5 * 9 / 9.5, 0.5 * 9 / 9.5, 0.5])
    assert np.all(np.isnan(out[2]))
    # Nothing summed (no pixel of its cell in reach): its peaks, not NaN.
    assert np.array_equal(out[3], peaks[3])
    # Which cards: dots under 2.5 pixels (the median of the valid ones).
    small, big = np.array([1.5, 1.5, 1.5]), np.array([2.5, 2.5, 1.0])
    valid = readable[:3]
    assert spot_kernels.small_card(small, small, valid)
    assert not spot_kernels.small_card(big, big, valid)
    assert not spot_kernels.small_card(small, small, np.zeros(3, dtype=bool))


def test_the_lifts_table_is_the_colour_table_below_the_white_and_goes_on_above_it():
    from pattern_locator.vision.centres import _colour_table

    white = np.array([180.0, 200.0, 220.0])
    raw = spot_kernels._raw_table(white, 2.2)
    table = _colour_table(white, 2.2)
    below = np.arange(256)[:, None] < white[None, :]
    assert np.allclose(raw[below], np.broadcast_to(table, raw.shape)[below], atol=1e-6)
    # Paper a highlight lifts above the card's white: darkness below 0,
    # which the lift then brings back up.
    assert (raw[~below] <= 1e-6).all() and raw[255, 0] < -0.5


def test_paper_is_lifted_when_its_upper_quartile_reaches_the_level():
    # The dot of glossy_dot on paper of level 210-225 (encoded): its ring's
    # upper quartile reaches 200, not 230; an object over part of the ring
    # leaves that quartile on the paper.
    flat = glossy_dot(0.0)
    touched = flat.copy()
    touched[:, 50:] = 40
    paper = int(flat[5, 5, 0])
    assert 210 <= paper <= 225
    for image in (flat, touched):
        for lift_level, lifted in ((200.0, True), (230.0, False)):
            level = spot_kernels._paper_level(
                image, 28, 28, 25, np.eye(2, dtype=np.float32)[None], 0, 12.3, 11.6, 5.0, 5.0,
                np.float32(image[:, :49].max()), np.float32(1.0), np.empty(625, np.uint8),
                0.001 * np.eye(2, dtype=np.float32)[None], np.float32(0.0), np.float32(0.0),
                np.zeros((1, 1), np.int16), 0, np.float32(10.0), np.float32(100.0),
                np.empty((625, 3)), np.float32(lift_level))
            assert level[3] == lifted, (lift_level, image is touched)
