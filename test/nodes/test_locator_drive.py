"""
The locator driving, as a real process over DDS: odometry, odom_bridged, the gaze target.

One locator on the simulated floor's map (``config/floor_building.yaml``)
is fed by this test as by a robot driving west across room 3 of floor 4
at 0.3 m/s: images rendered by ``sim/floor_scene.py`` (the floor's walls
and cards) with their camera_info, joint states bracketing each image,
and exact odometry (nav_msgs/Odometry at 50 Hz). The tests run in order,
along one drive:

* with odometry, ``robot_location/odom_bridged`` carries the last fix
  forward between images, its covariance growing;
* a move that odometry explains is published at once, where the speed
  limit alone (``gates.max_speed_m_s`` 0.1 here) holds it back until a
  second image agrees;
* the target switches to the next card before the current one leaves the
  view (handover); a card predicted visible but not in the image is still
  a target; none is when no card is predicted visible;
* the ``uncertainty.*``, ``gaze.*`` and odometry parameters are refused or
  applied through the parameter services.
"""

import math
from pathlib import Path

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped, PoseStamped, PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
import numpy as np
from pattern_locator.localization.odom import odom_pose
from pattern_locator.nodes.image_codec import fill_camera_info, fill_msg
from pattern_locator.sim.drive import yaw_pose
from pattern_locator.sim.floor_file import load_floor_world
from pattern_locator.sim.floor_scene import FloorScene
from pattern_locator.vision.camera import CameraModel
from pattern_locator.vision.geometry import quaternion_xyzw
import pytest
from ros_tools import client_node, locator_process, spin_until
from sensor_msgs.msg import CameraInfo, Image, JointState
from test_locator_node import ParameterClient

FLOOR_MAP = Path(__file__).resolve().parents[2] / 'config' / 'floor_building.yaml'
WORLD = load_floor_world()
BUILDING = WORLD.building
SCENE = FloorScene(WORLD)
HEAD = SCENE.head
CAMERA = CameraModel.from_fov(640, 480, 48.0)
ROOM = BUILDING.room(4, 3)
CURRENT = (4, 3, 3)                  # the north wall's card the head looks at first
T0 = 1000.0                          # the drive's first stamp (s)
START_X, Y, SPEED = 9.0, 10.0, 0.3   # standing at x = 9 m until T0 + 0.4 s, then west
ODOM_HZ = 50.0


def x_at(t: float) -> float:
    return START_X - SPEED * max(0.0, t - (T0 + 0.4))


def base_at(t: float):
    """Return the true T_building_base (heading west)."""
    return yaw_pose(x_at(t), Y, math.pi, WORLD.z)


def aimed_at(T_building_base, ids):
    centre = BUILDING.card(ids).T_building_card.t
    return HEAD.aim_angles(T_building_base.inverse().apply(centre[None])[0])


def centre_in_camera(T_building_base, pan, tilt, ids):
    T_camera = SCENE.true_camera_pose(T_building_base, pan, tilt)
    return T_camera.inverse().apply(BUILDING.card(ids).T_building_card.t[None])[0]


def stamp_of(t: float):
    from builtin_interfaces.msg import Time
    sec = int(math.floor(t))
    return Time(sec=sec, nanosec=int(round((t - sec) * 1e9)))


def seconds(header) -> float:
    return header.stamp.sec + header.stamp.nanosec * 1e-9


def near(a: float, b: float) -> bool:
    return abs(a - b) < 1e-6


@pytest.fixture(scope='module')
def locator(tmp_path_factory):
    log = tmp_path_factory.mktemp('locator_drive') / 'output.txt'
    with locator_process(log, [f'building_map:={FLOOR_MAP}', 'gates.max_speed_m_s:=0.1']) as p:
        yield p


