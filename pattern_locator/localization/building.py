"""
The building map: floors, rooms and the cards on their walls.

Frames (method.md section 5): ``building`` -> room frame (``T_building_room``)
-> card frame (``T_room_card``), each a :class:`~.geometry.Pose` with
``X_parent = R @ X_child + t``, so ``T_building_card = T_building_room @
T_room_card``. A card's frame is the pattern frame: origin at the centre dot,
x right, y up (towards point 1), z out of the wall into the room.

The file format is documented at the top of the shipped
``config/building.yaml``. A card may also carry its standard deviations, as
a surveyed map (``pattern-locator survey``) writes them: ``std_dev:
{position_m: [x, y, z], rotation_deg: [x, y, z]}`` about the room frame's
axes (either part optional). Loading checks everything a typo could break and
raises :class:`~.errors.ConfigError` with one line naming the file and the
exact place (``floor 1 room 3 card 2: ...``).
"""

from dataclasses import dataclass
import difflib
import math
from pathlib import Path
import re
from typing import Any, Callable, Dict, Iterable, List, Optional, Sequence, Tuple, Union

import numpy as np

from ..card.pattern import Code, Ids, load_pattern_config, PatternConfig
from ..errors import CodeError, ConfigError, PrintError
from ..resources import config_path, read_yaml, UniqueKeyLoader
from ..vision.geometry import Pose, rotation_from_quaternion

DEFAULT_FRAME = 'building'
# A map of every card the shipped code has (12 floors x 81 rooms x 9 cards)
# is ~1 MB and ~150k YAML values; PyYAML reads ~20k values a second.
MAX_MAP_BYTES = 4 * 1024 * 1024
MAX_MAP_VALUES = 500_000
TOLERANCE = 1e-6          # unit quaternion / orthonormal rotation, as the file must give them
ORIENTATIONS = ('rpy_deg', 'quaternion', 'rotation', 'facing_deg')
CARD_FORMATS = ('pdf', 'svg', 'png')

_TOP_KEYS = ('building', 'floors')
_BUILDING_KEYS = ('frame',)
_FLOOR_KEYS = ('floor', 'name', 'rooms')
_ROOM_KEYS = ('room', 'name', 'frame', 'pose', 'relative_to', 'size', 'cards')
_RELATIVE_KEYS = ('floor', 'room')
_CARD_KEYS = ('pattern', 'code', 'pose', 'std_dev')
_STD_DEV_KEYS = ('position_m', 'rotation_deg')
_POSE_KEYS = ('position',) + ORIENTATIONS
# tf2 frame ids: no spaces, no leading slash (ROS 2 rejects it).
_FRAME_RE = re.compile(r'^[A-Za-z0-9_][A-Za-z0-9_./-]*$')


def default_room_frame(floor: int, room: int) -> str:
    """Return the default frame name of a room, ``floor_<f>/room_<r>``."""
    return f'floor_{floor}/room_{room}'


