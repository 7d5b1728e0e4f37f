"""
Rosbag2 bags: the simulated recording, the checked-in bag and replay over DDS.

The replay tests play the checked-in bag (``test/data/paper_route``, the
paper's route at 5 Hz) into a real ``locator`` process and compare every pose
it publishes with ``/sim/true_pose`` at the same stamp.
"""

import json
import math
from pathlib import Path
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
import numpy as np
from pattern_locator.errors import ConfigError
from pattern_locator.nodes.bags import (IMAGE_TOPIC, JOINT_SAMPLE_OFFSET_NS, play, record_sim,
                                        sim_stops, SIM_TOPICS, START_NS, TRUTH_TOPIC)
from pattern_locator.sim.paper_setup import route
from pattern_locator.vision.geometry import rotation_from_quaternion
import pytest
from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
from ros_tools import client_node, locator_process, spin_until
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys import get_typestore, Stores
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import String, UInt16MultiArray
import yaml

BAG = Path(__file__).resolve().parents[1] / 'data' / 'paper_route'
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
FRAME = 'floor_1/room_3'
# Measured on the checked-in bag: at most 1.0 cm and 0.14 degrees of heading.
POSITION_TOLERANCE_M = 0.03
HEADING_TOLERANCE_DEG = 1.0


def read_bag(path):
    """Return {topic: [(bag time ns, message)]} with rosbags' own deserializer."""
    out = {}
    with Reader(path) as reader:
        for connection, stamp_ns, raw in reader.messages():
            msg = TYPESTORE.deserialize_cdr(raw, connection.msgtype)
            out.setdefault(connection.topic, []).append((stamp_ns, msg))
    return out


def stamp_ns(msg) -> int:
    return msg.header.stamp.sec * 10 ** 9 + msg.header.stamp.nanosec


def directory_size(path: Path) -> int:
    return sum(p.stat().st_size for p in path.rglob('*') if p.is_file())


# Recording and the checked-in bag --------------------------------------------------------


def test_record_sim_writes_a_readable_bag(tmp_path):
    out = record_sim(tmp_path / 'sim', n_stops=3, rate_hz=4.0)
    with Reader(out) as reader:
        assert {t: i.msgtype for t, i in reader.topics.items()} == SIM_TOPICS
        counts = {t: i.msgcount for t, i in reader.topics.items()}
    assert counts == {'/camera/image_raw': 3, '/camera/camera_info': 3,
                      '/camera/joint_states': 6, '/sim/true_pose': 3}
    bag = read_bag(out)
    images = [m for _, m in bag['/camera/image_raw']]
    stamps = [stamp_ns(m) for m in images]
    assert stamps == [START_NS + i * 250_000_000 for i in range(3)]
    assert all(s % 10 ** 6 != 0 for s in stamps), 'stamps should not be round'
    assert [stamp_ns(m) for _, m in bag['/sim/true_pose']] == stamps
    assert [stamp_ns(m) for _, m in bag['/camera/camera_info']] == stamps
    for image in images:
        assert (image.width, image.height, image.encoding, image.step) == (640, 480, 'bgr8',
                                                                           1920)
        assert image.data.size == 640 * 480 * 3
        assert image.header.frame_id == 'camera_optical_frame'
    assert all(m.header.frame_id == FRAME for _, m in bag['/sim/true_pose'])
    joints = [m for _, m in bag['/camera/joint_states']]
    assert all(list(m.name) == ['camera_pan', 'camera_tilt'] for m in joints)
    # One sample just before and one just after each image, with the stop's angles.
    for k, (T_room_base, _, pan, tilt) in enumerate(sim_stops(3)):
        before, after = joints[2 * k], joints[2 * k + 1]
        assert stamp_ns(before) == stamps[k] - JOINT_SAMPLE_OFFSET_NS
        assert stamp_ns(after) == stamps[k] + JOINT_SAMPLE_OFFSET_NS
        assert np.allclose(before.position, [pan, tilt])
        assert np.allclose(after.position, [pan, tilt])
        p = bag['/sim/true_pose'][k][1].pose.position
        assert np.allclose([p.x, p.y, p.z], T_room_base.t)
    # Bag times never run backwards within a topic and follow the header stamps.
    for topic, messages in bag.items():
        times = [t for t, _ in messages]
        assert times == sorted(times), topic
        assert all(0 <= t - stamp_ns(m) < 10 ** 7 for t, m in messages), topic
    info = bag['/camera/camera_info'][0][1]
    assert (info.width, info.height, info.distortion_model) == (640, 480, 'plumb_bob')
    assert info.k[0] == pytest.approx(320.0 / math.tan(math.radians(30.0)))

    with pytest.raises(ConfigError, match='exists already'):
        record_sim(out, n_stops=1)
    with pytest.raises(ConfigError, match='30 stops'):
        record_sim(tmp_path / 'none', n_stops=0)


