"""
``pattern-locator bench --survey``: how well the survey maps cards, and how fast.

Three walks, each with the truth of every card "as hung" (off the plan by up
to 5 cm and 3 degrees) and odometry with a 3 % scale error, a 0.5 deg/m yaw
bias and random-walk noise (``sim.walk``):

* **room (rendered)**: the paper's room, six cards, two minutes of walking at
  0.35 m/s, 10 frames/s, 1280x720 with a 90 degree field of view. Every
  frame is rendered (the project's ray-cast renderer) and goes through the
  detector and the exact estimator, in a process pool, as the survey does;
* **room and corridor (rendered)**: the room plus a 20 m corridor (14 cards),
  about three minutes (skipped by ``--quick``);
* **floor (simulated sightings)**: a whole floor, 36 cards round a 76 m
  corridor loop and four rooms, walked twice round (about 200 m, 5,600
  frames). Rendering it would take an hour on two shared cores, so its
  sightings come from ``survey.simulate``: the detector's visibility rules
  and its reported covariance at the true pose, with errors drawn from that
  covariance scaled per distance and view-angle bin by the NEES measured on
  the rendered room's sightings. Several seeds give the ellipse figure.

Figures: card position error (RMS, max, mm) and orientation error (deg),
absolute (the map's frame fixed by one anchor: the lowest-numbered card at
its true pose) and relative (after the best-fit similarity); cards mapped of
those seen twice or more; detection time per 1000 frames (pool wall time and
summed CPU); optimisation CPU time per 1000 frames on one core (the process
pinned to one CPU); and the fraction of cards whose true position error lies
inside their 95 % ellipsoid (chi-square, 3 dof).
"""

from dataclasses import dataclass
import math
import multiprocessing
import os
import time
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from ..card.pattern import load_pattern_config
from ..sim.walk import (drift_odometry, FloorPlan, make_walk, OdometryDrift, paper_room_plan,
                        ring_floor_plan, room_corridor_plan, Walk, WalkRenderer)
from ..survey.align import apply, fit_transform
from ..survey.detect import default_jobs, sightings_of
from ..survey.graph import BagMotion, optimise, SurveyOptions
from ..survey.record import default_survey_camera
from ..survey.sightings import Sighting
from ..survey.simulate import (calibrate, sighting_nees, SightingModel, simulate_sightings,
                               view_angle_deg)
from ..vision.geometry import rotation_angle

CHI2_3_95 = 7.815

_WORKER = {}


def _init(plan: FloorPlan, walk: Walk, camera) -> None:
    from ..vision.locate import CardLocator
    pattern = load_pattern_config()
    _WORKER.update(plan=plan, walk=walk, camera=camera, renderer=WalkRenderer(plan, camera,
                                                                              pattern),
                   locator=CardLocator(pattern, fit_prior=False))     # as the survey's


def _render_and_detect(frame: int):
    """Render one frame of the walk and detect its cards; return (sightings, detect CPU s)."""
    from ..vision.pose_exact import PosePrior
    walk, camera = _WORKER['walk'], _WORKER['camera']
    sample = int(walk.frames[frame])
    image = _WORKER['renderer'].render(walk.camera_pose(sample), seed=10_000 + frame)
    up = walk.T_base_camera.R.T @ np.array([0.0, 0.0, 1.0])
    start = time.process_time()
    located = _WORKER['locator'].locate(image, camera, PosePrior(up_in_camera=up))
    cpu = time.process_time() - start
    stamp = round(float(walk.times_s[sample]) * 1e9)
    # As the survey takes them (survey/detect.py): no unsure planar flip.
    out, _ = sightings_of(located, 0, frame, stamp)
    return out, cpu


@dataclass
class Rendered:
    """The rendered sightings of a walk and what detecting them cost."""

    sightings: List[Sighting]
    frames: int
    detect_cpu_s: float
    wall_s: float
    jobs: int


def render_walk(plan: FloorPlan, walk: Walk, jobs: int) -> Rendered:
    """Render and detect every frame of a walk in a process pool."""
    camera = default_survey_camera()
    frames = list(range(len(walk.frames)))
    start = time.perf_counter()
    context = multiprocessing.get_context('spawn')
    with context.Pool(jobs, initializer=_init, initargs=(plan, walk, camera)) as pool:
        results = pool.map(_render_and_detect, frames, chunksize=8)
    sightings = [s for found, _ in results for s in found]
    return Rendered(sightings, len(frames), sum(c for _, c in results),
                    time.perf_counter() - start, jobs)


def motion_of(walk: Walk, drift: OdometryDrift, seed: int, camera=None) -> BagMotion:
    """Return the graph's view of a simulated walk: drifting odometry, fixed mount."""
    odometry = drift_odometry(walk, drift, seed=seed)
    stamps = np.array([round(float(t) * 1e9) for t in walk.times_s], dtype=np.int64)
    frames = range(len(walk.frames))
    return BagMotion('sim', 'tf_static', {f: walk.T_base_camera for f in frames},
                     stamps, np.array([T.R for T in odometry]), np.array([T.t for T in odometry]),
                     cameras={f: camera for f in frames} if camera is not None else {})


