"""Pan/tilt head kinematics, base pose from the camera pose, joint state matching."""

import array
import math

from hypothesis import given, settings, strategies as st
import numpy as np
from pattern_locator.errors import ConfigError, PatternLocatorError
from pattern_locator.localization.head import (angles_from_joint_state, base_pose_from_camera,
                                               covariance_to_base, head_angles, HeadGeometry,
                                               HeadStateError, JointStateBuffer, R_TILT_OPTICAL,
                                               up_in_camera)
from pattern_locator.vision.geometry import look_at, Pose, rodrigues
from pattern_locator.vision.pose_exact import PosePrior
import pytest

HEAD = HeadGeometry()
DEG = math.pi / 180.0


def wall_card(x, y, height, facing_rad):
    """Return ``T_room_card`` of an upright card: x along the wall, y up, z into the room."""
    z_axis = np.array([math.cos(facing_rad), math.sin(facing_rad), 0.0])
    y_axis = np.array([0.0, 0.0, 1.0])
    return Pose(np.column_stack([np.cross(y_axis, z_axis), y_axis, z_axis]),
                np.array([x, y, height]))


def random_base(rng, level=False):
    """Return a random ``T_room_base``: any heading, a little roll/pitch unless level."""
    yaw = rodrigues(np.array([0.0, 0.0, rng.uniform(-math.pi, math.pi)]))
    tip = np.zeros(3) if level else np.append(rng.normal(0.0, 0.05, 2), 0.0)
    return Pose(rodrigues(tip) @ yaw, np.array([rng.uniform(0, 10), rng.uniform(0, 5),
                                                rng.uniform(-0.2, 0.5)]))


def random_angles(rng, head=HEAD):
    return rng.uniform(*head.pan_limits_rad), rng.uniform(*head.tilt_limits_rad)


# Kinematics ------------------------------------------------------------------

def test_optical_rotation_is_the_standard_rpy():
    def rot_x(a):
        return np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)],
                         [0, math.sin(a), math.cos(a)]])

    def rot_z(a):
        return np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0],
                         [0, 0, 1]])

    # Fixed-axis roll, pitch, yaw = (-pi/2, 0, -pi/2): R = Rz(yaw) Ry(pitch) Rx(roll).
    np.testing.assert_allclose(R_TILT_OPTICAL, rot_z(-math.pi / 2) @ rot_x(-math.pi / 2),
                               atol=1e-15)


def test_zero_angles_look_forward_with_image_down_world_down():
    T = HEAD.T_base_camera(0.0, 0.0)
    np.testing.assert_allclose(T.R[:, 2], [1, 0, 0], atol=1e-15)   # optical axis: base +x
    np.testing.assert_allclose(T.R[:, 1], [0, 0, -1], atol=1e-15)  # image down: base -z
    np.testing.assert_allclose(T.R[:, 0], [0, -1, 0], atol=1e-15)  # image right: base -y
    np.testing.assert_allclose(T.t, [0.03, 0.0, 1.10], atol=1e-15)
    assert np.linalg.det(T.R) == pytest.approx(1.0)


