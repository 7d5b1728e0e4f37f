"""The plausibility gates on fixes: each gate on poses built here, and continuity over time."""

import math

import numpy as np
from pattern_locator.card.pattern import load_pattern_config
from pattern_locator.errors import ConfigError
from pattern_locator.localization.building import building_from_dict, load_building
from pattern_locator.localization.gates import (BaseMotion, FixGates, GateParameters,
                                                pose_in_building, REASONS)
from pattern_locator.vision.geometry import Pose, rodrigues
import pytest

PATTERN = load_pattern_config()
BUILDING = load_building(None, PATTERN)
ROOM = BUILDING.room(1, 3)                   # 10 x 5 m, its frame turned 180 deg in the building
CARD = BUILDING.card((1, 3, 1))              # on the wall x = 0, facing +x
COV = np.diag([0.02 ** 2] * 3 + [math.radians(0.5) ** 2] * 3)


def base(x, y, yaw_deg=0.0, z=0.0, roll_deg=0.0, pitch_deg=0.0):
    """Return ``T_room_base``: fixed-axis roll, pitch, then yaw, as ROS."""
    R = (rodrigues([0.0, 0.0, math.radians(yaw_deg)])
         @ rodrigues([0.0, math.radians(pitch_deg), 0.0])
         @ rodrigues([math.radians(roll_deg), 0.0, 0.0]))
    return Pose(R, np.array([x, y, z], dtype=float))


def camera_seeing_card(x, y, height=1.1):
    """Return ``T_camera_card`` for a camera at room (x, y, height) looking at CARD."""
    eye = np.array([x, y, height])
    forward = CARD.T_room_card.t - eye
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    T_room_camera = Pose(np.column_stack([right, down, forward]), eye)
    return T_room_camera.inverse() @ CARD.T_room_card


def check(gates, T_room_base, covariance=COV, T_camera_card='auto'):
    if isinstance(T_camera_card, str):
        T_camera_card = camera_seeing_card(*T_room_base.t[:2])
    return gates.check(T_room_base, covariance, ROOM.frame, ROOM, T_camera_card)


def test_a_plausible_fix_passes_every_gate():
    gates = FixGates(BUILDING)
    assert check(gates, base(4.0, 2.5, 180.0)) is None
    assert check(gates, base(4.0, 2.5, 180.0, z=0.3, roll_deg=5.0, pitch_deg=-5.0)) is None
    assert gates.counts() == dict.fromkeys(REASONS, 0)


@pytest.mark.parametrize('pose, words, reason', [
    # Seen: a frame rotated 180 deg published a base 1.8 m above the floor, rolled -160 deg.
    (base(4.0, 2.5, 180.0, z=1.8, roll_deg=-160.0), 'rolled -160.0 deg', 'roll_pitch'),
    (base(4.0, 2.5, 180.0, pitch_deg=20.0), 'pitched 20.0 deg', 'roll_pitch'),
    (base(4.0, 2.5, 180.0, z=1.8), 'base 1.80 m above the floor', 'base_height'),
    (base(4.0, 2.5, 180.0, z=-0.9), 'base -0.90 m', 'base_height'),
    (base(14.0, 2.5, 180.0), 'outside floor_1/room_3', 'outside_footprint'),
    (base(4.0, -3.0, 180.0), 'outside floor_1/room_3', 'outside_footprint'),
])
def test_an_implausible_base_is_refused(pose, words, reason):
    gates = FixGates(BUILDING)
    rejection = check(gates, pose, T_camera_card=camera_seeing_card(4.0, 2.5))
    assert rejection.reason == reason and words in rejection.message
    assert gates.counts()[reason] == 1


def test_footprint_margin_and_modes():
    # Within the margin (0.5 m) of the wall: passes; the building's box is
    # wider than the room; 'off' checks nothing.
    assert check(FixGates(BUILDING), base(10.4, 2.5, 180.0)) is None
    assert check(FixGates(BUILDING), base(10.6, 2.5, 180.0)).reason == 'outside_footprint'
    assert check(FixGates(BUILDING, GateParameters(footprint_margin_m=1.0)),
                 base(10.6, 2.5, 180.0)) is None
    # x = -3 in room 3 is x = 13 in the building (the room is turned): inside
    # the building's box, outside the room.
    building_wide = FixGates(BUILDING, GateParameters(footprint='building'))
    assert check(building_wide, base(-3.0, 2.5, 0.0), T_camera_card=None) is None
    assert check(building_wide, base(-30.0, 2.5, 0.0), T_camera_card=None).reason == \
        'outside_footprint'
    off = FixGates(BUILDING, GateParameters(footprint='off'))
    assert check(off, base(-30.0, 2.5, 0.0), T_camera_card=None) is None


