"""
Reading a survey bag: its topics, camera_info, odometry, head angles, static transforms, images.

Bags are rosbag2 directories (MCAP or sqlite3), read with ``rosbags`` and
its ROS 2 Jazzy type store, so no ROS install is needed. :func:`scan_bag`
reads everything but the images in one pass and checks the bag is usable;
:func:`iter_images` then streams the images' serialized bytes (decoded in
the detection workers, so the main process never holds more than a few).

Every problem with a bag is a :class:`~pattern_locator.errors.ConfigError`
naming the bag and the problem in one line: no such bag, an unknown topic
asked for, no camera_info, no images, corrupt data (a damaged chunk or an
undecodable message).
"""

from dataclasses import dataclass, field
import math
from pathlib import Path
import struct
from typing import Dict, Iterator, List, Optional, Sequence, Tuple

import numpy as np
from rosbags.rosbag2 import Reader
from rosbags.typesys import get_typestore, Stores

from ..errors import ConfigError, PatternLocatorError
from ..localization.head import angles_from_joint_state, HeadGeometry
from ..vision.camera import CameraModel
from ..vision.geometry import Pose, rodrigues, rotation_from_quaternion

IMAGE_TOPIC = '/camera/image_raw'
INFO_TOPIC = '/camera/camera_info'
ODOM_TOPIC = '/odom'
JOINTS_TOPIC = '/camera/joint_states'
TF_STATIC_TOPIC = '/tf_static'
IMAGE_TYPE = 'sensor_msgs/msg/Image'
INFO_TYPE = 'sensor_msgs/msg/CameraInfo'
ODOM_TYPE = 'nav_msgs/msg/Odometry'
JOINTS_TYPE = 'sensor_msgs/msg/JointState'
TF_TYPE = 'tf2_msgs/msg/TFMessage'
# Odometry is interpolated to an image's stamp across gaps no longer than this.
MAX_ODOM_GAP_S = 0.5
MAX_JOINT_GAP_S = 0.5

_TYPESTORE = None


def typestore():
    """Build the ROS 2 Jazzy type store once per process and return it."""
    global _TYPESTORE
    if _TYPESTORE is None:
        _TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
    return _TYPESTORE


@dataclass(frozen=True)
class SurveyTopics:
    """The topics to read; None: the default name if the bag has it, else its only one."""

    image: Optional[str] = None
    camera_info: Optional[str] = None
    odom: Optional[str] = None
    joint_states: Optional[str] = None


@dataclass(frozen=True, eq=False)
class Mount:
    """
    Where the camera sits on the odometry's base frame, and how that was decided.

    ``fixed``: a static ``T_base_camera``; ``head``: the project's pan/tilt
    head (``HeadGeometry``) at the recorded joint angles; ``source`` says
    which: ``tf_static``, ``--camera-mount``, ``joint_states`` or ``camera``
    (no mount: the odometry is the camera's own).
    """

    source: str
    fixed: Optional[Pose] = None
    head: Optional[HeadGeometry] = None


@dataclass(frozen=True, eq=False)
class BagData:
    """What a bag holds besides its images (read by :func:`scan_bag`)."""

    path: str
    image_topic: str
    info_topic: str
    odom_topic: Optional[str]
    joints_topic: Optional[str]
    n_images: int
    info_stamps_ns: np.ndarray
    cameras: Tuple[CameraModel, ...]
    odom_stamps_ns: Optional[np.ndarray] = None
    odom_poses: Tuple[Pose, ...] = ()
    base_frame: str = ''
    camera_frame: str = ''
    joint_stamps_ns: Optional[np.ndarray] = None
    joint_angles: Optional[np.ndarray] = None          # (N, 2) pan, tilt (rad)
    tf_static: Dict[str, Tuple[str, Pose]] = field(default_factory=dict)

    def camera_at(self, stamp_ns: int) -> CameraModel:
        """Return the camera_info of this stamp, else the latest before it, else the first."""
        i = int(np.searchsorted(self.info_stamps_ns, stamp_ns, side='right')) - 1
        return self.cameras[max(i, 0)]

    def odometry_at(self, stamp_ns: int) -> Optional[Pose]:
        """Return ``T_odom_base`` interpolated to a stamp; None outside or across a gap."""
        if self.odom_stamps_ns is None:
            return None
        return _interpolate(self.odom_stamps_ns, self.odom_poses, stamp_ns, MAX_ODOM_GAP_S)

    def head_angles_at(self, stamp_ns: int) -> Optional[Tuple[float, float]]:
        """Return (pan, tilt) interpolated to a stamp; None outside or across a gap."""
        stamps = self.joint_stamps_ns
        if stamps is None or not len(stamps):
            return None
        i = int(np.searchsorted(stamps, stamp_ns, side='left'))
        if i < len(stamps) and stamps[i] == stamp_ns:
            return tuple(float(v) for v in self.joint_angles[i])
        if i == 0 or i == len(stamps) or (stamps[i] - stamps[i - 1]) * 1e-9 > MAX_JOINT_GAP_S:
            return None
        w = (stamp_ns - stamps[i - 1]) / (stamps[i] - stamps[i - 1])
        a, b = self.joint_angles[i - 1], self.joint_angles[i]
        return float(a[0] + w * (b[0] - a[0])), float(a[1] + w * (b[1] - a[1]))

    def static_transform(self, parent: str, child: str) -> Optional[Pose]:
        """Return ``T_parent_child`` from the bag's /tf_static chain, None if it has none."""
        if not parent or not child:
            return None
        if parent == child:
            return Pose.identity()
        T = Pose.identity()
        frame, seen = child, set()
        while frame in self.tf_static and frame not in seen:
            seen.add(frame)
            up, T_up_frame = self.tf_static[frame]
            T = T_up_frame @ T
            if up == parent:
                return T
            frame = up
        return None


