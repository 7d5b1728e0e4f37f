"""
Camera intrinsics: the ROS camera-info model, loaded from its standard YAML.

Pixels follow OpenCV: the optical frame is x right, y down, z forward, and
pixel (u, v) = (fx * x' + cx, fy * y' + cy) with (x', y') the distorted
normalised coordinates. Distortion models: ``plumb_bob`` (k1 k2 p1 p2 k3),
``rational_polynomial`` (8 coefficients) and ``equidistant`` (fisheye k1..k4).
"""

from dataclasses import dataclass, field
import math
import numbers
import operator
from pathlib import Path
from typing import Any, Optional, Sequence, Tuple, Union

import cv2
import numpy as np
import yaml

from ..errors import CameraError
from ..resources import read_yaml, UniqueKeyLoader

DISTORTION_MODELS = ('plumb_bob', 'rational_polynomial', 'equidistant', 'none')
# Coefficients each model takes (ROS camera_info): plumb_bob k1 k2 p1 p2 k3
# (OpenCV's 4-coefficient form, k3 = 0, is read too), rational_polynomial
# k1 k2 p1 p2 k3 k4 k5 k6, equidistant (fisheye) k1 k2 k3 k4.
D_COUNTS = {'plumb_bob': (4, 5), 'rational_polynomial': (8,), 'equidistant': (4,)}

# Invariants of every CameraModel (checked on construction). They keep the
# numbers finite downstream; they are loose because a camera cropped to a
# small box of an image (the renderer does that) is still a CameraModel.
MAX_IMAGE_SIDE = 65536                # pixels
MAX_FOCAL_PX = 1.0e7
MIN_FOCAL_PER_SIDE = 0.02             # fx, fy >= this * the longer image side
MAX_FOCAL_RATIO = 10.0                # fx / fy within 1/10 .. 10 (binning 1x4 is 4)
MAX_PRINCIPAL_PX = 1.0e6
MAX_DISTORTION_COEFF = 1.0e4

# Plausibility of a calibration given for a whole image (camera_info, YAML):
# what a real lens and sensor can give (camera_from_calibration).
FOV_RANGE_DEG = (0.1, 170.0)          # per axis, from fx and the width, fy and the height
CALIBRATION_FOCAL_RATIO = 2.0         # fx / fy within 1/2 .. 2
PRINCIPAL_MARGIN = 0.25               # cx in [-0.25 W, 1.25 W], cy likewise
ROTATION_TOLERANCE = 1e-3             # R^T R = I and det R = 1 within this
DISTORTION_FOV_FACTOR = 2.0           # ray angles at the border vs. without distortion
BORDER_ROUND_TRIP_PX = 0.5            # undistort then distort the border: back within this
NAME_CHARS = 80                       # a camera name from a message is cut to this
SOURCE_CHARS = 300                    # where an error's source (a path) is cut
MAX_FILE_BYTES = 64 * 1024            # a camera-info YAML is under 1 KB and 60 values
MAX_FILE_VALUES = 2000


def _fmt(value: float) -> str:
    """Return a number for a message: 6 significant digits, any size."""
    try:
        return f'{float(value):.6g}'
    except OverflowError:               # an int beyond float range
        return f'(an integer of {int(value).bit_length()} bits)'


def _index(value: Any, what: str, source: str) -> int:
    """Return an integer field (not a bool, not a float such as 640.0); CameraError if not."""
    if isinstance(value, (bool, np.bool_)):
        raise CameraError(f'{source}: {what} must be an integer, got {value!r}')
    try:
        return operator.index(value)
    except TypeError:
        shown = repr(value) if isinstance(value, numbers.Number) else type(value).__name__
        raise CameraError(f'{source}: {what} must be an integer, got {shown[:40]}') from None


