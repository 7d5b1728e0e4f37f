"""The robot's place from one image: detection, map, head kinematics and fusion."""

import math

import numpy as np
from pattern_locator.errors import ConfigError
from pattern_locator.localization.building import building_from_dict
from pattern_locator.localization.localizer import RobotLocalizer
from pattern_locator.vision.geometry import rotation_angle
import pytest
from scene_tools import base_pose, BUILDING, CAMERA, HEAD, PATTERN, view


def localizer(**kwargs):
    return RobotLocalizer(PATTERN, BUILDING, HEAD, **kwargs)


def aim(T_room_base, target):
    """Head angles that centre a room point (kept within the EVI-D31's limits)."""
    target_in_base = T_room_base.inverse().apply(np.asarray(target)[None])[0]
    return HEAD.clamp(*HEAD.aim_angles(target_in_base))


@pytest.mark.parametrize('x, y, yaw, card', [
    (3.0, 2.0, 170.0, 1), (6.0, 1.5, 60.0, 3), (5.0, 3.5, -60.0, 5), (7.5, 2.5, -10.0, 4),
])
def test_base_pose_in_the_room_frame(x, y, yaw, card):
    T_room_base = base_pose(x, y, yaw)
    mapped = BUILDING.card((1, 3, card))
    pan, tilt = aim(T_room_base, mapped.T_room_card.t)
    image, _ = view(1, 3, T_room_base, pan, tilt, seed=card)
    result = localizer().process(image, CAMERA, pan, tilt)
    fix = result.fix
    assert fix is not None, result.problems
    assert fix.frame_id == mapped.room_frame
    assert fix.ids.as_tuple()[:2] == (1, 3)
    distance = np.linalg.norm(mapped.T_room_card.t - T_room_base.t)
    assert np.linalg.norm(fix.T_frame_base.t - T_room_base.t) < 0.01 * distance
    assert math.degrees(rotation_angle(fix.T_frame_base.R, T_room_base.R)) < 1.0
    # The covariance is a proper 6x6 and the error is plausible under it.
    cov = fix.covariance
    assert cov.shape == (6, 6) and np.allclose(cov, cov.T, atol=1e-12)
    assert np.all(np.linalg.eigvalsh(cov) > 0)
    err = fix.T_frame_base.t - T_room_base.t
    assert err @ np.linalg.solve(cov[:3, :3], err) < 30.0
    # Centred card: the head hardly needs to move.
    assert abs(fix.target_pan) < math.radians(3) and abs(fix.target_tilt) < math.radians(3)


def test_the_papers_estimator_gives_a_fix_with_a_covariance():
    # The paper's estimator has no covariance of its own: the first-order one
    # at its pose lets the node publish it like the exact one.
    T_room_base = base_pose(6.0, 1.5, 60.0)
    pan, tilt = aim(T_room_base, BUILDING.card((1, 3, 3)).T_room_card.t)
    image, _ = view(1, 3, T_room_base, pan, tilt, seed=3)
    paper = localizer(estimator='paper').process(image, CAMERA, pan, tilt).fix
    assert paper is not None
    assert np.linalg.norm(paper.T_frame_base.t - T_room_base.t) < 0.05
    cov = paper.covariance
    assert cov.shape == (6, 6) and np.all(np.linalg.eigvalsh(cov) > 0)
    err = paper.T_frame_base.t - T_room_base.t
    assert err @ np.linalg.solve(cov[:3, :3], err) < 30.0


def test_building_frame_output():
    T_room_base = base_pose(4.0, 2.5, 180.0)
    pan, tilt = aim(T_room_base, BUILDING.card((1, 3, 1)).T_room_card.t)
    image, _ = view(1, 3, T_room_base, pan, tilt)
    fix = localizer(output_frame='building').process(image, CAMERA, pan, tilt).fix
    room = BUILDING.room(1, 3)
    truth = room.T_building_room @ T_room_base
    assert fix.frame_id == BUILDING.frame
    assert np.linalg.norm(fix.T_frame_base.t - truth.t) < 0.03


def test_several_cards_biggest_or_fused():
    # Facing the north wall from 4 m: its two cards, 2 m either side, are in view.
    T_room_base = base_pose(5.0, 1.0, 90.0)
    pan, tilt = 0.0, math.radians(15.0)
    image, _ = view(1, 3, T_room_base, pan, tilt, camera=CAMERA)
    biggest = localizer().process(image, CAMERA, pan, tilt)
    fused = localizer(fusion='fused').process(image, CAMERA, pan, tilt)
    assert biggest.fix is not None and fused.fix is not None
    assert biggest.cards_seen >= 1
    for fix in (biggest.fix, fused.fix):
        assert np.linalg.norm(fix.T_frame_base.t - T_room_base.t) < 0.1
    assert biggest.cards_seen == 2 and fused.fix.cards_used == 2
    assert biggest.fix.cards_used == 1
    # Fusing can only shrink the uncertainty.
    assert np.trace(fused.fix.covariance[:3, :3]) < np.trace(biggest.fix.covariance[:3, :3])


def test_card_missing_from_the_map_gives_no_pose():
    # A map holding only another room: the card is read but not located.
    data = {'floors': [{'floor': 0, 'rooms': [{'room': 1, 'pose': {
        'position': [0, 0, 0], 'rpy_deg': [0, 0, 0]}, 'cards': [{'pattern': 1, 'pose': {
            'position': [0, 2.5, 2.15], 'facing_deg': 0}}]}]}]}
    other = building_from_dict(data, PATTERN, 'test map')
    T_room_base = base_pose(4.0, 2.5, 180.0)
    pan, tilt = aim(T_room_base, BUILDING.card((1, 3, 1)).T_room_card.t)
    image, _ = view(1, 3, T_room_base, pan, tilt)
    result = RobotLocalizer(PATTERN, other, HEAD).process(image, CAMERA, pan, tilt)
    assert result.fix is None
    assert result.cards_seen == 1 and result.target is not None
    assert any('not in the building map' in p for p in result.problems)


def test_grey_image_gives_geometry_but_no_pose():
    T_room_base = base_pose(4.0, 2.5, 180.0)
    pan, tilt = aim(T_room_base, BUILDING.card((1, 3, 1)).T_room_card.t)
    image, _ = view(1, 3, T_room_base, pan, tilt)
    result = localizer().process(image.min(axis=2), CAMERA, pan, tilt)
    assert result.fix is None and result.target is not None
    assert any('no code' in p for p in result.problems)


def test_bad_settings_are_config_errors():
    with pytest.raises(ConfigError, match='output frame'):
        localizer(output_frame='world')
    with pytest.raises(ConfigError, match='fusion'):
        localizer(fusion='average')
