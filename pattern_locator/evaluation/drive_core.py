"""
The drive-core bench: the ROS-free cores of issue 12 on the simulated floor, frame by frame.

``pattern-locator bench --drive-core [OPTIONS]`` (``--drive-core --help``
lists them). It drives a route of ``config/sim_floor.yaml`` (``FloorSim``)
and plays the robot's parts the way the nodes will, without ROS:

* **the head**: an EVI-D31-like pan/tilt that turns at piecewise constant
  speeds in the camera's speed steps (commands take effect 10-30 ms after
  they are sent, speed changes are instant, as the emulated camera's);
* **the driver**: every 0.1 s it asks the position; the camera latches it
  at its next video field (0-20 ms later), the answer is stamped when it
  arrives less its wire time, late by a USB-serial adapter's latency timer
  (0-16 ms) and the OS (:class:`JointTiming`), and published at once
  (``--publish-delay-ms``: later, as the driver that published after its
  commands' ACKs, ~32 ms); the angles are quantised to the camera's units.
  Then it aims the head: the gaze planner's card from
  the last fix carried forward by odometry (``OdomBridge``), the
  feed-forward rates that cancel the base's motion plus the driver's
  correction (``tracking.controller.wanted_rate``: the gain, fast slews),
  quantised to speed steps; zoom so that the card is about a quarter
  of the image wide. Without a pose, or with no card predicted, it sweeps.
  With ``--driver target`` the driver is map-free, as the camera_driver
  node: it centres the locator's target (``TargetChooser``, what the
  locator node publishes on ``pattern_locator/target``: the gaze planner's
  card as seen or predicted, or with ``--no-gaze`` and without odometry
  the biggest card seen), adds the feed-forward of the base's twist, holds
  the head 0.5 s after the last target and sweeps after 3 s;
* **the locator**: each frame (``--rate`` per second, motion blur and
  optionally interlace rendered by the sim) goes to ``RobotLocalizer``
  with the head's angles interpolated to the image's stamp from the joint
  states that have arrived (``JointStateBuffer``): 50 ms after the
  exposure (the image's way to the locator) once a joint state stamped
  after the image has come, else when the locator's ``joint_state_wait_s``
  is up (``--joint-wait-ms``, the node's default 150; then the last one
  is held), the
  odometry since the last fix and the base's twist (``OdomBuffer``;
  ``--no-odometry``: none, the gates' speed limits instead, no bridge);
* **the truth**: the sim's base pose at each image's stamp and the head's
  true angles.

It prints ``coverage_95`` (the fraction of fixes whose true 3-D position
error lies inside their own 95 % ellipse), the error while driving and at
stops (median, p95, max), wrong rooms and ids, fix coverage (driving time
with a fix younger than 0.5 s), the odometry bridge's error and coverage,
and the measurements behind each covariance term: for every fix, the error
split into the image's part (the base from the estimated camera pose and
the *true* head angles) and the head's part, each normalised by its own
term, and the head-angle errors at the image stamps against the model.
Every figure says how many frames it rests on.
"""

import argparse
import bisect
from dataclasses import dataclass, field, replace
import functools
import json
import math
import sys
import time
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from ..errors import PatternLocatorError
from ..localization.gates import GateParameters
from ..localization.gaze import feed_forward_rates, GazePlanner
from ..localization.head import angle_jacobian, base_pose_from_camera, HeadGeometry, \
    HeadStateError, JointStateBuffer
from ..localization.localizer import RobotLocalizer
from ..localization.odom import BaseTwist, OdomBridge, OdomBuffer
from ..localization.target_choice import biggest_seen, seen_cards, TargetChooser
from ..localization.uncertainty import chi2_95, UncertaintyParameters
from ..sim.floor_sim import Exposure, FloorSim
from ..tracking.controller import (joint_aim_to_point, pan_aim_in_travel, TrackingParams,
                                   wanted_rate)
from ..visca.zoom_table import ZoomTable
from ..vision.geometry import Pose, rotation_vector

# The EVI-D31's speed steps (visca.md): pan 24 steps to 80 deg/s, tilt 20 to 50 deg/s.
PAN_STEP_RAD_S = math.radians(80.0 / 24.0)
TILT_STEP_RAD_S = math.radians(50.0 / 20.0)
PAN_STEPS, TILT_STEPS = 24, 20
PAN_UNITS_PER_RAD = 8.8 * 180.0 / math.pi
TILT_UNITS_PER_RAD = 12.0 * 180.0 / math.pi
ANSWER_WIRE_S = 11 * 10 / 9600.0
EXPOSURES = {'sharp': Exposure(0.02, blur=False), 'blur': Exposure(0.02),
             'interlaced': Exposure(0.02, interlace=True)}
CHI2_3 = chi2_95(3)
# The harness driver's search: pan speed, tilt and focal length (a card 5 m away
# is ~90 px wide, in a 24 deg field of view).
SEARCH_PAN_RAD_S = math.radians(80.0 / 24.0 * 4)
SEARCH_TILT_RAD = math.radians(14.0)
SEARCH_FX_PX = 1500.0
# The map-free driver (--driver target): the camera_driver's defaults.
TARGET_TIMEOUT_S = 0.5
SEARCH_AFTER_S = 3.0
DRIVERS = ('planner', 'target')


@dataclass(frozen=True)
class JointTiming:
    """
    How the joint states' stamps relate to when the head was where they say.

    The driver asks every ``period_s`` (+- ``period_jitter_s``); the camera
    latches the position at its next field (uniform within ``field_s``) and
    answers; the answer's stamp (its arrival less the wire time) is late by
    a uniform ``usb_latency_s`` (an FTDI adapter's latency timer) and an
    exponential ``os_jitter_s``. Commands take effect ``command_latency_s``
    (uniform within the range) after they are sent. ``publish_s``: from
    the answer's arrival to the joint state's publication (0: the driver
    publishes it before its commands).
    """

    period_s: float = 0.1
    period_jitter_s: float = 0.003
    field_s: float = 0.02
    usb_latency_s: float = 0.016
    os_jitter_s: float = 0.001
    command_latency_s: Tuple[float, float] = (0.01, 0.03)
    publish_s: float = 0.0

    def stamp_error_rms(self) -> float:
        """Return the RMS of (stamp - latch): the model's ``joint_stamp_sigma_s``."""
        u, e = self.usb_latency_s, self.os_jitter_s
        mean = u / 2.0 + e
        variance = u * u / 12.0 + e * e
        return math.sqrt(mean * mean + variance)


