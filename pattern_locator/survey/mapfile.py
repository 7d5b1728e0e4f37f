"""
The survey's outputs as files: the building map (YAML), the cards (JSON), and the anchors.

The YAML is ``config/building.yaml``'s schema (``localization.building``), so
the locator loads it as is; each card also carries its standard deviations
(``std_dev``: position in metres and rotation in degrees, about the room's
axes). Room frames follow :func:`room_frames`.
"""

from dataclasses import dataclass
import json
import math
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from ..errors import ConfigError
from ..localization.building import BuildingMap, default_room_frame, load_building
from ..vision.geometry import Pose

RoomKey = Tuple[int, int]


@dataclass(frozen=True, eq=False)
class MapCard:
    """
    A card of a surveyed map, in the building frame.

    ``covariance``: 6x6 over (x, y, z, rx, ry, rz), the position (m) and a
    small turn (rad) about the building's axes; zero for an anchor. None
    with ``pose`` None for a card not connected to the building frame.
    """

    ids: Tuple[int, int, int]
    code: str
    T_building_card: Optional[Pose]
    covariance: Optional[np.ndarray]
    sightings: int
    connected: bool
    anchor: bool = False

    @property
    def placed(self) -> bool:
        """Return True when the card goes into the building map: connected, seen twice or more."""
        return self.connected and self.T_building_card is not None and (
            self.anchor or self.sightings >= 2)


@dataclass(frozen=True, eq=False)
class RoomFrame:
    """A room of the output map: its frame's pose in the building, name and plot size."""

    T_building_room: Pose
    frame: str
    name: str = ''
    size: Optional[Tuple[float, float, float]] = None
    source: str = 'card'            # 'card': on its lowest-numbered card; 'anchors'


def upright_frame_on(T_building_card: Pose) -> Pose:
    """
    Return the gravity-aligned frame sitting on a card.

    Origin at the card's centre, z up (the building's z), x out of the card's
    wall (its normal made horizontal), y = z cross x (along the wall, the
    card's right). An upright card then sits at the origin with
    ``facing_deg: 0``. A card lying flat (normal vertical) keeps its own x.
    """
    normal = T_building_card.R[:, 2].copy()
    normal[2] = 0.0
    if np.linalg.norm(normal) < 1e-6:
        normal = T_building_card.R[:, 0].copy()
        normal[2] = 0.0
    x = normal / np.linalg.norm(normal)
    z = np.array([0.0, 0.0, 1.0])
    return Pose(np.column_stack([x, np.cross(z, x), z]), T_building_card.t.copy())


def room_frames(cards: Sequence[MapCard], anchors: Optional[BuildingMap] = None
                ) -> Dict[RoomKey, RoomFrame]:
    """
    Return the frame of every room with a placed card.

    A room listed in the anchors keeps the anchors' pose, frame name, name
    and size. Any other room's frame sits on its lowest-numbered placed card
    (:func:`upright_frame_on`): the paper fixes each room's frame on one
    card, and the upright version keeps z up for the robot.
    """
    out: Dict[RoomKey, RoomFrame] = {}
    for card in sorted((c for c in cards if c.placed), key=lambda c: c.ids):
        key = card.ids[:2]
        if key in out:
            continue
        if anchors is not None and key in anchors.rooms:
            room = anchors.rooms[key]
            out[key] = RoomFrame(room.T_building_room, room.frame, room.name, room.size,
                                 'anchors')
        else:
            out[key] = RoomFrame(upright_frame_on(card.T_building_card),
                                 default_room_frame(*key))
    return out


def rpy_deg(R: np.ndarray) -> Tuple[float, float, float]:
    """Return (roll, pitch, yaw) in degrees with ``R = Rz(yaw) Ry(pitch) Rx(roll)``."""
    R = np.asarray(R, dtype=float)
    pitch = math.asin(float(np.clip(-R[2, 0], -1.0, 1.0)))
    if abs(R[2, 0]) < 1.0 - 1e-12:
        roll = math.atan2(R[2, 1], R[2, 2])
        yaw = math.atan2(R[1, 0], R[0, 0])
    else:
        # Gimbal lock: only roll - yaw (or roll + yaw) is defined; put it in roll.
        roll, yaw = math.atan2(-R[1, 2], R[1, 1]), 0.0
    return tuple(math.degrees(v) for v in (roll, pitch, yaw))


def covariance_in(R_frame_building: np.ndarray, covariance: np.ndarray) -> np.ndarray:
    """Return a (position, rotation) 6x6 covariance re-expressed about another frame's axes."""
    A = np.zeros((6, 6))
    A[:3, :3] = A[3:, 3:] = R_frame_building
    return A @ covariance @ A.T


