"""
Map-guided gaze: which card the head should look at next, and how to keep it in view.

ROS-free. From the building map and the robot's pose (the last fix carried
forward by odometry, ``odom.OdomBridge``), :meth:`GazePlanner.choose`
picks the card that will give the best next fix and the head angles that
aim at it (``HeadGeometry.aim_angles``), or None when no card is
predicted visible (the driver then searches).

A card is **predicted visible** when

* the camera is in front of it, within ``min_distance_m`` ..
  ``max_distance_m`` of it and at most ``max_view_angle_deg`` off its
  normal;
* the head can aim at it (pan and tilt inside the travel, less a margin);
* the line of sight stays in one **space**: the map has no walls, so the
  planner is conservative. The robot is in the rooms whose footprint holds
  it (or, in a doorway between footprints, those within
  ``doorway_margin_m``). Rooms whose footprints touch along at least
  ``min_opening_m`` (within ``touch_m``: the corridors of a loop) are one
  space, and rooms a wall's thickness apart are not. A card is a
  candidate only if its room is in the robot's space and the straight
  lines from the camera to the card's centre and side edges stay inside
  that space's footprints with ``sight_clearance_m`` to spare (so that a
  wall's corner is not grazed; the first ``doorway_m`` of them, where the
  robot stands, excepted). Rooms without a size are never predicted visible, except
  the room of ``room_hint`` (the last fix's).

Among the candidates the best has the lowest **score**: its distance
(a fix's error grows with it) times a penalty for obliquity
(``1 + view_weight (1 / cos(view) - 1)``), plus ``slew_weight_m_per_rad``
per radian the head must turn to it; a card to turn to (new, handover,
better) that is predicted gone ``stay_horizon_s`` ahead costs
``leave_weight_m`` more: each handover is a blind slew, so the head takes
the card it can keep. **Handover**: the current card is
kept while it stays predicted visible ``lookahead_s`` ahead (the base's
twist carried forward) and no other card scores better than
``switch_ratio`` times its score; when it is about to leave the view the
best card visible both now and then takes over, before it leaves. A card
is taken (new, handover, better) only if it is still predicted visible
when the head has turned to it at ``slew_rate_deg_s`` and ``min_dwell_s``
after: leaving a room, a card on the far wall 180 degrees round is gone by
the time a 2.3 s slew gets there.
**Ahead**: when no card is predicted visible now but one is from the pose
``lookahead_s`` ahead (the robot about to pass a door or a corner), the
head aims at that card now, from where the robot is, so that it is centred
when it comes into sight instead of searched for after.

:func:`feed_forward_rates` gives the head rates that cancel the base's
motion for a target fixed in the world: what the tracking controller adds
to its feedback so that a turning base does not drag the card out of view.
"""

from dataclasses import dataclass, fields
import math
from typing import Collection, Dict, List, Optional, Sequence, Tuple

import numpy as np

from .building import BuildingMap, MappedCard
from .footprints import components, Footprint, footprints, neighbours
from .head import HeadGeometry
from .odom import BaseTwist
from ..card.pattern import Ids
from ..errors import ConfigError
from ..vision.geometry import Pose, rodrigues

IdsKey = Tuple[int, int, int]
# Poses ahead at which a slewed-to card must still be in sight: on this grid (s).
LASTS_STEP_S = 0.25
REASONS = ('new', 'keep', 'better', 'handover', 'ahead')


