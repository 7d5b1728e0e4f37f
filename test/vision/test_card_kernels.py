"""Compiled kernels of the cards and code stages: numpy's arithmetic, indices kept in bounds."""

import math

import cv2
import numba
import numpy as np
from pattern_locator.card.pattern import PatternConfig, RING_POINTS
from pattern_locator.sim.render import (card_pose_facing, CardPlacement, DotCardTexture,
                                        render_scene, RenderOptions)
from pattern_locator.vision import card_kernels
from pattern_locator.vision.camera import CameraModel
from pattern_locator.vision.cards import (_ring_rho, _zones, fit_homography, group,
                                          rank_candidates)
from pattern_locator.vision.code_reading import read_code
from pattern_locator.vision.detector import Detector
from pattern_locator.vision.detector_params import DetectorParams
from pattern_locator.vision.dots import segment
import pytest

CFG = PatternConfig()
PARAMS = DetectorParams()
VGA = CameraModel.from_focal(640, 480, 1000.0)


@pytest.fixture(scope='module')
def blobs():
    T = card_pose_facing(2.5, 50.0, 30.0, 10.0, (-60.0, 40.0), VGA)
    result = render_scene(VGA, [CardPlacement(T, DotCardTexture(CFG, CFG.encode(2, 17, 3)))],
                          RenderOptions(noise_sigma=2.0, background='clutter', seed=5))
    return segment(result.image, PARAMS).blobs


def test_pairwise_sum_adds_in_numpys_order():
    # The response fit picks the crosstalk of least summed error: the sum
    # must round as numpy's does for the pick to be numpy's.
    rng = np.random.default_rng(3)
    for n in (0, 1, 7, 8, 9, 48, 128, 129, 300, 1000, 5000):
        x = rng.normal(size=n) * 10.0 ** rng.integers(-8, 8, size=n)
        assert card_kernels._pairwise_sum(x, n) == np.sum(x), n


def test_angles_wrap_as_numpy_wraps_them():
    rng = np.random.default_rng(4)
    a = np.concatenate([rng.uniform(-4 * np.pi, 4 * np.pi, 2000),
                        [-np.pi, np.pi, 0.0, -0.0, 3 * np.pi, -3 * np.pi, 2 * np.pi, 1e-300,
                         np.nextafter(-np.pi, 0.0), np.nextafter(np.pi, 0.0)]])
    expected = (a + np.pi) % (2 * np.pi) - np.pi
    got = np.array([card_kernels._wrap(x) for x in a])
    assert np.array_equal(got.view(np.int64), expected.view(np.int64))


def _opencv_covariance(blobs, j: int) -> np.ndarray:
    """Second central moments (image pixels^2) of component ``j``, from OpenCV's moments."""
    x, y, w, h = (int(c) for c in blobs.box[j])
    m = cv2.moments((blobs.labels[y:y + h, x:x + w] == blobs.label[j]).view(np.uint8),
                    binaryImage=True)
    a = max(m['m00'], 1.0)
    s2 = float(blobs.scale * blobs.scale)
    return s2 * np.array([[m['mu20'] / a + 1 / 12, m['mu11'] / a],
                          [m['mu11'] / a, m['mu02'] / a + 1 / 12]])


def test_blob_shape_matches_opencv_moments_and_lapack(blobs):
    assert len(blobs) > 20
    for j in range(len(blobs)):
        cov = _opencv_covariance(blobs, j)
        # As the detector calls it (a Python int label: one compiled signature).
        xx, xy, yy = card_kernels.blob_covariance(blobs.labels, blobs.box[j],
                                                  int(blobs.label[j]), blobs.scale)
        assert np.allclose([xx, xy, yy], [cov[0, 0], cov[0, 1], cov[1, 1]], rtol=1e-12,
                           atol=1e-12)
        small, big, ex, ey = card_kernels._eig2(xx, xy, yy)
        evals, evecs = np.linalg.eigh(cov)
        assert np.allclose([small, big], evals, rtol=1e-12, atol=1e-12)
        if evals[1] - evals[0] > 1e-6 * evals[1]:
            assert abs(abs(ex * evecs[0, 1] + ey * evecs[1, 1]) - 1.0) < 1e-9


