"""The debug picture draws what was found."""

import math

import numpy as np
from pattern_locator.localization.localizer import RobotLocalizer
from pattern_locator.vision.overlay import draw_overlay
from scene_tools import base_pose, BUILDING, CAMERA, HEAD, PATTERN, view


def test_overlay_marks_the_dots_and_the_location():
    T_room_base = base_pose(4.0, 2.5, 180.0)
    image, _ = view(1, 3, T_room_base, 0.0, math.radians(15.0))
    localizer = RobotLocalizer(PATTERN, BUILDING, HEAD)
    result = localizer.process(image, CAMERA, 0.0, math.radians(15.0))
    assert result.detections and result.fix is not None
    drawn = draw_overlay(image, result.detections, 'floor 1 room 3 card 1')
    assert drawn.shape == image.shape and drawn is not image
    changed = np.any(drawn != image, axis=2)
    # Something is drawn around every dot, and the text at the top.
    for u, v in result.detections[0].points_px:
        window = changed[int(v) - 6:int(v) + 7, int(u) - 6:int(u) + 7]
        assert window.any()
    assert changed[:30].any()
    # The input is left alone.
    assert np.array_equal(image, view(1, 3, T_room_base, 0.0, math.radians(15.0))[0])


def test_overlay_of_a_grey_image_without_cards():
    drawn = draw_overlay(np.full((48, 64), 200, np.uint8), [])
    assert drawn.shape == (48, 64, 3)