def rpy_rotation(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """Return ``Rz(yaw) @ Ry(pitch) @ Rx(roll)`` (radians; fixed axes, as ROS and URDF)."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    return rz @ ry @ rx


def wall_card_rotation(facing_deg: float) -> np.ndarray:
    """
    Return the rotation of an upright card on a wall, its +z at heading ``facing_deg``.

    The heading is measured in the room's floor plane from room +x towards +y.
    Card +y is room +z (up) and card x = y cross z (right, along the wall).
    """
    a = math.radians(facing_deg)
    z_axis = np.array([math.cos(a), math.sin(a), 0.0])
    y_axis = np.array([0.0, 0.0, 1.0])
    return np.column_stack([np.cross(y_axis, z_axis), y_axis, z_axis])


@dataclass(frozen=True)
class CardStdDev:
    """
    How well a card's pose is known (a survey's result): standard deviations about the room's axes.

    ``position_m``: of the card's centre along room x, y, z (metres);
    ``rotation_deg``: of small rotations about room x, y, z (degrees).
    """

    position_m: Tuple[float, float, float]
    rotation_deg: Tuple[float, float, float]


@dataclass(frozen=True, eq=False)
class MappedCard:
    """
    One card of the building map.

    ``eq=False``: the poses hold numpy arrays, so cards compare by identity.
    ``std_dev``: the card pose's uncertainty when the map gives one.
    """

    ids: Ids
    code: Code
    room_frame: str
    T_room_card: Pose
    T_building_card: Pose
    std_dev: Optional[CardStdDev] = None

    def label(self) -> str:
        """Return ``floor F room R card P``, as the error messages name it."""
        return _card_label(self.ids.floor, self.ids.room, self.ids.pattern)


@dataclass(frozen=True, eq=False)
class Room:
    """A room: its ids, frame name, pose in the building, optional box size, cards by number."""

    floor: int
    room: int
    frame: str
    T_building_room: Pose
    size: Optional[Tuple[float, float, float]]
    cards: Tuple[MappedCard, ...]
    name: str = ''

    @property
    def centre(self) -> Optional[np.ndarray]:
        """Return the centre of the room's box in the room frame (None without a size)."""
        return None if self.size is None else np.asarray(self.size, dtype=float) / 2.0


class BuildingMap:
    """The validated building: rooms by ``(floor, room)`` and cards by ids and by code."""

    def __init__(self, frame: str, rooms: Dict[Tuple[int, int], Room],
                 floor_names: Optional[Dict[int, str]] = None, source: str = '') -> None:
        self.frame = frame
        self.rooms: Dict[Tuple[int, int], Room] = dict(sorted(rooms.items()))
        self.floor_names: Dict[int, str] = dict(floor_names or {})
        self.source = source
        self._by_ids: Dict[Tuple[int, int, int], MappedCard] = {}
        self._by_code: Dict[Code, MappedCard] = {}
        self._by_frame: Dict[str, Room] = {}
        for room in self.rooms.values():
            self._by_frame[room.frame] = room
            for card in room.cards:
                self._by_ids[card.ids.as_tuple()] = card
                self._by_code[card.code] = card

    def __repr__(self) -> str:
        return (f'BuildingMap(frame={self.frame!r}, {len(self.floors)} floors, '
                f'{len(self.rooms)} rooms, {len(self._by_ids)} cards)')

    @property
    def floors(self) -> List[int]:
        """Return the floor numbers that have rooms or a name, in order."""
        return sorted({f for f, _ in self.rooms} | set(self.floor_names))

    def card(self, ids: Union[Ids, Tuple[int, int, int]]) -> MappedCard:
        """Return the card with these ids; CodeError if the map has no such card."""
        ids = ids if isinstance(ids, Ids) else Ids(*ids)
        try:
            return self._by_ids[ids.as_tuple()]
        except KeyError:
            raise CodeError(f'card floor {ids.floor} room {ids.room} pattern {ids.pattern} '
                            f'is not in the building map') from None

    def card_by_code(self, code: Union[Code, str]) -> MappedCard:
        """Return the card with this colour code; CodeError if it is not in the map."""
        code = Code.parse(str(code))
        try:
            return self._by_code[code]
        except KeyError:
            raise CodeError(f'code {code} is not in the building map') from None

    def cards(self) -> List[MappedCard]:
        """Return every card, ordered by floor, room and card number."""
        return [self._by_ids[k] for k in sorted(self._by_ids)]

    def mirror_pairs(self) -> List[Tuple[MappedCard, MappedCard]]:
        """
        Return the pairs of cards whose codes are each other's mirror images.

        On cards printed without handedness marks a mirror image of one (a
        glass door, thin paper against the light) reads as the other: only
        the localizer's gates then stand between it and a wrong place.
        """
        pairs = []
        for card in self.cards():
            mirrored = card.code.mirrored()
            other = self._by_code.get(mirrored)
            if other is not None and mirrored != card.code and card.ids.as_tuple() < \
                    other.ids.as_tuple():
                pairs.append((card, other))
        return pairs

    def room(self, floor: int, room: int) -> Room:
        """Return a room; CodeError if the map has no such room."""
        try:
            return self.rooms[(floor, room)]
        except KeyError:
            raise CodeError(f'floor {floor} room {room} is not in the building map') from None

    def room_by_frame(self, frame: str) -> Room:
        """Return the room whose frame is ``frame``; CodeError if none is."""
        try:
            return self._by_frame[frame]
        except KeyError:
            raise CodeError(f'no room of the building map has the frame {frame!r}') from None


