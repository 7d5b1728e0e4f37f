"""The drawn card a node reads at start: every pass runs, and the detector reads it."""

import dataclasses

import numpy as np
from pattern_locator.card.pattern import load_pattern_config
from pattern_locator.vision.detector import Detector
from pattern_locator.vision.drawn_card import drawn_cards


def test_warm_up_reads_both_drawn_cards():
    config = load_pattern_config()
    assert Detector(config).warm_up() == 2
    # Cards printed without handedness marks (the paper's) read as well.
    unmarked = dataclasses.replace(config, handedness_mark=None)
    assert Detector(unmarked).warm_up() == 2


def test_drawn_dots_are_where_the_card_puts_them():
    config = load_pattern_config()
    ids, code = next(iter(config.all_codes()))
    image = drawn_cards(config, code, scales_px_per_m=(1000.0,))
    cards = Detector(config).detect(image)
    assert [card.ids for card in cards] == [ids]
    centre = np.array([0.5 * config.card_size * 1000.0 + 20.0, 240.0])
    plane = config.model_points()[:, :2] * [1000.0, -1000.0] + centre
    # Pixel centres: OpenCV draws a circle of centre (x, y) round pixel (x, y).
    assert np.max(np.abs(cards[0].points_px - plane)) < 0.2
