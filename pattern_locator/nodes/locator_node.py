"""
The ``locator`` node: camera images in, the robot's place in the building out.

Topic names are relative, so a namespace (``__ns:=/robot2``, a launch
file's ``namespace``) moves them all; ``/diagnostics`` stays absolute.

Subscribes
    ``camera/image_raw`` (sensor_msgs/Image, sensor-data QoS),
    ``camera/camera_info`` (sensor_msgs/CameraInfo, sensor-data QoS; kept by
    stamp, so each image uses the intrinsics of its own stamp: a zoom
    camera's change), ``camera/joint_states`` (sensor_msgs/JointState,
    reliable: ``camera_pan``/``camera_tilt``, used while
    ``use_joint_states`` is true, else the fixed angles), ``odom``
    (nav_msgs/Odometry, reliable, while ``use_odometry`` is true: the base's
    motion since the last fix for the continuity gate, its twist for the
    covariance, the bridge and the gaze).

Publishes
    ``robot_location`` (geometry_msgs/PoseStamped: the base pose, the image's
    stamp, the room frame or ``building``), ``robot_location/ids``
    (std_msgs/UInt16MultiArray: floor, room, pattern),
    ``robot_location/with_covariance``
    (geometry_msgs/PoseWithCovarianceStamped; transient local, depth 1, like
    AMCL's ``amcl_pose``: a late subscriber gets the last fix),
    ``robot_location/odom_bridged`` (geometry_msgs/PoseWithCovarianceStamped:
    the last fix carried forward by odometry, at the odometry's rate and
    stamps, its covariance growing; robot_location's frame),
    ``pattern_locator/target`` (geometry_msgs/PointStamped: the centre of the
    card the head should centre, in ``camera_optical_frame``, metres, the
    image's stamp; chosen by the map-guided gaze from the bridged pose,
    ``localization/target_choice.py``: the card as seen, or its centre
    predicted at a handover; without odometry the biggest card seen),
    ``pattern_locator/debug_image`` (only drawn while someone subscribes) and
    ``/diagnostics``.

Services
    ``~/reset`` (std_srvs/Trigger): forget the last fix, the pose carried
    forward by odometry and the gaze's card, for a robot carried elsewhere
    (else ``odom_bridged`` keeps publishing the old place, and the gaze
    looks for the cards near it, until a new fix): the next fix is judged
    as a first one (held back until a second image agrees, while
    ``gates.confirm_first_fix``), with no last fix to decide a planar flip
    or a partly hidden card's code. ``robot_location/with_covariance`` is
    published anew, holding no fix until the next: a subscriber that joins
    after the reset does not start from the old place.

Parameters: see :data:`PARAMETERS` (``config/locator.yaml`` and
``docs/ros.md``); those marked dynamic apply at run time, after a check
that refuses a bad value with the reason; the others are read-only.

Only the newest frame is processed: when the work is slower than the camera,
older frames are dropped and counted, never queued. Bad input (an oversized
frame, an unknown encoding, a short buffer, a bad camera_info or joint
state, a code not in the map) gives a throttled warning (one line per kind
of problem every few seconds, foreign strings quoted and cut) and a count
by reason in the diagnostics, never a pose. Nothing non-finite is ever
published, whatever the core returns.
"""

import collections
import dataclasses
import math
import threading
import time
from typing import Any, Dict, Optional, Sequence, Tuple

import cv2
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PointStamped, PoseStamped, PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
import numpy as np
from rclpy.node import Node
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, qos_profile_sensor_data, QoSProfile,
                       ReliabilityPolicy)
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import MultiArrayDimension, UInt16MultiArray
from std_srvs.srv import Trigger

from .image_codec import camera_from_info, fill_msg, image_from_msg
from .memory import HeapTrimmer
from .ros_helpers import (all_finite, describe_values, fill_pose, Param, Parameters,
                          ProblemLog, run_node, stamp_key, stamp_seconds, wall_timer)
from ..card.pattern import load_pattern_config
from ..errors import PatternLocatorError
from ..localization.building import BuildingMap, load_building
from ..localization.gates import FOOTPRINTS, GateParameters
from ..localization.gaze import GazeParameters
from ..localization.head import (angles_from_joint_state, HeadGeometry, HeadMotion,
                                 JointStateBuffer)
from ..localization.localizer import (FrameResult, FUSION_MODES, OUTPUT_FRAMES, RobotFix,
                                      RobotLocalizer)
from ..localization.odom import BaseTwist, BridgedPose, covariance_from_ros, OdomBridge, OdomBuffer
from ..localization.target_choice import biggest_seen, seen_cards, TargetChoice, TargetChooser
from ..localization.uncertainty import TERMS, UncertaintyParameters
from ..vision.camera import CameraModel
from ..vision.geometry import Pose, rotation_from_quaternion
from ..vision.locate import ESTIMATORS
from ..vision.overlay import draw_overlay

THROTTLE_S = 5.0
CAMERA_INFO_HISTORY = 60
# An image that overtook its own camera_info waits this long for it (a
# loaded machine delayed it by more than 50 ms: see _camera_for).
CAMERA_INFO_WAIT_S = 0.2
# Without its own camera_info an image takes the latest only if the last
# this many that came agree (a camera not zooming).
CAMERA_INFO_STEADY = 3
# After this many images in a row without their own camera_info the camera
# is taken not to stamp camera_info with its images: no more waiting.
CAMERA_INFO_MISSES = 10
# A joint state this much older than the newest one means the clock went back
# (a bag replayed again, a simulator restarted): the history starts afresh.
CLOCK_JUMP_S = 1.0
# No image message is allowed more bytes per pixel than this (rgba8 with
# padding): a frame over it is refused before anything reads its data.
MAX_BYTES_PER_PIXEL = 8
# Frames above this many bytes leave big buffers behind: trim the heap when idle.
LARGE_FRAME_BYTES = 4 * 1024 * 1024
TIMES_KEPT = 200
# Fixes over which the covariance terms' shares are given (their medians).
SHARES_KEPT = 100
# Odometry whose newest sample is this much older than an image has stopped:
# the image does not wait for a newer one.
ODOM_FLOWING_S = 1.0