# Loading ----------------------------------------------------------------------


def load_building(path: Optional[Union[str, Path]] = None,
                  pattern: Optional[PatternConfig] = None) -> BuildingMap:
    """
    Load and validate a building map.

    Defaults: the shipped ``config/building.yaml`` and the shipped pattern
    configuration. Any problem raises ConfigError with one line naming the
    file and the place.
    """
    path = Path(path) if path is not None else config_path('building.yaml')
    pattern = pattern if pattern is not None else load_pattern_config()
    data = read_yaml(path, 'the building map', loader=UniqueKeyLoader,
                     max_bytes=MAX_MAP_BYTES, max_nodes=MAX_MAP_VALUES)
    return building_from_dict(data, pattern, str(path))


def building_from_dict(data: Any, pattern: PatternConfig,
                       source: str = 'building') -> BuildingMap:
    """Build a BuildingMap from parsed YAML; ConfigError names the file and the place."""
    if not isinstance(data, dict):
        raise ConfigError(f'{source}: expected a mapping with "floors" at the top level, got '
                          f'{_kind(data)}')
    _check_keys(source, data, _TOP_KEYS, required=('floors',))
    frame = DEFAULT_FRAME
    if data.get('building') is not None:
        building = data['building']
        _check_keys(f'{source}: building', building, _BUILDING_KEYS)
        if 'frame' in building:
            frame = _frame_name(f'{source}: building', building['frame'])
    floors = data['floors']
    if not isinstance(floors, list) or not floors:
        raise ConfigError(f'{source}: floors must be a non-empty list, got '
                          f'{_kind(floors) if floors != [] else "an empty list"}')
    ranges = pattern.id_ranges()
    rooms: Dict[Tuple[int, int], Room] = {}
    frames: Dict[str, str] = {frame: 'the building frame'}
    floor_names: Dict[int, str] = {}
    for i, floor_data in enumerate(floors):
        floor = _number_key(f'{source}: floors[{i}]', floor_data, _FLOOR_KEYS, 'floor')
        where = f'{source}: floor {floor}'
        _check_keys(where, floor_data, _FLOOR_KEYS)
        _check_range(where, ranges, 'floor', floor)
        if floor in floor_names:
            raise ConfigError(f'{where}: duplicate floor (listed twice)')
        floor_names[floor] = _text(where, 'name', floor_data.get('name', ''))
        room_list = floor_data.get('rooms', [])
        if room_list is None:
            room_list = []
        if not isinstance(room_list, list):
            raise ConfigError(f'{where}: rooms must be a list, got {_kind(room_list)}')
        for j, room_data in enumerate(room_list):
            room = _room(source, floor, j, room_data, pattern, ranges, rooms, frames)
            rooms[(room.floor, room.room)] = room
    return BuildingMap(frame, rooms, floor_names, source)


