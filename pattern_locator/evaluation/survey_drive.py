"""
A surveyed map of the drive demo's floor: the survey run on the floor world, for ``bench --drive``.

Issue 13's last target is that a surveyed map drives the demo as well as the
hand-written one. This module makes that map without rendering (the survey's
sightings are simulated, as ``bench --survey`` does for its whole floor):

* the floor world (``config/sim_floor.yaml`` with ``config/floor_building.yaml``)
  with its cards "as hung" by a seed (``load_floor_world(as_hung_seed=...)``,
  the very poses the sim then renders): the plan is the hand-written map,
  the truth the hung cards;
* a surveyor's walk (``sim.walk.make_walk``, a hand-held camera 1.25 m up)
  along :data:`SURVEY_ROUTE`: into each of the eight rooms and twice round
  the corridor loop; line of sight from the world's own solids (walls, door
  jambs and lintels, signs), drifting odometry (``drift_odometry``);
* sightings from ``survey.simulate`` (the detector's visibility rules and
  covariance, errors from the default NEES table) and the survey's
  optimisation (``survey.graph.optimise``), anchored on a few cards at their
  true poses (what a tape or a total station gives);
* the map written with every room of the hand-written map as an anchor
  room (``survey.mapfile.room_frames``): the rooms keep their frames, frame
  names, names and sizes, so the locator's fixes are in the same frames.

Run it as ``python -m pattern_locator.evaluation.survey_drive -o MAP
--as-hung-seed N``, then ``pattern-locator bench --drive --building-map MAP
--as-hung-seed N``.
"""

import argparse
from dataclasses import dataclass
import math
from pathlib import Path
import sys
from typing import List, Optional, Sequence, Tuple

import numpy as np

from .bench_survey import motion_of
from ..card.pattern import load_pattern_config, PatternConfig
from ..errors import PatternLocatorError
from ..localization.building import BuildingMap, load_building
from ..sim.floor_file import load_floor_world
from ..sim.floor_world import FloorWorld
from ..sim.walk import CAMERA_HEIGHT_M, FloorPlan, HungCard, make_walk, OdometryDrift, Walk
from ..survey.graph import optimise, SurveyOptions
from ..survey.mapfile import building_yaml, room_frames, write_text
from ..survey.record import default_survey_camera
from ..survey.simulate import simulate_sightings
from ..vision.geometry import rotation_angle

# The surveyor's route on the floor of config/sim_floor.yaml (x, y in metres):
# from the south corridor into rooms 1, 3, 4 and 2, up the east corridor into
# room 6, along the north corridor into rooms 8, 5 and 7, down the west
# corridor, then once more round the corridor loop (a loop ties the map).


def _visit(door_x: float, corridor_y: float, inside_y: float, west: float, east: float
           ) -> List[Tuple[float, float]]:
    """Return a room visit through a door in a south or north wall, back to the corridor."""
    return [(door_x, corridor_y), (door_x, inside_y), (west, inside_y), (east, inside_y),
            (door_x, inside_y), (door_x, corridor_y)]


SURVEY_ROUTE = np.array(
    [(3.5, 6.3)] + _visit(6.0, 6.3, 2.6, 3.0, 9.5) + _visit(9.0, 6.3, 10.0, 5.0, 11.0)
    + _visit(15.8, 6.3, 10.0, 14.0, 20.5) + _visit(18.6, 6.3, 2.6, 15.5, 22.0)
    + [(23.7, 6.3), (23.7, 15.2), (20.5, 15.2), (15.5, 15.2), (20.5, 15.2), (23.7, 15.2),
       (23.7, 18.9)]
    + _visit(18.6, 18.9, 22.6, 15.5, 22.0) + _visit(7.3, 18.9, 15.2, 4.5, 10.5)
    + _visit(6.0, 18.9, 22.6, 3.0, 9.5)
    + [(1.1, 18.9), (1.1, 6.3), (3.5, 6.3), (23.7, 6.3), (23.7, 18.9), (1.1, 18.9),
       (1.1, 6.3), (3.5, 6.3)], dtype=float)
