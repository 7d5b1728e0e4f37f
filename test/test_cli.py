"""The pattern-locator command line: detect and make-pattern, in-process and once as a process."""

import argparse
import json
import math
from pathlib import Path
import re
import subprocess
import sys

import cv2
import numpy as np
from pattern_locator.card.pattern import Ids, pattern_config_from_dict, PatternConfig
from pattern_locator.cli import main
from pattern_locator.sim.render import (card_pose_facing, CardPlacement, DotCardTexture, Occluder,
                                        printed_card_texture, render_scene, RenderOptions)
from pattern_locator.vision.camera import CameraModel, save_camera
from pattern_locator.vision.pose_exact import paper_angles
import pytest
import yaml

ROOT = Path(__file__).resolve().parent.parent
CFG = PatternConfig()
CAMERA = CameraModel.from_focal(640, 480, 1000.0)
CODE = CFG.encode(2, 17, 3)
OTHER = CFG.encode(9, 64, 8)
PREFIX = 'pattern-locator: error:'


def strict_json(line):
    """Parse one line of JSON, refusing NaN and Infinity (not JSON)."""
    def refuse(name):
        raise ValueError(f'{name} in JSON output')
    return json.loads(line, parse_constant=refuse)


def json_lines(text):
    return [strict_json(line) for line in text.splitlines() if line.strip()]


def error_lines(text):
    lines = [line for line in text.splitlines() if line.strip()]
    assert all(line.startswith(PREFIX) for line in lines), lines
    assert not any('Traceback' in line for line in lines)
    return lines


@pytest.fixture(scope='module')
def scene(tmp_path_factory):
    """Images on disk: one card, two cards, a hidden dot, no card; the camera file."""
    root = tmp_path_factory.mktemp('cli')
    T = card_pose_facing(2.0, 40.0, 30.0, 0.0, (20.0, 10.0), CAMERA)
    T_far = card_pose_facing(3.5, 30.0, 250.0, -10.0, (170.0, 60.0), CAMERA)
    T_near = card_pose_facing(1.6, 35.0, 60.0, 5.0, (-160.0, -40.0), CAMERA)
    T_flat = card_pose_facing(2.0, 10.0, 30.0, 0.0, (20.0, 10.0), CAMERA)
    # Far and nearly face on: the two planar poses fit almost equally.
    T_faceon = card_pose_facing(5.7, 5.0, 90.0, 0.0, (0.0, 0.0), CAMERA)
    options = {'noise_sigma': 1.5, 'defocus_sigma_px': 0.5, 'seed': 1}
    # Outer point 7 behind a small pale object.
    patch = np.array([[-0.135, -0.02], [-0.095, -0.02], [-0.095, 0.02], [-0.135, 0.02]])
    images = {
        'one.png': ([(T, CODE)], RenderOptions(**options)),
        'two.png': ([(T_far, OTHER), (T_near, CODE)], RenderOptions(**options)),
        'hidden.png': ([(T, CODE)], RenderOptions(
            occluders=(Occluder(0, patch, (0.8, 0.8, 0.75)),), **options)),
        'none.png': ([], RenderOptions(background='clutter', **options)),
        'flat.png': ([(T_flat, CODE)], RenderOptions(**options)),
        'faceon.png': ([(T_faceon, CODE)], RenderOptions(**options)),
    }
    paths = {}
    for name, (cards, opts) in images.items():
        placements = [CardPlacement(pose, DotCardTexture(CFG, code)) for pose, code in cards]
        paths[name] = str(root / name)
        assert cv2.imwrite(paths[name], render_scene(CAMERA, placements, opts).image)
    paths['camera'] = str(root / 'camera.yaml')
    save_camera(CAMERA, paths['camera'])
    return root, paths, {'one': T, 'near': T_near, 'far': T_far, 'flat': T_flat,
                         'faceon': T_faceon}


def detect(capsys, *args):
    status = main(['detect', *args])
    out, err = capsys.readouterr()
    return status, out, err


# detect --json ----------------------------------------------------------------------------

