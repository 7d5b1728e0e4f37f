"""
Plausibility gates on the robot's pose: a wrong location is worse than none.

A fix from one card passes the **static gates** (:meth:`FixGates.check`)
only if: its pose and covariance are finite and the covariance is positive
definite and not huge; the camera is in front of the card, at a plausible
distance and angle; the base is on the floor of its room (height, roll and
pitch within bounds) and inside the room's footprint from the building map
(plus a margin) or, with ``footprint='adjacent'`` (a robot driving through
the building sees cards through doors), in a room next to it; inside the
building when the room has no size. The
**continuity gate** (:meth:`FixGates.check_continuity`) compares the fix
with the last one returned: a jump beyond what the robot's motion allows
(its odometry when given, else a maximum speed and yaw rate), by
Mahalanobis distance, is held back until a second image agrees with it.
Every rejection is counted by reason (:data:`REASONS`).

Besides bad input, these gates are what stops the mirror image of a card
printed without a handedness mark: it decodes, and gives a pose that is
plausible on its own (the camera mirrored about the card's normal), but
not continuous with where the robot was.

Frames: the building frame is z up (gravity along -z), as the building
map's; each room's z is up from its floor, and its ``size`` is the box from
its origin along +x, +y, +z (building.yaml). Covariances are 6x6: position
(m), then a small rotation about the frame's axes (rad), as
``RobotFix.covariance``.
"""

from dataclasses import dataclass, fields
import math
from typing import Dict, NamedTuple, Optional, Tuple

import numpy as np

from .building import BuildingMap, Room
from .footprints import footprints, neighbours
from ..errors import ConfigError
from ..vision.geometry import Pose, rotation_vector, skew

# Reasons a fix is not returned (diagnostics keys: ``rejected_<reason>``).
REASONS = (
    'not_finite',                # NaN or inf in the pose or the covariance
    'covariance',                # covariance not symmetric positive definite, or too large
    'camera_behind_card',        # the camera is not in front of the card
    'camera_distance',           # camera too close to or too far from the card
    'view_angle',                # seen too obliquely to be true
    'base_height',               # base not at the floor's height
    'roll_pitch',                # base tipped more than a ground robot can be
    'outside_footprint',         # base outside its room (plus margin) or the building
    'jump',                      # not continuous with the last fix: held until confirmed
    'unconfirmed_first',         # the first fix (or the first after a reset): held likewise
    'partial_code',              # a card partly hidden, its code completed from the map
                                 # (or one of several codes that fit), not where the last
                                 # fix puts the robot, or no last fix to choose by
    'planar_flip',               # the card's other planar pose fits nearly as well and
                                 # neither a gate nor the last fix rules it out
)
FOOTPRINTS = ('room', 'adjacent', 'building', 'off')
# The flip gate's default (GateParameters.max_flip_probability), which the
# command line, the survey and the benchmark also judge poses by.
MAX_FLIP_PROBABILITY = 0.001
# A close planar flip whose fit rises less than this (PoseEstimate.flip_barrier,
# noise units as other_probability counts them, about half a chi-square) on
# the way to the other pose lies in one valley: no fix, whatever decided the
# side. Synthetic views, 0.08 px of noise: 2-5 deg off face on at 2.5-6 m the
# median barrier was 0-8 and up to 62 % of the poses more than 4 sigmas off;
# 10-15 deg off at 4-6 m it was 9 or more in 88-100 % of the unsure draws
# (two poses). With the side decided by up and height (card 1 m above the
# camera, 6-8 m away), 17 of the 19 poses more than 4 sigmas off of 200 lay
# in the valley.
FLIP_VALLEY_BARRIER = 9.0
# Rooms next to each other (footprint mode 'adjacent') run side by side this far at least.
ADJACENT_MIN_LENGTH_M = 0.5


def flip_unsure(other_probability: float, flip_barrier: float) -> bool:
    """
    Tell whether a pose's planar flip is unsure with no last fix to go by.

    The other pose more likely than the flip gate's default, or the two in
    one shallow valley of the fit: the poses the survey and the benchmark
    count unsure (the localizer's gate also weighs its last fix).
    """
    return other_probability > MAX_FLIP_PROBABILITY or not flip_barrier >= FLIP_VALLEY_BARRIER


