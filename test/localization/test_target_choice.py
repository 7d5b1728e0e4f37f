"""
The locator's target on the simulated floor: the gaze planner's card, seen or predicted.

The cards "seen" are what the floor's walls leave in sight of the camera
(``FloorScene.views``: every dot in the image and not hidden), with their
true centres: the chooser's logic is judged against the world it never
sees (it has only the map).
"""

import math

import numpy as np
from pattern_locator.errors import ConfigError
from pattern_locator.localization.gaze import GazeParameters
from pattern_locator.localization.odom import BaseTwist
from pattern_locator.localization.target_choice import (SeenCard, TargetChooser,
                                                        TargetParameters)
from pattern_locator.sim.drive import yaw_pose
from pattern_locator.sim.floor_file import load_floor_world
from pattern_locator.sim.floor_scene import FloorScene
from pattern_locator.vision.camera import CameraModel
import pytest

WORLD = load_floor_world()
BUILDING = WORLD.building
SCENE = FloorScene(WORLD)
HEAD = SCENE.head
CAMERA = CameraModel.from_fov(640, 480, 48.0)       # the EVI-D31 at its widest
WEST = BaseTwist((0.3, 0.0, 0.0), (0.0, 0.0, 0.0))   # driving forward at 0.3 m/s


def pose(x, y, heading_deg):
    return yaw_pose(x, y, math.radians(heading_deg), WORLD.z)


def aimed_at(T_building_base, ids):
    """Return the head angles that put the card's centre on the optical axis."""
    centre = BUILDING.card(ids).T_building_card.t
    return HEAD.aim_angles(T_building_base.inverse().apply(centre[None])[0])


def centre_in_camera(T_building_base, pan, tilt, ids):
    T_camera = SCENE.true_camera_pose(T_building_base, pan, tilt)
    return T_camera.inverse().apply(BUILDING.card(ids).T_building_card.t[None])[0]


def seen_from(T_building_base, pan, tilt):
    """Return the cards the walls leave whole in the image, biggest (nearest) first."""
    T_camera = SCENE.true_camera_pose(T_building_base, pan, tilt)
    views = sorted((v for v in SCENE.views(T_camera, CAMERA) if v.complete),
                   key=lambda v: v.distance_m)
    return [SeenCard(v.ids.as_tuple(),
                     tuple(centre_in_camera(T_building_base, pan, tilt, v.ids.as_tuple())))
            for v in views]


def test_without_a_pose_the_target_is_the_biggest_card_seen():
    chooser = TargetChooser(BUILDING, HEAD)
    T = pose(9.0, 10.0, 180.0)
    pan, tilt = aimed_at(T, (4, 3, 3))
    seen = seen_from(T, pan, tilt)
    assert seen and seen[0].ids == (4, 3, 3)
    choice = chooser.choose(0.0, seen, None, pan, tilt)
    assert (choice.ids, choice.source, choice.reason) == ((4, 3, 3), 'seen', 'no pose')
    assert choice.point == seen[0].centre
    # A card the map does not know is still a target without a pose (as before the planner).
    unknown = [SeenCard(None, (0.1, 0.0, 3.0))]
    assert chooser.choose(0.1, unknown, None, pan, tilt).point == (0.1, 0.0, 3.0)
    empty = chooser.choose(0.2, [], None, pan, tilt)
    assert (empty.point, empty.source) == (None, 'none')


def test_handover_to_the_next_card_before_the_current_one_leaves_the_view():
    # Driving west across room 3 at y = 10 m, the head on the north wall's card
    # (4, 3, 3): it comes too close for the head's tilt. The target must switch
    # to another card while (4, 3, 3) is still whole in the image.
    chooser = TargetChooser(BUILDING, HEAD)
    current = (4, 3, 3)
    handed = None
    for k, x in enumerate(np.arange(9.0, 5.0, -0.05)):
        T = pose(float(x), 10.0, 180.0)
        pan, tilt = aimed_at(T, current)
        seen = seen_from(T, pan, tilt)
        choice = chooser.choose(0.2 * k, seen, T, pan, tilt, WEST, camera=CAMERA)
        if choice.ids != current:
            handed = (T, pan, tilt, seen, choice)
            break
        # The first time too: the card seen is taken as the current one.
        assert (choice.source, choice.reason) == ('seen', 'keep')
        assert choice.point == next(s.centre for s in seen if s.ids == current)
    assert handed is not None, 'no handover across the room'
    T, pan, tilt, seen, choice = handed
    assert choice.reason == 'handover' and choice.visible_ahead
    # Before the current card leaves the view: it is still whole in this image.
    assert current in [s.ids for s in seen]
    # The next card is not in the image: its centre is predicted from the pose,
    # the map and the head's angles (exact here, as the pose is).
    assert choice.ids not in [s.ids for s in seen]
    assert choice.source == 'predicted'
    assert np.allclose(choice.point, centre_in_camera(T, pan, tilt, choice.ids), atol=1e-9)
    # The driver's turn towards it (pan = -atan2(x, z), its bearing in the tilted
    # camera: within a few degrees of the joints' turn at 85 deg off the axis, and
    # closed by the next images) brings it whole into sight.
    aim_pan, aim_tilt = aimed_at(T, choice.ids)
    driver_pan = -math.atan2(choice.point[0], choice.point[2])
    assert driver_pan == pytest.approx(aim_pan - pan, abs=0.1)
    assert choice.ids in [s.ids for s in seen_from(T, aim_pan, aim_tilt)]
    # The next image, the head still turning: the new card is kept, predicted.
    again = chooser.choose(100.0, seen, T, pan, tilt, WEST, camera=CAMERA)
    assert (again.ids, again.source, again.reason) == (choice.ids, 'predicted', 'keep')
    # Once the head is on it, the target is the card as seen.
    seen_now = seen_from(T, aim_pan, aim_tilt)
    done = chooser.choose(100.2, seen_now, T, aim_pan, aim_tilt, WEST, camera=CAMERA)
    assert (done.ids, done.source) == (choice.ids, 'seen')
    assert done.point == next(s.centre for s in seen_now if s.ids == choice.ids)


