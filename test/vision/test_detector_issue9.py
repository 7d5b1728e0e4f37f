"""
Issue 9, one regression test per class of finding, on rendered images.

The detector met real buildings at their edges: colour casts that turned a
green centre black, colour channels shifted by a cheap lens or composite
video, mirror images read as another card, fine textures and dark noisy
frames that made thousands of blobs (seconds and gigabytes a frame), dim
light, motion blur, occlusion, interlaced frames of a panning camera and
far cards. Each test renders its class of image and checks the behaviour
that must hold: the right id or none, never a wrong one; bounded work.
Nothing here is timed (the benchmark does that): work is bounded by counts
and by the memory numpy allocates.
"""

import math
import tracemalloc

import cv2
import numpy as np
from pattern_locator.card.pattern import Code, PatternConfig
from pattern_locator.sim.render import (card_pose_facing, CardPlacement, DotCardTexture,
                                        MirroredTexture, Occluder, render_scene, RenderOptions)
from pattern_locator.vision import cards as card_stage
from pattern_locator.vision.camera import CameraModel
from pattern_locator.vision.detector import Detector, DetectorParams
from pattern_locator.vision.dots import segment
import pytest

CFG = PatternConfig()                       # the shipped card: handedness marks printed
PAPER_CFG = PatternConfig(handedness_mark=None)     # the paper's cards: no marks
DETECTOR = Detector(CFG)
VGA = CameraModel.from_focal(640, 480, 1000.0)
HD = CameraModel.from_fov(1280, 720, 70.0, D=[-0.25, 0.07, 0.0, 0.0, 0.0])


def render(cards, camera=VGA, config=CFG, **options):
    """Render ``[(pose, code or texture), ...]``; options go to RenderOptions."""
    placements = [CardPlacement(pose, DotCardTexture(config, what) if isinstance(what, Code)
                                else what) for pose, what in cards]
    return render_scene(camera, placements, RenderOptions(**options)).image


def ids_found(image, camera=VGA, detector=DETECTOR):
    return [c.ids.as_tuple() for c in detector.detect(image, camera) if c.ids is not None]


def green_centre_without_green_ring(config=CFG):
    """Ids whose code has a green centre and no green dot on the ring."""
    for ids, code in config.all_codes():
        if code.centre == 'G' and 'G' not in code.ring and ids.room > 40:
            return ids.as_tuple(), code


# Wrong ids ------------------------------------------------------------------------------

# Lights that are weak in green (magenta, sodium, warm LED, a red wall), as
# R, G, B gains; with a sensor whose colour filters overlap, which greys
# colours (a printed green comes closest to black).
WEAK_GREEN_LIGHTS = [(1.30, 1.04, 1.22), (1.3, 0.7, 1.3), (1.4, 0.9, 0.7), (1.4, 0.8, 0.8)]


@pytest.mark.parametrize('cast', WEAK_GREEN_LIGHTS)
def test_green_centre_under_weak_green_light_is_never_read_black(cast):
    ids, code = green_centre_without_green_ring()
    black = Code('K', code.ring)
    seen = 0
    for k, (distance, tilt, gain) in enumerate([(1.6, 20.0, 0.5), (2.5, 45.0, 1.0),
                                                (3.5, 30.0, 1.3)]):
        T = card_pose_facing(distance, tilt, 60.0 * k, 10.0, (30.0, -20.0), VGA)
        image = render([(T, code)], gain=gain, colour_cast=cast, crosstalk=0.3,
                       noise_sigma=2.0, defocus_sigma_px=0.7, seed=k)
        found = DETECTOR.detect(image, VGA)
        assert all(c.code != black for c in found), (cast, distance)
        assert all(c.ids.as_tuple() == ids for c in found), (cast, distance)
        seen += len(found)
    assert seen >= 2                  # read right, not just refused


# A printer whose inks come out far too dark (sRGB): its green is nearer
# black than the configured green is.
DARK_INKS = PatternConfig(colours_rgb=(('K', (0, 0, 0)), ('R', (150, 10, 20)),
                                       ('G', (10, 100, 40)), ('B', (10, 30, 130))))