@dataclass(frozen=True)
class GateParameters:
    """
    The gates' thresholds; the defaults suit a ground robot indoors.

    Each field is meant to be a ROS parameter of the locator node under the
    same name, prefixed ``gates.``.
    """

    # Covariance: the largest position standard deviation a fix may have.
    max_position_sigma_m: float = 1.0
    # The camera in front of the card: distance and angle off the card's normal.
    # Beyond 75 deg the detector's dot centres are biased well beyond their
    # noise (errors of 10-27 cm at 6 m, 2-4 times the covariance's, measured
    # by bench --drive-core); a card so oblique is not trusted.
    min_camera_distance_m: float = 0.3
    max_camera_distance_m: float = 20.0
    max_view_angle_deg: float = 75.0
    # The base on its room's floor (room frame z), not tipped over.
    min_base_height_m: float = -0.5
    max_base_height_m: float = 0.5
    max_roll_deg: float = 10.0
    max_pitch_deg: float = 10.0
    # 'room': inside the card's room (its size in the map) plus the margin,
    # or inside the building's box when the room has no size; 'adjacent':
    # the card's room or a room next to it (their footprints within
    # adjacent_gap_m along at least 0.5 m: a card seen through a door), for
    # a robot driving through the building; 'building': inside the box of
    # every sized room; 'off'.
    footprint: str = 'adjacent'
    footprint_margin_m: float = 0.5
    # Judge each fix against the last one (off: every image stands alone, as
    # for unrelated still images; the static gates still apply).
    continuity: bool = True
    adjacent_gap_m: float = 0.5
    # Continuity, without odometry: how fast the base can move and turn.
    max_speed_m_s: float = 1.0
    max_yaw_rate_deg_s: float = 90.0
    # A jump beyond this Mahalanobis distance from the last fix is held back.
    max_jump_mahalanobis: float = 5.0
    # Standard deviations added to both fixes' before comparing them (an
    # estimator's covariance can be overconfident).
    jump_sigma_floor_m: float = 0.05
    jump_sigma_floor_deg: float = 2.0
    # A held-back fix is returned when an image at most this much later agrees.
    confirm_within_s: float = 2.0
    # Hold back the first fix too, until a second image agrees with it.
    confirm_first_fix: bool = True
    # A stamp this much older than the last fix's means the clock jumped back
    # (a bag replayed again): continuity starts over.
    clock_jump_back_s: float = 1.0
    # A partly hidden card's code comes from the map only within this long of
    # the last fix: the jump test lets the base go max_speed_m_s times the
    # time since, and a card missing from the map that reads as a mapped one
    # hanging elsewhere must not fall within that.
    partial_code_max_age_s: float = 1.0
    # The planar flip: a card seen far away and nearly face on fits its dots
    # almost as well turned the other way about an axis in its plane. When
    # the other pose is more likely than this (the estimator's
    # other_probability, from the residuals, up and height), a static gate
    # or the last fix (its jump test's distances as likelihoods: they grow
    # alike as the last fix ages, with odometry's covariance or the speed
    # limits) must bring it below, or the card gives no fix. When the two lie
    # in one shallow valley of the fit (FLIP_VALLEY_BARRIER) there is no fix
    # at all, however sure the side.
    max_flip_probability: float = MAX_FLIP_PROBABILITY

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name == 'footprint':
                if value not in FOOTPRINTS:
                    raise ConfigError(f'gates: footprint must be one of '
                                      f'{", ".join(FOOTPRINTS)}, got {value!r}')
            elif f.name in ('confirm_first_fix', 'continuity'):
                if not isinstance(value, bool):
                    raise ConfigError(f'gates: {f.name} must be true or false, got '
                                      f'{value!r}')
            elif (isinstance(value, bool) or not isinstance(value, (int, float))
                  or not math.isfinite(value)):
                raise ConfigError(f'gates: {f.name} must be a finite number, got {value!r}')
            elif value < 0.0 and f.name != 'min_base_height_m':
                raise ConfigError(f'gates: {f.name} must be >= 0, got {value!r}')
        if self.min_camera_distance_m >= self.max_camera_distance_m:
            raise ConfigError('gates: min_camera_distance_m must be below '
                              'max_camera_distance_m')
        if self.min_base_height_m >= self.max_base_height_m:
            raise ConfigError('gates: min_base_height_m must be below max_base_height_m')
        if self.max_flip_probability > 0.5:
            raise ConfigError('gates: max_flip_probability must be at most 0.5 (the chosen '
                              f'pose is the likelier one), got {self.max_flip_probability!r}')


