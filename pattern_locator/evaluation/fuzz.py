"""
``pattern-locator bench --fuzz``: malformed messages into a real locator process.

A ``locator`` process (joint states on) receives, over DDS, tens of
thousands of malformed ``camera/image_raw``, ``camera/camera_info`` and
``camera/joint_states`` messages, interleaved with good ones, in slots of
their own on one increasing timeline (each slot 10 s of stamps: no slot's
joint states reach another's images). In a slot one input is bad and the
others are good, so a pose stamped in that slot is a pose for bad input.
Bursts of large noise frames test memory. The summary line gives: poses for
bad input, non-finite values published, tracebacks in the node's output,
the node's RSS against its warm baseline (peak, and after the bursts once
the node went idle), log bytes per minute of garbage, and whether a good
image is still located at the end.

Categories are *structural* (the message itself is broken: the node must
refuse it whatever the core does) or *implausible* (well-formed but
impossible values: intrinsics, joint angles; the ROS-free validators'
job). The test suite runs a short version (``test/nodes/test_fuzz_node.py``).
"""

from dataclasses import dataclass, field
import math
import os
from pathlib import Path
import re
import tempfile
import time
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from ..nodes.bags import render_stop
from ..nodes.image_codec import fill_camera_info
from ..nodes.node_process import locator_process
from ..resources import config_path
from ..vision.camera import CameraModel
from ..vision.geometry import Pose, rodrigues

# The good view: 2.5 m in front of card 1 of floor 1 room 3, head tilted up.
# A narrow lens: the card spans ~40 px, well inside what the detector reads
# (a 60 degree lens left it ~25 px wide, at the edge of its range).
GOOD_CAMERA = CameraModel.from_fov(320, 240, 40.0)
TILT = math.radians(15.0)
GOOD_BASE = Pose(rodrigues(np.array([0.0, 0.0, math.pi])), np.array([3.0, 2.5, 0.0]))
SLOT_S = 10
FIRST_SLOT_SEC = 1_000_000
BIG_SIDE = 2000              # noise frames of the bursts: 2000x2000 bgr8, 12 MB
JOINT_OFFSET_NS = 50_000_000


@dataclass(frozen=True)
class Case:
    """One slot's messages: what is published, in order, and which category it tests."""

    category: str
    structural: bool
    messages: Tuple[Tuple[str, object], ...]      # (topic key, message)


@dataclass
class FuzzSummary:
    """What one fuzz run measured."""

    messages: int = 0
    bad_slots: int = 0
    good_sent: int = 0
    good_located: int = 0
    poses_for_bad: Dict[str, int] = field(default_factory=dict)
    slots_by_category: Dict[str, int] = field(default_factory=dict)
    non_finite: int = 0
    tracebacks: int = 0
    rss_baseline_mb: float = math.nan
    rss_peak_mb: float = math.nan
    rss_after_mb: float = math.nan
    log_bytes: int = 0
    garbage_s: float = 0.0
    alive: bool = False
    final_good_located: bool = False
    node_counts: Dict[str, str] = field(default_factory=dict)

    @property
    def structural_poses(self) -> int:
        """Return the poses for bad input in structural categories."""
        return sum(n for c, n in self.poses_for_bad.items() if c in STRUCTURAL)

    @property
    def log_bytes_per_min(self) -> float:
        """Return the node's log bytes per minute of garbage."""
        return self.log_bytes / max(self.garbage_s, 1e-9) * 60.0

    def line(self) -> str:
        """Return the one-line summary."""
        return (f'fuzz: {self.messages} messages ({self.bad_slots} bad slots), '
                f'poses for bad input {sum(self.poses_for_bad.values())} '
                f'(structural {self.structural_poses}), non-finite values {self.non_finite}, '
                f'tracebacks {self.tracebacks}, RSS baseline {self.rss_baseline_mb:.0f} MB '
                f'peak {self.rss_peak_mb:.0f} MB after bursts {self.rss_after_mb:.0f} MB '
                f'({self.rss_after_mb - self.rss_baseline_mb:+.0f} MB), log '
                f'{self.log_bytes_per_min / 1024:.1f} KB/min over {self.garbage_s:.0f} s, '
                f'good located {self.good_located}/{self.good_sent}, node alive '
                f'{"yes" if self.alive else "NO"}, good image after: '
                f'{"located" if self.final_good_located else "NOT located"}')


# Messages ------------------------------------------------------------------------------


def _stamp(msg, ns: int) -> None:
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(ns), 10 ** 9)