class Drive:
    """The robot's side of the graph: publishers, what came back, the drive's clock."""

    def __init__(self, node, executor):
        self.node, self.executor = node, executor
        self.received = {k: [] for k in ('pose', 'cov', 'bridged', 'target', 'diag')}
        for topic, kind, key in (('robot_location', PoseStamped, 'pose'),
                                 ('robot_location/with_covariance', PoseWithCovarianceStamped,
                                  'cov'),
                                 ('robot_location/odom_bridged', PoseWithCovarianceStamped,
                                  'bridged'),
                                 ('pattern_locator/target', PointStamped, 'target'),
                                 ('/diagnostics', DiagnosticArray, 'diag')):
            node.create_subscription(kind, topic, self.received[key].append, 500)
        self.image = node.create_publisher(Image, 'camera/image_raw', 10)
        self.info = node.create_publisher(CameraInfo, 'camera/camera_info', 10)
        self.joints = node.create_publisher(JointState, 'camera/joint_states', 50)
        self.odom = node.create_publisher(Odometry, 'odom', 200)
        self.odom_until = T0 - 1.0
        self.frames = 0

    def spin(self, condition, timeout: float) -> bool:
        return spin_until(self.executor, condition, timeout)

    def publish_odometry(self, until: float) -> None:
        """Publish exact odometry (odom frame: the base at T0) up to ``until``, 10 at a time."""
        step = 1.0 / ODOM_HZ
        batch = 0
        while self.odom_until + step <= until + 1e-9:
            self.odom_until += step
            t = self.odom_until
            msg = Odometry()
            msg.header.stamp = stamp_of(t)
            msg.header.frame_id = 'odom'
            msg.child_frame_id = 'base_link'
            T = odom_pose(START_X - x_at(t), 0.0, 0.0)
            msg.pose.pose.position.x, msg.pose.pose.position.y, msg.pose.pose.position.z = \
                (float(v) for v in T.t)
            (msg.pose.pose.orientation.x, msg.pose.pose.orientation.y,
             msg.pose.pose.orientation.z, msg.pose.pose.orientation.w) = \
                (float(v) for v in quaternion_xyzw(T.R))
            driven = START_X - x_at(t)
            variances = [(0.01 * driven) ** 2 + 1e-6] * 2 + [1e-6] * 3 + [1e-5]
            msg.pose.covariance = [float(v) for v in np.diag(variances).ravel()]
            msg.twist.twist.linear.x = SPEED if t > T0 + 0.4 else 0.0
            self.odom.publish(msg)
            batch += 1
            if batch % 10 == 0:
                self.spin(lambda: False, 0.02)

    def frame(self, t: float, pan: float, tilt: float) -> None:
        """Publish odometry past ``t``, joint states around it, its camera_info and image."""
        self.publish_odometry(t + 0.1)
        for offset in (-0.05, 0.05):
            self.joint_state(t + offset, pan, tilt)
        self.camera_frame(t, pan, tilt)

    def joint_state(self, t: float, pan: float, tilt: float) -> None:
        """Publish the head's angles stamped ``t``."""
        joints = JointState()
        joints.header.stamp = stamp_of(t)
        joints.name = ['camera_pan', 'camera_tilt']
        joints.position = [float(pan), float(tilt)]
        self.joints.publish(joints)

    def camera_frame(self, t: float, pan: float, tilt: float) -> None:
        """Publish the camera_info and the image stamped ``t``, the head at ``pan``, ``tilt``."""
        image = SCENE.render_still(SCENE.true_camera_pose(base_at(t), pan, tilt), CAMERA,
                                   seed=self.frames)
        self.frames += 1
        info = CameraInfo()
        fill_camera_info(info, CAMERA)
        info.header.stamp = stamp_of(t)
        info.header.frame_id = 'camera_optical_frame'
        msg = Image()
        fill_msg(msg, image, 'bgr8')
        msg.header.stamp = stamp_of(t)
        msg.header.frame_id = 'camera_optical_frame'
        self.spin(lambda: False, 0.02)
        self.info.publish(info)
        self.image.publish(msg)

    def stamped(self, key: str, t: float):
        return [m for m in self.received[key] if near(seconds(m.header), t)]

    def look(self, t: float, ids=CURRENT, expect_pose: bool = True):
        """Send the image at ``t`` with the head on card ``ids``; return (pose, target)."""
        pan, tilt = aimed_at(base_at(t), ids)
        self.frame(t, pan, tilt)
        assert self.spin(lambda: self.stamped('target', t), 10.0), f'no target at {t}'
        if expect_pose:
            assert self.spin(lambda: self.stamped('pose', t), 3.0), f'no pose at {t}'
        else:
            self.spin(lambda: False, 0.5)
        pose = self.stamped('pose', t)
        return (pose[0] if pose else None), self.stamped('target', t)[0]

    def diagnostics(self) -> dict:
        for array in reversed(self.received['diag']):
            for status in array.status:
                if status.name == 'pattern_locator: locator':
                    return {kv.key: kv.value for kv in status.values}
        return {}

    def wait_diagnostics(self, condition, timeout: float = 4.0) -> dict:
        self.spin(lambda: condition(self.diagnostics()), timeout)
        return self.diagnostics()