def test_checked_in_bag():
    assert (BAG / 'metadata.yaml').is_file()
    assert directory_size(BAG) < 3 * 1024 * 1024, 'the test bag should stay a few MB'
    bag = read_bag(BAG)
    images = [m for _, m in bag[IMAGE_TOPIC]]
    assert len(images) == len(route()) == 30
    assert {(m.width, m.height, m.encoding) for m in images} == {(640, 480, 'bgr8')}
    assert len(bag[TRUTH_TOPIC]) == 30 and len(bag['/camera/joint_states']) == 60
    # The ground truth is what the current code would record (else regenerate the bag:
    # python -m pattern_locator.nodes.bags test/data/paper_route).
    for (T_room_base, _, _, _), (_, truth) in zip(sim_stops(30), bag[TRUTH_TOPIC]):
        p, q = truth.pose.position, truth.pose.orientation
        assert np.allclose([p.x, p.y, p.z], T_room_base.t, atol=1e-9)
        assert np.allclose(rotation_from_quaternion([q.x, q.y, q.z, q.w]), T_room_base.R,
                           atol=1e-9)
    # ROS's own deserializer reads the recorded bytes too.
    classes = {'/camera/image_raw': Image, '/camera/camera_info': CameraInfo,
               '/camera/joint_states': JointState, '/sim/true_pose': PoseStamped}
    with Reader(BAG) as reader:
        seen = set()
        for connection, _, raw in reader.messages():
            if connection.topic not in seen:
                msg = deserialize_message(bytes(raw), classes[connection.topic])
                assert msg.header.stamp.sec > 0
                seen.add(connection.topic)
    assert seen == set(classes)
    # The recording says which card each image looks at: the route's.
    metadata = yaml.safe_load((BAG / 'metadata.yaml').read_text())
    custom = metadata['rosbag2_bagfile_information']['custom_data']
    recorded = json.loads(custom['pattern_locator.record_sim'])
    assert recorded['cards'] == [number for _, number in route()]


# Playing: errors and any topics -------------------------------------------------------------