def _image(ns: int, width: int, height: int, encoding: str, step: int, data: bytes,
           frame_id: str = 'camera_optical_frame'):
    from sensor_msgs.msg import Image
    msg = Image()
    _stamp(msg, ns)
    msg.header.frame_id = frame_id
    msg.width, msg.height, msg.encoding, msg.step = width, height, encoding, step
    msg.data = data
    return msg


def _info(ns: int, camera: CameraModel, **fields):
    from sensor_msgs.msg import CameraInfo
    msg = CameraInfo()
    fill_camera_info(msg, camera)
    _stamp(msg, ns)
    msg.header.frame_id = 'camera_optical_frame'
    for name, value in fields.items():
        setattr(msg, name, value)
    return msg


def _joints(ns: int, names: Sequence[str], positions: Sequence[float]):
    from sensor_msgs.msg import JointState
    msg = JointState()
    _stamp(msg, ns)
    msg.name = list(names)
    msg.position = [float(v) for v in positions]
    return msg


def _garbage_text(rng: np.random.Generator) -> str:
    length = int(rng.choice([1, 20, 300, 5000, 135_000]))
    # No NUL: a ROS string cannot hold one (DDS would cut the string there).
    alphabet = 'abcXYZ019_/\\\'"\n\r\t\x07\x1b[31m\u00e9\u4e2d\U0001f600 '
    return ''.join(rng.choice(list(alphabet), size=length))


