"""
The plane-to-image homography of a card's dots and the refinement of its pose, compiled.

What ``cv2.findHomography(obj, img, 0)`` computes: a linear fit on
Hartley-normalised points, then Levenberg-Marquardt on the reprojection
error in the image (at most 10 steps, as OpenCV's refinement), scaled so
that ``H[2, 2]`` is 1. Both reach the same least-squares map (within 0.003
px on 2000 random views, ours never the worse fit: OpenCV's ten steps stop
a little short; test_fit_kernels.py); the linear start differs (OpenCV's
takes the null vector of the 2N x 9 system, this one fixes the normalised
map's ``H[2, 2]`` at 1: no eigen-decomposition, which numba would take from
SciPy). OpenCV's call cost 70-180 us in the detector (for 7-20 points),
most of it not arithmetic; this one about 14 us. The
detector fits two or three homographies a frame (the cards stage's check,
the refit to the measured dots, their outlier rounds).

The pose's Levenberg-Marquardt (:func:`refine_pose`) minimises what
``cv2.solvePnPRefineLM`` does, the reprojection error in the ideal image,
to the same optimum or a lower one (where OpenCV's 20 steps stop short in
a far card's flat valley), in about a third of its time (27 against 95 us).
:func:`refine_pose_prior` is the same with a prior's up and camera height
as measurements too: the MAP pose of a close planar call.

The exact estimator's other small passes are here too (:func:`project_points`,
:func:`pose_cost`, :func:`circle_image_centres`, :func:`point_residuals`,
:func:`pose_jacobian`, :func:`pose_covariance_matrix`,
:func:`circle_axis_angle`): as numpy calls
on 17 points they were some thirty calls of fixed cost a pose (274 us a
pose with them, 105 without); the results agree with the numpy code's to
1e-12 (test_fit_kernels.py). So are its start, IPPE's two planar poses
(:func:`planar_poses`, the solutions of OpenCV's ``solvePnPGeneric`` with
``SOLVEPNP_IPPE`` to rounding on exact points; OpenCV's call cost 80-110 us
a card in the detector's frame), and its last steps in one call
(:func:`refine_exact`); and the cards stage's rounds of fitting a
homography and dropping the points off it (:func:`fit_homography_inliers`).
"""

import math

import numba
import numpy as np

from .card_kernels import _pairwise_sum, _solve, homography_inliers

# As card_kernels: compiled once per installation, numpy's arithmetic, the GIL kept.
_kernel = numba.njit(cache=True, nogil=False, error_model='numpy')

_MAX_STEPS = 10


