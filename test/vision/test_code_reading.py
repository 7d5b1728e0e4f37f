"""Order and code stage: inks read against a fitted camera response, with margins; handedness."""

import numpy as np
from pattern_locator.card.pattern import Code, PatternConfig, RING_POINTS
from pattern_locator.vision.centres import SpotMeasures
from pattern_locator.vision.code_reading import handedness, ink_darkness, read_code
from pattern_locator.vision.detector_params import DetectorParams
import pytest

CFG = PatternConfig()
PARAMS = DetectorParams()
INKS = dict(zip('KRGB', ink_darkness(CFG)))


def seen(code: Code, point1_slot=3, crosstalk=0.0, white_error=(1.0, 1.0, 1.0), light=(1, 1, 1),
         blur=None, noise=0.0, seed=0):
    """Darkness (BGR) a camera would measure of every dot, in slot order."""
    rng = np.random.default_rng(seed)
    letters = [code.centre] + [code.ring[(k - point1_slot) % RING_POINTS]
                               for ring in range(CFG.n_rings) for k in range(RING_POINTS)]
    d = np.array([INKS[c] for c in letters])
    t = crosstalk
    mix = (np.full((3, 3), t / 2) + np.eye(3) * (1 - 1.5 * t)) * np.asarray(light, float)
    mix /= mix.sum(axis=1, keepdims=True)
    d = d @ mix.T
    a = rng.uniform(0.6, 1.0, len(d)) if blur is None else np.full(len(d), blur)
    d = a[:, None] * d
    d = 1.0 - np.asarray(white_error) * (1.0 - d)
    return d + rng.normal(0.0, noise, d.shape)


ALL = np.ones(CFG.n_dots, dtype=bool)


def test_reads_the_code_and_point1_slot():
    code = CFG.encode(2, 17, 3)
    reading = read_code(seen(code, point1_slot=5), ALL, 2, CFG, PARAMS)
    assert reading.code == code and reading.point1_slot == 5
    assert reading.ring_codes == (str(code.ring), str(code.ring)) and reading.margin > 0.8


@pytest.mark.parametrize('light', [(1.3, 0.7, 1.3), (1.4, 0.8, 0.8), (0.7, 1.2, 1.3)])
def test_green_centre_without_green_ring_under_coloured_light_and_grey_sensor(light):
    # Magenta, red and cyan light (BGR gains), a sensor whose filters
    # overlap a lot: green is read green, not black.
    code = Code.parse('G-KBRRRRRR')
    bgr = light[::-1]
    white = np.array(bgr) * 200.0
    reading = read_code(seen(code, crosstalk=0.3, light=bgr, noise=0.005, seed=1), ALL, 2,
                        CFG, PARAMS, white)
    assert reading is not None and reading.code == code


# A card printed with its inks far too dark (green sRGB 10, 100, 40 for 32,
# 176, 80), as the detector measured it under magenta light at 2.9 m: code
# G-KBRRRRBB, point 1 in slot 2. Its centre is nearer black than the
# configured green, and was read black (another floor), but it is not the
# black of point 1 (rows 3 and 11): its green channel is 0.1 less dark.
DARK_GREEN_CENTRE = np.array([
    [0.9421, 0.8698, 0.9558], [0.7821, 0.9291, 0.9461], [0.7826, 0.9305, 0.9464],
    [0.9661, 0.9674, 0.9661], [0.7776, 0.9285, 0.9457], [0.9369, 0.928, 0.705],
    [0.9346, 0.9254, 0.705], [0.9372, 0.9261, 0.7084], [0.9372, 0.9271, 0.7119],
    [0.7806, 0.9288, 0.9461], [0.7796, 0.9327, 0.9477], [0.9659, 0.9671, 0.9653],
    [0.7781, 0.9304, 0.9457], [0.9387, 0.9271, 0.7085], [0.9364, 0.9244, 0.7079],
    [0.9372, 0.9287, 0.7074], [0.9382, 0.9237, 0.7137]])
