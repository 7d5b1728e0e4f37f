"""The survey's conversions and files: covariances, map YAML and JSON, alignment."""

import math

import numpy as np
from pattern_locator.card.pattern import load_pattern_config
from pattern_locator.errors import ConfigError
from pattern_locator.localization.building import building_from_dict, rpy_rotation
from pattern_locator.sim.render import card_pose_facing
from pattern_locator.survey.align import apply, fit_transform, robust_rigid
from pattern_locator.survey.factors import building_covariance, from_gtsam, to_gtsam
from pattern_locator.survey.mapfile import (building_yaml, cards_json, MapCard, room_frames,
                                            rpy_deg, upright_frame_on)
from pattern_locator.survey.sightings import (Sighting, tangent_covariance,
                                              tangent_covariances)
from pattern_locator.vision.geometry import Pose, rodrigues
import pytest
import yaml

PATTERN = load_pattern_config()


def _covariance(rng) -> np.ndarray:
    L = np.tril(rng.normal(size=(6, 6))) * 1e-3 + np.eye(6) * 1e-3
    return L @ L.T


def test_the_detectors_covariance_becomes_gtsams_tangent():
    # Sample the detector's (camera position, turn about the card's axes) errors,
    # map each perturbed pose into GTSAM's local coordinates, compare covariances.
    rng = np.random.default_rng(0)
    T = card_pose_facing(3.0, 40.0, 120.0)
    sigma = _covariance(rng)
    T_card_camera = T.inverse()
    base = to_gtsam(T)
    samples = []
    for d in rng.multivariate_normal(np.zeros(6), sigma, 4000):
        moved = Pose(rodrigues(d[3:]) @ T_card_camera.R, T_card_camera.t + d[:3])
        samples.append(base.localCoordinates(to_gtsam(moved.inverse())))
    empirical = np.cov(np.array(samples).T)
    predicted = tangent_covariance(T, sigma)
    assert np.abs(empirical - predicted).max() < 0.08 * np.abs(predicted).max()
    s = Sighting(0, 0, 0, 'K-KRRRRRRR', (0, 1, 1), T, sigma, 0.0, 1.0, 17)
    assert np.allclose(tangent_covariances([s])[0], predicted, atol=1e-18)


def test_a_cards_marginal_is_turned_to_the_building_axes():
    rng = np.random.default_rng(1)
    T = Pose(rpy_rotation(0.3, -0.2, 1.1), np.array([1.0, 2.0, 3.0]))
    marginal = _covariance(rng)
    base = to_gtsam(T)
    positions, turns = [], []
    for xi in rng.multivariate_normal(np.zeros(6), marginal, 4000):
        moved = from_gtsam(base.retract(xi))
        positions.append(moved.t - T.t)
        dR = moved.R @ T.R.T
        turns.append(0.5 * np.array([dR[2, 1] - dR[1, 2], dR[0, 2] - dR[2, 0],
                                     dR[1, 0] - dR[0, 1]]))
    empirical = np.cov(np.hstack([positions, turns]).T)
    predicted = building_covariance(T, marginal)
    assert np.abs(empirical - predicted).max() < 0.08 * np.abs(predicted).max()


@pytest.mark.parametrize('rpy', [(0.0, 0.0, 0.0), (90.0, 0.0, 90.0), (12.5, -33.0, 171.0),
                                 (-170.0, 89.9999, 20.0)])
def test_rpy_degrees_read_back_as_the_same_rotation(rpy):
    R = rpy_rotation(*np.radians(rpy))
    assert np.allclose(rpy_rotation(*np.radians(rpy_deg(R))), R, atol=1e-9)


def test_the_upright_frame_on_a_card_has_z_up_and_x_out_of_its_wall():
    tilted = rpy_rotation(math.radians(91.0), math.radians(2.0), math.radians(30.0))
    frame = upright_frame_on(Pose(tilted, np.array([1.0, 2.0, 2.15])))
    assert np.allclose(frame.R[:, 2], [0.0, 0.0, 1.0])
    normal = tilted[:, 2]
    assert frame.R[:, 0] @ normal > 0.999 and abs(frame.R[2, 0]) < 1e-12
    assert np.allclose(frame.t, [1.0, 2.0, 2.15])


