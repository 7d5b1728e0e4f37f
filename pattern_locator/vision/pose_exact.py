"""
The exact pose estimator (method.md section 4), the project's default.

Every dot is a known point of the card's plane with a known identity, so the
camera pose is a planar Perspective-n-Point problem over up to 17 points:

* dot centres are undistorted to an ideal pinhole image with the same K;
* IPPE gives both planar solutions, each refined by Levenberg-Marquardt on
  the reprojection error;
* the projected centre of a circle is not the centre of its image ellipse:
  each dot's observed centre is corrected by the ellipse-centre offset the
  current pose predicts (Heikkila 2000), and the pose refined again;
* the solution with the lower reprojection error wins, unless the two are
  nearly equal (``ambiguity`` close to 1, the planar "flip"), where what is
  known about the camera (a :class:`PosePrior`) decides, and the other
  solution's probability is reported (``other_probability``); in such a
  close call the prior's up and height also take part in the last
  refinement (the MAP pose) and in the covariance;
* the covariance is ``s^2 (J^T J)^-1`` with J the Jacobian of the
  reprojection with respect to the camera pose in the pattern frame.
"""

from dataclasses import dataclass
import math
from typing import Dict, List, Optional, Tuple

import cv2
import numpy as np

from .camera import CameraModel
from .fit_kernels import (circle_axis_angle, circle_image_centres, planar_poses,
                          point_residuals, pose_cost, pose_covariance_matrix, pose_jacobian,
                          project_points, refine_exact, refine_pose, refine_pose_prior)
from .geometry import Pose, rodrigues, rotation_vector
from .per_config import made_once
from ..card.pattern import PatternConfig
from ..errors import EstimationError

MIN_POINTS = 6
DEFAULT_MIN_SIGMA_PX = 0.05   # floor of the pixel noise used for the covariance
MIN_OUTLIER_PX = 0.2          # a dot this far off the fit (and OUTLIER_FACTOR times the
OUTLIER_FACTOR = 5.0          # median residual) is dropped


@dataclass(frozen=True)
class PosePrior:
    """
    What is known about the camera besides the image, to resolve the planar flip.

    ``up_in_camera``: the card's +y (up on the wall) expressed in the camera
    frame, known on a robot from the head's tilt and the base's attitude.
    ``camera_height``: the camera's y coordinate in the pattern frame (its
    height relative to the card's centre), known from the robot's geometry.
    ``previous_camera_in_pattern``: the last position, for continuity.
    """

    up_in_camera: Optional[np.ndarray] = None
    up_sigma_rad: float = math.radians(5.0)
    camera_height: Optional[float] = None
    height_sigma: float = 0.15
    previous_camera_in_pattern: Optional[np.ndarray] = None
    previous_sigma: float = 0.5

    def penalty(self, T_camera_pattern: Pose, previous: bool = True) -> float:
        """Chi-square-like disagreement of a pose with this prior (``previous``: its last term)."""
        total = 0.0
        up, up_weight, height, height_weight = self.fit_terms()
        if up_weight > 0.0:
            seen = T_camera_pattern.R[:, 1]
            angle = math.acos(float(np.clip(seen @ up, -1.0, 1.0)))
            total += (angle * up_weight) ** 2
        camera = T_camera_pattern.inverse().t
        if height_weight > 0.0:
            total += ((camera[1] - height) * height_weight) ** 2
        if previous and self.previous_camera_in_pattern is not None:
            d = np.linalg.norm(camera - np.asarray(self.previous_camera_in_pattern))
            total += (d / self.previous_sigma) ** 2
        return total

    @property
    def fits(self) -> bool:
        """Whether the prior has a term the pose's fit can use (up or height)."""
        _, up_weight, _, height_weight = self.fit_terms()
        return up_weight > 0.0 or height_weight > 0.0

    def fit_terms(self) -> Tuple[np.ndarray, float, float, float]:
        """
        Return up (unit, camera frame), 1/its sigma, the height and 1/its sigma (0: none).

        A term that is not a finite number with a positive, finite sigma
        (an up of length 0, a NaN height) is left out, weight 0.
        """
        up, up_weight = np.zeros(3), 0.0
        if self.up_in_camera is not None:
            given = np.asarray(self.up_in_camera, dtype=float).reshape(-1)
            norm = float(np.linalg.norm(given)) if given.shape == (3,) else math.nan
            if math.isfinite(norm) and norm > 0.0 and _usable_sigma(self.up_sigma_rad):
                up, up_weight = given / norm, 1.0 / self.up_sigma_rad
        height, height_weight = 0.0, 0.0
        if self.camera_height is not None and math.isfinite(self.camera_height) \
                and _usable_sigma(self.height_sigma):
            height, height_weight = float(self.camera_height), 1.0 / self.height_sigma
        return up, up_weight, height, height_weight

    def information(self, T_camera_pattern: Pose) -> np.ndarray:
        """
        Return the 6x6 information the up and height terms add to a pose (no last position).

        In :func:`pose_covariance`'s parameters (camera position, rotation
        about the pattern's axes), at ``T_camera_pattern``. A turn dtheta
        moves the pattern's +y in the camera by R (e_y x dtheta); the
        height is the position's y.
        """
        _, up_weight, _, height_weight = self.fit_terms()
        info = np.zeros((6, 6))
        info[1, 1] = height_weight ** 2
        if up_weight > 0.0:
            J = up_weight * T_camera_pattern.R @ np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 0.0],
                                                           [-1.0, 0.0, 0.0]])
            info[3:, 3:] = J.T @ J
        return info


