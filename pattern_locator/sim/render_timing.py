"""
How long the floor sim takes per frame: ``python -m pattern_locator.sim.render_timing``.

ROS-free benchmark (a separate command, not a test). It drives a route of
the floor, points the head at the nearest card it can see whole (the
truth's oracle gaze, held still over the exposure, so the base's motion
blurs the cards as a lagging head would), zooms so the card is about a
quarter of the image wide, and times :meth:`FloorSim.frame` (rendering
and truth) at 640x480 for each exposure mode, in the same run, with the
one-room ``SimScene`` on the paper's route (zoomed the same way) as the
reference. Prints mean, p99 and max per frame, and the share of frames
that show a card. A blurred card's box is bigger, so more often takes
fewer sub-samples per pixel (``fast_render.MAX_BOX_SAMPLES``): blur can
make a frame cheaper.
"""

import argparse
import sys
import time
from typing import Callable, Dict, List, Optional, Sequence

import numpy as np

from .floor_sim import Exposure, FloorSim
from .world import SimRoute, SimScene
from ..visca.zoom_table import ZoomTable

MODES: Dict[str, Exposure] = {
    'sharp': Exposure(0.02, blur=False),
    'blur 20 ms': Exposure(0.02),
    'blur 20 ms, interlaced': Exposure(0.02, interlace=True),
}


def _row(name: str, times: Sequence[float], shown: Optional[int] = None) -> str:
    ms = 1000.0 * np.asarray(times)
    cards = '' if shown is None else f'{100.0 * shown / len(times):8.0f}'
    return (f'{name:<36}{len(ms):7d}{ms.mean():9.1f}{np.percentile(ms, 99):9.1f}'
            f'{ms.max():9.1f}{cards}')


def time_floor(route: str, frames: int, seed: int,
               clock: Callable[[], float] = time.perf_counter) -> List[str]:
    """Return the table's rows for the floor's route, one per exposure mode."""
    table = ZoomTable.load()
    rows = []
    sims = {name: FloorSim.floor(route, exposure=exposure, seed=seed)
            for name, exposure in MODES.items()}
    first = next(iter(sims.values()))
    times = np.linspace(0.0, first.duration_s, frames)
    plans = []
    for t in times:
        state = first.state(float(t))
        gaze = first.scene.oracle_gaze(state.pose)
        if gaze is None:
            plans.append((float(t), (0.0, 0.0), table.camera_at(0)))
            continue
        ids, pan, tilt = gaze
        distance = float(np.linalg.norm(first.world.card(ids).T_building_card.t
                                        - first.scene.true_camera_pose(state.pose, pan,
                                                                       tilt).t))
        plans.append((float(t), (pan, tilt),
                      _zoomed(table, distance, float(first.world.pattern.card_size))))
    for sim in sims.values():
        sim.frame(0.0, lambda _: (0.0, 0.0), table.camera_at(0))      # warm the caches
    spent: Dict[str, List[float]] = {name: [] for name in sims}
    shown = dict.fromkeys(sims, 0)
    names = list(sims)
    for k, (t, angles, camera) in enumerate(plans):
        # Modes take turns going first, so that a busy spell hits them alike.
        for name in names[k % len(names):] + names[:k % len(names)]:
            start = clock()
            frame = sims[name].frame(t, lambda _, a=angles: a, camera, seed=k)
            spent[name].append(clock() - start)
            shown[name] += bool(frame.truth.views)
    for name in names:
        rows.append(_row(f'floor {route}: {name}', spent[name], shown[name]))
    return rows


def _zoomed(table: ZoomTable, distance: float, card_size: float):
    """Return the camera zoomed so that the card is a quarter of the image wide."""
    return table.camera_at(table.zoom_for_focal(0.25 * table.width * distance / card_size))


def time_room(frames: int, clock: Callable[[], float] = time.perf_counter) -> str:
    """Return the row of the one-room SimScene on the paper route (the reference)."""
    scene = SimScene()
    table = ZoomTable.load()
    route = SimRoute.paper_route('drive', dwell_s=1.0)
    spent = []
    for k, t in enumerate(np.linspace(0.0, route.duration_s, frames)):
        base = route.pose_at(float(t))
        stop = route.stop_at(float(t))
        card = route.stops[stop if stop is not None else 0].card
        pan, tilt = scene.card_angles(base, 0.0, 0.0, card)
        distance = float(np.linalg.norm(scene.card(card).T_room_card.t - scene.true_camera_pose(
            base, pan, tilt).t))
        camera = _zoomed(table, distance, float(scene.pattern.card_size))
        start = clock()
        scene.render(base, pan, tilt, camera, seed=k)
        spent.append(clock() - start)
    return _row('one room (SimScene)', spent)


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Print the table; return the exit status."""
    parser = argparse.ArgumentParser(prog='python -m pattern_locator.sim.render_timing',
                                     description=__doc__.split('\n\n')[0].strip())
    parser.add_argument('--route', default='tour', help='route of config/sim_floor.yaml')
    parser.add_argument('--frames', type=int, default=120, help='frames per mode')
    parser.add_argument('--seed', type=int, default=7)
    args = parser.parse_args(argv)
    if args.frames < 2:
        print('render_timing: --frames must be at least 2', file=sys.stderr)
        return 2
    print(f'{"640x480, per frame (ms)":<36}{"frames":>7}{"mean":>9}{"p99":>9}{"max":>9}'
          f'{"card %":>8}')
    print(time_room(args.frames))
    for row in time_floor(args.route, args.frames, args.seed):
        print(row)
    return 0


if __name__ == '__main__':
    sys.exit(main())
