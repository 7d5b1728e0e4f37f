"""
The ``sim`` node: a simulated robot with an emulated EVI-D31 in the example building.

The robot drives a route through one room (``sim_world.SimRoute``); at
``frame_rate_hz`` the node renders what the head camera sees from the
robot's pose and the emulated camera's current pan, tilt and zoom
(``sim_world.SimScene``, intrinsics from the zoom table) and publishes it
with the ground truth. The emulated camera answers VISCA on a
pseudo-terminal (``visca_emulator``): the real ``camera_driver`` opens the
path in ``camera_link`` exactly like the robot's serial port.

Topic names are relative (a namespace moves them all).

Publishes
    ``camera/image_raw`` (sensor_msgs/Image, bgr8, sensor-data QoS),
    ``camera/camera_info`` (sensor-data QoS),
    ``sim/true_pose`` (geometry_msgs/PoseStamped: base_link in the room frame),
    ``sim/true_camera_pose`` (PoseStamped: the optical frame in the room frame),
    ``sim/true_target`` (geometry_msgs/PointStamped: the centre of the card in
    view nearest the optical axis, or of the route's current card when none
    is in view, in ``camera_optical_frame``, metres: the convention of the
    locator's ``pattern_locator/target``). All stamped with the image's stamp.

Frames are rendered on the steady clock, so the sim runs with
``use_sim_time`` too; stamps are the node's ROS time. ``frame_rate_hz``,
``jpeg_quality`` and ``loop`` can be set at run time; the route and the
camera are read-only.

The route clock starts once the camera has been addressed and has finished
its power-up, and someone subscribes to the images (``wait_for_camera``).
"""

from dataclasses import replace
import math
import os
from pathlib import Path
import tempfile
import time
from typing import Optional, Tuple

from geometry_msgs.msg import PointStamped, PoseStamped
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, Image

from .image_codec import fill_camera_info, fill_msg
from .ros_helpers import describe_values, fill_pose, Param, Parameters, run_node, wall_timer
from ..errors import PatternLocatorError
from ..localization.head import HeadGeometry
from ..sim.world import RouteStop, SimRoute, SimScene
from ..visca.emulator import EmulatedEviD31
from ..visca.zoom_table import ZoomTable
from ..vision.geometry import Pose

PARAMETERS: Tuple[Param, ...] = (
    Param('floor', 1, 'floor of the simulated room', 0, 255),
    Param('room', 3, 'room of the simulated route', 1, 255),
    Param('mode', 'stops', "route: still at each stop (like the paper's images) or driving "
          'between stops', choices=('stops', 'drive')),
    Param('dwell_s', 2.5, 'time at each stop', 0.0, 600.0),
    Param('speed_m_s', 0.3, 'driving speed between stops', 0.01, 3.0),
    Param('n_stops', 30, 'stops of the paper route to drive', 1, 30),
    Param('seed', 7, 'seed of the headings and the image noise', 0, 2 ** 31),
    Param('frame_rate_hz', 10.0, 'camera frame rate', 0.5, 60.0, dynamic=True),
    Param('camera_link', '', 'path of the emulated camera port (a symlink to its '
          'pseudo-terminal; empty: a per-process temporary path)'),
    Param('zoom_table', '', 'zoom -> intrinsics YAML (empty: the shipped '
          'config/evi_d31_zoom.yaml)'),
    Param('field_rate_hz', 50.0, 'video fields per second (PAL EVI-D31: 50)', 1.0, 120.0),
    Param('init_s', 1.0, "the emulated camera's power-up initialisation", 0.0, 30.0),
    Param('wait_for_camera', True, 'start the route once the camera is addressed and '
          'initialised and the images have a subscriber'),
    Param('loop', False, 'drive the route again after its end', dynamic=True),
    Param('camera_frame', 'camera_optical_frame', 'frame of the images'),
    Param('jpeg_quality', 0, 'pass the images through JPEG at this quality (0: off)', 0, 100,
          dynamic=True),
    Param('head_mount_pitch_deg', 0.0, 'the camera is mounted pitched up by this on the tilt '
          'link (the locator must be told the same)', -60.0, 60.0),
    Param('route_stops', [0.0], 'a route of its own: x, y (m, room frame), heading (deg), '
          'card, repeated; [0.0]: the paper route'),
)


