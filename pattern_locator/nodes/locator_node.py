"""
The ``locator`` node: camera images in, the robot's place in the building out.

Subscribes to ``/camera/image_raw`` (sensor_msgs/Image, sensor-data QoS),
``/camera/camera_info`` (sensor_msgs/CameraInfo, kept current: a zoom
camera's intrinsics change) and ``/camera/joint_states``
(sensor_msgs/JointState, ``camera_pan``/``camera_tilt``; only when
``use_joint_states`` is true, else the fixed angles are used).

Publishes ``/robot_location`` (geometry_msgs/PoseStamped: the base pose, the
image's stamp, the room frame or ``building``), ``/robot_location/ids``
(std_msgs/UInt16MultiArray: floor, room, pattern),
``/robot_location/with_covariance`` (geometry_msgs/PoseWithCovarianceStamped),
``/pattern_locator/target`` (geometry_msgs/PointStamped: pan and tilt to
centre the card, its size in px), ``/pattern_locator/debug_image`` (only
drawn while someone subscribes) and ``/diagnostics``. The node's settings are
in ``config/locator.yaml``; each is declared with a description and a range.

Only the newest frame is processed: when the work is slower than the camera,
older frames are dropped and counted, never queued. Bad input (an unknown
encoding, a short buffer, a bad camera_info, a code not in the map) gives a
throttled warning and a diagnostics entry, never a pose.
"""

import collections
import math
import threading
import time
from typing import Optional, Tuple

import cv2
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PointStamped, PoseStamped, PoseWithCovarianceStamped
import numpy as np
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import MultiArrayDimension, UInt16MultiArray

from .image_codec import camera_from_info, fill_msg, image_from_msg
from .ros_helpers import fill_pose, parameter_values, run_node, stamp_seconds
from ..card.pattern import load_pattern_config
from ..errors import PatternLocatorError
from ..localization.building import load_building
from ..localization.head import angles_from_joint_state, HeadGeometry, JointStateBuffer
from ..localization.localizer import FrameResult, RobotLocalizer
from ..vision.camera import CameraModel
from ..vision.overlay import draw_overlay

THROTTLE_S = 5.0


CAMERA_INFO_HISTORY = 60
PARAMETERS = (
    'pattern_config', 'building_map', 'estimator', 'output_frame', 'fusion', 'base_frame',
    'min_tilt_deg', 'max_reprojection_px', 'use_joint_states', 'fixed_pan_deg', 'fixed_tilt_deg',
    'joint_state_max_age_s', 'joint_state_wait_s', 'opencv_threads', 'head.base_to_pan_xyz',
    'head.pan_to_tilt_xyz', 'head.tilt_to_optical_xyz', 'head.mount_pitch_deg')


