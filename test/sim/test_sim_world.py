"""Sim world: the robot's route over time, the head camera's view and its ground truth."""

from dataclasses import replace
import math

import numpy as np
from pattern_locator.errors import CodeError, ConfigError
from pattern_locator.nodes.bags import sim_stops
from pattern_locator.sim.render import CardPlacement, DotCardTexture, render_scene
from pattern_locator.sim.world import RouteStop, SIM_RENDER_OPTIONS, SimRoute, SimScene
from pattern_locator.visca.zoom_table import ZoomTable
from pattern_locator.vision.geometry import rotation_angle
from pattern_locator.vision.locate import CardLocator
import pytest

SCENE = SimScene()
TABLE = ZoomTable.load()
WIDE = TABLE.camera_at(0)
LOCATOR = CardLocator(SCENE.pattern)


def heading_of(pose):
    return math.atan2(pose.R[1, 0], pose.R[0, 0])


def straight_past_card_1(mode='drive', **timing):
    """Return a drive along the room, 3 m from card 1 (west wall, x = 0, y = 2.5), facing it."""
    stops = [RouteStop((3.0, 1.0), math.pi, 1), RouteStop((3.0, 4.0), math.pi, 1)]
    return SimRoute(stops, mode, **timing)


# Route --------------------------------------------------------------------------------


def test_paper_route_is_the_bag_recordings():
    route = SimRoute.paper_route(dwell_s=2.0)
    recorded = sim_stops(30, seed=7)
    assert len(route.stops) == 30 and route.duration_s == 60.0
    for stop, (T_room_base, number, _, _) in zip(route.stops, recorded):
        assert stop.card == number
        np.testing.assert_allclose(stop.pose().t, T_room_base.t, atol=1e-12)
        assert rotation_angle(stop.pose().R, T_room_base.R) < 1e-9
    assert len(SimRoute.paper_route(n_stops=5).stops) == 5
    with pytest.raises(ConfigError, match='30 stops, asked for 31'):
        SimRoute.paper_route(n_stops=31)


def test_stops_mode_dwells_then_jumps():
    route = SimRoute.paper_route('stops', dwell_s=1.5, n_stops=4)
    assert route.duration_s == 6.0
    for i, stop in enumerate(route.stops):
        assert route.dwell_window(i) == (1.5 * i, 1.5 * (i + 1))
        for t in (1.5 * i, 1.5 * i + 0.7, 1.5 * i + 1.4999):
            assert route.stop_at(t) == i
            pose = route.pose_at(t)
            np.testing.assert_array_equal(pose.t, stop.pose().t)
            np.testing.assert_array_equal(pose.R, stop.pose().R)
    # Before the start and after the end: the first and the last stop.
    assert route.stop_at(-3.0) == 0 and route.stop_at(100.0) == 3
    np.testing.assert_array_equal(route.pose_at(100.0).t, route.stops[-1].pose().t)
    assert route.pose_at(5.0).t[2] == 0.0


def test_drive_mode_timing_speed_and_heading():
    route = SimRoute.paper_route('drive', dwell_s=1.0, speed_m_s=0.3, max_yaw_rate_rad_s=0.5)
    dt = 0.01
    times = np.arange(0.0, route.duration_s + dt, dt)
    poses = [route.pose_at(t) for t in times]
    xy = np.array([p.t[:2] for p in poses])
    speed = np.linalg.norm(np.diff(xy, axis=0), axis=1) / dt
    assert speed.max() <= 0.3 + 1e-9
    assert speed.max() > 0.29                     # it does drive at full speed somewhere
    heading = np.unwrap([heading_of(p) for p in poses])
    yaw_rate = np.abs(np.diff(heading)) / dt
    # Continuous and rate-limited (a jump would show as a huge rate).
    assert yaw_rate.max() <= 0.5 + 1e-6
    assert all(p.t[2] == 0.0 for p in poses)
    states = [route.stop_at(t) for t in times]
    for i, stop in enumerate(route.stops):
        start, end = route.dwell_window(i)
        inside = (times >= start) & (times < end)
        assert inside.any() and all(states[k] == i for k in np.flatnonzero(inside))
        np.testing.assert_allclose(route.pose_at(start + 0.5).t[:2], stop.position)
        assert abs(heading_of(route.pose_at(start + 0.5)) - stop.heading) < 1e-9
    driving = [s is None for s in states]
    assert any(driving)
    # Only the stops' dwell windows are not driving.
    assert sum(not d for d in driving) == pytest.approx(30 * 1.0 / dt, abs=30)