def _real_array(values: Any, what: str, source: str, most: int = 16) -> np.ndarray:
    """Return a flat float array of at most ``most`` real numbers; CameraError if not."""
    if isinstance(values, (str, bytes)) or not hasattr(values, '__len__'):
        raise CameraError(f'{source}: {what} must be a list of numbers, got '
                          f'{type(values).__name__}')
    if isinstance(values, (list, tuple)) and 0 < len(values) <= most and all(
            isinstance(row, (list, tuple)) for row in values):
        values = [v for row in values for v in row]      # rows of a matrix
    if len(values) > most:
        raise CameraError(f'{source}: {what} has {len(values)} values, more than {most}')
    if isinstance(values, np.ndarray):
        if values.dtype.kind not in 'iuf':
            raise CameraError(f'{source}: {what} must hold numbers, got a {values.dtype} array')
        return values.astype(float).reshape(-1)
    out = np.empty(len(values))
    for i, v in enumerate(values):
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, numbers.Real):
            shown = repr(v)[:40] if isinstance(v, (str, numbers.Number)) else type(v).__name__
            raise CameraError(f'{source}: {what}[{i}] must be a number, got {shown}')
        try:
            out[i] = float(v)
        except OverflowError:           # an int beyond float range
            raise CameraError(f'{source}: {what}[{i}] is too large') from None
    return out


def _check_structure(width: Any, height: Any, K: Any, D: Any, distortion_model: Any,
                     source: str, ranges: bool = True
                     ) -> Tuple[int, int, np.ndarray, np.ndarray, str]:
    """
    Check the invariants every CameraModel holds; return normalised values.

    Size: integers 1..MAX_IMAGE_SIDE. K: 3x3, finite, bottom row exactly
    [0, 0, 1], no skew (OpenCV ignores it), fx, fy > 0 within loose bounds.
    D: finite, as many as the model takes (an empty D is no distortion).
    ``ranges``: also the loose bounds (focal length, fx / fy, principal
    point, coefficients); camera_from_calibration checks tighter ones first.
    """
    width = _index(width, 'image_width', source)
    height = _index(height, 'image_height', source)
    if not (0 < width <= MAX_IMAGE_SIDE and 0 < height <= MAX_IMAGE_SIDE):
        raise CameraError(f'{source}: image size must be positive (at most {MAX_IMAGE_SIDE} '
                          f'px a side), got {_fmt(width)}x{_fmt(height)}')
    K = _real_array(np.ravel(K) if isinstance(K, np.ndarray) else K, 'camera_matrix K',
                    source)
    if K.size != 9:
        raise CameraError(f'{source}: camera_matrix K must have 9 values, got {K.size}')
    K = K.reshape(3, 3)
    if not np.all(np.isfinite(K)):
        raise CameraError(f'{source}: camera_matrix K must be finite')
    if not np.array_equal(K[2], [0.0, 0.0, 1.0]):
        raise CameraError(f'{source}: camera_matrix K is not a valid K: its last row must be '
                          f'[0, 0, 1], got [{", ".join(_fmt(v) for v in K[2])}]')
    if K[1, 0] != 0.0:
        raise CameraError(f'{source}: camera_matrix K is not a valid K: K[1][0] must be 0, '
                          f'got {_fmt(K[1, 0])}')
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    if not (fx > 0.0 and fy > 0.0):
        raise CameraError(f'{source}: camera_matrix K is not a valid K: fx and fy must be '
                          f'positive (fx={_fmt(fx)}, fy={_fmt(fy)})')
    if abs(K[0, 1]) > 1e-9 * fx:
        raise CameraError(f'{source}: camera_matrix K has a skew K[0][1] = {_fmt(K[0, 1])}; '
                          f'OpenCV ignores skew, so it must be 0')
    lowest = MIN_FOCAL_PER_SIDE * max(width, height)
    for name, f in (('fx', fx), ('fy', fy)) if ranges else ():
        if not lowest <= f <= MAX_FOCAL_PX:
            raise CameraError(f'{source}: {name} = {_fmt(f)} px is out of range for a '
                              f'{width}x{height} image ({_fmt(lowest)}..{_fmt(MAX_FOCAL_PX)})')
    if ranges and not 1.0 / MAX_FOCAL_RATIO <= fx / fy <= MAX_FOCAL_RATIO:
        raise CameraError(f'{source}: fx / fy = {_fmt(fx / fy)} is out of range '
                          f'(1/{MAX_FOCAL_RATIO:g}..{MAX_FOCAL_RATIO:g})')
    if ranges and not (abs(cx) <= MAX_PRINCIPAL_PX and abs(cy) <= MAX_PRINCIPAL_PX):
        raise CameraError(f'{source}: principal point ({_fmt(cx)}, {_fmt(cy)}) is out of '
                          f'range')
    if not isinstance(distortion_model, str):
        raise CameraError(f'{source}: distortion model must be text, got '
                          f'{type(distortion_model).__name__}')
    if distortion_model not in DISTORTION_MODELS:
        raise CameraError(f'{source}: distortion model {distortion_model[:NAME_CHARS]!r} not '
                          f'supported (use one of {", ".join(DISTORTION_MODELS)})')
    D = _real_array(D, 'distortion_coefficients D', source)
    if not np.all(np.isfinite(D)):
        raise CameraError(f'{source}: distortion coefficients must be finite')
    if distortion_model == 'none':
        if np.any(D != 0.0):
            raise CameraError(f'{source}: distortion model none takes no coefficients, got '
                              f'{D.size} non-zero')
        D = np.zeros(5)
    elif D.size == 0:
        D = np.zeros(D_COUNTS[distortion_model][-1])
    elif D.size not in D_COUNTS[distortion_model]:
        counts = ' or '.join(str(n) for n in D_COUNTS[distortion_model])
        raise CameraError(f'{source}: {distortion_model} needs {counts} distortion '
                          f'coefficients, got {D.size}')
    if D.size == 4 and distortion_model == 'plumb_bob':
        D = np.append(D, 0.0)          # OpenCV's 4-coefficient form: k3 = 0
    worst = float(np.max(np.abs(D))) if D.size else 0.0
    if worst > MAX_DISTORTION_COEFF:
        raise CameraError(f'{source}: distortion coefficient {_fmt(worst)} is out of range '
                          f'(|D| <= {MAX_DISTORTION_COEFF:g})')
    return width, height, K, D, distortion_model


