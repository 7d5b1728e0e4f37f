"""
The card as printed is the card the detector reads.

The printable module lays out the A3 sheet a user prints: the dots and
marks, and beside them an "UP" arrow, the card's label and a 100 mm scale
bar. Its own raster of that sheet (not the renderer's drawing of a card)
is hung in the scene: the ids must come back, and its mirror image must
give none.
"""

from pattern_locator.card.pattern import Ids, PatternConfig
from pattern_locator.sim.render import (card_pose_facing, CardPlacement, MirroredTexture,
                                        printed_card_texture, render_scene, RenderOptions)
from pattern_locator.vision.camera import CameraModel
from pattern_locator.vision.detector import Detector
import pytest

CFG = PatternConfig()
DETECTOR = Detector(CFG)
VGA = CameraModel.from_focal(640, 480, 1000.0)
HD = CameraModel.from_fov(1280, 720, 70.0, D=[-0.25, 0.07, 0.0, 0.0, 0.0])


def printed_card(ids, mirrored=False):
    """Return the card's square of its printed sheet as a texture (mirrored: as in a mirror)."""
    texture = printed_card_texture(CFG, Ids(*ids))
    return MirroredTexture(texture) if mirrored else texture


@pytest.mark.parametrize('camera, distance, view, azimuth, roll, ids', [
    (VGA, 1.8, 10.0, 30.0, 5.0, (5, 42, 7)),
    (VGA, 3.5, 50.0, 200.0, -15.0, (11, 23, 8)),
    (HD, 2.2, 35.0, 300.0, 10.0, (0, 1, 9)),
    (HD, 3.8, 20.0, 90.0, -5.0, (10, 75, 1)),
], ids=['vga-near', 'vga-steep', 'hd-near', 'hd-far'])
def test_the_printed_sheet_reads_as_its_ids_and_its_mirror_as_none(
        camera, distance, view, azimuth, roll, ids):
    T = card_pose_facing(distance, view, azimuth, roll, (40.0, -30.0), camera)
    for mirrored, expected in ((False, [ids]), (True, [])):
        image = render_scene(camera, [CardPlacement(T, printed_card(ids, mirrored))],
                             RenderOptions(background='clutter', noise_sigma=2.0,
                                           seed=ids[1])).image
        found = [c.ids.as_tuple() for c in DETECTOR.detect(image, camera) if c.ids is not None]
        assert found == expected, 'mirrored' if mirrored else 'printed'
