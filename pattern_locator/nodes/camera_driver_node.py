"""
The ``camera_driver`` node: the Sony EVI-D31 over VISCA, and the tracking loop.

Talks VISCA over a serial port (``port``, 9600 8N1) through
``visca.camera.EviD31`` (Address Set, IF_Clear, power and initialisation at
start; every error reply handled; reconnects when the port vanishes). One
thread runs ``tracking.head_loop.HeadLoop`` at ``rate_hz``: a position
inquiry per cycle, the tracking controller (``tracking``), and a Drive only
when the decision changes. A port that does not exist or cannot be opened
is reported at once in one line and retried with backoff; the node runs
(parameters, diagnostics) meanwhile.

Topic names are relative (a namespace moves them); ``/diagnostics`` is absolute.

Subscribes
    ``pattern_locator/target`` (geometry_msgs/PointStamped): the card centre
    in ``camera_optical_frame`` (metres) in the image stamped in the header;
    the node turns it into the pan and tilt turns that centre it and, with
    the camera_info of that time, the card's apparent size for the zoom.
    ``camera/camera_info`` (sensor-data QoS) when the node does not publish
    it itself.
    ``odom`` (nav_msgs/Odometry, sensor-data QoS): the base's heading and
    twist; with ``odometry_feed_forward`` the head turns against the base's
    turns and follows the card's apparent motion from the base's
    translation (``tracking.controller``).

Publishes
    ``camera/joint_states`` (sensor_msgs/JointState, reliable, depth 10):
    ``camera_pan`` and ``camera_tilt`` in radians with REP 103 signs (pan
    positive = left, tilt positive = up; the camera's own VISCA pan is
    positive right), and ``camera_zoom`` in camera units (0 wide .. 1023
    tele); stamped when the position answer left the camera.
    ``camera/camera_info`` for the current zoom when ``zoom_table`` is set.
    ``/diagnostics``: OK only while fresh positions flow; WARN while
    starting or when answers stop for a moment, ERROR when the camera is
    gone or positions stopped for long.

Services (std_srvs/Trigger): ``~/home``, ``~/reset``.

Shutter (issue 12): ``shutter_s`` > 0 puts the camera in shutter priority at
the nearest of its speeds (``visca.exposure``; the table by
``video_standard``) in every start-up, so again after a reconnect or a
power cycle; the camera's answers are logged once per setting (``shutter
1/250 s (shutter priority)``) and shown in the diagnostics. A camera that
refuses it gets one warning and keeps tracking at its own exposure.

Parameters: :data:`PARAMETERS`; the tracking settings, the rate and the
zoom inquiry period apply at run time (validated: a refused change says
why), the port and the names are read-only.
"""

import collections
import math
import os
import threading
import time
from typing import Any, Dict, Optional, Tuple

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PointStamped
from nav_msgs.msg import Odometry
import rclpy
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data, QoSProfile
from sensor_msgs.msg import CameraInfo, JointState
from std_srvs.srv import Trigger

from .image_codec import camera_from_info, fill_camera_info
from .ros_helpers import (all_finite, describe_values, Param, Parameters,
                          ProblemLog, quote, run_node, stamp_key, stamp_seconds, wall_timer)
from ..card.pattern import load_pattern_config
from ..errors import ConfigError, PatternLocatorError
from ..tracking.controller import TrackingController, TrackingParams
from ..tracking.head_loop import HeadLoop, HeadReading
from ..visca.camera import EviD31
from ..visca.exposure import ShutterRequest
from ..visca.protocol import VIDEO_STANDARDS, ViscaError
from ..visca.zoom_table import ZoomTable

THROTTLE_S = 5.0
# A target nearer than this to the camera has no direction worth turning to.
MIN_TARGET_DISTANCE_M = 0.01
CAMERA_INFO_HISTORY = 60
BACKOFF_MAX_S = 5.0

TRACKING_PARAMETERS = (
    'gain', 'slew_band_deg', 'slew_decel_deg_s2', 'dead_band_deg', 'max_pan_speed_deg_s',
    'max_tilt_speed_deg_s', 'pan_limits_deg', 'tilt_limits_deg', 'target_timeout_s', 'search',
    'search_ahead_first', 'search_after_s', 'search_speed_deg_s', 'search_tilt_levels_deg',
    'zoom_control', 'target_size_px', 'rate_hz', 'odometry_feed_forward', 'head_mount_pitch_deg')

