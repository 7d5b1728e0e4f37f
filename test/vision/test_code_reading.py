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


def test_one_ring_is_enough_when_the_other_is_hidden_there():
    code = CFG.encode(7, 63, 2)
    valid = ALL.copy()
    valid[1:4] = False                         # three outer dots hidden, point 1 among them
    reading = read_code(seen(code, point1_slot=1), valid, 2, CFG, PARAMS)
    assert reading.code == code
    assert reading.ring_codes[0].count('?') == 3 and reading.ring_codes[0][0] == '?'
    assert reading.ring_codes[1] == code.ring


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
