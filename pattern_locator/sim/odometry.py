"""
Simulated wheel-and-gyro odometry with realistic drift, for the ``odom`` frame.

ROS-free. :class:`OdometrySim` samples a route at a fixed rate and turns
the base's true motion between samples into what a robot's odometry would
report, seeded and reproducible:

* forward motion from the wheels: ``(1 + scale_error)`` times the true
  distance plus white noise of ``speed_noise_m_s`` on the speed while the
  base moves (still wheels read exactly zero);
* yaw from a gyro: ``(1 + yaw_scale_error)`` times the true turn plus a
  constant ``yaw_bias_rad_s`` and white noise of ``yaw_rate_noise_rad_s``,
  standing or not (a gyro drifts at rest);
* sideways motion (only a teleport has any) scaled like the forward one.

The measured speeds are integrated at the midpoint heading into
``T_odom_base``; the odom frame is where the base stood at the first
sample (``T_building_odom``), as on a robot that starts its odometry at
power-up. Each sample carries the twist in ``base_link`` and covariances
in ROS order (x, y, z, roll, pitch, yaw). The pose covariance is first
order: the white noise propagated step by step, plus the drift the
systematic errors cause, each taken as unknown with a standard deviation
equal to its size (the pose's sensitivity to the scale error, the yaw
bias and the yaw scale error is integrated along the way), so the stated
covariance covers the drift rather than hiding it. The twist covariance
is the noise plus the systematic errors at the current speeds.
"""

from dataclasses import dataclass
import math
from typing import List, Protocol

import numpy as np

from .drive import wrap_angle, yaw_pose
from ..errors import ConfigError
from ..vision.geometry import Pose

# Variance of the axes a planar base does not move in (z, roll, pitch): tiny, not zero,
# so that a filter fusing the message does not divide by zero.
_PLANAR_VARIANCE = 1e-6


class Trajectory(Protocol):
    """What odometry needs of a route: the base's true pose over time."""

    def pose_at(self, t: float) -> Pose:
        """Return ``T_building_base`` at route time ``t``."""
        ...


@dataclass(frozen=True)
class OdometryModel:
    """
    The odometry's errors and rate.

    ``scale_error``: odometry distance = (1 + scale_error) x true distance.
    ``yaw_bias_rad_s``: constant gyro bias. ``yaw_scale_error``: measured
    turn = (1 + yaw_scale_error) x true turn. Noise: standard deviations of
    the measured speed and yaw rate per sample (white, at ``rate_hz``).
    """

    scale_error: float = 0.02
    yaw_bias_rad_s: float = 0.002
    yaw_scale_error: float = 0.0
    speed_noise_m_s: float = 0.01
    yaw_rate_noise_rad_s: float = 0.005
    rate_hz: float = 50.0

    def __post_init__(self) -> None:
        for name in ('scale_error', 'yaw_bias_rad_s', 'yaw_scale_error', 'speed_noise_m_s',
                     'yaw_rate_noise_rad_s', 'rate_hz'):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or \
                    not math.isfinite(value):
                raise ConfigError(f'odometry: {name} must be a finite number, got {value!r}')
        if self.rate_hz <= 0.0 or self.speed_noise_m_s < 0.0 or self.yaw_rate_noise_rad_s < 0.0:
            raise ConfigError('odometry: rate_hz must be > 0 and the noises >= 0')
        if abs(self.scale_error) >= 0.5 or abs(self.yaw_scale_error) >= 0.5:
            raise ConfigError('odometry: scale errors must be within +-0.5')


@dataclass(frozen=True, eq=False)
class OdomSample:
    """
    One odometry message's content.

    ``T_odom_base``: the base in the odom frame. ``x, y, yaw``: the same in
    the plane. ``linear_x``, ``linear_y``, ``angular_z``: the measured twist
    in ``base_link`` (m/s, rad/s). Covariances: 6 x 6, ROS order (x, y, z,
    roll, pitch, yaw). ``T_building_base``: the truth at the same instant.
    """

    stamp_s: float
    T_odom_base: Pose
    x: float
    y: float
    yaw: float
    linear_x: float
    linear_y: float
    angular_z: float
    pose_covariance: np.ndarray
    twist_covariance: np.ndarray
    T_building_base: Pose


def _covariance6(planar: np.ndarray) -> np.ndarray:
    """Embed an (x, y, yaw) covariance into ROS's 6 x 6 order."""
    out = np.zeros((6, 6))
    out[2, 2] = out[3, 3] = out[4, 4] = _PLANAR_VARIANCE
    out[:2, :2] = planar[:2, :2]
    out[:2, 5] = planar[:2, 2]
    out[5, :2] = planar[2, :2]
    out[5, 5] = planar[2, 2]
    return out