PARAMETERS: Tuple[Param, ...] = (
    Param('port', '/dev/ttyUSB0', 'serial port of the camera'),
    Param('baud', 9600, 'serial speed (the EVI-D31 talks 9600)', 1200, 115200),
    Param('address', 1, 'VISCA address of the camera', 1, 7),
    Param('rate_hz', 10.0, 'control cycles (position inquiries, joint states, commands) per '
          'second', 1.0, 30.0, dynamic=True),
    Param('startup_timeout_s', 15.0, 'give up one start-up attempt after this (then retry)',
          1.0, 120.0, dynamic=True),
    Param('tracking', True, 'keep pattern_locator/target centred', dynamic=True),
    Param('gain', 3.0, 'speed = card rate + gain * angular error (1/s)', 0.1, 20.0,
          dynamic=True),
    Param('slew_band_deg', 3.0, 'further off: close the error as fast as the head can '
          'without entering this band within a cycle (0: the gain everywhere)', 0.0, 90.0,
          dynamic=True),
    Param('slew_decel_deg_s2', 200.0, "the head's braking for the slews (deg/s^2)", 10.0,
          10000.0, dynamic=True),
    Param('dead_band_deg', 0.3, 'no correction inside this error', 0.0, 10.0, dynamic=True),
    Param('max_pan_speed_deg_s', 80.0, 'pan speed limit', 3.4, 80.0, dynamic=True),
    Param('max_tilt_speed_deg_s', 50.0, 'tilt speed limit', 2.5, 50.0, dynamic=True),
    Param('pan_limits_deg', [-100.0, 100.0], 'pan travel used (REP 103: + = left)',
          dynamic=True),
    Param('tilt_limits_deg', [-25.0, 25.0], 'tilt travel used (+ = up)', dynamic=True),
    Param('target_timeout_s', 0.5, 'stop the head when no target image is newer than this',
          0.05, 10.0, dynamic=True),
    Param('search', True, 'sweep to search when no card was seen', dynamic=True),
    Param('search_ahead_first', True, 'a head turned aside sweeps back through straight '
          'ahead first (where the robot goes)', dynamic=True),
    Param('search_after_s', 3.0, 'start the sweep after this long without a target (before '
          'the first one: with a locator running)', 0.5, 600.0, dynamic=True),
    Param('search_speed_deg_s', 20.0, 'pan speed of the sweep', 3.4, 80.0, dynamic=True),
    Param('search_tilt_levels_deg', [0.0, 15.0], 'tilt of successive sweep passes',
          dynamic=True),
    Param('odometry_feed_forward', True, "turn the head against the base's turns and "
          "follow the card through the base's motion, from odom", dynamic=True),
    Param('head_mount_pitch_deg', 0.0, 'the camera is mounted pitched up by this on the tilt '
          "link (the card's elevation for the feed-forward)", -60.0, 60.0, dynamic=True),
    Param('zoom_control', False, 'zoom to keep the card at target_size_px', dynamic=True),
    Param('target_size_px', 120.0, "the card's outer ring semi-axis to zoom to", 10.0, 1000.0,
          dynamic=True),
    Param('shutter_s', 0.0, 'exposure time to set (s): shutter priority at the nearest of '
          "the camera's speeds in log scale (1/10000 .. 1/50 s); 0: leave the camera's auto "
          'exposure alone', 0.0, 0.04),
    Param('video_standard', 'pal', "the camera's video standard, for its shutter speeds: pal "
          '(EVI-D31) or ntsc (EVI-D30)', choices=VIDEO_STANDARDS),
    Param('zoom_table', '', 'zoom -> intrinsics YAML; set to publish camera/camera_info '
          '(empty: do not publish)'),
    Param('zoom_every', 5, 'cycles between zoom inquiries', 1, 100, dynamic=True),
    Param('pan_joint', 'camera_pan', 'joint name of the pan axis'),
    Param('tilt_joint', 'camera_tilt', 'joint name of the tilt axis'),
    Param('zoom_joint', 'camera_zoom', 'joint name of the zoom (camera units)'),
    Param('camera_frame', 'camera_optical_frame', 'frame of camera_info'),
    Param('pattern_config', '', "pattern YAML, for the card's size (empty: the shipped one)"),
)


