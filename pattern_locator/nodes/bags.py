"""
Rosbag2 bags: record the simulated robot into one, play any one into the ROS graph.

Bags are real rosbag2 directories (``metadata.yaml`` + an MCAP file with
zstd-compressed chunks), written and read with the pure-Python ``rosbags``
library, so ``ros2 bag info/play`` reads them too and no rosbag2 install is
needed here.

* :func:`record_sim` renders the paper's 30-stop route (``paper_setup.route``)
  through floor 1 room 3 of the shipped building: per stop an image
  (``/camera/image_raw``, bgr8), its ``/camera/camera_info``, the head's
  angles on ``/camera/joint_states`` (one sample just before and one just
  after the image) and the true base pose on ``/sim/true_pose``
  (PoseStamped in the room frame), all with the image's header stamp.
* :func:`play` publishes every message of a bag (any topics whose types are
  importable in this ROS environment) with the recorded timing, or ``rate``
  times faster, and waits until reliable subscribers have acknowledged all of
  it before returning.

Regenerate the checked-in test bag with
``python -m pattern_locator.nodes.bags test/data/paper_route`` (the directory must
not exist).
"""

import importlib
import json
import math
from pathlib import Path
import shutil
import sys
import time
from typing import Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np
from rosbags.interfaces import QosDurability, QosReliability
from rosbags.rosbag2 import (CompressionFormat, CompressionMode, Reader, ReaderError,
                             StoragePlugin, Writer, WriterError)

from .image_codec import encode_image
from ..card.pattern import load_pattern_config
from ..errors import ConfigError, PatternLocatorError
from ..localization.building import load_building
from ..localization.head import HeadGeometry
from ..sim.paper_setup import route
from ..sim.render import CardPlacement, DotCardTexture, render_scene, RenderOptions
from ..survey.bagio import typestore
from ..vision.camera import CameraModel
from ..vision.geometry import Pose, quaternion_xyzw, rodrigues

IMAGE_TOPIC = '/camera/image_raw'
INFO_TOPIC = '/camera/camera_info'
JOINTS_TOPIC = '/camera/joint_states'
TRUTH_TOPIC = '/sim/true_pose'
SIM_TOPICS = {
    IMAGE_TOPIC: 'sensor_msgs/msg/Image',
    INFO_TOPIC: 'sensor_msgs/msg/CameraInfo',
    JOINTS_TOPIC: 'sensor_msgs/msg/JointState',
    TRUTH_TOPIC: 'geometry_msgs/msg/PoseStamped',
}
SIM_FLOOR, SIM_ROOM = 1, 3
OPTICAL_FRAME = 'camera_optical_frame'
PAN_JOINT, TILT_JOINT = 'camera_pan', 'camera_tilt'
# First image stamp: a fixed date (2023-11-14) plus an offset, so stamps are not round.
START_NS = 1_700_000_000 * 10 ** 9 + 37_123_457
# Joint-state samples this long before and after each image (the head is still at a
# stop; a quarter of the period at rates above 5 Hz).
JOINT_SAMPLE_OFFSET_NS = 50_000_000
# Recording latency (bag time - header stamp) of each topic; camera_info before the image.
_LATENCY_NS = {JOINTS_TOPIC: 1_000_000, TRUTH_TOPIC: 1_000_000, INFO_TOPIC: 2_000_000,
               IMAGE_TOPIC: 4_000_000}
# The robot faces the card it looks at, give or take this much (seeded), so that
# the head pans.
HEADING_SPREAD_DEG = 25.0
# Checked-in test bag (test/data/paper_route): 5 Hz keeps the replay test short.
TEST_BAG_OPTIONS = {'rate_hz': 5.0, 'jpeg': True}

PLAYER_DEPTH = 100
# After the player saw its subscribers, the time it leaves them to see it.
MATCH_GRACE_S = 0.3


# Recording ---------------------------------------------------------------------------


def default_sim_camera() -> CameraModel:
    """Return the recorded camera: 640x480, 60 degrees horizontal field of view."""
    return CameraModel.from_fov(640, 480, 60.0, name='sim_camera')