class SimHead:
    """A pan/tilt head turning at piecewise constant rates within its travel."""

    def __init__(self, head: HeadGeometry, pan: float = 0.0, tilt: float = 0.0) -> None:
        self.head = head
        self._t: List[float] = [-1e9]
        self._state: List[Tuple[float, float, float, float]] = [(pan, tilt, 0.0, 0.0)]

    def __call__(self, t: float) -> Tuple[float, float]:
        """Return the true (pan, tilt) at time ``t``."""
        i = bisect.bisect_right(self._t, t) - 1
        pan, tilt, rp, rt = self._state[max(i, 0)]
        dt = t - self._t[max(i, 0)]
        return self.head.clamp(pan + rp * dt, tilt + rt * dt)

    def rates_at(self, t: float) -> Tuple[float, float]:
        """Return the commanded rates in force at ``t``."""
        i = bisect.bisect_right(self._t, t) - 1
        return self._state[max(i, 0)][2:]

    def command(self, t: float, pan_rate: float, tilt_rate: float) -> None:
        """Change the rates from time ``t`` on (later than every earlier command)."""
        pan, tilt = self(t)
        if t <= self._t[-1]:
            t = self._t[-1] + 1e-6
        self._t.append(t)
        self._state.append((pan, tilt, pan_rate, tilt_rate))


def _quantise(rate: float, step: float, steps: int) -> float:
    n = min(int(round(abs(rate) / step)), steps)
    return math.copysign(n * step, rate)


@dataclass
class FrameRecord:
    """What one frame gave, against the truth (the bench's raw data)."""

    t: float
    phase: str
    speed: float
    yaw_rate: float
    room: Optional[Tuple[int, int]]
    cards_in_view: int
    head_error: Tuple[float, float]          # interpolated - true angles at the stamp (rad)
    head_sigma: Tuple[float, float]          # the model's (timing, interpolation, resolution)
    head_rates: Tuple[float, float]
    ids: Optional[Tuple[int, int, int]] = None
    wrong_id: bool = False
    wrong_room: bool = False
    error: Optional[np.ndarray] = None       # fix - truth, position (m, building frame)
    d2: Optional[float] = None               # Mahalanobis^2 of the position error
    d2_rotation: Optional[float] = None      # ... of the rotation error
    rot_err2: Optional[float] = None         # squared rotation error (rad^2)
    d2_image: Optional[float] = None         # the image part against the image (+map) term
    d2_head: Optional[float] = None          # the head part against the head terms
    image_error_m: Optional[float] = None
    head_error_m: Optional[float] = None
    sigmas: Dict[str, float] = field(default_factory=dict)
    blur_px: float = 0.0
    true_blur_px: float = 0.0
    pixel_sigma_px: float = 0.0
    residual_sigma_px: float = 0.0
    d2_image_unit: Optional[float] = None    # the image part against the image term at 1 px
    distance_m: float = 0.0
    view_deg: float = 0.0
    size_px: float = 0.0
    fx_px: float = 0.0
    # What the covariance is made of, to refit its parameters offline
    # (position_covariance): the image term at 1 px, the angle Jacobian, the
    # head's rates, rate changes, interval and hold, the map term.
    calib: Dict[str, object] = field(default_factory=dict)
    bridge_error_m: Optional[float] = None
    bridge_d2: Optional[float] = None
    bridge_age_s: Optional[float] = None
    # The locator's target (--driver target): the point, the head angles it is
    # relative to, its source and reason.
    target: Optional[Tuple[Tuple[float, float, float], float, float]] = None
    target_source: str = ''
    target_reason: str = ''
    problem: str = ''
    rejections: Tuple[str, ...] = ()         # gates that refused a fix in this frame


@dataclass(frozen=True)
class DriveCoreConfig:
    """One bench run: route, rates, exposure, covariance model, map, seed."""

    route: str = 'short'
    seconds: Optional[float] = None
    frame_rate_hz: float = 5.0
    max_speed_m_s: float = 0.5
    exposure: str = 'blur'
    shutter_s: Optional[float] = None     # the camera's shutter (else the exposure's 20 ms)
    covariance: str = 'model'            # 'model' | 'fisher' (the estimator's alone)
    as_hung: bool = False                 # cards off the map by a few cm, the map saying so
    seed: int = 1
    timing: JointTiming = JointTiming()
    uncertainty: Optional[UncertaintyParameters] = None
    driver: str = 'planner'               # 'planner' | 'target' (map-free, the locator's target)
    odometry: bool = True                 # the locator takes odometry (else speed limits)
    gaze: bool = True                     # the locator's target from the gaze planner
    # The locator's joint_state_wait_s: how long an image waits for a joint
    # state stamped after it before the last one is held.
    joint_wait_s: float = 0.15


def config_exposure(config: DriveCoreConfig) -> Exposure:
    """Return the run's exposure: its kind, with the camera's shutter if one is set."""
    exposure = EXPOSURES[config.exposure]
    if config.shutter_s is not None:
        exposure = replace(exposure, exposure_s=float(config.shutter_s))
    return exposure