@dataclass(frozen=True, eq=False)
class BaseMotion:
    """
    The base's motion from odometry since a stamp (the last fix's), with its covariance.

    ``T_start_end``: the base at the image's time in the base frame at
    ``since_stamp_s``. ``covariance``: 6x6 of that motion, translation (m)
    then rotation (rad), in the start base frame.
    """

    since_stamp_s: float
    T_start_end: Pose
    covariance: np.ndarray


class Rejection(NamedTuple):
    """Why a fix was not returned: a reason of :data:`REASONS` and one line of detail."""

    reason: str
    message: str


def pose_in_building(T_frame_base: Pose, covariance: np.ndarray, frame_id: str,
                     building: BuildingMap) -> Tuple[Pose, np.ndarray, Optional[Room]]:
    """Return a fix's pose and covariance in the building frame, and its room (if any)."""
    if frame_id == building.frame:
        return T_frame_base, covariance, None
    room = building.room_by_frame(frame_id)
    R = room.T_building_room.R
    J = np.zeros((6, 6))
    J[:3, :3] = R
    J[3:, 3:] = R
    return room.T_building_room @ T_frame_base, J @ covariance @ J.T, room


def _roll_pitch(R: np.ndarray) -> Tuple[float, float]:
    """Return (roll, pitch) in radians of a rotation whose frame has z up (ZYX Euler)."""
    return (math.atan2(R[2, 1], R[2, 2]),
            math.asin(float(np.clip(-R[2, 0], -1.0, 1.0))))


class _Fix(NamedTuple):
    stamp: float
    T: Pose                     # base in the building frame
    covariance: np.ndarray      # in the building frame