def sim_stops(n_stops: int = 30, seed: int = 7, head: Optional[HeadGeometry] = None
              ) -> List[Tuple[Pose, int, float, float]]:
    """
    Return the route's stops as (T_room_base, card number, pan, tilt).

    The base stands on the floor under the route's camera position, facing
    the card the route looks at give or take ``HEADING_SPREAD_DEG``; the head
    aims at the card centre, clamped to its travel limits.
    """
    head = head or HeadGeometry()
    stops = route()
    if not 1 <= n_stops <= len(stops):
        raise ConfigError(f'record-sim: the route has {len(stops)} stops, asked for {n_stops}')
    building = load_building()
    rng = np.random.default_rng(seed)
    out = []
    for position, number in stops[:n_stops]:
        card = building.card((SIM_FLOOR, SIM_ROOM, number)).T_room_card.t
        yaw = math.atan2(card[1] - position[1], card[0] - position[0])
        yaw += math.radians(rng.uniform(-HEADING_SPREAD_DEG, HEADING_SPREAD_DEG))
        T_room_base = Pose(rodrigues(np.array([0.0, 0.0, yaw])),
                           np.array([position[0], position[1], 0.0]))
        pan, tilt = head.clamp(*head.aim_angles(T_room_base.inverse().apply(card[None])[0]))
        out.append((T_room_base, number, pan, tilt))
    return out


def render_stop(T_room_base: Pose, pan: float, tilt: float, camera: CameraModel,
                seed: int, jpeg: bool = False, noise_sigma: float = 0.0) -> np.ndarray:
    """
    Return the BGR image the head camera sees in the simulated room.

    A painted wall with a soft light gradient and a warm cast; ``jpeg``: the
    image went through JPEG at quality 90 (an MJPEG camera).
    """
    pattern = load_pattern_config()
    room = load_building(None, pattern).room(SIM_FLOOR, SIM_ROOM)
    T_camera_room = (T_room_base @ HeadGeometry().T_base_camera(pan, tilt)).inverse()
    cards = []
    for card in room.cards:
        T_camera_card = T_camera_room @ card.T_room_card
        if T_camera_card.t[2] > 0.3:
            cards.append(CardPlacement(T_camera_card, DotCardTexture(pattern, card.code),
                                       code=card.code, config=pattern))
    options = RenderOptions(background='white', gain=0.85, gradient=0.15,
                            gradient_angle_deg=30.0, colour_cast=(1.0, 0.97, 0.92),
                            defocus_sigma_px=0.5, noise_sigma=noise_sigma,
                            jpeg_quality=90 if jpeg else None, seed=seed)
    return render_scene(camera, cards, options).image


def record_sim(out_dir: Union[str, Path], n_stops: int = 30, seed: int = 7,
               camera: Optional[CameraModel] = None, rate_hz: float = 2.0,
               jpeg: bool = False, noise_sigma: float = 0.0) -> Path:
    """
    Render the paper's route into a new rosbag2 bag directory; return its path.

    Stop ``i`` is stamped ``START_NS + i / rate_hz``. Size per 640x480 stop
    (zstd-compressed MCAP): 12 kB as rendered, 24 kB with ``jpeg``; sensor
    noise does not compress: 310 kB at ``noise_sigma`` 0.5 (8-bit units),
    440 kB at 1.0.
    """
    out_dir = Path(out_dir)
    camera = camera or default_sim_camera()
    if not (math.isfinite(rate_hz) and rate_hz > 0.0):
        raise ConfigError(f'record-sim: rate must be a positive number of Hz, got {rate_hz!r}')
    if out_dir.exists():
        raise ConfigError(f'{out_dir}: exists already, not overwriting')
    head = HeadGeometry()
    stops = sim_stops(n_stops, seed, head)
    frame = load_building().room(SIM_FLOOR, SIM_ROOM).frame
    ts = typestore()
    writer = Writer(out_dir, version=Writer.VERSION_LATEST, storage_plugin=StoragePlugin.MCAP)
    # STORAGE: zstd-compressed MCAP chunks, which rosbag2's own MCAP plugin reads.
    writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    writer.set_custom_data('pattern_locator.record_sim', json.dumps({
        'floor': SIM_FLOOR, 'room': SIM_ROOM, 'seed': seed, 'rate_hz': rate_hz,
        'jpeg': jpeg, 'noise_sigma': noise_sigma,
        'cards': [number for _, number, _, _ in stops]}))
    try:
        writer.open()
    except (OSError, WriterError) as exc:
        raise ConfigError(f'{out_dir}: cannot write the bag ({exc})') from None
    try:
        connections = {topic: writer.add_connection(topic, msgtype, typestore=ts)
                       for topic, msgtype in SIM_TOPICS.items()}

        def write(topic, stamp_ns, msg):
            data = ts.serialize_cdr(msg, SIM_TOPICS[topic])
            writer.write(connections[topic], stamp_ns + _LATENCY_NS[topic], data)

        info = _camera_info(ts, camera)
        # Fast recordings: keep each stop's joint samples closer to it than to the next.
        offset_ns = min(JOINT_SAMPLE_OFFSET_NS, round(0.25e9 / rate_hz))
        for i, (T_room_base, _, pan, tilt) in enumerate(stops):
            stamp_ns = START_NS + round(i * 1e9 / rate_hz)
            image = render_stop(T_room_base, pan, tilt, camera, seed * 1000 + i, jpeg,
                                noise_sigma)
            write(JOINTS_TOPIC, stamp_ns - offset_ns,
                  _joint_state(ts, stamp_ns - offset_ns, pan, tilt))
            write(TRUTH_TOPIC, stamp_ns, _pose_stamped(ts, stamp_ns, frame, T_room_base))
            info.header = _header(ts, stamp_ns, OPTICAL_FRAME)
            write(INFO_TOPIC, stamp_ns, info)
            write(IMAGE_TOPIC, stamp_ns, _image(ts, stamp_ns, image))
            write(JOINTS_TOPIC, stamp_ns + offset_ns,
                  _joint_state(ts, stamp_ns + offset_ns, pan, tilt))
    except BaseException:
        # A half-written bag is no use: remove it (the directory did not exist before).
        writer.abort()
        shutil.rmtree(out_dir, ignore_errors=True)
        raise
    writer.close()
    return out_dir


