"""
A window of the image zoomed and sharpened, for a far card seen through a soft lens.

At 5.5-8 m a card's ring dots are three or four pixels across. Blurred by
a soft lens (an analog camera such as the EVI-D31, a lens focused nearer)
they fade below the dots' thresholds and merge: no stage finds them at the
image's own scale. Upsampled twice and sharpened by an unsharp mask about
as wide as that blur, the window shows them as a card at half the distance
would, and the detector's every stage (and every check against a wrong
id) runs on it unchanged, with the camera that sees the window.
"""

from dataclasses import dataclass
from typing import Optional

import cv2
import numpy as np

from .camera import CameraModel

# Upsampling factor, and the unsharp mask: its Gaussian's sigma (pixels of
# the image, about a soft lens's blur) and how much of the difference it adds.
ZOOM = 2
_SHARPEN_SIGMA_PX = 1.2
_SHARPEN_AMOUNT = 1.5
# The dots' noise (image pixels) a zoomed card's pose counts at least: their
# errors against the truth on rendered soft far cards, 0.03-0.28 px, lean
# the same way for neighbours (sharpening and merged blur), which the fit's
# residuals (0.07-0.3 px) do not show; counted at the residuals, a far card
# at 35 degrees was sure of the wrong planar side (8.8 m off). At 0.15 px one
# of 15 poses sure of their side was beyond 4 sigmas, at 0.2 none of 5; at
# 0.3 none is sure (320 soft far frames): a localizer takes such a card
# where its last fix tells the side.
ZOOMED_PIXEL_SIGMA = 0.3


@dataclass(frozen=True)
class ZoomedWindow:
    """The window's zoomed, sharpened pixels, the camera that sees them and where it was."""

    image: np.ndarray
    camera: Optional[CameraModel]
    x0: int
    y0: int

    def to_image(self) -> np.ndarray:
        """Return the 3x3 map from the window's pixels to the image's."""
        return _window_to_image(self.x0, self.y0)


def _window_to_image(x0: int, y0: int) -> np.ndarray:
    """Return the 3x3 map from the pixels of a window zoomed from (x0, y0) to the image's."""
    # cv2.resize puts window pixel x' over image pixel (x' + 0.5) / ZOOM - 0.5.
    offset = (ZOOM - 1) / 2.0
    return np.array([[1.0 / ZOOM, 0.0, x0 - offset / ZOOM],
                     [0.0, 1.0 / ZOOM, y0 - offset / ZOOM],
                     [0.0, 0.0, 1.0]])


def zoom_window(image: np.ndarray, camera: Optional[CameraModel], u: float, v: float,
                half: int) -> Optional[ZoomedWindow]:
    """Zoom and sharpen the window of ``half`` pixels round (u, v); None if it is too small."""
    h, w = image.shape[:2]
    x0, y0 = max(0, int(u) - half), max(0, int(v) - half)
    x1, y1 = min(w, int(u) + half + 1), min(h, int(v) + half + 1)
    if x1 - x0 < 8 or y1 - y0 < 8:
        return None
    big = cv2.resize(np.ascontiguousarray(image[y0:y1, x0:x1]),
                     ((x1 - x0) * ZOOM, (y1 - y0) * ZOOM), interpolation=cv2.INTER_CUBIC)
    blur = cv2.GaussianBlur(big, (0, 0), _SHARPEN_SIGMA_PX * ZOOM)
    big = cv2.addWeighted(big, 1.0 + _SHARPEN_AMOUNT, blur, -_SHARPEN_AMOUNT, 0.0)
    window_camera = None
    if camera is not None:
        # The same lens (distortion acts on normalised points): K scaled and moved.
        to_window = np.linalg.inv(_window_to_image(x0, y0))
        window_camera = CameraModel(big.shape[1], big.shape[0], to_window @ camera.K,
                                    camera.D, camera.distortion_model, camera.name)
    return ZoomedWindow(big, window_camera, x0, y0)