@pytest.fixture(scope='module')
def drive(locator):
    with client_node('locator_drive_client') as (node, executor):
        d = Drive(node, executor)
        assert d.spin(lambda: d.image.get_subscription_count() > 0
                      and d.odom.get_subscription_count() > 0
                      and d.joints.get_subscription_count() > 0, 20.0), \
            'the locator never subscribed: ' + locator.log.read_text()
        d.params = ParameterClient(node, executor, '/locator')
        yield d


def in_room(T_building_base):
    return ROOM.T_building_room.inverse() @ T_building_base


def test_odom_bridged_carries_the_fix_forward_with_growing_covariance(drive, locator):
    # Standing: the first fix waits for a second agreeing image.
    pose, _ = drive.look(T0, expect_pose=False)
    assert pose is None
    for t in (T0 + 0.2, T0 + 0.4):
        pose, _ = drive.look(t)
        assert pose.header.frame_id == 'floor_4/room_3'
        p = pose.pose.position
        assert np.linalg.norm([p.x, p.y, p.z] - in_room(base_at(t)).t) < 0.05
    before = len(drive.received['bridged'])
    # Two seconds of driving without images: only odometry.
    drive.publish_odometry(T0 + 2.4)
    assert drive.spin(lambda: any(seconds(m.header) > T0 + 2.35
                                  for m in drive.received['bridged']), 5.0), \
        locator.log.read_text()[-2000:]
    bridged = [m for m in drive.received['bridged'][before:] if seconds(m.header) > T0 + 0.4]
    assert len(bridged) >= 0.9 * 2.0 * ODOM_HZ
    sigmas = []
    for m in bridged:
        assert m.header.frame_id == 'floor_4/room_3'
        cov = np.array(m.pose.covariance).reshape(6, 6)
        assert np.all(np.isfinite(cov)) and np.all(np.linalg.eigvalsh((cov + cov.T) / 2) > 0)
        p = m.pose.pose.position
        truth = in_room(base_at(seconds(m.header))).t
        assert np.linalg.norm([p.x - truth[0], p.y - truth[1], p.z - truth[2]]) < 0.05
        sigmas.append(math.sqrt(np.trace(cov[:3, :3])))
    # Its covariance grows as the robot drives away from its fix.
    assert sigmas[-1] > 1.5 * sigmas[0]
    assert all(b >= a - 1e-6 for a, b in zip(sigmas, sigmas[1:]))