def _header(ts, stamp_ns: int, frame_id: str):
    Time = ts.types['builtin_interfaces/msg/Time']
    Header = ts.types['std_msgs/msg/Header']
    return Header(stamp=Time(sec=stamp_ns // 10 ** 9, nanosec=stamp_ns % 10 ** 9),
                  frame_id=frame_id)


def _camera_info(ts, camera: CameraModel):
    RegionOfInterest = ts.types['sensor_msgs/msg/RegionOfInterest']
    K = np.asarray(camera.K, dtype=float)
    return ts.types['sensor_msgs/msg/CameraInfo'](
        header=_header(ts, 0, OPTICAL_FRAME), height=camera.height, width=camera.width,
        distortion_model='plumb_bob', d=np.asarray(camera.D, dtype=float).ravel(),
        k=K.ravel(), r=np.eye(3).ravel(), p=np.hstack([K, np.zeros((3, 1))]).ravel(),
        binning_x=0, binning_y=0,
        roi=RegionOfInterest(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))


def _image(ts, stamp_ns: int, image: np.ndarray):
    height, width, encoding, is_bigendian, step, data = encode_image(image, 'bgr8')
    return ts.types['sensor_msgs/msg/Image'](
        header=_header(ts, stamp_ns, OPTICAL_FRAME), height=height, width=width,
        encoding=encoding, is_bigendian=is_bigendian, step=step,
        data=np.frombuffer(data, dtype=np.uint8))


def _joint_state(ts, stamp_ns: int, pan: float, tilt: float):
    return ts.types['sensor_msgs/msg/JointState'](
        header=_header(ts, stamp_ns, ''), name=[PAN_JOINT, TILT_JOINT],
        position=np.array([pan, tilt], dtype=float), velocity=np.zeros(0),
        effort=np.zeros(0))


def _pose_stamped(ts, stamp_ns: int, frame: str, T: Pose):
    Point = ts.types['geometry_msgs/msg/Point']
    Quaternion = ts.types['geometry_msgs/msg/Quaternion']
    Pose_ = ts.types['geometry_msgs/msg/Pose']
    x, y, z, w = (float(v) for v in quaternion_xyzw(T.R))
    return ts.types['geometry_msgs/msg/PoseStamped'](
        header=_header(ts, stamp_ns, frame),
        pose=Pose_(position=Point(x=float(T.t[0]), y=float(T.t[1]), z=float(T.t[2])),
                   orientation=Quaternion(x=x, y=y, z=z, w=w)))


# Reading -----------------------------------------------------------------------------


def open_bag(bag: Union[str, Path]) -> Reader:
    """Return an open rosbags Reader; ConfigError when it is not a readable rosbag2 bag."""
    path = Path(bag)
    if not path.exists():
        raise ConfigError(f'{path}: no such bag')
    if path.is_dir() and not (path / 'metadata.yaml').is_file():
        raise ConfigError(f'{path}: not a rosbag2 bag (no metadata.yaml in the directory)')
    try:
        reader = Reader(path)
        reader.open()
    except (ReaderError, OSError, KeyError, ValueError) as exc:
        raise ConfigError(f'{path}: not a readable rosbag2 bag ({exc})') from None
    return reader


def message_class(type_name: str):
    """Return the ROS message class of ``pkg/msg/Name``; ConfigError if it is not installed."""
    parts = type_name.split('/')
    if len(parts) != 3 or parts[1] != 'msg' or not all(parts):
        raise ConfigError(f'message type {type_name!r} is not a ROS 2 message type '
                          '(expected package/msg/Name)')
    try:
        module = importlib.import_module(f'{parts[0]}.msg')
        cls = getattr(module, parts[2])
    except (ImportError, AttributeError):
        raise ConfigError(f'unknown message type {type_name}: not installed in this ROS '
                          'environment') from None
    return cls


def _check_definition(topic: str, type_name: str, digest: str) -> None:
    """Refuse a recording whose message definition differs from the installed one."""
    ts = typestore()
    if not digest.startswith('RIHS01_') or type_name not in ts.types:
        return
    if ts.hash_rihs01(type_name) != digest:
        raise ConfigError(f'{topic}: the bag recorded {type_name} with a different definition '
                          'than ROS 2 Jazzy (another distribution?); cannot play it')


def _qos(connections):
    """Return the player's QoS for a topic: reliable unless every recorder saw best effort."""
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    profiles = [q for c in connections
                for q in (getattr(c.ext, 'offered_qos_profiles', None) or ())]
    qos = QoSProfile(depth=PLAYER_DEPTH)
    qos.reliability = ReliabilityPolicy.RELIABLE
    qos.durability = DurabilityPolicy.VOLATILE
    if profiles and all(q.reliability == QosReliability.BEST_EFFORT for q in profiles):
        qos.reliability = ReliabilityPolicy.BEST_EFFORT
    if profiles and all(q.durability == QosDurability.TRANSIENT_LOCAL for q in profiles):
        qos.durability = DurabilityPolicy.TRANSIENT_LOCAL
    return qos


def parse_remaps(remaps: Sequence[str]) -> Dict[str, str]:
    """Return {bag topic: published topic} from ``FROM:=TO`` strings; ConfigError if bad."""
    out = {}
    for item in remaps:
        source, sep, target = str(item).partition(':=')
        if not sep or not source or not target:
            raise ConfigError(f'bag play: a remap is FROM:=TO, got {item!r}')
        out['/' + source.lstrip('/')] = '/' + target.lstrip('/')
    return out


class _Clock:
    """Publish the bag's time on /clock at ``hz`` while playing (``--clock``)."""

    def __init__(self, node, hz: float) -> None:
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from rosgraph_msgs.msg import Clock
        self._msg = Clock()
        self._period = 1.0 / hz
        self._last = -math.inf
        self._last_ns = -1
        # What rclcpp's ClockQoS offers: best effort, the newest only.
        self._pub = node.create_publisher(
            Clock, '/clock', QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT))

    def publish(self, bag_ns: int, force: bool = False) -> None:
        """Publish ``bag_ns`` if a period has passed (or ``force``); /clock never goes back."""
        now = time.monotonic()
        bag_ns = max(int(bag_ns), self._last_ns)
        if force or now - self._last >= self._period:
            self._msg.clock.sec, self._msg.clock.nanosec = divmod(bag_ns, 10 ** 9)
            self._pub.publish(self._msg)
            self._last, self._last_ns = now, bag_ns

    def restart(self) -> None:
        """Start a new pass of the bag (``--loop``): its time may go back to the start once."""
        self._last_ns = -1

    def sleep_until(self, due: float, bag_ns_at: Callable[[float], int]) -> None:
        """Sleep until ``due`` (monotonic), publishing the bag time meanwhile."""
        while True:
            now = time.monotonic()
            if now >= due:
                return
            time.sleep(min(due - now, max(0.0, self._last + self._period - now) or
                           self._period))
            # Woken late (a busy machine), the time is the next message's, not past
            # it: that message's own stamp follows and /clock must not go back.
            self.publish(bag_ns_at(min(time.monotonic(), due)))


