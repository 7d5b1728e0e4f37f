"""The paper's estimator on exact synthetic projections of the dots."""

import math

import numpy as np
from pattern_locator.card.pattern import PatternConfig
from pattern_locator.errors import EstimationError
from pattern_locator.vision.camera import CameraModel
from pattern_locator.vision.geometry import look_at, Pose, rodrigues, rotation_angle
from pattern_locator.vision.pose_paper import (camera_axes, camera_position, estimate_paper,
                                               fit_conic, pose_from_angles, ring_view)
import pytest

CFG = PatternConfig()
# The paper's camera: f = 25 mm on a 640 x 480 sensor of about 7.5 um pixels.
CAM = CameraModel.from_focal(640, 480, 3333.0)


def aimed(D, phi_deg, theta_deg, roll=0.0):
    """T_camera_pattern of an upright camera aimed at the pattern centre."""
    C = camera_position(math.radians(phi_deg), math.radians(theta_deg), D)
    return look_at(C, np.zeros(3), up=(0.0, 1.0, 0.0), roll=roll).inverse(), C


def image(T, camera=CAM, clip=True):
    """Exact dot centres in pixels; dots outside the image are NaN."""
    px = camera.project(T.apply(CFG.model_points()))
    if clip:
        out = ((px[:, 0] < 0) | (px[:, 0] > camera.width - 1)
               | (px[:, 1] < 0) | (px[:, 1] > camera.height - 1))
        px[out] = np.nan
    return px


def true_psi_deg(T, theta_deg):
    """Image angle of the pattern direction l = (cos theta, -sin theta, 0)."""
    t = math.radians(theta_deg)
    l_dir = np.array([math.cos(t), -math.sin(t), 0.0])
    return math.degrees(math.atan2(T.R[1] @ l_dir, T.R[0] @ l_dir))


def angle_diff(a, b):
    return abs((a - b + 180.0) % 360.0 - 180.0)


def test_aimed_view_recovers_the_paper_angles():
    T, C = aimed(3.0, 40.0, 30.0)
    est = estimate_paper(image(T), CAM, CFG)
    assert est.rings_used == (0, 1)
    assert abs(est.phi_deg - 40.0) < 1.0
    assert angle_diff(est.theta_deg, 30.0) < 1.5
    assert angle_diff(est.psi_deg, true_psi_deg(T, 30.0)) < 1.0
    assert abs(est.distance_m - 3.0) < 0.03
    assert np.linalg.norm(est.camera_in_pattern - C) < 0.02 * 3.0
    # The pose agrees with the angles and with the truth.
    pose_C = -est.T_camera_pattern.R.T @ est.T_camera_pattern.t
    assert np.allclose(pose_C, est.camera_in_pattern, atol=1e-9)
    assert math.degrees(rotation_angle(est.T_camera_pattern.R, T.R)) < 0.5
    assert est.reprojection_rms_px < 0.1
    # The reported ellipse is the outer ring's, centred on the centre dot.
    u0, v0, a, b, psi = est.ellipse
    assert abs(a - CAM.fx * CFG.ring_radii[0] / 3.0) < 0.01 * a
    assert abs(b / a - math.cos(math.radians(40.0))) < 0.01
    assert math.hypot(u0, v0) < 5.0
    assert angle_diff(math.degrees(psi), est.psi_deg) < 1e-9


def test_camera_axes_is_a_rotation_that_reproduces_the_pan_formulas():
    for psi, phi, theta in [(0.3, 0.7, 2.0), (-2.5, 1.2, -0.4), (3.0, 0.1, 5.0)]:
        R = camera_axes(psi, phi, theta)
        assert np.allclose(R.T @ R, np.eye(3), atol=1e-12)
        assert abs(np.linalg.det(R) - 1.0) < 1e-12
        # Orthographic image of the ring, rotated by psi: method.md step 6.
        ring = CFG.model_points()[1:9]
        pose = pose_from_angles(psi, phi, theta, 1.0)
        xy = ring @ pose.R[:2].T
        c, s = math.cos(psi), math.sin(psi)
        u = xy[:, 0] * c + xy[:, 1] * s
        v = -xy[:, 0] * s + xy[:, 1] * c
        alpha = np.radians(45.0 * np.arange(8))
        R0 = CFG.ring_radii[0]
        assert np.allclose(u, R0 * np.sin(alpha - theta), atol=1e-12)
        assert np.allclose(v, -R0 * math.cos(phi) * np.cos(alpha - theta), atol=1e-12)


