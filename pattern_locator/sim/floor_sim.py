"""
The simulated robot on a floor, tick by tick: what the sim node calls.

ROS-free. A :class:`FloorSim` holds a world (``floor_world``), a route
(``drive.DriveRoute`` through the floor, or the paper's one-room route),
the renderer (``floor_scene``) and the odometry (``odometry``). The node
calls, with route time ``t`` (seconds since the route started):

* :meth:`FloorSim.frame` ``(t, head_at, camera, seed)`` at its frame rate:
  the image whose exposure is centred on ``t`` (the image's stamp) and its
  :class:`FrameTruth`. ``head_at(time) -> (pan, tilt)`` gives the head's
  joint angles (rad, REP 103) at any time near ``t`` (the exposure reaches
  half an exposure, or half a field period plus half an exposure, either
  side); :class:`HeadTrack` builds one from the emulated camera's states.
  A live node stamps its frame ``sim.exposure.latest_stamp(now)``, so the
  whole exposure lies in the past;
* :meth:`FloorSim.odometry` ``(t)``: every odometry sample due up to ``t``
  (publish them as nav_msgs/Odometry, frame ``odom``, child ``base_link``);
* :meth:`FloorSim.state` ``(t)``: the base's true pose and twist.

Poses are in the building frame. The odom frame is the base's pose at
route time 0 (``FloorSim.T_building_odom``).
"""

from collections import deque
from dataclasses import dataclass, replace
import math
from pathlib import Path
from typing import Callable, Deque, List, Optional, Tuple, Union

import numpy as np

from .drive import DriveRoute, DriveState, wrap_angle
from .floor_file import load_floor_world
from .floor_scene import CardView, Field, FloorScene
from .floor_world import FloorWorld
from .odometry import OdometryModel, OdometrySim, OdomSample
from .render import RenderOptions
from .world import PAPER_FLOOR, PAPER_ROOM, SIM_RENDER_OPTIONS, SimRoute
from ..card.pattern import Ids
from ..errors import ConfigError
from ..localization.building import BuildingMap, load_building
from ..localization.head import HeadGeometry
from ..vision.camera import CameraModel
from ..vision.geometry import Pose

HeadAt = Callable[[float], Tuple[float, float]]


@dataclass(frozen=True)
class Exposure:
    """
    How a frame is exposed.

    ``exposure_s``: the shutter time of a frame (progressive) or of each
    field (interlaced). ``interlace``: the frame is two fields
    ``field_period_s`` apart, the even rows first (an analogue EVI-D31 on
    a frame grabber: PAL, 50 fields/s). ``blur``: smear cards along their
    motion during the exposure.

    The camera's automatic exposure (:meth:`image_options`): the scene's
    light is what gives the render options' brightness at ``reference_s``
    (the EVI-D31's own shutter in full auto, 1/50 s) and unity gain. A
    shorter shutter collects less light; the camera makes it up with gain,
    up to ``max_gain``, and the gain amplifies the sensor's noise with the
    signal; below what the gain can make up, the image darkens.
    """

    exposure_s: float = 0.02
    interlace: bool = False
    field_period_s: float = 0.02
    blur: bool = True
    reference_s: float = 0.02
    # +18 dB, the top of the EVI-D30/D31's gain range (?): Sony lists the
    # range for its successors (EVI-D100: -3..+18 dB); not measured.
    max_gain: float = 7.94

    def __post_init__(self) -> None:
        for name in ('exposure_s', 'field_period_s', 'reference_s', 'max_gain'):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not (
                    math.isfinite(value) and value >= 0.0):
                raise ConfigError(f'sim exposure: {name} must be a number >= 0, got {value!r}')
        if self.reference_s <= 0.0 or self.max_gain < 1.0:
            raise ConfigError(f'sim exposure: reference_s must be > 0 and max_gain >= 1, got '
                              f'{self.reference_s!r} and {self.max_gain!r}')

    def sensor_gain(self) -> float:
        """Return the gain the automatic exposure applies (1 at ``reference_s`` or longer)."""
        if self.exposure_s <= 0.0:
            return 1.0
        return min(max(self.reference_s / self.exposure_s, 1.0), self.max_gain)

    def image_options(self, options: RenderOptions) -> RenderOptions:
        """
        Return ``options`` (the look at ``reference_s``) as this shutter makes it.

        The gain multiplies the noise as well as the signal: the sim's noise
        is the camera's read and amplifier noise, which the gain amplifies
        whole (no shot noise is drawn, so this is the noise's worst case).
        Longer shutters than the reference keep the reference's look (the
        iris closes). An exposure of 0 (an idealised instant) keeps it too.
        """
        if self.exposure_s <= 0.0 or self.exposure_s >= self.reference_s:
            return options
        gain = self.sensor_gain()
        light = min(1.0, self.exposure_s * gain / self.reference_s)
        return replace(options, gain=options.gain * light, noise_sigma=options.noise_sigma * gain)

    def latest_stamp(self, now: float) -> float:
        """Return the latest stamp whose exposure has ended by ``now`` (a live node's frame)."""
        return now - (self.field_period_s / 2.0 if self.interlace else 0.0) - \
            self.exposure_s / 2.0

    def windows(self, t: float) -> List[Tuple[float, float]]:
        """Return the (start, end) of each field's exposure for a frame stamped ``t``."""
        half = self.exposure_s / 2.0
        if not self.interlace:
            return [(t - half, t + half)]
        shift = self.field_period_s / 2.0
        return [(t - shift - half, t - shift + half), (t + shift - half, t + shift + half)]


