"""
``bag record-sim --survey``: render a survey walk into a rosbag2 bag, with its truth.

The walk (``sim.walk``) goes through the paper's room and the corridor in
front of it (or any :class:`~pattern_locator.sim.walk.FloorPlan`), the cards
hung "as hung" (off the plan by up to 5 cm and 3 degrees). The bag holds:

* ``/camera/image_raw`` (bgr8) and ``/camera/camera_info`` per frame;
* ``/odom`` (nav_msgs/Odometry, ``odom`` -> ``base_link``) at twice the
  frame rate, with a scale error, a yaw bias and noise
  (``walk.OdometryDrift``);
* ``/tf_static``: ``base_link`` -> ``camera_optical_frame`` (the mount);
* ``/sim/true_pose``: the true base pose in the building frame per frame.

Beside them in the bag directory, ``truth.yaml`` is a building map of the
cards as hung (the truth) and ``plan.yaml`` the nominal map they were hung
from. Both load with ``load_building``.
"""

import json
from pathlib import Path
import shutil
from typing import Optional, Union

import numpy as np
from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer, WriterError

from .bagio import (IMAGE_TOPIC, INFO_TOPIC, JOINTS_TOPIC, ODOM_TOPIC, TF_STATIC_TOPIC,
                    typestore)
from .mapfile import building_yaml, room_frames, truth_cards, write_text
from ..card.pattern import load_pattern_config
from ..errors import ConfigError
from ..nodes.image_codec import encode_image
from ..sim.walk import (drift_odometry, FloorPlan, make_walk, OdometryDrift, room_corridor_plan,
                        Walk, WalkRenderer)
from ..vision.camera import CameraModel
from ..vision.geometry import Pose, quaternion_xyzw

TRUTH_TOPIC = '/sim/true_pose'
SURVEY_TOPICS = {
    IMAGE_TOPIC: 'sensor_msgs/msg/Image',
    INFO_TOPIC: 'sensor_msgs/msg/CameraInfo',
    ODOM_TOPIC: 'nav_msgs/msg/Odometry',
    TF_STATIC_TOPIC: 'tf2_msgs/msg/TFMessage',
    TRUTH_TOPIC: 'geometry_msgs/msg/PoseStamped',
}
OPTICAL_FRAME = 'camera_optical_frame'
BASE_FRAME = 'base_link'
ODOM_FRAME = 'odom'
START_NS = 1_700_000_000 * 10 ** 9 + 41_234_567
# Recording latency (bag time - header stamp) of each topic.
_LATENCY_NS = {INFO_TOPIC: 2_000_000, IMAGE_TOPIC: 4_000_000, ODOM_TOPIC: 1_000_000,
               TRUTH_TOPIC: 1_000_000, TF_STATIC_TOPIC: 0, JOINTS_TOPIC: 1_000_000}


def default_survey_camera() -> CameraModel:
    """
    Return the survey camera: 1280x720 with a 90 degree horizontal field of view.

    Wide, so that one image holds two cards of a room (what ties them
    together without odometry); f = 640 px, more than the 640x480 60 degree
    camera's 554 px.
    """
    return CameraModel.from_fov(1280, 720, 90.0, name='survey_camera')