def test_orthographic_ring_gives_the_angles_exactly():
    f, D = 3333.0, 2.0
    for phi, theta, roll in [(40.0, 30.0, 0.0), (65.0, 250.0, 0.4), (25.0, 125.0, -1.0),
                             (55.0, 300.0, 2.9)]:
        T, _ = aimed(D, phi, theta, roll)
        for ring in range(CFG.n_rings):
            P = CFG.model_points()[1 + 8 * ring:9 + 8 * ring]
            ortho = f / D * (P @ T.R[:2].T)
            view = ring_view(ortho)
            psi = true_psi_deg(T, theta)
            # psi comes back on one 180-degree branch; theta goes with it.
            shift = 0.0 if angle_diff(math.degrees(view.psi), psi) < 90.0 else 180.0
            assert angle_diff(math.degrees(view.psi) + shift, psi) < 1e-6
            assert abs(math.degrees(view.phi) - phi) < 1e-6
            assert angle_diff(math.degrees(view.theta) + shift, theta) < 1e-6
            assert abs(view.a - f * CFG.ring_radii[ring] / D) < 1e-6
            assert math.hypot(view.u0, view.v0) < 1e-6
        # The whole estimator on orthographic pixels around the principal point.
        P = CFG.model_points()
        px = f / D * (P @ T.R[:2].T) + [CAM.cx, CAM.cy]
        est = estimate_paper(px, CAM, CFG)
        assert abs(est.phi_deg - phi) < 1e-6
        assert abs(est.distance_m - D) < 1e-9
        shift = 0.0 if angle_diff(est.theta_deg, theta) < 90.0 else 180.0
        assert angle_diff(est.theta_deg + shift, theta) < 1e-6
        assert angle_diff(est.psi_deg + shift, true_psi_deg(T, theta)) < 1e-6


def sweep():
    """Exact images over theta (full circle), phi 25..70 deg and D 1.25..8 m."""
    rows = []
    for D in (1.25, 2.0, 3.0, 5.0, 8.0):
        for phi in (25.0, 35.0, 45.0, 55.0, 70.0):
            for theta in range(0, 360, 30):
                T, C = aimed(D, phi, theta)
                est = estimate_paper(image(T), CAM, CFG)
                R = CFG.ring_radii[est.rings_used[0]]
                rows.append({
                    'D': D, 'rings': est.rings_used,
                    'eps': R * math.sin(math.radians(phi)) / D,
                    'phi': abs(est.phi_deg - phi),
                    'theta': angle_diff(est.theta_deg, theta),
                    'psi': angle_diff(est.psi_deg, true_psi_deg(T, theta)),
                    'dist': abs(est.distance_m - D) / D,
                    'pos': np.linalg.norm(est.camera_in_pattern - C) / D,
                    'rot': math.degrees(rotation_angle(est.T_camera_pattern.R, T.R)),
                    'ambiguity': est.ambiguity_ratio})
    return rows


def test_sweep_errors_are_second_order_in_the_weak_perspective_ratio():
    # With the camera aimed at the centre psi and theta are exact under full
    # perspective; tilt and distance err by O(eps^2), eps = R sin(phi) / D.
    # Measured worst cases over this sweep (640 x 480, f = 3333 px): phi 0.097
    # deg, D 0.30 %, position 0.32 % of D, all at D = 1.25 m, where the outer
    # ring leaves the image at low tilt and the inner ring is used alone;
    # phi / eps^2 <= 1.07 rad, (dD / D) / eps^2 in 0.41..0.50, (|dC| / D) /
    # eps^2 <= 1.18.
    rows = sweep()
    assert {r['rings'] for r in rows if r['D'] == 1.25} == {(0, 1), (1,)}
    for r in rows:
        eps2 = r['eps'] ** 2
        assert math.radians(r['phi']) <= 1.5 * eps2, r
        assert r['dist'] <= 0.6 * eps2, r
        assert r['pos'] <= 1.5 * eps2, r
        assert r['psi'] < 1e-6, r
        assert r['theta'] < 1e-3, r
        assert r['rot'] <= math.degrees(1.5 * eps2), r
        # The perspective cue picks the right 180-degree branch clearly.
        assert r['ambiguity'] > 10.0, r
    assert max(r['phi'] for r in rows) < 0.15
    assert max(r['dist'] for r in rows) < 0.004
    assert max(r['pos'] for r in rows) < 0.004
    # Small ratio, small error: at 8 m everything is within 0.005 deg / 0.02 %.
    far = [r for r in rows if r['D'] == 8.0]
    assert max(r['phi'] for r in far) < 0.005
    assert max(r['pos'] for r in far) < 2e-4


