"""
The paper's experiment as a scene: its room, its cards, its camera and route.

Section 4 of the paper: rooms of 50 m^2 and 2.5 m high, cards at 2.15 m on
the walls (at most 6 a room), a Sony EVI-D31 with f = 25 mm on a robot,
distances 1.25-8 m, a 30-image route (Fig. 7). The camera here is a 1/3-type
sensor (4.8 mm wide) digitised at 640x480, so fx = 25 mm / 7.5 um = 3333 px;
at the shortest distances only the inner ring fits in the image, which is
why the paper printed two rings.
"""

from dataclasses import dataclass
import math
from typing import List, Tuple

import numpy as np

from ..localization.building import wall_card_rotation
from ..vision.camera import CameraModel
from ..vision.geometry import look_at, Pose, rodrigues

ROOM_SIZE = (10.0, 5.0)           # metres: 50 m^2
ROOM_HEIGHT = 2.5
CARD_HEIGHT = 2.15
CAMERA_HEIGHT = 1.10              # the EVI-D31 on the robot's mast
FOCAL_MM = 25.0
PIXEL_PITCH_MM = 0.0075


def paper_camera() -> CameraModel:
    """640x480, f = 25 mm on a 1/3-type sensor: fx = 3333 px, no distortion."""
    return CameraModel.from_focal(640, 480, FOCAL_MM / PIXEL_PITCH_MM, name='evi_d31_25mm')


@dataclass(frozen=True)
class WallCard:
    """A card on a wall of the room: its number and ``T_room_card``."""

    number: int
    T_room_card: Pose


def _card_on_wall(number: int, x: float, y: float, facing_deg: float) -> WallCard:
    """
    Card centre at (x, y, CARD_HEIGHT), its +z (out of the wall) at ``facing_deg``.

    Room frame: x along the long wall, y across, z up, origin at a floor corner.
    Card frame: x right along the wall, y up, z into the room.
    """
    return WallCard(number, Pose(wall_card_rotation(facing_deg), np.array([x, y, CARD_HEIGHT])))


def room_cards() -> List[WallCard]:
    """Six cards: two on each long wall, one on each short wall."""
    length, width = ROOM_SIZE
    return [
        _card_on_wall(1, 0.0, width / 2, 0.0),            # west wall, facing +x
        _card_on_wall(2, 3.0, width, -90.0),              # north wall
        _card_on_wall(3, 7.0, width, -90.0),
        _card_on_wall(4, length, width / 2, 180.0),       # east wall
        _card_on_wall(5, 7.0, 0.0, 90.0),                 # south wall
        _card_on_wall(6, 3.0, 0.0, 90.0),
    ]


def route() -> List[Tuple[np.ndarray, int]]:
    """
    30 stops (camera position in the room, card it looks at), as in Fig. 7.

    The robot crosses the room lengthwise and back, looking at the card that
    the paper's rule would pick (the biggest complete one, seen at more than
    25 degrees of tilt), covering distances of about 1.25 to 8 m.
    """
    cards = {c.number: c for c in room_cards()}
    stops = []
    xs = np.linspace(1.0, 9.0, 15)
    for i, x in enumerate(xs):
        y = 1.6 + 0.5 * math.sin(i / 2.5)
        stops.append(np.array([x, y, CAMERA_HEIGHT]))
    for i, x in enumerate(xs[::-1]):
        y = 3.5 - 0.4 * math.cos(i / 2.0)
        stops.append(np.array([x, y, CAMERA_HEIGHT]))
    chosen = []
    for position in stops:
        best = None
        for card in cards.values():
            rel = position - card.T_room_card.t
            distance = float(np.linalg.norm(rel))
            cos_view = float(rel @ card.T_room_card.R[:, 2]) / distance
            phi = math.degrees(math.acos(np.clip(cos_view, -1.0, 1.0)))
            if cos_view <= 0 or not 1.2 <= distance <= 8.2 or not 25.0 <= phi <= 72.0:
                continue
            if best is None or distance < best[0]:
                best = (distance, card.number)
        if best is not None:
            chosen.append((position, best[1]))
    return chosen


def tracking_camera_pose(position: np.ndarray, target: np.ndarray, rng: np.random.Generator,
                         pointing_error_deg: float = 0.3) -> Pose:
    """
    ``T_room_camera`` of an upright pan/tilt camera aimed at ``target``.

    A small random pointing error stands for the tracking loop's residual.
    """
    pose = look_at(position, target, up=(0.0, 0.0, 1.0))
    err = np.deg2rad(rng.normal(0.0, pointing_error_deg, 2))
    return Pose(pose.R @ rodrigues(np.array([err[0], err[1], 0.0])), pose.t)
