"""The covariance model: each term on its own, and honest coverage on rendered frames."""

import functools
import math

import numpy as np
from pattern_locator.card.pattern import load_pattern_config
from pattern_locator.errors import ConfigError
from pattern_locator.localization.building import building_from_dict
from pattern_locator.localization.gates import GateParameters
from pattern_locator.localization.head import (angle_jacobian, base_pose_from_camera,
                                               HeadGeometry, HeadMotion, JointStateBuffer)
from pattern_locator.localization.localizer import RobotLocalizer
from pattern_locator.localization.odom import BaseTwist
from pattern_locator.localization.uncertainty import (card_std_dev, chi2_95, fix_covariance,
                                                      inside_95, predicted_blur_px,
                                                      UncertaintyParameters)
from pattern_locator.sim.floor_sim import FloorSim
from pattern_locator.visca.zoom_table import ZoomTable
from pattern_locator.vision.geometry import Pose
import pytest

PATTERN = load_pattern_config()
HEAD = HeadGeometry()
TABLE = ZoomTable.load()
MODEL_POINTS = PATTERN.model_points()
ALL_DOTS = np.ones(len(MODEL_POINTS), dtype=bool)


def room_map(std_dev=None):
    card = {'pattern': 1, 'pose': {'position': [0.0, 2.5, 2.15], 'facing_deg': 0}}
    if std_dev is not None:
        card['std_dev'] = std_dev
    data = {'floors': [{'floor': 1, 'rooms': [{'room': 1, 'size': [8.0, 5.0, 2.5], 'pose': {
        'position': [10.0, 0.0, 0.0], 'rpy_deg': [0, 0, 90]}, 'cards': [card]}]}]}
    return building_from_dict(data, PATTERN)


def seen_from(card, x, y, yaw_deg=180.0):
    """Return (T_room_base, pan, tilt, T_camera_card) of a base at room (x, y) aimed at card."""
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    T_room_base = Pose(np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]),
                       np.array([x, y, 0.0]))
    target = T_room_base.inverse().apply(card.T_room_card.t[None])[0]
    pan, tilt = HEAD.aim_angles(target)
    T_room_camera = T_room_base @ HEAD.T_base_camera(pan, tilt)
    return T_room_base, pan, tilt, T_room_camera.inverse() @ card.T_room_card


def covariance(parameters, card, motion, T_camera_card, twist=None, residual=0.02):
    T_room_base = base_pose_from_camera(card.T_room_card, T_camera_card, HEAD, motion.pan,
                                        motion.tilt)
    return fix_covariance(parameters, TABLE.camera_at(600), MODEL_POINTS, ALL_DOTS, residual,
                          T_camera_card, card.T_room_card, T_room_base, card, HEAD, motion,
                          twist)


def test_the_head_timing_term_is_the_rate_times_the_stamp_error():
    card = room_map().card((1, 1, 1))
    _, pan, tilt, T_camera_card = seen_from(card, 4.0, 1.0)
    params = UncertaintyParameters()
    still = covariance(params, card, HeadMotion(pan, tilt), T_camera_card)
    assert not np.any(still.terms['head_timing'])
    rates = np.array([0.3, -0.2])
    moving = covariance(params, card, HeadMotion(pan, tilt, *rates), T_camera_card)
    # Exactly the base's displacement for angles off by rate * sigma_t (first order).
    direction = angle_jacobian(card.T_room_card, T_camera_card, HEAD, pan, tilt) @ rates
    expected = np.outer(direction, direction) * params.joint_stamp_sigma_s ** 2
    assert np.allclose(moving.terms['head_timing'], expected, rtol=1e-9, atol=1e-15)
    step = base_pose_from_camera(card.T_room_card, T_camera_card, HEAD,
                                 pan + 1e-4 * rates[0], tilt + 1e-4 * rates[1])
    base = base_pose_from_camera(card.T_room_card, T_camera_card, HEAD, pan, tilt)
    assert np.allclose((step.t - base.t) / 1e-4, direction[:3], rtol=1e-3, atol=1e-5)
    # Twice the rate, twice the standard deviation.
    double = covariance(params, card, HeadMotion(pan, tilt, *(2 * rates)), T_camera_card)
    assert np.allclose(double.terms['head_timing'], 4 * moving.terms['head_timing'])
    # The interpolation term follows the change of rate and the interval; holding, the rate.
    changing = covariance(params, card, HeadMotion(pan, tilt, 0.0, 0.0, (0.5, 0.0), 0.1),
                          T_camera_card)
    J = angle_jacobian(card.T_room_card, T_camera_card, HEAD, pan, tilt)
    spread = (params.interpolation_factor * 0.5 * 0.1) ** 2
    assert np.allclose(changing.terms['head_interpolation'],
                       spread * np.outer(J[:, 0], J[:, 0]))
    held = covariance(params, card, HeadMotion(pan, tilt, 0.0, 0.2, hold_s=0.05), T_camera_card)
    assert np.allclose(held.terms['head_interpolation'],
                       (0.2 * 0.05) ** 2 * np.outer(J[:, 1], J[:, 1]))


