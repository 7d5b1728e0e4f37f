"""
The ``sim`` node: a simulated robot with an emulated EVI-D31, on the floor or in the paper's room.

The robot drives a route (``world``: ``floor``, a route of the floor world
``config/sim_floor.yaml`` through corridors, doors and rooms; ``paper``, the
paper's one room and its stops, or ``route_stops``). A thread renders, at
``frame_rate_hz``, what the head camera sees through
:class:`~pattern_locator.sim.floor_sim.FloorSim`: walls hide cards, the base's
and the head's motion during the exposure blur them, ``interlace`` draws two
fields. The head's angles over the exposure come from the emulated camera's
states (:class:`~pattern_locator.sim.floor_sim.HeadTrack`), which answers
VISCA on a pseudo-terminal (``visca.emulator``): the real ``camera_driver``
opens the path in ``camera_link`` exactly like the robot's serial port. A
timer publishes the base's odometry, with the drift of
:mod:`~pattern_locator.sim.odometry`.

Topic names are relative (a namespace moves them all); ``/clock`` and
``/diagnostics`` are absolute.

Publishes
    ``camera/image_raw`` (sensor_msgs/Image, bgr8, sensor-data QoS),
    ``camera/camera_info`` (sensor-data QoS), stamped with the middle of the
    frame's exposure (a frame is published once its exposure has ended);
    ``odom`` (nav_msgs/Odometry, frame ``odom_frame``, child ``base_frame``,
    pose and twist with their covariances, at ``odom_rate_hz``);
    ``sim/true_pose`` (geometry_msgs/PoseStamped: base_link in the frame of
    the room it is in, the room it was last in while in a doorway),
    ``sim/true_camera_pose`` (PoseStamped: the optical frame, same room frame),
    ``sim/true_pose/building`` (PoseStamped: base_link in the building frame),
    ``sim/true_room`` (std_msgs/UInt16MultiArray ``[floor, room]``, room 0 in a
    doorway), ``sim/true_twist`` (geometry_msgs/TwistStamped: the base's true
    speed and yaw rate in base_link), ``sim/true_target`` (geometry_msgs/
    PointStamped: the centre of the card in view nearest the optical axis, or
    of the card the head could turn to when none is, in
    ``camera_optical_frame``, metres: the convention of the locator's
    ``pattern_locator/target``); all the truth stamped with the image's stamp;
    ``/diagnostics`` (the route's state and the rendering's cost, 1 Hz);
    ``/clock`` (rosgraph_msgs/Clock) with ``publish_clock``.

Time: frames and odometry run on the sim's clock, diagnostics on the steady
clock. The sim's clock is the steady clock, or with ``real_time_factor``
below 1 (and ``publish_clock``) the steady clock slowed that much
(:class:`~pattern_locator.sim.sim_clock.ScaledClock`): the route, the
odometry and the emulated camera run slower than the wall, and a machine too
slow to render ``frame_rate_hz`` in real time gives the stack the frames of
each sim second that a faster one would (all of them at a low enough
factor). Stamps are the node's ROS time, or with
``publish_clock`` the sim's own time (seconds since the node started), which
it publishes on ``/clock`` for nodes with ``use_sim_time``.
``frame_rate_hz``, ``jpeg_quality`` and ``loop`` can be set
at run time; the world, the route and the camera are read-only.

The route clock starts once the camera has been addressed and has finished
its power-up, and someone subscribes to the images (``wait_for_camera``),
and once the stack is up: the camera driver and a locator have found each
other over DDS (``wait_for_stack``) and, with ``wait_for_target``, the
locator has found a card and sent its first target; after
``stack_timeout_s`` the route starts anyway, with a warning. A robot that
starts driving before the stack is warm loses its first seconds to DDS
discovery and the head's first search. Odometry starts with the route (the
odom frame is the base's pose at the start).
"""

from dataclasses import replace
import math
import os
from pathlib import Path
import statistics
import tempfile
import threading
import time
from typing import Any, Dict, List, Optional, Tuple

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PointStamped, PoseStamped, TwistStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import MultiArrayDimension, UInt16MultiArray

