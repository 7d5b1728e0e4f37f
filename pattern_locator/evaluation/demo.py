"""
``pattern-locator demo``: the paper's 30-image route, located image by image.

Until the simulated robot runs as ROS nodes, the demo drives the core
directly: it renders what the tracking camera sees at each stop of the
route (paper_setup), locates the camera from the card in view, and prints
located against true positions and the errors in the form of the paper's
Table 1, beside the paper's own figures. A plot of both over the room's
plan is written as a PNG.
"""

from dataclasses import dataclass
import math
from pathlib import Path
import sys
from typing import Dict, List, Optional, Tuple

import numpy as np

from ..card.pattern import Ids, load_pattern_config
from ..sim.paper_setup import paper_camera, room_cards, route, tracking_camera_pose
from ..sim.render import CardPlacement, DotCardTexture, render_scene, RenderOptions
from ..vision.locate import CardLocator
from ..vision.pose_exact import paper_angles

# The paper's Table 1 (absolute errors): average, std dev, greatest.
PAPER_TABLE1 = {
    'phi (deg)': (0.44, 0.37, 2.10),
    'theta (deg)': (0.83, 0.84, 3.74),
    "D' (cm)": (2.89, 2.21, 11.30),
    'x (cm)': (3.01, 2.05, 7.90),
    'y (cm)': (2.95, 2.43, 11.79),
    'z (cm)': (3.09, 2.57, 8.16),
}
FLOOR, ROOM = 1, 3


@dataclass(frozen=True)
class StopResult:
    """One stop: the truth and what was located (None when nothing was)."""

    index: int
    card: int
    true_position: np.ndarray
    located: Optional[np.ndarray]
    ids_ok: bool
    errors: Optional[Dict[str, float]]


def imaging_options(rng: np.random.Generator, seed: int) -> RenderOptions:
    """Indoor diffuse light, a little defocus, sensor noise: a 2002 CCD, kindly."""
    return RenderOptions(
        supersample=3, gain=float(rng.uniform(0.8, 1.1)),
        colour_cast=tuple(float(c) for c in rng.uniform(0.92, 1.08, 3)),
        gradient=float(rng.uniform(0.0, 0.1)), gradient_angle_deg=float(rng.uniform(0, 360)),
        defocus_sigma_px=float(rng.uniform(0.4, 0.8)), noise_sigma=2.0,
        background='wall', seed=seed)


def run_route(estimator: str = 'exact', seed: int = 7) -> List[StopResult]:
    cfg = load_pattern_config()
    camera = paper_camera()
    locator = CardLocator(cfg, estimator=estimator)
    cards = {c.number: c for c in room_cards()}
    rng = np.random.default_rng(seed)
    results = []
    for index, (position, number) in enumerate(route()):
        card = cards[number]
        T_room_camera = tracking_camera_pose(position, card.T_room_card.t, rng)
        T_camera_card = T_room_camera.inverse() @ card.T_room_card
        ids = Ids(FLOOR, ROOM, number)
        placement = CardPlacement(T_camera_card, DotCardTexture(cfg, cfg.encode(*ids.as_tuple())),
                                  code=cfg.encode(*ids.as_tuple()), config=cfg)
        image = render_scene(camera, [placement], imaging_options(rng, seed + index)).image
        located = [c for c in locator.locate(image, camera) if c.T_camera_pattern is not None]
        if not located:
            results.append(StopResult(index, number, position, None, False, None))
            continue
        best = located[0]
        T_room_camera_est = card.T_room_card @ best.T_camera_pattern.inverse()
        est = T_room_camera_est.t
        _, phi_true, theta_true, d_true = paper_angles(T_camera_card, camera, cfg)
        dtheta = (best.theta_deg - theta_true + 180.0) % 360.0 - 180.0
        errors = {
            'phi (deg)': abs(best.phi_deg - phi_true),
            'theta (deg)': abs(dtheta),
            "D' (cm)": abs(best.distance_m - d_true) * 100.0,
            'x (cm)': abs(est[0] - position[0]) * 100.0,
            'y (cm)': abs(est[1] - position[1]) * 100.0,
            'z (cm)': abs(est[2] - position[2]) * 100.0,
        }
        results.append(StopResult(index, number, position, est,
                                  best.detection.ids == ids, errors))
    return results


def summary_table(results: List[StopResult]) -> str:
    rows = [r.errors for r in results if r.errors is not None]
    lines = [f'{"abs. error":<12}' + ''.join(f'{k:>13}' for k in PAPER_TABLE1)]
    for label, fn in (('average', np.mean), ('std dev', np.std), ('greatest', np.max),
                      ('smallest', np.min)):
        values = [fn([r[k] for r in rows]) if rows else math.nan for k in PAPER_TABLE1]
        lines.append(f'{label:<12}' + ''.join(f'{v:>13.2f}' for v in values))
    for i, label in enumerate(('Table 1 avg', 'Table 1 std', 'Table 1 max')):
        lines.append(f'{label:<12}' + ''.join(f'{PAPER_TABLE1[k][i]:>13.2f}'
                                              for k in PAPER_TABLE1))
    return '\n'.join(lines)


def plot_paths(results: List[StopResult], path: Path, title: str) -> Path:
    """Plot the room's plan with the true and located positions (matplotlib); return the file."""
    from .route_plot import plot_route
    return plot_route(results, path, title)


def print_results(results: List[StopResult], true_label: str) -> Tuple[int, int]:
    """Print the per-stop table (true and located positions, ids); return (located, wrong)."""
    print(f'{"stop":>4} {"card":>4}  {true_label:>23}  {"located x, y, z (m)":>22}'
          f'  {"error (cm)":>10}  ids')
    for r in results:
        t = r.true_position
        if r.located is None:
            print(f'{r.index + 1:>4} {"-":>4}  {t[0]:7.3f} {t[1]:7.3f} {t[2]:7.3f}  '
                  f'{"not located":>22}')
            continue
        e = r.located
        print(f'{r.index + 1:>4} {r.card:>4}  {t[0]:7.3f} {t[1]:7.3f} {t[2]:7.3f}  '
              f'{e[0]:6.3f} {e[1]:6.3f} {e[2]:6.3f}  {np.linalg.norm(e - t) * 100:10.2f}  '
              f'{f"{FLOOR}/{ROOM}/{r.card}" if r.ids_ok else "WRONG"}')
    located = sum(r.located is not None for r in results)
    wrong = sum(r.located is not None and not r.ids_ok for r in results)
    return located, wrong


def run_demo(estimator: str = 'exact', seed: int = 7, output_dir: str = 'out') -> int:
    print(f"pattern_locator demo: the paper's route, {estimator} estimator "
          f'(f = 25 mm, 640x480, cards at 2.15 m, camera at 1.10 m)')
    results = run_route(estimator, seed)
    located, wrong = print_results(results, 'true x, y, z (m)')
    print(f'\nlocated {located}/{len(results)} images, wrong floor/room/card: {wrong}')
    print("\nTable 1 form (absolute errors), this run and the paper's:")
    print(summary_table(results))
    plot = plot_paths(results, Path(output_dir) / f'demo_core_{estimator}.png',
                      f"demo --core: the paper's route, image by image ({estimator} estimator)")
    print(f'\nplot of the true and located positions: {plot}')
    sys.stdout.flush()
    return 0 if located == len(results) and wrong == 0 else 1
