"""
A card partly hidden, its code completed from the map: followed, never a start.

The detector completes a code whose slots an object hides from the map's
codes when exactly one fits (``vision/code_reading.resolve_partial``). A
card missing from the map can fit a mapped code on the slots that show, so
``RobotLocalizer`` takes such a fix only where its last fix puts the robot
(``gates.check_partial``). When several mapped codes fit the slots seen,
the detector hands them all on (``CardDetection.candidates``) and the
localizer takes the one that puts the robot where its last fix allows, only
when exactly one does. Rendered on the drive floor: an object painted over
both dots of one ring point of a corridor card.
"""

import dataclasses
import math

import cv2
import numpy as np
from pattern_locator.localization.building import BuildingMap
from pattern_locator.localization.gates import FixGates, GateParameters
from pattern_locator.localization.head import HeadGeometry
from pattern_locator.localization.localizer import RobotLocalizer
from pattern_locator.localization.target_choice import seen_cards
from pattern_locator.sim.drive import yaw_pose
from pattern_locator.sim.floor_file import load_floor_world
from pattern_locator.sim.floor_scene import FloorScene
from pattern_locator.vision.camera import CameraModel
from pattern_locator.vision.geometry import Pose, rodrigues
import pytest

WORLD = load_floor_world()
HEAD = HeadGeometry()
CAMERA = CameraModel.from_focal(640, 480, 900.0)
IDS = (4, 12, 3)            # the east corridor's west wall card, facing east
BASE = yaw_pose(24.3, 10.0, math.pi, 12.0)


def _hide_point(clean, T_camera_card, point):
    """Return ``clean`` with an object painted over both dots of ring ``point``."""
    pattern = WORLD.pattern
    points = [pattern.model_points()[pattern.dot_index(r, point)] for r in range(pattern.n_rings)]
    px = CAMERA.project(T_camera_card.apply(np.array(points)))
    radius = 2.2 * pattern.ring_dot_radius * CAMERA.fx / float(np.linalg.norm(T_camera_card.t))
    hidden = clean.copy()
    a, b = px[0], px[-1]
    along = (b - a) / np.linalg.norm(b - a)
    side = np.array([-along[1], along[0]]) * radius
    band = np.array([a - along * radius + side, a - along * radius - side,
                     b + along * radius - side, b + along * radius + side])
    cv2.fillConvexPoly(hidden, np.round(band).astype(np.int32), (70, 80, 95))
    return hidden


@pytest.fixture(scope='module')
def scene():
    """Return (head pan, tilt, the clean image, the card in the camera frame)."""
    card = WORLD.card(IDS)
    pan, tilt = HEAD.aim_angles(BASE.inverse().apply(card.T_building_card.t[None])[0])
    scene = FloorScene(WORLD, HEAD)
    T_camera = scene.true_camera_pose(BASE, pan, tilt)
    clean = scene.render_still(T_camera, CAMERA, seed=3)
    return pan, tilt, clean, T_camera.inverse() @ card.T_building_card


@pytest.fixture(scope='module')
def frames(scene):
    """Return (head pan, tilt, the clean image, the image with ring point 2 hidden)."""
    pan, tilt, clean, T_camera_card = scene
    return pan, tilt, clean, _hide_point(clean, T_camera_card, 2)


def localizer(building=WORLD.building):
    return RobotLocalizer(WORLD.pattern, building, HEAD, output_frame='building',
                          gates=GateParameters(footprint='adjacent'))


def test_a_partly_hidden_card_is_read_from_the_map(frames):
    pan, tilt, _, hidden = frames
    dets = localizer().locator.detector.detect(hidden, CAMERA)
    assert [(d.ids.as_tuple(), d.slots_from_map) for d in dets] == [(IDS, 1)]


def test_it_follows_a_located_robot_and_never_starts_one(frames):
    pan, tilt, clean, hidden = frames
    loc = localizer()
    # Alone it starts nothing, however often it is seen.
    for k in range(3):
        result = loc.process(hidden, CAMERA, pan, tilt, stamp_s=0.1 * k)
        assert result.fix is None and result.rejections == ('partial_code',)
    # Two clean images locate the robot (the first is confirmed by the second) ...
    assert loc.process(clean, CAMERA, pan, tilt, stamp_s=1.0).fix is None
    assert loc.process(clean, CAMERA, pan, tilt, stamp_s=1.1).fix is not None
    # ... and then the partly hidden card gives fixes where the robot is.
    fix = loc.process(hidden, CAMERA, pan, tilt, stamp_s=1.2).fix
    assert fix is not None and fix.ids.as_tuple() == IDS
    assert np.linalg.norm(fix.T_frame_base.t - BASE.t) < 0.03
    assert loc.rejection_counts()['partial_code'] == 3


