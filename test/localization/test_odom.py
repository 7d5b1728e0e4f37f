"""Odometry between fixes: the buffer's motions against exact poses, the bridge's growth."""

import functools
import math

import numpy as np
from pattern_locator.errors import ConfigError
from pattern_locator.localization.building import load_building
from pattern_locator.localization.gates import compose_with_motion, pose_in_building
from pattern_locator.localization.odom import (BaseTwist, odom_pose, OdomBridge, OdomBuffer,
                                               OdomNoise)
from pattern_locator.resources import config_path
from pattern_locator.sim.drive import DriveRoute, Waypoint
from pattern_locator.sim.odometry import OdometryModel, OdometrySim
from pattern_locator.vision.geometry import Pose, rodrigues, rotation_vector
import pytest

FLOOR = load_building(config_path('floor_building.yaml'))
NO_FLOOR = OdomNoise(0.0, 0.0, 0.0, 0.0, 0.0)


def arc(t):
    """Return the exact pose of a base driving a left-hand circle of radius 2 m at 0.5 m/s."""
    yaw = 0.25 * t
    return odom_pose(2.0 * math.sin(yaw), 2.0 * (1.0 - math.cos(yaw)), yaw)


def filled(stamps, noise=NO_FLOOR, covariance=None):
    buffer = OdomBuffer(noise=noise)
    for t in stamps:
        buffer.add(t, arc(t), None if covariance is None else covariance(t))
    return buffer


def close(a: Pose, b: Pose, position=1e-9, angle=1e-9):
    return (np.linalg.norm(a.t - b.t) <= position
            and np.linalg.norm(rotation_vector(a.R.T @ b.R)) <= angle)


def test_motion_between_samples_is_the_exact_relative_pose():
    buffer = filled(np.arange(0.0, 10.01, 0.02))
    for t0, t1 in ((0.0, 4.0), (2.5, 9.9), (6.0, 1.0)):
        motion = buffer.motion_between(t0, t1)
        assert motion.since_stamp_s == t0
        assert close(motion.T_start_end, arc(t0).inverse() @ arc(t1))


def test_motion_between_interpolates_between_samples():
    # 50 Hz samples of a 0.25 rad/s arc: linear interpolation is good to ~0.1 mm.
    buffer = filled(np.arange(0.0, 10.01, 0.02))
    motion = buffer.motion_between(1.013, 7.377)
    assert close(motion.T_start_end, arc(1.013).inverse() @ arc(7.377), 2e-4, 2e-5)


def test_a_motion_composed_with_its_start_lands_on_its_end():
    buffer = filled(np.arange(0.0, 10.01, 0.02))
    T_map_odom = Pose(rodrigues([0.0, 0.0, 0.7]), np.array([3.0, -1.0, 12.0]))
    motion = buffer.motion_between(2.0, 8.0)
    start = T_map_odom @ arc(2.0)
    end, _ = compose_with_motion(start, np.eye(6) * 1e-4, motion.T_start_end, motion.covariance)
    assert close(end, T_map_odom @ arc(8.0), 1e-9, 1e-9)


def test_not_covered_stamps_give_none():
    buffer = OdomBuffer(max_gap_s=0.5, max_extrapolation_s=0.1)
    for t in (0.0, 0.1, 0.2, 1.0, 1.1):                     # a gap of 0.8 s
        buffer.add(t, arc(t))
    assert buffer.motion_between(0.0, 0.2) is not None
    assert buffer.motion_between(0.0, 0.6) is None          # in the gap
    assert buffer.motion_between(0.0, 1.05) is not None      # after it
    assert buffer.motion_between(-0.5, 0.1) is None         # before the first sample
    assert buffer.motion_between(0.0, 1.15) is not None     # held 50 ms past the last
    assert buffer.motion_between(0.0, 1.5) is None          # too far past it
    assert OdomBuffer().motion_between(0.0, 1.0) is None