def test_detect_json(scene, capsys):
    _, paths, poses = scene
    status, out, err = detect(capsys, paths['one.png'], '--camera', paths['camera'], '--json')
    assert status == 0 and err == ''
    (record,) = json_lines(out)
    assert record['image'] == paths['one.png']
    assert isinstance(record['time_ms'], float) and record['time_ms'] >= 0.0
    (card,) = record['patterns']
    assert card['code'] == str(CODE)
    assert (card['floor'], card['room'], card['pattern']) == (2, 17, 3)
    assert card['estimator'] == 'exact'
    assert len(card['points_px']) == CFG.n_dots
    assert all(len(p) == 2 for p in card['points_px'])
    T = poses['one']
    truth = T.inverse().t
    M = np.array(card['T_camera_pattern'])
    assert M.shape == (4, 4) and np.allclose(M[3], [0.0, 0.0, 0.0, 1.0])
    assert np.allclose(M[:3, :3].T @ M[:3, :3], np.eye(3), atol=1e-6)
    # The camera position is the inverse of the reported transform, and near
    # the truth (0.5 % of the distance, see test_locate).
    position = np.array(card['camera_in_pattern_m'])
    assert np.allclose(position, -M[:3, :3].T @ M[:3, 3], atol=1e-4)
    assert np.linalg.norm(position - truth) < 0.005 * 2.0
    S = np.array(card['covariance'])
    assert S.shape == (6, 6) and np.allclose(S, S.T, rtol=1e-3, atol=0.0)
    assert np.all(np.linalg.eigvalsh(S) > 0.0)
    assert 0.0 < card['reprojection_rms_px'] < 0.1
    assert card['ambiguity'] >= 1.0
    psi, phi, theta, distance = paper_angles(T, CAMERA, CFG)
    assert card['phi_deg'] == pytest.approx(phi, abs=0.3)
    assert card['theta_deg'] == pytest.approx(theta, abs=0.5)
    assert card['psi_deg'] == pytest.approx(psi, abs=0.5)
    assert card['distance_m'] == pytest.approx(distance, rel=0.003)
    # The points are the dots, in dot-index order (centre first).
    centre = CAMERA.project(T.t[None])[0]
    assert np.linalg.norm(np.array(card['points_px'][0]) - centre) < 0.3


def test_detect_json_several_images_and_cards(scene, capsys):
    _, paths, poses = scene
    names = ['two.png', 'none.png', 'hidden.png']
    status, out, err = detect(capsys, *[paths[n] for n in names], '--camera', paths['camera'],
                              '--json')
    assert status == 0 and err == ''
    records = json_lines(out)
    assert [r['image'] for r in records] == [paths[n] for n in names]
    two, none, hidden = records
    # Biggest (nearest) first, each with its own pose.
    assert [c['code'] for c in two['patterns']] == [str(CODE), str(OTHER)]
    for card, key in zip(two['patterns'], ('near', 'far')):
        truth = poses[key].inverse().t
        position = np.array(card['camera_in_pattern_m'])
        assert np.linalg.norm(position - truth) < 0.005 * np.linalg.norm(truth)
    assert none['patterns'] == []
    # A hidden dot is null; the pose comes from the other 16.
    (card,) = hidden['patterns']
    point7 = CFG.dot_index(0, 7)
    assert card['points_px'][point7] is None
    assert sum(p is None for p in card['points_px']) == 1
    assert np.linalg.norm(np.array(card['camera_in_pattern_m'])
                          - poses['one'].inverse().t) < 0.005 * 2.0


def test_detect_paper_estimator(scene, capsys):
    _, paths, poses = scene
    status, out, err = detect(capsys, paths['one.png'], '--camera', paths['camera'], '--json',
                              '--estimator', 'paper')
    assert status == 0 and err == ''
    (card,) = json_lines(out)[0]['patterns']
    assert card['estimator'] == 'paper' and card['code'] == str(CODE)
    assert np.array(card['covariance']).shape == (6, 6) and card['ambiguity'] is None
    _, phi, theta, distance = paper_angles(poses['one'], CAMERA, CFG)
    assert card['phi_deg'] == pytest.approx(phi, abs=1.0)
    assert card['distance_m'] == pytest.approx(distance, rel=0.01)
    assert np.linalg.norm(np.array(card['camera_in_pattern_m'])
                          - poses['one'].inverse().t) < 0.02 * 2.0