def test_branch_choice_keeps_the_upright_camera_below_the_card():
    T, C = aimed(2.5, 50.0, 200.0)
    est = estimate_paper(image(T), CAM, CFG)
    R = est.T_camera_pattern.R
    # Camera down (+y of the optical frame) ~ pattern down, camera right ~ +x.
    assert R[1] @ np.array([0.0, 1.0, 0.0]) < -0.5
    assert R[0] @ np.array([1.0, 0.0, 0.0]) > 0.5
    assert est.camera_in_pattern[1] < 0.0
    assert np.linalg.norm(est.camera_in_pattern - C) < 0.01
    # The other branch is the mirror pose (C_x, C_y flipped), also upright:
    # only perspective separates them, not the camera's "down" direction.
    alt = est.alternative_T_camera_pattern
    alt_C = -alt.R.T @ alt.t
    assert np.allclose(alt_C, est.camera_in_pattern * [-1.0, -1.0, 1.0], atol=1e-9)
    # Camera x and y (rows 0, 1): same in-plane components, opposite normal ones.
    assert np.allclose(alt.R[:2, :2], R[:2, :2], atol=1e-9)
    assert np.allclose(alt.R[:2, 2], -R[:2, 2], atol=1e-9)
    assert est.ambiguity_ratio > 10.0


def test_off_centre_card_gives_the_centred_pose():
    # A wide, distorted camera turned away from the card: the virtual rotation
    # is exact, so the card's pose matches the aimed view to rounding.
    wide = CameraModel.from_focal(1280, 960, 900.0, D=[-0.25, 0.08, 0.001, -0.0005, 0.0])
    for D, phi, theta in [(2.0, 40.0, 200.0), (3.0, 55.0, 120.0), (1.5, 30.0, 300.0)]:
        T, C = aimed(D, phi, theta)
        centred = estimate_paper(image(T, wide), wide, CFG)
        for rvec in [(0.25, -0.3, 0.1), (-0.2, 0.35, -0.4)]:
            turn = rodrigues(np.array(rvec))
            moved = Pose(turn @ T.R, turn @ T.t)
            px = image(moved, wide)
            assert np.all(np.isfinite(px))
            assert np.linalg.norm(px[0] - [wide.cx, wide.cy]) > 200.0
            est = estimate_paper(px, wide, CFG)
            assert np.allclose(est.camera_in_pattern, centred.camera_in_pattern, atol=1e-9)
            assert np.allclose(est.T_camera_pattern.R, turn @ centred.T_camera_pattern.R,
                               atol=1e-9)
            assert abs(est.phi_deg - centred.phi_deg) < 1e-7
            assert angle_diff(est.theta_deg, centred.theta_deg) < 1e-7
            assert np.linalg.norm(est.camera_in_pattern - C) < 0.01 * D
            # Without the centre dot: aim at the conic centre, then at the
            # pole of the vanishing line; the branch is still clear.
            px[0] = np.nan
            est = estimate_paper(px, wide, CFG)
            assert np.linalg.norm(est.camera_in_pattern - C) < 0.01 * D
            assert est.ambiguity_ratio > 10.0


def test_both_rings_agree_with_each_ring_and_beat_them_under_noise():
    T, C = aimed(3.0, 45.0, 135.0)
    px = image(T)
    both = estimate_paper(px, CAM, CFG)
    outer, inner = px.copy(), px.copy()
    outer[9:] = np.nan
    inner[1:9] = np.nan
    est_outer = estimate_paper(outer, CAM, CFG)
    est_inner = estimate_paper(inner, CAM, CFG)
    assert (both.rings_used, est_outer.rings_used, est_inner.rings_used) == ((0, 1), (0,), (1,))
    for est in (est_outer, est_inner):
        assert abs(est.phi_deg - both.phi_deg) < 0.05
        assert np.linalg.norm(est.camera_in_pattern - both.camera_in_pattern) < 0.005
    # The inner ring's ellipse is reported when the outer one is incomplete.
    assert abs(est_inner.ellipse[2] / both.ellipse[2] - 72.0 / 113.0) < 0.01
    # Under pixel noise the R^2-weighted combination beats either ring alone.
    rng = np.random.default_rng(7)
    errors = {'both': [], 'outer': [], 'inner': []}
    for _ in range(100):
        noisy = px + rng.normal(0.0, 0.3, px.shape)
        for name, drop in (('both', []), ('outer', slice(9, 17)), ('inner', slice(1, 9))):
            data = noisy.copy()
            data[drop] = np.nan
            est = estimate_paper(data, CAM, CFG)
            errors[name].append(np.linalg.norm(est.camera_in_pattern - C))
    mean = {k: float(np.mean(v)) for k, v in errors.items()}
    assert mean['both'] < mean['outer'] < mean['inner']