@dataclass
class MapErrors:
    """A surveyed map against the truth."""

    abs_rms_mm: float
    abs_max_mm: float
    abs_rot_rms_deg: float
    rel_rms_mm: float
    rel_max_mm: float
    rel_rot_rms_deg: float
    mapped: int
    seen_twice: int
    inside: int
    judged: int
    optimise_cpu_s: float


def map_errors(result, plan: FloorPlan, anchor: Tuple[int, int, int], cpu_s: float
               ) -> MapErrors:
    """Return the errors of an optimised map against the plan's truth."""
    placed = [c for c in result.cards if c.placed]
    truth = {c.ids.as_tuple(): c.T_true for c in plan.cards}
    est = np.array([c.T_building_card.t for c in placed])
    tru = np.array([truth[c.ids].t for c in placed])
    absolute = [c for c in placed if c.ids != anchor]
    ab = np.array([np.linalg.norm(c.T_building_card.t - truth[c.ids].t) for c in absolute])
    ab_rot = np.array([math.degrees(rotation_angle(c.T_building_card.R, truth[c.ids].R))
                       for c in absolute])
    T, s = fit_transform(est, tru, scale=True)
    rel = np.linalg.norm(apply(T, s, est) - tru, axis=1)
    rel_rot = np.array([math.degrees(rotation_angle(T.R @ c.T_building_card.R, truth[c.ids].R))
                        for c in placed])
    inside = 0
    for c in absolute:
        e = c.T_building_card.t - truth[c.ids].t
        inside += float(e @ np.linalg.solve(c.covariance[:3, :3], e)) <= CHI2_3_95
    twice = sum(c.sightings >= 2 for c in result.cards)
    mapped = sum(c.placed and c.sightings >= 2 for c in result.cards)
    rms = (lambda v: float(np.sqrt(np.mean(np.square(v)))) if len(v) else float('nan'))
    mx = (lambda v: float(np.max(v)) if len(v) else float('nan'))
    return MapErrors(rms(ab) * 1e3, mx(ab) * 1e3, rms(ab_rot), rms(rel) * 1e3, mx(rel) * 1e3,
                     rms(rel_rot), mapped, twice, inside, len(absolute), cpu_s)


def _pinned_optimise(sightings, motions, anchors, options):
    """Optimise on one CPU; return (result, CPU seconds)."""
    previous = None
    if hasattr(os, 'sched_setaffinity'):
        previous = os.sched_getaffinity(0)
        os.sched_setaffinity(0, {min(previous)})
    try:
        start = time.process_time()
        result = optimise(sightings, motions, anchors, options)
        return result, time.process_time() - start
    finally:
        if previous is not None:
            os.sched_setaffinity(0, previous)


def nees_table(sightings: Sequence[Sighting], plan: FloorPlan, walk: Walk):
    """Return the NEES per distance and view-angle bin of rendered sightings."""
    truth = {c.ids.as_tuple(): c.T_true for c in plan.cards}
    rows = []
    for s in sightings:
        T_true = walk.camera_pose(int(walk.frames[s.frame])).inverse() @ truth[s.ids]
        rows.append((float(np.linalg.norm(T_true.t)), view_angle_deg(T_true),
                     sighting_nees(s, T_true)))
    return calibrate(rows), rows


def _row(name: str, e: MapErrors, frames: int) -> str:
    return (f'| {name} | {e.abs_rms_mm:.2f} / {e.abs_max_mm:.2f} | {e.abs_rot_rms_deg:.3f} | '
            f'{e.rel_rms_mm:.2f} / {e.rel_max_mm:.2f} | {e.rel_rot_rms_deg:.3f} | '
            f'{e.mapped}/{e.seen_twice} | {e.inside}/{e.judged} | '
            f'{1000.0 * e.optimise_cpu_s / frames:.2f} |')


HEADER = ('| walk | absolute RMS / max (mm) | abs. orientation RMS (deg) | relative RMS / max '
          '(mm) | rel. orientation RMS (deg) | mapped / seen twice | inside 95 % ellipse | '
          'optimisation CPU s per 1000 frames |\n|---|---|---|---|---|---|---|---|')


def _rendered_section(name: str, plan: FloorPlan, walk: Walk, jobs: int, seed: int,
                      lines: List[str]) -> Tuple[Rendered, list]:
    rendered = render_walk(plan, walk, jobs)
    anchor = min(c.ids.as_tuple() for c in plan.cards)
    anchors = {anchor: plan.card(anchor).T_true}
    motion = motion_of(walk, OdometryDrift(), seed + 1, default_survey_camera())
    for label, options in ((f'{name}, odometry', SurveyOptions()),
                           (f'{name}, odometry, dots refined (bundle adjustment)',
                            SurveyOptions(refine_dots=True)),
                           (f'{name}, no odometry', SurveyOptions(use_odometry=False))):
        result, cpu = _pinned_optimise(rendered.sightings, [motion], anchors, options)
        lines.append(_row(label, map_errors(result, plan, anchor, cpu), rendered.frames))
    return rendered, anchors