def _fmt(values, digits: int) -> str:
    return '[' + ', '.join(f'{v:.{digits}f}' for v in values) + ']'


def building_yaml(cards: Sequence[MapCard], rooms: Dict[RoomKey, RoomFrame],
                  header: Sequence[str] = (), footer: Sequence[str] = (),
                  building_frame: str = 'building',
                  floor_names: Optional[Dict[int, str]] = None) -> str:
    """Return the text of a building map holding the placed cards (and comments)."""
    lines = [f'# {line}' if line else '#' for line in header]
    lines += [f'building: {{frame: {building_frame}}}', '', 'floors:']
    placed = sorted((c for c in cards if c.placed), key=lambda c: c.ids)
    floors = sorted({c.ids[0] for c in placed})
    if not floors:
        raise ConfigError('survey: no card could be placed, so there is no map to write')
    for floor in floors:
        lines.append(f'  - floor: {floor}')
        if floor_names and floor_names.get(floor):
            lines.append(f'    name: {json.dumps(floor_names[floor])}')
        lines.append('    rooms:')
        for key in sorted(k for k in rooms if k[0] == floor):
            room = rooms[key]
            lines.append(f'      - room: {key[1]}')
            if room.name:
                lines.append(f'        name: {json.dumps(room.name)}')
            if room.frame != default_room_frame(*key):
                lines.append(f'        frame: {room.frame}')
            lines.append(f'        pose: {_pose_text(room.T_building_room)}')
            if room.size is not None:
                lines.append(f'        size: {_fmt(room.size, 3)}')
            lines.append('        cards:')
            for card in (c for c in placed if c.ids[:2] == key):
                T_room_card = room.T_building_room.inverse() @ card.T_building_card
                lines.append(f'          - pattern: {card.ids[2]}')
                lines.append(f'            code: {card.code}')
                lines.append(f'            pose: {_pose_text(T_room_card)}')
                if card.covariance is not None:
                    cov = covariance_in(room.T_building_room.R.T, card.covariance)
                    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
                    lines.append(f'            std_dev: {{position_m: {_fmt(sd[:3], 6)}, '
                                 f'rotation_deg: {_fmt(np.degrees(sd[3:]), 4)}}}')
    lines += [f'# {line}' if line else '#' for line in footer]
    return '\n'.join(lines) + '\n'


def _pose_text(T: Pose) -> str:
    return f'{{position: {_fmt(T.t, 6)}, rpy_deg: {_fmt(rpy_deg(T.R), 6)}}}'


def cards_json(cards: Sequence[MapCard], frame: str = 'building') -> dict:
    """Return the ``--cards-json`` document (issue 13's exact form)."""
    out = []
    for card in sorted(cards, key=lambda c: c.ids):
        f, r, p = card.ids
        item = {'code': card.code, 'floor': f, 'room': r, 'pattern': p,
                'T_building_card': None, 'covariance': None,
                'sightings': int(card.sightings), 'connected': bool(card.connected)}
        if card.connected and card.T_building_card is not None:
            item['T_building_card'] = [[float(f'{v:.9g}') for v in row]
                                       for row in card.T_building_card.matrix()]
            cov = np.zeros((6, 6)) if card.anchor else card.covariance
            item['covariance'] = [[float(f'{v:.6g}') for v in row] for row in cov]
        if card.anchor:
            item['anchor'] = True
        out.append(item)
    return {'frame': frame, 'cards': out}


def write_text(path: Union[str, Path], text: str, what: str) -> None:
    """Write a file; ConfigError in one line if it cannot be written."""
    try:
        Path(path).write_text(text, encoding='utf-8')
    except OSError as exc:
        raise ConfigError(f'{path}: cannot write {what} ({exc.strerror or exc})') from None


def load_anchors(path: Union[str, Path], pattern) -> BuildingMap:
    """Load an anchors file (a building map listing known cards); ConfigError if it has none."""
    anchors = load_building(path, pattern)
    if not anchors.cards():
        raise ConfigError(f'{path}: the anchors list no card (give at least one)')
    return anchors


def truth_cards(cards: Sequence[Tuple[Tuple[int, int, int], str, Pose]]) -> List[MapCard]:
    """Return exact cards (zero covariance) for writing a truth or anchors map."""
    return [MapCard(tuple(ids), str(code), T, np.zeros((6, 6)), 2, True, True)
            for ids, code, T in cards]
