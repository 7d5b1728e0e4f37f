"""Sub-pixel centres stage: windows shared in the plane, dot tests, colour per channel."""

import numpy as np
from pattern_locator.card.pattern import PatternConfig
from pattern_locator.sim.render import (card_pose_facing, CardPlacement, DotCardTexture,
                                        Occluder, render_scene, RenderOptions)
from pattern_locator.vision.camera import CameraModel
from pattern_locator.vision.centres import card_paper, measure_spots, plane_layout
from pattern_locator.vision.detector_params import DetectorParams
from pattern_locator.vision.dots import segment
from pattern_locator.vision.pose_exact import ellipse_centres
import pytest

CFG = PatternConfig(handedness_mark=None)
VGA = CameraModel.from_focal(640, 480, 1000.0)
LAYOUT = plane_layout(CFG.model_points()[:, :2], CFG.dot_radii(), CFG.card_size / 2)
MODEL = CFG.model_points()[:, :2]
# Paper between the centre dot and the inner ring, between slots, and near the corners.
_MID = np.radians(22.5 + 45.0 * np.arange(8))
PAPER_XY = np.vstack([0.041 * np.column_stack([np.sin(_MID), np.cos(_MID)]),
                      [[0.13, 0.13], [-0.13, 0.13], [0.13, -0.13], [-0.13, -0.13]]])


def true_homography(T):
    H = VGA.K @ np.column_stack([T.R[:, 0], T.R[:, 1], T.t])
    return H / H[2, 2]


def ellipse_pixels(T):
    ideal = ellipse_centres(T, MODEL, CFG.dot_radii(), VGA.K)
    return ideal


def measure(T, H=None, **options):
    code = CFG.encode(2, 17, 3)
    result = render_scene(VGA, [CardPlacement(T, DotCardTexture(CFG, code))],
                          RenderOptions(**options))
    dot_image = segment(result.image, DetectorParams())
    H = true_homography(T) if H is None else H
    paper = card_paper(dot_image, VGA, H, PAPER_XY)
    return measure_spots(dot_image, VGA, H, LAYOUT, np.arange(CFG.n_dots), paper), result, paper


@pytest.mark.parametrize('distance, tilt', [(1.5, 20.0), (3.0, 60.0), (5.0, 30.0)])
def test_centres_are_the_ellipse_centres(distance, tilt):
    T = card_pose_facing(distance, tilt, 50.0, 10.0, (30.0, -20.0), VGA)
    spots, _, _ = measure(T, noise_sigma=1.0, defocus_sigma_px=0.5, seed=1)
    assert np.all(spots.valid)
    assert np.max(np.linalg.norm(spots.points - ellipse_pixels(T), axis=1)) < 0.2


def test_a_homography_a_pixel_off_still_gives_the_centres():
    T = card_pose_facing(2.5, 45.0, 120.0, 0.0, (0.0, 0.0), VGA)
    H = true_homography(T)
    shifted = np.array([[1.0, 0.0, 0.9], [0.0, 1.0, -0.7], [0.0, 0.0, 1.0]]) @ H
    spots, _, _ = measure(T, H=shifted, noise_sigma=1.0, seed=2)
    assert np.max(np.linalg.norm(spots.points - ellipse_pixels(T), axis=1)) < 0.2


def test_paper_white_and_noise():
    T = card_pose_facing(2.0, 20.0, 0.0, 0.0, (0.0, 0.0), VGA)
    _, result, paper = measure(T, noise_sigma=4.0, seed=3)
    assert paper.colour == pytest.approx([255 * 0.85 ** (1 / 2.2)] * 3, abs=3)
    # The darkest of three noisy channels is less noisy than each: 0.75 sigma.
    assert 0.6 * 4.0 < paper.sigma < 0.95 * 4.0


def test_a_hidden_half_dot_and_an_object_beside_one_are_told():
    # Outer point 3 half under a pale object; outer point 7 with a grey
    # object a dot's radius away: point 3 is no dot, point 7 still is.
    half = np.array([[0.113, -0.1], [0.3, -0.1], [0.3, 0.1], [0.113, 0.1]])
    beside = np.array([[-0.2, -0.03], [-0.135, -0.03], [-0.135, 0.03], [-0.2, 0.03]])
    T = card_pose_facing(2.0, 30.0, 40.0, 0.0, (0.0, 0.0), VGA)
    spots, result, _ = measure(T, noise_sigma=1.0, seed=4,
                               occluders=(Occluder(0, half, (0.85, 0.85, 0.85)),
                                          Occluder(0, beside, (0.35, 0.3, 0.28))))
    p3, p7 = CFG.dot_index(0, 3), CFG.dot_index(0, 7)
    assert 0.4 < result.truth[0].dot_visible[p3] < 0.6
    assert not spots.valid[p3]
    assert spots.valid[p7]
    assert np.linalg.norm(spots.points[p7] - ellipse_pixels(T)[p7]) < 0.2