def test_indices_outside_the_arrays_are_never_used(blobs):
    # numba does not check bounds: the kernels must.
    for ci in (-1, len(blobs), 10 ** 9):
        assert group(blobs, ci, CFG, PARAMS, VGA) is None
        status, slot_blob = card_kernels.group_slots(
            blobs.u, blobs.v, blobs.area, blobs.box, blobs.label, blobs.labels, blobs.scale, ci,
            _ring_rho(CFG), PARAMS.min_ellipse_fill, 64.0, False)
        assert status == 0 and np.all(slot_blob == -1)
    slot_blob = np.full((CFG.n_rings, RING_POINTS), -1, dtype=np.intp)
    slot_blob[0, :3] = [0, len(blobs), -5]
    rows, points = card_kernels.slot_points(slot_blob, blobs.u, blobs.v, 1)
    assert list(rows) == [0, CFG.n_rings * RING_POINTS]
    assert np.array_equal(points, [[blobs.u[0], blobs.v[0]], [blobs.u[1], blobs.v[1]]])
    reach = np.full(len(blobs), 50.0)
    score = card_kernels.ring_evidence(
        blobs.u, blobs.v, blobs.area, blobs.box, blobs.label, blobs.labels, blobs.scale,
        np.array([-1, len(blobs)], dtype=np.intp), reach, 6, 18, 1.9, 5.9, 16, 10 ** 6)
    assert np.array_equal(score, [0.0, 0.0])


def test_bad_values_give_a_clear_error_not_a_wrong_answer(blobs):
    u = blobs.u.copy()
    u[3] = np.nan
    with pytest.raises(ValueError, match='finite'):
        rank_candidates(type(blobs)(u, blobs.v, blobs.area, blobs.box, blobs.label,
                                    blobs.labels, blobs.scale, blobs.origin), CFG, PARAMS)
    colour = np.full((CFG.n_dots - 1, 3), 0.5)
    with pytest.raises(ValueError, match='read_code'):
        read_code(colour, np.ones(CFG.n_dots - 1, bool), CFG.n_rings, CFG, PARAMS)


def test_a_map_sending_a_point_to_infinity_rejects_it_without_raising():
    # A plane point on the homography's vanishing line divides by zero:
    # inf, as in numpy, never Python's ZeroDivisionError.
    H = np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [1.0, 0.0, 1.0]])
    obj = np.array([[-1.0, 0.0], [0.1, 0.1], [0.0, 0.0]])
    img = np.array([[0.0, 0.0], [370.0 / 1.1, 290.0 / 1.1], [320.0, 240.0]])
    tol = np.empty(3)
    ok, now, count, same = card_kernels.homography_inliers(
        H, obj, img, np.full(3, 0.01), 1.0, 0.75, tol, np.ones(3, bool), True)
    assert ok and list(now) == [False, True, True] and count == 2 and not same
    H[0, 0] = np.inf
    assert not card_kernels.homography_inliers(H, obj, img, np.full(3, 0.01), 1.0, 0.75, tol,
                                               np.ones(3, bool), True)[0]
    # Through fit_homography: a map OpenCV cannot fit is no card.
    flat = np.column_stack([np.linspace(0, 1, 8), np.zeros(8)])
    assert fit_homography(flat, flat * 100, np.full(8, 0.01), 1.0) == (None, None)