def _uncertainty(config: DriveCoreConfig) -> Optional[UncertaintyParameters]:
    if config.covariance == 'fisher':
        return UncertaintyParameters.fisher_only()
    params = config.uncertainty or UncertaintyParameters()
    exposure = config_exposure(config)
    # What a node is configured with: its camera's exposure and its camera
    # link's stamp error (the default timing's is the parameters' default).
    params = replace(params, exposure_s=exposure.exposure_s,
                     field_period_s=exposure.field_period_s if exposure.interlace else 0.0)
    if replace(config.timing, publish_s=0.0) != JointTiming():
        params = replace(params, joint_stamp_sigma_s=config.timing.stamp_error_rms())
    if config.as_hung:
        # The sim's as-hung errors (FloorWorld.as_hung: a shift uniform in a disc
        # of 5 cm, a turn uniform up to 3 deg about a random axis) have these
        # standard deviations per axis: 5 / 2 cm, and sqrt(E[angle^2] / 3) =
        # sqrt(3 / 3) = 1 deg.
        params = replace(params, map_position_sigma_m=0.025, map_rotation_sigma_deg=1.0)
    return params


def run(config: DriveCoreConfig, progress: bool = False) -> List[FrameRecord]:
    """Drive the route once; return one record per frame."""
    sim = FloorSim.floor(config.route, max_speed_m_s=config.max_speed_m_s,
                         exposure=config_exposure(config), seed=config.seed,
                         as_hung_seed=config.seed if config.as_hung else None)
    world = sim.world
    building = world.building
    head = sim.scene.head
    pattern = world.pattern
    rng = np.random.default_rng(config.seed + 1000)
    timing = config.timing
    zoom_table = ZoomTable.load()
    # 'adjacent': a card seen through a door locates the base in the next room.
    localizer = RobotLocalizer(pattern, building, head, output_frame='building',
                               gates=GateParameters(footprint='adjacent'),
                               uncertainty=_uncertainty(config))
    joints = JointStateBuffer(head=head)
    odom = OdomBuffer()
    bridge = OdomBridge(odom, building)
    planner = GazePlanner(building, head)
    chooser = TargetChooser(building, head) if config.driver == 'target' else None
    target: Optional[FrameRecord] = None
    sim_head = SimHead(head, 0.0, math.radians(12.0))
    zoom = 0.0
    duration = sim.duration_s if config.seconds is None else min(sim.duration_s, config.seconds)
    dt = 0.005
    next_inquiry = 0.0
    next_frame = 1.0 / config.frame_rate_hz
    pending: List[Tuple[float, float, float, float]] = []     # (arrival, stamp, pan, tilt)
    current: Optional[Tuple[int, int, int]] = None
    search_dir = 1.0
    records: List[FrameRecord] = []
    T_building_odom = sim.T_building_odom
    frame_seed = config.seed * 100000
    steps = int(math.ceil(duration / dt))
    iterator = range(steps + 1)
    if progress:
        from tqdm import tqdm
        iterator = tqdm(iterator, disable=None, desc=f'{config.route} seed {config.seed}',
                        unit='step', mininterval=1.0)
    last_reading = (0.0, 0.0, math.radians(12.0))
    for k in iterator:
        t = k * dt
        for sample in sim.odometry(t):
            odom.add(sample.stamp_s, sample.T_odom_base, sample.pose_covariance,
                     BaseTwist((sample.linear_x, sample.linear_y, 0.0),
                               (0.0, 0.0, sample.angular_z)))
        while pending and pending[0][0] <= t:
            _, stamp, pan, tilt = pending.pop(0)
            joints.add(stamp, pan, tilt)
            last_reading = (stamp, pan, tilt)
        if t >= next_inquiry:
            # The camera latches at its next field and answers; the stamp is late.
            latch = t + 0.005 + rng.uniform(0.0, timing.field_s)
            pan, tilt = sim_head(latch)
            pan = round(pan * PAN_UNITS_PER_RAD) / PAN_UNITS_PER_RAD
            tilt = round(tilt * TILT_UNITS_PER_RAD) / TILT_UNITS_PER_RAD
            stamp = latch + rng.uniform(0.0, timing.usb_latency_s) + rng.exponential(
                timing.os_jitter_s)
            pending.append((stamp + ANSWER_WIRE_S + timing.publish_s, stamp, pan, tilt))
            pending.sort()
            next_inquiry += timing.period_s + rng.uniform(-1.0, 1.0) * timing.period_jitter_s
            # The driver's cycle: decide on the reading that has just come back.
            if chooser is not None:
                zoom, search_dir = _control_target(
                    t + 0.03, sim_head, last_reading, target, odom if config.odometry else None,
                    head, zoom, search_dir, zoom_table, pattern.card_size, timing, rng)
            else:
                current, zoom, search_dir = _control(
                    t + 0.03, sim_head, last_reading, bridge, odom, planner, head, building,
                    current, zoom, search_dir, zoom_table, pattern.card_size, timing, rng)
        if _frame_due(t, next_frame, sim.exposure.exposure_s, joints, config.joint_wait_s):
            stamp = next_frame
            next_frame += 1.0 / config.frame_rate_hz
            camera = zoom_table.camera_at(zoom)
            frame = sim.frame(stamp, sim_head, camera, seed=frame_seed + len(records))
            records.append(_locate(frame, camera, stamp, localizer, joints, odom, bridge,
                                   building, head, sim_head, world, T_building_odom, config,
                                   chooser))
            if records[-1].target is not None:
                target = records[-1]
    return records


def _frame_due(t: float, stamp: float, exposure_s: float, joints: JointStateBuffer,
               wait_s: float) -> bool:
    """
    Tell whether the locator takes the frame stamped ``stamp`` at ``t``.

    As the node: 50 ms after the exposure (the image's way to the locator)
    once a joint state stamped at or after the image has come, else when
    its wait (``joint_state_wait_s``) is up, holding the last one.
    """
    arrived = stamp + exposure_s + 0.05
    if t + 1e-9 < arrived:
        return False
    latest = joints.latest()
    return (latest is not None and latest[0] >= stamp) or (
        t + 1e-9 >= stamp + exposure_s + max(wait_s, 0.05))


@functools.lru_cache(maxsize=4)
def _driver_law(period_s: float) -> TrackingParams:
    """Return the camera driver's default tracking settings at this control period."""
    return TrackingParams(control_period_s=period_s)


