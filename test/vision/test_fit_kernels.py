"""The compiled fits (fit_kernels): OpenCV's maps, refused when degenerate; the pose's passes."""

import cv2
import numpy as np
from pattern_locator.card.pattern import PatternConfig
from pattern_locator.vision import fit_kernels
from pattern_locator.vision.fit_kernels import fit_homography_points


def _project(H, obj):
    p = np.column_stack([obj, np.ones(len(obj))]) @ H.T
    return p[:, :2] / p[:, 2:]


def _random_homography(rng):
    """Return a plane-to-image map of a card somewhere in a 1280x720 view, steep or not."""
    return np.array([[rng.uniform(300, 3000), rng.uniform(-500, 500), rng.uniform(0, 1280)],
                     [rng.uniform(-500, 500), rng.uniform(300, 3000), rng.uniform(0, 720)],
                     [rng.uniform(-3, 3), rng.uniform(-3, 3), 1.0]])


def test_the_fit_is_opencvs_least_squares_homography():
    rng = np.random.default_rng(3)
    for _ in range(500):
        n = int(rng.integers(4, 20))
        obj = rng.uniform(-0.15, 0.15, (n, 2))
        H0 = _random_homography(rng)
        img = _project(H0, obj) + rng.normal(0.0, rng.choice([0.01, 0.3, 2.0]), (n, 2))
        expected, _ = cv2.findHomography(obj, img, 0)
        ok, H = fit_homography_points(obj, img)
        assert ok and H[2, 2] == 1.0
        # The same map (within a few thousandths of a pixel: OpenCV's ten
        # steps stop a little short), never a worse fit.
        assert np.max(np.abs(_project(H, obj) - _project(expected, obj))) < 0.01
        cost = np.sum((_project(H, obj) - img) ** 2)
        assert cost <= np.sum((_project(expected, obj) - img) ** 2) * (1 + 1e-9) + 1e-12


def test_degenerate_points_are_refused():
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    assert not fit_homography_points(square[:3], square[:3])[0]
    line = np.column_stack([np.linspace(0.0, 1.0, 6), np.zeros(6)])
    assert not fit_homography_points(line, line * 3.0)[0]
    same = np.zeros((6, 2))
    assert not fit_homography_points(same, same)[0]
    bad = square.copy()
    bad[1, 0] = np.nan
    ok, H = fit_homography_points(square, bad)
    assert not ok and not np.any(H)


def test_the_pose_refinement_reaches_opencvs_optimum_or_better():
    from pattern_locator.card.pattern import PatternConfig
    from pattern_locator.vision.fit_kernels import refine_pose

    rng = np.random.default_rng(5)
    obj = PatternConfig().model_points().astype(float)
    K = np.array([[1000.0, 0.0, 320.0], [0.0, 1000.0, 240.0], [0.0, 0.0, 1.0]])

    def cost(R, t):
        p = obj @ R.T + t
        return np.sum((p[:, :2] / p[:, 2:] * 1000.0 + [320.0, 240.0] - img) ** 2)

    for _ in range(300):
        rvec = rng.normal(0.0, 0.6, 3)
        tvec = np.array([rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), rng.uniform(1.2, 8.0)])
        img, _ = cv2.projectPoints(obj, rvec, tvec, K, None)
        img = img.reshape(-1, 2) + rng.normal(0.0, rng.choice([0.02, 0.3, 1.0]), (len(obj), 2))
        r0, t0 = rvec + rng.normal(0.0, 0.02, 3), tvec + rng.normal(0.0, 0.02, 3)
        r_cv, t_cv = cv2.solvePnPRefineLM(
            obj, img.reshape(-1, 1, 2), K, None, r0.reshape(3, 1).copy(), t0.reshape(3, 1).copy(),
            (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 20, 1e-10))
        R, t = refine_pose(obj, img, K, cv2.Rodrigues(r0)[0], t0.copy())
        R_cv = cv2.Rodrigues(r_cv)[0]
        assert np.allclose(R @ R.T, np.eye(3), atol=1e-12)
        # Never a worse fit. (Far cards' valleys are flat: there OpenCV's 20
        # steps stop short, by up to 8 cm along the line of sight at 7.6 m;
        # run on, it comes this way.)
        assert cost(R, t) <= cost(R_cv, t_cv.ravel()) * (1 + 1e-9) + 1e-12


