"""
The ``pattern-locator`` command line: make-pattern, detect, inks, bench, demo.

Errors a user can cause end as one readable line on stderr and exit status 2.
"""

import argparse
import json
import math
import os
import sys
import time
from typing import List, Optional, Sequence

import numpy as np

from . import __version__
from .card.pattern import load_pattern_config
from .errors import ConfigError, ImageError, PatternLocatorError
from .localization.gates import FLIP_VALLEY_BARRIER, MAX_FLIP_PROBABILITY
from .vision.image_file import DEFAULT_MAX_PIXELS
from .vision.locate import CardLocator, ESTIMATORS, LocatedCard

PROG = 'pattern-locator'
DEMO_ROUTES = ('loop', 'tour', 'short', 'paper-stops')


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


class _Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line, like every other error."""

    def error(self, message: str) -> None:  # noqa: D102 (argparse's own contract)
        self.exit(2, f'{self.prog}: error: {message} (see {self.prog} --help)\n')


def _number_in(low: float, high: float, kind=float, what: str = 'value'):
    """Return an argparse type: a finite number of ``kind`` within [low, high]."""
    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'{what} must be a number, got {text!r}') from None
        if not (math.isfinite(value) and low <= value <= high):
            raise argparse.ArgumentTypeError(f'{what} must be in {low:g}..{high:g}, got {text}')
        return value
    return parse


def _parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog=PROG, description='Locate a camera from printed colour-dot cards.')
    parser.add_argument('--version', action='version', version=f'{PROG} {__version__}',
                        help='print the version and exit')
    sub = parser.add_subparsers(title='commands')

    make = sub.add_parser('make-pattern', help='print a card (SVG, PDF or PNG)',
                          description='Write a printable card at true millimetre scale: one '
                                      'card by its ids, or every card of a building map.')
    make.add_argument('--floor', type=int, help='floor id of the card (0-11 by default)')
    make.add_argument('--room', type=int, help='room id on its floor (1-81 by default)')
    make.add_argument('--pattern', type=int, help='card number in the room (1-9 by default)')
    make.add_argument('--all', metavar='BUILDING', dest='building',
                      help='print every card of a building map into the directory -o '
                           '(instead of --floor/--room/--pattern)')
    make.add_argument('--format', choices=('pdf', 'svg', 'png'),
                      help='file format with --all (default pdf); a single card takes it '
                           'from the suffix of -o')
    make.add_argument('-o', '--output', required=True,
                      help='output file, its suffix (.svg, .pdf, .png) picking the format; '
                           'a directory with --all')
    make.add_argument('--paper', default='a3', choices=('a3', 'tabloid', 'a4', 'letter'),
                      help='sheet size; a4 and letter tile the card over several sheets '
                           '(default: a3)')
    make.add_argument('--dpi', type=_number_in(72, 2400, what='--dpi'), default=300.0,
                      help='PNG resolution, 72-2400 (default 300)')
    make.add_argument('--pattern-config', help='pattern YAML (default: the shipped one)')
    make.set_defaults(handler=_make_pattern)

    detect = sub.add_parser('detect', help='find cards in images and locate the camera',
                            description='Detect cards and estimate the camera pose.')
    detect.add_argument('images', nargs='+', metavar='IMAGE',
                        help='image files (PNG, JPEG, ...; colour for the code, grey gives '
                             'geometry only)')
    detect.add_argument('--camera', required=True,
                        help='ROS camera-info YAML of the camera that took the images')
    detect.add_argument('--estimator', choices=ESTIMATORS, default='exact',
                        help="pose estimator: exact (default) or the paper's")
    detect.add_argument('--min-tilt', type=_number_in(0.0, 89.0, what='--min-tilt'),
                        default=0.0, metavar='DEG',
                        help="reject views tilted less than this (the paper's rule: 25)")
    detect.add_argument('--max-pixels', type=_number_in(1, 2 ** 31, int, '--max-pixels'),
                        default=DEFAULT_MAX_PIXELS, metavar='N',
                        help=f'refuse images with more pixels than this, from their header '
                             f'and before decoding (default {DEFAULT_MAX_PIXELS})')
    detect.add_argument('--json', action='store_true', help='one JSON object per image')
    detect.add_argument('--pattern-config', help='pattern YAML (default: the shipped one)')
    detect.set_defaults(handler=_detect)

    inks = sub.add_parser(
        'inks', help="measure a printed card's inks for the pattern configuration",
        description='Measure the inks of one printed card from photos or scans of it '
                    '(face-on, evenly lit, the whole card in view), compare them with those '
                    'of the pattern configuration, and print the `inks:` block that makes the '
                    "detector read that printer's cards. Exit status 0: the inks match; 1: "
                    'they differ (put the block in the pattern configuration); 2: an error.')
    inks.add_argument('images', nargs='+', metavar='IMAGE',
                      help='colour photos or scans of the same printed card')
    inks.add_argument('--floor', type=int, required=True, help="the card's floor id")
    inks.add_argument('--room', type=int, required=True, help="the card's room id")
    inks.add_argument('--pattern', type=int, required=True, help="the card's number in its room")
    inks.add_argument('--camera', help='ROS camera-info YAML of the camera (optional: undoes '
                                       'its lens; a scan needs none)')
    inks.add_argument('--max-pixels', type=_number_in(1, 2 ** 31, int, '--max-pixels'),
                      default=DEFAULT_MAX_PIXELS, metavar='N',
                      help=f'refuse images with more pixels than this (default '
                           f'{DEFAULT_MAX_PIXELS})')
    inks.add_argument('--pattern-config', help='pattern YAML (default: the shipped one)')
    inks.set_defaults(handler=_inks)

    bench = sub.add_parser('bench', help='accuracy and speed against AprilTag and ArUco',
                           description='Render seeded scenes and compare with AprilTag '
                                       'and ArUco, printing tables.')
    bench.add_argument('--scenes', type=int, default=None,
                       help='scenes per distance bin and camera (default 40); with --stress, '
                            'frames per condition and camera (default 10; --inks: 2)')
    bench.add_argument('--seed', type=int, default=1, help='seed of the scenes (default 1)')
    bench.add_argument('--quick', action='store_true',
                       help='a smoke test: one scene each; its figures are noise')
    bench.add_argument('--stress', action='store_true',
                       help='one row per hard condition (textures, dark noise, clutter, '
                            'coloured light, chromatic shift, mirrors, dim, blur, occlusion, '
                            'interlace, far) next to AprilTag on the same frames')
    bench.add_argument('--inks', action='store_true',
                       help="cards printed in several printers' inks, read by the configured "
                            'colours and by the inks `pattern-locator inks` measured')
    bench.add_argument('--output-dir', default='out',
                       help='where the plots, logs and summaries go (default out/)')
    bench.add_argument('--tracking', action='store_true',
                       help='the tracking loop in closed loop (sim + camera_driver + locator)')
    bench.add_argument('--node', action='store_true',
                       help='the locator node end to end over DDS: throughput and latency')
    bench.add_argument('--fuzz', action='store_true',
                       help='malformed messages into a locator process: poses for bad input, '
                            'non-finite values, tracebacks, memory, log volume')
    bench.add_argument('--messages', type=int, default=32_000,
                       help='messages of the --fuzz run (default 32000; --quick: 3000)')
    bench.add_argument('--drive-core', nargs=argparse.REMAINDER, metavar='OPTION',
                       help='the ROS-free cores of issue 12 on the simulated floor (covariance '
                            'coverage, odometry bridge, gaze); the options after it are its '
                            'own (--drive-core --help)')
    bench.add_argument('--survey', action='store_true',
                       help='the survey: map accuracy, ellipses and timings on rendered and '
                            'simulated walks, with and without odometry')
    bench.add_argument('--drive', action='store_true',
                       help='the drive through the floor (sim + camera_driver + locator) over '
                            'several seeds: coverage, errors, handovers, head, VISCA')
    bench.add_argument('--runs', type=_number_in(1, 100, int, '--runs'), default=3,
                       help='--drive: seeds run, from --seed (default 3; --quick: 1)')
    bench.add_argument('--route', choices=('loop', 'tour', 'short'), default='loop',
                       help='--drive: the floor route (default loop; --quick: short)')
    bench.add_argument('--max-speed', type=_number_in(0.05, 3.0, what='--max-speed'),
                       default=0.5, help='--drive: cap on the speed (m/s, default 0.5)')
    bench.add_argument('--compare-feed-forward', action='store_true',
                       help='--drive: every seed with and without the odometry feed-forward')
    bench.add_argument('--load', type=_number_in(0, 64, int, '--load'), default=0,
                       help='--drive: add this many busy processes (a loaded machine)')
    bench.add_argument('--building-map', metavar='PATH',
                       help="--drive: the locator's map instead of config/floor_building.yaml "
                            "(a surveyed one, with that map's room frames)")
    bench.add_argument('--as-hung-seed', type=_number_in(0, 2 ** 31 - 1, int, '--as-hung-seed'),
                       help='--drive: the sim hangs the cards off their mapped poses (up to 5 '
                            'cm, 3 deg) with this seed')
    bench.set_defaults(handler=_bench)

    survey = sub.add_parser(
        'survey', help="map a building's cards from walks recorded in bags",
        description='Detect the cards in every frame of rosbag2 bags (MCAP or sqlite3) and '
                    'optimise card and camera poses (GTSAM) into a building map the locator '
                    'loads. With --check MAP: how well an existing map agrees with a walk.')
    survey.add_argument('bags', nargs='+', metavar='BAG', help='rosbag2 bag directories')
    survey.add_argument('-o', '--output', help='the building map to write (YAML)')
    survey.add_argument('--check', metavar='MAP',
                        help='compare this building map with the walk instead, card by card '
                             '(exit 1 when a card moved)')
    survey.add_argument('--anchors', help='a building map of the cards whose poses are known')
    survey.add_argument('--cards-json', help='also write every card as JSON here')
    survey.add_argument('--report', metavar='DIR', help='write plots and notes into DIR')
    survey.add_argument('--image-topic', help='default: /camera/image_raw, or the only image '
                                              'topic')
    survey.add_argument('--camera-info-topic', help='default: /camera/camera_info, or the '
                                                    'only one')
    survey.add_argument('--odom-topic', help='default: /odom, or the only Odometry topic')
    survey.add_argument('--joint-states-topic', help="the pan/tilt head's joint states "
                                                     '(default: /camera/joint_states)')
    survey.add_argument('--jobs', type=int, help='detection processes (default: all cores)')
    survey.add_argument('--camera-mount', type=float, nargs=6,
                        metavar=('X', 'Y', 'Z', 'ROLL', 'PITCH', 'YAW'),
                        help="the camera optical frame on the odometry's base: metres and "
                             'degrees (R = Rz(yaw) Ry(pitch) Rx(roll)); used when the bag has '
                             'no /tf_static chain')
    survey.add_argument('--no-odometry', action='store_true', help='ignore the odometry')
    survey.add_argument('--no-vertical-prior', action='store_true',
                        help='do not assume the cards hang vertical')
    survey.add_argument('--refine-dots', action='store_true',
                        help='end with a bundle adjustment on the dots of the sightings (slower; '
                             'see bench --survey for what it gains)')
    survey.add_argument('--card-height', type=float, metavar='M',
                        help="the cards' nominal height above the floor (needs odometry)")
    survey.set_defaults(handler=_survey)

    bag = sub.add_parser('bag', help='record a simulated route, or play a bag into ROS',
                         description='rosbag2 bags (MCAP) without ros2cli.')
    bag_sub = bag.add_subparsers(title='bag commands')
    record = bag_sub.add_parser('record-sim', help="render the paper's route into a bag")
    record.add_argument('out', help='bag directory to create')
    record.add_argument('--stops', type=int, default=30, help='route stops (1-30)')
    record.add_argument('--rate', type=float, help='images per second (default 2; 10 with '
                                                   '--survey)')
    record.add_argument('--seed', type=int, default=7, help='seed of the noise (default 7)')
    record.add_argument('--survey', action='store_true',
                        help='a survey walk through a room and a corridor instead: cards as '
                             'hung, odometry with drift, truth.yaml beside the bag')
    record.add_argument('--frames', type=int, help='with --survey: stop after this many images')
    record.set_defaults(handler=_bag_record)
    play = bag_sub.add_parser('play', help='publish a bag with its recorded timing')
    play.add_argument('bag', help='bag directory (or .mcap / .db3 file)')
    play.add_argument('--rate', type=float, default=1.0, help='speed factor (default 1)')
    play.add_argument('--topics', nargs='+', metavar='TOPIC', help='play only these topics')
    play.add_argument('--remap', nargs='+', metavar='FROM:=TO', default=[],
                      help='publish a bag topic under another name')
    play.add_argument('--wait-for-subscribers', nargs='*', metavar='TOPIC',
                      help='publish nothing before these topics (none named: every played '
                           'topic) have a subscriber')
    play.add_argument('--wait-timeout', type=float, default=30.0, metavar='S',
                      help='give up waiting for subscribers after this (default 30 s)')
    play.add_argument('--clock', nargs='?', type=float, const=40.0, default=0.0, metavar='HZ',
                      help='publish the bag time on /clock (default 40 Hz)')
    play.add_argument('--loop', action='store_true', help='play again and again until Ctrl-C')
    play.add_argument('--start-offset', type=float, default=0.0, metavar='S',
                      help="skip the bag's first S seconds")
    play.add_argument('--delay', type=float, default=0.0, metavar='S',
                      help='wait S seconds before playing (each loop)')
    play.set_defaults(handler=_bag_play)

    fake = sub.add_parser('fake-camera', help='an emulated EVI-D31 on a pseudo-terminal',
                          description='Start an emulated Sony EVI-D31 answering VISCA on a '
                                      'pseudo-terminal; print its port; run until Ctrl-C.')
    fake.add_argument('--link', help='also reach it through this path (a symlink)')
    fake.add_argument('--init-s', type=float, default=2.0,
                      help='power-up initialisation time (default 2 s)')
    fake.add_argument('--faults', default='', metavar='SPEC',
                      help='play a broken camera: name=value,... e.g. '
                           "'bad_position_probability=0.3,lose_completions=1' "
                           '(an unknown name lists the known ones)')
    fake.set_defaults(handler=_fake_camera)

    layout = sub.add_parser(
        'check-layout', help='where a route or a room has no card in view (before printing)',
        description='From the building map alone (the gaze planner: range, view angle, the '
                    "head's travel, line of sight within a room's space), print where a route "
                    'has no card predicted visible, and per room the share of places and '
                    'headings with one. Exit 1 when a route is blind longer than '
                    '--max-blind-m.')
    layout.add_argument('map', help='the building map (YAML)')
    layout.add_argument('--route', action='append', default=[], metavar='FILE[:NAME]',
                        help='a route: a YAML list of [x, y] (building frame), or '
                             "{floor: N, waypoints: [...]}, or a sim floor file's route "
                             '(config/sim_floor.yaml:loop); repeatable')
    layout.add_argument('--floor', type=int, help="the floor (default: the route file's, or "
                                                  "the map's only floor)")
    layout.add_argument('--params', default=None, metavar='FILE',
                        help="the locator's params file for the head's geometry and gaze.* "
                             '(default: the shipped config/locator.yaml)')
    layout.add_argument('--rooms', action='store_true',
                        help='also sample every room on a grid (the default without --route)')
    layout.add_argument('--step', type=_number_in(0.01, 5.0, what='--step'), default=0.1,
                        help='route sampling step, m (default 0.1)')
    layout.add_argument('--max-blind-m', type=_number_in(0.0, 1000.0, what='--max-blind-m'),
                        default=1.0, help='longest blind stretch a route may have (default 1 m)')
    layout.set_defaults(handler=_check_layout)

    demo = sub.add_parser('demo', help='the simulated robot drives through the floor '
                          '(make demo)',
                          description='Run sim, camera_driver and locator as processes over '
                                      'DDS: the robot drives a route through the floor '
                                      '(default loop); print a per-room table, plot the '
                                      'floor, write out/demo_summary.json. --route '
                                      "paper-stops: the paper's route in one room, its "
                                      'Table 1.')
    demo.add_argument('--route', choices=DEMO_ROUTES, default='loop',
                      help='floor route (loop: 93 m, about 4 min; tour: 120 m, about 6.5 '
                           "min; short: 12 m, 40 s) or paper-stops (the paper's room)")
    demo.add_argument('--max-speed', type=_number_in(0.05, 3.0, what='--max-speed'),
                      default=0.5, help='floor routes: cap on the speed (m/s, default 0.5)')
    demo.add_argument('--no-feed-forward', action='store_true',
                      help="floor routes: the driver ignores the base's odometry")
    demo.add_argument('--interlace', action='store_true',
                      help='floor routes: interlaced frames (two fields)')
    demo.add_argument('--shutter', type=_number_in(0.0, 0.04, what='--shutter'),
                      default=0.004, help="floor routes: the camera's shutter the driver "
                      "sets, s (default 0.004 = 1/250; 0: the camera's auto exposure, 1/50)")
    demo.add_argument('--real-time-factor', default=1.0,
                      type=_number_in(0.05, 1.0, what='--real-time-factor'),
                      help='floor routes: run the world this much slower than the wall, '
                      "every node on the sim's /clock (a machine too slow to render 10 "
                      'frames a second; default 1)')
    demo.add_argument('--estimator', choices=ESTIMATORS, default='exact',
                      help="the locator's pose estimator (default exact)")
    demo.add_argument('--stops', type=int, default=30, help='paper-stops: route stops (1-30)')
    demo.add_argument('--dwell', type=float, default=2.5,
                      help='paper-stops: seconds at each stop')
    demo.add_argument('--zoom', action='store_true',
                      help='paper-stops: let the driver zoom on the card (floor routes zoom '
                           'unless --no-zoom)')
    demo.add_argument('--no-zoom', action='store_true',
                      help='floor routes: keep the camera at its widest (far cards then give '
                           'fixes too uncertain for the demo)')
    demo.add_argument('--core', action='store_true',
                      help="no ROS: the core alone on the paper's own camera (f = 25 mm)")
    demo.add_argument('--seed', type=int, default=7,
                      help='seed of the images and the odometry (and of --core)')
    demo.add_argument('--output-dir', default='out',
                      help='where the plot and the node logs go (default out/)')
    demo.set_defaults(handler=_demo)
    return parser


# make-pattern ----------------------------------------------------------------

def _make_pattern(args: argparse.Namespace) -> int:
    from .card.pattern import Ids
    from .card.printable import write_card
    given = [f'--{name}' for name in ('floor', 'room', 'pattern')
             if getattr(args, name) is not None]
    if args.building and given:
        raise ConfigError(f'make-pattern: --all prints every card of the map; it takes no '
                          f'{", ".join(given)}')
    if args.format and not args.building:
        raise ConfigError('make-pattern: --format is for --all; a single card takes its '
                          'format from the suffix of -o')
    cfg = load_pattern_config(args.pattern_config)
    if args.building:
        from tqdm import tqdm
        from .localization.building import load_building, write_building_cards
        building = load_building(args.building, cfg)
        written = write_building_cards(
            building, cfg, args.output, paper=args.paper, fmt=args.format or 'pdf',
            dpi=args.dpi, progress=lambda cards: tqdm(cards, desc='cards', unit='card',
                                                      disable=None, leave=False))
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
    from .vision.image_file import read_image
    cfg = load_pattern_config(args.pattern_config)
    camera = load_camera(args.camera)
    locator = CardLocator(cfg, estimator=args.estimator, min_tilt_deg=args.min_tilt)
    status = 0
    for name in args.images:
        try:
            image = read_image(name, max_pixels=args.max_pixels)
        except ImageError as exc:
            _error(str(exc))
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


# inks --------------------------------------------------------------------------

def _inks(args: argparse.Namespace) -> int:
    from .card.pattern import Ids
    from .vision.camera import load_camera
    from .vision.image_file import read_image
    from .vision.ink_check import MIN_MATCH_MARGIN, measure_inks
    cfg = load_pattern_config(args.pattern_config)
    ids = Ids(args.floor, args.room, args.pattern)
    cfg.encode(*ids.as_tuple())                 # ids out of range: one line, before reading
    camera = load_camera(args.camera) if args.camera else None
    images = [(name, read_image(name, max_pixels=args.max_pixels)) for name in args.images]
    report = measure_inks(images, cfg, ids, camera)
    print(f'card floor {ids.floor} room {ids.room} card {ids.pattern} (code {report.code}), '
          f'{report.images} image(s), ring dots {2 * report.dot_radius_px:.0f} px across')
    print(report.table())
    differ = [ink.letter for ink in report.inks if not ink.matches]
    if differ:
        print(f'The detector would not read ink {", ".join(differ)} as configured (it reads '
              f'each dot by the nearest configured ink; a margin below {MIN_MATCH_MARGIN} is '
              f'unsure). Put this in the pattern configuration, for every node and tool that '
              f'reads these cards:')
    else:
        print('The inks match the configuration. To read them by the measured inks anyway, '
              'put this in the pattern configuration:')
    print(report.yaml_block())
    return 1 if differ else 0


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
        'other_probability': None,
        'other_camera_in_pattern_m': None,
        'flip_barrier': None,
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
        # Either estimator (the paper's flip as the exact one sees the dots).
        out['other_probability'] = float(f'{card.other_probability:.3g}')
        if card.other_probability > 0.0 and card.alternative is not None:
            out['other_camera_in_pattern_m'] = _rounded(card.alternative.inverse().t, 5)
        if math.isfinite(card.flip_barrier):
            out['flip_barrier'] = float(f'{card.flip_barrier:.3g}')
    else:
        out['problem'] = card.problem
    return out


def _print_text(name: str, elapsed_ms: float, located: List[LocatedCard]) -> None:
    print(f'{name}: {len(located)} card(s) in {elapsed_ms:.1f} ms')
    for card in located:
        det = card.detection
        if det.code is None:
            heading = 'a card, code not read (grey image: geometry only)'
        elif det.ids is None:
            heading = f'{det.code}  (not a code of this layout)'
        else:
            heading = (f'{det.code}  floor {det.ids.floor} room {det.ids.room} '
                       f'card {det.ids.pattern}')
        print(f'  {heading}  ({det.n_points} dots)')
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
        if card.other_probability > MAX_FLIP_PROBABILITY and card.alternative is not None:
            x, y, z = card.alternative.inverse().t
            print(f'    other planar pose {100.0 * card.other_probability:.2g} % likely: camera '
                  f'at x {x:+.3f} y {y:+.3f} z {z:+.3f} m (the image alone does not decide; on '
                  "a robot, up, the camera's height or the last fix may)")
        # As the localizer's gate: a barrier that is not known to be high enough
        # (NaN included) is a shallow valley.
        if card.alternative is not None and not card.flip_barrier >= FLIP_VALLEY_BARRIER:
            print(f'    in one shallow valley of the fit with its other planar pose (barrier '
                  f'{card.flip_barrier:.2g}): the turn is less sure than the sd says')


# bench and demo ---------------------------------------------------------------------

def _bench(args: argparse.Namespace) -> int:
    kinds = [name for name in ('stress', 'inks', 'node', 'tracking', 'fuzz', 'survey', 'drive')
             if getattr(args, name)]
    if args.drive_core is not None:
        kinds.append('drive_core')
    if len(kinds) > 1:
        raise ConfigError('bench: choose one of --stress, --inks, --node, --tracking, --fuzz, '
                          '--survey, --drive, --drive-core (got '
                          f'{" and ".join("--" + k.replace("_", "-") for k in kinds)})')
    if args.drive_core is not None:
        from .evaluation.drive_core import main as drive_core_main
        return drive_core_main(args.drive_core)
    if args.drive:
        from .evaluation.bench_drive import run_drive_bench
        return run_drive_bench(runs=1 if args.quick else args.runs, seed=args.seed,
                               route='short' if args.quick else args.route,
                               max_speed_m_s=args.max_speed,
                               compare_feed_forward=args.compare_feed_forward, load=args.load,
                               output_dir=args.output_dir, building_map=args.building_map,
                               as_hung_seed=args.as_hung_seed)
    if args.tracking:
        from .evaluation.bench_tracking import run_tracking_bench
        return run_tracking_bench()
    if args.fuzz:
        from .evaluation.fuzz import run_fuzz_bench
        if args.messages < 100:
            raise ConfigError(f'bench --fuzz: --messages must be at least 100, got '
                              f'{args.messages}')
        return run_fuzz_bench(messages=3000 if args.quick else args.messages, seed=args.seed)
    if args.node:
        from .evaluation.bench_node import run_node_bench
        return run_node_bench(frames_per_size=10 if args.quick else 40)
    if args.survey:
        from .evaluation.bench_survey import run_survey_bench
        return run_survey_bench(quick=args.quick, seed=args.seed)
    if args.scenes is not None and not 1 <= args.scenes <= 1000:
        raise ConfigError(f'bench: --scenes must be 1..1000, got {args.scenes}')
    if args.inks:
        from .evaluation.bench_inks import run_inks_bench
        return run_inks_bench(per_camera=args.scenes or 2, seed=args.seed, quick=args.quick)
    if args.stress:
        from .evaluation.stress import run_stress
        return run_stress(per_camera=args.scenes or 10, seed=args.seed, quick=args.quick,
                          output_dir=args.output_dir)
    from .evaluation.bench import run_bench
    return run_bench(scenes_per_bin=args.scenes or 40, seed=args.seed, quick=args.quick,
                     output_dir=args.output_dir)


def _bag_record(args: argparse.Namespace) -> int:
    if args.survey:
        from .survey.record import record_survey_main
        return record_survey_main(args.out, frames=args.frames,
                                  rate_hz=10.0 if args.rate is None else args.rate,
                                  seed=args.seed)
    from .nodes.bags import record_sim_main
    return record_sim_main(args.out, n_stops=args.stops,
                           rate_hz=2.0 if args.rate is None else args.rate, seed=args.seed)


def _survey(args: argparse.Namespace) -> int:
    from .survey.bagio import SurveyTopics
    from .survey.run import options_from, parse_mount
    topics = SurveyTopics(args.image_topic, args.camera_info_topic, args.odom_topic,
                          args.joint_states_topic)
    options = options_from(args.no_odometry, args.no_vertical_prior, args.card_height)
    mount = parse_mount(args.camera_mount)
    if args.check:
        from .survey.check import check_main
        return check_main(args.check, args.bags, topics=topics, jobs=args.jobs,
                          camera_mount=mount, options=options)
    if not args.output:
        raise ConfigError('survey needs -o building.yaml (or --check MAP)')
    from .survey.run import survey_main
    return survey_main(args.bags, args.output, args.anchors, args.cards_json, args.report,
                       topics, args.jobs, mount, options, refine_dots=args.refine_dots)


def _bag_play(args: argparse.Namespace) -> int:
    from .nodes.bags import parse_remaps, play_main
    return play_main(args.bag, rate=args.rate, topics=args.topics,
                     remap=parse_remaps(args.remap),
                     wait_for_subscribers=args.wait_for_subscribers,
                     discovery_timeout_s=args.wait_timeout, clock_hz=args.clock,
                     loops=0 if args.loop else 1, start_offset_s=args.start_offset,
                     delay_s=args.delay)


def _check_layout(args: argparse.Namespace) -> int:
    from .localization.layout_check import check_layout_main
    from .resources import config_path
    return check_layout_main(args.map, args.route, args.params or str(config_path('locator.yaml')),
                             args.floor, args.step, args.max_blind_m, args.rooms)


def _fake_camera(args: argparse.Namespace) -> int:
    from .visca.emulator import run_fake_camera
    return run_fake_camera(args.link, args.init_s, args.faults)


def _demo(args: argparse.Namespace) -> int:
    if args.core:
        from .evaluation.demo import run_demo
        return run_demo(estimator=args.estimator, seed=args.seed, output_dir=args.output_dir)
    if args.route != 'paper-stops':
        from .evaluation.demo_system import run_floor_demo
        return run_floor_demo(route=args.route, max_speed_m_s=args.max_speed,
                              output_dir=args.output_dir, seed=args.seed,
                              estimator=args.estimator, zoom_control=not args.no_zoom,
                              feed_forward=not args.no_feed_forward,
                              interlace=args.interlace, shutter_s=args.shutter,
                              real_time_factor=args.real_time_factor)
    if not 1 <= args.stops <= 30:
        raise ConfigError(f'demo: --stops must be 1..30, got {args.stops}')
    from .evaluation.demo_system import run_system_demo
    return run_system_demo(estimator=args.estimator, output_dir=args.output_dir,
                           n_stops=args.stops, dwell_s=args.dwell, zoom_control=args.zoom)


if __name__ == '__main__':
    sys.exit(main())
