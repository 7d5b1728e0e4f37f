"""
Keep a card on the optical axis of the pan/tilt head (ROS-free core of the tracking loop).

The camera driver feeds a :class:`TrackingController` with

* the locator's targets (:meth:`TrackingController.on_target`): for the
  image taken at ``stamp_s``, the head motion that would centre the card
  *as seen in that image*, and the card's apparent size;
* the head's readings (:meth:`TrackingController.on_head_state`) from
  position inquiries, stamped when the position was read;

and calls :meth:`TrackingController.update` at its control rate, which
returns a :class:`HeadCommand`: signed pan and tilt speeds and a zoom
direction. The driver only ever sends Pan-tilt Drive (speed) commands;
there are no absolute moves, so a Drive is never refused because an
AbsolutePosition move is running.

Units are SI, angles in radians with REP 103 signs: pan positive = turn
left (counter-clockwise seen from above), tilt positive = up. Converting to
VISCA's signs (pan positive = right) is the driver's job. The speeds are
always multiples of the EVI-D31's speed steps (:data:`PAN_STEP_RAD_S`,
:data:`TILT_STEP_RAD_S`), so :attr:`HeadCommand.pan_steps` is exact.

Latency: a target describes the head's position when the image was taken,
and the head has moved since. Each target is turned into an absolute aim
direction in joint angles, ``aim = head_at(stamp_s) + error`` (the head's
angles at the image's stamp interpolated from the readings), and the loop
drives the head (its latest reading, moved on at the speed last commanded)
towards the aim. A straight-line fit over the recent aims gives the card's
angular rate, which is fed forward and carries the aim up to now, so a
card passing at a steady rate is followed without a lag.
"""

import bisect
from collections import deque
from dataclasses import dataclass
import math
import threading
from typing import Deque, List, Optional, Sequence, Tuple

from ..errors import ConfigError
from ..localization.head import EVI_D31_PAN_LIMITS_RAD, EVI_D31_TILT_LIMITS_RAD, limit_pair
from ..visca.protocol import (PAN_MAX_DEG_S, PAN_SPEED_MAX, TILT_MAX_DEG_S, TILT_SPEED_MAX,
                              ZOOM_TELE, ZOOM_WIDE)

# The EVI-D31's speed steps (visca.md): pan 1..24 of 80/24 deg/s, tilt 1..20 of 2.5 deg/s.
PAN_MAX_STEPS = PAN_SPEED_MAX
TILT_MAX_STEPS = TILT_SPEED_MAX
PAN_STEP_RAD_S = math.radians(PAN_MAX_DEG_S / PAN_SPEED_MAX)
TILT_STEP_RAD_S = math.radians(TILT_MAX_DEG_S / TILT_SPEED_MAX)

# Zoom position units at the two ends (zoom direct / zoom inquiry).
ZOOM_WIDE_UNITS = ZOOM_WIDE
ZOOM_TELE_UNITS = ZOOM_TELE

MODE_TRACK = 'track'
MODE_HOLD = 'hold'
MODE_SEARCH = 'search'
MODE_IDLE = 'idle'
MODES = (MODE_TRACK, MODE_HOLD, MODE_SEARCH, MODE_IDLE)

ZOOM_WIDE_DIR, ZOOM_STOP, ZOOM_TELE_DIR = -1, 0, 1

# Head readings kept for matching image stamps (the locator's latency is well below).
HISTORY_S = 2.0
# An aim this far from where the fitted rate says it should be is a new card
# (or the same one found again): the rate fit starts over.
RATE_RESET_RAD = math.radians(5.0)
# The rate fit needs this many aims spanning at least this long.
RATE_MIN_AIMS = 3
RATE_MIN_SPAN_S = 0.15
# A zoom stops when the size is back within this fraction of the zoom band.
ZOOM_STOP_FRACTION = 1.0 / 3.0
# A head turned further than this to a side searches back through straight ahead first.
AHEAD_BAND_RAD = math.radians(15.0)
# The search sweep turns back this far inside the pan limits.
SEARCH_MARGIN_RAD = math.radians(2.0)