def test_a_move_odometry_explains_passes_where_the_speed_limit_holds_it(drive, locator):
    # 0.6 m in 2 s, the speed limit allowing 0.2 m: with odometry, published at once.
    t = T0 + 2.4
    pose, _ = drive.look(t)
    p = pose.pose.position
    assert np.linalg.norm([p.x, p.y, p.z] - in_room(base_at(t)).t) < 0.05
    values = drive.wait_diagnostics(lambda v: int(v.get('located_with_odometry', 0)) >= 1)
    assert int(values['located_with_odometry']) >= 1
    jumps = int(values['gate_rejected_jump'])

    # The same move with the speed limit alone: held until a second image agrees.
    assert drive.params.set_value('use_odometry', False) == (True, '')
    published = len(drive.received['bridged'])
    drive.publish_odometry(T0 + 4.4)
    pose, _ = drive.look(T0 + 4.4, expect_pose=False)
    assert pose is None, 'a 0.6 m jump passed the speed limit'
    pose, _ = drive.look(T0 + 4.6)
    assert pose is not None
    values = drive.wait_diagnostics(lambda v: int(v.get('gate_rejected_jump', 0)) > jumps)
    assert int(values['gate_rejected_jump']) == jumps + 1
    # Without odometry nothing is bridged.
    assert len(drive.received['bridged']) == published
    assert values['odom_bridged'] == 'off'
    assert drive.params.set_value('use_odometry', True) == (True, '')


def test_the_target_hands_over_before_the_current_card_leaves_the_view(drive, locator):
    # Driving on west, the head kept on the north wall's card: it comes too
    # close for the tilt, and the target turns to another card first.
    t = T0 + 4.8
    handover = None
    while x_at(t) > 6.5:
        T = base_at(t)
        pan, tilt = aimed_at(T, CURRENT)
        _, target = drive.look(t)
        point = np.array([target.point.x, target.point.y, target.point.z])
        errors = {card.ids.as_tuple(): np.linalg.norm(
            point - centre_in_camera(T, pan, tilt, card.ids.as_tuple()))
            for card in ROOM.cards}
        ids = min(errors, key=errors.get)
        assert errors[ids] < 0.1, (t, errors)
        if ids != CURRENT:
            handover = (t, ids)
            break
        t = round(t + 0.2, 6)
    assert handover is not None, 'the target never left the current card'
    t, ids = handover
    # The current card was still whole in that image: the handover came first.
    T = base_at(t)
    views = SCENE.views(SCENE.true_camera_pose(T, *aimed_at(T, CURRENT)), CAMERA)
    assert any(v.ids.as_tuple() == CURRENT and v.complete for v in views)
    assert not any(v.ids.as_tuple() == ids for v in views)        # so it was predicted
    values = drive.wait_diagnostics(lambda v: int(v.get('targets: handover', 0)) >= 1)
    assert int(values['targets: handover']) >= 1
    assert int(values['targets: predicted']) >= 1
    drive.next_t, drive.next_card = round(t + 0.2, 6), ids


def empty_view(T):
    """Return head angles at which the camera sees no card at all."""
    for pan_deg in range(0, 95, 5):
        for sign in (1.0, -1.0):
            pan, tilt = math.radians(sign * pan_deg), math.radians(-20.0)
            if not SCENE.views(SCENE.true_camera_pose(T, pan, tilt), CAMERA):
                return pan, tilt
    raise AssertionError('no empty view')


def test_a_card_predicted_visible_is_the_target_and_none_when_none_is(drive, locator):
    t, card = drive.next_t, drive.next_card
    T = base_at(t)
    pan, tilt = empty_view(T)
    drive.frame(t, pan, tilt)
    assert drive.spin(lambda: drive.stamped('target', t), 10.0), 'no target, one predicted'
    target = drive.stamped('target', t)[0]
    point = [target.point.x, target.point.y, target.point.z]
    # The card handed over to (kept: nothing better in view), its centre predicted.
    errors = {c.ids.as_tuple(): np.linalg.norm(point - centre_in_camera(T, pan, tilt,
                                                                        c.ids.as_tuple()))
              for c in ROOM.cards}
    assert min(errors, key=errors.get) == card and errors[card] < 0.1, errors

    # No card within 1.5 m: none predicted visible, so no target (the driver searches).
    assert drive.params.set_value('gaze.max_distance_m', 1.5) == (True, '')
    t = round(t + 0.2, 6)
    drive.frame(t, *empty_view(base_at(t)))
    values = drive.wait_diagnostics(lambda v: int(v.get('targets: none predicted', 0)) >= 1)
    assert int(values['targets: none predicted']) == 1, values
    assert values['target_source'] == 'none'
    assert not drive.stamped('target', t)
    assert drive.params.set_value('gaze.max_distance_m', 8.0) == (True, '')
    drive.next_t = round(t + 0.2, 6)


