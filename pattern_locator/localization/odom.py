"""
Odometry between fixes: a buffer of odom poses, the motion between two stamps, the bridge.

ROS-free. The locator's ``odom`` callback turns each nav_msgs/Odometry into
:meth:`OdomBuffer.add` ``(stamp_s, T_odom_base, covariance, twist)``; then

* :meth:`OdomBuffer.motion_between` ``(t0, t1)`` gives the base's motion
  from ``t0`` to ``t1`` as a :class:`~.gates.BaseMotion` (what the
  continuity gate and the pose prior take) with the covariance of that
  motion alone;
* :meth:`OdomBuffer.twist_at` gives the base's twist at an image's stamp
  (for the covariance terms of a moving base and for the head's
  feed-forward);
* an :class:`OdomBridge` holds the last fix and composes it with the
  odometry since (:meth:`OdomBridge.at`): a building pose at the
  odometry's rate whose covariance grows with the odometry's, so that a
  robot always has one (``robot_location/odom_bridged``).

Poses between samples are interpolated (linear in position, along the
shortest rotation in attitude). Covariances follow nav_msgs: 6x6, position
(m) then a small rotation (rad) about the parent frame's axes (ROS's
roll/pitch/yaw order is that order for small angles).

How the motion's covariance comes from the odometry's: a dead-reckoning
pose's covariance grows as ``S1 = F S0 F^T + Q`` with ``F`` the swing of
the start's heading error over the path (``[[I, -[p1 - p0]x], [0, I]]``),
so the motion's own covariance is ``Q = S1 - F S0 F^T``, rotated into the
start base frame. Odometry whose covariance is correlated over time (a
scale error) can make ``Q`` indefinite: its negative part is dropped. A
floor (:class:`OdomNoise`, a fraction of the distance and of the turn,
plus a gyro drift) is always added, so odometry that publishes zeros (many
drivers do) or too little still gives an honest motion covariance.
"""

import bisect
from dataclasses import dataclass
import math
import threading
from typing import List, Optional, Sequence, Tuple

import numpy as np

from .building import BuildingMap
from .gates import BaseMotion, compose_with_motion, pose_in_building
from ..errors import ConfigError
from ..vision.geometry import Pose, rodrigues, rotation_vector, skew

# Variance added to every diagonal term of a motion's covariance, so that a
# standing robot's motion (exactly zero) still has an invertible covariance.
_TINY_VARIANCE = 1e-10


@dataclass(frozen=True)
class OdomNoise:
    """
    The least uncertainty odometry has, whatever its messages say (the covariance floor).

    Per motion: ``translation_fraction`` of the distance driven (standard
    deviation in each horizontal axis), ``vertical_m_per_m`` per metre in
    z, ``turn_fraction`` of the angle turned plus ``yaw_drift_rad_s`` per
    second (a gyro's bias), ``tilt_rad_per_m`` of roll and pitch per metre
    (a floor's unevenness). The defaults are half the simulated odometry's
    systematic errors (``sim.odometry.OdometryModel``: 2 % scale, 0.002
    rad/s bias): the floor backs up the odometry's covariance, it does not
    replace it.
    """

    translation_fraction: float = 0.01
    vertical_m_per_m: float = 0.001
    turn_fraction: float = 0.005
    yaw_drift_rad_s: float = 0.001
    tilt_rad_per_m: float = 0.001

    def __post_init__(self) -> None:
        for name in ('translation_fraction', 'vertical_m_per_m', 'turn_fraction',
                     'yaw_drift_rad_s', 'tilt_rad_per_m'):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not (
                    math.isfinite(value) and value >= 0.0):
                raise ConfigError(f'odometry noise: {name} must be a number >= 0, got {value!r}')

    def covariance(self, motion: Pose, duration_s: float) -> np.ndarray:
        """Return the floor's 6x6 for a motion (start base frame) lasting ``duration_s``."""
        distance = float(np.linalg.norm(motion.t))
        turn = float(np.linalg.norm(rotation_vector(motion.R)))
        out = np.zeros((6, 6))
        out[0, 0] = out[1, 1] = (self.translation_fraction * distance) ** 2
        out[2, 2] = (self.vertical_m_per_m * distance) ** 2
        out[3, 3] = out[4, 4] = (self.tilt_rad_per_m * distance) ** 2
        out[5, 5] = (self.turn_fraction * turn + self.yaw_drift_rad_s * abs(duration_s)) ** 2
        return out + _TINY_VARIANCE * np.eye(6)


