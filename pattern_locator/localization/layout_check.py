"""
Does a building's card layout keep a card in view? A check before the robot drives.

ROS-free. The gaze planner (``gaze.GazePlanner``) predicts, from the
building map alone, which cards the head could aim at from a base pose:
in range, not too oblique, inside the pan/tilt travel, with a line of
sight inside the room's space. Where it predicts none, the robot has no
fix until it has moved on (the driver searches), so the places a route
crosses with no card predicted are where fix coverage is lost whatever
the detector does. :func:`check_route` walks a route (the base facing
along each leg, and turning in place at each corner) and returns its
blind stretches; :func:`check_rooms` samples every room of a floor on a
grid and a set of headings.

The planner is conservative (the map has no walls, so a card through a
door is not predicted), so a route the check passes can still see more
than it says, never less, as far as the map is true.
"""

from dataclasses import dataclass, fields
import math
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from .building import BuildingMap, load_building
from .gaze import GazeParameters, GazePlanner
from .head import HeadGeometry
from ..errors import ConfigError
from ..resources import read_yaml
from ..vision.geometry import Pose, yaw_of, yaw_pose

# Headings at which a turn in place at a corner is sampled.
TURN_STEP_RAD = math.radians(10.0)
# The command's room grid: places every half metre, eight headings.
ROOM_STEP_M = 0.5
ROOM_HEADINGS = 8


@dataclass(frozen=True)
class BlindStretch:
    """A part of a route where no card is predicted visible."""

    start_m: float                       # distance along the route
    end_m: float
    start_xy: Tuple[float, float]
    end_xy: Tuple[float, float]
    heading_deg: float                   # the base's heading where it starts
    turning: bool                        # a turn in place at a corner


@dataclass(frozen=True)
class RouteCheck:
    """The route's length, how much of it is blind, and where."""

    length_m: float
    samples: int
    blind_samples: int
    stretches: Tuple[BlindStretch, ...]

    @property
    def blind_m(self) -> float:
        """Return the blind length along the route (turns in place count nothing)."""
        return sum(s.end_m - s.start_m for s in self.stretches)

    def longest_m(self) -> float:
        """Return the longest blind stretch's length (0 when none)."""
        return max((s.end_m - s.start_m for s in self.stretches), default=0.0)


@dataclass(frozen=True)
class RoomCheck:
    """One room sampled on a grid: places, views with a card, places blind at every heading."""

    floor: int
    room: int
    name: str
    places: int
    views: int
    views_with_card: int
    blind_places: Tuple[Tuple[float, float], ...]


def floor_height(building: BuildingMap, floor: int) -> float:
    """Return the floor's height in the building frame (its rooms' origin)."""
    heights = [room.T_building_room.t[2] for key, room in building.rooms.items()
               if key[0] == floor]
    if not heights:
        raise ConfigError(f'layout check: the map has no room on floor {floor}')
    return float(min(heights))


def route_poses(waypoints_xy: Sequence[Sequence[float]], z: float, step_m: float = 0.1
                ) -> List[Tuple[float, Pose, bool]]:
    """
    Return ``(distance along, base pose, turning)`` every ``step_m`` along the polyline.

    The base faces along each leg; at each corner it turns in place from one
    leg's heading to the next (sampled every 10 degrees, at the corner's
    distance).
    """
    points = np.asarray(waypoints_xy, dtype=float).reshape(-1, 2)
    if len(points) < 2 or not np.all(np.isfinite(points)) or not step_m > 0.0:
        raise ConfigError('layout check: a route needs two or more finite [x, y] waypoints')
    out: List[Tuple[float, Pose, bool]] = []
    along = 0.0
    previous: Optional[float] = None
    for a, b in zip(points[:-1], points[1:]):
        length = float(np.linalg.norm(b - a))
        if length < 1e-9:
            continue
        heading = math.atan2(b[1] - a[1], b[0] - a[0])
        if previous is not None:
            turn = math.remainder(heading - previous, 2.0 * math.pi)
            for k in range(1, int(abs(turn) / TURN_STEP_RAD)):
                out.append((along, yaw_pose(a[0], a[1], previous + math.copysign(
                    k * TURN_STEP_RAD, turn), z), True))
        n = max(int(math.ceil(length / step_m)), 1)
        for k in range(n):
            s = k / n
            out.append((along + s * length, yaw_pose(*(a + s * (b - a)), heading, z), False))
        along += length
        previous = heading
    if previous is None:
        raise ConfigError('layout check: a route needs two or more distinct waypoints')
    last = points[-1]
    out.append((along, yaw_pose(last[0], last[1], previous, z), False))
    return out