def _random_views(rng, count):
    for _ in range(count):
        R, _ = cv2.Rodrigues(rng.normal(0.0, 0.6, 3))
        t = np.array([rng.normal(0, 0.5), rng.normal(0, 0.5), rng.uniform(0.5, 8.0)])
        K = np.array([[rng.uniform(300, 1500), rng.normal(0, 1), rng.uniform(200, 700)],
                      [0.0, rng.uniform(300, 1500), rng.uniform(200, 500)], [0.0, 0.0, 1.0]])
        yield R, t, K


def test_pose_kernels_are_their_numpy_definitions():
    # Projection, the centres of circles' image ellipses (from the inverse of
    # each circle's conic, as the numpy code had it) and the pose's Jacobian.
    cfg = PatternConfig()
    obj, radii = cfg.model_points(), cfg.dot_radii()
    for R, t, K in _random_views(np.random.default_rng(5), 300):
        cam = obj @ R.T + t
        pixels = np.column_stack([K[0, 0] * cam[:, 0] / cam[:, 2] + K[0, 1] * cam[:, 1] / cam[:, 2]
                                  + K[0, 2], K[1, 1] * cam[:, 1] / cam[:, 2] + K[1, 2]])
        assert np.allclose(fit_kernels.project_points(R, t, obj, K), pixels, rtol=0, atol=1e-9)
        img = pixels + 0.5
        assert np.allclose(fit_kernels.point_residuals(R, t, obj, img, K),
                           np.hypot(*(pixels - img).T), rtol=0, atol=1e-9)
        H = K @ np.column_stack([R[:, 0], R[:, 1], t])
        C = np.zeros((len(obj), 3, 3))
        C[:, 0, 0] = C[:, 1, 1] = 1.0
        C[:, 0, 2] = C[:, 2, 0] = -obj[:, 0]
        C[:, 1, 2] = C[:, 2, 1] = -obj[:, 1]
        C[:, 2, 2] = obj[:, 0] ** 2 + obj[:, 1] ** 2 - radii ** 2
        dual = H[None] @ np.linalg.inv(C) @ H.T[None]
        centres = dual[:, :2, 2] / dual[:, 2:3, 2]
        got = fit_kernels.circle_image_centres(R, t, np.ascontiguousarray(obj[:, :2]), radii, K)
        assert np.allclose(got, centres, rtol=0, atol=1e-9)
        # Jacobian by central differences of the projection, moving the camera
        # (c = -R^T t) and turning it about the pattern's axes.
        J = fit_kernels.pose_jacobian(R, t, obj, K)
        c = -R.T @ t
        step = 1e-6
        for k in range(6):
            moved = []
            for sign in (1.0, -1.0):
                dc, dtheta = np.zeros(3), np.zeros(3)
                (dc if k < 3 else dtheta)[k % 3] = sign * step
                R2 = R @ cv2.Rodrigues(dtheta)[0].T
                moved.append(fit_kernels.project_points(R2, -R2 @ (c + dc), obj, K))
            numeric = ((moved[0] - moved[1]) / (2 * step)).reshape(-1)
            assert np.allclose(J[:, k], numeric, rtol=1e-5, atol=1e-4 * np.abs(numeric).max())
        # As numpy's inverse, to the precision of the information matrix
        # (its condition number reaches 1e9: rotations against metres).
        cov = fit_kernels.pose_covariance_matrix(R, t, obj, K, 0.3)
        expected = 0.09 * np.linalg.inv(J.T @ J)
        assert np.abs(cov - expected).max() <= 1e-6 * np.abs(expected).max()


