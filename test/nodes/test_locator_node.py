"""
The locator node as a real process over DDS.

An image of the shipped building's paper room is published with its
camera_info; the node must answer with the base pose, the ids, the
covariance (latched for late subscribers) and the card's centre as a point
in the optical frame; apply parameter changes through ROS's parameter
services (and refuse bad ones with the reason); and shut down cleanly on
Ctrl-C. Malformed input: ``test_fuzz_node.py``.
"""

import math
import subprocess
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped, PoseStamped, PoseWithCovarianceStamped
import numpy as np
from pattern_locator.nodes.image_codec import fill_camera_info, fill_msg
from pattern_locator.vision.camera import CameraModel
import pytest
from rcl_interfaces.msg import ParameterType
from rcl_interfaces.srv import DescribeParameters, GetParameters, SetParameters
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from ros_tools import client_node, locator_process, spin_until
from scene_tools import base_pose, BUILDING, CAMERA, view
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import UInt16MultiArray
from std_srvs.srv import Trigger
from test_image_codec import bayer_mosaic, packed, yuv422

TILT_DEG = 15.0
TRUTH = base_pose(4.0, 2.5, 180.0)     # 4 m in front of card 1 of floor 1 room 3


@pytest.fixture(scope='module')
def locator(tmp_path_factory):
    log = tmp_path_factory.mktemp('locator') / 'output.txt'
    # Unrelated scenes one after another: each image stands alone.
    with locator_process(log, ['use_joint_states:=false', f'fixed_tilt_deg:={TILT_DEG}',
                               'gates.continuity:=false']) as proc:
        yield proc


@pytest.fixture(scope='module')
def graph(locator):
    with client_node('locator_test_client') as (node, executor):
        yield from _graph(node, executor)


def _graph(node, executor):
    received = {'pose': [], 'ids': [], 'cov': [], 'target': [], 'diag': []}
    # Relative names: the client is in the root namespace, like the locator.
    node.create_subscription(PoseStamped, 'robot_location', received['pose'].append, 10)
    node.create_subscription(UInt16MultiArray, 'robot_location/ids', received['ids'].append, 10)
    node.create_subscription(PoseWithCovarianceStamped, 'robot_location/with_covariance',
                             received['cov'].append, 10)
    node.create_subscription(PointStamped, 'pattern_locator/target', received['target'].append,
                             10)
    node.create_subscription(DiagnosticArray, '/diagnostics', received['diag'].append, 10)
    publishers = {'image': node.create_publisher(Image, 'camera/image_raw', 10),
                  'info': node.create_publisher(CameraInfo, 'camera/camera_info', 10)}
    yield node, executor, publishers, received


def info_msg(camera: CameraModel, width=None) -> CameraInfo:
    msg = CameraInfo()
    fill_camera_info(msg, camera)
    if width is not None:
        msg.width = width
    return msg


def image_msg(image, stamp_s: int) -> Image:
    msg = Image()
    fill_msg(msg, image, 'bgr8')
    msg.header.stamp.sec = stamp_s
    msg.header.frame_id = 'camera_optical_frame'
    return msg


def send(graph, image_message, info_message, stamp_s, timeout=8.0):
    """Publish until a pose with this stamp comes back (best-effort input may drop)."""
    node, executor, publishers, received = graph

    def got():
        return any(m.header.stamp.sec == stamp_s for m in received['pose'])

    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        publishers['info'].publish(info_message)
        publishers['image'].publish(image_message)
        if spin_until(executor, got, 1.0):
            return [m for m in received['pose'] if m.header.stamp.sec == stamp_s][0]
    return None


def diagnostics(received) -> dict:
    """Return the locator's latest diagnostics values (empty before the first)."""
    for array in reversed(received['diag']):
        for status in array.status:
            if status.name == 'pattern_locator: locator':
                return {kv.key: kv.value for kv in status.values}
    return {}


def position_error(pose) -> float:
    p = pose.pose.position
    return float(np.linalg.norm([p.x - TRUTH.t[0], p.y - TRUTH.t[1], p.z - TRUTH.t[2]]))