@dataclass(frozen=True)
class BaseTwist:
    """The base's velocity in ``base_link``: ``linear`` (m/s) and ``angular`` (rad/s), (3,)."""

    linear: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    angular: Tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def speed_m_s(self) -> float:
        """Return the speed (m/s)."""
        return float(np.linalg.norm(self.linear))

    @property
    def yaw_rate_rad_s(self) -> float:
        """Return the yaw rate (rad/s, + = left)."""
        return float(self.angular[2])


class OdomBuffer:
    """
    Recent odometry poses with covariances, in stamp order (thread-safe).

    ``history_s``: samples older than this before the newest are dropped
    (the bridge cannot reach further back than this from its fix).
    ``max_gap_s``: two samples further apart than this are not
    interpolated (the odometry stopped). ``max_extrapolation_s``: a stamp
    up to this much after the newest sample uses the newest (held, with
    the floor's growth); later ones are unknown. A sample more than
    ``clock_jump_back_s`` older than the newest means the clock jumped
    back (a bag replayed again): the buffer starts over.
    """

    def __init__(self, history_s: float = 60.0, max_gap_s: float = 0.5,
                 max_extrapolation_s: float = 0.1, noise: OdomNoise = OdomNoise(),
                 clock_jump_back_s: float = 1.0) -> None:
        for name, value in (('history_s', history_s), ('max_gap_s', max_gap_s),
                            ('max_extrapolation_s', max_extrapolation_s),
                            ('clock_jump_back_s', clock_jump_back_s)):
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not (
                    math.isfinite(value) and value >= 0.0):
                raise ConfigError(f'odometry buffer: {name} must be a number >= 0, got '
                                  f'{value!r}')
        self.history_s = float(history_s)
        self.max_gap_s = float(max_gap_s)
        self.max_extrapolation_s = float(max_extrapolation_s)
        self.noise = noise
        self.clock_jump_back_s = float(clock_jump_back_s)
        self._stamps: List[float] = []
        self._poses: List[Pose] = []
        self._covariances: List[Optional[np.ndarray]] = []
        self._twists: List[Optional[BaseTwist]] = []
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return len(self._stamps)

    def clear(self) -> None:
        """Forget every sample."""
        with self._lock:
            self._stamps.clear()
            self._poses.clear()
            self._covariances.clear()
            self._twists.clear()

    @property
    def span(self) -> Optional[Tuple[float, float]]:
        """Return the (oldest, newest) stamps held, or None."""
        with self._lock:
            return (self._stamps[0], self._stamps[-1]) if self._stamps else None

    def add(self, stamp_s: float, T_odom_base: Pose, covariance: Optional[np.ndarray] = None,
            twist: Optional[BaseTwist] = None) -> None:
        """
        Insert one odometry sample (a sample with an existing stamp replaces it).

        ``covariance``: the message's 6x6 pose covariance (None, or a first
        element below zero, as REP 105 drivers say "unknown": the floor
        alone is used). ``twist``: the message's twist in ``base_link``.
        ConfigError, and nothing stored, for a pose or covariance that is
        not finite, a rotation that is not one, or a covariance of the
        wrong shape.
        """
        stamp_s = float(stamp_s)
        R = np.asarray(T_odom_base.R, dtype=float)
        t = np.asarray(T_odom_base.t, dtype=float).reshape(3)
        if not (math.isfinite(stamp_s) and np.all(np.isfinite(R)) and np.all(np.isfinite(t))):
            raise ConfigError('odometry: stamp or pose not finite')
        if R.shape != (3, 3) or np.abs(R.T @ R - np.eye(3)).max() > 1e-3:
            raise ConfigError('odometry: orientation is not a rotation (quaternion not unit?)')
        cov = None
        if covariance is not None:
            cov = np.asarray(covariance, dtype=float)
            if cov.size == 36:
                cov = cov.reshape(6, 6)
            if cov.shape != (6, 6):
                raise ConfigError(f'odometry: covariance must be 6x6, got {cov.shape}')
            if not np.all(np.isfinite(cov)):
                raise ConfigError('odometry: covariance not finite')
            cov = None if cov[0, 0] < 0.0 else 0.5 * (cov + cov.T)
        if twist is not None and not (np.all(np.isfinite(twist.linear))
                                      and np.all(np.isfinite(twist.angular))):
            raise ConfigError('odometry: twist not finite')
        # Re-orthonormalise: compositions over minutes must stay rotations.
        u, _, vt = np.linalg.svd(R)
        pose = Pose(u @ vt, t.copy())
        with self._lock:
            if self._stamps and stamp_s < self._stamps[-1] - self.clock_jump_back_s:
                self._stamps.clear()
                self._poses.clear()
                self._covariances.clear()
                self._twists.clear()
            i = bisect.bisect_left(self._stamps, stamp_s)
            if i < len(self._stamps) and self._stamps[i] == stamp_s:
                self._poses[i], self._covariances[i], self._twists[i] = pose, cov, twist
            else:
                self._stamps.insert(i, stamp_s)
                self._poses.insert(i, pose)
                self._covariances.insert(i, cov)
                self._twists.insert(i, twist)
            cut = bisect.bisect_left(self._stamps, self._stamps[-1] - self.history_s)
            if cut > 0:
                del self._stamps[:cut], self._poses[:cut], self._covariances[:cut]
                del self._twists[:cut]

    # Queries ----------------------------------------------------------------------

    def pose_at(self, stamp_s: float) -> Optional[Tuple[Pose, Optional[np.ndarray]]]:
        """Return ``T_odom_base`` and its covariance at a stamp (None when not covered)."""
        with self._lock:
            found = self._locate(float(stamp_s))
        if found is None:
            return None
        return found[0], found[1]

    def motion_between(self, t0: float, t1: float) -> Optional[BaseMotion]:
        """
        Return the base's motion from ``t0`` to ``t1`` (either order), or None if not covered.

        ``BaseMotion.since_stamp_s`` is ``t0``; ``T_start_end`` is the base at
        ``t1`` in the base frame at ``t0``; its covariance is the motion's
        own (module docstring), in the start base frame.
        """
        t0, t1 = float(t0), float(t1)
        with self._lock:
            a = self._locate(t0)
            b = self._locate(t1)
        if a is None or b is None:
            return None
        (T0, S0, _), (T1, S1, _) = a, b
        motion = T0.inverse() @ T1
        cov = self.noise.covariance(motion, t1 - t0)
        if S0 is not None and S1 is not None:
            cov = cov + _motion_covariance(T0, S0, T1, S1, t1 >= t0)
        return BaseMotion(t0, motion, 0.5 * (cov + cov.T))

    def twist_at(self, stamp_s: float, window_s: float = 0.1) -> Optional[BaseTwist]:
        """
        Return the base's twist at a stamp: the messages' (interpolated), else from poses.

        Without twists in the messages, the twist is the pose's change over
        ``window_s`` centred on the stamp (clipped to the samples held).
        """
        stamp_s = float(stamp_s)
        with self._lock:
            found = self._locate(stamp_s)
            if found is None:
                return None
            twist = found[2]
            if twist is not None:
                return twist
            lo = max(stamp_s - window_s / 2.0, self._stamps[0])
            hi = min(stamp_s + window_s / 2.0, self._stamps[-1])
            if hi - lo < 1e-6:
                return BaseTwist()
            a, b = self._locate(lo), self._locate(hi)
        if a is None or b is None:
            return None
        delta = a[0].inverse() @ b[0]
        dt = hi - lo
        return BaseTwist(tuple(float(v) for v in delta.t / dt),
                         tuple(float(v) for v in rotation_vector(delta.R) / dt))

    def _locate(self, stamp: float
                ) -> Optional[Tuple[Pose, Optional[np.ndarray], Optional[BaseTwist]]]:
        """Interpolate pose, covariance and twist at ``stamp`` (caller holds the lock)."""
        stamps = self._stamps
        if not stamps or not math.isfinite(stamp):
            return None
        if stamp >= stamps[-1]:
            if stamp - stamps[-1] > self.max_extrapolation_s:
                return None
            return self._poses[-1], self._covariances[-1], self._twists[-1]
        if stamp < stamps[0]:
            return None
        i = bisect.bisect_right(stamps, stamp)
        s0, s1 = stamps[i - 1], stamps[i]
        if s0 == stamp:
            return self._poses[i - 1], self._covariances[i - 1], self._twists[i - 1]
        if s1 - s0 > self.max_gap_s:
            return None
        w = (stamp - s0) / (s1 - s0) if s1 > s0 else 0.0
        P0, P1 = self._poses[i - 1], self._poses[i]
        R = P0.R @ rodrigues(w * rotation_vector(P0.R.T @ P1.R))
        pose = Pose(R, P0.t + w * (P1.t - P0.t))
        C0, C1 = self._covariances[i - 1], self._covariances[i]
        cov = None if C0 is None or C1 is None else C0 + w * (C1 - C0)
        W0, W1 = self._twists[i - 1], self._twists[i]
        twist = None
        if W0 is not None and W1 is not None:
            linear = np.add(W0.linear, w * np.subtract(W1.linear, W0.linear))
            angular = np.add(W0.angular, w * np.subtract(W1.angular, W0.angular))
            twist = BaseTwist(tuple(float(v) for v in linear), tuple(float(v) for v in angular))
        return pose, cov, twist