# The anchors: the four corridor-end cards, at the corners of the loop.
DEFAULT_ANCHORS = ((4, 9, 1), (4, 13, 2), (4, 11, 1), (4, 14, 2))


@dataclass(frozen=True, eq=False)
class WorldPlan(FloorPlan):
    """A walk plan whose line of sight is the floor world's (its solids, in 3-D)."""

    world: Optional[FloorWorld] = None
    eye_height_m: float = CAMERA_HEIGHT_M

    def line_of_sight(self, eye_xy: np.ndarray, card: HungCard) -> bool:
        """Return True when no wall, jamb, lintel or sign cuts the eye-to-card line."""
        eye = np.array([eye_xy[0], eye_xy[1], self.floor_z + self.eye_height_m])
        return not bool(self.world.blocked(eye, card.T_true.t)[0])


def floor_plan(world: FloorWorld, route: np.ndarray = SURVEY_ROUTE) -> WorldPlan:
    """Return the world's cards as a walk plan: planned = the map's poses, true = as hung."""
    cards = tuple(HungCard(c.ids, c.code, c.map_card.T_building_card, c.T_building_card)
                  for c in world.cards)
    return WorldPlan(f'floor {world.floor} ({world.source})', world.floor, world.z, cards,
                     np.zeros((0, 4)), np.asarray(route, dtype=float), world=world)


@dataclass(frozen=True)
class CardError:
    """One card of a map against the truth: position (m) and rotation (deg) errors."""

    ids: Tuple[int, int, int]
    position_m: float
    rotation_deg: float
    anchor: bool


@dataclass(frozen=True, eq=False)
class SurveyedFloor:
    """A surveyed map of the floor: its text, what went in, and its cards' errors."""

    text: str
    world: FloorWorld
    walk: Walk
    sightings: int
    errors: Tuple[CardError, ...]          # the surveyed map's placed cards
    hand_errors: Tuple[CardError, ...]     # the hand-written map's cards, same truth
    missing: Tuple[Tuple[int, int, int], ...]


def map_card_errors(building: BuildingMap, world: FloorWorld,
                    anchors: Sequence[Tuple[int, int, int]] = ()) -> Tuple[CardError, ...]:
    """Return every card of ``building`` on the world's floor against the world's truth."""
    out = []
    for card in building.cards():
        if card.ids.floor != world.floor:
            continue
        true = world.card(card.ids).T_building_card
        out.append(CardError(card.ids.as_tuple(),
                             float(np.linalg.norm(card.T_building_card.t - true.t)),
                             math.degrees(rotation_angle(card.T_building_card.R, true.R)),
                             card.ids.as_tuple() in anchors))
    return tuple(out)


def survey_floor(as_hung_seed: int, seed: int = 1, rate_hz: float = 5.0,
                 anchors: Sequence[Tuple[int, int, int]] = DEFAULT_ANCHORS,
                 route: np.ndarray = SURVEY_ROUTE, pattern: Optional[PatternConfig] = None,
                 world_path: Optional[str] = None) -> SurveyedFloor:
    """
    Survey the floor world with its cards hung by ``as_hung_seed``; return the map's text.

    ``seed`` draws the walk's sway, the sightings' errors and the odometry's
    noise; ``rate_hz`` is the camera's frame rate. The map is checked by
    loading it back (``load_building``); its errors are those of the loaded
    map (the file's rounding included).
    """
    pattern = pattern if pattern is not None else load_pattern_config()
    world = load_floor_world(world_path, pattern, as_hung_seed=as_hung_seed)
    hand = world.building
    plan = floor_plan(world, route)
    walk = make_walk(plan, rate_hz=rate_hz, seed=seed)
    camera = default_survey_camera()
    sightings = simulate_sightings(plan, walk, camera, pattern, seed=seed + 100)
    motion = motion_of(walk, OdometryDrift(), seed + 200, camera)
    known = {ids: world.card(ids).T_building_card for ids in anchors}
    result = optimise(sightings, [motion], known, SurveyOptions())
    # Every room of the hand-written map is an anchor room: its frame (pose and
    # name), name and size carry over, so fixes come in the frames the robot knows.
    rooms = room_frames(result.cards, hand)
    placed = [c for c in result.cards if c.placed]
    missing = tuple(sorted(c.ids.as_tuple() for c in world.cards
                           if c.ids.as_tuple() not in {m.ids for m in placed}))
    header = [f'Surveyed (simulated) map of floor {world.floor} of {hand.source}: cards '
              f'as hung with seed {as_hung_seed}',
              f'pattern_locator.evaluation.survey_drive: walk seed {seed}, {walk.length_m:.0f} '
              f'm, {len(walk.frames)} frames at {rate_hz:g} Hz, {len(sightings)} simulated '
              f'sightings, drifting odometry',
              result.frame_note,
              "room frames: the hand-written map's (every room an anchor room)",
              "Poses in metres and degrees; std_dev about each room's axes."]
    footer = (['Not placed: ' + ', '.join(str(ids) for ids in missing)] if missing else [])
    text = building_yaml(result.cards, rooms, header, footer, building_frame=hand.frame,
                         floor_names=hand.floor_names)
    surveyed = _load_text(text, pattern)
    return SurveyedFloor(text, world, walk, len(sightings),
                         map_card_errors(surveyed, world, anchors),
                         map_card_errors(hand, world), missing)