def test_pose_covariance_of_a_degenerate_view_is_infinite():
    # Every point on one ray: J^T J is singular, the pose unknown.
    obj = np.zeros((6, 3))
    cov = fit_kernels.pose_covariance_matrix(np.eye(3), np.array([0.0, 0.0, 2.0]), obj,
                                             np.diag([500.0, 500.0, 1.0]), 0.3)
    assert np.all(np.isinf(cov))


def test_circle_axis_angle_is_the_long_axis_of_the_image_conic():
    for R, t, K in _random_views(np.random.default_rng(8), 300):
        H = K @ np.column_stack([R[:, 0], R[:, 1], t])
        Hinv = np.linalg.inv(H)
        Q = Hinv.T @ np.diag([1.0, 1.0, -0.113 ** 2]) @ Hinv
        quad = Q[:2, :2] * np.sign(Q[0, 0] + Q[1, 1])
        _, vectors = np.linalg.eigh(quad)
        long_axis = vectors[:, 0]                  # the smaller eigenvalue's
        angle = fit_kernels.circle_axis_angle(R, t, K, 0.113)
        assert -np.pi / 2 <= angle < np.pi / 2
        assert abs(np.cos(angle) * long_axis[1] - np.sin(angle) * long_axis[0]) < 1e-9
    # Seen straight on, the ellipse is a circle: no axis, 0.
    K = np.diag([800.0, 800.0, 1.0])
    assert fit_kernels.circle_axis_angle(np.diag([1.0, -1.0, -1.0]), np.array([0, 0, 2.0]), K,
                                         0.113) == 0.0


def _opencv_ippe(obj, img, K):
    """Return the two (R, t) of OpenCV's IPPE (solvePnPGeneric)."""
    n, rvecs, tvecs, _ = cv2.solvePnPGeneric(obj, img.reshape(-1, 1, 2), K, None,
                                             flags=cv2.SOLVEPNP_IPPE)
    return [(cv2.Rodrigues(r)[0], t.ravel()) for r, t in list(zip(rvecs, tvecs))[:n]]


def test_planar_poses_are_opencvs_ippe_solutions():
    from pattern_locator.vision.fit_kernels import planar_poses, project_points, refine_pose

    rng = np.random.default_rng(8)
    obj = PatternConfig().model_points().astype(float)
    # No skew: OpenCV's projections ignore K[0, 1] (ours take it).
    K = np.array([[900.0, 0.0, 330.0], [0.0, 910.0, 230.0], [0.0, 0.0, 1.0]])
    tried = 0
    for _ in range(400):
        rvec = rng.normal(0.0, 1.0, 3)
        rvec *= rng.uniform(0.0, 1.3) / np.linalg.norm(rvec)
        R0 = cv2.Rodrigues(rvec)[0]
        t0 = np.array([rng.uniform(-0.5, 0.5), rng.uniform(-0.4, 0.4), rng.uniform(0.8, 8.0)])
        if np.any((obj @ R0.T + t0)[:, 2] < 0.3):
            continue
        tried += 1
        exact = project_points(R0, t0, obj, K)
        sigma = float(rng.choice([0.0, 0.2, 1.0]))
        img = exact + rng.normal(0.0, sigma, exact.shape)
        ok, Rs, ts, errors, projected = planar_poses(obj, img, K)
        assert ok
        for k in range(2):
            assert np.allclose(Rs[k] @ Rs[k].T, np.eye(3), atol=1e-12)
            assert np.linalg.det(Rs[k]) > 0.0
            assert np.allclose(projected[k], project_points(Rs[k], ts[k], obj, K))
            assert np.isclose(errors[k], np.sum((projected[k] - img) ** 2), rtol=1e-12, atol=0.0)
        opencv = _opencv_ippe(obj, img, K)
        if sigma == 0.0:
            # Exact points: each of OpenCV's solutions is one of ours, to rounding.
            for R, t in opencv:
                near = min(range(2), key=lambda k: np.abs(Rs[k] - R).max())
                assert np.abs(Rs[near] - R).max() < 1e-9
                assert np.abs(ts[near] - t).max() < 1e-9 * np.linalg.norm(t)
        else:
            # Noisy ones: the homographies differ (OpenCV fits its own), and
            # the best start fits the points as well as OpenCV's, within 2 %.
            best_opencv = min(np.sum((project_points(R, t, obj, K) - img) ** 2)
                              for R, t in opencv)
            assert errors.min() <= 1.02 * best_opencv
        # The refinement takes our best start and OpenCV's to the same optimum.
        best = int(np.argmin(errors))
        R_ref, t_ref = min(opencv,
                           key=lambda s: np.sum((project_points(s[0], s[1], obj, K) - img) ** 2))
        Ra, ta = refine_pose(obj, img, K, Rs[best], ts[best])
        Rb, tb = refine_pose(obj, img, K, R_ref, t_ref)
        if np.abs(Rs[best] - R_ref).max() < 0.1:
            assert np.abs(Ra - Rb).max() < 1e-6 and np.abs(ta - tb).max() < 1e-6
    assert tried > 300


