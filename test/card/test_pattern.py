"""Pattern geometry, code layout and the code's text form."""

import numpy as np
from pattern_locator.card.pattern import (Code, Ids, load_pattern_config, pattern_config_from_dict,
                                          PatternConfig)
from pattern_locator.errors import CodeError, ConfigError
from pattern_locator.resources import config_path
import pytest
import yaml


@pytest.fixture(scope='module')
def cfg():
    return load_pattern_config()


def test_shipped_config_matches_the_issue(cfg):
    assert cfg.card_size == pytest.approx(0.300)
    assert cfg.ring_radii == pytest.approx((0.113, 0.072))
    assert cfg.ring_dot_radius == pytest.approx(0.014)
    assert cfg.centre_dot_radius == pytest.approx(0.024)
    assert cfg.n_dots == 17


def test_point_positions_follow_the_pattern_frame(cfg):
    pts = cfg.model_points()
    outer = pts[1:9]
    assert np.allclose(pts[0], 0.0)
    assert np.allclose(outer[0], [0.0, 0.113, 0.0])      # point 1 up
    assert np.allclose(outer[2], [0.113, 0.0, 0.0])      # point 3 right
    assert np.allclose(outer[4], [0.0, -0.113, 0.0])     # point 5 down
    assert np.allclose(outer[6], [-0.113, 0.0, 0.0])     # point 7 left
    inner = pts[9:17]
    assert np.allclose(inner / 0.072, outer / 0.113)
    assert cfg.dot_index(1, 3) == 11
    assert cfg.dot_ring_point(11) == (1, 3)


def test_all_8748_codes_round_trip(cfg):
    seen = set()
    count = 0
    for ids, code in cfg.all_codes():
        text = str(code)
        assert cfg.decode(text) == ids
        assert cfg.decode(Code.parse(text)) == ids
        seen.add(text)
        count += 1
    assert count == 8748 == len(seen)


def test_default_layout_digits(cfg):
    # floor = centre * 3 + point 8; room = points 2-5; pattern = points 6-7.
    code = cfg.encode(floor=7, room=1, pattern=1)
    assert str(code) == 'G-KRRRRRRG'
    assert cfg.decode('B-KBBBBBBB') == Ids(11, 81, 9)
    assert cfg.decode('K-KRRRRRRR') == Ids(0, 1, 1)
    assert cfg.encode(0, 2, 1).ring[4] == 'G'          # point 5 is the room's last digit


@pytest.mark.parametrize('text, words', [
    ('R-RRGBBGRG', 'point 1 must be black'),
    ('R-KRGKBGRG', 'point 4 is K'),
    ('X-KRGBBGRG', 'invalid code'),
    ('R-KRGBBGR', 'invalid code'),
    ('RKRGBBGRG', 'invalid code'),
])
def test_invalid_codes_name_the_problem(cfg, text, words):
    with pytest.raises(CodeError, match=words):
        cfg.decode(text)


@pytest.mark.parametrize('ids, words', [
    ((12, 1, 1), 'floor 12 out of range 0..11'),
    ((0, 0, 1), 'room 0 out of range 1..81'),
    ((0, 82, 1), 'room 82'),
    ((0, 1, 10), 'pattern 10 out of range 1..9'),
    ((0, 1.5, 1), 'room must be an integer'),
])
def test_out_of_range_ids_raise(cfg, ids, words):
    with pytest.raises(CodeError, match=words):
        cfg.encode(*ids)


def test_custom_layout_is_honoured():
    cfg = pattern_config_from_dict({'code': {'fields': {
        'floor': {'dots': [2], 'first': 1},
        'room': {'dots': ['centre', 3, 4, 5], 'first': 0},
        'pattern': {'dots': [6, 7, 8], 'first': 1},
    }}})
    assert cfg.id_ranges()['floor'] == range(1, 4)
    assert cfg.id_ranges()['pattern'] == range(1, 28)
    for ids, code in list(cfg.all_codes())[::97]:
        assert cfg.decode(code) == ids


@pytest.mark.parametrize('data, words', [
    ({'ring_radii': [0.072, 0.113]}, 'outer first'),
    ({'ring_radii': [0.2]}, 'does not fit'),
    ({'ring_dot_radius': 0.03}, 'overlap'),
    ({'colours': {'K': '#000000', 'R': 'red', 'G': '#00ff00', 'B': '#0000ff'}}, 'rrggbb'),
    ({'code': {'fields': {'floor': {'dots': ['centre', 8]}, 'room': {'dots': [2, 3, 4]},
                          'pattern': {'dots': [6, 7]}}}}, 'missing \\[5\\]'),
    ({'code': {'fields': {'floor': {'dots': ['centre', 1]}, 'room': {'dots': [2, 3, 4, 5]},
                          'pattern': {'dots': [6, 7, 8]}}}}, 'not "centre" or a ring point'),
    ({'card_size': 'big'}, 'must be numbers'),
    ({'colors': {'K': '#000000'}}, "unknown key 'colors'"),
    ({'code': {'angles_deg': [22.5]}}, "code: unknown key 'angles_deg'"),
    ({'code': {'fields': {'floor': {'dots': ['centre', 8], 'frist': 0}, 'room': {'dots': [
        2, 3, 4, 5]}, 'pattern': {'dots': [6, 7]}}}}, "fields.floor: unknown key 'frist'"),
    ({'handedness_mark': {'angle_deg': [22.5, 202.5]}}, 'handedness_mark: unknown key'),
    ({'inks': {'K': '#000000', 'R': '#ff0000', 'G': '#00ff00'}}, 'inks must define'),
    ({'inks': ['#000000']}, 'inks must map'),
])
def test_bad_configuration_names_the_problem(data, words):
    with pytest.raises(ConfigError, match=words):
        pattern_config_from_dict(data)