def _load_text(text: str, pattern: PatternConfig) -> BuildingMap:
    """Return the building map of a YAML text (through a file: what the locator does)."""
    import tempfile
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / 'surveyed.yaml'
        path.write_text(text, encoding='utf-8')
        return load_building(path, pattern)


def error_lines(floor: SurveyedFloor) -> List[str]:
    """Return the summary of the surveyed and hand-written maps' card errors (mm, deg)."""
    def row(name: str, errors: Sequence[CardError]) -> str:
        pos = np.array([e.position_m for e in errors if not e.anchor]) * 1000.0
        rot = np.array([e.rotation_deg for e in errors if not e.anchor])
        if pos.size == 0:
            return f'| {name} | 0 | - | - | - | - |'
        return (f'| {name} | {pos.size} | {float(np.median(pos)):.1f} | '
                f'{float(np.sqrt(np.mean(pos ** 2))):.1f} | {float(pos.max()):.1f} | '
                f'{float(np.sqrt(np.mean(rot ** 2))):.2f} / {float(rot.max()):.2f} |')

    anchors = sum(e.anchor for e in floor.errors)
    return ['| map | cards judged | position median (mm) | RMS (mm) | max (mm) | '
            'rotation RMS / max (deg) |', '|---|---|---|---|---|---|',
            row(f'surveyed ({anchors} anchors not counted)', floor.errors),
            row('hand-written (the plan)', floor.hand_errors)]


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Write a surveyed map of the drive floor and print its card errors; return 0 (2: error)."""
    parser = argparse.ArgumentParser(
        prog='python -m pattern_locator.evaluation.survey_drive',
        description='Survey the drive floor (simulated sightings) into a building map for '
                    'bench --drive --building-map.')
    parser.add_argument('-o', '--output', required=True, help='the building map to write')
    parser.add_argument('--as-hung-seed', type=int, default=3,
                        help="the sim's as-hung seed of the cards (default 3)")
    parser.add_argument('--seed', type=int, default=1, help='walk, sightings and odometry seed')
    parser.add_argument('--rate', type=float, default=5.0, help='frames per second (default 5)')
    args = parser.parse_args(argv)
    try:
        floor = survey_floor(args.as_hung_seed, args.seed, args.rate)
        write_text(args.output, floor.text, 'the building map')
    except PatternLocatorError as exc:
        print(f'survey_drive: {exc}', file=sys.stderr)
        return 2
    print(f'{args.output}: {len(floor.errors)} of {len(floor.world.cards)} cards placed from '
          f'{floor.sightings} sightings along {floor.walk.length_m:.0f} m '
          f'({len(floor.walk.frames)} frames); cards as hung with seed {args.as_hung_seed}')
    if floor.missing:
        print('not placed: ' + ', '.join(str(ids) for ids in floor.missing))
    print('\n'.join(error_lines(floor)))
    return 0


if __name__ == '__main__':
    sys.exit(main())