def test_no_target_when_no_card_is_predicted_visible():
    # In room 6, facing its door in the east wall (test_gaze: no card the head
    # can reach is predicted visible).
    chooser = TargetChooser(BUILDING, HEAD)
    T = pose(22.3, 15.2, 0.0)
    choice = chooser.choose(0.0, [], T, 0.0, 0.0, None, camera=CAMERA)
    assert (choice.point, choice.ids, choice.source, choice.reason) == (
        None, None, 'none', 'none predicted')
    # A card seen all the same (the planner is conservative) stays the target.
    seen = [SeenCard((4, 9, 1), (0.2, -0.3, 9.0))]
    choice = chooser.choose(0.2, seen, T, 0.0, 0.0, WEST, camera=CAMERA)
    assert (choice.ids, choice.source, choice.reason) == ((4, 9, 1), 'seen', 'unpredicted')


def test_driving_to_a_door_the_target_is_the_card_beyond_it_never_counted_missing():
    # In room 6, driving out through its east door: nothing in sight now, a
    # corridor card will be. The head is sent to it (predicted), and images
    # that cannot show it yet (the wall) never leave it out as missing.
    chooser = TargetChooser(BUILDING, HEAD, parameters=TargetParameters(missing_frames=2))
    T = pose(22.3, 15.2, 0.0)
    for k in range(5):
        choice = chooser.choose(0.1 * k, [], T, 0.0, 0.0, WEST, camera=CAMERA)
        assert (choice.source, choice.reason) == ('predicted', 'ahead'), k
        assert choice.ids[:2] != (4, 6)
        pan, tilt = HEAD.aim_angles(T.inverse().apply(
            BUILDING.card(choice.ids).T_building_card.t[None])[0])
        assert -math.atan2(choice.point[0], choice.point[2]) == pytest.approx(pan, abs=0.05)
    assert chooser.excluded == ()


def test_a_predicted_card_missing_from_the_images_is_left_out_for_a_while():
    # Something the map does not know hides the planner's card: after a few
    # images that should have shown it, another card (or none) is chosen.
    chooser = TargetChooser(BUILDING, HEAD, parameters=TargetParameters(missing_frames=3,
                                                                        exclude_s=2.0))
    T = pose(9.0, 10.0, 180.0)
    first = chooser.choose(0.0, [], T, 0.0, 0.0)     # no camera: no image to miss it in
    assert first.source == 'predicted'
    hidden = first.ids
    pan, tilt = aimed_at(T, hidden)
    stamps = [0.2, 0.4, 0.6]
    for stamp in stamps:          # the head on it, the card not detected
        choice = chooser.choose(stamp, [], T, pan, tilt, camera=CAMERA)
        assert choice.ids == hidden
    assert chooser.excluded == (hidden,)
    other = chooser.choose(0.8, [], T, pan, tilt, camera=CAMERA)
    assert other.ids != hidden
    # Back in the choice once the time is up (and at once when seen).
    later = chooser.choose(2.7, [], T, pan, tilt, camera=CAMERA)
    assert chooser.excluded == ()
    assert later.ids is not None
    # Images whose camera looks elsewhere do not count as misses.
    chooser.reset()
    for stamp in (0.0, 0.2, 0.4, 0.6, 0.8):
        chooser.choose(stamp, [], T, math.radians(90.0), 0.0, camera=CAMERA)
    assert chooser.excluded == ()


def test_the_clock_going_back_starts_afresh_and_parameters_are_checked():
    chooser = TargetChooser(BUILDING, HEAD, GazeParameters(lookahead_s=0.0))
    T = pose(9.0, 10.0, 180.0)
    pan, tilt = aimed_at(T, (4, 3, 3))
    chooser.choose(50.0, seen_from(T, pan, tilt), T, pan, tilt)
    assert chooser.current == (4, 3, 3)
    chooser.choose(10.0, [], None, pan, tilt)          # a replay from the start
    assert chooser.current is None
    for bad in ({'missing_frames': 0}, {'exclude_s': -1.0}, {'edge_margin': 0.5},
                {'missing_frames': True}):
        with pytest.raises(ConfigError):
            TargetParameters(**bad)
