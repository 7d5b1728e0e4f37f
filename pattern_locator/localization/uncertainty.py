"""
The covariance of a fix: every term that really limits it, each from a measurement.

ROS-free. A fix composes the card's pose from the map, the camera's pose
from the image and the head's angles at the image's stamp. Each brings
its own error, and :func:`fix_covariance` adds them up (first order, as
independent terms) in the fix's frame (position, then a small rotation
about the frame's axes, as ``RobotFix.covariance``):

``image``
    The estimator's Fisher covariance ``s^2 (J^T J)^-1`` with the pixel
    noise ``s`` the larger of the fit's own residual noise and the
    detector's measured centre noise (``pixel_sigma_px``), plus the noise
    motion blur adds to the dot centres (``blur_sigma_per_px`` per pixel
    of smear, the smear predicted from the head's and the base's motion
    over the exposure).
``head_timing``
    The head's angles are interpolated to the image's stamp from joint
    states stamped when the camera's answer arrived: an error ``dt`` in
    the relative timing moves them by ``rate * dt``
    (``joint_stamp_sigma_s``, and ``image_stamp_sigma_s`` for the image's
    own stamp, which also moves the base by its twist).
``head_interpolation``
    Between two joint states the head is where a straight line puts it
    only if its speed did not change; a change of rate ``dw`` in an
    interval ``T`` leaves an error of about ``interpolation_factor * dw *
    T``. Holding the last sample past its stamp leaves ``rate * hold``.
``head_resolution``
    The joint angles' quantisation (the EVI-D31 reports pan in 1/8.8 deg,
    tilt in 1/12 deg): a uniform error of one step, ``step / sqrt(12)``.
``map``
    The card's pose in the map, where the map gives its standard
    deviations (``std_dev`` of a card, :attr:`MappedCard.std_dev`), or
    the parameters' defaults for cards without one.
``floor``
    What the other terms leave unexplained (``floor_position_m``,
    ``floor_rotation_deg``).

The default parameters are the values measured by ``pattern-locator bench
--drive-core`` (``docs/robot_localization.md`` has the measurements).
"""

from dataclasses import dataclass, fields
import math
from typing import Dict, Optional, Sequence, Tuple

import numpy as np

from .building import CardStdDev
from .head import angle_jacobian, covariance_to_base, HeadGeometry, HeadMotion
from .odom import BaseTwist
from ..errors import ConfigError
from ..vision.camera import CameraModel
from ..vision.geometry import Pose, rodrigues, skew
from ..vision.pose_exact import DEFAULT_MIN_SIGMA_PX, pose_covariance

TERMS = ('image', 'head_timing', 'head_interpolation', 'head_resolution', 'map', 'floor')
# The EVI-D31's joint resolution (visca.md): pan 8.8 units per degree, tilt 12.
EVI_D31_PAN_STEP_RAD = math.radians(1.0 / 8.8)
EVI_D31_TILT_STEP_RAD = math.radians(1.0 / 12.0)


@dataclass(frozen=True)
class UncertaintyParameters:
    """
    The sizes of the error sources (module docstring); defaults as measured.

    ``exposure_s``: the shutter time (of each field when interlaced);
    ``field_period_s``: the time between an interlaced frame's two fields
    (0 for a progressive camera). ``map_position_sigma_m`` and
    ``map_rotation_sigma_deg``: for cards whose map entry gives no
    ``std_dev``. Each field is meant to be a ROS parameter of the locator
    under the same name, prefixed ``uncertainty.``.
    """

    # The detector's dot-centre noise on still frames (per axis, median over cards).
    pixel_sigma_px: float = 0.014
    # The estimator's error over its Fisher bound at the fit's own residual noise.
    residual_factor: float = 1.1
    # Centre noise added per pixel of smear.
    blur_sigma_per_px: float = 0.005
    exposure_s: float = 0.02
    field_period_s: float = 0.0
    # RMS of (joint state stamp - when the camera latched the position).
    joint_stamp_sigma_s: float = 0.010
    image_stamp_sigma_s: float = 0.0
    interpolation_factor: float = 0.2
    pan_step_rad: float = EVI_D31_PAN_STEP_RAD
    tilt_step_rad: float = EVI_D31_TILT_STEP_RAD
    map_position_sigma_m: float = 0.0
    map_rotation_sigma_deg: float = 0.0
    # What the other terms leave unexplained: 0 in the sim (a 1 mm floor made
    # the covariance too cautious, coverage_95 0.985-0.99); a real camera's
    # calibration error is a reason to raise it.
    floor_position_m: float = 0.0
    floor_rotation_deg: float = 0.0

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not (
                    math.isfinite(value) and value >= 0.0):
                raise ConfigError(f'uncertainty: {f.name} must be a number >= 0, got {value!r}')

    @staticmethod
    def fisher_only() -> 'UncertaintyParameters':
        """
        Return the parameters of the estimator's covariance alone (the locator before issue 12).

        Pixel noise from the fit's residuals with the estimator's own floor;
        no head, blur, map or floor terms.
        """
        return UncertaintyParameters(
            pixel_sigma_px=DEFAULT_MIN_SIGMA_PX, residual_factor=1.0, blur_sigma_per_px=0.0,
            joint_stamp_sigma_s=0.0, image_stamp_sigma_s=0.0, interpolation_factor=0.0,
            pan_step_rad=0.0, tilt_step_rad=0.0, floor_position_m=0.0)


