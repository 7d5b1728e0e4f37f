"""
The ``camera_driver`` node: the Sony EVI-D31 over VISCA, and the tracking loop.

Talks VISCA over a serial port (``port``, 9600 8N1) through
``visca_camera.EviD31`` (Address Set, IF_Clear, power and initialisation at
start; every error reply handled; reconnects when the port vanishes). One
thread runs ``head_loop.HeadLoop`` at ``rate_hz``: a position inquiry per
cycle, the tracking controller (``tracking``), and a Drive only when the
decision changes.

Subscribes
    /pattern_locator/target (geometry_msgs/PointStamped): x, y = pan and
    tilt turns (radians, REP 103) that centre the card in the image stamped
    in the header, z = its size in pixels.

Publishes
    /camera/joint_states (sensor_msgs/JointState): ``camera_pan`` and
    ``camera_tilt`` in radians with REP 103 signs (pan positive = left,
    tilt positive = up; the camera's own VISCA pan is positive right), and
    ``camera_zoom`` in camera units (0 wide .. 1023 tele); stamped when the
    position answer left the camera (arrival minus its wire time).
    /camera/camera_info for the current zoom when ``zoom_table`` is set.
    /diagnostics: connection, error counts, sockets, tracking mode.

Services (std_srvs/Trigger): ~/home, ~/reset.
"""

import math
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PointStamped
import rclpy
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, JointState
from std_srvs.srv import Trigger

from .image_codec import fill_camera_info
from .ros_helpers import (declare_integer, declare_number, declare_value, parameter_values,
                          run_node, stamp_seconds)
from ..errors import PatternLocatorError
from ..tracking.controller import TrackingController, TrackingParams
from ..tracking.head_loop import HeadLoop, HeadReading
from ..visca.camera import EviD31
from ..visca.protocol import ViscaError
from ..visca.zoom_table import ZoomTable

PARAMETERS = (
    'port', 'baud', 'address', 'rate_hz', 'startup_timeout_s', 'tracking', 'gain',
    'dead_band_deg', 'max_pan_speed_deg_s', 'max_tilt_speed_deg_s', 'pan_limits_deg',
    'tilt_limits_deg', 'target_timeout_s', 'search', 'search_ahead_first', 'search_after_s',
    'search_speed_deg_s',
    'search_tilt_levels_deg', 'zoom_control', 'target_size_px', 'zoom_table', 'zoom_every',
    'pan_joint', 'tilt_joint', 'zoom_joint', 'camera_frame')


