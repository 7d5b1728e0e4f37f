"""
The ``pattern-locator`` command line: make-pattern, detect, bench, demo.

Errors a user can cause end as one readable line on stderr and exit status 2.
"""

import argparse
import json
import math
import os
from pathlib import Path
import sys
import time
from typing import List, Optional, Sequence

import cv2
import numpy as np

from .card.pattern import load_pattern_config
from .errors import ConfigError, PatternLocatorError
from .vision.locate import CardLocator, ESTIMATORS, LocatedCard

PROG = 'pattern-locator'


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    if not getattr(args, 'handler', None):
        parser.print_help()
        return 2
    try:
        return int(args.handler(args) or 0)
    except PatternLocatorError as exc:
        _error(str(exc))
        return 2
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        # The reader went away (`... | head`): stop quietly, as Unix tools do.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 1


def _error(message: str) -> None:
    print(f'{PROG}: error: {message}', file=sys.stderr)


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=PROG, description='Locate a camera from printed colour-dot cards.')
    sub = parser.add_subparsers(title='commands')

    make = sub.add_parser('make-pattern', help='print a card (SVG, PDF or PNG)',
                          description='Write a printable card at true millimetre scale.')
    make.add_argument('--floor', type=int)
    make.add_argument('--room', type=int)
    make.add_argument('--pattern', type=int, help='card number in the room')
    make.add_argument('--all', metavar='BUILDING', dest='building',
                      help='print every card of a building map into the directory -o')
    make.add_argument('--format', choices=('pdf', 'svg', 'png'), default='pdf',
                      help='file format with --all (default pdf)')
    make.add_argument('-o', '--output', required=True,
                      help='output file, its suffix (.svg, .pdf, .png) picking the format; '
                           'a directory with --all')
    make.add_argument('--paper', default='a3', choices=('a3', 'tabloid', 'a4', 'letter'),
                      help='sheet size; a4 and letter tile the card over several sheets '
                           '(default: a3)')
    make.add_argument('--dpi', type=float, default=300.0, help='PNG resolution (default 300)')
    make.add_argument('--pattern-config', help='pattern YAML (default: the shipped one)')
    make.set_defaults(handler=_make_pattern)

    detect = sub.add_parser('detect', help='find cards in images and locate the camera',
                            description='Detect cards and estimate the camera pose.')
    detect.add_argument('images', nargs='+', metavar='IMAGE')
    detect.add_argument('--camera', required=True, help='ROS camera-info YAML')
    detect.add_argument('--estimator', choices=ESTIMATORS, default='exact')
    detect.add_argument('--min-tilt', type=float, default=0.0, metavar='DEG',
                        help="reject views tilted less than this (the paper's rule: 25)")
    detect.add_argument('--json', action='store_true', help='one JSON object per image')
    detect.add_argument('--pattern-config', help='pattern YAML (default: the shipped one)')
    detect.set_defaults(handler=_detect)

    bench = sub.add_parser('bench', help='accuracy and speed against AprilTag and ArUco',
                           description='Render seeded scenes and compare with AprilTag '
                                       'and ArUco, printing tables.')
    bench.add_argument('--scenes', type=int, default=None,
                       help='scenes per distance bin and camera (default 40); with --stress, '
                            'frames per condition and camera (default 10)')
    bench.add_argument('--seed', type=int, default=1, help='seed of the scenes (default 1)')
    bench.add_argument('--quick', action='store_true',
                       help='a smoke test: one scene each; its figures are noise')
    bench.add_argument('--stress', action='store_true',
                       help='one row per hard condition (textures, dark noise, clutter, '
                            'coloured light, chromatic shift, mirrors, dim, blur, occlusion, '
                            'interlace, far) next to AprilTag on the same frames')
    bench.add_argument('--output-dir', default='out',
                       help='where the plots go (default out/)')
    bench.add_argument('--tracking', action='store_true',
                       help='the tracking loop in closed loop (sim + camera_driver + locator)')
    bench.add_argument('--node', action='store_true',
                       help='the locator node end to end over DDS: throughput and latency')
    bench.set_defaults(handler=_bench)

    bag = sub.add_parser('bag', help='record a simulated route, or play a bag into ROS',
                         description='rosbag2 bags (MCAP) without ros2cli.')
    bag_sub = bag.add_subparsers(title='bag commands')
    record = bag_sub.add_parser('record-sim', help="render the paper's route into a bag")
    record.add_argument('out', help='bag directory to create')
    record.add_argument('--stops', type=int, default=30, help='route stops (1-30)')
    record.add_argument('--rate', type=float, default=2.0, help='images per second')
    record.add_argument('--seed', type=int, default=7)
    record.set_defaults(handler=_bag_record)
    play = bag_sub.add_parser('play', help='publish a bag with its recorded timing')
    play.add_argument('bag', help='bag directory (or .mcap / .db3 file)')
    play.add_argument('--rate', type=float, default=1.0, help='speed factor (default 1)')
    play.set_defaults(handler=_bag_play)

    fake = sub.add_parser('fake-camera', help='an emulated EVI-D31 on a pseudo-terminal',
                          description='Start an emulated Sony EVI-D31 answering VISCA on a '
                                      'pseudo-terminal; print its port; run until Ctrl-C.')
    fake.add_argument('--link', help='also reach it through this path (a symlink)')
    fake.add_argument('--init-s', type=float, default=2.0,
                      help='power-up initialisation time (default 2 s)')
    fake.set_defaults(handler=_fake_camera)

    demo = sub.add_parser('demo', help="the simulated robot on the paper's route (make demo)",
                          description='Run sim, camera_driver and locator as processes over '
                                      "DDS along the paper's route; print the errors in the "
                                      'form of its Table 1 and plot the paths.')
    demo.add_argument('--estimator', choices=ESTIMATORS, default='exact')
    demo.add_argument('--stops', type=int, default=30, help='route stops (1-30)')
    demo.add_argument('--dwell', type=float, default=2.5, help='seconds at each stop')
    demo.add_argument('--zoom', action='store_true', help='let the driver zoom on the card')
    demo.add_argument('--core', action='store_true',
                      help="no ROS: the core alone on the paper's own camera (f = 25 mm)")
    demo.add_argument('--seed', type=int, default=7, help='seed of --core')
    demo.add_argument('--output-dir', default='out',
                      help='where the plot and the node logs go (default out/)')
    demo.set_defaults(handler=_demo)
    return parser