def test_the_colour_fit_undoes_the_sensors_crosstalk():
    # Dots of known inks seen through a sensor whose filters overlap by
    # t = 0.3: the fit finds that t (its inks' directions), and no white error.
    inks = np.array([[1.0, 1.0, 1.0], [0.9, 0.8, 0.1], [0.6, 0.2, 0.8], [0.2, 0.7, 0.9]])
    crosstalk = np.linspace(0.0, 0.45, 7)
    mix = np.full((3, 3), 0.15) + np.eye(3) * (1 - 1.5 * 0.3)
    mix /= mix.sum(axis=1, keepdims=True)
    letters = np.array([0, 1, 2, 3, 1, 2, 3, 1, 2, 3, 1, 2])
    dark = (inks[letters] @ mix.T) * np.linspace(0.6, 0.9, len(letters))[:, None]
    white_error, unit_inks = card_kernels.fit_response(dark, inks, np.ones(3), crosstalk)
    expected = inks @ mix.T
    expected /= np.linalg.norm(expected, axis=1, keepdims=True)
    assert np.allclose(white_error, 1.0, atol=1e-6)
    assert np.allclose(unit_inks, expected, atol=1e-9)
    assert math.isclose(float(np.linalg.norm(unit_inks[1])), 1.0)


def test_one_compiled_signature_per_kernel_after_warm_up_and_a_detection(blobs):
    # Each argument-type combination compiles again (seconds): warm_up's
    # types must be the detector's, and no call may drift from them.
    card_kernels.warm_up()
    T = card_pose_facing(3.0, 30.0, 200.0, -20.0, (80.0, 60.0), VGA)
    image = render_scene(VGA, [CardPlacement(T, DotCardTexture(CFG, CFG.encode(2, 17, 3)))],
                         RenderOptions(noise_sigma=1.0, background='photo', seed=8)).image
    assert Detector(CFG).detect(image, VGA)
    # The kernels the stages call from Python (other tests here call helpers
    # with their own types).
    kernels = [getattr(card_kernels, name) for name in (
        'centre_evidence', 'ring_evidence', 'ring_of_spots', 'group_slots', 'slot_points',
        'homography_inliers', 'read_colours', 'in_disc')]
    assert all(isinstance(k, numba.core.registry.CPUDispatcher) for k in kernels)
    assert all(len(k.signatures) == 1 for k in kernels), \
        {k.__name__: k.signatures for k in kernels if len(k.signatures) != 1}


def test_points_in_a_cards_disc_are_those_the_inverse_map_puts_there():
    rng = np.random.default_rng(12)
    disagree = inside = 0
    for _ in range(300):
        H = np.array([[rng.uniform(300, 3000), rng.uniform(-500, 500), rng.uniform(0, 1280)],
                      [rng.uniform(-500, 500), rng.uniform(-3000, -300), rng.uniform(0, 720)],
                      [rng.uniform(-3, 3), rng.uniform(-3, 3), 1.0]])
        pts = np.vstack([rng.uniform(-100.0, 1400.0, (40, 2)),
                         H[:2, 2] + rng.normal(0.0, 60.0, (10, 2))])
        reach = float(rng.uniform(0.01, 0.3))
        p = np.column_stack([pts, np.ones(len(pts))]) @ np.linalg.inv(H).T
        expected = np.hypot(p[:, 0] / p[:, 2], p[:, 1] / p[:, 2]) < reach
        got = card_kernels.in_disc(H, pts, reach)
        # The adjugate and LAPACK's inverse differ by rounding: only a point
        # on the disc's edge to the last bits may go either way.
        disagree += int(np.count_nonzero(got != expected))
        inside += int(np.count_nonzero(expected))
    assert disagree == 0 and inside > 0
    # Points mapped from the plane: inside and outside by construction.
    H = np.array([[800.0, 20.0, 320.0], [-10.0, -790.0, 240.0], [0.1, -0.2, 1.0]])
    plane = np.array([[0.05, 0.0], [0.0, -0.099], [0.101, 0.0], [0.2, 0.2]])
    image = np.column_stack([plane, np.ones(4)]) @ H.T
    image = image[:, :2] / image[:, 2:]
    assert card_kernels.in_disc(H, image, 0.1).tolist() == [True, True, False, False]


def test_median_in_place_is_numpys_median():
    rng = np.random.default_rng(6)
    for n in range(1, 80):
        for values in (rng.normal(size=n), rng.integers(0, 4, size=n).astype(float)):
            scratch = np.concatenate([values, rng.normal(size=3)])
            assert card_kernels._median_in_place(scratch, n) == np.median(values), (n, values)