def check_route(planner: GazePlanner, waypoints_xy: Sequence[Sequence[float]], z: float,
                step_m: float = 0.1) -> RouteCheck:
    """Walk the route; return where no card is predicted visible."""
    poses = route_poses(waypoints_xy, z, step_m)
    stretches: List[BlindStretch] = []
    blind = 0
    current: Optional[List[Any]] = None
    for along, pose, turning in poses:
        if planner.options(pose):
            if current is not None:
                stretches.append(BlindStretch(*current))
                current = None
            continue
        blind += 1
        xy = (float(pose.t[0]), float(pose.t[1]))
        if current is None:
            heading = math.degrees(yaw_of(pose.R))
            current = [along, along, xy, xy, heading, turning]
        else:
            current[1], current[3] = along, xy
            current[5] = current[5] or turning
    if current is not None:
        stretches.append(BlindStretch(*current))
    length = poses[-1][0] if poses else 0.0
    return RouteCheck(length, len(poses), blind, tuple(stretches))


def check_rooms(planner: GazePlanner, building: BuildingMap, floor: int, step_m: float = 0.5,
                headings: int = 8, margin_m: float = 0.3) -> List[RoomCheck]:
    """
    Sample each sized room of ``floor`` on a grid (``margin_m`` off its walls) and headings.

    A place is blind when no heading predicts a card: a robot standing there
    cannot be located by turning its head alone.
    """
    if not step_m > 0.0 or headings < 1:
        raise ConfigError('layout check: the grid step must be > 0 and headings >= 1')
    out = []
    angles = [2.0 * math.pi * k / headings for k in range(headings)]
    for (f, r), room in sorted(building.rooms.items()):
        if f != floor or room.size is None:
            continue
        sx, sy = float(room.size[0]), float(room.size[1])
        xs = np.arange(margin_m, sx - margin_m + 1e-9, step_m) if sx > 2 * margin_m else [sx / 2]
        ys = np.arange(margin_m, sy - margin_m + 1e-9, step_m) if sy > 2 * margin_m else [sy / 2]
        places = views = seen = 0
        blind: List[Tuple[float, float]] = []
        room_yaw = yaw_of(room.T_building_room.R)
        for x in xs:
            for y in ys:
                p = room.T_building_room.apply(np.array([[x, y, 0.0]]))[0]
                places += 1
                here = 0
                for a in angles:
                    views += 1
                    if planner.options(yaw_pose(p[0], p[1], room_yaw + a, p[2])):
                        here += 1
                seen += here
                if here == 0:
                    blind.append((round(float(p[0]), 2), round(float(p[1]), 2)))
        out.append(RoomCheck(f, r, room.name or '', places, views, seen, tuple(blind)))
    return out


def locator_parameters(data: Mapping[str, Any]) -> Dict[str, Any]:
    """Return the ``ros__parameters`` of a locator params file's (first) node section."""
    if not isinstance(data, Mapping):
        raise ConfigError('layout check: the params file is not a mapping of node sections')
    for key, section in data.items():
        if isinstance(section, Mapping) and isinstance(section.get('ros__parameters'), Mapping):
            return dict(section['ros__parameters'])
    raise ConfigError('layout check: the params file has no ros__parameters section')


def head_and_gaze(params: Mapping[str, Any]) -> Tuple[HeadGeometry, GazeParameters]:
    """Return the head geometry and gaze parameters a locator params file gives."""
    try:
        head = HeadGeometry(
            base_to_pan_xyz=tuple(params.get('head.base_to_pan_xyz', (0.0, 0.0, 1.0))),
            pan_to_tilt_xyz=tuple(params.get('head.pan_to_tilt_xyz', (0.0, 0.0, 0.05))),
            tilt_to_optical_xyz=tuple(params.get('head.tilt_to_optical_xyz',
                                                 (0.03, 0.0, 0.05))),
            mount_pitch_rad=math.radians(float(params.get('head.mount_pitch_deg', 0.0))))
        names = {f.name for f in fields(GazeParameters)}
        gaze = GazeParameters(**{k[len('gaze.'):]: float(v) for k, v in params.items()
                                 if k.startswith('gaze.') and k[len('gaze.'):] in names})
    except (TypeError, ValueError) as error:
        raise ConfigError(f'layout check: bad head or gaze parameter: {error}') from None
    return head, gaze