def run_survey_bench(quick: bool = False, seed: int = 1, floor_seeds: Optional[int] = None
                     ) -> int:
    """Run the survey benchmark and print its tables; return 0."""
    jobs = default_jobs()
    print(f'pattern_locator bench --survey (seed {seed}{", quick" if quick else ""}); '
          f'{jobs} detection processes; optimisation pinned to one CPU')
    lines = [HEADER]
    detection = []
    room = paper_room_plan(seed)
    room_walk = make_walk(room, seed=seed, duration_s=20.0 if quick else None)
    print(f'room: {len(room_walk.frames)} frames, {room_walk.length_m:.1f} m, '
          f'{room_walk.times_s[-1]:.0f} s; rendering and detecting ...', flush=True)
    rendered, _ = _rendered_section('room (rendered)', room, room_walk, jobs, seed, lines)
    detection.append(('room (rendered)', rendered))
    table, rows = nees_table(rendered.sightings, room, room_walk)
    if not quick:
        corridor = room_corridor_plan(seed)
        corridor_walk = make_walk(corridor, seed=seed)
        print(f'room and corridor: {len(corridor_walk.frames)} frames, '
              f'{corridor_walk.length_m:.1f} m; rendering and detecting ...', flush=True)
        more, _ = _rendered_section('room and corridor (rendered)', corridor, corridor_walk,
                                    jobs, seed, lines)
        detection.append(('room and corridor (rendered)', more))
        more_table, more_rows = nees_table(more.sightings, corridor, corridor_walk)
        table, rows = calibrate(rows + more_rows), rows + more_rows
    model = SightingModel(nees=table)
    floor = ring_floor_plan(seed)
    floor_walk = make_walk(floor, seed=seed, rate_hz=3.0 if quick else 10.0)
    n_seeds = floor_seeds if floor_seeds is not None else (1 if quick else 10)
    print(f'floor: {len(floor_walk.frames)} frames, {floor_walk.length_m:.1f} m, '
          f'{len(floor.cards)} cards; {n_seeds} seeds of simulated sightings ...', flush=True)
    camera = default_survey_camera()
    pattern = load_pattern_config()
    anchor = min(c.ids.as_tuple() for c in floor.cards)
    anchors = {anchor: floor.card(anchor).T_true}
    totals: Dict[str, List[MapErrors]] = {}
    for k in range(n_seeds):
        sightings = simulate_sightings(floor, floor_walk, camera, pattern, model,
                                       seed=seed * 100 + k)
        motion = motion_of(floor_walk, OdometryDrift(), seed * 100 + k + 50)
        for label, options in (('floor (simulated sightings), odometry', SurveyOptions()),
                               ('floor (simulated sightings), no odometry',
                                SurveyOptions(use_odometry=False))):
            result, cpu = _pinned_optimise(sightings, [motion], anchors, options)
            totals.setdefault(label, []).append(map_errors(result, floor, anchor, cpu))
    for label, errors in totals.items():
        lines.append(_row(f'{label}, {len(errors)} seeds', _merge(errors),
                          len(floor_walk.frames) * len(errors)))
    print()
    print('\n'.join(lines))
    print()
    print('| walk | frames | detection wall s per 1000 frames | detection CPU s per 1000 '
          'frames | sightings per frame |\n|---|---|---|---|---|')
    for name, r in detection:
        print(f'| {name} | {r.frames} | {1000.0 * r.wall_s / r.frames:.1f} ({r.jobs} '
              f'processes, rendering included) | {1000.0 * r.detect_cpu_s / r.frames:.1f} | '
              f'{len(r.sightings) / max(r.frames, 1):.2f} |')
    print()
    print('NEES of the rendered sightings (e^T Sigma^-1 e / 6 over (camera position, '
          'rotation) against the truth; rows: distance 0-3, 3-5, 5+ m; columns: view angle '
          "0-30, 30-50, 50+ deg); from the median (used to draw the floor's sighting errors) "
          'and the mean (gross errors included):')
    for row, mean_row in zip(table, calibrate(rows, robust=False)):
        print('  ' + '  '.join(f'{v:6.2f}' for v in row) + '    |  '
              + '  '.join(f'{v:7.2f}' for v in mean_row))
    print(f'  ({len(rows)} rendered sightings; overall mean '
          f'{np.mean([r[2] for r in rows]):.2f})')
    return 0


def _merge(errors: Sequence[MapErrors]) -> MapErrors:
    """Return the errors of several seeds together (RMS over all, max of maxima, sums)."""
    def rms(name):
        return float(np.sqrt(np.mean([getattr(e, name) ** 2 for e in errors])))
    return MapErrors(rms('abs_rms_mm'), max(e.abs_max_mm for e in errors),
                     rms('abs_rot_rms_deg'), rms('rel_rms_mm'),
                     max(e.rel_max_mm for e in errors), rms('rel_rot_rms_deg'),
                     sum(e.mapped for e in errors), sum(e.seen_twice for e in errors),
                     sum(e.inside for e in errors), sum(e.judged for e in errors),
                     sum(e.optimise_cpu_s for e in errors))