def _control(t: float, sim_head: SimHead, reading, bridge: OdomBridge, odom: OdomBuffer,
             planner: GazePlanner, head: HeadGeometry, building, current, zoom: float,
             search_dir: float, zoom_table: ZoomTable, card_size: float, timing: JointTiming,
             rng) -> Tuple[Optional[Tuple[int, int, int]], float, float]:
    """One driver cycle: choose a card, command the head's rates and the zoom."""
    stamp, pan_read, tilt_read = reading
    rp, rt = sim_head.rates_at(t)
    # The driver's estimate of the head now: the reading moved on at the commanded rates.
    pan_now, tilt_now = pan_read + rp * (t - stamp), tilt_read + rt * (t - stamp)
    bridged = bridge.at(t - 0.02)
    twist = odom.twist_at(t - 0.02)
    choice = None
    if bridged is not None:
        choice = planner.choose(bridged.T_frame_base, current, twist, head_pan=pan_now)
    latency = rng.uniform(*timing.command_latency_s)
    if choice is None:
        # Search: sweep the pan slowly enough for sharp cards, look up, a medium zoom.
        if pan_now > math.radians(90.0):
            search_dir = -1.0
        elif pan_now < math.radians(-90.0):
            search_dir = 1.0
        tilt_rate = 2.0 * (SEARCH_TILT_RAD - tilt_now)
        sim_head.command(t + latency, search_dir * SEARCH_PAN_RAD_S,
                         _quantise(tilt_rate, TILT_STEP_RAD_S, TILT_STEPS))
        return None, float(zoom_table.zoom_for_focal(SEARCH_FX_PX)), search_dir
    card = building.card(choice.ids)
    target = bridged.T_frame_base.inverse().apply(card.T_building_card.t[None])[0]
    ff_pan, ff_tilt = (0.0, 0.0)
    if twist is not None:
        try:
            ff_pan, ff_tilt = feed_forward_rates(head, target, twist)
        except ValueError:
            pass
    # The driver's law (gain, slews); both within the travel (less than a
    # turn): the plain difference is the way the head can go; a wrapped one
    # could point through the stop.
    law = _driver_law(timing.period_s)
    pan_rate = wanted_rate(choice.pan - pan_now, ff_pan, law)
    tilt_rate = wanted_rate(choice.tilt - tilt_now, ff_tilt, law)
    sim_head.command(t + latency, _quantise(pan_rate, PAN_STEP_RAD_S, PAN_STEPS),
                     _quantise(tilt_rate, TILT_STEP_RAD_S, TILT_STEPS))
    # Zoom: the card a quarter of the image wide, changed only when off by a quarter.
    wanted = zoom_table.zoom_for_focal(0.25 * zoom_table.width * choice.option.distance_m
                                       / card_size)
    fx_now = zoom_table.camera_at(zoom).fx
    fx_wanted = zoom_table.camera_at(wanted).fx
    off_axis = math.hypot(choice.pan - pan_now, choice.tilt - tilt_now)
    if off_axis > math.radians(5.0):
        wanted, fx_wanted = 0.0, zoom_table.camera_at(0.0).fx      # find it wide first
    if abs(math.log(fx_wanted / fx_now)) > math.log(1.25):
        zoom = float(wanted)
    return choice.ids.as_tuple(), zoom, search_dir


def _control_target(t: float, sim_head: SimHead, reading, target: Optional[FrameRecord],
                    odom: Optional[OdomBuffer], head: HeadGeometry, zoom: float,
                    search_dir: float, zoom_table: ZoomTable, card_size: float,
                    timing: JointTiming, rng) -> Tuple[float, float]:
    """
    One cycle of a map-free driver: centre the locator's latest target, else hold, else sweep.

    The target's aim is the head's angles that centre the target's point
    from the head at the image's stamp (as the driver's), carried
    to now by the feed-forward rates of the base's twist (odometry), plus
    the driver's correction.
    """
    stamp, pan_read, tilt_read = reading
    rp, rt = sim_head.rates_at(t)
    pan_now, tilt_now = pan_read + rp * (t - stamp), tilt_read + rt * (t - stamp)
    latency = rng.uniform(*timing.command_latency_s)
    age = math.inf if target is None else t - target.t
    if age > SEARCH_AFTER_S:
        if pan_now > math.radians(90.0):
            search_dir = -1.0
        elif pan_now < math.radians(-90.0):
            search_dir = 1.0
        tilt_rate = 2.0 * (SEARCH_TILT_RAD - tilt_now)
        sim_head.command(t + latency, search_dir * SEARCH_PAN_RAD_S,
                         _quantise(tilt_rate, TILT_STEP_RAD_S, TILT_STEPS))
        return float(zoom_table.zoom_for_focal(SEARCH_FX_PX)), search_dir
    if age > TARGET_TIMEOUT_S:
        sim_head.command(t + latency, 0.0, 0.0)
        return zoom, search_dir
    point, pan_s, tilt_s = target.target
    x, y, z = point
    # As the driver does (TrackingController.on_target_point, which ignores
    # a point straight above or below the head).
    try:
        aim_pan, aim_tilt = joint_aim_to_point(pan_s, tilt_s, head.mount_pitch_rad, point)
    except ValueError:
        return zoom, search_dir
    aim_pan = pan_aim_in_travel(pan_s + math.remainder(aim_pan - pan_s, 2.0 * math.pi),
                                head.pan_limits_rad)
    ff_pan = ff_tilt = 0.0
    twist = odom.twist_at(t - 0.02) if odom is not None else None
    if twist is not None:
        try:
            in_base = head.T_base_camera(pan_s, tilt_s).apply(np.array([point]))[0]
            ff_pan, ff_tilt = feed_forward_rates(head, in_base, twist)
        except ValueError:
            pass
    aim_pan, aim_tilt = head.clamp(aim_pan + ff_pan * age, aim_tilt + ff_tilt * age)
    law = _driver_law(timing.period_s)      # the driver's gain and slews
    pan_rate = wanted_rate(aim_pan - pan_now, ff_pan, law)
    tilt_rate = wanted_rate(aim_tilt - tilt_now, ff_tilt, law)
    sim_head.command(t + latency, _quantise(pan_rate, PAN_STEP_RAD_S, PAN_STEPS),
                     _quantise(tilt_rate, TILT_STEP_RAD_S, TILT_STEPS))
    distance = math.sqrt(x * x + y * y + z * z)
    wanted = zoom_table.zoom_for_focal(0.25 * zoom_table.width * distance / card_size)
    fx_now = zoom_table.camera_at(zoom).fx
    fx_wanted = zoom_table.camera_at(wanted).fx
    if math.hypot(aim_pan - pan_now, aim_tilt - tilt_now) > math.radians(5.0):
        wanted, fx_wanted = 0.0, zoom_table.camera_at(0.0).fx      # find it wide first
    if abs(math.log(fx_wanted / fx_now)) > math.log(1.25):
        zoom = float(wanted)
    return zoom, search_dir