def quantise_speed(speed_rad_s: float, step_rad_s: float, max_steps: int) -> int:
    """
    Return the signed number of speed steps nearest to a speed (0 = stop).

    The magnitude is clipped to ``max_steps``. For the EVI-D31 pass
    (:data:`PAN_STEP_RAD_S`, :data:`PAN_MAX_STEPS`) or (:data:`TILT_STEP_RAD_S`,
    :data:`TILT_MAX_STEPS`). The sign is kept as given (REP 103 here); VISCA
    wants the magnitude as the speed byte (1..max, also when stopping) and
    the sign as the direction byte.
    """
    if not math.isfinite(speed_rad_s):
        raise ValueError(f'speed must be finite, got {speed_rad_s!r}')
    if not (math.isfinite(step_rad_s) and step_rad_s > 0.0):
        raise ValueError(f'speed step must be > 0, got {step_rad_s!r}')
    if max_steps < 1:
        raise ValueError(f'max_steps must be >= 1, got {max_steps!r}')
    steps = min(int(math.floor(abs(speed_rad_s) / step_rad_s + 0.5)), int(max_steps))
    return steps if speed_rad_s >= 0.0 else -steps


@dataclass(frozen=True)
class HeadCommand:
    """
    What the head should do until the next update.

    ``pan_speed``, ``tilt_speed``: rad/s, REP 103 signs, always a whole
    number of the head's speed steps (0 = stop). ``zoom``: -1 wide, 0 stop,
    +1 tele. ``mode``: one of :data:`MODES`. ``pan_error``, ``tilt_error``:
    the aim minus the head's latest reading (rad) while tracking, 0
    otherwise (for logs and diagnostics).
    """

    pan_speed: float = 0.0
    tilt_speed: float = 0.0
    zoom: int = ZOOM_STOP
    mode: str = MODE_IDLE
    pan_error: float = 0.0
    tilt_error: float = 0.0

    @property
    def pan_steps(self) -> int:
        """Return the pan speed as signed VISCA steps (positive = left)."""
        return quantise_speed(self.pan_speed, PAN_STEP_RAD_S, PAN_MAX_STEPS)

    @property
    def tilt_steps(self) -> int:
        """Return the tilt speed as signed VISCA steps (positive = up)."""
        return quantise_speed(self.tilt_speed, TILT_STEP_RAD_S, TILT_MAX_STEPS)


def _positive(name: str, value, allow_zero: bool = False) -> float:
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f'tracking: {name} must be a number, got {value!r}')
    if not math.isfinite(value) or value < 0.0 or (value == 0.0 and not allow_zero):
        raise ConfigError(f'tracking: {name} must be {">=" if allow_zero else ">"} 0, '
                          f'got {value!r}')
    return value


def _step_range(axis: str, min_speed: float, max_speed: float, step: float,
                max_steps: int) -> Tuple[int, int]:
    """Return the (lowest, highest) step counts the speed limits allow on one axis."""
    # The tolerance lets a limit given in deg/s land on its step.
    lo = max(1, math.ceil(min_speed / step - 1e-6))
    hi = min(max_steps, math.floor(max_speed / step + 1e-6))
    if hi < 1:
        raise ConfigError(f'tracking: max_{axis}_speed {max_speed!r} rad/s is below the '
                          f'slowest step ({step:.4f} rad/s)')
    if lo > hi:
        raise ConfigError(f'tracking: min_{axis}_speed {min_speed!r} rad/s is above '
                          f'max_{axis}_speed {max_speed!r} rad/s (in whole steps of '
                          f'{step:.4f} rad/s)')
    return lo, hi