def test_the_covariance_terms_show_in_the_diagnostics_and_their_sizes_apply(drive, locator):
    values = drive.diagnostics()
    shares = {k[len('uncertainty_share_'):]: float(v) for k, v in values.items()
              if k.startswith('uncertainty_share_')}
    assert set(shares) == {'image', 'head_timing', 'head_interpolation', 'head_resolution',
                           'map', 'floor'}
    # Still head, exact map, no floor: the image limits these fixes.
    assert shares['image'] > 0.5 and shares['floor'] == 0.0 and shares['map'] == 0.0
    assert float(values['position_sigma_mm_median']) > 0.0

    params = drive.params
    description = params.description('uncertainty.floor_position_m')
    assert description.description and not description.read_only
    assert description.floating_point_range[0].to_value == 10.0
    ok, reason = params.set_value('uncertainty.pixel_sigma_px', -1.0)
    assert not ok and 'range' in reason
    ok, reason = params.set_value('gaze.min_distance_m', 9.0)
    assert not ok and 'min_distance_m must be below max_distance_m' in reason
    ok, reason = params.set_value('gaze.switch_ratio', 0.0)
    assert not ok and 'range' in reason
    ok, reason = params.set_value('odom_bridged_max_age_s', 0.0)
    assert not ok and 'range' in reason
    assert params.value('gaze.min_distance_m') == 1.0

    # A 5 cm floor on every fix: the published covariance says so.
    assert params.set_value('uncertainty.floor_position_m', 0.05) == (True, '')
    t = drive.next_t
    pose, _ = drive.look(t, drive.next_card)
    # The covariance comes on its own topic: it may land just after the pose.
    assert drive.spin(lambda: drive.stamped('cov', t), 3.0), f'no covariance at {t}'
    cov = np.array(drive.stamped('cov', t)[0].pose.covariance).reshape(6, 6)
    assert np.all(np.diag(cov)[:3] >= 0.05 ** 2)
    assert params.set_value('uncertainty.floor_position_m', 0.0) == (True, '')

    # odom_bridged stops once its fix is older than its limit.
    assert params.set_value('odom_bridged_max_age_s', 0.5) == (True, '')
    drive.publish_odometry(t + 1.5)
    assert drive.spin(lambda: 'stopped: the fix is' in drive.diagnostics().get(
        'odom_bridged', ''), 4.0), drive.diagnostics()
    late = [m for m in drive.received['bridged'] if seconds(m.header) > t + 0.5 + 1e-6]
    assert not late
    assert locator.poll() is None


def test_an_image_waits_for_the_joint_state_after_it_rather_than_hold_the_one_before(drive):
    # The driver reads the head at 10 Hz and changes its speed just after each
    # reading; the reading after an image comes up to a period plus its
    # delivery later. Held, the reading before this image is 3.6 deg of tilt
    # off (the head slewing up at 60 deg/s): the base ~7 cm off, the
    # covariance knowing nothing of it (no rate to hold with). Waited for,
    # the two readings bracket the image and put the head where it was.
    t = round(drive.next_t + 1.6, 6)
    card = drive.next_card
    pan, tilt = aimed_at(base_at(t), card)
    rate = math.radians(60.0)
    drive.publish_odometry(t + 0.1)
    drive.joint_state(t - 0.06, pan, tilt - 0.06 * rate)
    drive.camera_frame(t, pan, tilt)
    # The next reading 90 ms later: beyond the old 50 ms wait.
    drive.spin(lambda: False, 0.09)
    drive.joint_state(t + 0.04, pan, tilt + 0.04 * rate)
    assert drive.spin(lambda: drive.stamped('pose', t), 5.0), f'no pose at {t}'
    p = drive.stamped('pose', t)[0].pose.position
    error = np.linalg.norm([p.x, p.y, p.z] - in_room(base_at(t)).t)
    assert error < 0.02, f'the base {100 * error:.1f} cm off: the joint state before was held'