@pytest.mark.parametrize('cast', [(1.0, 1.0, 1.0), (1.3, 0.7, 1.3), (1.2, 1.0, 0.75),
                                  (0.75, 1.2, 1.2), (0.8, 1.4, 0.8)])
def test_green_centre_printed_too_dark_is_never_read_black(cast):
    # Neutral, magenta, tungsten, cyan and green light; the detector knows
    # the configured inks only. Not the black of point 1: no id, not another
    # floor.
    ids, code = green_centre_without_green_ring()
    for k, (distance, tilt) in enumerate([(1.5, 20.0), (2.9, 40.0), (3.6, 30.0)]):
        T = card_pose_facing(distance, tilt, 60.0 * k, 10.0, (30.0, -20.0), VGA)
        image = render([(T, DotCardTexture(DARK_INKS, code))], colour_cast=cast, crosstalk=0.2,
                       noise_sigma=1.5, defocus_sigma_px=0.6, seed=k)
        assert all(c.ids is None or c.ids.as_tuple() == ids
                   for c in DETECTOR.detect(image, VGA)), (cast, distance)


def test_green_centre_printed_too_dark_in_dim_green_light_is_never_read_black():
    # A stress frame (light green, seed 60) that read floor 2 for floor 8:
    # there the white fitted to such inks brings the centre near black.
    ids = (8, 7, 9)
    T = card_pose_facing(2.596, 13.914, 19.312, -22.933, (-212.262, -17.643), VGA)
    image = render([(T, DotCardTexture(DARK_INKS, CFG.encode(*ids)))], supersample=2,
                   gain=0.638, colour_cast=(0.776, 1.363, 0.806), gradient=0.11,
                   gradient_angle_deg=65.85, defocus_sigma_px=0.672, noise_sigma=1.149,
                   shot_noise=0.00966, jpeg_quality=85, crosstalk=0.1946, background='wall',
                   seed=44741746)
    assert all(c.ids is None or c.ids.as_tuple() == ids for c in DETECTOR.detect(image, VGA))


def bayer_demosaiced(image):
    """Return the image as a GBRG Bayer camera gives it, demosaiced as the node decodes it."""
    from pattern_locator.nodes.image_codec import decode_image
    channel = {'B': 0, 'G': 1, 'R': 2}
    mosaic = np.empty(image.shape[:2], np.uint8)
    for dy in range(2):
        for dx in range(2):
            mosaic[dy::2, dx::2] = image[dy::2, dx::2, channel['GBRG'[2 * dy + dx]]]
    h, w = mosaic.shape
    return decode_image(h, w, 'bayer_gbrg8', 0, w, mosaic.tobytes())


def test_black_centres_read_through_a_bayer_mosaic():
    # The paper's room seen by a 640x480 camera through a GBRG Bayer mosaic
    # (the node's encoding test): bilinear demosaicing gives the small
    # point-1 dots of a card 4 m away colour fringes; its big black centre
    # stays grey, and is read black.
    from scene_tools import base_pose, CAMERA, view
    image, _ = view(1, 3, base_pose(4.0, 2.5, 180.0), 0.0, math.radians(15.0))
    codes = [str(c.code) for c in DETECTOR.detect(bayer_demosaiced(image), CAMERA)]
    assert codes == ['K-KRRRBRRG']


def test_colour_channels_shifted_two_pixels_are_read_right():
    # Red and blue images 2 px from the green one (composite video, a cheap
    # lens), a lens's lateral colour and composite video's narrow chroma band.
    for k, ids in enumerate([(2, 17, 3), (5, 40, 6), (11, 81, 9)]):
        angle = math.radians(70.0 * k)
        T = card_pose_facing(2.0 + 0.8 * k, 35.0, 100.0 * k, 10.0, (40.0, 20.0), VGA)
        image = render([(T, CFG.encode(*ids))], channel_shift_px=(2 * math.cos(angle),
                                                                  2 * math.sin(angle)),
                       lateral_ca=0.002, chroma_blur_px=1.0, noise_sigma=1.5, seed=k)
        assert ids_found(image) == [ids], ids


