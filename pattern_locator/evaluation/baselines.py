"""
Comparison baselines: an AprilTag 36h11 card and an ArUco card, with pose.

Both are printed on the same square card (side ``card_size``) as the colour-dot
card, so the benchmark compares like with like: the marker's black square is
8 of the card's 10 cells (``0.8 * card_size``), inside a one-cell white quiet
zone, which is the standard tag36h11 layout and the usual way to print ArUco.

Card frame (as for the colour-dot card): origin at the card centre, x right,
y up, z out of the card toward the viewer; bitmap row 0 is the top (+y).

They are meant as a fair *best case* of each library, not a straw man:

* AprilTag: ``pupil_apriltags.Detector`` with the library defaults that most
  users run (``quad_decimate=2.0``, ``refine_edges=1``,
  ``decode_sharpening=0.25``, ``quad_sigma=0``), single thread. The wrapper
  (1.0.4) casts ``decode_sharpening`` to ``int`` and so silently runs with 0;
  we write the intended value into the C struct so the default really holds.
  Its corners put pixel centres at (0.5, 0.5); we shift them to OpenCV's
  convention (otherwise every corner is 0.5 px off). The card is the
  published tag36h11 image (OpenCV's dictionary draws it turned by 180 deg).
* ArUco: ``cv2.aruco.ArucoDetector`` on ``DICT_6X6_250`` with default
  parameters except ``CORNER_REFINE_SUBPIX``, the documented best practice
  for pose estimation.
* Pose, for both: the detected corners are undistorted with the full camera
  model, then ``SOLVEPNP_IPPE_SQUARE`` gives both planar solutions, each is
  polished with ``solvePnPRefineLM`` against the corners as detected
  (through the lens distortion) and the one with the lower reprojection
  error is kept. That is at least as good as what ``apriltag_ros``
  does (homography + iterative refinement) and as ArUco's own pose helpers.

Grayscale conversion is part of ``detect()`` on purpose: it is per-frame work
a user's pipeline does too, so it belongs in the timed call.
"""

from dataclasses import dataclass
from typing import Dict, List, Optional, Tuple, Union
import weakref

import cv2
import numpy as np

from ..errors import ImageError
from ..vision.camera import CameraModel
from ..vision.geometry import Pose

KINDS = ('apriltag', 'aruco')

# Cells across the whole card, and across the black-bordered marker in it.
CARD_CELLS = 10
MARKER_CELLS = 8

_DICTIONARIES = {
    'apriltag': cv2.aruco.DICT_APRILTAG_36h11,
    'aruco': cv2.aruco.DICT_6X6_250,
}

# Corner order as each detector reports it, for a card seen upright, as
# (x, y) signs in the card frame (y up):
# pupil-apriltags: bottom-left, bottom-right, top-right, top-left;
# ArUco: top-left, top-right, bottom-right, bottom-left.
_CORNER_SIGNS = {
    'apriltag': np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]]),
    'aruco': np.array([[-1.0, 1.0], [1.0, 1.0], [1.0, -1.0], [-1.0, -1.0]]),
}

# SOLVEPNP_IPPE_SQUARE needs the object points as (-s, s), (s, s), (s, -s),
# (-s, -s): index of the detector's corner for each of those.
_IPPE_ORDER = {
    'apriltag': np.array([3, 2, 1, 0]),
    'aruco': np.array([0, 1, 2, 3]),
}


def _check_kind(kind: str) -> None:
    if kind not in KINDS:
        raise ValueError(f'unknown marker kind {kind!r} (use one of {", ".join(KINDS)})')


def tag_black_size(kind: str, card_size: float = 0.3) -> float:
    """Edge length (m) of the marker's black square on a card of side ``card_size``."""
    _check_kind(kind)
    return card_size * MARKER_CELLS / CARD_CELLS


def tag_object_points(kind: str, card_size: float = 0.3) -> np.ndarray:
    """Black-square corners (4, 3) in the card frame, in the detector's corner order."""
    half = tag_black_size(kind, card_size) / 2.0
    pts = np.zeros((4, 3))
    pts[:, :2] = _CORNER_SIGNS[kind] * half
    return pts


