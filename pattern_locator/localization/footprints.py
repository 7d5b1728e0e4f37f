"""
Rooms' floor rectangles from the building map: who is where, and which rooms adjoin.

ROS-free. The map gives each sized room a box from its origin along +x, +y,
+z (``building.yaml``); its **footprint** is the floor rectangle of that box
in the building frame, at the room floor's height. Used by the gates (a fix
from a card seen through a door puts the base in the next room) and by the
gaze planner (which rooms are one space, where lines of sight run).
"""

import math
from typing import Dict, Iterable, List, Tuple

import cv2
import numpy as np

from .building import BuildingMap, Room
from ..vision.geometry import Pose

RoomKey = Tuple[int, int]
# A base stands on its room's floor: this far above or below it is still "on" it.
FLOOR_BAND_M = 0.5


class Footprint:
    """A sized room's floor rectangle in the building frame, and its floor's height."""

    def __init__(self, room: Room) -> None:
        if room.size is None:
            raise ValueError(f'{room.frame} has no size: no footprint')
        self.key: RoomKey = (room.floor, room.room)
        self.T_room_building: Pose = room.T_building_room.inverse()
        self.size = np.asarray(room.size, dtype=float)
        self.z = float(room.T_building_room.t[2])
        # Building (x, y) at this floor's height -> room (x, y): the 2-D part
        # of T_room_building. The planner tests thousands of points a frame,
        # and a 3-D pose per call cost more than the test.
        R, t = self.T_room_building.R, self.T_room_building.t
        self._rows = (float(R[0, 0]), float(R[0, 1]), float(R[1, 0]), float(R[1, 1]))
        self._offset = (float(R[0, 2] * self.z + t[0]), float(R[1, 2] * self.z + t[1]))

    def local(self, points_xy: np.ndarray) -> np.ndarray:
        """Return building (x, y) points (at this floor's height) in the room frame."""
        points_xy = np.asarray(points_xy, dtype=float).reshape(-1, 2)
        points = np.column_stack([points_xy, np.full(len(points_xy), self.z)])
        return self.T_room_building.apply(points)

    def contains(self, points_xy: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Return which points lie inside the rectangle grown by ``margin`` (bool array)."""
        points_xy = np.asarray(points_xy, dtype=float).reshape(-1, 2)
        return self.inside(points_xy[:, 0], points_xy[:, 1], margin)

    def inside(self, x, y, margin: float = 0.0):
        """Return whether building points (``x``, ``y``: arrays or numbers) lie inside, grown."""
        a, b, c, d = self._rows
        lx = x * a + y * b + self._offset[0]
        ly = x * c + y * d + self._offset[1]
        return ((lx >= -margin) & (lx <= self.size[0] + margin)
                & (ly >= -margin) & (ly <= self.size[1] + margin))

    def on_floor(self, z: float) -> bool:
        """Return whether a base at height ``z`` (building frame) stands on this room's floor."""
        return abs(z - self.z) <= FLOOR_BAND_M

    def grown(self, margin: float) -> np.ndarray:
        """Return the rectangle's corners grown by ``margin`` on every side (building xy)."""
        (x0, y0), (x1, y1) = (-margin, -margin), (self.size[0] + margin, self.size[1] + margin)
        corners = np.array([[x0, y0, self.z], [x1, y0, self.z], [x1, y1, self.z],
                            [x0, y1, self.z]])
        return self.T_room_building.inverse().apply(corners)[:, :2].astype(np.float32)

    def shared_length(self, other: 'Footprint', gap: float) -> float:
        """
        Return how long the two rectangles run side by side within ``gap`` of each other.

        0 when they are further apart (or on different floors). Rectangles
        that overlap give the overlap's longest extent.
        """
        if abs(self.z - other.z) > FLOOR_BAND_M:
            return 0.0
        half = gap / 2.0
        area, polygon = cv2.intersectConvexConvex(self.grown(half), other.grown(half))
        if polygon is None or area <= 0.0:
            return 0.0
        points = polygon.reshape(-1, 2).astype(float)
        return max(float(np.linalg.norm(u - v)) for u in points for v in points)


def footprints(building: BuildingMap) -> Dict[RoomKey, Footprint]:
    """Return the footprint of every sized room of the map."""
    return {key: Footprint(room) for key, room in building.rooms.items()
            if room.size is not None}


def neighbours(prints: Dict[RoomKey, Footprint], gap: float, min_length: float
               ) -> Dict[RoomKey, frozenset]:
    """Return, for each room, the rooms running alongside it within ``gap`` for ``min_length``."""
    keys = list(prints)
    out: Dict[RoomKey, set] = {k: set() for k in keys}
    for i, a in enumerate(keys):
        for b in keys[i + 1:]:
            if prints[a].shared_length(prints[b], gap) >= min_length:
                out[a].add(b)
                out[b].add(a)
    return {k: frozenset(v) for k, v in out.items()}


def components(links: Dict[RoomKey, Iterable[RoomKey]]) -> Dict[RoomKey, frozenset]:
    """Return, for each room, every room linked to it directly or through others."""
    out: Dict[RoomKey, frozenset] = {}
    for start in links:
        if start in out:
            continue
        seen: List[RoomKey] = [start]
        todo = [start]
        while todo:
            for other in links[todo.pop()]:
                if other not in seen:
                    seen.append(other)
                    todo.append(other)
        group = frozenset(seen)
        for k in seen:
            out[k] = group
    return out


def distance_outside(footprint: Footprint, xy: np.ndarray) -> float:
    """Return how far a point lies outside a footprint (0 inside)."""
    local = footprint.local(xy)[0]
    dx = max(-local[0], 0.0, local[0] - footprint.size[0])
    dy = max(-local[1], 0.0, local[1] - footprint.size[1])
    return math.hypot(dx, dy)
