"""
Settings of the tracking loop and the EVI-D31's speed steps (ROS-free).

:class:`TrackingParams` validates every setting on creation with a
one-line :class:`~pattern_locator.errors.ConfigError`; :func:`quantise_speed`
and :func:`step_range` turn speeds into the head's whole speed steps.
"""

from dataclasses import dataclass
import math
from typing import Tuple

from ..errors import ConfigError
from ..localization.head import EVI_D31_PAN_LIMITS_RAD, EVI_D31_TILT_LIMITS_RAD, limit_pair
from ..visca.protocol import PAN_MAX_DEG_S, PAN_SPEED_MAX, TILT_MAX_DEG_S, TILT_SPEED_MAX

# The EVI-D31's speed steps (visca.md): pan 1..24 of 80/24 deg/s, tilt 1..20 of 2.5 deg/s.
PAN_MAX_STEPS = PAN_SPEED_MAX
TILT_MAX_STEPS = TILT_SPEED_MAX
PAN_STEP_RAD_S = math.radians(PAN_MAX_DEG_S / PAN_SPEED_MAX)
TILT_STEP_RAD_S = math.radians(TILT_MAX_DEG_S / TILT_SPEED_MAX)


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


def _positive(name: str, value, allow_zero: bool = False) -> float:
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f'tracking: {name} must be a number, got {value!r}')
    if not math.isfinite(value) or value < 0.0 or (value == 0.0 and not allow_zero):
        raise ConfigError(f'tracking: {name} must be {">=" if allow_zero else ">"} 0, '
                          f'got {value!r}')
    return value


def step_range(axis: str, min_speed: float, max_speed: float, step: float,
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
    * ``slew_band_rad``: further off than this (a handover's slew, blind
      anyway) an axis closes its error as fast as it can stop at the band:
      not past it within a control period, nor faster than braking at
      ``slew_decel_rad_s2`` allows; within it, the gain. 0: the gain
      everywhere.
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
      ``search_ahead_first`` a head turned more than ``search.AHEAD_BAND_RAD`` to a
      side sweeps back through straight ahead first: after the robot moved
      on, the next card is likelier ahead of it than where the last one was.
    * ``head_timeout_s``: no head reading newer than this -> 'idle', stop.
    * ``rate_window_s``: the span of recent aims fitted for the card's
      angular rate (0 = no rate feed-forward). Rates under half the slowest
      step are taken as 0.
    * ``odometry_feed_forward``: with the base's odometry (``on_odometry``)
      the head turns against the base's yaw rate and follows the card's
      apparent motion from the base's translation (at the card's distance,
      when the target gives it), and an aim is carried from its image's
      stamp to now by the base's turn in between. Odometry older than
      ``odometry_timeout_s`` is not used. ``mount_pitch_rad``: the camera
      looks up by this at tilt 0 (the card's elevation for the translation
      term is the tilt aim plus this).
    * Zoom (if ``zoom_enabled``): start zooming when the card's size is
      off ``target_size_px`` by more than ``zoom_band`` (relative), stop
      when back within a third of it; never zoom in while the error
      exceeds ``zoom_max_error_rad``; zoom out when it exceeds twice that,
      and whenever no card is tracked.
    """

    gain: float = 3.0
    slew_band_rad: float = math.radians(3.0)
    slew_decel_rad_s2: float = math.radians(200.0)
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
    odometry_feed_forward: bool = True
    odometry_timeout_s: float = 0.5
    mount_pitch_rad: float = 0.0
    zoom_enabled: bool = False
    target_size_px: float = 120.0
    zoom_band: float = 0.15
    zoom_max_error_rad: float = math.radians(3.0)

    def __post_init__(self):
        def put(name, value):
            object.__setattr__(self, name, value)

        for name in ('gain', 'slew_decel_rad_s2', 'max_pan_speed', 'max_tilt_speed',
                     'min_pan_speed', 'min_tilt_speed', 'control_period_s', 'target_timeout_s',
                     'head_timeout_s', 'search_after_s', 'search_pan_speed',
                     'target_size_px', 'zoom_max_error_rad', 'odometry_timeout_s'):
            put(name, _positive(name, getattr(self, name)))
        for name in ('dead_band_rad', 'resume_band_rad', 'rate_window_s', 'slew_band_rad'):
            put(name, _positive(name, getattr(self, name), allow_zero=True))
        for name in ('search_enabled', 'search_ahead_first', 'zoom_enabled',
                     'odometry_feed_forward'):
            if not isinstance(getattr(self, name), bool):
                raise ConfigError(f'tracking: {name} must be true or false, got '
                                  f'{getattr(self, name)!r}')
        try:
            pitch = float(self.mount_pitch_rad)
        except (TypeError, ValueError):
            pitch = math.nan
        if not (math.isfinite(pitch) and abs(pitch) < math.pi / 2):
            raise ConfigError(f'tracking: mount_pitch_rad must be within +-90 deg, got '
                              f'{self.mount_pitch_rad!r}')
        put('mount_pitch_rad', pitch)
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
        step_range('pan', self.min_pan_speed, self.max_pan_speed, PAN_STEP_RAD_S,
                   PAN_MAX_STEPS)
        step_range('tilt', self.min_tilt_speed, self.max_tilt_speed, TILT_STEP_RAD_S,
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