@dataclass(frozen=True, eq=False)
class CameraModel:
    """
    Pinhole intrinsics with lens distortion, for one image size.

    Construction checks the invariants that keep every computation finite
    (see ``_check_structure``): integer size, a proper K, D as long as its
    model takes. A calibration from outside (a file, a topic) should come in
    through :func:`camera_from_calibration`, which also checks that it is
    plausible for its image (field of view, principal point, distortion).
    """

    width: int
    height: int
    K: np.ndarray
    D: np.ndarray = field(default_factory=lambda: np.zeros(5))
    distortion_model: str = 'plumb_bob'
    name: str = 'camera'

    def __post_init__(self) -> None:
        width, height, K, D, model = _check_structure(
            self.width, self.height, self.K, self.D, self.distortion_model,
            f'camera {self.name}')
        object.__setattr__(self, 'width', width)
        object.__setattr__(self, 'height', height)
        object.__setattr__(self, 'K', K)
        object.__setattr__(self, 'D', D)
        object.__setattr__(self, 'distortion_model', model)
        # Asked for every few points a frame: made once (the fields are frozen).
        distorted = model != 'none' and bool(np.any(D != 0.0))
        object.__setattr__(self, '_distorted', distorted)
        object.__setattr__(self, '_cv_coeffs', _cv_coefficients(D, model, distorted))
        object.__setattr__(self, '_focal', np.array([K[0, 0], K[1, 1]], dtype=np.float64))
        object.__setattr__(self, '_centre', np.array([K[0, 2], K[1, 2]], dtype=np.float64))

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
        return self._distorted

    def _cv_dist(self) -> np.ndarray:
        return self._cv_coeffs

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
        if not self._distorted:
            return (px.reshape(-1, 2) - self._centre) / self._focal
        if self.distortion_model == 'equidistant':
            out = cv2.fisheye.undistortPoints(px, self.K, self._cv_dist())
        else:
            criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-10)
            out = cv2.undistortPoints(px, self.K, self._cv_dist(), None, None, None, criteria)
        return out.reshape(-1, 2)

    def undistort_pixels(self, pixels: np.ndarray) -> np.ndarray:
        """Pixels of an ideal (distortion-free) camera with the same K."""
        n = self.normalize(pixels)
        return n * self._focal + self._centre

    def distort_pixels(self, ideal_px: np.ndarray) -> np.ndarray:
        """Return this camera's pixels of ideal-camera pixels (N, 2): undistort's inverse."""
        n = (np.asarray(ideal_px, dtype=float).reshape(-1, 2) - self._centre) / self._focal
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


