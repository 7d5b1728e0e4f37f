"""
The debug picture: what the locator saw, drawn over the image (like the paper's Fig. 6).

Every detected dot is circled, the outer ring's fitted ellipse drawn, each
card labelled with its code and ids, and the robot's location written at
the top.
"""

from typing import Optional, Sequence

import cv2
import numpy as np

from .detector import CardDetection

_DOT = (0, 255, 255)
_ELLIPSE = (0, 200, 0)
_TEXT = (0, 0, 255)


def draw_overlay(image: np.ndarray, detections: Sequence[CardDetection],
                 location: Optional[str] = None) -> np.ndarray:
    """Return a BGR copy of ``image`` with the detections and ``location`` drawn on it."""
    canvas = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR) if image.ndim == 2 else image.copy()
    for det in detections:
        seen = det.points_px[~np.isnan(det.points_px[:, 0])]
        for u, v in seen:
            cv2.circle(canvas, (int(round(u)), int(round(v))), 4, _DOT, 1, cv2.LINE_AA)
        ring = det.points_px[1:9]
        if not np.isnan(ring).any():
            cv2.ellipse(canvas, cv2.fitEllipse(ring.astype(np.float32)), _ELLIPSE, 1,
                        cv2.LINE_AA)
        label = str(det.code) if det.code is not None else (
            f'one of {len(det.candidates)} codes (partly hidden)' if det.candidates
            else 'no code (grey image)')
        if det.ids is not None:
            label += f'  f{det.ids.floor} r{det.ids.room} p{det.ids.pattern}'
        u, v = det.centre_px
        org = (int(u - det.size_px), int(max(12, v - det.size_px - 8)))
        cv2.putText(canvas, label, org, cv2.FONT_HERSHEY_SIMPLEX, 0.45, _TEXT, 1, cv2.LINE_AA)
    cv2.putText(canvas, location or 'not located', (10, 22), cv2.FONT_HERSHEY_SIMPLEX, 0.55,
                _TEXT, 2, cv2.LINE_AA)
    return canvas
