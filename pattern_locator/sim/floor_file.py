"""
The sim's floor file (``config/sim_floor.yaml``): walls, doors, obstacles, routes.

ROS-free. :func:`load_floor_world` reads and checks the file (its format is
documented at its top) and returns a :class:`~.floor_world.FloorWorld`
with the cards of the file's building map; anything it does not understand
raises ConfigError naming the file and the place.
"""

import math
from pathlib import Path
from typing import Any, Optional, Sequence, Tuple, Union

import numpy as np
import yaml

from .drive import DriveLimits, Waypoint
from .floor_world import Door, FloorWorld, Obstacle, Wall, WorldCard
from ..card.pattern import load_pattern_config, PatternConfig
from ..errors import ConfigError
from ..localization.building import BuildingMap, load_building
from ..resources import config_path, read_yaml

_TOP_KEYS = ('building_map', 'floor', 'wall_height', 'default_thickness', 'walls',
             'obstacles', 'robot', 'drive', 'routes')
_WALL_KEYS = ('name', 'from', 'to', 'thickness', 'height', 'doors')
_DOOR_KEYS = ('centre', 'width', 'height')
_OBSTACLE_KEYS = ('name', 'centre', 'size', 'yaw_deg')
_ROBOT_KEYS = ('radius', 'height')
_WAYPOINT_KEYS = ('xy', 'speed', 'stop_s', 'face_deg')
_DRIVE_KEYS = ('max_speed_m_s', 'accel_m_s2', 'yaw_rate_rad_s', 'yaw_accel_rad_s2',
               'corner_radius_m', 'transition_m')


def load_floor_world(path: Optional[Union[str, Path]] = None,
                     pattern: Optional[PatternConfig] = None,
                     as_hung_seed: Optional[int] = None, as_hung_m: float = 0.05,
                     as_hung_deg: float = 3.0,
                     building: Optional[BuildingMap] = None) -> FloorWorld:
    """
    Load the sim's floor (default: the shipped ``config/sim_floor.yaml``).

    The cards are the floor's cards of the file's building map; each must
    hang flat on a wall or obstacle face (within 2.5 mm), else ConfigError.
    ``as_hung_seed``: hang every card off its mapped pose by a seeded error
    of up to ``as_hung_m`` (position) and ``as_hung_deg`` (rotation); None
    hangs them exactly where the map says. ``building``: the map, if the
    caller has already loaded the file's ``building_map``.
    """
    path = Path(path) if path is not None else config_path('sim_floor.yaml')
    source = str(path)
    pattern = pattern if pattern is not None else load_pattern_config()
    # libyaml when PyYAML has it: the pure Python parser takes a noticeable time.
    data = read_yaml(path, 'the sim floor', loader=getattr(yaml, 'CSafeLoader', yaml.SafeLoader))
    _keys(source, data, _TOP_KEYS, ('building_map', 'floor', 'walls'))
    map_path = Path(_text(source, 'building_map', data['building_map']))
    if not map_path.is_absolute():
        map_path = path.parent / map_path
    if building is None:
        building = load_building(map_path, pattern)
    floor = _integer(source, 'floor', data['floor'])
    rooms = [r for (f, _), r in building.rooms.items() if f == floor]
    if not rooms:
        raise ConfigError(f'{source}: floor {floor} has no rooms in {map_path}')
    heights = {round(float(r.T_building_room.t[2]), 6) for r in rooms}
    if len(heights) != 1:
        raise ConfigError(f'{source}: the rooms of floor {floor} in {map_path} are not at one '
                          f'height ({sorted(heights)}); the sim needs a level floor')
    z = heights.pop()
    wall_height = _positive(source, 'wall_height', data.get('wall_height', 2.5))
    thickness = _positive(source, 'default_thickness', data.get('default_thickness', 0.2))
    walls = [_wall(source, i, w, wall_height, thickness)
             for i, w in enumerate(_list(source, 'walls', data['walls']))]
    obstacles = [_obstacle(source, i, o)
                 for i, o in enumerate(_list(source, 'obstacles', data.get('obstacles') or []))]
    robot = data.get('robot') or {}
    _keys(f'{source}: robot', robot, _ROBOT_KEYS)
    radius = _positive(f'{source}: robot', 'radius', robot.get('radius', 0.3))
    robot_height = _positive(f'{source}: robot', 'height', robot.get('height', 1.3))
    drive = data.get('drive') or {}
    _keys(f'{source}: drive', drive, _DRIVE_KEYS)
    limits = DriveLimits(**{k: _number(f'{source}: drive', k, v) for k, v in drive.items()})
    routes_data = data.get('routes') or {}
    if not isinstance(routes_data, dict):
        raise ConfigError(f'{source}: routes must be a mapping name -> waypoints')
    routes = {str(name): _waypoints(source, str(name), wps)
              for name, wps in routes_data.items()}
    cards = [WorldCard(card, card.T_building_card) for r in rooms for card in r.cards]
    world = FloorWorld(building, pattern, floor, z, walls, obstacles, cards, routes, limits,
                       radius, robot_height, source)
    world.check_cards_hang_on_faces()
    if as_hung_seed is not None:
        world = world.as_hung(as_hung_seed, as_hung_m, as_hung_deg)
    return world