DARK_GREEN_WHITE = np.array([217.0, 174.0, 216.0])


def test_a_dark_colour_in_the_centre_is_not_taken_for_black():
    assert read_code(DARK_GREEN_CENTRE, ALL, 2, CFG, PARAMS, DARK_GREEN_WHITE) is None
    # The same card with point 1's black in the centre reads, black centre.
    black = DARK_GREEN_CENTRE.copy()
    black[0] = 0.98 * black[3]
    reading = read_code(black, ALL, 2, CFG, PARAMS, DARK_GREEN_WHITE)
    assert reading is not None and reading.code == Code.parse('K-KBRRRRBB')


# A card 4 m away seen through a Bayer mosaic (GBRG, bilinear demosaicing,
# as the node decodes it): code K-KRRRBRRG, point 1 in slot 6. Its small
# point-1 dots have colour fringes (rows 7 and 15); its big centre is grey.
BAYER_CARD = np.array([
    [0.9543, 0.9554, 0.9528], [0.6565, 0.7142, 0.154], [0.7135, 0.7503, 0.1471],
    [0.2504, 0.6819, 0.6708], [0.6924, 0.7433, 0.1604], [0.6798, 0.727, 0.1573],
    [0.5807, 0.4005, 0.7015], [0.6619, 0.7304, 0.6915], [0.6836, 0.739, 0.1584],
    [0.6583, 0.6998, 0.1625], [0.6849, 0.7395, 0.1386], [0.2453, 0.7088, 0.6906],
    [0.6864, 0.722, 0.1529], [0.6796, 0.7208, 0.1444], [0.5791, 0.3971, 0.6955],
    [0.681, 0.7218, 0.6573], [0.6827, 0.733, 0.1671]])


def test_a_grey_black_centre_reads_though_point_1_has_colour_fringes():
    reading = read_code(BAYER_CARD, ALL, 2, CFG, PARAMS, np.array([237.0, 236.0, 236.0]), 1)
    assert reading is not None and reading.code == Code.parse('K-KRRRBRRG')


def test_a_black_centre_as_noisy_as_the_ring_still_reads():
    # Black against point 1 within the ring's own scatter: read.
    code = Code.parse('K-KBRGRRBG')
    for seed in range(40):
        reading = read_code(seen(code, noise=0.005, blur=0.9, seed=seed), ALL, 2, CFG, PARAMS)
        assert reading is not None and reading.code == code, seed


def test_a_clipped_white_is_undone():
    # Strong blue light clips the paper's blue: light channels lose darkness.
    code = Code.parse('G-KRRBRBBR')
    measured = seen(code, white_error=(1.4, 1.0, 1.0))
    assert measured[[i for i in range(1, 9) if i != 4]].min() < 0.3   # a blue dot's blue
    assert read_code(measured, ALL, 2, CFG, PARAMS).code == code


def test_unclear_colours_are_rejected_never_guessed():
    code = CFG.encode(2, 17, 3)
    d = seen(code)
    # The centre halfway between black and green: no centre.
    d[0] = 0.5 * (INKS['K'] + INKS['G'])
    assert read_code(d, ALL, 2, CFG, PARAMS) is None
    # The rings disagree on one slot.
    d = seen(code, point1_slot=0)
    d[1 + RING_POINTS + 2] = INKS['R'] if code.ring[2] != 'R' else INKS['B']
    assert read_code(d, ALL, 2, CFG, PARAMS) is None
    # Two black slots (an invalid card), and no black slot.
    assert read_code(seen(Code('R', 'KKGBRGBR')), ALL, 2, CFG, PARAMS) is None
    assert read_code(seen(Code('R', 'RGBRGBRG')), ALL, 2, CFG, PARAMS) is None
    # A whole slot unseen on both rings.
    valid = ALL.copy()
    valid[[1 + 4, 1 + RING_POINTS + 4]] = False
    assert read_code(seen(code), valid, 2, CFG, PARAMS) is None


