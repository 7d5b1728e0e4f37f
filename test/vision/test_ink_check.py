"""
A printer's inks, measured from a photo of a printed card, make the detector read its cards.

The sheet is the card printer's own raster (`printable`), its dots in a
printer's inks rather than the configuration's colours; the photo is the
renderer's (paper, black ink, light, blur, noise, JPEG). An office
printer's primaries (blue a dark violet) and a worse printer's (red
orange, green teal, blue violet) are read badly or wrongly by the
configured colours; measured and configured as `inks:`, they read as
well as the configured ones do.
"""

from dataclasses import replace

import cv2
import numpy as np
from pattern_locator.card.pattern import hex_colours, Ids, PatternConfig
from pattern_locator.errors import ConfigError, ImageError
from pattern_locator.sim.render import (card_pose_facing, CardPlacement, ink_reflectance,
                                        printed_card_texture, render_scene, RenderOptions)
from pattern_locator.vision.camera import CameraModel
from pattern_locator.vision.detector import Detector
from pattern_locator.vision.ink_check import linear_to_srgb, measure_inks
import pytest

CFG = PatternConfig()
HD = CameraModel.from_fov(1280, 720, 70.0, D=[-0.25, 0.07, 0.0, 0.0, 0.0])
VGA = CameraModel.from_focal(640, 480, 1000.0)
IDS = Ids(5, 42, 7)


# What printers made of the configured colours (sRGB as printed).
OFFICE = hex_colours({'K': '#231f20', 'R': '#ed1c24', 'G': '#00a651', 'B': '#2e3192'})
ODD = hex_colours({'K': '#000000', 'R': '#f05a28', 'G': '#00a99d', 'B': '#5b2c8f'})


def printed_sheet(inks, ids=IDS):
    """Return the card's printed sheet as a texture, its dots in ``inks``."""
    return printed_card_texture(CFG, ids, inks=inks)


def photo(texture, camera=HD, distance=0.8, view=8.0, seed=3, **options):
    T = card_pose_facing(distance, view, 30.0, 4.0, (20.0, -10.0), camera)
    opts = {'background': 'wall', 'noise_sigma': 1.5, 'defocus_sigma_px': 0.6,
            'jpeg_quality': 90, 'seed': seed}
    opts.update(options)
    return render_scene(camera, [CardPlacement(T, texture)], RenderOptions(**opts)).image


def as_photographed(inks):
    """Return the inks a photo shows against the paper (the renderer's paper and black ink)."""
    return {k: tuple(linear_to_srgb(ink_reflectance(np.array(rgb)) / 0.85))
            for k, rgb in inks}


@pytest.fixture(scope='module')
def office_photo():
    return photo(printed_sheet(OFFICE))


def test_the_inks_of_a_photographed_sheet_are_the_printed_ones(office_photo):
    report = measure_inks([('photo', office_photo)], CFG, IDS, HD)
    expected = as_photographed(OFFICE)
    for ink in report.inks:
        assert np.max(np.abs(np.subtract(ink.measured_rgb, expected[ink.letter]))) <= 4, ink
    # The office printer's blue is nearer black than blue by its direction.
    verdict = {ink.letter: (ink.read_as, ink.matches) for ink in report.inks}
    assert verdict['B'] == ('K', False) and verdict['R'] == ('R', True)
    assert not report.matches
    assert report.yaml_block().splitlines()[0] == 'inks:'


def test_a_card_printed_in_the_configured_colours_matches():
    report = measure_inks([('photo', photo(printed_sheet(CFG.colours_rgb), camera=VGA,
                                           distance=1.4))], CFG, IDS, VGA)
    assert report.matches
    assert all(ink.angle_deg < 2.0 for ink in report.inks)


def _reads(detector, inks, camera, n=8):
    """(right, wrong) reads of cards printed in ``inks`` over a spread of views and lights."""
    right = wrong = 0
    rng = np.random.default_rng(5)
    for k in range(n):
        ids = Ids(int(rng.integers(0, 12)), int(rng.integers(1, 82)), int(rng.integers(1, 10)))
        cast = tuple(float(c) for c in rng.uniform(0.8, 1.25, 3))
        image = photo(printed_sheet(inks, ids), camera, float(rng.uniform(1.3, 3.0)),
                      float(rng.uniform(0.0, 50.0)), seed=k, gain=float(rng.uniform(0.5, 1.1)),
                      colour_cast=cast, jpeg_quality=None)
        got = [c.ids for c in detector.detect(image, camera) if c.ids is not None]
        right += ids in got
        wrong += sum(1 for g in got if g != ids)
    return right, wrong


def test_the_measured_inks_make_the_detector_read_that_printers_cards():
    # The odd printer's cards read by the configured colours: few, or wrongly.
    before = _reads(Detector(CFG), ODD, VGA)
    report = measure_inks([('photo', photo(printed_sheet(ODD)))], CFG, IDS, HD)
    calibrated = replace(CFG, inks_rgb=tuple((i.letter, i.measured_rgb) for i in report.inks))
    after = _reads(Detector(calibrated), ODD, VGA)
    assert after == (8, 0), (before, after)
    assert before[0] < after[0]
    # A node's start-up read of its own drawn cards uses the inks too.
    assert Detector(calibrated).warm_up() == 2


def test_several_photos_are_averaged_and_must_agree(office_photo):
    other = photo(printed_sheet(OFFICE), camera=VGA, distance=1.2, view=20.0, seed=9)
    report = measure_inks([('a', office_photo), ('b', other)], CFG, IDS)
    assert report.images == 2 and [i.dots for i in report.inks] == [4, 6, 12, 12]
    swapped = np.ascontiguousarray(other[:, :, ::-1])         # red and blue exchanged
    with pytest.raises(ImageError, match='disagree on ink'):
        measure_inks([('a', office_photo), ('b', swapped)], CFG, IDS)


@pytest.mark.parametrize('change, words', [
    ('other ids', 'cannot tell point 1'),
    ('mirror', 'mirror'),
    ('far', 'take the card closer'),
    ('blank', 'no card found'),
    ('clipped', 'clipped white'),
    ('grey', 'colour image'),
])
def test_what_cannot_be_measured_is_refused_in_one_line(office_photo, change, words):
    image, ids, camera = office_photo, IDS, HD
    if change == 'other ids':
        ids = Ids(5, 42, 8)             # one ring point another ink
    elif change == 'mirror':
        image, camera = np.ascontiguousarray(office_photo[:, ::-1]), None
    elif change == 'far':
        image, camera = photo(printed_sheet(OFFICE), camera=VGA, distance=3.2), VGA
    elif change == 'blank':
        image = np.full_like(office_photo, 200)
    elif change == 'clipped':
        image = np.clip(office_photo.astype(np.int32) * 2, 0, 255).astype(np.uint8)
    elif change == 'grey':
        image = cv2.cvtColor(office_photo, cv2.COLOR_BGR2GRAY)
    with pytest.raises(ImageError, match=words) as err:
        measure_inks([('photo.png', image)], CFG, ids, camera)
    assert '\n' not in str(err.value) and 'photo.png' in str(err.value)


def test_a_card_without_every_ink_is_refused_before_any_image_is_read():
    code = next(code for _, code in CFG.all_codes() if set(code.centre + code.ring) == set('KRB'))
    ids = CFG.decode(code)
    with pytest.raises(ConfigError, match='has no G dot: measure a card that shows every ink, '
                                          'e.g. floor'):
        measure_inks([('never read', None)], CFG, ids)
    with pytest.raises(ConfigError, match='no images'):
        measure_inks([], CFG, IDS)