def test_the_map_term_from_the_cards_std_dev():
    plain = room_map()
    assert card_std_dev(plain.card((1, 1, 1)), UncertaintyParameters()).position_m == (0.0,) * 3
    surveyed = room_map({'position_m': 0.02, 'rotation_deg': [0.0, 0.0, 1.0]})
    card = surveyed.card((1, 1, 1))
    assert card.std_dev.position_m == (0.02,) * 3
    _, pan, tilt, T_camera_card = seen_from(card, 4.0, 2.5)
    terms = covariance(UncertaintyParameters(), card, HeadMotion(pan, tilt),
                       T_camera_card).terms['map']
    # The base 4 m in front of the card: a 1 deg turn about room z swings it 4 m * 1 deg
    # sideways (room y); the shift adds 2 cm everywhere.
    T_room_base = base_pose_from_camera(card.T_room_card, T_camera_card, HEAD, pan, tilt)
    lever = T_room_base.t - card.T_room_card.t
    assert math.sqrt(terms[1, 1]) == pytest.approx(
        math.hypot(0.02, lever[0] * math.radians(1.0)), rel=1e-6)
    assert math.sqrt(terms[2, 2]) == pytest.approx(0.02, rel=1e-6)
    assert math.sqrt(terms[5, 5]) == pytest.approx(math.radians(1.0), rel=1e-9)
    # In the building frame (the room is turned 90 deg) the same numbers about its axes.
    for bad in ({'position_m': -0.1}, {'rotation_deg': [1.0, 2.0]}, {'spread': 1.0}, {}):
        with pytest.raises(ConfigError, match='std_dev'):
            room_map(bad)


def test_blur_is_the_smear_of_the_cards_centre():
    card = room_map().card((1, 1, 1))
    _, pan, tilt, T_camera_card = seen_from(card, 5.0, 2.5)
    camera = TABLE.camera_at(600)
    rate = math.radians(10.0)
    smear = predicted_blur_px(camera, HEAD, T_camera_card, HeadMotion(pan, tilt, rate, 0.0),
                              None, 0.02)
    assert smear == pytest.approx(camera.fx * math.tan(rate * 0.02), rel=0.05)
    # The base turning left under a head turning right as fast: no smear.
    cancelled = predicted_blur_px(camera, HEAD, T_camera_card, HeadMotion(pan, tilt, -rate, 0),
                                  BaseTwist((0, 0, 0), (0, 0, rate)), 0.02)
    assert cancelled < 0.02 * smear
    params = UncertaintyParameters()
    sharp = covariance(params, card, HeadMotion(pan, tilt), T_camera_card)
    blurred = covariance(params, card, HeadMotion(pan, tilt, rate, 0.0), T_camera_card)
    assert blurred.blur_px == pytest.approx(smear)
    assert blurred.pixel_sigma_px == pytest.approx(math.hypot(
        params.residual_factor * sharp_residual(sharp), params.blur_sigma_per_px * smear))


def sharp_residual(fix_cov):
    return fix_cov.residual_sigma_px


def test_the_pixel_floor_and_the_residual_factor():
    card = room_map().card((1, 1, 1))
    _, pan, tilt, T_camera_card = seen_from(card, 5.0, 2.5)
    params = UncertaintyParameters()
    clean = covariance(params, card, HeadMotion(pan, tilt), T_camera_card, residual=0.001)
    assert clean.pixel_sigma_px == pytest.approx(params.pixel_sigma_px)
    noisy = covariance(params, card, HeadMotion(pan, tilt), T_camera_card, residual=0.3)
    n = len(MODEL_POINTS)
    assert noisy.pixel_sigma_px == pytest.approx(
        params.residual_factor * 0.3 * math.sqrt(n / (2 * n - 6)))
    ratio = noisy.terms['image'][0, 0] / clean.terms['image'][0, 0]
    assert ratio == pytest.approx((noisy.pixel_sigma_px / clean.pixel_sigma_px) ** 2)
    with pytest.raises(ConfigError):
        UncertaintyParameters(joint_stamp_sigma_s=-0.01)


