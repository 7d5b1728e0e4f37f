"""
``survey --report DIR``: a plan of each floor and a residual histogram (matplotlib).

Per floor, ``floor_<f>.png`` shows the cards (their ids and facing), their 95 %
uncertainty ellipses in the floor plane (magnified, the factor printed on the
plan, since they are millimetres on a plan of tens of metres) and the camera
path of each bag. ``residuals.png`` is the histogram of the sightings'
whitened residuals (their norm against the chi distribution with 6 degrees of
freedom). ``report.txt`` repeats the map's notes.
"""

import math
from pathlib import Path
from typing import Dict, Sequence, Tuple

import numpy as np

from ..errors import ConfigError

# chi-square with 2 degrees of freedom at 95 %: a 95 % ellipse in the plane.
CHI2_2_95 = 5.991


def _plt():
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    return plt


def write_report(out_dir, run, rooms: Dict[Tuple[int, int], object], notes: Sequence[str]
                 ) -> list:
    """Write the plots and notes into ``out_dir`` (created); return the files written."""
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f'{out}: cannot create the report directory '
                          f'({exc.strerror or exc})') from None
    plt = _plt()
    written = []
    cards = [c for c in run.result.cards if c.connected and c.T_building_card is not None]
    for floor in sorted({c.ids[0] for c in cards}):
        on_floor = [c for c in cards if c.ids[0] == floor]
        fig, ax = plt.subplots(figsize=(10, 7))
        for b, path in sorted(run.result.camera_paths.items()):
            if len(path):
                ax.plot(path[:, 0], path[:, 1], '-', lw=0.6, alpha=0.6,
                        label=f'camera path, {Path(run.bags[b].path).name}')
        sds = [math.sqrt(max(np.linalg.eigvalsh(c.covariance[:2, :2]).max(), 0.0))
               for c in on_floor if c.covariance is not None]
        span = max(np.ptp([c.T_building_card.t[0] for c in on_floor] + [0.0]),
                   np.ptp([c.T_building_card.t[1] for c in on_floor] + [0.0]), 1.0)
        largest = max(sds + [1e-6])
        magnify = 10 ** math.floor(math.log10(max(0.03 * span / (2.45 * largest), 1.0)))
        for c in on_floor:
            x, y = c.T_building_card.t[:2]
            normal = c.T_building_card.R[:2, 2]
            ax.plot(x, y, 'ks' if c.anchor else 'ro', ms=4)
            ax.arrow(x, y, 0.4 * normal[0], 0.4 * normal[1], width=0.02, color='0.4')
            ax.annotate(f'{c.ids[1]}/{c.ids[2]}', (x, y), textcoords='offset points',
                        xytext=(4, 4), fontsize=7)
            if c.covariance is not None and not c.anchor:
                _ellipse(ax, x, y, c.covariance[:2, :2] * magnify ** 2)
        ax.set_aspect('equal')
        ax.set_xlabel('building x (m)')
        ax.set_ylabel('building y (m)')
        ax.set_title(f'floor {floor}: {len(on_floor)} cards; 95 % ellipses magnified '
                     f"x{magnify:g}; arrows: the cards' facing; squares: anchors")
        if run.result.camera_paths:
            ax.legend(fontsize=7, loc='best')
        path = out / f'floor_{floor}.png'
        fig.savefig(path, dpi=120, bbox_inches='tight')
        plt.close(fig)
        written.append(path)
    fig, ax = plt.subplots(figsize=(7, 4))
    residuals = run.result.residuals
    if len(residuals):
        ax.hist(residuals, bins=60, alpha=0.7, label='sightings')
        ax.axvline(float(np.median(residuals)), color='k', lw=1,
                   label=f'median {np.median(residuals):.2f}; variance factor '
                         f'{run.result.sighting_variance_factor:.2f}')
    ax.set_xlabel('whitened residual norm of a sighting')
    ax.set_ylabel('sightings')
    ax.legend(fontsize=8)
    path = out / 'residuals.png'
    fig.savefig(path, dpi=120, bbox_inches='tight')
    plt.close(fig)
    written.append(path)
    path = out / 'report.txt'
    path.write_text('\n'.join(notes) + '\n', encoding='utf-8')
    written.append(path)
    return written


def _ellipse(ax, x: float, y: float, cov: np.ndarray) -> None:
    values, vectors = np.linalg.eigh(cov)
    t = np.linspace(0.0, 2.0 * math.pi, 60)
    circle = np.stack([np.cos(t), np.sin(t)])
    points = vectors @ (np.sqrt(np.clip(values, 0.0, None) * CHI2_2_95)[:, None] * circle)
    ax.plot(x + points[0], y + points[1], 'b-', lw=0.8)
