"""
Survey walks: cards "as hung" on a floor plan, a walk through it, drifting odometry, images.

ROS-free. The survey (``pattern_locator.survey``) is tested and benchmarked
on walks built here; the interface is deliberately small so that any world
can drive it:

* a :class:`FloorPlan`: the cards (each with its planned pose and its true,
  "as hung" pose, in the building frame), optional wall segments (line of
  sight: a card behind a wall is neither rendered nor seen), the floor's
  height and the waypoints of a walk;
* a :class:`Walk`: the true base poses over time on that floor and where
  the camera sits on the base;
* :func:`drift_odometry`: the base's odometry as a robot would report it,
  with a scale error, a yaw bias and noise;
* :class:`WalkRenderer`: the camera's images along the walk (the project's
  ray-cast renderer, per card box, with exact truth).

To drive it from another world (a whole floor with doors and corridors),
build a :class:`FloorPlan` from that world's cards and walls with
:func:`hang_cards` and give its route as waypoints.

Frames: building frame z up, the floor at ``FloorPlan.floor_z``;
``base_link`` REP 103 (x forward, y left, z up) at floor level; the camera's
optical frame (x right, y down, z forward).
"""

from dataclasses import dataclass, field, replace
import math
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from .fast_render import merge_boxes, pixel_box, UncodedFace
from .render import CardPlacement, DotCardTexture, render_scene, RenderOptions
from ..card.pattern import Code, Ids, load_pattern_config, PatternConfig
from ..errors import ConfigError
from ..localization.building import load_building, wall_card_rotation
from ..localization.head import R_TILT_OPTICAL
from ..vision.camera import CameraModel
from ..vision.geometry import Pose, rodrigues, yaw_of

# "As hung": off the plan by up to 5 cm along the wall and 3 degrees (issue 13).
# Walls are plumb and near their planned line, so the card's tilt out of the
# vertical and its offset out of the wall are small.
HANG_OFFSET_M = 0.05
HANG_WALL_OFFSET_M = 0.01
HANG_ROLL_DEG = 3.0
HANG_YAW_DEG = 2.0
HANG_TILT_DEG = 0.3
CARD_HEIGHT_M = 2.15
# A hand-held or mast camera: 1.25 m above the floor, pitched up 15 degrees
# (the cards hang about a metre above it).
CAMERA_HEIGHT_M = 1.25
CAMERA_PITCH_DEG = 15.0
# The renders of the sim: bags.render_stop's look with light sensor noise.
WALK_RENDER_OPTIONS = RenderOptions(supersample=3, background='white', gain=0.85,
                                    gradient=0.15, gradient_angle_deg=30.0,
                                    colour_cast=(1.0, 0.97, 0.92), defocus_sigma_px=0.5,
                                    noise_sigma=1.0)
_NOISE_PAD = 64


def camera_mount(height: float = CAMERA_HEIGHT_M, pitch_deg: float = CAMERA_PITCH_DEG,
                 forward: float = 0.1) -> Pose:
    """Return ``T_base_camera``: the optical frame looking forward, pitched up by ``pitch_deg``."""
    p = math.radians(pitch_deg)
    # A turn about base -y lifts the optical axis (base +x) towards +z.
    pitch = np.array([[math.cos(p), 0.0, -math.sin(p)], [0.0, 1.0, 0.0],
                      [math.sin(p), 0.0, math.cos(p)]])
    return Pose(pitch @ R_TILT_OPTICAL, np.array([forward, 0.0, height]))


def planar_pose(x: float, y: float, yaw: float, z: float = 0.0) -> Pose:
    """Return a pose on the floor: position (x, y, z), turned by ``yaw`` about +z."""
    return Pose(rodrigues(np.array([0.0, 0.0, yaw])), np.array([x, y, z]))


def _wrap(angle):
    return (np.asarray(angle) + math.pi) % (2.0 * math.pi) - math.pi


# Plans -------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class HungCard:
    """A card of a plan: its ids and code, where it should hang and where it hangs."""

    ids: Ids
    code: Code
    T_plan: Pose        # building frame, as planned (the nominal map)
    T_true: Pose        # building frame, as hung (the truth)