def _motion_covariance(T0: Pose, S0: np.ndarray, T1: Pose, S1: np.ndarray,
                       forward: bool) -> np.ndarray:
    """Return the covariance the odometry grew by between two poses, in the start base frame."""
    if not forward:
        # Backwards in time: the earlier pose is the one with the smaller covariance.
        T0, S0, T1, S1 = T1, S1, T0, S0
    F = np.eye(6)
    F[:3, 3:] = -skew(T1.t - T0.t)
    Q = S1 - F @ S0 @ F.T
    Q = 0.5 * (Q + Q.T)
    values, vectors = np.linalg.eigh(Q)
    Q = (vectors * np.clip(values, 0.0, None)) @ vectors.T
    J = np.zeros((6, 6))
    J[:3, :3] = T0.R.T
    J[3:, 3:] = T0.R.T
    return J @ Q @ J.T


@dataclass(frozen=True)
class BridgedPose:
    """
    The base's pose at ``stamp_s``: the last fix composed with the odometry since.

    ``T_frame_base`` and ``covariance`` (6x6, position then rotation about
    the frame's axes) in ``frame_id``; ``fix_stamp_s``: the fix's stamp
    (``age_s`` before ``stamp_s``).
    """

    stamp_s: float
    frame_id: str
    T_frame_base: Pose
    covariance: np.ndarray
    fix_stamp_s: float

    @property
    def age_s(self) -> float:
        """Return how long before ``stamp_s`` the fix was taken."""
        return self.stamp_s - self.fix_stamp_s


