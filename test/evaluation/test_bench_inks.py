"""The printers of ``bench --inks``, and the calibration its table rests on."""

from dataclasses import replace

from pattern_locator.card.pattern import PatternConfig
from pattern_locator.evaluation import stress
from pattern_locator.evaluation.bench import bench_cameras
from pattern_locator.evaluation.bench_inks import (CALIBRATION_IDS, calibration_photo, printers,
                                                   read_counts)
from pattern_locator.vision.ink_check import measure_inks
from pattern_locator.vision.locate import CardLocator

CFG = PatternConfig()


def test_printers_print_every_ink_and_the_first_as_configured():
    table = printers(CFG)
    assert table[0] == ('as configured', CFG.colours_rgb)
    for name, inks in table:
        assert [k for k, _ in inks] == list('KRGB'), name
        assert all(0 <= c <= 255 for _, rgb in inks for c in rgb), name


def test_the_odd_printers_cards_read_right_once_its_inks_are_measured():
    name, inks = printers(CFG)[-1]
    camera = bench_cameras()['1280x720 70deg barrel']
    report = measure_inks([('photo', calibration_photo(CFG, inks, camera))], CFG,
                          CALIBRATION_IDS, camera)
    assert name == 'odd printer' and not report.matches
    calibrated = replace(CFG, inks_rgb=tuple((i.letter, i.measured_rgb) for i in report.inks))
    frames = stress.make_frames(CFG, 1, 3, conditions=('plain', 'light tungsten'))
    codes = stress.stress_map(frames, CFG)
    found, wrong = read_counts(frames, replace(CFG, inks_rgb=inks),
                               CardLocator(calibrated, known_codes=codes))
    assert (found, wrong) == (len(frames), 0)
