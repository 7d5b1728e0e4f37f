"""
The simulated world of the ``sim`` node: a robot's route through a room and its camera's view.

ROS-free. :class:`SimRoute` is the robot base's trajectory over time (the
paper's 30 stops, still or driven between); :class:`SimScene` renders what
the pan/tilt head's camera sees of a room of the building map and gives the
ground truth (camera pose, head motion that would centre a card).

Rendering is fast enough for a live node (640x480 at tens of frames per
second on one core): the background (painted wall, light gradient, colour
cast, gamma) is rendered once per image size, and each frame only renders
the pixel boxes that can show a card, with ``render.render_scene`` and a
camera cropped to the box (exact: cropping shifts the principal point only,
and the light gradient is re-expressed for the box). Sensor noise outside
the boxes comes from a precomputed noise tile at a random offset.
"""

from dataclasses import dataclass, replace
import functools
import math
from typing import Dict, List, Optional, Sequence, Tuple

import cv2
import numpy as np

from .paper_setup import route
from .render import (CardPlacement, clip_in_front, DotCardTexture, NEAR_PLANE, render_scene,
                     RenderOptions)
from ..card.pattern import load_pattern_config, PatternConfig
from ..errors import CodeError, ConfigError, ImageError
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
# A box bigger than this many sub-samples (a close card, a long focal length) gets
# fewer sub-samples per pixel, so that no frame takes much longer than the others;
# big cards need them least.
MAX_BOX_SAMPLES = 1 << 18
# Noise outside the boxes: a tile this much bigger than the image, read at a random offset.
_NOISE_PAD = 64
_NOISE_SEED = 20231114


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


class _UncodedFace:
    """
    A card's printed face that render_scene does not know as a coded card.

    So it skips the dot truth, the slowest part of a small render, which the
    simulator does not use.
    """

    def __init__(self, texture: DotCardTexture) -> None:
        self.size = texture.size
        self.reflectance = texture.reflectance


@functools.lru_cache(maxsize=16)
def _distortion_margin(width: int, height: int, K: bytes, D: bytes, model: str) -> float:
    """Return the largest distance (px) between a pixel and its undistorted pixel."""
    camera = CameraModel(width, height, np.frombuffer(K).reshape(3, 3), np.frombuffer(D),
                         model)
    if not camera.has_distortion:
        return 0.0
    # Radial and tangential distortion peak on the border, at the corners.
    u = np.linspace(-0.5, width - 0.5, 33)
    v = np.linspace(-0.5, height - 0.5, 25)
    border = np.vstack([np.column_stack([u, np.full_like(u, v[0])]),
                        np.column_stack([u, np.full_like(u, v[-1])]),
                        np.column_stack([np.full_like(v, u[0]), v]),
                        np.column_stack([np.full_like(v, u[-1]), v])])
    inner = np.stack(np.meshgrid(u[::4], v[::4]), axis=-1).reshape(-1, 2)
    pixels = np.vstack([border, inner])
    return float(np.max(np.linalg.norm(camera.undistort_pixels(pixels) - pixels, axis=1)))


def _overlap(a: Tuple[int, int, int, int], b: Tuple[int, int, int, int]) -> bool:
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]