def tag_card_bitmap(kind: str, tag_id: int, cells_per_side_px: int = 1) -> np.ndarray:
    """
    Grayscale (uint8) image of the whole card, ``cells_per_side_px`` pixels per cell.

    The image is ``10 * cells_per_side_px`` pixels square: a one-cell white
    margin around the 8x8-cell black-bordered marker. Row 0 is the top of the
    card.
    """
    _check_kind(kind)
    dictionary = cv2.aruco.getPredefinedDictionary(_DICTIONARIES[kind])
    count = dictionary.bytesList.shape[0]
    if not 0 <= int(tag_id) < count:
        raise ValueError(f'{kind} id {tag_id} out of range 0..{count - 1}')
    if int(cells_per_side_px) < 1:
        raise ValueError(f'cells_per_side_px must be >= 1, got {cells_per_side_px}')
    marker = dictionary.generateImageMarker(int(tag_id), MARKER_CELLS)
    if kind == 'apriltag':
        # OpenCV's tag36h11 bit layout is the official one turned by 180
        # degrees: turn it back so the card matches the published tag images
        # (apriltag_to_image), i.e. what pupil-apriltags decodes as upright.
        marker = np.rot90(marker, 2)
    card = np.pad(marker, (CARD_CELLS - MARKER_CELLS) // 2, constant_values=255)
    n = int(cells_per_side_px)
    return np.ascontiguousarray(np.kron(card, np.ones((n, n), dtype=np.uint8)))


@dataclass(frozen=True)
class TagDetection:
    """One detected marker card and its pose."""

    tag_id: int
    corners_px: np.ndarray     # (4, 2) image pixels (distorted image), detector order
    T_camera_card: Pose        # X_cam = R X_card + t, card frame as in the module doc
    reprojection_rms_px: float


def _gray(image_bgr: np.ndarray) -> np.ndarray:
    img = np.asarray(image_bgr)
    if img.dtype != np.uint8:
        raise ImageError(f'image must be uint8, got {img.dtype}')
    if img.ndim == 2:
        return np.ascontiguousarray(img)
    if img.ndim == 3 and img.shape[2] == 3:
        return cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    if img.ndim == 3 and img.shape[2] == 4:
        return cv2.cvtColor(img, cv2.COLOR_BGRA2GRAY)
    if img.ndim == 3 and img.shape[2] == 1:
        return np.ascontiguousarray(img[:, :, 0])
    raise ImageError(f'image must be (H, W), (H, W, 3) or (H, W, 4) uint8, got shape '
                     f'{img.shape}')


def square_pose_solutions(corners_px: np.ndarray, kind: str, card_size: float,
                          camera: CameraModel) -> List[Tuple[Pose, float]]:
    """
    Both planar pose solutions of the four detected corners, best first.

    IPPE-square on the undistorted corners gives the two solutions of a
    square (the flip ambiguity); each is polished by Levenberg-Marquardt
    against the corners as detected (through the lens distortion, where the
    corner noise is). Each comes with its cost, the sum of squared
    reprojection errors (px^2) of the four corners through the full camera
    model. Empty if there is no valid pose.
    """
    _check_kind(kind)
    corners = np.asarray(corners_px, dtype=np.float64).reshape(4, 2)
    if not np.all(np.isfinite(corners)):
        return []
    order = _IPPE_ORDER[kind]
    obj_detector = tag_object_points(kind, card_size)
    obj = obj_detector[order]
    ideal = camera.undistort_pixels(corners)[order]
    if not np.all(np.isfinite(ideal)):
        return []
    K = camera.K
    zero = np.zeros(5)
    try:
        n, rvecs, tvecs, _ = cv2.solvePnPGeneric(
            obj, ideal, K, zero, flags=cv2.SOLVEPNP_IPPE_SQUARE)
    except cv2.error:
        return []
    fisheye = camera.distortion_model == 'equidistant' and camera.has_distortion
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-12)
    out = []
    for rvec, tvec in zip(rvecs[:n], tvecs[:n]):
        rvec = np.asarray(rvec, dtype=np.float64).reshape(3, 1)
        tvec = np.asarray(tvec, dtype=np.float64).reshape(3, 1)
        if fisheye:
            # solvePnPRefineLM has no fisheye model: refine on the ideal pixels.
            rvec, tvec = cv2.solvePnPRefineLM(obj, ideal, K, zero, rvec, tvec, criteria)
        else:
            rvec, tvec = cv2.solvePnPRefineLM(obj, corners[order], K, camera._cv_dist(),
                                              rvec, tvec, criteria)
        pose = Pose.from_rvec(rvec.reshape(3), tvec.reshape(3))
        if not np.all(np.isfinite(pose.t)) or pose.t[2] <= 0.0:
            continue
        projected = camera.project(pose.apply(obj_detector))
        out.append((pose, float(np.sum((projected - corners) ** 2))))
    out.sort(key=lambda solution: solution[1])
    return out


def square_pose(corners_px: np.ndarray, kind: str, card_size: float,
                camera: CameraModel) -> Optional[Tuple[Pose, float]]:
    """
    Card pose and reprojection RMS (px) from the four detected corners.

    The lower-reprojection-error solution of :func:`square_pose_solutions`
    (the standard choice); None if there is no valid pose. The RMS is over
    the detector's own corners through the full camera model, comparable
    with the colour-dot locator's residual.
    """
    solutions = square_pose_solutions(corners_px, kind, card_size, camera)
    if not solutions:
        return None
    pose, cost = solutions[0]
    return pose, float(np.sqrt(cost / 4.0))