def record_survey(out_dir: Union[str, Path], plan: Optional[FloorPlan] = None,
                  walk: Optional[Walk] = None, frames: Optional[int] = None,
                  rate_hz: float = 10.0, drift: OdometryDrift = OdometryDrift(),
                  camera: Optional[CameraModel] = None, seed: int = 1,
                  storage: str = 'mcap', with_tf_static: bool = True,
                  with_odometry: bool = True, progress: bool = True) -> Path:
    """
    Render a survey walk into a new bag directory; return its path.

    ``frames``: stop after this many images (default: the whole walk).
    ``storage``: ``mcap`` (zstd chunks) or ``sqlite3``. Without
    ``with_tf_static`` the mount is left for ``--camera-mount``.
    """
    from tqdm import tqdm
    out_dir = Path(out_dir)
    if out_dir.exists():
        raise ConfigError(f'{out_dir}: exists already, not overwriting')
    if storage not in ('mcap', 'sqlite3'):
        raise ConfigError(f'record-sim: storage must be mcap or sqlite3, got {storage!r}')
    if frames is not None and frames < 1:
        raise ConfigError(f'record-sim: --frames must be at least 1, got {frames}')
    pattern = load_pattern_config()
    plan = plan if plan is not None else room_corridor_plan(seed, pattern)
    walk = walk if walk is not None else make_walk(plan, rate_hz=rate_hz, seed=seed)
    camera = camera or default_survey_camera()
    renderer = WalkRenderer(plan, camera, pattern)
    odometry = drift_odometry(walk, drift, seed=seed + 1)
    frame_samples = walk.frames if frames is None else walk.frames[:frames]
    last = int(frame_samples[-1])
    ts = typestore()
    plugin = StoragePlugin.MCAP if storage == 'mcap' else StoragePlugin.SQLITE3
    writer = Writer(out_dir, version=Writer.VERSION_LATEST, storage_plugin=plugin)
    if storage == 'mcap':
        writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    writer.set_custom_data('pattern_locator.record_sim_survey', json.dumps({
        'plan': plan.name, 'seed': seed, 'rate_hz': rate_hz,
        'drift': {'scale_error': drift.scale_error,
                  'yaw_bias_rad_per_m': drift.yaw_bias_rad_per_m}}))
    try:
        writer.open()
    except (OSError, WriterError) as exc:
        raise ConfigError(f'{out_dir}: cannot write the bag ({exc})') from None
    try:
        topics = dict(SURVEY_TOPICS)
        if not with_tf_static:
            del topics[TF_STATIC_TOPIC]
        if not with_odometry:
            del topics[ODOM_TOPIC]
        connections = {t: writer.add_connection(t, ty, typestore=ts) for t, ty in topics.items()}

        def write(topic, stamp_ns, msg):
            writer.write(connections[topic], stamp_ns + _LATENCY_NS[topic],
                         ts.serialize_cdr(msg, topics[topic]))

        def stamp_of(sample: int) -> int:
            return START_NS + round(float(walk.times_s[sample]) * 1e9)

        if with_tf_static:
            write(TF_STATIC_TOPIC, START_NS, _tf_message(ts, START_NS, BASE_FRAME,
                                                         OPTICAL_FRAME, walk.T_base_camera))
        info = _camera_info(ts, camera)
        is_frame = np.zeros(last + 1, dtype=bool)
        is_frame[frame_samples] = True
        seeds = iter(range(seed * 100_000, seed * 100_000 + last + 1))
        bar = tqdm(total=len(frame_samples), disable=None if progress else True,
                   unit='frame', desc='render')
        for sample in range(last + 1):
            stamp = stamp_of(sample)
            if with_odometry:
                write(ODOM_TOPIC, stamp, _odometry(ts, stamp, odometry[sample]))
            if not is_frame[sample]:
                continue
            T_world_camera = walk.camera_pose(sample)
            image = renderer.render(T_world_camera, seed=next(seeds))
            info.header = _header(ts, stamp, OPTICAL_FRAME)
            write(INFO_TOPIC, stamp, info)
            write(IMAGE_TOPIC, stamp, _image(ts, stamp, image))
            write(TRUTH_TOPIC, stamp, _pose_stamped(ts, stamp, 'building',
                                                    walk.T_world_base[sample]))
            bar.update(1)
        bar.close()
    except BaseException:
        writer.abort()
        shutil.rmtree(out_dir, ignore_errors=True)
        raise
    writer.close()
    write_truth(out_dir, plan)
    return out_dir


def write_truth(out_dir: Path, plan: FloorPlan) -> None:
    """Write ``truth.yaml`` (cards as hung) and ``plan.yaml`` (as planned) into ``out_dir``."""
    for name, attr, what in (('truth.yaml', 'T_true', 'as hung (the truth)'),
                             ('plan.yaml', 'T_plan', 'as planned (the nominal map)')):
        cards = truth_cards([(c.ids.as_tuple(), str(c.code), getattr(c, attr))
                             for c in plan.cards])
        text = building_yaml(cards, room_frames(cards), header=[
            f'The cards of the sim plan "{plan.name}" {what}, written by',
            'pattern-locator bag record-sim --survey. Building frame: z up, the floor at '
            f'z = {plan.floor_z:g}.'])
        write_text(out_dir / name, text, 'the truth map')