@dataclass(frozen=True)
class TrackingParams:
    """
    Settings of the tracking loop (SI units, radians; validated on creation).

    * ``gain`` (1/s): speed = card rate + gain * error.
    * ``dead_band_rad``: an axis whose error falls inside it stops
      correcting, and starts again only when the error leaves
      ``resume_band_rad`` (hysteresis).
    * ``min_*_speed``, ``max_*_speed`` (rad/s): the head moves only in
      whole speed steps (:data:`PAN_STEP_RAD_S`, :data:`TILT_STEP_RAD_S`);
      these bound the steps used (the minimum rounded up to a step, the
      maximum down). The defaults are the EVI-D31's slowest and fastest.
    * ``control_period_s``: the driver's update period; a correction never
      crosses the remaining error within one period.
    * ``pan_limits_rad``, ``tilt_limits_rad``: travel; the aim is clamped
      to them and the head is never driven further out.
    * ``target_timeout_s``: no target image newer than this (by its stamp)
      -> the head stops ('hold'); ``search_after_s`` -> a search sweep at
      ``search_pan_speed`` across the pan travel, one pass at each of
      ``search_tilt_levels_rad`` in turn (if ``search_enabled``). With
      ``search_ahead_first`` a head turned more than ``AHEAD_BAND_RAD`` to a
      side sweeps back through straight ahead first: after the robot moved
      on, the next card is likelier ahead of it than where the last one was.
    * ``head_timeout_s``: no head reading newer than this -> 'idle', stop.
    * ``rate_window_s``: the span of recent aims fitted for the card's
      angular rate (0 = no rate feed-forward). Rates under half the slowest
      step are taken as 0.
    * Zoom (if ``zoom_enabled``): start zooming when the card's size is
      off ``target_size_px`` by more than ``zoom_band`` (relative), stop
      when back within a third of it; never zoom in while the error
      exceeds ``zoom_max_error_rad``; zoom out when it exceeds twice that,
      and whenever no card is tracked.
    """

    gain: float = 3.0
    dead_band_rad: float = math.radians(0.3)
    resume_band_rad: float = math.radians(0.6)
    max_pan_speed: float = math.radians(80.0)
    max_tilt_speed: float = math.radians(50.0)
    min_pan_speed: float = PAN_STEP_RAD_S
    min_tilt_speed: float = TILT_STEP_RAD_S
    control_period_s: float = 1.0 / 15.0
    pan_limits_rad: Tuple[float, float] = EVI_D31_PAN_LIMITS_RAD
    tilt_limits_rad: Tuple[float, float] = EVI_D31_TILT_LIMITS_RAD
    target_timeout_s: float = 0.5
    head_timeout_s: float = 0.5
    rate_window_s: float = 0.5
    search_enabled: bool = True
    search_ahead_first: bool = True
    search_after_s: float = 3.0
    search_pan_speed: float = math.radians(20.0)
    search_tilt_levels_rad: Tuple[float, ...] = (0.0, math.radians(15.0))
    zoom_enabled: bool = False
    target_size_px: float = 120.0
    zoom_band: float = 0.15
    zoom_max_error_rad: float = math.radians(3.0)

    def __post_init__(self):
        def put(name, value):
            object.__setattr__(self, name, value)

        for name in ('gain', 'max_pan_speed', 'max_tilt_speed', 'min_pan_speed',
                     'min_tilt_speed', 'control_period_s', 'target_timeout_s',
                     'head_timeout_s', 'search_after_s', 'search_pan_speed',
                     'target_size_px', 'zoom_max_error_rad'):
            put(name, _positive(name, getattr(self, name)))
        for name in ('dead_band_rad', 'resume_band_rad', 'rate_window_s'):
            put(name, _positive(name, getattr(self, name), allow_zero=True))
        for name in ('search_enabled', 'search_ahead_first', 'zoom_enabled'):
            if not isinstance(getattr(self, name), bool):
                raise ConfigError(f'tracking: {name} must be true or false, got '
                                  f'{getattr(self, name)!r}')
        if self.resume_band_rad < self.dead_band_rad:
            raise ConfigError(f'tracking: resume_band_rad ({self.resume_band_rad!r}) must be '
                              f'>= dead_band_rad ({self.dead_band_rad!r})')
        if self.control_period_s > 1.0:
            raise ConfigError(f'tracking: control_period_s must be <= 1 s, got '
                              f'{self.control_period_s!r}')
        if self.search_after_s < self.target_timeout_s:
            raise ConfigError(f'tracking: search_after_s ({self.search_after_s!r}) must be >= '
                              f'target_timeout_s ({self.target_timeout_s!r})')
        if not 0.0 < self.zoom_band < 1.0:
            raise ConfigError(f'tracking: zoom_band must be between 0 and 1 (relative), got '
                              f'{self.zoom_band!r}')
        put('pan_limits_rad', limit_pair(self.pan_limits_rad, 'pan_limits_rad', 'tracking'))
        put('tilt_limits_rad', limit_pair(self.tilt_limits_rad, 'tilt_limits_rad', 'tracking'))
        _step_range('pan', self.min_pan_speed, self.max_pan_speed, PAN_STEP_RAD_S,
                    PAN_MAX_STEPS)
        _step_range('tilt', self.min_tilt_speed, self.max_tilt_speed, TILT_STEP_RAD_S,
                    TILT_MAX_STEPS)
        if not self.min_pan_speed <= self.search_pan_speed <= self.max_pan_speed:
            raise ConfigError(f'tracking: search_pan_speed {self.search_pan_speed!r} must be '
                              f'between min_pan_speed and max_pan_speed')
        try:
            levels = tuple(float(v) for v in self.search_tilt_levels_rad)
        except (TypeError, ValueError):
            raise ConfigError(f'tracking: search_tilt_levels_rad must be a list of angles, got '
                              f'{self.search_tilt_levels_rad!r}')
        lo, hi = self.tilt_limits_rad
        if not levels or not all(math.isfinite(v) and lo <= v <= hi for v in levels):
            raise ConfigError(f'tracking: search_tilt_levels_rad must be one or more angles '
                              f'within tilt_limits_rad, got {self.search_tilt_levels_rad!r}')
        put('search_tilt_levels_rad', levels)