def test_the_gate_refuses_a_completed_code_away_from_the_last_fix():
    gates = FixGates(WORLD.building, GateParameters(footprint='off'))
    cov = np.diag([1e-4] * 3 + [1e-4] * 3)
    T = yaw_pose(5.0, 6.3, 0.0, 12.0)
    assert gates.check_partial(T, cov, 'building', 1.0).reason == 'partial_code'
    assert gates.check_continuity(T, cov, 'building', 1.0) is not None    # held, unconfirmed
    assert gates.check_continuity(T, cov, 'building', 1.1) is None
    assert gates.check_partial(yaw_pose(5.01, 6.3, 0.0, 12.0), cov, 'building', 1.2) is None
    far = gates.check_partial(yaw_pose(9.0, 6.3, 0.0, 12.0), cov, 'building', 1.2)
    assert far.reason == 'partial_code' and 'Mahalanobis' in far.message
    assert gates.check_partial(T, cov, 'building', None).reason == 'partial_code'


def test_a_completed_code_is_taken_only_soon_after_the_last_fix():
    # A card missing from the map, partly hidden, can read as a mapped card
    # that hangs metres away. Without odometry the jump test lets the base
    # go max_speed_m_s (1 m/s) times the time since the last fix, so after a
    # few seconds that card would pass as "where the robot can be".
    gates = FixGates(WORLD.building, GateParameters(footprint='off'))
    cov = np.diag([1e-4] * 3 + [1e-4] * 3)
    gates.check_continuity(yaw_pose(5.0, 6.3, 0.0, 12.0), cov, 'building', 1.0)
    assert gates.check_continuity(yaw_pose(5.0, 6.3, 0.0, 12.0), cov, 'building', 1.1) is None
    three_m_away = yaw_pose(8.0, 6.3, 0.0, 12.0)
    late = gates.check_partial(three_m_away, cov, 'building', 5.1)
    assert late is not None and late.reason == 'partial_code' and 'last 1 s' in late.message
    # The jump test alone (a long limit) would have taken it.
    lenient = FixGates(WORLD.building, GateParameters(footprint='off',
                                                      partial_code_max_age_s=60.0))
    lenient.check_continuity(yaw_pose(5.0, 6.3, 0.0, 12.0), cov, 'building', 1.0)
    lenient.check_continuity(yaw_pose(5.0, 6.3, 0.0, 12.0), cov, 'building', 1.1)
    assert lenient.check_partial(three_m_away, cov, 'building', 5.1) is None
    # Soon after, where the robot is: taken.
    assert gates.check_partial(yaw_pose(5.01, 6.3, 0.0, 12.0), cov, 'building', 2.0) is None


def _located(scene, point=7):
    """Return a localizer located by two clean images (stamps 1.0, 1.1) and the hidden image."""
    pan, tilt, clean, T_camera_card = scene
    loc = localizer()
    loc.process(clean, CAMERA, pan, tilt, stamp_s=1.0)
    assert loc.process(clean, CAMERA, pan, tilt, stamp_s=1.1).fix is not None
    return loc, _hide_point(clean, T_camera_card, point)


def test_a_hidden_card_seen_long_after_the_last_fix_gives_no_fix(scene):
    pan, tilt, clean, _ = scene
    loc, hidden = _located(scene)
    result = loc.process(hidden, CAMERA, pan, tilt, stamp_s=3.0)
    assert result.fix is None and result.rejections == ('partial_code',)
    assert 'last 1 s' in result.no_fix_reason
    # Following again: a clean image, then the hidden card within the second.
    assert loc.process(clean, CAMERA, pan, tilt, stamp_s=3.1).fix is not None
    assert loc.process(hidden, CAMERA, pan, tilt, stamp_s=3.2).fix is not None


# Point 7 (a digit of the card's number) hidden: the room's cards 1, 2 and 3
# differ only there, so the slots seen cannot tell them apart.
SIBLINGS = {(4, 12, 1), (4, 12, 2), (4, 12, 3)}


def test_a_hidden_slot_that_several_mapped_codes_fill_gives_them_all(scene):
    pan, tilt, clean, T_camera_card = scene
    hidden = _hide_point(clean, T_camera_card, 7)
    dets = localizer().locator.detector.detect(hidden, CAMERA)
    assert len(dets) == 1 and dets[0].ids is None and dets[0].code is None
    assert {c.ids.as_tuple() for c in dets[0].candidates} == SIBLINGS
    assert all(c.slots_from_map == 1 and c.code is not None for c in dets[0].candidates)
    # Each hypothesis is whole: its dots in its own order, point 1 first.
    for c in dets[0].candidates:
        assert np.allclose(c.points_px, dets[0].candidates[0].points_px, equal_nan=True)
    # Located alone, it has no pose and says why.
    located = localizer().locator.locate(hidden, CAMERA)
    assert located[0].T_camera_pattern is None and '3 known codes fit' in located[0].problem