PARAMETERS: Tuple[Param, ...] = (
    Param('pattern_config', '', 'pattern YAML (empty: the shipped config/pattern.yaml)'),
    Param('building_map', '', 'building map YAML (empty: the shipped config/building.yaml)'),
    Param('estimator', 'exact', 'pose estimator', choices=ESTIMATORS, dynamic=True),
    Param('output_frame', 'room', 'frame of robot_location: the room of the card seen, or '
          'the building frame', choices=OUTPUT_FRAMES, dynamic=True),
    Param('fusion', 'biggest', "several cards in view: the biggest (the paper's rule) or "
          'all fused', choices=FUSION_MODES, dynamic=True),
    Param('base_frame', 'base_link', 'frame name of the robot base'),
    Param('min_tilt_deg', 0.0, "reject views tilted less than this (the paper's rule: 25)",
          0.0, 89.0, dynamic=True),
    Param('max_reprojection_px', 1.5, 'reject poses with a larger RMS reprojection error',
          0.01, 100.0, dynamic=True),
    Param('up_sigma_deg', 5.0, "how well the head's tilt and the base's attitude give the "
          "card's up in the camera (deg): it resolves the planar flip and, in a close call, "
          'takes part in the pose', 0.1, 90.0, dynamic=True),
    Param('camera_height_sigma_m', 0.15, "how well the camera's height above the floor is "
          'known (m; the base on the floor): as up_sigma_deg', 0.001, 10.0, dynamic=True),
    Param('use_joint_states', True, 'take the head angles from camera/joint_states (else the '
          'fixed ones)', dynamic=True),
    Param('fixed_pan_deg', 0.0, 'head pan when joint states are not used (+ = left)',
          -180.0, 180.0, dynamic=True),
    Param('fixed_tilt_deg', 0.0, 'head tilt when joint states are not used (+ = up)',
          -90.0, 90.0, dynamic=True),
    Param('joint_state_max_age_s', 0.5, 'an image later than the last joint state by more '
          'than this has no head angles', 0.01, 10.0, dynamic=True),
    Param('joint_state_wait_s', 0.15, 'wait this long for a joint state newer than the image '
          'before holding the newest one (at least their period plus their delivery)', 0.0,
          1.0, dynamic=True),
    Param('joint_state_warmup_s', 1.0, 'an image with no joint state history around it (at '
          'start, after the clock went back) waits this long for one', 0.0, 10.0,
          dynamic=True),
    Param('max_image_pixels', 4_194_304, 'refuse larger frames before reading them '
          '(width * height)', 1, 100_000_000, dynamic=True),
    Param('opencv_threads', 1, 'threads OpenCV may use per frame (0: its default)', 0, 64,
          dynamic=True),
    Param('head.base_to_pan_xyz', [0.0, 0.0, 1.0], 'base_link to the pan joint (m)'),
    Param('head.pan_to_tilt_xyz', [0.0, 0.0, 0.05], 'pan joint to the tilt joint (m)'),
    Param('head.tilt_to_optical_xyz', [0.03, 0.0, 0.05], 'tilt joint to the optical centre (m)'),
    Param('head.mount_pitch_deg', 0.0, 'the camera is mounted pitched up by this: tilt 0 '
          'looks up by it (deg)', -60.0, 60.0),
    Param('joint_margin_deg', 5.0, "joint states beyond the head's travel by more than this "
          'are refused', 0.0, 45.0),
    Param('use_odometry', True, "take the base's motion from odom (nav_msgs/Odometry): the "
          'continuity gate, the covariance of a moving base, odom_bridged and the gaze',
          dynamic=True),
    Param('odom_wait_s', 0.05, 'wait this long for an odometry sample newer than the image '
          'before using the newest one', 0.0, 1.0, dynamic=True),
    Param('odom_bridged', True, 'publish robot_location/odom_bridged: the last fix carried '
          'forward by odometry, at the odometry rate', dynamic=True),
    Param('odom_bridged_max_age_s', 60.0, 'odom_bridged stops when its fix is older than this '
          '(s)', 0.1, 3600.0, dynamic=True),
    Param('odom_bridged_max_sigma_m', 1.0, 'odom_bridged stops when its position standard '
          'deviation exceeds this (m)', 0.01, 100.0, dynamic=True),
    Param('use_gaze', True, 'choose the target with the map-guided gaze planner (gaze.*; it '
          'needs odometry); false: the biggest card seen', dynamic=True),
)

# The output gates (localization/gates.py), one parameter each: a fix is
# published only if it passes them all. (description, low, high or choices)
_GATE_DESCRIPTIONS: Dict[str, Tuple[str, Any, Any]] = {
    'max_position_sigma_m': ('largest position standard deviation of a fix (m)', 0.001, 100.0),
    'min_camera_distance_m': ('camera nearer its card than this: refused (m)', 0.0, 100.0),
    'max_camera_distance_m': ('camera farther from its card than this: refused (m)', 0.1,
                              1000.0),
    'max_view_angle_deg': ("camera further off the card's normal: refused (deg)", 1.0, 90.0),
    'min_base_height_m': ("base below its room's floor by more: refused (m)", -100.0, 100.0),
    'max_base_height_m': ("base above its room's floor by more: refused (m)", -100.0, 100.0),
    'max_roll_deg': ('base rolled more than this: refused (deg)', 0.0, 180.0),
    'max_pitch_deg': ('base pitched more than this: refused (deg)', 0.0, 180.0),
    'footprint': ("where the base may be: inside the card's room, that room or one next to "
                  'it (a card seen through a door), the building, or anywhere',
                  FOOTPRINTS, None),
    'footprint_margin_m': ('margin around the footprint (m)', 0.0, 100.0),
    'adjacent_gap_m': ('rooms whose footprints are this close (along at least 0.5 m) are '
                       "next to each other, for footprint 'adjacent' (m)", 0.0, 10.0),
    'continuity': ('judge each fix against the last one (false: every image stands alone, '
                   'as for unrelated still images)', None, None),
    'max_speed_m_s': ('fastest the base moves, without odometry (m/s)', 0.01, 100.0),
    'max_yaw_rate_deg_s': ('fastest the base turns, without odometry (deg/s)', 0.1, 3600.0),
    'max_jump_mahalanobis': ('a fix further than this from what motion allows waits for a '
                             'second agreeing image', 0.5, 1000.0),
    'jump_sigma_floor_m': ('position sigma added when judging a jump (m)', 0.0, 10.0),
    'jump_sigma_floor_deg': ('rotation sigma added when judging a jump (deg)', 0.0, 180.0),
    'confirm_within_s': ('a held-back fix is published when an image this much later agrees '
                         '(s)', 0.0, 60.0),
    'confirm_first_fix': ('hold back the first fix too until a second image agrees', None,
                          None),
    'clock_jump_back_s': ('stamps going back more than this restart continuity (s)', 0.0,
                          3600.0),
    'partial_code_max_age_s': ("a partly hidden card's code is taken from the map only this "
                               'soon after the last fix (s)', 0.0, 60.0),
    'max_flip_probability': ('a card whose other planar pose is more likely than this gives a '
                             'fix only when a gate or the last fix rules that pose out', 0.0,
                             0.5),
}


