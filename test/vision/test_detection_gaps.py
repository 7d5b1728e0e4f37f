"""
Issue 9's detection gaps (far cards, occlusion): each class of miss found on the stress frames.

Every frame here is one the stress benchmark (``bench --stress``, its
``far`` and ``occlusion`` conditions) missed, rendered again from its
parameters; each test checks the card is now read right, and that its
mirror image still gives no id. Nothing is timed.
"""

import math

import numpy as np
from pattern_locator.card.pattern import Code, PatternConfig
from pattern_locator.sim.render import (card_pose_facing, CardPlacement, DotCardTexture,
                                        MirroredTexture, Occluder, render_scene, RenderOptions)
from pattern_locator.vision import cards as card_stage
from pattern_locator.vision.camera import CameraModel
from pattern_locator.vision.detector import Detector
from pattern_locator.vision.dots import segment

CFG = PatternConfig()
DETECTOR = Detector(CFG)
# The stress benchmark's two cameras.
VGA = CameraModel.from_focal(640, 480, 1000.0)
HD = CameraModel.from_fov(1280, 720, 70.0, D=[-0.25, 0.07, 0.0005, -0.0003, 0.0])


def render(camera, distance, tilt, azimuth, roll, offset, ids, occluders=(), mirrored=False,
           **options):
    """Render one stress frame; returns the image and the truth of its dots."""
    T = card_pose_facing(distance, tilt, azimuth, roll_deg=roll, offset_px=offset,
                         camera=camera)
    code = CFG.encode(*ids)
    face = DotCardTexture(CFG, code)
    if mirrored:
        face = MirroredTexture(face, 1.0)
    objects = tuple(Occluder(0, np.array(polygon), colour) for polygon, colour in occluders)
    result = render_scene(camera, [CardPlacement(T, face, code, CFG)],
                          RenderOptions(supersample=2, occluders=objects, **options))
    return result.image, result.truth[0].dot_pixels


def segmented(frame):
    """Render a frame and segment it: the image, its DotImage and the card's centre blob."""
    image, dots = render(**frame)
    dot_image = segment(image, DETECTOR.params)
    blobs = dot_image.blobs
    centre = int(np.argmin(np.hypot(blobs.u - dots[0, 0], blobs.v - dots[0, 1])))
    assert math.hypot(blobs.u[centre] - dots[0, 0], blobs.v[centre] - dots[0, 1]) < 2.0
    return image, dot_image, centre


def ids_found(image, camera):
    return [c.ids.as_tuple() for c in DETECTOR.detect(image, camera) if c.ids is not None]


# Occlusion: a dark object whose edge passes a pixel or two from the place a
# mirror would put a handedness mark. Its darkness there made the place look
# marked, so the card was 'unsure' (no id) though its own marks showed.
OBJECT_BESIDE_MIRROR_PLACE = {
    'camera': VGA, 'distance': 3.8747, 'tilt': 53.3198, 'azimuth': 54.879, 'roll': -17.717,
    'offset': (138.953, -72.942), 'ids': (6, 60, 5), 'gain': 0.6458,
    'colour_cast': (0.9682, 0.9511, 1.008), 'gradient': 0.0109, 'gradient_angle_deg': 79.6855,
    'defocus_sigma_px': 0.9208, 'noise_sigma': 1.7329, 'shot_noise': 0.0043,
    'crosstalk': 0.1989, 'seed': 251191188,
    'occluders': [([[-0.31472, -0.0215], [0.24191, 0.20246], [0.12993, 0.48078],
                    [-0.4267, 0.25682]], (0.35, 0.3, 0.28))]}


def test_object_beside_a_mirror_place_does_not_hide_the_cards_own_marks():
    frame = OBJECT_BESIDE_MIRROR_PLACE
    image, _ = render(**frame)
    assert ids_found(image, VGA) == [frame['ids']]
    mirror, _ = render(**frame, mirrored=True)
    assert ids_found(mirror, VGA) == []