def test_broken_yaml_file_is_one_clear_error(tmp_path):
    bad = tmp_path / 'pattern.yaml'
    bad.write_text('ring_radii: [0.113, 0.072\ncard_size: 0.3\n')
    with pytest.raises(ConfigError, match='malformed YAML at line'):
        load_pattern_config(bad)
    with pytest.raises(ConfigError, match='cannot read'):
        load_pattern_config(tmp_path / 'missing.yaml')


def test_defaults_equal_the_shipped_file(cfg):
    assert PatternConfig() == cfg


def test_the_shipped_file_sets_each_key_where_it_belongs():
    # Its handedness_mark key once sat inside a comment, its angles then
    # under `code:`, silently ignored (now an error).
    data = yaml.safe_load(config_path('pattern.yaml').read_text())
    assert data['handedness_mark'] == {'angles_deg': [22.5, 202.5]}
    assert sorted(data['code']) == ['centre_digits', 'fields', 'ring_digits']


def test_a_key_given_twice_is_refused(tmp_path):
    twice = tmp_path / 'pattern.yaml'
    twice.write_text('card_size: 0.3\ncard_size: 0.2\n')
    with pytest.raises(ConfigError, match='duplicate key'):
        load_pattern_config(twice)


def test_measured_inks_are_read_by_and_printed_from_colours():
    cfg = pattern_config_from_dict({'inks': {'K': '#343434', 'R': '#ee3c42', 'G': '#35aa60',
                                             'B': '#464898'}})
    assert cfg.ink_rgb('B') == (0x46, 0x48, 0x98) and cfg.colour_rgb('B') == (16, 64, 208)
    plain = PatternConfig()
    assert plain.inks_rgb is None and plain.ink_rgb('B') == plain.colour_rgb('B')


def test_handedness_marks_scale_with_the_card_and_are_chiral(cfg):
    mark = cfg.handedness_mark
    assert mark is not None and mark.angles_deg == (22.5, 202.5)
    # Between the rings, as far from the nearest dot of either ring.
    assert cfg.mark_radius == pytest.approx(0.85 * cfg.ring_dot_radius)
    points = cfg.mark_points()
    dots = cfg.model_points()[1:, :2]
    gaps = np.sort(np.linalg.norm(points[0] - dots, axis=1))
    assert gaps[0] == pytest.approx(gaps[1], rel=0.01)
    # Mirror images fall on blank paper: away from every dot and every mark.
    mirrored = cfg.mark_points(mirrored=True)
    assert np.allclose(mirrored, points * [-1.0, 1.0])
    assert np.min(np.linalg.norm(mirrored[:, None] - points[None], axis=2)) > 3 * cfg.mark_radius
    assert np.min(np.linalg.norm(mirrored[:, None] - cfg.model_points()[None, :, :2], axis=2)
                  - cfg.dot_radii()[None]) > 2 * cfg.mark_radius
    small = pattern_config_from_dict({'card_size': 0.2, 'ring_radii': [0.08, 0.05],
                                      'ring_dot_radius': 0.01, 'centre_dot_radius': 0.015})
    assert small.mark_distance == pytest.approx(0.13 / (2 * np.cos(np.pi / 8)))


def test_cards_without_marks_and_explicit_marks():
    paper = pattern_config_from_dict({'handedness_mark': None})
    assert paper.handedness_mark is None and paper.mark_points().shape == (0, 2)
    given = pattern_config_from_dict({'handedness_mark': {'angles_deg': [22.5, 157.5],
                                                          'radius': 0.01, 'distance': 0.095}})
    assert given.mark_radius == 0.01 and given.mark_distance == 0.095


@pytest.mark.parametrize('spec, words', [
    ({'angles_deg': [22.5, 337.5]}, 'mirror-symmetric'),
    ({'angles_deg': [0.0]}, 'within'),
    ({'distance': 0.2}, 'does not fit'),
    ({'radius': 'big'}, 'numbers'),
    ('yes', 'mapping'),
])
def test_bad_handedness_marks_name_the_problem(spec, words):
    with pytest.raises(ConfigError, match=words):
        pattern_config_from_dict({'handedness_mark': spec})


def test_a_mirror_reads_points_two_to_eight_backwards():
    code = Code.parse('B-KRGBBGRG')
    assert code.mirrored() == Code.parse('B-KGRGBBGR')
    assert code.mirrored().mirrored() == code