# The covariance model (localization/uncertainty.py), one parameter per term's size.
_UNCERTAINTY_DESCRIPTIONS: Dict[str, Tuple[str, Any, Any]] = {
    'pixel_sigma_px': ("the detector's dot-centre noise on still frames: the least pixel noise "
                       'of a fix (px)', 0.0, 10.0),
    'residual_factor': ("the estimator's error over its Fisher bound at the fit's own residual "
                        'noise', 0.0, 10.0),
    'blur_sigma_per_px': ('dot-centre noise added per pixel of predicted smear (px/px)', 0.0,
                          1.0),
    'exposure_s': ("the camera's shutter time, of each field when interlaced (s; the "
                   "camera_driver's shutter_s when it sets one)", 0.0, 1.0),
    'field_period_s': ("time between an interlaced frame's two fields; 0: a progressive camera "
                       '(s)', 0.0, 0.1),
    'joint_stamp_sigma_s': ("RMS error of the joint states' stamps against when the camera "
                            'latched the angles (s)', 0.0, 1.0),
    'image_stamp_sigma_s': ("RMS error of the images' stamps (s)", 0.0, 1.0),
    'interpolation_factor': ('head angle error between joint states per change of rate times '
                             'their interval', 0.0, 5.0),
    'pan_step_rad': ("the head's pan resolution (rad; EVI-D31: 1/8.8 deg)", 0.0, 0.1),
    'tilt_step_rad': ("the head's tilt resolution (rad; EVI-D31: 1/12 deg)", 0.0, 0.1),
    'map_position_sigma_m': ('position standard deviation of cards whose map entry gives no '
                             'std_dev (m)', 0.0, 10.0),
    'map_rotation_sigma_deg': ('rotation standard deviation of cards whose map entry gives no '
                               'std_dev (deg)', 0.0, 90.0),
    'floor_position_m': ('position standard deviation added to every fix (m)', 0.0, 10.0),
    'floor_rotation_deg': ('rotation standard deviation added to every fix (deg)', 0.0, 90.0),
}

# The map-guided gaze (localization/gaze.py): which card the target is.
_GAZE_DESCRIPTIONS: Dict[str, Tuple[str, Any, Any]] = {
    'min_distance_m': ('a card nearer the head than this is not aimed at (m)', 0.0, 100.0),
    'max_distance_m': ('a card farther from the head than this is not aimed at (m)', 0.1,
                       100.0),
    'max_view_angle_deg': ('a card seen further off its normal is not aimed at (deg)', 1.0,
                           89.0),
    'pan_margin_deg': ('aim only this far inside the pan travel (deg)', 0.0, 90.0),
    'tilt_margin_deg': ('aim only this far inside the tilt travel (deg)', 0.0, 45.0),
    'doorway_margin_m': ("outside every room's footprint but this close to some: a doorway, "
                         'where both rooms count (m)', 0.0, 10.0),
    'doorway_m': ('the first metres of a line of sight, where the robot stands, are not '
                  'checked (m)', 0.0, 10.0),
    'touch_m': ('rooms whose footprints are this close (along min_opening_m) are one space '
                '(m)', 0.0, 10.0),
    'min_opening_m': ('rooms touching along at least this are one space (m)', 0.0, 100.0),
    'sight_step_m': ('step along a line of sight (m)', 0.01, 1.0),
    'sight_clearance_m': ('lines of sight stay this far inside the footprints (m)', 0.0, 10.0),
    'card_half_width_m': ("half a card's width: lines of sight go to its edges too (m)", 0.0,
                          10.0),
    'lookahead_s': ('hand over to the next card when the current one leaves the view within '
                    'this, at the current twist (s)', 0.0, 60.0),
    'switch_ratio': ('switch to another card when its score is below this times the current '
                     "one's", 0.01, 1.0),
    'view_weight': ('weight of obliquity in the score (distance x (1 + w (1 / cos(view) - 1)))',
                    0.0, 100.0),
    'slew_weight_m_per_rad': ('score added per radian the head must turn (m/rad)', 0.0, 100.0),
    'slew_rate_deg_s': ("the head's pan speed in a slew: a card is taken only if still in sight "
                        'when the head gets there (deg/s; 0: not checked)', 0.0, 1000.0),
    'min_dwell_s': ('... and this long after (s)', 0.0, 60.0),
    'stay_horizon_s': ('a card to turn to that is predicted gone this far ahead costs '
                       'leave_weight_m more (s; at most lookahead_s: not checked)', 0.0, 60.0),
    'leave_weight_m': ('... this much (m)', 0.0, 100.0),
}

# Groups of parameters declared from a core's dataclass, one per field.
PARAMETER_GROUPS = (('gates', GateParameters, _GATE_DESCRIPTIONS),
                    ('uncertainty', UncertaintyParameters, _UNCERTAINTY_DESCRIPTIONS),
                    ('gaze', GazeParameters, _GAZE_DESCRIPTIONS))


def _group_parameters(prefix: str, cls: Any, descriptions: Dict[str, Tuple[str, Any, Any]]
                      ) -> Tuple[Param, ...]:
    defaults = cls()
    params = []
    for field in dataclasses.fields(cls):
        description, low, high = descriptions[field.name]
        default = getattr(defaults, field.name)
        if isinstance(low, tuple):
            params.append(Param(f'{prefix}.{field.name}', default, description, choices=low,
                                dynamic=True))
        elif isinstance(default, bool):
            params.append(Param(f'{prefix}.{field.name}', default, description, dynamic=True))
        else:
            params.append(Param(f'{prefix}.{field.name}', float(default), description, low,
                                high, dynamic=True))
    return tuple(params)


PARAMETERS = PARAMETERS + tuple(p for group in PARAMETER_GROUPS for p in _group_parameters(*group))


def _group(values: Dict[str, Any], prefix: str) -> Dict[str, Any]:
    return {name[len(prefix) + 1:]: value for name, value in values.items()
            if name.startswith(prefix + '.')}


def gate_parameters(values: Dict[str, Any]) -> GateParameters:
    """Return the gates' thresholds from the node's ``gates.*`` parameter values."""
    return GateParameters(**_group(values, 'gates'))


def uncertainty_parameters(values: Dict[str, Any]) -> UncertaintyParameters:
    """Return the covariance model's sizes from the node's ``uncertainty.*`` parameter values."""
    return UncertaintyParameters(**_group(values, 'uncertainty'))


def gaze_parameters(values: Dict[str, Any]) -> GazeParameters:
    """Return the gaze planner's parameters from the node's ``gaze.*`` parameter values."""
    return GazeParameters(**_group(values, 'gaze'))


def _same_intrinsics(a: Optional[CameraModel], b: Optional[CameraModel]) -> bool:
    """Return whether two camera_infos give the same intrinsics (None: refused, never)."""
    return (a is not None and b is not None and (a.width, a.height) == (b.width, b.height)
            and a.distortion_model == b.distortion_model
            and np.array_equal(a.K, b.K) and np.array_equal(a.D, b.D))


def rejection_reasons(result: FrameResult) -> Sequence[str]:
    """
    Return a short reason key per problem of a frame, for the diagnostics' counts.

    The core's own reason keys when its result carries them (``reasons``);
    otherwise the leading words of each problem (without the card's code
    and any numbers), e.g. 'reprojection error', 'not in the building map'.
    """
    reasons = getattr(result, 'reasons', None)
    if reasons:
        return [str(r)[:40] for r in reasons]
    keys = []
    for text in result.problems:
        if 'not in the building map' in str(text):
            keys.append('not in the building map')
            continue
        head, _, rest = str(text).partition(': ')
        if head.startswith('card ') and rest:
            text = rest
        words = []
        for word in str(text).replace(':', ' : ').split():
            if word == ':' or any(c.isdigit() for c in word) or word.startswith("'"):
                break
            words.append(word)
        keys.append((' '.join(words[:5]) or 'other')[:40])
    return keys