@dataclass(frozen=True)
class FrameTruth:
    """
    The truth of one frame, at its stamp (the middle of its exposure).

    ``T_building_base`` and ``T_building_camera`` (optical frame);
    ``pan``/``tilt``: the head's joint angles (rad, REP 103); the base's
    ``speed_m_s`` and ``yaw_rate_rad_s``; ``room``: (floor, room) of the map
    room holding the base (None in a doorway); ``views``: the cards in the
    image and how much of each is seen; ``target``: the view nearest the
    optical axis with every dot seen, or, when none is (``target_in_view``
    False), the card the head could turn to (``FloorScene.oracle_gaze``),
    or None; ``target_angles``: the head motion (pan, tilt) that centres it;
    ``blur_px``: each drawn card's motion blur in pixels; ``exposures``: each
    field's (start, end).
    """

    stamp_s: float
    T_building_base: Pose
    T_building_camera: Pose
    pan: float
    tilt: float
    speed_m_s: float
    yaw_rate_rad_s: float
    phase: str
    room: Optional[Tuple[int, int]]
    views: Tuple[CardView, ...]
    target: Optional[Ids]
    target_in_view: bool
    target_angles: Optional[Tuple[float, float]]
    blur_px: Tuple[Tuple[Tuple[int, int, int], float], ...]
    exposures: Tuple[Tuple[float, float], ...]


@dataclass(frozen=True)
class SimFrame:
    """A rendered frame (BGR uint8) and its truth."""

    image: np.ndarray
    truth: FrameTruth


class RoomRoute:
    """
    A one-room ``world.SimRoute`` (room frame) seen in the building frame.

    Its speed and yaw rate are finite differences over 10 ms. In ``stops``
    mode the robot jumps between stops: :attr:`teleports` tells the
    renderer not to blur across a jump.
    """

    def __init__(self, route: SimRoute, T_building_room: Pose) -> None:
        self.route = route
        self.T_building_room = T_building_room
        self.teleports = route.mode == 'stops'

    @property
    def duration_s(self) -> float:
        """Return the route's duration."""
        return self.route.duration_s

    def pose_at(self, t: float) -> Pose:
        """Return ``T_building_base`` at route time ``t``."""
        return self.T_building_room @ self.route.pose_at(t)

    def state_at(self, t: float) -> DriveState:
        """Return the base's pose and (finite-difference) twist at ``t``."""
        pose = self.pose_at(t)
        heading = math.atan2(pose.R[1, 0], pose.R[0, 0])
        stop = self.route.stop_at(t)
        if stop is not None or self.teleports:
            return DriveState(t, pose, heading, 0.0, 0.0, 0.0, 'stop', stop)
        dt = 0.005
        a, b = self.pose_at(t - dt), self.pose_at(t + dt)
        delta = a.inverse() @ b
        speed = float(delta.t[0]) / (2 * dt)
        rate = math.atan2(delta.R[1, 0], delta.R[0, 0]) / (2 * dt)
        return DriveState(t, pose, heading, speed, rate, 0.0, 'drive', None)


