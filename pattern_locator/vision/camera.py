"""
Camera intrinsics: the ROS camera-info model, loaded from its standard YAML.

Pixels follow OpenCV: the optical frame is x right, y down, z forward, and
pixel (u, v) = (fx * x' + cx, fy * y' + cy) with (x', y') the distorted
normalised coordinates. Distortion models: ``plumb_bob`` (k1 k2 p1 p2 k3),
``rational_polynomial`` (8 coefficients) and ``equidistant`` (fisheye k1..k4).
"""

from dataclasses import dataclass, field
import math
from pathlib import Path
from typing import Optional, Sequence, Union

import cv2
import numpy as np
import yaml

from ..errors import CameraError
from ..resources import read_yaml

DISTORTION_MODELS = ('plumb_bob', 'rational_polynomial', 'equidistant', 'none')


@dataclass(frozen=True, eq=False)
class CameraModel:
    """Pinhole intrinsics with lens distortion, for one image size."""

    width: int
    height: int
    K: np.ndarray
    D: np.ndarray = field(default_factory=lambda: np.zeros(5))
    distortion_model: str = 'plumb_bob'
    name: str = 'camera'

    def __post_init__(self) -> None:
        K = np.asarray(self.K, dtype=float).reshape(3, 3)
        D = np.asarray(self.D, dtype=float).reshape(-1)
        object.__setattr__(self, 'K', K)
        object.__setattr__(self, 'D', D)
        if self.width <= 0 or self.height <= 0:
            raise CameraError(f'camera {self.name}: image size must be positive, got '
                              f'{self.width}x{self.height}')
        if K[0, 0] <= 0 or K[1, 1] <= 0 or not np.all(np.isfinite(K)):
            raise CameraError(f'camera {self.name}: camera_matrix needs positive fx, fy '
                              f'(got fx={K[0, 0]}, fy={K[1, 1]})')
        if self.distortion_model not in DISTORTION_MODELS:
            raise CameraError(f'camera {self.name}: distortion model '
                              f'{self.distortion_model!r} not supported '
                              f'(use one of {", ".join(DISTORTION_MODELS)})')
        if not np.all(np.isfinite(D)):
            raise CameraError(f'camera {self.name}: distortion coefficients must be finite')

    @property
    def fx(self) -> float:
        return float(self.K[0, 0])

    @property
    def fy(self) -> float:
        return float(self.K[1, 1])

    @property
    def cx(self) -> float:
        return float(self.K[0, 2])

    @property
    def cy(self) -> float:
        return float(self.K[1, 2])

    @property
    def has_distortion(self) -> bool:
        return self.distortion_model != 'none' and bool(np.any(self.D != 0.0))

    def _cv_dist(self) -> np.ndarray:
        if not self.has_distortion:
            return np.zeros(5)
        if self.distortion_model == 'rational_polynomial':
            return np.pad(self.D, (0, max(0, 8 - len(self.D))))[:8]
        if self.distortion_model == 'equidistant':
            return np.pad(self.D, (0, max(0, 4 - len(self.D))))[:4]
        return np.pad(self.D, (0, max(0, 5 - len(self.D))))[:5]

    def project(self, points_camera: np.ndarray) -> np.ndarray:
        """Pixels (N, 2) of 3D points (N, 3) in the optical frame, with distortion."""
        pts = np.asarray(points_camera, dtype=np.float64).reshape(-1, 1, 3)
        zero = np.zeros(3)
        if self.distortion_model == 'equidistant' and self.has_distortion:
            out, _ = cv2.fisheye.projectPoints(pts, zero, zero, self.K, self._cv_dist())
        else:
            out, _ = cv2.projectPoints(pts, zero, zero, self.K, self._cv_dist())
        return out.reshape(-1, 2)

    def normalize(self, pixels: np.ndarray) -> np.ndarray:
        """Undistorted normalised coordinates (N, 2) (x/z, y/z) of pixels (N, 2)."""
        px = np.asarray(pixels, dtype=np.float64).reshape(-1, 1, 2)
        if not self.has_distortion:
            out = (px.reshape(-1, 2) - [self.cx, self.cy]) / [self.fx, self.fy]
            return out
        if self.distortion_model == 'equidistant':
            out = cv2.fisheye.undistortPoints(px, self.K, self._cv_dist())
        else:
            criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-10)
            out = cv2.undistortPoints(px, self.K, self._cv_dist(), None, None, None, criteria)
        return out.reshape(-1, 2)

    def undistort_pixels(self, pixels: np.ndarray) -> np.ndarray:
        """Pixels of an ideal (distortion-free) camera with the same K."""
        n = self.normalize(pixels)
        return n * [self.fx, self.fy] + [self.cx, self.cy]

    def distort_pixels(self, ideal_px: np.ndarray) -> np.ndarray:
        """Return this camera's pixels of ideal-camera pixels (N, 2): undistort's inverse."""
        n = (np.asarray(ideal_px, dtype=float).reshape(-1, 2) - [self.cx, self.cy]) / [
            self.fx, self.fy]
        return self.project(np.column_stack([n, np.ones(len(n))]))

    def scaled(self, factor: float) -> 'CameraModel':
        """Return this camera at ``factor`` times the resolution (binning/decimation)."""
        K = self.K.copy()
        K[:2] *= factor
        return CameraModel(int(round(self.width * factor)), int(round(self.height * factor)),
                           K, self.D.copy(), self.distortion_model, self.name)

    @staticmethod
    def from_fov(width: int, height: int, hfov_deg: float, D: Optional[Sequence[float]] = None,
                 name: str = 'camera') -> 'CameraModel':
        """Square pixels, centred principal point, horizontal field of view in degrees."""
        fx = (width / 2.0) / math.tan(math.radians(hfov_deg) / 2.0)
        K = np.array([[fx, 0.0, (width - 1) / 2.0], [0.0, fx, (height - 1) / 2.0],
                      [0.0, 0.0, 1.0]])
        return CameraModel(width, height, K, np.zeros(5) if D is None else np.asarray(D),
                           'plumb_bob', name)

    @staticmethod
    def from_focal(width: int, height: int, f_px: float, D: Optional[Sequence[float]] = None,
                   name: str = 'camera') -> 'CameraModel':
        """Square pixels of focal length ``f_px``, centred principal point."""
        K = np.array([[f_px, 0.0, (width - 1) / 2.0], [0.0, f_px, (height - 1) / 2.0],
                      [0.0, 0.0, 1.0]])
        return CameraModel(width, height, K, np.zeros(5) if D is None else np.asarray(D),
                           'plumb_bob', name)

    def to_yaml_dict(self) -> dict:
        """Return the standard ROS camera-info YAML content."""
        P = np.zeros((3, 4))
        P[:3, :3] = self.K
        return {
            'image_width': int(self.width),
            'image_height': int(self.height),
            'camera_name': self.name,
            'camera_matrix': {'rows': 3, 'cols': 3, 'data': [float(v) for v in self.K.flat]},
            'distortion_model': self.distortion_model,
            'distortion_coefficients': {'rows': 1, 'cols': len(self.D),
                                        'data': [float(v) for v in self.D]},
            'rectification_matrix': {'rows': 3, 'cols': 3,
                                     'data': [float(v) for v in np.eye(3).flat]},
            'projection_matrix': {'rows': 3, 'cols': 4, 'data': [float(v) for v in P.flat]},
        }