class CameraDriverNode(Node):
    """Thin ROS shell around :class:`head_loop.HeadLoop` and the EVI-D31."""

    def __init__(self, **kwargs) -> None:
        super().__init__('camera_driver', **kwargs)
        self._declare_parameters()
        p = parameter_values(self, PARAMETERS)
        self.params = p
        self.get_logger().info('camera_driver configuration: ' + ', '.join(
            f'{k}={v}' for k, v in sorted(p.items())))
        self.zoom_table = ZoomTable.load(p['zoom_table']) if p['zoom_table'] else None
        controller = TrackingController(self._tracking_params(p)) if p['tracking'] else None
        self.camera = EviD31(p['port'], baud=p['baud'], address=p['address'])
        self.loop = HeadLoop(self.camera, controller, clock=self._now_s,
                             zoom_every=p['zoom_every'])
        self.pub_joints = self.create_publisher(JointState, '/camera/joint_states',
                                                qos_profile_sensor_data)
        self.pub_info = (self.create_publisher(CameraInfo, '/camera/camera_info',
                                               qos_profile_sensor_data)
                         if self.zoom_table is not None else None)
        self.pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.create_subscription(PointStamped, '/pattern_locator/target', self._on_target, 10)
        self.create_service(Trigger, '~/home', lambda req, res: self._trigger('home', res))
        self.create_service(Trigger, '~/reset', lambda req, res: self._trigger('reset', res))
        self.create_timer(1.0, self._publish_diagnostics)
        self.readings = 0
        self._state = 'starting'
        self._stopping = threading.Event()
        self._thread = threading.Thread(target=self._run, name='camera-driver', daemon=True)
        self._thread.start()

    # Parameters ---------------------------------------------------------------------

    def _declare_parameters(self) -> None:
        declare_value(self, 'port', '/dev/ttyUSB0', 'serial port of the camera')
        declare_integer(self, 'baud', 9600, 'serial speed (the EVI-D31 talks 9600)',
                        1200, 115200)
        declare_integer(self, 'address', 1, 'VISCA address of the camera', 1, 7)
        declare_number(self, 'rate_hz', 10.0, 'control cycles (position inquiries, joint '
                       'states, commands) per second', 1.0, 30.0)
        declare_number(self, 'startup_timeout_s', 15.0, 'give up one start-up attempt after '
                       'this (then retry)', 1.0, 120.0)
        declare_value(self, 'tracking', True, 'keep /pattern_locator/target centred')
        declare_number(self, 'gain', 3.0, 'speed = gain * angular error (1/s)', 0.1, 20.0)
        declare_number(self, 'dead_band_deg', 0.3, 'no correction inside this error', 0.0, 10.0)
        declare_number(self, 'max_pan_speed_deg_s', 80.0, 'pan speed limit', 3.4, 80.0)
        declare_number(self, 'max_tilt_speed_deg_s', 50.0, 'tilt speed limit', 2.5, 50.0)
        declare_value(self, 'pan_limits_deg', [-100.0, 100.0], 'pan travel used (REP 103)')
        declare_value(self, 'tilt_limits_deg', [-25.0, 25.0], 'tilt travel used')
        declare_number(self, 'target_timeout_s', 0.5, 'stop the head when no target image is '
                       'newer than this', 0.05, 10.0)
        declare_value(self, 'search', True, 'sweep to search when no card was seen')
        declare_value(self, 'search_ahead_first', True, 'a head turned aside sweeps back '
                      'through straight ahead first (where the robot goes)')
        declare_number(self, 'search_after_s', 3.0, 'start the sweep after this long without '
                       'a target', 0.5, 600.0)
        declare_number(self, 'search_speed_deg_s', 20.0, 'pan speed of the sweep', 3.4, 80.0)
        declare_value(self, 'search_tilt_levels_deg', [0.0, 15.0],
                      'tilt of successive sweep passes')
        declare_value(self, 'zoom_control', False, 'zoom to keep the card at target_size_px')
        declare_number(self, 'target_size_px', 120.0, "the card's outer ring semi-axis to zoom "
                       'to', 10.0, 1000.0)
        declare_value(self, 'zoom_table', '', 'zoom -> intrinsics YAML; set to publish '
                      '/camera/camera_info (empty: do not publish)')
        declare_integer(self, 'zoom_every', 5, 'cycles between zoom inquiries', 1, 100)
        declare_value(self, 'pan_joint', 'camera_pan', 'joint name of the pan axis')
        declare_value(self, 'tilt_joint', 'camera_tilt', 'joint name of the tilt axis')
        declare_value(self, 'zoom_joint', 'camera_zoom', 'joint name of the zoom (camera units)')
        declare_value(self, 'camera_frame', 'camera_optical_frame', 'frame of camera_info')

    @staticmethod
    def _tracking_params(p) -> TrackingParams:
        def limits(name):
            values = [math.radians(float(v)) for v in p[name]]
            if len(values) != 2:
                raise PatternLocatorError(f'{name} needs two values [min, max], got {p[name]}')
            return tuple(values)

        return TrackingParams(
            gain=p['gain'], dead_band_rad=math.radians(p['dead_band_deg']),
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
            zoom_enabled=p['zoom_control'], target_size_px=p['target_size_px'])

    # Callbacks ----------------------------------------------------------------------

    def _now_s(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _on_target(self, msg: PointStamped) -> None:
        values = (msg.point.x, msg.point.y, msg.point.z)
        if not all(math.isfinite(v) for v in values):
            self.get_logger().warning(f'ignored a target with non-finite values {values}',
                                      throttle_duration_sec=5.0)
            return
        self.loop.on_target(stamp_seconds(msg.header.stamp), *values)

    def _trigger(self, action: str, response: Trigger.Response) -> Trigger.Response:
        if not self.camera.ready:
            response.success, response.message = False, f'camera not ready ({self._state})'
            return response
        response.success, response.message = self.loop.request(action).wait(30.0)
        self.get_logger().info(f'~/{action}: {response.message}')
        return response

    # The camera thread ------------------------------------------------------------------

    def _run(self) -> None:
        # Outer loop (re)starts the camera, inner loop runs cycles; the
        # transport itself reopens a vanished port and re-runs the start-up.
        backoff = 0.5
        while not self._stopping.is_set() and self.context.ok():
            try:
                self._state = 'starting'
                self.camera.start(timeout_s=self.params['startup_timeout_s'])
                self.get_logger().info(f'camera on {self.params["port"]} ready')
                backoff = 0.5
            except ViscaError as exc:
                self._state = f'start-up failed: {exc}'
                self.get_logger().error(f'camera start-up on {self.params["port"]} failed: '
                                        f'{exc}; retrying in {backoff:.1f} s',
                                        throttle_duration_sec=10.0)
                self._stopping.wait(backoff)
                backoff = min(2 * backoff, 5.0)
                continue
            self._cycles()
        self.camera.close()

    def _cycles(self) -> None:
        period = 1.0 / self.params['rate_hz']
        due = time.monotonic()
        was_ready = True
        while not self._stopping.is_set() and self.context.ok():
            due += period
            ready = self.camera.ready
            if ready and not was_ready:
                self.get_logger().info('camera back: tracking resumes')
                self.loop.reset_tracking()
            if not ready:
                if was_ready:
                    self.get_logger().warning(f'camera lost: {self.camera.transport.last_error}'
                                              ' (reconnecting)')
                self._state = 'reconnecting'
            else:
                self._state = 'ready'
                reading = self.loop.cycle()
                if reading is not None:
                    try:
                        self._publish(reading)
                    except Exception:  # noqa: B902 - Ctrl-C invalidates the context under us
                        if self.context.ok():
                            raise
                        return
            was_ready = ready
            # Never run late cycles back to back: the line is the bottleneck.
            due = max(due, time.monotonic())
            self._stopping.wait(max(0.0, due - time.monotonic()))

    def _publish(self, reading: HeadReading) -> None:
        p = self.params
        msg = JointState()
        msg.header.stamp = rclpy.time.Time(nanoseconds=int(reading.stamp_s * 1e9)).to_msg()
        msg.name = [p['pan_joint'], p['tilt_joint'], p['zoom_joint']]
        msg.position = [float(reading.pan), float(reading.tilt), float(reading.zoom_units)]
        self.pub_joints.publish(msg)
        self.readings += 1
        if self.pub_info is not None:
            info = CameraInfo()
            fill_camera_info(info, self.zoom_table.camera_at(reading.zoom_units))
            info.header.stamp, info.header.frame_id = msg.header.stamp, p['camera_frame']
            self.pub_info.publish(info)

    def _publish_diagnostics(self) -> None:
        transport = self.camera.transport
        stats = transport.stats
        status = DiagnosticStatus()
        status.name = 'camera_driver: EVI-D31'
        status.hardware_id = self.params['port']
        ready = self.camera.ready
        status.level = DiagnosticStatus.OK if ready else DiagnosticStatus.ERROR
        status.message = self._state if not self.loop.last_error or not ready else \
            f'ready; last error: {self.loop.last_error}'
        loop = self.loop.stats()
        values = {
            'connected': transport.connected, 'ready': ready,
            'reconnects': stats.reconnects, 'connection losses': stats.connection_losses,
            'commands sent': stats.sent, 'replies': stats.replies, 'timeouts': stats.timeouts,
            'error replies': sum(stats.errors.values()),
            'errors by kind': ', '.join(f'{k}={v}' for k, v in sorted(stats.errors.items())),
            'junk bytes': stats.junk_bytes, 'network changes': stats.network_changes,
            'sockets in use': ' '.join(str(s) for s in transport.sockets_in_use) or 'none',
            'joint states published': self.readings, 'tracking mode': loop['mode'],
            'tracking commands': loop['commands sent'],
            'last error': transport.last_error or loop['last error'],
        }
        status.values = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
        array = DiagnosticArray()
        array.header.stamp = self.get_clock().now().to_msg()
        array.status = [status]
        self.pub_diag.publish(array)

    def stop(self) -> None:
        """Stop the camera thread; the head is stopped and the port closed."""
        self._stopping.set()
        self._thread.join(timeout=5.0)


def main(args=None) -> None:
    run_node(CameraDriverNode, 'camera_driver', args)


if __name__ == '__main__':
    main()