def test_detect_min_tilt_reports_the_problem(scene, capsys):
    _, paths, _ = scene
    status, out, err = detect(capsys, paths['flat.png'], '--camera', paths['camera'], '--json',
                              '--min-tilt', '25')
    assert status == 0 and err == ''
    (card,) = json_lines(out)[0]['patterns']
    assert card['code'] == str(CODE)
    assert card['T_camera_pattern'] is None and card['camera_in_pattern_m'] is None
    assert 'tilt' in card['problem']


def test_detect_text(scene, capsys):
    _, paths, poses = scene
    status, out, err = detect(capsys, paths['one.png'], paths['none.png'], '--camera',
                              paths['camera'])
    assert status == 0 and err == ''
    assert f'{paths["one.png"]}: 1 card(s)' in out
    assert f'{paths["none.png"]}: 0 card(s)' in out
    assert str(CODE) in out and 'floor 2 room 17 card 3' in out
    match = re.search(r'camera in card frame: x (\S+) y (\S+) z (\S+) m\s+D (\S+) m', out)
    assert match is not None, out
    position = np.array([float(v) for v in match.groups()[:3]])
    assert np.linalg.norm(position - poses['one'].inverse().t) < 0.01
    assert float(match.group(4)) == pytest.approx(2.0, abs=0.01)


def test_detect_reports_the_other_planar_pose_when_the_image_cannot_decide(scene, capsys):
    _, paths, poses = scene
    status, out, _ = detect(capsys, paths['faceon.png'], paths['one.png'], '--camera',
                            paths['camera'], '--json')
    faceon, one = (lines['patterns'][0] for lines in json_lines(out))
    assert status == 0
    assert 1e-3 < faceon['other_probability'] <= 0.5
    truth = poses['faceon'].inverse().t
    positions = [np.array(faceon['camera_in_pattern_m']),
                 np.array(faceon['other_camera_in_pattern_m'])]
    # One of the two is the truth; they are apart (a turn about an axis in the card).
    assert min(np.linalg.norm(p - truth) for p in positions) < 0.05 * 5.7
    assert np.linalg.norm(positions[0] - positions[1]) > 0.1
    assert faceon['flip_barrier'] >= 0.0
    assert one['other_probability'] == 0.0 and one['other_camera_in_pattern_m'] is None
    assert one['flip_barrier'] is None
    status, out, _ = detect(capsys, paths['faceon.png'], '--camera', paths['camera'])
    assert status == 0 and re.search(r'other planar pose \S+ % likely: camera at x', out), out
    # The paper's estimator reports the same flip (the dots', not an estimator's).
    status, out, _ = detect(capsys, paths['faceon.png'], paths['one.png'], '--camera',
                            paths['camera'], '--json', '--estimator', 'paper')
    paper, paper_one = (lines['patterns'][0] for lines in json_lines(out))
    assert status == 0 and paper['estimator'] == 'paper'
    assert 1e-3 < paper['other_probability'] < 1.0 and paper['flip_barrier'] >= 0.0
    assert min(np.linalg.norm(np.array(paper['other_camera_in_pattern_m']) - p)
               for p in positions) < 0.1
    assert paper_one['other_probability'] == 0.0 and paper_one['flip_barrier'] is None


def test_detect_text_says_a_valley_whose_barrier_is_unknown_is_shallow(scene, capsys):
    # The localizer refuses a pose whose barrier is not at least
    # FLIP_VALLEY_BARRIER, a NaN one included; the text says the same of it.
    import dataclasses
    from pattern_locator.cli import _print_text
    from pattern_locator.vision.locate import CardLocator

    _, paths, _ = scene
    (card,) = CardLocator(CFG).locate(cv2.imread(paths['faceon.png']), CAMERA)
    assert card.alternative is not None
    for barrier, shallow in ((math.nan, True), (0.5, True), (math.inf, False)):
        _print_text('faceon', 1.0, [dataclasses.replace(card, flip_barrier=barrier)])
        out = capsys.readouterr().out
        assert ('shallow valley' in out) == shallow, out