def tracking_params(p: Dict[str, Any]) -> TrackingParams:
    """Return the tracking settings of the node's parameter values; ConfigError if bad."""
    def limits(name):
        try:
            values = [math.radians(float(v)) for v in p[name]]
        except (TypeError, ValueError):
            values = []
        if len(values) != 2:
            raise ConfigError(f'{name} needs two values [min, max], got {quote(p[name])}')
        return tuple(values)

    return TrackingParams(
        gain=p['gain'], slew_band_rad=math.radians(p['slew_band_deg']),
        slew_decel_rad_s2=math.radians(p['slew_decel_deg_s2']),
        dead_band_rad=math.radians(p['dead_band_deg']),
        resume_band_rad=2.0 * math.radians(p['dead_band_deg']),
        max_pan_speed=math.radians(p['max_pan_speed_deg_s']),
        max_tilt_speed=math.radians(p['max_tilt_speed_deg_s']),
        control_period_s=1.0 / p['rate_hz'], pan_limits_rad=limits('pan_limits_deg'),
        tilt_limits_rad=limits('tilt_limits_deg'), target_timeout_s=p['target_timeout_s'],
        search_enabled=p['search'], search_ahead_first=p['search_ahead_first'],
        search_after_s=p['search_after_s'],
        search_pan_speed=math.radians(p['search_speed_deg_s']),
        search_tilt_levels_rad=tuple(math.radians(float(v))
                                     for v in p['search_tilt_levels_deg']),
        zoom_enabled=p['zoom_control'], target_size_px=p['target_size_px'],
        odometry_feed_forward=p['odometry_feed_forward'],
        mount_pitch_rad=math.radians(p['head_mount_pitch_deg']))


def shutter_request(p: Dict[str, Any]) -> Optional[ShutterRequest]:
    """Return the shutter the node's parameters ask for (None: none); ConfigError if bad."""
    try:
        return ShutterRequest.from_seconds(float(p['shutter_s']), str(p['video_standard']))
    except ViscaError as exc:
        raise ConfigError(f'shutter_s: {exc}; 0 leaves the auto exposure') from None


def _is_device_path(port: str) -> bool:
    """Return whether ``port`` names a file (not a pyserial URL such as loop://)."""
    return '://' not in port


