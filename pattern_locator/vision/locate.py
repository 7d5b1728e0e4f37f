"""
From an image to located cards: detection followed by a pose estimator.

This is the one call the command line, the benchmark and the ROS node make;
it holds no ROS types.
"""

from dataclasses import dataclass
import math
from typing import Iterable, List, Optional, Tuple

import numpy as np

from .camera import CameraModel
from .detector import CardDetection, Detector, DetectorParams
from .geometry import Pose
from .pose_exact import covariance_of_pose, estimate_exact, paper_angles, PosePrior
from ..card.pattern import Code, PatternConfig
from ..errors import ConfigError, EstimationError

ESTIMATORS = ('exact', 'paper')


@dataclass(frozen=True)
class LocatedCard:
    """A detected card and, when it could be computed, the camera pose from it."""

    detection: CardDetection
    T_camera_pattern: Optional[Pose]
    covariance: Optional[np.ndarray]       # 6x6 (first-order at the pose for 'paper')
    reprojection_rms_px: Optional[float]
    ambiguity: Optional[float]             # exact estimator only
    psi_deg: Optional[float]
    phi_deg: Optional[float]
    theta_deg: Optional[float]
    distance_m: Optional[float]
    estimator: str
    problem: Optional[str] = None          # why there is no pose
    # Exact estimator, a close planar flip: the other solution, how likely it
    # is and how high the fit's cost rises between the two (PoseEstimate).
    alternative: Optional[Pose] = None
    other_probability: float = 0.0
    flip_barrier: float = math.inf
    # The prior's up and height in the fit (PoseEstimate.prior_information).
    prior_information: Optional[np.ndarray] = None

    @property
    def camera_in_pattern(self) -> Optional[np.ndarray]:
        if self.T_camera_pattern is None:
            return None
        return self.T_camera_pattern.inverse().t