def play(bag_dir: Union[str, Path], rate: float = 1.0, context=None,
         topics: Optional[Sequence[str]] = None, wait_acked_s: float = 10.0,
         wait_for_subscribers: Optional[Sequence[str]] = None,
         discovery_timeout_s: float = 10.0, remap: Optional[Mapping[str, str]] = None,
         clock_hz: float = 0.0, loops: int = 1, start_offset_s: float = 0.0,
         delay_s: float = 0.0, match_grace_s: float = MATCH_GRACE_S,
         progress: Optional[bool] = False) -> int:
    """
    Publish a bag's messages with the recorded timing; return how many were published.

    Like ``ros2 bag play``: ``rate`` is the speed factor (2.0 = twice as
    fast); ``topics`` plays only these (default: all); ``remap`` maps a bag
    topic to the topic it is published on; ``wait_for_subscribers`` lists
    published topics that must have a subscriber before anything is
    published (an empty list: every played topic; ConfigError after
    ``discovery_timeout_s``), and then ``match_grace_s`` lets the
    subscribers' side of the match complete (a best-effort subscription, as
    camera images have, drops what arrives before it matched the player);
    ``clock_hz`` > 0 publishes the bag time on ``/clock`` at that rate (and
    with each message); ``loops`` plays the bag that many times (0: until
    interrupted); ``start_offset_s`` skips the bag's first seconds;
    ``delay_s`` waits before each pass; ``progress`` shows a progress line
    on stderr (None: only when it is a terminal). Messages are published as
    recorded (serialized, headers untouched). Before returning, waits up to
    ``wait_acked_s`` for every reliable subscriber to acknowledge everything.
    Runs its own node in ``context`` (a new one, shut down at the end, when
    None).
    """
    import rclpy
    from rclpy.duration import Duration
    from rclpy.serialization import deserialize_message

    def positive(name, value, allow_zero=False):
        ok = isinstance(value, (int, float)) and math.isfinite(value) and (
            value >= 0.0 if allow_zero else value > 0.0)
        if not ok:
            kind = 'non-negative' if allow_zero else 'positive'
            raise ConfigError(f'bag play: {name} must be a {kind} number, got {value!r}')

    positive('rate', rate)
    for name, value in (('clock', clock_hz), ('start offset', start_offset_s),
                        ('delay', delay_s)):
        positive(name, value, allow_zero=True)
    if not isinstance(loops, int) or loops < 0:
        raise ConfigError(f'bag play: loops must be 0 (forever) or more, got {loops!r}')
    remap = dict(remap or {})
    reader = open_bag(bag_dir)
    try:
        by_topic: Dict[str, list] = {}
        for connection in reader.connections:
            by_topic.setdefault(connection.topic, []).append(connection)
        wanted = list(by_topic) if topics is None else list(topics)
        missing = [t for t in wanted if t not in by_topic]
        if missing:
            raise ConfigError(f'{bag_dir}: no topic {", ".join(missing)} in the bag (it has '
                              f'{", ".join(sorted(by_topic)) or "none"})')
        unknown_remaps = [t for t in remap if t not in by_topic]
        if unknown_remaps:
            raise ConfigError(f'bag play: cannot remap {", ".join(unknown_remaps)}: no such '
                              'topic in the bag')
        classes = {}
        for topic in wanted:
            types = {c.msgtype for c in by_topic[topic]}
            if len(types) != 1:
                raise ConfigError(f'{topic}: recorded with several types ({sorted(types)})')
            type_name = types.pop()
            classes[topic] = message_class(type_name)
            for c in by_topic[topic]:
                _check_definition(topic, type_name, c.digest or '')
        out_topics = {topic: remap.get(topic, topic) for topic in wanted}
        waited = (list(out_topics.values()) if wait_for_subscribers is not None
                  and not list(wait_for_subscribers) else list(wait_for_subscribers or ()))
        unknown = [t for t in waited if t not in out_topics.values()]
        if unknown:
            raise ConfigError(f'bag play: cannot wait for subscribers of {", ".join(unknown)}: '
                              'not a topic being played')
        connections = [c for topic in wanted for c in by_topic[topic]]
        total = sum(c.msgcount for c in connections)
        start_ns = reader.start_time + round(start_offset_s * 1e9)

        own_context = context is None
        if own_context:
            context = rclpy.context.Context()
            rclpy.init(args=[], context=context)
        node = None
        published = 0
        bar = None
        try:
            node = rclpy.create_node('pattern_locator_bag_player', context=context)
            publishers = {topic: node.create_publisher(classes[topic], out_topics[topic],
                                                       _qos(by_topic[topic]))
                          for topic in wanted}
            clock = _Clock(node, clock_hz) if clock_hz > 0.0 else None
            by_out = {out_topics[t]: p for t, p in publishers.items()}
            deadline = time.monotonic() + discovery_timeout_s
            for name in waited:
                while by_out[name].get_subscription_count() == 0:
                    if time.monotonic() > deadline:
                        raise ConfigError(f'bag play: no subscriber on {name} after '
                                          f'{discovery_timeout_s:g} s')
                    time.sleep(0.02)
            if waited and match_grace_s > 0.0:
                time.sleep(match_grace_s)
            if progress is not False:
                from tqdm import tqdm
                bar = tqdm(total=total * (loops or 1) if loops else None, unit='msg',
                           desc=f'playing {Path(bag_dir).name}',
                           disable=None if progress is None else False, leave=False)
            checked = set()
            done_loops = 0
            while loops == 0 or done_loops < loops:
                if delay_s > 0.0:
                    time.sleep(delay_s)
                start_wall = first_ns = None
                if clock is not None:
                    clock.restart()
                for connection, stamp_ns, raw in reader.messages(connections=connections,
                                                                 start=start_ns):
                    topic = connection.topic
                    if topic not in checked:
                        try:
                            deserialize_message(bytes(raw), classes[topic])
                        except Exception as exc:  # noqa: B902 - any failure means a bad record
                            raise ConfigError(f'{topic}: the recorded {connection.msgtype} '
                                              f'does not deserialize ({exc})') from None
                        checked.add(topic)
                    if start_wall is None:
                        start_wall, first_ns = time.monotonic(), stamp_ns
                    due = start_wall + (stamp_ns - first_ns) * 1e-9 / rate
                    if clock is not None:
                        clock.sleep_until(due, lambda now: first_ns + round(
                            (now - start_wall) * rate * 1e9))
                        clock.publish(stamp_ns, force=True)
                    else:
                        delay = due - time.monotonic()
                        if delay > 0.0:
                            time.sleep(delay)
                    publishers[topic].publish(bytes(raw))
                    published += 1
                    if bar is not None:
                        bar.update(1)
                        bar.set_postfix_str(f'bag time {stamp_ns * 1e-9:.3f} s', refresh=False)
                done_loops += 1
            unacked = [out_topics[t] for t, p in publishers.items()
                       if not p.wait_for_all_acked(Duration(seconds=wait_acked_s))]
            if unacked:
                node.get_logger().warning(
                    f'not every message was acknowledged within {wait_acked_s:g} s on: '
                    + ', '.join(unacked))
        finally:
            if bar is not None:
                bar.close()
            if node is not None:
                node.destroy_node()
            if own_context:
                rclpy.try_shutdown(context=context)
    finally:
        reader.close()
    return published