class Generator:
    """Seeded malformed (and good) messages, one slot at a time."""

    def __init__(self, seed: int = 1) -> None:
        self.rng = np.random.default_rng(seed)
        image = render_stop(GOOD_BASE, 0.0, TILT, GOOD_CAMERA, seed=seed, noise_sigma=1.0)
        self.good_data = image.tobytes()
        self.slot = 0

    def next_ns(self) -> int:
        """Return the stamp (ns) of the next slot."""
        self.slot += 1
        return (FIRST_SLOT_SEC + SLOT_S * self.slot) * 10 ** 9 + 123_456

    def _good_joints(self, ns: int) -> List[Tuple[str, object]]:
        return [('joints', _joints(ns - JOINT_OFFSET_NS, ['camera_pan', 'camera_tilt'],
                                   [0.0, TILT]))]

    def _good_after(self, ns: int) -> List[Tuple[str, object]]:
        return [('joints', _joints(ns + JOINT_OFFSET_NS, ['camera_pan', 'camera_tilt'],
                                   [0.0, TILT]))]

    def _good_image(self, ns: int):
        c = GOOD_CAMERA
        return _image(ns, c.width, c.height, 'bgr8', 3 * c.width, self.good_data)

    def good(self) -> Case:
        """Return a good slot (it must be located)."""
        ns = self.next_ns()
        return Case('good', True, tuple(self._good_joints(ns) + [
            ('info', _info(ns, GOOD_CAMERA)), ('image', self._good_image(ns))]
            + self._good_after(ns)))

    # Bad images (with a good camera_info for the size they claim) ---------------------

    def bad_image(self) -> Case:
        """Return a slot with a malformed image."""
        rng = self.rng
        ns = self.next_ns()
        w, h = int(rng.integers(2, 64)) * 2, int(rng.integers(2, 48)) * 2
        kind = str(rng.choice(['encoding', 'size mismatch', 'step too small', 'zero size',
                               'huge declared size', 'odd yuv width', 'tiny bayer',
                               'garbage frame_id', 'info size mismatch', 'mono16 odd']))
        data = rng.integers(0, 256, size=h * w * 3, dtype=np.uint8).tobytes()
        info_w, info_h = w, h
        frame_id = 'camera_optical_frame'
        if kind == 'encoding':
            msg = _image(ns, w, h, _garbage_text(rng), 3 * w, data)
        elif kind == 'size mismatch':
            msg = _image(ns, w, h, 'bgr8', 3 * w, data[:len(data) - int(rng.integers(1, 99))])
        elif kind == 'step too small':
            msg = _image(ns, w, h, 'bgr8', 3 * w - 1, data)
        elif kind == 'zero size':
            msg = _image(ns, 0, int(rng.integers(0, 3)), 'bgr8', 0, b'')
        elif kind == 'huge declared size':
            w, h = int(rng.integers(10 ** 4, 10 ** 6)), int(rng.integers(10 ** 4, 10 ** 6))
            msg = _image(ns, w, h, 'rgb8', 3 * w, data)
            info_w, info_h = min(w, 65536), min(h, 65536)
        elif kind == 'odd yuv width':
            w += 1
            msg = _image(ns, w, h, 'yuv422', 2 * w, data[:2 * w * h])
            info_w = w
        elif kind == 'tiny bayer':
            msg = _image(ns, 1, 1, 'bayer_rggb8', 1, b'\x10')
            info_w, info_h = 1, 1
        elif kind == 'garbage frame_id':
            frame_id = _garbage_text(rng)
            msg = _image(ns, w, h, 'bgr8', 3 * w, data[:5], frame_id)
        elif kind == 'info size mismatch':
            msg = _image(ns, w, h, 'bgr8', 3 * w, data)
            info_w = w + 2
        else:
            msg = _image(ns, w, h, 'mono16', 2 * w, data[:2 * w * h - 1])
        camera = CameraModel.from_fov(max(info_w, 1), max(info_h, 1), 60.0)
        return Case(f'image: {kind}', True, tuple(self._good_joints(ns) + [
            ('info', _info(ns, camera)), ('image', msg)] + self._good_after(ns)))

    def big_noise(self) -> Case:
        """Return a slot with a large noise frame (allowed in size: it is processed)."""
        ns = self.next_ns()
        side = BIG_SIDE
        data = self.rng.integers(0, 256, size=side * side * 3, dtype=np.uint8).tobytes()
        camera = CameraModel.from_fov(side, side, 60.0)
        return Case('image: large noise frame', True, tuple(self._good_joints(ns) + [
            ('info', _info(ns, camera)),
            ('image', _image(ns, side, side, 'bgr8', 3 * side, data))]
            + self._good_after(ns)))

    def oversize(self) -> Case:
        """Return a slot with a frame above max_image_pixels, full data (refused up front)."""
        ns = self.next_ns()
        w, h = 2600, 1700
        data = bytes(w * h * 3)
        camera = CameraModel.from_fov(w, h, 60.0)
        return Case('image: oversize', True, tuple(self._good_joints(ns) + [
            ('info', _info(ns, camera)), ('image', _image(ns, w, h, 'bgr8', 3 * w, data))]
            + self._good_after(ns)))

    # Bad camera_info (with the good image) ---------------------------------------------

    def bad_info(self, structural: bool) -> Case:
        """Return a slot with a malformed (structural) or implausible camera_info."""
        rng = self.rng
        ns = self.next_ns()
        c = GOOD_CAMERA
        k = [float(v) for v in c.K.ravel()]
        if structural:
            kind = str(rng.choice(['K not finite', 'K zero', 'fx negative', 'D not finite',
                                   'size zero', 'distortion model garbage']))
        else:
            kind = str(rng.choice(['fx extreme', 'K22 not 1', 'bottom row', 'skew',
                                   'fx far from fy', 'centre outside', 'D huge']))
        fields: Dict[str, object] = {}
        if kind == 'K not finite':
            bad_value = float(rng.choice([math.nan, math.inf, -math.inf]))
            k[int(rng.choice([0, 2, 4, 5, 8]))] = bad_value
        elif kind == 'K zero':
            k = [0.0] * 9
        elif kind == 'fx negative':
            k[0] = -k[0]
        elif kind == 'D not finite':
            fields['d'] = [0.0, float(rng.choice([math.nan, math.inf])), 0.0, 0.0, 0.0]
        elif kind == 'size zero':
            fields['width'] = 0
        elif kind == 'distortion model garbage':
            fields['distortion_model'] = _garbage_text(rng)
        elif kind == 'fx extreme':
            k[0] = k[4] = float(rng.choice([1e-300, 1e-30, 1e30, 5e307]))
        elif kind == 'K22 not 1':
            k[8] = float(rng.choice([0.0, 0.5, 2.0, 1e6]))
        elif kind == 'bottom row':
            k[6], k[7] = float(rng.uniform(-1, 1)), float(rng.uniform(-1, 1))
        elif kind == 'skew':
            k[1] = float(rng.uniform(50, 500))
            k[3] = float(rng.uniform(0.1, 10))
        elif kind == 'fx far from fy':
            k[4] = k[0] * float(rng.choice([0.01, 100.0]))
        elif kind == 'centre outside':
            k[2], k[5] = float(rng.choice([-5000.0, 1e6])), float(rng.choice([-5000.0, 1e6]))
        else:
            fields['d'] = [float(rng.choice([1e300, -1e300, 1e6])), 0.0, 0.0, 0.0, 0.0]
        fields['k'] = k
        return Case(f'camera_info: {kind}', structural, tuple(self._good_joints(ns) + [
            ('info', _info(ns, c, **fields)), ('image', self._good_image(ns))]
            + self._good_after(ns)))

    # Bad joint states (before and after the good image) --------------------------------

    def bad_joints(self, structural: bool) -> Case:
        """Return a slot whose joint states (before and after the image) are bad."""
        rng = self.rng
        ns = self.next_ns()
        if structural:
            kind = str(rng.choice(['not finite', 'pan missing', 'length mismatch', 'empty',
                                   'garbage names']))
        else:
            kind = str(rng.choice(['duplicate names', 'pan far outside travel',
                                   'tilt outside travel']))

        def one(t_ns):
            names, values = ['camera_pan', 'camera_tilt'], [0.0, TILT]
            if kind == 'not finite':
                values[int(rng.integers(0, 2))] = float(rng.choice([math.nan, math.inf]))
            elif kind == 'pan missing':
                names = ['camera_tilt']
                values = [TILT]
            elif kind == 'length mismatch':
                values = [0.0]
            elif kind == 'empty':
                names, values = [], []
            elif kind == 'garbage names':
                names = [_garbage_text(rng), _garbage_text(rng)]
            elif kind == 'duplicate names':
                names = ['camera_pan', 'camera_tilt', 'camera_pan', 'camera_tilt']
                values = [0.5, -0.4, 0.0, TILT]
            elif kind == 'pan far outside travel':
                values[0] = float(rng.choice([1e6, -65.0, 2 * math.pi + 0.5]))
            else:
                values[1] = float(rng.choice([math.radians(89.0), -1.5]))
            return ('joints', _joints(t_ns, names, values))

        return Case(f'joint_states: {kind}', structural, (
            one(ns - JOINT_OFFSET_NS), ('info', _info(ns, GOOD_CAMERA)),
            ('image', self._good_image(ns)), one(ns + JOINT_OFFSET_NS)))