def _stamp_key(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


class LocatorNode(Node):
    """Thin ROS shell around :class:`localizer.RobotLocalizer`."""

    def __init__(self, **kwargs) -> None:
        super().__init__('locator', **kwargs)
        self._declare_parameters()
        p = self._params()
        # One frame's work is small: OpenCV's own threads only contend with
        # the node's and the camera pipeline's.
        cv2.setNumThreads(int(p['opencv_threads']))
        pattern = load_pattern_config(p['pattern_config'] or None)
        building = load_building(p['building_map'] or None, pattern)
        self.head = HeadGeometry(
            base_to_pan_xyz=tuple(p['head.base_to_pan_xyz']),
            pan_to_tilt_xyz=tuple(p['head.pan_to_tilt_xyz']),
            tilt_to_optical_xyz=tuple(p['head.tilt_to_optical_xyz']),
            mount_pitch_rad=math.radians(p['head.mount_pitch_deg']))
        self.localizer = RobotLocalizer(
            pattern, building, self.head, estimator=p['estimator'],
            output_frame=p['output_frame'], fusion=p['fusion'],
            min_tilt_deg=p['min_tilt_deg'], max_reprojection_px=p['max_reprojection_px'])
        self.fixed_angles = (math.radians(p['fixed_pan_deg']), math.radians(p['fixed_tilt_deg']))
        self.use_joint_states = p['use_joint_states']
        self.joints = JointStateBuffer(max_age_s=p['joint_state_max_age_s'])
        self.joint_wait_s = p['joint_state_wait_s']
        self._joint_arrived = threading.Condition()
        self.get_logger().info('locator configuration: ' + ', '.join(
            f'{k}={v}' for k, v in sorted(p.items())))

        self.camera: Optional[CameraModel] = None
        # Recent intrinsics by stamp: a zooming camera's image is matched with
        # the camera_info of its own stamp, not with whatever came last.
        self._cameras_by_stamp: 'collections.OrderedDict[int, CameraModel]' = \
            collections.OrderedDict()
        self._camera_problem = 'no camera_info received yet'
        self._latest: Optional[Image] = None
        self._wake = threading.Condition()
        self._stopping = False
        self._last_logged = {}
        self._times = collections.deque(maxlen=100)
        self._latest_arrival = 0.0
        self._stats_lock = threading.Lock()
        self.stats = {'received': 0, 'processed': 0, 'dropped': 0, 'located': 0,
                      'rejected': 0, 'last_problem': ''}

        self.pub_pose = self.create_publisher(PoseStamped, '/robot_location', 10)
        self.pub_ids = self.create_publisher(UInt16MultiArray, '/robot_location/ids', 10)
        self.pub_cov = self.create_publisher(PoseWithCovarianceStamped,
                                             '/robot_location/with_covariance', 10)
        self.pub_target = self.create_publisher(PointStamped, '/pattern_locator/target', 10)
        self.pub_debug = self.create_publisher(Image, '/pattern_locator/debug_image', 1)
        self.pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.create_subscription(Image, '/camera/image_raw', self._on_image,
                                 qos_profile_sensor_data)
        self.create_subscription(CameraInfo, '/camera/camera_info', self._on_camera_info,
                                 qos_profile_sensor_data)
        if self.use_joint_states:
            self.create_subscription(JointState, '/camera/joint_states', self._on_joints,
                                     qos_profile_sensor_data)
        self.create_timer(1.0, self._publish_diagnostics)
        self._worker = threading.Thread(target=self._work, name='locator-worker', daemon=True)
        self._worker.start()

    # Parameters ---------------------------------------------------------------

    def _declare_parameters(self) -> None:
        def number(name, value, description, low, high):
            self.declare_parameter(name, value, ParameterDescriptor(
                description=description,
                floating_point_range=[FloatingPointRange(from_value=low, to_value=high)]))

        def text(name, value, description):
            self.declare_parameter(name, value, ParameterDescriptor(description=description))

        text('pattern_config', '', 'pattern YAML (empty: the shipped config/pattern.yaml)')
        text('building_map', '', 'building map YAML (empty: the shipped config/building.yaml)')
        text('estimator', 'exact', "pose estimator: 'exact' or 'paper'")
        text('output_frame', 'room', "frame of /robot_location: 'room' or 'building'")
        text('fusion', 'biggest', "several cards: 'biggest' (the paper's rule) or 'fused'")
        text('base_frame', 'base_link', 'frame name of the robot base')
        number('min_tilt_deg', 0.0, "reject views tilted less than this (the paper's rule: 25)",
               0.0, 89.0)
        number('max_reprojection_px', 1.5, 'reject poses with a larger RMS reprojection error',
               0.01, 100.0)
        self.declare_parameter('use_joint_states', True, ParameterDescriptor(
            description='take the head angles from /camera/joint_states (else the fixed ones)'))
        number('fixed_pan_deg', 0.0, 'head pan when joint states are not used (+ = left)',
               -180.0, 180.0)
        number('fixed_tilt_deg', 0.0, 'head tilt when joint states are not used (+ = up)',
               -90.0, 90.0)
        number('joint_state_max_age_s', 0.5, 'joint states older than this are stale',
               0.0, 10.0)
        number('joint_state_wait_s', 0.05, 'wait this long for a joint state newer than '
               'the image before using the newest one', 0.0, 1.0)
        number('head.mount_pitch_deg', 0.0, 'the camera is mounted pitched up by this: tilt 0 '
               'looks up by it (deg)', -60.0, 60.0)
        self.declare_parameter('opencv_threads', 1, ParameterDescriptor(
            description='threads OpenCV may use per frame (0: its default)',
            integer_range=[IntegerRange(from_value=0, to_value=64, step=1)]))
        for name, value, what in (
                ('head.base_to_pan_xyz', [0.0, 0.0, 1.0], 'base_link to the pan joint (m)'),
                ('head.pan_to_tilt_xyz', [0.0, 0.0, 0.05], 'pan joint to the tilt joint (m)'),
                ('head.tilt_to_optical_xyz', [0.03, 0.0, 0.05],
                 'tilt joint to the optical centre (m)')):
            self.declare_parameter(name, value, ParameterDescriptor(description=what))

    def _params(self) -> dict:
        return parameter_values(self, PARAMETERS)

    # Callbacks (executor thread: store only) ---------------------------------------

    def _on_image(self, msg: Image) -> None:
        with self._wake:
            self.stats['received'] += 1
            if self._latest is not None:
                self.stats['dropped'] += 1
            self._latest = msg
            self._latest_arrival = time.perf_counter()
            self._wake.notify()

    def _on_camera_info(self, msg: CameraInfo) -> None:
        try:
            self.camera = camera_from_info(msg)
            self._camera_problem = ''
            self._cameras_by_stamp[_stamp_key(msg.header.stamp)] = self.camera
            while len(self._cameras_by_stamp) > CAMERA_INFO_HISTORY:
                self._cameras_by_stamp.popitem(last=False)
        except PatternLocatorError as exc:
            self.camera = None
            self._camera_problem = f'bad camera_info: {exc}'

    def _on_joints(self, msg: JointState) -> None:
        try:
            pan, tilt = angles_from_joint_state(msg.name, msg.position)
        except PatternLocatorError as exc:
            self._problem(f'joint states: {exc}')
            return
        stamp = stamp_seconds(msg.header.stamp)
        latest = self.joints.latest()
        if latest is not None and stamp < latest[0] - 1.0:
            # Time went backwards (a bag replayed again, a simulator reset).
            self.joints.clear()
        self.joints.add(stamp, pan, tilt)
        with self._joint_arrived:
            self._joint_arrived.notify_all()

    # Work (its own thread) ------------------------------------------------------------

    def _work(self) -> None:
        while True:
            with self._wake:
                while self._latest is None and not self._stopping:
                    self._wake.wait(0.5)
                if self._stopping:
                    return
                msg, self._latest = self._latest, None
                arrival = self._latest_arrival
            try:
                self._process(msg)
                # Time from the image's arrival in this process to the end of
                # its processing: the node's share of the latency.
                self._times.append((time.perf_counter() - arrival) * 1000.0)
            except PatternLocatorError as exc:
                self._problem(str(exc))
            except Exception as exc:  # noqa: B902 - the node must outlive any one frame
                if not self.context.ok():
                    return                   # Ctrl-C shut the context down mid-frame
                self._problem(f'unexpected {type(exc).__name__}: {exc}')

    def _process(self, msg: Image) -> None:
        with self._stats_lock:
            self.stats['processed'] += 1
        camera = self._cameras_by_stamp.get(_stamp_key(msg.header.stamp), self.camera)
        if camera is None:
            self._problem(self._camera_problem)
            return
        if (camera.width, camera.height) != (msg.width, msg.height):
            self._problem(f'camera_info is for {camera.width}x{camera.height} but the image is '
                          f'{msg.width}x{msg.height}')
            return
        image = image_from_msg(msg)          # a view of the message: the detector only reads
        pan, tilt = self._head_angles(msg)
        result = self.localizer.process(image, camera, pan, tilt)
        for problem in result.problems:
            self._problem(problem)
        self._publish(msg, result, image, camera)

    def _head_angles(self, msg: Image) -> Tuple[float, float]:
        if not self.use_joint_states:
            return self.fixed_angles
        stamp = stamp_seconds(msg.header.stamp)
        # An image can overtake the joint state taken just after it: wait a
        # little for a sample on its far side rather than hold an old one.
        deadline = time.monotonic() + self.joint_wait_s
        with self._joint_arrived:
            while True:
                latest = self.joints.latest()
                remaining = deadline - time.monotonic()
                if (latest is not None and latest[0] >= stamp) or remaining <= 0:
                    break
                self._joint_arrived.wait(remaining)
        return self.joints.at(stamp)

    def _problem(self, text: str) -> None:
        """Count and report a problem; each distinct message at most every few seconds."""
        with self._stats_lock:
            self.stats['rejected'] += 1
            self.stats['last_problem'] = text
            now = time.monotonic()
            if len(self._last_logged) > 256:
                self._last_logged.clear()
            due = now - self._last_logged.get(text, -math.inf) >= THROTTLE_S
            if due:
                self._last_logged[text] = now
        if due:
            self.get_logger().warning(text)

    # Output ---------------------------------------------------------------------

    def _publish(self, msg: Image, result: FrameResult, image: np.ndarray,
                 camera: CameraModel) -> None:
        header = msg.header
        if result.target is not None:
            target = PointStamped()
            target.header = header
            target.point.x, target.point.y, target.point.z = (float(v) for v in result.target)
            self.pub_target.publish(target)
        if self.pub_debug.get_subscription_count() > 0:
            self._publish_debug(msg, result, image)
        fix = result.fix
        if fix is None:
            return
        with self._stats_lock:
            self.stats['located'] += 1
        pose = PoseStamped()
        pose.header.stamp = header.stamp
        pose.header.frame_id = fix.frame_id
        fill_pose(pose.pose, fix.T_frame_base)
        with_cov = PoseWithCovarianceStamped()
        with_cov.header = pose.header
        with_cov.pose.pose = pose.pose
        with_cov.pose.covariance = [float(v) for v in np.asarray(fix.covariance).ravel()]
        ids = UInt16MultiArray()
        ids.layout.dim = [MultiArrayDimension(label=name, size=1, stride=1)
                          for name in ('floor', 'room', 'pattern')]
        ids.data = [int(v) for v in fix.ids.as_tuple()]
        self.pub_ids.publish(ids)
        self.pub_cov.publish(with_cov)
        self.pub_pose.publish(pose)

    def _publish_debug(self, msg: Image, result: FrameResult, image: np.ndarray) -> None:
        location = None
        if result.fix is not None:
            f = result.fix
            x, y, z = f.T_frame_base.t
            location = (f'floor {f.ids.floor} room {f.ids.room} card {f.ids.pattern}  '
                        f'base {x:.2f} {y:.2f} {z:.2f} m in {f.frame_id}')
        out = Image()
        out.header = msg.header
        fill_msg(out, draw_overlay(image, result.detections, location), 'bgr8')
        self.pub_debug.publish(out)

    def _publish_diagnostics(self) -> None:
        with self._stats_lock:
            s = dict(self.stats)
        status = DiagnosticStatus()
        status.name = 'pattern_locator: locator'
        status.hardware_id = self.camera.name if self.camera else 'camera'
        ok = self.camera is not None
        status.level = DiagnosticStatus.OK if ok else DiagnosticStatus.WARN
        status.message = 'running' if ok else self._camera_problem
        times = sorted(self._times)
        median = f'{times[len(times) // 2]:.2f}' if times else 'n/a'
        status.values = [KeyValue(key=k, value=str(v)) for k, v in s.items()] + [
            KeyValue(key='estimator', value=self.localizer.locator.estimator),
            KeyValue(key='frame_ms_median', value=median)]
        array = DiagnosticArray()
        array.header.stamp = self.get_clock().now().to_msg()
        array.status = [status]
        self.pub_diag.publish(array)

    def stop(self) -> None:
        with self._wake:
            self._stopping = True
            self._wake.notify()
        self._worker.join(timeout=2.0)


def main(args=None) -> None:
    run_node(LocatorNode, 'locator', args)


if __name__ == '__main__':
    main()
