"""
What the survey's graph is given: the options, each bag's motion, and the variables' keys.

Keys: ``X(n)`` a keyframe's base pose (building <- base), ``L(j)`` a card's
pose (building <- card), ``F(b)`` bag b's floor plane.
"""

from dataclasses import dataclass, field
import math
from typing import Dict, Optional, Tuple

import gtsam
import numpy as np

from ..vision.geometry import Pose

MAX_ODOM_GAP_S = 0.5


EXACT_SIGMA = 1e-6


def X(i: int) -> int:
    """Return the key of frame ``i``'s base pose."""
    return gtsam.symbol('x', i)


def L(j: int) -> int:
    """Return the key of card ``j``'s pose."""
    return gtsam.symbol('l', j)


def F(bag: int) -> int:
    """Return the key of a bag's floor plane."""
    return gtsam.symbol('f', bag)


@dataclass(frozen=True)
class SurveyOptions:
    """
    How the survey weighs what it knows.

    Odometry noise after calibration, a random walk: translation ``odom_sd_m
    + odom_sd_per_sqrt_m * sqrt(d)`` and heading ``odom_sd_yaw_rad +
    odom_sd_yaw_per_sqrt_m * sqrt(d)`` for a step of length d, isotropic in 3D
    when the odometry is the camera's own. ``rescale_noise``: the odometry's
    noise is then scaled (within ``odom_scale_bounds``) so that its residuals
    weigh like the sightings'.
    ``planar_sd``: z (m) and roll/pitch (rad) of a base's odometry step (loose:
    the floor below holds them).
    ``merge_m``, ``merge_s``: consecutive frames of a bag within this much
    odometry and time share one pose variable (a keyframe): the graph stays
    small at any frame rate, and every sighting is kept.
    ``card_floor_sd_m``, ``card_floor_sd_rad``: added to every card's
    covariance: what all the sightings of a card share (the print, the card's
    flatness, the detector's geometric biases) no number of sightings averages
    away; measured on rendered walks (``bench --survey``).
    ``refine_dots``: a last round with the sightings at least
    ``refine_min_distance_m`` away as reprojection factors over their dots
    (bundle adjustment, :mod:`.refine`; needs the bags' cameras).
    ``level_floor``: the bases of a bag (with odometry and a known camera
    mount) stand on one floor plane, level within ``floor_level_sd_rad``
    (gravity: what keeps a long map from tilting), each base upright on it
    within ``base_tilt_sd_rad`` and at its height within ``base_height_sd_m``
    (an uneven floor does not accumulate, unlike odometry).
    """

    use_odometry: bool = True
    calibrate_odometry: bool = True
    vertical_prior: bool = True
    vertical_sd_rad: float = math.radians(0.3)
    card_height_m: Optional[float] = None
    card_height_sd_m: float = 0.02
    huber_k: float = 3.5
    odom_sd_m: float = 0.0002
    odom_sd_per_sqrt_m: float = 0.005
    odom_sd_yaw_rad: float = math.radians(0.005)
    odom_sd_yaw_per_sqrt_m: float = math.radians(0.2)
    planar_sd: float = 0.01
    merge_m: float = 0.25
    merge_s: float = 1.0
    level_floor: bool = True
    floor_level_sd_rad: float = math.radians(0.1)
    base_tilt_sd_rad: float = math.radians(0.2)
    base_height_sd_m: float = 0.003
    card_floor_sd_m: float = 0.0005
    card_floor_sd_rad: float = math.radians(0.01)
    refine_dots: bool = False
    refine_min_distance_m: float = 0.0
    rescale_noise: bool = True
    odom_scale_bounds: Tuple[float, float] = (0.05, 20.0)
    max_rounds: int = 8
    first_card_tilt_sd_rad: float = math.radians(5.0)


@dataclass(frozen=True, eq=False)
class BagMotion:
    """
    What the graph needs of one bag besides its sightings.

    ``odom_*``: the raw odometry ``T_odom_base`` samples (None: no odometry).
    ``mounts``: ``T_base_camera`` per frame index (frames missing or None:
    the camera's place on the base is unknown then, so the frame stands
    alone). ``mount_source``: as ``bagio.Mount.source``; ``camera`` means
    the odometry, if any, is the camera's own (3D noise model).
    """

    name: str
    mount_source: str
    mounts: Dict[int, Optional[Pose]]
    odom_stamps_ns: Optional[np.ndarray] = None
    odom_R: Optional[np.ndarray] = None
    odom_p: Optional[np.ndarray] = None
    cameras: Dict[int, object] = field(default_factory=dict)      # frame -> CameraModel

    @property
    def has_odometry(self) -> bool:
        """Return True when the bag has odometry samples."""
        return self.odom_stamps_ns is not None and len(self.odom_stamps_ns) > 1
