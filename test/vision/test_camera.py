"""Camera intrinsics: ROS camera-info YAML, projection, undistortion and the one validator."""

import math

from hypothesis import given, HealthCheck, settings, strategies as st
import numpy as np
from pattern_locator.errors import CameraError
from pattern_locator.visca.zoom_table import ZoomTable
from pattern_locator.vision.camera import (camera_from_calibration, camera_from_dict,
                                           CameraModel, load_camera, save_camera)
import pytest
import yaml

FUZZ = settings(max_examples=80, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow])
VGA_K = [[500.0, 0.0, 319.5], [0.0, 500.0, 239.5], [0.0, 0.0, 1.0]]


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


def set_k(index, value):
    def change(d):
        d['camera_matrix']['data'][index] = value
    return change


@pytest.mark.parametrize('change, words', [
    (lambda d: d.pop('camera_matrix'), 'missing camera_matrix'),
    (lambda d: d['camera_matrix'].update(data=[0] * 9), 'all zeros'),
    (lambda d: d['camera_matrix'].update(data=[1, 2, 3]), 'rows x cols = 3 x 3 does not match'),
    (lambda d: d['camera_matrix'].update(rows=9, cols=1), 'rows must be 3'),
    (lambda d: d['camera_matrix'].update(rows=3.0), 'rows must be an integer'),
    (lambda d: d['distortion_coefficients'].update(cols=4), '1 x 4 does not match its 5'),
    (lambda d: d['camera_matrix'].update(data='fx'), 'data must be a list'),
    (lambda d: d['camera_matrix']['data'].__setitem__(0, '1000'), 'must be a number'),
    (lambda d: d['camera_matrix']['data'].__setitem__(0, True), 'must be a number'),
    (lambda d: d.update(image_width='wide'), 'image_width must be an integer'),
    # Seen in fuzzing: a float width, a bool, infinity (a traceback then).
    (lambda d: d.update(image_width=1280.7), 'image_width must be an integer'),
    (lambda d: d.update(image_width=True), 'image_width must be an integer'),
    (lambda d: d.update(image_height=math.inf), 'image_height must be an integer'),
    (lambda d: d.update(image_width=0), 'image size must be positive'),
    (lambda d: d.update(image_width=10 ** 9), 'image size must be positive'),
    (lambda d: d.update(distortion_model='kannala'), 'not supported'),
    (lambda d: d.update(distortion_model=['plumb_bob']), 'must be text'),
    (lambda d: d['distortion_coefficients'].update(data=[0.1, 0.2], cols=2), 'needs 4 or 5'),
    (lambda d: d.update(distortion_model='rational_polynomial'), 'needs 8'),
    (lambda d: d.update(camera_name={'a': 1}), 'camera_name must be text'),
    # Seen in fuzzing: K's last row [1, 1, 1], K[2][2] = 0 (a LinAlgError then),
    # K[1][0] != 0, NaN, skew.
    (lambda d: d['camera_matrix']['data'].__setitem__(slice(6, 9), [1, 1, 1]), 'last row'),
    (set_k(8, 0.0), 'last row must be \\[0, 0, 1\\]'),
    (set_k(3, 5.0), 'K\\[1\\]\\[0\\] must be 0'),
    (set_k(1, 2.0), 'skew'),
    (set_k(0, math.nan), 'must be finite'),
    (set_k(0, -900.0), 'fx and fy must be positive'),
    # Seen in fuzzing: finite but absurd focal lengths gave NaN poses.
    (set_k(0, 1e-300), 'horizontal field of view of 180 deg'),
    (set_k(4, 5e307), 'vertical field of view of 8.25e-304 deg'),
    (set_k(0, 5.0), 'field of view'),
    (set_k(0, 1e6), 'field of view of 0.0733 deg'),
    (set_k(4, 3000.0), 'fx / fy'),
    # Seen in fuzzing: the principal point far outside the image (poses 1.2 km off).
    (set_k(2, 1e5), 'principal point cx'),
    (set_k(5, -400.0), 'principal point cy'),
    # Seen in fuzzing: D = 1e300.
    (lambda d: d['distortion_coefficients']['data'].__setitem__(0, 1e300), 'out of range'),
    (lambda d: d['distortion_coefficients']['data'].__setitem__(0, -1.0),
     'cannot be undone at the image border'),
    (lambda d: d['distortion_coefficients'].update(data=[0.3, -0.6, 0, 0, 0]),
     'cannot be undone'),
    (lambda d: d['distortion_coefficients'].update(data=[100.0, 0, 0, 0, 0]),
     'scales the field of view'),
    (lambda d: d['rectification_matrix'].update(data=[1, 0, 0, 0, 1, 0, 0, 0, -1]),
     'not a rotation'),
    (lambda d: d['rectification_matrix'].update(data=[2, 0, 0, 0, 2, 0, 0, 0, 2]),
     'not a rotation'),
    (lambda d: d['projection_matrix']['data'].__setitem__(10, 2.0), 'not a valid P'),
    (lambda d: d['projection_matrix']['data'].__setitem__(0, 1e-3), 'P fx'),
    (lambda d: d['projection_matrix']['data'].__setitem__(6, 1e5), 'P principal point cy'),
])
def test_bad_camera_files_name_the_problem(tmp_path, change, words):
    data = barrel_camera().to_yaml_dict()
    change(data)
    with pytest.raises(CameraError, match=words) as error:
        load_camera(write(tmp_path, data))
    message = str(error.value)
    assert '\n' not in message and len(message) < 300 + len(str(tmp_path))
    assert message.startswith(str(tmp_path))