def test_the_motion_covariance_is_what_the_odometry_grew_by():
    # Dead reckoning whose covariance grows linearly in time: the motion's own
    # covariance is the difference (the start's heading error swung over the path
    # removed), turned into the start's base frame.
    growth = np.diag([1e-4, 4e-4, 1e-6, 1e-6, 1e-6, 2e-5])
    buffer = filled(np.arange(0.0, 10.01, 0.02), covariance=lambda t: growth * t)
    motion = buffer.motion_between(0.0, 4.0)
    R0 = arc(0.0).R
    expected = np.zeros((6, 6))
    expected[:3, :3] = R0.T @ (growth * 4.0)[:3, :3] @ R0
    expected[3:, 3:] = R0.T @ (growth * 4.0)[3:, 3:] @ R0
    assert np.allclose(motion.covariance, expected, atol=1e-9)
    # From a later start: the start's own uncertainty is not the motion's.
    later = buffer.motion_between(4.0, 8.0).covariance
    assert np.all(np.linalg.eigvalsh(later) >= -1e-12)
    assert np.trace(later) < np.trace(growth * 8.0)


def test_the_floor_covers_odometry_that_publishes_no_covariance():
    buffer = filled(np.arange(0.0, 10.01, 0.02), noise=OdomNoise())
    motion = buffer.motion_between(0.0, 8.0)                # 4 m and 2 rad
    sigma_xy = math.sqrt(motion.covariance[0, 0])
    assert sigma_xy == pytest.approx(0.01 * np.linalg.norm(motion.T_start_end.t), rel=1e-6)
    sigma_yaw = math.sqrt(motion.covariance[5, 5])
    assert sigma_yaw == pytest.approx(0.005 * 2.0 + 0.001 * 8.0, rel=1e-6)
    # A standing robot: still an invertible covariance.
    standing = OdomBuffer()
    for t in np.arange(0.0, 1.0, 0.02):
        standing.add(t, odom_pose(1.0, 2.0, 0.3), np.zeros((6, 6)))
    np.linalg.cholesky(standing.motion_between(0.0, 0.9).covariance)


def test_twist_from_messages_or_from_poses():
    buffer = OdomBuffer()
    for t in np.arange(0.0, 4.0, 0.02):
        buffer.add(t, arc(t))
    twist = buffer.twist_at(2.0)
    assert twist.linear[0] == pytest.approx(0.5, abs=1e-3)
    assert twist.angular[2] == pytest.approx(0.25, abs=1e-3)
    given = OdomBuffer(max_gap_s=2.0)
    given.add(0.0, arc(0.0), twist=BaseTwist((0.4, 0.0, 0.0), (0.0, 0.0, 0.1)))
    given.add(1.0, arc(1.0), twist=BaseTwist((0.6, 0.0, 0.0), (0.0, 0.0, 0.3)))
    halfway = given.twist_at(0.5)
    assert halfway.linear[0] == pytest.approx(0.5) and halfway.yaw_rate_rad_s == pytest.approx(0.2)


def test_bad_samples_are_refused_and_a_clock_jump_starts_over():
    buffer = OdomBuffer()
    with pytest.raises(ConfigError, match='not finite'):
        buffer.add(0.0, odom_pose(math.nan, 0.0, 0.0))
    with pytest.raises(ConfigError, match='not a rotation'):
        buffer.add(0.0, Pose(np.eye(3) * 2.0, np.zeros(3)))
    with pytest.raises(ConfigError, match='6x6'):
        buffer.add(0.0, odom_pose(0.0, 0.0, 0.0), np.eye(5))
    assert len(buffer) == 0
    for t in np.arange(10.0, 12.0, 0.1):
        buffer.add(t, arc(t))
    buffer.add(0.0, arc(0.0))                                # a bag replayed again
    assert len(buffer) == 1 and buffer.span == (0.0, 0.0)
    # "Unknown" covariance (first element -1, as drivers say it): the floor alone.
    buffer.add(0.1, arc(0.1), np.full((6, 6), -1.0))
    assert buffer.motion_between(0.0, 0.1) is not None