def test_a_slot_the_rings_disagree_on_is_unknown_and_only_a_map_may_fill_it():
    code = CFG.encode(2, 17, 3)
    d = seen(code, point1_slot=0)
    d[1 + RING_POINTS + 2] = INKS['R'] if code.ring[2] != 'R' else INKS['B']
    # Without a map: rejected (as in the test above).
    assert read_code(d, ALL, 2, CFG, PARAMS, max_hidden=1) is None
    # With one: a partial reading, that slot unknown.
    reading = read_code(d, ALL, 2, CFG, PARAMS, max_hidden=3, known_codes=True)
    assert reading.code is None and reading.point1_slot == 0
    assert reading.slot_letters == code.ring[:2] + '?' + code.ring[3:]
    assert reading.ring_codes == (reading.slot_letters,) * 2
    assert np.isnan(reading.slot_margins[2])
    # It counts as a hidden slot: with two more hidden, over the limit.
    valid = ALL.copy()
    valid[[1 + 5, 1 + RING_POINTS + 5, 1 + 6, 1 + RING_POINTS + 6]] = False
    assert read_code(d, valid, 2, CFG, PARAMS, max_hidden=2, known_codes=True) is None
    assert read_code(d, valid, 2, CFG, PARAMS, max_hidden=3, known_codes=True) is not None
    # Point 1 read as two colours: seven coloured slots would make it point 1
    # (as when it is hidden), but neither ring saw black there: rejected. (A
    # coloured centre: a black one is refused with point 1 unseen.)
    code = CFG.encode(5, 17, 3)
    d = seen(code, point1_slot=0)
    d[1] = INKS['R']
    d[1 + RING_POINTS] = INKS['B']
    assert read_code(d, ALL, 2, CFG, PARAMS, max_hidden=3, known_codes=True) is None
    # One ring saw the black: point 1, as for a hidden slot.
    d[1] = INKS['K']
    assert read_code(d, ALL, 2, CFG, PARAMS, max_hidden=3, known_codes=True).code == code


def test_one_ring_is_enough_when_the_other_is_hidden_there():
    code = CFG.encode(7, 63, 2)
    valid = ALL.copy()
    valid[1:4] = False                         # three outer dots hidden, point 1 among them
    reading = read_code(seen(code, point1_slot=1), valid, 2, CFG, PARAMS)
    assert reading.code == code
    assert reading.ring_codes[0].count('?') == 3 and reading.ring_codes[0][0] == '?'
    assert reading.ring_codes[1] == code.ring


def greyed(colour, keep=0.15):
    """Take most of a dot's chroma away (as JPEG's half-resolution chroma does to a far dot)."""
    mean = colour.mean()
    return mean + keep * (colour - mean)


def test_a_far_dot_greyed_to_black_in_one_ring_is_read_from_the_other():
    code = CFG.encode(2, 17, 3)                 # K-KRGBGRBB
    d = seen(code, point1_slot=0, blur=0.9)
    inner = 1 + RING_POINTS
    for k in range(1, RING_POINTS):
        grey = d.copy()
        grey[inner + k] = greyed(d[inner + k])
        # Point 1 is black in both rings elsewhere, and the greyed dot is lighter than it.
        assert read_code(grey, ALL, 2, CFG, PARAMS).code == code, k
    grey = d.copy()
    grey[inner + 2] = greyed(d[inner + 2])
    # A dot as dark as point 1 may be black: the rings disagree, and only a map may tell.
    dark = grey.copy()
    dark[inner + 2] = d[inner]
    assert read_code(dark, ALL, 2, CFG, PARAMS) is None
    reading = read_code(dark, ALL, 2, CFG, PARAMS, max_hidden=3, known_codes=True)
    assert reading.code is None and reading.slot_letters[2] == '?'
    # Point 1 seen black by one ring only (the other's hidden there): no point 1 to go by.
    hidden = ALL.copy()
    hidden[inner] = False
    assert read_code(grey, hidden, 2, CFG, PARAMS) is None
    # The other ring's colour unclear (half its chroma gone: below the usual
    # margin): nothing to read it from, and the slot stays one for the map
    # (not a rejected card).
    unclear = grey.copy()
    unclear[1 + 2] = greyed(d[1 + 2], keep=0.5)
    assert read_code(unclear, ALL, 2, CFG, PARAMS) is None
    reading = read_code(unclear, ALL, 2, CFG, PARAMS, max_hidden=3, known_codes=True)
    assert reading.code is None and reading.slot_letters[2] == '?'
    # Two slots read black by every ring: no point 1 to go by.
    two = grey.copy()
    two[[1 + 5, inner + 5]] = d[1]
    assert read_code(two, ALL, 2, CFG, PARAMS) is None
    # The greyed dot keeps another ink's hue than the other ring reads (blue, not green).
    other = grey.copy()
    other[inner + 2] = greyed(0.9 * INKS['B'])
    assert read_code(other, ALL, 2, CFG, PARAMS) is None
    # Another slot seen by one ring only: the chroma that greyed one dot may
    # have turned that one's colour, with no second ring to show it.
    one_ring = ALL.copy()
    one_ring[1 + 5] = False
    assert read_code(grey, one_ring, 2, CFG, PARAMS) is None
    assert read_code(d, one_ring, 2, CFG, PARAMS).code == code


