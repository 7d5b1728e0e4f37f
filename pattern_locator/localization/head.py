"""
Pan/tilt head kinematics and the head's angles at an image's time.

Chain (``Pose`` maps child into parent, ``X_parent = R X_child + t``)::

    base_link -> camera_pan_link -> camera_tilt_link -> camera_optical_frame

* ``base_link``: REP 103, x forward, y left, z up. The defaults put it at
  floor level under the mast (as the paper's robot: the camera's optical
  centre 1.10 m above the floor at tilt 0).
* ``camera_pan`` joint: ``camera_pan_link`` sits at ``base_to_pan_xyz`` in
  ``base_link`` and is turned by ``pan`` about its +z axis. Positive pan =
  turn left (counter-clockwise seen from above), REP 103. The EVI-D31 counts
  pan positive to the *right*: the camera driver negates it.
* ``camera_tilt`` joint: ``camera_tilt_link`` (x forward, y left, z up at
  tilt 0) sits at ``pan_to_tilt_xyz`` in ``camera_pan_link`` and is turned
  by ``tilt`` about the link's **-y** axis, so positive tilt = the camera
  looks up, which is the EVI-D31's own "up" sign. (A right-handed rotation
  about +y would tip the nose down; in a URDF the joint's axis is
  ``0 -1 0``.)
* ``camera_optical_frame`` (x right, y down, z forward) sits at
  ``tilt_to_optical_xyz`` in ``camera_tilt_link``, rotated by the standard
  fixed rpy = (-pi/2, 0, -pi/2): optical z = link x, optical x = link -y,
  optical y = link -z.

Joint angles (radians) come from ``/camera/joint_states``; a
:class:`JointStateBuffer` matches them to an image's stamp by linear
interpolation and reports missing, stale or gappy joint states rather than
guessing. Fixed configured angles are used only when no joint_states topic
is configured (:func:`head_angles`).
"""

import bisect
from dataclasses import dataclass, field
import math
import numbers
import threading
from typing import List, Optional, Sequence, Tuple

import numpy as np

from ..errors import ConfigError, PatternLocatorError
from ..vision.geometry import Pose, skew

# EVI-D31 travel (visca.md): pan +-100 deg, tilt +-25 deg.
EVI_D31_PAN_LIMITS_RAD = (-math.radians(100.0), math.radians(100.0))
EVI_D31_TILT_LIMITS_RAD = (-math.radians(25.0), math.radians(25.0))
# Joint states may be this far outside the travel (encoder and rounding
# slack); beyond it they are refused, never stored or used.
JOINT_MARGIN_RAD = math.radians(5.0)
MAX_JOINTS = 256              # names in one JointState: a head has a handful

# camera_optical_frame axes in camera_tilt_link (columns): rpy (-pi/2, 0, -pi/2).
R_TILT_OPTICAL = np.array([[0.0, 0.0, 1.0],
                           [-1.0, 0.0, 0.0],
                           [0.0, -1.0, 0.0]])


class HeadStateError(PatternLocatorError):
    """The head's angles at an image's time are unknown (missing, stale or bad joint states)."""


def _rot_z(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _rot_tilt(tilt: float) -> np.ndarray:
    """Return the rotation by ``tilt`` about -y: +x turns up (towards +z) for tilt > 0."""
    c, s = math.cos(tilt), math.sin(tilt)
    return np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])


def _xyz(value, name: str) -> Tuple[float, float, float]:
    try:
        xyz = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise ConfigError(f'head geometry: {name} must be three numbers, got {value!r}')
    if len(xyz) != 3 or not all(math.isfinite(v) for v in xyz):
        raise ConfigError(f'head geometry: {name} must be three finite numbers, got {value!r}')
    return xyz


def limit_pair(value, name: str, owner: str = 'head geometry') -> Tuple[float, float]:
    """Return travel limits (min, max) in radians; ConfigError naming ``owner`` if bad."""
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ConfigError(f'{owner}: {name} must be (min, max) in radians, got {value!r}')
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise ConfigError(f'{owner}: {name} must be finite with min < max, got {value!r}')
    return lo, hi