def _release_apriltag_detector(detector: object) -> None:
    """
    Free a pupil_apriltags.Detector's C objects in a safe order.

    pupil-apriltags 1.0.4 frees the tag family before the detector, whose
    destructor then writes into the freed family: heap corruption and
    segfaults when a Detector is collected (pupil-labs/apriltags PR #65,
    duckietown/lib-dt-apriltags PR #26). Destroy the detector first and
    disarm the wrapper's own ``__del__``.
    """
    ptr = getattr(detector, 'tag_detector_ptr', None)
    if ptr is None:
        return
    detector.tag_detector_ptr = None
    libc = detector.libc
    libc.apriltag_detector_destroy.restype = None
    libc.apriltag_detector_destroy(ptr)
    libc.tag36h11_destroy.restype = None
    for family in detector.tag_families.values():
        libc.tag36h11_destroy(family)
    detector.tag_families = {}


class AprilTagLocator:
    """
    AprilTag 36h11 card locator (pupil-apriltags, library defaults).

    Not thread-safe: use one locator per thread (the C detector keeps state).
    """

    kind = 'apriltag'

    def __init__(self, card_size: float = 0.3, nthreads: int = 1,
                 **detector_kwargs: float) -> None:
        # Imported here so the ArUco baseline works without pupil-apriltags.
        import pupil_apriltags

        if card_size <= 0.0:
            raise ValueError(f'card_size must be positive, got {card_size}')
        self.card_size = float(card_size)
        params: Dict[str, float] = {'quad_decimate': 2.0, 'quad_sigma': 0.0,
                                    'refine_edges': 1, 'decode_sharpening': 0.25}
        params.update(detector_kwargs)
        self.params = params
        detector = pupil_apriltags.Detector(families='tag36h11', nthreads=int(nthreads),
                                            **params)
        weakref.finalize(self, _release_apriltag_detector, detector)
        # pupil-apriltags 1.0.4 stores int(decode_sharpening), i.e. 0 for the
        # 0.25 default; set the double ourselves so the default is real.
        detector.tag_detector_ptr.contents.decode_sharpening = float(
            params['decode_sharpening'])
        self._detector = detector

    def detect(self, image_bgr: np.ndarray, camera: CameraModel) -> List[TagDetection]:
        """All tag36h11 cards in a BGR (or gray) uint8 image, with their poses."""
        gray = _gray(image_bgr)
        out = []
        for det in self._detector.detect(gray):
            # The C library puts pixel centres at (0.5, 0.5) (measured: +0.50
            # px on both axes, AprilRobotics/apriltag#121); OpenCV and our
            # camera model put them at integers.
            corners = np.asarray(det.corners, dtype=np.float64).reshape(4, 2) - 0.5
            solved = square_pose(corners, self.kind, self.card_size, camera)
            if solved is None:
                continue
            out.append(TagDetection(int(det.tag_id), corners, solved[0], solved[1]))
        return out


class ArucoLocator:
    """
    ArUco DICT_6X6_250 card locator (OpenCV, sub-pixel corner refinement).

    ``parameter_overrides`` sets further ``cv2.aruco.DetectorParameters``
    attributes by name (e.g. ``relativeCornerRefinmentWinSize=0.5``) for
    sensitivity studies; the defaults are OpenCV's plus SUBPIX refinement.
    """

    kind = 'aruco'

    def __init__(self, card_size: float = 0.3, **parameter_overrides: float) -> None:
        if card_size <= 0.0:
            raise ValueError(f'card_size must be positive, got {card_size}')
        self.card_size = float(card_size)
        params = cv2.aruco.DetectorParameters()
        params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        for name, value in parameter_overrides.items():
            if not hasattr(params, name):
                raise ValueError(f'cv2.aruco.DetectorParameters has no parameter {name!r}')
            setattr(params, name, value)
        self.params = params
        self._detector = cv2.aruco.ArucoDetector(
            cv2.aruco.getPredefinedDictionary(_DICTIONARIES['aruco']), params)

    def detect(self, image_bgr: np.ndarray, camera: CameraModel) -> List[TagDetection]:
        """All DICT_6X6_250 cards in a BGR (or gray) uint8 image, with their poses."""
        gray = _gray(image_bgr)
        corners_list, ids, _ = self._detector.detectMarkers(gray)
        out = []
        if ids is None:
            return out
        for corners, tag_id in zip(corners_list, np.asarray(ids).reshape(-1)):
            corners = np.asarray(corners, dtype=np.float64).reshape(4, 2)
            solved = square_pose(corners, self.kind, self.card_size, camera)
            if solved is None:
                continue
            out.append(TagDetection(int(tag_id), corners, solved[0], solved[1]))
        return out


def make_locator(kind: str, card_size: float = 0.3) -> Union[AprilTagLocator, ArucoLocator]:
    """Return the baseline locator of ``kind`` ('apriltag' or 'aruco')."""
    _check_kind(kind)
    return AprilTagLocator(card_size) if kind == 'apriltag' else ArucoLocator(card_size)


__all__ = ['KINDS', 'AprilTagLocator', 'ArucoLocator', 'TagDetection', 'make_locator',
           'square_pose', 'square_pose_solutions', 'tag_black_size', 'tag_card_bitmap',
           'tag_object_points']