def _room(source: str, floor: int, index: int, data: Any, pattern: PatternConfig,
          ranges: Dict[str, range], rooms: Dict[Tuple[int, int], Room],
          frames: Dict[str, str]) -> Room:
    number = _number_key(f'{source}: floor {floor} rooms[{index}]', data, _ROOM_KEYS, 'room')
    label = f'floor {floor} room {number}'
    where = f'{source}: {label}'
    _check_keys(where, data, _ROOM_KEYS, required=('pose',))
    _check_range(where, ranges, 'room', number)
    if (floor, number) in rooms:
        raise ConfigError(f'{where}: duplicate room (listed twice on floor {floor})')
    frame = default_room_frame(floor, number)
    if data.get('frame') is not None:
        frame = _frame_name(where, data['frame'])
    if frame in frames:
        raise ConfigError(f'{where}: duplicate frame {frame!r} (also {frames[frame]})')
    frames[frame] = label
    pose = _pose(f'{where}: pose', data['pose'])
    if data.get('relative_to') is not None:
        pose = _relative_room(f'{where}: relative_to', data['relative_to'], rooms) @ pose
    size = None
    if data.get('size') is not None:
        size = _numbers(where, 'size', data['size'], 3, 'size must be [length, width, height] '
                        'in metres')
        if min(size) <= 0.0:
            raise ConfigError(f'{where}: size must be positive, got {list(size)}')
        size = tuple(float(s) for s in size)
    card_list = data.get('cards', [])
    if card_list is None:
        card_list = []
    if not isinstance(card_list, list):
        raise ConfigError(f'{where}: cards must be a list, got {_kind(card_list)}')
    cards: Dict[int, MappedCard] = {}
    for k, card_data in enumerate(card_list):
        card = _card(source, floor, number, k, card_data, pattern, ranges, frame, pose)
        if card.ids.pattern in cards:
            # Codes are a one-to-one function of the ids under a valid pattern
            # configuration, so a repeated code is a card listed twice.
            raise ConfigError(f'{source}: {card.label()}: duplicate code {card.code}: card '
                              f'{card.ids.pattern} is listed twice in {label}')
        cards[card.ids.pattern] = card
    name = _text(where, 'name', data.get('name', ''))
    return Room(floor, number, frame, pose, size, tuple(cards[p] for p in sorted(cards)), name)


def _relative_room(where: str, data: Any, rooms: Dict[Tuple[int, int], Room]) -> Pose:
    _check_keys(where, data, _RELATIVE_KEYS, required=_RELATIVE_KEYS)
    key = (_integer(where, 'floor', data['floor']), _integer(where, 'room', data['room']))
    if key not in rooms:
        raise ConfigError(f'{where}: unknown room floor {key[0]} room {key[1]} (name a room '
                          f'listed earlier in the file)')
    return rooms[key].T_building_room


def _card(source: str, floor: int, room: int, index: int, data: Any, pattern: PatternConfig,
          ranges: Dict[str, range], room_frame: str, T_building_room: Pose) -> MappedCard:
    number = _number_key(f'{source}: floor {floor} room {room} cards[{index}]', data,
                         _CARD_KEYS, 'pattern')
    where = f'{source}: {_card_label(floor, room, number)}'
    _check_keys(where, data, _CARD_KEYS + ('std_dev',), required=('pose',))
    _check_range(where, ranges, 'pattern', number)
    expected = pattern.encode(floor, room, number)
    if data.get('code') is not None:
        try:
            given = Code.parse(str(data['code']))
        except CodeError as exc:
            raise ConfigError(f'{where}: code: {exc}') from None
        if given != expected:
            read = pattern.decode(given)
            raise ConfigError(
                f'{where}: code {given} does not match {_card_label(floor, room, number)} '
                f'(expected {expected}; {given} is '
                f'{_card_label(read.floor, read.room, read.pattern)})')
    T_room_card = _pose(f'{where}: pose', data['pose'])
    std_dev = None
    if data.get('std_dev') is not None:
        std_dev = _std_dev(f'{where}: std_dev', data['std_dev'])
    return MappedCard(Ids(floor, room, number), expected, room_frame, T_room_card,
                      T_building_room @ T_room_card, std_dev)


def _std_dev(where: str, data: Any) -> CardStdDev:
    """Read ``{position_m: s | [sx, sy, sz], rotation_deg: s | [sx, sy, sz]}`` (>= 0)."""
    _check_keys(where, data, _STD_DEV_KEYS)
    if not data:
        raise ConfigError(f'{where}: give position_m, rotation_deg or both')
    values = []
    for key in _STD_DEV_KEYS:
        value = data.get(key, 0.0)
        message = f'{key} must be a number or [x, y, z] (standard deviations about the room axes)'
        if isinstance(value, list):
            triple = _numbers(where, key, value, 3, message)
        else:
            triple = [_number(where, key, value, message)] * 3
        if not all(math.isfinite(v) and v >= 0.0 for v in triple):
            raise ConfigError(f'{where}: {key} must be finite and >= 0, got {value!r}')
        values.append(tuple(float(v) for v in triple))
    return CardStdDev(*values)