class OdomBridge:
    """
    The last fix carried forward by odometry (``robot_location/odom_bridged``).

    ``odometry``: the buffer the odom callback fills. ``building``: with it,
    poses come in the building frame (a room frame's fix is converted), so
    the bridge's frame does not change as the robot passes from room to
    room; without it, in the fix's frame. ``max_position_sigma_m``: beyond
    this standard deviation (the largest of the position's), :meth:`at`
    gives None: the bridge has drifted too far to be a location.
    ``max_age_s``: likewise for the fix's age.
    """

    def __init__(self, odometry: OdomBuffer, building: Optional[BuildingMap] = None,
                 max_position_sigma_m: float = 1.0, max_age_s: float = 60.0) -> None:
        for name, value in (('max_position_sigma_m', max_position_sigma_m),
                            ('max_age_s', max_age_s)):
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not (
                    math.isfinite(value) and value > 0.0):
                raise ConfigError(f'odometry bridge: {name} must be a number > 0, got '
                                  f'{value!r}')
        self.odometry = odometry
        self.building = building
        self.max_position_sigma_m = float(max_position_sigma_m)
        self.max_age_s = float(max_age_s)
        self._fix: Optional[Tuple[float, str, Pose, np.ndarray]] = None
        self._lock = threading.Lock()

    def reset(self) -> None:
        """Forget the fix (no pose until the next one)."""
        with self._lock:
            self._fix = None

    @property
    def fix_stamp_s(self) -> Optional[float]:
        """Return the stamp of the fix carried forward, or None."""
        with self._lock:
            return None if self._fix is None else self._fix[0]

    def update(self, fix, stamp_s: float) -> None:
        """
        Take a new fix, taken at ``stamp_s``.

        ``fix``: a ``localizer.RobotFix``, or anything with ``frame_id``,
        ``T_frame_base`` and ``covariance``. A fix older than the one held
        is ignored (fixes may arrive out of order from a worker), unless
        the clock jumped back.
        """
        stamp_s = float(stamp_s)
        frame_id, T, cov = fix.frame_id, fix.T_frame_base, np.asarray(fix.covariance, float)
        if self.building is not None and frame_id != self.building.frame:
            T, cov, _ = pose_in_building(T, cov, frame_id, self.building)
            frame_id = self.building.frame
        with self._lock:
            if self._fix is not None and stamp_s < self._fix[0]:
                if stamp_s > self._fix[0] - self.odometry.clock_jump_back_s:
                    return
            self._fix = (stamp_s, frame_id, T, cov)

    def at(self, stamp_s: float) -> Optional[BridgedPose]:
        """Return the bridged pose at ``stamp_s``, or None (no fix, no odometry, drifted)."""
        with self._lock:
            fix = self._fix
        if fix is None:
            return None
        fix_stamp, frame_id, T, cov = fix
        if abs(stamp_s - fix_stamp) > self.max_age_s:
            return None
        motion = self.odometry.motion_between(fix_stamp, stamp_s)
        if motion is None:
            return None
        pose, covariance = compose_with_motion(T, cov, motion.T_start_end, motion.covariance)
        sigma = math.sqrt(max(float(np.max(np.linalg.eigvalsh(covariance[:3, :3]))), 0.0))
        if not (sigma <= self.max_position_sigma_m):
            return None
        return BridgedPose(float(stamp_s), frame_id, pose, covariance, fix_stamp)


def odom_pose(x: float, y: float, yaw: float, z: float = 0.0) -> Pose:
    """Return a planar ``T_odom_base`` (a test and bench helper)."""
    c, s = math.cos(yaw), math.sin(yaw)
    return Pose(np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]), np.array([x, y, z]))


def covariance_from_ros(values: Sequence[float]) -> np.ndarray:
    """Return a nav_msgs 36-value covariance as 6x6 (ConfigError if not 36 values)."""
    array = np.asarray(values, dtype=float)
    if array.size != 36:
        raise ConfigError(f'odometry: covariance must have 36 values, got {array.size}')
    return array.reshape(6, 6)