from .image_codec import fill_camera_info, fill_msg
from .ros_helpers import describe_values, fill_pose, Param, Parameters, run_node, wall_timer
from ..errors import ConfigError, PatternLocatorError
from ..localization.building import load_building
from ..localization.head import HeadGeometry
from ..sim.drive import DriveState
from ..sim.floor_file import load_floor_world
from ..sim.floor_scene import FloorScene
from ..sim.floor_sim import Exposure, FloorSim, FrameTruth, HeadTrack, RoomRoute
from ..sim.floor_world import FloorWorld
from ..sim.odometry import OdometryModel, OdomSample
from ..sim.sim_clock import ScaledClock
from ..sim.world import PAPER_FLOOR, PAPER_ROOM, RouteStop, SimRoute
from ..visca.emulator import EmulatedEviD31
from ..visca.zoom_table import ZoomTable
from ..vision.geometry import Pose

ROUTES = ('tour', 'loop', 'short')

PARAMETERS: Tuple[Param, ...] = (
    Param('world', 'floor', 'where the robot drives: the floor of the world file, or the '
          "paper's one room", choices=('floor', 'paper')),
    Param('world_file', '', 'floor world YAML (empty: the shipped config/sim_floor.yaml)'),
    Param('route', 'tour', 'route of the floor world', choices=ROUTES),
    Param('max_speed_m_s', 0.5, "cap on the floor route's cruise speeds", 0.05, 3.0),
    Param('as_hung_seed', -1, 'floor world: hang the cards off their mapped poses by a seeded '
          'few cm and degrees (-1: where the map says)', -1, 2 ** 31),
    Param('floor', 1, 'paper world: floor of the room', 0, 255),
    Param('room', 3, 'paper world: the room', 1, 255),
    Param('mode', 'stops', "paper world: still at each stop (like the paper's images) or "
          'driving between stops', choices=('stops', 'drive')),
    Param('dwell_s', 2.5, 'paper world: time at each stop', 0.0, 600.0),
    Param('speed_m_s', 0.3, 'paper world: driving speed between stops', 0.01, 3.0),
    Param('n_stops', 30, 'paper world: stops of the paper route to drive', 1, 30),
    Param('seed', 7, 'seed of the headings, the odometry and the image noise', 0, 2 ** 31),
    Param('frame_rate_hz', 10.0, 'camera frame rate', 0.5, 60.0, dynamic=True),
    Param('exposure_s', 0.02, "the camera's shutter in its automatic exposure, of each "
          'field when interlaced (the light is set for it; a shorter shutter the driver '
          'sets is made up with gain and noise)', 0.0, 0.2),
    Param('motion_blur', True, 'smear the cards along their motion during the exposure'),
    Param('interlace', False, 'two fields 1 / field_rate_hz apart, the even rows first (an '
          'analogue camera on a frame grabber)'),
    Param('odom_rate_hz', 50.0, 'odometry messages per second', 1.0, 200.0),
    Param('odom_scale_error', 0.02, 'odometry distance = (1 + this) x the true distance',
          -0.4, 0.4),
    Param('odom_yaw_bias_rad_s', 0.002, "the gyro's constant bias", -0.1, 0.1),
    Param('odom_speed_noise_m_s', 0.01, 'white noise of the measured speed', 0.0, 1.0),
    Param('odom_yaw_rate_noise_rad_s', 0.005, 'white noise of the measured yaw rate', 0.0,
          1.0),
    Param('odom_frame', 'odom', 'frame of the odometry pose'),
    Param('base_frame', 'base_link', 'frame of the robot base (odometry child frame)'),
    Param('publish_clock', False, 'publish the sim time on /clock and stamp with it (for '
          'nodes with use_sim_time)'),
    Param('clock_rate_hz', 100.0, '/clock messages per second', 1.0, 1000.0),
    Param('real_time_factor', 1.0, 'sim seconds per wall second: below 1 the route, the '
          'odometry, the emulated camera and /clock run that much slower, so a machine too '
          'slow to render in real time drops fewer frames (needs publish_clock)', 0.05, 1.0),
    Param('camera_link', '', 'path of the emulated camera port (a symlink to its '
          'pseudo-terminal; empty: a per-process temporary path)'),
    Param('zoom_table', '', 'zoom -> intrinsics YAML (empty: the shipped '
          'config/evi_d31_zoom.yaml)'),
    Param('field_rate_hz', 50.0, 'video fields per second (PAL EVI-D31: 50)', 1.0, 120.0),
    Param('init_s', 1.0, "the emulated camera's power-up initialisation", 0.0, 30.0),
    Param('wait_for_camera', True, 'start the route once the camera is addressed and '
          'initialised and the images have a subscriber'),
    Param('wait_for_stack', True, 'and once a camera driver and a locator have found each '
          'other (camera/joint_states and pattern_locator/target each have a publisher and '
          'a subscriber)'),
    Param('wait_for_target', False, "and once the locator's first pattern_locator/target "
          'came (it has found a card)'),
    Param('stack_timeout_s', 20.0, 'start the route anyway (with a warning) after waiting '
          'this long for the stack, once the camera is ready', 0.0, 600.0),
    Param('loop', False, 'drive the route again after its end', dynamic=True),
    Param('camera_frame', 'camera_optical_frame', 'frame of the images'),
    Param('jpeg_quality', 0, 'pass the images through JPEG at this quality (0: off)', 0, 100,
          dynamic=True),
    Param('head_mount_pitch_deg', 0.0, 'the camera is mounted pitched up by this on the tilt '
          'link (the locator must be told the same)', -60.0, 60.0),
    Param('route_stops', [0.0], 'paper world: a route of its own: x, y (m, room frame), '
          'heading (deg), card, repeated; [0.0]: the paper route'),
)

