"""
A sighting: one card's pose seen in one image, with its covariance in the survey's form.

The detector's covariance (``pose_exact.pose_covariance``) is over the camera
position in the card frame and a small turn of the camera about the card's
axes, (c, theta). The factor graph needs it over GTSAM's tangent of
``T_camera_card``: a right perturbation ``T_camera_card @ Exp(rho, nu)``,
rotation first, both in the card frame. :func:`tangent_covariance` converts
one into the other.
"""

from dataclasses import dataclass
import math
from typing import List, Optional, Sequence, Tuple

import numpy as np

from ..vision.geometry import Pose, skew

# Bins of distance (m) and view angle (deg) whose sightings share a noise level: the
# detector's covariance is pessimistic for near, frontal views and optimistic for far,
# grazing ones, so the survey estimates a variance factor per bin.
DISTANCE_EDGES = (0.0, 3.0, 5.0, np.inf)
ANGLE_EDGES = (0.0, 30.0, 50.0, 90.0)


@dataclass(frozen=True, eq=False)
class Sighting:
    """
    A card seen in one frame of one bag.

    ``T_camera_card``: the exact estimator's pose; ``covariance``: its 6x6
    over (camera position in the card frame, m; turn about the card's axes,
    rad), as ``LocatedCard.covariance``. ``points_px``: the 17 dot centres
    (NaN where unseen), kept for the bundle adjustment.
    """

    bag: int
    frame: int
    stamp_ns: int
    code: str
    ids: Tuple[int, int, int]
    T_camera_card: Pose
    covariance: np.ndarray
    reprojection_rms_px: float
    ambiguity: float
    n_points: int
    points_px: Optional[np.ndarray] = None

    @property
    def distance_m(self) -> float:
        """Return the distance from the camera to the card's centre."""
        return float(np.linalg.norm(self.T_camera_card.t))

    @property
    def view_angle_deg(self) -> float:
        """Return the angle between the card's normal and the line to the camera (phi)."""
        c = self.T_camera_card.inverse().t
        return math.degrees(math.acos(float(np.clip(c[2] / np.linalg.norm(c), -1.0, 1.0))))

    @property
    def group(self) -> int:
        """Return the sighting's bin of distance and view angle (0..8; see GROUP_EDGES)."""
        i = int(np.searchsorted(DISTANCE_EDGES, self.distance_m, side='right')) - 1
        j = int(np.searchsorted(ANGLE_EDGES, self.view_angle_deg, side='right')) - 1
        return 3 * min(max(i, 0), 2) + min(max(j, 0), 2)


def tangent_covariance(T_camera_card: Pose, covariance: np.ndarray) -> np.ndarray:
    """
    Return the detector's (c, theta) covariance as GTSAM's tangent of ``T_camera_card``.

    With ``T_card_camera = (R, c)`` turned by theta about the card's axes
    (``R' = Exp(theta) R``, ``c' = c + dc``) and ``T_camera_card @ Exp(rho,
    nu)`` GTSAM's right perturbation (rho a turn, nu a shift, card axes):
    ``rho = -theta`` and ``nu = -dc - [c]x theta`` to first order.
    """
    c = T_camera_card.inverse().t
    A = np.zeros((6, 6))
    A[:3, 3:] = -np.eye(3)
    A[3:, :3] = -np.eye(3)
    A[3:, 3:] = -skew(c)
    out = A @ np.asarray(covariance, dtype=float) @ A.T
    return 0.5 * (out + out.T)


def tangent_covariances(sightings: Sequence[Sighting]) -> List[np.ndarray]:
    """Return :func:`tangent_covariance` of many sightings at once."""
    if not sightings:
        return []
    R = np.array([s.T_camera_card.R for s in sightings])
    t = np.array([s.T_camera_card.t for s in sightings])
    c = -np.einsum('nji,nj->ni', R, t)                  # camera position in the card frame
    A = np.zeros((len(sightings), 6, 6))
    A[:, :3, 3:] = -np.eye(3)
    A[:, 3:, :3] = -np.eye(3)
    A[:, 3, 4], A[:, 3, 5] = c[:, 2], -c[:, 1]          # -[c]x
    A[:, 4, 3], A[:, 4, 5] = -c[:, 2], c[:, 0]
    A[:, 5, 3], A[:, 5, 4] = c[:, 1], -c[:, 0]
    cov = np.array([s.covariance for s in sightings])
    out = A @ cov @ A.transpose(0, 2, 1)
    return list(0.5 * (out + out.transpose(0, 2, 1)))
