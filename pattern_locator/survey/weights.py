"""
How much to trust what: outliers and the a-posteriori variance factors of each group.

The detector's covariance is too pessimistic for near, frontal views and too
optimistic for far, grazing ones, and the odometry's noise is not known: each
group's variance factor is its whitened chi-square over its redundancy
(variance component estimation), so the weights and the ellipses come from
the walk itself.
"""

from typing import Dict, List, Optional, Tuple

import gtsam
import numpy as np

from .problem import Problem

# Sightings whose whitened error is beyond this chi-square (6 dof, p = 1e-4) are dropped.
OUTLIER_CHI2 = 27.86


def marginals_of(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values) -> gtsam.Marginals:
    """Return the marginals; QR when Cholesky finds the system too poorly conditioned."""
    try:
        return gtsam.Marginals(graph, values)
    except RuntimeError:
        return gtsam.Marginals(graph, values, gtsam.Marginals.Factorization.QR)


def outliers(problem: Problem, sighting_factors, values, dropped,
             factors: Dict[object, Optional[float]], group: Dict) -> set:
    """Return the sightings far beyond the robust kernel (chi-square 6 dof, p < 1e-4)."""
    norms = {}
    for key, factor in sighting_factors.items():
        if key not in dropped:
            w = np.asarray(factor.whitenedError(values))
            norms[key] = float(w @ w)
    if not norms:
        return set()
    # Against each bin's own variance factor: the covariances may be pessimistic.
    overall = factors.get('sightings') or 1.0
    out = {key for key, q in norms.items()
           if q / max(factors.get(('sight', group[key])) or overall, 0.05) > OUTLIER_CHI2}
    # Never drop a card's last sightings: its map pose would go with them.
    per_card: Dict[Tuple[int, int, int], int] = {}
    for key in norms:
        ids = problem.frame_sightings[key[0]][key[1]].ids
        per_card[ids] = per_card.get(ids, 0) + 1
    keep = set()
    for key in sorted(out):
        ids = problem.frame_sightings[key[0]][key[1]].ids
        per_card[ids] -= 1
        if per_card[ids] < 2:
            keep.add(key)
            per_card[ids] += 1
    return out - keep


# How many factors of a group to sample for its redundancy, and the fewest a group needs
# for a variance factor of its own.
REDUNDANCY_SAMPLES = {'sight': 12, 'odom': 30}


MIN_GROUP = 20


def variance_factors(problem: Problem, values, marginals, sighting_factors, dropped,
                     odometry, group: Dict, fractions: Dict[object, float],
                     reuse: bool) -> Dict[object, Optional[float]]:
    """
    Return the a-posteriori variance factors of the sightings and of the odometry.

    A group's factor is its whitened chi-square over its redundancy, the
    part of its dimensions not used up by the estimate: ``sum_i (d_i -
    tr(A_i Sigma_i A_i^T))`` with A_i a factor's whitened Jacobian and
    Sigma_i the joint marginal of its variables, estimated from a seeded
    sample of the group's factors (``fractions`` keeps each group's estimate;
    with ``reuse`` a group already estimated is not sampled again: the
    weights move little between the last rounds). Groups: the keyframes' own
    sightings per bin of distance and view angle (``('sight', g)``; a later
    member's sighting also carries odometry and is left out), the odometry's
    translation (``odom_xy``) and heading (``odom_yaw``); a base's z, roll
    and pitch are held by the floor, not counted. ``sightings``: all the
    sightings' bins together.
    """
    rng = np.random.default_rng(rounds_seed(fractions))
    planar = [np.array([3, 4]), np.array([2])]
    full = [np.array([3, 4, 5]), np.array([0, 1, 2])]
    own = [k for k in sighting_factors if k not in dropped
           and problem.sighting_member[k[0]][k[1]] == 0]
    groups: List[Tuple[object, list]] = []
    for g in range(9):
        groups.append((('sight', g), [(sighting_factors[k], np.arange(6)) for k in own
                                      if group[k] == g]))
    for name, which in (('odom_xy', 0), ('odom_yaw', 1)):
        groups.append((name, [(f, (full if problem.motions[bag].mount_source == 'camera'
                                   else planar)[which]) for bag, f in odometry]))
    out: Dict[object, Optional[float]] = {'sightings': None}
    total_chi2 = total_redundancy = 0.0
    for name, items in groups:
        out[name] = None
        if not items:
            continue
        chi2 = dims = 0.0
        for f, rows in items:
            w = np.asarray(f.whitenedError(values))[rows]
            chi2 += float(w @ w)
            dims += len(rows)
        if len(items) >= MIN_GROUP and not (reuse and name in fractions):
            samples = REDUNDANCY_SAMPLES['sight' if isinstance(name, tuple) else 'odom']
            picks = rng.choice(len(items), min(samples, len(items)), replace=False)
            used = []
            for i in picks:
                f, rows = items[i]
                A = f.linearize(values).jacobian()[0][rows]
                sigma = marginals.jointMarginalCovariance(gtsam.KeyVector(list(f.keys()))
                                                          ).fullMatrix()
                used.append(float(np.trace(A @ sigma @ A.T)) / len(rows))
            fractions[name] = max(1.0 - float(np.mean(used)), 0.02)
        if name in fractions:
            redundancy = fractions[name] * dims
            if len(items) >= MIN_GROUP:
                out[name] = chi2 / redundancy
            if isinstance(name, tuple):
                total_chi2 += chi2
                total_redundancy += redundancy
    if total_redundancy > 0.0:
        out['sightings'] = total_chi2 / total_redundancy
    return out


def rounds_seed(fractions: Dict[object, float]) -> int:
    """Return a seed that changes as groups get estimated (new picks each time)."""
    return len(fractions)
