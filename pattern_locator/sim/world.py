"""
The one-room world of the ``sim`` node: a robot's route through a room and its camera's view.

ROS-free. :class:`SimRoute` is the robot base's trajectory over time (the
paper's 30 stops, still or driven between); :class:`SimScene` renders what
the pan/tilt head's camera sees of a room of the building map and gives the
ground truth (camera pose, head motion that would centre a card). A whole
floor with walls, doors, a continuous drive and odometry is
``floor_sim.FloorSim``.

Rendering is fast enough for a live node (640x480 at tens of frames per
second on one core): ``fast_render.BoxRenderer`` renders only the pixel
boxes that can show a card.
"""

from dataclasses import dataclass
import math
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from .fast_render import BoxCard, BoxRenderer, UncodedFace
from .paper_setup import route
from .render import DotCardTexture, NEAR_PLANE, RenderOptions
from ..card.pattern import load_pattern_config, PatternConfig
from ..errors import CodeError, ConfigError
from ..localization.building import BuildingMap, load_building, MappedCard, Room
from ..localization.head import HeadGeometry
from ..vision.camera import CameraModel
from ..vision.geometry import Pose, rodrigues

ROUTE_MODES = ('stops', 'drive')
PAPER_FLOOR, PAPER_ROOM = 1, 3
# The robot faces the card it looks at give or take this much (seeded), so that
# the head pans; the same rule and random draws as bags.sim_stops.
HEADING_SPREAD_DEG = 25.0
DEFAULT_DWELL_S = 3.0
DEFAULT_SPEED_M_S = 0.3
DEFAULT_YAW_RATE_RAD_S = 0.5
# bags.render_stop's look (a painted wall, soft light gradient, warm cast, slight
# defocus) plus light sensor noise. 3 x 3 sub-samples per pixel: with 2 x 2 the
# locator's position error on cards 2-5 m away at wide angle trebled (aliasing).
SIM_RENDER_OPTIONS = RenderOptions(supersample=3, background='white', gain=0.85, gradient=0.15,
                                   gradient_angle_deg=30.0, colour_cast=(1.0, 0.97, 0.92),
                                   defocus_sigma_px=0.5, noise_sigma=1.0)


# Route -------------------------------------------------------------------------------