def test_colour_is_each_channels_own_even_shifted_two_pixels():
    T = card_pose_facing(2.0, 20.0, 30.0, 0.0, (0.0, 0.0), VGA)
    plain, _, _ = measure(T, noise_sigma=1.0, seed=5)
    shifted, _, _ = measure(T, noise_sigma=1.0, seed=5, channel_shift_px=(2.0, 0.0))
    assert np.max(np.abs(shifted.colour - plain.colour)) < 0.08
    # Red dots are light in red, dark in blue and green (BGR order).
    red = [i for i, c in enumerate(CFG.dot_colours(CFG.encode(2, 17, 3))) if c == 'R']
    assert np.all(plain.colour[red, 2] < 0.45) and np.all(plain.colour[red, :2] > 0.8)


def test_plane_layout_gives_each_place_its_nearest_dot_edge():
    owner = LAYOUT.owner
    n = owner.shape[0]
    # The centre of the card is the centre dot's; just outside outer point 1, point 1's.
    assert owner[n // 2, n // 2] == 0
    row = int((LAYOUT.half - (CFG.ring_radii[0] + CFG.ring_dot_radius + 0.003))
              / LAYOUT.resolution)
    assert owner[row, n // 2] == CFG.dot_index(0, 1)


def test_point_reflection_reflects_each_window_through_its_point():
    from pattern_locator.vision.centres import _point_reflection

    rng = np.random.default_rng(3)
    k, s = 5, 9
    a = rng.uniform(0, 1, (k, s, s)).astype(np.float32)
    # Centres inside, on a pixel, half way, and near the edges.
    c = np.array([[4.0, 4.0], [4.5, 3.25], [0.3, 7.9], [8.0, 0.0], [2.7, 5.1]])
    bilinear, nearest = _point_reflection(a, c), _point_reflection(a, c, nearest=True)

    def at(w, x, y):
        return w[y, x] if 0 <= x < s and 0 <= y < s else 0.0

    for i in range(k):
        for y in range(s):
            for x in range(s):
                px, py = 2 * c[i, 0] - x, 2 * c[i, 1] - y
                x0, y0 = int(np.floor(px)), int(np.floor(py))
                fx, fy = px - x0, py - y0
                want = ((1 - fy) * ((1 - fx) * at(a[i], x0, y0) + fx * at(a[i], x0 + 1, y0))
                        + fy * ((1 - fx) * at(a[i], x0, y0 + 1) + fx * at(a[i], x0 + 1, y0 + 1)))
                assert bilinear[i, y, x] == pytest.approx(want, abs=1e-6)
                xn, yn = int(np.floor(px + 0.5)), int(np.floor(py + 0.5))
                assert nearest[i, y, x] == at(a[i], xn, yn)


def test_windows_inside_and_across_the_border_hold_the_image_pixels():
    from pattern_locator.vision.centres import _Windows

    image = np.random.default_rng(4).integers(0, 256, (60, 80, 3), dtype=np.uint8)
    dot_image = segment(image, DetectorParams(field='frame'))
    axes = np.tile(np.eye(2), (2, 1, 1))
    semi = np.array([[3.0, 2.0], [3.0, 2.0]])
    for pred in (np.array([[20.0, 30.0], [60.0, 10.0]]),      # both inside
                 np.array([[20.0, 30.0], [78.0, 1.0]])):     # one across a corner
        g = _Windows(dot_image, np.arange(2), 1, pred, axes, semi, axes)
        size = g.pixels.shape[1]
        for i in range(2):
            for y in range(size):
                for x in range(size):
                    u, v = g.base[i, 0] + x, g.base[i, 1] + y
                    inside = 0 <= u < 80 and 0 <= v < 60
                    assert g.in_image[i, y, x] == inside
                    if inside:
                        assert np.array_equal(g.pixels[i, y, x], dot_image.image[v, u])