@dataclass(frozen=True, eq=False)
class FloorPlan:
    """
    A floor to walk through: cards as hung, walls (line of sight) and a route.

    ``walls``: (M, 4) segments ``x0 y0 x1 y1`` in the building's floor plane;
    a card hangs on one of them (its centre within a few cm). ``route``:
    (K, 2) waypoints of the walk on the floor. ``rooms``: (floor, room) ->
    (x0, y0, x1, y1) floor-plan box, for plots.
    """

    name: str
    floor: int
    floor_z: float
    cards: Tuple[HungCard, ...]
    walls: np.ndarray
    route: np.ndarray
    rooms: Dict[Tuple[int, int], Tuple[float, float, float, float]] = field(
        default_factory=dict)

    def card(self, ids: Tuple[int, int, int]) -> HungCard:
        """Return the card with these (floor, room, pattern) ids; ConfigError if none."""
        for card in self.cards:
            if card.ids.as_tuple() == tuple(ids):
                return card
        raise ConfigError(f'plan {self.name}: no card {tuple(ids)}')

    def line_of_sight(self, eye_xy: np.ndarray, card: HungCard) -> bool:
        """Return True when no wall crosses the floor-plane line from ``eye_xy`` to the card."""
        if len(self.walls) == 0:
            return True
        target = card.T_true.t[:2]
        eye = np.asarray(eye_xy, dtype=float)[:2]
        span = target - eye
        length = float(np.linalg.norm(span))
        if length < 1e-6:
            return True
        # Stop 5 cm short of the card: it hangs on a wall, which the line must reach.
        end = eye + span * max(0.0, (length - 0.05) / length)
        return not np.any(_crossings(eye, end, self.walls))


def _crossings(a: np.ndarray, b: np.ndarray, walls: np.ndarray) -> np.ndarray:
    """Return which wall segments the segment a-b crosses (proper intersections)."""
    p, q = walls[:, :2], walls[:, 2:]
    d1, d2 = b - a, q - p
    denom = d1[0] * d2[:, 1] - d1[1] * d2[:, 0]
    with np.errstate(divide='ignore', invalid='ignore'):
        s = ((p[:, 0] - a[0]) * d2[:, 1] - (p[:, 1] - a[1]) * d2[:, 0]) / denom
        t = ((p[:, 0] - a[0]) * d1[1] - (p[:, 1] - a[1]) * d1[0]) / denom
    return (np.abs(denom) > 1e-12) & (s > 0.0) & (s < 1.0) & (t >= 0.0) & (t <= 1.0)


def hang_cards(planned: Sequence[Tuple[Ids, Code, Pose]], seed: int,
               offset_m: float = HANG_OFFSET_M, roll_deg: float = HANG_ROLL_DEG,
               yaw_deg: float = HANG_YAW_DEG, tilt_deg: float = HANG_TILT_DEG,
               wall_offset_m: float = HANG_WALL_OFFSET_M) -> Tuple[HungCard, ...]:
    """
    Return the planned cards as they were hung: each off its plan by a seeded error.

    Along the wall by up to ``offset_m`` (uniform in a disc), out of it by up
    to ``wall_offset_m``, turned on the wall by up to ``roll_deg``, about the
    vertical by up to ``yaw_deg`` and out of the vertical by up to
    ``tilt_deg`` (uniform). Planned cards must be upright wall cards.
    """
    rng = np.random.default_rng(seed)
    out = []
    for ids, code, T_plan in planned:
        r = offset_m * math.sqrt(rng.uniform())
        a = rng.uniform(0.0, 2.0 * math.pi)
        shift = np.array([r * math.cos(a), r * math.sin(a),
                          rng.uniform(-wall_offset_m, wall_offset_m)])
        roll, yaw, tilt = (math.radians(rng.uniform(-m, m))
                           for m in (roll_deg, yaw_deg, tilt_deg))
        # In the card's own axes: z the normal (roll), y up (yaw), x along the wall (tilt).
        turn = rodrigues(np.array([0.0, yaw, 0.0])) @ rodrigues(np.array([tilt, 0.0, 0.0])) \
            @ rodrigues(np.array([0.0, 0.0, roll]))
        T_true = Pose(T_plan.R @ turn, T_plan.t + T_plan.R @ shift)
        out.append(HungCard(ids, code, T_plan, T_true))
    return tuple(out)