def _pose(where: str, data: Any) -> Pose:
    _check_keys(where, data, _POSE_KEYS, required=('position',))
    given = [k for k in ORIENTATIONS if k in data]
    if len(given) != 1:
        raise ConfigError(f'{where}: give exactly one orientation of '
                          f'{", ".join(ORIENTATIONS)}; got '
                          f'{", ".join(given) if given else "none"}')
    position = np.array(_numbers(where, 'position', data['position'], 3,
                                 'position must be [x, y, z] in metres'))
    kind = given[0]
    value = data[kind]
    if kind == 'rpy_deg':
        rpy = _numbers(where, kind, value, 3, 'rpy_deg must be [roll, pitch, yaw] in degrees')
        R = rpy_rotation(*np.deg2rad(rpy))
    elif kind == 'quaternion':
        q = np.array(_numbers(where, kind, value, 4, 'quaternion must be [x, y, z, w]'))
        norm = float(np.linalg.norm(q))
        if abs(norm - 1.0) > TOLERANCE:
            raise ConfigError(f'{where}: quaternion {_fmt(q)} is not unit (norm {norm:.6g}; '
                              f'it must be 1 within {TOLERANCE:g})')
        R = rotation_from_quaternion(q)
    elif kind == 'rotation':
        R = _rotation(where, value)
    else:
        R = wall_card_rotation(_number(where, kind, value,
                                       'facing_deg must be one number in degrees'))
    return Pose(R, position)


def _rotation(where: str, value: Any) -> np.ndarray:
    message = 'rotation must be a 3x3 matrix [[r11, r12, r13], [r21, ...], [r31, ...]]'
    if not isinstance(value, list) or len(value) != 3:
        raise ConfigError(f'{where}: {message}, got {value!r}')
    R = np.array([_numbers(where, 'rotation', row, 3, message) for row in value])
    error = float(np.abs(R.T @ R - np.eye(3)).max())
    if error > TOLERANCE:
        raise ConfigError(f'{where}: rotation is not orthonormal (R^T R differs from the '
                          f'identity by {error:.3g}; allowed {TOLERANCE:g})')
    det = float(np.linalg.det(R))
    if det < 0.0:
        raise ConfigError(f'{where}: rotation is not orthonormal with det +1 (det {det:.6g}: '
                          f'a mirror image, not a rotation)')
    # Within tolerance: use the nearest exact rotation, so compositions stay exact.
    u, _, vt = np.linalg.svd(R)
    return u @ vt


# Small checks -------------------------------------------------------------------


def _check_keys(where: str, data: Any, allowed: Sequence[str],
                required: Sequence[str] = ()) -> None:
    if not isinstance(data, dict):
        raise ConfigError(f'{where}: expected a mapping with keys {", ".join(allowed)}; got '
                          f'{_kind(data)}')
    for key in data:
        if key not in allowed:
            close = difflib.get_close_matches(str(key), allowed, n=1)
            hint = f'did you mean {close[0]!r}? ' if close else ''
            raise ConfigError(f'{where}: unknown key {key!r} ({hint}allowed: '
                              f'{", ".join(allowed)})')
    for key in required:
        if data.get(key) is None:
            raise ConfigError(f'{where}: missing {key!r}')


def _number_key(where: str, data: Any, allowed: Sequence[str], key: str) -> int:
    # The number names the place in every later message, so read it first.
    if not isinstance(data, dict):
        raise ConfigError(f'{where}: expected a mapping with keys {", ".join(allowed)}; got '
                          f'{_kind(data)}')
    if data.get(key) is None:
        raise ConfigError(f'{where}: missing {key!r}')
    return _integer(where, key, data[key])