# Errors ----------------------------------------------------------------------------------

def test_bad_images_among_good_ones(scene, capfd):
    root, paths, _ = scene
    garbage = root / 'x.png'
    garbage.write_bytes(b'not an image at all ' * 50)
    truncated = root / 'truncated.png'
    truncated.write_bytes(Path(paths['one.png']).read_bytes()[:2000])
    missing = str(root / 'missing.png')
    args = [missing, str(garbage), paths['one.png'], str(truncated), str(root)]
    status = main(['detect', *args, '--camera', paths['camera'], '--json'])
    # capfd also catches what OpenCV or libpng might print on the C side.
    out, err = capfd.readouterr()
    assert status == 2
    lines = error_lines(err)
    assert len(lines) == 4
    for line, name in zip(lines, [missing, str(garbage), str(truncated), str(root)]):
        assert name in line
    (record,) = json_lines(out)
    assert record['image'] == paths['one.png']
    assert [c['code'] for c in record['patterns']] == [str(CODE)]


@pytest.mark.parametrize('content, words', [
    (None, 'cannot read camera file'),
    ('image_width: [640\ncamera_matrix: {', 'malformed YAML'),
    ('image_width: 640\nimage_height: 480\ncamera_matrix:\n  rows: 3\n  cols: 3\n'
     '  data: [0, 0, 0, 0, 0, 0, 0, 0, 0]\n', 'camera_matrix'),
    ('- 1\n- 2\n', 'not a camera-info YAML'),
    ('', 'not a camera-info YAML'),
    ('image_width: 640\nimage_height: 480\n', 'missing camera_matrix'),
])
def test_bad_camera_file(scene, capfd, tmp_path, content, words):
    _, paths, _ = scene
    # A deep path, as a user's may be: the message names it whole.
    camera = tmp_path / ('calibration_of_the_robot_head_camera_' * 3) / 'camera.yaml'
    camera.parent.mkdir()
    if content is not None:
        camera.write_text(content)
    status = main(['detect', paths['one.png'], '--camera', str(camera), '--json'])
    out, err = capfd.readouterr()
    assert status == 2 and out == ''
    (line,) = error_lines(err)
    assert str(camera) in line and words in line


def test_image_size_differs_from_the_camera_file(scene, capsys, tmp_path):
    _, paths, _ = scene
    small = str(tmp_path / 'small.png')
    cv2.imwrite(small, cv2.resize(cv2.imread(paths['one.png']), (320, 240)))
    status, out, err = detect(capsys, small, paths['one.png'], '--camera', paths['camera'],
                              '--json')
    assert status == 2
    (line,) = error_lines(err)
    assert small in line and '320x240' in line and '640x480' in line
    assert [r['image'] for r in json_lines(out)] == [paths['one.png']]


def test_usage_errors(capsys):
    assert main([]) == 2
    with pytest.raises(SystemExit) as info:
        main(['detect', 'image.png'])         # --camera is required
    assert info.value.code == 2
    with pytest.raises(SystemExit):
        main(['detect', 'image.png', '--camera', 'c.yaml', '--estimator', 'best'])
    capsys.readouterr()


# make-pattern ---------------------------------------------------------------------------

def test_make_pattern(tmp_path, capsys):
    output = tmp_path / 'card.svg'
    status = main(['make-pattern', '--floor', '2', '--room', '17', '--pattern', '3', '-o',
                   str(output)])
    out, err = capsys.readouterr()
    assert status == 0
    assert output.is_file() and '<svg' in output.read_text()
    assert str(output) in out.splitlines()
    assert str(CODE) in err