@dataclass(frozen=True)
class GazeParameters:
    """The planner's limits and weights (module docstring); defaults for the EVI-D31."""

    min_distance_m: float = 1.0
    max_distance_m: float = 8.0
    max_view_angle_deg: float = 65.0
    pan_margin_deg: float = 2.0
    tilt_margin_deg: float = 0.5
    doorway_margin_m: float = 0.35
    doorway_m: float = 0.4
    touch_m: float = 0.05
    min_opening_m: float = 0.5
    sight_step_m: float = 0.05
    sight_clearance_m: float = 0.1
    card_half_width_m: float = 0.15
    lookahead_s: float = 1.5
    switch_ratio: float = 0.7
    view_weight: float = 1.0
    # A slew is blind (the card smeared beyond reading) for about its angle
    # over 80 deg/s: 3 m/rad found 0.2-0.7 points of fix coverage more than
    # 1 on the loop route (bench --drive-core, target driver, seeds 1-2); with
    # the fast slews and the leave cost, 5 m/rad 1.0 and 0.1 points more
    # than 3 (8: 1.5 and -0.2).
    slew_weight_m_per_rad: float = 5.0
    # A card is worth turning to only if it is still in sight when the head
    # gets there (at this pan speed, the EVI-D31's fastest) and this long after.
    slew_rate_deg_s: float = 80.0
    min_dwell_s: float = 0.5
    # Every handover is blind for a slew: among the cards to turn to, one
    # predicted gone ``stay_horizon_s`` ahead (the twist carried forward)
    # costs this much more, so the head takes the card it can keep.
    stay_horizon_s: float = 4.0
    leave_weight_m: float = 2.0

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not (
                    math.isfinite(value) and value >= 0.0):
                raise ConfigError(f'gaze: {f.name} must be a number >= 0, got {value!r}')
        if self.min_distance_m >= self.max_distance_m:
            raise ConfigError('gaze: min_distance_m must be below max_distance_m')
        if not 0.0 < self.max_view_angle_deg < 90.0:
            raise ConfigError('gaze: max_view_angle_deg must be within 0..90')
        if self.sight_step_m <= 0.0 or not 0.0 < self.switch_ratio <= 1.0:
            raise ConfigError('gaze: sight_step_m must be > 0 and switch_ratio within 0..1')


@dataclass(frozen=True)
class CardOption:
    """A card predicted visible from a pose: where the head must aim and how good it is."""

    ids: Ids
    pan: float
    tilt: float
    distance_m: float
    view_angle_deg: float
    score: float


@dataclass(frozen=True)
class GazeChoice:
    """
    The card to look at: its option, why (:data:`REASONS`), and whether it stays in view.

    ``reason``: ``new`` (no current card, or it was not visible), ``keep``,
    ``better`` (another card scores much better), ``handover`` (the
    current card leaves the view within the lookahead) or ``ahead`` (none
    is visible now; this one will be, from the pose the lookahead gives:
    aimed at from here). ``visible_ahead``:
    the chosen card is predicted visible ``lookahead_s`` ahead too.
    """

    option: CardOption
    reason: str
    visible_ahead: bool

    @property
    def ids(self) -> Ids:
        """Return the chosen card's ids."""
        return self.option.ids

    @property
    def pan(self) -> float:
        """Return the head's pan angle that aims at the card, in radians."""
        return self.option.pan

    @property
    def tilt(self) -> float:
        """Return the head's tilt angle that aims at the card, in radians."""
        return self.option.tilt