def test_history_is_bounded():
    buffer = OdomBuffer(history_s=5.0)
    for t in np.arange(0.0, 20.0, 0.02):
        buffer.add(t, arc(t))
    assert len(buffer) <= 5.0 / 0.02 + 2
    assert buffer.motion_between(10.0, 19.0) is None
    assert buffer.motion_between(15.0, 19.0) is not None


class Fix:
    """A fix as the localizer returns it (the fields the bridge reads)."""

    def __init__(self, frame_id, T, covariance):
        self.frame_id, self.T_frame_base, self.covariance = frame_id, T, covariance


@functools.lru_cache(maxsize=1)
def _simulated(seconds=45.0, seed=3):
    route = DriveRoute([Waypoint((3.5, 6.3), 0.5), Waypoint((20.0, 6.3), 0.5),
                        Waypoint((23.7, 6.3), 0.3), Waypoint((23.7, 15.0), stop_s=1.0)],
                       z=12.0)
    model = OdometryModel(rate_hz=20.0)
    return route, OdometrySim(route, model, seed).advance_to(seconds)


def simulated():
    """Return a route along the floor's corridors and its odometry (with drift) in a buffer."""
    route, samples = _simulated()
    buffer = OdomBuffer(history_s=120.0)
    for sample in samples:
        buffer.add(sample.stamp_s, sample.T_odom_base, sample.pose_covariance)
    return route, buffer


def test_the_bridge_composes_the_fix_with_the_odometry_and_its_covariance_grows():
    route, buffer = simulated()
    bridge = OdomBridge(buffer, FLOOR)
    assert bridge.at(5.0) is None                            # no fix yet
    start_cov = np.diag([0.01 ** 2] * 3 + [math.radians(0.5) ** 2] * 3)
    bridge.update(Fix('building', route.pose_at(2.0), start_cov), 2.0)
    sigmas, errors = [], []
    for t in (2.0, 5.0, 10.0, 20.0, 30.0, 44.0):
        pose = bridge.at(t)
        assert pose.fix_stamp_s == 2.0 and pose.age_s == pytest.approx(t - 2.0)
        assert pose.frame_id == 'building'
        sigmas.append(math.sqrt(max(np.linalg.eigvalsh(pose.covariance[:3, :3]))))
        error = pose.T_frame_base.t - route.pose_at(t).t
        errors.append(float(error @ np.linalg.solve(pose.covariance[:3, :3], error)))
    assert sigmas[0] == pytest.approx(0.01, rel=1e-3)
    assert all(b > a for a, b in zip(sigmas, sigmas[1:]))    # it grows as the robot drives
    # The drift (2 % scale, a gyro bias) stays inside the grown 95 % ellipse.
    assert max(errors) < 7.81


def test_the_bridge_converts_a_room_fix_and_keeps_the_newest():
    route, buffer = simulated()
    bridge = OdomBridge(buffer, FLOOR)
    room = FLOOR.room(4, 9)
    T_room_base = room.T_building_room.inverse() @ route.pose_at(3.0)
    cov = np.diag([1e-4] * 3 + [1e-4] * 3)
    bridge.update(Fix(room.frame, T_room_base, cov), 3.0)
    expected, expected_cov, _ = pose_in_building(T_room_base, cov, room.frame, FLOOR)
    at_fix = bridge.at(3.0)
    assert close(at_fix.T_frame_base, expected, 1e-9, 1e-9)
    assert np.allclose(at_fix.covariance, expected_cov, atol=1e-9)
    bridge.update(Fix('building', route.pose_at(2.5), cov), 2.5)   # older: ignored
    assert bridge.fix_stamp_s == 3.0
    bridge.reset()
    assert bridge.at(4.0) is None


def test_the_bridge_stops_when_it_has_drifted_too_far():
    route, buffer = simulated()
    bridge = OdomBridge(buffer, FLOOR, max_position_sigma_m=0.05)
    bridge.update(Fix('building', route.pose_at(2.0), np.eye(6) * 1e-4), 2.0)
    assert bridge.at(3.0) is not None
    assert bridge.at(44.0) is None
    with pytest.raises(ConfigError):
        OdomBridge(buffer, max_position_sigma_m=0.0)