def test_a_big_turn_slows_the_drive_down():
    stops = [RouteStop((1.0, 1.0), 0.0, 1), RouteStop((1.3, 1.0), math.pi / 2, 1)]
    route = SimRoute(stops, 'drive', dwell_s=0.0, speed_m_s=0.3, max_yaw_rate_rad_s=0.5)
    # 90 degrees on a half cosine at 0.5 rad/s peak: pi * (pi/2) / (2 * 0.5) s.
    assert route.duration_s == pytest.approx(math.pi ** 2 / 2.0)
    mid = route.pose_at(route.duration_s / 2.0)
    np.testing.assert_allclose(mid.t, [1.15, 1.0, 0.0], atol=1e-12)
    assert heading_of(mid) == pytest.approx(math.pi / 4.0)


def test_straight_drive_past_a_card():
    route = straight_past_card_1(dwell_s=0.5, speed_m_s=0.25)
    assert route.duration_s == pytest.approx(0.5 + 3.0 / 0.25 + 0.5)
    pose = route.pose_at(0.5 + 6.0)
    np.testing.assert_allclose(pose.t, [3.0, 2.5, 0.0], atol=1e-12)
    assert route.stop_at(6.5) is None and route.stop_at(0.2) == 0 and route.stop_at(12.8) == 1


def test_facing_cards_faces_the_card():
    room = SCENE.room
    route = SimRoute.facing_cards(room, [((3.0, 2.5), 1), ((5.0, 2.5), 3)])
    # Card 1 is straight ahead to -x: heading pi (wrapped to -pi).
    assert abs(route.stops[0].heading) == pytest.approx(math.pi)
    card3 = SCENE.card(3).T_room_card.t
    assert route.stops[1].heading == pytest.approx(math.atan2(card3[1] - 2.5, card3[0] - 5.0))
    with pytest.raises(CodeError, match='has no card 9'):
        SimRoute.facing_cards(room, [((3.0, 2.5), 9)])


@pytest.mark.parametrize('kwargs, message', [
    ({'mode': 'teleport'}, 'mode must be one of stops, drive'),
    ({'speed_m_s': 0.0}, 'speed_m_s must be a positive number'),
    ({'max_yaw_rate_rad_s': float('inf')}, 'max_yaw_rate_rad_s must be a positive'),
    ({'dwell_s': 0.0, 'mode': 'stops'}, 'dwell_s must be a number >= 0.001'),
    ({'dwell_s': -1.0, 'mode': 'drive'}, 'dwell_s must be a number >= 0'),
])
def test_bad_routes(kwargs, message):
    with pytest.raises(ConfigError, match=message):
        SimRoute([RouteStop((1.0, 1.0), 0.0, 1)], **kwargs)
    with pytest.raises(ConfigError, match='at least one stop'):
        SimRoute([])


# Scene: truth -------------------------------------------------------------------------


def aimed_at(number, T_room_base):
    """Return head angles that put card ``number``'s centre on the optical axis."""
    return SCENE.card_angles(T_room_base, 0.0, 0.0, number)


def test_card_angles_are_zero_when_the_head_aims_at_the_card():
    base = RouteStop((4.0, 1.5), 2.8, 1).pose()
    pan, tilt = aimed_at(1, base)
    assert SCENE.card_angles(base, pan, tilt, 1) == pytest.approx((0.0, 0.0), abs=1e-12)
    # The card's centre is then on the optical axis: it images at the principal point.
    T_camera_room = SCENE.true_camera_pose(base, pan, tilt).inverse()
    centre = T_camera_room.apply(SCENE.card(1).T_room_card.t[None])[0]
    np.testing.assert_allclose(centre[:2], [0.0, 0.0], atol=1e-9)
    # Errors are what is left to turn, with REP 103 signs: + pan = left, + tilt = up.
    d_pan, d_tilt = SCENE.card_angles(base, pan - 0.1, tilt + 0.05, 1)
    assert (d_pan, d_tilt) == pytest.approx((0.1, -0.05), abs=1e-9)
    # Seen from the centre of the room card 1 (x = 0) is behind a robot facing +x.
    pan_back, _ = SCENE.card_angles(RouteStop((5.0, 2.5), 0.0, 1).pose(), 0.0, 0.0, 1)
    assert abs(pan_back) == pytest.approx(math.pi, abs=1e-6)
    with pytest.raises(CodeError, match='has no card 42'):
        SCENE.card_angles(base, 0.0, 0.0, 42)


def test_true_camera_pose_is_the_head_chain():
    base = RouteStop((4.0, 1.5), 0.3, 1).pose()
    T = SCENE.true_camera_pose(base, 0.2, -0.1)
    expected = base @ SCENE.head.T_base_camera(0.2, -0.1)
    np.testing.assert_allclose(T.matrix(), expected.matrix())
    assert T.t[2] == pytest.approx(SCENE.head.camera_height(0.2, -0.1))