def test_a_distortion_that_folds_back_inside_the_image_is_refused():
    # Undistortion converges at the border, but on the far side of a fold:
    # pixels inside the image would have two rays.
    K = CameraModel.from_fov(640, 480, 60.0).K
    with pytest.raises(CameraError, match='folds back inside the image'):
        camera_from_calibration(640, 480, K, [-2.0, 0.4, 0.0, 0.0, 1.0])


def test_unreadable_and_malformed_files(tmp_path):
    with pytest.raises(CameraError, match='cannot read camera file'):
        load_camera(tmp_path / 'nope.yaml')
    with pytest.raises(CameraError, match='malformed YAML'):
        load_camera(write(tmp_path, 'camera_matrix: {data: [1, 2\n'))
    with pytest.raises(CameraError, match='not a camera-info YAML'):
        load_camera(write(tmp_path, '- just\n- a list\n'))


def test_real_calibration_forms_are_accepted():
    # Zeros for R and P (what an uncalibrated driver leaves), plain lists, an
    # empty D, the 4-coefficient plumb_bob, a fisheye, rational_polynomial.
    data = barrel_camera().to_yaml_dict()
    data['rectification_matrix']['data'] = [0.0] * 9
    data['projection_matrix'] = [0.0] * 12
    data['camera_matrix'] = data['camera_matrix']['data']
    assert camera_from_dict(data).distortion_model == 'plumb_bob'
    data['distortion_coefficients'] = {'rows': 1, 'cols': 4, 'data': [-0.25, 0.07, 0.0, 0.0]}
    assert list(camera_from_dict(data).D) == [-0.25, 0.07, 0.0, 0.0, 0.0]
    data['distortion_coefficients'] = []
    assert not camera_from_dict(data).has_distortion
    wide = CameraModel.from_fov(800, 600, 100.0)
    fisheye = camera_from_calibration(800, 600, wide.K, [0.05, -0.02, 0.003, 0.0], 'equidistant')
    assert fisheye.has_distortion
    rational = camera_from_calibration(640, 480, VGA_K, [0.1, 0.01, 0, 0, 0, 0.05, 0, 0],
                                       'rational_polynomial', np.eye(3),
                                       np.hstack([VGA_K, np.zeros((3, 1))]))
    assert rational.D.size == 8


def test_every_zoom_of_the_shipped_table_is_a_plausible_calibration():
    table = ZoomTable.load()
    for zoom in np.linspace(*table.zoom_range, 12):
        camera = table.camera_at(zoom)
        again = camera_from_calibration(camera.width, camera.height, camera.K, camera.D,
                                        camera.distortion_model)
        assert np.array_equal(again.K, camera.K)


def test_every_camera_model_holds_the_invariants():
    # Even built directly (not through a file or a topic): the numbers that
    # gave NaN poses cannot make a CameraModel at all.
    for K in ([[1e-300, 0, 320], [0, 1e-300, 240], [0, 0, 1]],
              [[5e307, 0, 320], [0, 5e307, 240], [0, 0, 1]],
              [[500, 0, 320], [0, 500, 240], [0, 0, 0]],
              [[500, 0, 320], [0, 500, 240], [1, 1, 1]]):
        with pytest.raises(CameraError):
            CameraModel(640, 480, np.array(K, dtype=float))
    for width in (640.0, True, -1):
        with pytest.raises(CameraError, match='image_width|image size'):
            CameraModel(width, 480, np.array(VGA_K))
    with pytest.raises(CameraError, match='out of range'):
        CameraModel(640, 480, np.array(VGA_K), [1e300, 0, 0, 0, 0])
    with pytest.raises(CameraError, match='needs 8'):
        CameraModel(640, 480, np.array(VGA_K), [0.1] * 5, 'rational_polynomial')
    with pytest.raises(CameraError, match='takes no coefficients'):
        CameraModel(640, 480, np.array(VGA_K), [0.1] * 5, 'none')
    # A crop of an image keeps its principal point outside the crop: allowed.
    crop = CameraModel(20, 10, np.array([[500.0, 0, -300.0], [0, 500.0, 235.0], [0, 0, 1]]))
    assert crop.cx == -300.0