def test_positive_pan_turns_left():
    T = HEAD.T_base_camera(90 * DEG, 0.0)
    np.testing.assert_allclose(T.R[:, 2], [0, 1, 0], atol=1e-15)   # looks along base +y
    np.testing.assert_allclose(T.R[:, 0], [1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(T.t, [0.0, 0.03, 1.10], atol=1e-15)
    assert HEAD.T_base_camera(-30 * DEG, 0.0).R[1, 2] < 0.0       # negative pan: right


def test_positive_tilt_looks_up():
    T = HEAD.T_base_camera(0.0, 10 * DEG)
    axis = T.R[:, 2]
    assert axis[2] > 0.0
    np.testing.assert_allclose(axis, [math.cos(10 * DEG), 0.0, math.sin(10 * DEG)],
                               atol=1e-15)
    # The image stays upright: its x axis is horizontal.
    assert T.R[2, 0] == pytest.approx(0.0, abs=1e-15)
    assert HEAD.T_base_camera(0.0, -10 * DEG).R[2, 2] < 0.0


def test_matches_an_upright_look_at_camera():
    """Optical centre from the offsets and the axis from the angles, built independently."""
    rng = np.random.default_rng(1)
    head = HeadGeometry((0.1, -0.02, 0.8), (0.01, 0.015, 0.06), (0.04, 0.01, 0.03))
    for _ in range(20):
        pan, tilt = random_angles(rng, head)
        cp, sp, ct, st = math.cos(pan), math.sin(pan), math.cos(tilt), math.sin(tilt)
        a, b, c = head.tilt_to_optical_xyz
        in_pan = np.array(head.pan_to_tilt_xyz) + [a * ct - c * st, b, a * st + c * ct]
        eye = np.array(head.base_to_pan_xyz) + [cp * in_pan[0] - sp * in_pan[1],
                                                sp * in_pan[0] + cp * in_pan[1], in_pan[2]]
        direction = np.array([ct * cp, ct * sp, st])
        expected = look_at(eye, eye + direction, up=(0.0, 0.0, 1.0))
        T = head.T_base_camera(pan, tilt)
        np.testing.assert_allclose(T.R, expected.R, atol=1e-12)
        np.testing.assert_allclose(T.t, expected.t, atol=1e-12)


def test_chain_composes_the_links():
    pan, tilt = 0.4, -0.2
    T = HEAD.T_base_pan(pan) @ HEAD.T_pan_tilt(tilt) @ HEAD.T_tilt_optical()
    np.testing.assert_allclose(HEAD.T_base_camera(pan, tilt).matrix(), T.matrix())
    # The pan joint turns about its z, the tilt joint about its y (sign: -y).
    np.testing.assert_allclose(HEAD.T_base_pan(pan).R[:, 2], [0, 0, 1])
    np.testing.assert_allclose(HEAD.T_pan_tilt(tilt).R[:, 1], [0, 1, 0])
    np.testing.assert_allclose(HEAD.T_pan_tilt(tilt).R, rodrigues(np.array([0, -tilt, 0])),
                               atol=1e-15)


def test_camera_height_matches_the_offsets():
    assert HEAD.camera_height() == pytest.approx(1.10, abs=1e-12)
    for tilt in np.linspace(-25 * DEG, 25 * DEG, 7):
        expected = 1.0 + 0.05 + 0.03 * math.sin(tilt) + 0.05 * math.cos(tilt)
        for pan in (-1.5, 0.0, 0.7):
            assert HEAD.camera_height(pan, tilt) == pytest.approx(expected, abs=1e-12)
    tall = HeadGeometry(base_to_pan_xyz=(0.2, 0.0, 1.4))
    assert tall.camera_height() == pytest.approx(1.50, abs=1e-12)


def test_limits_are_the_evi_d31_travel():
    assert HEAD.pan_limits_rad == pytest.approx((-100 * DEG, 100 * DEG))
    assert HEAD.tilt_limits_rad == pytest.approx((-25 * DEG, 25 * DEG))
    assert HEAD.within_limits(99 * DEG, -24 * DEG)
    assert not HEAD.within_limits(101 * DEG, 0.0)
    assert not HEAD.within_limits(0.0, 26 * DEG)
    assert HEAD.within_limits(0.0, 26 * DEG, tolerance_rad=2 * DEG)
    assert HEAD.clamp(2.0, -1.0) == pytest.approx((100 * DEG, -25 * DEG))
    assert HEAD.clamp(0.1, 0.2) == (0.1, 0.2)


def test_geometry_accepts_lists_and_rejects_bad_values():
    head = HeadGeometry(base_to_pan_xyz=[0, 0, 2], pan_limits_rad=[-1, 1])
    assert head.base_to_pan_xyz == (0.0, 0.0, 2.0)
    assert head.pan_limits_rad == (-1.0, 1.0)
    hash(head)  # frozen and hashable after normalising
    with pytest.raises(ConfigError, match='base_to_pan_xyz'):
        HeadGeometry(base_to_pan_xyz=(0.0, 1.0))
    with pytest.raises(ConfigError, match='tilt_to_optical_xyz'):
        HeadGeometry(tilt_to_optical_xyz=(0.0, float('nan'), 0.0))
    with pytest.raises(ConfigError, match='pan_to_tilt_xyz'):
        HeadGeometry(pan_to_tilt_xyz='abc')
    with pytest.raises(ConfigError, match='tilt_limits_rad'):
        HeadGeometry(tilt_limits_rad=(0.5, -0.5))


def test_aim_angles_put_the_target_on_the_optical_axis():
    rng = np.random.default_rng(2)
    offset_head = HeadGeometry((0.1, -0.02, 0.8), (0.01, 0.015, 0.06), (0.04, 0.01, 0.03))
    for head in (HEAD, offset_head):
        for _ in range(30):
            target = np.array([rng.uniform(-6, 6), rng.uniform(-6, 6), rng.uniform(0.0, 2.5)])
            if np.hypot(*target[:2]) < 0.5:
                continue
            pan, tilt = head.aim_angles(target)
            seen = head.T_base_camera(pan, tilt).inverse().apply(target[None])[0]
            assert seen[2] > 0.0
            assert np.hypot(seen[0], seen[1]) < 1e-9 * seen[2]
    # A card at 2.15 m seen from 3 m away needs the head tilted up.
    pan, tilt = HEAD.aim_angles([0.0, 3.0, 2.15])
    assert pan == pytest.approx(90 * DEG)
    assert 15 * DEG < tilt < 25 * DEG
    with pytest.raises(ValueError, match='too close'):
        offset_head.aim_angles([0.1, -0.02, 0.5])


# Base pose -------------------------------------------------------------------

def test_base_pose_from_camera_round_trip():
    rng = np.random.default_rng(3)
    for _ in range(50):
        T_room_base = random_base(rng)
        T_room_card = wall_card(rng.uniform(0, 10), rng.uniform(0, 5), 2.15,
                                rng.uniform(-math.pi, math.pi))
        pan, tilt = random_angles(rng)
        # Truth chain room <- base <- pan <- tilt <- optical, and the card in the room.
        T_room_camera = (T_room_base @ HEAD.T_base_pan(pan) @ HEAD.T_pan_tilt(tilt)
                         @ HEAD.T_tilt_optical())
        T_camera_card = T_room_camera.inverse() @ T_room_card
        found = base_pose_from_camera(T_room_card, T_camera_card, HEAD, pan, tilt)
        np.testing.assert_allclose(found.R, T_room_base.R, atol=1e-12)
        np.testing.assert_allclose(found.t, T_room_base.t, atol=1e-12)


def test_base_pose_in_the_building_frame():
    rng = np.random.default_rng(4)
    T_building_room = Pose(rodrigues(np.array([0.0, 0.0, 0.7])), np.array([20.0, -3.0, 6.5]))
    T_room_base = random_base(rng, level=True)
    T_room_card = wall_card(0.0, 2.5, 2.15, 0.0)
    pan, tilt = 0.3, 0.1
    T_camera_card = (T_room_base @ HEAD.T_base_camera(pan, tilt)).inverse() @ T_room_card
    found = base_pose_from_camera(T_building_room @ T_room_card, T_camera_card, HEAD, pan, tilt)
    expected = T_building_room @ T_room_base
    np.testing.assert_allclose(found.matrix(), expected.matrix(), atol=1e-12)


def test_wrong_angles_move_the_base():
    """The head angles matter: a 1 degree pan error turns the base by 1 degree."""
    T_room_card = wall_card(0.0, 2.5, 2.15, 0.0)
    T_room_base = Pose(np.eye(3), np.array([4.0, 2.5, 0.0]))
    T_camera_card = (T_room_base @ HEAD.T_base_camera(math.pi, 0.2)).inverse() @ T_room_card
    found = base_pose_from_camera(T_room_card, T_camera_card, HEAD, math.pi + DEG, 0.2)
    yaw = math.atan2(found.R[1, 0], found.R[0, 0])
    assert yaw == pytest.approx(-DEG, abs=1e-9)


# Up in the camera --------------------------------------------------------------

def test_up_in_camera_level_base():
    np.testing.assert_allclose(up_in_camera(HEAD, 0.0, 0.0), [0, -1, 0], atol=1e-15)
    for tilt in (-20 * DEG, 10 * DEG, 25 * DEG):
        for pan in (-1.0, 0.0, 1.5):
            up = up_in_camera(HEAD, pan, tilt)
            np.testing.assert_allclose(up, [0.0, -math.cos(tilt), math.sin(tilt)],
                                       atol=1e-15)
            np.testing.assert_allclose(up, HEAD.T_base_camera(pan, tilt).R.T @ [0, 0, 1],
                                       atol=1e-15)
    # Looking up, the world's up leans forward (towards +z) from the image's -y.
    assert up_in_camera(HEAD, 0.0, 10 * DEG)[2] > 0.0


def test_up_in_camera_is_the_card_up_seen_by_the_camera():
    rng = np.random.default_rng(5)
    for level in (True, False):
        for _ in range(20):
            T_room_base = random_base(rng, level=level)
            T_room_card = wall_card(5.0, 0.0, 2.15, math.pi / 2)
            pan, tilt = random_angles(rng)
            T_camera_card = ((T_room_base @ HEAD.T_base_camera(pan, tilt)).inverse()
                             @ T_room_card)
            # The world's up in base_link: exact on a ramp, (0, 0, 1) when level.
            base_up = T_room_base.R.T @ [0.0, 0.0, 1.0]
            up = up_in_camera(HEAD, pan, tilt, base_up=base_up * 3.0)
            np.testing.assert_allclose(up, T_camera_card.R[:, 1], atol=1e-12)
            assert PosePrior(up_in_camera=up).penalty(T_camera_card) < 1e-12
            if level:
                np.testing.assert_allclose(up_in_camera(HEAD, pan, tilt), up, atol=1e-12)
    with pytest.raises(ValueError):
        up_in_camera(HEAD, 0.0, 0.0, base_up=(0.0, 0.0, 0.0))


# Covariance ----------------------------------------------------------------------

def _perturbed_base(T_room_card, T_camera_card, pan, tilt, delta):
    """Return the base pose after moving the camera by delta (position, rotation, angles)."""
    T_card_camera = T_camera_card.inverse()
    moved = Pose(rodrigues(delta[3:6]) @ T_card_camera.R, T_card_camera.t + delta[:3])
    return base_pose_from_camera(T_room_card, moved.inverse(), HEAD, pan + delta[6],
                                 tilt + delta[7])


@pytest.mark.parametrize('angle_sigma', [(0.0, 0.0), (2e-3, 3e-3)])
def test_covariance_to_base_matches_monte_carlo(angle_sigma):
    rng = np.random.default_rng(6)
    T_room_base = random_base(rng)
    T_room_card = wall_card(3.0, 5.0, 2.15, -math.pi / 2)
    pan, tilt = 0.6, 0.3
    T_camera_card = (T_room_base @ HEAD.T_base_camera(pan, tilt)).inverse() @ T_room_card
    # A correlated camera covariance of a realistic size: cm and mrad.
    L = np.diag([0.01, 0.02, 0.015, 3e-3, 2e-3, 4e-3]) @ (np.eye(6) + 0.4 * rng.normal(
        size=(6, 6)))
    cov = L @ L.T
    predicted = covariance_to_base(cov, T_room_card, T_camera_card, HEAD, pan, tilt,
                                   angle_sigma_rad=angle_sigma)
    n = 6000
    deltas = np.zeros((n, 8))
    deltas[:, :6] = rng.multivariate_normal(np.zeros(6), cov, size=n)
    deltas[:, 6:] = rng.normal(size=(n, 2)) * angle_sigma
    truth = base_pose_from_camera(T_room_card, T_camera_card, HEAD, pan, tilt)
    np.testing.assert_allclose(truth.matrix(), T_room_base.matrix(), atol=1e-12)
    samples = np.zeros((n, 6))
    for k, delta in enumerate(deltas):
        base = _perturbed_base(T_room_card, T_camera_card, pan, tilt, delta)
        samples[k, :3] = base.t - truth.t
        samples[k, 3:] = Pose(base.R @ truth.R.T, np.zeros(3)).rvec()
    empirical = np.cov(samples.T)
    # Compare on the correlation scale: sampling error ~ 1/sqrt(n) = 0.013.
    scale = np.sqrt(np.outer(np.diag(predicted), np.diag(predicted)))
    assert np.max(np.abs(empirical - predicted) / scale) < 0.06
    np.testing.assert_allclose(predicted, predicted.T)


def test_covariance_to_base_lever_arm():
    """A pure camera rotation moves the base by the lever arm: zero at the optical centre."""
    head = HeadGeometry((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    T_room_card = wall_card(0.0, 0.0, 2.15, 0.0)
    T_camera_card = (Pose(np.eye(3), np.array([3.0, 0.0, 2.15]))
                     @ head.T_base_camera(math.pi, 0.0)).inverse() @ T_room_card
    cov = np.diag([0.0, 0.0, 0.0, 1e-4, 1e-4, 1e-4])
    out = covariance_to_base(cov, T_room_card, T_camera_card, head, math.pi, 0.0)
    np.testing.assert_allclose(out[:3, :3], 0.0, atol=1e-18)
    np.testing.assert_allclose(out[3:, 3:], 1e-4 * np.eye(3), atol=1e-15)
    with pytest.raises(ValueError, match='6x6'):
        covariance_to_base(np.eye(3), T_room_card, T_camera_card, head, 0.0, 0.0)


# Joint states --------------------------------------------------------------------

def test_buffer_interpolates_between_samples():
    buf = JointStateBuffer()
    buf.add(10.0, 0.1, -0.2)
    buf.add(10.1, 0.3, 0.0)
    assert buf.at(10.05) == pytest.approx((0.2, -0.1))
    assert buf.at(10.075) == pytest.approx((0.25, -0.05))
    assert buf.at(10.0) == pytest.approx((0.1, -0.2))
    assert buf.at(10.1) == pytest.approx((0.3, 0.0))


def test_buffer_holds_the_last_sample_briefly():
    buf = JointStateBuffer(max_age_s=0.5)
    buf.add(10.0, 0.1, 0.2)
    assert buf.at(10.0) == (0.1, 0.2)
    assert buf.at(10.4) == (0.1, 0.2)
    with pytest.raises(HeadStateError,
                       match=r'joint states stale: last at 10\.000 s, image at 10\.600 s'):
        buf.at(10.6)


def test_buffer_without_samples():
    buf = JointStateBuffer()
    assert len(buf) == 0 and buf.latest() is None
    with pytest.raises(HeadStateError, match='no joint states received'):
        buf.at(1.0)
    assert issubclass(HeadStateError, PatternLocatorError)


def test_buffer_image_older_than_the_history():
    buf = JointStateBuffer(history_s=1.0)
    for k in range(31):
        buf.add(10.0 + 0.1 * k, 0.01 * k, 0.0)
    # Samples more than history_s behind the newest (13.0) are dropped, but
    # the one at the cut is kept so the whole window stays bracketed.
    assert buf.at(12.05) == pytest.approx((0.205, 0.0))
    assert buf.at(12.0) == pytest.approx((0.2, 0.0))
    with pytest.raises(HeadStateError, match=r'image at 11\.500 s is older than the joint '
                                             r'state history \(oldest sample at 12\.000 s\)'):
        buf.at(11.5)
    assert len(buf) == 11


def test_buffer_gap_between_samples():
    buf = JointStateBuffer(max_gap_s=0.25)
    buf.add(10.0, 0.0, 0.0)
    buf.add(10.2, 0.2, 0.0)
    buf.add(10.6, 0.6, 0.0)
    assert buf.at(10.1) == pytest.approx((0.1, 0.0))
    with pytest.raises(HeadStateError, match=r'gap in joint states: no sample between '
                                             r'10\.200 s and 10\.600 s'):
        buf.at(10.4)
    # A late sample that fills the gap makes it usable.
    buf.add(10.4, 0.4, 0.1)
    assert buf.at(10.5) == pytest.approx((0.5, 0.05))


def test_buffer_out_of_order_and_duplicates():
    buf = JointStateBuffer()
    buf.add(10.2, 0.2, 0.0)
    buf.add(10.0, 0.0, 0.0)
    buf.add(10.1, 0.5, 0.0)
    assert buf.at(10.05) == pytest.approx((0.25, 0.0))
    assert buf.latest() == (10.2, 0.2, 0.0)
    buf.add(10.1, 0.1, 0.3)                      # same stamp: replaces
    assert len(buf) == 3
    assert buf.at(10.1) == pytest.approx((0.1, 0.3))
    assert buf.at(10.15) == pytest.approx((0.15, 0.15))
    buf.add(5.0, 1.0, 0.4)                       # older than the history: dropped
    assert len(buf) == 3
    buf.clear()
    with pytest.raises(HeadStateError, match='no joint states received'):
        buf.at(10.1)


def test_buffer_rejects_bad_values():
    buf = JointStateBuffer()
    with pytest.raises(HeadStateError, match='not finite'):
        buf.add(1.0, float('nan'), 0.0)
    with pytest.raises(HeadStateError, match='not finite'):
        buf.add(float('inf'), 0.0, 0.0)
    assert len(buf) == 0
    with pytest.raises(ConfigError, match='max_gap_s'):
        JointStateBuffer(max_gap_s=0.0)
    with pytest.raises(ConfigError, match='history_s'):
        JointStateBuffer(history_s=float('nan'))


def test_angles_from_joint_state():
    names = ['camera_zoom', 'camera_tilt', 'camera_pan']
    assert angles_from_joint_state(names, [300.0, -0.1, 0.4]) == (0.4, -0.1)
    assert angles_from_joint_state(['p', 't'], [1.0, 0.2], pan_joint='p',
                                   tilt_joint='t') == (1.0, 0.2)
    assert angles_from_joint_state(array_names(), array.array('d', [0.1, 0.2])) == (0.1, 0.2)
    with pytest.raises(HeadStateError, match="joint 'camera_tilt' missing"):
        angles_from_joint_state(['camera_pan'], [0.0])
    with pytest.raises(HeadStateError, match="joint 'camera_pan' missing"):
        angles_from_joint_state([], [])
    with pytest.raises(HeadStateError, match="joint 'camera_pan' position is not a number"):
        angles_from_joint_state(['camera_pan', 'camera_tilt'], [float('nan'), 0.0])
    with pytest.raises(HeadStateError, match='2 names but 1 positions'):
        angles_from_joint_state(['camera_pan', 'camera_tilt'], [0.0])


def array_names():
    return ['camera_pan', 'camera_tilt']


def test_duplicate_joint_names_are_refused():
    # Seen: duplicate names, the first one used, a pose 0.31 m and 30 deg off.
    names = ['camera_pan', 'camera_tilt', 'camera_pan']
    with pytest.raises(HeadStateError, match="names 'camera_pan' twice"):
        angles_from_joint_state(names, [0.0, 0.1, 0.5])
    # Any joint named twice makes the message untrustworthy.
    with pytest.raises(HeadStateError, match="names 'camera_zoom' twice"):
        angles_from_joint_state(['camera_zoom', 'camera_pan', 'camera_tilt', 'camera_zoom'],
                                [1.0, 0.0, 0.0, 2.0])


@pytest.mark.parametrize('pan, tilt, words', [
    # Seen: pan = 1e6 rad accepted; a driver's malformed replies gave pan
    # -65 rad and 113.6 deg, tilt 33 deg.
    (1e6, 0.0, 'pan 5.72958e\\+07 deg is outside'),
    (-65.0, 0.0, 'pan'),
    (math.radians(113.6), 0.0, 'pan 113.6 deg'),
    (0.0, math.radians(33.0), 'tilt 33 deg is outside the head travel -25..25 deg'),
])
def test_angles_outside_the_travel_are_refused(pan, tilt, words):
    with pytest.raises(HeadStateError, match=words):
        angles_from_joint_state(['camera_pan', 'camera_tilt'], [pan, tilt])
    buf = JointStateBuffer()
    with pytest.raises(HeadStateError, match=words):
        buf.add(1.0, pan, tilt)
    assert len(buf) == 0


def test_travel_margin_and_a_wider_head():
    edge = math.radians(100.0 + 4.9)
    assert angles_from_joint_state(array_names(), [edge, 0.0])[0] == edge
    with pytest.raises(HeadStateError):
        angles_from_joint_state(array_names(), [edge, 0.0], margin_rad=0.0)
    wide = HeadGeometry(pan_limits_rad=(-3.0, 3.0), tilt_limits_rad=(-1.5, 1.5))
    assert angles_from_joint_state(array_names(), [2.9, 1.4], head=wide) == (2.9, 1.4)
    buf = JointStateBuffer(head=wide)
    buf.add(1.0, 2.9, 1.4)
    assert buf.at(1.0) == (2.9, 1.4)


@pytest.mark.parametrize('names, positions, words', [
    ([1, 2], [0.0, 0.0], 'names must be text'),
    (['camera_pan', 'camera_tilt'], ['0.1', 0.0], 'not a number'),
    (['camera_pan', 'camera_tilt'], [True, 0.0], 'not a number'),
    (['x' * 500] * 2, [0.0, 0.0], 'twice'),
    (['j%d' % i for i in range(1000)], [0.0] * 1000, 'more than 256'),
    (None, [], 'must be sequences'),
])
def test_malformed_joint_states_are_one_line_errors(names, positions, words):
    with pytest.raises(HeadStateError, match=words) as error:
        angles_from_joint_state(names, positions)
    assert '\n' not in str(error.value) and len(str(error.value)) < 250


JOINT_NAMES = st.sampled_from(['camera_pan', 'camera_tilt', 'camera_zoom', '', 'x'])
POSITIONS = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.floats(-2.0, 2.0),
                      st.integers(-10, 10), st.booleans(), st.none(), st.text(max_size=2))


@settings(max_examples=100, deadline=None, derandomize=True, database=None)
@given(names=st.lists(JOINT_NAMES, max_size=5), positions=st.lists(POSITIONS, max_size=5))
def test_any_joint_state_gives_angles_within_travel_or_a_head_state_error(names, positions):
    try:
        pan, tilt = angles_from_joint_state(names, positions)
    except HeadStateError as exc:
        assert '\n' not in str(exc)
        return
    assert len(set(names)) == len(names) and len(names) == len(positions)
    assert positions[names.index('camera_pan')] == pan
    assert HEAD.within_limits(pan, tilt, tolerance_rad=math.radians(5.0))


@settings(max_examples=40, deadline=None, derandomize=True, database=None)
@given(samples=st.lists(st.tuples(st.floats(0.0, 3.0), POSITIONS, POSITIONS), max_size=20),
       stamps=st.lists(st.floats(-1.0, 5.0), max_size=5))
def test_the_buffer_never_holds_or_gives_a_bad_angle(samples, stamps):
    buf = JointStateBuffer()
    for stamp, pan, tilt in samples:
        try:
            buf.add(stamp, pan, tilt)
        except HeadStateError:
            pass
    for stamp in stamps:
        try:
            pan, tilt = buf.at(stamp)
        except HeadStateError:
            continue
        assert math.isfinite(pan) and math.isfinite(tilt)
        assert HEAD.within_limits(pan, tilt, tolerance_rad=math.radians(5.0))


def test_head_angles_fixed_only_without_a_topic():
    assert head_angles(10.0, None, (0.1, 0.2)) == (0.1, 0.2)
    buf = JointStateBuffer()
    with pytest.raises(HeadStateError, match='no joint states received'):
        head_angles(10.0, buf, (0.1, 0.2))
    buf.add(10.0, -0.3, 0.05)
    assert head_angles(10.1, buf, (0.1, 0.2)) == (-0.3, 0.05)
    with pytest.raises(HeadStateError, match='stale'):
        head_angles(11.0, buf, (0.1, 0.2))