def _card(ids, T, sightings=5, connected=True, anchor=False, sd=0.002):
    cov = None if not connected else (np.zeros((6, 6)) if anchor else
                                      np.diag([sd ** 2] * 3 + [1e-6] * 3))
    return MapCard(ids, str(PATTERN.encode(*ids)), T if connected else None, cov, sightings,
                   connected, anchor)


def _pose(x, y, facing_deg, z=2.15):
    a = math.radians(facing_deg)
    z_axis = np.array([math.cos(a), math.sin(a), 0.0])
    y_axis = np.array([0.0, 0.0, 1.0])
    return Pose(np.column_stack([np.cross(y_axis, z_axis), y_axis, z_axis]),
                np.array([x, y, z]))


def test_the_map_loads_with_the_building_loader_and_keeps_poses_and_sds():
    cards = [_card((1, 3, 2), _pose(3.0, 12.0, -90.0)), _card((1, 3, 1), _pose(10.0, 9.5, 180.0)),
             _card((1, 4, 2), _pose(15.0, 7.0, 90.0), sd=0.004),
             _card((1, 3, 5), _pose(5.0, 7.0, 90.0), sightings=1),
             _card((1, 5, 1), None, connected=False)]
    rooms = room_frames(cards)
    text = building_yaml(cards, rooms, header=['a test map'], footer=['the end'])
    building = building_from_dict(yaml.safe_load(text), PATTERN, 'test')
    assert sorted(c.ids.as_tuple() for c in building.cards()) == [(1, 3, 1), (1, 3, 2),
                                                                  (1, 4, 2)]
    for card in cards[:3]:
        got = building.card(card.ids)
        assert np.allclose(got.T_building_card.t, card.T_building_card.t, atol=2e-6)
        assert np.allclose(got.T_building_card.R, card.T_building_card.R, atol=1e-7)
    # Room 3's frame sits on its lowest-numbered card: that card is at its origin.
    first = building.card((1, 3, 1))
    assert np.allclose(first.T_room_card.t, 0.0, atol=1e-6)
    assert np.allclose(building.room(1, 3).T_building_room.R[:, 2], [0.0, 0.0, 1.0])
    sd = building.card((1, 4, 2)).std_dev.position_m
    assert sd == pytest.approx((0.004, 0.004, 0.004), abs=2e-6)
    assert building.card((1, 4, 2)).std_dev.rotation_deg == pytest.approx(
        (math.degrees(1e-3),) * 3, abs=1e-4)
    assert text.startswith('# a test map') and '# the end' in text


def test_a_bad_std_dev_is_named_in_one_line():
    base = {'floors': [{'floor': 1, 'rooms': [{'room': 3, 'pose': {
        'position': [0, 0, 0], 'rpy_deg': [0, 0, 0]}, 'cards': [{
            'pattern': 1, 'pose': {'position': [0, 0, 2], 'facing_deg': 0},
            'std_dev': None}]}]}]}
    card = base['floors'][0]['rooms'][0]['cards'][0]
    for bad, words in (({'position_m': [0.1, -0.1, 0.1]}, 'must be finite and >= 0'),
                       ({'position': [0.1, 0.1, 0.1]}, "unknown key 'position'"),
                       ({'rotation_deg': [1, 2]}, r'a number or \[x, y, z\]')):
        card['std_dev'] = bad
        with pytest.raises(ConfigError, match=words) as err:
            building_from_dict(base, PATTERN, 'map.yaml')
        assert 'floor 1 room 3 card 1: std_dev' in str(err.value)
        assert '\n' not in str(err.value)