@pytest.mark.parametrize('contrast', [1.0, 0.45], ids=['mirror', 'through the paper'])
def test_a_mirror_image_never_gives_an_id(contrast):
    # Seen in a mirror (or from behind thin paper against the light, faded),
    # a card shows its ring in the other order: another valid code. The
    # handedness marks show paper where they belong and a mark where a
    # mirror puts them.
    ids = (2, 17, 3)
    for k, (distance, tilt) in enumerate([(1.5, 20.0), (2.5, 40.0), (4.0, 10.0)]):
        T = card_pose_facing(distance, tilt, 130.0 * k, 0.0, (20.0, 10.0), VGA)
        mirror = MirroredTexture(DotCardTexture(CFG, CFG.encode(*ids)), contrast)
        image = render([(T, mirror)], noise_sigma=1.5, seed=k)
        assert DETECTOR.detect(image, VGA) == [], (distance, tilt)
        # The same card seen directly is read.
        direct = render([(T, CFG.encode(*ids))], noise_sigma=1.5, seed=k)
        assert ids_found(direct) == [ids]


def test_cards_without_marks_still_read_and_their_mirror_reads_as_the_mirrored_code():
    # The paper's cards carry no marks: they are read with a configuration
    # that says so. Their mirror image then reads as the mirrored code, at a
    # mirrored pose: what the localizer's plausibility gates must catch (and
    # a building map should not hold a code and its mirror image).
    detector = Detector(PAPER_CFG)
    code = PAPER_CFG.encode(2, 17, 3)
    T = card_pose_facing(2.0, 30.0, 40.0, 0.0, (20.0, 10.0), VGA)
    direct = render([(T, code)], config=PAPER_CFG, noise_sigma=1.5)
    assert [c.code for c in detector.detect(direct, VGA)] == [code]
    mirror = render([(T, MirroredTexture(DotCardTexture(PAPER_CFG, code)))], config=PAPER_CFG,
                    noise_sigma=1.5)
    assert [c.code for c in detector.detect(mirror, VGA)] == [code.mirrored()]
    # A detector set up for marked cards does not read an unmarked one.
    assert DETECTOR.detect(direct, VGA) == []


# Bounded work ---------------------------------------------------------------------------

def peak_mb(run):
    tracemalloc.start()
    try:
        run()
        return tracemalloc.get_traced_memory()[1] / 1e6
    finally:
        tracemalloc.stop()


def test_fine_texture_at_1280x720_costs_bounded_memory_and_candidates_and_finds_the_card():
    # Carpet, gravel, foliage: noise blurred by 0.6-1.2 px filled the old
    # detector's blob pairs (7 GB, 6 s at this size). A card lies on it.
    T = card_pose_facing(2.0, 35.0, 20.0, 10.0, (-200.0, 80.0), HD)
    code = CFG.encode(3, 9, 4)
    image = render([(T, code)], camera=HD, background='texture', noise_sigma=2.0, seed=11)
    dot_image = segment(image, DETECTOR.params)
    chosen = card_stage.rank_candidates(dot_image.blobs, CFG, DETECTOR.params)
    assert len(chosen) <= DETECTOR.params.max_candidates
    found = []
    assert peak_mb(lambda: found.extend(DETECTOR.detect(image, HD))) < 100.0
    assert [c.code for c in found] == [code]


def test_dark_noisy_frame_makes_no_card_and_few_blobs():
    # A night scene at low gain with strong sensor noise behind nothing.
    image = render_scene(VGA, [], RenderOptions(background='night', gain=0.15, shot_noise=0.04,
                                                noise_sigma=5.0, seed=4)).image
    dot_image = segment(image, DETECTOR.params)
    assert len(dot_image.blobs) < 500          # noise-aware: not one blob per noise speck
    assert DETECTOR.detect(image, VGA) == []


