"""
Keep a card on the optical axis of the pan/tilt head (ROS-free core of the tracking loop).

The camera driver feeds a :class:`TrackingController` with

* the locator's targets (:meth:`TrackingController.on_target_point`, or
  :meth:`TrackingController.on_target`): for the image taken at
  ``stamp_s``, the card's centre in that image's optical frame (or the
  head motion that would centre the card *as seen in that image*), and
  the card's apparent size;
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
direction in joint angles: the angles that centre the point from the head
at ``stamp_s`` (:func:`joint_aim_to_point`; near the axis, ``aim =
head_at(stamp_s) + error``), the head's angles at the image's stamp
interpolated from the readings; and the loop
drives the head (its latest reading, moved on at the speed last commanded)
towards the aim. A straight-line fit over the recent aims gives the card's
angular rate, which is fed forward and carries the aim up to now, so a
card passing at a steady rate is followed without a lag.

The base's odometry (:meth:`TrackingController.on_odometry`, with
``odometry_feed_forward``): while the base turns, a card still in the world
sweeps across the joint angles at minus the base's yaw rate, and the fit
over aims in joint angles would learn that rate only after a window and
keep it after the turn ended. With odometry the aims are kept in the odom
frame's heading (``aim pan + base yaw at the image's stamp``); an aim is
carried to now by the base's turn since its image (exact, from the
odometry) and the head's rate is ``- yaw rate`` plus the card's apparent
motion from the base's translation: for a card at bearing ``b`` (the pan
aim), elevation ``e`` (the tilt aim plus the mount's pitch) and distance
``d`` (the target's), a base moving at ``(vx, vy)`` in ``base_link`` sees it
turn at ``(sin b vx - cos b vy) / (d cos e)`` in pan and ``sin e (cos b vx +
sin b vy) / d`` in tilt. Without a distance the odom-frame aims' fitted rate
stands in for the translation. In 'hold' the head keeps only this
feed-forward (it turns against the base instead of stopping).

Where to look: :mod:`~pattern_locator.tracking.params` (settings, speed
steps), :mod:`~pattern_locator.tracking.history` (readings, aims, the
rate fit, the base's odometry), :mod:`~pattern_locator.tracking.zoom`,
:mod:`~pattern_locator.tracking.search`; this module holds the modes, the
feed-forward (:meth:`TrackingController._feed_forward`) and the per-axis
speed choice. Other sources of an aim (a gaze target from the map) would
go through :class:`~pattern_locator.tracking.history.AimTrack`.
"""

from dataclasses import dataclass
import functools
import math
import threading
from typing import List, Optional, Sequence, Tuple

import numpy as np

from .history import AimTrack, BaseTrack, HeadHistory, HISTORY_S
from .params import (PAN_MAX_STEPS, PAN_STEP_RAD_S, quantise_speed, step_range, TILT_MAX_STEPS,
                     TILT_STEP_RAD_S, TrackingParams)
from .search import SEARCH_TILT_BAND_RAD, SearchSweep
from .zoom import ZOOM_STOP, ZOOM_TELE_UNITS, ZOOM_WIDE_UNITS, ZoomControl
from ..localization.head import HeadGeometry

__all__ = ['HeadCommand', 'joint_aim_to_point', 'MODE_HOLD', 'MODE_IDLE', 'MODE_SEARCH',
           'MODE_TRACK', 'MODES', 'pan_aim_in_travel', 'PAN_MAX_STEPS', 'PAN_STEP_RAD_S',
           'quantise_speed', 'TILT_MAX_STEPS', 'TILT_STEP_RAD_S', 'TrackingController',
           'TrackingParams', 'wanted_rate', 'ZOOM_TELE_UNITS', 'ZOOM_WIDE_UNITS']

MODE_TRACK = 'track'
MODE_HOLD = 'hold'
MODE_SEARCH = 'search'
MODE_IDLE = 'idle'
MODES = (MODE_TRACK, MODE_HOLD, MODE_SEARCH, MODE_IDLE)