class HeadTrack:
    """
    The head's joint angles over time from timestamped samples, as ``head_at`` needs.

    Linear interpolation between samples, linear extrapolation (from the
    last two) up to ``max_extrapolation_s`` beyond them, then held. Pan is
    unwrapped between samples.
    """

    def __init__(self, max_samples: int = 64, max_extrapolation_s: float = 0.1) -> None:
        self._samples: Deque[Tuple[float, float, float]] = deque(maxlen=max_samples)
        self.max_extrapolation_s = float(max_extrapolation_s)

    def add(self, t: float, pan: float, tilt: float) -> None:
        """Record the angles (rad) at time ``t`` (samples in time order)."""
        if self._samples and t <= self._samples[-1][0]:
            if t == self._samples[-1][0]:
                self._samples[-1] = (t, pan, tilt)
            return
        self._samples.append((float(t), float(pan), float(tilt)))

    def __call__(self, t: float) -> Tuple[float, float]:
        """Return (pan, tilt) at time ``t``."""
        if not self._samples:
            raise ConfigError('sim: the head track has no samples')
        s = list(self._samples)
        if len(s) == 1:
            return s[0][1], s[0][2]
        times = [x[0] for x in s]
        k = int(np.searchsorted(times, t))
        if k == 0:
            a, b = s[0], s[1]
            t = max(t, a[0] - self.max_extrapolation_s)
        elif k >= len(s):
            a, b = s[-2], s[-1]
            t = min(t, b[0] + self.max_extrapolation_s)
        else:
            a, b = s[k - 1], s[k]
        f = (t - a[0]) / (b[0] - a[0])
        pan = a[1] + f * wrap_angle(b[1] - a[1])
        return wrap_angle(pan), a[2] + f * (b[2] - a[2])