# Small readers ------------------------------------------------------------------------


def _keys(where: str, data: Any, allowed: Sequence[str], required: Sequence[str] = ()) -> None:
    if not isinstance(data, dict):
        raise ConfigError(f'{where}: expected a mapping with keys {", ".join(allowed)}, got '
                          f'{data!r}')
    for key in data:
        if key not in allowed:
            raise ConfigError(f'{where}: unknown key {key!r} (allowed: {", ".join(allowed)})')
    for key in required:
        if data.get(key) is None:
            raise ConfigError(f'{where}: missing {key!r}')


def _list(where: str, name: str, value: Any) -> list:
    if not isinstance(value, list):
        raise ConfigError(f'{where}: {name} must be a list, got {value!r}')
    return value


def _text(where: str, name: str, value: Any) -> str:
    if not isinstance(value, str) or not value:
        raise ConfigError(f'{where}: {name} must be text, got {value!r}')
    return value


def _integer(where: str, name: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ConfigError(f'{where}: {name} must be an integer, got {value!r}')
    return value


def _number(where: str, name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(
            value):
        raise ConfigError(f'{where}: {name} must be a number, got {value!r}')
    return float(value)


def _positive(where: str, name: str, value: Any) -> float:
    number = _number(where, name, value)
    if number <= 0.0:
        raise ConfigError(f'{where}: {name} must be positive, got {value!r}')
    return number


def _point(where: str, name: str, value: Any, n: int = 2) -> Tuple[float, ...]:
    if not isinstance(value, list) or len(value) != n:
        raise ConfigError(f'{where}: {name} must be [{", ".join("xyz"[:n])}], got {value!r}')
    return tuple(_number(where, name, v) for v in value)


def _wall(source: str, index: int, data: Any, height: float, thickness: float) -> Wall:
    where = f'{source}: walls[{index}]'
    _keys(where, data, _WALL_KEYS, ('name', 'from', 'to'))
    name = _text(where, 'name', data['name'])
    where = f'{source}: wall {name!r}'
    start, end = _point(where, 'from', data['from']), _point(where, 'to', data['to'])
    if math.dist(start, end) < 1e-6:
        raise ConfigError(f'{where}: from and to are the same point')
    wall = Wall(name, start, end, _positive(where, 'thickness',
                                            data.get('thickness', thickness)),
                _positive(where, 'height', data.get('height', height)))
    doors = []
    a, b = np.array(start), np.array(end)
    u = (b - a) / wall.length
    spans = []
    for k, door_data in enumerate(_list(where, 'doors', data.get('doors') or [])):
        here = f'{where}: doors[{k}]'
        _keys(here, door_data, _DOOR_KEYS, _DOOR_KEYS)
        door = Door(_point(here, 'centre', door_data['centre']),
                    _positive(here, 'width', door_data['width']),
                    _positive(here, 'height', door_data['height']))
        rel = np.array(door.centre) - a
        along, across = float(rel @ u), float(abs(rel[0] * u[1] - rel[1] * u[0]))
        if across > 0.01:
            raise ConfigError(f"{here}: the centre is {across:.2f} m off the wall's centre "
                              f'line')
        if along - door.width / 2.0 < 0.0 or along + door.width / 2.0 > wall.length:
            raise ConfigError(f'{here}: the door does not fit in the wall')
        if door.height > wall.height:
            raise ConfigError(f'{here}: the door is higher than the wall')
        spans.append((along - door.width / 2.0, along + door.width / 2.0))
        doors.append(door)
    spans.sort()
    for (_, right), (left, _) in zip(spans, spans[1:]):
        if left < right:
            raise ConfigError(f'{where}: doors overlap')
    return Wall(wall.name, wall.start, wall.end, wall.thickness, wall.height, tuple(doors))


def _obstacle(source: str, index: int, data: Any) -> Obstacle:
    where = f'{source}: obstacles[{index}]'
    _keys(where, data, _OBSTACLE_KEYS, ('name', 'centre', 'size'))
    name = _text(where, 'name', data['name'])
    where = f'{source}: obstacle {name!r}'
    size = _point(where, 'size', data['size'], 3)
    if min(size) <= 0.0:
        raise ConfigError(f'{where}: size must be positive, got {list(size)}')
    return Obstacle(name, _point(where, 'centre', data['centre'], 3), size,
                    _number(where, 'yaw_deg', data.get('yaw_deg', 0.0)))


def _waypoints(source: str, name: str, data: Any) -> Tuple[Waypoint, ...]:
    where = f'{source}: route {name}'
    out = []
    for k, w in enumerate(_list(where, 'the route', data)):
        here = f'{where}: waypoint {k}'
        _keys(here, w, _WAYPOINT_KEYS, ('xy',))
        face = w.get('face_deg')
        out.append(Waypoint(_point(here, 'xy', w['xy']),
                            _positive(here, 'speed', w.get('speed', 0.5)),
                            _number(here, 'stop_s', w.get('stop_s', 0.0)),
                            None if face is None else _number(here, 'face_deg', face)))
    if len(out) < 2:
        raise ConfigError(f'{where}: needs at least two waypoints')
    return tuple(out)
