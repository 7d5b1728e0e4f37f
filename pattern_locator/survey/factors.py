"""
The graph's factors, all GTSAM's own, and conversions between the project's poses and GTSAM's.

GTSAM's ``Pose3`` tangent is (rotation, translation), a right perturbation in
the body frame: ``T @ Exp(omega, v)``. A factor written in Python is called
back from C++ and costs about a hundred times more per evaluation (2,000 such
factors made Levenberg-Marquardt take seconds), so the partial priors
(vertical cards, the floor, the nominal height) are GTSAM's prior and
between factors made partial by their noise and re-anchored each round at
the current estimate; only the optional reprojection factors of
:mod:`.refine` are Python.
"""

import math
from typing import Dict, List, Sequence, Tuple

import gtsam
import numpy as np

from .model import EXACT_SIGMA, F, L, SurveyOptions, X
from .problem import Edge, Problem
from ..vision.geometry import Pose, rodrigues


def to_gtsam(T: Pose) -> gtsam.Pose3:
    """Return the GTSAM pose of a project pose (``X_parent = R X_child + t`` both)."""
    return gtsam.Pose3(gtsam.Rot3(np.asarray(T.R, dtype=float)),
                       np.asarray(T.t, dtype=float))


def from_gtsam(T: gtsam.Pose3) -> Pose:
    """Return the project pose of a GTSAM pose."""
    m = T.matrix()
    return Pose(m[:3, :3].copy(), m[:3, 3].copy())


def building_covariance(T_building_card: Pose, marginal: np.ndarray) -> np.ndarray:
    """
    Return a card's GTSAM marginal as (x, y, z, rx, ry, rz) about the building's axes.

    A right perturbation ``(omega, v)`` in the card frame moves the card by
    ``R v`` and turns it by ``R omega`` about the building's axes.
    """
    R = T_building_card.R
    A = np.zeros((6, 6))
    A[:3, 3:] = R
    A[3:, :3] = R
    out = A @ np.asarray(marginal, dtype=float) @ A.T
    return 0.5 * (out + out.T)


def sighting_factor(problem: Problem, key: Tuple[int, int], Y: Pose, cov: np.ndarray, huber
                    ) -> gtsam.BetweenFactorPose3:
    """Return the factor keyframe base -> card measuring ``Y`` with covariance ``cov``."""
    n, k = key
    noise = gtsam.noiseModel.Robust.Create(huber, gtsam.noiseModel.Gaussian.Covariance(cov))
    return gtsam.BetweenFactorPose3(X(n), L(problem.card_index[problem.frame_sightings[n][k].ids]),
                                    to_gtsam(Y), noise)


class CarriedSightings:
    """
    The sightings of keyframes' later members, carried to the keyframe by odometry.

    A member's sighting ``Y = T_base_card`` becomes ``step @ Y`` with ``step``
    the corrected odometry from the keyframe to the member; the step's
    uncertainty joins the sighting's, moved into the card's frame by the
    adjoint of ``Y^-1``. Rebuilt each round (the calibration moves the steps).
    """

    def __init__(self, problem: Problem, later: List[Tuple[Tuple[int, int], Pose]],
                 tangent: Dict[Tuple[int, int], np.ndarray], group: Dict) -> None:
        self.problem = problem
        self.group = np.array([group[key] for key, _ in later], dtype=int)
        self.keys = [key for key, _ in later]
        self.YR = np.array([Y.R for _, Y in later])
        self.Yt = np.array([Y.t for _, Y in later])
        self.adjoint = np.array([to_gtsam(Y).inverse().AdjointMap() for _, Y in later])
        self.tangent = np.array([tangent[key] for key in self.keys])
        self.cards = [L(problem.card_index[problem.frame_sightings[n][k].ids])
                      for n, k in self.keys]
        self.members = [(n, problem.sighting_member[n][k]) for n, k in self.keys]

    def factors(self, calibration, noise_scale, huber, sighting_scale
                ) -> Dict[Tuple[int, int], object]:
        """Return the carried sightings' factors under a calibration and odometry noise."""
        pairs, R, t, lengths, bags = self.problem.member_step_arrays(calibration)
        index = {pair: i for i, pair in enumerate(pairs)}
        at = np.array([index[m] for m in self.members])
        sigmas = np.zeros((len(pairs), 6))
        for bag in set(bags.tolist()):
            mine = bags == bag
            sigmas[mine] = self.problem.odometry_sigmas(int(bag), lengths[mine], noise_scale)
        A = self.adjoint
        cov = self.tangent * sighting_scale[self.group][:, None, None] + np.einsum(
            'nij,nj,nkj->nik', A, sigmas[at] ** 2, A)
        ZR = R[at] @ self.YR
        Zt = np.einsum('nij,nj->ni', R[at], self.Yt) + t[at]
        out = {}
        for i, key in enumerate(self.keys):
            noise = gtsam.noiseModel.Robust.Create(
                huber, gtsam.noiseModel.Gaussian.Covariance(cov[i]))
            out[key] = gtsam.BetweenFactorPose3(X(key[0]), self.cards[i],
                                                gtsam.Pose3(gtsam.Rot3(ZR[i]), Zt[i]), noise)
        return out