def _header(ts, stamp_ns: int, frame_id: str):
    Time = ts.types['builtin_interfaces/msg/Time']
    return ts.types['std_msgs/msg/Header'](
        stamp=Time(sec=stamp_ns // 10 ** 9, nanosec=stamp_ns % 10 ** 9), frame_id=frame_id)


def _camera_info(ts, camera: CameraModel):
    K = np.asarray(camera.K, dtype=float)
    return ts.types['sensor_msgs/msg/CameraInfo'](
        header=_header(ts, 0, OPTICAL_FRAME), height=camera.height, width=camera.width,
        distortion_model='plumb_bob', d=np.asarray(camera.D, dtype=float).ravel(),
        k=K.ravel(), r=np.eye(3).ravel(), p=np.hstack([K, np.zeros((3, 1))]).ravel(),
        binning_x=0, binning_y=0,
        roi=ts.types['sensor_msgs/msg/RegionOfInterest'](x_offset=0, y_offset=0, height=0,
                                                         width=0, do_rectify=False))


def _image(ts, stamp_ns: int, image: np.ndarray):
    height, width, encoding, is_bigendian, step, data = encode_image(image, 'bgr8')
    return ts.types['sensor_msgs/msg/Image'](
        header=_header(ts, stamp_ns, OPTICAL_FRAME), height=height, width=width,
        encoding=encoding, is_bigendian=is_bigendian, step=step,
        data=np.frombuffer(data, dtype=np.uint8))


def _geometry_pose(ts, T: Pose):
    x, y, z, w = (float(v) for v in quaternion_xyzw(T.R))
    return ts.types['geometry_msgs/msg/Pose'](
        position=ts.types['geometry_msgs/msg/Point'](x=float(T.t[0]), y=float(T.t[1]),
                                                     z=float(T.t[2])),
        orientation=ts.types['geometry_msgs/msg/Quaternion'](x=x, y=y, z=z, w=w))


def _pose_stamped(ts, stamp_ns: int, frame: str, T: Pose):
    return ts.types['geometry_msgs/msg/PoseStamped'](header=_header(ts, stamp_ns, frame),
                                                     pose=_geometry_pose(ts, T))


def _odometry(ts, stamp_ns: int, T_odom_base: Pose):
    cov = np.zeros(36)
    Vector3 = ts.types['geometry_msgs/msg/Vector3']
    zero = Vector3(x=0.0, y=0.0, z=0.0)
    return ts.types['nav_msgs/msg/Odometry'](
        header=_header(ts, stamp_ns, ODOM_FRAME), child_frame_id=BASE_FRAME,
        pose=ts.types['geometry_msgs/msg/PoseWithCovariance'](
            pose=_geometry_pose(ts, T_odom_base), covariance=cov),
        twist=ts.types['geometry_msgs/msg/TwistWithCovariance'](
            twist=ts.types['geometry_msgs/msg/Twist'](linear=zero, angular=zero),
            covariance=cov))


def _tf_message(ts, stamp_ns: int, parent: str, child: str, T: Pose):
    x, y, z, w = (float(v) for v in quaternion_xyzw(T.R))
    transform = ts.types['geometry_msgs/msg/Transform'](
        translation=ts.types['geometry_msgs/msg/Vector3'](x=float(T.t[0]), y=float(T.t[1]),
                                                          z=float(T.t[2])),
        rotation=ts.types['geometry_msgs/msg/Quaternion'](x=x, y=y, z=z, w=w))
    stamped = ts.types['geometry_msgs/msg/TransformStamped'](
        header=_header(ts, stamp_ns, parent), child_frame_id=child, transform=transform)
    return ts.types['tf2_msgs/msg/TFMessage'](transforms=[stamped])


def record_survey_main(out: Union[str, Path], frames: Optional[int] = None,
                       rate_hz: float = 10.0, seed: int = 1) -> int:
    """Record the room-and-corridor survey walk into ``out``; print what was written."""
    path = record_survey(out, frames=frames, rate_hz=rate_hz, seed=seed)
    size = sum(p.stat().st_size for p in path.rglob('*') if p.is_file())
    print(f'{path}: {size / 1e6:.2f} MB; truth in {path / "truth.yaml"}, plan in '
          f'{path / "plan.yaml"}')
    return 0