def test_node_locates_the_robot_and_points_at_the_card(locator, graph):
    node, executor, publishers, received = graph
    assert spin_until(executor, lambda: publishers['image'].get_subscription_count() > 0
                      and publishers['info'].get_subscription_count() > 0, 20.0), \
        'the locator never subscribed: ' + locator.log.read_text()
    image, T_room_camera = view(1, 3, TRUTH, 0.0, math.radians(TILT_DEG))

    pose = send(graph, image_msg(image, 100), info_msg(CAMERA), 100)
    assert pose is not None, 'no robot_location for a good image: ' + locator.log.read_text()
    assert pose.header.frame_id == 'floor_1/room_3'
    assert position_error(pose) < 0.04
    assert spin_until(executor, lambda: received['ids'] and received['cov'], 3.0)
    assert list(received['ids'][-1].data) == [1, 3, 1]
    assert [d.label for d in received['ids'][-1].layout.dim] == ['floor', 'room', 'pattern']
    cov = np.array(received['cov'][-1].pose.covariance).reshape(6, 6)
    assert np.all(np.linalg.eigvalsh((cov + cov.T) / 2) > 0)

    # The target is what RViz can show: the card's centre in the optical frame, metres.
    assert spin_until(executor, lambda: any(m.header.stamp.sec == 100
                                            for m in received['target']), 3.0)
    target = [m for m in received['target'] if m.header.stamp.sec == 100][0]
    assert target.header.frame_id == 'camera_optical_frame'
    card = BUILDING.card((1, 3, 1)).T_room_card.t
    expected = T_room_camera.inverse().apply(card[None])[0]
    got = np.array([target.point.x, target.point.y, target.point.z])
    assert np.linalg.norm(got - expected) < 0.04, (got, expected)
    assert 3.5 < expected[2] < 4.5       # in front, about 4 m away


def test_a_late_subscriber_gets_the_last_fix(locator, graph):
    """robot_location/with_covariance is latched (transient local, depth 1) like amcl_pose."""
    node, executor, publishers, received = graph
    image, _ = view(1, 3, TRUTH, 0.0, math.radians(TILT_DEG))
    assert send(graph, image_msg(image, 150), info_msg(CAMERA), 150) is not None
    late = []
    qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
    node.create_subscription(PoseWithCovarianceStamped, 'robot_location/with_covariance',
                             late.append, qos)
    assert spin_until(executor, lambda: late, 5.0), 'a late subscriber got no fix'
    assert len(late) == 1 and late[0].header.stamp.sec == 150


def encoded(image, encoding: str, stamp_s: int) -> Image:
    """Return the scene as a message in ``encoding`` (the codec tests' own encoders)."""
    if encoding == 'rgb8':
        pixels = image[:, :, ::-1]
    elif encoding == 'bgra8':
        pixels = np.concatenate([image, np.full(image.shape[:2] + (1,), 255, np.uint8)], 2)
    elif encoding == 'mono8':
        pixels = image.min(axis=2)
    elif encoding == 'yuv422':
        pixels = yuv422(image, 'UYVY')
    else:
        pixels = bayer_mosaic(image, encoding.split('_')[1][:4].upper())
    h, w, enc, big, step, data = packed(encoding, pixels)
    msg = Image()
    msg.height, msg.width, msg.encoding, msg.is_bigendian, msg.step = h, w, enc, big, step
    msg.data = data
    msg.header.stamp.sec = stamp_s
    return msg


def test_every_encoding_gives_the_same_place(locator, graph):
    image, _ = view(1, 3, TRUTH, 0.0, math.radians(TILT_DEG))
    info = info_msg(CAMERA)
    for k, encoding in enumerate(['rgb8', 'bgra8', 'yuv422', 'bayer_rggb8', 'bayer_gbrg8']):
        pose = send(graph, encoded(image, encoding, 400 + k), info, 400 + k)
        assert pose is not None, f'{encoding}: no pose: ' + locator.log.read_text()[-2000:]
        # Bilinear demosaicing shifts dot centres by a fraction of a pixel: 2-3 %
        # of the distance here, against 0.3 % for the other encodings.
        tolerance = 0.15 if encoding.startswith('bayer') else 0.06
        assert position_error(pose) < tolerance, f'{encoding}: {position_error(pose):.3f} m'
    # Grey: geometry only, so no location.
    assert send(graph, encoded(image, 'mono8', 450), info, 450, timeout=2.0) is None
    assert locator.poll() is None