def odometry_factors(problem: Problem, edges: Sequence[Edge],
                     calibration: Dict[int, Tuple[float, float]],
                     noise_scale: Tuple[float, float], huber
                     ) -> List[Tuple[int, gtsam.BetweenFactorPose3]]:
    """Return the odometry factors of the edges under a calibration and noise scale."""
    out = []
    for bag in problem.odometry:
        mine = [e for e in edges if e.bag == bag]
        if not mine:
            continue
        numbers, R, p = problem.corrected_arrays(bag, *calibration.get(bag, (0.0, 0.0)))
        position = {int(n): k for k, n in enumerate(numbers)}
        ia = np.array([position[e.a] for e in mine])
        ib = np.array([position[e.b] for e in mine])
        step_R = np.einsum('nji,njk->nik', R[ia], R[ib])
        step_t = np.einsum('nji,nj->ni', R[ia], p[ib] - p[ia])
        sigmas = problem.odometry_sigmas(bag, np.array([e.length for e in mine]), noise_scale)
        for e, Rs, ts, sig in zip(mine, step_R, step_t, sigmas):
            noise = gtsam.noiseModel.Robust.Create(huber, gtsam.noiseModel.Diagonal.Sigmas(sig))
            out.append((bag, gtsam.BetweenFactorPose3(X(e.a), X(e.b),
                                                      gtsam.Pose3(gtsam.Rot3(Rs), ts), noise)))
    return out


def add_gauge(graph: gtsam.NonlinearFactorGraph, gauge: Dict[int, Pose],
              anchors: Dict[int, Pose], options: SurveyOptions) -> None:
    for j, T in gauge.items():
        if anchors:
            sigmas = np.full(6, EXACT_SIGMA)
        else:
            # Position and heading exact; the tilt (about the card's x) and the turn on
            # the wall (about its normal) are left to the vertical priors and odometry.
            tilt = options.first_card_tilt_sd_rad
            sigmas = np.array([tilt, EXACT_SIGMA, tilt, EXACT_SIGMA, EXACT_SIGMA,
                               EXACT_SIGMA])
        graph.add(gtsam.PriorFactorPose3(L(j), to_gtsam(T),
                                         gtsam.noiseModel.Diagonal.Sigmas(sigmas)))


def on_floor(problem: Problem, active: set) -> Dict[int, List[int]]:
    """Return each bag's keyframes that stand on its floor (odometry and a known mount)."""
    out: Dict[int, List[int]] = {}
    for n in sorted(active):
        bag = problem.frames[n][0]
        if problem.frame_odom[n] is not None and problem.motions[bag].mount_source != 'camera':
            out.setdefault(bag, []).append(n)
    return out


def flat(T: gtsam.Pose3) -> gtsam.Pose3:
    """Return a pose made level: its heading and x, y kept, z = 0, no roll or pitch."""
    R = T.rotation().matrix()
    t = T.translation()
    return gtsam.Pose3(gtsam.Rot3.Yaw(math.atan2(R[1, 0], R[0, 0])),
                       np.array([t[0], t[1], 0.0]))


def floor_factors(problem: Problem, values: gtsam.Values, floors: Dict[int, List[int]],
                  options: SurveyOptions) -> List:
    """
    Return the floor factors, linearised about the current estimate.

    Per bag a floor plane (a pose whose x-y plane is the floor) with a prior
    that it is level; per keyframe a between factor plane -> base holding the
    base upright on the plane at height 0, free in x, y and heading.
    """
    out = []
    free = 1e4
    level = gtsam.noiseModel.Diagonal.Sigmas(np.array(
        [options.floor_level_sd_rad, options.floor_level_sd_rad, free, free, free, free]))
    on = gtsam.noiseModel.Diagonal.Sigmas(np.array(
        [options.base_tilt_sd_rad, options.base_tilt_sd_rad, free, free, free,
         options.base_height_sd_m]))
    for bag, numbers in floors.items():
        plane = values.atPose3(F(bag))
        out.append(gtsam.PriorFactorPose3(F(bag), flat(plane), level))
        for n in numbers:
            relative = plane.between(values.atPose3(X(n)))
            out.append(gtsam.BetweenFactorPose3(F(bag), X(n), flat(relative), on))
    return out