def test_scaled_and_constructors_give_valid_models():
    camera = barrel_camera().scaled(0.5)
    assert (camera.width, camera.height) == (640, 360)
    again = camera_from_calibration(camera.width, camera.height, camera.K, camera.D)
    assert np.allclose(again.K, camera.K)


# Property-based ------------------------------------------------------------------

def odd_numbers():
    return st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                     st.floats(min_value=-2000, max_value=2000),
                     st.integers(min_value=-10 ** 400, max_value=10 ** 400),
                     st.booleans(), st.none(), st.text(max_size=3))


def k_values():
    plausible = st.tuples(st.floats(100, 3000), st.floats(100, 3000), st.floats(0, 640),
                          st.floats(0, 480)).map(
        lambda v: [v[0], 0.0, v[2], 0.0, v[1], v[3], 0.0, 0.0, 1.0])
    return st.one_of(plausible, st.lists(odd_numbers(), min_size=0, max_size=12),
                     st.lists(st.floats(-1e4, 1e4), min_size=9, max_size=9))


@FUZZ
@given(width=st.one_of(st.integers(-5, 70000), odd_numbers()),
       height=st.one_of(st.integers(-5, 70000), odd_numbers()),
       K=k_values(),
       D=st.one_of(st.lists(st.floats(-2, 2), max_size=9), st.lists(odd_numbers(), max_size=9)),
       model=st.sampled_from(['plumb_bob', 'rational_polynomial', 'equidistant', 'none', '',
                              'x']),
       R=st.one_of(st.none(), st.lists(st.floats(-2, 2), min_size=9, max_size=9)),
       P=st.one_of(st.none(), st.lists(odd_numbers(), min_size=12, max_size=12)))
def test_any_calibration_gives_a_valid_camera_or_a_camera_error(
        width, height, K, D, model, R, P):
    try:
        camera = camera_from_calibration(width, height, K, D, model, R, P)
    except CameraError as exc:
        assert '\n' not in str(exc) and len(str(exc)) < 400
        return
    assert isinstance(camera.width, int) and isinstance(camera.height, int)
    assert np.all(np.isfinite(camera.K)) and np.all(np.isfinite(camera.D))
    # Every pixel of the image undistorts to a finite ray that projects back.
    corners = np.array([[-0.5, -0.5], [camera.width - 0.5, camera.height - 0.5],
                        [camera.cx, camera.cy]])
    rays = camera.normalize(corners)
    assert np.all(np.isfinite(rays))
    back = camera.project(np.column_stack([rays, np.ones(3)]))
    assert np.allclose(back, corners, atol=0.5)


@settings(FUZZ, max_examples=40)
# Up to 70 degrees: with k1 = -0.1 a wider lens folds back before its corners
# (r (1 + k1 r^2) peaks at r = 1.83), which the validator rightly refuses.
@given(width=st.integers(64, 4000), aspect=st.floats(0.5, 1.0), hfov=st.floats(5.0, 70.0),
       ratio=st.floats(0.95, 1.05), centre=st.tuples(st.floats(-0.1, 0.1),
                                                     st.floats(-0.1, 0.1)),
       k1=st.floats(-0.1, 0.1), k2=st.floats(-0.02, 0.02), p=st.floats(-1e-3, 1e-3))
def test_plausible_calibrations_are_accepted(width, aspect, hfov, ratio, centre, k1, k2, p):
    height = max(1, int(width * aspect))
    fx = width / 2.0 / math.tan(math.radians(hfov) / 2.0)
    K = [[fx, 0.0, width * (0.5 + centre[0])], [0.0, fx * ratio, height * (0.5 + centre[1])],
         [0.0, 0.0, 1.0]]
    camera = camera_from_calibration(width, height, K, [k1, k2, p, -p, 0.0])
    assert camera.fx == fx


@settings(FUZZ, max_examples=40)
@given(key=st.sampled_from(['image_width', 'image_height', 'camera_name', 'camera_matrix',
                            'distortion_model', 'distortion_coefficients',
                            'rectification_matrix', 'projection_matrix']),
       value=st.recursive(st.one_of(odd_numbers(), st.text(max_size=5)),
                          lambda inner: st.one_of(st.lists(inner, max_size=12),
                                                  st.dictionaries(st.sampled_from(
                                                      ['rows', 'cols', 'data']), inner)),
                          max_leaves=20))
def test_any_yaml_value_gives_a_valid_camera_or_a_camera_error(tmp_path_factory, key, value):
    data = barrel_camera().to_yaml_dict()
    data[key] = value
    path = tmp_path_factory.mktemp('cam') / 'cam.yaml'
    try:
        path.write_text(yaml.safe_dump(data))
    except (OverflowError, ValueError):
        return
    try:
        camera = load_camera(path)
    except CameraError as exc:
        assert '\n' not in str(exc)
        return
    assert np.all(np.isfinite(camera.K))
