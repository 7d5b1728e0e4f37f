"""Camera intrinsics: ROS camera-info YAML, projection and undistortion."""

import numpy as np
from pattern_locator.errors import CameraError
from pattern_locator.vision.camera import CameraModel, load_camera, save_camera
import pytest
import yaml


def barrel_camera():
    return CameraModel.from_fov(1280, 720, 70.0, D=[-0.25, 0.07, 0.001, -0.0005, 0.0])


def test_yaml_round_trip(tmp_path):
    cam = barrel_camera()
    path = tmp_path / 'cam.yaml'
    save_camera(cam, path)
    back = load_camera(path)
    assert (back.width, back.height) == (1280, 720)
    assert np.allclose(back.K, cam.K) and np.allclose(back.D, cam.D)
    assert back.distortion_model == 'plumb_bob'


def test_project_and_normalize_are_inverse_with_distortion():
    cam = barrel_camera()
    rng = np.random.default_rng(1)
    pts = np.column_stack([rng.uniform(-0.6, 0.6, 200), rng.uniform(-0.35, 0.35, 200),
                           np.ones(200)]) * rng.uniform(1.0, 5.0, (200, 1))
    px = cam.project(pts)
    back = cam.normalize(px)
    assert np.allclose(back, pts[:, :2] / pts[:, 2:3], atol=1e-7)
    # Barrel distortion pulls image corners inwards.
    corner = cam.project(np.array([[0.6, 0.35, 1.0]]))[0]
    ideal = cam.undistort_pixels(corner[None])[0]
    assert np.linalg.norm(ideal - [cam.cx, cam.cy]) > np.linalg.norm(corner - [cam.cx, cam.cy])


def write(tmp_path, data):
    path = tmp_path / 'cam.yaml'
    path.write_text(yaml.safe_dump(data) if isinstance(data, dict) else data)
    return path


@pytest.mark.parametrize('change, words', [
    (lambda d: d.pop('camera_matrix'), 'missing camera_matrix'),
    (lambda d: d['camera_matrix'].update(data=[0] * 9), 'not a valid K'),
    (lambda d: d['camera_matrix'].update(data=[1, 2, 3]), 'must have 9 values'),
    (lambda d: d.update(image_width='wide'), 'must be integers'),
    (lambda d: d.update(image_width=0), 'image size must be positive'),
    (lambda d: d.update(distortion_model='kannala'), 'not supported'),
    (lambda d: d['distortion_coefficients'].update(data=[0.1, 0.2]), 'needs 4..5'),
])
def test_bad_camera_files_name_the_problem(tmp_path, change, words):
    data = barrel_camera().to_yaml_dict()
    change(data)
    with pytest.raises(CameraError, match=words):
        load_camera(write(tmp_path, data))


def test_unreadable_and_malformed_files(tmp_path):
    with pytest.raises(CameraError, match='cannot read camera file'):
        load_camera(tmp_path / 'nope.yaml')
    with pytest.raises(CameraError, match='malformed YAML'):
        load_camera(write(tmp_path, 'camera_matrix: {data: [1, 2\n'))
    with pytest.raises(CameraError, match='not a camera-info YAML'):
        load_camera(write(tmp_path, '- just\n- a list\n'))