@dataclass(frozen=True)
class PoseEstimate:
    """A camera pose from one card, with its uncertainty and how it was chosen."""

    T_camera_pattern: Pose          # X_camera = R X_pattern + t
    covariance: np.ndarray          # 6x6: camera position (m), rotation (rad) in the pattern frame
    reprojection_rms_px: float
    ambiguity: float                # other solution's RMS / this one's (>= 1 unless a prior chose)
    alternative: Optional[Pose]     # the other planar solution
    n_points: int
    chosen_by: str                  # 'reprojection' or 'prior'
    # How likely the other planar solution is when the two are a close call
    # (0.0: the image rules it out), from the residuals and the prior's up
    # and height, not its last position (the localizer weighs continuity
    # with its own jump test: gates.GateParameters.max_flip_probability).
    # Above 0.5 when the last position chose the one the image likes less.
    other_probability: float = 0.0
    # How far the fit's cost rises (as other_probability counts it) on the
    # way from the chosen solution to the other: low, the two lie in one
    # flat valley (near face on and far), where the chosen pose's own
    # covariance does not hold (_flip_barrier). inf when not a close call.
    flip_barrier: float = math.inf
    # What the prior's up and height added to the fit (PosePrior.information,
    # in the covariance's parameters), None when the fit is the image's alone.
    prior_information: Optional[np.ndarray] = None

    @property
    def camera_in_pattern(self) -> np.ndarray:
        return self.T_camera_pattern.inverse().t