def read_route(spec: str) -> Tuple[List[Tuple[float, float]], Optional[int], str]:
    """
    Return ``(waypoints, floor or None, name)`` from ``FILE`` or ``FILE:NAME``.

    The file holds a list of ``[x, y]`` (building frame, metres), or a
    mapping with ``waypoints:`` and an optional ``floor:``, or a sim floor
    file's ``routes:`` (``config/sim_floor.yaml``: waypoints ``{xy: [x, y]}``;
    NAME picks one when it has several).
    """
    path, _, name = spec.partition(':') if not Path(spec).is_file() else (spec, '', '')
    data = read_yaml(path, 'the route')
    floor = data.get('floor') if isinstance(data, Mapping) else None
    if isinstance(data, Mapping) and isinstance(data.get('routes'), Mapping):
        routes = data['routes']
        if not name and len(routes) == 1:
            name = next(iter(routes))
        if name not in routes:
            raise ConfigError(f'{path}: name a route as {path}:NAME, one of '
                              f'{", ".join(map(str, routes))}')
        data = routes[name]
    elif isinstance(data, Mapping):
        data = data.get('waypoints')
    points = []
    for item in data if isinstance(data, list) else [None]:
        xy = item.get('xy') if isinstance(item, Mapping) else item
        try:
            x, y = (float(v) for v in xy)
        except (TypeError, ValueError):
            raise ConfigError(f'{path}: a waypoint must be [x, y] or {{xy: [x, y]}}, got '
                              f'{item!r}') from None
        points.append((x, y))
    if isinstance(floor, bool) or not (floor is None or isinstance(floor, int)):
        raise ConfigError(f'{path}: floor must be an integer, got {floor!r}')
    return points, floor, name or Path(path).stem


def check_layout_main(map_path: str, routes: Sequence[str], params_path: str,
                      floor: Optional[int], step_m: float, max_blind_m: float,
                      rooms: bool) -> int:
    """``pattern-locator check-layout``: print the checks; 1 if a route is blind too long."""
    building = load_building(map_path)
    head, gaze = head_and_gaze(locator_parameters(read_yaml(params_path, 'the locator params')))
    planner = GazePlanner(building, head, gaze)
    floors = sorted({key[0] for key in building.rooms})
    failed = False
    checked_floors = set()
    for spec in routes:
        waypoints, route_floor, name = read_route(spec)
        on = floor if floor is not None else route_floor
        if on is None:
            if len(floors) != 1:
                raise ConfigError(f'check-layout: the map has floors {floors}: say --floor')
            on = floors[0]
        checked_floors.add(on)
        result = check_route(planner, waypoints, floor_height(building, on), step_m)
        longest = result.longest_m()
        verdict = 'ok' if longest <= max_blind_m else 'BLIND'
        failed |= verdict != 'ok'
        print(f'route {name} (floor {on}): {result.length_m:.1f} m, no card predicted over '
              f'{result.blind_m:.1f} m ({100.0 * result.blind_samples / result.samples:.1f} % '
              f'of {result.samples} places), longest {longest:.1f} m: {verdict}')
        for s in result.stretches:
            kind = ' turning in place' if s.turning else ''
            print(f'  {s.start_m:6.1f}-{s.end_m:6.1f} m  ({s.start_xy[0]:.1f}, '
                  f'{s.start_xy[1]:.1f}) -> ({s.end_xy[0]:.1f}, {s.end_xy[1]:.1f})  heading '
                  f'{s.heading_deg:.0f} deg{kind}')
    if rooms or not routes:
        for f in ([floor] if floor is not None else sorted(checked_floors) or floors):
            print(f'floor {f}: views with a card predicted (places x {ROOM_HEADINGS} '
                  f'headings, grid {ROOM_STEP_M:g} m), places with none at any heading')
            for r in check_rooms(planner, building, f, ROOM_STEP_M, ROOM_HEADINGS):
                share = 100.0 * r.views_with_card / r.views if r.views else math.nan
                blind = ', '.join(f'({x:.1f}, {y:.1f})' for x, y in r.blind_places[:4])
                more = f' +{len(r.blind_places) - 4}' if len(r.blind_places) > 4 else ''
                print(f'  room {r.room:3d} {r.name[:28]:28s} {share:5.1f} %  blind places '
                      f'{len(r.blind_places)}/{r.places} {blind}{more}')
    return 1 if failed else 0


__all__ = ['BlindStretch', 'check_layout_main', 'check_rooms', 'check_route', 'floor_height',
           'head_and_gaze', 'locator_parameters', 'read_route', 'RoomCheck', 'route_poses',
           'RouteCheck']