def test_visible_cards():
    base = RouteStop((3.0, 2.5), math.pi, 1).pose()
    pan, tilt = aimed_at(1, base)
    assert SCENE.visible_cards(base, pan, tilt, WIDE) == [1]
    assert SCENE.visible_cards(base, pan + math.pi, tilt, WIDE) == [4]
    assert SCENE.card_numbers == [1, 2, 3, 4, 5, 6]


# Scene: images ------------------------------------------------------------------------


@pytest.mark.parametrize('zoom', [0, 250])
def test_a_rendered_card_is_located(zoom):
    camera = TABLE.camera_at(zoom)
    route = straight_past_card_1(dwell_s=1.0)
    for t in (2.0, 6.0, 10.0):                          # 3.2 .. 3.6 m from the card
        base = route.pose_at(t)
        pan, tilt = aimed_at(1, base)
        pan, tilt = pan + 0.02, tilt - 0.01                # not quite centred
        image = SCENE.render(base, pan, tilt, camera, seed=3)
        assert image.shape == (480, 640, 3) and image.dtype == np.uint8
        found = [c for c in LOCATOR.locate(image, camera) if c.T_camera_pattern is not None]
        assert [c.detection.ids.as_tuple() for c in found] == [(1, 3, 1)]
        truth = SCENE.true_camera_pose(base, pan, tilt).inverse() @ SCENE.card(1).T_room_card
        error = np.linalg.norm(found[0].camera_in_pattern - truth.inverse().t)
        assert error < 0.03


@pytest.mark.parametrize('case', ['borders', 'corner'])
def test_boxes_render_the_same_image_as_the_whole_frame(case):
    # Rendering only the boxes round the cards is an optimisation: the image
    # must be the one render_scene gives for the whole frame (noise aside),
    # with the wide lens's distortion.
    options = replace(SIM_RENDER_OPTIONS, noise_sigma=0.0, supersample=2)
    scene = SimScene(options=options)
    if case == 'borders':
        # Cards 5 and 6 at the image's left and right borders (5 cut by it).
        base = RouteStop((5.0, 4.5), -math.pi / 2.0, 5).pose()
        pan, tilt = scene.card_angles(base, 0.0, 0.0, 5)
        pan = (pan + scene.card_angles(base, 0.0, 0.0, 6)[0]) / 2.0
        assert scene.visible_cards(base, pan, tilt, WIDE) == [5, 6]
    else:
        # Card 1, 2 m away, in the bottom right corner.
        base = RouteStop((2.0, 2.0), math.pi, 1).pose()
        pan, tilt = scene.card_angles(base, 0.0, 0.0, 1)
        pan, tilt = pan + 0.36, tilt + 0.27
        assert scene.visible_cards(base, pan, tilt, WIDE) == [1]
    image = scene.render(base, pan, tilt, WIDE, seed=5)
    T_camera_room = scene.true_camera_pose(base, pan, tilt).inverse()
    cards = [CardPlacement(T_camera_room @ card.T_room_card,
                           DotCardTexture(scene.pattern, card.code))
             for card in scene.room.cards]
    whole = render_scene(WIDE, cards, replace(options, seed=5)).image
    difference = np.abs(image.astype(int) - whole)
    assert difference.max() <= 1
    assert np.ptp(image) > 100                      # the cards are there


def test_rendering_is_deterministic_for_a_seed():
    base = RouteStop((3.0, 2.0), math.pi, 1).pose()
    pan, tilt = aimed_at(1, base)
    first = SCENE.render(base, pan, tilt, WIDE, seed=11)
    np.testing.assert_array_equal(first, SCENE.render(base, pan, tilt, WIDE, seed=11))
    other = SCENE.render(base, pan, tilt, WIDE, seed=12)
    assert not np.array_equal(first, other)
    # Only noise differs: about the options' noise_sigma (1 grey level).
    assert np.std(first.astype(float) - other) == pytest.approx(math.sqrt(2.0), rel=0.2)


def test_looking_away_from_every_card_gives_the_wall():
    base = RouteStop((5.0, 2.5), 0.0, 4).pose()
    image = SCENE.render(base, 0.0, -0.4, WIDE, seed=1)    # at the floor
    assert SCENE.visible_cards(base, 0.0, -0.4, WIDE) == []
    assert 200 < image.mean() < 245 and image.std() < 15


def test_sim_scene_options_are_checked():
    with pytest.raises(ConfigError, match='background must be white or black'):
        SimScene(options=replace(SIM_RENDER_OPTIONS, background='wall'))
    with pytest.raises(ConfigError, match='gradient must be in'):
        SimScene(options=replace(SIM_RENDER_OPTIONS, gradient=1.5))
    with pytest.raises(CodeError, match='floor 1 room 9 is not in the building map'):
        SimScene(room=9)