def _box_walls(x0: float, y0: float, x1: float, y1: float,
               doors: Sequence[Tuple[str, float, float]] = ()) -> List[List[float]]:
    """Return the four walls of a box as segments, each door ('s'|'n'|'w'|'e', a, b) cut out."""
    sides = {'s': ((x0, y0), (x1, y0)), 'n': ((x0, y1), (x1, y1)),
             'w': ((x0, y0), (x0, y1)), 'e': ((x1, y0), (x1, y1))}
    out = []
    for name, (p, q) in sides.items():
        cuts = sorted((a, b) for side, a, b in doors if side == name)
        horizontal = name in 'sn'
        lo, hi = (p[0], q[0]) if horizontal else (p[1], q[1])
        for a, b in cuts + [(hi, hi)]:
            if a > lo:
                out.append([lo, p[1], a, p[1]] if horizontal else [p[0], lo, p[0], a])
            lo = b
    return out


def _wall_card(ids: Tuple[int, int, int], pattern: PatternConfig, x: float, y: float,
               facing_deg: float, z: float) -> Tuple[Ids, Code, Pose]:
    return (Ids(*ids), pattern.encode(*ids),
            Pose(wall_card_rotation(facing_deg), np.array([x, y, z])))


def paper_room_plan(seed: int = 1, pattern: Optional[PatternConfig] = None) -> FloorPlan:
    """
    Return the paper's room (floor 1 room 3 of the shipped map, six cards) as a plan.

    Building frame as in ``config/building.yaml``: the room spans x 0..10,
    y 7..12 on the floor at z = 3. The route loops round the middle of the
    room, 2-3 m from its walls, about 42 m: two minutes at 0.35 m/s.
    """
    pattern = pattern if pattern is not None else load_pattern_config()
    room = load_building(None, pattern).room(1, 3)
    floor_z = float(room.T_building_room.t[2])
    planned = [(c.ids, c.code, c.T_building_card) for c in room.cards]
    route = np.array([[7.5, 10.0], [2.5, 10.2], [2.2, 8.8], [7.8, 8.7], [7.5, 10.0],
                      [5.0, 9.5], [2.0, 8.9], [2.0, 10.3], [8.0, 10.2], [8.0, 8.8],
                      [2.5, 8.9], [2.5, 10.0], [7.0, 10.0]])
    return FloorPlan('paper room', 1, floor_z, hang_cards(planned, seed),
                     np.array(_box_walls(0.0, 7.0, 10.0, 12.0)), route,
                     {(1, 3): (0.0, 7.0, 10.0, 12.0)})


def room_corridor_plan(seed: int = 1, pattern: Optional[PatternConfig] = None) -> FloorPlan:
    """
    Return the paper's room and the corridor in front of it, with cards on the corridor walls.

    The room (floor 1 room 3, x 0..10, y 7..12) opens through a 1.2 m door
    in its south wall onto the corridor (y 5..7, x 0..20.2), whose eight
    cards are floor 1 room 10 (cards 1-8, alternately on its south and
    north walls). The route loops the room, walks out to the corridor's east
    end and back, and returns into the room: about 75 m.
    """
    pattern = pattern if pattern is not None else load_pattern_config()
    room = load_building(None, pattern).room(1, 3)
    z = float(room.T_building_room.t[2])
    planned = [(c.ids, c.code, c.T_building_card) for c in room.cards]
    xs = [1.5, 4.0, 6.5, 9.0, 11.5, 14.0, 16.5, 19.0]
    for k, x in enumerate(xs):
        south = k % 2 == 0
        planned.append(_wall_card((1, 10, k + 1), pattern, x, 5.0 if south else 7.0,
                                  90.0 if south else -90.0, z + CARD_HEIGHT_M))
    walls = _box_walls(0.0, 7.0, 10.0, 12.0, doors=[('s', 4.4, 5.6)])
    walls += _box_walls(0.0, 5.0, 20.2, 7.0, doors=[('n', 4.4, 5.6)])
    route = np.array([[5.0, 8.4], [1.5, 8.4], [1.4, 10.6], [8.6, 10.6], [8.6, 8.4],
                      [5.0, 8.2], [5.0, 6.0], [1.0, 6.0], [19.2, 6.0], [8.0, 6.0],
                      [5.0, 6.0], [5.0, 8.5], [2.0, 9.5]])
    rooms = {(1, 3): (0.0, 7.0, 10.0, 12.0), (1, 10): (0.0, 5.0, 20.2, 7.0)}
    return FloorPlan('room and corridor', 1, z, hang_cards(planned, seed), np.array(walls),
                     route, rooms)


