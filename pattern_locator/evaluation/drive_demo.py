"""
The drive through the floor (``pattern-locator demo``, ``bench --drive``): run it, judge it.

Three processes talk over DDS (localhost discovery), as on the robot:
``sim`` (the robot drives a route of ``config/sim_floor.yaml`` through
corridors, doors and rooms, renders what its head camera sees, owns the
emulated EVI-D31 and publishes odometry), ``camera_driver`` (keeps the card
centred, odometry fed forward) and ``locator`` (given the floor's building
map ``config/floor_building.yaml``). This process only watches
(:class:`DriveObserver`): the sim's truth at every image stamp, every fix
with its ids and covariance, the nodes' diagnostics. :func:`judge` turns
that into :class:`DriveMetrics`:

* ``fix_coverage``: the fraction of the route's time (start to end, stops
  included) at which the robot had a fix younger than 0.5 s that had
  already arrived (a fix counts from its arrival, with the age of its
  image); ``fix_coverage_by_stamp`` counts it from its image's stamp;
* errors: the base's 3-D position error of each fix against the truth at
  its image's stamp, in the fix's own frame; ``coverage_95``: the fraction
  of fixes whose error lies inside their own 95 % ellipsoid (position block
  of the published covariance, chi-square 3 dof: 7.815);
* ``wrong_ids``: fixes whose card was not in the image (from the sim's
  world at the true camera pose): a misread card, the one thing never to
  publish; ``other_room``: fixes of a card of another room than the robot's
  (seen through a door: the pose is right in that room's frame);
* handovers: a fix of a new card after fixes of another; the time between
  the last fix of the old and the first of the new;
* the located card's angle off the true optical axis in images where the
  head has been on it for a second (fixes of the same card, none more than
  0.5 s apart), could centre it (within the head's travel) and was told to
  (the locator's target of that image is this card, not the next one the
  gaze already looks for), and those while the base turns; VISCA traffic
  from the driver's diagnostics.
"""

from dataclasses import dataclass, field
import json
import math
import os
from pathlib import Path
import signal
import sys
import tempfile
import time
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from ..errors import PatternLocatorError
from ..localization.building import BuildingMap, load_building
from ..localization.head import HeadGeometry
from ..nodes.node_process import node_process
from ..resources import config_path
from ..sim.floor_file import load_floor_world
from ..sim.floor_scene import FloorScene
from ..sim.floor_world import FloorWorld
from ..vision.geometry import Pose, rotation_from_quaternion

FLOOR_ROUTES = ('loop', 'tour', 'short')
# The robot's camera looks up 15 deg at tilt 0, as in the one-room demo: cards
# 1.05 m above the lens are in the EVI-D31's +25 deg from 2.2 m away instead of 2.3 m.
MOUNT_PITCH_DEG = 15.0
FRESH_S = 0.5
CHI2_3_95 = 7.814727903251178
# Off-axis angles count as "in a turn" above this yaw rate.
TURNING_RAD_S = 0.1
COVERAGE_STEP_S = 0.05
# Off-axis angles count once the head has been on a card this long (not its acquisition).
SETTLED_S = 1.0
# A target names the fix's card when it lies this close to the card's true centre
# (the locator's measured centre is off by millimetres to centimetres).
TARGET_MATCH_M = 0.3
# The EVI-D31's travel (deg): a card beyond it cannot be centred (the gaze's job).
PAN_TRAVEL_DEG = 100.0
TILT_TRAVEL_DEG = 25.0


def pose_from_msg(msg) -> Pose:
    """Return the Pose of a geometry_msgs/Pose."""
    q = msg.orientation
    return Pose(rotation_from_quaternion(np.array([q.x, q.y, q.z, q.w])),
                np.array([msg.position.x, msg.position.y, msg.position.z]))


@dataclass
class TruthFrame:
    """The sim's truth at one image stamp (any field may be missing if a message was lost)."""

    T_building_base: Optional[Pose] = None
    T_room_camera: Optional[Pose] = None
    camera_frame_id: str = ''
    speed_m_s: Optional[float] = None
    yaw_rate_rad_s: Optional[float] = None


@dataclass
class Fix:
    """One published fix: its image stamp, arrival, frame, pose, covariance and ids."""

    stamp_ns: int
    arrival_ns: int
    frame_id: str
    T_frame_base: Pose
    covariance: Optional[np.ndarray] = None
    ids: Optional[Tuple[int, int, int]] = None


