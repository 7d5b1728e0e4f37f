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
"""

import math

import numba
import numpy as np

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
def _solve(M, b):
    """Solve the square system M x = b (Gaussian elimination, partial pivoting): (ok, x)."""
    n = b.shape[0]
    A = M.copy()
    x = b.copy()
    for col in range(n):
        pivot = col
        for r in range(col + 1, n):
            if abs(A[r, col]) > abs(A[pivot, col]):
                pivot = r
        if not abs(A[pivot, col]) > 1e-300:
            return False, x
        if pivot != col:
            for c in range(n):
                A[col, c], A[pivot, c] = A[pivot, c], A[col, c]
            x[col], x[pivot] = x[pivot], x[col]
        for r in range(col + 1, n):
            f = A[r, col] / A[col, col]
            for c in range(col, n):
                A[r, c] -= f * A[col, c]
            x[r] -= f * x[col]
    for col in range(n - 1, -1, -1):
        total = x[col]
        for c in range(col + 1, n):
            total -= A[col, c] * x[c]
        x[col] = total / A[col, col]
    return True, x


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
def _pose_cost(obj, img, K, R, t):
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
    n = obj.shape[0]
    R = R.copy()
    t = t.copy()
    JtJ = np.empty((6, 6))
    Jtr = np.empty(6)
    jrow = np.empty(6)
    lam = 1e-3
    cost = _pose_cost(obj, img, K, R, t)
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
                _accumulate(JtJ, Jtr, jrow, res)
        improved = False
        for _ in range(8):
            solved, step = _damped_step(JtJ, Jtr, lam)
            if not solved:
                return R, t
            R_trial = _mul3(_rotation(-step[0], -step[1], -step[2]), R)
            t_trial = np.empty(3)
            for k in range(3):
                t_trial[k] = t[k] - step[3 + k]
            trial_cost = _pose_cost(obj, img, K, R_trial, t_trial)
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


def warm_up() -> None:
    """Compile (or load from the cache) the kernels with the argument types the detector uses."""
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.5, 0.4]])
    fit_homography_points(square, square * 2.0 + 1.0)
    plane = np.column_stack([square, np.zeros(len(square))])
    refine_pose(plane, square * 100.0, np.eye(3) * 100.0, np.eye(3), np.array([0.0, 0.0, 1.0]))


warm_up()