def test_planar_poses_refuse_degenerate_points():
    from pattern_locator.vision.fit_kernels import planar_poses

    K = np.array([[900.0, 0.0, 320.0], [0.0, 900.0, 240.0], [0.0, 0.0, 1.0]])
    line = np.column_stack([np.linspace(0.0, 0.2, 6), np.zeros(6), np.zeros(6)])
    assert not planar_poses(line, line[:, :2] * 900.0 + 300.0, K)[0]
    obj = PatternConfig().model_points().astype(float)
    img = np.full((len(obj), 2), 300.0)
    img[3, 0] = np.nan
    assert not planar_poses(obj, img, K)[0]
    assert not planar_poses(obj[:3], img[:3], K)[0]


def test_refine_exact_is_its_numpy_steps():
    from pattern_locator.vision.fit_kernels import (circle_image_centres, planar_poses,
                                                    point_residuals, project_points,
                                                    refine_exact, refine_pose)

    rng = np.random.default_rng(13)
    cfg = PatternConfig()
    obj, radii = cfg.model_points().astype(float), cfg.dot_radii().astype(float)
    K = np.array([[1000.0, 0.0, 320.0], [0.0, 1000.0, 240.0], [0.0, 0.0, 1.0]])
    dropped = 0
    for _ in range(200):
        rvec = rng.normal(0.0, 0.5, 3)
        t0 = np.array([rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3), rng.uniform(1.0, 6.0)])
        img = project_points(cv2.Rodrigues(rvec)[0], t0, obj, K) + rng.normal(0.0, 0.3, (17, 2))
        if rng.random() < 0.3:
            img[int(rng.integers(0, 17))] += rng.normal(0.0, 8.0, 2)    # a dot off the fit
        _, Rs, ts, _, projected = planar_poses(obj, img, K)
        R, t, residual, outliers, ss, used = refine_exact(obj, img, K, Rs[0], ts[0],
                                                          projected[0], radii, True, 0.2, 5.0)
        corrected = img - (circle_image_centres(Rs[0], ts[0], obj[:, :2].copy(), radii, K)
                           - projected[0])
        assert np.array_equal(used, corrected)
        R_np, t_np = refine_pose(obj, corrected, K, Rs[0], ts[0])
        res_np = point_residuals(R_np, t_np, obj, corrected, K)
        median = float(np.partition(res_np, 8)[8])
        assert np.array_equal(R, R_np) and np.array_equal(t, t_np)
        assert np.array_equal(residual, res_np)
        assert np.array_equal(outliers, res_np > max(0.2, 5.0 * median))
        assert ss == float(np.sum(res_np ** 2))
        dropped += int(outliers.any())
    assert dropped > 20