def _check_range(where: str, ranges: Dict[str, range], field: str, value: int) -> None:
    span = ranges[field]
    if value not in span:
        raise ConfigError(f'{where}: ids out of range: {field} {value} is not in '
                          f'{span.start}..{span.stop - 1} under the pattern configuration')


def _integer(where: str, name: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ConfigError(f'{where}: {name} must be an integer, got {value!r}')
    return value


def _text(where: str, name: str, value: Any) -> str:
    if not isinstance(value, str):
        raise ConfigError(f'{where}: {name} must be text, got {value!r}')
    return value


def _numbers(where: str, name: str, value: Any, count: int, message: str) -> List[float]:
    if not isinstance(value, list) or len(value) != count:
        raise ConfigError(f'{where}: {message}, got {value!r}')
    return [_number(where, name, item, message, shown=value) for item in value]


def _number(where: str, name: str, value: Any, message: str, shown: Any = None) -> float:
    if isinstance(value, str):
        # PyYAML reads 1e-3 (no dot) as text: say so rather than "not a number".
        raise ConfigError(f'{where}: {name}: {value!r} is text, not a number (write numbers '
                          f'unquoted, exponents with a dot: 1.0e-3)')
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(
            value):
        raise ConfigError(f'{where}: {message}, got {value if shown is None else shown!r}')
    return float(value)


def _frame_name(where: str, value: Any) -> str:
    if not isinstance(value, str) or not _FRAME_RE.match(value):
        raise ConfigError(f'{where}: frame must be a tf2 frame name (letters, digits, _ . / -, '
                          f'no leading /), got {value!r}')
    return value


def _card_label(floor: int, room: int, pattern: int) -> str:
    return f'floor {floor} room {room} card {pattern}'


def _kind(value: Any) -> str:
    if value is None:
        return 'nothing'
    if isinstance(value, dict):
        return 'a mapping'
    if isinstance(value, list):
        return 'a list'
    return repr(value)


def _fmt(values: np.ndarray) -> str:
    return '[' + ', '.join(f'{v:.6g}' for v in values) + ']'


# Printing -------------------------------------------------------------------------


def card_file_name(card: MappedCard, fmt: str = 'pdf') -> str:
    """Return the file name of a card, e.g. ``floor1_room3_card2_K-KRGBGRBB.pdf``."""
    f, r, p = card.ids.as_tuple()
    return f'floor{f}_room{r}_card{p}_{card.code}.{fmt}'


def write_building_cards(building: BuildingMap, pattern: PatternConfig,
                         out_dir: Union[str, Path], paper: str = 'a3', fmt: str = 'pdf',
                         dpi: float = 300,
                         progress: Callable[[Iterable[MappedCard]], Iterable[MappedCard]] = iter
                         ) -> List[Path]:
    """
    Write every card of the building into ``out_dir`` (created if needed).

    One file per card (:func:`card_file_name`); a tiled SVG or PNG card gives
    one file per sheet (``printable.tile_paths``). Returns the files written.
    ``progress`` wraps the cards as they are written (e.g. a progress bar).
    Raises PrintError for an unknown format or an unwritable directory and
    ConfigError when ``pattern`` is not the code layout the map was checked
    against (the printed cards would not be the mapped ones).
    """
    from ..card.printable import write_card       # cv2 only when printing
    fmt = str(fmt).lower().lstrip('.')
    if fmt not in CARD_FORMATS:
        raise PrintError(f'unknown card format {fmt!r}; use {", ".join(CARD_FORMATS)}')
    cards = building.cards()
    for card in cards:
        try:
            code = pattern.encode(*card.ids.as_tuple())
        except CodeError as exc:
            code = exc
        if code != card.code:
            raise ConfigError(f'{building.source or "building"}: {card.label()}: the map has '
                              f'code {card.code} but this pattern configuration gives {code}; '
                              f'load the map with the same pattern configuration')
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise PrintError(f'{out}: cannot create the output directory '
                         f'({exc.strerror or exc})') from None
    written: List[Path] = []
    for card in progress(cards):
        written.extend(write_card(out / card_file_name(card, fmt), pattern, card.ids,
                                  paper=paper, dpi=dpi))
    return written