@_kernel
def fit_homography_points(obj, img):
    """
    Homography (3x3, ``H[2, 2]`` = 1) taking plane points ``obj`` (N, 2) to ``img`` (N, 2).

    Returns ``(ok, H)``; ``ok`` False (H zero) for fewer than 4 points, a
    degenerate layout or a result that is not finite.
    """
    n = obj.shape[0]
    H = np.zeros((3, 3))
    if n < 4 or img.shape[0] != n or obj.shape[1] != 2 or img.shape[1] != 2:
        return False, H
    # Hartley normalisation: centroid at the origin, mean distance sqrt(2).
    mo0 = mo1 = mi0 = mi1 = 0.0
    for i in range(n):
        mo0 += obj[i, 0]
        mo1 += obj[i, 1]
        mi0 += img[i, 0]
        mi1 += img[i, 1]
    mo0, mo1, mi0, mi1 = mo0 / n, mo1 / n, mi0 / n, mi1 / n
    do = di = 0.0
    for i in range(n):
        do += math.hypot(obj[i, 0] - mo0, obj[i, 1] - mo1)
        di += math.hypot(img[i, 0] - mi0, img[i, 1] - mi1)
    if not (do > 0.0 and di > 0.0):
        return False, H
    so, si = math.sqrt(2.0) * n / do, math.sqrt(2.0) * n / di
    # The linear fit with Hn[2, 2] = 1 (the normalised origin is the points'
    # centroid, in view: its scale is not zero): normal equations, 8 x 8.
    M = np.zeros((8, 8))
    b = np.zeros(8)
    row = np.empty(8)
    for i in range(n):
        x, y = (obj[i, 0] - mo0) * so, (obj[i, 1] - mo1) * so
        u, v = (img[i, 0] - mi0) * si, (img[i, 1] - mi1) * si
        for axis in range(2):
            if axis == 0:
                row[0], row[1], row[2], row[3], row[4], row[5] = x, y, 1.0, 0.0, 0.0, 0.0
                row[6], row[7], target = -u * x, -u * y, u
            else:
                row[0], row[1], row[2], row[3], row[4], row[5] = 0.0, 0.0, 0.0, x, y, 1.0
                row[6], row[7], target = -v * x, -v * y, v
            for a in range(8):
                b[a] += row[a] * target
                for c in range(8):
                    M[a, c] += row[a] * row[c]
    ok, h = _solve(M, b)
    if not ok:
        return False, H
    # Undo the normalisation: H = Ti^-1 Hn To.
    Hn = np.ones((3, 3))
    for k in range(8):
        Hn[k // 3, k % 3] = h[k]
    To = np.array([[so, 0.0, -so * mo0], [0.0, so, -so * mo1], [0.0, 0.0, 1.0]])
    Ti_inv = np.array([[1.0 / si, 0.0, mi0], [0.0, 1.0 / si, mi1], [0.0, 0.0, 1.0]])
    G = _mul3(_mul3(Ti_inv, Hn), To)
    if not abs(G[2, 2]) > 1e-300:
        return False, H
    p = np.empty(8)
    for k in range(8):
        p[k] = G[k // 3, k % 3] / G[2, 2]
    p = _refine(obj, img, p)
    for k in range(8):
        H[k // 3, k % 3] = p[k]
    H[2, 2] = 1.0
    for r in range(3):
        for c in range(3):
            if not abs(H[r, c]) < np.inf:
                return False, np.zeros((3, 3))
    return True, H


@_kernel
def fit_homography_inliers(obj, img, radii, max_error, min_tolerance, min_points, anchored):
    """
    Homography from plane points to pixels, refitted without the points off it.

    :func:`.cards.fit_homography`'s rounds in one call: fit to the points
    kept (:func:`fit_homography_points`), keep those on the fit
    (:func:`.card_kernels.homography_inliers`, tolerances set on the first
    fit), up to four fits, until the kept points stay the same. Returns
    ``(ok, H, inliers)``; ``ok`` False when a fit fails, fewer than
    ``min_points`` points stay on it or, when ``anchored``, the last point
    (the centre) is off.
    """
    n = obj.shape[0]
    inliers = np.ones(n, dtype=np.bool_)
    tol = np.empty(n)
    H = np.zeros((3, 3))
    if n < min_points:
        return False, H, inliers
    for step in range(4):
        m = 0
        for i in range(n):
            m += inliers[i]
        kept_obj = np.empty((m, 2))
        kept_img = np.empty((m, 2))
        k = 0
        for i in range(n):
            if inliers[i]:
                kept_obj[k, 0], kept_obj[k, 1] = obj[i, 0], obj[i, 1]
                kept_img[k, 0], kept_img[k, 1] = img[i, 0], img[i, 1]
                k += 1
        ok, H = fit_homography_points(kept_obj, kept_img)
        if not ok:
            return False, H, inliers
        ok, now, count, same = homography_inliers(H, obj, img, radii, max_error, min_tolerance,
                                                  tol, inliers, step == 0)
        if not ok or count < min_points or (anchored and not now[n - 1]):
            return False, H, inliers
        if same:
            break
        inliers = now
    return True, H, inliers


@_kernel
def _cost(obj, img, p):
    """Sum of squared image distances of the map ``p`` (8 parameters, h22 = 1)."""
    total = 0.0
    for i in range(obj.shape[0]):
        x, y = obj[i, 0], obj[i, 1]
        w = p[6] * x + p[7] * y + 1.0
        du = (p[0] * x + p[1] * y + p[2]) / w - img[i, 0]
        dv = (p[3] * x + p[4] * y + p[5]) / w - img[i, 1]
        total += du * du + dv * dv
    return total


@_kernel
def _refine(obj, img, p):
    """Levenberg-Marquardt on the reprojection error from ``p``; the best parameters found."""
    n = obj.shape[0]
    JtJ = np.empty((8, 8))
    Jtr = np.empty(8)
    jrow = np.empty(8)
    lam = 1e-3
    cost = _cost(obj, img, p)
    for _ in range(_MAX_STEPS):
        JtJ[:, :] = 0.0
        Jtr[:] = 0.0
        for i in range(n):
            x, y = obj[i, 0], obj[i, 1]
            w = p[6] * x + p[7] * y + 1.0
            u = (p[0] * x + p[1] * y + p[2]) / w
            v = (p[3] * x + p[4] * y + p[5]) / w
            for axis in range(2):
                for k in range(8):
                    jrow[k] = 0.0
                if axis == 0:
                    jrow[0], jrow[1], jrow[2] = x / w, y / w, 1.0 / w
                    jrow[6], jrow[7] = -u * x / w, -u * y / w
                    res = u - img[i, 0]
                else:
                    jrow[3], jrow[4], jrow[5] = x / w, y / w, 1.0 / w
                    jrow[6], jrow[7] = -v * x / w, -v * y / w
                    res = v - img[i, 1]
                _accumulate(JtJ, Jtr, jrow, res)
        improved = False
        for _ in range(8):
            solved, step = _damped_step(JtJ, Jtr, lam)
            if not solved:
                return p
            trial = p - step
            trial_cost = _cost(obj, img, trial)
            if trial_cost < cost:
                done = cost - trial_cost <= 1e-15 * max(cost, 1e-30) \
                    or _norm(step) <= 1e-12 * (_norm(p) + 1e-12)
                p, cost = trial, trial_cost
                lam = max(lam * 0.1, 1e-12)
                improved = True
                if done:
                    return p
                break
            lam *= 10.0
        if not improved:
            return p
    return p


@_kernel
def _mul3(A, B):
    """3x3 matrix product (numba's @ needs BLAS from SciPy)."""
    C = np.zeros((3, 3))
    for r in range(3):
        for c in range(3):
            C[r, c] = (A[r, 0] * B[0, c] + A[r, 1] * B[1, c]) + A[r, 2] * B[2, c]
    return C


@_kernel
def _accumulate(JtJ, Jtr, jrow, res):
    """Add one residual's row to the normal equations (J^T J, J^T r)."""
    n = jrow.shape[0]
    for a in range(n):
        Jtr[a] += jrow[a] * res
        for b in range(n):
            JtJ[a, b] += jrow[a] * jrow[b]


@_kernel
def _damped_step(JtJ, Jtr, lam):
    """Levenberg-Marquardt's step for damping ``lam`` (Marquardt's scaling): (ok, step)."""
    M = JtJ.copy()
    for a in range(M.shape[0]):
        M[a, a] += lam * (JtJ[a, a] + 1e-12)
    return _solve(M, Jtr)


@_kernel
def _norm(a):
    total = 0.0
    for k in range(a.shape[0]):
        total += a[k] * a[k]
    return math.sqrt(total)


@_kernel
def _rotation(w0, w1, w2):
    """Rotation matrix of the rotation vector (w0, w1, w2) (Rodrigues' formula)."""
    angle = math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    R = np.eye(3)
    if angle < 1e-300:
        return R
    k0, k1, k2 = w0 / angle, w1 / angle, w2 / angle
    s, c = math.sin(angle), math.cos(angle)
    K = np.array([[0.0, -k2, k1], [k2, 0.0, -k0], [-k1, k0, 0.0]])
    KK = _mul3(K, K)
    for r in range(3):
        for col in range(3):
            R[r, col] += s * K[r, col] + (1.0 - c) * KK[r, col]
    return R


@_kernel
def pose_cost(obj, img, K, R, t):
    """Sum of squared distances in the ideal image (K's pinhole, skew included)."""
    total = 0.0
    for i in range(obj.shape[0]):
        x = R[0, 0] * obj[i, 0] + R[0, 1] * obj[i, 1] + R[0, 2] * obj[i, 2] + t[0]
        y = R[1, 0] * obj[i, 0] + R[1, 1] * obj[i, 1] + R[1, 2] * obj[i, 2] + t[1]
        z = R[2, 0] * obj[i, 0] + R[2, 1] * obj[i, 1] + R[2, 2] * obj[i, 2] + t[2]
        du = (K[0, 0] * x + K[0, 1] * y) / z + K[0, 2] - img[i, 0]
        dv = K[1, 1] * y / z + K[1, 2] - img[i, 1]
        total += du * du + dv * dv
    return total


@_kernel
def refine_pose(obj, img, K, R, t):
    """
    Levenberg-Marquardt on the reprojection error from the pose (R, t): the best pose found.

    ``obj`` (N, 3) plane points, ``img`` (N, 2) ideal-image points, ``K``
    the camera matrix; ``X_camera = R X + t``. Each step turns R by a small
    rotation about the camera's axes and moves t (at most 20 steps, as the
    detector asked of OpenCV). Returns ``(R, t)``; the input when no step
    lowers the error.
    """
    return refine_pose_prior(obj, img, K, R, t, 1.0, np.zeros(3), 0.0, 0.0, 0.0)


@_kernel
def _prior_cost(R, t, up, up_weight, height, height_weight):
    """Sum the prior's squared residuals: up (chord of R's column 1 to ``up``), camera height."""
    total = 0.0
    if up_weight > 0.0:
        for k in range(3):
            d = (R[k, 1] - up[k]) * up_weight
            total += d * d
    if height_weight > 0.0:
        d = (-(R[0, 1] * t[0] + R[1, 1] * t[1] + R[2, 1] * t[2]) - height) * height_weight
        total += d * d
    return total


@_kernel
def refine_pose_prior(obj, img, K, R, t, pixel_weight, up, up_weight, height, height_weight):
    """
    :func:`refine_pose` on the reprojection error plus what is known of the camera: the MAP pose.

    The image's residuals count in units of the pixel noise (``pixel_weight``
    = 1 / sigma); ``up`` (a unit vector in the camera frame) is where the
    pattern's +y should point, ``up_weight`` = 1 / its sigma (radians; 0: not
    known); ``height`` the camera's y in the pattern frame, ``height_weight``
    = 1 / its sigma (metres; 0: not known). With both weights 0 and
    ``pixel_weight`` 1 it is :func:`refine_pose`, to the bit.
    """
    n = obj.shape[0]
    R = R.copy()
    t = t.copy()
    JtJ = np.empty((6, 6))
    Jtr = np.empty(6)
    jrow = np.empty(6)
    lam = 1e-3
    pw2 = pixel_weight * pixel_weight
    cost = pw2 * pose_cost(obj, img, K, R, t) + _prior_cost(
        R, t, up, up_weight, height, height_weight)
    if not cost < np.inf:
        return R, t
    for _ in range(20):
        JtJ[:, :] = 0.0
        Jtr[:] = 0.0
        for i in range(n):
            rx = R[0, 0] * obj[i, 0] + R[0, 1] * obj[i, 1] + R[0, 2] * obj[i, 2]
            ry = R[1, 0] * obj[i, 0] + R[1, 1] * obj[i, 1] + R[1, 2] * obj[i, 2]
            rz = R[2, 0] * obj[i, 0] + R[2, 1] * obj[i, 1] + R[2, 2] * obj[i, 2]
            x, y, z = rx + t[0], ry + t[1], rz + t[2]
            iz = 1.0 / z
            # d(pixel)/d(camera point), rows u and v.
            a0, a1, a2 = K[0, 0] * iz, K[0, 1] * iz, -(K[0, 0] * x + K[0, 1] * y) * iz * iz
            b1, b2 = K[1, 1] * iz, -K[1, 1] * y * iz * iz
            for axis in range(2):
                if axis == 0:
                    d0, d1, d2 = a0, a1, a2
                    res = (K[0, 0] * x + K[0, 1] * y) * iz + K[0, 2] - img[i, 0]
                else:
                    d0, d1, d2 = 0.0, b1, b2
                    res = K[1, 1] * y * iz + K[1, 2] - img[i, 1]
                # A turn w moves the point by w x (R X): d/dw = -[R X]x.
                jrow[0] = d1 * (-rz) + d2 * ry
                jrow[1] = d0 * rz + d2 * (-rx)
                jrow[2] = d0 * (-ry) + d1 * rx
                jrow[3], jrow[4], jrow[5] = d0, d1, d2
                for k in range(6):
                    jrow[k] *= pixel_weight
                _accumulate(JtJ, Jtr, jrow, res * pixel_weight)
        if up_weight > 0.0:
            # The pattern's +y in the camera, s = R e_y: a turn w moves it by w x s.
            s0, s1, s2 = R[0, 1], R[1, 1], R[2, 1]
            for k in range(3):
                jrow[3], jrow[4], jrow[5] = 0.0, 0.0, 0.0
                if k == 0:
                    jrow[0], jrow[1], jrow[2] = 0.0, s2, -s1
                elif k == 1:
                    jrow[0], jrow[1], jrow[2] = -s2, 0.0, s0
                else:
                    jrow[0], jrow[1], jrow[2] = s1, -s0, 0.0
                for a in range(3):
                    jrow[a] *= up_weight
                _accumulate(JtJ, Jtr, jrow, (R[k, 1] - up[k]) * up_weight)
        if height_weight > 0.0:
            # The camera's height c_y = -s . t: d/dw = -(s x t), d/dt = -s.
            s0, s1, s2 = R[0, 1], R[1, 1], R[2, 1]
            jrow[0] = -(s1 * t[2] - s2 * t[1]) * height_weight
            jrow[1] = -(s2 * t[0] - s0 * t[2]) * height_weight
            jrow[2] = -(s0 * t[1] - s1 * t[0]) * height_weight
            jrow[3], jrow[4], jrow[5] = -s0 * height_weight, -s1 * height_weight, \
                -s2 * height_weight
            _accumulate(JtJ, Jtr, jrow,
                        (-(s0 * t[0] + s1 * t[1] + s2 * t[2]) - height) * height_weight)
        improved = False
        for _ in range(8):
            solved, step = _damped_step(JtJ, Jtr, lam)
            if not solved:
                return R, t
            R_trial = _mul3(_rotation(-step[0], -step[1], -step[2]), R)
            t_trial = np.empty(3)
            for k in range(3):
                t_trial[k] = t[k] - step[3 + k]
            trial_cost = pw2 * pose_cost(obj, img, K, R_trial, t_trial) + _prior_cost(
                R_trial, t_trial, up, up_weight, height, height_weight)
            if trial_cost < cost:
                done = cost - trial_cost <= 1e-15 * max(cost, 1e-30) \
                    or _norm(step) <= 1e-12 * (1.0 + _norm(t))
                R, t, cost = R_trial, t_trial, trial_cost
                lam = max(lam * 0.1, 1e-12)
                improved = True
                if done:
                    return R, t
                break
            lam *= 10.0
        if not improved:
            return R, t
    return R, t


@_kernel
def project_points(R, t, obj, K):
    """Ideal-image pixels (N, 2) of plane points ``obj`` (N, 3) at the pose (R, t)."""
    n = obj.shape[0]
    out = np.empty((n, 2))
    for i in range(n):
        x = R[0, 0] * obj[i, 0] + R[0, 1] * obj[i, 1] + R[0, 2] * obj[i, 2] + t[0]
        y = R[1, 0] * obj[i, 0] + R[1, 1] * obj[i, 1] + R[1, 2] * obj[i, 2] + t[1]
        z = R[2, 0] * obj[i, 0] + R[2, 1] * obj[i, 1] + R[2, 2] * obj[i, 2] + t[2]
        out[i, 0] = K[0, 0] * (x / z) + K[0, 1] * (y / z) + K[0, 2]
        out[i, 1] = K[1, 1] * (y / z) + K[1, 2]
    return out


@_kernel
def planar_poses(obj, img, K):
    """
    Return the two poses IPPE gives a plane seen in the ideal image (Collins and Bartoli, 2014).

    ``obj`` (N, 3) plane points (z = 0), ``img`` (N, 2) their ideal-image
    pixels, ``K`` the camera matrix. As ``cv2.solvePnPGeneric`` with
    ``SOLVEPNP_IPPE`` computes: the homography from the points (their
    centroid the origin) to normalised image points, its Jacobian at the
    origin, and the two rotations that give that Jacobian to first order
    (the plane turned towards the camera or away, about the line of
    sight); each with its least-squares translation. Returns ``(ok, R (2,
    3, 3), t (2, 3), squared reprojection error (2,), projections (2, N,
    2))``; ``ok`` False when the points are degenerate or a result is not
    finite.
    """
    n = obj.shape[0]
    Rs = np.zeros((2, 3, 3))
    ts = np.zeros((2, 3))
    errors = np.full(2, np.inf)
    projected = np.zeros((2, n, 2))
    if n < 4:
        return False, Rs, ts, errors, projected
    cx = cy = 0.0
    for i in range(n):
        cx += obj[i, 0]
        cy += obj[i, 1]
    cx, cy = cx / n, cy / n
    plane = np.empty((n, 2))
    norm = np.empty((n, 2))
    for i in range(n):
        plane[i, 0], plane[i, 1] = obj[i, 0] - cx, obj[i, 1] - cy
        y = (img[i, 1] - K[1, 2]) / K[1, 1]
        norm[i, 0] = (img[i, 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
        norm[i, 1] = y
    ok, H = fit_homography_points(plane, norm)
    if not ok:
        return False, Rs, ts, errors, projected
    # The origin's image v = (p, q, 1) and the Jacobian there.
    p, q = H[0, 2], H[1, 2]
    j00, j01 = H[0, 0] - H[2, 0] * p, H[0, 1] - H[2, 1] * p
    j10, j11 = H[1, 0] - H[2, 0] * q, H[1, 1] - H[2, 1] * q
    # Rv: the rotation taking the z axis onto v.
    nv = math.sqrt(p * p + q * q + 1.0)
    ax, ay, az = p / nv, q / nv, 1.0 / nv
    d = 1.0 / (1.0 + az)
    Rv = np.empty((3, 3))
    Rv[0, 0], Rv[0, 1], Rv[0, 2] = 1.0 - ax * ax * d, -ax * ay * d, ax
    Rv[1, 0], Rv[1, 1], Rv[1, 2] = -ax * ay * d, 1.0 - ay * ay * d, ay
    Rv[2, 0], Rv[2, 1], Rv[2, 2] = -ax, -ay, 1.0 - (ax * ax + ay * ay) * d
    b00, b01 = Rv[0, 0] - p * Rv[2, 0], Rv[0, 1] - p * Rv[2, 1]
    b10, b11 = Rv[1, 0] - q * Rv[2, 0], Rv[1, 1] - q * Rv[2, 1]
    det = b00 * b11 - b01 * b10
    if not abs(det) > 1e-300:
        return False, Rs, ts, errors, projected
    a00 = (b11 * j00 - b01 * j10) / det
    a01 = (b11 * j01 - b01 * j11) / det
    a10 = (-b10 * j00 + b00 * j10) / det
    a11 = (-b10 * j01 + b00 * j11) / det
    # The largest singular value of A scales it to the rotation's 2 x 2 block.
    s00 = a00 * a00 + a01 * a01
    s01 = a00 * a10 + a01 * a11
    s11 = a10 * a10 + a11 * a11
    gamma = math.sqrt(0.5 * (s00 + s11 + math.sqrt((s00 - s11) ** 2 + 4.0 * s01 * s01)))
    if not gamma > 1e-12:
        return False, Rs, ts, errors, projected
    r00, r01, r10, r11 = a00 / gamma, a01 / gamma, a10 / gamma, a11 / gamma
    c0 = math.sqrt(max(1.0 - r00 * r00 - r10 * r10, 0.0))
    c1 = math.sqrt(max(1.0 - r01 * r01 - r11 * r11, 0.0))
    if -r00 * r01 - r10 * r11 < 0.0:
        c1 = -c1
    local = np.empty((3, 3))
    M = np.zeros((3, 3))
    rhs = np.zeros(3)
    for k in range(2):
        sign = 1.0 if k == 0 else -1.0
        # Columns: the plane's x and y axes in v's frame, and their cross product.
        local[0, 0], local[1, 0], local[2, 0] = r00, r10, sign * c0
        local[0, 1], local[1, 1], local[2, 1] = r01, r11, sign * c1
        local[0, 2] = local[1, 0] * local[2, 1] - local[2, 0] * local[1, 1]
        local[1, 2] = local[2, 0] * local[0, 1] - local[0, 0] * local[2, 1]
        local[2, 2] = local[0, 0] * local[1, 1] - local[1, 0] * local[0, 1]
        R = _mul3(Rv, local)
        # The translation (for the centred points) in least squares:
        # x (r3.P + t3) = r1.P + t1 and y (r3.P + t3) = r2.P + t2.
        M[:] = 0.0
        rhs[:] = 0.0
        for i in range(n):
            X, Y = plane[i, 0], plane[i, 1]
            p0 = R[0, 0] * X + R[0, 1] * Y
            p1 = R[1, 0] * X + R[1, 1] * Y
            p2 = R[2, 0] * X + R[2, 1] * Y
            x, y = norm[i, 0], norm[i, 1]
            # Rows (1, 0, -x) and (0, 1, -y) against x p2 - p0 and y p2 - p1.
            e0, e1 = x * p2 - p0, y * p2 - p1
            M[0, 0] += 1.0
            M[0, 2] -= x
            M[1, 1] += 1.0
            M[1, 2] -= y
            M[2, 2] += x * x + y * y
            rhs[0] += e0
            rhs[1] += e1
            rhs[2] -= x * e0 + y * e1
        M[2, 0], M[2, 1] = M[0, 2], M[1, 2]
        solved, t = _solve(M, rhs)
        if not solved:
            return False, Rs, ts, errors, projected
        # Back from the centred points: t - R c.
        for r in range(3):
            t[r] -= R[r, 0] * cx + R[r, 1] * cy
            for col in range(3):
                Rs[k, r, col] = R[r, col]
            ts[k, r] = t[r]
        projected[k] = project_points(R, t, obj, K)
        total = 0.0
        for i in range(n):
            du, dv = projected[k, i, 0] - img[i, 0], projected[k, i, 1] - img[i, 1]
            total += du * du + dv * dv
        errors[k] = total
    finite = True
    for k in range(2):
        finite = finite and math.isfinite(errors[k])
    return finite, Rs, ts, errors, projected


@_kernel
def _plane_homography(R, t, K):
    """``K [r1 r2 t]``: the map from the pattern plane (z = 0) to the ideal image."""
    H = np.empty((3, 3))
    for r in range(3):
        for col in range(3):
            H[r, col] = K[r, 0] * (R[0, col] if col < 2 else t[0]) \
                + K[r, 1] * (R[1, col] if col < 2 else t[1]) \
                + K[r, 2] * (R[2, col] if col < 2 else t[2])
    return H


@_kernel
def circle_image_centres(R, t, xy, radii, K):
    """
    Ideal-image centres (N, 2) of the image ellipses of plane circles at the pose (R, t).

    The image conic's centre is the pole of the line at infinity: with
    ``H = K [r1 r2 t]`` and the circle's dual conic ``C* = [[c c^T - r^2 I,
    c], [c^T, 1]]`` (its point conic's inverse times -r^2), the centre is
    ``H C* h3`` dehomogenised, ``h3`` the third row of H.
    """
    H = _plane_homography(R, t, K)
    n = xy.shape[0]
    out = np.empty((n, 2))
    for i in range(n):
        cx, cy, r2 = xy[i, 0], xy[i, 1], radii[i] * radii[i]
        v0 = (cx * cx - r2) * H[2, 0] + cx * cy * H[2, 1] + cx * H[2, 2]
        v1 = cx * cy * H[2, 0] + (cy * cy - r2) * H[2, 1] + cy * H[2, 2]
        v2 = cx * H[2, 0] + cy * H[2, 1] + H[2, 2]
        d0 = H[0, 0] * v0 + H[0, 1] * v1 + H[0, 2] * v2
        d1 = H[1, 0] * v0 + H[1, 1] * v1 + H[1, 2] * v2
        d2 = H[2, 0] * v0 + H[2, 1] * v1 + H[2, 2] * v2
        out[i, 0] = d0 / d2
        out[i, 1] = d1 / d2
    return out


@_kernel
def pose_jacobian(R, t, obj, K):
    """
    d(pixels)/d(camera position, camera rotation about the pattern's axes), (2N, 6).

    The camera at c = -R^T t sees X at p = R (X - c); moving it by dc and
    turning it by dtheta about the pattern's axes changes p by -R dc + R
    [X - c]x dtheta (the form of a PoseWithCovariance in the pattern frame).
    """
    n = obj.shape[0]
    c = np.empty(3)
    for k in range(3):
        c[k] = -(R[0, k] * t[0] + R[1, k] * t[1] + R[2, k] * t[2])
    J = np.empty((2 * n, 6))
    M = np.empty((3, 3))
    for i in range(n):
        d0, d1, d2 = obj[i, 0] - c[0], obj[i, 1] - c[1], obj[i, 2] - c[2]
        x = R[0, 0] * d0 + R[0, 1] * d1 + R[0, 2] * d2
        y = R[1, 0] * d0 + R[1, 1] * d1 + R[1, 2] * d2
        z = R[2, 0] * d0 + R[2, 1] * d1 + R[2, 2] * d2
        # R [d]x, row by row.
        for r in range(3):
            M[r, 0] = R[r, 1] * d2 - R[r, 2] * d1
            M[r, 1] = -R[r, 0] * d2 + R[r, 2] * d0
            M[r, 2] = R[r, 0] * d1 - R[r, 1] * d0
        u0, u1, u2 = K[0, 0] / z, K[0, 1] / z, -(K[0, 0] * x + K[0, 1] * y) / (z * z)
        w1, w2 = K[1, 1] / z, -K[1, 1] * y / (z * z)
        for k in range(3):
            J[2 * i, k] = -(u0 * R[0, k] + u1 * R[1, k] + u2 * R[2, k])
            J[2 * i, 3 + k] = u0 * M[0, k] + u1 * M[1, k] + u2 * M[2, k]
            J[2 * i + 1, k] = -(w1 * R[1, k] + w2 * R[2, k])
            J[2 * i + 1, 3 + k] = w1 * M[1, k] + w2 * M[2, k]
    return J


@_kernel
def point_residuals(R, t, obj, img, K):
    """Distances (N,) in the ideal image between ``img`` and the projections of ``obj``."""
    projected = project_points(R, t, obj, K)
    out = np.empty(obj.shape[0])
    for i in range(obj.shape[0]):
        du, dv = projected[i, 0] - img[i, 0], projected[i, 1] - img[i, 1]
        out[i] = math.sqrt(du * du + dv * dv)
    return out


@_kernel
def refine_exact(obj, observed, K, R, t, projected, radii, bias_correction, min_outlier,
                 outlier_factor):
    """
    Refine the chosen planar solution (R, t) and find the dots off the fit.

    :func:`.pose_exact.estimate_exact`'s last steps in one call: the dots'
    centres corrected from image-ellipse centres to projected circle
    centres (when ``bias_correction``; the offset from the start's
    ``projected`` points), the Levenberg-Marquardt refinement
    (:func:`refine_pose`), each dot's residual, and the dots more than
    ``min_outlier`` pixels and ``outlier_factor`` times the median residual
    off. Returns ``(R, t, residual, outliers, sum of squared residuals,
    the corrected centres)``, the sum in numpy's order.
    """
    n = obj.shape[0]
    corrected = observed
    if bias_correction:
        xy = np.empty((n, 2))
        for i in range(n):
            xy[i, 0], xy[i, 1] = obj[i, 0], obj[i, 1]
        centres = circle_image_centres(R, t, xy, radii, K)
        corrected = np.empty((n, 2))
        for i in range(n):
            for a in range(2):
                corrected[i, a] = observed[i, a] - (centres[i, a] - projected[i, a])
    R, t = refine_pose(obj, corrected, K, R, t)
    residual = point_residuals(R, t, obj, corrected, K)
    median = np.sort(residual)[n // 2]
    limit = max(min_outlier, outlier_factor * median)
    outliers = np.empty(n, dtype=np.bool_)
    squares = np.empty(n)
    for i in range(n):
        outliers[i] = residual[i] > limit
        squares[i] = residual[i] ** 2
    return R, t, residual, outliers, _pairwise_sum(squares, n), corrected


@_kernel
def pose_covariance_matrix(R, t, obj, K, sigma):
    """
    ``sigma^2 (J^T J)^-1`` (6x6) with J :func:`pose_jacobian`; all inf when J^T J is singular.

    The inverse column by column (:func:`_solve`): numba's inverse would
    take LAPACK from SciPy, and numpy's costs some 20 us of overhead.
    """
    J = pose_jacobian(R, t, obj, K)
    info = np.zeros((6, 6))
    for r in range(J.shape[0]):
        for a in range(6):
            for b in range(6):
                info[a, b] += J[r, a] * J[r, b]
    cov = np.empty((6, 6))
    unit = np.zeros(6)
    for k in range(6):
        unit[:] = 0.0
        unit[k] = 1.0
        ok, column = _solve(info, unit)
        if not ok:
            return np.full((6, 6), np.inf)
        for a in range(6):
            cov[a, k] = sigma * sigma * column[a]
    return cov


@_kernel
def circle_axis_angle(R, t, K, radius):
    """
    Angle (radians, [-pi/2, pi/2)) of the long axis of a centred plane circle's image ellipse.

    The image conic is ``H^-T diag(1, 1, -r^2) H^-1`` with ``H = K [r1 r2
    t]``; the adjugate stands for the inverse (the conic's scale, det(H)^2,
    changes neither its axes nor its sign). The long axis is the
    eigenvector of the quadratic part's smaller eigenvalue (the part made
    positive definite), 90 degrees from the larger one's at half
    ``atan2(2b, a - c)``; a circle's image that is a circle gives 0.
    """
    H = _plane_homography(R, t, K)
    # adj[i, j]: the cofactor of H[j, i].
    adj = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            r0, r1 = (j + 1) % 3, (j + 2) % 3
            c0, c1 = (i + 1) % 3, (i + 2) % 3
            adj[i, j] = H[r0, c0] * H[r1, c1] - H[r0, c1] * H[r1, c0]
    r2 = radius * radius
    q = np.empty(3)         # Q[0, 0], Q[0, 1], Q[1, 1] of adj^T diag(1, 1, -r^2) adj
    for k, (i, j) in enumerate(((0, 0), (0, 1), (1, 1))):
        q[k] = adj[0, i] * adj[0, j] + adj[1, i] * adj[1, j] - r2 * adj[2, i] * adj[2, j]
    sign = 1.0 if q[0] + q[2] > 0.0 else (-1.0 if q[0] + q[2] < 0.0 else 0.0)
    a, b, c = sign * q[0], sign * q[1], sign * q[2]
    if b == 0.0 and a == c:
        return 0.0
    angle = 0.5 * math.atan2(2.0 * b, a - c) + 0.5 * math.pi
    return (angle + 0.5 * math.pi) % math.pi - 0.5 * math.pi


def warm_up() -> None:
    """Compile (or load from the cache) the kernels with the argument types the detector uses."""
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.5, 0.4]])
    fit_homography_points(square, square * 2.0 + 1.0)
    fit_homography_inliers(square, square * 2.0 + 1.0, np.ones(len(square)), 1.0, 0.75, 4,
                           True)
    plane = np.column_stack([square, np.zeros(len(square))])
    K, R, t = np.eye(3) * 100.0, np.eye(3), np.array([0.0, 0.0, 1.0])
    refine_pose(plane, square * 100.0, K, R, t)
    refine_pose_prior(plane, square * 100.0, K, R, t, 2.0, np.array([0.0, 1.0, 0.0]), 10.0,
                      0.0, 5.0)
    project_points(R, t, plane, K)
    pose_cost(plane, square * 100.0, K, R, t)
    planar_poses(plane, square * 100.0, K)
    circle_image_centres(R, t, square, np.ones(len(square)), K)
    pose_jacobian(R, t, plane, K)
    point_residuals(R, t, plane, square, K)
    refine_exact(plane, square * 100.0, K, R, t, square * 100.0, np.ones(len(square)), True,
                 0.2, 5.0)
    pose_covariance_matrix(R, t, plane, K, 1.0)
    circle_axis_angle(R, t, K, 1.0)


warm_up()