def default_camera_link() -> str:
    """Return a per-process path for the emulated camera's port symlink."""
    return str(Path(tempfile.gettempdir()) / f'pattern_locator_sim_{os.getpid()}' / 'evi_d31')


def route_from_parameters(p) -> SimRoute:
    """Return the paper route, or the one ``route_stops`` lists (x, y, heading_deg, card)."""
    values = list(p['route_stops'])
    if values == [0.0]:
        return SimRoute.paper_route(mode=p['mode'], dwell_s=p['dwell_s'],
                                    speed_m_s=p['speed_m_s'], seed=p['seed'],
                                    n_stops=p['n_stops'])
    if len(values) % 4:
        raise PatternLocatorError(f'sim: route_stops needs groups of 4 numbers (x, y, '
                                  f'heading_deg, card), got {len(values)} numbers')
    stops = [RouteStop((float(x), float(y)), math.radians(float(h)), int(c))
             for x, y, h, c in zip(*[iter(values)] * 4)]
    return SimRoute(stops, mode=p['mode'], dwell_s=p['dwell_s'], speed_m_s=p['speed_m_s'])


class SimNode(Node):
    """Thin ROS shell around the sim world and the emulated camera."""

    def __init__(self, **kwargs) -> None:
        super().__init__('sim', **kwargs)
        self.parameters = Parameters(self, PARAMETERS)
        p = self.parameters.values()
        if (p['floor'], p['room']) != (1, 3):
            raise PatternLocatorError('sim: only the paper route (floor 1, room 3) is built in')
        self.scene = SimScene(floor=p['floor'], room=p['room'], head=HeadGeometry(
            mount_pitch_rad=math.radians(p['head_mount_pitch_deg'])))
        self._set_jpeg(p['jpeg_quality'])
        self.route = route_from_parameters(p)
        self.zoom_table = ZoomTable.load(p['zoom_table'] or None)
        link = p['camera_link'] or default_camera_link()
        Path(link).parent.mkdir(parents=True, exist_ok=True)
        self.camera = EmulatedEviD31(field_rate_hz=p['field_rate_hz'], init_s=p['init_s'],
                                     link_path=link, seed=p['seed']).start()
        self.params = p
        self.room_frame = self.scene.room.frame
        self._frame = 0
        self._route_start: Optional[float] = None
        self._finished = False
        self.pub_image = self.create_publisher(Image, 'camera/image_raw',
                                               qos_profile_sensor_data)
        self.pub_info = self.create_publisher(CameraInfo, 'camera/camera_info',
                                              qos_profile_sensor_data)
        self.pub_true = self.create_publisher(PoseStamped, 'sim/true_pose', 10)
        self.pub_true_camera = self.create_publisher(PoseStamped, 'sim/true_camera_pose', 10)
        self.pub_true_target = self.create_publisher(PointStamped, 'sim/true_target', 10)
        self.get_logger().info(f'emulated EVI-D31 on {self.camera.port}')
        self.get_logger().info('sim configuration: ' + describe_values(p))
        self.get_logger().info(f'route: {len(self.route.stops)} stops in {self.room_frame}, '
                               f'{self.route.duration_s:.1f} s ({p["mode"]})')
        # Frames come on the steady clock: the sim renders whatever the ROS
        # time does (use_sim_time without a /clock); stamps are ROS time.
        self._timer = wall_timer(self, 1.0 / p['frame_rate_hz'], self._tick)
        self.parameters.on_change(lambda values: None, self._apply)

    def _set_jpeg(self, quality: int) -> None:
        self.scene.options = replace(self.scene.options,
                                     jpeg_quality=int(quality) if quality else None)

    def _apply(self, changed) -> None:
        self.params = {**self.params, **changed}
        if 'jpeg_quality' in changed:
            self._set_jpeg(changed['jpeg_quality'])
        if 'frame_rate_hz' in changed:
            self.destroy_timer(self._timer)
            self._timer = wall_timer(self, 1.0 / self.params['frame_rate_hz'], self._tick)

    def _route_time(self) -> Optional[float]:
        now = time.monotonic()
        if self._route_start is None:
            state = self.camera.state()
            ready = (self.camera.address is not None and state.powered
                     and not state.initialising and self.pub_image.get_subscription_count() > 0)
            if self.params['wait_for_camera'] and not ready:
                return None
            self._route_start = now
            self.get_logger().info('route started')
        t = now - self._route_start
        if t > self.route.duration_s:
            if self.params['loop']:
                return t % self.route.duration_s
            if not self._finished:
                self._finished = True
                self.get_logger().info('route finished')
        return t

    def _tick(self) -> None:
        t = self._route_time()
        # The camera's state and the stamp are taken together: the image shows
        # the head where it was at the stamp.
        state = self.camera.state()
        stamp = self.get_clock().now().to_msg()
        pan, tilt = -math.radians(state.pan_deg), math.radians(state.tilt_deg)
        T_room_base = self.route.pose_at(0.0 if t is None else t)
        camera = self.zoom_table.camera_at(state.zoom_units)
        self._frame += 1
        try:
            image = self.scene.render(T_room_base, pan, tilt, camera, seed=self._frame)
        except PatternLocatorError as exc:
            self.get_logger().error(f'render failed: {exc}', throttle_duration_sec=5.0)
            return
        frame = self.params['camera_frame']
        info = CameraInfo()
        fill_camera_info(info, camera)
        info.header.stamp, info.header.frame_id = stamp, frame
        msg = Image()
        fill_msg(msg, image, 'bgr8')
        msg.header.stamp, msg.header.frame_id = stamp, frame
        self.pub_info.publish(info)
        self.pub_image.publish(msg)
        self._publish_truth(stamp, T_room_base, pan, tilt, t, camera)

    def _publish_truth(self, stamp, T_room_base: Pose, pan: float, tilt: float,
                       t: Optional[float], camera) -> None:
        for publisher, T in ((self.pub_true, T_room_base),
                             (self.pub_true_camera,
                              self.scene.true_camera_pose(T_room_base, pan, tilt))):
            msg = PoseStamped()
            msg.header.stamp, msg.header.frame_id = stamp, self.room_frame
            fill_pose(msg.pose, T)
            publisher.publish(msg)
        # The card the head should be on: the one in view nearest the optical
        # axis (any card locates the robot), else the one the route faces.
        in_view = self.scene.visible_cards(T_room_base, pan, tilt, camera)
        card = min(in_view, key=lambda n: math.hypot(
            *self.scene.card_angles(T_room_base, pan, tilt, n))) if in_view \
            else self._current_card(t)
        T_camera_room = self.scene.true_camera_pose(T_room_base, pan, tilt).inverse()
        centre = T_camera_room.apply(self.scene.card(card).T_room_card.t[None])[0]
        target = PointStamped()
        target.header.stamp, target.header.frame_id = stamp, self.params['camera_frame']
        target.point.x, target.point.y, target.point.z = (float(v) for v in centre)
        self.pub_true_target.publish(target)

    def _current_card(self, t: Optional[float]) -> int:
        stops = self.route.stops
        if t is None:
            return stops[0].card
        index = self.route.stop_at(t)
        if index is None:
            # Driving: the card of the stop ahead.
            index = next((i for i in range(len(stops)) if self.route.dwell_window(i)[0] > t),
                         len(stops) - 1)
        return stops[index].card

    def stop(self) -> None:
        """Close the emulated camera (its pseudo-terminal and symlink)."""
        self.camera.stop()


def main(args=None) -> None:
    run_node(SimNode, 'sim', args)


if __name__ == '__main__':
    main()