def _interpolate(stamps: np.ndarray, poses: Sequence[Pose], stamp_ns: int, max_gap_s: float
                 ) -> Optional[Pose]:
    i = int(np.searchsorted(stamps, stamp_ns, side='left'))
    if i < len(stamps) and stamps[i] == stamp_ns:
        return poses[i]
    if i == 0 or i == len(stamps) or (stamps[i] - stamps[i - 1]) * 1e-9 > max_gap_s:
        return None
    w = (stamp_ns - stamps[i - 1]) / (stamps[i] - stamps[i - 1])
    a, b = poses[i - 1], poses[i]
    step = a.inverse() @ b
    return a @ Pose(rodrigues(w * step.rvec()), w * step.t)


def resolve_mount(bag: BagData, camera_mount: Optional[Sequence[float]] = None,
                  head: Optional[HeadGeometry] = None) -> Mount:
    """
    Decide where the camera sits on the odometry's base.

    In this order: the bag's /tf_static chain from the odometry's child frame
    to the camera_info's frame; ``camera_mount`` (x y z roll pitch yaw, m and
    rad, as ``--camera-mount``); the head's joint angles with the project's
    pan/tilt head (``head``, default geometry); else none (the odometry is
    the camera's own).
    """
    T = bag.static_transform(bag.base_frame, bag.camera_frame)
    if T is not None and bag.odom_topic is not None:
        return Mount('tf_static', fixed=T)
    if camera_mount is not None:
        return Mount('--camera-mount', fixed=mount_from_xyzrpy(camera_mount))
    if bag.joints_topic is not None and bag.joint_stamps_ns is not None and len(
            bag.joint_stamps_ns):
        return Mount('joint_states', head=head or HeadGeometry())
    return Mount('camera', fixed=Pose.identity())


def mount_from_xyzrpy(values: Sequence[float]) -> Pose:
    """Return the pose of ``x y z roll pitch yaw`` (m, rad; R = Rz Ry Rx as ROS)."""
    from ..localization.building import rpy_rotation
    values = [float(v) for v in values]
    if len(values) != 6 or not all(math.isfinite(v) for v in values):
        raise ConfigError(f'--camera-mount needs six finite numbers x y z roll pitch yaw, got '
                          f'{values!r}')
    return Pose(rpy_rotation(*values[3:]), np.array(values[:3]))


def camera_on_base(bag: BagData, mount: Mount, stamp_ns: int) -> Optional[Pose]:
    """Return ``T_base_camera`` at an image's stamp; None when the head's angles are unknown."""
    if mount.fixed is not None:
        return mount.fixed
    angles = bag.head_angles_at(stamp_ns)
    if angles is None:
        return None
    return mount.head.T_base_camera(*angles)


# Scanning ------------------------------------------------------------------------------