def test_min_tilt_rejects_near_frontal_views():
    T, _ = aimed(3.0, 20.0, 80.0)
    with pytest.raises(EstimationError, match='min_tilt_deg'):
        estimate_paper(image(T), CAM, CFG, min_tilt_deg=25.0)
    # Off by default; the paper's 25 degrees accepts a 30-degree view.
    assert abs(estimate_paper(image(T), CAM, CFG).phi_deg - 20.0) < 0.1
    T, _ = aimed(3.0, 30.0, 80.0)
    assert abs(estimate_paper(image(T), CAM, CFG, min_tilt_deg=25.0).phi_deg - 30.0) < 0.1


def test_frontal_view_still_gives_the_position():
    T, C = aimed(2.0, 0.0, 0.0, roll=0.3)
    est = estimate_paper(image(T), CAM, CFG)
    assert est.phi_deg < 0.1
    assert np.linalg.norm(est.camera_in_pattern - C) < 0.005
    assert math.degrees(rotation_angle(est.T_camera_pattern.R, T.R)) < 0.1


def test_incomplete_rings_and_bad_input_raise():
    T, _ = aimed(3.0, 40.0, 30.0)
    px = image(T)
    missing = px.copy()
    missing[3] = np.nan
    missing[12] = np.nan
    with pytest.raises(EstimationError, match='no complete ring'):
        estimate_paper(missing, CAM, CFG)
    # One point of the outer ring missing: the inner ring alone is used.
    missing = px.copy()
    missing[5, 0] = np.nan
    assert estimate_paper(missing, CAM, CFG).rings_used == (1,)
    with pytest.raises(EstimationError, match='shape'):
        estimate_paper(px[:9], CAM, CFG)
    # Collinear points and a hyperbola are not ellipses.
    line = px.copy()
    line[1:17] = np.column_stack([np.linspace(100, 500, 16), np.linspace(50, 400, 16)])
    with pytest.raises(EstimationError, match='degenerate conic'):
        estimate_paper(line, CAM, CFG)
    t = np.linspace(-1.0, 1.0, 8)
    side = np.array([1.0, -1.0] * 4)
    hyperbola = np.column_stack([40.0 * np.cosh(t) * side, 30.0 * np.sinh(t)])
    with pytest.raises(EstimationError, match='degenerate conic'):
        ring_view(hyperbola)


def test_conic_fit_is_exact_for_points_on_an_ellipse():
    t = np.radians(45.0 * np.arange(8) + 10.0)
    a, b, u0, v0 = 120.0, 70.0, 5.0, -3.0
    x, y = a * np.cos(t), b * np.sin(t)
    for psi in (0.0, 0.6, -1.2, math.pi / 2, 1.5, -0.01):
        pts = np.column_stack([u0 + x * math.cos(psi) - y * math.sin(psi),
                               v0 + x * math.sin(psi) + y * math.cos(psi)])
        A, B, C, D, E = fit_conic(pts)
        assert np.allclose(A * pts[:, 0] ** 2 + B * pts[:, 0] * pts[:, 1] + C * pts[:, 1] ** 2
                           + D * pts[:, 0] + E * pts[:, 1], 1.0, atol=1e-9)
        view = ring_view(pts, centre_px=(u0, v0))
        assert np.allclose([view.u0, view.v0, view.a, view.b], [u0, v0, a, b], atol=1e-9)
        assert angle_diff(math.degrees(view.psi), math.degrees(psi)) % 180.0 < 1e-9
        assert -math.pi / 2 < view.psi <= math.pi / 2


def test_ellipse_centre_is_off_the_centre_dot_towards_the_near_side():
    # Upright camera below the card: the near side (point 5) is at the bottom
    # of the image and the ellipse centre lies below the centre dot, halfway
    # between the images of points 1 and 5 (the vertices on the symmetry axis).
    T, _ = aimed(2.0, 50.0, 180.0)
    px = image(T)
    est = estimate_paper(px, CAM, CFG)
    u0, v0 = est.ellipse[:2]
    v1, v5 = px[1, 1] - CAM.cy, px[5, 1] - CAM.cy
    assert v5 > -v1 > 0.0
    assert abs(u0) < 1e-9
    assert abs(v0 - (v1 + v5) / 2.0) < 1e-6