def bag_summary(bag: Union[str, Path]) -> Dict[str, Tuple[str, int]]:
    """Return {topic: (type, message count)} of a bag."""
    reader = open_bag(bag)
    try:
        return {topic: (info.msgtype or '(several)', info.msgcount)
                for topic, info in sorted(reader.topics.items())}
    finally:
        reader.close()


# Command-line entry points ---------------------------------------------------------------


def _size(path: Path) -> int:
    if path.is_file():
        return path.stat().st_size
    return sum(p.stat().st_size for p in path.rglob('*') if p.is_file())


def record_sim_main(out: Union[str, Path], **opts) -> int:
    """Record the simulated route into ``out`` and print what was written; return 0."""
    path = record_sim(out, **opts)
    topics = bag_summary(path)
    print(f'{path}: {_size(path) / 1e6:.2f} MB, '
          + ', '.join(f'{t} {n} x {ty}' for t, (ty, n) in topics.items()))
    return 0


def play_main(bag: Union[str, Path], rate: float = 1.0, **opts) -> int:
    """Play a bag into the ROS graph and print how many messages went out; return 0."""
    started = time.monotonic()
    opts.setdefault('progress', None)
    count = play(bag, rate=rate, **opts)
    print(f'{bag}: published {count} messages in {time.monotonic() - started:.1f} s')
    return 0


if __name__ == '__main__':
    if len(sys.argv) != 2:
        print('usage: python -m pattern_locator.nodes.bags OUT_DIR  (writes the test bag)',
              file=sys.stderr)
        sys.exit(2)
    try:
        sys.exit(record_sim_main(sys.argv[1], **TEST_BAG_OPTIONS))
    except PatternLocatorError as exc:
        print(f'error: {exc}', file=sys.stderr)
        sys.exit(2)