class GazePlanner:
    """
    Choose the card the head should look at (module docstring).

    ``building``: the map (its rooms' sizes are the footprints);
    ``head``: the head's geometry and travel. Not thread-safe; cheap
    enough to call at a driver's control rate (tens of cards).
    """

    def __init__(self, building: BuildingMap, head: Optional[HeadGeometry] = None,
                 parameters: Optional[GazeParameters] = None) -> None:
        self.building = building
        self.head = head if head is not None else HeadGeometry()
        self.parameters = parameters if parameters is not None else GazeParameters()
        self._cards: List[MappedCard] = building.cards()
        self._centres = np.array([c.T_building_card.t for c in self._cards]).reshape(-1, 3)
        self._normals = np.array([c.T_building_card.R[:, 2] for c in self._cards]
                                 ).reshape(-1, 3)
        self._footprints: Dict[Tuple[int, int], Footprint] = footprints(building)
        angles = np.linspace(0.0, 2.0 * math.pi, 8, endpoint=False)
        # A sample and the ring of points round it that must be inside too.
        self._ring = np.vstack([np.zeros((1, 2)), self.parameters.sight_clearance_m
                                * np.column_stack([np.cos(angles), np.sin(angles)])])
        p = self.parameters
        self._space = components(neighbours(self._footprints, p.touch_m, p.min_opening_m))

    # Spaces -------------------------------------------------------------------------

    def same_space(self, a: Tuple[int, int], b: Tuple[int, int]) -> bool:
        """Return whether two rooms (floor, room) are one space for the planner."""
        return a == b or (a in self._space and b in self._space[a])

    def rooms_at(self, T_building_base: Pose) -> Tuple[List[Tuple[int, int]], bool]:
        """
        Return the rooms the base is in and whether it stands in a doorway.

        In a room's footprint (its floor within half a metre): that room (or
        those, where footprints overlap). Outside every footprint: the
        rooms within ``doorway_margin_m`` (a doorway), else none.
        """
        x, y = (float(v) for v in T_building_base.t[:2])
        z = float(T_building_base.t[2])
        level = [f for f in self._footprints.values() if f.on_floor(z)]
        inside = [f.key for f in level if f.inside(x, y)]
        if inside:
            return inside, False
        near = [f.key for f in level if f.inside(x, y, self.parameters.doorway_margin_m)]
        return near, bool(near)

    # Visibility ------------------------------------------------------------------------

    def options(self, T_building_base: Pose, room_hint: Optional[Tuple[int, int]] = None,
                exclude: Collection[IdsKey] = (), head_pan: Optional[float] = None
                ) -> List[CardOption]:
        """Return every card predicted visible from a pose, best (lowest score) first."""
        p = self.parameters
        head = self.head
        rooms, doorway = self.rooms_at(T_building_base)
        allowed = set()
        for key in rooms:
            allowed |= self._space.get(key, {key})
        if room_hint is not None and room_hint not in self._footprints:
            allowed.add(tuple(room_hint))
        if not allowed:
            return []
        eye = T_building_base.apply(np.array([head.base_to_pan_xyz]))[0]
        rel = eye - self._centres
        distance = np.linalg.norm(rel, axis=1)
        cos_view = np.einsum('ij,ij->i', rel, self._normals) / np.maximum(distance, 1e-9)
        ok = ((distance >= p.min_distance_m) & (distance <= p.max_distance_m)
              & (cos_view >= math.cos(math.radians(p.max_view_angle_deg))))
        T_base_building = T_building_base.inverse()
        (pan_lo, pan_hi), (tilt_lo, tilt_hi) = head.pan_limits_rad, head.tilt_limits_rad
        pan_margin, tilt_margin = math.radians(p.pan_margin_deg), math.radians(p.tilt_margin_deg)
        out = []
        for k in np.flatnonzero(ok):
            card = self._cards[int(k)]
            room = (card.ids.floor, card.ids.room)
            if room not in allowed or card.ids.as_tuple() in exclude:
                continue
            try:
                pan, tilt = head.aim_angles(T_base_building.apply(self._centres[k][None])[0])
            except ValueError:
                continue
            if not (pan_lo + pan_margin <= pan <= pan_hi - pan_margin
                    and tilt_lo + tilt_margin <= tilt <= tilt_hi - tilt_margin):
                continue
            if room in self._footprints and not self._clear(eye, card, allowed):
                continue
            view = math.degrees(math.acos(min(1.0, float(cos_view[k]))))
            score = float(distance[k]) * (1.0 + p.view_weight * (1.0 / float(cos_view[k]) - 1.0))
            if head_pan is not None:
                # Within the travel: the way the head turns, never through the stop.
                score += p.slew_weight_m_per_rad * abs(pan - head_pan)
            out.append(CardOption(card.ids, pan, tilt, float(distance[k]), view, score))
        return sorted(out, key=lambda o: o.score)

    def _clear(self, eye: np.ndarray, card: MappedCard, allowed: set) -> bool:
        """
        Return whether the lines of sight to the card's centre and side edges stay in the space.

        Each sample, with a ring of points ``sight_clearance_m`` round it (so
        that a wall's corner is not grazed), must lie inside the allowed
        rooms' footprints, except the first ``doorway_m`` from the eye (the
        robot stands where it stands: by a wall, in a doorway) and what is
        closer than ``sight_clearance_m`` to the card's wall (it hangs on a
        footprint's edge).
        """
        p = self.parameters
        T = card.T_building_card
        ends = [T.t + T.R @ np.array([x, 0.0, 0.02]) for x in
                (0.0, -p.card_half_width_m, p.card_half_width_m)]
        start = eye[:2]
        samples = []
        for end in ends:
            end = end[:2]
            length = float(np.linalg.norm(end - start))
            n = max(int(math.ceil(length / p.sight_step_m)), 1)
            along = np.linspace(0.0, length, n + 1)
            if length <= 0.0:
                continue
            points = start + (along / length)[:, None] * (end - start)
            # Off the card's wall by less than the clearance: the wall it hangs on.
            off_wall = (points - T.t[:2]) @ T.R[:2, 2]
            keep = (along > p.doorway_m) & (off_wall > p.sight_clearance_m)
            samples.append(points[keep])
        points = np.vstack(samples) if samples else np.zeros((0, 2))
        if not len(points):
            return True
        x = (points[:, 0:1] + self._ring[None, :, 0]).ravel()
        y = (points[:, 1:2] + self._ring[None, :, 1]).ravel()
        for key in allowed:
            footprint = self._footprints.get(key)
            if footprint is None:
                continue
            out = ~footprint.inside(x, y, 1e-6)
            if not out.any():
                return True
            x, y = x[out], y[out]           # what this room leaves to the others
        return False

    # Choice ------------------------------------------------------------------------------

    def choose(self, T_building_base: Pose, current_card: Optional[Sequence[int]] = None,
               twist: Optional[BaseTwist] = None, head_pan: Optional[float] = None,
               room_hint: Optional[Tuple[int, int]] = None,
               exclude: Collection[IdsKey] = ()) -> Optional[GazeChoice]:
        """
        Return the card to look at from ``T_building_base``; None: none visible now or ahead.

        ``current_card``: the ids the head looks at now (for handover and
        hysteresis); ``twist``: the base's (for the lookahead); ``head_pan``:
        the head's pan now (turning far costs); ``room_hint``: the room of
        the last fix (for rooms without a size); ``exclude``: cards the
        driver found missing where predicted (e.g. hidden by something the
        map does not know).
        """
        p = self.parameters
        exclude = {tuple(e) for e in exclude}
        now = self.options(T_building_base, room_hint, exclude, head_pan)
        ahead_pose = None
        if twist is not None and p.lookahead_s > 0.0 and (
                twist.speed_m_s > 1e-3 or abs(twist.yaw_rate_rad_s) > 1e-3):
            ahead_pose = T_building_base @ _moved(twist, p.lookahead_s)
        key = None
        if current_card is not None:
            key = tuple(int(v) for v in (current_card.as_tuple() if isinstance(current_card, Ids)
                                         else current_card))
        if not now:
            if ahead_pose is None:
                return None
            ahead = self.options(ahead_pose, room_hint, exclude)
            # The card aimed at ahead already stays the one (no flip-flop
            # between two cards while the door comes nearer).
            ahead.sort(key=lambda o: o.ids.as_tuple() != key)
            return self._ahead(T_building_base, ahead)
        ahead_ids = {o.ids.as_tuple() for o in now}
        if ahead_pose is not None:
            ahead_ids = {o.ids.as_tuple() for o in self.options(ahead_pose, room_hint, exclude)}
        staying = [o for o in now if o.ids.as_tuple() in ahead_ids]
        current = None
        if key is not None:
            current = next((o for o in now if o.ids.as_tuple() == key), None)
        later: Dict[float, set] = {}

        def visible_at(horizon: float) -> set:
            """Return the ids of the cards predicted visible ``horizon`` s ahead (cached)."""
            if horizon not in later:
                options = self.options(T_building_base @ _moved(twist, horizon), room_hint,
                                       exclude)
                later[horizon] = {o.ids.as_tuple() for o in options}
            return later[horizon]

        def cost(option: CardOption) -> float:
            """Return the option's score plus the cost of a handover soon after."""
            if ahead_pose is None or p.stay_horizon_s <= p.lookahead_s or p.leave_weight_m <= 0:
                return option.score
            gone = option.ids.as_tuple() not in visible_at(p.stay_horizon_s)
            return option.score + (p.leave_weight_m if gone else 0.0)

        def lasts(option: CardOption) -> bool:
            """Whether the card is still in sight once the head has turned to it, and a dwell."""
            if ahead_pose is None or head_pan is None or p.slew_rate_deg_s <= 0.0:
                return True
            horizon = (abs(option.pan - head_pan) / math.radians(p.slew_rate_deg_s)
                       + p.min_dwell_s)
            if horizon <= p.lookahead_s and option.ids.as_tuple() in ahead_ids:
                return True
            horizon = math.ceil(horizon / LASTS_STEP_S) * LASTS_STEP_S
            return option.ids.as_tuple() in visible_at(horizon)

        if len(staying) > 1:
            # Only a choice needs the look further ahead (an options() per image).
            staying.sort(key=cost)

        if current is None:
            best = next((o for o in staying if lasts(o)), None)
            if best is not None:
                return GazeChoice(best, 'new', True)
            best = next((o for o in now if lasts(o)), None)
            if best is not None:
                return GazeChoice(best, 'new', False)
            if ahead_pose is not None:
                # Every card in sight now is gone before the head gets there.
                choice = self._ahead(T_building_base, self.options(ahead_pose, room_hint,
                                                                   exclude))
                if choice is not None:
                    return choice
            return GazeChoice(now[0], 'new', bool(staying))
        others = [o for o in staying if o.ids != current.ids]
        if current.ids.as_tuple() not in ahead_ids:
            other = next((o for o in others if lasts(o)), None)
            if other is not None:
                return GazeChoice(other, 'handover', True)
            return GazeChoice(current, 'keep', False)
        if others and cost(others[0]) < p.switch_ratio * cost(current) and lasts(others[0]):
            return GazeChoice(others[0], 'better', True)
        return GazeChoice(current, 'keep', True)

    def _ahead(self, T_building_base: Pose, ahead: Sequence[CardOption]
               ) -> Optional[GazeChoice]:
        """Return the best card visible from the pose ahead, aimed at from here (or None)."""
        head = self.head
        (pan_lo, pan_hi), (tilt_lo, tilt_hi) = head.pan_limits_rad, head.tilt_limits_rad
        T_base_building = T_building_base.inverse()
        for option in ahead:
            centre = self.building.card(option.ids).T_building_card.t
            try:
                pan, tilt = head.aim_angles(T_base_building.apply(centre[None])[0])
            except ValueError:
                continue
            if pan_lo <= pan <= pan_hi and tilt_lo <= tilt <= tilt_hi:
                return GazeChoice(CardOption(option.ids, pan, tilt, option.distance_m,
                                             option.view_angle_deg, option.score),
                                  'ahead', True)
        return None