# Far: a card at 7.6 m in a cluttered room. Its centre is a small blob
# whose ring dots decimation lost; the local noise, measured where it is
# lowest within 40 px, is the card's own dots' edges and the clutter's, so
# the centre (half as dark as the white) was not 'clearly ink' by 9 noise
# sigmas and never became a far candidate.
FAR_BUSY = {
    'camera': HD, 'distance': 7.6219, 'tilt': 14.0251, 'azimuth': 165.351, 'roll': 19.113,
    'offset': (307.2, 2.811), 'ids': (8, 27, 7), 'gain': 0.9906,
    'colour_cast': (1.0216, 0.9913, 1.0113), 'gradient': 0.1095,
    'gradient_angle_deg': 126.1891, 'defocus_sigma_px': 0.8969, 'noise_sigma': 1.6644,
    'shot_noise': 0.0032, 'crosstalk': 0.2181, 'background': 'clutter', 'seed': 941185183}


def test_far_centre_darker_than_its_noisy_surroundings_say_is_a_candidate():
    frame = FAR_BUSY
    image, dot_image, centre = segmented(frame)
    blobs = dot_image.blobs
    # The class: by the local noise alone, the centre is not sure ink.
    u, v = blobs.u[[centre]], blobs.v[[centre]]
    white, noise = dot_image.white_at(u, v), dot_image.noise_at(u, v)
    dark = dot_image.peak_darkness(u, v, white)
    assert dark[0] * white[0] < card_stage._FAR_MIN_CONTRAST * noise[0]
    assert dark[0] >= card_stage._FAR_INK_DARKNESS
    assert ids_found(image, HD) == [frame['ids']]


# Far: a card at 7.8 m, 50 degrees. Its point 1 is 18 % darker than the
# paper, its marks (smaller than the dots) 10-12 %: below the dots' fixed
# bar (12 %), so no mark was seen and the card was 'unsure'.
FAR_PALE_MARKS = {
    'camera': HD, 'distance': 7.7809, 'tilt': 49.9483, 'azimuth': 183.08, 'roll': 27.805,
    'offset': (-248.712, 44.787), 'ids': (3, 77, 2), 'gain': 0.9567,
    'colour_cast': (1.0246, 1.0243, 0.9689), 'gradient': 0.1961,
    'gradient_angle_deg': 103.2181, 'defocus_sigma_px': 0.6853, 'noise_sigma': 1.5141,
    'shot_noise': 0.0029, 'crosstalk': 0.0884, 'background': 'clutter', 'seed': 18040542}


def test_far_cards_pale_marks_are_measured_against_point_1():
    frame = FAR_PALE_MARKS
    image, _ = render(**frame)
    assert ids_found(image, HD) == [frame['ids']]
    mirror, _ = render(**frame, mirrored=True)
    assert ids_found(mirror, HD) == []


# Far, JPEG: cards at 5.8 and 7.2 m in JPEG frames (quality 81, 82). JPEG
# keeps the colour at half the resolution (4:2:0) and quantises it, which
# greys the 3-pixel dots' colours as a sensor's overlapping filters do, but
# more than the colour response's fit allowed (crosstalk to 0.45, in steps
# of 0.075): no ink fitted, or the rings disagreed.
FAR_JPEG = [{
    'camera': VGA, 'distance': 5.8469, 'tilt': 31.7959, 'azimuth': 173.145, 'roll': -28.94,
    'offset': (30.633, 119.826), 'ids': (4, 70, 2), 'gain': 0.9427,
    'colour_cast': (0.982, 1.0328, 1.03), 'gradient': 0.2238, 'gradient_angle_deg': 303.5453,
    'defocus_sigma_px': 0.8651, 'noise_sigma': 1.6555, 'shot_noise': 0.0048,
    'jpeg_quality': 81, 'crosstalk': 0.2984, 'background': 'clutter', 'seed': 434909156}, {
    'camera': VGA, 'distance': 7.2298, 'tilt': 48.6076, 'azimuth': 90.298, 'roll': 7.348,
    'offset': (-149.211, 83.909), 'ids': (1, 57, 7), 'gain': 0.9089,
    'colour_cast': (0.9604, 1.0153, 0.9717), 'gradient': 0.0157, 'gradient_angle_deg': 287.4729,
    'defocus_sigma_px': 0.8066, 'noise_sigma': 2.4625, 'shot_noise': 0.003, 'jpeg_quality': 82,
    'crosstalk': 0.2284, 'background': 'clutter', 'seed': 486858148}]


