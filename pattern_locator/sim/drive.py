"""
A continuous drive through the floor: waypoints to a smooth, limited trajectory.

ROS-free. A route is a list of :class:`Waypoint` (building frame, metres):
the robot starts at rest at the first one, drives the legs between them at
each leg's cruise speed and ends at rest at the last one. A waypoint with
``stop_s > 0`` (and the first and the last) is a **stop**: the robot comes
to rest there, stands ``stop_s`` seconds, turns in place to the next leg's
heading (or to ``face_deg``) and drives on. Any other waypoint is a
**corner**, driven without stopping along a curve whose curvature ramps
linearly up to ``1 / corner_radius_m`` over ``transition_m``, holds and
ramps back down (a clothoid-arc-clothoid turn), so that the yaw rate
changes smoothly too.

Speed along each run between two stops is the fastest profile that keeps

* the leg's cruise speed and :attr:`DriveLimits.max_speed_m_s`,
* ``|acceleration| <= accel_m_s2`` (speed changes are smooth ramps, never
  jumps),
* ``|yaw rate| = speed * |curvature| <= yaw_rate_rad_s``,
* ``speed^2 * |d curvature / ds| <= yaw_accel_rad_s2`` on the ramps,

computed by the usual forward (accelerate) and backward (brake) passes
over the path sampled every ``step_m``. In-place turns follow a
trapezoidal yaw-rate profile with the same yaw-rate and yaw-acceleration
limits. Between samples the speed changes at constant acceleration, so
positions, speeds and yaw rates are continuous in time.
"""

from dataclasses import dataclass
import math
from typing import List, Optional, Sequence, Tuple

import numpy as np

from ..errors import ConfigError
from ..vision.geometry import Pose, yaw_pose

PHASES = ('stop', 'turn', 'drive')
# A corner sharper than this is not driven round: make the waypoint a stop.
MAX_CORNER_DEG = 150.0