@dataclass(frozen=True)
class HeadGeometry:
    """
    Mount offsets (metres) and travel limits (radians) of the pan/tilt head.

    Defaults: a camera on a 1 m mast over ``base_link`` at floor level; the
    tilt axis 5 cm above the pan link, the optical centre 3 cm in front of
    and 5 cm above the tilt axis, so the optical centre is 1.10 m above the
    floor at tilt 0. ``mount_pitch_rad``: the camera sits on the tilt link
    pitched up by this much (positive = up), so tilt 0 looks up by it: a
    head on a mast looking at cards above it gets the EVI-D31's +-25 deg
    travel where the cards are. Limits: the EVI-D31's travel, in joint
    angles. Sequences (lists from ROS parameters) are accepted and stored as
    tuples.
    """

    base_to_pan_xyz: Tuple[float, float, float] = (0.0, 0.0, 1.0)
    pan_to_tilt_xyz: Tuple[float, float, float] = (0.0, 0.0, 0.05)
    tilt_to_optical_xyz: Tuple[float, float, float] = (0.03, 0.0, 0.05)
    pan_limits_rad: Tuple[float, float] = field(default=EVI_D31_PAN_LIMITS_RAD)
    tilt_limits_rad: Tuple[float, float] = field(default=EVI_D31_TILT_LIMITS_RAD)
    mount_pitch_rad: float = 0.0

    def __post_init__(self):
        if not (math.isfinite(self.mount_pitch_rad) and abs(self.mount_pitch_rad) < math.pi / 2):
            raise ConfigError(f'head: mount_pitch_rad must be within +-90 deg, got '
                              f'{self.mount_pitch_rad!r}')
        object.__setattr__(self, 'mount_pitch_rad', float(self.mount_pitch_rad))
        for name in ('base_to_pan_xyz', 'pan_to_tilt_xyz', 'tilt_to_optical_xyz'):
            object.__setattr__(self, name, _xyz(getattr(self, name), name))
        for name in ('pan_limits_rad', 'tilt_limits_rad'):
            object.__setattr__(self, name, limit_pair(getattr(self, name), name))

    def T_base_pan(self, pan: float) -> Pose:
        """Return ``camera_pan_link`` in ``base_link``."""
        return Pose(_rot_z(pan), np.array(self.base_to_pan_xyz))

    def T_pan_tilt(self, tilt: float) -> Pose:
        """Return ``camera_tilt_link`` in ``camera_pan_link``."""
        return Pose(_rot_tilt(tilt + self.mount_pitch_rad), np.array(self.pan_to_tilt_xyz))

    def T_tilt_optical(self) -> Pose:
        """Return ``camera_optical_frame`` in ``camera_tilt_link`` (fixed)."""
        return Pose(R_TILT_OPTICAL.copy(), np.array(self.tilt_to_optical_xyz))

    def T_base_camera(self, pan: float, tilt: float) -> Pose:
        """Return ``camera_optical_frame`` in ``base_link`` at these joint angles."""
        return self.T_base_pan(pan) @ self.T_pan_tilt(tilt) @ self.T_tilt_optical()

    def camera_height(self, pan: float = 0.0, tilt: float = 0.0) -> float:
        """Return the z of the optical centre in ``base_link`` (metres)."""
        return float(self.T_base_camera(pan, tilt).t[2])

    def within_limits(self, pan: float, tilt: float, tolerance_rad: float = 0.0) -> bool:
        """Return whether both angles are inside the travel limits (+- tolerance)."""
        (p0, p1), (t0, t1) = self.pan_limits_rad, self.tilt_limits_rad
        return (p0 - tolerance_rad <= pan <= p1 + tolerance_rad
                and t0 - tolerance_rad <= tilt <= t1 + tolerance_rad)

    def clamp(self, pan: float, tilt: float) -> Tuple[float, float]:
        """Return the angles clipped to the travel limits."""
        (p0, p1), (t0, t1) = self.pan_limits_rad, self.tilt_limits_rad
        return min(max(pan, p0), p1), min(max(tilt, t0), t1)

    def aim_angles(self, target_in_base: Sequence[float]) -> Tuple[float, float]:
        """
        Return the (pan, tilt) that put a ``base_link`` point on the optical axis.

        Exact for these offsets (the optical centre is off both axes). The
        result is not clipped to the limits: see :meth:`clamp`. Raises
        ValueError when the point is too close to the head to be aimed at.
        """
        q = np.asarray(target_in_base, dtype=float).reshape(3) - self.base_to_pan_xyz
        # Lateral offset of the optical axis from the pan axis (tilt keeps y).
        lateral = self.pan_to_tilt_xyz[1] + self.tilt_to_optical_xyz[1]
        rho = math.hypot(q[0], q[1])
        if rho <= abs(lateral) + 1e-9:
            raise ValueError(f'target {list(target_in_base)} is too close to the pan axis')
        pan = math.atan2(q[1], q[0]) - math.asin(lateral / rho)
        in_pan = _rot_z(pan).T @ q - self.pan_to_tilt_xyz
        d, h = float(in_pan[0]), float(in_pan[2])
        # The optical axis passes at height b above the tilt axis (in the
        # tilt link): d sin(tilt) - h cos(tilt) = -b.
        b = self.tilt_to_optical_xyz[2]
        r = math.hypot(d, h)
        if r <= abs(b) + 1e-9:
            raise ValueError(f'target {list(target_in_base)} is too close to the tilt axis')
        tilt = math.atan2(h, d) - math.asin(b / r) - self.mount_pitch_rad
        wrap = 2.0 * math.pi
        return (pan + math.pi) % wrap - math.pi, (tilt + math.pi) % wrap - math.pi


