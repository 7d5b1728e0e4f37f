"""
Sighting-level simulation of a walk: what the detector would report, without rendering.

Rendering and detecting 10,000 frames takes an hour on two shared cores, so
the floor-scale figures of ``bench --survey`` come from here, calibrated
against rendered sightings (:func:`calibrate`):

* a card is seen when it is in the line of sight, in front of the camera,
  its outer ring wholly inside the image, its ring dots at least
  ``min_dot_px`` across and its normal within ``max_view_deg`` of the line
  to the camera (the rendered walks say which cards the detector found);
* the reported covariance is the exact estimator's ``sigma^2 (J^T J)^-1``
  at the true pose with the detector's reported pixel noise;
* the true error is drawn from that covariance times the ratio the
  rendered sightings showed between their actual squared errors and their
  reported covariances (per distance and view angle bin: the normalised
  estimation error squared, NEES, from its median: the rendered sightings'
  few gross errors are not simulated).
"""

from dataclasses import dataclass
import math
from typing import List, Optional, Sequence, Tuple

import numpy as np

from .sightings import ANGLE_EDGES, DISTANCE_EDGES, Sighting
from ..card.pattern import PatternConfig
from ..sim.walk import FloorPlan, Walk
from ..vision.camera import CameraModel
from ..vision.geometry import Pose, rodrigues
from ..vision.pose_exact import pose_covariance


@dataclass(frozen=True)
class SightingModel:
    """
    What a sighting looks like: when a card is seen, what is reported, how wrong it is.

    ``nees``: per (distance bin, view-angle bin) of :data:`DISTANCE_EDGES`
    and :data:`ANGLE_EDGES`, the mean of ``e^T Sigma^-1 e / 6`` over rendered
    sightings (1: the reported covariance is right; below: pessimistic).
    """

    reported_sigma_px: float = 0.05
    nees: Tuple[Tuple[float, ...], ...] = ((0.3, 0.3, 1.0), (0.3, 0.5, 2.0), (1.0, 1.0, 2.0))
    max_view_deg: float = 72.0
    min_dot_px: float = 3.0
    max_distance_m: float = 7.5

    def nees_at(self, distance: float, view_deg: float) -> float:
        """Return the NEES of the bin holding this distance and view angle."""
        i = min(int(np.searchsorted(DISTANCE_EDGES, distance, side='right')) - 1, 2)
        j = min(int(np.searchsorted(ANGLE_EDGES, view_deg, side='right')) - 1, 2)
        return float(self.nees[max(i, 0)][max(j, 0)])


def view_angle_deg(T_camera_card: Pose) -> float:
    """Return the angle between the card's normal and the line to the camera (phi)."""
    c = T_camera_card.inverse().t
    return math.degrees(math.acos(float(np.clip(c[2] / np.linalg.norm(c), -1.0, 1.0))))


def seen(T_camera_card: Pose, camera: CameraModel, pattern: PatternConfig,
         model: SightingModel) -> bool:
    """Return True when the detector would find this card (the model's rules)."""
    if T_camera_card.t[2] <= 0.3 or np.linalg.norm(T_camera_card.t) > model.max_distance_m:
        return False
    if view_angle_deg(T_camera_card) > model.max_view_deg:
        return False
    points = T_camera_card.apply(pattern.model_points())
    if np.any(points[:, 2] <= 0.0):
        return False
    px = camera.project(points)
    outer = px[:9]
    if np.any(outer < 1.0) or np.any(outer[:, 0] > camera.width - 2.0) or np.any(
            outer[:, 1] > camera.height - 2.0):
        return False
    dot_px = camera.fx * 2.0 * float(pattern.dot_radii()[1]) / float(points[1, 2])
    return dot_px >= model.min_dot_px


def simulate_sightings(plan: FloorPlan, walk: Walk, camera: CameraModel,
                       pattern: PatternConfig, model: SightingModel = SightingModel(),
                       seed: int = 0, bag: int = 0, start_ns: int = 0,
                       frames: Optional[Sequence[int]] = None) -> List[Sighting]:
    """Return the sightings of a walk's frames as the calibrated detector would report them."""
    rng = np.random.default_rng(seed)
    obj = pattern.model_points()
    samples = walk.frames if frames is None else frames
    out: List[Sighting] = []
    for frame, sample in enumerate(samples):
        T_world_camera = walk.camera_pose(int(sample))
        T_camera_world = T_world_camera.inverse()
        stamp = start_ns + round(float(walk.times_s[sample]) * 1e9)
        for card in plan.cards:
            T = T_camera_world @ card.T_true
            if not seen(T, camera, pattern, model):
                continue
            if not plan.line_of_sight(T_world_camera.t[:2], card):
                continue
            cov = pose_covariance(T, obj, camera.K, model.reported_sigma_px)
            truth_cov = cov * model.nees_at(float(np.linalg.norm(T.t)), view_angle_deg(T))
            e = rng.multivariate_normal(np.zeros(6), truth_cov)
            T_card_camera = T.inverse()
            noisy = Pose(rodrigues(e[3:]) @ T_card_camera.R, T_card_camera.t + e[:3])
            out.append(Sighting(bag, frame, stamp, str(card.code), card.ids.as_tuple(),
                                noisy.inverse(), cov, model.reported_sigma_px, math.inf,
                                pattern.n_dots))
    return out


# The median of chi-square with 6 degrees of freedom: a robust NEES is median(6 NEES) / this.
CHI2_6_MEDIAN = 5.348


def calibrate(errors: Sequence[Tuple[float, float, float]], minimum: int = 8,
              robust: bool = True) -> Tuple[Tuple[float, ...], ...]:
    """
    Return the NEES table from rendered sightings: (distance, view angle, NEES) each.

    ``robust``: the bin's NEES from its median (a few gross errors, which the
    survey's robust kernel and outlier test handle, do not set the noise of
    all), else its mean. A bin with fewer than ``minimum`` sightings takes
    its distance row's (or all sightings') value.
    """
    errors = np.asarray(errors, dtype=float).reshape(-1, 3)

    def level(values: np.ndarray) -> float:
        if robust:
            return float(np.median(6.0 * values)) / CHI2_6_MEDIAN
        return float(np.mean(values))

    overall = level(errors[:, 2]) if len(errors) else 1.0
    table = []
    for i in range(3):
        in_row = (errors[:, 0] >= DISTANCE_EDGES[i]) & (errors[:, 0] < DISTANCE_EDGES[i + 1])
        row_mean = level(errors[in_row, 2]) if in_row.sum() >= minimum else overall
        row = []
        for j in range(3):
            cell = in_row & (errors[:, 1] >= ANGLE_EDGES[j]) & (errors[:, 1] < ANGLE_EDGES[j + 1])
            row.append(level(errors[cell, 2]) if cell.sum() >= minimum else row_mean)
        table.append(tuple(row))
    return tuple(table)


def sighting_nees(sighting: Sighting, T_camera_card_true: Pose) -> float:
    """Return a sighting's ``e^T Sigma^-1 e / 6`` against the true pose (e over (c, theta))."""
    est = sighting.T_camera_card.inverse()
    true = T_camera_card_true.inverse()
    dR = est.R @ true.R.T
    theta = 0.5 * np.array([dR[2, 1] - dR[1, 2], dR[0, 2] - dR[2, 0], dR[1, 0] - dR[0, 1]])
    e = np.concatenate([est.t - true.t, theta])
    return float(e @ np.linalg.solve(sighting.covariance, e)) / 6.0
