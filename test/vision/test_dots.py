"""Dots stage: segmentation against the local white and noise, interlace, full resolution."""

import numpy as np
from pattern_locator.card.pattern import PatternConfig
from pattern_locator.errors import ConfigError
from pattern_locator.sim.render import (card_pose_facing, CardPlacement, DotCardTexture,
                                        render_scene, RenderOptions)
from pattern_locator.vision.camera import CameraModel
from pattern_locator.vision.detector_params import DetectorParams
from pattern_locator.vision.dots import _threshold, check_image, combed, one_field, segment
import pytest

CFG = PatternConfig()
VGA = CameraModel.from_focal(640, 480, 1000.0)
PARAMS = DetectorParams()


def card_image(distance=2.0, **options):
    T = card_pose_facing(distance, 30.0, 40.0, 10.0, (20.0, -10.0), VGA)
    result = render_scene(VGA, [CardPlacement(T, DotCardTexture(CFG, CFG.encode(2, 17, 3)))],
                          RenderOptions(**options))
    return result.image, result.truth[0].dot_pixels


def test_every_dot_of_a_card_is_a_blob_where_the_truth_says():
    image, truth = card_image(noise_sigma=1.5, seed=1)
    blobs = segment(image, PARAMS).blobs
    for u, v in truth:
        d = np.hypot(blobs.u - u, blobs.v - v)
        # Decimated by two: centroids within a pixel of the truth.
        assert d.min() < 1.0


def test_the_threshold_follows_the_noise():
    # The same card, clean and with strong noise: the paper's noise raises
    # the margin a dot needs, so noise specks on the wall make no blobs.
    clean = segment(card_image(noise_sigma=0.5, seed=2)[0], PARAMS)
    noisy = segment(card_image(noise_sigma=8.0, seed=2)[0], PARAMS)
    assert noisy.noise.min() > 3 * clean.noise.min()
    assert len(noisy.blobs) < 120
    # Quieter paper lets fainter dots through: the threshold is the white
    # less the larger of a fraction of it and a multiple of the noise.
    assert len(clean.blobs) >= 17


def test_the_margin_a_dot_needs_grows_with_the_noise_up_to_half_the_white():
    white = np.array([200.0, 200.0, 200.0, 200.0, 20.0])
    noise = np.array([1.0, 8.0, 30.0, 60.0, 1.0])
    # A quarter of the white, ten noise sigmas, at most half the white;
    # nothing where the white is too dark to tell.
    assert _threshold(white, noise, PARAMS).tolist() == [150, 120, 100, 100, 0]


def test_full_resolution_window_finds_what_decimation_merges():
    # At 7 m the two rings' dots are a pixel or two apart.
    image, truth = card_image(distance=7.0, noise_sigma=1.0, seed=3)
    dot_image = segment(image, PARAMS)
    u, v = np.round(truth[0]).astype(int)
    fine = dot_image.blobs_in(u - 40, v - 40, u + 41, v + 41)
    assert fine.scale == 1 and fine.origin == (u - 40, v - 40)
    found = [np.hypot(fine.u - x, fine.v - y).min() < 0.8 for x, y in truth]
    assert sum(found) >= 15


def test_interlace_is_told_by_its_comb_and_one_field_is_rebuilt():
    image, _ = card_image(noise_sigma=1.5, seed=4)
    assert not combed(image)
    T = card_pose_facing(2.0, 30.0, 40.0, 10.0, (20.0, -10.0), VGA)
    placement = CardPlacement(T, DotCardTexture(CFG, CFG.encode(2, 17, 3)))
    combed_image = render_scene(VGA, [placement], RenderOptions(noise_sigma=1.5, seed=4,
                                                                interlace_shift_px=6.0)).image
    assert combed(combed_image)
    even = one_field(combed_image, 'even')
    assert np.array_equal(even[0::2], combed_image[0::2])
    mid = (combed_image[0:-2:2].astype(int) + combed_image[2::2]) / 2
    assert np.all(np.abs(even[1:-1:2] - mid) <= 0.5 + 1e-9)
    odd = one_field(combed_image, 'odd')
    assert np.array_equal(odd[1::2], combed_image[1::2])
    # Auto mode uses the even field on this frame, and records it.
    assert segment(combed_image, PARAMS).field == 'even'
    assert segment(image, PARAMS).field is None


def test_bad_parameters_and_images():
    with pytest.raises(ConfigError, match='field'):
        DetectorParams(field='both')
    with pytest.raises(ConfigError, match='decimate'):
        DetectorParams(decimate=3)
    grey = check_image(np.zeros((40, 50, 1), np.uint8))
    assert grey.shape == (40, 50)


@pytest.mark.parametrize('size, decimate', [((480, 640), 2), ((480, 640), 1), ((250, 330), 2)])
def test_a_windows_threshold_is_the_full_resolution_thresholds_part(size, decimate):
    # Resized round the window only (a whole number of cells a side), or
    # cut from the whole (any other size): the same pixels either way.
    image, _ = card_image(noise_sigma=2.0, seed=4, background='clutter')
    image = np.ascontiguousarray(image[:size[0], :size[1]])
    dot_image = segment(image, DetectorParams(decimate=decimate))
    full = dot_image._full_threshold()
    rng = np.random.default_rng(7)
    h, w = size
    for _ in range(200):
        x0, y0 = int(rng.integers(0, w)), int(rng.integers(0, h))
        x1 = min(w, x0 + int(rng.integers(1, 200)))
        y1 = min(h, y0 + int(rng.integers(1, 200)))
        assert np.array_equal(dot_image._threshold_in(x0, y0, x1, y1), full[y0:y1, x0:x1])