def test_a_room_without_a_size_uses_the_building_and_no_size_checks_nothing():
    data = {'floors': [{'floor': 0, 'rooms': [
        {'room': 1, 'pose': {'position': [0, 0, 0], 'rpy_deg': [0, 0, 0]},
         'size': [10.0, 5.0, 2.5]},
        {'room': 2, 'pose': {'position': [10.0, 0, 0], 'rpy_deg': [0, 0, 0]}}]}]}
    building = building_from_dict(data, PATTERN, 'test')
    gates = FixGates(building)
    room2 = building.room(0, 2)
    assert gates.check(base(-5.0, 2.0), COV, room2.frame, room2) is None   # x = 5 in the box
    assert gates.check(base(5.0, 2.0), COV, room2.frame, room2).reason == 'outside_footprint'
    del data['floors'][0]['rooms'][0]['size']
    unsized = building_from_dict(data, PATTERN, 'test')
    assert FixGates(unsized).check(base(500.0, 2.0), COV, room2.frame) is None


@pytest.mark.parametrize('change, reason, words', [
    (lambda t, c: (Pose(t.R, np.array([np.nan, 0, 0])), c), 'not_finite', 'not finite'),
    (lambda t, c: (t, c + np.diag([np.inf] + [0.0] * 5)), 'not_finite', 'not finite'),
    (lambda t, c: (t, None), 'covariance', 'no 6x6'),
    (lambda t, c: (t, np.eye(3)), 'covariance', 'no 6x6'),
    (lambda t, c: (t, -c), 'covariance', 'not positive definite'),
    (lambda t, c: (t, c + np.triu(np.ones((6, 6)), 1) * 1e-5), 'covariance', 'symmetric'),
    (lambda t, c: (t, np.zeros((6, 6))), 'covariance', 'symmetric'),
    (lambda t, c: (t, c * 1e4), 'covariance', 'uncertain by 2 m'),
])
def test_pose_and_covariance_must_be_finite_and_positive_definite(change, reason, words):
    gates = FixGates(BUILDING)
    T, cov = change(base(4.0, 2.5, 180.0), COV)
    rejection = gates.check(T, cov, ROOM.frame, ROOM)
    assert rejection.reason == reason and words in rejection.message


def test_the_camera_must_be_in_front_of_the_card_at_a_plausible_distance():
    gates = FixGates(BUILDING)
    behind = camera_seeing_card(-2.0, 2.5)           # beyond the wall the card hangs on
    assert check(gates, base(4.0, 2.5, 180.0), T_camera_card=behind).reason == \
        'camera_behind_card'
    # The same camera turned away: the card behind the camera.
    turned = Pose(np.diag([-1.0, 1.0, -1.0]), np.zeros(3)) @ camera_seeing_card(4.0, 2.5)
    assert check(gates, base(4.0, 2.5, 180.0), T_camera_card=turned).reason == \
        'camera_behind_card'
    far = camera_seeing_card(30.0, 2.5)
    assert check(gates, base(4.0, 2.5, 180.0), T_camera_card=far).reason == 'camera_distance'
    near = camera_seeing_card(0.1, 2.5, height=2.15)
    assert check(gates, base(4.0, 2.5, 180.0), T_camera_card=near).reason == 'camera_distance'
    grazing = camera_seeing_card(0.3, 9.0, height=2.15)
    rejection = check(gates, base(4.0, 2.5, 180.0), T_camera_card=grazing)
    assert rejection.reason == 'view_angle' and 'off its normal' in rejection.message


def test_parameters_are_checked():
    for bad in ({'max_speed_m_s': -1.0}, {'max_roll_deg': math.nan}, {'footprint': 'floor'},
                {'confirm_first_fix': 1}, {'max_jump_mahalanobis': '5'},
                {'min_camera_distance_m': 30.0}, {'min_base_height_m': 1.0},
                {'max_flip_probability': 0.6}):
        with pytest.raises(ConfigError, match='gates:'):
            GateParameters(**bad)
    assert GateParameters(min_base_height_m=-1.0).min_base_height_m == -1.0


# Continuity ---------------------------------------------------------------------

def continuity(gates, T, stamp, odometry=None, cov=COV):
    return gates.check_continuity(T, cov, ROOM.frame, stamp, odometry)


def test_the_first_fix_waits_for_a_second_agreeing_image():
    gates = FixGates(BUILDING)
    first = continuity(gates, base(4.0, 2.5, 180.0), 10.0)
    assert first.reason == 'unconfirmed_first'
    assert continuity(gates, base(4.02, 2.5, 181.0), 10.1) is None
    assert gates.last_stamp == 10.1
    # Without the rule, the first fix is returned at once.
    assert continuity(FixGates(BUILDING, GateParameters(confirm_first_fix=False)),
                      base(4.0, 2.5), 10.0) is None


def started(T=None, stamp=10.0, **parameters):
    gates = FixGates(BUILDING, GateParameters(confirm_first_fix=False, **parameters))
    assert continuity(gates, T if T is not None else base(4.0, 2.5, 180.0), stamp) is None
    return gates


