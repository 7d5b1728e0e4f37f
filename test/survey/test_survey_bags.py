"""
Survey bags: reading topics, odometry, mounts; every bad bag gives one line and exit 2.

Small bags are written here with rosbags itself (real rosbag2 files, MCAP or
sqlite3); the rendered survey bag comes from the session fixture.
"""

import math
from pathlib import Path

import numpy as np
from pattern_locator.cli import main
from pattern_locator.errors import ConfigError
from pattern_locator.localization.head import HeadGeometry
from pattern_locator.sim.walk import make_walk, paper_room_plan
from pattern_locator.survey.bagio import (camera_on_base, decode_image, iter_images,
                                          resolve_mount, scan_bag, SurveyTopics, typestore)
from pattern_locator.survey.record import (_camera_info, _header, _image, _odometry, _tf_message,
                                           record_survey)
from pattern_locator.vision.camera import CameraModel
from pattern_locator.vision.geometry import Pose, rodrigues
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer

TS = typestore()
CAMERA = CameraModel.from_fov(64, 48, 60.0)
T0 = 1_700_000_000 * 10 ** 9
TYPES = {'/camera/image_raw': 'sensor_msgs/msg/Image',
         '/camera/camera_info': 'sensor_msgs/msg/CameraInfo',
         '/odom': 'nav_msgs/msg/Odometry',
         '/tf_static': 'tf2_msgs/msg/TFMessage',
         '/camera/joint_states': 'sensor_msgs/msg/JointState',
         '/chatter': 'std_msgs/msg/String'}


def write_bag(path: Path, messages, topics=None, storage='mcap') -> Path:
    """Write (topic, stamp ns, message) into a new bag; declare ``topics`` (default: used)."""
    plugin = StoragePlugin.MCAP if storage == 'mcap' else StoragePlugin.SQLITE3
    writer = Writer(path, version=Writer.VERSION_LATEST, storage_plugin=plugin)
    writer.open()
    names = topics if topics is not None else sorted({t for t, _, _ in messages})
    connections = {t: writer.add_connection(t, TYPES[t], typestore=TS) for t in names}
    for topic, stamp, msg in messages:
        writer.write(connections[topic], stamp, TS.serialize_cdr(msg, TYPES[topic]))
    writer.close()
    return path


def _frames(n=3, image=True, info=True, odom=False, grey=128):
    out = []
    picture = np.full((CAMERA.height, CAMERA.width, 3), grey, dtype=np.uint8)
    for i in range(n):
        stamp = T0 + i * 100_000_000
        if info:
            msg = _camera_info(TS, CAMERA)
            msg.header = _header(TS, stamp, 'camera_optical_frame')
            out.append(('/camera/camera_info', stamp, msg))
        if image:
            out.append(('/camera/image_raw', stamp, _image(TS, stamp, picture)))
        if odom:
            T = Pose(rodrigues(np.array([0.0, 0.0, 0.1 * i])), np.array([0.5 * i, 0.0, 0.0]))
            out.append(('/odom', stamp, _odometry(TS, stamp, T)))
    return out


def _survey_exit(capsys, *args):
    status = main(['survey', *[str(a) for a in args]])
    err = capsys.readouterr().err.strip()
    return status, err


def _one_line_exit_2(capsys, args, words):
    status, err = _survey_exit(capsys, *args)
    assert status == 2
    assert len(err.splitlines()) == 1, err
    assert err.startswith('pattern-locator: error: ') and words in err, err


def test_a_bag_without_camera_info_is_refused(tmp_path, capsys):
    bag = write_bag(tmp_path / 'b', _frames(info=False))
    _one_line_exit_2(capsys, [bag, '-o', tmp_path / 'm.yaml'], 'no camera_info in the bag')


def test_a_camera_info_topic_without_messages_is_refused(tmp_path, capsys):
    bag = write_bag(tmp_path / 'b', _frames(info=False),
                    topics=['/camera/image_raw', '/camera/camera_info'])
    _one_line_exit_2(capsys, [bag, '-o', tmp_path / 'm.yaml'], 'no camera_info (topic')


def test_a_bag_without_images_is_refused(tmp_path, capsys):
    bag = write_bag(tmp_path / 'b', _frames(image=False))
    _one_line_exit_2(capsys, [bag, '-o', tmp_path / 'm.yaml'], 'no image in the bag')
    empty = write_bag(tmp_path / 'c', _frames(image=False),
                      topics=['/camera/image_raw', '/camera/camera_info'])
    _one_line_exit_2(capsys, [empty, '-o', tmp_path / 'm.yaml'], 'no images (topic')


def test_an_unknown_topic_is_named_with_the_bags_topics(tmp_path, capsys):
    bag = write_bag(tmp_path / 'b', _frames())
    _one_line_exit_2(capsys, [bag, '-o', tmp_path / 'm.yaml', '--image-topic', '/front/image'],
                     'unknown topic /front/image (the bag has /camera/camera_info')
    _one_line_exit_2(capsys, [bag, '-o', tmp_path / 'm.yaml', '--odom-topic', '/odom'],
                     'unknown topic /odom')
    _one_line_exit_2(capsys, [bag, '-o', tmp_path / 'm.yaml', '--image-topic',
                              '/camera/camera_info'],
                     'topic /camera/camera_info is sensor_msgs/msg/CameraInfo, not')


