"""
The factor graph on simulated sightings of walks with known truth (no rendering).

The sightings are what the detector would report (``survey.simulate``):
its covariance at the true pose, errors drawn from it; the odometry drifts
(3 % scale, 0.5 deg/m yaw bias, random walk).
"""

from dataclasses import replace
import math

import numpy as np
from pattern_locator.card.pattern import load_pattern_config
from pattern_locator.errors import ConfigError
from pattern_locator.sim.walk import (drift_odometry, FloorPlan, make_walk, OdometryDrift,
                                      paper_room_plan)
from pattern_locator.survey.align import apply, fit_transform
from pattern_locator.survey.graph import BagMotion, optimise, SurveyOptions
from pattern_locator.survey.record import default_survey_camera
from pattern_locator.survey.simulate import SightingModel, simulate_sightings
from pattern_locator.vision.geometry import Pose, rodrigues, rotation_angle
import pytest

PATTERN = load_pattern_config()
CAMERA = default_survey_camera()
DRIFT = OdometryDrift()


def _motion(walk, drift=DRIFT, seed=5, name='sim'):
    odometry = drift_odometry(walk, drift, seed=seed)
    stamps = np.array([round(float(t) * 1e9) for t in walk.times_s], dtype=np.int64)
    return BagMotion(name, 'tf_static', {f: walk.T_base_camera for f in range(len(walk.frames))},
                     stamps, np.array([T.R for T in odometry]), np.array([T.t for T in odometry]))


def _errors(result, plan: FloorPlan):
    placed = [c for c in result.cards if c.placed]
    est = np.array([c.T_building_card.t for c in placed])
    tru = np.array([plan.card(c.ids).T_true.t for c in placed])
    T, s = fit_transform(est, tru, scale=True)
    relative = np.linalg.norm(apply(T, s, est) - tru, axis=1)
    absolute = np.linalg.norm(est - tru, axis=1)
    return absolute, relative


@pytest.fixture(scope='module')
def room():
    plan = paper_room_plan(seed=5)
    walk = make_walk(plan, rate_hz=4.0, seed=5, duration_s=45.0)
    sightings = simulate_sightings(plan, walk, CAMERA, PATTERN, SightingModel(), seed=6)
    return plan, walk, sightings


def test_a_room_is_mapped_to_millimetres_and_the_odometry_calibrated(room):
    plan, walk, sightings = room
    anchor = plan.cards[0]
    result = optimise(sightings, [_motion(walk)], {anchor.ids.as_tuple(): anchor.T_true},
                      SurveyOptions(card_height_m=2.15, card_height_sd_m=0.01))
    assert all(c.placed for c in result.cards) and len(result.cards) == 6
    absolute, relative = _errors(result, plan)
    assert np.sqrt(np.mean(relative ** 2)) < 0.002
    assert absolute.max() < 0.01
    for c in result.cards:
        assert rotation_angle(c.T_building_card.R, plan.card(c.ids).T_true.R) < math.radians(0.1)
        # Hung within 0.3 degrees of plumb, and held so by the vertical prior.
        assert abs(c.T_building_card.R[2, 2]) < math.sin(math.radians(0.4))
    # The odometry said 3 % too far and drifted 0.5 deg/m: the fit corrects both.
    scale, bias = result.calibration[0]
    assert scale == pytest.approx(1.0 / (1.0 + DRIFT.scale_error) - 1.0, abs=0.002)
    assert bias == pytest.approx(-DRIFT.yaw_bias_rad_per_m / (1.0 + DRIFT.scale_error),
                                 abs=math.radians(0.05))
    # The anchor keeps its given pose, exactly, with a zero covariance.
    first = next(c for c in result.cards if c.ids == anchor.ids.as_tuple())
    assert first.anchor and np.array_equal(first.T_building_card.t, anchor.T_true.t)
    assert not first.covariance.any()


def test_without_odometry_frames_seeing_two_cards_tie_the_room(room):
    plan, walk, sightings = room
    anchor = plan.cards[0]
    result = optimise(sightings, [_motion(walk)], {anchor.ids.as_tuple(): anchor.T_true},
                      SurveyOptions(use_odometry=False))
    assert not result.calibration
    placed = [c for c in result.cards if c.placed]
    assert len(placed) >= 5
    _, relative = _errors(result, plan)
    assert np.sqrt(np.mean(relative ** 2)) < 0.003
    # Only frames with two cards or more are in the graph.
    assert result.frames < len({(s.bag, s.frame) for s in sightings})


def test_a_group_of_cards_seen_apart_is_reported_unconnected(room):
    # Two bags without odometry: one saw cards 1-3, the other cards 4-6, never a card
    # of both in one frame. The second group cannot be placed in the first's frame.
    plan, walk, sightings = room
    first = [s for s in sightings if s.ids[2] <= 3]
    second = [replace(s, bag=1) for s in sightings if s.ids[2] > 3]
    both = {s.frame for s in first} & {s.frame for s in second}
    first = [s for s in first if s.frame not in both]
    second = [s for s in second if s.frame not in both]
    empty = BagMotion('b', 'camera', {})
    result = optimise(first + second, [empty, empty], None, SurveyOptions(use_odometry=False))
    by_card = {c.ids[2]: c for c in result.cards}
    placed = [n for n, c in by_card.items() if c.placed]
    apart = [n for n, c in by_card.items() if n > 3 and c.sightings >= 2]
    assert placed and all(n <= 3 for n in placed)
    assert apart, 'the second group was seen'
    for n in apart:
        card = by_card[n]
        assert not card.connected and card.T_building_card is None and card.covariance is None
    f, r, p = min(c.ids for c in result.cards if c.sightings >= 2)
    assert f'no anchors: the building frame sits on the first card, floor {f} room {r} ' \
        f'card {p}' in result.frame_note


def test_a_wrong_sighting_does_not_move_the_map(room):
    plan, walk, sightings = room
    anchor = plan.cards[0]
    # Ten sightings of one card read 30 cm and 5 degrees off (a flipped pose, say).
    target = sightings[40].ids
    bad = []
    for s in sightings:
        if s.ids == target and len(bad) < 10:
            wrong = Pose(rodrigues(np.array([0.0, math.radians(5.0), 0.0])) @ s.T_camera_card.R,
                         s.T_camera_card.t + np.array([0.3, 0.0, 0.0]))
            bad.append(replace(s, T_camera_card=wrong))
    spoiled = list(sightings) + bad
    result = optimise(spoiled, [_motion(walk)], {anchor.ids.as_tuple(): anchor.T_true})
    assert result.outliers >= 10
    _, relative = _errors(result, plan)
    assert np.sqrt(np.mean(relative ** 2)) < 0.003


def test_anchors_the_bags_never_saw_are_refused(room):
    plan, walk, sightings = room
    unseen = {(4, 40, 4): Pose(np.eye(3), np.zeros(3))}
    with pytest.raises(ConfigError, match='none of the anchors was seen'):
        optimise(sightings, [_motion(walk)], unseen)