@pytest.mark.parametrize('args, words', [
    (['--floor', '2', '--room', '99', '--pattern', '3'], 'room 99'),
    (['--floor', '12', '--room', '1', '--pattern', '3'], 'floor 12'),
    (['--floor', '0', '--room', '1', '--pattern', '0'], 'pattern 0'),
])
def test_make_pattern_out_of_range(tmp_path, capsys, args, words):
    output = tmp_path / 'card.svg'
    status = main(['make-pattern', *args, '-o', str(output)])
    out, err = capsys.readouterr()
    assert status == 2 and out == ''
    (line,) = error_lines(err)
    assert words in line and 'out of range' in line
    assert not output.exists()


# The console entry point, once, as a separate process ------------------------------------------

def test_console_script_in_a_process(scene):
    root, paths, poses = scene
    missing = str(root / 'missing.png')
    run = subprocess.run(
        [sys.executable, '-m', 'pattern_locator.cli', 'detect', paths['one.png'], missing,
         '--camera', paths['camera'], '--json'],
        cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert run.returncode == 2
    (line,) = error_lines(run.stderr)
    assert missing in line
    (record,) = json_lines(run.stdout)
    (card,) = record['patterns']
    assert card['code'] == str(CODE)
    distance = np.linalg.norm(np.array(card['camera_in_pattern_m'])
                              - poses['one'].inverse().t)
    assert math.isfinite(distance) and distance < 0.005 * 2.0


def test_make_pattern_all_cards_of_a_building(tmp_path, capsys):
    building = tmp_path / 'building.yaml'
    building.write_text(
        'floors:\n'
        '  - floor: 2\n'
        '    rooms:\n'
        '      - room: 5\n'
        '        pose: {position: [0, 0, 6], rpy_deg: [0, 0, 0]}\n'
        '        cards:\n'
        '          - {pattern: 1, pose: {position: [0, 2.5, 2.15], facing_deg: 0}}\n'
        '          - {pattern: 2, pose: {position: [10, 2.5, 2.15], facing_deg: 180}}\n')
    status = main(['make-pattern', '--all', str(building), '-o', str(tmp_path / 'cards'),
                   '--format', 'svg'])
    out, err = capsys.readouterr()
    assert status == 0, err
    written = sorted(p.name for p in (tmp_path / 'cards').iterdir())
    assert len(written) == 2 and written[0].startswith('floor2_room5_card1_')
    assert out.split() == [str(tmp_path / 'cards' / name) for name in written]


def test_make_pattern_needs_ids_or_a_building(tmp_path, capsys):
    status = main(['make-pattern', '--room', '3', '-o', str(tmp_path / 'x.svg')])
    out, err = capsys.readouterr()
    assert status == 2 and out == ''
    assert err.strip() == ('pattern-locator: error: make-pattern needs --floor, --pattern '
                           '(or --all BUILDING)')


# Polish: version, help, conflicting options, grey images -------------------------------------

def _all_parsers(parser):
    yield parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for child in action.choices.values():
                yield from _all_parsers(child)


def test_every_option_of_every_command_has_help():
    from pattern_locator.cli import _parser
    missing = [f'{p.prog} {a.option_strings or a.dest}' for p in _all_parsers(_parser())
               for a in p._actions
               if not isinstance(a, (argparse._HelpAction, argparse._SubParsersAction))
               and not a.help]
    assert missing == []


def test_version_is_the_package_version(capsys):
    with pytest.raises(SystemExit) as info:
        main(['--version'])
    assert info.value.code == 0
    version = re.search(r'<version>([^<]+)</version>', (ROOT / 'package.xml').read_text())
    assert capsys.readouterr().out.strip() == f'pattern-locator {version.group(1)}'


@pytest.mark.parametrize('args, words', [
    (['--floor', '2', '--all', 'config/building.yaml'], 'takes no --floor'),
    (['--floor', '2', '--room', '1', '--pattern', '1', '--format', 'svg'],
     '--format is for --all'),
    (['--floor', '2', '--room', '1', '--pattern', '1', '--dpi', '5'],
     '--dpi must be in 72..2400'),
    (['--floor', '2', '--room', '1', '--pattern', '1', '--dpi', 'nan'], '--dpi must be in'),
])
def test_make_pattern_refuses_conflicting_or_bad_options_in_one_line(tmp_path, capsys, args,
                                                                     words):
    output = tmp_path / 'card.png'
    try:
        status = main(['make-pattern', *args, '-o', str(output)])
    except SystemExit as exc:
        status = exc.code
    out, err = capsys.readouterr()
    assert status == 2 and out == ''
    (line,) = [line for line in err.splitlines() if line.strip()]
    assert words in line and 'Traceback' not in err
    assert not output.exists()


def test_detect_says_a_directory_is_a_directory(scene, capsys):
    root, paths, _ = scene
    status, out, err = detect(capsys, str(root), '--camera', paths['camera'])
    assert status == 2 and out == ''
    (line,) = error_lines(err)
    assert str(root) in line and 'is a directory' in line


def test_a_grey_image_gives_geometry_and_says_so_without_python_none(
        scene, capsys, tmp_path):
    _, paths, poses = scene
    grey = tmp_path / 'grey.png'
    cv2.imwrite(str(grey), cv2.cvtColor(cv2.imread(paths['one.png']), cv2.COLOR_BGR2GRAY))
    status, out, err = detect(capsys, str(grey), '--camera', paths['camera'])
    assert status == 0 and err == ''
    assert 'None' not in out
    assert 'code not read (grey image' in out


def test_detect_refuses_an_image_over_max_pixels_from_its_header(scene, capfd):
    _, paths, _ = scene
    status = main(['detect', paths['one.png'], '--camera', paths['camera'],
                   '--max-pixels', '100000'])
    out, err = capfd.readouterr()
    assert status == 2 and out == ''
    (line,) = error_lines(err)
    assert paths['one.png'] in line and '640x480' in line


def test_detect_refuses_a_truncated_jpeg_in_one_line(scene, capfd, tmp_path):
    _, paths, _ = scene
    ok, data = cv2.imencode('.jpg', cv2.imread(paths['one.png']))
    truncated = tmp_path / 'cut.jpg'
    truncated.write_bytes(data.tobytes()[:len(data) // 2])
    status = main(['detect', str(truncated), '--camera', paths['camera']])
    out, err = capfd.readouterr()
    assert status == 2 and out == ''
    (line,) = error_lines(err)
    assert str(truncated) in line and 'truncated' in line


# inks ---------------------------------------------------------------------------------------

def test_inks_says_whether_the_printed_inks_match_and_prints_the_block(tmp_path, capsys):
    office = (('K', (35, 31, 32)), ('R', (237, 28, 36)), ('G', (0, 166, 81)),
              ('B', (46, 49, 146)))
    paths = {}
    for name, inks in (('as_configured.png', None), ('office.png', office)):
        T = card_pose_facing(0.9, 8.0, 30.0, 4.0, (20.0, -10.0), CAMERA)
        texture = printed_card_texture(CFG, Ids(2, 17, 3), inks=inks)
        image = render_scene(CAMERA, [CardPlacement(T, texture)],
                             RenderOptions(noise_sigma=1.5, seed=2)).image
        paths[name] = str(tmp_path / name)
        assert cv2.imwrite(paths[name], image)
    ids = ['--floor', '2', '--room', '17', '--pattern', '3']
    assert main(['inks', paths['as_configured.png'], *ids]) == 0
    out, _ = capsys.readouterr()
    assert 'The inks match' in out
    assert main(['inks', paths['office.png'], *ids, '--camera', str(tmp_path / 'none.yaml')]) == 2
    error_lines(capsys.readouterr().err)
    assert main(['inks', paths['office.png'], *ids]) == 1
    out, _ = capsys.readouterr()
    assert 'would not read ink B' in out
    block = out[out.index('inks:'):]
    measured = pattern_config_from_dict(yaml.safe_load(block))
    assert measured.ink_rgb('B')[2] < 170 and measured.colour_rgb('B') == CFG.colour_rgb('B')
    # Other ids than the card's, and ids out of range: one line each, status 2.
    for wrong in (['--floor', '2', '--room', '17', '--pattern', '4'],
                  ['--floor', '2', '--room', '170', '--pattern', '3']):
        assert main(['inks', paths['office.png'], *wrong]) == 2
        assert len(error_lines(capsys.readouterr().err)) == 1