class _Axis:
    """One joint's speed levels, limits and dead-band state."""

    def __init__(self, step: float, min_speed: float, max_speed: float, max_steps: int,
                 limits: Tuple[float, float]):
        lo, hi = _step_range('', min_speed, max_speed, step, max_steps)
        magnitudes = [k * step for k in range(lo, hi + 1)]
        self.levels: List[float] = sorted([-m for m in magnitudes] + [0.0] + magnitudes)
        self.slowest, self.fastest = magnitudes[0], magnitudes[-1]
        self.limits = limits
        self.settled = False

    def nearest(self, speed: float, levels: Optional[Sequence[float]] = None) -> float:
        """Return the allowed speed nearest to ``speed``."""
        return min(self.levels if levels is None else levels, key=lambda v: abs(v - speed))

    def within_travel(self, position: float, speed: float) -> float:
        """Return ``speed``, or 0 when it would drive further past a travel limit."""
        lo, hi = self.limits
        if (speed > 0.0 and position >= hi) or (speed < 0.0 and position <= lo):
            return 0.0
        return speed


class TrackingController:
    """
    Pan/tilt (and zoom) speeds that keep the card centred, from targets and head readings.

    Modes, by the age of the newest target image at ``update(now_s)``:
    'track' (younger than ``target_timeout_s``), 'hold' (head stopped, up to
    ``search_after_s``), 'search' (a sweep until a target arrives) and 'idle'
    (no head reading newer than ``head_timeout_s``: nothing is moved).
    Without any target yet, the search starts ``search_after_s`` after the
    first update. All stamps are seconds on one clock (the images'). A head
    reading more than the history (2 s) older than the newest one means the
    clock jumped back (a replayed bag, a restarted simulation): everything
    is forgotten. Thread-safe: the callbacks and :meth:`update` may run on
    different threads.

    Per axis and per update, while tracking:

    * error = aim (carried to now by the fitted rate, clamped to the travel)
      minus the head's angle now (the latest reading, moved on at the speed
      last commanded: the controller assumes its commands are executed);
      speed = rate + gain * error, rounded to the nearest speed step;
    * dead band: once the error is inside ``dead_band_rad`` the axis only
      follows the card's rate (a still card: it stops), until the error
      leaves ``resume_band_rad``;
    * outside the dead band the speed must close the error (at least the
      slowest step), but not cross it within one ``control_period_s``: the
      fastest step that does not is used. When even the slowest step would
      cross it, the axis pulses at that step for one period if that leaves
      at most half the error on the other side, else it settles (stops
      correcting) as inside the dead band.
    """

    def __init__(self, params: Optional[TrackingParams] = None):
        self._params = params if params is not None else TrackingParams()
        p = self._params
        self._pan = _Axis(PAN_STEP_RAD_S, p.min_pan_speed, p.max_pan_speed, PAN_MAX_STEPS,
                          p.pan_limits_rad)
        self._tilt = _Axis(TILT_STEP_RAD_S, p.min_tilt_speed, p.max_tilt_speed,
                           TILT_MAX_STEPS, p.tilt_limits_rad)
        self._lock = threading.Lock()
        self._reset()

    @property
    def params(self) -> TrackingParams:
        """Return the settings."""
        return self._params

    def reset(self) -> None:
        """Forget targets, readings and modes (e.g. after the driver reconnected)."""
        with self._lock:
            self._reset()

    def _reset(self) -> None:
        self._stamps: List[float] = []
        self._readings: List[Tuple[float, float]] = []
        self._zoom_units: Optional[float] = None
        # The speeds last commanded (assumed to be running).
        self._speeds = (0.0, 0.0)
        # Aims (stamp, pan, tilt) of recent targets, oldest first.
        self._aims: Deque[Tuple[float, float, float]] = deque()
        self._rate = (0.0, 0.0)
        self._last_target_s: Optional[float] = None
        self._size_px: Optional[float] = None
        self._start_s: Optional[float] = None
        self._mode = MODE_IDLE
        self._zooming = ZOOM_STOP
        self._search_dir = 1.0
        self._search_level = 0
        self._pan.settled = self._tilt.settled = False

    # Inputs -----------------------------------------------------------------

    def on_head_state(self, stamp_s: float, pan: float, tilt: float,
                      zoom_units: Optional[float] = None) -> bool:
        """
        Add a head reading: joint angles (rad, REP 103) and optionally the zoom position.

        ``stamp_s``: when the position was read (as close to the camera's
        sampling as the driver can tell). Returns False (and ignores it)
        when a value is not finite.
        """
        values = (stamp_s, pan, tilt) + (() if zoom_units is None else (zoom_units,))
        if not all(math.isfinite(float(v)) for v in values):
            return False
        stamp_s, pan, tilt = float(stamp_s), float(pan), float(tilt)
        with self._lock:
            if self._stamps and stamp_s < self._stamps[-1] - HISTORY_S:
                self._reset()
            newest = not self._stamps or stamp_s >= self._stamps[-1]
            i = bisect.bisect_left(self._stamps, stamp_s)
            if i < len(self._stamps) and self._stamps[i] == stamp_s:
                self._readings[i] = (pan, tilt)
            else:
                self._stamps.insert(i, stamp_s)
                self._readings.insert(i, (pan, tilt))
            # Keep one reading at or before the cut so old stamps stay bracketed.
            keep = bisect.bisect_right(self._stamps, self._stamps[-1] - HISTORY_S) - 1
            if keep > 0:
                del self._stamps[:keep]
                del self._readings[:keep]
            if zoom_units is not None and newest:
                self._zoom_units = float(zoom_units)
        return True

    def on_target(self, stamp_s: float, pan_error: float, tilt_error: float,
                  size_px: Optional[float] = None) -> bool:
        """
        Add the locator's measurement for the image taken at ``stamp_s``.

        ``pan_error``, ``tilt_error``: the head motion (rad, REP 103) that
        would centre the card as seen in that image. ``size_px``: the card's
        apparent size (the outer ring's long semi-axis, px), used by the zoom.
        Returns False (and ignores it) when there is no head reading yet, a
        value is not finite, or a newer target was already taken.
        """
        values = (stamp_s, pan_error, tilt_error) + (() if size_px is None else (size_px,))
        if not all(math.isfinite(float(v)) for v in values):
            return False
        stamp_s = float(stamp_s)
        with self._lock:
            if not self._stamps:
                return False
            if stamp_s < self._stamps[-1] - HISTORY_S:
                # Older than any head reading we could still have: a clock jump.
                return False
            if self._aims and stamp_s <= self._aims[-1][0]:
                return False
            head_pan, head_tilt = self._head_at(stamp_s)
            aim = (self._clamp(head_pan + float(pan_error), self._pan.limits),
                   self._clamp(head_tilt + float(tilt_error), self._tilt.limits))
            self._add_aim(stamp_s, aim)
            self._last_target_s = stamp_s
            if size_px is not None:
                self._size_px = float(size_px)
        return True

    def _head_at(self, stamp_s: float) -> Tuple[float, float]:
        """Return the head's (pan, tilt) at a stamp: interpolated, or the nearest reading."""
        stamps, readings = self._stamps, self._readings
        i = bisect.bisect_right(stamps, stamp_s)
        if i == 0:
            return readings[0]
        if i == len(stamps):
            return readings[-1]
        t0, t1 = stamps[i - 1], stamps[i]
        w = (stamp_s - t0) / (t1 - t0)
        (p0, a0), (p1, a1) = readings[i - 1], readings[i]
        return p0 + w * (p1 - p0), a0 + w * (a1 - a0)

    def _add_aim(self, stamp_s: float, aim: Tuple[float, float]) -> None:
        if self._aims:
            last_stamp, last_pan, last_tilt = self._aims[-1]
            dt = stamp_s - last_stamp
            expected = (last_pan + self._rate[0] * dt, last_tilt + self._rate[1] * dt)
            lost = dt > self._params.target_timeout_s
            jump = max(abs(aim[0] - expected[0]), abs(aim[1] - expected[1])) > RATE_RESET_RAD
            if lost or jump:
                self._aims.clear()
                self._rate = (0.0, 0.0)
        self._aims.append((stamp_s,) + aim)
        window = self._params.rate_window_s
        while self._aims and self._aims[0][0] < stamp_s - window:
            self._aims.popleft()
        self._rate = self._fit_rate()

    def _fit_rate(self) -> Tuple[float, float]:
        """Return the (pan, tilt) rate of the recent aims: a least-squares line's slope."""
        aims = self._aims
        if (self._params.rate_window_s <= 0.0 or len(aims) < RATE_MIN_AIMS
                or aims[-1][0] - aims[0][0] < RATE_MIN_SPAN_S):
            return 0.0, 0.0
        n = len(aims)
        t_mean = sum(a[0] for a in aims) / n
        rates = []
        for k, axis in ((1, self._pan), (2, self._tilt)):
            mean = sum(a[k] for a in aims) / n
            stt = sum((a[0] - t_mean) ** 2 for a in aims)
            rate = sum((a[0] - t_mean) * (a[k] - mean) for a in aims) / stt
            if abs(rate) < 0.5 * axis.slowest:
                # Slower than the head can follow by one step: noise, or a
                # transient of the fit; feeding it forward only stirs the loop.
                rate = 0.0
            rates.append(min(max(rate, -axis.fastest), axis.fastest))
        return rates[0], rates[1]

    @staticmethod
    def _clamp(value: float, limits: Tuple[float, float]) -> float:
        return min(max(value, limits[0]), limits[1])

    # Control ----------------------------------------------------------------

    def update(self, now_s: float) -> HeadCommand:
        """Return the command for the next control period, at time ``now_s``."""
        now_s = float(now_s)
        with self._lock:
            if self._start_s is None or now_s < self._start_s:
                self._start_s = now_s
            mode = self._mode_at(now_s)
            if mode != self._mode:
                # Entering a mode: each axis and the zoom start afresh.
                self._pan.settled = self._tilt.settled = False
                self._zooming = ZOOM_STOP
                if mode == MODE_SEARCH:
                    self._start_search()
                self._mode = mode
            if mode == MODE_TRACK:
                command = self._track(now_s)
            elif mode == MODE_SEARCH:
                command = self._search(now_s)
            elif mode == MODE_HOLD:
                command = HeadCommand(zoom=self._zoom_out(), mode=MODE_HOLD)
            else:
                command = HeadCommand(mode=MODE_IDLE)
            self._speeds = (command.pan_speed, command.tilt_speed)
            return command

    def _mode_at(self, now_s: float) -> str:
        p = self._params
        if not self._stamps or now_s - self._stamps[-1] > p.head_timeout_s:
            return MODE_IDLE
        last = self._last_target_s if self._last_target_s is not None else self._start_s
        since = now_s - last
        if self._last_target_s is not None and since <= p.target_timeout_s:
            return MODE_TRACK
        if p.search_enabled and since >= p.search_after_s:
            return MODE_SEARCH
        return MODE_HOLD

    def _head_now(self, now_s: float) -> Tuple[float, float]:
        """Return the head's angles now: the latest reading moved on at the commanded speeds."""
        # Without this the head lags its reading by up to a reading period
        # plus the reply's delay, and the loop settles that far ahead of a
        # moving card.
        age = min(max(now_s - self._stamps[-1], 0.0), self._params.head_timeout_s)
        (pan, tilt), (v_pan, v_tilt) = self._readings[-1], self._speeds
        return (self._clamp(pan + v_pan * age, self._pan.limits),
                self._clamp(tilt + v_tilt * age, self._tilt.limits))

    def _track(self, now_s: float) -> HeadCommand:
        stamp, aim_pan, aim_tilt = self._aims[-1]
        pan, tilt = self._head_now(now_s)
        speeds, errors = [], []
        for axis, aim, rate, position in ((self._pan, aim_pan, self._rate[0], pan),
                                          (self._tilt, aim_tilt, self._rate[1], tilt)):
            carried = aim + rate * (now_s - stamp)
            aim_now = self._clamp(carried, axis.limits)
            if aim_now != carried:
                # The card is beyond the travel: wait at the limit, do not chase it.
                rate = 0.0
            error = aim_now - position
            speeds.append(axis.within_travel(position, self._axis_speed(axis, error, rate)))
            errors.append(error)
        return HeadCommand(speeds[0], speeds[1], self._track_zoom(errors), MODE_TRACK,
                           errors[0], errors[1])

    def _axis_speed(self, axis: _Axis, error: float, rate: float) -> float:
        """Return one axis's speed level for an error (rad) and the card's rate (rad/s)."""
        p = self._params
        size = abs(error)
        if axis.settled and size > p.resume_band_rad:
            axis.settled = False
        elif not axis.settled and size < p.dead_band_rad:
            axis.settled = True
        if axis.settled:
            return axis.nearest(rate)
        sign = 1.0 if error > 0.0 else -1.0
        # closing: how fast each level shrinks the error (the card moves at rate).
        closing = [(v, (v - rate) * sign) for v in axis.levels]
        fits = [v for v, c in closing if c > 0.0 and c * p.control_period_s <= size]
        if fits:
            return axis.nearest(rate + p.gain * error, fits)
        slowest = min(((c, v) for v, c in closing if c > 0.0), default=None)
        if slowest is not None and slowest[0] * p.control_period_s <= 1.5 * size:
            return slowest[1]
        axis.settled = True
        return axis.nearest(rate)

    def _track_zoom(self, errors: Sequence[float]) -> int:
        p = self._params
        if not p.zoom_enabled:
            return ZOOM_STOP
        error = max(abs(e) for e in errors)
        if error > 2.0 * p.zoom_max_error_rad:
            # The card may leave the picture: widen the view.
            self._zooming = ZOOM_STOP
            return self._zoom_out()
        if self._size_px is None:
            self._zooming = ZOOM_STOP
            return ZOOM_STOP
        ratio = self._size_px / p.target_size_px
        stop_band = p.zoom_band * ZOOM_STOP_FRACTION
        if self._zooming == ZOOM_TELE_DIR and (ratio >= 1.0 - stop_band
                                               or error > p.zoom_max_error_rad):
            self._zooming = ZOOM_STOP
        elif self._zooming == ZOOM_WIDE_DIR and ratio <= 1.0 + stop_band:
            self._zooming = ZOOM_STOP
        if self._zooming == ZOOM_STOP:
            if ratio > 1.0 + p.zoom_band:
                self._zooming = ZOOM_WIDE_DIR
            elif ratio < 1.0 - p.zoom_band and error <= p.zoom_max_error_rad:
                self._zooming = ZOOM_TELE_DIR
        units = self._zoom_units
        if units is not None and ((self._zooming == ZOOM_TELE_DIR and units >= ZOOM_TELE_UNITS)
                                  or (self._zooming == ZOOM_WIDE_DIR
                                      and units <= ZOOM_WIDE_UNITS)):
            return ZOOM_STOP
        return self._zooming

    def _zoom_out(self) -> int:
        """Return zoom wide until the wide end (when the zoom is controlled)."""
        if not self._params.zoom_enabled:
            return ZOOM_STOP
        if self._zoom_units is not None and self._zoom_units <= ZOOM_WIDE_UNITS:
            return ZOOM_STOP
        return ZOOM_WIDE_DIR

    def _start_search(self) -> None:
        """Sweep first back through straight ahead, else where the card was last seen."""
        towards = 1.0
        pan = self._readings[-1][0] if self._readings else 0.0
        if self._params.search_ahead_first and abs(pan) > AHEAD_BAND_RAD:
            towards = -pan
        elif self._aims:
            # Where it was going if it was moving, else where it was.
            towards = self._rate[0] or (self._aims[-1][1] - self._readings[-1][0])
        self._search_dir = -1.0 if towards < 0.0 else 1.0
        self._search_level = 0

    def _search(self, now_s: float) -> HeadCommand:
        p = self._params
        pan, tilt = self._head_now(now_s)
        lo, hi = p.pan_limits_rad
        margin = min(SEARCH_MARGIN_RAD, 0.25 * (hi - lo))
        lo, hi = lo + margin, hi - margin
        if (self._search_dir > 0.0 and pan >= hi) or (self._search_dir < 0.0 and pan <= lo):
            # One pass done: come back at the next tilt level.
            self._search_dir = -self._search_dir
            self._search_level = (self._search_level + 1) % len(p.search_tilt_levels_rad)
        pan_speed = self._pan.within_travel(
            pan, self._pan.nearest(self._search_dir * p.search_pan_speed))
        level = p.search_tilt_levels_rad[self._search_level]
        tilt_speed = self._tilt.within_travel(tilt, self._axis_speed(self._tilt, level - tilt,
                                                                     0.0))
        return HeadCommand(pan_speed, tilt_speed, self._zoom_out(), MODE_SEARCH)