STRUCTURAL_KINDS = {
    'image': ['encoding', 'size mismatch', 'step too small', 'zero size', 'huge declared size',
              'odd yuv width', 'tiny bayer', 'garbage frame_id', 'info size mismatch',
              'mono16 odd', 'large noise frame', 'oversize'],
    'camera_info': ['K not finite', 'K zero', 'fx negative', 'D not finite', 'size zero',
                    'distortion model garbage'],
    'joint_states': ['not finite', 'pan missing', 'length mismatch', 'empty', 'garbage names'],
}
STRUCTURAL = {f'{topic}: {kind}' for topic, kinds in STRUCTURAL_KINDS.items()
              for kind in kinds}


# The run --------------------------------------------------------------------------------


def rss_mb(pid: int, field: str = 'VmRSS') -> float:
    """
    Return a process's resident memory in MB (NaN when it cannot be read).

    ``field``: ``VmRSS`` (all of it), ``RssAnon`` (its private memory: the
    heap), ``RssShmem`` (shared memory it touched: DDS segments).
    """
    try:
        text = Path(f'/proc/{pid}/status').read_text()
    except OSError:
        return math.nan
    match = re.search(rf'^{field}:\s+(\d+)\s+kB', text, re.MULTILINE)
    return int(match[1]) / 1024.0 if match else math.nan


def memory_text(pid: int) -> str:
    """Return RSS with its private (anon) and shared-memory parts, for progress lines."""
    return (f'RSS {rss_mb(pid):.0f} MB (anon {rss_mb(pid, "RssAnon"):.0f}, shm '
            f'{rss_mb(pid, "RssShmem"):.0f})')