def _merge_boxes(items: List[Tuple[Tuple[int, int, int, int], CardPlacement]]
                 ) -> List[Tuple[Tuple[int, int, int, int], List[CardPlacement]]]:
    """Group cards whose boxes overlap (one render each, so the nearest card wins)."""
    groups = [(box, [placement]) for box, placement in items]
    merged = True
    while merged:
        merged = False
        for i in range(len(groups)):
            for j in range(i + 1, len(groups)):
                (a, cards_a), (b, cards_b) = groups[i], groups[j]
                if _overlap(a, b):
                    groups[i] = ((min(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]),
                                  max(a[3], b[3])), cards_a + cards_b)
                    del groups[j]
                    merged = True
                    break
            if merged:
                break
    return groups


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
        if options.background not in ('white', 'black'):
            raise ConfigError(f'sim: the background must be white or black, got '
                              f'{options.background!r}')
        if options.occluders or options.shot_noise:
            raise ConfigError('sim: occluders and shot noise are not simulated')
        if not (math.isfinite(options.gradient) and abs(options.gradient) < 1.0):
            raise ConfigError(f'sim: gradient must be in (-1, 1), got {options.gradient!r}')
        self.pattern = pattern if pattern is not None else load_pattern_config()
        self.building = building if building is not None else load_building(None, self.pattern)
        self.room: Room = self.building.room(floor, room)
        self.head = head or HeadGeometry()
        self.options = options
        self._cards: Dict[int, MappedCard] = {c.ids.pattern: c for c in self.room.cards}
        # Card textures are built once: the sim renders the same cards every frame.
        self._faces = {number: _UncodedFace(DotCardTexture(self.pattern, card.code))
                       for number, card in self._cards.items()}
        self._frames: Dict[Tuple[int, int], Tuple[np.ndarray, np.ndarray, np.ndarray]] = {}

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
        rng = np.random.default_rng(seed)
        frame = self._noisy_background(camera.width, camera.height, rng)
        margin = _distortion_margin(camera.width, camera.height, camera.K.tobytes(),
                                    camera.D.tobytes(), camera.distortion_model)
        # Room for the blur around a card (OpenCV's float kernels reach 4 sigma).
        margin += 4.0 * self.options.defocus_sigma_px + self.options.motion_blur_px / 2.0 + 2.0
        items = []
        for number, card in self._cards.items():
            T_camera_card = T_camera_room @ card.T_room_card
            box = self._pixel_box(camera, T_camera_card, self._faces[number].size / 2.0,
                                  margin)
            if box is not None:
                items.append((box, CardPlacement(T_camera_card, self._faces[number])))
        for box, placements in _merge_boxes(items):
            x0, y0, x1, y1 = box
            frame[y0:y1, x0:x1] = self._render_box(camera, box, placements,
                                                   int(rng.integers(1 << 31)))
        if self.options.jpeg_quality is not None:
            ok, data = cv2.imencode('.jpg', frame,
                                    [cv2.IMWRITE_JPEG_QUALITY, self.options.jpeg_quality])
            if not ok:
                raise ImageError('sim: JPEG encoding failed')
            frame = cv2.imdecode(data, cv2.IMREAD_COLOR)
        return frame

    @staticmethod
    def _pixel_box(camera: CameraModel, T_camera_card: Pose, half: float, margin: float
                   ) -> Optional[Tuple[int, int, int, int]]:
        """
        Return the pixels (x0, y0, x1, y1), ends exclusive, that may show the card.

        The ideal (distortion-free) pixels of the card's visible outline,
        widened by ``margin``, which covers the distortion and the blur.
        """
        corners = np.array([[-half, half, 0.0], [half, half, 0.0], [half, -half, 0.0],
                            [-half, -half, 0.0]])
        front = clip_in_front(T_camera_card.apply(corners))
        if len(front) < 3:
            return None
        ideal = (front[:, :2] / front[:, 2:]) @ camera.K[:2, :2].T + camera.K[:2, 2]
        low = np.floor(ideal.min(axis=0) - margin)
        high = np.ceil(ideal.max(axis=0) + margin) + 1
        x0, y0 = (int(max(v, 0)) for v in low)
        x1, y1 = int(min(high[0], camera.width)), int(min(high[1], camera.height))
        return (x0, y0, x1, y1) if x0 < x1 and y0 < y1 else None

    def _render_box(self, camera: CameraModel, box: Tuple[int, int, int, int],
                    placements: List[CardPlacement], seed: int) -> np.ndarray:
        """Render the cards in a box of the image, as if the whole image were rendered."""
        x0, y0, x1, y1 = box
        w, h = x1 - x0, y1 - y0
        K = camera.K.copy()
        K[0, 2] -= x0
        K[1, 2] -= y0
        crop = CameraModel(w, h, K, camera.D, camera.distortion_model, camera.name)
        options = self.options
        # The light gradient is linear in the pixel position: re-express the
        # image's gradient about the box's centre and over the box's reach.
        angle = math.radians(options.gradient_angle_deg)
        ca, sa = math.cos(angle), math.sin(angle)
        reach = abs(ca) * (camera.width - 1) / 2.0 + abs(sa) * (camera.height - 1) / 2.0
        box_reach = abs(ca) * (w - 1) / 2.0 + abs(sa) * (h - 1) / 2.0
        offset = (ca * (x0 + (w - 1) / 2.0 - (camera.width - 1) / 2.0)
                  + sa * (y0 + (h - 1) / 2.0 - (camera.height - 1) / 2.0))
        light = 1.0 + options.gradient * offset / max(reach, 1e-9)
        s = int(options.supersample)
        while s > 1 and w * h * s * s > MAX_BOX_SAMPLES:
            s -= 1
        box_options = replace(options, supersample=s, gain=options.gain * light,
                              gradient=options.gradient * box_reach / (light * max(reach, 1e-9)),
                              jpeg_quality=None, seed=seed)
        return render_scene(crop, placements, box_options).image

    def _noisy_background(self, width: int, height: int, rng: np.random.Generator
                          ) -> np.ndarray:
        """Return a new image of the background with sensor noise."""
        key = (width, height)
        if key not in self._frames:
            blank = CameraModel.from_focal(width, height, 1000.0)
            clean = render_scene(blank, [], replace(self.options, noise_sigma=0.0,
                                                    jpeg_quality=None, seed=0)).image
            noise = np.rint(np.random.default_rng(_NOISE_SEED).normal(
                0.0, self.options.noise_sigma, (height + _NOISE_PAD, width + _NOISE_PAD, 3)))
            # Saturating uint8 add and subtract: the cheapest way to add noise per frame.
            self._frames[key] = (clean, np.clip(noise, 0, 255).astype(np.uint8),
                                 np.clip(-noise, 0, 255).astype(np.uint8))
        clean, up, down = self._frames[key]
        frame = clean.copy()
        if self.options.noise_sigma > 0:
            dy, dx = (int(v) for v in rng.integers(0, _NOISE_PAD + 1, 2))
            cv2.add(frame, up[dy:dy + height, dx:dx + width], dst=frame)
            cv2.subtract(frame, down[dy:dy + height, dx:dx + width], dst=frame)
        return frame