def test_debug_image_while_someone_looks(locator, graph):
    node, executor, publishers, received = graph
    debug = []
    node.create_subscription(Image, 'pattern_locator/debug_image', debug.append, 5)
    assert spin_until(executor, lambda: node.count_publishers('/pattern_locator/debug_image')
                      > 0, 10.0)
    image, _ = view(1, 3, TRUTH, 0.0, math.radians(TILT_DEG))
    assert send(graph, image_msg(image, 500), info_msg(CAMERA), 500) is not None
    assert spin_until(executor, lambda: any(m.header.stamp.sec == 500 for m in debug), 5.0)
    shown = [m for m in debug if m.header.stamp.sec == 500][0]
    assert (shown.width, shown.height, shown.encoding) == (640, 480, 'bgr8')
    assert bytes(shown.data) != image.tobytes()       # something was drawn on it


def zooming_infos(first_stamp: int, factor: float):
    """Return camera_infos of two frames, the second's focal length ``factor`` times."""
    first = info_msg(CAMERA)
    first.header.stamp.sec = first_stamp
    zoomed = info_msg(CAMERA)
    zoomed.header.stamp.sec = first_stamp + 1
    zoomed.k = [factor * v if i in (0, 4) else v for i, v in enumerate(first.k)]
    zoomed.p = [factor * v if i in (0, 5) else v for i, v in enumerate(first.p)]
    return first, zoomed


def publish_until(graph, infos, image, stamp_s: int, done, timeout: float = 8.0) -> None:
    """Publish the camera_infos, then the image stamped ``stamp_s``, until ``done()``."""
    node, executor, publishers, received = graph
    deadline = time.monotonic() + timeout
    while not done() and time.monotonic() < deadline:
        for info in infos:
            publishers['info'].publish(info)
        spin_until(executor, lambda: False, 0.05)
        publishers['image'].publish(image_msg(image, stamp_s))
        spin_until(executor, done, 1.0)


def test_each_image_uses_the_camera_info_of_its_own_stamp(locator, graph):
    # A zooming camera: the camera_info of the next frame (other intrinsics)
    # arrives before this frame is processed; this frame must keep its own.
    node, executor, publishers, received = graph
    assert spin_until(executor, lambda: publishers['image'].get_subscription_count() > 0, 20.0)
    image, _ = view(1, 3, TRUTH, 0.0, math.radians(TILT_DEG))

    def got():
        return any(m.header.stamp.sec == 600 for m in received['pose'])

    publish_until(graph, zooming_infos(600, 2.0), image, 600, got)
    pose = [m for m in received['pose'] if m.header.stamp.sec == 600]
    assert pose, locator.log.read_text()
    assert position_error(pose[0]) < 0.04


def test_no_location_when_its_own_camera_info_is_missing_while_zooming(locator, graph):
    # The camera_infos of two earlier frames differ (the camera zooms) and the
    # image's own never comes (a loaded machine): the latest would put the
    # fix out along the line of sight with a covariance of millimetres.
    node, executor, publishers, received = graph
    assert spin_until(executor, lambda: publishers['image'].get_subscription_count() > 0, 20.0)
    image, _ = view(1, 3, TRUTH, 0.0, math.radians(TILT_DEG))

    def refused():
        return 'intrinsics are changing' in locator.log.read_text()

    publish_until(graph, zooming_infos(900, 1.1), image, 902, refused)
    assert refused(), locator.log.read_text()
    assert not any(m.header.stamp.sec == 902 for m in received['pose'])


class ParameterClient:
    """rclpy clients of a node's parameter services (what ``ros2 param`` uses)."""

    def __init__(self, node, executor, target: str):
        self.executor = executor
        self.set = node.create_client(SetParameters, f'{target}/set_parameters')
        self.get = node.create_client(GetParameters, f'{target}/get_parameters')
        self.describe = node.create_client(DescribeParameters, f'{target}/describe_parameters')
        for client in (self.set, self.get, self.describe):
            assert client.wait_for_service(timeout_sec=10.0), client.srv_name

    def _call(self, client, request):
        future = client.call_async(request)
        assert spin_until(self.executor, future.done, 10.0), client.srv_name
        return future.result()

    def set_value(self, name: str, value):
        """Return (successful, reason) of setting one parameter."""
        request = SetParameters.Request()
        request.parameters = [Parameter(name, value=value).to_parameter_msg()]
        result = self._call(self.set, request).results[0]
        return result.successful, result.reason

    def value(self, name: str):
        request = GetParameters.Request(names=[name])
        value = self._call(self.get, request).values[0]
        return {ParameterType.PARAMETER_STRING: value.string_value,
                ParameterType.PARAMETER_DOUBLE: value.double_value,
                ParameterType.PARAMETER_INTEGER: value.integer_value,
                ParameterType.PARAMETER_BOOL: value.bool_value}[value.type]

    def description(self, name: str):
        return self._call(self.describe, DescribeParameters.Request(names=[name])).descriptors[0]