# make-pattern ----------------------------------------------------------------

def _make_pattern(args: argparse.Namespace) -> int:
    from .card.pattern import Ids
    from .card.printable import write_card
    cfg = load_pattern_config(args.pattern_config)
    if args.building:
        from .localization.building import load_building, write_building_cards
        building = load_building(args.building, cfg)
        written = write_building_cards(building, cfg, args.output, paper=args.paper,
                                       fmt=args.format, dpi=args.dpi)
        for path in written:
            print(path)
        print(f'{len(building.cards())} cards of {args.building}', file=sys.stderr)
        return 0
    missing = [f'--{name}' for name in ('floor', 'room', 'pattern')
               if getattr(args, name) is None]
    if missing:
        raise ConfigError(f'make-pattern needs {", ".join(missing)} (or --all BUILDING)')
    code = cfg.encode(args.floor, args.room, args.pattern)
    written = write_card(args.output, cfg, Ids(args.floor, args.room, args.pattern),
                         paper=args.paper, dpi=args.dpi)
    for path in written:
        print(path)
    print(f'floor {args.floor} room {args.room} card {args.pattern}: code {code}',
          file=sys.stderr)
    return 0


# detect ------------------------------------------------------------------------

def _detect(args: argparse.Namespace) -> int:
    from .vision.camera import load_camera
    cfg = load_pattern_config(args.pattern_config)
    camera = load_camera(args.camera)
    locator = CardLocator(cfg, estimator=args.estimator, min_tilt_deg=args.min_tilt)
    status = 0
    for name in args.images:
        image = _read_image(name)
        if isinstance(image, str):
            _error(image)
            status = 2
            continue
        if image.shape[1] != camera.width or image.shape[0] != camera.height:
            _error(f'{name}: image is {image.shape[1]}x{image.shape[0]} but the camera file '
                   f'is for {camera.width}x{camera.height}')
            status = 2
            continue
        start = time.perf_counter()
        located = locator.locate(image, camera)
        elapsed_ms = (time.perf_counter() - start) * 1000.0
        if args.json:
            print(json.dumps({'image': name, 'time_ms': round(elapsed_ms, 3),
                              'patterns': [card_json(c) for c in located]}))
        else:
            _print_text(name, elapsed_ms, located)
    return status


def _read_image(name: str):
    path = Path(name)
    if not path.is_file():
        return f'{name}: no such image file'
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        return f'{name}: cannot decode image (not a PNG/JPEG/... file, or corrupt)'
    if image.dtype == np.uint16:
        image = (image >> 8).astype(np.uint8)
    if image.dtype != np.uint8:
        return f'{name}: unsupported pixel type {image.dtype} (use 8 or 16 bits)'
    if image.ndim == 3 and image.shape[2] == 4:
        image = cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
    # A grey image is kept grey: the detector finds the geometry, not the code.
    return image


def _rounded(values, digits: int) -> List:
    return np.round(np.asarray(values, dtype=float), digits).tolist()