class _Client:
    """This process's side: publishers of the three inputs, subscribers of every output."""

    def __init__(self, node, executor) -> None:
        from diagnostic_msgs.msg import DiagnosticArray
        from geometry_msgs.msg import PointStamped, PoseStamped, PoseWithCovarianceStamped
        from rclpy.qos import QoSProfile
        from sensor_msgs.msg import CameraInfo, Image, JointState

        self.node, self.executor = node, executor
        deep = QoSProfile(depth=1000)
        self.pubs = {'image': node.create_publisher(Image, 'camera/image_raw', 10),
                     'info': node.create_publisher(CameraInfo, 'camera/camera_info', 50),
                     'joints': node.create_publisher(JointState, 'camera/joint_states', 50)}
        self.poses: List[int] = []
        self.non_finite = 0
        self.diagnostics: Dict[str, str] = {}
        node.create_subscription(PoseStamped, 'robot_location', self._on_pose, deep)
        node.create_subscription(PoseWithCovarianceStamped, 'robot_location/with_covariance',
                                 self._on_cov, deep)
        node.create_subscription(PointStamped, 'pattern_locator/target', self._on_target, deep)
        node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diag, 10)

    @staticmethod
    def _key(msg) -> int:
        return msg.header.stamp.sec * 10 ** 9 + msg.header.stamp.nanosec

    def _check(self, values) -> None:
        if not all(math.isfinite(v) for v in values):
            self.non_finite += 1

    def _on_pose(self, msg) -> None:
        p, q = msg.pose.position, msg.pose.orientation
        self._check([p.x, p.y, p.z, q.x, q.y, q.z, q.w])
        self.poses.append(self._key(msg))

    def _on_cov(self, msg) -> None:
        p = msg.pose.pose.position
        self._check([p.x, p.y, p.z] + list(msg.pose.covariance))

    def _on_target(self, msg) -> None:
        self._check([msg.point.x, msg.point.y, msg.point.z])

    def _on_diag(self, msg) -> None:
        for status in msg.status:
            if status.name == 'pattern_locator: locator':
                self.diagnostics = {kv.key: kv.value for kv in status.values}

    def spin(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while True:
            self.executor.spin_once(timeout_sec=max(0.0, min(0.01, end - time.monotonic())))
            if time.monotonic() >= end:
                return

    def publish(self, case: Case) -> int:
        for key, msg in case.messages:
            self.pubs[key].publish(msg)
        return len(case.messages)

    def wait_for_pose(self, ns: int, timeout_s: float) -> bool:
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.02)
            if ns in self.poses:
                return True
        return ns in self.poses


def _stamp_of(case: Case) -> int:
    for key, msg in case.messages:
        if key == 'image':
            return msg.header.stamp.sec * 10 ** 9 + msg.header.stamp.nanosec
    raise ValueError('a case without an image')


def run_fuzz(messages: int = 32_000, seed: int = 1, bursts: int = 5, burst_frames: int = 20,
             slot_rate_hz: float = 50.0, implausible: bool = True, log_dir: Optional[Path] = None,
             progress: Optional[Callable[[str], None]] = None) -> FuzzSummary:
    """
    Run a locator process, feed it about ``messages`` messages; return the summary.

    Slots are published at ``slot_rate_hz``; one slot in 20 is good (it
    must be located: the node keeps working), and ``bursts`` bursts of
    ``burst_frames`` large noise frames and oversized frames are spread
    over the run. ``implausible``: include the implausible categories too.
    """
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    os.environ.setdefault('FASTRTPS_DEFAULT_PROFILES_FILE',
                          str(config_path('fastdds_large_messages.xml')))
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    say = progress or (lambda text: None)
    summary = FuzzSummary()
    gen = Generator(seed)
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(log_dir or tmp) / 'locator_fuzz.log'
        log.parent.mkdir(parents=True, exist_ok=True)
        # Continuity off: the good images are sparse and unrelated, and no pose
        # for bad input must come from the validators alone, not be hidden
        # by the gates holding back jumps.
        with locator_process(log, ['use_joint_states:=true', 'joint_state_warmup_s:=0.2',
                                   'gates.continuity:=false']) as proc:
            context = Context()
            rclpy.init(context=context)
            node = rclpy.create_node('locator_fuzzer', context=context)
            executor = SingleThreadedExecutor(context=context)
            executor.add_node(node)
            try:
                client = _Client(node, executor)
                _run(client, gen, proc, log, summary, messages, bursts, burst_frames,
                     slot_rate_hz, implausible, say)
            finally:
                executor.shutdown()
                node.destroy_node()
                rclpy.shutdown(context=context)
            summary.alive = proc.poll() is None
        text = log.read_text(errors='replace')
        summary.tracebacks = text.count('Traceback')
    return summary


