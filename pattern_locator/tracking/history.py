"""
What the tracking controller remembers: the head's recent readings and the card's aims.

ROS-free, not thread-safe (the controller holds its lock). :class:`HeadHistory`
keeps the head's readings by stamp, so the head's angles when an image was
taken can be interpolated. :class:`AimTrack` keeps the aims (the joint
angles that centre the card, one per target, or, with odometry, the same
turned into the odom frame's heading) and fits the card's angular rate over
the recent ones, which the controller feeds forward. :class:`BaseTrack`
keeps the base's odometry (heading and twist), so the head can turn against
the base's turns.
"""

import bisect
from collections import deque
import math
from typing import Deque, List, Optional, Tuple

# Head readings kept for matching image stamps (the locator's latency is well below).
HISTORY_S = 2.0
# An aim this far from where the fitted rate says it should be is a new card
# (or the same one found again): the rate fit starts over.
RATE_RESET_RAD = math.radians(5.0)
# The rate fit needs this many aims spanning at least this long.
RATE_MIN_AIMS = 3
RATE_MIN_SPAN_S = 0.15


class HeadHistory:
    """The head's readings (stamp, pan, tilt) of the last :data:`HISTORY_S`, and its zoom."""

    def __init__(self) -> None:
        self.stamps: List[float] = []
        self.readings: List[Tuple[float, float]] = []
        self.zoom_units: Optional[float] = None

    def __bool__(self) -> bool:
        return bool(self.stamps)

    @property
    def newest_stamp(self) -> float:
        """Return the newest reading's stamp (there must be one)."""
        return self.stamps[-1]

    @property
    def newest(self) -> Tuple[float, float]:
        """Return the newest reading as (pan, tilt); there must be one."""
        return self.readings[-1]

    def jumped_back(self, stamp_s: float) -> bool:
        """Return True for a stamp older than anything kept: the clock jumped back."""
        return bool(self.stamps) and stamp_s < self.stamps[-1] - HISTORY_S

    def add(self, stamp_s: float, pan: float, tilt: float,
            zoom_units: Optional[float] = None) -> None:
        """Insert a reading in stamp order (the same stamp replaces); forget old ones."""
        newest = not self.stamps or stamp_s >= self.stamps[-1]
        i = bisect.bisect_left(self.stamps, stamp_s)
        if i < len(self.stamps) and self.stamps[i] == stamp_s:
            self.readings[i] = (pan, tilt)
        else:
            self.stamps.insert(i, stamp_s)
            self.readings.insert(i, (pan, tilt))
        # Keep one reading at or before the cut so old stamps stay bracketed.
        keep = bisect.bisect_right(self.stamps, self.stamps[-1] - HISTORY_S) - 1
        if keep > 0:
            del self.stamps[:keep]
            del self.readings[:keep]
        if zoom_units is not None and newest:
            self.zoom_units = float(zoom_units)

    def at(self, stamp_s: float) -> Tuple[float, float]:
        """Return the head's (pan, tilt) at a stamp: interpolated, or the nearest reading."""
        stamps, readings = self.stamps, self.readings
        i = bisect.bisect_right(stamps, stamp_s)
        if i == 0:
            return readings[0]
        if i == len(stamps):
            return readings[-1]
        t0, t1 = stamps[i - 1], stamps[i]
        w = (stamp_s - t0) / (t1 - t0)
        (p0, a0), (p1, a1) = readings[i - 1], readings[i]
        return p0 + w * (p1 - p0), a0 + w * (a1 - a0)


