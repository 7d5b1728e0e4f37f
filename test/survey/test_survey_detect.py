"""The survey's detection: a pose whose planar flip is unsure is no sighting."""

import dataclasses

from pattern_locator.card.pattern import PatternConfig
from pattern_locator.sim.render import (card_pose_facing, CardPlacement, DotCardTexture,
                                        render_scene, RenderOptions)
from pattern_locator.survey import detect
from pattern_locator.survey.bagio import IMAGE_TYPE, typestore
from pattern_locator.survey.record import _image
from pattern_locator.vision.camera import CameraModel

CFG = PatternConfig()
CAMERA = CameraModel.from_focal(640, 480, 1000.0)


def image_of(distance, tilt_deg, azimuth_deg, offset_px):
    """Return an image of one card."""
    T = card_pose_facing(distance, tilt_deg, azimuth_deg, 0.0, offset_px, CAMERA)
    card = CardPlacement(T, DotCardTexture(CFG, CFG.encode(1, 3, 1)))
    options = RenderOptions(noise_sigma=1.5, defocus_sigma_px=0.5, seed=1)
    return render_scene(CAMERA, [card], options).image


def task(frame, distance, tilt_deg, azimuth_deg, offset_px):
    """Return a survey frame of one card (detect._detect's task), no up known."""
    image = image_of(distance, tilt_deg, azimuth_deg, offset_px)
    ts = typestore()
    return 0, frame, 0, ts.serialize_cdr(_image(ts, 0, image), IMAGE_TYPE), CAMERA, None


def test_a_far_card_nearly_face_on_is_counted_not_sighted():
    detect._init_worker(CFG)
    # 5.7 m away, 5 deg off face on: the other planar pose is likely.
    _, _, _, sightings, problem, _, unsure = detect._detect(task(0, 5.7, 5.0, 90.0, (0, 0)))
    assert problem is None and sightings == [] and unsure == 1
    # 2 m away, 40 deg off: the image rules the other pose out.
    _, _, _, sightings, problem, _, unsure = detect._detect(task(1, 2.0, 40.0, 30.0, (20, 10)))
    assert problem is None and len(sightings) == 1 and unsure == 0


def test_a_pose_in_one_valley_with_its_flip_is_counted_not_sighted():
    # However sure the side (up or height may decide it), a pose whose fit
    # lies in one shallow valley with the other planar pose is no sighting.
    detect._init_worker(CFG)
    located = detect._LOCATOR.locate(image_of(2.0, 40.0, 30.0, (20, 10)), CAMERA)
    assert len(located) == 1 and located[0].T_camera_pattern is not None
    card = located[0]
    sightings, unsure = detect.sightings_of([card], 0, 0, 0)
    assert len(sightings) == 1 and unsure == 0
    valley = dataclasses.replace(card, alternative=card.T_camera_pattern, other_probability=0.0,
                                 flip_barrier=2.0)
    sightings, unsure = detect.sightings_of([valley], 0, 0, 0)
    assert sightings == [] and unsure == 1


def test_the_survey_fits_no_prior_into_its_poses():
    # The survey's graph holds the keyframes upright with its floor factors:
    # its locator lets up choose between the planar solutions only, where
    # the robot's locator fits it into a close call's pose too.
    from pattern_locator.vision.locate import CardLocator
    from pattern_locator.vision.pose_exact import PosePrior
    detect._init_worker(CFG)
    image = image_of(6.0, 6.0, 180.0, (0, 0))      # far, nearly face on: a close call
    located = detect._LOCATOR.locate(image, CAMERA, PosePrior(up_in_camera=[0.0, -1.0, 0.0]))
    robot = CardLocator(CFG).locate(image, CAMERA, PosePrior(up_in_camera=[0.0, -1.0, 0.0]))
    assert len(located) == 1 and len(robot) == 1
    assert located[0].flip_barrier < float('inf')
    assert located[0].prior_information is None and robot[0].prior_information is not None