# Renders timed for the diagnostics (the last this many).
RENDER_HISTORY = 100


def default_camera_link() -> str:
    """Return a per-process path for the emulated camera's port symlink."""
    return str(Path(tempfile.gettempdir()) / f'pattern_locator_sim_{os.getpid()}' / 'evi_d31')


def route_from_parameters(p) -> SimRoute:
    """Return the paper route, or the one ``route_stops`` lists (x, y, heading_deg, card)."""
    values = list(p['route_stops'])
    if values == [0.0]:
        if (p['floor'], p['room']) != (PAPER_FLOOR, PAPER_ROOM):
            raise PatternLocatorError(f'sim: the paper route is in floor {PAPER_FLOOR} room '
                                      f'{PAPER_ROOM}; give route_stops for another room')
        return SimRoute.paper_route(mode=p['mode'], dwell_s=p['dwell_s'],
                                    speed_m_s=p['speed_m_s'], seed=p['seed'],
                                    n_stops=p['n_stops'])
    if len(values) % 4:
        raise PatternLocatorError(f'sim: route_stops needs groups of 4 numbers (x, y, '
                                  f'heading_deg, card), got {len(values)} numbers')
    stops = [RouteStop((float(x), float(y)), math.radians(float(h)), int(c))
             for x, y, h, c in zip(*[iter(values)] * 4)]
    return SimRoute(stops, mode=p['mode'], dwell_s=p['dwell_s'], speed_m_s=p['speed_m_s'])


class LoopedRoute:
    """
    A route driven again and again while :attr:`looping` (route time taken modulo its duration).

    The floor's ``tour`` and ``loop`` end where and as they start, so their
    repeats join smoothly; other routes jump back to their start.
    """

    def __init__(self, route: Any) -> None:
        self.route = route
        self.looping = False
        self.teleports = getattr(route, 'teleports', False)

    @property
    def duration_s(self) -> float:
        """Return one pass's duration."""
        return self.route.duration_s

    def _t(self, t: float) -> float:
        d = self.route.duration_s
        return t % d if self.looping and t > d and d > 0.0 else t

    def pose_at(self, t: float) -> Pose:
        """Return ``T_building_base`` at route time ``t``."""
        return self.route.pose_at(self._t(t))

    def state_at(self, t: float) -> DriveState:
        """Return the base's pose and twist at route time ``t``."""
        return replace(self.route.state_at(self._t(t)), t=t)

    def stop_at(self, t: float) -> Optional[int]:
        """Return the stop the robot stands at, None otherwise."""
        return self.route.stop_at(self._t(t))