class FixGates:
    """
    The gates of one locator: static checks per fix, continuity over time, counts.

    Not thread-safe: one thread processes the images (the locator's worker);
    :meth:`counts` returns a copy, safe to read from another thread.
    """

    def __init__(self, building: BuildingMap,
                 parameters: Optional[GateParameters] = None) -> None:
        self.building = building
        self.parameters = parameters if parameters is not None else GateParameters()
        self._counts: Dict[str, int] = dict.fromkeys(REASONS, 0)
        self._accepted: Optional[_Fix] = None
        self._pending: Optional[_Fix] = None
        self._building_box = self._box_of_rooms()
        self._footprints = footprints(building)
        self._adjacent = neighbours(self._footprints, self.parameters.adjacent_gap_m,
                                    ADJACENT_MIN_LENGTH_M)

    # Counts and state -------------------------------------------------------------

    def counts(self) -> Dict[str, int]:
        """Return the number of rejections so far, by reason (every reason listed)."""
        return dict(self._counts)

    def count(self, rejection: Rejection) -> Rejection:
        """Count a rejection; return it."""
        self._counts[rejection.reason] += 1
        return rejection

    def reset(self) -> None:
        """Forget the last fix and any held-back one (continuity starts over)."""
        self._accepted = None
        self._pending = None

    @property
    def last_stamp(self) -> Optional[float]:
        """Return the stamp of the last fix returned (what odometry is measured from)."""
        return None if self._accepted is None else self._accepted.stamp

    # Static gates ----------------------------------------------------------------

    def check(self, T_frame_base: Pose, covariance: Optional[np.ndarray], frame_id: str,
              room: Optional[Room] = None, T_camera_card: Optional[Pose] = None,
              counted: bool = True) -> Optional[Rejection]:
        """
        Return why a fix fails a static gate (counted), or None if it passes them all.

        ``T_frame_base`` and ``covariance`` in the frame ``frame_id`` (a room's
        or the building's); ``room``: the room the base should be in (the
        card's; default: the room of ``frame_id``); ``T_camera_card``: the
        card in the camera frame, when the fix comes from one card.
        ``counted=False``: a hypothesis tried, not a fix refused; not counted.
        """
        rejection = self._static(T_frame_base, covariance, frame_id, room, T_camera_card)
        if rejection is not None and counted:
            self.count(rejection)
        return rejection

    def _static(self, T_frame_base: Pose, covariance: Optional[np.ndarray], frame_id: str,
                room: Optional[Room], T_camera_card: Optional[Pose]) -> Optional[Rejection]:
        p = self.parameters
        arrays = [T_frame_base.R, T_frame_base.t]
        if T_camera_card is not None:
            arrays += [T_camera_card.R, T_camera_card.t]
        if covariance is None or np.shape(covariance) != (6, 6):
            return Rejection('covariance', 'no 6x6 covariance')
        if not all(np.all(np.isfinite(a)) for a in arrays + [covariance]):
            return Rejection('not_finite', 'pose or covariance not finite')
        rejection = _check_covariance(covariance, p.max_position_sigma_m)
        if rejection is not None:
            return rejection
        if T_camera_card is not None:
            rejection = self._check_camera(T_camera_card)
            if rejection is not None:
                return rejection
        T_building_base, _, frame_room = pose_in_building(T_frame_base, covariance, frame_id,
                                                          self.building)
        room = room if room is not None else frame_room
        roll, pitch = _roll_pitch(T_building_base.R)
        if abs(roll) > math.radians(p.max_roll_deg) or abs(pitch) > math.radians(
                p.max_pitch_deg):
            return Rejection('roll_pitch', f'base rolled {math.degrees(roll):.1f} deg, pitched '
                             f'{math.degrees(pitch):.1f} deg (limits {p.max_roll_deg:g}, '
                             f'{p.max_pitch_deg:g} deg)')
        if room is not None:
            height = float((room.T_building_room.inverse() @ T_building_base).t[2])
            if not p.min_base_height_m <= height <= p.max_base_height_m:
                return Rejection('base_height', f'base {height:.2f} m above the floor of '
                                 f'{room.frame} (limits {p.min_base_height_m:g}..'
                                 f'{p.max_base_height_m:g} m)')
        return self._check_footprint(T_building_base, room)

    def _check_camera(self, T_camera_card: Pose) -> Optional[Rejection]:
        p = self.parameters
        camera = T_camera_card.inverse().t          # the camera in the card frame
        distance = float(np.linalg.norm(camera))
        if camera[2] <= 0.0 or T_camera_card.t[2] <= 0.0:
            return Rejection('camera_behind_card', f'the camera would be behind the card '
                             f'(or the card behind the camera): {distance:.2f} m away')
        if not p.min_camera_distance_m <= distance <= p.max_camera_distance_m:
            return Rejection('camera_distance', f'the camera would be {distance:.3g} m from '
                             f'the card (limits {p.min_camera_distance_m:g}..'
                             f'{p.max_camera_distance_m:g} m)')
        angle = math.degrees(math.acos(min(1.0, camera[2] / distance)))
        if angle > p.max_view_angle_deg:
            return Rejection('view_angle', f'the card would be seen {angle:.1f} deg off its '
                             f'normal (limit {p.max_view_angle_deg:g} deg)')
        return None

    def _check_footprint(self, T_building_base: Pose, room: Optional[Room]
                         ) -> Optional[Rejection]:
        p = self.parameters
        if p.footprint == 'off':
            return None
        if p.footprint in ('room', 'adjacent') and room is not None and room.size is not None:
            x, y = (room.T_building_room.inverse().apply(T_building_base.t[None])[0, :2])
            length, width = room.size[0], room.size[1]
            m = p.footprint_margin_m
            if -m <= x <= length + m and -m <= y <= width + m:
                return None
            if p.footprint == 'adjacent':
                xy = T_building_base.t[None, :2]
                for key in self._adjacent.get((room.floor, room.room), ()):
                    other = self._footprints[key]
                    if other.on_floor(float(T_building_base.t[2])) and other.contains(xy)[0]:
                        return None
            where = ' or a room next to it' if p.footprint == 'adjacent' else ''
            return Rejection('outside_footprint', f'base at ({x:.2f}, {y:.2f}) m is outside '
                             f'{room.frame} ({length:g} x {width:g} m, margin {m:g} m){where}')
        if self._building_box is None:
            return None                   # no room has a size: nothing to check against
        low, high = self._building_box
        m = p.footprint_margin_m
        x, y, z = T_building_base.t
        if np.all(low - m <= [x, y, z]) and np.all([x, y, z] <= high + m):
            return None
        return Rejection('outside_footprint', f'base at ({x:.2f}, {y:.2f}, {z:.2f}) m is '
                         f'outside the building (margin {m:g} m)')

    def _box_of_rooms(self) -> Optional[Tuple[np.ndarray, np.ndarray]]:
        """Return the building-frame box around every sized room (None if none is)."""
        corners = []
        for room in self.building.rooms.values():
            if room.size is None:
                continue
            box = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)],
                           dtype=float) * np.asarray(room.size, dtype=float)
            corners.append(room.T_building_room.apply(box))
        if not corners:
            return None
        points = np.vstack(corners)
        return points.min(axis=0), points.max(axis=0)

    # Continuity ---------------------------------------------------------------------

    def check_continuity(self, T_frame_base: Pose, covariance: np.ndarray, frame_id: str,
                         stamp_s: Optional[float], odometry: Optional[BaseMotion] = None
                         ) -> Optional[Rejection]:
        """
        Return why a fix is held back (counted), or None to return it (it becomes the last).

        Without a stamp, or with ``continuity`` off, continuity is not
        judged: the fix passes and nothing is remembered. ``odometry``: the base's motion since
        :attr:`last_stamp`; it is used when its ``since_stamp_s`` is that
        stamp (within 1 ms), else the maximum speed and yaw rate are.
        """
        p = self.parameters
        fix = self._judged(T_frame_base, covariance, frame_id, stamp_s)
        if fix is None:
            return None
        last = self._accepted
        if last is not None and fix.stamp < last.stamp - p.clock_jump_back_s:
            self.reset()
            last = None
        if last is None:
            if not p.confirm_first_fix or self._confirms(fix):
                return self._accept(fix)
            self._pending = fix
            return self.count(Rejection('unconfirmed_first', 'first fix: held back until a '
                                        'second image agrees with it'))
        distance = self._distance(last, fix, odometry)
        if distance <= p.max_jump_mahalanobis or self._confirms(fix):
            return self._accept(fix)
        self._pending = fix
        jump = float(np.linalg.norm(fix.T.t - last.T.t))
        return self.count(Rejection(
            'jump', f'{jump:.2f} m from the last fix {fix.stamp - last.stamp:.2f} s ago '
            f'(Mahalanobis {distance:.3g} > {p.max_jump_mahalanobis:g}): held back until a '
            f'second image agrees'))

    def check_partial(self, T_frame_base: Pose, covariance: np.ndarray, frame_id: str,
                      stamp_s: Optional[float], odometry: Optional[BaseMotion] = None,
                      label: str = 'card') -> Optional[Rejection]:
        """
        Return why a fix from a card whose code was completed from the map is refused, or None.

        Such a code is only as sure as the map is complete (a card missing
        from the map, partly hidden, can read as a mapped one), so it is
        taken only as a check of where the robot already is: there must be
        a last fix and this one must be continuous with it (the jump test,
        without the second-image confirmation). It never starts or restarts
        the location.
        """
        distance = self.distance_from_last(T_frame_base, covariance, frame_id, stamp_s,
                                           odometry)
        if distance is None:
            return self.count(Rejection(
                'partial_code', f'{label}: code partly hidden and completed from the map; '
                'taken only to follow a robot located in the last '
                f'{self.parameters.partial_code_max_age_s:g} s'))
        if distance > self.parameters.max_jump_mahalanobis:
            return self.count(Rejection(
                'partial_code', f'{label}: code partly hidden and completed from the map, '
                f'{distance:.3g} (Mahalanobis) from where the last fix puts the robot'))
        return None

    def distance_from_last(self, T_frame_base: Pose, covariance: np.ndarray, frame_id: str,
                           stamp_s: Optional[float], odometry: Optional[BaseMotion] = None,
                           max_age_s: Optional[float] = None) -> Optional[float]:
        """
        Return how far (Mahalanobis) a fix is from where the last fix puts the robot.

        None when that cannot be judged (no last fix, no stamp, the
        continuity gate off) or the last fix is more than ``max_age_s``
        older (default ``partial_code_max_age_s``, for a partly hidden
        card's code). Nothing is counted or remembered.
        """
        fix = self._judged(T_frame_base, covariance, frame_id, stamp_s)
        last = self._accepted
        age = self.parameters.partial_code_max_age_s if max_age_s is None else max_age_s
        if fix is None or last is None or not fix.stamp - last.stamp <= age:
            return None
        return self._distance(last, fix, odometry)

    def _judged(self, T_frame_base: Pose, covariance: np.ndarray, frame_id: str,
                stamp_s: Optional[float]) -> Optional[_Fix]:
        """Return a fix in the building frame for the continuity tests, or None if not judged."""
        if not self.parameters.continuity or stamp_s is None or not math.isfinite(stamp_s):
            return None
        T, cov, _ = pose_in_building(T_frame_base, covariance, frame_id, self.building)
        return _Fix(float(stamp_s), T, cov)

    def _accept(self, fix: _Fix) -> None:
        self._accepted = fix
        self._pending = None
        return None

    def _confirms(self, fix: _Fix) -> bool:
        """Return whether ``fix`` agrees with the held-back fix (which it then confirms)."""
        pending = self._pending
        if pending is None or abs(fix.stamp - pending.stamp) > self.parameters.confirm_within_s:
            return False
        return self._distance(pending, fix, None) <= self.parameters.max_jump_mahalanobis

    def _distance(self, before: _Fix, after: _Fix, odometry: Optional[BaseMotion]) -> float:
        """Return the Mahalanobis distance of ``after`` from where ``before`` allows it."""
        p = self.parameters
        floor = np.diag([p.jump_sigma_floor_m ** 2] * 3
                        + [math.radians(p.jump_sigma_floor_deg) ** 2] * 3)
        if odometry is not None and abs(odometry.since_stamp_s - before.stamp) <= 1e-3:
            predicted, predicted_cov = _predict(before, odometry)
            delta = _difference(predicted, after.T)
        else:
            predicted_cov = before.covariance
            delta = _difference(before.T, after.T)
            dt = abs(after.stamp - before.stamp)
            delta[:3] = _shrink(delta[:3], p.max_speed_m_s * dt)
            # Turning in place: the yaw rate allows a rotation about the vertical.
            delta[5:] = _shrink(delta[5:], math.radians(p.max_yaw_rate_deg_s) * dt)
        total = predicted_cov + after.covariance + floor
        try:
            d2 = float(delta @ np.linalg.solve(total, delta))
        except np.linalg.LinAlgError:
            return math.inf
        return math.sqrt(d2) if d2 >= 0.0 and math.isfinite(d2) else math.inf


