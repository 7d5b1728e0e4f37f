"""The robot's place from one image: detection, map, head kinematics and fusion."""

import dataclasses
import math

import cv2
import numpy as np
from pattern_locator.errors import ConfigError
from pattern_locator.localization.building import building_from_dict
from pattern_locator.localization.gates import GateParameters, REASONS
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


# Gates, end to end ------------------------------------------------------------------

def test_a_frame_rotated_180_degrees_gives_no_pose():
    # Seen: a frame rotated 180 deg published a base 1.8 m above the floor,
    # rolled -160 deg. It decodes and gives a pose; the roll gate refuses it.
    T_room_base = base_pose(4.0, 1.2, 160.0)
    pan, tilt = aim(T_room_base, BUILDING.card((0, 1, 1)).T_room_card.t)
    image, _ = view(0, 1, T_room_base, pan, tilt)
    loc = localizer()
    result = loc.process(cv2.rotate(image, cv2.ROTATE_180), CAMERA, pan, tilt)
    assert result.fix is None and result.cards_seen == 1
    assert result.rejections == ('roll_pitch',)
    assert 'base rolled' in result.no_fix_reason
    assert loc.rejection_counts()['roll_pitch'] == 1
    # Without the gates it would have been a pose well off the floor.
    ungated = localizer(gates=GateParameters(max_roll_deg=180.0, max_pitch_deg=90.0,
                                             max_base_height_m=5.0, footprint='off'))
    fix = ungated.process(cv2.rotate(image, cv2.ROTATE_180), CAMERA, pan, tilt).fix
    assert fix is not None and fix.T_frame_base.t[2] > 1.0


def test_a_mirrored_card_is_never_located():
    # Card 1 of floor 0 room 1 reads K-KRRRRRRR: the same code mirrored, as a
    # card printed without a handedness mark. Its mirror image (a reflection,
    # a flipped frame) puts the camera mirrored about the card's normal:
    # 2.6 m from the truth here, plausible on its own. Continuity refuses it.
    unmarked = dataclasses.replace(PATTERN, handedness_mark=None)
    T_room_base = base_pose(4.0, 1.2, 160.0)
    pan, tilt = aim(T_room_base, BUILDING.card((0, 1, 1)).T_room_card.t)
    image, _ = view(0, 1, T_room_base, pan, tilt, pattern=unmarked)
    mirrored = np.ascontiguousarray(cv2.flip(image, 1))

    def localizer(**kwargs):
        return RobotLocalizer(unmarked, BUILDING, HEAD, **kwargs)

    def run(loc, frames):
        out = []
        for k, frame in enumerate(frames):
            out.append(loc.process(frame, CAMERA, pan, tilt, stamp_s=10.0 + 0.1 * k))
        return out

    # The robot located, then a mirrored frame: held back as a jump; the
    # next true frame is continuous with the last fix and returned.
    loc = localizer()
    results = run(loc, [image, image, mirrored, image])
    assert [r.fix is None for r in results] == [True, False, True, False]
    assert results[0].rejections == ('unconfirmed_first',)
    assert results[2].rejections == ('jump',) and results[2].cards_seen == 1
    assert 'held back' in results[2].no_fix_reason
    for r in (results[1], results[3]):
        assert np.linalg.norm(r.fix.T_frame_base.t - T_room_base.t) < 0.05
    # A mirrored frame first: held; the true frames after it do not confirm
    # it, so the mirrored pose is never returned.
    loc = localizer()
    results = run(loc, [mirrored, image, image])
    assert [r.fix is None for r in results] == [True, True, False]
    assert np.linalg.norm(results[2].fix.T_frame_base.t - T_room_base.t) < 0.05
    counts = loc.rejection_counts()
    assert set(counts) == set(REASONS) and counts['unconfirmed_first'] == 2


def test_a_mirrored_marked_card_gives_no_id_at_all():
    # The shipped cards carry handedness marks: the detector itself refuses
    # the mirror image, so the gates never see it.
    T_room_base = base_pose(4.0, 1.2, 160.0)
    pan, tilt = aim(T_room_base, BUILDING.card((0, 1, 1)).T_room_card.t)
    image, _ = view(0, 1, T_room_base, pan, tilt)
    mirrored = np.ascontiguousarray(cv2.flip(image, 1))
    loc = localizer()
    assert loc.process(image, CAMERA, pan, tilt).cards_seen == 1
    result = loc.process(mirrored, CAMERA, pan, tilt)
    assert result.fix is None and result.cards_seen == 0 and result.rejections == ()


def test_without_a_stamp_every_plausible_fix_is_returned():
    # The locator node before it passes stamps: the static gates only.
    T_room_base = base_pose(4.0, 1.2, 160.0)
    pan, tilt = aim(T_room_base, BUILDING.card((0, 1, 1)).T_room_card.t)
    image, _ = view(0, 1, T_room_base, pan, tilt)
    loc = localizer()
    first = loc.process(image, CAMERA, pan, tilt)
    assert first.fix is not None and first.rejections == () and first.no_fix_reason == ''
    assert loc.last_fix_stamp is None
    assert sum(loc.rejection_counts().values()) == 0