def _wrap(angle: float) -> float:
    """Return the angle in [-pi, pi)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def _base_pose(x: float, y: float, heading: float) -> Pose:
    return Pose(rodrigues(np.array([0.0, 0.0, heading])), np.array([x, y, 0.0]))


@dataclass(frozen=True)
class RouteStop:
    """A stop of a route: base position (room frame, m), heading (rad) and the card looked at."""

    position: Tuple[float, float]
    heading: float
    card: int

    def pose(self) -> Pose:
        """Return ``T_room_base`` at the stop (base on the floor, z = 0)."""
        return _base_pose(self.position[0], self.position[1], self.heading)


class SimRoute:
    """
    The robot base's trajectory through a room over time.

    ``mode='stops'``: the robot stands at stop i for ``dwell_s`` seconds,
    then is at stop i + 1 (the paper's still images). ``mode='drive'``: it
    dwells ``dwell_s`` at each stop and drives between stops in a straight
    line at a constant speed of at most ``speed_m_s``, its heading turning
    from one stop's heading to the next one's along a half-cosine whose
    yaw rate never exceeds ``max_yaw_rate_rad_s`` (a big turn makes the
    drive slower). Times are seconds from the start of the route; before 0
    the robot is at the first stop, after ``duration_s`` it stays at the
    last one.
    """

    def __init__(self, stops: Sequence[RouteStop], mode: str = 'stops',
                 dwell_s: float = DEFAULT_DWELL_S, speed_m_s: float = DEFAULT_SPEED_M_S,
                 max_yaw_rate_rad_s: float = DEFAULT_YAW_RATE_RAD_S) -> None:
        if mode not in ROUTE_MODES:
            raise ConfigError(f'sim route: mode must be one of {", ".join(ROUTE_MODES)}, '
                              f'got {mode!r}')
        if not stops:
            raise ConfigError('sim route: needs at least one stop')
        for name, value in (('speed_m_s', speed_m_s), ('max_yaw_rate_rad_s',
                                                       max_yaw_rate_rad_s)):
            if not (math.isfinite(value) and value > 0.0):
                raise ConfigError(f'sim route: {name} must be a positive number, got {value!r}')
        lowest = 0.0 if mode == 'drive' else 1e-3
        if not (math.isfinite(dwell_s) and dwell_s >= lowest):
            raise ConfigError(f'sim route: dwell_s must be a number >= {lowest:g} in '
                              f'{mode} mode, got {dwell_s!r}')
        self._stops = tuple(RouteStop((float(s.position[0]), float(s.position[1])),
                                      _wrap(float(s.heading)), int(s.card)) for s in stops)
        self.mode = mode
        self.dwell_s = float(dwell_s)
        self.speed_m_s = float(speed_m_s)
        self.max_yaw_rate_rad_s = float(max_yaw_rate_rad_s)
        arrive = [0.0]
        for a, b in zip(self._stops, self._stops[1:]):
            drive = 0.0
            if mode == 'drive':
                distance = math.dist(a.position, b.position)
                turn = abs(_wrap(b.heading - a.heading))
                # Half-cosine heading profile: peak rate = pi * turn / (2 * time).
                drive = max(distance / self.speed_m_s,
                            math.pi * turn / (2.0 * self.max_yaw_rate_rad_s))
            arrive.append(arrive[-1] + self.dwell_s + drive)
        self._arrive = np.array(arrive)

    @property
    def stops(self) -> Tuple[RouteStop, ...]:
        """Return the stops in route order."""
        return self._stops

    @property
    def duration_s(self) -> float:
        """Return the time at which the robot has dwelt at the last stop."""
        return float(self._arrive[-1]) + self.dwell_s

    def dwell_window(self, index: int) -> Tuple[float, float]:
        """Return (arrival, departure) times at stop ``index``."""
        start = float(self._arrive[index])
        return start, start + self.dwell_s

    def stop_at(self, t_s: float) -> Optional[int]:
        """Return the index of the stop the robot is dwelling at, None while driving."""
        i = self._segment(t_s)
        if t_s < self._arrive[i] + self.dwell_s or i == len(self._stops) - 1:
            return i
        return None

    def pose_at(self, t_s: float) -> Pose:
        """Return ``T_room_base`` at time ``t_s`` (base on the floor, z = 0)."""
        i = self._segment(t_s)
        leave = self._arrive[i] + self.dwell_s
        if t_s < leave or i == len(self._stops) - 1:
            return self._stops[i].pose()
        a, b = self._stops[i], self._stops[i + 1]
        s = (t_s - leave) / (self._arrive[i + 1] - leave)
        x, y = (1.0 - s) * np.asarray(a.position) + s * np.asarray(b.position)
        heading = a.heading + _wrap(b.heading - a.heading) * 0.5 * (1.0 - math.cos(math.pi * s))
        return _base_pose(float(x), float(y), heading)

    def _segment(self, t_s: float) -> int:
        """Return the last stop reached at ``t_s`` (0 before the start)."""
        if not math.isfinite(t_s):
            raise ValueError(f'time must be a finite number, got {t_s!r}')
        return max(int(np.searchsorted(self._arrive, t_s, side='right')) - 1, 0)

    @staticmethod
    def facing_cards(room: Room, stops: Sequence[Tuple[Sequence[float], int]],
                     heading_spread_deg: float = 0.0, seed: int = 7, mode: str = 'stops',
                     dwell_s: float = DEFAULT_DWELL_S, speed_m_s: float = DEFAULT_SPEED_M_S,
                     max_yaw_rate_rad_s: float = DEFAULT_YAW_RATE_RAD_S) -> 'SimRoute':
        """
        Build a route from (x, y) positions and card numbers of ``room``.

        At each stop the base faces the card's centre, turned by a uniform
        random angle within +-``heading_spread_deg`` (drawn from ``seed``).
        """
        cards = {card.ids.pattern: card for card in room.cards}
        rng = np.random.default_rng(seed)
        out = []
        for position, number in stops:
            if number not in cards:
                raise CodeError(f'sim route: floor {room.floor} room {room.room} has no card '
                                f'{number}')
            target = cards[number].T_room_card.t
            heading = math.atan2(target[1] - position[1], target[0] - position[0])
            heading += math.radians(rng.uniform(-heading_spread_deg, heading_spread_deg))
            out.append(RouteStop((float(position[0]), float(position[1])), heading, number))
        return SimRoute(out, mode, dwell_s, speed_m_s, max_yaw_rate_rad_s)

    @staticmethod
    def paper_route(mode: str = 'stops', dwell_s: float = DEFAULT_DWELL_S,
                    speed_m_s: float = DEFAULT_SPEED_M_S, seed: int = 7, n_stops: int = 30,
                    max_yaw_rate_rad_s: float = DEFAULT_YAW_RATE_RAD_S,
                    building: Optional[BuildingMap] = None) -> 'SimRoute':
        """
        Return the paper's route (``paper_setup.route``) through floor 1 room 3.

        The base stands under the route's camera positions with the headings
        of ``bags.sim_stops`` for the same seed (the same recording).
        """
        stops = route()
        if not 1 <= n_stops <= len(stops):
            raise ConfigError(f'sim route: the paper route has {len(stops)} stops, asked for '
                              f'{n_stops}')
        room = (building or load_building()).room(PAPER_FLOOR, PAPER_ROOM)
        return SimRoute.facing_cards(room, [(p[:2], n) for p, n in stops[:n_stops]],
                                     HEADING_SPREAD_DEG, seed, mode, dwell_s, speed_m_s,
                                     max_yaw_rate_rad_s)


# Scene -------------------------------------------------------------------------------


class SimScene:
    """
    A room of the building as the head's camera sees it, and the ground truth.

    ``options``: the look of the images (default :data:`SIM_RENDER_OPTIONS`);
    its seed is ignored (each render takes one). The background must be
    uniform (``white`` or ``black``), with a light gradient below 1, no
    occluders and no shot noise: the background is rendered once. Not
    thread-safe (per-size caches).
    """

    def __init__(self, building: Optional[BuildingMap] = None,
                 pattern: Optional[PatternConfig] = None, floor: int = PAPER_FLOOR,
                 room: int = PAPER_ROOM, head: Optional[HeadGeometry] = None,
                 options: RenderOptions = SIM_RENDER_OPTIONS) -> None:
        self._renderer = BoxRenderer(options)
        self.pattern = pattern if pattern is not None else load_pattern_config()
        self.building = building if building is not None else load_building(None, self.pattern)
        self.room: Room = self.building.room(floor, room)
        self.head = head or HeadGeometry()
        self.options = options
        self._cards: Dict[int, MappedCard] = {c.ids.pattern: c for c in self.room.cards}
        # Card textures are built once: the sim renders the same cards every frame.
        self._faces = {number: UncodedFace(DotCardTexture(self.pattern, card.code))
                       for number, card in self._cards.items()}

    @property
    def card_numbers(self) -> List[int]:
        """Return the numbers of the room's cards."""
        return sorted(self._cards)

    def card(self, number: int) -> MappedCard:
        """Return a card of the room by number; CodeError if the room has none."""
        try:
            return self._cards[number]
        except KeyError:
            raise CodeError(f'sim: floor {self.room.floor} room {self.room.room} has no card '
                            f'{number}') from None

    def true_camera_pose(self, T_room_base: Pose, pan: float, tilt: float) -> Pose:
        """Return ``T_room_camera`` of the optical frame at these head angles (rad)."""
        return T_room_base @ self.head.T_base_camera(pan, tilt)

    def card_angles(self, T_room_base: Pose, pan: float, tilt: float, card_number: int
                    ) -> Tuple[float, float]:
        """
        Return the head motion (pan, tilt, rad) that puts the card's centre on the optical axis.

        REP 103 signs: + pan = turn left, + tilt = look up; the pan error is
        wrapped to [-pi, pi). Exact for the head's offsets
        (``HeadGeometry.aim_angles``); not clipped to the travel limits.
        """
        centre = self.card(card_number).T_room_card.t
        aim_pan, aim_tilt = self.head.aim_angles(T_room_base.inverse().apply(centre[None])[0])
        return _wrap(aim_pan - pan), _wrap(aim_tilt - tilt)

    def visible_cards(self, T_room_base: Pose, pan: float, tilt: float, camera: CameraModel
                      ) -> List[int]:
        """Return the numbers of the cards whose centre is in front and inside the image."""
        T_camera_room = self.true_camera_pose(T_room_base, pan, tilt).inverse()
        out = []
        for number, card in sorted(self._cards.items()):
            centre = T_camera_room.apply(card.T_room_card.t[None])
            if centre[0, 2] > NEAR_PLANE:
                u, v = camera.project(centre)[0]
                if -0.5 <= u < camera.width - 0.5 and -0.5 <= v < camera.height - 0.5:
                    out.append(number)
        return out

    def render(self, T_room_base: Pose, pan: float, tilt: float, camera: CameraModel,
               seed: int = 0) -> np.ndarray:
        """Return the BGR uint8 image the head's camera sees (deterministic for a seed)."""
        T_camera_room = self.true_camera_pose(T_room_base, pan, tilt).inverse()
        cards = [BoxCard(T_camera_room @ card.T_room_card, self._faces[number])
                 for number, card in self._cards.items()]
        return self._renderer.render(camera, cards, seed)
