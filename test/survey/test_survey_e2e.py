"""
The survey end to end on a bag written by ``bag record-sim --survey``, with its truth.

The walk's cards hang "as hung" (off the plan by up to 5 cm and 3 degrees);
``truth.yaml`` beside the bag holds where they really are.
"""

import json

from conftest import BAG_FRAMES, BAG_RATE_HZ, BAG_SEED
import numpy as np
from pattern_locator.card.pattern import load_pattern_config
from pattern_locator.cli import main
from pattern_locator.localization.building import load_building
from pattern_locator.sim.walk import make_walk, room_corridor_plan
from pattern_locator.survey.align import apply, fit_transform
import pytest
import yaml

PATTERN = load_pattern_config()


@pytest.fixture(scope='module')
def surveyed(room_bag, tmp_path_factory):
    """Survey the bag with one anchor (the truth's first card); return the outputs."""
    out = tmp_path_factory.mktemp('surveyed')
    truth = load_building(room_bag / 'truth.yaml', PATTERN)
    # The anchor: the card the walk's camera aimed at most in the recorded frames.
    plan = room_corridor_plan(BAG_SEED, PATTERN)
    walk = make_walk(plan, rate_hz=BAG_RATE_HZ, seed=BAG_SEED,
                     duration_s=BAG_FRAMES / BAG_RATE_HZ + 1.0)
    aimed = walk.targets[walk.frames[:BAG_FRAMES]]
    first = truth.card(plan.cards[int(np.bincount(aimed[aimed >= 0]).argmax())].ids)
    anchors = yaml.safe_load((room_bag / 'truth.yaml').read_text())
    anchors['floors'] = [{'floor': first.ids.floor, 'rooms': [
        dict(room, cards=[c for c in room['cards'] if c['pattern'] == first.ids.pattern])
        for room in f['rooms'] if room['room'] == first.ids.room]}
        for f in anchors['floors'] if f['floor'] == first.ids.floor]
    (out / 'anchors.yaml').write_text(yaml.safe_dump(anchors))
    status = main(['survey', str(room_bag), '-o', str(out / 'map.yaml'), '--anchors',
                   str(out / 'anchors.yaml'), '--cards-json', str(out / 'cards.json'),
                   '--report', str(out / 'report'), '--jobs', '2'])  # the pool's path
    return status, out, truth, first


def test_the_surveyed_map_loads_and_matches_the_truth(surveyed, capsys):
    status, out, truth, first = surveyed
    assert status == 0
    building = load_building(out / 'map.yaml', PATTERN)
    cards = building.cards()
    assert len(cards) >= 4
    est = np.array([c.T_building_card.t for c in cards])
    tru = np.array([truth.card(c.ids).T_building_card.t for c in cards])
    # Absolute: the anchor fixes the frame. Relative: after the best similarity.
    assert np.abs(est - tru).max() < 0.02
    T, s = fit_transform(est, tru, scale=True)
    assert np.sqrt(np.mean(np.sum((apply(T, s, est) - tru) ** 2, axis=1))) < 0.005
    assert np.allclose(building.card(first.ids).T_building_card.t, first.T_building_card.t,
                       atol=2e-6)
    for card in cards:
        if card.ids != first.ids:
            assert 0.0 < max(card.std_dev.position_m) < 0.02


def test_the_cards_json_and_the_report_are_written(surveyed):
    _, out, truth, first = surveyed
    doc = json.loads((out / 'cards.json').read_text())
    assert doc['frame'] == 'building'
    by_ids = {(c['floor'], c['room'], c['pattern']): c for c in doc['cards']}
    anchor = by_ids[first.ids.as_tuple()]
    assert anchor['anchor'] is True and anchor['covariance'] == [[0.0] * 6] * 6
    for ids, card in by_ids.items():
        assert card['code'] == str(PATTERN.encode(*ids))
        if card['connected']:
            T = np.array(card['T_building_card'])
            assert T.shape == (4, 4) and np.allclose(T[3], [0, 0, 0, 1])
            cov = np.array(card['covariance'])
            assert cov.shape == (6, 6) and np.allclose(cov, cov.T)
            assert np.linalg.norm(T[:3, 3] - truth.card(ids).T_building_card.t) < 0.02
    assert sorted(p.name for p in (out / 'report').iterdir()) == [
        'floor_1.png', 'report.txt', 'residuals.png']
    notes = (out / 'report' / 'report.txt').read_text()
    assert 'camera mount from tf_static' in notes and 'odometry calibration not estimated' in notes


def test_check_finds_the_card_that_was_moved(surveyed, room_bag, capsys):
    _, out, _, _ = surveyed
    building = load_building(out / 'map.yaml', PATTERN)
    moved_ids = building.cards()[-1].ids
    data = yaml.safe_load((out / 'map.yaml').read_text())
    for f in data['floors']:
        for room in f['rooms']:
            for card in room['cards']:
                if (f['floor'], room['room'], card['pattern']) == moved_ids.as_tuple():
                    card['pose']['position'][0] += 0.05     # rehung 5 cm along the wall
    (out / 'moved.yaml').write_text(yaml.safe_dump(data))
    capsys.readouterr()
    status = main(['survey', '--check', str(out / 'moved.yaml'), str(room_bag), '--jobs', '1'])
    lines = capsys.readouterr().out.splitlines()
    assert status == 1
    label = f'floor {moved_ids.floor} room {moved_ids.room} card {moved_ids.pattern}:'
    flagged = [line for line in lines if 'MOVED' in line]
    assert len(flagged) == 1 and flagged[0].startswith(label), lines
    assert any(' ok ' in line for line in lines)
    assert lines[-1].endswith('1 moved')
