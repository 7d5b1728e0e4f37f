"""The floor's routes (speed, yaw rate, acceleration, stops) and the simulated odometry."""

import math

import numpy as np
from pattern_locator.errors import ConfigError
from pattern_locator.sim.drive import DriveLimits, DriveRoute, Waypoint
from pattern_locator.sim.odometry import OdometryModel, OdometrySim
import pytest


def test_the_tour_keeps_its_limits_and_changes_speed_smoothly(floor_world):
    route = floor_world.route('tour')
    limits = route.limits
    dt = 0.01
    track = route.track(dt)
    t, x, y, heading, speed, rate, acc = track.T
    # Positions and headings are continuous: their differences are the twist.
    moved = np.hypot(np.diff(x), np.diff(y)) / dt
    np.testing.assert_allclose(moved, (speed[1:] + speed[:-1]) / 2.0, atol=2e-3)
    np.testing.assert_allclose(np.diff(heading) / dt, (rate[1:] + rate[:-1]) / 2.0, atol=5e-3)
    # Speed: 0.3 .. 0.8 m/s when cruising, never more; smooth ramps at most 0.3 m/s^2.
    assert speed.max() <= 0.8 + 1e-9 and speed.max() > 0.79
    cruising = speed[(acc == 0.0) & (speed > 0.05) & (rate == 0.0)]
    assert cruising.min() >= 0.3 - 1e-9
    assert np.abs(np.diff(speed) / dt).max() <= limits.accel_m_s2 + 1e-6
    assert np.abs(acc).max() == pytest.approx(limits.accel_m_s2)
    # Turns: yaw rate up to 0.5 rad/s, reached; yaw acceleration bounded (no jumps).
    assert np.abs(rate).max() <= 0.5 + 1e-9 and np.abs(rate).max() > 0.49
    assert np.abs(np.diff(rate) / dt).max() <= limits.yaw_accel_rad_s2 + limits.accel_m_s2 + 1e-3
    # Stops: the robot stands 3 s at the far end of each of five rooms.
    stands = [(i, end - start) for i, start, end in route.stops]
    assert [i for i, length in stands if length == 3.0] == [3, 8, 12, 16, 20]
    for i, start, end in route.stops:
        still = (t > start) & (t < end)
        assert np.all(speed[still] == 0.0) and np.all(rate[still] == 0.0)
    # The robot keeps clear of every wall.
    assert floor_world.clearance(track[:, 1:3]).min() >= floor_world.robot_radius
    # Corners are driven round: at a corner waypoint the path passes inside it.
    corner = np.array(floor_world.routes['tour'][1].xy)
    assert 0.1 < np.hypot(x - corner[0], y - corner[1]).min() < 0.5


def test_a_capped_route_and_a_route_that_cannot_be_driven():
    waypoints = [Waypoint((0.0, 0.0), 0.8), Waypoint((10.0, 0.0), 0.8),
                 Waypoint((10.0, 5.0), stop_s=1.0)]
    capped = DriveRoute(waypoints, DriveLimits(max_speed_m_s=0.5))
    assert capped.track(0.05)[:, 4].max() == pytest.approx(0.5)
    assert capped.length_m == pytest.approx(DriveRoute(waypoints).length_m)
    with pytest.raises(ConfigError, match='waypoint 1 turns 180 deg'):
        DriveRoute([Waypoint((0.0, 0.0)), Waypoint((5.0, 0.0)), Waypoint((1.0, 0.0))])
    with pytest.raises(ConfigError, match='needs 1.26 m of straight leg before it'):
        DriveRoute([Waypoint((0.0, 0.0)), Waypoint((1.0, 0.0)), Waypoint((1.0, 5.0))])
    with pytest.raises(ConfigError, match='speed_m_s must be a positive number'):
        DriveLimits(max_speed_m_s=0.0)


def straight_then_stand(distance=30.0, speed=0.5, stand_s=60.0):
    return DriveRoute([Waypoint((0.0, 0.0), speed), Waypoint((distance, 0.0), stop_s=stand_s)])


