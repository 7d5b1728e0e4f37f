"""
``pattern-locator bench --node``: the locator node end to end over DDS.

A real ``locator`` process receives rendered images of the shipped building
(with their camera_info) from this process, which measures, per resolution:
the sustained throughput (poses per second while images arrive at a fixed
rate), the latency from publishing an image to receiving its
``/robot_location``, and, in the same run and on the same images, the
core's own time per frame (``RobotLocalizer.process`` in this process): the
difference is the node's overhead (conversion, DDS, threads). A first table
compares medians; a second gives each series' tail (mean, p95, p99, max; the
node's own time as its diagnostics report it: median, p95, max).
"""

import math
import os
from pathlib import Path
import tempfile
import time
from typing import Dict, List

import cv2
import numpy as np

from .bench import time_stats
from ..card.pattern import load_pattern_config
from ..localization.building import load_building
from ..localization.head import HeadGeometry
from ..localization.localizer import RobotLocalizer
from ..nodes.bags import render_stop
from ..nodes.image_codec import fill_camera_info, fill_msg
from ..nodes.node_process import locator_process
from ..resources import config_path
from ..vision.camera import CameraModel
from ..vision.geometry import Pose, rodrigues

TILT_DEG = 15.0


def _frames(camera: CameraModel, n: int) -> List[np.ndarray]:
    """Render ``n`` views of the paper's room from spots 3-6 m in front of its card 1."""
    rng = np.random.default_rng(3)
    frames = []
    for i in range(n):
        x, y = rng.uniform(3.0, 6.0), rng.uniform(2.0, 3.0)
        base = Pose(rodrigues(np.array([0.0, 0.0, math.pi + rng.uniform(-0.1, 0.1)])),
                    np.array([x, y, 0.0]))
        frames.append(render_stop(base, 0.0, math.radians(TILT_DEG), camera, seed=i,
                                  noise_sigma=1.5))
    return frames


def _core_ms(camera: CameraModel, frames: List[np.ndarray], rate_hz: float = 0.0
             ) -> List[float]:
    """
    Return the core's time per frame (ms), back to back or paced at ``rate_hz``.

    Paced like the node's input, each frame starts with caches gone cold and
    the CPU clocked down: that is the core time the node is measured against.
    """
    pattern = load_pattern_config()
    localizer = RobotLocalizer(pattern, load_building(None, pattern), HeadGeometry())
    for image in frames[:3]:        # warm up, as the node is before it is measured
        localizer.process(image, camera, 0.0, math.radians(TILT_DEG))
    times = []
    due = time.perf_counter()
    for image in frames[3:]:
        if rate_hz > 0.0:
            due += 1.0 / rate_hz
            time.sleep(max(0.0, due - time.perf_counter()))
        start = time.perf_counter()
        localizer.process(image, camera, 0.0, math.radians(TILT_DEG))
        times.append((time.perf_counter() - start) * 1000.0)
    return times


def _run_node_bench(camera: CameraModel, frames: List[np.ndarray], rate_hz: float) -> Dict:
    # Both sides need room for images in shared memory (a writer puts the
    # sample in its own segment), and discovery stays on this machine.
    os.environ.setdefault('FASTRTPS_DEFAULT_PROFILES_FILE', str(config_path(
        'fastdds_large_messages.xml')))
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    with tempfile.TemporaryDirectory() as tmp, locator_process(
            Path(tmp) / 'locator.log',
            # Rendered scenes at unrelated poses: each image stands alone.
            ['use_joint_states:=false', f'fixed_tilt_deg:={TILT_DEG}',
             'gates.continuity:=false']):
        return _measure(camera, frames, rate_hz)


def _measure(camera: CameraModel, frames: List[np.ndarray], rate_hz: float) -> Dict:
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import PoseStamped
    from sensor_msgs.msg import CameraInfo, Image

    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node('locator_bench', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    arrivals: Dict[int, float] = {}
    node.create_subscription(PoseStamped, '/robot_location',
                             lambda m: arrivals.setdefault(m.header.stamp.nanosec,
                                                           time.perf_counter()), 50)
    diagnostics = []
    node.create_subscription(DiagnosticArray, '/diagnostics',
                             lambda m: diagnostics.append(m), 10)
    pub_image = node.create_publisher(Image, '/camera/image_raw', 10)
    pub_info = node.create_publisher(CameraInfo, '/camera/camera_info', 10)
    info = CameraInfo()
    fill_camera_info(info, camera)
    try:
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline and (pub_image.get_subscription_count() == 0
                                               or node.count_publishers('/robot_location') == 0):
            executor.spin_once(timeout_sec=0.05)
        messages = []
        for i, image in enumerate(frames):
            msg = Image()
            fill_msg(msg, image, 'bgr8')
            msg.header.stamp.sec = 1000
            msg.header.stamp.nanosec = i + 1
            messages.append(msg)
        # Warm up (first frames pay for imports and caches), then measure.
        for msg in messages[:3]:
            pub_info.publish(info)
            pub_image.publish(msg)
            end = time.monotonic() + 2.0
            while time.monotonic() < end and msg.header.stamp.nanosec not in arrivals:
                executor.spin_once(timeout_sec=0.01)
        sent: Dict[int, float] = {}
        period = 1.0 / rate_hz
        start = time.perf_counter()
        for i, msg in enumerate(messages[3:]):
            due = start + i * period
            # Block in the wait set until due (a busy loop here would take the
            # CPU the node needs).
            while time.perf_counter() < due:
                executor.spin_once(timeout_sec=max(0.0, due - time.perf_counter()))
            pub_info.publish(info)
            sent[msg.header.stamp.nanosec] = time.perf_counter()
            pub_image.publish(msg)
        end = time.perf_counter() + 2.5
        while time.perf_counter() < end:
            executor.spin_once(timeout_sec=0.01)
        counts = {kv.key: kv.value for kv in diagnostics[-1].status[0].values} if diagnostics \
            else {}
        duration = (len(messages) - 3) * period
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=context)
    latencies = [(arrivals[k] - t) * 1000.0 for k, t in sent.items() if k in arrivals]
    return {
        'sent': len(sent), 'located': len(latencies), 'node': counts,
        'fps': len(latencies) / duration if duration else math.nan,
        'latencies_ms': latencies,
    }