def card_json(card: LocatedCard) -> dict:
    """Return the JSON form of one located card (``detect --json``)."""
    det = card.detection
    points = [None if np.isnan(p[0]) else _rounded(p, 3) for p in det.points_px]
    out = {
        'code': str(det.code) if det.code is not None else None,
        'floor': det.ids.floor if det.ids else None,
        'room': det.ids.room if det.ids else None,
        'pattern': det.ids.pattern if det.ids else None,
        'points_px': points,
        'estimator': card.estimator,
        'T_camera_pattern': None,
        'camera_in_pattern_m': None,
        'covariance': None,
        'reprojection_rms_px': None,
        'ambiguity': None,
        'psi_deg': None, 'phi_deg': None, 'theta_deg': None, 'distance_m': None,
    }
    if card.T_camera_pattern is not None:
        out.update({
            'T_camera_pattern': _rounded(card.T_camera_pattern.matrix(), 7),
            'camera_in_pattern_m': _rounded(card.camera_in_pattern, 5),
            'reprojection_rms_px': round(float(card.reprojection_rms_px), 4),
            'psi_deg': round(card.psi_deg, 3), 'phi_deg': round(card.phi_deg, 3),
            'theta_deg': round(card.theta_deg, 3), 'distance_m': round(card.distance_m, 5),
        })
        if card.covariance is not None:
            out['covariance'] = [[float(f'{v:.4g}') for v in row] for row in card.covariance]
        if card.ambiguity is not None and math.isfinite(card.ambiguity):
            out['ambiguity'] = round(float(card.ambiguity), 3)
    else:
        out['problem'] = card.problem
    return out


def _print_text(name: str, elapsed_ms: float, located: List[LocatedCard]) -> None:
    print(f'{name}: {len(located)} card(s) in {elapsed_ms:.1f} ms')
    for card in located:
        det = card.detection
        ids = (f'floor {det.ids.floor} room {det.ids.room} card {det.ids.pattern}'
               if det.ids else 'no code (grey image)')
        print(f'  {det.code}  {ids}  ({det.n_points} dots)')
        if card.T_camera_pattern is None:
            print(f'    no pose: {card.problem}')
            continue
        x, y, z = card.camera_in_pattern
        print(f'    camera in card frame: x {x:+.3f} y {y:+.3f} z {z:+.3f} m   '
              f'D {card.distance_m:.3f} m  phi {card.phi_deg:.2f}  theta {card.theta_deg:.2f}  '
              f'psi {card.psi_deg:.2f} deg')
        extra = f'    reprojection {card.reprojection_rms_px:.3f} px'
        if card.covariance is not None:
            sd = np.sqrt(np.diag(card.covariance)[:3]) * 1000.0
            extra += f'   position sd {sd[0]:.1f} {sd[1]:.1f} {sd[2]:.1f} mm'
        if card.ambiguity is not None and math.isfinite(card.ambiguity):
            extra += f'   ambiguity {card.ambiguity:.2f}'
        print(extra)


# bench and demo ---------------------------------------------------------------------

def _bench(args: argparse.Namespace) -> int:
    kinds = [name for name in ('stress', 'node', 'tracking') if getattr(args, name)]
    if len(kinds) > 1:
        raise ConfigError(f'bench: choose one of --stress, --node, --tracking (got '
                          f'{" and ".join("--" + k for k in kinds)})')
    if args.tracking:
        from .evaluation.bench_tracking import run_tracking_bench
        return run_tracking_bench()
    if args.node:
        from .evaluation.bench_node import run_node_bench
        return run_node_bench(frames_per_size=10 if args.quick else 40)
    if args.scenes is not None and not 1 <= args.scenes <= 1000:
        raise ConfigError(f'bench: --scenes must be 1..1000, got {args.scenes}')
    if args.stress:
        from .evaluation.stress import run_stress
        return run_stress(per_camera=args.scenes or 10, seed=args.seed, quick=args.quick,
                          output_dir=args.output_dir)
    from .evaluation.bench import run_bench
    return run_bench(scenes_per_bin=args.scenes or 40, seed=args.seed, quick=args.quick,
                     output_dir=args.output_dir)


def _bag_record(args: argparse.Namespace) -> int:
    from .nodes.bags import record_sim_main
    return record_sim_main(args.out, n_stops=args.stops, rate_hz=args.rate, seed=args.seed)


def _bag_play(args: argparse.Namespace) -> int:
    from .nodes.bags import play_main
    return play_main(args.bag, rate=args.rate)


def _fake_camera(args: argparse.Namespace) -> int:
    from .visca.emulator import run_fake_camera
    return run_fake_camera(args.link, args.init_s)


def _demo(args: argparse.Namespace) -> int:
    if args.core:
        from .evaluation.demo import run_demo
        return run_demo(estimator=args.estimator, seed=args.seed, output_dir=args.output_dir)
    if not 1 <= args.stops <= 30:
        raise ConfigError(f'demo: --stops must be 1..30, got {args.stops}')
    from .evaluation.demo_system import run_system_demo
    return run_system_demo(estimator=args.estimator, output_dir=args.output_dir,
                           n_stops=args.stops, dwell_s=args.dwell, zoom_control=args.zoom)


if __name__ == '__main__':
    sys.exit(main())