def card_std_dev(card, parameters: UncertaintyParameters) -> CardStdDev:
    """
    Return a mapped card's pose standard deviations about its room's axes.

    From the card's ``std_dev`` attribute when the map gives one (an object
    or a mapping with ``position_m`` and ``rotation_deg``, each a number or
    three numbers), else the parameters' defaults.
    """
    given = getattr(card, 'std_dev', None)
    position = rotation = None
    if given is not None:
        if isinstance(given, dict):
            position, rotation = given.get('position_m'), given.get('rotation_deg')
        else:
            position = getattr(given, 'position_m', None)
            rotation = getattr(given, 'rotation_deg', None)

    def three(value, default: float) -> Tuple[float, float, float]:
        if value is None:
            return (default,) * 3
        array = np.broadcast_to(np.asarray(value, dtype=float).reshape(-1), (3,))
        return tuple(float(v) for v in array)

    return CardStdDev(three(position, parameters.map_position_sigma_m),
                      three(rotation, parameters.map_rotation_sigma_deg))


@dataclass(frozen=True)
class FixCovariance:
    """A fix's covariance (6x6) and each term of it (:data:`TERMS`), in the fix's frame."""

    total: np.ndarray
    terms: Dict[str, np.ndarray]
    pixel_sigma_px: float          # the pixel noise the image term used
    blur_px: float                 # the predicted smear of the card's centre
    residual_sigma_px: float = 0.0  # the fit's own pixel noise (residuals)

    def position_sigmas(self) -> Dict[str, float]:
        """Return each term's largest position standard deviation (m), for logs and benches."""
        return {name: math.sqrt(max(float(np.max(np.linalg.eigvalsh(c[:3, :3]))), 0.0))
                for name, c in self.terms.items()}


def predicted_blur_px(camera: CameraModel, head: HeadGeometry, T_camera_card: Pose,
                      motion: HeadMotion, twist: Optional[BaseTwist], duration_s: float) -> float:
    """
    Return how far the card's centre moves in the image over ``duration_s`` (pixels).

    The head turns at its rates and the base moves with its twist (None:
    standing); the card stands still in the world.
    """
    if duration_s <= 0.0:
        return 0.0
    T_base_camera = head.T_base_camera(motion.pan, motion.tilt)
    T_base_later = head.T_base_camera(motion.pan + motion.pan_rate * duration_s,
                                      motion.tilt + motion.tilt_rate * duration_s)
    moved = Pose.identity()
    if twist is not None:
        moved = Pose(rodrigues(np.asarray(twist.angular, dtype=float) * duration_s),
                     np.asarray(twist.linear, dtype=float) * duration_s)
    # The later camera in the earlier camera's frame.
    T_camera_later = T_base_camera.inverse() @ moved @ T_base_later
    centre = T_camera_card.t
    later = T_camera_later.inverse().apply(centre[None])[0]
    if centre[2] <= 0.0 or later[2] <= 0.0:
        return 0.0
    a = camera.K @ (centre / centre[2])
    b = camera.K @ (later / later[2])
    return float(math.hypot(b[0] - a[0], b[1] - a[1]))


