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


def test_a_degenerate_homography_measures_nothing_and_raises_nothing():
    T = card_pose_facing(2.0, 20.0, 0.0, 0.0, (0.0, 0.0), VGA)
    result = render_scene(VGA, [CardPlacement(T, DotCardTexture(CFG, CFG.encode(2, 17, 3)))],
                          RenderOptions(seed=5))
    dot_image = segment(result.image, DetectorParams())
    good = true_homography(T)
    paper = card_paper(dot_image, VGA, good, PAPER_XY)
    # Every plane point on the map's line at infinity, or no map at all.
    for H in (np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]]), np.zeros((3, 3)),
              np.full((3, 3), np.nan)):
        spots = measure_spots(dot_image, VGA, H, LAYOUT, np.arange(CFG.n_dots), paper)
        assert not np.any(spots.valid)
        assert card_paper(dot_image, VGA, H, PAPER_XY) is None


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
