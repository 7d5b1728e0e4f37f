"""
``pattern-locator bench --drive``: the drive through the floor over several seeds.

Each run is the demo's closed loop (:mod:`.drive_demo`: sim, camera_driver
and locator as processes over DDS) on one floor route with its own seed
(image noise, odometry noise); ``--compare-feed-forward`` runs every seed
twice, with the driver's odometry feed-forward and without. The table gives,
per run and over all runs: fix coverage, the error of the fixes while
driving and at stops (median, p95, max), the time between the last fix of
one card and the first of the next (handover), wrong ids and fixes of
another room's card, ``coverage_95``, the angle off the optical axis of the
card the locator told the head to centre, in located images while the base
turns (median, p95), and the VISCA traffic.
The machine's load (load average over its cores, before and after) is
printed with the table: ``--load N`` adds N busy processes for a loaded run.
``--as-hung-seed N`` hangs the sim's cards off their mapped poses (up to 5 cm
and 3 degrees) and ``--building-map PATH`` gives the locator another map
than ``config/floor_building.yaml`` (a surveyed one, ``survey_drive``): the
judge takes the truth from the as-hung world and the locator's map only to
place the fixes' frames.
"""

from contextlib import contextmanager
import json
import math
import os
from pathlib import Path
import subprocess
import sys
import time
from typing import Dict, Iterator, List, Optional, Sequence, Tuple

import numpy as np

from .drive_demo import DriveMetrics, DriveSetup, judge, run_drive, write_summary
from ..errors import ConfigError
from ..localization.building import BuildingMap, load_building
from ..sim.floor_file import load_floor_world


@contextmanager
def busy_processes(count: int) -> Iterator[None]:
    """Run ``count`` processes that only burn CPU (a loaded machine), stopped at the end."""
    procs = [subprocess.Popen([sys.executable, '-c', 'while True: pass'])
             for _ in range(max(0, count))]
    try:
        yield
    finally:
        for proc in procs:
            proc.kill()
            proc.wait()


def _load() -> str:
    one, five, _ = os.getloadavg()
    cores = os.cpu_count() or 1
    state = 'loaded' if one > cores else 'idle'
    return f'load average {one:.1f} (5 min {five:.1f}) on {cores} cores: {state}'


def _stats(values: np.ndarray, scale: float = 1.0) -> Tuple[float, float, float]:
    if values.size == 0:
        return math.nan, math.nan, math.nan
    return (float(np.median(values)) * scale, float(np.percentile(values, 95)) * scale,
            float(values.max()) * scale)


def _row(name: str, m: DriveMetrics) -> List[str]:
    drive = _stats(m.errors_m[m.driving], 100.0)
    still = _stats(m.errors_m[~m.driving], 100.0)
    hand = _stats(m.handovers_s)
    turn = _stats(m.off_axis_turning_deg)
    cmds = m.visca.get('commands_sent_per_s', math.nan)
    replies = m.visca.get('replies_per_s', math.nan)
    return [name, f'{100 * m.fix_coverage:.1f}', '{:.1f}/{:.1f}/{:.1f}'.format(*drive),
            '{:.1f}/{:.1f}/{:.1f}'.format(*still),
            '{:.2f}/{:.2f}/{:.2f}'.format(*hand) + f' ({m.handovers_s.size})',
            f'{m.wrong_ids}', f'{m.other_room}', f'{m.coverage_95:.2f}',
            '{:.2f}/{:.2f}'.format(*turn[:2]) + f' ({m.off_axis_turning_deg.size})',
            f'{cmds:.1f}/{replies:.1f}']


HEADER = ['run', 'cov %', 'err driving cm', 'err stops cm', 'handover s (n)', 'wrong',
          'other room', 'cov95', 'off-axis turning', 'VISCA cmd/reply /s']
LEGEND = ('cov %: fix coverage (a fix younger than 0.5 s had arrived); errors: median/p95/'
          'max of the base position; handover: last fix of a card to the first of the next; '
          "wrong: fixes of a card not in the image; other room: fixes of another room's "
          'card (through a door); cov95: fixes inside their own 95 % ellipsoid; off-axis '
          'turning: the angle off the optical axis of the card the head was told to centre, '
          'in located images while the base turns (median/p95 deg, images)')


def _table(rows: Sequence[Sequence[str]]) -> str:
    widths = [max(len(r[k]) for r in [HEADER, *rows]) for k in range(len(HEADER))]
    lines = ['  '.join(c.rjust(w) if k else c.ljust(w) for k, (c, w) in
                       enumerate(zip(row, widths))) for row in [HEADER, *rows]]
    lines.insert(1, '  '.join('-' * w for w in widths))
    return '\n'.join(lines)