def ring_floor_plan(seed: int = 1, pattern: Optional[PatternConfig] = None) -> FloorPlan:
    """
    Return a whole floor: a corridor ring of 76 m around a core, four rooms, 36 cards.

    The corridor (2 m wide) runs round the rectangle x 0..28, y 0..14 (its
    centre line is 76 m long, a loop); the core inside it (x 2..26, y 2..12)
    holds four rooms of 6 m x 4 m opening onto the corridor through doors.
    Twenty corridor cards (rooms 20-23 by side, 5 per side) hang alternately
    on its outer and inner walls; each room has four cards. The route goes
    round the ring twice, visiting each room on the way: about 250 m.
    """
    pattern = pattern if pattern is not None else load_pattern_config()
    z = 0.0
    h = z + CARD_HEIGHT_M
    planned = []
    walls = _box_walls(0.0, 0.0, 28.0, 14.0)
    # The core's walls, with a door into each room.
    rooms = {(0, 1): (4.0, 2.0, 10.0, 6.0), (0, 2): (18.0, 2.0, 24.0, 6.0),
             (0, 3): (18.0, 8.0, 24.0, 12.0), (0, 4): (4.0, 8.0, 10.0, 12.0)}
    doors_core = {'s': [(6.5, 7.5), (20.5, 21.5)], 'n': [(6.5, 7.5), (20.5, 21.5)]}
    walls += _box_walls(2.0, 2.0, 26.0, 12.0, doors=[(side, a, b) for side, cuts in
                                                     doors_core.items() for a, b in cuts])
    for (floor, number), (x0, y0, x1, y1) in rooms.items():
        door = 's' if y0 < 7.0 else 'n'
        walls += _box_walls(x0, y0, x1, y1, doors=[(door, x0 + 2.5, x0 + 3.5)])
        # A room's door side is the core's outer wall; its own wall there is the core's.
        cx, cy = (x0 + x1) / 2.0, (y0 + y1) / 2.0
        far_y, far_facing = (y1, -90.0) if door == 's' else (y0, 90.0)
        planned += [_wall_card((floor, number, 1), pattern, x0, cy, 0.0, h),
                    _wall_card((floor, number, 2), pattern, cx - 1.2, far_y, far_facing, h),
                    _wall_card((floor, number, 3), pattern, cx + 1.2, far_y, far_facing, h),
                    _wall_card((floor, number, 4), pattern, x1, cy, 180.0, h)]
    # Corridor cards: room 20 south side, 21 east, 22 north, 23 west.
    sides = [(20, [(x, 0.0, 90.0) if k % 2 == 0 else (x, 2.0, -90.0)
                   for k, x in enumerate([3.0, 8.5, 14.0, 19.5, 25.0])]),
             (21, [(28.0, y, 180.0) if k % 2 == 0 else (26.0, y, 0.0)
                   for k, y in enumerate([1.0, 4.0, 7.0, 10.0, 13.0])]),
             (22, [(x, 14.0, -90.0) if k % 2 == 0 else (x, 12.0, 90.0)
                   for k, x in enumerate([25.0, 19.5, 14.0, 8.5, 3.0])]),
             (23, [(0.0, y, 0.0) if k % 2 == 0 else (2.0, y, 180.0)
                   for k, y in enumerate([13.0, 10.0, 7.0, 4.0, 1.0])])]
    for number, spots in sides:
        for k, (x, y, facing) in enumerate(spots):
            planned.append(_wall_card((0, number, k + 1), pattern, x, y, facing, h))
    # Round the ring (centre line 1 m from the outer wall) twice, into each room on the way.
    ring = [[1.0, 1.0], [27.0, 1.0], [27.0, 13.0], [1.0, 13.0], [1.0, 1.0]]

    def visit(x_door, y_corridor, y_in):
        return [[x_door, y_corridor], [x_door, y_in], [x_door - 1.5, y_in], [x_door + 1.5, y_in],
                [x_door, y_in], [x_door, y_corridor]]

    route = ([[1.0, 1.0], [7.0, 1.0]] + visit(7.0, 1.0, 3.5)[1:] + [[21.0, 1.0]]
             + visit(21.0, 1.0, 3.5)[1:] + [[27.0, 1.0], [27.0, 13.0], [21.0, 13.0]]
             + visit(21.0, 13.0, 10.5)[1:] + [[7.0, 13.0]] + visit(7.0, 13.0, 10.5)[1:]
             + [[1.0, 13.0]] + ring)
    rooms.update({(0, 20): (0.0, 0.0, 28.0, 2.0), (0, 21): (26.0, 0.0, 28.0, 14.0),
                  (0, 22): (0.0, 12.0, 28.0, 14.0), (0, 23): (0.0, 0.0, 2.0, 14.0)})
    return FloorPlan('ring floor', 0, z, hang_cards(planned, seed), np.array(walls),
                     np.array(route, dtype=float), rooms)