def _locate(frame, camera, stamp: float, localizer: RobotLocalizer, joints: JointStateBuffer,
            odom: OdomBuffer, bridge: OdomBridge, building, head: HeadGeometry,
            sim_head: SimHead, world, T_building_odom: Pose, config: DriveCoreConfig,
            chooser: Optional[TargetChooser] = None) -> FrameRecord:
    """Process one frame as the locator would (its target too, given a chooser)."""
    truth = frame.truth
    true_pan, true_tilt = truth.pan, truth.tilt
    record = FrameRecord(stamp, truth.phase, truth.speed_m_s, truth.yaw_rate_rad_s, truth.room,
                         len(truth.views), (math.nan, math.nan), (math.nan, math.nan),
                         sim_head.rates_at(stamp))
    # What the bridge said before this frame.
    bridged = bridge.at(stamp)
    if bridged is not None:
        err = bridged.T_frame_base.t - truth.T_building_base.t
        record.bridge_error_m = float(np.linalg.norm(err))
        record.bridge_d2 = _d2(err, bridged.covariance[:3, :3])
        record.bridge_age_s = bridged.age_s
    try:
        motion = joints.motion_at(stamp)
    except HeadStateError as exc:
        record.problem = str(exc)
        return record
    record.head_error = (motion.pan - true_pan, motion.tilt - true_tilt)
    params = localizer.uncertainty or UncertaintyParameters.fisher_only()
    record.head_sigma = _head_sigma(motion, params)
    record.calib = {'rates': (motion.pan_rate, motion.tilt_rate),
                    'rate_change': tuple(motion.rate_change), 'interval': motion.interval_s,
                    'hold': motion.hold_s}
    odometry = twist = None
    if config.odometry:
        if localizer.last_fix_stamp is not None:
            odometry = odom.motion_between(localizer.last_fix_stamp, stamp)
        twist = odom.twist_at(stamp)
    result = localizer.process(frame.image, camera, motion.pan, motion.tilt, stamp, odometry,
                               motion, twist)
    fix = result.fix
    record.rejections = result.rejections
    blurs = dict(truth.blur_px)
    if fix is not None and config.odometry:
        bridge.update(fix, stamp)
    if chooser is not None:
        seen, _ = seen_cards(result, camera, building)
        if config.gaze:
            bridged = bridge.at(stamp) if config.odometry else None
            last = localizer.last_fix
            room = None if last is None else (last.ids.floor, last.ids.room)
            choice = chooser.choose(stamp, seen, None if bridged is None else
                                    bridged.T_frame_base, motion.pan, motion.tilt, twist,
                                    room, camera)
        else:
            choice = biggest_seen(seen, 'gaze off')
        record.target_source, record.target_reason = choice.source, choice.reason
        if choice.point is not None:
            record.target = (choice.point, motion.pan, motion.tilt)
    if fix is None:
        record.problem = result.no_fix_reason
        return record
    ids = fix.ids.as_tuple()
    record.ids = ids
    record.wrong_id = ids not in {v.ids.as_tuple() for v in truth.views}
    located_room = world.room_at(fix.T_frame_base.t[:2])
    record.wrong_room = (located_room is not None and truth.room is not None
                         and (located_room.floor, located_room.room) != truth.room)
    err = fix.T_frame_base.t - truth.T_building_base.t
    record.error = err
    record.d2 = _d2(err, fix.covariance[:3, :3])
    rot_err = rotation_vector(fix.T_frame_base.R @ truth.T_building_base.R.T)
    record.d2_rotation = _d2(rot_err, fix.covariance[3:, 3:])
    record.rot_err2 = float(rot_err @ rot_err)
    record.true_blur_px = float(blurs.get(ids, 0.0))
    record.distance_m = float(np.linalg.norm(fix.T_camera_card.t))
    eye = fix.T_camera_card.inverse().t
    record.view_deg = math.degrees(math.acos(min(1.0, eye[2] / np.linalg.norm(eye))))
    record.size_px = fix.size_px
    record.fx_px = camera.fx
    card = building.card(fix.ids)
    # The image's part: the base from the estimated camera pose and the true angles.
    image_only = base_pose_from_camera(card.T_building_card, fix.T_camera_card, head,
                                       true_pan, true_tilt)
    image_err = image_only.t - truth.T_building_base.t
    head_err = fix.T_frame_base.t - image_only.t
    record.image_error_m = float(np.linalg.norm(image_err))
    record.head_error_m = float(np.linalg.norm(head_err))
    terms = fix.uncertainty
    if terms is not None:
        record.sigmas = terms.position_sigmas()
        record.blur_px = terms.blur_px
        record.pixel_sigma_px = terms.pixel_sigma_px
        image_cov = terms.terms['image'] + terms.terms['map']
        head_cov = (terms.terms['head_timing'] + terms.terms['head_interpolation']
                    + terms.terms['head_resolution'])
        record.d2_image = _d2(image_err, image_cov[:3, :3])
        unit = terms.terms['image'] / terms.pixel_sigma_px ** 2
        record.d2_image_unit = _d2(image_err, unit[:3, :3])
        record.residual_sigma_px = terms.residual_sigma_px
        record.calib.update(
            image_unit=unit[:3, :3], map=terms.terms['map'][:3, :3],
            Ja=angle_jacobian(card.T_building_card, fix.T_camera_card, head, motion.pan,
                              motion.tilt)[:3], blur_pred=terms.blur_px,
            residual=terms.residual_sigma_px)
        record.d2_head = _d2(head_err, head_cov[:3, :3] + 1e-12 * np.eye(3))
    return record