def estimate_exact(points_px: np.ndarray, camera: CameraModel, config: PatternConfig,
                   prior: Optional[PosePrior] = None, pixel_sigma: Optional[float] = None,
                   bias_correction: bool = True, ambiguity_threshold: float = 2.0,
                   fit_prior: bool = True) -> PoseEstimate:
    """
    Camera pose from detected dot centres (``(n_dots, 2)`` pixels, NaN = not seen).

    ``fit_prior``: in a close call, fit the prior's up and height with the
    dots (the MAP pose); False: the prior only chooses between the planar
    solutions (for a caller that counts up and height elsewhere, as the
    survey's graph does).
    """
    points_px = np.asarray(points_px, dtype=float)
    if points_px.shape != (config.n_dots, 2):
        raise EstimationError(f'expected {config.n_dots} dot positions, got {points_px.shape}')
    seen = ~np.isnan(points_px).any(axis=1)
    if np.count_nonzero(seen) < MIN_POINTS:
        raise EstimationError(f'need at least {MIN_POINTS} dots for a pose, got '
                              f'{np.count_nonzero(seen)}')
    obj = _model_points(config)[seen]
    radii = _dot_radii(config)[seen]
    observed = camera.undistort_pixels(points_px[seen])
    K = _f64(camera.K)

    # IPPE's two planar solutions are close to optimal: their residuals tell
    # them apart, and only the chosen one is corrected and refined. (Each
    # candidate: squared error, R, t, projection.)
    candidates = sorted(_ippe(obj, observed, K), key=lambda sol: sol[0])
    n = len(obj)
    rms = [math.sqrt(c[0] / n) for c in candidates]
    ambiguity = rms[1] / max(rms[0], 1e-9) if len(candidates) > 1 else math.inf
    best, chosen_by, other_probability, barrier = 0, 'reprojection', 0.0, math.inf
    if ambiguity < ambiguity_threshold:
        # A close call: compare the two at their own optimum, then with what
        # is known about the camera. How likely the other one still is
        # (image and prior) tells the localizer whether the choice is sure.
        candidates = sorted((_refined_candidate(obj, observed, K, r, t)
                             for _, r, t, _ in candidates), key=lambda sol: sol[0])
        rms = [math.sqrt(c[0] / n) for c in candidates]
        ambiguity = rms[1] / max(rms[0], 1e-9)
        noise2 = _flip_noise2(rms[0], pixel_sigma)
        # Without the last position (the localizer weighs continuity itself)
        # for the other's probability; with it, for the choice.
        costs = _flip_costs(candidates, noise2, prior, previous=False)
        if prior is not None and prior.previous_camera_in_pattern is not None:
            best = int(np.argmin(_flip_costs(candidates, noise2, prior)))
        else:
            best = int(np.argmin(costs))
        if best != 0:
            chosen_by = 'prior'
        other_probability = 1.0 / (1.0 + math.exp(float(np.clip(
            0.5 * (costs[1 - best] - costs[best]), -700.0, 700.0))))
        barrier = _flip_barrier(obj, observed, K, candidates, best, noise2)
    # (Each candidate carries its projection, made for its residual.) The
    # centres' bias correction depends only weakly on the pose: computed
    # from IPPE's pose it leaves a bias far below the noise after the
    # refinement. A dot partly hidden by an occluder or merged with a
    # neighbour keeps a centre far off the others' fit: drop it and solve
    # again. (fit_kernels.refine_exact.)
    _, R, t, projected = candidates[best]
    R, t, residual, outliers, ss, corrected = refine_exact(
        obj, _f64(observed), K, _f64(R), _f64(t), _f64(projected), _f64(radii),
        bool(bias_correction), MIN_OUTLIER_PX, OUTLIER_FACTOR)
    dropped = int(np.count_nonzero(outliers))
    if dropped and n - dropped >= MIN_POINTS:
        cleaned = points_px.copy()
        cleaned[np.flatnonzero(seen)[outliers]] = np.nan
        return estimate_exact(cleaned, camera, config, prior, pixel_sigma, bias_correction,
                              ambiguity_threshold, fit_prior)
    other = candidates[1 - best] if len(candidates) > 1 else None
    sigma = max(math.sqrt(ss / max(2 * n - 6, 1)), pixel_sigma or 0.0, DEFAULT_MIN_SIGMA_PX)
    prior_information = None
    if fit_prior and prior is not None and prior.fits and math.isfinite(barrier):
        # A close call: far and nearly face on, the image alone leaves the
        # card's turn in a shallow valley, where the dots' sub-pixel errors
        # set it (_flip_barrier). What is known of up and height then holds
        # the pose: the fit is the MAP pose of the image and those two, and
        # its covariance theirs together. (Elsewhere the image alone pins
        # the turn far tighter than a few degrees of up.)
        up, up_weight, height, height_weight = prior.fit_terms()
        R, t = refine_pose_prior(obj, corrected, K, R, t, 1.0 / sigma, _f64(up), up_weight,
                                 height, height_weight)
        ss = float(np.sum(point_residuals(R, t, obj, corrected, K) ** 2))
        prior_information = prior.information(Pose(R, t))
    pose = Pose(R, t)
    return PoseEstimate(
        T_camera_pattern=pose,
        covariance=pose_covariance(pose, obj, K, sigma, prior_information),
        reprojection_rms_px=math.sqrt(ss / n),
        ambiguity=(rms[1 - best] / max(rms[best], 1e-9)) if other is not None else math.inf,
        alternative=Pose(other[1], other[2]) if other is not None else None,
        n_points=n,
        chosen_by=chosen_by,
        other_probability=other_probability if other is not None else 0.0,
        flip_barrier=barrier if other is not None else math.inf,
        prior_information=prior_information,
    )


def _usable_sigma(sigma: float) -> bool:
    """Tell whether a prior's sigma can weigh a term: positive and finite."""
    return math.isfinite(sigma) and sigma > 0.0


def _flip_noise2(best_rms: float, pixel_sigma: Optional[float]) -> float:
    """
    Return the pixel variance the two planar solutions' costs are counted in.

    The better fit's RMS per dot (both image axes together, so twice a
    coordinate's variance), floored: the image's evidence is counted at
    about half its weight, which makes the other solution's probability an
    over-estimate, the safe side for a sure choice.
    """
    return max(pixel_sigma or 0.0, best_rms, DEFAULT_MIN_SIGMA_PX) ** 2


