"""
The floor plan as a matplotlib plot: walls, doors, obstacles, rooms, cards and tracks.

ROS-free; matplotlib is imported when a plot is made, with its object API
(no pyplot state), so it works headless. Metres on both axes, equal
aspect. Cards are short bars on their wall with a tick pointing into the
room, labelled ``room.card`` (the floor is in the title). Tracks are
(N, 2) arrays of building x, y (the true path, the located path, ...).
"""

from pathlib import Path
from typing import Any, Mapping, Optional, Sequence, Union

import numpy as np

from .floor_world import FloorWorld

# Distinct, print-friendly colours for tracks, in order.
TRACK_COLOURS = ('tab:blue', 'tab:red', 'tab:green', 'tab:orange', 'tab:purple', 'tab:brown')


def plot_floor_plan(world: FloorWorld, ax: Optional[Any] = None,
                    tracks: Optional[Mapping[str, np.ndarray]] = None,
                    points: Optional[Mapping[str, np.ndarray]] = None,
                    title: Optional[str] = None, label_cards: bool = True,
                    label_rooms: bool = True) -> Any:
    """
    Draw the floor plan on ``ax`` (a new figure's axes if None) and return the axes.

    ``tracks``: name -> (N, 2) path drawn as a line; ``points``: name ->
    (N, 2) drawn as dots (fixes, say). Both are labelled in the legend.
    """
    if ax is None:
        from matplotlib.figure import Figure
        xmin, ymin, xmax, ymax = world.bounds()
        width = 10.0
        height = max(3.0, width * (ymax - ymin) / max(xmax - xmin, 1e-9))
        ax = Figure(figsize=(width, min(height, 14.0)), layout='constrained').add_subplot()
    from matplotlib.patches import Polygon, Rectangle
    solids = world.solids
    for k in range(len(solids)):
        corners = solids.corners(k)
        footprint = corners[[0, 2, 6, 4], :2]
        above_floor = solids.low[k, 2] - world.z > 1e-6
        is_wall = k < len(solids) - len(world.obstacles)
        if is_wall and not above_floor:
            ax.add_patch(Polygon(footprint, closed=True, facecolor='0.35', edgecolor='0.2',
                                 linewidth=0.5, zorder=2))
        elif is_wall:
            # A lintel: the wall above a door; the door is the gap below it.
            ax.add_patch(Polygon(footprint, closed=True, facecolor='none', edgecolor='0.45',
                                 linewidth=0.6, linestyle=':', zorder=2))
        else:
            ax.add_patch(Polygon(footprint, closed=True, facecolor='tab:olive',
                                 edgecolor='tab:olive', linewidth=1.0, zorder=3))
    for room in world.rooms:
        if room.size is None:
            continue
        origin = room.T_building_room.t[:2]
        yaw = float(np.degrees(np.arctan2(room.T_building_room.R[1, 0],
                                          room.T_building_room.R[0, 0])))
        ax.add_patch(Rectangle(tuple(origin), room.size[0], room.size[1], angle=yaw,
                               facecolor='0.96', edgecolor='none', zorder=0))
        if label_rooms:
            # Corridors (narrow rooms) are labelled a quarter along, along their length.
            length, width = room.size[0], room.size[1]
            at = np.array([length / 2.0, width / 2.0, 0.0])
            rotation = yaw
            if min(length, width) < 3.0:
                at[0 if length >= width else 1] *= 0.5
                rotation = yaw + (0.0 if length >= width else 90.0)
            centre = room.T_building_room.apply(at[None])[0]
            wide = min(length, width) >= 3.0
            name = f'room {room.room}' + (f'\n{room.name}' if room.name and wide else '')
            ax.text(centre[0], centre[1], name, ha='center', va='center', fontsize=7,
                    color='0.45', rotation=(rotation + 90.0) % 180.0 - 90.0, zorder=1)
    half = float(world.pattern.card_size) / 2.0
    for card in world.cards:
        T = card.T_building_card
        a, b = T.apply(np.array([[-half, 0.0, 0.0], [half, 0.0, 0.0]]))[:, :2]
        centre, normal = T.t[:2], T.R[:2, 2]
        ax.plot([a[0], b[0]], [a[1], b[1]], color='tab:red', linewidth=2.5,
                solid_capstyle='butt', zorder=4)
        tip = centre + 0.35 * normal
        ax.plot([centre[0], tip[0]], [centre[1], tip[1]], color='tab:red', linewidth=0.8,
                zorder=4)
        if label_cards:
            label = centre + 0.75 * normal
            ax.text(label[0], label[1], f'{card.ids.room}.{card.ids.pattern}', fontsize=6,
                    ha='center', va='center', color='darkred', zorder=5)
    for k, (name, xy) in enumerate((tracks or {}).items()):
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        ax.plot(xy[:, 0], xy[:, 1], color=TRACK_COLOURS[k % len(TRACK_COLOURS)],
                linewidth=1.2, label=name, zorder=6)
    for k, (name, xy) in enumerate((points or {}).items()):
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        colour = TRACK_COLOURS[(k + len(tracks or {})) % len(TRACK_COLOURS)]
        ax.plot(xy[:, 0], xy[:, 1], linestyle='none', marker='.', markersize=3,
                color=colour, label=name, zorder=7)
    xmin, ymin, xmax, ymax = world.bounds()
    pad = 0.8
    ax.set_xlim(xmin - pad, xmax + pad)
    ax.set_ylim(ymin - pad, ymax + pad)
    ax.set_aspect('equal')
    ax.set_xlabel('x (m, building frame)')
    ax.set_ylabel('y (m, building frame)')
    ax.set_title(title if title is not None else
                 f'floor {world.floor}: cards labelled room.card')
    if tracks or points:
        ax.legend(loc='upper right', fontsize=7)
    return ax


def save_floor_plan(world: FloorWorld, path: Union[str, Path],
                    tracks: Optional[Mapping[str, np.ndarray]] = None,
                    points: Optional[Mapping[str, np.ndarray]] = None,
                    title: Optional[str] = None, dpi: int = 150) -> Path:
    """Write the plan (PNG, PDF or SVG by the file's suffix) and return its path."""
    ax = plot_floor_plan(world, tracks=tracks, points=points, title=title)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    ax.figure.savefig(path, dpi=dpi)
    return path


def track_xy(poses: Sequence[Any]) -> np.ndarray:
    """Return the (N, 2) x, y of a sequence of poses (``.t``) for a track."""
    return np.array([[float(p.t[0]), float(p.t[1])] for p in poses]).reshape(-1, 2)