def _fit_rounds_numpy(obj, img, radii, max_error, min_tolerance, min_points, anchored=True):
    """Refit without the points off the fit, one kernel call a step (the kernel's spec)."""
    from pattern_locator.vision.card_kernels import homography_inliers

    inliers = np.ones(len(obj), dtype=bool)
    tol = np.empty(len(obj))
    for step in range(4):
        ok, H = fit_homography_points(obj[inliers], img[inliers])
        if not ok:
            return None
        ok, now, count, same = homography_inliers(H, obj, img, radii, max_error, min_tolerance,
                                                  tol, inliers, step == 0)
        if not ok or count < min_points or (anchored and not now[-1]):
            return None
        if same:
            break
        inliers = now
    return H, inliers


def test_homography_rounds_drop_the_points_off_the_fit_as_one_step_at_a_time():
    from pattern_locator.vision.fit_kernels import fit_homography_inliers

    rng = np.random.default_rng(17)
    dropped = refused = last_dropped = 0
    for _ in range(400):
        n = int(rng.integers(6, 18))
        obj = rng.uniform(-0.12, 0.12, (n, 2))
        H0 = _random_homography(rng)
        img = _project(H0, obj) + rng.normal(0.0, 0.3, (n, 2))
        for _ in range(int(rng.integers(0, 4))):
            img[int(rng.integers(0, n))] += rng.normal(0.0, 20.0, 2)
        radii = np.full(n, 0.01)
        for anchored in (True, False):
            expected = _fit_rounds_numpy(obj, img, radii, 0.25, 0.75, 6, anchored)
            ok, H, inliers = fit_homography_inliers(obj, img, radii, 0.25, 0.75, 6, anchored)
            assert ok == (expected is not None)
            if ok:
                assert np.array_equal(H, expected[0]) and np.array_equal(inliers, expected[1])
                dropped += int(not inliers.all())
                # Unanchored, the last point may be dropped like any other.
                last_dropped += int(not anchored and not inliers[-1])
            refused += int(not ok)
    assert dropped > 100 and refused > 10 and last_dropped > 5


def test_the_prior_refinement_finds_the_map_pose():
    from pattern_locator.vision.fit_kernels import (pose_cost, _prior_cost, refine_pose,
                                                    refine_pose_prior)

    rng = np.random.default_rng(17)
    obj = PatternConfig().model_points().astype(float)
    K = np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])
    sigma, up_sigma, height_sigma = 0.3, np.radians(5.0), 0.1

    def total(R, t, up, height):
        return pose_cost(obj, img, K, R, t) / sigma ** 2 + _prior_cost(
            R, t, up, 1.0 / up_sigma, height, 1.0 / height_sigma)

    for _ in range(100):
        R0 = cv2.Rodrigues(rng.normal(0.0, 0.3, 3))[0]
        t0 = np.array([rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3), rng.uniform(1.5, 8.0)])
        img = fit_kernels.project_points(R0, t0, obj, K) + rng.normal(0.0, sigma, (17, 2))
        up = R0[:, 1] + rng.normal(0.0, 0.05, 3)
        up /= np.linalg.norm(up)
        height = float(-(R0.T @ t0)[1]) + rng.normal(0.0, 0.2)
        # Weights 0 and 1: the image's refinement, to the bit.
        R_img, t_img = refine_pose(obj, img, K, R0, t0)
        R_same, t_same = refine_pose_prior(obj, img, K, R0, t0, 1.0, np.zeros(3), 0.0, 0.0, 0.0)
        assert np.array_equal(R_img, R_same) and np.array_equal(t_img, t_same)
        # With up and height, a minimum of the sum: no small step lowers it,
        # and it is no higher than the image's own optimum.
        R, t = refine_pose_prior(obj, img, K, R_img, t_img, 1.0 / sigma, up, 1.0 / up_sigma,
                                 height, 1.0 / height_sigma)
        best = total(R, t, up, height)
        assert best <= total(R_img, t_img, up, height) + 1e-9
        for _ in range(12):
            step = rng.normal(0.0, 1.0, 6) * np.array([1e-3] * 3 + [1e-3] * 3)
            R_near = cv2.Rodrigues(step[:3])[0] @ R
            assert total(R_near, t + step[3:], up, height) >= best - 1e-7 * max(best, 1.0)