def _flip_costs(candidates, noise2: float, prior: Optional[PosePrior],
                previous: bool = True) -> List[float]:
    """Return each planar solution's cost: squared residuals over ``noise2``, plus the prior's."""
    return [c[0] / noise2 + (prior.penalty(Pose(c[1], c[2]), previous) if prior is not None
                             else 0.0) for c in candidates]


def _flip_barrier(obj: np.ndarray, observed: np.ndarray, K: np.ndarray, candidates,
                  best: int, sigma2: float, steps: int = 8) -> float:
    """
    Return how far the cost rises between the chosen planar solution and the other (noise units).

    Along the straight path between them (rotation vector and translation
    interpolated), ``steps`` points inside. Far away and nearly face on the
    two can lie in one shallow valley of the reprojection error: its
    floor, not the noise, then sets how the card is turned: rendered at
    5.8 m, 6 deg off face on, poses 0.4-0.6 m off scored 4-8 sigmas against
    their own covariance. A barrier of a few units means the valley,
    whichever solution is chosen.
    """
    (cost_a, R_a, t_a, _), (_, R_b, t_b, _) = candidates[best], candidates[1 - best]
    turn = rotation_vector(R_b @ R_a.T)
    t_a, t_b = np.asarray(t_a, dtype=float), np.asarray(t_b, dtype=float)
    highest = cost_a
    for k in range(1, steps + 1):
        s = k / (steps + 1.0)
        # The squared error as the refinement counts it, no arrays per step.
        highest = max(highest, pose_cost(obj, observed, K, _f64(rodrigues(s * turn) @ R_a),
                                         _f64((1.0 - s) * t_a + s * t_b)))
    return (highest - cost_a) / sigma2


def covariance_of_pose(T_camera_pattern: Pose, points_px: np.ndarray, camera: CameraModel,
                       config: PatternConfig, pixel_sigma: Optional[float] = None) -> np.ndarray:
    """
    Return the first-order 6x6 covariance of any pose estimate from its dots.

    For an estimator other than this module's (the paper's): the pixel noise
    is taken from the dots' reprojection residuals at that pose, so a pose
    that fits its dots worse gets a larger covariance. It does not know the
    estimator's own inefficiency; the exact estimator reaches this bound.
    """
    points_px = np.asarray(points_px, dtype=float)
    seen = ~np.isnan(points_px).any(axis=1)
    obj = _model_points(config)[seen]
    observed = camera.undistort_pixels(points_px[seen])
    residual = point_residuals(_f64(T_camera_pattern.R), _f64(T_camera_pattern.t), obj,
                               observed, _f64(camera.K))
    n = len(obj)
    sigma = max(math.sqrt(float(np.sum(residual ** 2)) / max(2 * n - 6, 1)),
                pixel_sigma or 0.0, DEFAULT_MIN_SIGMA_PX)
    return pose_covariance(T_camera_pattern, obj, camera.K, sigma)


def pose_covariance(T_camera_pattern: Pose, object_points: np.ndarray, K: np.ndarray,
                    sigma_px: float, prior_information: Optional[np.ndarray] = None
                    ) -> np.ndarray:
    """
    ``sigma^2 (J^T J)^-1`` for the camera pose in the pattern frame.

    Parameters: camera position (x, y, z, metres) and a small rotation of the
    camera about the pattern frame's axes (radians), the form
    PoseWithCovariance uses. With the true pose and the true pixel noise this
    is the Cramer-Rao bound of any unbiased estimator. With
    ``prior_information`` (:meth:`PosePrior.information`) it is the MAP
    pose's: ``(J^T J / sigma^2 + prior_information)^-1``.
    """
    R, t, obj = _f64(T_camera_pattern.R), _f64(T_camera_pattern.t), _f64(object_points)
    if prior_information is None:
        return pose_covariance_matrix(R, t, obj, _f64(K), float(sigma_px))
    J = pose_jacobian(R, t, obj, _f64(K))
    info = J.T @ J / float(sigma_px) ** 2 + prior_information
    try:
        covariance = np.linalg.inv(info)
    except np.linalg.LinAlgError:
        return np.full((6, 6), np.inf)
    return 0.5 * (covariance + covariance.T)