class DriveObserver:
    """A node in this process that records the truth, the fixes and the diagnostics."""

    def __init__(self, context, namespace: str = '', odometry: bool = False,
                 sim_time: bool = False, building: Optional[BuildingMap] = None) -> None:
        from diagnostic_msgs.msg import DiagnosticArray
        from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
        from geometry_msgs.msg import TwistStamped
        import rclpy
        from rclpy.qos import (DurabilityPolicy, qos_profile_sensor_data, QoSProfile,
                               ReliabilityPolicy)
        from sensor_msgs.msg import CameraInfo
        from std_msgs.msg import UInt16MultiArray

        from rclpy.parameter import Parameter
        # With the sim's /clock, a fix's arrival is on that clock too.
        self.node = rclpy.create_node('drive_observer', context=context,
                                      namespace='/' + namespace.strip('/'),
                                      parameter_overrides=[Parameter('use_sim_time',
                                                                     value=sim_time)])
        self.frames: Dict[int, TruthFrame] = {}
        self.fixes: List[Fix] = []
        self._ids: List[Tuple[int, int, int]] = []
        self._unpaired: List[Fix] = []
        self.building: Optional[BuildingMap] = building
        self.cameras: Dict[Tuple[float, ...], Any] = {}
        self.camera_of: Dict[int, Tuple[float, ...]] = {}
        self.sim_status: Dict[str, str] = {}
        self.sim_message = ''
        # (arrival, key -> value) of the camera driver's and the locator's diagnostics.
        self.driver_diagnostics: List[Tuple[float, Dict[str, str]]] = []
        self.locator_diagnostics: Dict[str, str] = {}
        n = self.node
        n.create_subscription(PoseStamped, 'sim/true_pose/building', lambda m: self._truth(
            m, T_building_base=pose_from_msg(m.pose)), 100)
        n.create_subscription(PoseStamped, 'sim/true_camera_pose', lambda m: self._truth(
            m, T_room_camera=pose_from_msg(m.pose), camera_frame_id=m.header.frame_id), 100)
        n.create_subscription(TwistStamped, 'sim/true_twist', lambda m: self._truth(
            m, speed_m_s=m.twist.linear.x, yaw_rate_rad_s=m.twist.angular.z), 100)
        n.create_subscription(CameraInfo, 'camera/camera_info', self._on_camera_info,
                              qos_profile_sensor_data)
        # The fixes: robot_location and its ids (both kept 10 deep by the locator, so a
        # busy observer loses neither), the covariance by stamp (its topic is latched,
        # kept 1 deep: one can be lost, then that fix has no covariance).
        n.create_subscription(UInt16MultiArray, 'robot_location/ids', self._on_ids, 100)
        n.create_subscription(PoseStamped, 'robot_location', self._on_fix, 100)
        n.create_subscription(PoseWithCovarianceStamped, 'robot_location/with_covariance',
                              self._on_covariance, QoSProfile(
                                  depth=100, reliability=ReliabilityPolicy.RELIABLE,
                                  durability=DurabilityPolicy.TRANSIENT_LOCAL))
        self.covariances: Dict[int, np.ndarray] = {}
        self.mispaired = 0
        self._rooms_by_frame = {}
        n.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics, 50)
        # The locator's target per image stamp (the card centre in the optical frame,
        # metres): which card the head was told to centre.
        from geometry_msgs.msg import PointStamped
        self.targets: Dict[int, np.ndarray] = {}
        n.create_subscription(PointStamped, 'pattern_locator/target', lambda m: self.targets.
                              __setitem__(self._key(m), np.array([m.point.x, m.point.y,
                                                                  m.point.z])), 100)
        # (stamp ns, T_odom_base, 6x6 pose covariance) of every odometry message, if asked.
        self.odometry: List[Tuple[int, Pose, np.ndarray]] = []
        if odometry:
            from nav_msgs.msg import Odometry
            n.create_subscription(Odometry, 'odom', lambda m: self.odometry.append((
                self._key(m), pose_from_msg(m.pose.pose),
                np.array(m.pose.covariance, dtype=float).reshape(6, 6))), 200)

    @staticmethod
    def _key(msg) -> int:
        return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec

    def _truth(self, msg, **values) -> None:
        frame = self.frames.setdefault(self._key(msg), TruthFrame())
        for name, value in values.items():
            setattr(frame, name, value)

    def _on_camera_info(self, msg) -> None:
        key = (msg.width, msg.height) + tuple(float(v) for v in msg.k) + tuple(
            float(v) for v in msg.d)
        if key not in self.cameras:
            from ..nodes.image_codec import camera_from_info
            try:
                self.cameras[key] = camera_from_info(msg)
            except Exception:  # noqa: B902 - a bad camera_info is the sim's bug, not ours
                return
        self.camera_of[self._key(msg)] = key

    def _on_ids(self, msg) -> None:
        self._ids.append(tuple(int(v) for v in msg.data))
        self._pair()

    def _on_fix(self, msg) -> None:
        now = self.node.get_clock().now().nanoseconds
        self.fixes.append(Fix(self._key(msg), now, msg.header.frame_id,
                              pose_from_msg(msg.pose)))
        self._unpaired.append(self.fixes[-1])
        self._pair()

    def _on_covariance(self, msg) -> None:
        self.covariances[self._key(msg)] = np.array(msg.pose.covariance,
                                                    dtype=float).reshape(6, 6)

    def _pair(self) -> None:
        # The locator publishes the ids just before each pose: the n-th ids are the
        # n-th pose's. A room frame names the room: ids of another room mean a message
        # was lost on one side, and that pair is not made (counted as mispaired).
        while self._unpaired and self._ids:
            fix, ids = self._unpaired.pop(0), self._ids.pop(0)
            room = self.room_of_frame(fix.frame_id)
            if room is not None and room != ids[:2]:
                self.mispaired += 1
                continue
            fix.ids = ids

    def room_of_frame(self, frame_id: str) -> Optional[Tuple[int, int]]:
        """Return (floor, room) of a room frame name of the floor's map (None otherwise)."""
        if self.building is None:
            return None
        if frame_id not in self._rooms_by_frame:
            try:
                room = self.building.room_by_frame(frame_id)
                self._rooms_by_frame[frame_id] = (room.floor, room.room)
            except Exception:  # noqa: B902 - the building frame or an unknown one
                self._rooms_by_frame[frame_id] = None
        return self._rooms_by_frame[frame_id]

    def _on_diagnostics(self, msg) -> None:
        for status in msg.status:
            values = {kv.key: kv.value for kv in status.values}
            if status.name.startswith('sim'):
                self.sim_status, self.sim_message = values, status.message
            elif status.name.startswith('camera_driver'):
                self.driver_diagnostics.append((time.monotonic(), values))
            elif status.name.rsplit(': ', 1)[-1] == 'locator':     # 'pattern_locator: locator'
                self.locator_diagnostics = values

    def route_window(self) -> Optional[Tuple[int, int]]:
        """Return the route's (start, end) stamps (ns) from the sim's diagnostics, if known."""
        start = self.sim_status.get('route start stamp', '')
        if not start:
            return None
        sec, nsec = start.split('.')
        begin = int(sec) * 1_000_000_000 + int(nsec)
        duration = float(self.sim_status.get('route duration s', 'nan'))
        return begin, begin + int(duration * 1e9)


