"""The layout check (``localization/layout_check.py``, ``pattern-locator check-layout``)."""

import copy
import math

from pattern_locator.card.pattern import load_pattern_config
from pattern_locator.cli import main
from pattern_locator.errors import ConfigError
from pattern_locator.localization.building import building_from_dict
from pattern_locator.localization.gaze import GazePlanner
from pattern_locator.localization.head import HeadGeometry
from pattern_locator.localization.layout_check import check_rooms, check_route, \
    floor_height, head_and_gaze, locator_parameters, read_route, route_poses
from pattern_locator.resources import config_path
import pytest
import yaml

FLOOR_MAP = config_path('floor_building.yaml')
SIM_FLOOR = config_path('sim_floor.yaml')
SOUTH_CORRIDOR = [(2.0, 6.3), (23.7, 6.3)]


@pytest.fixture(scope='module')
def floor_data():
    with open(FLOOR_MAP) as f:
        return yaml.safe_load(f)


def planner_for(data):
    building = building_from_dict(data, load_pattern_config(), 'test map')
    return building, GazePlanner(building, HeadGeometry())


def without_south_corridor_signs(data):
    """Return the floor map with only the end cards of the south corridor (rooms 9, 13)."""
    data = copy.deepcopy(data)
    for room in data['floors'][0]['rooms']:
        if room['room'] in (9, 13):
            room['cards'] = [c for c in room['cards']
                             if c['pose']['position'][0] in (0.0, 12.3)
                             and c['pose']['position'][1] == 1.0]
    return data


def test_the_shipped_floor_routes_always_have_a_card_in_view(floor_data):
    building, planner = planner_for(floor_data)
    for name in ('loop', 'tour'):
        waypoints, _, _ = read_route(f'{SIM_FLOOR}:{name}')
        result = check_route(planner, waypoints, floor_height(building, 4), step_m=0.2)
        assert result.length_m > 90.0
        # Doorways (the map has no doors, so the planner sees no further) only.
        assert result.longest_m() <= 1.0, result.stretches


def test_a_corridor_without_its_signs_is_blind_for_metres(floor_data):
    building, planner = planner_for(floor_data)
    z = floor_height(building, 4)
    assert check_route(planner, SOUTH_CORRIDOR, z, 0.2).longest_m() <= 1.0
    building, planner = planner_for(without_south_corridor_signs(floor_data))
    result = check_route(planner, SOUTH_CORRIDOR, z, 0.2)
    # The west end card is behind, the east end beyond 8 m until the last 8 m.
    assert result.longest_m() >= 8.0
    first = result.stretches[0]
    assert first.start_xy[0] < 4.0 and first.end_xy[0] > 12.0 and not first.turning


def test_a_route_turns_in_place_at_its_corners():
    poses = route_poses([(0.0, 0.0), (2.0, 0.0), (2.0, 2.0)], 0.0, 0.5)
    turning = [p for _, p, t in poses if t]
    headings = [math.degrees(math.atan2(p.R[1, 0], p.R[0, 0])) for p in turning]
    assert len(turning) == 8 and all(0.0 < h < 90.0 for h in headings)
    assert poses[-1][0] == pytest.approx(4.0)
    with pytest.raises(ConfigError, match='two or more'):
        route_poses([(0.0, 0.0)], 0.0)
    with pytest.raises(ConfigError, match='two or more'):
        route_poses([(0.0, 0.0), (math.nan, 1.0)], 0.0)
    with pytest.raises(ConfigError, match='distinct'):
        route_poses([(1.0, 2.0), (1.0, 2.0)], 0.0)


def test_a_room_sampled_on_a_grid(floor_data):
    building, planner = planner_for(floor_data)
    rooms = check_rooms(planner, building, 4, step_m=2.0, headings=4)
    assert {r.room for r in rooms} == set(range(1, 15))
    for r in rooms:
        assert r.views == 4 * r.places and 0 < r.views_with_card <= r.views
    with pytest.raises(ConfigError, match='no room on floor 7'):
        floor_height(building, 7)


def test_routes_in_three_formats(tmp_path):
    plain = tmp_path / 'plain.yaml'
    plain.write_text('[[0, 0], [1, 2.5]]\n')
    assert read_route(str(plain)) == ([(0.0, 0.0), (1.0, 2.5)], None, 'plain')
    mapping = tmp_path / 'mapping.yaml'
    mapping.write_text('floor: 4\nwaypoints: [[0, 0], [1, 0]]\n')
    assert read_route(str(mapping))[1] == 4
    waypoints, floor, name = read_route(f'{SIM_FLOOR}:short')
    assert name == 'short' and floor == 4 and waypoints[0] == (3.5, 6.3)
    with pytest.raises(ConfigError, match='one of tour, loop, short'):
        read_route(str(SIM_FLOOR))
    bad = tmp_path / 'bad.yaml'
    bad.write_text('[[0, 0], [1]]\n')
    with pytest.raises(ConfigError, match='waypoint must be'):
        read_route(str(bad))


def test_the_locator_params_give_the_head_and_gaze():
    with open(config_path('locator.yaml')) as f:
        params = locator_parameters(yaml.safe_load(f))
    head, gaze = head_and_gaze({**params, 'head.mount_pitch_deg': 15.0,
                                'gaze.max_distance_m': 6.0})
    assert head.mount_pitch_rad == pytest.approx(math.radians(15.0))
    assert gaze.max_distance_m == 6.0
    with pytest.raises(ConfigError, match='ros__parameters'):
        locator_parameters({'locator': {}})
    with pytest.raises(ConfigError, match='not a mapping'):
        locator_parameters(['locator'])
    with pytest.raises(ConfigError):
        head_and_gaze({'gaze.max_distance_m': -1.0})


def test_the_command_line_exits_1_on_a_blind_route(tmp_path, floor_data, capsys):
    route = tmp_path / 'corridor.yaml'
    waypoints = [list(p) for p in SOUTH_CORRIDOR]
    route.write_text(yaml.safe_dump({'floor': 4, 'waypoints': waypoints}))
    assert main(['check-layout', str(FLOOR_MAP), '--route', str(route), '--step', '0.25']) == 0
    assert 'route corridor (floor 4)' in capsys.readouterr().out
    blind = tmp_path / 'blind.yaml'
    blind.write_text(yaml.safe_dump(without_south_corridor_signs(floor_data)))
    assert main(['check-layout', str(blind), '--route', str(route), '--step', '0.25']) == 1
    assert 'BLIND' in capsys.readouterr().out
    assert main(['check-layout', str(FLOOR_MAP), '--route', str(tmp_path / 'none.yaml')]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith('pattern-locator: error:') and '\n' not in err