def ellipse_centres(T_camera_pattern: Pose, centres_xy: np.ndarray, radii: np.ndarray,
                    K: np.ndarray) -> np.ndarray:
    """Ideal-image centres of the image ellipses of plane circles (N, 2)."""
    return circle_image_centres(_f64(T_camera_pattern.R), _f64(T_camera_pattern.t),
                                _f64(np.asarray(centres_xy)[:, :2]), _f64(radii), _f64(K))


def paper_angles(T_camera_pattern: Pose, camera: CameraModel, config: PatternConfig
                 ) -> Tuple[float, float, float, float]:
    """
    Return the paper's (psi, phi, theta) in degrees and distance D (m) for a pose.

    phi: angle of the line centre -> camera to the card normal; theta: its
    azimuth from +y (point 1) towards +x; D: optical centre to card centre;
    psi: angle of the outer ring's image ellipse long axis to the image
    horizontal (ideal image).
    """
    R, t = _f64(T_camera_pattern.R), _f64(T_camera_pattern.t)
    c = -(R.T @ t)
    distance = math.sqrt(float(c @ c))
    phi = math.degrees(math.acos(min(max(float(c[2]) / distance, -1.0), 1.0)))
    theta = math.degrees(math.atan2(c[0], c[1])) % 360.0
    psi = math.degrees(circle_axis_angle(R, t, _f64(camera.K), float(config.ring_radii[0])))
    return psi, phi, theta, distance


# Internals -----------------------------------------------------------------

# Per pattern configuration, made once (per_config.made_once; lru_cache
# hashed the configuration on every pose): its dots' plane points and radii.
_PER_CONFIG: Dict[int, Tuple[PatternConfig, Tuple[np.ndarray, np.ndarray]]] = {}


def _per_config(config: PatternConfig) -> Tuple[np.ndarray, np.ndarray]:
    return made_once(_PER_CONFIG, config, _dots_of)


def _dots_of(config: PatternConfig) -> Tuple[np.ndarray, np.ndarray]:
    points, radii = config.model_points(), config.dot_radii()
    points.flags.writeable = False
    radii.flags.writeable = False
    return points, radii


def _model_points(config: PatternConfig) -> np.ndarray:
    return _per_config(config)[0]


def _dot_radii(config: PatternConfig) -> np.ndarray:
    return _per_config(config)[1]


def _f64(a) -> np.ndarray:
    """Contiguous float64, as the compiled kernels take their arrays (one signature each)."""
    return np.ascontiguousarray(a, dtype=np.float64)


def _ippe(obj: np.ndarray, observed_px: np.ndarray, K: np.ndarray):
    """Return the planar solutions (IPPE's): (squared error, R, t, projection) each."""
    obj = _f64(obj)
    observed_px = _f64(observed_px)
    # IPPE compiled (fit_kernels.planar_poses): OpenCV's solvePnPGeneric
    # costs 80-110 us a card in the detector's frame, a twentieth of it.
    ok, Rs, ts, errors, projected = planar_poses(obj, observed_px, K)
    if ok:
        return [(float(errors[k]), Rs[k], ts[k], projected[k]) for k in range(2)]
    image = observed_px.reshape(-1, 1, 2)

    def finite_solutions(flags: int):
        n, rvecs, tvecs, _ = cv2.solvePnPGeneric(obj, image, K, None, flags=flags)
        return [(r, t) for r, t in list(zip(rvecs, tvecs))[:n]
                if np.isfinite(r).all() and np.isfinite(t).all()]

    try:
        # A degenerate homography (the compiled IPPE's failure) may still
        # have OpenCV's IPPE solutions; where those are NaN (some exact,
        # noise-free views), the global SQPnP gives the one solution.
        found = finite_solutions(cv2.SOLVEPNP_IPPE) or finite_solutions(cv2.SOLVEPNP_SQPNP)
    except cv2.error as exc:
        raise EstimationError(f'planar PnP failed: {exc.msg if hasattr(exc, "msg") else exc}')
    if not found:
        raise EstimationError('planar PnP found no solution (degenerate dot layout)')
    solutions = []
    for r, t in found:
        R = cv2.Rodrigues(np.asarray(r, dtype=np.float64).reshape(3, 1))[0]
        t = np.asarray(t, dtype=np.float64).reshape(3)
        projected = project_points(R, t, obj, K)
        ss = float(np.sum((projected - observed_px) ** 2))
        solutions.append((ss, R, t, projected))
    return solutions


def _refined_candidate(obj, observed, K, R, t):
    R, t = refine_pose(obj, observed, K, R, t)
    projected = project_points(R, t, obj, K)
    return float(np.sum((projected - observed) ** 2)), R, t, projected