# Walks -------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Walk:
    """
    The truth of a walk: base poses at ``times_s`` and the camera's mount on the base.

    ``frames``: the indices of the samples at which the camera took an image
    (odometry is sampled at every time, images at a divisor of the rate).
    ``targets``: the card each sample's camera aimed at (-1: none).
    """

    times_s: np.ndarray
    T_world_base: Tuple[Pose, ...]
    T_base_camera: Pose
    frames: np.ndarray
    targets: np.ndarray

    def camera_pose(self, index: int) -> Pose:
        """Return ``T_world_camera`` at sample ``index``."""
        return self.T_world_base[index] @ self.T_base_camera

    @property
    def length_m(self) -> float:
        """Return the distance the base travelled (m)."""
        xy = np.array([T.t[:2] for T in self.T_world_base])
        return float(np.sum(np.linalg.norm(np.diff(xy, axis=0), axis=1)))


def make_walk(plan: FloorPlan, rate_hz: float = 10.0, speed_m_s: float = 0.35,
              odometry_per_frame: int = 2, mount: Optional[Pose] = None,
              hfov_deg: float = 90.0, max_yaw_rate: float = 0.8,
              look_range_m: Tuple[float, float] = (1.0, 6.0), max_view_deg: float = 65.0,
              duration_s: Optional[float] = None, floor_tilt_deg: float = 0.15,
              floor_bump_m: float = 0.0015, seed: int = 0) -> Walk:
    """
    Walk the plan's route at ``speed_m_s``, the camera turned to frame as many cards as it can.

    The base moves along the waypoints at constant speed (holonomic: a
    person carrying the camera, or a robot that can turn as it drives). At
    each sample it looks for the heading that puts the most cards in the
    camera's view (``hfov_deg``, less a margin): cards in the line of sight,
    within ``look_range_m`` and at most ``max_view_deg`` off their normal;
    two cards in one image are what ties them together. A card already seen
    often counts less, so that every card gets its share of views. It aims
    at the middle of the chosen cards, turning at most ``max_yaw_rate``; with none in
    sight it faces along the route. A small seeded sway varies the views.
    Images are taken at ``rate_hz``, odometry samples ``odometry_per_frame``
    times as often; ``duration_s`` stops the walk early. The floor is not
    quite flat: the base rolls and pitches by ``floor_tilt_deg`` and rises by
    ``floor_bump_m`` (standard deviations, varying over about a metre).
    """
    if not (rate_hz > 0 and speed_m_s > 0 and odometry_per_frame >= 1):
        raise ConfigError('walk: rate, speed and odometry_per_frame must be positive')
    mount = mount if mount is not None else camera_mount()
    rng = np.random.default_rng(seed)
    dt = 1.0 / (rate_hz * odometry_per_frame)
    route = np.asarray(plan.route, dtype=float)
    legs = np.linalg.norm(np.diff(route, axis=0), axis=1)
    along = np.concatenate([[0.0], np.cumsum(legs)])
    n = int(float(along[-1]) / (speed_m_s * dt)) + 1
    if duration_s is not None:
        n = min(n, int(duration_s / dt) + 1)
    s = np.arange(n) * speed_m_s * dt
    xy = np.column_stack([np.interp(s, along, route[:, 0]), np.interp(s, along, route[:, 1])])
    leg = np.clip(np.searchsorted(along, s, side='right') - 1, 0, len(legs) - 1)
    tangent = np.arctan2(*(np.diff(route, axis=0)[leg][:, ::-1].T))
    mount_yaw = math.atan2(mount.R[1, 2], mount.R[0, 2])   # the optical axis' heading on the base
    cards = plan.cards
    centres = np.array([c.T_true.t for c in cards])
    normals = np.array([c.T_true.R[:, 2] for c in cards])
    cos_view = math.cos(math.radians(max_view_deg))
    half = math.radians(hfov_deg / 2.0) * 0.8
    candidates = np.radians(np.arange(0.0, 360.0, 5.0))
    sway = 0.15 * np.tanh(np.cumsum(rng.normal(0.0, 0.02, n)))
    heading = float(tangent[0])
    headings, targets = np.zeros(n), np.full(n, -1)
    looks = np.zeros(len(cards))
    for k in range(n):
        eye = np.array([xy[k, 0], xy[k, 1], plan.floor_z + mount.t[2]])
        to_card = centres - eye
        dist = np.linalg.norm(to_card, axis=1)
        facing = -np.einsum('ij,ij->i', to_card, normals) / np.maximum(dist, 1e-9)
        ok = (dist >= look_range_m[0]) & (dist <= look_range_m[1]) & (facing >= cos_view)
        ok &= np.array([bool(o) and plan.line_of_sight(eye[:2], c) for o, c in zip(ok, cards)])
        want = float(tangent[k])
        if ok.any():
            bearings = np.arctan2(to_card[ok, 1], to_card[ok, 0])
            inside = np.abs(_wrap(bearings[None, :] - candidates[:, None])) < half
            # A card seen less so far counts more: every card gets its share of views.
            count = inside @ (1.0 / (1.0 + looks[ok] / 30.0))
            best = np.flatnonzero(count >= count.max() - 1e-9)
            # Of the best views, the one needing the least turn, aimed at its cards' middle.
            view = candidates[best[np.argmin(np.abs(_wrap(candidates[best] - heading
                                                          - mount_yaw)))]]
            chosen = bearings[inside[np.flatnonzero(candidates == view)[0]]]
            want = view + float(np.mean(_wrap(chosen - view))) - mount_yaw + sway[k]
            targets[k] = int(np.flatnonzero(ok)[np.argmin(np.abs(_wrap(bearings - view)))])
            in_view = np.flatnonzero(ok)[np.abs(_wrap(bearings - heading - mount_yaw)) < half]
            looks[in_view] += 1.0
        step = float(_wrap(want - heading))
        heading += float(np.clip(step, -max_yaw_rate * dt, max_yaw_rate * dt))
        headings[k] = heading
    # A real floor is not flat: the base rocks and bumps a little, smoothly
    # (over about a metre); its odometry does not see it.
    bumps = _smooth(rng, n, speed_m_s * dt, (floor_tilt_deg, floor_tilt_deg, floor_bump_m))
    poses = tuple(Pose(rodrigues(np.array([0.0, 0.0, h]))
                       @ rodrigues(np.radians(np.array([b[0], b[1], 0.0]))),
                       np.array([x, y, plan.floor_z + b[2]]))
                  for (x, y), h, b in zip(xy, headings, bumps))
    frames = np.arange(0, n, odometry_per_frame)
    return Walk(np.arange(n) * dt, poses, mount, frames, targets)