def _cv_coefficients(D: np.ndarray, model: str, distorted: bool) -> np.ndarray:
    """Return OpenCV's distortion coefficients for a checked ``D`` of ``model`` (read-only)."""
    if not distorted:
        out = np.zeros(5)
    elif model == 'rational_polynomial':
        out = np.pad(D, (0, max(0, 8 - len(D))))[:8]
    elif model == 'equidistant':
        out = np.pad(D, (0, max(0, 4 - len(D))))[:4]
    else:
        out = np.pad(D, (0, max(0, 5 - len(D))))[:5]
    out = np.array(out, dtype=np.float64)
    # Shared by every call: nobody may change it.
    out.flags.writeable = False
    return out


def _fov_deg(focal: float, side: int) -> float:
    """Return the field of view (deg) of ``side`` pixels at a focal length (pinhole)."""
    return math.degrees(2.0 * math.atan(side / (2.0 * focal)))


def _check_plausible_k(K: np.ndarray, width: int, height: int, what: str, source: str) -> None:
    """Field of view, fx / fy and principal point of a whole image's K (or P's left 3x3)."""
    low, high = FOV_RANGE_DEG
    for axis, focal, side in (('horizontal', K[0, 0], width), ('vertical', K[1, 1], height)):
        fov = _fov_deg(focal, side)
        if not low <= fov <= high:
            name = 'fx' if axis == 'horizontal' else 'fy'
            raise CameraError(f'{source}: {what} {name} = {_fmt(focal)} px gives a {axis} field '
                              f'of view of {fov:.3g} deg over {side} px (plausible: '
                              f'{low:g}..{high:g} deg)')
    ratio = K[0, 0] / K[1, 1]
    if not 1.0 / CALIBRATION_FOCAL_RATIO <= ratio <= CALIBRATION_FOCAL_RATIO:
        raise CameraError(f'{source}: {what} fx / fy = {_fmt(ratio)}: pixels that far from '
                          f'square are implausible (1/{CALIBRATION_FOCAL_RATIO:g}..'
                          f'{CALIBRATION_FOCAL_RATIO:g})')
    for name, c, side in (('cx', K[0, 2], width), ('cy', K[1, 2], height)):
        if not -PRINCIPAL_MARGIN * side <= c <= (1.0 + PRINCIPAL_MARGIN) * side:
            raise CameraError(f'{source}: {what} principal point {name} = {_fmt(c)} is far '
                              f'outside the image (0..{side} px, margin '
                              f'{PRINCIPAL_MARGIN:.0%})')


def _check_distortion(camera: CameraModel, source: str) -> None:
    """
    Check that the distortion can be undone everywhere in the image.

    Undistorting the border pixels must give finite rays that distort back
    onto the same pixels, and along each ray from the principal point out to
    the border, distorted points must move outwards (a model that folds back
    maps two directions onto one pixel: no pose from it can be trusted).
    """
    if not camera.has_distortion:
        return
    w, h = camera.width, camera.height
    u = np.linspace(-0.5, w - 0.5, 9)
    v = np.linspace(-0.5, h - 0.5, 9)
    border = np.vstack([np.column_stack([u, np.full(9, v[0])]),
                        np.column_stack([u, np.full(9, v[-1])]),
                        np.column_stack([np.full(9, u[0]), v]),
                        np.column_stack([np.full(9, u[-1]), v])])
    problem = 'distortion cannot be undone at the image border'
    with np.errstate(all='ignore'):
        try:
            rays = camera.normalize(border)
            ok = np.all(np.isfinite(rays)) and np.max(np.abs(rays)) < 1e3
            back = camera.project(np.column_stack([rays, np.ones(len(rays))])) if ok else None
        except cv2.error:
            ok, back = False, None
        if ok:
            error = float(np.max(np.linalg.norm(back - border, axis=1)))
            ok = math.isfinite(error) and error <= BORDER_ROUND_TRIP_PX
            if not ok and math.isfinite(error):
                problem = (f'distortion cannot be undone at the image border (undistorting and '
                           f'distorting back is off by {error:.3g} px)')
        if ok:
            # The ray angle at the border against the angle without distortion.
            radius = np.linalg.norm((border - [camera.cx, camera.cy]) / [camera.fx, camera.fy],
                                    axis=1)
            plain = radius if camera.distortion_model == 'equidistant' else np.arctan(radius)
            angle = np.arctan(np.linalg.norm(rays, axis=1))
            far = plain > 1e-3
            ratio = angle[far] / plain[far]
            if ratio.size and not (1.0 / DISTORTION_FOV_FACTOR <= ratio.min()
                                   and ratio.max() <= DISTORTION_FOV_FACTOR):
                ok = False
                worst = ratio.min() if ratio.min() < 1.0 / ratio.max() else ratio.max()
                problem = (f'distortion scales the field of view at the image border by '
                           f'{worst:.3g} (plausible: 1/{DISTORTION_FOV_FACTOR:g}..'
                           f'{DISTORTION_FOV_FACTOR:g})')
        if ok:
            t = np.linspace(0.0, 1.0, 33)
            along = (t[:, None, None] * rays[None]).reshape(-1, 2)
            px = camera.project(np.column_stack([along, np.ones(len(along))]))
            px = px.reshape(len(t), len(rays), 2)
            outward = px[1:] - [camera.cx, camera.cy]
            step = np.diff(px, axis=0)
            ok = bool(np.all(np.isfinite(px)) and np.all(np.sum(step * outward, axis=2) > 0.0))
            if not ok:
                problem = 'distortion folds back inside the image (not monotonic)'
    if not ok:
        raise CameraError(f'{source}: {problem} (D = [{", ".join(_fmt(d) for d in camera.D)}])')