def test_far_card_in_a_jpeg_frame_is_read_with_greyer_colours():
    for frame in FAR_JPEG:
        image, _ = render(**frame)
        assert ids_found(image, VGA) == [frame['ids']]
    mirror, _ = render(**FAR_JPEG[0], mirrored=True)
    assert ids_found(mirror, VGA) == []


# Occlusion: a black object over a corner of the card, covering most of an
# inner ring dot. Even under the object, that dot was read for its colour:
# black, a second point 1 (or, with point 1's own dots hidden, a wrong
# one). Its colour is the object's, as seen where paper should be round it.
BLACK_CORNER = {
    'camera': HD, 'distance': 3.6741, 'tilt': 32.1841, 'azimuth': 279.044, 'roll': -24.854,
    'offset': (194.659, 202.63), 'ids': (7, 6, 4), 'gain': 1.0116,
    'colour_cast': (1.0154, 1.026, 0.9623), 'gradient': 0.1899, 'gradient_angle_deg': 80.1185,
    'defocus_sigma_px': 0.8892, 'noise_sigma': 2.6698, 'shot_noise': 0.0008,
    'crosstalk': 0.0052, 'background': 'clutter', 'seed': 845405580,
    'occluders': [([[0.15, 0.15], [-0.05426, 0.15], [0.15, -0.05426]], (0.05, 0.05, 0.06))]}


def test_dot_under_a_black_object_is_not_read_as_black():
    frame = BLACK_CORNER
    image, _ = render(**frame)
    code = CFG.encode(*frame['ids'])
    # Points 1 and 2 are hidden: a map completes them; its other card
    # differs in a slot that shows (point 6).
    near = Code(code.centre, code.ring[:5] + ('G' if code.ring[5] != 'G' else 'B') + code.ring[6:])
    detector = Detector(CFG, known_codes=[code, CFG.encode(0, 1, 1), near])
    found = [c.ids.as_tuple() for c in detector.detect(image, HD) if c.ids is not None]
    assert found == [frame['ids']]


# Far and steep: a card at 6.6 m seen 54 degrees off its axis. Decimated, its
# ring dots are too pale to be blobs, so only the far candidates' faint spots
# can make its centre a candidate; of its two rings those spots showed dots
# in four of the eight directions round the centre (the others merged or too
# pale at the faint threshold), and five were asked for.
FAR_STEEP = {
    'camera': HD, 'distance': 6.5947, 'tilt': 54.0306, 'azimuth': 323.045, 'roll': -28.994,
    'offset': (-333.42, -247.28), 'ids': (11, 17, 6), 'gain': 0.7913,
    'colour_cast': (0.9951, 0.9953, 1.0451), 'gradient': 0.1901,
    'gradient_angle_deg': 57.9215, 'defocus_sigma_px': 0.8467, 'noise_sigma': 2.1981,
    'shot_noise': 0.0099, 'crosstalk': 0.0859, 'background': 'clutter', 'seed': 556351291}


def test_far_steep_cards_faint_ring_in_four_directions_is_a_candidate():
    frame = FAR_STEEP
    image, dot_image, centre = segmented(frame)
    blobs = dot_image.blobs
    # The class: no ranked candidate there; found through the faint ring only.
    ranked = card_stage.rank_candidates(blobs, CFG, DETECTOR.params,
                                        dot_image.noise_at(blobs.u, blobs.v))
    assert centre not in ranked
    far = card_stage.far_candidates(dot_image, CFG, ranked, np.zeros(len(blobs), dtype=bool))
    assert centre in far
    assert ids_found(image, HD) == [frame['ids']]
    mirror, _ = render(**frame, mirrored=True)
    assert ids_found(mirror, HD) == []