@dataclass(frozen=True)
class DriveSetup:
    """How a drive is run: the route, its speed, the seeds, what the driver does."""

    route: str = 'loop'
    max_speed_m_s: float = 0.5
    seed: int = 7
    as_hung_seed: int = -1
    feed_forward: bool = True
    interlace: bool = False
    exposure_s: float = 0.02          # the camera's shutter in its automatic exposure
    # The driver sets the camera's shutter (shutter priority; 0: its automatic
    # exposure). 1/250 s smears a card a fifth as much while the head slews;
    # the camera's gain makes up the light, with five times the noise.
    shutter_s: float = 0.004
    frame_rate_hz: float = 10.0
    estimator: str = 'exact'
    zoom_control: bool = True          # the driver zooms on its card (a far card's fix)
    timeout_s: float = 0.0            # 0: the route's duration plus a margin
    until_s: float = 0.0              # > 0: stop after this much route time
    camera_init_s: float = 1.0        # the emulated camera's power-up
    sim_time: bool = False            # the sim publishes /clock, every node runs on it
    # < 1 (with sim_time): the sim's world and clock run this much slower than the
    # wall, so a slow machine renders the frames of a sim second a faster one would.
    real_time_factor: float = 1.0
    record_odometry: bool = False
    namespace: str = ''
    driver_parameters: Tuple[str, ...] = ()
    locator_parameters: Tuple[str, ...] = ()
    # The locator's building map ('': config/floor_building.yaml, the sim's own). A
    # surveyed map (evaluation/survey_drive.py) must keep that map's room frames.
    building_map: str = ''


