"""
A card drawn face-on on white paper: the image the detector reads at start.

The detector's per-pixel passes are compiled on their first call (or loaded
from numba's cache), which takes from a fraction of a second to seconds. A
node that reads a drawn image at start pays that before its first camera
frame, and learns at once whether its detector reads its own cards.
"""

from typing import Sequence, Tuple

import cv2
import numpy as np

from ..card.pattern import Code, PatternConfig

# Sub-pixel precision of the drawn circles (OpenCV's fixed-point shift).
_SHIFT = 4
PAPER_BGR = (235, 235, 235)


def draw_card(image: np.ndarray, config: PatternConfig, code: Code, centre_px: Tuple[float, float],
              px_per_m: float) -> None:
    """
    Draw the card of ``code`` face-on into a BGR ``image`` (in place), point 1 up.

    The card's paper, its dots in their printed inks and its handedness
    marks, ``px_per_m`` image pixels per metre of card, centred at
    ``centre_px`` (x, y).
    """
    cx, cy = centre_px
    half = 0.5 * config.card_size * px_per_m
    cv2.rectangle(image, (int(cx - half), int(cy - half)), (int(cx + half), int(cy + half)),
                  PAPER_BGR, -1)
    points = config.model_points()[:, :2]
    # The inks as printed (they are what a camera sees of a printed card).
    circles = [(p, r, config.ink_rgb(letter)) for p, r, letter in
               zip(points, config.dot_radii(), config.dot_colours(code))]
    black = config.ink_rgb('K')
    circles += [(p, config.mark_radius, black) for p in config.mark_points()]
    for (x, y), radius, (r, g, b) in circles:
        centre = (int(round((cx + x * px_per_m) * (1 << _SHIFT))),
                  int(round((cy - y * px_per_m) * (1 << _SHIFT))))
        cv2.circle(image, centre, int(round(radius * px_per_m * (1 << _SHIFT))), (b, g, r), -1,
                   cv2.LINE_AA, _SHIFT)


def drawn_cards(config: PatternConfig, code: Code, scales_px_per_m: Sequence[float] = (
        1000.0, 330.0), size: Tuple[int, int] = (640, 480)) -> np.ndarray:
    """
    Return a grey-background BGR image (``size`` = width, height) of the card at each scale.

    The default scales give a card whose dots are measured on the image
    decimated by two and one whose dots are measured at full resolution,
    so that every pass of the detector runs.
    """
    width, height = size
    image = np.full((height, width, 3), 128, dtype=np.uint8)
    x = 0.0
    for scale in scales_px_per_m:
        side = config.card_size * scale
        x += 0.5 * side + 20.0
        draw_card(image, config, code, (x, 0.5 * height), scale)
        x += 0.5 * side
    # A little noise, as a camera has: flat paper would give a noise of zero.
    rng = np.random.default_rng(0)
    noisy = image.astype(np.int16) + rng.integers(-2, 3, image.shape, dtype=np.int16)
    return np.clip(noisy, 0, 255).astype(np.uint8)