def test_a_grey_object_over_a_dot_is_not_a_black_point():
    code = CFG.encode(2, 17, 3)
    d = seen(code, point1_slot=0, blur=0.95)
    d[1 + 6] = [0.6, 0.6, 0.6]                 # grey object over outer point 7
    reading = read_code(d, ALL, 2, CFG, PARAMS)
    assert reading.code == code and reading.not_dots == (7,)


def marks(valid, peak, inside=(True, True, True, True)):
    n = len(valid)
    return SpotMeasures(np.zeros((n, 2)), np.zeros((n, 2)), np.array(valid, bool),
                        np.array(valid, bool), np.array(peak),
                        np.full((n, 3), np.nan), np.ones(n), np.array(inside))


def test_handedness():
    # Marks 1, 2 then their mirror images.
    assert handedness(marks([1, 1, 0, 0], [0.7, 0.7, 0.0, 0.0]), 0.7) == 'ok'
    assert handedness(marks([0, 0, 1, 1], [0.0, 0.0, 0.7, 0.7]), 0.7) == 'mirror'
    # One mark hidden by an object, the other in place: still the card.
    assert handedness(marks([1, 0, 0, 0], [0.7, 0.5, 0.4, 0.0]), 0.7) == 'ok'
    # Too faint to tell, or marks both ways: unsure.
    assert handedness(marks([1, 1, 0, 0], [0.2, 0.2, 0.0, 0.0]), 0.7) == 'unsure'
    assert handedness(marks([1, 0, 1, 0], [0.7, 0.0, 0.7, 0.0]), 0.7) == 'unsure'


def test_a_far_cards_faint_marks_say_it_is_seen_directly_only_against_blank_mirror_places():
    # Marks a pixel or two across fail the dot tests (not valid), yet are
    # dark where they belong; the mirror images' places are paper.
    faint = [0.16, 0.15, 0.0, 0.0]
    assert handedness(marks([0, 0, 0, 0], faint), 0.26) == 'ok'
    # Seen in a mirror: the marks at the mirror images' places. No id.
    assert handedness(marks([0, 0, 0, 0], faint[2:] + faint[:2]), 0.26) == 'unsure'
    # A mirror image's place not paper, one mark too pale, a place off the
    # image, or no point 1 to compare with: unsure.
    assert handedness(marks([0, 0, 0, 0], [0.16, 0.15, 0.05, 0.0]), 0.26) == 'unsure'
    assert handedness(marks([0, 0, 0, 0], [0.16, 0.06, 0.0, 0.0]), 0.26) == 'unsure'
    assert handedness(marks([0, 0, 0, 0], faint, (True, True, True, False)), 0.26) == 'unsure'
    assert handedness(marks([0, 0, 0, 0], [0.0, 0.0, 0.0, 0.0]), 0.0) == 'unsure'
