"""Cards stage: candidates ranked by evidence under a budget, slots, homography verified."""

import numpy as np
from pattern_locator.card.pattern import PatternConfig
from pattern_locator.sim.render import (card_pose_facing, CardPlacement, DotCardTexture,
                                        render_scene, RenderOptions)
from pattern_locator.vision.camera import CameraModel
from pattern_locator.vision.cards import (apply_h, fit_homography, group, h_scale,
                                          rank_candidates)
from pattern_locator.vision.detector_params import DetectorParams
from pattern_locator.vision.dots import segment

CFG = PatternConfig()
VGA = CameraModel.from_focal(640, 480, 1000.0)
PARAMS = DetectorParams()


def scene(distance=2.0, background='wall', seed=1):
    T = card_pose_facing(distance, 35.0, 60.0, 20.0, (40.0, -30.0), VGA)
    result = render_scene(VGA, [CardPlacement(T, DotCardTexture(CFG, CFG.encode(2, 17, 3)))],
                          RenderOptions(noise_sigma=1.5, background=background, seed=seed))
    return segment(result.image, PARAMS), result.truth[0].dot_pixels


def centre_blob(blobs, truth):
    return int(np.argmin(np.hypot(blobs.u - truth[0, 0], blobs.v - truth[0, 1])))


def test_the_card_centre_leads_the_candidates_even_among_clutter_and_texture():
    for background in ('clutter', 'texture', 'photo'):
        dot_image, truth = scene(background=background, seed=7)
        chosen = rank_candidates(dot_image.blobs, CFG, PARAMS)
        assert 1 <= len(chosen) <= PARAMS.max_candidates
        assert centre_blob(dot_image.blobs, truth) in chosen[:3], background


def test_the_budget_caps_candidates():
    dot_image, _ = scene(background='photo', seed=3)
    assert len(rank_candidates(dot_image.blobs, CFG, DetectorParams(max_candidates=2))) <= 2


def test_group_assigns_every_slot_and_the_homography_maps_the_plane():
    dot_image, truth = scene()
    guess = group(dot_image.blobs, centre_blob(dot_image.blobs, truth), CFG, PARAMS, VGA)
    assert guess is not None
    assert np.count_nonzero(guess.slot_blob >= 0) >= 14
    # Slot k of ring r is some rotation of point k + 1: the homography maps
    # the slot-ordered plane onto the true dots, up to that rotation.
    mapped = apply_h(guess.homography, CFG.model_points()[:, :2])
    d = np.linalg.norm(mapped[:, None] - truth[None], axis=2).min(axis=1)
    assert np.all(d < 1.5)            # decimated blob centroids: about a pixel


def test_a_far_card_groups_on_full_resolution_blobs():
    dot_image, truth = scene(distance=7.0, seed=2)
    u, v = np.round(truth[0]).astype(int)
    fine = dot_image.blobs_in(u - 45, v - 45, u + 46, v + 46)
    guess = group(fine, centre_blob(fine, truth), CFG, PARAMS, VGA)
    assert guess is not None and np.count_nonzero(guess.slot_blob >= 0) >= 10


def test_homography_fit_drops_outliers_and_needs_the_centre():
    rng = np.random.default_rng(4)
    H = np.array([[500.0, 30.0, 320.0], [-20.0, -480.0, 240.0], [0.05, 0.02, 1.0]])
    obj = np.vstack([CFG.model_points()[1:, :2], [[0.0, 0.0]]])
    img = apply_h(H, obj) + rng.normal(0, 0.05, (len(obj), 2))
    img[3] += [6.0, -4.0]
    radii = np.full(len(obj), CFG.ring_dot_radius)
    fitted, inliers = fit_homography(obj, img, radii, 0.25)
    assert not inliers[3] and inliers.sum() == len(obj) - 1
    assert np.max(np.abs(apply_h(fitted, obj[inliers]) - apply_h(H, obj[inliers]))) < 0.2
    assert h_scale(fitted, obj[:1])[0] > 100
    img[-1] += [9.0, 9.0]                       # the centre off: no card
    assert fit_homography(obj, img, radii, 0.25) == (None, None)
