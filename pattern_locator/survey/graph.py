"""
The survey's factor graph: card and camera poses from sightings and odometry, with GTSAM.

Variables: one pose per card ``L(j)`` (building <- card) and one per frame
that saw a card ``X(i)`` (building <- base; the base is the camera itself
when the bag has no odometry or no mount). Factors:

* per sighting, a pose-graph factor ``X(i) -> L(j)`` measuring ``T_base_card
  = T_base_camera @ T_camera_card`` with the sighting's covariance, under a
  robust kernel (Huber by default), so that a bad sighting cannot drag the
  map; after each round, sightings far beyond the kernel are dropped;
* odometry between consecutive frames of one bag (never across bags), from
  the bag's odometry corrected for a per-bag **scale error** and **yaw bias**
  (rad per metre travelled); the two are estimated by alternating with the
  graph: given the poses they are a small least-squares fit, given them the
  poses are the graph's optimum; a few rounds converge;
* a **vertical** prior per card (its normal horizontal; switchable);
* an optional **nominal height** per card above the floor of a base that saw it;
* the gauge: every anchor's given pose, exactly; without anchors, the first
  card fixes the building frame (its position and heading exactly, its tilt
  left to the vertical priors and the odometry).

Only what is connected to the gauge through sightings and odometry is
optimised; the rest is reported unconnected. After the optimisation the
sightings' and the odometry's noise are re-scaled by their a-posteriori
variance factors (so that the covariances say what the residuals show), and
each card's covariance is its marginal in the building frame.
"""

from dataclasses import dataclass, field
import math
import time
from typing import Dict, List, Optional, Sequence, Tuple

import gtsam
import numpy as np

from .factors import (add_gauge, building_covariance, CarriedSightings, flat, floor_factors,
                      from_gtsam, odometry_factors, on_floor, re_anchored_priors,
                      refined_factors, sighting_factor, to_gtsam)
from .mapfile import MapCard
from .model import BagMotion, F, L, SurveyOptions, X
from .odometry import fit_calibration
from .problem import first_poses, Problem
from .sightings import Sighting, tangent_covariances
from .weights import marginals_of, outliers, variance_factors
from ..errors import ConfigError
from ..localization.building import wall_card_rotation
from ..vision.geometry import Pose

__all__ = ['BagMotion', 'optimise', 'SurveyOptions', 'SurveyResult']


@dataclass(frozen=True, eq=False)
class SurveyResult:
    """
    The optimised map and what the optimisation found out on the way.

    ``card_position_covariance`` gives the joint covariance of several cards'
    positions (what a comparison that removes the frame needs).
    """

    cards: List[MapCard]
    frame_note: str
    # bag -> (scale, yaw bias rad/m) of the bags whose odometry was calibrated
    calibration: Dict[int, Tuple[float, float]]
    camera_paths: Dict[int, np.ndarray]                 # bag -> (N, 3) camera positions
    residuals: np.ndarray                               # whitened sighting residual norms
    sighting_variance_factor: float
    odometry_scale: Tuple[float, float]         # (translation, heading) on the model's sd
    outliers: int
    used_sightings: int
    frames: int
    rounds: int
    timings: Dict[str, float] = field(default_factory=dict)
    values: Optional[gtsam.Values] = None
    marginals: Optional[gtsam.Marginals] = None
    card_index: Dict[Tuple[int, int, int], int] = field(default_factory=dict)
    frame_keys: Dict[Tuple[int, int], int] = field(default_factory=dict)

    def card_position_covariance(self, ids: Sequence[Tuple[int, int, int]]) -> np.ndarray:
        """Return the joint (3N, 3N) covariance of cards' positions about the building axes."""
        keys = [L(self.card_index[i]) for i in ids]
        joint = self.marginals.jointMarginalCovariance(gtsam.KeyVector(keys)).fullMatrix()
        n = len(keys)
        A = np.zeros((3 * n, 6 * n))
        for k, key in enumerate(keys):
            A[3 * k:3 * k + 3, 6 * k + 3:6 * k + 6] = self.values.atPose3(key).rotation().matrix()
        return A @ joint @ A.T * self.sighting_variance_factor