def _optional_matrix(values: Any, rows: int, cols: int, what: str, source: str
                     ) -> Optional[np.ndarray]:
    """Return a rows x cols matrix, or None when not given (None, empty or all zeros)."""
    if values is None:
        return None
    array = _real_array(np.ravel(values) if isinstance(values, np.ndarray) else values,
                        what, source)
    if array.size == 0 or (array.size == rows * cols and not np.any(array)):
        return None                     # ROS leaves R and P zero when it has none
    if array.size != rows * cols:
        raise CameraError(f'{source}: {what} must have {rows * cols} values, got {array.size}')
    if not np.all(np.isfinite(array)):
        raise CameraError(f'{source}: {what} must be finite')
    return array.reshape(rows, cols)


def camera_from_calibration(width: Any, height: Any, K: Any, D: Any = (),
                            distortion_model: Any = 'plumb_bob', R: Any = None, P: Any = None,
                            source: str = 'camera_info', name: str = 'camera') -> CameraModel:
    """
    Return the CameraModel of a calibration given for a whole image, if it is plausible.

    The one validator of intrinsics from outside (camera-info YAML, the
    camera_info topic). On top of CameraModel's invariants: each axis's
    field of view within ``FOV_RANGE_DEG``, fx / fy within
    ``CALIBRATION_FOCAL_RATIO``, the principal point in the image or near it,
    a distortion that can be undone over the whole image; ``R`` (3x3) a
    rotation, ``P`` (3x4) a projection with last row [0, 0, 1, 0] and a
    plausible left 3x3 (``R``, ``P``: None, empty or all zeros = not given;
    they are checked, not used). ``D`` empty = no distortion. Raises
    CameraError with one short line starting with ``source``.
    """
    # A file path is shown whole (a user must find the file); only a source
    # too long for one line (a foreign frame id, say) is cut, visibly.
    source = str(source)
    if len(source) > SOURCE_CHARS:
        source = source[:SOURCE_CHARS - 3] + '...'
    name = str(name)[:NAME_CHARS] or 'camera'
    K = _real_array(np.ravel(K) if isinstance(K, np.ndarray) else K, 'camera_matrix K',
                    source)
    if K.size == 9 and not np.any(K):
        raise CameraError(f'{source}: camera_matrix K is all zeros (an uncalibrated camera)')
    width, height, K, D_checked, model = _check_structure(width, height, K, D,
                                                          distortion_model, source, False)
    _check_plausible_k(K, width, height, 'K', source)
    rotation = _optional_matrix(R, 3, 3, 'rectification_matrix R', source)
    if rotation is not None:
        error = float(np.max(np.abs(rotation.T @ rotation - np.eye(3))))
        det = float(np.linalg.det(rotation))
        if error > ROTATION_TOLERANCE or abs(det - 1.0) > ROTATION_TOLERANCE:
            raise CameraError(f'{source}: rectification_matrix R is not a rotation (R^T R is '
                              f'off the identity by {_fmt(error)}, det {_fmt(det)})')
    projection = _optional_matrix(P, 3, 4, 'projection_matrix P', source)
    if projection is not None:
        if not np.array_equal(projection[2], [0.0, 0.0, 1.0, 0.0]):
            raise CameraError(f'{source}: projection_matrix P is not a valid P: its last row '
                              f'must be [0, 0, 1, 0], got '
                              f'[{", ".join(_fmt(v) for v in projection[2])}]')
        left = projection[:, :3]
        if left[1, 0] != 0.0 or not (left[0, 0] > 0.0 and left[1, 1] > 0.0):
            raise CameraError(f'{source}: projection_matrix P is not a valid P (needs P[1][0] '
                              f'= 0 and positive fx, fy)')
        _check_plausible_k(left, width, height, 'P', source)
    camera = CameraModel(width, height, K, D_checked, model, name)
    _check_distortion(camera, source)
    return camera