class OdometrySim:
    """
    Odometry of a route, sample by sample at ``model.rate_hz`` from ``start_s``.

    :meth:`advance_to` returns every sample due up to a time, in order;
    samples are at ``start_s + k / rate_hz`` and their noise is drawn from
    ``seed`` in order, so a run is reproducible however the caller polls.
    """

    def __init__(self, route: Trajectory, model: OdometryModel = OdometryModel(),
                 seed: int = 0, start_s: float = 0.0) -> None:
        self.route = route
        self.model = model
        self.start_s = float(start_s)
        self._rng = np.random.default_rng(seed)
        self._k = 0
        first = route.pose_at(self.start_s)
        self.T_building_odom = first
        self._true_prev = first
        self._x = self._y = self._yaw = 0.0
        self._white = np.zeros((3, 3))
        # d (x, y, yaw) / d (scale_error, yaw_bias, yaw_scale_error), columns.
        self._sensitivity = np.zeros((3, 3))

    @property
    def period_s(self) -> float:
        """Return the time between samples."""
        return 1.0 / self.model.rate_hz

    def advance_to(self, t: float) -> List[OdomSample]:
        """Return the samples stamped after the last call and at or before ``t``."""
        out = []
        while self.start_s + self._k * self.period_s <= t + 1e-12:
            out.append(self._step())
        return out

    def _step(self) -> OdomSample:
        m = self.model
        stamp = self.start_s + self._k * self.period_s
        true = self.route.pose_at(stamp)
        dt = self.period_s
        if self._k == 0:
            forward = side = turn = 0.0
        else:
            delta = self._true_prev.inverse() @ true
            forward, side = float(delta.t[0]), float(delta.t[1])
            turn = math.atan2(delta.R[1, 0], delta.R[0, 0])
        self._true_prev = true
        moving = math.hypot(forward, side) > 1e-9
        # One draw each per sample, moving or not, so the stream stays aligned.
        n_speed, n_yaw = self._rng.standard_normal(2)
        speed = (1.0 + m.scale_error) * forward / dt + (m.speed_noise_m_s * n_speed
                                                        if moving else 0.0)
        lateral = (1.0 + m.scale_error) * side / dt
        rate = ((1.0 + m.yaw_scale_error) * turn / dt + m.yaw_bias_rad_s
                + m.yaw_rate_noise_rad_s * n_yaw) if self._k else 0.0
        if self._k:
            mid = self._yaw + 0.5 * rate * dt
            c, s = math.cos(mid), math.sin(mid)
            self._x += (c * speed - s * lateral) * dt
            self._y += (s * speed + c * lateral) * dt
            self._yaw = wrap_angle(self._yaw + rate * dt)
            self._propagate(speed, lateral, mid, dt, moving,
                            np.array([[forward / dt, 0.0, 0.0], [side / dt, 0.0, 0.0],
                                      [0.0, 1.0, turn / dt]]))
        self._k += 1
        noise_v = m.speed_noise_m_s ** 2 if moving else 0.0
        twist = np.zeros((6, 6))
        twist[0, 0] = noise_v + (m.scale_error * speed) ** 2 + _PLANAR_VARIANCE
        twist[1, 1] = (m.scale_error * lateral) ** 2 + _PLANAR_VARIANCE
        twist[2, 2] = twist[3, 3] = twist[4, 4] = _PLANAR_VARIANCE
        twist[5, 5] = (m.yaw_rate_noise_rad_s ** 2 + m.yaw_bias_rad_s ** 2
                       + (m.yaw_scale_error * rate) ** 2 + _PLANAR_VARIANCE)
        return OdomSample(stamp, yaw_pose(self._x, self._y, self._yaw), self._x, self._y,
                          self._yaw, speed, lateral, rate, _covariance6(self.covariance()),
                          twist, true)

    def covariance(self) -> np.ndarray:
        """Return the (x, y, yaw) covariance of the current odometry pose."""
        m = self.model
        sizes = np.array([m.scale_error, m.yaw_bias_rad_s, m.yaw_scale_error]) ** 2
        return self._white + (self._sensitivity * sizes) @ self._sensitivity.T

    def _propagate(self, speed: float, lateral: float, yaw: float, dt: float, moving: bool,
                   d_twist: np.ndarray) -> None:
        """
        First-order growth of the pose's uncertainty over one step.

        ``d_twist``: d (speed, lateral, yaw rate) / d (scale error, yaw bias,
        yaw scale error) of this step.
        """
        m = self.model
        c, s = math.cos(yaw), math.sin(yaw)
        F = np.array([[1.0, 0.0, (-s * speed - c * lateral) * dt],
                      [0.0, 1.0, (c * speed - s * lateral) * dt],
                      [0.0, 0.0, 1.0]])
        G = np.array([[c * dt, -s * dt, 0.0], [s * dt, c * dt, 0.0], [0.0, 0.0, dt]])
        # The midpoint heading moves with half the step's turn.
        G[0, 2] = 0.5 * dt * F[0, 2]
        G[1, 2] = 0.5 * dt * F[1, 2]
        Q = np.diag([m.speed_noise_m_s ** 2 if moving else 0.0, 0.0,
                     m.yaw_rate_noise_rad_s ** 2])
        self._white = F @ self._white @ F.T + G @ Q @ G.T
        self._sensitivity = F @ self._sensitivity + G @ d_twist
