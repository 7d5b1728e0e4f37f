"""
A bag's odometry, its correction for a scale error and a yaw bias, and fitting the two.

The correction scales each raw step's displacement by ``1 + scale`` and turns
it about the vertical by the yaw error accumulated before it (``yaw_bias``
per metre travelled). :func:`fit_calibration` finds the two that best explain
the optimised keyframe poses (a small least-squares fit, alternated with the
graph by ``graph.optimise``).
"""

from typing import Dict, Optional, Tuple

import gtsam
import numpy as np

from .model import BagMotion, MAX_ODOM_GAP_S, X


def rz(angles: np.ndarray) -> np.ndarray:
    c, s = np.cos(angles), np.sin(angles)
    out = np.zeros(angles.shape + (3, 3))
    out[..., 0, 0], out[..., 0, 1] = c, -s
    out[..., 1, 0], out[..., 1, 1] = s, c
    out[..., 2, 2] = 1.0
    return out


class Odometry:
    """A bag's raw odometry and its correction for a scale error and a yaw bias."""

    def __init__(self, motion: BagMotion) -> None:
        self.stamps = np.asarray(motion.odom_stamps_ns, dtype=np.int64)
        self.R = np.asarray(motion.odom_R, dtype=float)
        self.p = np.asarray(motion.odom_p, dtype=float)
        self.dp = np.diff(self.p, axis=0)
        self.d = np.linalg.norm(self.dp, axis=1)
        self.along = np.concatenate([[0.0], np.cumsum(self.d)])
        gaps = np.diff(self.stamps) * 1e-9 > MAX_ODOM_GAP_S
        self.gaps_before = np.concatenate([[0], np.cumsum(gaps)])

    def locate(self, stamp_ns: int) -> Optional[Tuple[int, float]]:
        """Return (segment, weight) of a stamp in the samples; None outside or in a gap."""
        i = int(np.searchsorted(self.stamps, stamp_ns, side='right')) - 1
        if i < 0 or i >= len(self.stamps):
            return None
        if i == len(self.stamps) - 1:
            return (i - 1, 1.0) if self.stamps[i] == stamp_ns and i > 0 else None
        if (self.stamps[i + 1] - self.stamps[i]) * 1e-9 > MAX_ODOM_GAP_S:
            return None
        w = (stamp_ns - self.stamps[i]) / (self.stamps[i + 1] - self.stamps[i])
        return i, float(w)

    def corrected(self, scale: float, yaw_bias: float, where: np.ndarray, weights: np.ndarray
                  ) -> Tuple[np.ndarray, np.ndarray]:
        """
        Correct the odometry and return the heading correction and position at the stamps.

        Each raw step's displacement is scaled by ``1 + scale`` and turned
        about the vertical by the yaw error accumulated before it
        (``yaw_bias`` per metre travelled); the orientations turn with it.
        """
        phi = yaw_bias * self.along
        steps = (1.0 + scale) * np.einsum('nij,nj->ni', rz(phi[:-1]), self.dp)
        p = np.vstack([self.p[:1], self.p[:1] + np.cumsum(steps, axis=0)])
        w = weights[:, None]
        pos = p[where] * (1.0 - w) + p[where + 1] * w
        phi_at = phi[where] * (1.0 - weights) + phi[where + 1] * weights
        return phi_at, pos

    def raw_rotation(self, where: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """Return the raw orientation interpolated at located stamps (N, 3, 3)."""
        a, b = self.R[where], self.R[where + 1]
        step = so3_log(np.einsum('nji,njk->nik', a, b)) * np.asarray(weights)[:, None]
        return a @ so3_exp(step)


def so3_log(R: np.ndarray) -> np.ndarray:
    """Return the rotation vectors of rotations (N, 3, 3) below about 170 degrees."""
    cos = np.clip((np.trace(R, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    angle = np.arccos(cos)
    vee = np.stack([R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]],
                   axis=1)
    sin = np.sin(angle)
    factor = np.where(angle < 1e-6, 0.5 + angle ** 2 / 12.0, angle / (2.0 * np.where(
        sin == 0.0, 1.0, sin)))
    return vee * factor[:, None]


def so3_exp(v: np.ndarray) -> np.ndarray:
    """Return the rotations (N, 3, 3) of rotation vectors (N, 3)."""
    angle = np.linalg.norm(v, axis=1)
    K = np.zeros((len(v), 3, 3))
    K[:, 0, 1], K[:, 0, 2] = -v[:, 2], v[:, 1]
    K[:, 1, 0], K[:, 1, 2] = v[:, 2], -v[:, 0]
    K[:, 2, 0], K[:, 2, 1] = -v[:, 1], v[:, 0]
    small = angle < 1e-6
    safe = np.where(small, 1.0, angle)
    a = np.where(small, 1.0 - angle ** 2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - angle ** 2 / 24.0, (1.0 - np.cos(safe)) / safe ** 2)
    return np.eye(3)[None] + a[:, None, None] * K + b[:, None, None] * (K @ K)


def fit_calibration(problem, values: gtsam.Values,
                    calibration: Dict[int, Tuple[float, float]],
                    noise_scale: Tuple[float, float], fitted_bags: set
                    ) -> Dict[int, Tuple[float, float]]:
    """
    Return each bag's (scale, yaw bias) that best explains the optimised frame poses.

    A bag with fewer than five odometry edges keeps its calibration (and is
    not added to ``fitted_bags``).
    """
    out = dict(calibration)
    for bag in problem.odometry:
        numbers, _, _ = problem.corrected_arrays(bag, 0.0, 0.0)
        position = {int(n): k for k, n in enumerate(numbers)}
        edges = [e for e in problem.edges if e.bag == bag and values.exists(X(e.a))
                 and values.exists(X(e.b))]
        if len(edges) < 5:
            continue
        ia = np.array([position[e.a] for e in edges])
        ib = np.array([position[e.b] for e in edges])
        opt = [values.atPose3(X(int(n))).matrix() if values.exists(X(int(n))) else np.eye(4)
               for n in numbers]
        opt = np.array(opt)
        Ro, po = opt[:, :3, :3], opt[:, :3, 3]
        rel_R = np.einsum('nji,njk->nik', Ro[ia], Ro[ib])
        rel_t = np.einsum('nji,nj->ni', Ro[ia], po[ib] - po[ia])
        sig = problem.odometry_sigmas(bag, np.array([e.length for e in edges]), noise_scale)
        params = np.array(out.get(bag, (0.0, 0.0)), dtype=float)

        def residual(p: np.ndarray) -> np.ndarray:
            _, R, t = problem.corrected_arrays(bag, p[0], p[1])
            step_R = np.einsum('nji,njk->nik', R[ia], R[ib])
            step_t = np.einsum('nji,nj->ni', R[ia], t[ib] - t[ia])
            dR = np.einsum('nji,njk->nik', step_R, rel_R)
            r = np.empty((len(edges), 6))
            r[:, 0] = 0.5 * (dR[:, 2, 1] - dR[:, 1, 2])
            r[:, 1] = 0.5 * (dR[:, 0, 2] - dR[:, 2, 0])
            r[:, 2] = 0.5 * (dR[:, 1, 0] - dR[:, 0, 1])
            r[:, 3:] = np.einsum('nji,nj->ni', step_R, rel_t - step_t)
            return (r / sig).ravel()

        for _ in range(5):
            r0 = residual(params)
            J = np.empty((len(r0), 2))
            for d, h in ((0, 1e-5), (1, 1e-6)):
                q = params.copy()
                q[d] += h
                J[:, d] = (residual(q) - r0) / h
            # Huber weights keep an odometry glitch from bending the fit.
            w = np.sqrt(np.minimum(1.0, 3.0 / np.maximum(np.abs(r0), 1e-12)))
            step = np.linalg.lstsq(J * w[:, None], -r0 * w, rcond=None)[0]
            params += step
            if abs(step[0]) < 1e-7 and abs(step[1]) < 1e-9:
                break
        out[bag] = (float(params[0]), float(params[1]))
        fitted_bags.add(bag)
    return out