def test_the_last_fix_chooses_the_one_that_hangs_where_the_robot_is(scene):
    pan, tilt, clean, T_camera_card = scene
    hidden = _hide_point(clean, T_camera_card, 7)
    loc = localizer()
    result = loc.process(hidden, CAMERA, pan, tilt, stamp_s=0.0)
    assert result.fix is None and result.rejections == ('partial_code',)
    assert 'there is none' in result.no_fix_reason
    assert loc.process(clean, CAMERA, pan, tilt, stamp_s=1.0).fix is None
    assert loc.process(clean, CAMERA, pan, tilt, stamp_s=1.1).fix is not None
    for k in range(3):
        fix = loc.process(hidden, CAMERA, pan, tilt, stamp_s=1.2 + 0.1 * k).fix
        assert fix is not None and fix.ids.as_tuple() == IDS
        assert np.linalg.norm(fix.T_frame_base.t - BASE.t) < 0.03
    # The hypotheses tried and left are not counted as fixes refused.
    assert loc.rejection_counts()['partial_code'] == 1


def test_two_that_would_both_put_the_robot_there_give_no_fix(scene):
    pan, tilt, clean, T_camera_card = scene
    hidden = _hide_point(clean, T_camera_card, 7)
    # A map in which card 2 of the room hangs where card 3 does (a map
    # error, or two cards hung one over the other).
    building = WORLD.building
    rooms = dict(building.rooms)
    room = rooms[(4, 12)]
    here = building.card(IDS)
    cards = tuple(dataclasses.replace(c, T_room_card=here.T_room_card,
                                      T_building_card=here.T_building_card)
                  if c.ids.as_tuple() == (4, 12, 2) else c for c in room.cards)
    rooms[(4, 12)] = dataclasses.replace(room, cards=cards)
    twin = BuildingMap(building.frame, rooms, building.floor_names)
    loc = localizer(twin)
    assert loc.process(clean, CAMERA, pan, tilt, stamp_s=1.0).fix is None
    assert loc.process(clean, CAMERA, pan, tilt, stamp_s=1.1).fix is not None
    result = loc.process(hidden, CAMERA, pan, tilt, stamp_s=1.2)
    assert result.fix is None and result.rejections == ('partial_code',)
    assert '2 of the 3 mapped codes' in result.no_fix_reason


def test_the_head_keeps_following_the_card_it_chose(scene):
    pan, tilt, _, T_camera_card = scene
    loc, hidden = _located(scene)
    result = loc.process(hidden, CAMERA, pan, tilt, stamp_s=1.2)
    assert result.fix is not None and result.detections[0].ids is None
    # The target chooser names the card the fix took, where the card is.
    seen, lost = seen_cards(result, CAMERA, WORLD.building)
    assert not lost and seen[0].ids == IDS
    assert np.linalg.norm(np.array(seen[0].centre) - T_camera_card.t) < 0.05


def test_the_one_that_fits_must_pass_the_gates_too(scene):
    pan, tilt, _, _ = scene
    loc, hidden = _located(scene)
    # A gate that refuses the card where it is: the one hypothesis where the
    # robot is may not be taken, and the others are elsewhere.
    loc.gates.parameters = dataclasses.replace(loc.gates.parameters, max_camera_distance_m=1.0)
    result = loc.process(hidden, CAMERA, pan, tilt, stamp_s=1.2)
    assert result.fix is None and result.rejections == ('partial_code',)
    assert '1 of the 3 mapped codes' in result.no_fix_reason


def test_a_hypothesis_tried_is_judged_by_the_gates_but_not_counted():
    gates = FixGates(WORLD.building, GateParameters(footprint='off'))
    cov = np.diag([1e-4] * 6)
    level = yaw_pose(5.0, 6.3, 0.0, 12.0)
    tipped = Pose(rodrigues(np.array([math.radians(30.0), 0.0, 0.0])), level.t)
    assert gates.check(tipped, cov, 'building', counted=False).reason == 'roll_pitch'
    assert gates.counts()['roll_pitch'] == 0
    assert gates.check(tipped, cov, 'building').reason == 'roll_pitch'
    assert gates.counts()['roll_pitch'] == 1
    assert gates.check(level, cov, 'building', counted=False) is None
    assert gates.distance_from_last(level, cov, 'building', 1.0) is None   # no last fix