def test_cards_json_has_exactly_the_issues_form():
    anchor = _card((1, 3, 1), _pose(0.0, 0.0, 0.0), anchor=True)
    placed = _card((1, 3, 2), _pose(3.0, 2.5, -90.0))
    once = _card((1, 3, 4), _pose(9.0, 0.0, 180.0), sightings=1)
    apart = _card((1, 5, 1), None, sightings=3, connected=False)
    doc = cards_json([placed, apart, once, anchor])
    assert set(doc) == {'frame', 'cards'} and doc['frame'] == 'building'
    by_ids = {(c['floor'], c['room'], c['pattern']): c for c in doc['cards']}
    keys = {'code', 'floor', 'room', 'pattern', 'T_building_card', 'covariance', 'sightings',
            'connected'}
    assert set(by_ids[(1, 3, 2)]) == keys
    assert set(by_ids[(1, 3, 1)]) == keys | {'anchor'} and by_ids[(1, 3, 1)]['anchor'] is True
    assert by_ids[(1, 3, 1)]['covariance'] == [[0.0] * 6] * 6
    item = by_ids[(1, 3, 2)]
    assert item['code'] == str(PATTERN.encode(1, 3, 2))
    assert np.allclose(item['T_building_card'], placed.T_building_card.matrix())
    assert np.array(item['covariance']).shape == (6, 6)
    assert by_ids[(1, 3, 4)]['sightings'] == 1 and by_ids[(1, 3, 4)]['connected'] is True
    assert by_ids[(1, 5, 1)] == {'code': str(PATTERN.encode(1, 5, 1)), 'floor': 1, 'room': 5,
                                 'pattern': 1, 'T_building_card': None, 'covariance': None,
                                 'sightings': 3, 'connected': False}


def test_a_similarity_is_recovered_and_a_moved_point_is_left_out():
    rng = np.random.default_rng(2)
    source = rng.uniform(-10, 10, (8, 3))
    T = Pose(rpy_rotation(0.1, -0.05, 0.8), np.array([1.0, -2.0, 0.5]))
    target = apply(T, 1.02, source)
    got, scale = fit_transform(source, target, scale=True)
    assert scale == pytest.approx(1.02) and np.allclose(got.R, T.R) and np.allclose(got.t, T.t)
    rigid = apply(T, 1.0, source)
    rigid[3] += [0.05, 0.0, 0.0]
    fit, inliers = robust_rigid(source, rigid, np.full(8, 0.01))
    assert list(np.flatnonzero(~inliers)) == [3]
    assert np.allclose(fit.R, T.R, atol=1e-9)


def test_the_reprojection_factors_jacobians_match_finite_differences():
    import gtsam
    from pattern_locator.survey.refine import reprojection_factor
    K = np.array([[640.0, 0.0, 640.0], [0.0, 640.0, 360.0], [0.0, 0.0, 1.0]])
    base = gtsam.Pose3(gtsam.Rot3.Yaw(0.3), np.array([1.0, 2.0, 0.0]))
    mount = Pose(np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]),
                 np.array([0.1, 0.0, 1.2]))
    camera = base.compose(to_gtsam(mount))
    card = camera.compose(gtsam.Pose3(gtsam.Rot3.Ypr(0.1, 0.2, 3.0), np.array([0.2, -0.1, 3.0])))
    factor = reprojection_factor(1, 2, mount, PATTERN.model_points(), np.zeros((17, 2)), K, 1.0)
    values = gtsam.Values()
    values.insert(1, base)
    values.insert(2, card)
    analytic = factor.linearize(values).jacobian()[0]
    e0 = factor.unwhitenedError(values)
    numeric = []
    for key in (1, 2):
        for d in range(6):
            step = np.zeros(6)
            step[d] = 1e-6
            moved = gtsam.Values(values)
            moved.update(key, values.atPose3(key).retract(step))
            numeric.append((factor.unwhitenedError(moved) - e0) / 1e-6)
    assert np.abs(analytic - np.array(numeric).T).max() < 1e-3 * np.abs(analytic).max()