def test_twenty_thousand_blobs_give_a_bounded_number_of_candidates():
    # A 1280x720 field of 20,000 dots in random sizes, some in rings of eight.
    rng = np.random.default_rng(3)
    image = np.full((720, 1280, 3), 235, np.uint8)
    ys, xs = np.mgrid[4:716:7, 4:1276:7]
    keep = rng.random(ys.shape) < 0.99
    for x, y, r in zip(xs[keep], ys[keep], rng.integers(1, 3, size=np.count_nonzero(keep))):
        cv2.circle(image, (int(x), int(y)), int(r), (40, 40, 40), -1)
    dot_image = segment(image, DetectorParams(noise_factor=3.0))
    assert len(dot_image.blobs) > 15000
    chosen = card_stage.rank_candidates(dot_image.blobs, CFG, DETECTOR.params)
    assert len(chosen) <= DETECTOR.params.max_candidates
    assert peak_mb(lambda: Detector(CFG, DetectorParams(noise_factor=3.0)).detect(
        image, CameraModel.from_focal(1280, 720, 900.0))) < 100.0


# Found ----------------------------------------------------------------------------------

# Blotches of the dots' own sizes behind the card (a patterned carpet, gravel
# or leaves seen close, a busy poster): hundreds of candidate centres, each
# with ring-dot-sized neighbours all round. Ranked by neighbour counts and
# quiet alone, the card fell outside the budget in these four (and in 30 %
# of such frames); in its own frame a card's centre has bare paper round it
# and no more neighbours than its two rings and marks.
@pytest.mark.parametrize('camera, distance, view, azimuth, roll, offset, ids, seed', [
    (VGA, 3.61, 20.0, 177.0, 7.0, (-132.0, 11.0), (10, 22, 4), 2),
    (HD, 2.88, 24.0, 345.0, -7.0, (-29.0, -100.0), (4, 65, 4), 11),
    (VGA, 3.65, 17.0, 286.0, -4.0, (28.0, 47.0), (7, 41, 2), 16),
    (HD, 3.85, 19.0, 254.0, -6.0, (97.0, -54.0), (9, 59, 8), 19),
], ids=['vga-3.6m', 'hd-2.9m', 'vga-3.7m', 'hd-3.9m'])
def test_found_before_blotches_of_its_dots_sizes(camera, distance, view, azimuth, roll, offset,
                                                 ids, seed):
    T = card_pose_facing(distance, view, azimuth, roll, offset, camera)
    image = render([(T, CFG.encode(*ids))], camera=camera, background='mottled',
                   noise_sigma=2.0, seed=seed)
    blobs = segment(image, DETECTOR.params).blobs
    chosen = card_stage.rank_candidates(blobs, CFG, DETECTOR.params)
    centre = camera.project(T.t[None])[0]
    nearest = int(np.argmin(np.hypot(blobs.u - centre[0], blobs.v - centre[1])))
    assert len(blobs) > 300 and nearest in chosen
    assert ids_found(image, camera) == [ids]


@pytest.mark.parametrize('name, options', [
    ('dim, gain 0.3, warm', {'gain': 0.3, 'colour_cast': (1.25, 1.0, 0.75), 'noise_sigma': 3.0,
                             'shot_noise': 0.015}),
    ('motion blur 7 px', {'motion_blur_px': 7.0, 'motion_blur_angle_deg': 30.0,
                          'noise_sigma': 2.0}),
], ids=['dim', 'blur'])
def test_found_in_dim_light_and_with_motion_blur(name, options):
    for k, (distance, tilt, ids) in enumerate([(1.6, 10.0, (2, 17, 3)), (2.5, 40.0, (7, 63, 2)),
                                               (3.5, 25.0, (0, 1, 1))]):
        T = card_pose_facing(distance, tilt, 80.0 * k, 5.0, (30.0, -20.0), VGA)
        image = render([(T, CFG.encode(*ids))], defocus_sigma_px=0.6, seed=k, **options)
        assert ids_found(image) == [ids], (name, distance)


def covered_fraction(polygon):
    """Fraction of the card's area under a card-plane polygon."""
    from pattern_locator.sim.render import _in_polygon
    g = np.linspace(-CFG.card_size / 2, CFG.card_size / 2, 200)
    x, y = np.meshgrid(g, g)
    return float(np.mean(_in_polygon(x, y, polygon)))