class FloorSim:
    """
    A robot driving a route through a world, its camera's frames and its odometry.

    ``route``: a :class:`~.drive.DriveRoute` or a :class:`RoomRoute`.
    ``seed``: the odometry's noise (frames take their own seed per call).
    """

    def __init__(self, world: FloorWorld, route: Union[DriveRoute, RoomRoute],
                 head: Optional[HeadGeometry] = None,
                 options: RenderOptions = SIM_RENDER_OPTIONS,
                 exposure: Exposure = Exposure(), odometry: OdometryModel = OdometryModel(),
                 seed: int = 7) -> None:
        self.world = world
        self.route = route
        self.scene = FloorScene(world, head, options)
        self.exposure = exposure
        self._odometry = OdometrySim(route, odometry, seed)
        self.odometry_model = odometry

    @staticmethod
    def floor(route: str = 'tour', world_path: Optional[Union[str, Path]] = None,
              as_hung_seed: Optional[int] = None, max_speed_m_s: Optional[float] = None,
              **kwargs) -> 'FloorSim':
        """
        Return the sim of a route of the shipped world file, or of ``world_path``.

        ``max_speed_m_s`` caps every leg's cruise speed; ``kwargs`` go to
        the constructor (head, options, exposure, odometry, seed).
        """
        world = load_floor_world(world_path, as_hung_seed=as_hung_seed)
        limits = world.limits
        if max_speed_m_s is not None:
            limits = replace(limits, max_speed_m_s=float(max_speed_m_s))
        return FloorSim(world, world.route(route, limits), **kwargs)

    @staticmethod
    def paper(mode: str = 'drive', dwell_s: float = 3.0, speed_m_s: float = 0.3,
              seed: int = 7, n_stops: int = 30, building: Optional[BuildingMap] = None,
              **kwargs) -> 'FloorSim':
        """
        Return the sim of the paper's room (floor 1 room 3 of ``building.yaml``) and route.

        ``SimRoute.paper_route`` (the same stops and headings as
        ``world.SimScene``'s) in :meth:`one_room`. ``kwargs`` go to the
        constructor.
        """
        building = building if building is not None else load_building()
        route = SimRoute.paper_route(mode=mode, dwell_s=dwell_s, speed_m_s=speed_m_s,
                                     seed=seed, n_stops=n_stops, building=building)
        kwargs.setdefault('seed', seed)
        return FloorSim.one_room(route, PAPER_FLOOR, PAPER_ROOM, building, **kwargs)

    @staticmethod
    def one_room(route: SimRoute, floor: int = PAPER_FLOOR, room: int = PAPER_ROOM,
                 building: Optional[BuildingMap] = None, **kwargs) -> 'FloorSim':
        """
        Return the sim of a one-room ``SimRoute`` (room frame, e.g. the node's ``route_stops``).

        The world is the room's four walls and its cards
        (``FloorWorld.from_room``); poses are in the building frame.
        """
        building = building if building is not None else load_building()
        world = FloorWorld.from_room(building, floor, room)
        return FloorSim(world, RoomRoute(route, building.room(floor, room).T_building_room),
                        **kwargs)

    @property
    def duration_s(self) -> float:
        """Return the route's duration."""
        return self.route.duration_s

    @property
    def T_building_odom(self) -> Pose:
        """Return the odom frame in the building frame (the base's pose at time 0)."""
        return self._odometry.T_building_odom

    def state(self, t: float) -> DriveState:
        """Return the base's true pose (building frame) and twist at route time ``t``."""
        return self.route.state_at(t)

    def odometry(self, t: float) -> List[OdomSample]:
        """Return every odometry sample due since the last call, up to route time ``t``."""
        return self._odometry.advance_to(t)

    def camera_pose(self, t: float, head_at: HeadAt) -> Pose:
        """Return ``T_building_camera`` at route time ``t``."""
        pan, tilt = head_at(t)
        return self.scene.true_camera_pose(self._base_pose(t, t), pan, tilt)

    def _base_pose(self, t: float, stamp: float) -> Pose:
        # A route that jumps (the paper's stops) is rendered at the stamp's pose.
        return self.route.pose_at(stamp if getattr(self.route, 'teleports', False) else t)

    def frame(self, t: float, head_at: HeadAt, camera: CameraModel, seed: int = 0) -> SimFrame:
        """Return the frame stamped ``t`` (the middle of its exposure) and its truth."""
        image, blurs = self.render(t, head_at, camera, seed)
        return SimFrame(image, self.truth(t, head_at, camera, blurs))

    def render(self, t: float, head_at: HeadAt, camera: CameraModel, seed: int = 0
               ) -> Tuple[np.ndarray, dict]:
        """
        Return the image stamped ``t`` and its cards' blurs (for :meth:`truth`).

        Apart from the truth so that a node can send the image first: the
        truth's views cost milliseconds that would add to every image's latency.
        """
        fields = []
        for start, end in self.exposure.windows(t):
            middle = (start + end) / 2.0
            fields.append(Field(*(self.scene.true_camera_pose(self._base_pose(x, t), *head_at(x))
                                  for x in (start, middle, end))))
        return self.scene.render(camera, fields, seed, self.exposure.blur,
                                 self.exposure.image_options(self.scene.options))

    def truth(self, t: float, head_at: HeadAt, camera: CameraModel,
              blurs: Optional[dict] = None) -> FrameTruth:
        """Return the truth of a frame stamped ``t`` (without rendering it)."""
        state = self.route.state_at(t)
        pan, tilt = head_at(t)
        T_camera = self.scene.true_camera_pose(state.pose, pan, tilt)
        views = tuple(self.scene.views(T_camera, camera))
        complete = [v for v in views if v.complete]
        target = min(complete, key=lambda v: v.off_axis_deg).ids if complete else None
        if target is None:
            gaze = self.scene.oracle_gaze(state.pose)
            target = None if gaze is None else Ids(*gaze[0])
        angles = (self.scene.card_angles(state.pose, pan, tilt, target.as_tuple())
                  if target is not None else None)
        room = self.world.room_at(state.pose.t[:2])
        return FrameTruth(t, state.pose, T_camera, pan, tilt, state.speed_m_s,
                          state.yaw_rate_rad_s, state.phase,
                          None if room is None else (room.floor, room.room), views, target,
                          bool(complete), angles, tuple(sorted((blurs or {}).items())),
                          tuple(self.exposure.windows(t)))