def run_drive(out: Path, setup: DriveSetup, progress: bool = False) -> DriveObserver:
    """
    Run sim, camera_driver and locator as processes along a floor route; return what was seen.

    Ends when the sim says the route has finished (or its time reached
    ``setup.until_s``), plus half a second for the last fixes, or after the
    timeout, with a message. Node logs go to ``out``.
    """
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    os.environ.setdefault('FASTRTPS_DEFAULT_PROFILES_FILE',
                          str(config_path('fastdds_large_messages.xml')))
    out.mkdir(parents=True, exist_ok=True)
    world = load_floor_world()
    duration = world.route(setup.route, _limits(world, setup)).duration_s
    if setup.real_time_factor < 1.0 and not setup.sim_time:
        raise PatternLocatorError('a real-time factor below 1 needs sim_time (the slowed '
                                  'time is on /clock)')
    timeout = setup.timeout_s or duration / setup.real_time_factor + 90.0
    context = Context()
    rclpy.init(context=context)
    locator_map = setup.building_map or str(config_path('floor_building.yaml'))
    # The observer pairs fixes with ids by the fix's frame: the locator's map names it.
    observer = DriveObserver(context, setup.namespace, setup.record_odometry, setup.sim_time,
                             load_building(setup.building_map) if setup.building_map
                             else world.building)
    sim_time = [] if not setup.sim_time else ['-p', 'use_sim_time:=true']
    # A SIGTERM (a CI's timeout, kill) ends the drive like Ctrl-C: the node
    # processes are stopped on the way out instead of being left running.
    previous = _terminate_as_interrupt()
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(observer.node)
    link = Path(tempfile.mkdtemp(prefix='pattern_locator_drive_')) / 'evi_d31'
    pitch = f'{MOUNT_PITCH_DEG}'
    try:
        with node_process('sim_node', out / 'sim.log', [
                f'camera_link:={link}', 'world:=floor', f'route:={setup.route}',
                f'init_s:={float(setup.camera_init_s)}',
                f'max_speed_m_s:={float(setup.max_speed_m_s)}', f'seed:={setup.seed}',
                f'as_hung_seed:={setup.as_hung_seed}',
                f'interlace:={str(setup.interlace).lower()}',
                f'exposure_s:={float(setup.exposure_s)}',
                f'frame_rate_hz:={float(setup.frame_rate_hz)}',
                f'head_mount_pitch_deg:={pitch}',
                f'publish_clock:={str(setup.sim_time).lower()}',
                f'real_time_factor:={float(setup.real_time_factor)}'], setup.namespace,
                sim_time) as sim, \
                node_process('camera_driver_node', out / 'camera_driver.log', [
                    f'port:={link}', f'zoom_control:={str(setup.zoom_control).lower()}',
                    f'odometry_feed_forward:={str(setup.feed_forward).lower()}',
                    f'head_mount_pitch_deg:={pitch}',
                    # Cards are never far apart on the floor: look for the next one
                    # soon, briskly, at the tilt where cards are seen from the corridor.
                    'search_after_s:=1.0', 'search_speed_deg_s:=30.0',
                    'search_tilt_levels_deg:=[10.0, 0.0]',
                    f'shutter_s:={float(setup.shutter_s)}',
                    *setup.driver_parameters], setup.namespace, sim_time) as driver, \
                node_process('locator_node', out / 'locator.log', [
                    f'building_map:={locator_map}',
                    f'estimator:={setup.estimator}', f'head.mount_pitch_deg:={pitch}',
                    # Cards of a room are seen from the corridor through its door: the
                    # base is then outside the card's room but inside the building.
                    'gates.footprint:=building',
                    # Only fixes good to 2.5 cm (largest position sd): the far cards
                    # straight down a corridor give honest fixes of 5-10 cm sd that an
                    # EKF would weigh (the node's default keeps them, up to 1 m), but
                    # the drive is judged on the error of every fix published.
                    'gates.max_position_sigma_m:=0.025',
                    # The blur term of the covariance: the shutter the camera exposes with.
                    f'uncertainty.exposure_s:={float(setup.shutter_s or setup.exposure_s)}',
                    *setup.locator_parameters], setup.namespace, sim_time) as locator:
            deadline = time.monotonic() + timeout
            finished_at = None
            shown = -1
            while time.monotonic() < deadline:
                executor.spin_once(timeout_sec=0.05)
                for proc, name in ((sim, 'sim'), (driver, 'camera_driver'),
                                   (locator, 'locator')):
                    if proc.poll() is not None:
                        raise PatternLocatorError(f'{name} exited with {proc.returncode}; '
                                                  f'see {proc.log}')
                if progress:
                    shown = _show_progress(observer, duration, shown)
                route_time = float(observer.sim_status.get('route time s', '0') or 0.0)
                if observer.sim_message == 'finished' or (
                        setup.until_s > 0.0 and route_time >= setup.until_s):
                    finished_at = finished_at or time.monotonic()
                    if time.monotonic() - finished_at > 0.5 / setup.real_time_factor:
                        break
            else:
                print(f'drive: the route did not finish within {timeout:.0f} s',
                      file=sys.stderr)
            if progress:
                print(file=sys.stderr)
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
        executor.shutdown()
        observer.node.destroy_node()
        rclpy.shutdown(context=context)
        try:
            link.parent.rmdir()
        except OSError:
            pass
    return observer


def _terminate_as_interrupt():
    """Make SIGTERM raise KeyboardInterrupt (main thread only); return the old handler."""
    def interrupt(signum, frame):
        raise KeyboardInterrupt

    try:
        return signal.signal(signal.SIGTERM, interrupt)
    except ValueError:         # not the main thread
        return None


def _limits(world: FloorWorld, setup: DriveSetup):
    from dataclasses import replace
    return replace(world.limits, max_speed_m_s=float(setup.max_speed_m_s))