def _smooth(rng: np.random.Generator, n: int, step_m: float, sds: Sequence[float]
            ) -> np.ndarray:
    """Return (n, k) smooth random processes with standard deviations ``sds`` (1 m scale)."""
    a = math.exp(-max(step_m, 1e-9) / 1.0)
    out = np.zeros((n, len(sds)))
    value = rng.normal(0.0, 1.0, len(sds))
    for i in range(n):
        value = a * value + math.sqrt(1.0 - a * a) * rng.normal(0.0, 1.0, len(sds))
        out[i] = value
    return out * np.asarray(sds, dtype=float)


# Odometry ----------------------------------------------------------------------------


@dataclass(frozen=True)
class OdometryDrift:
    """
    How a base's odometry errs: a scale error, a yaw bias, and noise per metre.

    Each true step of length d (m) and turn a (rad) is reported as
    ``(1 + scale_error) * d`` and ``a + yaw_bias_rad_per_m * d + noise``,
    the noises growing with the square root of the distance travelled.
    """

    scale_error: float = 0.03
    yaw_bias_rad_per_m: float = math.radians(0.5)
    sigma_xy_per_sqrt_m: float = 0.003
    sigma_yaw_per_sqrt_m: float = math.radians(0.1)


def drift_odometry(walk: Walk, drift: OdometryDrift = OdometryDrift(), seed: int = 0
                   ) -> Tuple[Pose, ...]:
    """Return the odometry ``T_odom_base`` at every sample: the walk as the wheels saw it."""
    rng = np.random.default_rng(seed)
    x, y, yaw = 0.0, 0.0, 0.0
    out = [planar_pose(0.0, 0.0, 0.0)]
    for a, b in zip(walk.T_world_base, walk.T_world_base[1:]):
        step = a.inverse() @ b
        dx, dy = step.t[:2]
        turn = yaw_of(step.R)
        d = math.hypot(dx, dy)
        noise = math.sqrt(d)
        dx = (1.0 + drift.scale_error) * dx + rng.normal(0.0, drift.sigma_xy_per_sqrt_m * noise)
        dy = (1.0 + drift.scale_error) * dy + rng.normal(0.0, drift.sigma_xy_per_sqrt_m * noise)
        turn += drift.yaw_bias_rad_per_m * d + rng.normal(
            0.0, drift.sigma_yaw_per_sqrt_m * noise)
        c, s = math.cos(yaw), math.sin(yaw)
        x, y = x + c * dx - s * dy, y + s * dx + c * dy
        yaw += turn
        out.append(planar_pose(x, y, yaw))
    return tuple(out)


