"""Building map: the shipped example, frame composition, lookups, validation and printing."""

import math
from pathlib import Path
import textwrap

import numpy as np
# The package is not declared an application import, so it sorts as third party.
from pattern_locator.card.pattern import CENTRE, Code, CodeField, Ids, load_pattern_config
from pattern_locator.card.pattern import PatternConfig
from pattern_locator.errors import CodeError, ConfigError, PrintError
from pattern_locator.localization.building import (building_from_dict, BuildingMap, card_file_name,
                                                   default_room_frame, load_building, rpy_rotation,
                                                   wall_card_rotation, write_building_cards)
from pattern_locator.sim.paper_setup import CARD_HEIGHT, room_cards, ROOM_HEIGHT, ROOM_SIZE
from pattern_locator.vision.geometry import Pose, quaternion_xyzw
import pytest

PATTERN = load_pattern_config()


@pytest.fixture(scope='module')
def building() -> BuildingMap:
    return load_building()


def assert_pose_close(a: Pose, b: Pose, tol: float = 1e-9) -> None:
    np.testing.assert_allclose(a.R, b.R, atol=tol)
    np.testing.assert_allclose(a.t, b.t, atol=tol)


# The shipped example -----------------------------------------------------------


def test_shipped_building_is_the_papers(building):
    assert building.frame == 'building'
    assert building.floors == [0, 1, 2, 3]
    for (floor, number), room in building.rooms.items():
        assert (room.floor, room.room) == (floor, number)
        assert room.frame == default_room_frame(floor, number) == f'floor_{floor}/room_{number}'
        length, width, height = room.size
        assert 45.0 <= length * width <= 55.0
        assert height == pytest.approx(2.5)
        assert 4 <= len(room.cards) <= 6
        assert [c.ids.pattern for c in room.cards] == list(range(1, len(room.cards) + 1))
        # Floor f is at z = 3 f and every room stands upright.
        assert room.T_building_room.t[2] == pytest.approx(3.0 * floor)
        np.testing.assert_allclose(room.T_building_room.R[:, 2], [0, 0, 1], atol=1e-12)
    for floor in building.floors:
        assert 3 <= sum(1 for f, _ in building.rooms if f == floor) <= 4


def test_cards_hang_at_215_on_the_walls_facing_into_the_room(building):
    for room in building.rooms.values():
        length, width, _ = room.size
        centre = room.centre
        for card in room.cards:
            T = card.T_room_card
            x, y, z = T.t
            assert z == pytest.approx(2.15)
            on_wall = (min(abs(x), abs(x - length)) < 1e-9 and 0 < y < width) or (
                min(abs(y), abs(y - width)) < 1e-9 and 0 < x < length)
            assert on_wall, card.label()
            # Upright: card +y is room +z; card +z is horizontal and the room's
            # centre is in front of the card.
            np.testing.assert_allclose(T.R[:, 1], [0, 0, 1], atol=1e-12)
            assert abs(T.R[2, 2]) < 1e-12
            assert (centre - T.t) @ T.R[:, 2] > 1.0
            np.testing.assert_allclose(T.R.T @ T.R, np.eye(3), atol=1e-12)
            assert np.linalg.det(T.R) == pytest.approx(1.0)


def test_rooms_of_a_floor_do_not_overlap(building):
    boxes = {}
    for key, room in building.rooms.items():
        length, width, _ = room.size
        corners = room.T_building_room.apply(
            [[0, 0, 0], [length, 0, 0], [0, width, 0], [length, width, 0]])
        boxes[key] = (corners[:, 0].min(), corners[:, 1].min(), corners[:, 0].max(),
                      corners[:, 1].max())
    keys = sorted(boxes)
    for i, a in enumerate(keys):
        for b in keys[i + 1:]:
            if a[0] != b[0]:
                continue
            (ax0, ay0, ax1, ay1), (bx0, by0, bx1, by1) = boxes[a], boxes[b]
            overlap = max(0.0, min(ax1, bx1) - max(ax0, bx0)) * max(
                0.0, min(ay1, by1) - max(ay0, by0))
            assert overlap < 1e-9, (a, b)