def test_parameters_are_validated_and_applied_at_run_time(locator, graph):
    node, executor, publishers, received = graph
    params = ParameterClient(node, executor, '/locator')
    image, _ = view(1, 3, TRUTH, 0.0, math.radians(TILT_DEG))
    info = info_msg(CAMERA)

    # Descriptors: choices listed, ranges given, the read-only ones marked.
    estimator = params.description('estimator')
    assert 'one of: exact, paper' in estimator.additional_constraints
    assert not estimator.read_only
    assert params.description('building_map').read_only
    assert params.description('head.mount_pitch_deg').read_only
    tilt_range = params.description('min_tilt_deg').floating_point_range[0]
    assert (tilt_range.from_value, tilt_range.to_value) == (0.0, 89.0)

    # Refused, with the reason, and nothing changed.
    ok, reason = params.set_value('estimator', 'bogus')
    assert not ok and 'exact, paper' in reason
    ok, reason = params.set_value('building_map', '/tmp/other.yaml')
    assert not ok and 'read-only' in reason.lower()
    ok, reason = params.set_value('max_reprojection_px', 1000.0)
    assert not ok and 'range' in reason
    ok, reason = params.set_value('max_reprojection_px', 3)
    assert not ok and 'type' in reason.lower()
    assert params.value('estimator') == 'exact'

    # Applied: the paper's estimator, then the building frame.
    assert params.set_value('estimator', 'paper') == (True, '')
    assert params.value('estimator') == 'paper'
    pose = send(graph, image_msg(image, 700), info, 700)
    assert pose is not None, locator.log.read_text()[-2000:]
    assert position_error(pose) < 0.05
    assert spin_until(executor, lambda: diagnostics(received).get('estimator') == 'paper', 3.0)
    assert spin_until(executor, lambda: any(m.header.stamp.sec == 700 for m in received['cov']),
                      3.0)
    cov = [m for m in received['cov'] if m.header.stamp.sec == 700][0]
    c = np.array(cov.pose.covariance).reshape(6, 6)
    assert np.all(np.linalg.eigvalsh((c + c.T) / 2) > 0)      # the paper's poses carry one

    assert params.set_value('output_frame', 'building')[0]
    pose = send(graph, image_msg(image, 701), info, 701)
    assert pose is not None and pose.header.frame_id == 'building'

    # A number: frames above max_image_pixels are refused before they are read.
    before = int(diagnostics(received).get('refused_oversize', 0))
    assert params.set_value('max_image_pixels', 640 * 480 - 1)[0]
    publishers['info'].publish(info)
    publishers['image'].publish(image_msg(image, 702))
    assert spin_until(executor, lambda: int(diagnostics(received).get(
        'refused_oversize', 0)) > before, 5.0)
    assert not any(m.header.stamp.sec == 702 for m in received['pose'])

    for name, value in (('estimator', 'exact'), ('output_frame', 'room'),
                        ('max_image_pixels', 4_194_304)):
        assert params.set_value(name, value)[0]
    pose = send(graph, image_msg(image, 703), info, 703)
    assert pose is not None and pose.header.frame_id == 'floor_1/room_3'

    # The prior's sigmas: in range, applied; out of range, refused with the reason.
    ok, reason = params.set_value('up_sigma_deg', 0.0)
    assert not ok and 'up_sigma_deg' in reason, reason
    assert params.set_value('up_sigma_deg', 10.0)[0]
    assert params.set_value('camera_height_sigma_m', 0.3)[0]
    pose = send(graph, image_msg(image, 704), info, 704)
    assert pose is not None and position_error(pose) < 0.04
    for name, value in (('up_sigma_deg', 5.0), ('camera_height_sigma_m', 0.15)):
        assert params.set_value(name, value)[0]