def fix_covariance(parameters: UncertaintyParameters, camera: CameraModel,
                   model_points: np.ndarray, seen: np.ndarray, reprojection_rms_px: float,
                   T_camera_card: Pose, T_frame_card: Pose, T_frame_base: Pose, card,
                   head: HeadGeometry, motion: HeadMotion,
                   twist: Optional[BaseTwist] = None,
                   prior_information: Optional[np.ndarray] = None) -> FixCovariance:
    """
    Return a fix's covariance, term by term (module docstring), in the frame of ``T_frame_card``.

    ``model_points``: the card's dot centres (pattern frame); ``seen``: the
    dots the pose used (bool mask); ``reprojection_rms_px``: the fit's RMS
    residual; ``T_camera_card``: the estimated pose; ``T_frame_card`` and
    ``T_frame_base``: the card and the base in the output frame; ``card``:
    the map's card (for ``std_dev``); ``motion``: the head's angles and
    rates at the stamp; ``twist``: the base's (None: standing);
    ``prior_information``: what up and height added to the pose's fit
    (``PoseEstimate.prior_information``), in its image term.
    """
    p = parameters
    seen = np.asarray(seen, dtype=bool)
    obj = np.asarray(model_points, dtype=float)[seen]
    n = len(obj)
    residual_sigma = float(reprojection_rms_px) * math.sqrt(n / max(2 * n - 6, 1))
    blur = predicted_blur_px(camera, head, T_camera_card, motion, twist,
                             p.exposure_s + p.field_period_s)
    sigma_px = math.sqrt(max(p.residual_factor * residual_sigma, p.pixel_sigma_px, 1e-6) ** 2
                         + (p.blur_sigma_per_px * blur) ** 2)
    cov_camera = pose_covariance(T_camera_card, obj, camera.K, sigma_px, prior_information)
    pan, tilt = motion.pan, motion.tilt
    terms: Dict[str, np.ndarray] = {}
    terms['image'] = covariance_to_base(cov_camera, T_frame_card, T_camera_card, head, pan, tilt)

    Ja = angle_jacobian(T_frame_card, T_camera_card, head, pan, tilt)
    rates = np.array([motion.pan_rate, motion.tilt_rate])
    # Relative timing of the joint states and the image: both stamps' errors.
    head_dir = Ja @ rates
    timing = np.outer(head_dir, head_dir) * p.joint_stamp_sigma_s ** 2
    if p.image_stamp_sigma_s > 0.0 and twist is not None:
        # The image's own stamp moves the base too (the fix is reported at it).
        R = T_frame_base.R
        base_dir = np.concatenate([R @ np.asarray(twist.linear, dtype=float),
                                   R @ np.asarray(twist.angular, dtype=float)])
        both = head_dir + base_dir
        timing = timing + np.outer(both, both) * p.image_stamp_sigma_s ** 2
    elif p.image_stamp_sigma_s > 0.0:
        timing = timing + np.outer(head_dir, head_dir) * p.image_stamp_sigma_s ** 2
    terms['head_timing'] = timing
    interpolation = (p.interpolation_factor * np.asarray(motion.rate_change, dtype=float)
                     * motion.interval_s) ** 2 + (rates * motion.hold_s) ** 2
    terms['head_interpolation'] = Ja @ np.diag(interpolation) @ Ja.T
    resolution = np.array([p.pan_step_rad, p.tilt_step_rad]) ** 2 / 12.0
    terms['head_resolution'] = Ja @ np.diag(resolution) @ Ja.T
    terms['map'] = _map_term(card_std_dev(card, p), getattr(card, 'T_room_card', None),
                             T_frame_card, T_frame_base)
    terms['floor'] = np.diag([p.floor_position_m ** 2] * 3
                             + [math.radians(p.floor_rotation_deg) ** 2] * 3)
    total = np.sum(list(terms.values()), axis=0)
    return FixCovariance(0.5 * (total + total.T), terms, sigma_px, blur, residual_sigma)


def _map_term(std: CardStdDev, T_room_card: Optional[Pose], T_frame_card: Pose,
              T_frame_base: Pose) -> np.ndarray:
    """Return the covariance the card's own pose error gives the base (frame axes)."""
    sp = np.asarray(std.position_m, dtype=float)
    sr = np.radians(np.asarray(std.rotation_deg, dtype=float))
    if not (np.any(sp > 0.0) or np.any(sr > 0.0)):
        return np.zeros((6, 6))
    # The standard deviations are about the room's axes: turn them to the frame's.
    R = np.eye(3)
    if T_room_card is not None:
        R = T_frame_card.R @ T_room_card.R.T          # R_frame_room
    cov = np.zeros((6, 6))
    cov[:3, :3] = R @ np.diag(sp ** 2) @ R.T
    cov[3:, 3:] = R @ np.diag(sr ** 2) @ R.T
    # The base hangs off the card: turning the card swings it about the card's centre.
    J = np.eye(6)
    J[:3, 3:] = -skew(T_frame_base.t - T_frame_card.t)
    return J @ cov @ J.T


def chi2_95(dof: int) -> float:
    """Return the 95 % quantile of chi-square with ``dof`` degrees of freedom (1..6)."""
    table = {1: 3.841459, 2: 5.991465, 3: 7.814728, 4: 9.487729, 5: 11.070498, 6: 12.591587}
    if dof not in table:
        raise ValueError(f'chi2_95: dof must be 1..6, got {dof}')
    return table[dof]


def inside_95(error: Sequence[float], covariance: np.ndarray) -> bool:
    """Return whether an error vector lies inside its covariance's 95 % ellipsoid."""
    e = np.asarray(error, dtype=float).reshape(-1)
    c = np.asarray(covariance, dtype=float)[:len(e), :len(e)]
    try:
        d2 = float(e @ np.linalg.solve(c, e))
    except np.linalg.LinAlgError:
        return False
    return bool(math.isfinite(d2) and d2 <= chi2_95(len(e)))