BOTTOM_BAND = np.array([[-0.3, -0.3], [0.3, -0.3], [0.3, -0.09], [-0.3, -0.09]])
CORNER = np.array([[0.16, 0.16], [0.16 - 0.18, 0.16], [0.16, 0.16 - 0.18]]) + 0.0
ROUND = np.column_stack([0.4 + 0.3 * np.cos(np.linspace(0, 2 * np.pi, 40)),
                         0.3 * np.sin(np.linspace(0, 2 * np.pi, 40))])


@pytest.mark.parametrize('polygon, colour', [
    (BOTTOM_BAND, (0.35, 0.3, 0.28)), (CORNER, (0.8, 0.8, 0.78)), (ROUND, (0.6, 0.45, 0.38))],
    ids=['band, dark', 'corner, pale', 'round, skin'])
def test_found_with_a_fifth_of_the_card_hidden(polygon, colour):
    # An object over 15-20 % of the card hides outer-ring dots (a whole slot
    # or more); the other ring's dots and the homography carry the card.
    assert 0.1 <= covered_fraction(polygon) <= 0.3
    code = CFG.encode(4, 12, 3)
    for k, (distance, tilt) in enumerate([(2.0, 30.0), (3.5, 20.0)]):
        T = card_pose_facing(distance, tilt, 200.0, 15.0, (20.0, 10.0), VGA)
        result = render_scene(VGA, [CardPlacement(T, DotCardTexture(CFG, code))],
                              RenderOptions(occluders=(Occluder(0, polygon, colour),),
                                            noise_sigma=1.5, seed=k))
        visible = result.truth[0].dot_visible
        assert np.count_nonzero(visible[1:9] < 1.0) >= 1
        (card,) = DETECTOR.detect(result.image, VGA)
        assert card.code == code
        # Hidden dots are not reported.
        assert np.all(np.isnan(card.points_px[visible == 0.0, 0]))


def test_interlaced_frame_of_a_panning_camera_is_found_and_one_field_can_be_chosen():
    # The two fields 8 px apart (the head panned between them) and blurred by
    # the pan during each field: combs on every dot.
    ids = (6, 77, 1)
    T = card_pose_facing(2.5, 25.0, 300.0, -10.0, (-30.0, 20.0), VGA)
    image = render([(T, CFG.encode(*ids))], interlace_shift_px=8.0, motion_blur_px=3.0,
                   noise_sigma=1.5, seed=5)
    assert ids_found(image) == [ids]                      # field='auto' sees the comb
    even = Detector(CFG, DetectorParams(field='even'))
    (card,) = even.detect(image, VGA)
    assert card.ids.as_tuple() == ids
    # The even field is the frame's time: its dots are where the even rows show them.
    still = render([(T, CFG.encode(*ids))], noise_sigma=1.5, motion_blur_px=3.0, seed=5)
    (ref,) = even.detect(still, VGA)
    assert np.nanmax(np.linalg.norm(card.points_px - ref.points_px, axis=1)) < 0.5


@pytest.mark.parametrize('distance, tilt', [(6.0, 30.0), (7.5, 15.0)])
def test_found_at_six_to_eight_metres(distance, tilt):
    ids = (9, 64, 8)
    T = card_pose_facing(distance, tilt, 45.0, 20.0, (50.0, -30.0), VGA)
    image = render([(T, CFG.encode(*ids))], noise_sigma=2.0, defocus_sigma_px=0.7, seed=2,
                   background='clutter')
    assert ids_found(image) == [ids]


