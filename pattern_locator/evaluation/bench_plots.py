"""
The benchmarks' plots (matplotlib, drawn off-screen).

Each run kind writes its own files (``<kind>_errors.png``,
``<kind>_times.png``), so a quick run never overwrites a full run's plots,
nor the stress run either.
"""

from pathlib import Path
from typing import Dict, List, Sequence, Tuple

import numpy as np

from ..errors import ConfigError


def _pyplot():
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    return plt


def _plain_ticks(axis, subs=(1.0, 2.0, 5.0)) -> None:
    """Label a log axis with plain numbers (2, 5, 10) rather than powers of ten."""
    from matplotlib.ticker import FuncFormatter, LogLocator

    axis.set_major_locator(LogLocator(base=10, subs=subs))
    axis.set_major_formatter(FuncFormatter(lambda v, _: f'{v:g}'))
    axis.set_minor_formatter(FuncFormatter(lambda v, _: ''))


def _target(output_dir: str, name: str) -> Path:
    out = Path(output_dir)
    if out.exists() and not out.is_dir():
        raise ConfigError(f'plots: {out} is not a directory')
    out.mkdir(parents=True, exist_ok=True)
    return out / name


def error_plot(errors: Dict[str, Sequence[Tuple[float, float]]], output_dir: str,
               kind: str) -> Path:
    """
    Position error against distance, one colour per marker, both axes logarithmic.

    ``errors`` maps a marker to (distance m, error m) pairs of the scenes
    where it was found; the lines are the medians per distance bin.
    """
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7.5, 4.8), dpi=110)
    for marker, pairs in errors.items():
        if not pairs:
            continue
        d, e = np.array(pairs, dtype=float).T
        e = np.maximum(e * 1000.0, 1e-3)                      # mm, above 0 for the log axis
        dots = ax.scatter(d, e, s=9, alpha=0.35, label=f'{marker} ({len(d)} found)')
        edges = np.geomspace(max(d.min(), 0.5), d.max() * 1.0001, 7)
        centre, median = [], []
        for lo, hi in zip(edges[:-1], edges[1:]):
            inside = (d >= lo) & (d < hi)
            if np.count_nonzero(inside) >= 2:
                centre.append(np.sqrt(lo * hi))
                median.append(np.median(e[inside]))
        if centre:
            ax.plot(centre, median, '-o', color=dots.get_facecolor()[0][:3], lw=2, ms=4)
    ax.set_xscale('log')
    ax.set_yscale('log')
    _plain_ticks(ax.xaxis, (1.0, 1.5, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0))
    _plain_ticks(ax.yaxis)
    ax.set_xlabel('distance to the card (m)')
    ax.set_ylabel('camera position error (mm)')
    ax.set_title('Position error against distance (points: scenes; lines: medians)')
    ax.grid(True, which='both', alpha=0.3)
    ax.legend(loc='upper left', fontsize=8)
    path = _target(output_dir, f'{kind}_errors.png')
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def time_plot(times: Dict[str, Sequence[float]], output_dir: str, kind: str,
              title: str = 'Time per frame (single thread, pose included)') -> Path:
    """
    Distribution of the time per frame, one row per series, log time axis.

    Box (quartiles), whiskers (1st to 99th percentile), the points beyond
    them, and the mean and max written at the right.
    """
    plt = _pyplot()
    names: List[str] = [k for k, v in times.items() if len(v)]
    fig, ax = plt.subplots(figsize=(8.0, 0.45 * max(len(names), 2) + 1.4), dpi=110)
    data = [np.maximum(np.asarray(times[k], dtype=float), 1e-3) for k in names]
    ax.set_xscale('log')
    if data:
        ax.boxplot(data, orientation='horizontal', whis=(1, 99), widths=0.6, showfliers=True,
                   flierprops={'markersize': 3, 'alpha': 0.5})
        ax.set_yticks(range(1, len(names) + 1))
        ax.set_yticklabels(names, fontsize=8)
        low = min(float(np.min(v)) for v in data)
        high = max(float(np.max(v)) for v in data)
        for i, v in enumerate(data, start=1):
            ax.text(high * 1.4, i, f'mean {np.mean(v):.1f}  max {np.max(v):.1f}', va='center',
                    fontsize=7)
        ax.set_xlim(low / 1.5, high * 12)
    _plain_ticks(ax.xaxis)
    ax.set_xlabel('ms per frame')
    ax.set_title(title)
    ax.grid(True, axis='x', which='both', alpha=0.3)
    path = _target(output_dir, f'{kind}_times.png')
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path