def pan_aim_in_travel(aim: float, limits: Tuple[float, float]) -> float:
    """
    Return the pan aim (rad), a whole turn either way, that the travel reaches or comes nearest.

    A target's turn is measured within +-180 deg of the head's pan, so a card
    just past 180 deg to one side reads as just under 180 to the other: a
    head at +80 deg with a card at -98 deg (travel +-100) must go right, not
    left to its limit.
    """
    lo, hi = limits
    return min((aim, aim - 2.0 * math.pi, aim + 2.0 * math.pi),
               key=lambda a: max(lo - a, a - hi, 0.0))


def joint_aim_to_point(pan: float, tilt: float, mount_pitch: float,
                       point: Sequence[float]) -> Tuple[float, float]:
    """
    Return the head's (pan, tilt) (rad, REP 103) that put a point on the optical axis.

    ``point``: in ``camera_optical_frame`` (x right, y down, z forward) of a
    head at ``pan``, ``tilt``, its camera pitched up by ``mount_pitch`` on
    the tilt link; any direction, also behind the image plane. Adding the
    point's angles in the image to the joint angles is right only near the
    axis: a card 100 deg round, seen from a camera pitched up 20 deg, would
    put the tilt 40 deg off. The head's own kinematics
    (:class:`~pattern_locator.localization.head.HeadGeometry`) without the
    optical centre's few centimetres off the axes (a card is metres away;
    its next image corrects them). Raises ValueError for a point on the pan
    axis (straight above or below the head).
    """
    head = _axes_only(float(mount_pitch))
    in_base = head.T_base_camera(pan, tilt).apply(np.asarray(point, dtype=float).reshape(1, 3))
    return head.aim_angles(in_base[0])


@functools.lru_cache(maxsize=8)
def _axes_only(mount_pitch: float) -> HeadGeometry:
    """Return a head with the pan, tilt and optical axes through one point."""
    return HeadGeometry(base_to_pan_xyz=(0.0, 0.0, 0.0), pan_to_tilt_xyz=(0.0, 0.0, 0.0),
                        tilt_to_optical_xyz=(0.0, 0.0, 0.0), mount_pitch_rad=mount_pitch)


def wanted_rate(error: float, rate: float, params: TrackingParams) -> float:
    """
    Return the speed (rad/s) an axis wants for an error (rad) and its card's rate (rad/s).

    Within ``params.slew_band_rad``: the card's rate plus the gain times the
    error. Beyond it (a handover's slew, blind anyway), the gain's
    exponential tail would add tenths of a second of smeared images: as fast as
    can be held for a control period and still be braked at
    ``params.slew_decel_rad_s2`` before the band.
    """
    p = params
    size = abs(error)
    if p.slew_band_rad <= 0.0 or size <= p.slew_band_rad:
        return rate + p.gain * error
    # The speed held for a control period and then braked at the
    # deceleration covers exactly the distance to the band:
    # v T + v^2 / (2 a) = beyond.
    a, period = p.slew_decel_rad_s2, p.control_period_s
    fast = a * (math.sqrt(period * period + 2.0 * (size - p.slew_band_rad) / a) - period)
    return rate + math.copysign(max(p.gain * size, fast), error)


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