def pooled(metrics: Sequence[DriveMetrics]) -> DriveMetrics:
    """Pool several runs' metrics into one (coverage weighted by route time)."""
    total = sum(m.duration_s for m in metrics)
    cat = np.concatenate
    visca: Dict[str, float] = {}
    for key in ('commands_sent_per_s', 'replies_per_s'):
        values = [m.visca[key] for m in metrics if key in m.visca]
        if values:
            visca[key] = float(np.mean(values))
    inside = sum(m.coverage_95 * m.errors_m.size for m in metrics if m.errors_m.size)
    n = sum(m.errors_m.size for m in metrics)
    return DriveMetrics(
        duration_s=total, images=sum(m.images for m in metrics),
        located=sum(m.located for m in metrics), wrong_ids=sum(m.wrong_ids for m in metrics),
        other_room=sum(m.other_room for m in metrics),
        fix_coverage=sum(m.fix_coverage * m.duration_s for m in metrics) / total,
        fix_coverage_by_stamp=sum(m.fix_coverage_by_stamp * m.duration_s
                                  for m in metrics) / total,
        errors_m=cat([m.errors_m for m in metrics]), driving=cat([m.driving for m in metrics]),
        coverage_95=inside / n if n else math.nan,
        handovers_s=cat([m.handovers_s for m in metrics]),
        off_axis_deg=cat([m.off_axis_deg for m in metrics]),
        off_axis_turning_deg=cat([m.off_axis_turning_deg for m in metrics]), rooms=[],
        visca=visca, latency_ms=cat([m.latency_ms for m in metrics]),
        unpaired=sum(m.unpaired for m in metrics))


def run_drive_bench(runs: int = 3, seed: int = 1, route: str = 'loop',
                    max_speed_m_s: float = 0.5, compare_feed_forward: bool = False,
                    load: int = 0, output_dir: str = 'out', building_map: Optional[str] = None,
                    as_hung_seed: Optional[int] = None) -> int:
    """
    Run the drive ``runs`` times (seeds ``seed``...); print the table; 0 if no wrong id.

    ``building_map``: the locator's map instead of ``config/floor_building.yaml``
    (a surveyed one: it must keep that map's room frames). ``as_hung_seed``:
    the sim hangs the cards off their mapped poses with this seed; the judge
    takes the truth from that same world.
    """
    out = Path(output_dir) / 'bench_drive'
    world = load_floor_world(as_hung_seed=as_hung_seed)
    locator_building = load_building(building_map) if building_map else None
    if locator_building is not None:
        _check_room_frames(locator_building, world)
    variants = [True, False] if compare_feed_forward else [True]
    print(f'bench --drive: route {route!r} of floor {world.floor} at up to {max_speed_m_s} '
          f'm/s, {runs} seed(s) from {seed}'
          + (', each with and without the odometry feed-forward' if compare_feed_forward
             else '') + f'; {load} busy process(es) added; logs in {out}/', flush=True)
    print(f'locator map {building_map or "config/floor_building.yaml"}; cards '
          + (f'as hung (seed {as_hung_seed})' if as_hung_seed is not None
             else 'where the map says'), flush=True)
    print(f'before: {_load()}', flush=True)
    results: Dict[bool, List[DriveMetrics]] = {v: [] for v in variants}
    rows = []
    started = time.monotonic()
    with busy_processes(load):
        for k in range(runs):
            for ff in variants:
                suffix = '' if len(variants) == 1 else (' ff' if ff else ' no ff')
                name = f'seed {seed + k}{suffix}'
                setup = DriveSetup(route=route, max_speed_m_s=max_speed_m_s, seed=seed + k,
                                   feed_forward=ff, building_map=building_map or '',
                                   as_hung_seed=-1 if as_hung_seed is None else as_hung_seed)
                run_dir = out / name.replace(' ', '_')
                observer = run_drive(run_dir, setup, progress=True)
                metrics = judge(observer, world, locator_building=locator_building)
                write_summary(metrics, run_dir / 'drive_summary.json',
                              {'seed': seed + k, 'feed_forward': ff, 'route': route,
                               'building_map': building_map, 'as_hung_seed': as_hung_seed})
                results[ff].append(metrics)
                rows.append(_row(name, metrics))
                print(f'  {name}: {metrics.located} fixes, coverage '
                      f'{100 * metrics.fix_coverage:.1f} %, wrong ids {metrics.wrong_ids}',
                      flush=True)
        after = _load()
    for ff in variants:
        label = 'all' + ('' if len(variants) == 1 else (' ff' if ff else ' no ff'))
        rows.append(_row(label, pooled(results[ff])))
    print()
    print(_table(rows))
    print(LEGEND)
    print(f'after: {after}; {time.monotonic() - started:.0f} s wall')
    summary = {('ff' if ff else 'no_ff'): [m.summary() for m in results[ff]]
               for ff in variants}
    out.mkdir(parents=True, exist_ok=True)
    path = out / 'bench_drive.json'
    path.write_text(json.dumps(summary, indent=2, default=str) + '\n')
    print(f'per-run summaries: {path}', flush=True)
    wrong = sum(m.wrong_ids for ms in results.values() for m in ms)
    return 0 if wrong == 0 else 1


def _check_room_frames(building: BuildingMap, world) -> None:
    """Raise ConfigError unless the map has the world's rooms, frames and frame poses."""
    for room in world.rooms:
        key = (room.floor, room.room)
        other = building.rooms.get(key)
        if other is None or other.frame != room.frame or np.linalg.norm(
                other.T_building_room.t - room.T_building_room.t) > 1e-6 or np.abs(
                other.T_building_room.R - room.T_building_room.R).max() > 1e-9:
            raise ConfigError(f'{building.source}: floor {key[0]} room {key[1]} is not the '
                              f"floor map's room (frame {room.frame!r} at its pose): fixes in "
                              'it could not be judged')