class CardLocator:
    """Detect cards and estimate the camera pose from each."""

    def __init__(self, config: PatternConfig, estimator: str = 'exact',
                 detector_params: DetectorParams = DetectorParams(),
                 min_tilt_deg: float = 0.0, pixel_sigma: Optional[float] = None,
                 known_codes: Optional[Iterable[Code]] = None, fit_prior: bool = True):
        """
        Detect with ``detector_params``, locate with ``estimator``.

        ``known_codes`` (a building map's codes) let the detector complete a
        card partly hidden by an object (see :class:`Detector`).
        ``fit_prior``: as :func:`.pose_exact.estimate_exact`'s.
        """
        if estimator not in ESTIMATORS:
            raise ConfigError(f'unknown estimator {estimator!r}: use one of '
                              f'{", ".join(ESTIMATORS)}')
        self.config = config
        self.estimator = estimator
        self.detector = Detector(config, detector_params, known_codes)
        self.min_tilt_deg = min_tilt_deg
        self.pixel_sigma = pixel_sigma
        self.fit_prior = fit_prior

    def locate(self, image: np.ndarray, camera: CameraModel,
               prior: Optional[PosePrior] = None) -> List[LocatedCard]:
        """Every card in the image, biggest first, each with a pose when possible."""
        cards = sorted(self.detector.detect(image, camera), key=lambda c: -c.size_px)
        return [self.pose_of(card, camera, prior) for card in cards]

    def pose_of(self, card: CardDetection, camera: CameraModel,
                prior: Optional[PosePrior] = None) -> LocatedCard:
        if card.code is None and card.candidates:
            n = len(card.candidates)
            return _no_pose(card, self.estimator, f'code partly hidden: {n} known '
                            f'code{"s" if n > 1 else ""} fit the slots seen (a localizer '
                            'chooses by its last fix)')
        if card.code is None:
            return _no_pose(card, self.estimator, 'grey image: no code, so no pose')
        try:
            if self.estimator == 'paper':
                return self._paper(card, camera, prior)
            return self._exact(card, camera, prior)
        except EstimationError as exc:
            return _no_pose(card, self.estimator, str(exc))

    def _pixel_sigma(self, card: CardDetection) -> Optional[float]:
        """Return the dots' noise the pose counts at least: the locator's, or the card's floor."""
        if card.min_pixel_sigma > 0.0:
            return max(self.pixel_sigma or 0.0, card.min_pixel_sigma)
        return self.pixel_sigma

    def _exact(self, card: CardDetection, camera: CameraModel,
               prior: Optional[PosePrior]) -> LocatedCard:
        est = estimate_exact(card.points_px, camera, self.config, prior=prior,
                             pixel_sigma=self._pixel_sigma(card), fit_prior=self.fit_prior)
        psi, phi, theta, distance = paper_angles(est.T_camera_pattern, camera, self.config)
        if phi < self.min_tilt_deg:
            return _no_pose(card, 'exact', f'tilt {phi:.1f} deg below the minimum '
                                           f'{self.min_tilt_deg:.1f} deg')
        return LocatedCard(card, est.T_camera_pattern, est.covariance, est.reprojection_rms_px,
                           est.ambiguity, psi, phi, theta, distance, 'exact',
                           alternative=est.alternative,
                           other_probability=est.other_probability,
                           flip_barrier=est.flip_barrier,
                           prior_information=est.prior_information)

    def _paper(self, card: CardDetection, camera: CameraModel,
               prior: Optional[PosePrior]) -> LocatedCard:
        from .pose_paper import estimate_paper
        est = estimate_paper(card.points_px, camera, self.config, min_tilt_deg=self.min_tilt_deg)
        sigma = self._pixel_sigma(card)
        covariance = covariance_of_pose(est.T_camera_pattern, card.points_px, camera,
                                        self.config, sigma)
        alternative, other_probability, barrier = flip_as_exact_sees(
            est.T_camera_pattern, card.points_px, camera, self.config, prior, sigma)
        return LocatedCard(card, est.T_camera_pattern, covariance, est.reprojection_rms_px, None,
                           est.psi_deg, est.phi_deg, est.theta_deg, est.distance_m, 'paper',
                           alternative=alternative, other_probability=other_probability,
                           flip_barrier=barrier)


def flip_as_exact_sees(T_camera_pattern: Pose, points_px: np.ndarray, camera: CameraModel,
                       config: PatternConfig, prior: Optional[PosePrior] = None,
                       pixel_sigma: Optional[float] = None
                       ) -> Tuple[Optional[Pose], float, float]:
    """
    Return the planar flip of a pose from another estimator: other pose, probability, barrier.

    The flip is the dots' ambiguity, not an estimator's: the exact
    estimator's two planar solutions on the same dots (with the same prior)
    stand for it, and the pose is taken as the nearer of the two (camera
    positions). The other one, how likely it is (the exact estimator's
    ``other_probability``, or its complement when the pose is at the
    solution that estimator did not choose) and its ``flip_barrier``: what
    the localizer's flip gate judges. ``(None, 0, inf)`` when the dots give
    the exact estimator no pose or only one solution.
    """
    try:
        exact = estimate_exact(points_px, camera, config, prior=prior, pixel_sigma=pixel_sigma)
    except EstimationError:
        return None, 0.0, math.inf
    if exact.alternative is None:
        return None, 0.0, math.inf
    here = T_camera_pattern.inverse().t
    chosen, other = exact.T_camera_pattern, exact.alternative
    # No close call (no barrier): the dots rule the other solution out.
    probability = exact.other_probability if math.isfinite(exact.flip_barrier) else 0.0
    if np.linalg.norm(here - other.inverse().t) < np.linalg.norm(here - chosen.inverse().t):
        return chosen, 1.0 - probability, exact.flip_barrier
    return other, probability, exact.flip_barrier


def _no_pose(card: CardDetection, estimator: str, problem: str) -> LocatedCard:
    return LocatedCard(card, None, None, None, None, None, None, None, None, estimator, problem)