def _drawn_blobs(centres_and_radii, size=(480, 640)):
    """Segment black discs drawn on white paper: (u, v, radius) each, the first the candidate."""
    image = np.full(size + (3,), 230, np.uint8)
    for u, v, r in centres_and_radii:
        cv2.circle(image, (int(round(u * 16)), int(round(v * 16))), int(round(r * 16)),
                   (30, 30, 30), -1, cv2.LINE_AA, 4)
    blobs = segment(image, PARAMS).blobs
    first = int(np.argmin(np.hypot(blobs.u - centres_and_radii[0][0],
                                   blobs.v - centres_and_radii[0][1])))
    return blobs, first


def _ring_scores(blobs, candidates, budget=10 ** 6):
    """Score ``candidates`` as rank_candidates does, with the reach centre_evidence gives."""
    rho_out = CFG.ring_radii[0] / CFG.centre_dot_radius
    u, v, area = (blobs.u.astype(float), blobs.v.astype(float), blobs.area.astype(float))
    _, _, reach = card_kernels.centre_evidence(u, v, area, blobs.box, float(blobs.scale),
                                               rho_out, 10.0, 6, 16)
    return card_kernels.ring_evidence(
        u, v, area, blobs.box, blobs.label, blobs.labels, int(blobs.scale),
        np.asarray(candidates, dtype=np.intp), reach, 6, 18, *_zones(CFG), 16, budget)


def _ring_score(blobs, ci):
    return _ring_scores(blobs, [ci])[0]


def _card_discs(u0=320.0, v0=240.0, r=12.0):
    """Return a card's centre and its two rings of eight discs, in the card's proportions."""
    discs = [(u0, v0, r)]
    for ring in CFG.ring_radii:
        for k in range(RING_POINTS):
            a = k * np.pi / 4
            rho = ring / CFG.centre_dot_radius * r
            discs.append((u0 + rho * np.sin(a), v0 - rho * np.cos(a),
                          CFG.ring_dot_radius / CFG.centre_dot_radius * r))
    return discs


def test_ring_evidence_gives_a_card_full_marks_and_less_for_what_a_card_has_not():
    # A card: 16 ring dots all round, bare paper between centre and rings.
    blobs, ci = _drawn_blobs(_card_discs())
    assert _ring_score(blobs, ci) == 16 + 2 * 8
    # Blobs on the bare paper (a texture's neighbours at every distance).
    blobs, ci = _drawn_blobs(_card_discs() + [(320.0 + 20.0, 240.0, 4.0),
                                              (320.0 - 19.0, 240.0 + 5.0, 4.0)])
    assert _ring_score(blobs, ci) == 16 + 2 * 8 - 2 * card_kernels._CLEAR_WEIGHT
    # Small blobs among the rings, more than a card has there.
    rng = np.random.default_rng(2)
    extra = []
    for _ in range(20000):
        rho, a = rng.uniform(3.3, 5.4) * 12.0, rng.uniform(0.0, 2 * np.pi)
        u, v = 320.0 + rho * np.cos(a), 240.0 + rho * np.sin(a)
        if all(math.hypot(u - x, v - y) > r + 10.0 for x, y, r in _card_discs() + extra):
            extra.append((u, v, 3.5))
    blobs, ci = _drawn_blobs(_card_discs() + extra)
    assert len(extra) >= 12 and len(blobs) == 1 + 16 + len(extra)
    assert _ring_score(blobs, ci) == 16 + 2 * 8 - (16 + len(extra) - 18)


def test_ring_evidence_stops_at_its_budget():
    blobs, ci = _drawn_blobs(_card_discs())
    score = _ring_scores(blobs, [ci, ci, ci], budget=1)
    # The first candidate is scored whatever the budget; none after it.
    assert score[0] == 32.0 and np.all(np.isneginf(score[1:]))
