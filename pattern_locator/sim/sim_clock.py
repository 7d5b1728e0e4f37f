"""
The sim's clock: the steady clock slowed by a real-time factor.

A simulated robot on a machine too slow to render its frames in real time
skips frames, so what the stack sees depends on the machine. Run the world
(route, odometry, the emulated camera's motion and its serial line) on a
clock that advances ``rate`` sim seconds per wall second, and every frame
gets ``1 / rate`` times the wall time: a stack on sim time (``/clock``,
``use_sim_time``) then sees the frames a computer ``1 / rate`` times faster
would give it (Gazebo's real-time factor).
"""

import math
import time
from typing import Callable


class ScaledClock:
    """
    Seconds that run at ``rate`` times the base clock's from ``origin``.

    ``clock()`` is the sim time on the base clock's scale: equal to the
    base clock at ``origin``, then slower by ``rate``. :meth:`wall_s`
    turns a stretch of sim time into the wall time to wait for it.
    """

    def __init__(self, rate: float = 1.0, base: Callable[[], float] = time.monotonic) -> None:
        if not (math.isfinite(rate) and 0.0 < rate <= 1.0):
            raise ValueError(f'real-time factor {rate} is not in (0, 1]')
        self.rate = float(rate)
        self._base = base
        self.origin = base()

    def __call__(self) -> float:
        """Return the sim time now."""
        return self.origin + (self._base() - self.origin) * self.rate

    def wall_s(self, sim_s: float) -> float:
        """Return the wall seconds in which ``sim_s`` sim seconds pass."""
        return sim_s / self.rate
