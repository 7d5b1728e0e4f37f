"""The compiled fits (fit_kernels): OpenCV's least-squares maps, refused when degenerate."""

import cv2
import numpy as np
from pattern_locator.vision.fit_kernels import fit_homography_points


def _project(H, obj):
    p = np.column_stack([obj, np.ones(len(obj))]) @ H.T
    return p[:, :2] / p[:, 2:]


def test_the_fit_is_opencvs_least_squares_homography():
    rng = np.random.default_rng(3)
    for _ in range(500):
        n = int(rng.integers(4, 20))
        obj = rng.uniform(-0.15, 0.15, (n, 2))
        H0 = np.array([[rng.uniform(300, 3000), rng.uniform(-500, 500), rng.uniform(0, 1280)],
                       [rng.uniform(-500, 500), rng.uniform(300, 3000), rng.uniform(0, 720)],
                       [rng.uniform(-3, 3), rng.uniform(-3, 3), 1.0]])
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
