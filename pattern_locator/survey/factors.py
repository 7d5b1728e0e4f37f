"""
The survey's own GTSAM factors and conversions between the project's poses and GTSAM's.

GTSAM's ``Pose3`` tangent is (rotation, translation), a right perturbation in
the body frame: ``T @ Exp(omega, v)``. The two custom factors are few (one
or two per card), so their Python cost does not matter:

* :func:`vertical_factor`: a card hangs vertical (its normal is horizontal),
  one scalar per card;
* :func:`height_factor`: a card's centre is a nominal height above the floor
  a base stood on when it saw the card.
"""

from typing import List, Optional

import gtsam
import numpy as np

from ..vision.geometry import Pose, skew

UP = np.array([0.0, 0.0, 1.0])
E_Z = np.array([0.0, 0.0, 1.0])


def to_gtsam(T: Pose) -> gtsam.Pose3:
    """Return the GTSAM pose of a project pose (``X_parent = R X_child + t`` both)."""
    return gtsam.Pose3(gtsam.Rot3(np.asarray(T.R, dtype=float)),
                       np.asarray(T.t, dtype=float))


def from_gtsam(T: gtsam.Pose3) -> Pose:
    """Return the project pose of a GTSAM pose."""
    m = T.matrix()
    return Pose(m[:3, :3].copy(), m[:3, 3].copy())


def building_covariance(T_building_card: Pose, marginal: np.ndarray) -> np.ndarray:
    """
    Return a card's GTSAM marginal as (x, y, z, rx, ry, rz) about the building's axes.

    A right perturbation ``(omega, v)`` in the card frame moves the card by
    ``R v`` and turns it by ``R omega`` about the building's axes.
    """
    R = T_building_card.R
    A = np.zeros((6, 6))
    A[:3, 3:] = R
    A[3:, :3] = R
    out = A @ np.asarray(marginal, dtype=float) @ A.T
    return 0.5 * (out + out.T)


def vertical_error(R: np.ndarray) -> float:
    """Return the vertical component of a card's normal (0 for a card on a plumb wall)."""
    return float(UP @ R @ E_Z)


def vertical_factor(key: int, sigma_rad: float) -> gtsam.CustomFactor:
    """Return a factor pulling the card's normal into the horizontal plane (sd ``sigma_rad``)."""
    noise = gtsam.noiseModel.Isotropic.Sigma(1, sigma_rad)

    def error(this, values, H: Optional[List[np.ndarray]]) -> np.ndarray:
        R = values.atPose3(this.keys()[0]).rotation().matrix()
        if H is not None:
            J = np.zeros((1, 6))
            J[0, :3] = -UP @ R @ skew(E_Z)
            H[0] = J
        return np.array([vertical_error(R)])

    return gtsam.CustomFactor(noise, [key], error)


def height_error(T_world_base: Pose, T_world_card: Pose) -> float:
    """Return the card centre's height above the base's floor plane."""
    return float((T_world_base.R.T @ (T_world_card.t - T_world_base.t))[2])


def height_factor(base_key: int, card_key: int, height_m: float, sigma_m: float
                  ) -> gtsam.CustomFactor:
    """Return a factor holding a card ``height_m`` above a base that saw it (sd ``sigma_m``)."""
    noise = gtsam.noiseModel.Isotropic.Sigma(1, sigma_m)

    def error(this, values, H: Optional[List[np.ndarray]]) -> np.ndarray:
        keys = this.keys()
        X = values.atPose3(keys[0])
        L = values.atPose3(keys[1])
        Rx = X.rotation().matrix()
        Rl = L.rotation().matrix()
        p = Rx.T @ (L.translation() - X.translation())
        if H is not None:
            Jx = np.zeros((1, 6))
            Jx[0, :3] = E_Z @ skew(p)
            Jx[0, 3:] = -E_Z
            Jl = np.zeros((1, 6))
            Jl[0, 3:] = E_Z @ Rx.T @ Rl
            H[0] = Jx
            H[1] = Jl
        return np.array([p[2] - height_m])

    return gtsam.CustomFactor(noise, [base_key, card_key], error)