def _head_sigma(motion, params: UncertaintyParameters) -> Tuple[float, float]:
    rates = np.array([motion.pan_rate, motion.tilt_rate])
    var = ((rates * params.joint_stamp_sigma_s) ** 2
           + (params.interpolation_factor * np.asarray(motion.rate_change) * motion.interval_s)
           ** 2 + (rates * motion.hold_s) ** 2
           + np.array([params.pan_step_rad, params.tilt_step_rad]) ** 2 / 12.0)
    return float(math.sqrt(var[0])), float(math.sqrt(var[1]))


def _d2(error: np.ndarray, covariance: np.ndarray) -> float:
    try:
        value = float(error @ np.linalg.solve(covariance, error))
    except np.linalg.LinAlgError:
        return math.inf
    return value if math.isfinite(value) else math.inf


# The detector's centre noise -----------------------------------------------------------


def centre_noise(views: int = 60, seed: int = 1, route: str = 'loop') -> Dict[str, float]:
    """
    Return the detector's dot-centre error on still frames against the exact ellipse centres.

    Base poses along ``route``; the head aims at the nearest card it can
    see whole (the sim's oracle gaze), zoomed so that the card is a quarter
    to an eighth of the image wide; the frame is rendered still (no blur).
    Each detected dot's undistorted centre is compared with the image
    ellipse's centre at the true pose: the per-axis RMS (``sigma_px``),
    the RMS of each card's common shift (``shift_px``, a bias shared by
    its dots) and the fit's own residual noise (``residual_px``, what the
    estimator sees), medians and 95th percentiles over cards.
    """
    from ..vision.detector import Detector
    from ..vision.pose_exact import ellipse_centres, estimate_exact
    sim = FloorSim.floor(route, seed=seed)
    scene, world = sim.scene, sim.world
    pattern = world.pattern
    detector = Detector(pattern)
    table = ZoomTable.load()
    rng = np.random.default_rng(seed)
    points, radii = pattern.model_points(), pattern.dot_radii()
    sigmas, shifts, residuals = [], [], []
    tried = 0
    while len(sigmas) < views and tried < 20 * views:
        tried += 1
        state = sim.state(float(rng.uniform(0.0, sim.duration_s)))
        gaze = scene.oracle_gaze(state.pose)
        if gaze is None:
            continue
        ids, pan, tilt = gaze
        T_camera = scene.true_camera_pose(state.pose, pan, tilt)
        card = world.card(ids)
        distance = float(np.linalg.norm(card.T_building_card.t - T_camera.t))
        fraction = float(rng.uniform(0.125, 0.25))
        camera = table.camera_at(table.zoom_for_focal(
            fraction * table.width * distance / pattern.card_size))
        image = scene.render_still(T_camera, camera, seed=int(rng.integers(1 << 30)))
        found = [d for d in detector.detect(image, camera) if d.ids is not None
                 and d.ids.as_tuple() == tuple(ids)]
        if not found:
            continue
        det = found[0]
        seen = ~np.isnan(det.points_px).any(axis=1)
        T_camera_card = T_camera.inverse() @ card.T_building_card
        truth = ellipse_centres(T_camera_card, points[:, :2], radii, camera.K)
        error = camera.undistort_pixels(det.points_px[seen]) - truth[seen]
        sigmas.append(math.sqrt(float(np.mean(error ** 2))))
        shifts.append(float(np.linalg.norm(error.mean(axis=0))))
        try:
            est = estimate_exact(det.points_px, camera, pattern)
        except Exception:             # noqa: BLE001 (a measurement: a failed fit is skipped)
            continue
        n = est.n_points
        residuals.append(est.reprojection_rms_px * math.sqrt(n / max(2 * n - 6, 1)))

    def q(values):
        return (float(np.median(values)), float(np.percentile(values, 95))) if values else (
            math.nan, math.nan)

    return {'cards': len(sigmas), 'sigma_px': q(sigmas), 'shift_px': q(shifts),
            'residual_px': q(residuals)}


# Summary ------------------------------------------------------------------------------


def _stats(values: Sequence[float]) -> Dict[str, float]:
    v = np.asarray([x for x in values if x is not None and math.isfinite(x)], dtype=float)
    if not len(v):
        return {'n': 0, 'median': math.nan, 'p95': math.nan, 'max': math.nan}
    return {'n': int(len(v)), 'median': float(np.median(v)),
            'p95': float(np.percentile(v, 95)), 'max': float(v.max())}


def _coverage(d2: Sequence[Optional[float]], limit: float = CHI2_3) -> Tuple[float, int]:
    values = [x for x in d2 if x is not None]
    if not values:
        return math.nan, 0
    return float(np.mean([x <= limit for x in values])), len(values)