def test_motion_within_the_speed_passes_and_a_jump_is_held_back():
    gates = started()
    assert continuity(gates, base(4.08, 2.5, 182.0), 10.1) is None       # 0.8 m/s
    rejection = continuity(gates, base(7.0, 2.5, 180.0), 10.2)            # 29 m/s
    assert rejection.reason == 'jump'
    assert '2.92 m from the last fix' in rejection.message
    # Back where the robot is: continuous with the last fix, returned.
    assert continuity(gates, base(4.1, 2.5, 182.0), 10.3) is None
    # A jump that a second image confirms is returned with the second image.
    assert continuity(gates, base(7.0, 2.5, 180.0), 10.4).reason == 'jump'
    assert continuity(gates, base(7.01, 2.5, 180.0), 10.5) is None
    assert gates.counts()['jump'] == 2


def test_a_confirmation_must_come_soon_and_agree():
    gates = started()
    assert continuity(gates, base(7.0, 2.5, 180.0), 10.1).reason == 'jump'
    # Another jump elsewhere does not confirm the first: it is held in turn.
    assert continuity(gates, base(4.0, 0.5, 180.0), 10.15).reason == 'jump'
    assert continuity(gates, base(7.0, 2.5, 180.0), 10.2).reason == 'jump'
    # Agreeing, but later than confirm_within_s (2 s) and still too far to
    # drive from the last fix (3 m in 2.5 s at 1 m/s).
    assert continuity(gates, base(7.0, 2.5, 180.0), 12.6).reason == 'jump'


def test_time_allows_motion():
    gates = started()
    assert continuity(gates, base(7.0, 2.5, 180.0), 14.0) is None        # 3 m in 4 s
    assert continuity(gates, base(7.0, 2.5, 90.0), 14.1).reason == 'jump'   # 900 deg/s
    assert continuity(gates, base(7.0, 2.5, 90.0), 15.2) is None         # 90 deg in 1.2 s


def test_odometry_replaces_the_speed_limit():
    gates = started()
    still = BaseMotion(10.0, Pose.identity(), np.diag([1e-4] * 3 + [1e-4] * 3))
    # Standing still by odometry: 0.6 m is a jump, though 1 m/s for 1 s allows it.
    assert continuity(gates, base(3.4, 2.5, 180.0), 11.0, still).reason == 'jump'
    assert continuity(gates, base(3.4, 2.5, 180.0), 11.0) is None
    # Odometry says 2 m forward in 0.2 s (heading 180 deg: towards x = 1.4): allowed.
    forward = BaseMotion(11.0, Pose(np.eye(3), np.array([2.0, 0.0, 0.0])),
                         np.diag([0.01] * 3 + [1e-4] * 3))
    assert continuity(gates, base(1.4, 2.5, 180.0), 11.2, forward) is None
    # Odometry from another stamp is not used (the speed limit is).
    stale = BaseMotion(5.0, Pose(np.eye(3), np.array([2.0, 0.0, 0.0])), np.eye(6) * 1e-4)
    assert continuity(gates, base(-0.6, 2.5, 180.0), 11.3, stale).reason == 'jump'


def test_no_stamp_no_continuity_and_a_clock_jump_back_starts_over():
    gates = started()
    assert continuity(gates, base(8.0, 4.0, 0.0), None) is None
    assert gates.last_stamp == 10.0                      # nothing remembered
    # A bag replayed again: continuity starts over, with the first-fix rule.
    gates = FixGates(BUILDING)
    continuity(gates, base(4.0, 2.5), 10.0)
    assert continuity(gates, base(4.0, 2.5), 10.1) is None
    assert continuity(gates, base(8.0, 1.0), 3.0).reason == 'unconfirmed_first'
    assert continuity(gates, base(8.0, 1.0), 3.1) is None
    gates.reset()
    assert gates.last_stamp is None


def test_a_mirrored_card_view_is_a_jump():
    # The mirror image of a card whose code reads the same mirrored gives the
    # camera mirrored about the card's normal: a plausible pose on its own,
    # caught by continuity. (End to end, on rendered images: test_localizer.)
    gates = started(base(4.0, 1.2, 160.0))
    mirrored = base(4.0, 3.8, -160.0)            # y mirrored about the card's y = 2.5
    assert check(gates, mirrored) is None
    assert continuity(gates, mirrored, 10.1).reason == 'jump'


def test_fixes_are_compared_in_the_building_frame():
    # Same place given in the room frame and in the building frame: no jump.
    gates = started()
    T_building, cov, room = pose_in_building(base(4.0, 2.5, 180.0), COV, ROOM.frame, BUILDING)
    assert room is ROOM
    assert gates.check_continuity(T_building, cov, BUILDING.frame, 10.1) is None
    # A room frame with another place: a jump.
    other = BUILDING.room(0, 1)
    assert gates.check_continuity(base(4.0, 2.5, 180.0), COV, other.frame, 10.2).reason == \
        'jump'