def _check_covariance(covariance: np.ndarray, max_sigma_m: float) -> Optional[Rejection]:
    scale = float(np.max(np.abs(covariance)))
    if scale == 0.0 or np.max(np.abs(covariance - covariance.T)) > 1e-9 * scale:
        return Rejection('covariance', 'covariance not symmetric positive definite')
    try:
        np.linalg.cholesky(covariance)
    except np.linalg.LinAlgError:
        return Rejection('covariance', 'covariance not positive definite')
    sigma = math.sqrt(float(np.max(np.linalg.eigvalsh(covariance[:3, :3]))))
    if sigma > max_sigma_m:
        return Rejection('covariance', f'position uncertain by {sigma:.3g} m (limit '
                         f'{max_sigma_m:g} m)')
    return None


def _difference(a: Pose, b: Pose) -> np.ndarray:
    """Return b - a: position difference, then the rotation taking a to b (frame axes)."""
    return np.concatenate([b.t - a.t, rotation_vector(b.R @ a.R.T)])


def _shrink(vector: np.ndarray, allowance: float) -> np.ndarray:
    """Return ``vector`` shortened by ``allowance`` (not past zero): motion the robot can do."""
    norm = float(np.linalg.norm(vector))
    if norm <= allowance:
        return np.zeros_like(vector)
    return vector * (1.0 - allowance / norm)