def _node_ms(counts: Dict[str, str], statistic: str) -> float:
    """Return one of the node's own timings (``median``, ``p95``, ``max``) from its diagnostics."""
    try:
        return float(counts[f'in_node_ms_{statistic}'])
    except (KeyError, ValueError):
        return math.nan


def tail_table(rows: Dict[str, Dict[str, object]]) -> str:
    """
    Each series' median, mean, p95, p99 and max (ms), per resolution.

    ``rows`` maps a resolution to its series: ``tight``, ``paced`` and
    ``latency`` (lists of ms) and ``node`` (the node's diagnostics values,
    which keep its own time as median, p95 and max: its other columns
    read ``-``).
    """
    def cell(value: float) -> str:
        return f'{value:>8.2f}' if math.isfinite(value) else f'{"-":>8}'

    lines = [f'{"resolution, series":<26}{"median":>8}{"mean":>8}{"p95":>8}{"p99":>8}{"max":>8}']
    for size, row in rows.items():
        for label, key in (('core tight', 'tight'), ('core paced', 'paced'),
                           ('in the node', 'node'), ('latency', 'latency')):
            if key == 'node':
                values = (_node_ms(row['node'], 'median'), math.nan,
                          _node_ms(row['node'], 'p95'), math.nan, _node_ms(row['node'], 'max'))
            else:
                series = row[key]
                median, mean, p99, largest = time_stats(series)
                p95 = float(np.percentile(series, 95)) if len(series) else math.nan
                values = (median, mean, p95, p99, largest)
            lines.append(f'{f"{size} {label}":<26}' + ''.join(cell(v) for v in values))
    return '\n'.join(lines)


def run_node_bench(frames_per_size: int = 40, rate_hz: float = 30.0) -> int:
    """Print throughput and latency of the node next to the core's time per frame."""
    cv2.setNumThreads(1)
    print(f'locator node over DDS: {frames_per_size} images per resolution published at '
          f'{rate_hz:g} Hz to a locator process on this machine')
    print(f'{"resolution":<12}{"core tight":>11}{"core ms":>9}{"node ms":>9}{"latency med":>13}'
          f'{"p95":>8}{"DDS":>7}{"node - core":>13}{"located":>9}{"fps":>7}')
    tails: Dict[str, Dict[str, object]] = {}
    for camera in (CameraModel.from_fov(640, 480, 60.0), CameraModel.from_fov(1280, 720, 60.0)):
        frames = _frames(camera, frames_per_size + 3)
        tight_times = _core_ms(camera, frames)
        paced_times = _core_ms(camera, frames, rate_hz)
        result = _run_node_bench(camera, frames, rate_hz)
        tight, core = float(np.median(tight_times)), float(np.median(paced_times))
        latencies = result['latencies_ms']
        latency = float(np.median(latencies)) if latencies else math.nan
        latency_p95 = float(np.percentile(latencies, 95)) if latencies else math.nan
        node = _node_ms(result['node'], 'median')
        size = f'{camera.width}x{camera.height}'
        tails[size] = {'tight': tight_times, 'paced': paced_times,
                       'latency': latencies, 'node': result['node']}
        print(f'{size:<12}{tight:>11.2f}{core:>9.2f}{node:>9.2f}'
              f'{latency:>13.2f}{latency_p95:>8.2f}'
              f'{latency - node:>7.2f}{node - core:>13.2f}'
              f'{f"{result["located"]}/{result["sent"]}":>9}{result["fps"]:>7.1f}')
    print("core tight: the core's median time per frame back to back in this process; "
          'core ms: the same, paced at the rate above as the node receives them (each frame '
          'starts with cold caches); '
          'node ms: median time from the arrival of an image in the node to its pose '
          'published (from the node diagnostics); latency: image published -> /robot_location '
          'received; '
          'DDS: latency minus node ms (carrying the image to the node and the pose back, '
          'rclpy included); node - core: what the node adds to the core (conversion, hand-off '
          'to its worker, publishing); '
          'fps: poses per second '
          'while images arrive at the rate above (the node drops frames it cannot keep up with)')
    print('\nThe same series with their tails (ms); the node reports median, p95 and max of '
          'its recent frames (its diagnostics), so its mean and p99 are not known here:')
    print(tail_table(tails))
    return 0