def _yaml_matrix(data: dict, key: str, source: str, rows: Optional[int],
                 cols: Optional[int]) -> Any:
    """
    Return the data list of a ``{rows, cols, data}`` entry (or a plain list).

    ``rows``, ``cols`` given in the file must be integers that agree with the
    data and, where the shape is fixed, with it (``None``: any).
    """
    entry = data.get(key)
    if entry is None:
        return None
    if isinstance(entry, list):
        return entry
    if not isinstance(entry, dict):
        raise CameraError(f'{source}: {key} must be a mapping with rows, cols and data, got '
                          f'{type(entry).__name__}')
    values = entry.get('data')
    if not isinstance(values, list):
        raise CameraError(f'{source}: {key}: data must be a list of numbers')
    shape = []
    for part, expected in (('rows', rows), ('cols', cols)):
        if part not in entry:
            shape.append(None)
            continue
        value = _index(entry[part], f'{key}: {part}', source)
        if expected is not None and value != expected:
            raise CameraError(f'{source}: {key}: {part} must be {expected}, got {value}')
        shape.append(value)
    if None not in shape and shape[0] * shape[1] != len(values):
        raise CameraError(f'{source}: {key}: rows x cols = {shape[0]} x {shape[1]} does not '
                          f'match its {len(values)} values')
    return values


def camera_from_dict(data: Any, source: str = 'camera') -> CameraModel:
    """Build a CameraModel from a parsed ROS camera-info YAML; CameraError names the problem."""
    if not isinstance(data, dict):
        raise CameraError(f'{source}: not a camera-info YAML (expected a mapping)')
    for key in ('image_width', 'image_height', 'camera_matrix'):
        if data.get(key) is None:
            raise CameraError(f'{source}: missing {key}')
    K = _yaml_matrix(data, 'camera_matrix', source, 3, 3)
    D = _yaml_matrix(data, 'distortion_coefficients', source, 1, None)
    R = _yaml_matrix(data, 'rectification_matrix', source, 3, 3)
    P = _yaml_matrix(data, 'projection_matrix', source, 3, 4)
    model = data.get('distortion_model') or 'plumb_bob'
    name = data.get('camera_name', 'camera')
    if isinstance(name, (bool, float)) or not isinstance(name, (str, int)):
        raise CameraError(f'{source}: camera_name must be text, got {type(name).__name__}')
    return camera_from_calibration(data['image_width'], data['image_height'], K,
                                   () if D is None else D, model, R, P, source, str(name))


def load_camera(path: Union[str, Path]) -> CameraModel:
    """Load a ROS camera-info YAML file; CameraError in one readable line if bad."""
    path = Path(path)
    data = read_yaml(path, 'camera file', error=CameraError, loader=UniqueKeyLoader,
                     max_bytes=MAX_FILE_BYTES, max_nodes=MAX_FILE_VALUES)
    return camera_from_dict(data, str(path))


def save_camera(camera: CameraModel, path: Union[str, Path]) -> None:
    with open(path, 'w', encoding='utf-8') as stream:
        yaml.safe_dump(camera.to_yaml_dict(), stream, sort_keys=False)