def test_diagnostics_report_processing_and_waiting_apart(locator, graph):
    node, executor, publishers, received = graph
    assert spin_until(executor, lambda: 'processing_ms_median' in diagnostics(received)
                      and diagnostics(received)['processing_ms_median'] != 'n/a', 5.0)
    values = diagnostics(received)
    for key in ('processing_ms_median', 'processing_ms_p95', 'joint_wait_ms_median',
                'queue_ms_median', 'in_node_ms_median'):
        assert float(values[key]) >= 0.0, key
    # Fixed head angles: nothing is waited for. A wait would last its whole
    # joint_state_wait_s / odom_wait_s (50 ms each); what remains is the
    # thread's scheduling on a busy machine (up to a few ms), not a wait.
    assert float(values['joint_wait_ms_max']) < 20.0


def test_reset_makes_the_next_fix_a_first_one(locator, graph):
    # With continuity on, a first fix waits until a second image agrees;
    # after ~/reset (a robot carried elsewhere) the next fix waits again,
    # instead of being judged as a jump from where the robot was.
    node, executor, publishers, received = graph
    params = ParameterClient(node, executor, '/locator')
    assert params.set_value('gates.continuity', True) == (True, '')
    try:
        image, _ = view(1, 3, TRUTH, 0.0, math.radians(TILT_DEG))
        info = info_msg(CAMERA)

        def held_back() -> int:
            return int(diagnostics(received).get('gate_rejected_unconfirmed_first', -1))

        assert spin_until(executor, lambda: held_back() >= 0, 5.0)
        before = held_back()
        assert send(graph, image_msg(image, 1000), info, 1000) is not None
        assert spin_until(executor, lambda: held_back() > before, 5.0)
        # A fix published before the reset (continuity lets the second agree).
        assert send(graph, image_msg(image, 1001), info, 1001) is not None
        assert set(latched_stamps(node, executor)) == {1001}

        reset = node.create_client(Trigger, '/locator/reset')
        assert reset.wait_for_service(timeout_sec=10.0)
        future = reset.call_async(Trigger.Request())
        assert spin_until(executor, future.done, 10.0)
        answer = future.result()
        assert answer.success, answer.message
        assert 'floor 1 room 3 card 1' in answer.message, answer.message
        assert spin_until(executor, lambda: diagnostics(received).get('resets') == '1', 5.0)
        # A subscriber that joins now does not start from the old place.
        assert latched_stamps(node, executor) == []

        after_reset = held_back()
        pose = send(graph, image_msg(image, 1010), info, 1010)
        assert pose is not None and position_error(pose) < 0.04
        assert spin_until(executor, lambda: held_back() > after_reset, 5.0)
        assert send(graph, image_msg(image, 1011), info, 1011) is not None
        assert set(latched_stamps(node, executor)) == {1011}
        # A subscriber from before the reset goes on receiving (the new publisher matches it).
        assert spin_until(executor, lambda: any(m.header.stamp.sec == 1011
                                                for m in received['cov']), 5.0)
    finally:
        assert params.set_value('gates.continuity', False) == (True, '')


def latched_stamps(node, executor, window: float = 1.5) -> list:
    """Return the stamps (seconds) a subscriber joining robot_location/with_covariance gets."""
    got = []
    latched = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
    sub = node.create_subscription(PoseWithCovarianceStamped, '/robot_location/with_covariance',
                                   lambda m: got.append(m.header.stamp.sec), latched)
    try:
        assert spin_until(executor, lambda: sub.get_publisher_count() >= 1, 10.0)
        # Matched: a latched fix arrives at once; none within the window is none.
        spin_until(executor, lambda: bool(got), window)
        return got
    finally:
        node.destroy_subscription(sub)


def test_ctrl_c_is_a_clean_shutdown(locator, graph):
    import signal
    locator.send_signal(signal.SIGINT)
    locator.wait(timeout=15)
    output = locator.log.read_text()
    assert locator.returncode == 0, output
    assert 'Traceback' not in output, output
    # Run-time changes are logged, and no log line is long.
    assert 'parameters set: estimator=' in output
    assert max(len(line) for line in output.splitlines()) < 1200


def test_a_bad_configuration_exits_1_with_one_line_on_stderr(tmp_path):
    missing = tmp_path / 'no_such_building.yaml'
    proc = subprocess.run([sys.executable, '-m', 'pattern_locator.nodes.locator_node',
                           '--ros-args', '-p', f'building_map:={missing}'],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 1
    assert proc.stderr.strip().splitlines()[-1] == (
        f'locator: error: {missing}: cannot read the building map (No such file or directory)')
