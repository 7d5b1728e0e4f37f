"""
Conversions between the project's poses and GTSAM's.

GTSAM's ``Pose3`` tangent is (rotation, translation), a right perturbation in
the body frame: ``T @ Exp(omega, v)``. The graph uses GTSAM's own factors
only: a factor written in Python is called back from C++ and costs about a
hundred times more per evaluation (measured: 2,000 such factors made
Levenberg-Marquardt take seconds).
"""

import gtsam
import numpy as np

from ..vision.geometry import Pose


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