def test_building_pose_is_room_pose_then_card_pose(building):
    for room in building.rooms.values():
        for card in room.cards:
            assert card.room_frame == room.frame
            assert_pose_close(card.T_building_card, room.T_building_room @ card.T_room_card)
    # One by hand: floor 1 room 3 is turned 180 degrees about z at (10, 12, 3),
    # so its card 1 (room x = 0, y = 2.5, facing room +x) faces building -x.
    card = building.card(Ids(1, 3, 1))
    np.testing.assert_allclose(card.T_building_card.t, [10.0, 9.5, 5.15], atol=1e-12)
    np.testing.assert_allclose(card.T_building_card.R[:, 2], [-1, 0, 0], atol=1e-12)


def test_papers_room_matches_paper_setup(building):
    room = building.room(1, 3)
    assert room.size == pytest.approx(ROOM_SIZE + (ROOM_HEIGHT,))
    expected = room_cards()
    assert [c.ids.pattern for c in room.cards] == [c.number for c in expected]
    for card, wall_card in zip(room.cards, expected):
        assert_pose_close(card.T_room_card, wall_card.T_room_card, 1e-12)
        assert card.T_room_card.t[2] == CARD_HEIGHT


def test_every_code_is_the_code_of_its_ids(building):
    cards = building.cards()
    assert len(cards) == sum(len(r.cards) for r in building.rooms.values())
    assert [c.ids.as_tuple() for c in cards] == sorted(c.ids.as_tuple() for c in cards)
    assert len({c.code for c in cards}) == len(cards)
    for card in cards:
        assert card.code == PATTERN.encode(*card.ids.as_tuple())
        assert PATTERN.decode(card.code) == card.ids


def test_lookup_by_ids_code_room_and_frame(building):
    card = building.card(Ids(2, 4, 3))
    assert card.ids == Ids(2, 4, 3)
    assert building.card((2, 4, 3)) is card
    assert building.card_by_code(card.code) is card
    assert building.card_by_code(str(card.code).lower()) is card
    assert building.room(2, 4).cards[2] is card
    assert building.room_by_frame('floor_2/room_4') is building.room(2, 4)
    with pytest.raises(CodeError, match='card floor 2 room 4 pattern 9 is not in the building '
                                        'map'):
        building.card(Ids(2, 4, 9))
    missing = PATTERN.encode(0, 4, 1)          # the ground floor has no room 4
    with pytest.raises(CodeError, match=f'code {missing} is not in the building map'):
        building.card_by_code(missing)
    with pytest.raises(CodeError, match='invalid code'):
        building.card_by_code('X-KRGB')
    with pytest.raises(CodeError, match='floor 0 room 4 is not in the building map'):
        building.room(0, 4)
    with pytest.raises(CodeError, match='frame'):
        building.room_by_frame('floor_9/room_9')


def test_mirror_pairs_are_the_cards_a_reflection_confuses(building):
    pairs = building.mirror_pairs()
    # The paper's building holds one such pair (and self-mirrored codes, which are none).
    assert [(a.code, b.code) for a, b in pairs] == \
        [(a.code, a.code.mirrored()) for a, _ in pairs]
    assert len(pairs) == 1
    a, b = pairs[0]
    assert a.code.mirrored() == b.code and b.code.mirrored() == a.code and a.code != b.code
    for card in building.cards():
        if card.code.mirrored() == card.code:
            assert all(card not in pair for pair in pairs)


# Orientation forms ----------------------------------------------------------------