class LocatorNode(Node):
    """Thin ROS shell around :class:`localizer.RobotLocalizer`."""

    def __init__(self, **kwargs) -> None:
        super().__init__('locator', **kwargs)
        self.parameters = Parameters(self, PARAMETERS)
        p = self.parameters.values()
        groups = tuple(prefix + '.' for prefix, _, _ in PARAMETER_GROUPS)
        for line in describe_values({k: v for k, v in p.items() if not k.startswith(groups)}):
            self.get_logger().info('locator configuration: ' + line)
        for prefix, _, _ in PARAMETER_GROUPS:
            for line in describe_values(_group(p, prefix)):
                self.get_logger().info(f'locator {prefix}: ' + line)
        cv2.setNumThreads(int(p['opencv_threads']))
        self.pattern = load_pattern_config(p['pattern_config'] or None)
        building = load_building(p['building_map'] or None, self.pattern)
        self.building: BuildingMap = building
        pairs = building.mirror_pairs()
        if self.pattern.handedness_mark is None and pairs:
            shown = ', '.join(f'{a.label()} / {b.label()}' for a, b in pairs[:5])
            self.get_logger().warn(
                f'the cards carry no handedness marks and {len(pairs)} pair(s) of cards in the '
                f'map are mirror images of each other ({shown}): a reflection of one reads as '
                'the other, and only the gates (continuity, wall side) refuse it')
        self.head = HeadGeometry(
            base_to_pan_xyz=tuple(p['head.base_to_pan_xyz']),
            pan_to_tilt_xyz=tuple(p['head.pan_to_tilt_xyz']),
            tilt_to_optical_xyz=tuple(p['head.tilt_to_optical_xyz']),
            mount_pitch_rad=math.radians(p['head.mount_pitch_deg']))
        self.localizer = RobotLocalizer(
            self.pattern, building, self.head, estimator=p['estimator'],
            output_frame=p['output_frame'], fusion=p['fusion'],
            min_tilt_deg=p['min_tilt_deg'], max_reprojection_px=p['max_reprojection_px'],
            camera_height_sigma=p['camera_height_sigma_m'], up_sigma_deg=p['up_sigma_deg'],
            gates=gate_parameters(p), uncertainty=uncertainty_parameters(p))
        # Every pass of the detector run once now (the compiled ones are loaded
        # at import), not on the first camera frame; and a drawn card read.
        started = time.monotonic()
        read = self.localizer.locator.detector.warm_up()
        self.get_logger().info(f'detector ready in {time.monotonic() - started:.2f} s')
        if read < 2:
            self.get_logger().error(f'the detector read {read} of 2 cards drawn face-on at start: '
                                    'check the pattern configuration')
        self.joint_margin_rad = math.radians(p['joint_margin_deg'])
        self.joints = JointStateBuffer(max_age_s=p['joint_state_max_age_s'], head=self.head,
                                       margin_rad=self.joint_margin_rad)
        # Odometry (executor thread adds, the worker reads; both thread-safe) and
        # the last published fix carried forward by it, in the building frame.
        self.odom = OdomBuffer(clock_jump_back_s=CLOCK_JUMP_S)
        self.bridge = OdomBridge(self.odom, building, p['odom_bridged_max_sigma_m'],
                                 p['odom_bridged_max_age_s'])
        self._odom_arrived = threading.Condition()
        # The room frame of the last published fix (odom_bridged's frame when
        # output_frame is 'room') and its (floor, room), for the gaze.
        self._fix_frame: Optional[str] = None
        self._fix_room: Optional[Tuple[int, int]] = None
        self.chooser = TargetChooser(building, self.head, gaze_parameters(p))
        self.settings: Dict[str, Any] = dict(p)
        # The worker holds this while it processes a frame; run-time
        # parameter changes take it to change the localizer between frames.
        self._settings_lock = threading.Lock()
        self.parameters.on_change(self._validate, self._apply)

        self.problems = ProblemLog(self.get_logger(), THROTTLE_S)
        self.heap = HeapTrimmer()
        self.camera: Optional[CameraModel] = None
        # Recent intrinsics by stamp: a zooming camera's image is matched with
        # the camera_info of its own stamp, not with whatever came last.
        self._cameras_by_stamp: 'collections.OrderedDict[int, Optional[CameraModel]]' = \
            collections.OrderedDict()
        self._camera_problem = 'no camera_info received yet'
        self._info_arrived = threading.Condition()
        # Images in a row without a camera_info of their stamp (see _camera_for).
        self._info_misses = CAMERA_INFO_MISSES
        # The intrinsics of the last camera_infos as they came (see _camera_for).
        self._recent_cameras: 'collections.deque[Optional[CameraModel]]' = \
            collections.deque(maxlen=CAMERA_INFO_STEADY)
        self._joint_arrived = threading.Condition()
        # The oldest joint state since the history (re)started: an image before
        # it has no head angles yet and waits for the warm-up.
        self._joint_first_stamp: Optional[float] = None
        self._latest: Optional[Tuple[Image, float]] = None
        self._wake = threading.Condition()
        self._stopping = False
        self._times: Dict[str, collections.deque] = {
            k: collections.deque(maxlen=TIMES_KEPT)
            for k in ('processing', 'joint_wait', 'queue', 'in_node')}
        self._stats_lock = threading.Lock()
        self.stats = {'received': 0, 'processed': 0, 'dropped': 0, 'located': 0,
                      'refused_oversize': 0, 'clock_jumps': 0, 'odom_received': 0,
                      'located_with_odometry': 0, 'odom_bridged_published': 0, 'resets': 0}
        # Per published fix: each covariance term's share of the position variance.
        self._shares: 'collections.deque[Dict[str, float]]' = collections.deque(
            maxlen=SHARES_KEPT)
        self._position_sigmas: 'collections.deque[float]' = collections.deque(maxlen=SHARES_KEPT)
        # Targets by source and by reason; the last choice.
        self._target_counts: Dict[str, int] = collections.Counter()
        self._last_target: Optional[TargetChoice] = None
        self._bridge_state = 'no odometry yet'

        self.pub_pose = self.create_publisher(PoseStamped, 'robot_location', 10)
        self.pub_ids = self.create_publisher(UInt16MultiArray, 'robot_location/ids', 10)
        self.pub_cov = self._latched_fix_publisher()
        self.pub_bridged = self.create_publisher(PoseWithCovarianceStamped,
                                                 'robot_location/odom_bridged', 10)
        self.pub_target = self.create_publisher(PointStamped, 'pattern_locator/target', 10)
        self.pub_debug = self.create_publisher(Image, 'pattern_locator/debug_image', 1)
        self.pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self._image_sub = self._subscribe_images()
        # The worker asks the executor thread to renew the image subscription.
        self._renew_images = self.create_guard_condition(self._on_renew_images)
        self.create_subscription(CameraInfo, 'camera/camera_info', self._on_camera_info,
                                 qos_profile_sensor_data)
        # Joint states are reliable, as ROS publishes them (robot_state_publisher).
        self.create_subscription(JointState, 'camera/joint_states', self._on_joints,
                                 QoSProfile(depth=50))
        # Odometry: reliable, as nav_msgs/Odometry publishers (diff drive
        # controllers, robot_localization) publish it.
        self.create_subscription(Odometry, 'odom', self._on_odom, QoSProfile(depth=50))
        self.create_service(Trigger, '~/reset', self._on_reset)
        wall_timer(self, 1.0, self._publish_diagnostics)
        self._worker = threading.Thread(target=self._work, name='locator-worker', daemon=True)
        self._worker.start()

    def _latched_fix_publisher(self) -> Any:
        # Transient local, depth 1: a late subscriber gets the last fix.
        latched = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                             reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        return self.create_publisher(PoseWithCovarianceStamped,
                                     'robot_location/with_covariance', latched)

    def _subscribe_images(self) -> Any:
        # Best effort, like the sensor-data profile, but only the newest frame:
        # the node processes no other, and the reader keeps no backlog of
        # large frames.
        return self.create_subscription(
            Image, 'camera/image_raw', self._on_image,
            QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT))

    def _on_renew_images(self) -> None:
        """
        Give back what a burst of big frames left behind (executor thread, when idle).

        The DDS reader keeps buffers as large as the largest frame it took;
        a new reader starts small. Then the heap's free top goes back.
        """
        self.destroy_subscription(self._image_sub)
        self._image_sub = self._subscribe_images()
        self.heap.trim()
        self.stats['renewals'] = self.stats.get('renewals', 0) + 1

    # Parameters ---------------------------------------------------------------

    @staticmethod
    def _validate(values: Dict[str, Any]) -> Optional[str]:
        # Ranges and choices are checked by Parameters; the groups also check
        # their values together (a minimum below its maximum).
        gate_parameters(values)          # ConfigError: refused with its reason
        uncertainty_parameters(values)
        gaze_parameters(values)
        return None

    def _apply(self, changed: Dict[str, Any]) -> None:
        with self._settings_lock:
            self.settings.update(changed)
            s = self.settings
            locator = self.localizer.locator
            locator.estimator = s['estimator']
            locator.min_tilt_deg = float(s['min_tilt_deg'])
            self.localizer.output_frame = s['output_frame']
            self.localizer.fusion = s['fusion']
            self.localizer.max_reprojection_px = float(s['max_reprojection_px'])
            self.localizer.up_sigma = math.radians(float(s['up_sigma_deg']))
            self.localizer.camera_height_sigma = float(s['camera_height_sigma_m'])
            self.joints.max_age_s = float(s['joint_state_max_age_s'])
            if any(name.startswith('gates.') for name in changed):
                self.localizer.gates.parameters = gate_parameters(s)
            if any(name.startswith('uncertainty.') for name in changed):
                self.localizer.uncertainty = uncertainty_parameters(s)
            if any(name.startswith('gaze.') for name in changed):
                self.chooser.set_gaze(gaze_parameters(s))
            self.bridge.max_age_s = float(s['odom_bridged_max_age_s'])
            self.bridge.max_position_sigma_m = float(s['odom_bridged_max_sigma_m'])
            if 'estimator' in changed or 'output_frame' in changed:
                # A fix from the other estimator or frame is no prior for the next.
                self.localizer.last_fix = None
            if 'opencv_threads' in changed:
                cv2.setNumThreads(int(s['opencv_threads']))

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response
                  ) -> Trigger.Response:
        """Forget where the robot was (the module docstring's ``~/reset``)."""
        with self._settings_lock:            # between frames, as a parameter change
            had = self.localizer.last_fix
            self.localizer.reset()
            self.bridge.reset()
            self.chooser.reset()
            self._fix_frame = self._fix_room = None
            # The latched fix is the old place too: a subscriber that joins
            # now (a navigation stack restarted) would start from it. A new
            # publisher holds nothing until the next fix.
            self.destroy_publisher(self.pub_cov)
            self.pub_cov = self._latched_fix_publisher()
        with self._stats_lock:
            self.stats['resets'] += 1
        where = (f'the last fix (floor {had.ids.floor} room {had.ids.room} card '
                 f'{had.ids.pattern}, in {had.frame_id})' if had is not None
                 else 'nothing (no fix yet)')
        response.success = True
        response.message = f'locator reset: forgot {where}; the next fix counts as a first one'
        self.get_logger().info(response.message)
        return response

    # Callbacks (executor thread: store only) ---------------------------------------

    def _on_image(self, msg: Image) -> None:
        with self._stats_lock:
            self.stats['received'] += 1
        limit = int(self.settings['max_image_pixels'])
        try:
            pixels = int(msg.width) * int(msg.height)
            size = len(msg.data)
        except (TypeError, ValueError):
            pixels, size = 0, 0
        if pixels > limit or size > limit * MAX_BYTES_PER_PIXEL:
            with self._stats_lock:
                self.stats['refused_oversize'] += 1
            self.problems.report('oversize image', f'image refused: {msg.width}x{msg.height}, '
                                 f'{size} bytes, above max_image_pixels = {limit}')
            return
        with self._wake:
            if self._latest is not None:
                with self._stats_lock:
                    self.stats['dropped'] += 1
            self._latest = (msg, time.perf_counter())
            self._wake.notify()

    def _on_camera_info(self, msg: CameraInfo) -> None:
        key = stamp_key(msg.header.stamp)
        try:
            camera = camera_from_info(msg)
        except Exception as exc:  # noqa: B902 - any field of a foreign message can be wrong
            detail = str(exc) if isinstance(exc, PatternLocatorError) else \
                f'{type(exc).__name__}: {exc}'
            self.camera = None
            self._camera_problem = f'bad camera_info: {detail}'
            self.problems.report('camera_info', self._camera_problem)
            # The image of this stamp must not fall back on other intrinsics.
            self._remember_camera(key, None)
            return
        self.camera = camera
        self._camera_problem = ''
        self._remember_camera(key, camera)

    def _remember_camera(self, key: int, camera: Optional[CameraModel]) -> None:
        with self._info_arrived:
            self._cameras_by_stamp[key] = camera
            self._recent_cameras.append(camera)
            while len(self._cameras_by_stamp) > CAMERA_INFO_HISTORY:
                self._cameras_by_stamp.popitem(last=False)
            self._info_arrived.notify_all()

    def _on_joints(self, msg: JointState) -> None:
        try:
            pan, tilt = angles_from_joint_state(msg.name, msg.position, head=self.head,
                                                margin_rad=self.joint_margin_rad)
            stamp = stamp_seconds(msg.header.stamp)
            latest = self.joints.latest()
            if latest is not None and stamp < latest[0] - CLOCK_JUMP_S:
                # The clock went back (a bag replayed again, a simulator reset).
                self.joints.clear()
                self._joint_first_stamp = None
                # The gates restart continuity on their own when the images'
                # stamps go back: a stray joint state must not clear them.
                with self._stats_lock:
                    self.stats['clock_jumps'] += 1
                self.get_logger().info(
                    f'joint states went back {latest[0] - stamp:.1f} s in time (a replay, a '
                    'restarted simulation): head angle history restarted',
                    throttle_duration_sec=THROTTLE_S)
            self.joints.add(stamp, pan, tilt)
            if self._joint_first_stamp is None or stamp < self._joint_first_stamp:
                self._joint_first_stamp = stamp
        except PatternLocatorError as exc:
            self.problems.report('joint_states', f'joint states: {exc}')
            return
        except Exception as exc:  # noqa: B902 - any field of a foreign message can be wrong
            self.problems.report('joint_states', f'joint states: {type(exc).__name__}: {exc}')
            return
        with self._joint_arrived:
            self._joint_arrived.notify_all()

    def _on_odom(self, msg: Odometry) -> None:
        with self._stats_lock:
            self.stats['odom_received'] += 1
        try:
            stamp = stamp_seconds(msg.header.stamp)
            pose = msg.pose.pose
            q = (pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w)
            norm = math.sqrt(sum(v * v for v in q))
            if not (math.isfinite(norm) and abs(norm - 1.0) <= 0.01):
                raise PatternLocatorError(f'odometry: orientation is not a unit quaternion '
                                          f'(norm {norm:.3g})')
            T_odom_base = Pose(rotation_from_quaternion(np.array(q)),
                               np.array([pose.position.x, pose.position.y, pose.position.z]))
            linear, angular = msg.twist.twist.linear, msg.twist.twist.angular
            twist = BaseTwist((linear.x, linear.y, linear.z), (angular.x, angular.y, angular.z))
            span = self.odom.span
            if span is not None and stamp < span[1] - CLOCK_JUMP_S:
                # The clock went back (a replay): the fix carried forward is from the future.
                self.bridge.reset()
            self.odom.add(stamp, T_odom_base, covariance_from_ros(msg.pose.covariance), twist)
        except PatternLocatorError as exc:
            self.problems.report('odom', str(exc))
            return
        except Exception as exc:  # noqa: B902 - any field of a foreign message can be wrong
            self.problems.report('odom', f'odometry: {type(exc).__name__}: {exc}')
            return
        with self._odom_arrived:
            self._odom_arrived.notify_all()
        self._publish_bridged(msg.header.stamp, stamp)

    def _publish_bridged(self, ros_stamp: Any, stamp: float) -> None:
        """Publish the last fix carried forward to an odometry sample's stamp (if it may be)."""
        s = self.settings
        if not (s['use_odometry'] and s['odom_bridged']):
            self._bridge_state = 'off'
            return
        bridged = self.bridge.at(stamp)
        if bridged is None:
            self._bridge_state = self._why_not_bridged(stamp)
            return
        out = self._in_output_frame(bridged)
        if out is None:
            self._bridge_state = 'not published: non-finite pose or covariance'
            self.problems.report('rejected: non-finite odom_bridged',
                                 'odom_bridged not published: not finite')
            return
        frame_id, T, covariance = out
        msg = PoseWithCovarianceStamped()
        msg.header.stamp = ros_stamp
        msg.header.frame_id = frame_id
        fill_pose(msg.pose.pose, T)
        msg.pose.covariance = [float(v) for v in covariance.ravel()]
        self.pub_bridged.publish(msg)
        sigma = math.sqrt(max(float(np.max(np.linalg.eigvalsh(covariance[:3, :3]))), 0.0))
        self._bridge_state = f'publishing: fix {bridged.age_s:.1f} s old, sigma {sigma:.3f} m'
        with self._stats_lock:
            self.stats['odom_bridged_published'] += 1

    def _why_not_bridged(self, stamp: float) -> str:
        """Return why the bridge has no pose at ``stamp`` (for the diagnostics)."""
        fix_stamp = self.bridge.fix_stamp_s
        if fix_stamp is None:
            return 'waiting for a fix'
        if abs(stamp - fix_stamp) > self.bridge.max_age_s:
            return (f'stopped: the fix is {stamp - fix_stamp:.1f} s old (limit '
                    f'{self.bridge.max_age_s:g} s)')
        if self.odom.motion_between(fix_stamp, stamp) is None:
            return 'stopped: no odometry around the fix'
        return (f'stopped: position sigma above {self.bridge.max_position_sigma_m:g} m')

    def _in_output_frame(self, bridged: BridgedPose
                         ) -> Optional[Tuple[str, Pose, np.ndarray]]:
        """Return a bridged pose in robot_location's frame (the last fix's room, or building)."""
        T, covariance, frame_id = bridged.T_frame_base, bridged.covariance, bridged.frame_id
        room_frame = self._fix_frame
        if self.settings['output_frame'] == 'room' and room_frame and room_frame != frame_id:
            room = self.building.room_by_frame(room_frame)
            R = room.T_building_room.R.T
            J = np.zeros((6, 6))
            J[:3, :3] = R
            J[3:, 3:] = R
            T = room.T_building_room.inverse() @ T
            covariance = J @ covariance @ J.T
            frame_id = room_frame
        if not (all_finite(np.ravel(T.t)) and all_finite(np.ravel(T.R))
                and all_finite(np.ravel(covariance))):
            return None
        return frame_id, T, covariance

    # Work (its own thread) ------------------------------------------------------------

    def _work(self) -> None:
        large = False
        while True:
            with self._wake:
                while self._latest is None and not self._stopping:
                    if not self._wake.wait(0.5) and large:
                        # Idle after big frames: give their buffers back.
                        self._renew_images.trigger()
                        large = False
                if self._stopping:
                    return
                (msg, arrival), self._latest = self._latest, None
            large = large or len(msg.data) > LARGE_FRAME_BYTES
            try:
                self._process(msg, arrival)
            except PatternLocatorError as exc:
                self.problems.report('image', str(exc))
            except Exception as exc:  # noqa: B902 - the node must outlive any one frame
                if not self.context.ok():
                    return                   # Ctrl-C shut the context down mid-frame
                self.problems.report('unexpected', f'unexpected {type(exc).__name__}: {exc}')
            finally:
                del msg

    def _process(self, msg: Image, arrival: float) -> None:
        started = time.perf_counter()
        with self._stats_lock:
            self.stats['processed'] += 1
        self._times['queue'].append((started - arrival) * 1000.0)
        camera = self._camera_for(stamp_key(msg.header.stamp))
        if isinstance(camera, str):
            self.problems.report('camera_info', camera)
            return
        if camera is None:
            self.problems.report('camera_info', self._camera_problem)
            return
        if (camera.width, camera.height) != (msg.width, msg.height):
            self.problems.report('image', f'camera_info is for {camera.width}x{camera.height} '
                                 f'but the image is {msg.width}x{msg.height}')
            return
        image = image_from_msg(msg)          # a view of the message: the detector only reads
        stamp = stamp_seconds(msg.header.stamp)
        waited = time.perf_counter()
        motion = self._head_motion(msg)
        if motion is not None:
            self._wait_for_odometry(stamp)
        waited = time.perf_counter() - waited
        self._times['joint_wait'].append(waited * 1000.0)
        if motion is None:
            return
        with self._settings_lock:
            odometry = twist = None
            if self.settings['use_odometry']:
                last = self.localizer.last_fix_stamp
                if last is not None:
                    odometry = self.odom.motion_between(last, stamp)
                twist = self.odom.twist_at(stamp)
            result = self.localizer.process(image, camera, motion.pan, motion.tilt, stamp,
                                            odometry, motion, twist)
            self._publish(msg, result, image, camera, motion, twist,
                          odometry is not None)
        for problem, reason in zip(result.problems, rejection_reasons(result)):
            self.problems.report(f'rejected: {reason}', problem)
        done = time.perf_counter()
        # The node's own work, apart from the wait for a later joint state;
        # and the whole stay of the image in the node (queue + wait + work).
        self._times['processing'].append((done - started - waited) * 1000.0)
        self._times['in_node'].append((done - arrival) * 1000.0)

    def _camera_for(self, key: int):
        """
        Return the intrinsics of an image's stamp: its own, else the latest (None: none).

        A string (why there is no location) when its own camera_info was
        refused, and when it did not come while the intrinsics change. While
        camera_info comes with the images' stamps (a driver publishing both),
        an image that overtook its own camera_info waits a little for it: a
        zoom camera's previous intrinsics would be wrong for it (a focal
        length 11 % off put a fix 27 cm out along the line of sight, its
        covariance saying 3 mm).
        Should it not come, the latest serve only if the last few agree.
        """
        deadline = time.monotonic() + CAMERA_INFO_WAIT_S
        with self._info_arrived:
            while key not in self._cameras_by_stamp and self._info_misses < CAMERA_INFO_MISSES:
                remaining = deadline - time.monotonic()
                if remaining <= 0.0 or self._stopping:
                    break
                self._info_arrived.wait(remaining)
            if key in self._cameras_by_stamp:
                self._info_misses = 0
                camera = self._cameras_by_stamp[key]
                return ('no location for an image whose own camera_info was refused'
                        if camera is None else camera)
            self._info_misses = min(self._info_misses + 1, CAMERA_INFO_MISSES)
            recent = list(self._recent_cameras)
        if any(not _same_intrinsics(c, recent[-1]) for c in recent):
            return (f"no location: the image's own camera_info did not come within "
                    f'{CAMERA_INFO_WAIT_S * 1000.0:.0f} ms and the intrinsics are changing '
                    f'(a zooming camera): the latest would be wrong for it')
        return self.camera

    def _head_motion(self, msg: Image) -> Optional[HeadMotion]:
        """Return the head's angles and rates at the image's stamp (None: not known)."""
        s = self.settings
        if not s['use_joint_states']:
            return HeadMotion.still(math.radians(s['fixed_pan_deg']),
                                    math.radians(s['fixed_tilt_deg']))
        stamp = stamp_seconds(msg.header.stamp)
        # An image can overtake the joint state taken just after it: wait a
        # little for a sample on its far side rather than hold an old one.
        # With no history around the image (at start; after the clock went
        # back, before the new joint states came) wait longer: the first
        # joint state is on its way (a replay publishes it first).
        start = time.monotonic()
        short = start + float(s['joint_state_wait_s'])
        long = start + max(float(s['joint_state_warmup_s']), float(s['joint_state_wait_s']))
        with self._joint_arrived:
            while True:
                latest = self.joints.latest()
                first = self._joint_first_stamp
                covered = latest is not None and first is not None and first <= stamp
                now = time.monotonic()
                if covered and latest[0] >= stamp:
                    break
                if (covered and now >= short) or now >= long or self._stopping:
                    break
                if not covered and self._latest is not None:
                    # A newer frame is waiting: it has better chances (a live
                    # camera whose driver is not publishing yet).
                    break
                self._joint_arrived.wait((short if covered else long) - now)
        try:
            return self.joints.motion_at(stamp)
        except PatternLocatorError as exc:
            self.problems.report('head angles', str(exc))
            return None

    def _wait_for_odometry(self, stamp: float) -> None:
        """
        Wait up to ``odom_wait_s`` for an odometry sample at or after the image's stamp.

        Only while odometry flows (its newest sample less than a second
        before the image): without odometry nothing is waited for.
        """
        s = self.settings
        if not s['use_odometry']:
            return
        deadline = time.monotonic() + float(s['odom_wait_s'])
        with self._odom_arrived:
            while True:
                span = self.odom.span
                if span is None or span[1] >= stamp or stamp - span[1] > ODOM_FLOWING_S:
                    return
                remaining = deadline - time.monotonic()
                if remaining <= 0.0 or self._stopping:
                    return
                self._odom_arrived.wait(remaining)

    # Output ---------------------------------------------------------------------

    def _choose_target(self, result: FrameResult, camera: CameraModel, motion: HeadMotion,
                       stamp: float, twist: Optional[BaseTwist]) -> TargetChoice:
        """Return the image's target: the gaze planner's card, else the biggest card seen."""
        seen, biggest_lost = seen_cards(result, camera, self.building)
        if biggest_lost:
            self.problems.report('rejected: non-finite target',
                                 'no target from the biggest card: its centre is not finite')
        s = self.settings
        if not s['use_gaze']:
            self.chooser.reset()
            return biggest_seen(seen, 'gaze off')
        pose = None
        if s['use_odometry']:
            bridged = self.bridge.at(stamp)
            if bridged is not None:
                pose = bridged.T_frame_base
        return self.chooser.choose(stamp, seen, pose, motion.pan, motion.tilt, twist,
                                   self._fix_room, camera)

    def _publish(self, msg: Image, result: FrameResult, image: np.ndarray,
                 camera: CameraModel, motion: HeadMotion, twist: Optional[BaseTwist],
                 with_odometry: bool) -> None:
        header = msg.header
        stamp = stamp_seconds(header.stamp)
        fix = result.fix
        if fix is not None:
            covariance = np.asarray(fix.covariance, dtype=float)
            ids = tuple(fix.ids.as_tuple())
            problem = _unpublishable(fix, covariance, ids)
            if problem:
                self.problems.report(f'rejected: {problem}', f'fix not published: {problem}')
            else:
                # Carried forward from here by odometry (odom_bridged, the gaze).
                self.bridge.update(fix, stamp)
                self._fix_frame = self.building.room(ids[0], ids[1]).frame
                self._fix_room = (ids[0], ids[1])
                # The fix first: the target's choice and the debug image cost
                # milliseconds that would add to its latency.
                self._publish_fix(header, fix, covariance, ids, with_odometry)
        choice = self._choose_target(result, camera, motion, stamp, twist)
        self._count_target(choice)
        if choice.point is not None:
            if all_finite(choice.point):
                target = PointStamped()
                target.header.stamp = header.stamp
                target.header.frame_id = header.frame_id or 'camera_optical_frame'
                target.point.x, target.point.y, target.point.z = choice.point
                self.pub_target.publish(target)
            else:
                self.problems.report('rejected: non-finite target',
                                     'no target published: the card centre is not finite')
        if self.pub_debug.get_subscription_count() > 0:
            self._publish_debug(msg, result, image)

    def _publish_fix(self, header, fix, covariance: np.ndarray, ids: Tuple[int, ...],
                     with_odometry: bool) -> None:
        """Publish a fix: its ids, its pose with covariance, its pose."""
        with self._stats_lock:
            self.stats['located'] += 1
            if with_odometry:
                self.stats['located_with_odometry'] += 1
        self._record_terms(fix)
        pose = PoseStamped()
        pose.header.stamp = header.stamp
        pose.header.frame_id = fix.frame_id
        fill_pose(pose.pose, fix.T_frame_base)
        with_cov = PoseWithCovarianceStamped()
        with_cov.header = pose.header
        with_cov.pose.pose = pose.pose
        with_cov.pose.covariance = [float(v) for v in covariance.ravel()]
        ids_msg = UInt16MultiArray()
        ids_msg.layout.dim = [MultiArrayDimension(label=name, size=1, stride=1)
                              for name in ('floor', 'room', 'pattern')]
        ids_msg.data = [int(v) for v in ids]
        self.pub_ids.publish(ids_msg)
        self.pub_cov.publish(with_cov)
        self.pub_pose.publish(pose)

    def _count_target(self, choice: TargetChoice) -> None:
        with self._stats_lock:
            self._target_counts[choice.source] += 1
            self._target_counts[choice.reason] += 1
            self._last_target = choice

    def _record_terms(self, fix: RobotFix) -> None:
        """Keep each covariance term's share of a published fix's position variance."""
        total = np.asarray(fix.covariance, dtype=float)[:3, :3]
        trace = float(np.trace(total))
        with self._stats_lock:
            self._position_sigmas.append(math.sqrt(max(trace, 0.0)))
            if fix.uncertainty is None or not trace > 0.0:
                return
            self._shares.append({name: float(np.trace(term[:3, :3])) / trace
                                 for name, term in fix.uncertainty.terms.items()})

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
        counts, last = self.problems.snapshot()
        status = DiagnosticStatus()
        status.name = 'pattern_locator: locator'
        camera = self.camera
        status.hardware_id = camera.name[:80] if camera else 'camera'
        ok = camera is not None
        status.level = DiagnosticStatus.OK if ok else DiagnosticStatus.WARN
        status.message = 'running' if ok else self._camera_problem[:200]
        values = dict(s)
        values['rejected'] = sum(counts.values())
        values.update({f'gate_rejected_{reason}': n
                       for reason, n in self.localizer.rejection_counts().items()})
        values['last_problem'] = last
        values['estimator'] = self.localizer.locator.estimator
        values['output_frame'] = self.localizer.output_frame
        values.update(self._odometry_values())
        values.update(self._uncertainty_values())
        values.update(self._target_values())
        for name, series in self._times.items():
            values.update(_timing(name, series))
        values.update({f'problems: {k}': v for k, v in sorted(counts.items())})
        status.values = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
        array = DiagnosticArray()
        array.header.stamp = self.get_clock().now().to_msg()
        array.status = [status]
        self.pub_diag.publish(array)

    def _odometry_values(self) -> Dict[str, str]:
        """Return the diagnostics of the odometry and of odom_bridged."""
        span = self.odom.span
        if not self.settings['use_odometry']:
            state = 'off (use_odometry false)'
        elif span is None:
            state = 'none received'
        else:
            state = f'{len(self.odom)} samples over {span[1] - span[0]:.1f} s'
        return {'odometry': state, 'odom_bridged': self._bridge_state}

    def _uncertainty_values(self) -> Dict[str, str]:
        """
        Return each covariance term's median share of the position variance over recent fixes.

        The shares of one fix add up to 1: the term with the largest share
        is what limits the fixes (uncertainty.* sets its size).
        """
        with self._stats_lock:
            shares = list(self._shares)
            sigmas = sorted(self._position_sigmas)
        values = {'position_sigma_mm_median': f'{1000.0 * sigmas[len(sigmas) // 2]:.2f}'
                  if sigmas else 'n/a'}
        for term in TERMS:
            column = sorted(f.get(term, 0.0) for f in shares)
            values[f'uncertainty_share_{term}'] = (f'{column[len(column) // 2]:.3f}'
                                                   if column else 'n/a')
        return values

    def _target_values(self) -> Dict[str, str]:
        """Return the last target's card, source and reason, and the counts of each."""
        with self._stats_lock:
            counts = dict(self._target_counts)
            last = self._last_target
        values = {'target_card': 'none' if last is None or last.ids is None
                  else '/'.join(str(v) for v in last.ids),
                  'target_source': 'n/a' if last is None else last.source,
                  'target_reason': 'n/a' if last is None else last.reason,
                  'gaze_excluded': ' '.join('/'.join(str(v) for v in ids)
                                            for ids in self.chooser.excluded) or 'none'}
        values.update({f'targets: {k}': str(v) for k, v in sorted(counts.items())})
        return values

    def stop(self) -> None:
        """Stop the worker thread."""
        with self._wake:
            self._stopping = True
            self._wake.notify()
        for condition in (self._joint_arrived, self._info_arrived, self._odom_arrived):
            with condition:
                condition.notify_all()
        self._worker.join(timeout=2.0)