def summarise(records: Sequence[FrameRecord], fix_age_s: float = 0.5) -> dict:
    """Return the bench's figures from the records of one or more runs."""
    fixes = [r for r in records if r.error is not None]
    driving = [r for r in fixes if r.phase != 'stop']
    stops = [r for r in fixes if r.phase == 'stop']
    out: dict = {'images': len(records), 'located': len(fixes)}
    out['coverage_95'], _ = _coverage([r.d2 for r in fixes])
    out['coverage_95_driving'], _ = _coverage([r.d2 for r in driving])
    out['coverage_95_stops'], _ = _coverage([r.d2 for r in stops])
    out['coverage_95_rotation'], _ = _coverage([r.d2_rotation for r in fixes])
    out['rotation_error_deg'] = _stats([math.degrees(math.sqrt(max(0.0, r.rot_err2)))
                                        for r in fixes if r.rot_err2 is not None])
    out['error_m'] = _stats([float(np.linalg.norm(r.error)) for r in fixes])
    out['error_driving_m'] = _stats([float(np.linalg.norm(r.error)) for r in driving])
    out['error_stops_m'] = _stats([float(np.linalg.norm(r.error)) for r in stops])
    out['wrong_ids'] = sum(r.wrong_id for r in fixes)
    out['wrong_rooms'] = sum(r.wrong_room for r in fixes)
    # Fix coverage: at each driving frame, was there a fix younger than fix_age_s?
    last = -math.inf
    fresh = total = 0
    for r in records:
        if r.error is not None:
            last = r.t
        if r.phase != 'stop':
            total += 1
            fresh += (r.t - last) < fix_age_s
    out['fix_coverage'] = fresh / total if total else math.nan
    out['bridge_error_m'] = _stats([r.bridge_error_m for r in records])
    out['bridge_coverage_95'], _ = _coverage([r.bridge_d2 for r in records])
    out['image_term_coverage_95'], _ = _coverage([r.d2_image for r in fixes])
    out['head_term_coverage_95'], _ = _coverage([r.d2_head for r in fixes])
    out['image_error_m'] = _stats([r.image_error_m for r in fixes])
    out['head_error_m'] = _stats([r.head_error_m for r in fixes])
    moving = [r for r in records if not math.isnan(r.head_error[0])]
    for axis, name in ((0, 'pan'), (1, 'tilt')):
        e = np.array([r.head_error[axis] for r in moving])
        s = np.array([r.head_sigma[axis] for r in moving])
        out[f'head_{name}_error_deg'] = _stats(np.degrees(np.abs(e)))
        ok = s > 0
        out[f'head_{name}_within_2sigma'] = float(np.mean(np.abs(e[ok]) <= 1.96 * s[ok])) \
            if ok.any() else math.nan
    out['blur_px'] = _stats([r.true_blur_px for r in fixes])
    counts: Dict[str, int] = {}
    for r in records:
        for reason in r.rejections:
            counts[reason] = counts.get(reason, 0) + 1
    out['rejections'] = counts
    sig = {}
    for name in ('image', 'head_timing', 'head_interpolation', 'head_resolution', 'map'):
        sig[name] = _stats([r.sigmas.get(name) for r in fixes if r.sigmas])['median']
    out['term_sigma_median_m'] = sig
    targets: Dict[str, int] = {}
    for r in records:
        for key in (r.target_source, r.target_reason):
            if key:
                targets[key] = targets.get(key, 0) + 1
    out['targets'] = targets
    return out


def _fmt_stats(s: Dict[str, float], scale: float = 100.0, unit: str = 'cm') -> str:
    if not s['n']:
        return 'none'
    return (f'median {s["median"] * scale:.2f}, p95 {s["p95"] * scale:.2f}, max '
            f'{s["max"] * scale:.2f} {unit} ({s["n"]})')