def test_joint_states_give_the_rates_and_their_change():
    buffer = JointStateBuffer()
    # Pan at 0.2 rad/s, then from 0.25 s at 0.5 rad/s; tilt still; samples every 0.1 s.
    for t in np.arange(0.0, 0.45, 0.1):
        pan = 0.2 * t if t <= 0.25 else 0.05 + 0.5 * (t - 0.25)
        buffer.add(t, pan, 0.1)
    motion = buffer.motion_at(0.25)
    assert motion.pan_rate == pytest.approx((0.05 + 0.5 * 0.05 - 0.04) / 0.1)
    assert motion.tilt_rate == 0.0 and motion.interval_s == pytest.approx(0.1)
    assert motion.rate_change[0] > 0.1 and motion.hold_s == 0.0
    held = buffer.motion_at(0.45)
    assert held.hold_s == pytest.approx(0.05) and held.pan_rate == pytest.approx(0.5)
    assert (held.pan, held.tilt) == buffer.at(0.45)


# On rendered frames ---------------------------------------------------------------------


@functools.lru_cache(maxsize=2)
def rendered(as_hung: bool, count: int = 24):
    """Still frames along the loop: (image, camera, pan, tilt, true base pose)."""
    sim = FloorSim.floor('loop', seed=3, as_hung_seed=11 if as_hung else None)
    frames = []
    rng = np.random.default_rng(5)
    for t in np.linspace(5.0, sim.duration_s - 5.0, 4 * count):
        state = sim.state(float(t))
        gaze = sim.scene.oracle_gaze(state.pose)
        if gaze is None:
            continue
        ids, pan, tilt = gaze
        # A head a little off the card (as a tracking loop leaves it).
        pan += float(rng.normal(0.0, 0.02))
        tilt += float(rng.normal(0.0, 0.01))
        T_camera = sim.scene.true_camera_pose(state.pose, pan, tilt)
        distance = float(np.linalg.norm(sim.world.card(ids).T_building_card.t - T_camera.t))
        camera = TABLE.camera_at(TABLE.zoom_for_focal(0.2 * TABLE.width * distance / 0.3))
        image = sim.scene.render_still(T_camera, camera, seed=len(frames))
        frames.append((image, camera, pan, tilt, state.pose))
        if len(frames) == count:
            break
    return sim.world.building, tuple(frames)


def coverage(as_hung: bool, parameters):
    building, frames = rendered(as_hung)
    localizer = RobotLocalizer(PATTERN, building, HEAD, output_frame='building',
                               gates=GateParameters(footprint='adjacent'),
                               uncertainty=parameters)
    inside, d2 = [], []
    for image, camera, pan, tilt, truth in frames:
        fix = localizer.process(image, camera, pan, tilt).fix
        assert fix is not None
        error = fix.T_frame_base.t - truth.t
        inside.append(inside_95(error, fix.covariance[:3, :3]))
        d2.append(float(error @ np.linalg.solve(fix.covariance[:3, :3], error)))
    return float(np.mean(inside)), float(np.median(d2)), len(frames)


def test_the_covariance_covers_the_error_of_still_frames():
    covered, median_d2, n = coverage(False, UncertaintyParameters())
    assert n >= 10
    # Honest both ways: the errors mostly inside their 95 % ellipse, and not far
    # inside it (the median of a chi-square with 3 degrees of freedom is 2.37).
    assert covered >= 0.85
    assert 0.4 <= median_d2 <= 2.5 * chi2_95(3)


def test_a_map_off_by_centimetres_needs_the_map_term():
    # Cards hung off their mapped pose (up to 5 cm and 3 deg, as a real building's):
    # the image alone claims millimetres and the error is centimetres; with the
    # map's standard deviations (what FloorWorld.as_hung draws) the ellipses hold.
    fisher, _, _ = coverage(True, UncertaintyParameters.fisher_only())
    with_map, median_d2, _ = coverage(True, UncertaintyParameters(
        map_position_sigma_m=0.025, map_rotation_sigma_deg=1.0))
    assert fisher <= 0.5
    assert with_map >= 0.85 and median_d2 >= 0.2