def test_a_corrupt_chunk_is_reported_not_a_traceback(tmp_path, capsys, room_bag):
    copy = tmp_path / 'corrupt'
    copy.mkdir()
    for f in room_bag.iterdir():
        copy.joinpath(f.name).write_bytes(f.read_bytes())
    mcap = next(copy.glob('*.mcap'))
    data = bytearray(mcap.read_bytes())
    middle = len(data) // 2
    data[middle:middle + 4096] = bytes(4096)            # zero a stretch inside a chunk
    mcap.write_bytes(bytes(data))
    _one_line_exit_2(capsys, [copy, '-o', tmp_path / 'm.yaml', '--jobs', '1'], 'corrupt data')


def test_not_a_bag_and_no_bag_are_refused(tmp_path, capsys):
    _one_line_exit_2(capsys, [tmp_path / 'none', '-o', tmp_path / 'm.yaml'], 'no such bag')
    (tmp_path / 'dir').mkdir()
    _one_line_exit_2(capsys, [tmp_path / 'dir', '-o', tmp_path / 'm.yaml'],
                     'not a rosbag2 bag (no metadata.yaml')


def test_frames_with_no_card_say_so(tmp_path, capsys):
    bag = write_bag(tmp_path / 'b', _frames())
    _one_line_exit_2(capsys, [bag, '-o', tmp_path / 'm.yaml', '--jobs', '1'],
                     'no card was seen in')


def test_odometry_is_interpolated_to_the_image_stamps_and_sqlite3_reads(tmp_path):
    bag = write_bag(tmp_path / 'b', _frames(odom=True), storage='sqlite3')
    data = scan_bag(bag)
    assert data.odom_topic == '/odom' and data.n_images == 3
    halfway = data.odometry_at(T0 + 50_000_000)
    assert np.allclose(halfway.t, [0.25, 0.0, 0.0])
    assert math.isclose(math.atan2(halfway.R[1, 0], halfway.R[0, 0]), 0.05)
    assert data.odometry_at(T0 - 1) is None and data.odometry_at(T0 + 300_000_000) is None
    images = list(iter_images(data))
    assert [stamp for _, stamp, _ in images] == [T0, T0 + 100_000_000, T0 + 200_000_000]
    assert decode_image(images[0][2]).shape == (48, 64, 3)


def test_the_mount_comes_from_tf_static_then_the_option_then_the_head(tmp_path):
    T_base_camera = Pose(rodrigues(np.array([0.1, -1.2, 0.3])), np.array([0.1, 0.0, 1.2]))
    # A chain base_link -> mast -> camera_optical_frame in /tf_static.
    mast = Pose(np.eye(3), np.array([0.0, 0.0, 1.0]))
    frames = _frames(odom=True)
    frames.append(('/tf_static', T0, _tf_message(TS, T0, 'base_link', 'mast', mast)))
    frames.append(('/tf_static', T0, _tf_message(TS, T0, 'mast', 'camera_optical_frame',
                                                 mast.inverse() @ T_base_camera)))
    data = scan_bag(write_bag(tmp_path / 'tf', frames))
    mount = resolve_mount(data, camera_mount=(0, 0, 0, 0, 0, 0))
    assert mount.source == 'tf_static'
    assert np.allclose(camera_on_base(data, mount, T0).matrix(), T_base_camera.matrix())
    plain = scan_bag(write_bag(tmp_path / 'plain', _frames(odom=True)))
    given = resolve_mount(plain, camera_mount=(0.1, 0.0, 1.2, 0.0, -math.pi / 2, 0.0))
    assert given.source == '--camera-mount'
    assert np.allclose(camera_on_base(plain, given, T0).t, [0.1, 0.0, 1.2])
    assert resolve_mount(plain).source == 'camera'
    # The project's pan/tilt head, at the recorded joint angles.
    joints = _frames(odom=True)
    for i, (pan, tilt) in enumerate([(0.0, 0.0), (0.2, 0.1)]):
        msg = TS.types['sensor_msgs/msg/JointState'](
            header=_header(TS, T0 + i * 200_000_000, ''), name=['camera_pan', 'camera_tilt'],
            position=np.array([pan, tilt]), velocity=np.zeros(0), effort=np.zeros(0))
        joints.append(('/camera/joint_states', T0 + i * 200_000_000, msg))
    head = scan_bag(write_bag(tmp_path / 'head', joints))
    mount = resolve_mount(head)
    assert mount.source == 'joint_states'
    expected = HeadGeometry().T_base_camera(0.1, 0.05)
    assert np.allclose(camera_on_base(head, mount, T0 + 100_000_000).matrix(),
                       expected.matrix())
    assert camera_on_base(head, mount, T0 + 300_000_000) is None


def test_record_sim_survey_writes_truth_and_an_sqlite3_bag_reads_back(tmp_path):
    plan = paper_room_plan(seed=2)
    walk = make_walk(plan, rate_hz=5.0, seed=2, duration_s=1.0)
    camera = CameraModel.from_fov(320, 180, 90.0)
    out = record_survey(tmp_path / 'small', plan=plan, walk=walk, camera=camera, seed=2,
                        storage='sqlite3', progress=False)
    data = scan_bag(out, SurveyTopics(image='/camera/image_raw'))
    assert data.n_images == len(walk.frames) == 6
    assert data.odom_topic == '/odom' and len(data.odom_poses) == 11
    assert resolve_mount(data).source == 'tf_static'
    assert (out / 'truth.yaml').is_file() and (out / 'plan.yaml').is_file()
    with pytest.raises(ConfigError, match='exists already'):
        record_survey(out, plan=plan, walk=walk, camera=camera, progress=False)