def compose_with_motion(T_frame_start: Pose, covariance: np.ndarray, motion: Pose,
                        motion_covariance: np.ndarray) -> Tuple[Pose, np.ndarray]:
    """
    Return ``T_frame_start @ motion`` and its covariance (first order).

    ``covariance``: 6x6 of ``T_frame_start`` (position, then a small
    rotation about the frame's axes); ``motion_covariance``: 6x6 of the
    motion in the start base frame (translation, then rotation about the
    start base's axes), as :class:`BaseMotion` gives it. The two are taken
    as independent: a pose and the odometry measured after it.
    """
    predicted = T_frame_start @ motion
    R = T_frame_start.R
    # The start's rotation error swings the motion's translation.
    J_start = np.eye(6)
    J_start[:3, 3:] = -skew(R @ motion.t)
    J_motion = np.zeros((6, 6))
    J_motion[:3, :3] = R
    J_motion[3:, 3:] = R
    cov = (J_start @ np.asarray(covariance, dtype=float) @ J_start.T
           + J_motion @ np.asarray(motion_covariance, dtype=float) @ J_motion.T)
    return predicted, 0.5 * (cov + cov.T)


def _predict(before: _Fix, odometry: BaseMotion) -> Tuple[Pose, np.ndarray]:
    """Return the pose odometry predicts from ``before`` and its covariance (first order)."""
    return compose_with_motion(before.T, before.covariance, odometry.T_start_end,
                               odometry.covariance)