def test_play_refuses_what_it_cannot_play(tmp_path):
    with pytest.raises(ConfigError, match='no such bag'):
        play(tmp_path / 'missing')
    (tmp_path / 'empty').mkdir()
    with pytest.raises(ConfigError, match='not a rosbag2 bag'):
        play(tmp_path / 'empty')
    with pytest.raises(ConfigError, match='no topic /nope'):
        play(BAG, topics=['/nope'])
    with pytest.raises(ConfigError, match='rate'):
        play(BAG, rate=0.0)
    # A type ROS knows but this install has no Python package for.
    trajectory = tmp_path / 'trajectory'
    with Writer(trajectory, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connection = writer.add_connection('/plan', 'trajectory_msgs/msg/JointTrajectory',
                                           typestore=TYPESTORE)
        writer.write(connection, 1, bytes(64))
    with pytest.raises(ConfigError,
                       match='unknown message type trajectory_msgs/msg/JointTrajectory'):
        play(trajectory)
    # Recorded with another definition of std_msgs/String (another ROS distribution).
    other = tmp_path / 'other'
    with Writer(other, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connection = writer.add_connection('/chatter', 'std_msgs/msg/String',
                                           msgdef='string data\nint32 extra',
                                           rihs01='RIHS01_' + '0' * 64)
        writer.write(connection, 1, bytes(64))
    with pytest.raises(ConfigError, match='different definition'):
        play(other)


@pytest.fixture
def client():
    """Yield (node, executor) in a context of their own; shut down afterwards."""
    with client_node('bags_test_client') as pair:
        yield pair


@pytest.fixture(scope='module')
def chatter(tmp_path_factory):
    """Return a bag as another robot might have recorded it: other topics, sqlite3 storage."""
    path = tmp_path_factory.mktemp('bags') / 'chatter'
    with Writer(path, version=8, storage_plugin=StoragePlugin.SQLITE3) as writer:
        connection = writer.add_connection('/chatter', 'std_msgs/msg/String',
                                           typestore=TYPESTORE)
        for i in range(20):
            msg = TYPESTORE.types['std_msgs/msg/String'](data=f'hello {i}')
            writer.write(connection, 10 ** 9 + i * 50_000_000,
                         TYPESTORE.serialize_cdr(msg, 'std_msgs/msg/String'))
    return path


def test_play_any_topics_from_a_sqlite3_bag(chatter, client):
    node, executor = client
    got = []
    node.create_subscription(String, '/bags_test/chatter', lambda m: got.append(m.data),
                             QoSProfile(depth=50))
    started = time.monotonic()
    count = play(chatter, rate=2.0, remap={'/chatter': '/bags_test/chatter'},
                 wait_for_subscribers=['/bags_test/chatter'])
    elapsed = time.monotonic() - started
    assert count == 20
    assert elapsed >= 19 * 0.05 / 2.0, 'faster than the recorded timing allows'
    assert spin_until(executor, lambda: len(got) == 20, 5.0), got
    assert got == [f'hello {i}' for i in range(20)]


def test_play_options_like_rosbag2(chatter, client, capsys):
    from rosgraph_msgs.msg import Clock
    node, executor = client
    got, clocks = [], []
    node.create_subscription(String, '/opt/chatter', lambda m: got.append(m.data),
                             QoSProfile(depth=100))
    # Best effort, as rclpy's own time source subscribes.
    node.create_subscription(Clock, '/clock', lambda m: clocks.append(
        m.clock.sec + m.clock.nanosec * 1e-9), qos_profile_sensor_data)
    # --start-offset 0.5 skips the first ten; --clock publishes the bag's time;
    # --wait-for-subscribers with no topic named waits for every played one.
    count = play(chatter, rate=2.0, remap={'/chatter': '/opt/chatter'}, wait_for_subscribers=[],
                 start_offset_s=0.5, clock_hz=100.0, progress=True)
    assert count == 10
    assert spin_until(executor, lambda: len(got) == 10, 5.0), got
    assert got == [f'hello {i}' for i in range(10, 20)]
    assert clocks, 'no /clock'
    assert clocks == sorted(clocks) and 1.5 - 1e-9 <= clocks[0] and clocks[-1] <= 1.95 + 1e-9
    assert 'playing chatter' in capsys.readouterr().err      # the progress line
    # --loop (here two passes) and --topics; with --clock the time goes back
    # once, at the second pass, and never within a pass.
    got.clear()
    trace = []
    # A deep queue: play() runs in this thread, the executor takes them after.
    node.create_subscription(Clock, '/clock', lambda m: trace.append(
        m.clock.sec + m.clock.nanosec * 1e-9),
        QoSProfile(depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT))
    assert play(chatter, rate=4.0, topics=['/chatter'], remap={'/chatter': '/opt/chatter'},
                wait_for_subscribers=['/opt/chatter'], loops=2, clock_hz=100.0) == 40
    assert spin_until(executor, lambda: len(got) == 40, 5.0), len(got)
    assert got == [f'hello {i}' for i in range(20)] * 2
    spin_until(executor, lambda: False, 0.2)
    backs = [k for k in range(1, len(trace)) if trace[k] < trace[k - 1]]
    assert len(backs) == 1 and trace[backs[0] - 1] >= 1.9 and trace[backs[0]] <= 1.1, trace


def test_bag_play_command_line_errors(chatter, capsys):
    from pattern_locator.cli import main
    cases = [(['--remap', 'nonsense'], 'a remap is FROM:=TO'),
             (['--remap', '/nope:=/x'], 'cannot remap /nope'),
             (['--wait-for-subscribers', '--wait-timeout', '0.3'], 'no subscriber on /chatter'),
             (['--topics', '/nope'], 'no topic /nope'),
             (['--rate', '0'], 'rate must be a positive number')]
    for options, message in cases:
        assert main(['bag', 'play', str(chatter)] + options) == 2, options
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0], (options, err)


# Replay into a real locator process ---------------------------------------------------------


@pytest.fixture(scope='module')
def locator(tmp_path_factory):
    """One locator, fresh at the first replay, replayed into again and again."""
    tmp = tmp_path_factory.mktemp('replay')
    # The checked-in bag shows the paper's cards, printed without handedness
    # marks: the locator is told so (the shipped pattern has marks).
    pattern = tmp / 'pattern.yaml'
    pattern.write_text('handedness_mark: null\n')
    # The bag holds still images of the paper's stops, 5 a second: the robot
    # 'jumps' 0.6 m between images, so each image must stand alone.
    with locator_process(tmp / 'locator.txt', ['use_joint_states:=true', 'gates.continuity:=false',
                                               f'pattern_config:={pattern}']) as proc:
        yield proc


class Listener:
    """The test's side of the graph: what the locator publishes and the truth."""

    def __init__(self, node):
        self.poses, self.ids, self.covs, self.truth, self.diags = [], [], [], {}, []
        deep = QoSProfile(depth=500)      # play() blocks: everything waits in the queues
        self.subs = [
            node.create_subscription(PoseStamped, '/robot_location', self.poses.append, deep),
            node.create_subscription(UInt16MultiArray, '/robot_location/ids', self.ids.append,
                                     deep),
            node.create_subscription(PoseWithCovarianceStamped,
                                     '/robot_location/with_covariance', self.covs.append,
                                     deep),
            node.create_subscription(PoseStamped, TRUTH_TOPIC,
                                     lambda m: self.truth.__setitem__(stamp_ns(m), m), deep),
            node.create_subscription(DiagnosticArray, '/diagnostics', self.diags.append, deep),
        ]

    def counts(self):
        """Return the latest diagnostics counts of the locator (None before the first)."""
        for array in reversed(self.diags):
            for status in array.status:
                if status.name == 'pattern_locator: locator':
                    values = {kv.key: kv.value for kv in status.values}
                    counts = {k: int(values[k]) for k in ('received', 'processed', 'dropped',
                                                          'located', 'clock_jumps')}
                    counts['stamp'] = stamp_ns(array) * 1e-9
                    return counts
        return None


def replay(locator, client, rate, listener=None):
    """Play the checked-in bag into the locator; return (listener, counts, image stamps)."""
    node, executor = client
    if listener is None:
        listener = Listener(node)
    listener.poses.clear()
    listener.ids.clear()
    listener.covs.clear()
    listener.truth.clear()
    assert spin_until(executor, lambda: all(s.get_publisher_count() > 0
                                            for s in listener.subs[:3])
                      and listener.counts() is not None, 20.0), \
        'the locator never came up: ' + locator.log.read_text()
    before = listener.counts()
    # The player joins this process's graph (already matched with the locator);
    # delivery is checked below, so the acknowledgements are not waited for long.
    count = play(BAG, rate=rate, context=node.context, wait_for_subscribers=list(SIM_TOPICS),
                 wait_acked_s=0.2)
    finished = time.time()
    assert count == 150

    def settled():
        # A diagnostics report from after the last image, with every received image
        # handled and every pose it counted delivered.
        now = listener.counts()
        return (now['stamp'] > finished + 0.1
                and now['processed'] + now['dropped'] == now['received']
                and len(listener.poses) >= now['located'] - before['located'])

    assert spin_until(executor, settled, 10.0), \
        f'locator did not settle: {listener.counts()}\n' + locator.log.read_text()
    after = listener.counts()
    delta = {k: after[k] - before[k] for k in ('received', 'processed', 'dropped', 'located',
                                               'clock_jumps')}
    image_stamps = [stamp_ns(m) for _, m in read_bag(BAG)[IMAGE_TOPIC]]
    assert locator.poll() is None, 'the locator died: ' + locator.log.read_text()
    return listener, delta, image_stamps


def heading_deg(q) -> float:
    R = rotation_from_quaternion([q.x, q.y, q.z, q.w])
    return math.degrees(math.atan2(R[1, 0], R[0, 0]))


def check_poses(listener, image_stamps):
    """Compare every pose with the truth; return the worst (position m, heading deg)."""
    cards = {s: number for s, (_, number) in zip(image_stamps, route())}
    poses = listener.poses
    assert len(listener.truth) == len(image_stamps)
    assert len(listener.ids) == len(listener.covs) == len(poses)
    errors = []
    for pose, ids, cov in zip(poses, listener.ids, listener.covs):
        stamp = stamp_ns(pose)
        assert stamp in cards, f'a pose stamped {stamp}, which is no image of the bag'
        assert stamp_ns(cov) == stamp
        assert pose.header.frame_id == FRAME and cov.header.frame_id == FRAME
        assert list(ids.data) == [1, 3, cards[stamp]]
        truth = listener.truth[stamp].pose
        p, t = pose.pose.position, truth.position
        distance = float(np.linalg.norm([p.x - t.x, p.y - t.y, p.z - t.z]))
        turn = abs((heading_deg(pose.pose.orientation) - heading_deg(truth.orientation)
                    + 180.0) % 360.0 - 180.0)
        errors.append((distance, turn))
        c = np.array(cov.pose.covariance).reshape(6, 6)
        assert np.allclose(c, c.T) and np.all(np.linalg.eigvalsh(c) > 0.0)
    return np.max(errors, axis=0)


def test_replays_deliver_every_image_five_times_in_a_row(locator, client):
    """A fresh locator, then the same bag again and again (time goes back each time)."""
    listener = Listener(client[0])
    for k in range(5):
        rate = 1.0 if k == 0 else 2.0
        listener, delta, image_stamps = replay(locator, client, rate, listener)
        n = len(image_stamps)
        assert (delta['received'], delta['processed'], delta['dropped']) == (n, n, 0), \
            (k, delta, locator.log.read_text()[-3000:])
        assert delta['located'] == len(listener.poses) == n, (k, delta)
        assert delta['clock_jumps'] == (0 if k == 0 else 1), (k, delta)
        worst = check_poses(listener, image_stamps)
        assert worst[0] < POSITION_TOLERANCE_M, f'position error up to {worst[0]:.3f} m'
        assert worst[1] < HEADING_TOLERANCE_DEG, f'heading error up to {worst[1]:.2f} deg'
        print(f'replay {k + 1} at {rate:g}x: {len(listener.poses)}/{n} located, worst '
              f'{100 * worst[0]:.2f} cm, {worst[1]:.3f} deg; diagnostics {delta}')
    text = locator.log.read_text()
    # Unmarked cards and a map holding a code and its mirror image: said at start.
    assert 'carry no handedness marks and 1 pair(s) of cards' in text, text[:3000]
    # The replays' time going back never cost an image its head angles.
    for warning in ('older than the joint state history', 'joint states stale',
                    'no joint states received', 'gap in joint states'):
        assert warning not in text, text[-3000:]


def test_replay_ten_times_faster(locator, client):
    listener, delta, image_stamps = replay(locator, client, rate=10.0)
    assert {stamp_ns(p) for p in listener.poses} <= set(image_stamps), \
        'a pose with a stamp the locator never received'
    assert 0.8 * len(image_stamps) <= delta['received'] <= len(image_stamps)
    assert delta['processed'] + delta['dropped'] == delta['received']
    assert delta['located'] == len(listener.poses) <= delta['processed']
    print(f'replay at 10x: {len(listener.poses)} located; diagnostics {delta}')