class AimTrack:
    """
    The recent aims (stamp, pan, tilt) and the card's (pan, tilt) rate fitted over them.

    ``window_s``: the span fitted (0: no rate); ``lost_after_s``: a gap this
    long starts the fit over; ``slowest``, ``fastest``: per axis, the rate
    is taken as 0 below half the slowest speed step and clipped to the
    fastest.
    """

    def __init__(self, window_s: float, lost_after_s: float,
                 slowest: Tuple[float, float], fastest: Tuple[float, float]) -> None:
        self.window_s = window_s
        self.lost_after_s = lost_after_s
        self.slowest = slowest
        self.fastest = fastest
        self.aims: Deque[Tuple[float, float, float]] = deque()
        self.rate = (0.0, 0.0)

    def __bool__(self) -> bool:
        return bool(self.aims)

    @property
    def newest(self) -> Tuple[float, float, float]:
        """Return the newest aim as (stamp, pan, tilt); there must be one."""
        return self.aims[-1]

    def clear(self) -> None:
        """Forget every aim and the rate (the aims' frame changed)."""
        self.aims.clear()
        self.rate = (0.0, 0.0)

    def add(self, stamp_s: float, aim: Tuple[float, float]) -> None:
        """Add an aim; a gap or a jump off the fitted line starts the fit over."""
        if self.aims:
            last_stamp, last_pan, last_tilt = self.aims[-1]
            dt = stamp_s - last_stamp
            expected = (last_pan + self.rate[0] * dt, last_tilt + self.rate[1] * dt)
            lost = dt > self.lost_after_s
            jump = max(abs(aim[0] - expected[0]), abs(aim[1] - expected[1])) > RATE_RESET_RAD
            if lost or jump:
                self.aims.clear()
                self.rate = (0.0, 0.0)
        self.aims.append((stamp_s,) + tuple(aim))
        while self.aims and self.aims[0][0] < stamp_s - self.window_s:
            self.aims.popleft()
        self.rate = self._fit()

    def _fit(self) -> Tuple[float, float]:
        """Return the (pan, tilt) rate of the recent aims: a least-squares line's slope."""
        aims = self.aims
        if (self.window_s <= 0.0 or len(aims) < RATE_MIN_AIMS
                or aims[-1][0] - aims[0][0] < RATE_MIN_SPAN_S):
            return 0.0, 0.0
        n = len(aims)
        t_mean = sum(a[0] for a in aims) / n
        rates = []
        for k in (1, 2):
            mean = sum(a[k] for a in aims) / n
            stt = sum((a[0] - t_mean) ** 2 for a in aims)
            rate = sum((a[0] - t_mean) * (a[k] - mean) for a in aims) / stt
            if abs(rate) < 0.5 * self.slowest[k - 1]:
                # Slower than the head can follow by one step: noise, or a
                # transient of the fit; feeding it forward only stirs the loop.
                rate = 0.0
            fastest = self.fastest[k - 1]
            rates.append(min(max(rate, -fastest), fastest))
        return rates[0], rates[1]


class BaseTrack:
    """
    The base's odometry of the last :data:`HISTORY_S`: heading (unwrapped) and twist by stamp.

    Only the heading and the twist in ``base_link`` are kept: the head's
    feed-forward needs how far the base turned between two instants
    (:meth:`yaw_at`, exact up to the odometry's own drift, which over a
    second is far below a degree) and how it moves now (:attr:`newest`).
    """

    def __init__(self) -> None:
        self.stamps: List[float] = []
        self.yaws: List[float] = []
        # (linear x, linear y, yaw rate) per sample.
        self.twists: List[Tuple[float, float, float]] = []

    def __bool__(self) -> bool:
        return bool(self.stamps)

    @property
    def newest_stamp(self) -> float:
        """Return the newest sample's stamp (there must be one)."""
        return self.stamps[-1]

    @property
    def newest(self) -> Tuple[float, float, float]:
        """Return the newest twist (linear x, linear y, yaw rate); there must be one."""
        return self.twists[-1]

    def jumped_back(self, stamp_s: float) -> bool:
        """Return True for a stamp older than anything kept: the clock jumped back."""
        return bool(self.stamps) and stamp_s < self.stamps[-1] - HISTORY_S

    def add(self, stamp_s: float, yaw: float, linear_x: float, linear_y: float,
            yaw_rate: float) -> bool:
        """Append a sample (stamps must increase: an older or equal one is ignored)."""
        if self.stamps and stamp_s <= self.stamps[-1]:
            return False
        if self.yaws:
            # Unwrap against the previous heading: the base never turns half a turn
            # between two odometry samples.
            yaw = self.yaws[-1] + math.remainder(yaw - self.yaws[-1], 2.0 * math.pi)
        self.stamps.append(stamp_s)
        self.yaws.append(yaw)
        self.twists.append((linear_x, linear_y, yaw_rate))
        keep = bisect.bisect_right(self.stamps, stamp_s - HISTORY_S) - 1
        if keep > 0:
            del self.stamps[:keep]
            del self.yaws[:keep]
            del self.twists[:keep]
        return True

    def yaw_at(self, stamp_s: float, max_extrapolation_s: float) -> float:
        """
        Return the heading (unwrapped, rad) at a stamp.

        Interpolated between samples; beyond the newest, carried on at its
        yaw rate for at most ``max_extrapolation_s``; before the oldest, the
        oldest.
        """
        stamps = self.stamps
        i = bisect.bisect_right(stamps, stamp_s)
        if i == 0:
            return self.yaws[0]
        if i == len(stamps):
            ahead = min(stamp_s - stamps[-1], max_extrapolation_s)
            return self.yaws[-1] + self.twists[-1][2] * ahead
        t0, t1 = stamps[i - 1], stamps[i]
        w = (stamp_s - t0) / (t1 - t0)
        return self.yaws[i - 1] + w * (self.yaws[i] - self.yaws[i - 1])