def build_sim(p: Dict[str, Any]) -> Tuple[FloorSim, LoopedRoute, str]:
    """Return the sim of the node's parameters, its looping route and a line describing it."""
    head = HeadGeometry(mount_pitch_rad=math.radians(p['head_mount_pitch_deg']))
    # The scene's light is set for the camera's automatic exposure (reference_s).
    exposure = Exposure(exposure_s=p['exposure_s'], reference_s=p['exposure_s'] or 0.02,
                        interlace=p['interlace'],
                        field_period_s=1.0 / p['field_rate_hz'], blur=p['motion_blur'])
    odometry = OdometryModel(scale_error=p['odom_scale_error'],
                             yaw_bias_rad_s=p['odom_yaw_bias_rad_s'],
                             speed_noise_m_s=p['odom_speed_noise_m_s'],
                             yaw_rate_noise_rad_s=p['odom_yaw_rate_noise_rad_s'],
                             rate_hz=p['odom_rate_hz'])
    if p['world'] == 'floor':
        world = load_floor_world(p['world_file'] or None, as_hung_seed=(
            None if p['as_hung_seed'] < 0 else p['as_hung_seed']))
        limits = replace(world.limits, max_speed_m_s=float(p['max_speed_m_s']))
        inner = world.route(p['route'], limits)
        what = (f'floor {world.floor}, route {p["route"]}: {inner.length_m:.1f} m in '
                f'{inner.duration_s:.1f} s (at most {p["max_speed_m_s"]} m/s)')
    else:
        building = load_building()
        room_route = route_from_parameters(p)
        world = FloorWorld.from_room(building, p['floor'], p['room'])
        inner = RoomRoute(room_route, building.room(p['floor'], p['room']).T_building_room)
        what = (f'paper room: {len(room_route.stops)} stops in floor {p["floor"]} room '
                f'{p["room"]}, {room_route.duration_s:.1f} s ({p["mode"]})')
    route = LoopedRoute(inner)
    sim = FloorSim(world, route, head=head, exposure=exposure, odometry=odometry,
                   seed=p['seed'])
    return sim, route, what


def ids_message(values: Tuple[int, ...], labels: Tuple[str, ...]) -> UInt16MultiArray:
    """Return a UInt16MultiArray of ``values`` with its dimensions labelled."""
    msg = UInt16MultiArray()
    msg.layout.dim = [MultiArrayDimension(label=label, size=1, stride=1) for label in labels]
    msg.data = [int(v) for v in values]
    return msg