def _timing(name: str, series: 'collections.deque') -> Dict[str, str]:
    """Return median, p95 and max of a series of milliseconds, as diagnostics values."""
    values = sorted(series)
    if not values:
        return {f'{name}_ms_median': 'n/a'}
    return {f'{name}_ms_median': f'{values[len(values) // 2]:.2f}',
            f'{name}_ms_p95': f'{values[min(len(values) - 1, int(0.95 * len(values)))]:.2f}',
            f'{name}_ms_max': f'{values[-1]:.2f}'}


def _unpublishable(fix: Any, covariance: np.ndarray, ids: Tuple[int, ...]) -> str:
    """Return why a fix must not be published (the node's last guard), or ''."""
    T = fix.T_frame_base
    if not (all_finite(np.ravel(T.t)) and all_finite(np.ravel(T.R))):
        return 'non-finite pose'
    if covariance.shape != (6, 6) or not all_finite(covariance.ravel()):
        return 'non-finite covariance'
    if len(ids) != 3 or not all(isinstance(v, (int, np.integer)) and 0 <= v <= 65535
                                for v in ids):
        return 'ids out of range'
    if not isinstance(fix.frame_id, str) or not fix.frame_id:
        return 'no frame'
    return ''


def main(args=None) -> None:
    run_node(LocatorNode, 'locator', args)


if __name__ == '__main__':
    main()