def optimise(sightings: Sequence[Sighting], motions: Sequence[BagMotion],
             anchors: Optional[Dict[Tuple[int, int, int], Pose]] = None,
             options: SurveyOptions = SurveyOptions()) -> SurveyResult:
    """Map the cards: build the graph, optimise, re-weigh, return cards with covariances."""
    timings: Dict[str, float] = {}
    start = time.perf_counter()
    problem = Problem(sightings, motions, options)
    anchors = dict(anchors or {})
    if not problem.card_ids:
        raise ConfigError('survey: no card was seen in the bags')
    seen_anchors = {problem.card_index[ids]: T for ids, T in anchors.items()
                    if ids in problem.card_index}
    if anchors and not seen_anchors:
        raise ConfigError('survey: none of the anchors was seen in the bags (anchors: '
                          + ', '.join(f'floor {f} room {r} card {p}'
                                      for f, r, p in sorted(anchors)) + ')')
    calibration = {bag: (0.0, 0.0) for bag in problem.odometry}
    if seen_anchors:
        gauge = seen_anchors
        frame_note = ('building frame from the anchors: '
                      + ', '.join(f'floor {f} room {r} card {p}' for f, r, p in sorted(
                          problem.card_ids[j] for j in seen_anchors)))
    else:
        twice = [j for j, ids in enumerate(problem.card_ids) if problem.counts[ids] >= 2]
        first = twice[0] if twice else 0
        gauge = {first: Pose(wall_card_rotation(0.0), np.zeros(3))}
        f, r, p = problem.card_ids[first]
        frame_note = (f'no anchors: the building frame sits on the first card, floor {f} '
                      f'room {r} card {p} (origin at its centre, x out of its wall, z up)')
    init_cards, init_frames = first_poses(problem, gauge,
                                          problem.corrected_poses(calibration))
    active = set(init_frames)
    values = gtsam.Values()
    for j, T in init_cards.items():
        values.insert(L(j), to_gtsam(T))
    for n, T in init_frames.items():
        values.insert(X(n), to_gtsam(T))
    huber = gtsam.noiseModel.mEstimator.Huber.Create(options.huber_k)
    keys = [(n, k) for n in sorted(active) for k in range(len(problem.frame_sightings[n]))]
    tangent = dict(zip(keys, tangent_covariances(
        [problem.frame_sightings[n][k] for n, k in keys])))
    group = {key: problem.frame_sightings[key[0]][key[1]].group for key in keys}
    # A keyframe's own sightings change only with their group's noise; its later
    # members' also with the odometry.
    own_Y = {}
    later = []
    for key in keys:
        n, k = key
        m = problem.sighting_member[n][k]
        Y = problem.members[n][m][1] @ problem.frame_sightings[n][k].T_camera_card
        if m == 0:
            own_Y[key] = Y
        else:
            later.append((key, Y))
    sighting_scale = np.ones(9)

    def own_factors() -> Dict[Tuple[int, int], gtsam.BetweenFactorPose3]:
        return {key: sighting_factor(problem, key, Y, tangent[key] * sighting_scale[group[key]],
                                     huber) for key, Y in own_Y.items()}

    own = own_factors()
    carried = CarriedSightings(problem, later, tangent, group) if later else None
    fixed = gtsam.NonlinearFactorGraph()
    add_gauge(fixed, gauge, seen_anchors, options)
    floors = on_floor(problem, active) if options.level_floor else {}
    for bag, numbers in floors.items():
        first = values.atPose3(X(numbers[0]))
        t = first.translation()
        values.insert(F(bag), gtsam.Pose3(flat(first).rotation(),
                                          np.array([t[0], t[1], t[2]])))
    edges = [e for e in problem.edges if e.a in active and e.b in active]
    timings['setup_s'] = time.perf_counter() - start

    dropped: set = set()
    noise_scale = (1.0, 1.0)
    rounds = 0
    build = t_opt = t_weigh = 0.0
    marginals = None
    factors: Dict[str, Optional[float]] = {}
    vce_rounds = 0
    vce_done = False
    scaled_any = False
    fractions: Dict[object, float] = {}
    fitted_bags: set = set()
    while True:
        rounds += 1
        last = rounds >= options.max_rounds
        t0 = time.perf_counter()
        graph = gtsam.NonlinearFactorGraph()
        graph.push_back(fixed)
        sighting_factors = dict(own)
        if carried is not None:
            sighting_factors.update(carried.factors(calibration, noise_scale, huber,
                                                    sighting_scale))
        for key, factor in sighting_factors.items():
            if key not in dropped:
                graph.add(factor)
        odometry = odometry_factors(problem, edges, calibration, noise_scale, huber)
        for _, factor in odometry:
            graph.add(factor)
        for factor in re_anchored_priors(problem, values, init_cards, active, gauge, options):
            graph.add(factor)
        for factor in floor_factors(problem, values, floors, options):
            graph.add(factor)
        build += time.perf_counter() - t0
        t0 = time.perf_counter()
        params = gtsam.LevenbergMarquardtParams()
        params.setRelativeErrorTol(1e-6 if vce_done or vce_rounds else 1e-4)
        params.setAbsoluteErrorTol(1e-9)
        params.setMaxIterations(50)
        values = gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()
        t_opt += time.perf_counter() - t0
        t0 = time.perf_counter()
        # Re-weigh (outliers, the noise levels) after the first round, and again once
        # the odometry's calibration has settled (a miscalibrated odometry looks noisy);
        # then one last round with the final weights.
        settled = True
        if problem.odometry and options.calibrate_odometry:
            fitted = fit_calibration(problem, values, calibration, noise_scale, fitted_bags)
            # Moving a frame by more than 0.1 mm per metre or heading 1e-5 rad per metre.
            moved = max((max(abs(fitted[b][0] - calibration[b][0]) / 1e-4,
                             abs(fitted[b][1] - calibration[b][1]) / 1e-5) for b in fitted),
                        default=0.0)
            calibration = fitted
            settled = moved <= 1.0
        # The sightings' noise per bin is judged from the first round; the odometry's
        # once its calibration has settled. Each is re-judged until it holds still.
        weigh = not vce_done and (rounds == 1 or settled or vce_rounds == 0)
        final = settled and vce_done
        if weigh:
            marginals = marginals_of(graph, values)
            factors = variance_factors(problem, values, marginals, sighting_factors,
                                       dropped, odometry, group, fractions,
                                       reuse=vce_rounds >= 2)
            dropped |= outliers(problem, sighting_factors, values, dropped, factors,
                                group)
            steady = True
            if options.rescale_noise:
                vce_rounds += 1
                for g in range(9):
                    f = factors.get(('sight', g))
                    if f is not None:
                        scaled_any = True
                        steady = steady and abs(math.log(f)) < 0.2
                        sighting_scale[g] = min(max(sighting_scale[g] * f, 1e-2), 1e3)
                own = own_factors()
                if settled and factors['odom_xy'] is not None:
                    lo, hi = options.odom_scale_bounds
                    scaled = tuple(min(max(old * math.sqrt(factors[name]), lo), hi)
                                   for old, name in zip(noise_scale, ('odom_xy', 'odom_yaw')))
                    steady = steady and max(abs(math.log(a / b)) for a, b in
                                            zip(scaled, noise_scale)) < 0.1
                    noise_scale = scaled
            vce_done = settled and (steady or vce_rounds >= 4)
        t_weigh += time.perf_counter() - t0
        if final or last:
            break
    if options.refine_dots:
        t0 = time.perf_counter()
        refined = refined_factors(problem, sighting_factors, dropped, calibration, group,
                                  sighting_scale, options)
        graph = gtsam.NonlinearFactorGraph()
        graph.push_back(fixed)
        for key, factor in refined.items():
            if key not in dropped:
                graph.add(factor)
        for _, factor in odometry:
            graph.add(factor)
        for factor in re_anchored_priors(problem, values, init_cards, active, gauge, options):
            graph.add(factor)
        for factor in floor_factors(problem, values, floors, options):
            graph.add(factor)
        values = gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()
        t_opt += time.perf_counter() - t0
    t0 = time.perf_counter()
    marginals = marginals_of(graph, values)
    t_weigh += time.perf_counter() - t0
    timings['build_s'] = build
    timings['optimise_s'] = t_opt
    timings['weigh_s'] = t_weigh

    t0 = time.perf_counter()
    residuals = np.array([float(np.linalg.norm(sighting_factors[k].whitenedError(values)))
                          for k in sighting_factors if k not in dropped])
    # The bins' noise is already scaled; what is left is the sightings' overall factor.
    variance_factor = 1.0
    if options.rescale_noise and not scaled_any and factors.get('sightings') is not None:
        variance_factor = factors['sightings']
    cards: List[MapCard] = []
    for j, ids in enumerate(problem.card_ids):
        if j not in init_cards:
            cards.append(MapCard(ids, problem.codes[ids], None, None, problem.counts[ids],
                                 False))
        elif j in seen_anchors:
            cards.append(MapCard(ids, problem.codes[ids], seen_anchors[j], np.zeros((6, 6)),
                                 problem.counts[ids], True, True))
        else:
            T = from_gtsam(values.atPose3(L(j)))
            cov = building_covariance(T, marginals.marginalCovariance(L(j))) * variance_factor
            cov = cov + np.diag([options.card_floor_sd_m ** 2] * 3
                                + [options.card_floor_sd_rad ** 2] * 3)
            cards.append(MapCard(ids, problem.codes[ids], T, cov, problem.counts[ids], True))
    paths: Dict[int, List[np.ndarray]] = {}
    for n in sorted(active):
        T = from_gtsam(values.atPose3(X(n))) @ problem.frame_mount[n]
        paths.setdefault(problem.frames[n][0], []).append(T.t)
    timings['marginals_s'] = time.perf_counter() - t0
    return SurveyResult(
        cards=cards, frame_note=frame_note,
        calibration={b: c for b, c in calibration.items() if b in fitted_bags},
        camera_paths={b: np.array(p) for b, p in paths.items()}, residuals=residuals,
        sighting_variance_factor=variance_factor,
        odometry_scale=noise_scale,
        outliers=len(dropped), used_sightings=len(sighting_factors) - len(dropped),
        frames=len(active), rounds=rounds, timings=timings, values=values,
        marginals=marginals,
        card_index=problem.card_index,
        frame_keys={problem.frames[n]: n for n in active})
