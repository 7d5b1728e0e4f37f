"""
The tracking loop's search sweep: pan across the travel, one pass per tilt level (ROS-free).

A sweep starts back through straight ahead when the head is turned aside
(``search_ahead_first``: after the robot moved on, the next card is likelier
ahead of it than where the last one was), else towards where the card was
going or was. At each end of the pan travel (less a margin) it turns and
moves on to the next of ``search_tilt_levels_rad``. The pan waits while the
tilt is more than ``SEARCH_TILT_BAND_RAD`` from its level: a pass started
while the tilt still climbs sweeps past a card above the old level unseen
(the view leaves a card 6 deg aside in 0.6 s at 30 deg/s), and the next
pass that could show it is a whole travel away.
"""

import math
from typing import Optional, Tuple

from .params import TrackingParams

# A head turned further than this to a side searches back through straight ahead first.
AHEAD_BAND_RAD = math.radians(15.0)
# The search sweep turns back this far inside the pan limits.
SEARCH_MARGIN_RAD = math.radians(2.0)
# The pan waits while the tilt is further than this from its level (a tenth
# of the EVI-D31's widest vertical view).
SEARCH_TILT_BAND_RAD = math.radians(3.5)


class SearchSweep:
    """The sweep's direction and tilt level; not thread-safe."""

    def __init__(self, params: TrackingParams) -> None:
        self._params = params
        self.direction = 1.0
        self.level = 0

    def start(self, head_pan: Optional[float], card_pan: Optional[float],
              card_rate: float) -> None:
        """
        Start a sweep from the head at ``head_pan`` (None: no reading).

        ``card_pan``: where the last card was (None: none seen); ``card_rate``:
        its fitted pan rate (rad/s), which wins when it is not zero.
        """
        towards = 1.0
        pan = head_pan if head_pan is not None else 0.0
        if self._params.search_ahead_first and abs(pan) > AHEAD_BAND_RAD:
            towards = -pan
        elif card_pan is not None:
            # Where it was going if it was moving, else where it was.
            towards = card_rate or (card_pan - pan)
        self.direction = -1.0 if towards < 0.0 else 1.0
        self.level = 0

    def step(self, pan: float) -> Tuple[float, float]:
        """Return (the pan speed wanted, the tilt level to hold) for the head at ``pan``."""
        p = self._params
        lo, hi = p.pan_limits_rad
        margin = min(SEARCH_MARGIN_RAD, 0.25 * (hi - lo))
        lo, hi = lo + margin, hi - margin
        if (self.direction > 0.0 and pan >= hi) or (self.direction < 0.0 and pan <= lo):
            # One pass done: come back at the next tilt level.
            self.direction = -self.direction
            self.level = (self.level + 1) % len(p.search_tilt_levels_rad)
        return self.direction * p.search_pan_speed, p.search_tilt_levels_rad[self.level]