# Rendering ---------------------------------------------------------------------------


class WalkRenderer:
    """
    Render what the camera sees on a plan: each visible card in its own pixel box.

    Only cards in the line of sight and in front of the camera are drawn;
    the rest of the image is the background with sensor noise. Boxes that
    overlap are rendered together (the nearer card wins).
    """

    def __init__(self, plan: FloorPlan, camera: CameraModel,
                 pattern: Optional[PatternConfig] = None,
                 options: RenderOptions = WALK_RENDER_OPTIONS) -> None:
        if options.background not in ('white', 'black') or options.occluders:
            raise ConfigError('walk renderer: the background must be white or black, with no '
                              'occluders')
        self.plan = plan
        self.camera = camera
        self.pattern = pattern if pattern is not None else load_pattern_config()
        self.options = options
        self._textures = [DotCardTexture(self.pattern, c.code) for c in plan.cards]
        clean = render_scene(camera, [], replace(options, noise_sigma=0.0, jpeg_quality=None,
                                                 gradient=0.0, seed=0)).image
        self._clean = clean
        self._noise = np.random.default_rng(12345).normal(
            0.0, options.noise_sigma, (camera.height + _NOISE_PAD, camera.width + _NOISE_PAD,
                                       3)).astype(np.float32)

    def visible(self, T_world_camera: Pose) -> List[int]:
        """Return the indices of the cards in the line of sight and in front of the camera."""
        out = []
        T_camera_world = T_world_camera.inverse()
        for k, card in enumerate(self.plan.cards):
            T = T_camera_world @ card.T_true
            normal_towards = float(T.R[:, 2] @ -T.t)
            if T.t[2] > 0.3 and normal_towards > 0 and self.plan.line_of_sight(
                    T_world_camera.t[:2], card):
                out.append(k)
        return out

    def render(self, T_world_camera: Pose, seed: int = 0) -> np.ndarray:
        """Return the BGR image at this camera pose (deterministic for a seed)."""
        rng = np.random.default_rng(seed)
        cam = self.camera
        dy, dx = (int(v) for v in rng.integers(0, _NOISE_PAD + 1, 2))
        frame = np.clip(self._clean.astype(np.float32)
                        + self._noise[dy:dy + cam.height, dx:dx + cam.width], 0, 255)
        frame = np.rint(frame).astype(np.uint8)
        T_camera_world = T_world_camera.inverse()
        items = []
        margin = 4.0 * self.options.defocus_sigma_px + 3.0
        for k in self.visible(T_world_camera):
            T = T_camera_world @ self.plan.cards[k].T_true
            box = pixel_box(cam, T, self._textures[k].size / 2.0, margin)
            if box is not None:
                items.append((box, CardPlacement(T, UncodedFace(self._textures[k]))))
        for box, placements in merge_boxes(items):
            x0, y0, x1, y1 = box
            K = cam.K.copy()
            K[0, 2] -= x0
            K[1, 2] -= y0
            crop = CameraModel(x1 - x0, y1 - y0, K, cam.D, cam.distortion_model)
            # The light gradient is dropped inside boxes: the white card's level
            # matches the background's, which has none either.
            options = replace(self.options, gradient=0.0, jpeg_quality=None,
                              seed=int(rng.integers(1 << 31)))
            frame[y0:y1, x0:x1] = render_scene(crop, placements, options).image
        return frame