def open_reader(path: Path) -> Reader:
    """Return an open rosbags Reader; ConfigError when it is not a readable rosbag2 bag."""
    if not path.exists():
        raise ConfigError(f'{path}: no such bag')
    if path.is_dir() and not (path / 'metadata.yaml').is_file():
        raise ConfigError(f'{path}: not a rosbag2 bag (no metadata.yaml in the directory)')
    try:
        reader = Reader(path)
        reader.open()
    except Exception as exc:  # noqa: B902 - rosbags raises many kinds on a damaged bag
        raise ConfigError(f'{path}: not a readable rosbag2 bag ({_why(exc)})') from None
    return reader


def _why(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return f'{type(exc).__name__}: {text[0]}' if text else type(exc).__name__


def _choose(path: Path, topics: Dict[str, str], asked: Optional[str], default: str,
            msgtype: str, what: str, required: bool) -> Optional[str]:
    """Return the topic to read for one role; ConfigError for an unknown or wrong one."""
    listing = ', '.join(f'{t} ({ty})' for t, ty in sorted(topics.items())) or 'none'
    if asked is not None:
        if asked not in topics:
            raise ConfigError(f'{path}: unknown topic {asked} (the bag has {listing})')
        if topics[asked] != msgtype:
            raise ConfigError(f'{path}: topic {asked} is {topics[asked]}, not {msgtype} '
                              f'({what})')
        return asked
    if topics.get(default) == msgtype:
        return default
    of_type = sorted(t for t, ty in topics.items() if ty == msgtype)
    if len(of_type) == 1:
        return of_type[0]
    if len(of_type) > 1:
        raise ConfigError(f'{path}: several {what} topics ({", ".join(of_type)}): choose one '
                          f'with the {what} topic option')
    if required:
        raise ConfigError(f'{path}: no {what} in the bag (no {msgtype} topic; it has {listing})')
    return None


def scan_bag(path, topics: SurveyTopics = SurveyTopics()) -> BagData:
    """Read a bag's camera_info, odometry, joint states and /tf_static; check it has images."""
    path = Path(path)
    reader = open_reader(path)
    try:
        types = {}
        for c in reader.connections:
            types.setdefault(c.topic, c.msgtype)
        counts = {t: info.msgcount for t, info in reader.topics.items()}
        image = _choose(path, types, topics.image, IMAGE_TOPIC, IMAGE_TYPE, 'image', True)
        info = _choose(path, types, topics.camera_info, INFO_TOPIC, INFO_TYPE, 'camera_info',
                       True)
        odom = _choose(path, types, topics.odom, ODOM_TOPIC, ODOM_TYPE, 'odometry', False)
        joints = _choose(path, types, topics.joint_states, JOINTS_TOPIC, JOINTS_TYPE,
                         'joint_states', False)
        if not counts.get(image):
            raise ConfigError(f'{path}: no images (topic {image} has no messages)')
        if not counts.get(info):
            raise ConfigError(f'{path}: no camera_info (topic {info} has no messages)')
        wanted = {info, TF_STATIC_TOPIC} | ({odom} if odom else set()) | (
            {joints} if joints else set())
        connections = [c for c in reader.connections if c.topic in wanted
                       and (c.topic != TF_STATIC_TOPIC or c.msgtype == TF_TYPE)]
        ts = typestore()
        info_stamps, cameras = [], []
        odom_stamps, odom_poses = [], []
        joint_stamps, joint_angles = [], []
        tf_static: Dict[str, Tuple[str, Pose]] = {}
        base_frame = camera_frame = ''
        try:
            for connection, _, raw in reader.messages(connections=connections):
                msg = ts.deserialize_cdr(raw, connection.msgtype)
                if connection.topic == info:
                    info_stamps.append(_stamp(msg.header))
                    cameras.append(_camera(path, msg))
                    camera_frame = camera_frame or msg.header.frame_id
                elif connection.topic == odom:
                    odom_stamps.append(_stamp(msg.header))
                    odom_poses.append(_pose(msg.pose.pose))
                    base_frame = base_frame or msg.child_frame_id
                elif connection.topic == joints:
                    try:
                        angles = angles_from_joint_state(list(msg.name), list(msg.position))
                    except PatternLocatorError:
                        continue            # no head joints in this message
                    joint_stamps.append(_stamp(msg.header))
                    joint_angles.append(angles)
                else:
                    for t in msg.transforms:
                        tf_static[t.child_frame_id.lstrip('/')] = (
                            t.header.frame_id.lstrip('/'), _transform(t.transform))
        except PatternLocatorError:
            raise
        except Exception as exc:  # noqa: B902 - a damaged chunk or record, of any kind
            raise ConfigError(f'{path}: corrupt data ({_why(exc)})') from None
    finally:
        reader.close()
    order = np.argsort(info_stamps, kind='stable')
    data = {'path': str(path), 'image_topic': image, 'info_topic': info, 'odom_topic': None,
            'joints_topic': None, 'n_images': int(counts[image]),
            'info_stamps_ns': np.asarray(info_stamps, dtype=np.int64)[order],
            'cameras': tuple(cameras[i] for i in order), 'tf_static': tf_static,
            'camera_frame': camera_frame.lstrip('/')}
    if odom and odom_stamps:
        stamps, poses = _sorted_unique(odom_stamps, odom_poses)
        data.update(odom_topic=odom, odom_stamps_ns=stamps, odom_poses=poses,
                    base_frame=base_frame.lstrip('/'))
    if joints and joint_stamps:
        stamps, angles = _sorted_unique(joint_stamps, joint_angles)
        data.update(joints_topic=joints, joint_stamps_ns=stamps,
                    joint_angles=np.asarray(angles, dtype=float).reshape(-1, 2))
    return BagData(**data)


def _sorted_unique(stamps: List[int], values: List) -> Tuple[np.ndarray, tuple]:
    stamps = np.asarray(stamps, dtype=np.int64)
    order = np.argsort(stamps, kind='stable')
    keep = np.ones(len(order), dtype=bool)
    keep[1:] = np.diff(stamps[order]) > 0
    order = order[keep]
    return stamps[order], tuple(values[i] for i in order)


def _stamp(header) -> int:
    return int(header.stamp.sec) * 10 ** 9 + int(header.stamp.nanosec)


def _pose(p) -> Pose:
    q = np.array([p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w])
    if not np.all(np.isfinite(q)) or np.linalg.norm(q) < 1e-9:
        q = np.array([0.0, 0.0, 0.0, 1.0])
    return Pose(rotation_from_quaternion(q), np.array([p.position.x, p.position.y,
                                                       p.position.z]))


def _transform(t) -> Pose:
    q = np.array([t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w])
    if not np.all(np.isfinite(q)) or np.linalg.norm(q) < 1e-9:
        q = np.array([0.0, 0.0, 0.0, 1.0])
    return Pose(rotation_from_quaternion(q), np.array([t.translation.x, t.translation.y,
                                                       t.translation.z]))


def _camera(path: Path, msg) -> CameraModel:
    from ..nodes.image_codec import camera_from_info
    try:
        return camera_from_info(msg)
    except PatternLocatorError as exc:
        raise ConfigError(f'{path}: unusable camera_info ({exc})') from None


# Images --------------------------------------------------------------------------------


def image_stamp(raw: bytes) -> int:
    """
    Return the header stamp of a serialized sensor_msgs/Image without decoding it.

    CDR: a 4-byte encapsulation header (byte 1: 0 big-endian, 1 little-endian),
    then ``header.stamp.sec`` (int32) and ``nanosec`` (uint32).
    """
    if len(raw) < 12:
        raise ConfigError('an image message is too short to hold a header')
    order = '<' if raw[1] & 1 else '>'
    sec, nanosec = struct.unpack_from(order + 'iI', raw, 4)
    return sec * 10 ** 9 + nanosec


def iter_images(bag: BagData) -> Iterator[Tuple[int, int, bytes]]:
    """Yield (index, header stamp ns, serialized image) in recorded order."""
    path = Path(bag.path)
    reader = open_reader(path)
    try:
        connections = [c for c in reader.connections if c.topic == bag.image_topic]
        index = 0
        messages = reader.messages(connections=connections)
        while True:
            try:
                item = next(messages)
            except StopIteration:
                break
            except Exception as exc:  # noqa: B902 - a damaged chunk, of any kind
                raise ConfigError(f'{path}: corrupt data in the images ({_why(exc)})') from None
            raw = bytes(item[2])
            yield index, image_stamp(raw), raw
            index += 1
    finally:
        reader.close()


def decode_image(raw: bytes, topic: str = IMAGE_TOPIC) -> np.ndarray:
    """Return the BGR or grey image of a serialized sensor_msgs/Image; ConfigError if bad."""
    from ..nodes.image_codec import image_from_msg
    try:
        msg = typestore().deserialize_cdr(raw, IMAGE_TYPE)
    except Exception as exc:  # noqa: B902 - any failure means a bad record
        raise ConfigError(f'{topic}: an image does not deserialize ({_why(exc)})') from None
    return image_from_msg(msg)
