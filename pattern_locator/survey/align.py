"""
Aligning two sets of card positions: the best rigid or similarity transform, and robustly.

Used by ``survey --check`` (a new walk against an existing map: rigid, with
the cards that moved left out) and by the benchmark (a surveyed map against
the truth: a similarity, "relative" errors).
"""

from typing import Optional, Sequence, Tuple

import numpy as np

from ..vision.geometry import Pose


def fit_transform(source: np.ndarray, target: np.ndarray, scale: bool = False,
                  weights: Optional[np.ndarray] = None) -> Tuple[Pose, float]:
    """
    Return (T, s) minimising ``sum w |s R source + t - target|^2`` (Umeyama 1991).

    ``scale`` False: a rigid transform (s = 1). Needs three points not on one
    line for a unique rotation; with fewer the rotation is the identity.
    """
    source = np.asarray(source, dtype=float).reshape(-1, 3)
    target = np.asarray(target, dtype=float).reshape(-1, 3)
    w = np.ones(len(source)) if weights is None else np.asarray(weights, dtype=float)
    w = w / w.sum()
    mu_s = w @ source
    mu_t = w @ target
    a, b = source - mu_s, target - mu_t
    if len(source) < 3:
        return Pose(np.eye(3), mu_t - mu_s), 1.0
    cov = (b * w[:, None]).T @ a
    u, d, vt = np.linalg.svd(cov)
    sign = np.ones(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        sign[2] = -1.0
    R = u @ np.diag(sign) @ vt
    s = 1.0
    if scale:
        var = float(w @ np.sum(a * a, axis=1))
        s = float(np.sum(d * sign) / var) if var > 0 else 1.0
    t = mu_t - s * R @ mu_s
    return Pose(R, t), s


def apply(T: Pose, s: float, points: np.ndarray) -> np.ndarray:
    """Return ``s R p + t`` for each point."""
    return s * np.asarray(points, dtype=float) @ T.R.T + T.t


def robust_rigid(source: np.ndarray, target: np.ndarray, tolerance: Sequence[float]
                 ) -> Tuple[Pose, np.ndarray]:
    """
    Return a rigid fit of source to target and which points it holds (inliers).

    Every single point proposes a shift, every pair a shift and a turn about
    the vertical (maps are level), and seeded triples a full rigid fit; the
    proposal that holds the most points within their ``tolerance`` (m) wins,
    refitted on those. A few moved cards among many cannot tilt it.
    """
    source = np.asarray(source, dtype=float).reshape(-1, 3)
    target = np.asarray(target, dtype=float).reshape(-1, 3)
    tol = np.asarray(tolerance, dtype=float).reshape(-1)
    n = len(source)
    best, best_count, best_cost = None, -1, np.inf
    rng = np.random.default_rng(0)
    proposals = [[i] for i in range(n)] + [[i, j] for i in range(n) for j in range(i + 1, n)]
    proposals = proposals[:2000]
    if n >= 3:
        proposals += [list(rng.choice(n, 3, replace=False)) for _ in range(500)]
    for subset in proposals:
        if len(subset) == 3:
            T, _ = fit_transform(source[subset], target[subset])
        elif len(subset) == 2:
            T = _two_point(source[subset], target[subset])
        else:
            T = Pose(np.eye(3), target[subset[0]] - source[subset[0]])
        err = np.linalg.norm(apply(T, 1.0, source) - target, axis=1)
        inliers = err <= tol
        count = int(inliers.sum())
        cost = float(np.sum(np.minimum(err / tol, 1.0) ** 2))
        if count > best_count or (count == best_count and cost < best_cost):
            best, best_count, best_cost = inliers, count, cost
    for _ in range(3):
        T, _ = fit_transform(source[best], target[best]) if best.sum() >= 3 else (
            Pose(np.eye(3), np.mean(target[best] - source[best], axis=0)), 1.0)
        err = np.linalg.norm(apply(T, 1.0, source) - target, axis=1)
        inliers = err <= tol
        if inliers.sum() < best.sum() or np.array_equal(inliers, best):
            break
        best = inliers
    return T, best


def _two_point(source: np.ndarray, target: np.ndarray) -> Pose:
    """Return the rigid fit of two points turning only about the vertical (z)."""
    a = source[1] - source[0]
    b = target[1] - target[0]
    angle = np.arctan2(b[1], b[0]) - np.arctan2(a[1], a[0])
    c, s = np.cos(angle), np.sin(angle)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    mid_s, mid_t = source.mean(axis=0), target.mean(axis=0)
    return Pose(R, mid_t - R @ mid_s)