class CameraDriverNode(Node):
    """Thin ROS shell around :class:`head_loop.HeadLoop` and the EVI-D31."""

    def __init__(self, **kwargs) -> None:
        super().__init__('camera_driver', **kwargs)
        self.parameters = Parameters(self, PARAMETERS)
        p = self.parameters.values()
        self.params = p
        self.parameters.check_all(self._validate)
        for line in describe_values(p):
            self.get_logger().info('camera_driver configuration: ' + line)
        self.zoom_table = ZoomTable.load(p['zoom_table']) if p['zoom_table'] else None
        self.card_radius_m = float(load_pattern_config(p['pattern_config'] or None)
                                   .ring_radii[0])
        controller = TrackingController(tracking_params(p)) if p['tracking'] else None
        self.camera = EviD31(p['port'], baud=p['baud'], address=p['address'],
                             shutter_s=p['shutter_s'], video_standard=p['video_standard'])
        self._exposure_logged = 0
        self.loop = HeadLoop(self.camera, controller, clock=self._now_s,
                             zoom_every=p['zoom_every'], expected_rate_hz=p['rate_hz'],
                             locator_present=self._locator_present,
                             on_reading=self._on_reading)
        self.problems = ProblemLog(self.get_logger(), THROTTLE_S)
        # Changes for the camera thread, applied between two cycles.
        self._pending: Dict[str, Any] = {}
        self._tracking_on = bool(p['tracking'])
        self._pending_lock = threading.Lock()
        self._focal_by_stamp: 'collections.OrderedDict[int, float]' = collections.OrderedDict()
        self._focal: Optional[float] = None
        self.pub_joints = self.create_publisher(JointState, 'camera/joint_states',
                                                QoSProfile(depth=10))
        if self.zoom_table is not None:
            self.pub_info = self.create_publisher(CameraInfo, 'camera/camera_info',
                                                  qos_profile_sensor_data)
        else:
            self.pub_info = None
            self.create_subscription(CameraInfo, 'camera/camera_info', self._on_camera_info,
                                     qos_profile_sensor_data)
        self.pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self._target_sub = self.create_subscription(PointStamped, 'pattern_locator/target',
                                                    self._on_target, 10)
        self.create_subscription(Odometry, 'odom', self._on_odometry, qos_profile_sensor_data)
        self.create_service(Trigger, '~/home', lambda req, res: self._trigger('home', res))
        self.create_service(Trigger, '~/reset', lambda req, res: self._trigger('reset', res))
        wall_timer(self, 1.0, self._publish_diagnostics)
        self.parameters.on_change(self._validate, self._apply)
        self.readings = 0
        self.targets = 0
        self.odometry = 0
        self._last_reading_at: Optional[float] = None
        self._state = 'starting'
        self._failing = False
        self._stopping = threading.Event()
        self._thread = threading.Thread(target=self._run, name='camera-driver', daemon=True)
        self._thread.start()

    # Parameters ---------------------------------------------------------------------

    @staticmethod
    def _validate(values: Dict[str, Any]) -> Optional[str]:
        try:
            tracking_params(values)
            shutter_request(values)
        except ConfigError as exc:
            return str(exc)
        return None

    def _apply(self, changed: Dict[str, Any]) -> None:
        self.params = {**self.params, **changed}
        # Targets stop reaching the controller at once; the camera thread
        # swaps the controller and stops the head at its next cycle.
        self._tracking_on = bool(self.params['tracking'])
        with self._pending_lock:
            self._pending.update(changed)

    def _apply_pending(self) -> None:
        """Apply parameter changes (camera thread, between cycles)."""
        with self._pending_lock:
            changed, self._pending = self._pending, {}
        if not changed:
            return
        p = self.params
        if 'zoom_every' in changed:
            self.loop.zoom_every = max(1, int(p['zoom_every']))
        if 'rate_hz' in changed:
            self.loop.set_expected_rate(p['rate_hz'])
        if set(changed) & set(TRACKING_PARAMETERS + ('tracking',)):
            # A new controller (its history is short: the next targets rebuild
            # it), or none; either way the head stops first, since the last
            # Drive would otherwise run on.
            self.loop.controller = (TrackingController(tracking_params(p)) if p['tracking']
                                    else None)
            self.loop.reset_tracking()
            try:
                self.camera.stop()
            except ViscaError as exc:
                self.problems.report('camera', f'no stop after a tracking change: {exc}')

    # Callbacks ----------------------------------------------------------------------

    def _now_s(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _on_camera_info(self, msg: CameraInfo) -> None:
        try:
            camera = camera_from_info(msg)
        except Exception as exc:  # noqa: B902 - any field of a foreign message can be wrong
            self.problems.report('camera_info', f'bad camera_info: {exc}')
            return
        self._remember_focal(stamp_key(msg.header.stamp), camera.fx)

    def _remember_focal(self, key: int, fx: float) -> None:
        if not (math.isfinite(fx) and fx > 0.0):
            return
        self._focal = fx
        self._focal_by_stamp[key] = fx
        while len(self._focal_by_stamp) > CAMERA_INFO_HISTORY:
            self._focal_by_stamp.popitem(last=False)

    def _on_target(self, msg: PointStamped) -> None:
        if not self._tracking_on:
            return
        point = (msg.point.x, msg.point.y, msg.point.z)
        distance = math.hypot(*point) if all_finite(point) else math.nan
        # Any direction is a target: the gaze planner's handover to a card
        # more than 90 deg off the axis lies behind the image plane (z <= 0).
        if not distance >= MIN_TARGET_DISTANCE_M:
            self.problems.report('target', f'ignored a target that is not a finite point away '
                                 f'from the camera: {quote(point)}')
            return
        # The card's apparent size: its outer ring's radius over its distance,
        # at the focal length of the image's time (a zoom camera's changes).
        focal = self._focal_by_stamp.get(stamp_key(msg.header.stamp), self._focal)
        size = None
        if focal is not None:
            size = focal * self.card_radius_m / distance
        self.targets += 1
        self.loop.on_target_point(stamp_seconds(msg.header.stamp), point, size)

    def _on_odometry(self, msg: Odometry) -> None:
        q = msg.pose.pose.orientation
        twist = msg.twist.twist
        values = (q.x, q.y, q.z, q.w, twist.linear.x, twist.linear.y, twist.angular.z)
        if not all_finite(values) or q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w < 0.5:
            self.problems.report('odom', f'ignored odometry with a non-finite value or no '
                                 f'orientation: {quote(values)}')
            return
        yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
        controller = self.loop.controller
        if controller is not None and controller.on_odometry(
                stamp_seconds(msg.header.stamp), yaw, twist.linear.x, twist.linear.y,
                twist.angular.z):
            self.odometry += 1

    def _trigger(self, action: str, response: Trigger.Response) -> Trigger.Response:
        if not self.camera.ready:
            response.success, response.message = False, f'camera not ready ({self._state})'
            return response
        response.success, response.message = self.loop.request(action).wait(30.0)
        self.get_logger().info(f'~/{action}: {response.message}')
        return response

    # The camera thread ------------------------------------------------------------------

    def _locator_present(self) -> bool:
        """Return whether a locator publishes targets (the search waits for one)."""
        # The subscription's own name: remapped, as count_publishers' argument is not.
        sub = getattr(self, '_target_sub', None)
        if sub is None:
            return False
        try:
            return self.count_publishers(sub.topic_name) > 0
        except Exception:  # noqa: B902 - the context shut down under the camera thread
            return True

    def _run(self) -> None:
        # Outer loop (re)starts the camera, inner loop runs cycles; the
        # transport itself reopens a vanished port and re-runs the start-up.
        backoff = 0.5
        port = self.params['port']
        while not self._stopping.is_set() and self.context.ok():
            try:
                if _is_device_path(port) and not os.path.exists(port):
                    raise _PortMissing(f'port {port} does not exist')
                # Open first: a port that cannot be opened fails at once
                # (start() would retry it for the whole start-up timeout).
                self.camera.transport.open()
                self._state = 'starting'
                self.camera.start(timeout_s=self.params['startup_timeout_s'])
                self.get_logger().info(f'camera on {port} ready')
                self._failing = False
                backoff = 0.5
            except (ViscaError, _PortMissing) as exc:
                if self._stopping.is_set():
                    break
                self._state = f'start-up failed: {exc}'
                self._failing = True
                self.get_logger().error(f'camera on {port}: {exc}; retrying in {backoff:.1f} s',
                                        throttle_duration_sec=10.0)
                self._stopping.wait(backoff)
                backoff = min(2 * backoff, BACKOFF_MAX_S)
                continue
            self._cycles()
        self.camera.close(stop=self.camera.ready)

    def _cycles(self) -> None:
        due = time.monotonic()
        was_ready = True
        while not self._stopping.is_set() and self.context.ok():
            self._apply_pending()
            self._log_exposure()
            due += 1.0 / self.params['rate_hz']
            ready = self.camera.ready
            if ready and not was_ready:
                self.get_logger().info('camera back: tracking resumes')
                self.loop.reset_tracking()
            if not ready:
                if was_ready:
                    self.get_logger().warning(
                        f'camera lost: {self.camera.transport.last_error} (reconnecting)')
                self._state = 'reconnecting'
            else:
                self._state = 'ready'
                # The joint state goes out from the cycle, before its commands
                # (_on_reading).
                self.loop.cycle()
            was_ready = ready
            # Never run late cycles back to back: the line is the bottleneck.
            due = max(due, time.monotonic())
            self._stopping.wait(max(0.0, due - time.monotonic()))

    def _log_exposure(self) -> None:
        """Log each new outcome of the shutter setting once (start-up, power cycle)."""
        count, report = self.camera.exposure_count, self.camera.exposure
        if count == self._exposure_logged or report is None:
            return
        self._exposure_logged = count
        if report.applied:
            self.get_logger().info(report.message)
        else:
            self.get_logger().warning(report.message)

    def _exposure_text(self) -> str:
        request, report = self.camera.shutter_request, self.camera.exposure
        if request is None:
            return "the camera's own (shutter_s 0)"
        if report is None:
            return f'{request.describe()} asked, not set yet'
        return report.message

    def _on_reading(self, reading: HeadReading) -> None:
        """
        Publish a reading as soon as it is read, before the cycle's commands.

        The Drive's and zoom's ACKs take another 20-40 ms of the line: a
        joint state published after them came ~45 ms after its stamp, so a
        locator waiting 50 ms for the joint state after an image mostly
        held the one before, from before the head's last change of speed
        (fixes a few centimetres off, many sigmas).
        """
        try:
            self._publish(reading)
        except Exception:  # noqa: B902 - Ctrl-C invalidates the context under us
            if self.context.ok() and not self._stopping.is_set():
                raise

    def _publish(self, reading: HeadReading) -> None:
        p = self.params
        values = (reading.pan, reading.tilt, reading.zoom_units)
        if not all_finite(values + (reading.stamp_s,)):
            self.problems.report('reading', f'head reading not finite: {values}')
            return
        if reading.stamp_s <= 0.0:
            # use_sim_time before the first /clock: the time is 0, the reading has no stamp.
            self.problems.report('clock', 'no time yet (use_sim_time and no /clock so far): '
                                 'joint state not published')
            return
        msg = JointState()
        msg.header.stamp = rclpy.time.Time(nanoseconds=int(reading.stamp_s * 1e9)).to_msg()
        msg.name = [p['pan_joint'], p['tilt_joint'], p['zoom_joint']]
        msg.position = [float(v) for v in values]
        self.pub_joints.publish(msg)
        self.readings += 1
        self._last_reading_at = time.monotonic()
        if self.zoom_table is not None:
            camera = self.zoom_table.camera_at(reading.zoom_units)
            self._remember_focal(stamp_key(msg.header.stamp), camera.fx)
            info = CameraInfo()
            fill_camera_info(info, camera)
            info.header.stamp, info.header.frame_id = msg.header.stamp, p['camera_frame']
            self.pub_info.publish(info)

    # Diagnostics ------------------------------------------------------------------------

    def health(self) -> Tuple[bytes, str]:
        """
        Return the diagnostics level and message: OK only while fresh positions flow.

        A port that is missing or a start-up that failed is the node's own
        ERROR; otherwise the head loop judges the link (fresh positions at
        the expected rate, failed reads, error-only replies, silence).
        """
        if self._failing:
            return DiagnosticStatus.ERROR, self._state
        health = self.loop.health()
        # DiagnosticStatus.level is a byte (OK = b'\x00'), HeadHealth's an int.
        return bytes((health.level,)), health.message

    def _publish_diagnostics(self) -> None:
        transport = self.camera.transport
        stats = transport.stats
        status = DiagnosticStatus()
        status.name = 'camera_driver: EVI-D31'
        status.hardware_id = str(self.params['port'])[:80]
        status.level, status.message = self.health()
        status.message = status.message[:200]
        loop = self.loop.stats()
        age = (f'{time.monotonic() - self._last_reading_at:.2f}'
               if self._last_reading_at is not None else 'n/a')
        counts, _ = self.problems.snapshot()
        values = {
            'connected': transport.connected, 'ready': self.camera.ready,
            'state': self._state[:200],
            'position age s': age,
            'reconnects': stats.reconnects, 'connection losses': stats.connection_losses,
            'commands sent': stats.sent, 'replies': stats.replies, 'timeouts': stats.timeouts,
            'error replies': sum(stats.errors.values()),
            'errors by kind': ', '.join(f'{k}={v}' for k, v in sorted(stats.errors.items())),
            'junk bytes': stats.junk_bytes, 'network changes': stats.network_changes,
            'sockets in use': ' '.join(str(s) for s in transport.sockets_in_use) or 'none',
            'joint states published': self.readings, 'targets received': self.targets,
            'odometry received': self.odometry,
            'tracking mode': loop['mode'] if self.loop.controller is not None else 'off',
            'exposure': self._exposure_text()[:200],
            'tracking commands': loop['commands sent'],
            'last error': (transport.last_error or loop['last error'])[:200],
        }
        values.update({f'problems: {k}': v for k, v in sorted(counts.items())})
        status.values = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
        array = DiagnosticArray()
        array.header.stamp = self.get_clock().now().to_msg()
        array.status = [status]
        self.pub_diag.publish(array)

    def stop(self) -> None:
        """Stop the camera thread within a fraction of a second; the head is stopped."""
        self._stopping.set()
        # Ends every wait on the camera at once (a silent camera, a start-up).
        self.loop.stop()
        self._thread.join(timeout=0.3)
        if self._thread.is_alive():
            # Blocked on the camera (a start-up, an unanswered inquiry): closing
            # the port fails every waiter at once.
            self.camera.close(stop=False)
            self._thread.join(timeout=1.0)


class _PortMissing(PatternLocatorError):
    """The configured serial port does not exist (yet)."""


def main(args=None) -> None:
    run_node(CameraDriverNode, 'camera_driver', args)


if __name__ == '__main__':
    main()