def _matrix(data: dict, key: str, source: str, rows: int, cols: Optional[int]) -> np.ndarray:
    entry = data.get(key)
    if entry is None:
        raise CameraError(f'{source}: missing {key}')
    values = entry.get('data') if isinstance(entry, dict) else entry
    try:
        arr = np.asarray(values, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise CameraError(f'{source}: {key} must hold numbers') from None
    if cols is not None and arr.size != rows * cols:
        raise CameraError(f'{source}: {key} must have {rows * cols} values, got {arr.size}')
    return arr.reshape(rows, -1) if cols is not None else arr


def camera_from_dict(data: dict, source: str = 'camera') -> CameraModel:
    """Build a CameraModel from a parsed ROS camera-info YAML; CameraError names the problem."""
    if not isinstance(data, dict):
        raise CameraError(f'{source}: not a camera-info YAML (expected a mapping)')
    for key in ('image_width', 'image_height', 'camera_matrix'):
        if key not in data:
            raise CameraError(f'{source}: missing {key}')
    try:
        width, height = int(data['image_width']), int(data['image_height'])
    except (TypeError, ValueError):
        raise CameraError(f'{source}: image_width and image_height must be integers') from None
    K = _matrix(data, 'camera_matrix', source, 3, 3)
    model = str(data.get('distortion_model', 'plumb_bob') or 'plumb_bob')
    D = (_matrix(data, 'distortion_coefficients', source, 1, None)
         if 'distortion_coefficients' in data else np.zeros(5))
    expected = {'plumb_bob': (4, 5), 'rational_polynomial': (8, 14), 'equidistant': (4, 4)}
    low, high = expected.get(model, (0, 14))
    if D.size and not low <= D.size <= high and np.any(D != 0):
        raise CameraError(f'{source}: {model} needs {low}..{high} distortion coefficients, '
                          f'got {D.size}')
    if K[0, 0] <= 0 or K[1, 1] <= 0 or K[2, 2] != 1.0:
        raise CameraError(f'{source}: camera_matrix is not a valid K (fx={K[0, 0]}, '
                          f'fy={K[1, 1]}, last element {K[2, 2]})')
    try:
        return CameraModel(width, height, K, D, model, str(data.get('camera_name', 'camera')))
    except CameraError as exc:
        raise CameraError(f'{source}: {exc}') from None


def load_camera(path: Union[str, Path]) -> CameraModel:
    """Load a ROS camera-info YAML file; CameraError in one readable line if bad."""
    path = Path(path)
    data = read_yaml(path, 'camera file', error=CameraError)
    return camera_from_dict(data, str(path))


def save_camera(camera: CameraModel, path: Union[str, Path]) -> None:
    with open(path, 'w', encoding='utf-8') as stream:
        yaml.safe_dump(camera.to_yaml_dict(), stream, sort_keys=False)
