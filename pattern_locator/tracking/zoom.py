"""
The tracking loop's zoom: keep the card at a target size, with hysteresis (ROS-free).

Start zooming when the card's size is off ``target_size_px`` by more than
``zoom_band`` (relative), stop when back within a third of it; never zoom
in while the pointing error exceeds ``zoom_max_error_rad``; zoom out when it
exceeds twice that, and whenever no card is tracked. Stops at the ends.
"""

from typing import Optional, Sequence

from .params import TrackingParams
from ..visca.protocol import ZOOM_TELE, ZOOM_WIDE

# Zoom position units at the two ends (zoom direct / zoom inquiry).
ZOOM_WIDE_UNITS = ZOOM_WIDE
ZOOM_TELE_UNITS = ZOOM_TELE
ZOOM_WIDE_DIR, ZOOM_STOP, ZOOM_TELE_DIR = -1, 0, 1
# A zoom stops when the size is back within this fraction of the zoom band.
ZOOM_STOP_FRACTION = 1.0 / 3.0


class ZoomControl:
    """The zoom direction (-1 wide, 0 stop, +1 tele) for each update; not thread-safe."""

    def __init__(self, params: TrackingParams) -> None:
        self._params = params
        self.zooming = ZOOM_STOP

    def reset(self) -> None:
        """Stop (a new mode starts afresh)."""
        self.zooming = ZOOM_STOP

    def track(self, errors: Sequence[float], size_px: Optional[float],
              zoom_units: Optional[float]) -> int:
        """Return the direction while tracking: pointing ``errors`` (rad), the card's size."""
        p = self._params
        if not p.zoom_enabled:
            return ZOOM_STOP
        error = max(abs(e) for e in errors)
        if error > 2.0 * p.zoom_max_error_rad:
            # The card may leave the picture: widen the view.
            self.zooming = ZOOM_STOP
            return self.out(zoom_units)
        if size_px is None:
            self.zooming = ZOOM_STOP
            return ZOOM_STOP
        ratio = size_px / p.target_size_px
        stop_band = p.zoom_band * ZOOM_STOP_FRACTION
        if self.zooming == ZOOM_TELE_DIR and (ratio >= 1.0 - stop_band
                                              or error > p.zoom_max_error_rad):
            self.zooming = ZOOM_STOP
        elif self.zooming == ZOOM_WIDE_DIR and ratio <= 1.0 + stop_band:
            self.zooming = ZOOM_STOP
        if self.zooming == ZOOM_STOP:
            if ratio > 1.0 + p.zoom_band:
                self.zooming = ZOOM_WIDE_DIR
            elif ratio < 1.0 - p.zoom_band and error <= p.zoom_max_error_rad:
                self.zooming = ZOOM_TELE_DIR
        if zoom_units is not None and (
                (self.zooming == ZOOM_TELE_DIR and zoom_units >= ZOOM_TELE_UNITS)
                or (self.zooming == ZOOM_WIDE_DIR and zoom_units <= ZOOM_WIDE_UNITS)):
            return ZOOM_STOP
        return self.zooming

    def out(self, zoom_units: Optional[float]) -> int:
        """Return zoom wide until the wide end (when the zoom is controlled)."""
        if not self._params.zoom_enabled:
            return ZOOM_STOP
        if zoom_units is not None and zoom_units <= ZOOM_WIDE_UNITS:
            return ZOOM_STOP
        return ZOOM_WIDE_DIR
