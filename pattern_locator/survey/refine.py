"""
The final refinement on the dots' reprojections (bundle adjustment), where it helps.

A sighting's pose-graph factor is the exact estimator's pose with its
Fisher covariance: the reprojection likelihood linearised at that sighting's
own pose. Far from that pose (the optimised camera pose differs from it, as
it does for a distant or grazing card whose pose is poorly determined by
its own image) the linearisation is off; a reprojection factor is not.
:func:`reprojection_factor` replaces a sighting's factor by one over its dot
centres: the keyframe's base pose, the known step from it to the camera
(mount and, for a later member of the keyframe, odometry) and the card's
pose project the card's dots; the residual is the difference with the
detected centres (undistorted, corrected for the circle-centre bias at the
sighting's pose, as the estimator does), over the pixel noise the detector
used for the sighting's covariance.

It is a Python factor, a hundred times dearer than GTSAM's own, so it is
used only for the sightings that need it (``SurveyOptions.refine_dots``,
``refine_min_distance_m``); ``bench --survey`` measures whether it helps.
"""

import math
from typing import List, Optional

import gtsam
import numpy as np

from .sightings import Sighting
from ..card.pattern import PatternConfig
from ..vision.camera import CameraModel
from ..vision.geometry import Pose, skew
from ..vision.pose_exact import (DEFAULT_MIN_SIGMA_PX, ellipse_centres, MIN_OUTLIER_PX,
                                 OUTLIER_FACTOR)


def dot_observations(sighting: Sighting, camera: CameraModel, pattern: PatternConfig):
    """
    Return (card-frame dot centres (N, 3), ideal pixels (N, 2), pixel sigma) of a sighting.

    The pixels are undistorted and corrected for the offset between a
    circle's projected centre and its image ellipse's centre, as computed at
    the sighting's own pose (the estimator's correction).
    """
    points = np.asarray(sighting.points_px, dtype=float)
    seen = ~np.isnan(points).any(axis=1)
    model = pattern.model_points()[seen]
    radii = pattern.dot_radii()[seen]
    observed = camera.undistort_pixels(points[seen])
    T = sighting.T_camera_card
    projected = _pixels(T.apply(model), camera.K)
    offset = ellipse_centres(T, model[:, :2], radii, camera.K) - projected
    residual = np.linalg.norm(projected - (observed - offset), axis=1)
    # The estimator's own outlier rule: a dot far off the others' fit is left out.
    keep = residual <= max(MIN_OUTLIER_PX, OUTLIER_FACTOR * float(np.median(residual)))
    n = int(keep.sum())
    sigma = max(math.sqrt(float(np.sum(residual[keep] ** 2)) / max(2 * n - 6, 1)),
                DEFAULT_MIN_SIGMA_PX)
    return model[keep], (observed - offset)[keep], sigma


def _pixels(q: np.ndarray, K: np.ndarray) -> np.ndarray:
    return np.column_stack([K[0, 0] * q[:, 0] / q[:, 2] + K[0, 1] * q[:, 1] / q[:, 2] + K[0, 2],
                            K[1, 1] * q[:, 1] / q[:, 2] + K[1, 2]])


def reprojection_factor(base_key: int, card_key: int, T_base_camera: Pose, model: np.ndarray,
                        pixels: np.ndarray, K: np.ndarray, sigma_px: float,
                        huber_k: Optional[float] = None) -> gtsam.CustomFactor:
    """
    Return a factor on (base pose, card pose) over a sighting's dot centres.

    With ``T = (X C)^-1 L`` the card in the camera (X the base, C the
    camera on it, L the card) and q = T P a dot in the camera: right
    perturbations give ``dq/dL = R_T [-[P]x, I]`` and ``dq/dX = R_C^T [[s]x,
    -I]`` with s = X^-1 L P the dot in the base frame; then the pinhole's
    derivative.
    """
    C = T_base_camera
    Rc_t = C.R.T
    model = np.asarray(model, dtype=float)
    target = np.asarray(pixels, dtype=float)
    noise = gtsam.noiseModel.Isotropic.Sigma(2 * len(model), sigma_px)
    if huber_k is not None:
        noise = gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Huber.Create(huber_k),
                                               noise)

    def error(this, values, H: Optional[List[np.ndarray]]) -> np.ndarray:
        keys = this.keys()
        X = values.atPose3(keys[0]).matrix()
        Lm = values.atPose3(keys[1]).matrix()
        Rx, tx, Rl, tl = X[:3, :3], X[:3, 3], Lm[:3, :3], Lm[:3, 3]
        s = (model @ Rl.T + tl - tx) @ Rx                  # dots in the base frame
        q = (s - C.t) @ C.R                                 # dots in the camera frame
        out = (_pixels(q, K) - target).ravel()
        if H is not None:
            z = q[:, 2]
            dpix = np.zeros((len(q), 2, 3))
            dpix[:, 0, 0] = K[0, 0] / z
            dpix[:, 0, 1] = K[0, 1] / z
            dpix[:, 0, 2] = -(K[0, 0] * q[:, 0] + K[0, 1] * q[:, 1]) / z ** 2
            dpix[:, 1, 1] = K[1, 1] / z
            dpix[:, 1, 2] = -K[1, 1] * q[:, 1] / z ** 2
            R_T = Rc_t @ Rx.T @ Rl
            dq_l = np.concatenate([-R_T[None] @ np.array([skew(p) for p in model]),
                                   np.broadcast_to(R_T, (len(q), 3, 3))], axis=2)
            dq_x = np.concatenate([Rc_t[None] @ np.array([skew(p) for p in s]),
                                   np.broadcast_to(-Rc_t, (len(q), 3, 3))], axis=2)
            H[0] = (dpix @ dq_x).reshape(-1, 6)
            H[1] = (dpix @ dq_l).reshape(-1, 6)
        return out

    return gtsam.CustomFactor(noise, [base_key, card_key], error)