def base_pose_from_camera(T_room_card: Pose, T_camera_card: Pose, head: HeadGeometry,
                          pan: float, tilt: float) -> Pose:
    """
    Return ``T_room_base``, the robot base in the card's parent frame.

    ``T_room_base = T_room_card @ T_camera_card^-1 @ T_base_camera(pan, tilt)^-1``.
    Pass ``T_building_card`` (= ``T_building_room @ T_room_card``) to get the
    base in the building frame instead.
    """
    T_room_camera = T_room_card @ T_camera_card.inverse()
    return T_room_camera @ head.T_base_camera(pan, tilt).inverse()


def up_in_camera(head: HeadGeometry, pan: float, tilt: float,
                 base_up: Sequence[float] = (0.0, 0.0, 1.0)) -> np.ndarray:
    """
    Return the world's up direction in ``camera_optical_frame`` (unit vector).

    ``base_up``: the world's up in ``base_link`` (``(0, 0, 1)`` for a level
    base; an IMU's gravity direction, negated, on a ramp). For an upright
    wall card (card +y = world up) this is what
    ``pose_exact.PosePrior.up_in_camera`` expects. At pan = tilt = 0 it is
    (0, -1, 0) (image up); tilting up by t gives (0, -cos t, sin t).
    """
    up = np.asarray(base_up, dtype=float).reshape(3)
    norm = float(np.linalg.norm(up))
    if not norm > 0.0:
        raise ValueError(f'base_up must be a non-zero vector, got {list(base_up)}')
    return head.T_base_camera(pan, tilt).R.T @ (up / norm)


