"""
``pattern-locator survey``: bags in, building map out (and ``survey --check``).

The steps: read each bag (:mod:`.bagio`), decide the camera's mount, detect
the cards in every frame (:mod:`.detect`), optimise the map
(:mod:`.graph`), write the building map, the cards' JSON and the report.
Every problem a user can cause is a ConfigError: the command line prints it
as one line and exits 2.
"""

from dataclasses import dataclass, replace
import json
import math
from pathlib import Path
import sys
import time
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from .bagio import BagData, camera_on_base, Mount, resolve_mount, scan_bag, SurveyTopics
from .detect import detect_bags, DetectionStats
from .graph import BagMotion, optimise, SurveyOptions, SurveyResult
from .mapfile import (building_yaml, cards_json, load_anchors, MapCard, room_frames,
                      write_text)
from .sightings import Sighting
from ..card.pattern import load_pattern_config, PatternConfig
from ..errors import ConfigError


@dataclass(frozen=True)
class SurveyRun:
    """Everything a survey produced: the bags' data, sightings, the optimised map."""

    bags: Tuple[BagData, ...]
    mounts: Tuple[Mount, ...]
    sightings: Tuple[Sighting, ...]
    detection: DetectionStats
    result: SurveyResult
    optimise_cpu_s: float


def motions_of(bags: Sequence[BagData], mounts: Sequence[Mount],
               sightings: Sequence[Sighting]) -> List[BagMotion]:
    """Return the graph's view of each bag: its odometry and the camera's mount per frame."""
    frames: Dict[int, Dict[int, int]] = {}
    for s in sightings:
        frames.setdefault(s.bag, {})[s.frame] = s.stamp_ns
    out = []
    for b, (bag, mount) in enumerate(zip(bags, mounts)):
        mount_of = {frame: camera_on_base(bag, mount, stamp)
                    for frame, stamp in frames.get(b, {}).items()}
        kwargs = {'cameras': {frame: bag.camera_at(stamp)
                              for frame, stamp in frames.get(b, {}).items()}}
        if bag.odom_stamps_ns is not None and len(bag.odom_stamps_ns) > 1:
            kwargs.update(odom_stamps_ns=bag.odom_stamps_ns,
                          odom_R=np.array([T.R for T in bag.odom_poses]),
                          odom_p=np.array([T.t for T in bag.odom_poses]))
        out.append(BagMotion(bag.path, mount.source, mount_of, **kwargs))
    return out


def run_survey(bag_paths: Sequence[str], topics: SurveyTopics = SurveyTopics(),
               anchors_path: Optional[str] = None, jobs: Optional[int] = None,
               camera_mount: Optional[Sequence[float]] = None,
               options: SurveyOptions = SurveyOptions(),
               pattern: Optional[PatternConfig] = None, progress: bool = True,
               refine_dots: bool = False) -> SurveyRun:
    """Read, detect and optimise; return the run (no files written)."""
    pattern = pattern if pattern is not None else load_pattern_config()
    bags = tuple(scan_bag(p, topics) for p in bag_paths)
    mounts = tuple(resolve_mount(b, camera_mount) for b in bags)
    anchors = None
    if anchors_path is not None:
        anchors = {c.ids.as_tuple(): c.T_building_card
                   for c in load_anchors(anchors_path, pattern).cards()}
    sightings, stats = detect_bags(bags, mounts, pattern, jobs=jobs, progress=progress)
    if not sightings:
        raise ConfigError('survey: no card was seen in '
                          + ', '.join(str(p) for p in bag_paths)
                          + (f' ({stats.bad_frames} frames unusable: {stats.first_problem})'
                             if stats.bad_frames else ''))
    start = time.process_time()
    if refine_dots:
        options = replace(options, refine_dots=True)
    result = optimise(sightings, motions_of(bags, mounts, sightings), anchors, options)
    return SurveyRun(bags, mounts, tuple(sightings), stats, result,
                     time.process_time() - start)