def wrap_angle(angle: float) -> float:
    """Return the angle in [-pi, pi)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


@dataclass(frozen=True)
class Waypoint:
    """
    A point of a route (building frame, m) and how the robot leaves it.

    ``speed_m_s``: cruise speed of the leg from this waypoint to the next.
    ``stop_s``: stand this long here (makes it a stop). ``face_deg``: at a
    stop, turn to this heading before standing (default: the next leg's).
    """

    xy: Tuple[float, float]
    speed_m_s: float = 0.5
    stop_s: float = 0.0
    face_deg: Optional[float] = None


@dataclass(frozen=True)
class DriveLimits:
    """The base's limits: speed, acceleration, yaw rate and yaw acceleration, corners."""

    max_speed_m_s: float = 0.8
    accel_m_s2: float = 0.3
    yaw_rate_rad_s: float = 0.5
    yaw_accel_rad_s2: float = 0.8
    corner_radius_m: float = 1.0
    transition_m: float = 0.5
    step_m: float = 0.01

    def __post_init__(self) -> None:
        for name in ('max_speed_m_s', 'accel_m_s2', 'yaw_rate_rad_s', 'yaw_accel_rad_s2',
                     'corner_radius_m', 'transition_m', 'step_m'):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not (
                    math.isfinite(value) and value > 0.0):
                raise ConfigError(f'drive limits: {name} must be a positive number, got '
                                  f'{value!r}')


@dataclass(frozen=True)
class DriveState:
    """
    The base at one instant of a route.

    ``pose``: ``T_building_base`` (base on the floor, z = the route's z).
    ``speed_m_s`` (forward), ``yaw_rate_rad_s`` and ``accel_m_s2`` are the
    base's twist and its rate of change of speed. ``phase``: ``stop``
    (standing), ``turn`` (turning in place) or ``drive``. ``stop``: the index
    of the waypoint the robot stands or turns at, else None.
    """

    t: float
    pose: Pose
    heading: float
    speed_m_s: float
    yaw_rate_rad_s: float
    accel_m_s2: float
    phase: str
    stop: Optional[int]


@dataclass(frozen=True)
class _Corner:
    """A corner's curve in its own frame: start at the origin heading +x, turning left."""

    s: np.ndarray
    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray
    kappa: np.ndarray
    dkappa: np.ndarray
    tangent_m: float


def _corner(turn: float, limits: DriveLimits) -> _Corner:
    """Return the clothoid-arc-clothoid curve that turns left by ``turn`` > 0 radians."""
    k_max = 1.0 / limits.corner_radius_m
    ramp = limits.transition_m
    if turn <= k_max * ramp:
        k_peak, hold = turn / ramp, 0.0
    else:
        k_peak, hold = k_max, turn / k_max - ramp
    length = 2.0 * ramp + hold
    slope = k_peak / ramp

    def heading_at(s: np.ndarray) -> np.ndarray:
        # The exact integral of the piecewise linear curvature.
        down = np.clip(s - ramp - hold, 0.0, ramp)
        return (0.5 * slope * np.minimum(s, ramp) ** 2 + k_peak * np.clip(s - ramp, 0.0, hold)
                + k_peak * down - 0.5 * slope * down ** 2)

    n = max(int(math.ceil(length / limits.step_m)), 8)
    s = np.linspace(0.0, length, n + 1)
    kappa = np.where(s < ramp, slope * s,
                     np.where(s <= ramp + hold, k_peak, slope * (length - s)))
    dkappa = np.where(s < ramp, slope, np.where(s <= ramp + hold, 0.0, -slope))
    # Positions: the unit tangent integrated (trapezoid) on a 10 times finer grid.
    fine = np.linspace(0.0, length, 10 * n + 1)
    angle = heading_at(fine)
    h = fine[1] - fine[0]
    x = np.concatenate([[0.0], np.cumsum(0.5 * h * (np.cos(angle[1:]) + np.cos(angle[:-1])))])
    y = np.concatenate([[0.0], np.cumsum(0.5 * h * (np.sin(angle[1:]) + np.sin(angle[:-1])))])
    x, y = x[::10], y[::10]
    # The two straight legs meet where the outgoing line crosses the x axis.
    tangent = float(x[-1] - y[-1] * math.cos(turn) / math.sin(turn))
    return _Corner(s, x, y, heading_at(s), kappa, dkappa, tangent)


@dataclass
class _Run:
    """A stretch driven without stopping, sampled every step: path, speed and time."""

    s: np.ndarray
    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray
    kappa: np.ndarray
    v: np.ndarray
    t: np.ndarray              # time from the run's start at each sample
    start_s: float = 0.0       # route time of the run's start


@dataclass
class _Turn:
    """An in-place turn from ``start`` by ``angle`` with a trapezoidal yaw rate."""

    start_heading: float
    angle: float
    rate: float                # peak yaw rate
    accel: float
    ramp_s: float
    duration_s: float

    @staticmethod
    def make(start_heading: float, angle: float, limits: DriveLimits) -> '_Turn':
        a, w = limits.yaw_accel_rad_s2, limits.yaw_rate_rad_s
        size = abs(angle)
        if size * a >= w * w:
            ramp, rate = w / a, w
            duration = 2.0 * ramp + (size - w * w / a) / w
        else:
            rate = math.sqrt(size * a)
            ramp = rate / a
            duration = 2.0 * ramp
        return _Turn(start_heading, angle, rate, a, ramp, duration)

    def at(self, tau: float) -> Tuple[float, float, float]:
        """Return heading, yaw rate and yaw acceleration ``tau`` seconds into the turn."""
        sign = 1.0 if self.angle >= 0.0 else -1.0
        tau = min(max(tau, 0.0), self.duration_s)
        a, ramp, end = self.accel, self.ramp_s, self.duration_s
        if tau < ramp:
            done, rate, acc = 0.5 * a * tau ** 2, a * tau, a
        elif tau <= end - ramp:
            done, rate, acc = 0.5 * a * ramp ** 2 + self.rate * (tau - ramp), self.rate, 0.0
        else:
            left = end - tau
            done, rate, acc = abs(self.angle) - 0.5 * a * left ** 2, a * left, -a
        return self.start_heading + sign * done, sign * rate, sign * acc


@dataclass
class _Phase:
    kind: str                  # 'stop', 'turn' or 'drive'
    start_s: float
    duration_s: float
    stop: Optional[int]
    x: float = 0.0
    y: float = 0.0
    heading: float = 0.0
    turn: Optional[_Turn] = None
    run: Optional[_Run] = None


class DriveRoute:
    """
    A route through the floor over time (see the module docstring).

    Times are seconds from the start; before 0 the robot stands at the first
    waypoint, after :attr:`duration_s` at the last one. ``z`` is the floor's
    height in the building frame (the base's z).
    """

    def __init__(self, waypoints: Sequence[Waypoint], limits: DriveLimits = DriveLimits(),
                 z: float = 0.0, name: str = 'route') -> None:
        self.name = name
        self.limits = limits
        self.z = float(z)
        self.waypoints = tuple(self._checked(i, w) for i, w in enumerate(waypoints))
        if len(self.waypoints) < 2:
            raise ConfigError(f'route {name}: needs at least two waypoints')
        stops = [0] + [i for i, w in enumerate(self.waypoints[1:-1], 1) if w.stop_s > 0.0] + [
            len(self.waypoints) - 1]
        self._phases: List[_Phase] = []
        self.length_m = 0.0
        t = 0.0
        heading = self._leg_heading(0)
        for k, (a, b) in enumerate(zip(stops, stops[1:])):
            out = self._leg_heading(a)
            wp = self.waypoints[a]
            target = out if wp.face_deg is None else math.radians(wp.face_deg)
            x, y = wp.xy
            t = self._stand_and_turn(t, a, x, y, heading if k else target, target, wp.stop_s)
            if wp.face_deg is not None:
                t = self._stand_and_turn(t, a, x, y, target, out, 0.0)
            run = self._run(a, b)
            run.start_s = t
            self._phases.append(_Phase('drive', t, float(run.t[-1]), None, run=run))
            self.length_m += float(run.s[-1])
            t += float(run.t[-1])
            heading = float(run.heading[-1])
        last = len(self.waypoints) - 1
        wp = self.waypoints[last]
        target = heading if wp.face_deg is None else math.radians(wp.face_deg)
        self._stand_and_turn(t, last, wp.xy[0], wp.xy[1], heading, target, wp.stop_s)
        self._starts = np.array([p.start_s for p in self._phases])

    # Construction ----------------------------------------------------------------------

    def _checked(self, index: int, w: Waypoint) -> Waypoint:
        where = f'route {self.name}: waypoint {index}'
        try:
            x, y = (float(v) for v in w.xy)
        except (TypeError, ValueError):
            raise ConfigError(f'{where}: xy must be two numbers, got {w.xy!r}') from None
        numbers = {'x': x, 'y': y, 'speed_m_s': w.speed_m_s, 'stop_s': w.stop_s}
        if w.face_deg is not None:
            numbers['face_deg'] = w.face_deg
        for key, value in numbers.items():
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not \
                    math.isfinite(value):
                raise ConfigError(f'{where}: {key} must be a finite number, got {value!r}')
        if w.speed_m_s <= 0.0 or w.stop_s < 0.0:
            raise ConfigError(f'{where}: speed_m_s must be > 0 and stop_s >= 0, got '
                              f'{w.speed_m_s!r} and {w.stop_s!r}')
        return Waypoint((x, y), float(w.speed_m_s), float(w.stop_s),
                        None if w.face_deg is None else float(w.face_deg))

    def _leg_heading(self, index: int) -> float:
        """Return the heading of the leg leaving waypoint ``index`` (the last: arriving)."""
        if index == len(self.waypoints) - 1:
            index -= 1
        (x0, y0), (x1, y1) = self.waypoints[index].xy, self.waypoints[index + 1].xy
        if math.hypot(x1 - x0, y1 - y0) < 1e-6:
            raise ConfigError(f'route {self.name}: waypoints {index} and {index + 1} are the '
                              f'same point')
        return math.atan2(y1 - y0, x1 - x0)

    def _stand_and_turn(self, t: float, index: int, x: float, y: float, heading: float,
                        target: float, stand_s: float) -> float:
        """Append standing ``stand_s`` at a stop, then turning to ``target``; return the end."""
        if stand_s > 0.0 or index in (0, len(self.waypoints) - 1):
            self._phases.append(_Phase('stop', t, stand_s, index, x, y, heading))
            t += stand_s
        angle = wrap_angle(target - heading)
        if abs(angle) > 1e-9:
            turn = _Turn.make(heading, angle, self.limits)
            self._phases.append(_Phase('turn', t, turn.duration_s, index, x, y, heading,
                                       turn=turn))
            t += turn.duration_s
        return t

    def _run(self, first: int, last: int) -> _Run:
        """Sample the path from stop ``first`` to stop ``last`` and its speed profile."""
        limits = self.limits
        points = [np.asarray(self.waypoints[i].xy) for i in range(first, last + 1)]
        speeds = [min(self.waypoints[i].speed_m_s, limits.max_speed_m_s)
                  for i in range(first, last)]
        pieces = []             # (x, y, heading, kappa, dkappa, speed) arrays per piece
        start = points[0]
        for j in range(1, len(points) - 1):
            a, p, b = points[j - 1], points[j], points[j + 1]
            h_in = math.atan2(*(p - a)[::-1])
            h_out = math.atan2(*(b - p)[::-1])
            turn = wrap_angle(h_out - h_in)
            if abs(turn) < 1e-9:
                continue
            if abs(turn) > math.radians(MAX_CORNER_DEG):
                raise ConfigError(f'route {self.name}: waypoint {first + j} turns '
                                  f'{math.degrees(abs(turn)):.0f} deg; corners up to '
                                  f'{MAX_CORNER_DEG:.0f} deg are driven round, make it a stop')
            corner = _corner(abs(turn), limits)
            u = np.array([math.cos(h_in), math.sin(h_in)])
            begin = p - corner.tangent_m * u
            if (begin - start) @ u < -1e-9:
                raise ConfigError(
                    f'route {self.name}: waypoint {first + j}: its corner needs '
                    f'{corner.tangent_m:.2f} m of straight leg before it, but the leg from '
                    f'the previous corner or stop leaves {float((p - start) @ u):.2f} m')
            pieces.append(self._line(start, begin, speeds[j - 1]))
            sign = 1.0 if turn > 0 else -1.0
            c, s = math.cos(h_in), math.sin(h_in)
            cx, cy = corner.x, sign * corner.y
            pieces.append((begin[0] + c * cx - s * cy, begin[1] + s * cx + c * cy,
                           h_in + sign * corner.heading, sign * corner.kappa,
                           sign * corner.dkappa,
                           np.full(corner.s.shape, min(speeds[j - 1], speeds[j]))))
            start = p + corner.tangent_m * np.array([math.cos(h_out), math.sin(h_out)])
            if (points[j + 1] - start) @ np.array([math.cos(h_out), math.sin(h_out)]) < -1e-9:
                raise ConfigError(
                    f'route {self.name}: waypoint {first + j}: its corner needs '
                    f'{corner.tangent_m:.2f} m of straight leg after it, more than the leg '
                    f'to waypoint {first + j + 1}')
        pieces.append(self._line(start, points[-1], speeds[-1]))
        x, y, heading, kappa, dkappa, vmax = (np.concatenate(
            [piece[k][1:] if i else piece[k] for i, piece in enumerate(pieces)])
            for k in range(6))
        heading = np.unwrap(heading)
        steps = np.hypot(np.diff(x), np.diff(y))
        keep = np.concatenate([[True], steps > 1e-9])
        x, y, heading, kappa, dkappa, vmax = (
            a[keep] for a in (x, y, heading, kappa, dkappa, vmax))
        ds = np.hypot(np.diff(x), np.diff(y))
        s = np.concatenate([[0.0], np.cumsum(ds)])
        with np.errstate(divide='ignore'):
            vmax = np.minimum(vmax, limits.yaw_rate_rad_s / np.abs(kappa))
            vmax = np.minimum(vmax, np.sqrt(limits.yaw_accel_rad_s2 / np.abs(dkappa)))
        vmax[0] = vmax[-1] = 0.0
        # The forward (accelerate) and backward (brake) passes in closed form:
        # v(s)^2 = min over s' <= s of vmax(s')^2 + 2 a (s - s'), and the same
        # backwards, so both are running minima.
        two_a = 2.0 * limits.accel_m_s2
        limit = vmax ** 2
        forward = two_a * s + np.minimum.accumulate(limit - two_a * s)
        backward = -two_a * s + np.minimum.accumulate((limit + two_a * s)[::-1])[::-1]
        v = np.sqrt(np.maximum(np.minimum(forward, backward), 0.0))
        dt = 2.0 * ds / (v[1:] + v[:-1])
        t = np.concatenate([[0.0], np.cumsum(dt)])
        return _Run(s, x, y, heading, kappa, v, t)

    def _line(self, a: np.ndarray, b: np.ndarray, speed: float):
        length = float(np.linalg.norm(b - a))
        n = max(int(math.ceil(length / self.limits.step_m)), 1)
        f = np.linspace(0.0, 1.0, n + 1)
        heading = math.atan2(b[1] - a[1], b[0] - a[0]) if length > 0 else 0.0
        zeros = np.zeros(n + 1)
        return (a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), np.full(n + 1, heading),
                zeros, zeros, np.full(n + 1, speed))

    # Queries ---------------------------------------------------------------------------

    @property
    def duration_s(self) -> float:
        """Return the time at which the robot has stood its time at the last waypoint."""
        last = self._phases[-1]
        return last.start_s + last.duration_s

    @property
    def stops(self) -> List[Tuple[int, float, float]]:
        """Return (waypoint index, start, end) of every time the robot stands still."""
        return [(p.stop, p.start_s, p.start_s + p.duration_s) for p in self._phases
                if p.kind == 'stop']

    def state_at(self, t: float) -> DriveState:
        """Return the base's pose and twist at route time ``t``."""
        if not math.isfinite(t):
            raise ValueError(f'time must be a finite number, got {t!r}')
        i = max(int(np.searchsorted(self._starts, t, side='right')) - 1, 0)
        phase = self._phases[i]
        tau = min(max(t - phase.start_s, 0.0), phase.duration_s)
        if phase.kind == 'stop':
            return self._state(t, phase.x, phase.y, phase.heading, 0.0, 0.0, 0.0, 'stop',
                               phase.stop)
        if phase.kind == 'turn':
            heading, rate, _ = phase.turn.at(tau)
            return self._state(t, phase.x, phase.y, heading, 0.0, rate, 0.0, 'turn',
                               phase.stop)
        run = phase.run
        k = min(max(int(np.searchsorted(run.t, tau, side='right')) - 1, 0), len(run.t) - 2)
        ds = run.s[k + 1] - run.s[k]
        acc = (run.v[k + 1] ** 2 - run.v[k] ** 2) / (2.0 * ds)
        dt = tau - run.t[k]
        along = min(max(run.v[k] * dt + 0.5 * acc * dt * dt, 0.0), ds)
        f = along / ds
        speed = max(run.v[k] + acc * dt, 0.0)
        kappa = run.kappa[k] + f * (run.kappa[k + 1] - run.kappa[k])
        x = run.x[k] + f * (run.x[k + 1] - run.x[k])
        y = run.y[k] + f * (run.y[k + 1] - run.y[k])
        heading = run.heading[k] + f * (run.heading[k + 1] - run.heading[k])
        return self._state(t, float(x), float(y), float(heading), float(speed),
                           float(speed * kappa), float(acc), 'drive', None)

    def _state(self, t: float, x: float, y: float, heading: float, speed: float, rate: float,
               acc: float, phase: str, stop: Optional[int]) -> DriveState:
        heading = wrap_angle(heading)
        return DriveState(t, yaw_pose(x, y, heading, self.z), heading, speed, rate, acc, phase,
                          stop)

    def pose_at(self, t: float) -> Pose:
        """Return ``T_building_base`` at route time ``t``."""
        return self.state_at(t).pose

    def stop_at(self, t: float) -> Optional[int]:
        """Return the waypoint the robot stands at (not turning), None otherwise."""
        state = self.state_at(t)
        return state.stop if state.phase == 'stop' else None

    def track(self, dt: float = 0.1) -> np.ndarray:
        """
        Return the route every ``dt`` seconds from 0 to the end, one row per instant.

        Columns: t, x, y, heading (unwrapped), speed, yaw rate, acceleration
        (the same values as :meth:`state_at`, computed for all at once).
        """
        if not (math.isfinite(dt) and dt > 0.0):
            raise ValueError(f'dt must be a positive number, got {dt!r}')
        times = np.arange(0.0, self.duration_s + 0.5 * dt, dt)
        out = np.zeros((len(times), 7))
        out[:, 0] = times
        index = np.clip(np.searchsorted(self._starts, times, side='right') - 1, 0, None)
        for i, phase in enumerate(self._phases):
            rows = np.flatnonzero(index == i)
            if rows.size == 0:
                continue
            tau = np.clip(times[rows] - phase.start_s, 0.0, phase.duration_s)
            if phase.kind == 'stop':
                out[rows, 1:4] = phase.x, phase.y, phase.heading
            elif phase.kind == 'turn':
                turn = phase.turn
                values = np.array([turn.at(float(x)) for x in tau]).reshape(-1, 3)
                out[rows, 1:3] = phase.x, phase.y
                out[rows, 3], out[rows, 5] = values[:, 0], values[:, 1]
            else:
                run = phase.run
                k = np.clip(np.searchsorted(run.t, tau, side='right') - 1, 0, len(run.t) - 2)
                ds = run.s[k + 1] - run.s[k]
                acc = (run.v[k + 1] ** 2 - run.v[k] ** 2) / (2.0 * ds)
                step = tau - run.t[k]
                f = np.clip(run.v[k] * step + 0.5 * acc * step ** 2, 0.0, ds) / ds
                speed = np.maximum(run.v[k] + acc * step, 0.0)
                for column, values in ((1, run.x), (2, run.y), (3, run.heading)):
                    out[rows, column] = values[k] + f * (values[k + 1] - values[k])
                kappa = run.kappa[k] + f * (run.kappa[k + 1] - run.kappa[k])
                out[rows, 4], out[rows, 5], out[rows, 6] = speed, speed * kappa, acc
        out[:, 3] = np.unwrap(out[:, 3])
        return out