def _show_progress(observer: DriveObserver, duration: float, shown: int) -> int:
    """Print the route time and the fixes so far on one line (on a terminal, every 5 s)."""
    if not sys.stderr.isatty():
        return shown
    t = float(observer.sim_status.get('route time s', '0') or 0.0)
    step = int(t // 5)
    if step != shown:
        print(f'\r  route time {min(t, duration):5.0f} / {duration:.0f} s, '
              f'{len(observer.fixes)} fixes', end='', file=sys.stderr, flush=True)
    return step


# Judging ---------------------------------------------------------------------------------


@dataclass
class RoomRow:
    """One row of the per-room table."""

    name: str
    images: int = 0
    fixes: int = 0
    covered: int = 0
    samples: int = 0
    errors_m: List[float] = field(default_factory=list)
    wrong_ids: int = 0


@dataclass
class DriveMetrics:
    """What a drive gave (see the module docstring); errors in metres, angles in degrees."""

    duration_s: float
    images: int
    located: int
    wrong_ids: int
    other_room: int
    fix_coverage: float
    fix_coverage_by_stamp: float
    errors_m: np.ndarray
    driving: np.ndarray
    coverage_95: float
    handovers_s: np.ndarray
    off_axis_deg: np.ndarray
    off_axis_turning_deg: np.ndarray
    rooms: List[RoomRow]
    visca: Dict[str, float]
    latency_ms: np.ndarray
    unpaired: int
    track_time_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    fix_age_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    true_xy: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    fix_xy: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    wrong_xy: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    fix_time_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    # One dictionary per judged fix (route time, room, ids, error, sigma, motion, ...).
    records: List[Dict[str, Any]] = field(default_factory=list)
    # The locator's last diagnostics: frames received, dropped and rejected (by
    # reason), and its time per frame (queue, joint-state wait, processing).
    locator: Dict[str, str] = field(default_factory=dict)
    # The sim's rendering time per frame (part of the latency, not the robot's).
    sim_render: Dict[str, str] = field(default_factory=dict)

    def error_summary(self, mask: Optional[np.ndarray] = None) -> Dict[str, float]:
        """Return median, p95 and max of the errors (m), of the fixes in ``mask`` if given."""
        values = self.errors_m if mask is None else self.errors_m[mask]
        if values.size == 0:
            return {'median': math.nan, 'p95': math.nan, 'max': math.nan}
        return {'median': float(np.median(values)), 'p95': float(np.percentile(values, 95)),
                'max': float(values.max())}

    def summary(self) -> Dict[str, Any]:
        """Return what ``out/demo_summary.json`` holds, as a dictionary."""
        def clean(value):
            return None if isinstance(value, float) and not math.isfinite(value) else value

        def stats(values: np.ndarray) -> Dict[str, Optional[float]]:
            if values.size == 0:
                return {'median': None, 'p95': None, 'max': None}
            return {'median': float(np.median(values)),
                    'p95': float(np.percentile(values, 95)), 'max': float(values.max())}

        return {
            'wrong_ids': self.wrong_ids, 'fix_coverage': clean(self.fix_coverage),
            'error_m': {k: clean(v) for k, v in self.error_summary().items()},
            'coverage_95': clean(self.coverage_95), 'located': self.located,
            'images': self.images, 'route_s': self.duration_s,
            'fix_coverage_by_stamp': clean(self.fix_coverage_by_stamp),
            'other_room_fixes': self.other_room, 'unpaired_fixes': self.unpaired,
            'error_driving_m': {k: clean(v) for k, v in
                                self.error_summary(self.driving).items()},
            'error_stopped_m': {k: clean(v) for k, v in
                                self.error_summary(~self.driving).items()},
            'handover_s': stats(self.handovers_s), 'handovers': int(self.handovers_s.size),
            'off_axis_deg': stats(self.off_axis_deg),
            'off_axis_turning_deg': stats(self.off_axis_turning_deg),
            'latency_ms': stats(self.latency_ms), 'visca': self.visca,
            'locator': self.locator, 'sim_render': self.sim_render,
            'rooms': {r.name: {'images': r.images, 'fixes': r.fixes,
                               'fix_coverage': clean(r.covered / r.samples if r.samples
                                                     else math.nan),
                               'error_m': stats(np.array(r.errors_m)),
                               'wrong_ids': r.wrong_ids} for r in self.rooms},
        }


def _room_name(world: FloorWorld, xy: np.ndarray) -> str:
    room = world.room_at(xy)
    if room is None:
        return 'doorway'
    return f'{room.room} {room.name}'.strip() if room.name else str(room.room)


def _frame_pose(building: BuildingMap, frame_id: str) -> Optional[Pose]:
    """Return ``T_building_frame`` of a fix's frame (a room frame or the building's)."""
    if frame_id == building.frame:
        return Pose(np.eye(3), np.zeros(3))
    try:
        return building.room_by_frame(frame_id).T_building_room
    except Exception:  # noqa: B902 - an unknown frame: the fix cannot be judged
        return None


def judge(observer: DriveObserver, world: Optional[FloorWorld] = None,
          until_s: float = 0.0, locator_building: Optional[BuildingMap] = None
          ) -> DriveMetrics:
    """
    Return the metrics of a drive (see the module docstring); ``until_s``: its first part.

    ``world``: the truth (the sim's world, as hung if the sim hung it so).
    ``locator_building``: the map the locator was given, if not the world's;
    it places only the fixes' frames in the building, everything true (the
    sim's camera frames, the cards) comes from the world.
    """
    world = world if world is not None else load_floor_world()
    building = world.building
    fix_building = locator_building if locator_building is not None else building
    window = observer.route_window()
    if window is not None and until_s > 0.0:
        window = (window[0], min(window[1], window[0] + int(until_s * 1e9)))
    frames = observer.frames
    stamps = sorted(k for k, f in frames.items() if f.T_building_base is not None)
    if window is None:
        if not stamps:
            raise PatternLocatorError('drive: no truth from the sim (did it start?)')
        window = (stamps[0], stamps[-1])
    begin, end = window
    in_route = [k for k in stamps if begin <= k <= end]
    scene = FloorScene(world)
    rows: Dict[str, RoomRow] = {}

    def row(name: str) -> RoomRow:
        return rows.setdefault(name, RoomRow(name))

    true_room: Dict[int, str] = {}
    for k in in_route:
        name = _room_name(world, frames[k].T_building_base.t[:2])
        true_room[k] = name
        row(name).images += 1
    fixes = sorted((f for f in observer.fixes if begin <= f.stamp_ns <= end),
                   key=lambda f: f.stamp_ns)
    errors, driving, inside, wrong_xy, fix_xy, fix_times = [], [], [], [], [], []
    wrong = other_room = unpaired = 0
    latency, off_axis, turning, records = [], [], [], []
    judged: List[Fix] = []
    previous: Optional[Fix] = None
    track_start = 0
    for fix in fixes:
        truth = frames.get(fix.stamp_ns)
        T_building_frame = _frame_pose(fix_building, fix.frame_id)
        if truth is None or truth.T_building_base is None or T_building_frame is None:
            continue
        judged.append(fix)
        latency.append((fix.arrival_ns - fix.stamp_ns) * 1e-6)
        T_true = T_building_frame.inverse() @ truth.T_building_base
        e = fix.T_frame_base.t - T_true.t
        error = float(np.linalg.norm(e))
        errors.append(error)
        yaw_rate = truth.yaw_rate_rad_s or 0.0
        moving = abs(truth.speed_m_s or 0.0) > 1e-3 or abs(yaw_rate) > 1e-3
        driving.append(moving)
        covariance = observer.covariances.get(fix.stamp_ns)
        d2 = sigma = None
        if covariance is not None:
            sigma = covariance[:3, :3]
            try:
                d2 = float(e @ np.linalg.solve(sigma, e))
            except np.linalg.LinAlgError:
                d2 = math.inf
            inside.append(d2 <= CHI2_3_95)
        located_xy = (T_building_frame @ fix.T_frame_base).t[:2]
        fix_xy.append(located_xy)
        fix_times.append((fix.stamp_ns - begin) * 1e-9)
        name = true_room.get(fix.stamp_ns) or _room_name(world, truth.T_building_base.t[:2])
        r = row(name)
        r.fixes += 1
        r.errors_m.append(error)
        record = {'t_s': round(fix_times[-1], 3), 'room': name, 'ids': fix.ids,
                  'error_m': error, 'error_xyz_m': [float(v) for v in e],
                  'sigma_xyz_m': None if sigma is None else [
                      float(math.sqrt(max(v, 0.0))) for v in np.diag(sigma)],
                  'mahalanobis2': d2, 'speed_m_s': truth.speed_m_s,
                  'yaw_rate_rad_s': truth.yaw_rate_rad_s, 'latency_ms': latency[-1]}
        records.append(record)
        if fix.ids is None:
            unpaired += 1
            continue
        views = _views(scene, building, truth, observer, fix.stamp_ns)
        seen = views is None or any(v.ids.as_tuple() == tuple(fix.ids) for v in views)
        record['card_in_view'] = seen
        if not seen:
            # What the image held instead, for whoever looks into it.
            record['views'] = [(v.ids.as_tuple(), v.dots_visible, round(v.distance_m, 2))
                               for v in views]
            wrong += 1
            r.wrong_ids += 1
            wrong_xy.append(located_xy)
        here = world.room_at(truth.T_building_base.t[:2])
        if here is not None and (here.floor, here.room) != fix.ids[:2]:
            other_room += 1
        # The located card off the optical axis, in images where the head has been
        # on it for a while (fixes of it, none more than 0.5 s apart, for 1 s), could
        # centre it (the card within the head's travel) and was told to: the
        # locator's target of that image is this card. (The gaze may already aim at
        # the next card while this one still gives fixes at the edge of the view:
        # that is a handover, not the head failing to follow.)
        in_camera = _card_in_camera(world, building, truth, fix.ids)
        angle = None if in_camera is None else math.degrees(
            math.atan2(math.hypot(in_camera[0], in_camera[1]), in_camera[2]))
        target = observer.targets.get(fix.stamp_ns)
        targeted = bool(in_camera is not None and target is not None
                        and np.linalg.norm(target - in_camera) <= TARGET_MATCH_M)
        joints = _card_joint_angles(world, truth, fix.ids)
        reachable = joints is not None and abs(joints[0]) <= PAN_TRAVEL_DEG and \
            abs(joints[1]) <= TILT_TRAVEL_DEG
        if not (previous is not None and previous.ids == fix.ids
                and fix.stamp_ns - previous.stamp_ns <= int(FRESH_S * 1e9)):
            track_start = fix.stamp_ns
        track_age = (fix.stamp_ns - track_start) * 1e-9
        record.update(off_axis_deg=angle, card_joint_deg=joints, reachable=reachable,
                      track_age_s=round(track_age, 3), targeted=targeted)
        if track_age >= SETTLED_S and reachable and targeted and angle is not None:
            off_axis.append(angle)
            if abs(yaw_rate) >= TURNING_RAD_S:
                turning.append(angle)
        previous = fix
    # Coverage over the route's time, sampled.
    grid = np.arange(begin, end, int(COVERAGE_STEP_S * 1e9))
    fix_stamps = np.array([f.stamp_ns for f in fixes], dtype=np.int64)
    arrivals = np.array([f.arrival_ns for f in fixes], dtype=np.int64)
    covered, covered_stamp, ages = _coverage(grid, fix_stamps, arrivals)
    truth_keys = np.array(in_route, dtype=np.int64)
    for k, tau in enumerate(grid):
        if truth_keys.size == 0:
            break
        j = min(int(np.searchsorted(truth_keys, tau)), truth_keys.size - 1)
        r = row(true_room[int(truth_keys[j])])
        r.samples += 1
        r.covered += int(covered[k])
    handovers = _handovers(judged)
    true_xy = np.array([frames[k].T_building_base.t[:2] for k in in_route]).reshape(-1, 2)
    order = sorted(rows.values(), key=lambda r: (r.name == 'doorway', _room_key(r.name)))
    return DriveMetrics(
        duration_s=(end - begin) * 1e-9, images=len(in_route), located=len(fixes),
        wrong_ids=wrong, other_room=other_room,
        fix_coverage=float(covered.mean()) if grid.size else math.nan,
        fix_coverage_by_stamp=float(covered_stamp.mean()) if grid.size else math.nan,
        errors_m=np.array(errors), driving=np.array(driving, dtype=bool),
        coverage_95=float(np.mean(inside)) if inside else math.nan,
        handovers_s=np.array(handovers), off_axis_deg=np.array(off_axis),
        off_axis_turning_deg=np.array(turning), rooms=order,
        visca=_visca(observer.driver_diagnostics), latency_ms=np.array(latency),
        unpaired=unpaired + observer.mispaired, track_time_s=(grid - begin) * 1e-9, fix_age_s=ages,
        true_xy=true_xy, fix_xy=np.array(fix_xy).reshape(-1, 2),
        wrong_xy=np.array(wrong_xy).reshape(-1, 2), fix_time_s=np.array(fix_times),
        records=records, locator=_locator_counts(observer.locator_diagnostics),
        sim_render={k: v for k, v in (observer.sim_status or {}).items()
                    if k.startswith('render ms')})


# The locator's diagnostics that explain the coverage (the rest are its settings).
_LOCATOR_KEYS = ('received', 'processed', 'dropped', 'located', 'rejected')


def _locator_counts(values: Dict[str, str]) -> Dict[str, str]:
    """Return the locator's frame counts, rejections by reason and stage times."""
    return {k: v for k, v in values.items()
            if k in _LOCATOR_KEYS or k.startswith(('gate_rejected_', 'problems: '))
            or k.endswith(('_ms_median', '_ms_p95', '_ms_max'))}


def _room_key(name: str) -> Tuple[int, str]:
    head = name.split(' ', 1)[0]
    return (int(head), name) if head.isdigit() else (10 ** 6, name)


def _coverage(grid: np.ndarray, stamps: np.ndarray, arrivals: np.ndarray
              ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Return, at each grid time: a fix younger than 0.5 s had arrived; one was stamped; its age.

    The age is that of the youngest fix that had arrived (inf before the first).
    """
    fresh = int(FRESH_S * 1e9)
    covered = np.zeros(grid.size, dtype=bool)
    covered_stamp = np.zeros(grid.size, dtype=bool)
    ages = np.full(grid.size, np.inf)
    if stamps.size == 0:
        return covered, covered_stamp, ages
    order = np.argsort(stamps)
    sorted_stamps = stamps[order]
    for k, tau in enumerate(grid):
        j = int(np.searchsorted(sorted_stamps, tau, side='right'))
        covered_stamp[k] = j > 0 and tau - sorted_stamps[j - 1] <= fresh
        arrived = stamps[arrivals <= tau]
        if arrived.size:
            youngest = int(arrived.max())
            ages[k] = (tau - youngest) * 1e-9
            covered[k] = tau - youngest <= fresh
    return covered, covered_stamp, ages


def _views(scene: FloorScene, building: BuildingMap, truth: TruthFrame,
           observer: DriveObserver, stamp: int) -> Optional[list]:
    """Return the cards (some of their dots) in the image of ``stamp``; None: not known."""
    if truth.T_room_camera is None:
        return None      # not judged: the truth of the camera was lost
    T_building_frame = _frame_pose(building, truth.camera_frame_id)
    key = observer.camera_of.get(stamp)
    camera = observer.cameras.get(key) if key is not None else None
    if camera is None and observer.cameras:
        camera = next(iter(observer.cameras.values()))
    if T_building_frame is None or camera is None:
        return None
    return scene.views(T_building_frame @ truth.T_room_camera, camera)


def _handovers(fixes: Sequence[Fix]) -> List[float]:
    """Return the time (s) from the last fix of one card to the first of the next."""
    out = []
    last: Optional[Fix] = None
    for fix in fixes:
        if fix.ids is None:
            continue
        if last is not None and fix.ids != last.ids:
            out.append((fix.stamp_ns - last.stamp_ns) * 1e-9)
        last = fix
    return out


def _card_joint_angles(world: FloorWorld, truth: TruthFrame, ids: Tuple[int, int, int]
                       ) -> Optional[Tuple[float, float]]:
    """Return the head's (pan, tilt) in degrees that would centre the card (None: none)."""
    head = HeadGeometry(mount_pitch_rad=math.radians(MOUNT_PITCH_DEG))
    try:
        centre = world.card(ids).T_building_card.t
        pan, tilt = head.aim_angles(truth.T_building_base.inverse().apply(centre[None])[0])
    except Exception:  # noqa: B902 - not a card of this floor, or over the head
        return None
    return round(math.degrees(pan), 2), round(math.degrees(tilt), 2)


def _card_in_camera(world: FloorWorld, building: BuildingMap, truth: TruthFrame,
                    ids: Tuple[int, int, int]) -> Optional[np.ndarray]:
    """Return the card ``ids``'s true centre in the optical frame (m), None if unknown."""
    if truth.T_room_camera is None:
        return None
    T_building_frame = _frame_pose(building, truth.camera_frame_id)
    try:
        centre = world.card(ids).T_building_card.t
    except Exception:  # noqa: B902 - not a card of this floor: no angle
        return None
    if T_building_frame is None:
        return None
    return (T_building_frame @ truth.T_room_camera).inverse().apply(centre[None])[0]


def _visca(diagnostics: List[Tuple[float, Dict[str, str]]]) -> Dict[str, float]:
    """Return the VISCA traffic per second over the run from the driver's diagnostics."""
    rows = [(t, v) for t, v in diagnostics if 'commands sent' in v]
    if len(rows) < 2:
        return {}
    (t0, a), (t1, b) = rows[0], rows[-1]
    span = max(t1 - t0, 1e-9)
    out = {'seconds': round(span, 1)}
    for key in ('commands sent', 'replies', 'tracking commands', 'timeouts', 'error replies'):
        try:
            out[key.replace(' ', '_') + '_per_s'] = round((int(b[key]) - int(a[key])) / span, 2)
        except (KeyError, ValueError):
            continue
    return out


# Printing, plotting ----------------------------------------------------------------------


def _cm(value: float) -> str:
    return f'{value * 100:7.1f}' if math.isfinite(value) else f'{"-":>7}'


def room_table(metrics: DriveMetrics) -> str:
    """Return the per-room table as text."""
    lines = [f'{"room (true)":<26}{"images":>7}{"fixes":>7}{"fix cov.":>9}'
             f'{"err med":>8}{"p95":>8}{"max":>8}{"wrong":>6}   (errors in cm)']
    for r in metrics.rooms:
        e = np.array(r.errors_m)
        med, p95, top = ((float(np.median(e)), float(np.percentile(e, 95)), float(e.max()))
                         if e.size else (math.nan,) * 3)
        cov = f'{100 * r.covered / r.samples:8.0f}%' if r.samples else f'{"-":>9}'
        lines.append(f'{r.name[:25]:<26}{r.images:>7}{r.fixes:>7}{cov}{_cm(med)}{_cm(p95)}'
                     f'{_cm(top)}{r.wrong_ids:>6}')
    e = metrics.error_summary()
    lines.append(f'{"all":<26}{metrics.images:>7}{metrics.located:>7}'
                 f'{100 * metrics.fix_coverage:8.0f}%{_cm(e["median"])}{_cm(e["p95"])}'
                 f'{_cm(e["max"])}{metrics.wrong_ids:>6}')
    return '\n'.join(lines)


def plot_drive(world: FloorWorld, metrics: DriveMetrics, path: Path, title: str) -> Path:
    """Write the floor plan with the true and located tracks, and the fixes over time."""
    from matplotlib.figure import Figure
    from ..sim.plan_plot import plot_floor_plan

    fig = Figure(figsize=(11.0, 13.0), layout='constrained')
    grid = fig.add_gridspec(2, 1, height_ratios=[3.2, 1.0])
    ax = fig.add_subplot(grid[0])
    plot_floor_plan(world, ax=ax, tracks={'true path': metrics.true_xy}, title=title)
    # The fixes in colours of their own (the plan draws the cards red).
    ax.plot(metrics.fix_xy[:, 0], metrics.fix_xy[:, 1], linestyle='none', marker='.',
            markersize=3, color='tab:green', label='located (fixes)', zorder=7)
    if len(metrics.wrong_xy):
        ax.plot(metrics.wrong_xy[:, 0], metrics.wrong_xy[:, 1], linestyle='none', marker='x',
                markersize=7, color='black', label='WRONG card', zorder=8)
    ax.legend(loc='upper right', fontsize=7)
    ax_t = fig.add_subplot(grid[1])
    age = np.minimum(metrics.fix_age_s, 3.0)
    t = metrics.track_time_s
    ax_t.plot(t, age, color='tab:blue', linewidth=0.8, label='age of the newest fix (s)')
    ax_t.axhline(FRESH_S, color='tab:blue', linestyle=':', linewidth=0.8)
    ax_t.fill_between(t, 0.0, 3.0, where=metrics.fix_age_s > FRESH_S, color='tab:red',
                      alpha=0.15, linewidth=0, label=f'no fix younger than {FRESH_S} s')
    ax_t.set_ylim(0.0, 3.0)
    ax_t.set_xlabel('route time (s)')
    ax_t.set_ylabel('fix age (s, clipped at 3)')
    ax_e = ax_t.twinx()
    if metrics.fix_time_s.size:
        ax_e.plot(metrics.fix_time_s, metrics.errors_m * 100.0, '.', markersize=2,
                  color='tab:green', label='fix error (cm)')
    ax_e.set_ylabel('error (cm)')
    ax_e.set_ylim(0.0, max(5.0, float(np.percentile(metrics.errors_m * 100.0, 99)) * 1.2)
                  if metrics.errors_m.size else 5.0)
    handles = ax_t.get_legend_handles_labels()[0] + ax_e.get_legend_handles_labels()[0]
    ax_t.legend(handles=handles, loc='upper right', fontsize=7)
    ax_t.set_title(f"fix coverage {100 * metrics.fix_coverage:.1f} % of the route's "
                   f'{metrics.duration_s:.0f} s', fontsize=9)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    return path


def write_summary(metrics: DriveMetrics, path: Path, extra: Optional[Dict[str, Any]] = None
                  ) -> Path:
    """Write the JSON summary, and every fix's record beside it (``*_fixes.jsonl``)."""
    data = metrics.summary()
    data.update(extra or {})
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=2) + '\n')
    fixes = path.with_name(path.stem.replace('_summary', '') + '_fixes.jsonl')
    fixes.write_text(''.join(json.dumps(r, default=float) + '\n' for r in metrics.records))
    return path