def test_rpy_is_fixed_axis_roll_then_pitch_then_yaw():
    np.testing.assert_allclose(rpy_rotation(0, 0, math.pi / 2) @ [1, 0, 0], [0, 1, 0],
                               atol=1e-12)
    np.testing.assert_allclose(rpy_rotation(math.pi / 2, 0, 0) @ [0, 1, 0], [0, 0, 1],
                               atol=1e-12)
    np.testing.assert_allclose(rpy_rotation(0, math.pi / 2, 0) @ [0, 0, 1], [1, 0, 0],
                               atol=1e-12)
    # Roll first about the fixed x axis, then yaw about the fixed z axis:
    # y -> z (roll), z stays (yaw).
    np.testing.assert_allclose(rpy_rotation(math.pi / 2, 0, math.pi / 2) @ [0, 1, 0],
                               [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(rpy_rotation(math.pi / 2, 0, math.pi / 2) @ [1, 0, 0],
                               [0, 1, 0], atol=1e-12)


def _one_card_room(card_pose: dict, room_pose: dict = None, **room) -> dict:
    room_pose = room_pose or {'position': [0, 0, 0], 'rpy_deg': [0, 0, 0]}
    return {'floors': [{'floor': 1, 'rooms': [
        dict({'room': 3, 'pose': room_pose, 'cards': [{'pattern': 2, 'pose': card_pose}]},
             **room)]}]}


@pytest.mark.parametrize('facing', [0.0, 90.0, -90.0, 180.0, 33.0, -147.5])
def test_rpy_quaternion_rotation_and_facing_forms_agree(facing):
    R = wall_card_rotation(facing)
    position = [1.5, -2.0, 2.15]
    forms = [
        {'position': position, 'facing_deg': facing},
        {'position': position, 'rpy_deg': [90.0, 0.0, facing + 90.0]},
        {'position': position, 'quaternion': [float(v) for v in quaternion_xyzw(R)]},
        {'position': position, 'rotation': [[float(v) for v in row] for row in R]},
    ]
    poses = [building_from_dict(_one_card_room(form), PATTERN, 'test').card(
        Ids(1, 3, 2)).T_room_card for form in forms]
    for pose in poses:
        assert_pose_close(pose, poses[0], 1e-9)
    np.testing.assert_allclose(poses[0].R[:, 2], [math.cos(math.radians(facing)),
                                                  math.sin(math.radians(facing)), 0], atol=1e-12)


def test_near_unit_quaternion_and_rounded_rotation_are_accepted():
    half = math.sqrt(0.5)
    data = _one_card_room({'position': [0, 0, 0], 'quaternion': [0, 0, half, half + 4e-7]})
    R = building_from_dict(data, PATTERN, 'test').card(Ids(1, 3, 2)).T_room_card.R
    np.testing.assert_allclose(R, rpy_rotation(0, 0, math.pi / 2), atol=1e-6)
    assert np.abs(R.T @ R - np.eye(3)).max() < 1e-12
    # Six decimals, as a person types them: within 1e-6 and made exact.
    data = _one_card_room({'position': [0, 0, 0], 'rotation': [
        [0.707107, -0.707107, 0], [0.707107, 0.707107, 0], [0, 0, 1]]})
    R = building_from_dict(data, PATTERN, 'test').card(Ids(1, 3, 2)).T_room_card.R
    assert np.abs(R.T @ R - np.eye(3)).max() < 1e-12
    np.testing.assert_allclose(R, rpy_rotation(0, 0, math.pi / 4), atol=1e-6)


def test_room_relative_to_an_earlier_room():
    data = {'floors': [
        {'floor': 0, 'rooms': [{'room': 1, 'pose': {'position': [5, 0, 0],
                                                    'rpy_deg': [0, 0, 90]}}]},
        {'floor': 1, 'rooms': [{'room': 1, 'relative_to': {'floor': 0, 'room': 1},
                                'pose': {'position': [1, 0, 3], 'rpy_deg': [0, 0, 0]},
                                'cards': [{'pattern': 1, 'pose': {
                                    'position': [0, 2, 2.15], 'facing_deg': 0}}]}]}]}
    building = building_from_dict(data, PATTERN, 'test')
    np.testing.assert_allclose(building.room(1, 1).T_building_room.t, [5, 1, 3], atol=1e-12)
    card = building.card(Ids(1, 1, 1))
    np.testing.assert_allclose(card.T_building_card.t, [3, 1, 5.15], atol=1e-12)
    np.testing.assert_allclose(card.T_building_card.R[:, 2], [0, 1, 0], atol=1e-12)


def test_optional_parts_and_custom_frames():
    data = {'building': {'frame': 'map'}, 'floors': [
        {'floor': 0, 'name': 'cellar', 'rooms': [
            {'room': 7, 'frame': 'lab', 'pose': {'position': [0, 0, 0], 'rpy_deg': [0, 0, 0]}}]},
        {'floor': 5}]}
    building = building_from_dict(data, PATTERN, 'test')
    assert building.frame == 'map'
    assert building.floors == [0, 5]
    assert building.floor_names == {0: 'cellar', 5: ''}
    room = building.room(0, 7)
    assert (room.frame, room.size, room.cards, room.centre) == ('lab', None, (), None)
    assert building.cards() == []


# Validation errors ---------------------------------------------------------------------

ROOM_POSE = '{position: [0, 0, 0], rpy_deg: [0, 0, 0]}'
CARD_POSE = '{position: [0, 2.5, 2.15], facing_deg: 0}'
CODE_1_3_2 = str(PATTERN.encode(1, 3, 2))


def _yaml(cards: str = f'- {{pattern: 2, pose: {CARD_POSE}}}', rooms: str = None,
          floors: str = None) -> str:
    if rooms is None:
        rooms = (f'- room: 3\n  pose: {ROOM_POSE}\n  cards:\n'
                 + textwrap.indent(cards, '    '))
    if floors is None:
        floors = '- floor: 1\n  rooms:\n' + textwrap.indent(rooms, '    ')
    return 'building: {frame: building}\nfloors:\n' + textwrap.indent(floors, '  ')


def _card_yaml(pose: str) -> str:
    return _yaml(f'- {{pattern: 2, pose: {pose}}}')


ROOM_3 = f'- {{room: 3, pose: {ROOM_POSE}}}\n'
BAD = {
    'code mismatch': (
        _yaml(f'- {{pattern: 2, code: R-KRGBGRBB, pose: {CARD_POSE}}}'),
        'floor 1 room 3 card 2: code R-KRGBGRBB does not match floor 1 room 3 card 2 '
        f'(expected {CODE_1_3_2}; R-KRGBGRBB is floor 5 room 17 card 3)'),
    'invalid code text': (
        _yaml(f'- {{pattern: 2, code: K-KRGKRRRR, pose: {CARD_POSE}}}'),
        'floor 1 room 3 card 2: code: invalid code'),
    'duplicate code': (
        _yaml(f'- {{pattern: 2, pose: {CARD_POSE}}}\n- {{pattern: 1, pose: {CARD_POSE}}}\n'
              f'- {{pattern: 2, code: {CODE_1_3_2}, pose: {CARD_POSE}}}'),
        f'floor 1 room 3 card 2: duplicate code {CODE_1_3_2}: card 2 is listed twice in '
        'floor 1 room 3'),
    'duplicate room': (
        _yaml(rooms=ROOM_3 + ROOM_3),
        'floor 1 room 3: duplicate room (listed twice on floor 1)'),
    'duplicate floor': (
        _yaml(floors='- {floor: 1}\n- {floor: 1}'), 'floor 1: duplicate floor'),
    'duplicate frame': (
        _yaml(rooms=ROOM_3 + f'- {{room: 4, frame: floor_1/room_3, pose: {ROOM_POSE}}}'),
        "floor 1 room 4: duplicate frame 'floor_1/room_3' (also floor 1 room 3)"),
    'room frame is the building frame': (
        _yaml(rooms=f'- {{room: 4, frame: building, pose: {ROOM_POSE}}}'),
        "floor 1 room 4: duplicate frame 'building' (also the building frame)"),
    'bad frame name': (
        _yaml(rooms=f'- {{room: 4, frame: /room 4, pose: {ROOM_POSE}}}'),
        'floor 1 room 4: frame must be a tf2 frame name'),
    'floor out of range': (
        _yaml(floors='- {floor: 12}'),
        'floor 12: ids out of range: floor 12 is not in 0..11 under the pattern configuration'),
    'room out of range': (
        _yaml(rooms=f'- {{room: 0, pose: {ROOM_POSE}}}'),
        'floor 1 room 0: ids out of range: room 0 is not in 1..81'),
    'card out of range': (
        _yaml(f'- {{pattern: 10, pose: {CARD_POSE}}}'),
        'floor 1 room 3 card 10: ids out of range: pattern 10 is not in 1..9'),
    'id not an integer': (
        _yaml(f'- {{pattern: 2.0, pose: {CARD_POSE}}}'),
        'floor 1 room 3 cards[0]: pattern must be an integer, got 2.0'),
    'id a boolean': (
        _yaml(floors='- {floor: true}'), 'floors[0]: floor must be an integer, got True'),
    'unknown room': (
        _yaml(rooms=f'- {{room: 4, relative_to: {{floor: 1, room: 3}}, pose: {ROOM_POSE}}}\n'
              + ROOM_3),
        'floor 1 room 4: relative_to: unknown room floor 1 room 3 (name a room listed '
        'earlier in the file)'),
    'unknown top-level key': (
        _yaml() + '\nflors: []', "unknown key 'flors' (did you mean 'floors'? allowed: "
                                 'building, floors)'),
    'unknown room key': (
        _yaml(rooms=f'- {{room: 3, pose: {ROOM_POSE}, card: []}}'),
        "floor 1 room 3: unknown key 'card' (did you mean 'cards'?"),
    'unknown card key': (
        _yaml(f'- {{pattern: 2, pose: {CARD_POSE}, colour: red}}'),
        "floor 1 room 3 card 2: unknown key 'colour'"),
    'unknown pose key': (
        _card_yaml('{postion: [0, 0, 0], facing_deg: 0}'),
        "floor 1 room 3 card 2: pose: unknown key 'postion' (did you mean 'position'?"),
    'missing pose': (
        _yaml('- {pattern: 2}'), "floor 1 room 3 card 2: missing 'pose'"),
    'missing card number': (
        _yaml(f'- {{pose: {CARD_POSE}}}'), "floor 1 room 3 cards[0]: missing 'pattern'"),
    'unknown floor key': (
        _yaml(floors='- {floor: 1, room: []}'),
        "floor 1: unknown key 'room' (did you mean 'rooms'?"),
    'card not a mapping': (
        _yaml('- 2'), 'floor 1 room 3 cards[0]: expected a mapping with keys pattern, code, '
                      'pose, std_dev; got 2'),
    'missing floors': ('building: {frame: building}\n', "missing 'floors'"),
    'no floors': ('floors: []\n', 'floors must be a non-empty list, got an empty list'),
    'top level a list': ('- floor: 1\n', 'expected a mapping with "floors" at the top level'),
    'empty file': ('', 'expected a mapping with "floors" at the top level, got nothing'),
    'pose not a mapping': (
        _card_yaml('[0, 2.5, 2.15]'), 'floor 1 room 3 card 2: pose: expected a mapping'),
    'missing position': (
        _card_yaml('{facing_deg: 0}'), "floor 1 room 3 card 2: pose: missing 'position'"),
    'two numbers for a position': (
        _card_yaml('{position: [0, 2.5], facing_deg: 0}'),
        'floor 1 room 3 card 2: pose: position must be [x, y, z] in metres, got [0, 2.5]'),
    'number as text': (
        _card_yaml('{position: [0, 2.5, 1e-3], facing_deg: 0}'),
        "floor 1 room 3 card 2: pose: position: '1e-3' is text, not a number"),
    'not finite': (
        _card_yaml('{position: [0, .nan, 2.15], facing_deg: 0}'),
        'floor 1 room 3 card 2: pose: position must be [x, y, z] in metres'),
    'no orientation': (
        _card_yaml('{position: [0, 2.5, 2.15]}'),
        'floor 1 room 3 card 2: pose: give exactly one orientation of rpy_deg, quaternion, '
        'rotation, facing_deg; got none'),
    'two orientations': (
        _card_yaml('{position: [0, 2.5, 2.15], facing_deg: 0, rpy_deg: [90, 0, 90]}'),
        'pose: give exactly one orientation of rpy_deg, quaternion, rotation, facing_deg; '
        'got rpy_deg, facing_deg'),
    'facing a list': (
        _card_yaml('{position: [0, 2.5, 2.15], facing_deg: [0]}'),
        'pose: facing_deg must be one number in degrees, got [0]'),
    'short rpy': (
        _card_yaml('{position: [0, 2.5, 2.15], rpy_deg: [90, 0]}'),
        'pose: rpy_deg must be [roll, pitch, yaw] in degrees'),
    'non-unit quaternion': (
        _card_yaml('{position: [0, 2.5, 2.15], quaternion: [0, 0, 0.5, 0.5]}'),
        'floor 1 room 3 card 2: pose: quaternion [0, 0, 0.5, 0.5] is not unit (norm 0.707107'),
    'non-orthonormal rotation': (
        _yaml(rooms='- room: 3\n  pose: {position: [0, 0, 0], rotation: '
                    '[[1, 0, 0], [0, 1, 0.01], [0, 0, 1]]}'),
        'floor 1 room 3: pose: rotation is not orthonormal (R^T R differs from the identity '
        'by 0.01'),
    'rounded too coarsely': (
        _card_yaml('{position: [0, 0, 0], rotation: '
                   '[[0.7071, -0.7071, 0], [0.7071, 0.7071, 0], [0, 0, 1]]}'),
        'pose: rotation is not orthonormal'),
    'reflection': (
        _card_yaml('{position: [0, 0, 0], rotation: [[-1, 0, 0], [0, 1, 0], [0, 0, 1]]}'),
        'floor 1 room 3 card 2: pose: rotation is not orthonormal with det +1 (det -1'),
    'rotation not 3x3': (
        _card_yaml('{position: [0, 0, 0], rotation: [[1, 0, 0], [0, 1, 0]]}'),
        'pose: rotation must be a 3x3 matrix'),
    'bad size': (
        _yaml(rooms=f'- {{room: 3, pose: {ROOM_POSE}, size: [10, 0, 2.5]}}'),
        'floor 1 room 3: size must be positive'),
    'rooms not a list': (
        _yaml(floors='- {floor: 1, rooms: {room: 3}}'), 'floor 1: rooms must be a list'),
    'malformed YAML': (
        _yaml() + '\n  - {floor: 2\n', 'malformed YAML at line 1'),
    'duplicate key': (
        _yaml(rooms=f'- room: 3\n  pose: {ROOM_POSE}\n  pose: {ROOM_POSE}'),
        "malformed YAML at line 7: duplicate key 'pose'"),
}


@pytest.mark.parametrize('case', sorted(BAD))
def test_each_problem_is_named_in_one_line(tmp_path, case):
    text, words = BAD[case]
    path = tmp_path / 'building.yaml'
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_building(path, PATTERN)
    message = str(info.value)
    assert '\n' not in message
    assert message.startswith(f'{path}: ')
    if case == 'malformed YAML':
        # The unclosed flow mapping is reported where the parser gives up.
        line = len((_yaml() + '\n  - {floor: 2\n').splitlines()) + 1
        assert f'malformed YAML at line {line}' in message
    else:
        assert words in message, message


def test_good_example_of_the_error_cases_loads(tmp_path):
    # The bad cases above differ from this one only in the named problem.
    path = tmp_path / 'building.yaml'
    path.write_text(_yaml(f'- {{pattern: 2, code: {CODE_1_3_2}, pose: {CARD_POSE}}}'))
    assert load_building(path, PATTERN).card(Ids(1, 3, 2)).code == Code.parse(CODE_1_3_2)


def test_missing_file_is_named(tmp_path):
    with pytest.raises(ConfigError, match='cannot read the building map'):
        load_building(tmp_path / 'nowhere.yaml')


def test_codes_are_checked_under_the_given_pattern_configuration(tmp_path):
    # The same map under another code layout: its written codes no longer match.
    reversed_rooms = PatternConfig(fields=(
        CodeField('floor', (CENTRE, 8), 0), CodeField('room', (5, 4, 3, 2), 1),
        CodeField('pattern', (6, 7), 1)))
    # (Room 1 is RRRR either way round: room 2 is the first that differs.)
    with pytest.raises(ConfigError, match=r'floor 0 room 2 card 1: code \S+ does not match '
                                          r'floor 0 room 2 card 1 \(expected'):
        load_building(pattern=reversed_rooms)
    # Without written codes it loads, with that layout's codes.
    path = tmp_path / 'building.yaml'
    path.write_text(_yaml())
    card = load_building(path, reversed_rooms).card(Ids(1, 3, 2))
    assert card.code == reversed_rooms.encode(1, 3, 2) != PATTERN.encode(1, 3, 2)


# Printing ---------------------------------------------------------------------------------


def _two_card_building() -> BuildingMap:
    data = {'floors': [{'floor': 1, 'rooms': [
        {'room': 3, 'pose': {'position': [0, 0, 0], 'rpy_deg': [0, 0, 0]}, 'cards': [
            {'pattern': 1, 'pose': {'position': [0, 2.5, 2.15], 'facing_deg': 0}},
            {'pattern': 2, 'pose': {'position': [3, 5, 2.15], 'facing_deg': -90}}]}]}]}
    return building_from_dict(data, PATTERN, 'two.yaml')


def test_write_building_cards_writes_one_named_file_per_card(tmp_path):
    building = _two_card_building()
    out = tmp_path / 'cards' / 'nested'
    written = write_building_cards(building, PATTERN, out, fmt='svg')
    names = [f'floor1_room3_card{p}_{PATTERN.encode(1, 3, p)}.svg' for p in (1, 2)]
    assert [p.name for p in written] == names
    assert sorted(p.name for p in out.iterdir()) == sorted(names)
    for path in written:
        assert path.read_text().lstrip().startswith('<?xml')
    assert card_file_name(building.card(Ids(1, 3, 2))) == names[1].replace('.svg', '.pdf')


def test_write_building_cards_failures(tmp_path):
    building = _two_card_building()
    with pytest.raises(PrintError, match="unknown card format 'jpg'"):
        write_building_cards(building, PATTERN, tmp_path, fmt='jpg')
    blocker = tmp_path / 'file'
    blocker.write_text('')
    with pytest.raises(PrintError, match='cannot create the output directory'):
        write_building_cards(building, PATTERN, blocker / 'cards', fmt='svg')
    other = PatternConfig(fields=(
        CodeField('floor', (CENTRE, 8), 0), CodeField('room', (5, 4, 3, 2), 1),
        CodeField('pattern', (6, 7), 1)))
    with pytest.raises(ConfigError, match='two.yaml: floor 1 room 3 card 1: the map has code'):
        write_building_cards(building, other, tmp_path / 'x', fmt='svg')
    assert not (tmp_path / 'x').exists()
    with pytest.raises(ConfigError):
        write_building_cards(building, PATTERN, tmp_path / 'y', paper='b5', fmt='svg')


def test_shipped_paths_are_the_package_config():
    assert Path(load_building().source).name == 'building.yaml'
