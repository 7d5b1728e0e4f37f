"""
``pattern-locator bench --inks``: cards in a printer's inks, read before and after calibration.

A printer prints its own red, green and blue, not the configuration's
colours. For each printer below, the stress bench's frames (every
condition but the mirrors and the glare, both cameras) are rendered with the cards'
dots in that printer's inks, and read by the locator with the building's
codes twice: by the configured colours, and by the inks that
``pattern-locator inks`` measured from one rendered photo of that
printer's sheet (:mod:`..vision.ink_check`). Found and wrong ids per
printer, as the stress bench counts them.
"""

from dataclasses import replace
from typing import List, Sequence, Tuple

import numpy as np

from . import stress
from .bench import bench_cameras
from ..card.pattern import hex_colours, Ids, load_pattern_config, PatternConfig
from ..sim.render import (card_pose_facing, CardPlacement, printed_card_texture, render_scene,
                          RenderOptions)
from ..vision.camera import CameraModel
from ..vision.ink_check import InkReport, measure_inks
from ..vision.locate import CardLocator

Inks = Tuple[Tuple[str, Tuple[int, int, int]], ...]


def _mixed(inks: Inks, weight: float, towards: float) -> Inks:
    return tuple((k, tuple(int(round((1 - weight) * c + weight * towards)) for c in rgb))
                 for k, rgb in inks)


def printers(config: PatternConfig) -> List[Tuple[str, Inks]]:
    """Return the printers of the bench: (name, the sRGB each makes of K, R, G, B)."""
    return [
        ('as configured', config.colours_rgb),
        # The process colours an office (CMYK) printer makes of red, green and
        # blue: its blue is cyan and magenta, a dark violet.
        ('office printer', hex_colours({'K': '#231f20', 'R': '#ed1c24', 'G': '#00a651',
                                        'B': '#2e3192'})),
        ('dark inks', _mixed(config.colours_rgb, 0.3, 0.0)),
        ('faded inks', _mixed(config.colours_rgb, 0.35, 255.0)),
        # A printer far off: its red orange, its green teal, its blue violet.
        ('odd printer', hex_colours({'K': '#000000', 'R': '#f05a28', 'G': '#00a99d',
                                     'B': '#5b2c8f'})),
    ]


def calibration_photo(config: PatternConfig, inks: Inks, camera: CameraModel) -> np.ndarray:
    """Return a photo of one card of a printer's sheet: face-on at 0.8 m, ordinary light."""
    T = card_pose_facing(0.8, 8.0, 30.0, 4.0, (20.0, -10.0), camera)
    texture = printed_card_texture(config, CALIBRATION_IDS, inks=inks)
    options = RenderOptions(background='wall', noise_sigma=1.5, defocus_sigma_px=0.6,
                            jpeg_quality=90, seed=3)
    return render_scene(camera, [CardPlacement(T, texture)], options).image


CALIBRATION_IDS = Ids(5, 42, 7)


def read_counts(frames: Sequence[stress.Frame], printed: PatternConfig, locator: CardLocator
                ) -> Tuple[int, int]:
    """Return (found, wrong ids) over ``frames`` rendered with ``printed``'s inks."""
    cameras = bench_cameras()
    found = wrong = 0
    for frame in frames:
        camera = cameras[frame.camera_name]
        image = stress.render_frame(frame, camera, printed, 'dots')
        result = stress.score_located(locator.locate(image, camera), frame)
        found += result.found
        wrong += result.wrong_ids
    return found, wrong


def _inks_text(inks: Inks) -> str:
    return ' '.join('#{:02x}{:02x}{:02x}'.format(*rgb) for _, rgb in inks)


def run_inks_bench(per_camera: int = 2, seed: int = 1, quick: bool = False) -> int:
    """Print the table; return 0."""
    config = load_pattern_config()
    # Not the glare: a highlight is no printer's, and the table stays the
    # one measured before the stress bench had it.
    frames = [f for f in stress.make_frames(config, 1 if quick else per_camera, seed)
              if f.expected and f.condition != 'glare']
    codes = stress.stress_map(frames, config)
    plain = CardLocator(config, known_codes=codes)
    camera = bench_cameras()['1280x720 70deg barrel']
    print(f'{len(frames)} frames (stress conditions but the mirrors and the glare, both cameras, '
          f'seed {seed}),'
          " read with the building's codes; calibrated: by the inks `pattern-locator inks` "
          "measured from one photo of the printer's sheet")
    print(f'{"printer":<16} {"inks K R G B":<32} {"uncalibrated":>17}   '
          f'{"calibrated":>17}   measured (verdict)')
    for name, inks in printers(config)[:2 if quick else None]:
        printed = replace(config, inks_rgb=inks)
        report: InkReport = measure_inks([('photo', calibration_photo(config, inks, camera))],
                                         config, CALIBRATION_IDS, camera)
        calibrated = replace(config, inks_rgb=tuple((i.letter, i.measured_rgb)
                                                    for i in report.inks))
        before = read_counts(frames, printed, plain)
        after = read_counts(frames, printed, CardLocator(calibrated, known_codes=codes))
        cells = [f'{100.0 * found / len(frames):5.1f} % {wrong:3d} wrong'
                 for found, wrong in (before, after)]
        verdict = 'matches' if report.matches else 'differs'
        print(f'{name:<16} {_inks_text(inks):<32} {cells[0]:>17}   {cells[1]:>17}   '
              f'{_inks_text(tuple((i.letter, i.measured_rgb) for i in report.inks))} '
              f'({verdict})', flush=True)
    return 0
