"""
Rigid transforms and rotation helpers shared by the estimators and tools.

Convention: ``Pose(R, t)`` maps points of a *child* frame into a *parent*
frame, ``X_parent = R @ X_child + t``. ``T_camera_pattern`` therefore maps
pattern points into the camera frame.
"""

from dataclasses import dataclass
import math

import numpy as np


@dataclass(frozen=True)
class Pose:
    """A rigid transform ``X_parent = R @ X_child + t`` (metres)."""

    R: np.ndarray
    t: np.ndarray

    @staticmethod
    def from_matrix(T: np.ndarray) -> 'Pose':
        T = np.asarray(T, dtype=float)
        return Pose(T[:3, :3].copy(), T[:3, 3].copy())

    @staticmethod
    def from_rvec(rvec: np.ndarray, tvec: np.ndarray) -> 'Pose':
        return Pose(rodrigues(rvec), np.asarray(tvec, dtype=float).reshape(3))

    @staticmethod
    def identity() -> 'Pose':
        return Pose(np.eye(3), np.zeros(3))

    def matrix(self) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3] = self.R
        T[:3, 3] = self.t
        return T

    def inverse(self) -> 'Pose':
        return Pose(self.R.T, -self.R.T @ self.t)

    def __matmul__(self, other: 'Pose') -> 'Pose':
        return Pose(self.R @ other.R, self.R @ other.t + self.t)

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Map an (N, 3) array of child-frame points into the parent frame."""
        return np.asarray(points, dtype=float) @ self.R.T + self.t

    def rvec(self) -> np.ndarray:
        return rotation_vector(self.R)


def yaw_pose(x: float, y: float, heading: float, z: float = 0.0) -> Pose:
    """Return the pose of a base on a level floor at (x, y, z) with this heading (rad)."""
    c, s = math.cos(heading), math.sin(heading)
    return Pose(np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]), np.array([x, y, z]))


def yaw_of(R: np.ndarray) -> float:
    """Return the heading of a rotation's x axis in the xy plane (rad)."""
    return math.atan2(R[1, 0], R[0, 0])


def rodrigues(rvec: np.ndarray) -> np.ndarray:
    """Rotation matrix of a rotation vector (axis * angle, radians)."""
    r = np.asarray(rvec, dtype=float).reshape(3)
    angle = float(np.linalg.norm(r))
    if angle < 1e-12:
        return np.eye(3) + skew(r)
    k = r / angle
    K = skew(k)
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * (K @ K)


def rotation_vector(R: np.ndarray) -> np.ndarray:
    """Rotation vector (axis * angle) of a rotation matrix."""
    R = np.asarray(R, dtype=float)
    cos_angle = np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)
    angle = float(np.arccos(cos_angle))
    if angle < 1e-9:
        return np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / 2.0
    if np.pi - angle < 1e-6:
        # Near 180 degrees the antisymmetric part vanishes: take the axis from
        # the symmetric part instead.
        B = (R + np.eye(3)) / 2.0
        axis = np.sqrt(np.clip(np.diag(B), 0.0, None))
        i = int(np.argmax(axis))
        axis = B[i] / axis[i]
        return axis / np.linalg.norm(axis) * angle
    axis = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    return axis / (2.0 * np.sin(angle)) * angle


def skew(v: np.ndarray) -> np.ndarray:
    x, y, z = np.asarray(v, dtype=float).reshape(3)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def rotation_angle(Ra: np.ndarray, Rb: np.ndarray) -> float:
    """Angle (radians) of the rotation that takes ``Ra`` to ``Rb``."""
    cos_angle = (np.trace(np.asarray(Ra).T @ np.asarray(Rb)) - 1.0) / 2.0
    return float(np.arccos(np.clip(cos_angle, -1.0, 1.0)))


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray = (0.0, 0.0, 1.0),
            roll: float = 0.0) -> Pose:
    """
    Camera pose ``T_world_camera`` (optical frame) at ``eye`` looking at ``target``.

    The optical frame is x right, y down, z forward; ``up`` is the world
    direction that appears upwards in the image (before ``roll``, radians,
    which turns the camera about its optical axis, positive = clockwise in
    the image).
    """
    eye = np.asarray(eye, dtype=float)
    z = np.asarray(target, dtype=float) - eye
    z /= np.linalg.norm(z)
    up = np.asarray(up, dtype=float)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-9:
        # Looking straight along `up`: any horizontal x will do.
        x = np.cross(z, np.array([1.0, 0.0, 0.0]))
        if np.linalg.norm(x) < 1e-9:
            x = np.cross(z, np.array([0.0, 1.0, 0.0]))
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.column_stack([x, y, z])
    if roll:
        R = R @ rodrigues(np.array([0.0, 0.0, roll]))
    return Pose(R, eye)


def quaternion_xyzw(R: np.ndarray) -> np.ndarray:
    """Return the unit quaternion (x, y, z, w) of a rotation matrix, w >= 0."""
    R = np.asarray(R, dtype=float)
    tr = np.trace(R)
    if tr > 0.0:
        s = np.sqrt(tr + 1.0) * 2.0
        q = np.array([(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s,
                      (R[1, 0] - R[0, 1]) / s, 0.25 * s])
    else:
        i = int(np.argmax(np.diag(R)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = np.sqrt(1.0 + R[i, i] - R[j, j] - R[k, k]) * 2.0
        q = np.zeros(4)
        q[i] = 0.25 * s
        q[j] = (R[j, i] + R[i, j]) / s
        q[k] = (R[k, i] + R[i, k]) / s
        q[3] = (R[k, j] - R[j, k]) / s
    q /= np.linalg.norm(q)
    return q if q[3] >= 0.0 else -q


def rotation_from_quaternion(q_xyzw: np.ndarray) -> np.ndarray:
    x, y, z, w = np.asarray(q_xyzw, dtype=float) / np.linalg.norm(q_xyzw)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])
