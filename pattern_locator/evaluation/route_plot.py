"""
The demo's route plot.

The room's plan in metres, the cards, the numbered stops, the true and
located positions, the missed stops and an error scale.

matplotlib with the Agg backend (no display needed), imported when a plot is
drawn so that the rest of the demo does not pay for it.
"""

from pathlib import Path
from typing import Sequence, Tuple

import numpy as np

from .demo import StopResult
from ..sim.paper_setup import room_cards, ROOM_SIZE

# Located positions are drawn at their place; their error is also shown as a
# line from the truth, magnified so centimetres are visible on a 10 m plan.
ERROR_MAGNIFICATION = 20.0


def plot_route(results: Sequence[StopResult], path: Path, title: str,
               room_size: Tuple[float, float] = ROOM_SIZE) -> Path:
    """Draw the plan with cards, stops, true and located positions; write ``path``."""
    import matplotlib
    matplotlib.use('Agg')
    from matplotlib import pyplot as plt
    from matplotlib.lines import Line2D

    length, width = room_size
    fig, ax = plt.subplots(figsize=(11.0, 6.6), dpi=110, layout='constrained')
    ax.plot([0.0, length, length, 0.0, 0.0], [0.0, 0.0, width, width, 0.0], '-', lw=2.0,
            color='0.2', label='_walls')
    for card in room_cards():
        x, y = card.T_room_card.t[:2]
        normal = card.T_room_card.R[:2, 2]
        ax.plot(x, y, marker='s', ms=9, color='tab:orange', mec='k', zorder=4)
        # The label sits inside the room, off the wall, along the card's normal.
        ax.annotate(f'card {card.number}', (x, y), xytext=(x + 0.45 * normal[0],
                                                           y + 0.45 * normal[1]),
                    ha='center', va='center', fontsize=9, color='tab:brown', zorder=5)

    true = np.array([r.true_position[:2] for r in results])
    ax.plot(true[:, 0], true[:, 1], '-', color='tab:green', lw=1.0, alpha=0.6, zorder=2)
    errors_cm = []
    for r in results:
        tx, ty = r.true_position[:2]
        if r.located is None:
            ax.plot(tx, ty, 'o', ms=13, mfc='none', mec='red', mew=2.0, zorder=6)
            ax.plot(tx, ty, 'x', ms=9, color='red', mew=2.0, zorder=6)
        else:
            ax.plot(tx, ty, 'o', ms=5, color='tab:green', zorder=3)
            d = (r.located[:2] - r.true_position[:2]) * ERROR_MAGNIFICATION
            ax.plot([tx, tx + d[0]], [ty, ty + d[1]], '-', color='tab:blue', lw=1.5, zorder=4)
            ax.plot(r.located[0], r.located[1], '+', ms=9, mew=1.6,
                    color='tab:blue' if r.ids_ok else 'red', zorder=5)
            errors_cm.append(float(np.linalg.norm(r.located - r.true_position)) * 100.0)
        ax.annotate(str(r.index + 1), (tx, ty), xytext=(4, 4), textcoords='offset points',
                    fontsize=8, color='0.25', zorder=7)

    # The error scale: what 5 cm of error looks like at the plot's magnification.
    bar_cm = 5.0
    x0, y0 = 0.3, -0.55
    ax.plot([x0, x0 + bar_cm / 100.0 * ERROR_MAGNIFICATION], [y0, y0], '-', color='tab:blue',
            lw=3.0, clip_on=False)
    ax.text(x0 + bar_cm / 100.0 * ERROR_MAGNIFICATION + 0.1, y0,
            f'{bar_cm:.0f} cm of error (error lines drawn {ERROR_MAGNIFICATION:.0f}x)',
            va='center', fontsize=9)
    legend = [
        Line2D([], [], marker='o', ls='-', color='tab:green', label='true position (stop number)'),
        Line2D([], [], marker='+', ls='', color='tab:blue', mew=1.6, ms=9,
               label='located position'),
        Line2D([], [], ls='-', color='tab:blue', lw=1.5,
               label=f'error, {ERROR_MAGNIFICATION:.0f}x'),
        Line2D([], [], marker='x', ls='', color='red', mew=2.0, label='stop not located'),
        Line2D([], [], marker='+', ls='', color='red', mew=1.6,
               label='wrong floor/room/card'),
        Line2D([], [], marker='s', ls='', color='tab:orange', mec='k', label='card on a wall'),
    ]
    ax.legend(handles=legend, loc='upper left', bbox_to_anchor=(1.01, 1.0), fontsize=9)
    located = sum(r.located is not None for r in results)
    summary = f'{located}/{len(results)} stops located'
    if errors_cm:
        summary += (f'; camera position error median {np.median(errors_cm):.2f} cm, '
                    f'max {np.max(errors_cm):.2f} cm')
    ax.set_title(f'{title}\n{summary}', fontsize=11)
    ax.set_xlabel('x (m), room frame')
    ax.set_ylabel('y (m), room frame')
    ax.set_xlim(-0.6, length + 0.6)
    ax.set_ylim(-0.9, width + 0.6)
    ax.set_aspect('equal')
    ax.grid(True, color='0.9')
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path