class SimNode(Node):
    """Thin ROS shell around :class:`FloorSim` and the emulated camera."""

    def __init__(self, **kwargs) -> None:
        super().__init__('sim', **kwargs)
        self.parameters = Parameters(self, PARAMETERS)
        p = self.parameters.values()
        self.params = p
        try:
            self.sim, self.route, what = build_sim(p)
        except (ValueError, KeyError) as exc:
            raise ConfigError(f'sim: {exc}') from None
        self.world = self.sim.world
        self._set_jpeg(p['jpeg_quality'])
        self.route.looping = bool(p['loop'])
        self.zoom_table = ZoomTable.load(p['zoom_table'] or None)
        building = self.world.building
        self.building_frame = building.frame
        self._rooms = {(r.floor, r.room): r for r in self.world.rooms}
        start = self.world.room_at(self.route.pose_at(0.0).t[:2])
        first = self.world.rooms[0]
        self._room = ((start.floor, start.room) if start is not None else
                      (p['floor'], p['room']) if p['world'] == 'paper' else
                      (first.floor, first.room))
        link = p['camera_link'] or default_camera_link()
        Path(link).parent.mkdir(parents=True, exist_ok=True)
        if p['real_time_factor'] < 1.0 and not p['publish_clock']:
            # On ROS time the stamps would run at the wall's pace, the world slower.
            raise ConfigError(f"sim: real_time_factor {p['real_time_factor']} needs "
                              'publish_clock (the slowed time is only on /clock)')
        # Every time of the node is on this clock (the steady clock when the factor is 1).
        self._sim_clock = ScaledClock(p['real_time_factor'])
        self.camera = EmulatedEviD31(field_rate_hz=p['field_rate_hz'], init_s=p['init_s'],
                                     link_path=link, seed=p['seed'],
                                     auto_shutter_s=p['exposure_s'], clock=self._sim_clock,
                                     clock_rate=self._sim_clock.rate).start()
        self._head = HeadTrack(max_samples=128)
        self._head_lock = threading.Lock()
        self._zoom_units = 0.0
        self._shutter_s = p['exposure_s']
        self._route_start: Optional[float] = None
        self._route_start_stamp = 0
        # When the camera was first ready (the stack's wait runs from then).
        self._camera_ready_at: Optional[float] = None
        self._first_target = threading.Event()
        # The odometry timer and the frame thread both ask whether the route runs.
        self._start_lock = threading.Lock()
        self._finished = False
        self._frames = 0
        self._odometry_sent = 0
        self._render_ms: List[float] = []
        self._late_frames = 0
        self._stopping = threading.Event()
        self.pub_image = self.create_publisher(Image, 'camera/image_raw',
                                               qos_profile_sensor_data)
        self.pub_info = self.create_publisher(CameraInfo, 'camera/camera_info',
                                              qos_profile_sensor_data)
        self.pub_odom = self.create_publisher(Odometry, 'odom', QoSProfile(depth=50))
        self.pub_true = self.create_publisher(PoseStamped, 'sim/true_pose', 10)
        self.pub_true_camera = self.create_publisher(PoseStamped, 'sim/true_camera_pose', 10)
        self.pub_true_building = self.create_publisher(PoseStamped, 'sim/true_pose/building',
                                                       10)
        self.pub_true_room = self.create_publisher(UInt16MultiArray, 'sim/true_room', 10)
        self.pub_true_twist = self.create_publisher(TwistStamped, 'sim/true_twist', 10)
        self.pub_true_target = self.create_publisher(PointStamped, 'sim/true_target', 10)
        self.pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.pub_clock = (self.create_publisher(Clock, '/clock', QoSProfile(
            depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)) if p['publish_clock'] else None)
        # The locator's targets, only to know when it has found its first card
        # (best effort: matches any publisher).
        self._target_sub = (self.create_subscription(
            PointStamped, 'pattern_locator/target', lambda _: self._first_target.set(),
            qos_profile_sensor_data) if p['wait_for_target'] else None)
        self.get_logger().info(f'emulated EVI-D31 on {self.camera.port}')
        for line in describe_values(p):
            self.get_logger().info('sim configuration: ' + line)
        self.get_logger().info(f'route: {what}')
        # Rates per sim second (a slowed sim also publishes less per wall second).
        wall_s = self._sim_clock.wall_s
        wall_timer(self, wall_s(1.0 / p['odom_rate_hz']), self._on_odometry_timer)
        wall_timer(self, 1.0, self._publish_diagnostics)
        if self.pub_clock is not None:
            wall_timer(self, wall_s(1.0 / p['clock_rate_hz']), self._publish_clock)
        self.parameters.on_change(lambda values: None, self._apply)
        # Frames are rendered on a thread of their own, so the odometry and the
        # parameter services keep their pace while a frame renders.
        self._thread = threading.Thread(target=self._frame_loop, name='sim-frames',
                                        daemon=True)
        self._thread.start()

    # Parameters -------------------------------------------------------------------------

    def _set_jpeg(self, quality: int) -> None:
        scene = self.sim.scene
        options = replace(scene.options, jpeg_quality=int(quality) if quality else None)
        # A new scene (its renderer holds the options); the frame thread takes it
        # at its next frame.
        self.sim.scene = FloorScene(scene.world, scene.head, options)

    def _apply(self, changed) -> None:
        self.params = {**self.params, **changed}
        if 'jpeg_quality' in changed:
            self._set_jpeg(changed['jpeg_quality'])
        if 'loop' in changed:
            self.route.looping = bool(changed['loop'])

    # Clocks -----------------------------------------------------------------------------

    def _stamp_ns(self, at: float) -> int:
        """Return the ROS stamp (ns) of a time of the sim's clock."""
        if self.pub_clock is not None:
            return int(round((at - self._sim_clock.origin) * 1e9))
        return self.get_clock().now().nanoseconds - int(round((self._sim_clock() - at) * 1e9))

    @staticmethod
    def _time_msg(ns: int):
        from builtin_interfaces.msg import Time
        return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)

    def _publish_clock(self) -> None:
        msg = Clock()
        msg.clock = self._time_msg(self._stamp_ns(self._sim_clock()))
        self.pub_clock.publish(msg)

    def _sample_head(self) -> float:
        """Record the emulated head's angles now (for the exposures); return the time."""
        with self._head_lock:
            state = self.camera.state()
            self._head.add(state.stamp, -math.radians(state.pan_deg),
                           math.radians(state.tilt_deg))
            self._zoom_units = state.zoom_units
            self._shutter_s = state.shutter_s
            return state.stamp

    def _head_at(self, mono: float) -> Tuple[float, float]:
        with self._head_lock:
            return self._head(mono)

    def _stack_missing(self) -> List[str]:
        """Return what the stack still lacks before the route may start (empty: ready)."""
        missing = []
        if self.params['wait_for_stack']:
            # The graph as this node sees it: the driver publishes joint states
            # to the locator, the locator targets to the driver.
            own = 1 if self._target_sub is not None else 0
            if not (self.count_publishers('camera/joint_states') > 0
                    and self.count_subscribers('camera/joint_states') > 0):
                missing.append('camera/joint_states publisher and subscriber')
            if not (self.count_publishers('pattern_locator/target') > 0
                    and self.count_subscribers('pattern_locator/target') > own):
                missing.append('pattern_locator/target publisher and subscriber')
        if self.params['wait_for_target'] and not self._first_target.is_set():
            missing.append("the locator's first target")
        return missing

    def _started(self, now: float) -> bool:
        """Return whether the route runs, starting it when everything is ready."""
        if self._route_start is not None:
            return True
        with self._start_lock:
            return self._route_start is not None or self._start_if_ready(now)

    def _start_if_ready(self, now: float) -> bool:
        if self.params['wait_for_camera']:
            state = self.camera.state()
            if not (self.camera.address is not None and state.powered
                    and not state.initialising and self.pub_image.get_subscription_count() > 0):
                return False
        if self._camera_ready_at is None:
            self._camera_ready_at = now
        waited = now - self._camera_ready_at
        missing = self._stack_missing()
        if missing and waited < self.params['stack_timeout_s']:
            return False
        self._route_start = now
        self._route_start_stamp = self._stamp_ns(now)
        if missing:
            self.get_logger().warning(f'route started after waiting {waited:.1f} s for the '
                                      f'stack without {", ".join(missing)}')
        else:
            self.get_logger().info(f'route started (the stack was ready {waited:.1f} s after '
                                   'the camera)')
        return True

    # Odometry ---------------------------------------------------------------------------

    def _on_odometry_timer(self) -> None:
        now = self._sample_head()
        if not self._started(now):
            return
        try:
            for sample in self.sim.odometry(now - self._route_start):
                self._publish_odometry(sample)
        except Exception:  # noqa: B902 - a signal invalidates the context under us
            if self.context.ok():
                raise

    def _publish_odometry(self, sample: OdomSample) -> None:
        msg = Odometry()
        msg.header.stamp = self._time_msg(self._stamp_ns(self._route_start + sample.stamp_s))
        msg.header.frame_id = self.params['odom_frame']
        msg.child_frame_id = self.params['base_frame']
        fill_pose(msg.pose.pose, sample.T_odom_base)
        msg.pose.covariance = [float(v) for v in sample.pose_covariance.ravel()]
        msg.twist.twist.linear.x = float(sample.linear_x)
        msg.twist.twist.linear.y = float(sample.linear_y)
        msg.twist.twist.angular.z = float(sample.angular_z)
        msg.twist.covariance = [float(v) for v in sample.twist_covariance.ravel()]
        self.pub_odom.publish(msg)
        self._odometry_sent += 1

    # Frames -----------------------------------------------------------------------------

    def _frame_loop(self) -> None:
        due = self._sim_clock()
        while not self._stopping.is_set():
            self._stopping.wait(max(0.0, self._sim_clock.wall_s(due - self._sim_clock())))
            if self._stopping.is_set():
                break
            try:
                self._frame()
            except PatternLocatorError as exc:
                self.get_logger().error(f'render failed: {exc}', throttle_duration_sec=5.0)
            except Exception:  # noqa: B902 - a signal invalidates the context under us
                if self.context.ok() and not self._stopping.is_set():
                    raise
                return
            due += 1.0 / self.params['frame_rate_hz']
            if due < self._sim_clock():
                # Late (a loaded machine): the next frame now, never a burst.
                self._late_frames += 1
                due = self._sim_clock()

    def _frame(self) -> None:
        now = self._sample_head()
        if self._shutter_s != self.sim.exposure.exposure_s:
            # The camera's shutter now (the driver may set it): the frame's
            # exposure, its blur, and the gain that makes up its light.
            self.sim.exposure = replace(self.sim.exposure, exposure_s=self._shutter_s)
        origin = self._route_start if self._started(now) else now
        t = self.sim.exposure.latest_stamp(now - origin)
        if self._route_start is not None and not self._finished and \
                not self.route.looping and t > self.route.duration_s:
            self._finished = True
            self.get_logger().info('route finished')
        camera = self.zoom_table.camera_at(self._zoom_units)
        self._frames += 1

        def head_at(x: float) -> Tuple[float, float]:
            return self._head_at(x + origin)

        began = time.perf_counter()
        image, blurs = self.sim.render(t, head_at, camera,
                                       seed=self.params['seed'] * 100_003 + self._frames)
        self._render_ms.append((time.perf_counter() - began) * 1e3)
        del self._render_ms[:-RENDER_HISTORY]
        stamp = self._time_msg(self._stamp_ns(origin + t))
        name = self.params['camera_frame']
        info = CameraInfo()
        fill_camera_info(info, camera)
        info.header.stamp, info.header.frame_id = stamp, name
        msg = Image()
        fill_msg(msg, image, 'bgr8')
        msg.header.stamp, msg.header.frame_id = stamp, name
        self.pub_info.publish(info)
        self.pub_image.publish(msg)
        # The truth after the image: its cost is not the image's latency.
        self._publish_truth(stamp, self.sim.truth(t, head_at, camera, blurs))

    def _publish_truth(self, stamp, truth: FrameTruth) -> None:
        if truth.room is not None:
            self._room = truth.room
        room = self._rooms[self._room]
        T_room_building = room.T_building_room.inverse()
        for publisher, T, frame in (
                (self.pub_true, T_room_building @ truth.T_building_base, room.frame),
                (self.pub_true_camera, T_room_building @ truth.T_building_camera, room.frame),
                (self.pub_true_building, truth.T_building_base, self.building_frame)):
            msg = PoseStamped()
            msg.header.stamp, msg.header.frame_id = stamp, frame
            fill_pose(msg.pose, T)
            publisher.publish(msg)
        floor = self.world.floor
        self.pub_true_room.publish(ids_message(
            (floor, truth.room[1] if truth.room is not None else 0), ('floor', 'room')))
        twist = TwistStamped()
        twist.header.stamp, twist.header.frame_id = stamp, self.params['base_frame']
        twist.twist.linear.x = float(truth.speed_m_s)
        twist.twist.angular.z = float(truth.yaw_rate_rad_s)
        self.pub_true_twist.publish(twist)
        if truth.target is None:
            return
        centre = truth.T_building_camera.inverse().apply(
            self.world.card(truth.target).T_building_card.t[None])[0]
        target = PointStamped()
        target.header.stamp, target.header.frame_id = stamp, self.params['camera_frame']
        target.point.x, target.point.y, target.point.z = (float(v) for v in centre)
        self.pub_true_target.publish(target)

    # Diagnostics ------------------------------------------------------------------------

    def route_state(self) -> str:
        """Return the route's state: waiting, driving, looping or finished."""
        if self._route_start is None:
            return ('waiting for the camera and a subscriber' if self._camera_ready_at is None
                    else 'waiting for the stack')
        if self.route.looping:
            return 'looping'
        return 'finished' if self._finished else 'driving'

    def _publish_diagnostics(self) -> None:
        now = self._sim_clock()
        route_time = now - self._route_start if self._route_start is not None else 0.0
        render = list(self._render_ms)
        status = DiagnosticStatus()
        status.name = 'sim: route'
        status.hardware_id = str(self.camera.port)[:80]
        status.level = DiagnosticStatus.OK
        status.message = self.route_state()
        start = self._route_start_stamp
        values = {
            'world': self.params['world'],
            'route': self.params['route'] if self.params['world'] == 'floor' else 'paper',
            'route time s': f'{route_time:.2f}',
            'route duration s': f'{self.route.duration_s:.3f}',
            'route start stamp': f'{start // 1_000_000_000}.{start % 1_000_000_000:09d}'
            if self._route_start is not None else '',
            'frames': self._frames, 'late frames': self._late_frames,
            'render ms median': f'{statistics.median(render):.1f}' if render else '',
            'render ms max': f'{max(render):.1f}' if render else '',
            # The camera's shutter the frames are exposed with (the driver may set it).
            'exposure ms': f'{self.sim.exposure.exposure_s * 1e3:g}',
            'odometry messages': self._odometry_sent,
            'real time factor': f'{self._sim_clock.rate:g}',
        }
        status.values = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
        array = DiagnosticArray()
        array.header.stamp = self.get_clock().now().to_msg()
        array.status = [status]
        try:
            self.pub_diag.publish(array)
        except Exception:  # noqa: B902 - a signal invalidates the context under us
            if self.context.ok():
                raise

    def stop(self) -> None:
        """Stop the frames and close the emulated camera (its pseudo-terminal and symlink)."""
        self._stopping.set()
        self._thread.join(timeout=2.0)
        self.camera.stop()


def main(args=None) -> None:
    run_node(SimNode, 'sim', args)


if __name__ == '__main__':
    main()