def _moved(twist: BaseTwist, duration_s: float, steps: int = 8) -> Pose:
    """Return the base's motion over ``duration_s`` at a constant twist (base frame)."""
    step = Pose(rodrigues(np.asarray(twist.angular, dtype=float) * duration_s / steps),
                np.asarray(twist.linear, dtype=float) * duration_s / steps)
    out = Pose.identity()
    for _ in range(steps):
        out = out @ step
    return out


def _wrap(angle: float) -> float:
    """Return the angle in [-pi, pi)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def feed_forward_rates(head: HeadGeometry, target_in_base: Sequence[float], twist: BaseTwist,
                       step_s: float = 1e-3) -> Tuple[float, float]:
    """
    Return the (pan, tilt) rates (rad/s) that keep a world-fixed target on the optical axis.

    ``target_in_base``: the target (e.g. a card's centre) in ``base_link``
    now; ``twist``: the base's velocity in ``base_link``. The rates are the
    time derivative of ``head.aim_angles`` of the target as the base moves
    under it (central differences over ``step_s``): a base turning left at
    w gives a pan rate of about -w, and driving past a target adds the
    rate at which its bearing changes. ValueError when the target is too
    close to the head to be aimed at.
    """
    target = np.asarray(target_in_base, dtype=float).reshape(3)
    angles = []
    for sign in (-1.0, 1.0):
        moved = _moved(twist, sign * step_s, steps=1)
        angles.append(head.aim_angles(moved.inverse().apply(target[None])[0]))
    (pan0, tilt0), (pan1, tilt1) = angles
    return _wrap(pan1 - pan0) / (2.0 * step_s), (tilt1 - tilt0) / (2.0 * step_s)