def covariance_to_base(covariance: np.ndarray, T_room_card: Pose, T_camera_card: Pose,
                       head: HeadGeometry, pan: float, tilt: float,
                       angle_sigma_rad: Tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """
    Propagate the camera pose covariance to the base pose (first order).

    ``covariance``: 6x6 of the camera pose in the card frame, as
    ``pose_exact.PoseEstimate.covariance``: camera position (m), then a small
    rotation of the camera about the card frame's axes (rad). Returns the
    6x6 of :func:`base_pose_from_camera`'s result in the same form: base
    position in the room frame, small rotation about the room frame's axes
    (the form of geometry_msgs/PoseWithCovariance). ``angle_sigma_rad``:
    optional independent (pan, tilt) standard deviations (joint resolution,
    timing) added on top.
    """
    cov = np.asarray(covariance, dtype=float)
    if cov.shape != (6, 6):
        raise ValueError(f'covariance must be 6x6, got {cov.shape}')
    R_room_card = T_room_card.R
    T_card_camera = T_camera_card.inverse()
    T_camera_base = head.T_base_camera(pan, tilt).inverse()
    # Base = camera position + lever arm; turning the camera by dtheta (card
    # axes) swings the lever arm: d(base) = dc - [lever]x dtheta.
    lever = T_card_camera.R @ T_camera_base.t
    J = np.zeros((6, 6))
    J[:3, :3] = R_room_card
    J[:3, 3:] = -R_room_card @ skew(lever)
    J[3:, 3:] = R_room_card
    out = J @ cov @ J.T
    sigmas = np.asarray(angle_sigma_rad, dtype=float).reshape(2)
    if np.any(sigmas > 0.0):
        Ja = angle_jacobian(T_room_card, T_camera_card, head, pan, tilt)
        out = out + Ja @ np.diag(sigmas ** 2) @ Ja.T
    return 0.5 * (out + out.T)


def angle_jacobian(T_room_card: Pose, T_camera_card: Pose, head: HeadGeometry,
                   pan: float, tilt: float, step: float = 1e-6) -> np.ndarray:
    """Return d(base position, rotation about room axes)/d(pan, tilt) (central differences)."""
    J = np.zeros((6, 2))
    for k in range(2):
        d = (step, 0.0) if k == 0 else (0.0, step)
        plus = base_pose_from_camera(T_room_card, T_camera_card, head, pan + d[0], tilt + d[1])
        minus = base_pose_from_camera(T_room_card, T_camera_card, head, pan - d[0], tilt - d[1])
        J[:3, k] = (plus.t - minus.t) / (2.0 * step)
        # Small rotation: its vector is the antisymmetric part (arccos of the
        # trace would lose half the digits).
        dR = plus.R @ minus.R.T
        J[3:, k] = np.array([dR[2, 1] - dR[1, 2], dR[0, 2] - dR[2, 0],
                             dR[1, 0] - dR[0, 1]]) / (4.0 * step)
    return J


@dataclass(frozen=True)
class HeadMotion:
    """
    The head's angles at an image's stamp and how far to trust them.

    ``pan``, ``tilt``: what :meth:`JointStateBuffer.at` returns (rad).
    ``pan_rate``, ``tilt_rate``: the head's angular rates there (rad/s),
    from the bracketing samples (the last two when holding). ``rate_change``:
    how much the rates changed across the samples around the stamp (rad/s,
    pan and tilt): a head whose speed changed between two samples is not
    where a straight line between them puts it. ``interval_s``: the time
    between the bracketing samples. ``hold_s``: how long after the last
    sample the stamp lies (the angles are held that long; 0 when bracketed).
    """

    pan: float
    tilt: float
    pan_rate: float = 0.0
    tilt_rate: float = 0.0
    rate_change: Tuple[float, float] = (0.0, 0.0)
    interval_s: float = 0.0
    hold_s: float = 0.0

    @staticmethod
    def still(pan: float, tilt: float) -> 'HeadMotion':
        """Return the motion of a head standing at (pan, tilt) (fixed angles)."""
        return HeadMotion(float(pan), float(tilt))


class JointStateBuffer:
    """
    Recent (stamp_s, pan, tilt) samples; angles at an image's stamp by linear interpolation.

    ``history_s``: how far back samples are kept (relative to the newest).
    ``max_gap_s``: bracketing samples further apart than this are not
    interpolated. ``max_age_s``: an image up to this long after the last
    sample uses that sample (hold); later ones are "stale". Stamps are in
    seconds on the images' clock. Thread-safe (a joint_states callback may
    add while an image callback reads).
    """

    def __init__(self, history_s: float = 2.0, max_gap_s: float = 0.25,
                 max_age_s: float = 0.5, head: Optional['HeadGeometry'] = None,
                 margin_rad: float = JOINT_MARGIN_RAD):
        for name, value in (('history_s', history_s), ('max_gap_s', max_gap_s),
                            ('max_age_s', max_age_s)):
            if not (math.isfinite(value) and value > 0.0):
                raise ConfigError(f'joint state buffer: {name} must be > 0, got {value!r}')
        if not (math.isfinite(margin_rad) and margin_rad >= 0.0):
            raise ConfigError(f'joint state buffer: margin_rad must be >= 0, got '
                              f'{margin_rad!r}')
        self.head = head if head is not None else HeadGeometry()
        self.margin_rad = float(margin_rad)
        self.history_s = float(history_s)
        self.max_gap_s = float(max_gap_s)
        self.max_age_s = float(max_age_s)
        self._stamps: List[float] = []
        self._angles: List[Tuple[float, float]] = []
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return len(self._stamps)

    def clear(self) -> None:
        """Forget every sample (e.g. after the clock jumped back)."""
        with self._lock:
            self._stamps.clear()
            self._angles.clear()

    def latest(self) -> Optional[Tuple[float, float, float]]:
        """Return the newest sample as (stamp_s, pan, tilt), or None."""
        with self._lock:
            if not self._stamps:
                return None
            return (self._stamps[-1],) + self._angles[-1]

    def add(self, stamp_s: float, pan: float, tilt: float) -> None:
        """
        Insert a sample in stamp order (a sample with an existing stamp replaces it).

        HeadStateError, and nothing stored, for a value that is not finite or
        angles outside the head's travel plus ``margin_rad``.
        """
        try:
            stamp_s, pan, tilt = float(stamp_s), float(pan), float(tilt)
        except (TypeError, ValueError, OverflowError):
            raise HeadStateError('joint state values must be numbers') from None
        if not all(math.isfinite(v) for v in (stamp_s, pan, tilt)):
            raise HeadStateError(f'joint state not finite: stamp {stamp_s}, pan {pan}, '
                                 f'tilt {tilt}')
        check_travel(self.head, pan, tilt, self.margin_rad)
        with self._lock:
            i = bisect.bisect_left(self._stamps, stamp_s)
            if i < len(self._stamps) and self._stamps[i] == stamp_s:
                self._angles[i] = (pan, tilt)
            else:
                self._stamps.insert(i, stamp_s)
                self._angles.insert(i, (pan, tilt))
            # Keep the last sample at or before the cut too (when it is close
            # enough to interpolate from), so that any stamp within history_s
            # of the newest one stays bracketed.
            limit = self._stamps[-1] - self.history_s
            keep = bisect.bisect_right(self._stamps, limit) - 1
            if keep >= 0 and self._stamps[keep] < limit - self.max_gap_s:
                keep += 1
            if keep > 0:
                del self._stamps[:keep]
                del self._angles[:keep]

    def motion_at(self, stamp_s: float) -> HeadMotion:
        """
        Return the angles at ``stamp_s`` (as :meth:`at`) with the head's rates around it.

        HeadStateError when the angles are not known (as :meth:`at`).
        """
        pan, tilt = self.at(stamp_s)
        stamp_s = float(stamp_s)
        with self._lock:
            stamps, angles = list(self._stamps), list(self._angles)
        n = len(stamps)
        if n < 2:
            return HeadMotion(pan, tilt, hold_s=max(0.0, stamp_s - stamps[-1]))
        # i: the sample after the stamp (the last one when holding).
        i = min(max(bisect.bisect_right(stamps, stamp_s), 1), n - 1)

        def rate(k: int) -> Optional[np.ndarray]:
            """Return the rates over (k - 1, k), None outside the samples or across a gap."""
            if k < 1 or k >= n:
                return None
            dt = stamps[k] - stamps[k - 1]
            if not 0.0 < dt <= self.max_gap_s:
                return None
            return (np.asarray(angles[k]) - np.asarray(angles[k - 1])) / dt

        current = rate(i)
        if current is None:
            current = np.zeros(2)
        change = np.zeros(2)
        for other in (rate(i - 1), rate(i + 1)):
            if other is not None:
                change = np.maximum(change, np.abs(other - current))
        hold = max(0.0, stamp_s - stamps[-1])
        return HeadMotion(pan, tilt, float(current[0]), float(current[1]),
                          (float(change[0]), float(change[1])),
                          float(stamps[i] - stamps[i - 1]), hold)

    def at(self, stamp_s: float) -> Tuple[float, float]:
        """Return (pan, tilt) at ``stamp_s``; HeadStateError when they are not known."""
        stamp_s = float(stamp_s)
        with self._lock:
            stamps, angles = self._stamps, self._angles
            if not stamps:
                raise HeadStateError('no joint states received')
            last = stamps[-1]
            if stamp_s >= last:
                if stamp_s - last > self.max_age_s:
                    raise HeadStateError(
                        f'joint states stale: last at {last:.3f} s, image at {stamp_s:.3f} s '
                        f'({stamp_s - last:.3f} s later, max age {self.max_age_s:.3f} s)')
                return angles[-1]
            if stamp_s < stamps[0]:
                raise HeadStateError(
                    f'image at {stamp_s:.3f} s is older than the joint state history '
                    f'(oldest sample at {stamps[0]:.3f} s)')
            i = bisect.bisect_right(stamps, stamp_s)
            t0, t1 = stamps[i - 1], stamps[i]
            if t1 - t0 > self.max_gap_s:
                raise HeadStateError(
                    f'gap in joint states: no sample between {t0:.3f} s and {t1:.3f} s '
                    f'({t1 - t0:.3f} s, max gap {self.max_gap_s:.3f} s) around the image at '
                    f'{stamp_s:.3f} s')
            w = (stamp_s - t0) / (t1 - t0)
            (p0, a0), (p1, a1) = angles[i - 1], angles[i]
            return p0 + w * (p1 - p0), a0 + w * (a1 - a0)


def check_travel(head: HeadGeometry, pan: float, tilt: float,
                 margin_rad: float = JOINT_MARGIN_RAD) -> None:
    """Raise HeadStateError unless both angles are within the travel plus ``margin_rad``."""
    for joint, value, (low, high) in (('pan', pan, head.pan_limits_rad),
                                      ('tilt', tilt, head.tilt_limits_rad)):
        if not low - margin_rad <= value <= high + margin_rad:
            raise HeadStateError(
                f'{joint} {math.degrees(value):.6g} deg is outside the head travel '
                f'{math.degrees(low):.4g}..{math.degrees(high):.4g} deg (margin '
                f'{math.degrees(margin_rad):.3g} deg)')


def angles_from_joint_state(names: Sequence[str], positions: Sequence[float],
                            pan_joint: str = 'camera_pan', tilt_joint: str = 'camera_tilt',
                            head: Optional[HeadGeometry] = None,
                            margin_rad: float = JOINT_MARGIN_RAD) -> Tuple[float, float]:
    """
    Return (pan, tilt) from a JointState's names and positions (radians).

    HeadStateError, naming the problem in one line, when the message is not
    one to trust: names not unique (which one is meant?), a name that is not
    text, as many positions as names, a position that is not a finite
    number, a joint missing, angles outside ``head``'s travel (default: the
    EVI-D31's) plus ``margin_rad``.
    """
    try:
        names = list(names)
        positions = list(positions)
    except TypeError:
        raise HeadStateError('joint_states name and position must be sequences') from None
    if len(names) > MAX_JOINTS:
        raise HeadStateError(f'joint_states has {len(names)} names (more than {MAX_JOINTS})')
    if len(positions) != len(names):
        raise HeadStateError(f'joint_states has {len(names)} names but {len(positions)} '
                             'positions')
    if not all(isinstance(name, str) for name in names):
        raise HeadStateError('joint_states names must be text')
    index = {}
    for i, name in enumerate(names):
        if name in index:
            raise HeadStateError(f'joint_states names {_quote(name)} twice (positions '
                                 f'{index[name]} and {i}): which one is meant is unknown')
        index[name] = i
    result = []
    for joint in (pan_joint, tilt_joint):
        if joint not in index:
            shown = _quote(', '.join(names))
            raise HeadStateError(f'joint {joint!r} missing from joint_states (names: {shown})')
        value = positions[index[joint]]
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            raise HeadStateError(f'joint {joint!r} position is not a number '
                                 f'({type(value).__name__})')
        value = float(value)
        if not math.isfinite(value):
            raise HeadStateError(f'joint {joint!r} position is not a number ({value})')
        result.append(value)
    check_travel(head if head is not None else HeadGeometry(), result[0], result[1],
                 margin_rad)
    return result[0], result[1]


def _quote(text: str) -> str:
    """Return foreign text quoted and cut to ~80 characters for a log line."""
    shown = repr(text)
    return shown if len(shown) <= 80 else shown[:77] + '...'


def head_angles(stamp_s: float, buffer: Optional[JointStateBuffer],
                fixed_angles: Tuple[float, float]) -> Tuple[float, float]:
    """
    Return the head's (pan, tilt) for an image.

    With a joint_states topic configured (``buffer`` given) the angles come
    from it or a HeadStateError says why not: the fixed angles are never a
    silent fallback. Without one, the configured ``fixed_angles``.
    """
    if buffer is None:
        return float(fixed_angles[0]), float(fixed_angles[1])
    return buffer.at(stamp_s)
