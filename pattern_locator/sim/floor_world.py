"""
The simulated floor: walls with doors, obstacles and the map's cards, and what hides what.

ROS-free. A :class:`FloorWorld` is the physical truth the simulator renders
and drives through; the locator never sees it. Its walls, doors, obstacles
and routes come from the sim's own file (``config/sim_floor.yaml``, read by
``floor_file``); its cards are the building map's cards of one floor, hung
where the map says or, with ``as_hung_seed``, "as hung": each card off its
mapped pose by a seeded error of up to ``as_hung_m`` and ``as_hung_deg``,
never into its wall (what a survey of the real building would find).

Geometry: every wall, the part of a wall beside or above a door, and every
obstacle is a solid box standing upright (turned about z only). A line of
sight is blocked when it passes through a box (:meth:`FloorWorld.blocked`).
What a box hides of a card, seen from a camera, is the box's shadow on the
card's plane cast from the camera's centre: a convex polygon in the card
frame (:meth:`FloorWorld.occluders`), which the renderer paints in the
wall's colour. Doors are openings through their wall up to the door's
height, so through a door only what the jambs and the lintel leave is seen.
"""

from dataclasses import dataclass, field
import math
from typing import Dict, List, Optional, Sequence, Tuple, Union

import cv2
import numpy as np

from .drive import DriveLimits, DriveRoute, Waypoint
from ..card.pattern import Code, Ids, load_pattern_config, PatternConfig
from ..errors import CodeError, ConfigError
from ..localization.building import BuildingMap, MappedCard, Room
from ..vision.geometry import Pose, rodrigues

# A card's mounting face must lie within this of the card's plane (map poses).
ON_FACE_TOLERANCE_M = 0.0025
# What lies closer than this in front of a card's plane does not hide it (its own wall).
_FACE_MARGIN_M = 0.001
# Lines of sight stop this short of their end (a point on a face is not behind it).
_END_MARGIN_M = 0.002
# The occluder window: the card square widened by this on every side.
_WINDOW_MARGIN_M = 0.01


@dataclass(frozen=True)
class Door:
    """An opening through a wall: centre on the wall's centre line, width, height (m)."""

    centre: Tuple[float, float]
    width: float
    height: float


@dataclass(frozen=True)
class Wall:
    """A straight wall: centre line ``start`` -> ``end`` (building x, y), thickness, height."""

    name: str
    start: Tuple[float, float]
    end: Tuple[float, float]
    thickness: float
    height: float
    doors: Tuple[Door, ...] = ()

    @property
    def length(self) -> float:
        """Return the length of the wall's centre line."""
        return math.dist(self.start, self.end)


@dataclass(frozen=True)
class Obstacle:
    """An upright box: centre (x, y, height of its centre above the floor), size, yaw."""

    name: str
    centre: Tuple[float, float, float]
    size: Tuple[float, float, float]
    yaw_deg: float = 0.0


@dataclass(frozen=True, eq=False)
class WorldCard:
    """
    A card on the floor: its map entry and where it really hangs.

    ``T_building_card`` is the truth (the map's pose unless hung "as hung");
    ``map_card.T_building_card`` is what the locator believes.
    """

    map_card: MappedCard
    T_building_card: Pose

    @property
    def ids(self) -> Ids:
        """Return the card's (floor, room, pattern)."""
        return self.map_card.ids

    @property
    def code(self) -> Code:
        """Return the card's colour code."""
        return self.map_card.code


@dataclass(frozen=True, eq=False)
class Solids:
    """
    Upright boxes, as arrays: centre (M, 3), half sizes (M, 3), yaw (M,), names.

    Centres are in the building frame (z included); half sizes along the
    box's own x (along a wall), y (across it) and z.
    """

    centre: np.ndarray
    half: np.ndarray
    yaw: np.ndarray
    names: Tuple[str, ...]
    low: np.ndarray = field(init=False)
    high: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        reach_x = np.abs(c) * self.half[:, 0] + np.abs(s) * self.half[:, 1]
        reach_y = np.abs(s) * self.half[:, 0] + np.abs(c) * self.half[:, 1]
        reach = np.column_stack([reach_x, reach_y, self.half[:, 2]])
        object.__setattr__(self, 'low', self.centre - reach)
        object.__setattr__(self, 'high', self.centre + reach)

    def __len__(self) -> int:
        return len(self.names)

    def to_local(self, points: np.ndarray, index: Union[int, np.ndarray]) -> np.ndarray:
        """Return building points (..., 3) in the frame of box ``index`` (broadcast)."""
        d = points - self.centre[index]
        c, s = np.cos(self.yaw[index]), np.sin(self.yaw[index])
        return np.stack([c * d[..., 0] + s * d[..., 1], -s * d[..., 0] + c * d[..., 1],
                         d[..., 2]], axis=-1)

    def corners(self, index: int) -> np.ndarray:
        """Return the 8 corners of box ``index`` in the building frame."""
        signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)],
                         dtype=float)
        local = signs * self.half[index]
        c, s = math.cos(self.yaw[index]), math.sin(self.yaw[index])
        R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        return local @ R.T + self.centre[index]