def report(summary: dict, title: str) -> List[str]:
    """Return the printed lines of one summary."""
    s = summary
    lines = [title,
             f'  frames {s["images"]}, fixes {s["located"]}; fix coverage while driving '
             f'{s["fix_coverage"]:.3f}; wrong ids {s["wrong_ids"]}, wrong rooms '
             f'{s["wrong_rooms"]}',
             f'  coverage_95 {s["coverage_95"]:.3f} (driving {s["coverage_95_driving"]:.3f}, '
             f'stops {s["coverage_95_stops"]:.3f})',
             f'  error driving: {_fmt_stats(s["error_driving_m"])}',
             f'  rotation: coverage_95 {s["coverage_95_rotation"]:.3f}, error '
             f'{_fmt_stats(s["rotation_error_deg"], 1.0, "deg")}',
             f'  error at stops: {_fmt_stats(s["error_stops_m"])}',
             f'  parts of the error: image {_fmt_stats(s["image_error_m"])}; head '
             f'{_fmt_stats(s["head_error_m"])}',
             f'  terms alone, coverage_95: image(+map) {s["image_term_coverage_95"]:.3f}, head '
             f'{s["head_term_coverage_95"]:.3f}',
             '  head angle error at the stamps: pan '
             f'{_fmt_stats(s["head_pan_error_deg"], 1.0, "deg")} (within 1.96 sigma '
             f'{s["head_pan_within_2sigma"]:.3f}); tilt '
             f'{_fmt_stats(s["head_tilt_error_deg"], 1.0, "deg")} (within 1.96 sigma '
             f'{s["head_tilt_within_2sigma"]:.3f})',
             f'  blur of the fix card: {_fmt_stats(s["blur_px"], 1.0, "px")}',
             '  median sigma per term (cm): ' + ', '.join(
                 f'{k} {v * 100:.2f}' for k, v in s['term_sigma_median_m'].items()
                 if v == v),
             f'  odom_bridged: error {_fmt_stats(s["bridge_error_m"])}, coverage_95 '
             f'{s["bridge_coverage_95"]:.3f}',
             '  locator targets: ' + (', '.join(f'{k} {v}' for k, v in sorted(
                 s['targets'].items())) or 'none (--driver planner)'),
             '  gates refused: ' + (', '.join(f'{k} {v}' for k, v in sorted(
                 s['rejections'].items())) or 'nothing')]
    return lines


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run the bench; print the table; return the exit status."""
    parser = argparse.ArgumentParser(prog='pattern-locator bench --drive-core',
                                     description=__doc__.split('\n\n')[0].strip())
    parser.add_argument('--route', default='short', help='route of config/sim_floor.yaml '
                        '(short, loop, tour; default short)')
    parser.add_argument('--seconds', type=float, default=None,
                        help='stop after this much route time (default: the whole route)')
    parser.add_argument('--seeds', default='1', help='comma-separated seeds (default 1)')
    parser.add_argument('--rate', type=float, default=5.0, help='frames per second (default 5)')
    parser.add_argument('--max-speed', type=float, default=0.5,
                        help="cap of the route legs' speed, m/s (default 0.5)")
    parser.add_argument('--exposure', choices=sorted(EXPOSURES), default='blur')
    parser.add_argument('--shutter', type=float, default=None, metavar='S',
                        help="the camera's shutter, s (default the auto exposure's 1/50); a "
                             'shorter one blurs less and, with the gain making up the light, '
                             'is noisier')
    parser.add_argument('--covariance', choices=('model', 'fisher', 'both'), default='both',
                        help="the covariance model, the estimator's alone, or both in turn")
    parser.add_argument('--joint-hz', type=float, default=10.0,
                        help='joint state rate of the simulated driver (default 10)')
    parser.add_argument('--usb-latency-ms', type=float, default=16.0,
                        help="the stamps' lateness, uniform up to this (default 16, an FTDI "
                             "adapter's latency timer); the model's joint_stamp_sigma_s follows")
    parser.add_argument('--publish-delay-ms', type=float, default=0.0,
                        help="from the answer's arrival to the joint state's publication "
                             '(default 0; ~32: a driver publishing after its commands)')
    parser.add_argument('--joint-wait-ms', type=float, default=150.0,
                        help="the locator's joint_state_wait_s, ms (default 150; the last "
                             'joint state is held after it)')
    parser.add_argument('--as-hung', action='store_true',
                        help='cards off their mapped pose (the map giving its std_dev)')
    parser.add_argument('--driver', choices=DRIVERS, default='planner',
                        help='planner: the driver aims with the gaze planner itself; target: '
                             "a map-free driver centres the locator's target (as the nodes)")
    parser.add_argument('--no-odometry', action='store_true',
                        help="the locator takes no odometry (the gates' speed limits; no "
                             'bridge, so no gaze)')
    parser.add_argument('--no-gaze', action='store_true',
                        help="the locator's target is the biggest card seen (--driver target)")
    parser.add_argument('--json', metavar='FILE', help='write the summaries as JSON')
    parser.add_argument('--centre-noise', type=int, metavar='VIEWS', default=0,
                        help="only measure the detector's dot-centre noise on VIEWS still "
                             'frames (the pixel floor of the covariance) and exit')
    args = parser.parse_args(argv)
    if args.centre_noise > 0:
        noise = centre_noise(args.centre_noise, int(args.seeds.split(',')[0] or 1), args.route
                             if args.route != 'short' else 'loop')
        print(f'dot-centre noise on {noise["cards"]} still cards (median, p95): per axis '
              f'{noise["sigma_px"][0]:.4f}, {noise["sigma_px"][1]:.4f} px; common shift '
              f'{noise["shift_px"][0]:.4f}, {noise["shift_px"][1]:.4f} px; the fit\'s residual '
              f'noise {noise["residual_px"][0]:.4f}, {noise["residual_px"][1]:.4f} px')
        return 0
    try:
        seeds = [int(s) for s in args.seeds.split(',') if s.strip()]
    except ValueError:
        print(f'bench --drive-core: --seeds must be integers, got {args.seeds!r}',
              file=sys.stderr)
        return 2
    if not seeds or not (0.5 <= args.rate <= 25.0) or not (0.05 <= args.max_speed <= 0.8) or (
            args.seconds is not None and not args.seconds > 0.0) or not (
            1.0 <= args.joint_hz <= 50.0) or not (0.0 <= args.usb_latency_ms <= 200.0) or (
            args.shutter is not None and not 0.0001 <= args.shutter <= 0.02):
        print('bench --drive-core: need a seed, --rate within 0.5..25, --max-speed within '
              '0.05..0.8, --seconds > 0, --joint-hz within 1..50, --usb-latency-ms within '
              '0..200 and --shutter within 0.0001..0.02', file=sys.stderr)
        return 2
    try:
        FloorSim.floor(args.route)
    except PatternLocatorError as exc:
        print(f'bench --drive-core: {exc}', file=sys.stderr)
        return 2
    modes = ('fisher', 'model') if args.covariance == 'both' else (args.covariance,)
    summaries = {}
    for mode in modes:
        records: List[FrameRecord] = []
        start = time.perf_counter()
        for seed in seeds:
            timing = replace(JointTiming(), period_s=1.0 / args.joint_hz,
                             usb_latency_s=args.usb_latency_ms / 1000.0,
                             publish_s=args.publish_delay_ms / 1000.0)
            config = DriveCoreConfig(route=args.route, seconds=args.seconds,
                                     frame_rate_hz=args.rate, max_speed_m_s=args.max_speed,
                                     exposure=args.exposure, shutter_s=args.shutter,
                                     covariance=mode,
                                     as_hung=args.as_hung, seed=seed, timing=timing,
                                     driver=args.driver, odometry=not args.no_odometry,
                                     gaze=not args.no_gaze,
                                     joint_wait_s=args.joint_wait_ms / 1000.0)
            records.extend(run(config, progress=True))
        elapsed = time.perf_counter() - start
        summary = summarise(records)
        summaries[mode] = summary
        timing = ('' if (args.joint_hz, args.usb_latency_ms) == (10.0, 16.0) else
                  f', joint states {args.joint_hz:g} Hz late by <= {args.usb_latency_ms:g} ms')
        if (args.publish_delay_ms, args.joint_wait_ms) != (0.0, 150.0):
            timing += (f', joint states published {args.publish_delay_ms:g} ms after their '
                       f'answer, waited for {args.joint_wait_ms:g} ms')
        title = (f'{args.route}, seeds {",".join(map(str, seeds))}, {args.rate:g} fps, '
                 f'<= {args.max_speed:g} m/s, {args.exposure}'
                 f'{"" if args.shutter is None else f", shutter {args.shutter:g} s"}{timing}'
                 f'{", as hung" if args.as_hung else ""}, driver {args.driver}'
                 f'{", no odometry" if args.no_odometry else ""}'
                 f'{", no gaze" if args.no_gaze else ""}: covariance {mode} '
                 f'({elapsed:.0f} s)')
        print('\n'.join(report(summary, title)), flush=True)
    if args.json:
        with open(args.json, 'w', encoding='utf-8') as handle:
            json.dump(summaries, handle, indent=1, default=float)
    return 0


if __name__ == '__main__':
    sys.exit(main())