def re_anchored_priors(problem: Problem, values: gtsam.Values, cards: Dict[int, Pose],
                       active: set, gauge: Dict[int, Pose], options: SurveyOptions
                       ) -> List:
    """
    Return the vertical and height priors, linearised about the current estimate.

    Both are partial priors made of GTSAM's own factors (fast, unlike Python
    ones): a prior whose mean is the card's current pose with its normal
    made horizontal, tight only on that tilt (about the card's x) and with
    no weight elsewhere; and a between factor from a base to the card
    holding the card's height above the base, tight only along the card's
    up (its y). They are rebuilt each round, so the approximation follows
    the estimate.
    """
    out = []
    free = 1e4
    if options.vertical_prior:
        noise = gtsam.noiseModel.Diagonal.Sigmas(np.array(
            [options.vertical_sd_rad, free, free, free, free, free]))
        for j in cards:
            if j in gauge:
                continue
            T = from_gtsam(values.atPose3(L(j)))
            out.append(gtsam.PriorFactorPose3(L(j), to_gtsam(made_vertical(T)), noise))
    if options.card_height_m is not None:
        noise = gtsam.noiseModel.Diagonal.Sigmas(np.array(
            [free, free, free, free, options.card_height_sd_m, free]))
        best: Dict[int, Tuple[float, int]] = {}
        for n in active:
            if problem.frame_odom[n] is None:
                continue
            for s in problem.frame_sightings[n]:
                j = problem.card_index[s.ids]
                if j in cards and (j not in best or s.distance_m < best[j][0]):
                    best[j] = (s.distance_m, n)
        for j, (_, n) in best.items():
            base = values.atPose3(X(n))
            relative = base.between(values.atPose3(L(j)))
            t = relative.translation().copy()
            t[2] = options.card_height_m
            out.append(gtsam.BetweenFactorPose3(X(n), L(j),
                                                gtsam.Pose3(relative.rotation(), t), noise))
    return out


def made_vertical(T: Pose) -> Pose:
    """Return the card pose turned about its own x so that its normal is horizontal."""
    normal = T.R[:, 2]
    horizontal = np.array([normal[0], normal[1], 0.0])
    if np.linalg.norm(horizontal) < 1e-6:
        return T
    horizontal /= np.linalg.norm(horizontal)
    x = T.R[:, 0]
    angle = math.atan2(float(np.cross(normal, horizontal) @ x), float(normal @ horizontal))
    return Pose(T.R @ rodrigues(np.array([angle, 0.0, 0.0])), T.t)


def refined_factors(problem: Problem, sighting_factors, dropped, calibration, group,
                    sighting_scale, options: SurveyOptions) -> Dict[Tuple[int, int], object]:
    """Return the sightings' factors, the chosen ones as reprojection factors over their dots."""
    from .refine import dot_observations, reprojection_factor
    from ..card.pattern import load_pattern_config
    pattern = load_pattern_config()
    chosen = {}
    for key in sighting_factors:
        if key in dropped:
            continue
        n, k = key
        s = problem.frame_sightings[n][k]
        camera = problem.motions[s.bag].cameras.get(s.frame)
        if camera is None or s.points_px is None or s.distance_m < options.refine_min_distance_m:
            continue
        m = problem.sighting_member[n][k]
        if m:
            # A later member's camera sits on the keyframe by odometry, whose error a
            # pixel factor cannot carry: it keeps its pose factor.
            continue
        C = problem.members[n][m][1]
        model, pixels, sigma = dot_observations(s, camera, pattern)
        # Huber at the chi-square(2n) 99.9 % point, as the pose factors' kernel.
        dims = 2 * len(model)
        chosen[key] = reprojection_factor(X(n), L(problem.card_index[s.ids]), C, model, pixels,
                                          camera.K, sigma,
                                          math.sqrt(dims + 4.0 * math.sqrt(2.0 * dims)))
    return {**sighting_factors, **chosen}