# The 6 faces of a box as indices into Solids.corners (outward normals in local axes).
_FACES = (((0, 1, 3, 2), (-1, 0, 0)), ((4, 6, 7, 5), (1, 0, 0)),
          ((0, 4, 5, 1), (0, -1, 0)), ((2, 3, 7, 6), (0, 1, 0)),
          ((0, 2, 6, 4), (0, 0, -1)), ((1, 5, 7, 3), (0, 0, 1)))


class FloorWorld:
    """
    One floor: solids (walls, door jambs and lintels, obstacles), cards, rooms, routes.

    Build it with ``floor_file.load_floor_world`` (the sim's file) or
    :meth:`from_room` (one room of a map, four plain walls, no routes).
    """

    def __init__(self, building: BuildingMap, pattern: PatternConfig, floor: int, z: float,
                 walls: Sequence[Wall], obstacles: Sequence[Obstacle],
                 cards: Sequence[WorldCard], routes: Optional[Dict[str, Tuple[Waypoint, ...]]]
                 = None, limits: DriveLimits = DriveLimits(), robot_radius: float = 0.3,
                 robot_height: float = 1.3, source: str = 'floor') -> None:
        self.building = building
        self.pattern = pattern
        self.floor = int(floor)
        self.z = float(z)
        self.walls = tuple(walls)
        self.obstacles = tuple(obstacles)
        self.cards = tuple(sorted(cards, key=lambda c: c.ids.as_tuple()))
        self.routes = dict(routes or {})
        self.limits = limits
        self.robot_radius = float(robot_radius)
        self.robot_height = float(robot_height)
        self.source = source
        self.rooms: Tuple[Room, ...] = tuple(r for (f, _), r in sorted(building.rooms.items())
                                             if f == self.floor)
        self.solids = build_solids(self.walls, self.obstacles, self.z)
        self._by_ids = {c.ids.as_tuple(): c for c in self.cards}
        self._half = float(pattern.card_size) / 2.0
        self._built_routes: Dict[Tuple[str, DriveLimits], DriveRoute] = {}

    def __repr__(self) -> str:
        return (f'FloorWorld(floor {self.floor}, {len(self.walls)} walls, '
                f'{sum(len(w.doors) for w in self.walls)} doors, {len(self.obstacles)} '
                f'obstacles, {len(self.rooms)} rooms, {len(self.cards)} cards)')

    @staticmethod
    def from_room(building: BuildingMap, floor: int, room: int,
                  pattern: Optional[PatternConfig] = None, thickness: float = 0.2,
                  height: float = 2.5) -> 'FloorWorld':
        """
        Return a world of one room of ``building``: its box's four walls and its cards.

        The room needs a size in the map and must stand upright. Cards hang
        where the map says. No routes (drive the room with ``world.SimRoute``).
        """
        pattern = pattern if pattern is not None else load_pattern_config()
        r = building.room(floor, room)
        if r.size is None:
            raise ConfigError(f'sim: floor {floor} room {room} has no size in the map: its '
                              f'walls are unknown')
        T = r.T_building_room
        if abs(T.R[2, 2] - 1.0) > 1e-9:
            raise ConfigError(f'sim: floor {floor} room {room} does not stand upright')
        length, width, _ = r.size
        h = thickness / 2.0
        corners_room = [(-h, -h), (length + h, -h), (length + h, width + h), (-h, width + h)]
        xy = [tuple(T.apply(np.array([[x, y, 0.0]]))[0, :2]) for x, y in corners_room]
        names = ('wall y = 0', 'wall x = length', 'wall y = width', 'wall x = 0')
        walls = []
        for k, name in enumerate(names):
            a, b = np.array(xy[k]), np.array(xy[(k + 1) % 4])
            # Extend each wall over the corner squares so that the corners close.
            u = (b - a) / np.linalg.norm(b - a)
            walls.append(Wall(name, tuple(a - h * u), tuple(b + h * u), thickness, height))
        cards = [WorldCard(c, c.T_building_card) for c in r.cards]
        return FloorWorld(building, pattern, floor, float(T.t[2]), walls, [], cards,
                          source=f'{building.source or "building"}: floor {floor} room {room}')

    def as_hung(self, seed: int, max_m: float = 0.05, max_deg: float = 3.0) -> 'FloorWorld':
        """
        Return this world with every card off its mapped pose, as hung in a real building.

        Each card turns by up to ``max_deg`` and shifts by up to ``max_m``
        (:func:`as_hung_offset`, drawn from ``seed`` in ids order); the map,
        walls and routes are this world's.
        """
        for name, value in (('max_m', max_m), ('max_deg', max_deg)):
            if not (math.isfinite(value) and value >= 0.0):
                raise ConfigError(f'sim: as hung {name} must be a number >= 0, got {value!r}')
        rng = np.random.default_rng(seed)
        cards = [WorldCard(c.map_card, c.map_card.T_building_card @ as_hung_offset(
            rng, self._half, max_m, max_deg)) for c in self.cards]
        return FloorWorld(self.building, self.pattern, self.floor, self.z, self.walls,
                          self.obstacles, cards, self.routes, self.limits, self.robot_radius,
                          self.robot_height, self.source)

    def check_cards_hang_on_faces(self) -> None:
        """
        Raise ConfigError unless every card hangs flat on a face of a solid.

        Each corner of a card's mapped square must lie within 2.5 mm of a
        wall or obstacle face that faces the card's way (a typo in the map
        or the world file puts a card in mid-air, in a doorway or in a wall).
        """
        half = self._half
        for world_card in self.cards:
            card = world_card.map_card
            T = card.T_building_card
            normal = T.R[:, 2]
            corners = T.apply(np.array([[-half, -half, 0.0], [half, -half, 0.0],
                                        [half, half, 0.0], [-half, half, 0.0]]))
            every = np.arange(len(self.solids))
            for corner in corners:
                # Just behind the corner is inside a solid; just in front, nothing is.
                behind = self.solids.to_local(corner - ON_FACE_TOLERANCE_M * normal, every)
                ahead = self.solids.to_local(corner + ON_FACE_TOLERANCE_M * normal, every)
                inside = np.all(np.abs(behind) <= self.solids.half + 1e-9, axis=1)
                blocked = np.all(np.abs(ahead) <= self.solids.half + 1e-9, axis=1)
                if not inside.any() or blocked.any():
                    raise ConfigError(
                        f'{self.source}: {card.label()} does not hang flat on a wall or '
                        f'obstacle face (corner at {np.round(corner, 3).tolist()}; within '
                        f'{ON_FACE_TOLERANCE_M * 1000:.1f} mm)')

    # Cards and rooms -------------------------------------------------------------------

    def card(self, ids: Union[Ids, Tuple[int, int, int]]) -> WorldCard:
        """Return a card by ids; CodeError if the floor has no such card."""
        key = ids.as_tuple() if isinstance(ids, Ids) else tuple(ids)
        try:
            return self._by_ids[key]
        except KeyError:
            raise CodeError(f'sim: the floor has no card {key}') from None

    def room_at(self, xy: Sequence[float]) -> Optional[Room]:
        """Return the map's room whose box holds the point (x, y), None in a wall or door."""
        number = int(self.rooms_at(np.asarray(xy, dtype=float).reshape(1, 2))[0])
        return self.building.room(self.floor, number) if number else None

    def rooms_at(self, xy: np.ndarray) -> np.ndarray:
        """Return the room number holding each point (N, 2), 0 for none."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        out = np.zeros(len(xy), dtype=int)
        points = np.column_stack([xy, np.full(len(xy), self.z)])
        for room in self.rooms:
            if room.size is None:
                continue
            local = room.T_building_room.inverse().apply(points)
            inside = ((local[:, 0] >= 0.0) & (local[:, 0] <= room.size[0])
                      & (local[:, 1] >= 0.0) & (local[:, 1] <= room.size[1]) & (out == 0))
            out[inside] = room.room
        return out

    def bounds(self) -> Tuple[float, float, float, float]:
        """Return (xmin, ymin, xmax, ymax) of the solids."""
        return (float(self.solids.low[:, 0].min()), float(self.solids.low[:, 1].min()),
                float(self.solids.high[:, 0].max()), float(self.solids.high[:, 1].max()))

    # Routes ----------------------------------------------------------------------------

    def route(self, name: str, limits: Optional[DriveLimits] = None) -> DriveRoute:
        """
        Return a route of the file, built and checked against the walls.

        ``limits``: the base's limits (default: the file's). ConfigError when
        the route is unknown or passes closer to a solid than the robot's
        radius (a typo in a waypoint).
        """
        limits = limits if limits is not None else self.limits
        key = (name, limits)
        if key in self._built_routes:
            return self._built_routes[key]
        if name not in self.routes:
            known = ', '.join(sorted(self.routes)) or 'none'
            raise ConfigError(f'{self.source}: no route {name!r} (routes: {known})')
        route = DriveRoute(self.routes[name], limits, self.z, name)
        track = route.track(0.05)
        gap = self.clearance(track[:, 1:3])
        worst = int(np.argmin(gap))
        if gap[worst] < self.robot_radius:
            raise ConfigError(
                f'{self.source}: route {name} passes {gap[worst]:.2f} m from a wall or '
                f'obstacle at ({track[worst, 1]:.2f}, {track[worst, 2]:.2f}), t = '
                f'{track[worst, 0]:.1f} s; the robot needs {self.robot_radius:.2f} m')
        self._built_routes[key] = route
        return route

    def clearance(self, xy: np.ndarray) -> np.ndarray:
        """Return the distance (m) from each point (N, 2) to the nearest solid the robot hits."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        low = self.solids.low[:, 2] - self.z
        hits = low < self.robot_height
        if not hits.any():
            return np.full(len(xy), np.inf)
        index = np.flatnonzero(hits)
        points = np.column_stack([xy, np.full(len(xy), self.z)])[:, None, :]
        local = self.solids.to_local(points, index)
        half = self.solids.half[index]
        dx = np.maximum(np.abs(local[..., 0]) - half[:, 0], 0.0)
        dy = np.maximum(np.abs(local[..., 1]) - half[:, 1], 0.0)
        return np.hypot(dx, dy).min(axis=1)

    # Occlusion -------------------------------------------------------------------------

    def blocked(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """
        Return, for each segment ``a[i] -> b[i]`` (building frame), whether a solid cuts it.

        The last 2 mm before ``b`` do not count: a point on a face is seen
        from in front of the face.
        """
        a = np.asarray(a, dtype=float).reshape(-1, 3)
        b = np.asarray(b, dtype=float).reshape(-1, 3)
        length = np.linalg.norm(b - a, axis=1)
        end = np.clip(1.0 - _END_MARGIN_M / np.maximum(length, 1e-12), 0.0, 1.0)
        index = np.arange(len(self.solids))
        la = self.solids.to_local(a[:, None, :], index)
        lb = self.solids.to_local(b[:, None, :], index)
        d = lb - la
        half = self.solids.half[None, :, :]
        with np.errstate(divide='ignore', invalid='ignore'):
            t1 = (-half - la) / d
            t2 = (half - la) / d
        parallel = np.abs(d) < 1e-12
        outside = parallel & (np.abs(la) > half)
        t_low = np.where(parallel, -np.inf, np.minimum(t1, t2))
        t_high = np.where(parallel, np.inf, np.maximum(t1, t2))
        enter = t_low.max(axis=2)
        leave = t_high.min(axis=2)
        hit = ~outside.any(axis=2) & (enter < leave) & (leave > 0.0) & (enter < end[:, None])
        return hit.any(axis=1)

    def camera_in_front(self, card: WorldCard, centre: np.ndarray) -> bool:
        """Return whether the point (building frame) is on the card's printed side."""
        local = card.T_building_card.inverse().apply(np.asarray(centre, float)[None])[0]
        return bool(local[2] > _FACE_MARGIN_M)

    def occluders(self, card: WorldCard, centre: np.ndarray) -> List[np.ndarray]:
        """
        Return what hides the card from a camera whose centre is ``centre`` (building frame).

        Convex (N, 2) polygons in the card frame, clipped to the card square
        plus 1 cm: each solid's shadow on the card's plane from the camera's
        centre. Empty when nothing is in the way; call only for a camera in
        front of the card (:meth:`camera_in_front`).
        """
        T_card_building = card.T_building_card.inverse()
        c = T_card_building.apply(np.asarray(centre, float)[None])[0]
        if c[2] <= _FACE_MARGIN_M:
            raise ConfigError('sim: occluders need a camera in front of the card')
        h = self._half
        square = card.T_building_card.apply(np.array(
            [[-h, -h, 0.0], [h, -h, 0.0], [h, h, 0.0], [-h, h, 0.0]]))
        pyramid = np.vstack([square, np.asarray(centre, float)[None]])
        low, high = pyramid.min(axis=0), pyramid.max(axis=0)
        near = np.flatnonzero(np.all(self.solids.low <= high, axis=1)
                              & np.all(self.solids.high >= low, axis=1))
        window = h + _WINDOW_MARGIN_M
        # The card plane's shadow map is linear in homogeneous coordinates:
        # (x_h, y_h, w) = (x cz - cx z, y cz - cy z, cz - z) for a point (x, y, z).
        to_h = np.array([[c[2], 0.0, -c[0]], [0.0, c[2], -c[1]], [0.0, 0.0, -1.0]])
        offset = np.array([0.0, 0.0, c[2]])
        # Half-spaces g . (x_h, y_h, w) + g0 >= 0: in front of the card's plane,
        # before the camera's plane, inside the window.
        planes = [(np.array([0.0, 0.0, -1.0]), c[2] - _FACE_MARGIN_M),
                  (np.array([0.0, 0.0, 1.0]), -1e-9),
                  (np.array([1.0, 0.0, window]), 0.0), (np.array([-1.0, 0.0, window]), 0.0),
                  (np.array([0.0, 1.0, window]), 0.0), (np.array([0.0, -1.0, window]), 0.0)]
        out = []
        for index in near:
            corners = T_card_building.apply(self.solids.corners(int(index)))
            homogeneous = corners @ to_h.T + offset
            local_c = self.solids.to_local(np.asarray(centre, float), int(index))
            points = []
            for face, normal in _FACES:
                # Only faces that look at the camera make the box's shadow.
                k = int(np.flatnonzero(normal)[0])
                if normal[k] * local_c[k] <= self.solids.half[int(index), k]:
                    continue
                polygon = homogeneous[list(face)]
                for g, g0 in planes:
                    polygon = _clip(polygon, g, g0)
                    if len(polygon) == 0:
                        break
                points.extend(polygon)
            if len(points) < 3:
                continue
            points = np.array(points)
            xy = points[:, :2] / points[:, 2:]
            hull = cv2.convexHull(xy.astype(np.float32)).reshape(-1, 2).astype(np.float64)
            if len(hull) >= 3 and abs(cv2.contourArea(hull.astype(np.float32))) > 1e-8:
                out.append(hull)
        return out

    def visible_dots(self, card: WorldCard, centre: np.ndarray,
                     occluders: Optional[List[np.ndarray]] = None) -> np.ndarray:
        """Return, per dot of the card, whether the walls leave it in sight of ``centre``."""
        if not self.camera_in_front(card, centre):
            return np.zeros(self.pattern.n_dots, dtype=bool)
        if occluders is None:
            occluders = self.occluders(card, centre)
        dots = self.pattern.model_points()[:, :2]
        seen = np.ones(len(dots), dtype=bool)
        for polygon in occluders:
            seen &= ~_inside_convex(dots, polygon)
        return seen

    def hidden(self, card: WorldCard, occluders: List[np.ndarray]) -> bool:
        """Return whether one of ``occluders`` covers the whole card."""
        h = self._half
        square = np.array([[-h, -h], [h, -h], [h, h], [-h, h]])
        return any(_inside_convex(square, p, 1e-9).all() for p in occluders)


def _clip(polygon: np.ndarray, g: np.ndarray, g0: float) -> np.ndarray:
    """Clip a convex polygon (N, 3) to the half-space ``g . p + g0 >= 0``."""
    if len(polygon) == 0:
        return polygon
    value = polygon @ g + g0
    if np.all(value >= 0.0):
        return polygon
    out = []
    n = len(polygon)
    for i in range(n):
        p, q = polygon[i], polygon[(i + 1) % n]
        vp, vq = value[i], value[(i + 1) % n]
        if vp >= 0.0:
            out.append(p)
        if (vp >= 0.0) != (vq >= 0.0):
            out.append(p + (vp / (vp - vq)) * (q - p))
    return np.array(out).reshape(-1, 3)


def _inside_convex(points: np.ndarray, polygon: np.ndarray, tolerance: float = 0.0
                   ) -> np.ndarray:
    """Return which points (N, 2) lie inside a convex polygon (M, 2), either winding."""
    edges = np.roll(polygon, -1, axis=0) - polygon
    rel = points[:, None, :] - polygon[None, :, :]
    cross = edges[None, :, 0] * rel[..., 1] - edges[None, :, 1] * rel[..., 0]
    area = np.sum(polygon[:, 0] * np.roll(polygon[:, 1], -1)
                  - np.roll(polygon[:, 0], -1) * polygon[:, 1])
    sign = 1.0 if area >= 0 else -1.0
    scale = np.linalg.norm(edges, axis=1)[None, :]
    return np.all(sign * cross >= -tolerance * scale, axis=1)


def build_solids(walls: Sequence[Wall], obstacles: Sequence[Obstacle], z: float) -> Solids:
    """Cut the walls at their doors and return every box."""
    centres, halves, yaws, names = [], [], [], []

    def add(name: str, centre, half, yaw: float) -> None:
        centres.append(centre)
        halves.append(half)
        yaws.append(yaw)
        names.append(name)

    for wall in walls:
        a, b = np.array(wall.start), np.array(wall.end)
        length = wall.length
        u = (b - a) / length
        yaw = math.atan2(u[1], u[0])
        t = wall.thickness / 2.0
        # Spans along the wall (from, to, bottom, top): solid below/beside and lintels.
        openings = sorted((float((np.array(d.centre) - a) @ u), d) for d in wall.doors)
        cursor = 0.0
        spans = []
        for along, door in openings:
            left, right = along - door.width / 2.0, along + door.width / 2.0
            spans.append((cursor, left, 0.0, wall.height))
            if door.height < wall.height:
                spans.append((left, right, door.height, wall.height))
            cursor = right
        spans.append((cursor, length, 0.0, wall.height))
        for k, (s0, s1, h0, h1) in enumerate(spans):
            if s1 - s0 <= 1e-9:
                continue
            mid = a + u * (s0 + s1) / 2.0
            part = wall.name if len(spans) == 1 else f'{wall.name} [{k}]'
            add(part, (mid[0], mid[1], z + (h0 + h1) / 2.0),
                ((s1 - s0) / 2.0, t, (h1 - h0) / 2.0), yaw)
    for obstacle in obstacles:
        x, y, h = obstacle.centre
        sx, sy, sz = obstacle.size
        add(obstacle.name, (x, y, z + h), (sx / 2.0, sy / 2.0, sz / 2.0),
            math.radians(obstacle.yaw_deg))
    if not centres:
        return Solids(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), ())
    return Solids(np.array(centres, float), np.array(halves, float), np.array(yaws, float),
                  tuple(names))


def as_hung_offset(rng: np.random.Generator, half: float, max_m: float, max_deg: float
                   ) -> Pose:
    """
    Return a card's ``T_map_true``: a rotation of up to ``max_deg``, a shift of up to ``max_m``.

    The rotation's axis is uniform on the sphere and its angle uniform; the
    card then stands off its wall just enough for no corner to sink into
    it (a few mm), and slides in its plane by a uniform point of the disc
    that keeps the whole shift within ``max_m``.
    """
    axis = rng.standard_normal(3)
    axis /= np.linalg.norm(axis)
    R = rodrigues(axis * math.radians(rng.uniform(0.0, max_deg)))
    corners = np.array([[-half, -half, 0.0], [half, -half, 0.0], [half, half, 0.0],
                        [-half, half, 0.0]]) @ R.T
    standoff = max(0.0, 2.0 * _FACE_MARGIN_M - float(corners[:, 2].min()))
    radius = math.sqrt(max(max_m ** 2 - standoff ** 2, 0.0)) * math.sqrt(rng.uniform())
    angle = rng.uniform(0.0, 2.0 * math.pi)
    return Pose(R, np.array([radius * math.cos(angle), radius * math.sin(angle), standoff]))