# Far frames whose colour chroma shifted by 1.3-1.4 px, blurred and JPEG'd
# at 71 turned a slot seen by one ring to a wrong colour, next to a dot
# greyed to black. Reading the greyed slot from its other ring there (as a
# first version of the rule did) gave a wrong id in both.
FAR_SHIFTED_CHROMA = [
    (7.411851097906856, 48.66031859780872, 285.94296249246537, -18.062468154676747,
     (257.24329627497724, -106.38183006751233), (7, 23, 1),
     {'gain': 0.7485063768547002,
      'colour_cast': (0.8706189808922865, 1.007429020002562, 1.1219519991051516),
      'gradient': 0.24224680940493157, 'gradient_angle_deg': 316.9765101430081,
      'defocus_sigma_px': 0.8091217256637977, 'noise_sigma': 2.8803147003625202,
      'shot_noise': 0.006621783476027301, 'jpeg_quality': 71,
      'lateral_ca': 0.0013053976709720633,
      'channel_shift_px': (-1.408316700725377, -0.041438279748694073),
      'crosstalk': 0.1915892456301641, 'background': 'clutter', 'seed': 351851352}),
    (6.550437749059512, 48.22258461409193, 188.21886190630602, -27.19378724714499,
     (-97.26216787342108, 131.6735514695651), (2, 40, 1),
     {'gain': 0.9613692307785211,
      'colour_cast': (1.1510976095111332, 1.061644902741356, 0.7872574877475106),
      'gradient': 0.15473765672850617, 'gradient_angle_deg': 359.4943325276124,
      'defocus_sigma_px': 0.9302289997395323, 'noise_sigma': 1.1875786348910178,
      'shot_noise': 0.002416382830474192, 'jpeg_quality': 71,
      'lateral_ca': -0.0008471992590305647,
      'channel_shift_px': (1.305086261866988, -0.5059364400454356),
      'chroma_blur_px': 1.47513911963205, 'crosstalk': 0.2571470956938468,
      'background': 'wall', 'seed': 1071390604}),
]


@pytest.mark.parametrize('distance, view, azimuth, roll, offset, ids, options',
                         FAR_SHIFTED_CHROMA)
def test_far_card_with_shifted_chroma_gives_no_wrong_id(distance, view, azimuth, roll, offset,
                                                        ids, options):
    """A greyed dot is read from the other ring only when every other slot has both rings."""
    T = card_pose_facing(distance, view, azimuth, roll_deg=roll, offset_px=offset, camera=VGA)
    image = render([(T, CFG.encode(*ids))], VGA, supersample=2, **options)
    assert set(ids_found(image)) <= {ids}


# Glare: a glossy card's highlight --------------------------------------------------

def with_highlight(image, centre, sigma, amplitude):
    """Add a lamp's highlight (a Gaussian of light, clipping at white) to a rendered image."""
    h, w = image.shape[:2]
    yy, xx = np.mgrid[0:h, 0:w]
    spot = amplitude * np.exp(-((xx - centre[0]) ** 2 + (yy - centre[1]) ** 2) / (2 * sigma ** 2))
    return np.clip(image + spot[:, :, None], 0, 255).astype(np.uint8)


GLARE_CODE = CFG.encode(4, 33, 6)


def glare_image(camera, distance, shift, amplitude, sigma, seed=4):
    """Render the card 20 degrees off face-on, a highlight of ``sigma`` ring radii beside it."""
    T = card_pose_facing(distance, 20.0, 60.0, 5.0, (0.0, 0.0), camera)
    image = render([(T, GLARE_CODE)], camera, noise_sigma=1.5, seed=seed, gain=0.8)
    ring = CFG.ring_radii[0] * camera.fx / distance
    centre = (camera.width / 2 + shift * ring, camera.height / 2 - 0.2 * ring)
    return with_highlight(image.astype(float), centre, sigma * ring, amplitude)


@pytest.mark.parametrize('camera, distance, shift, amplitude', [
    (VGA, 3.0, 0.3, 100), (VGA, 2.0, 0.3, 70), (HD, 3.0, -0.3, 70), (HD, 3.0, 0.3, 100)])
def test_a_highlights_flank_is_not_read_as_ink_round_the_dots(camera, distance, shift, amplitude):
    # The grid's white (a max filter) on the flank is the brighter paper
    # nearer the highlight: the paper round the dots is their white there
    # (spot_kernels._paper_level). Before, none of these was found.
    image = glare_image(camera, distance, shift, amplitude, 0.3)
    assert [c.code for c in DETECTOR.detect(image, camera)] == [GLARE_CODE]


def test_highlights_of_any_strength_give_no_wrong_id():
    for amplitude in (40, 120, 200, 250):
        for sigma, shift in ((0.2, 0.0), (0.35, -0.4), (0.5, 0.5)):
            codes = [c.code for c in DETECTOR.detect(
                glare_image(HD, 2.5, shift, amplitude, sigma), HD) if c.code is not None]
            assert codes in ([], [GLARE_CODE]), (amplitude, sigma, shift)