def test_odometry_drift_statistics_match_their_parameters():
    model = OdometryModel(scale_error=0.03, yaw_bias_rad_s=0.004, speed_noise_m_s=0.02,
                          yaw_rate_noise_rad_s=0.01, rate_hz=50.0)
    route = straight_then_stand(distance=20.0, stand_s=20.0)
    odometry = OdometrySim(route, model, seed=3)
    samples = odometry.advance_to(route.duration_s)
    assert len(samples) == int(route.duration_s * 50.0) + 1
    assert samples[0].x == samples[0].y == samples[0].yaw == 0.0
    dt = 1.0 / model.rate_hz
    true = [s.T_building_base for s in samples]
    forward = np.array([(a.inverse() @ b).t[0] / dt for a, b in zip(true, true[1:])])
    speed = np.array([s.linear_x for s in samples[1:]])
    rate = np.array([s.angular_z for s in samples[1:]])
    moving = forward > 0.0
    assert 1500 < moving.sum() < len(forward) - 900
    # Speed: (1 + scale) x true, plus white noise of the stated size while moving.
    error = speed[moving] - (1.0 + model.scale_error) * forward[moving]
    assert abs(error.mean()) < 4 * model.speed_noise_m_s / math.sqrt(moving.sum())
    assert error.std() == pytest.approx(model.speed_noise_m_s, rel=0.06)
    assert np.all(speed[~moving] == 0.0)
    # Yaw rate (the robot drives straight): the bias plus white noise, standing or not.
    assert rate.mean() == pytest.approx(model.yaw_bias_rad_s,
                                        abs=4 * model.yaw_rate_noise_rad_s / math.sqrt(len(rate)))
    assert rate.std() == pytest.approx(model.yaw_rate_noise_rad_s, rel=0.06)
    # Integrated: the path is 3 % long, the heading drifts by bias x time, each
    # within 4 sigma of what the white noise adds.
    xy = np.array([[s.x, s.y] for s in samples])
    travelled = np.linalg.norm(np.diff(xy, axis=0), axis=1).sum()
    noise = model.speed_noise_m_s * math.sqrt(dt * moving.sum() * dt)
    assert travelled == pytest.approx(20.0 * 1.03, abs=4 * noise)
    last = samples[-1]
    noise = model.yaw_rate_noise_rad_s * math.sqrt(dt * last.stamp_s)
    assert last.yaw == pytest.approx(model.yaw_bias_rad_s * last.stamp_s, abs=4 * noise)
    # The stated covariance covers the drift: the errors are within 3 sigma
    # (the systematic errors are stated at their size, so 1 sigma each).
    sigma = np.sqrt(np.diag(last.pose_covariance)[[0, 1, 5]])
    drift = np.array([last.x - 20.0, last.y, last.yaw])
    assert np.all(np.abs(drift) < 3.0 * sigma)
    assert sigma[0] >= 0.03 * 20.0 and sigma[1] > 0.1
    assert sigma[2] == pytest.approx(model.yaw_bias_rad_s * last.stamp_s, rel=0.05)
    np.testing.assert_allclose(last.twist_covariance[5, 5], 0.01 ** 2 + 0.004 ** 2, rtol=0.01)


def test_odometry_is_reproducible_however_it_is_polled():
    route = straight_then_stand(distance=2.0, stand_s=1.0)
    whole = OdometrySim(route, seed=9).advance_to(route.duration_s)
    polled = OdometrySim(route, seed=9)
    pieces = []
    for t in np.arange(0.0, route.duration_s, 0.37):
        pieces.extend(polled.advance_to(float(t)))
    pieces.extend(polled.advance_to(route.duration_s))
    assert [s.stamp_s for s in pieces] == [s.stamp_s for s in whole]
    assert [s.x for s in pieces] == [s.x for s in whole]
    other = OdometrySim(route, seed=10).advance_to(route.duration_s)
    assert other[-1].x != whole[-1].x
    assert polled.advance_to(route.duration_s) == []