class _Axis:
    """One joint's speed levels, limits and dead-band state."""

    def __init__(self, step: float, min_speed: float, max_speed: float, max_steps: int,
                 limits: Tuple[float, float]):
        lo, hi = step_range('', min_speed, max_speed, step, max_steps)
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
    first update at which a locator is present (``update``'s
    ``locator_present``): before one runs nothing can see the card the
    sweep would show, and the head is left where it is. All stamps are
    seconds on one clock (the images'). A head reading more than the
    history (2 s) older than the newest one means the
    clock jumped back (a replayed bag, a restarted simulation): everything
    is forgotten. Thread-safe: the callbacks and :meth:`update` may run on
    different threads.

    Per axis and per update, while tracking:

    * error = aim (carried to now by the fitted rate, clamped to the travel)
      minus the head's angle now (the latest reading, moved on at the speed
      last commanded: the controller assumes its commands are executed);
      speed = rate + gain * error, rounded to the nearest speed step;
      beyond ``slew_band_rad`` (a slew) faster: :func:`wanted_rate`;
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
    def has_target(self) -> bool:
        """Return whether a target was ever taken (since the last reset)."""
        return self._last_target_s is not None

    @property
    def params(self) -> TrackingParams:
        """Return the settings."""
        return self._params

    def reset(self) -> None:
        """Forget targets, readings and modes (e.g. after the driver reconnected)."""
        with self._lock:
            self._reset()

    def _reset(self) -> None:
        p = self._params
        self._head = HeadHistory()
        # The speeds last commanded (assumed to be running).
        self._speeds = (0.0, 0.0)
        self._aims = AimTrack(p.rate_window_s, p.target_timeout_s,
                              (self._pan.slowest, self._tilt.slowest),
                              (self._pan.fastest, self._tilt.fastest))
        self._last_target_s: Optional[float] = None
        self._size_px: Optional[float] = None
        self._base = BaseTrack()
        # Whether the aims are in the odom frame's heading (else in joint angles).
        self._aims_in_odom = False
        # The newest target's distance (m), None when not given.
        self._distance_m: Optional[float] = None
        self._start_s: Optional[float] = None
        self._mode = MODE_IDLE
        self._zoom = ZoomControl(p)
        self._sweep = SearchSweep(p)
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
        with self._lock:
            if self._head.jumped_back(float(stamp_s)):
                self._reset()
            self._head.add(float(stamp_s), float(pan), float(tilt), zoom_units)
        return True

    def on_odometry(self, stamp_s: float, yaw: float, linear_x: float, linear_y: float,
                    yaw_rate: float) -> bool:
        """
        Add an odometry sample: the base's heading in the odom frame and its twist.

        ``yaw`` (rad), ``linear_x``, ``linear_y`` (m/s in ``base_link``),
        ``yaw_rate`` (rad/s, positive = left). Returns False (and ignores
        it) when a value is not finite or the stamp is not newer than the
        last one. A stamp more than the history older than the newest
        forgets the odometry (a clock jump).
        """
        values = (stamp_s, yaw, linear_x, linear_y, yaw_rate)
        if not all(math.isfinite(float(v)) for v in values):
            return False
        with self._lock:
            if self._base.jumped_back(float(stamp_s)):
                self._base = BaseTrack()
            return self._base.add(*(float(v) for v in values))

    def _odometry_at(self, stamp_s: float) -> bool:
        """Return whether odometry is fed forward for a time (fresh samples around it)."""
        p = self._params
        return (p.odometry_feed_forward and bool(self._base)
                and stamp_s - self._base.newest_stamp <= p.odometry_timeout_s
                and stamp_s >= self._base.stamps[0])

    def on_target(self, stamp_s: float, pan_error: float, tilt_error: float,
                  size_px: Optional[float] = None, distance_m: Optional[float] = None) -> bool:
        """
        Add the locator's measurement for the image taken at ``stamp_s``.

        ``pan_error``, ``tilt_error``: the head motion (rad, REP 103) that
        would centre the card as seen in that image. ``size_px``: the card's
        apparent size (the outer ring's long semi-axis, px), used by the zoom.
        ``distance_m``: the card's distance from the camera, used by the
        odometry feed-forward. Returns False (and ignores it) when there is
        no head reading yet, a value is not finite, or a newer target was
        already taken.
        """
        return self._add_target(stamp_s, (pan_error, tilt_error), None, size_px, distance_m)

    def on_target_point(self, stamp_s: float, point: Sequence[float],
                        size_px: Optional[float] = None) -> bool:
        """
        Add the card's centre in the optical frame of the image taken at ``stamp_s``.

        As :meth:`on_target`, with the aim exact for any direction
        (:func:`joint_aim_to_point`, the head's angles at the stamp and the
        mount's pitch) and the distance from the point. Returns False (and
        ignores it) as :meth:`on_target` does, and for a point at the camera.
        """
        values = tuple(float(v) for v in point)
        if len(values) != 3:
            return False
        return self._add_target(stamp_s, None, values, size_px, math.hypot(*values))

    def _add_target(self, stamp_s: float, errors: Optional[Tuple[float, float]],
                    point: Optional[Tuple[float, float, float]], size_px: Optional[float],
                    distance_m: Optional[float]) -> bool:
        values = ((stamp_s,) + tuple(errors or ()) + tuple(point or ())
                  + (() if size_px is None else (size_px,))
                  + (() if distance_m is None else (distance_m,)))
        if not all(math.isfinite(float(v)) for v in values):
            return False
        if distance_m is not None and float(distance_m) <= 0.0:
            return False
        stamp_s = float(stamp_s)
        with self._lock:
            if not self._head:
                return False
            if stamp_s < self._head.newest_stamp - HISTORY_S:
                # Older than any head reading we could still have: a clock jump.
                return False
            if self._aims and stamp_s <= self._aims.newest[0]:
                return False
            head_pan, head_tilt = self._head.at(stamp_s)
            if point is not None:
                try:
                    aim_pan, aim_tilt = joint_aim_to_point(head_pan, head_tilt,
                                                           self._params.mount_pitch_rad, point)
                except ValueError:
                    return False        # straight above or below the head: no pan aims at it
                # Unwrapped near the head: the travel check below picks the turn.
                aim_pan = head_pan + math.remainder(aim_pan - head_pan, 2.0 * math.pi)
            else:
                aim_pan, aim_tilt = head_pan + float(errors[0]), head_tilt + float(errors[1])
            aim = (self._clamp(pan_aim_in_travel(aim_pan, self._pan.limits), self._pan.limits),
                   self._clamp(aim_tilt, self._tilt.limits))
            in_odom = self._odometry_at(stamp_s)
            if in_odom != self._aims_in_odom:
                # The aims' frame changes: the old ones no longer compare.
                self._aims.clear()
                self._aims_in_odom = in_odom
            if in_odom:
                aim = (aim[0] + self._base_yaw(stamp_s), aim[1])
            self._aims.add(stamp_s, aim)
            self._distance_m = None if distance_m is None else float(distance_m)
            self._last_target_s = stamp_s
            if size_px is not None:
                self._size_px = float(size_px)
        return True

    @staticmethod
    def _clamp(value: float, limits: Tuple[float, float]) -> float:
        return min(max(value, limits[0]), limits[1])

    # Control ----------------------------------------------------------------

    def update(self, now_s: float, locator_present: bool = True) -> HeadCommand:
        """
        Return the command for the next control period, at time ``now_s``.

        ``locator_present``: whether a locator publishes targets (the
        driver's node knows); until the first target, the search waits for one.
        """
        now_s = float(now_s)
        with self._lock:
            if self._start_s is None or now_s < self._start_s or (
                    not locator_present and self._last_target_s is None):
                self._start_s = now_s
            mode = self._mode_at(now_s)
            if mode != self._mode:
                # Entering a mode: each axis and the zoom start afresh.
                self._pan.settled = self._tilt.settled = False
                self._zoom.reset()
                if mode == MODE_SEARCH:
                    self._start_search()
                self._mode = mode
            if mode == MODE_TRACK:
                command = self._track(now_s)
            elif mode == MODE_SEARCH:
                command = self._search(now_s)
            elif mode == MODE_HOLD:
                command = self._hold(now_s)
            else:
                command = HeadCommand(mode=MODE_IDLE)
            self._speeds = (command.pan_speed, command.tilt_speed)
            return command

    def _mode_at(self, now_s: float) -> str:
        p = self._params
        if not self._head or now_s - self._head.newest_stamp > p.head_timeout_s:
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
        age = min(max(now_s - self._head.newest_stamp, 0.0), self._params.head_timeout_s)
        (pan, tilt), (v_pan, v_tilt) = self._head.newest, self._speeds
        return (self._clamp(pan + v_pan * age, self._pan.limits),
                self._clamp(tilt + v_tilt * age, self._tilt.limits))

    def _base_yaw(self, stamp_s: float) -> float:
        """Return the base's odometry heading at a stamp (carried on up to the timeout)."""
        return self._base.yaw_at(stamp_s, self._params.odometry_timeout_s)

    def _feed_forward(self, now_s: float) -> Tuple[Tuple[float, float], Tuple[float, float]]:
        """
        Return the newest aim carried to now and the rate to follow, both in joint angles.

        Without odometry: the aim moved on by the card's fitted rate, and
        that rate. With it (see the module docstring): the aim moved on by
        the base's turn since its image and the card's rate from the base's
        translation; the rate is that one minus the base's yaw rate.
        """
        stamp, aim_pan, aim_tilt = self._aims.newest
        age = now_s - stamp
        if not (self._aims_in_odom and self._odometry_at(now_s)):
            if self._aims_in_odom:
                # Aims in the odom frame but the odometry stopped: the aim as it
                # was seen, at the heading the odometry last gave.
                aim_pan -= self._base_yaw(stamp)
                return (aim_pan, aim_tilt), (0.0, 0.0)
            rate = self._aims.rate
            return (aim_pan + rate[0] * age, aim_tilt + rate[1] * age), rate
        yaw_stamp, yaw_now = self._base_yaw(stamp), self._base_yaw(now_s)
        linear_x, linear_y, yaw_rate = self._base.newest
        translation = self._aims.rate
        if self._distance_m is not None:
            bearing = aim_pan - yaw_stamp
            elevation = aim_tilt + self._params.mount_pitch_rad
            horizontal = self._distance_m * max(math.cos(elevation), 0.05)
            c, s = math.cos(bearing), math.sin(bearing)
            translation = ((s * linear_x - c * linear_y) / horizontal,
                           math.sin(elevation) * (c * linear_x + s * linear_y)
                           / self._distance_m)
        aim = (aim_pan - yaw_now + translation[0] * age, aim_tilt + translation[1] * age)
        return aim, (translation[0] - yaw_rate, translation[1])

    def _hold(self, now_s: float) -> HeadCommand:
        """No fresh target: stop, or with odometry follow only the feed-forward."""
        zoom = self._zoom.out(self._head.zoom_units)
        if not (self._aims and self._aims_in_odom and self._odometry_at(now_s)):
            return HeadCommand(zoom=zoom, mode=MODE_HOLD)
        pan, tilt = self._head_now(now_s)
        _, rates = self._feed_forward(now_s)
        return HeadCommand(self._pan.within_travel(pan, self._pan.nearest(rates[0])),
                           self._tilt.within_travel(tilt, self._tilt.nearest(rates[1])),
                           zoom, MODE_HOLD)

    def _track(self, now_s: float) -> HeadCommand:
        pan, tilt = self._head_now(now_s)
        aims, rates = self._feed_forward(now_s)
        speeds, errors = [], []
        for axis, carried, rate, position in ((self._pan, aims[0], rates[0], pan),
                                              (self._tilt, aims[1], rates[1], tilt)):
            aim_now = self._clamp(carried, axis.limits)
            if aim_now != carried:
                # The card is beyond the travel: wait at the limit, do not chase it.
                rate = 0.0
            error = aim_now - position
            speeds.append(axis.within_travel(position, self._axis_speed(axis, error, rate)))
            errors.append(error)
        zoom = self._zoom.track(errors, self._size_px, self._head.zoom_units)
        return HeadCommand(speeds[0], speeds[1], zoom, MODE_TRACK, errors[0], errors[1])

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
            return axis.nearest(wanted_rate(error, rate, p), fits)
        slowest = min(((c, v) for v, c in closing if c > 0.0), default=None)
        if slowest is not None and slowest[0] * p.control_period_s <= 1.5 * size:
            return slowest[1]
        axis.settled = True
        return axis.nearest(rate)

    def _start_search(self) -> None:
        """Sweep first back through straight ahead, else where the card was last seen."""
        head_pan = self._head.newest[0] if self._head else None
        card_pan = self._aims.newest[1] if self._aims else None
        if card_pan is not None and self._aims_in_odom:
            card_pan -= self._base_yaw(self._aims.newest[0])
        self._sweep.start(head_pan, card_pan, self._aims.rate[0])

    def _search(self, now_s: float) -> HeadCommand:
        pan, tilt = self._head_now(now_s)
        wanted, level = self._sweep.step(pan)
        if abs(level - tilt) > SEARCH_TILT_BAND_RAD:    # levels lie within the travel
            wanted = 0.0                              # the tilt first (search.py)
        pan_speed = self._pan.within_travel(pan, self._pan.nearest(wanted))
        tilt_speed = self._tilt.within_travel(tilt, self._axis_speed(self._tilt, level - tilt,
                                                                     0.0))
        return HeadCommand(pan_speed, tilt_speed, self._zoom.out(self._head.zoom_units),
                           MODE_SEARCH)