def _run(client: _Client, gen: Generator, proc, log: Path, summary: FuzzSummary,
         messages: int, bursts: int, burst_frames: int, slot_rate_hz: float,
         implausible: bool, say: Callable[[str], None]) -> None:
    deadline = time.monotonic() + 30.0
    while time.monotonic() < deadline and any(
            p.get_subscription_count() == 0 for p in client.pubs.values()):
        client.spin(0.05)
    client.spin(0.3)
    # Warm up: good slots until they are located, then the baseline RSS.
    for _ in range(10):
        case = gen.good()
        client.publish(case)
        client.wait_for_pose(_stamp_of(case), 3.0)
    client.spin(1.5)
    summary.rss_baseline_mb = rss_mb(proc.pid)
    summary.rss_peak_mb = summary.rss_baseline_mb
    say(f'warm: {memory_text(proc.pid)}')
    log_start = log.stat().st_size
    started = time.monotonic()
    period = 1.0 / slot_rate_hz
    good_stamps: List[int] = []
    bad: Dict[int, str] = {}
    rng = gen.rng
    per_slot = 4
    n_slots = max(1, messages // per_slot)
    burst_at = {int(n_slots * (k + 1) / (bursts + 1)) for k in range(bursts)}
    due = time.monotonic()
    sent = 0
    for i in range(n_slots):
        if i in burst_at:
            for j in range(burst_frames):
                case = gen.big_noise() if j % 2 == 0 else gen.oversize()
                bad[_stamp_of(case)] = case.category
                sent += client.publish(case)
                client.spin(0.02)
                summary.rss_peak_mb = max(summary.rss_peak_mb, rss_mb(proc.pid))
            say(f'burst after {sent} messages: {memory_text(proc.pid)}')
        if i % 20 == 0:
            case = gen.good()
            good_stamps.append(_stamp_of(case))
        else:
            pick = rng.random()
            if pick < 0.4:
                case = gen.bad_image()
            elif pick < 0.7:
                case = gen.bad_info(structural=not implausible or rng.random() < 0.5)
            else:
                case = gen.bad_joints(structural=not implausible or rng.random() < 0.5)
            bad[_stamp_of(case)] = case.category
            summary.slots_by_category[case.category] = \
                summary.slots_by_category.get(case.category, 0) + 1
        sent += client.publish(case)
        due += period
        if case.category == 'good':
            # Let the node drain: a good slot must be located, not dropped.
            client.wait_for_pose(_stamp_of(case), 1.0)
            due = max(due, time.monotonic())
        client.spin(max(0.0, due - time.monotonic()))
        if i % 500 == 0:
            summary.rss_peak_mb = max(summary.rss_peak_mb, rss_mb(proc.pid))
            if i:
                say(f'{sent} messages, {len(client.poses)} poses, {memory_text(proc.pid)}')
    summary.garbage_s = time.monotonic() - started
    client.spin(3.0)
    summary.log_bytes = log.stat().st_size - log_start
    # After the bursts, idle: the node gave big buffers back.
    summary.rss_after_mb = rss_mb(proc.pid)
    say(f'idle after the garbage: {memory_text(proc.pid)}')
    summary.messages = sent
    summary.bad_slots = len(bad)
    summary.good_sent = len(good_stamps)
    located = set(client.poses)
    summary.good_located = sum(1 for s in good_stamps if s in located)
    for stamp in located:
        if stamp in bad:
            summary.poses_for_bad[bad[stamp]] = summary.poses_for_bad.get(bad[stamp], 0) + 1
    summary.non_finite = client.non_finite
    final = gen.good()
    for _ in range(3):
        client.publish(final)
        if client.wait_for_pose(_stamp_of(final), 3.0):
            break
    summary.final_good_located = _stamp_of(final) in set(client.poses)
    client.spin(1.2)
    summary.node_counts = dict(client.diagnostics)


def run_fuzz_bench(messages: int = 32_000, seed: int = 1) -> int:
    """Print the fuzz run's progress, the poses for bad input by category and the summary."""
    print(f'locator fuzz: about {messages} messages (malformed images, camera_info and joint '
          'states, good ones in between, bursts of 2000x2000 noise and oversized frames) into '
          'a locator process over DDS', flush=True)
    summary = run_fuzz(messages=messages, seed=seed,
                       progress=lambda text: print(f'  {text}', flush=True))
    print('\nslots by category (poses published for them):')
    for category in sorted(summary.slots_by_category):
        kind = 'structural' if category in STRUCTURAL else 'implausible'
        print(f'  {category:<42} {summary.slots_by_category[category]:>6}  {kind:<11} '
              f'poses {summary.poses_for_bad.get(category, 0)}')
    counts = summary.node_counts
    print(f"\nnode: received {counts.get('received')}, processed {counts.get('processed')}, "
          f"dropped {counts.get('dropped')}, refused oversize {counts.get('refused_oversize')}, "
          f"located {counts.get('located')}, problems counted {counts.get('rejected')}")
    print(summary.line())
    ok = (summary.structural_poses == 0 and summary.non_finite == 0 and summary.tracebacks == 0
          and summary.alive and summary.final_good_located)
    return 0 if ok else 1