def survey_main(bag_paths: Sequence[str], output: str, anchors: Optional[str] = None,
                cards_json_path: Optional[str] = None, report_dir: Optional[str] = None,
                topics: SurveyTopics = SurveyTopics(), jobs: Optional[int] = None,
                camera_mount: Optional[Sequence[float]] = None,
                options: SurveyOptions = SurveyOptions(), refine_dots: bool = False) -> int:
    """Survey the bags into ``output``; print a summary; return the exit status (0)."""
    pattern = load_pattern_config()
    anchor_map = load_anchors(anchors, pattern) if anchors is not None else None
    for path in (output, cards_json_path):
        if path is not None and not Path(path).parent.exists():
            raise ConfigError(f'{path}: no such directory {Path(path).parent}')
    run = run_survey(bag_paths, topics, anchors, jobs, camera_mount, options, pattern,
                     refine_dots=refine_dots)
    cards = run.result.cards
    rooms = room_frames(cards, anchor_map)
    header, footer = _notes(run, bag_paths, rooms)
    text = building_yaml(cards, rooms, header, footer,
                         building_frame=anchor_map.frame if anchor_map else 'building',
                         floor_names=anchor_map.floor_names if anchor_map else None)
    write_text(output, text, 'the building map')
    if cards_json_path is not None:
        write_text(cards_json_path, json.dumps(cards_json(cards), indent=1) + '\n',
                   'the cards JSON')
    if report_dir is not None:
        from .report import write_report
        write_report(report_dir, run, rooms, header + [''] + footer)
    for line in header[2:] + footer:
        print(line)
    print(f'{output}: {sum(c.placed for c in cards)} cards placed in {len(rooms)} rooms')
    return 0


def _notes(run: SurveyRun, bag_paths: Sequence[str], rooms) -> Tuple[List[str], List[str]]:
    """Return the map's header and footer comment lines (also printed)."""
    result, stats = run.result, run.detection
    header = ['Surveyed by pattern-locator survey ' + ' '.join(str(p) for p in bag_paths),
              "Poses in metres and degrees; std_dev about each room's axes."]
    for bag, mount in zip(run.bags, run.mounts):
        odom = f'odometry {bag.odom_topic}' if bag.odom_topic else 'no odometry'
        header.append(f'{bag.path}: {bag.n_images} images on {bag.image_topic}, {odom}, '
                      f'camera mount from {mount.source}')
    for b, bag in enumerate(run.bags):
        if b in result.calibration:
            scale, bias = result.calibration[b]
            header.append(f'{bag.path}: odometry scale error {-scale / (1 + scale):+.2%}, '
                          f'yaw bias {-math.degrees(bias):+.3f} deg/m (corrected)')
        elif bag.odom_topic:
            header.append(f'{bag.path}: odometry calibration not estimated (too little '
                          'odometry between sightings)')
    header.append(f'detection: {stats.frames} frames, {stats.sightings} sightings in '
                  f'{stats.frames_with_cards} frames, {stats.wall_s:.1f} s on {stats.jobs} '
                  f'process(es)' + (f'; {stats.bad_frames} frames unusable '
                                    f'({stats.first_problem})' if stats.bad_frames else '')
                  + (f'; {stats.unsure_flips} poses left out, their planar flip unsure or '
                     'in one valley' if stats.unsure_flips else ''))
    header.append(f'optimisation: {result.frames} keyframes, {result.used_sightings} '
                  f'sightings used, {result.outliers} dropped as outliers, '
                  f'{result.rounds} rounds, {run.optimise_cpu_s:.1f} s CPU')
    header.append(result.frame_note)
    anchored = sorted(k for k, r in rooms.items() if r.source == 'anchors')
    header.append('room frames: ' + ("on each room's lowest-numbered placed card (upright)"
                                     if not anchored else
                                     f'{len(anchored)} from the anchors, the others on their '
                                     'lowest-numbered placed card (upright)'))
    footer = []
    once = [c for c in result.cards if c.connected and not c.placed]
    apart = [c for c in result.cards if not c.connected]
    if once:
        footer.append('Seen once, not placed: ' + ', '.join(_label(c) for c in once))
    if apart:
        footer.append('Not connected to the building frame, not placed: '
                      + ', '.join(f'{_label(c)} ({c.sightings} sightings)' for c in apart))
    return header, footer


def _label(card: MapCard) -> str:
    f, r, p = card.ids
    return f'floor {f} room {r} card {p}'


def parse_mount(values: Optional[Sequence[float]]) -> Optional[Tuple[float, ...]]:
    """Return ``--camera-mount``'s six numbers (degrees turned to radians for roll pitch yaw)."""
    if values is None:
        return None
    values = [float(v) for v in values]
    if not all(math.isfinite(v) for v in values):
        raise ConfigError('--camera-mount needs finite numbers x y z (m) roll pitch yaw (deg)')
    return tuple(values[:3]) + tuple(math.radians(v) for v in values[3:])


def options_from(no_odometry: bool = False, no_vertical_prior: bool = False,
                 card_height: Optional[float] = None) -> SurveyOptions:
    """Return the graph's options from the command line's switches."""
    if card_height is not None and not (math.isfinite(card_height) and card_height > 0):
        raise ConfigError(f'--card-height must be a positive number of metres, got '
                          f'{card_height!r}')
    return replace(SurveyOptions(), use_odometry=not no_odometry,
                   vertical_prior=not no_vertical_prior, card_height_m=card_height)


def progress_enabled() -> bool:
    """Return True when stderr is a terminal (tqdm's own rule with ``disable=None``)."""
    return sys.stderr.isatty()
