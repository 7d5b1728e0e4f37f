"""Zoom -> intrinsics table: the shipped approximation, interpolation, inverse, validation."""

import math
import textwrap

import numpy as np
from pattern_locator.errors import ConfigError
from pattern_locator.visca.zoom_table import (approximate_hfov_deg, approximate_table, write_table,
                                              ZOOM_MAX, ZoomEntry, ZoomTable)
import pytest

TABLE = ZoomTable.load()

GOOD = """\
image_width: 640
image_height: 480
camera_name: test_cam
distortion_model: plumb_bob
entries:
  - {zoom: 100, fx: 800.0, fy: 810.0, cx: 320.0, cy: 240.0, d: [-0.04, 0.01, 0, 0, 0]}
  - {zoom: 500, fx: 3200.0, fy: 3240.0, cx: 330.0, cy: 230.0, d: [0.0, 0.03, 0, 0, 0]}
"""


def write(tmp_path, text, name='zoom.yaml'):
    path = tmp_path / name
    path.write_text(textwrap.dedent(text), encoding='utf-8')
    return path


# The shipped table -----------------------------------------------------------------


def test_shipped_table_is_the_public_approximation():
    assert (TABLE.width, TABLE.height) == (640, 480)
    assert TABLE.zoom_range == (0, ZOOM_MAX)
    assert 12 <= len(TABLE.entries) <= 16
    wide, tele = TABLE.camera_at(0), TABLE.camera_at(ZOOM_MAX)
    assert wide.fx == pytest.approx(705.4, abs=0.5)       # visca.md: about 705 px
    assert tele.fx == pytest.approx(8465, rel=1e-3)       # about 8500 px
    assert wide.D[0] == pytest.approx(-0.05) and tele.D[0] == 0.0
    for camera in (wide, tele):
        assert camera.fx == camera.fy
        assert (camera.cx, camera.cy) == (319.5, 239.5)
        assert camera.distortion_model == 'plumb_bob'
    # The approximation's focal length is exponential in the zoom, so log
    # interpolation reproduces it between the entries too.
    for zoom in range(0, ZOOM_MAX + 1, 37):
        fx = 320.0 / math.tan(math.radians(approximate_hfov_deg(zoom)) / 2.0)
        assert TABLE.camera_at(zoom).fx == pytest.approx(fx, rel=1e-4)


def test_shipped_file_is_what_the_generator_writes(tmp_path):
    path = tmp_path / 'regenerated.yaml'
    write_table(approximate_table(), path)
    assert ZoomTable.load(path).entries == TABLE.entries
    assert 'approximation' in path.read_text() and 'calibration' in path.read_text()


def test_hfov_approximation_ends():
    assert approximate_hfov_deg(0) == pytest.approx(48.8)
    tele = 2.0 * math.degrees(math.atan(math.tan(math.radians(24.4)) * 5.4 / 64.8))
    assert approximate_hfov_deg(ZOOM_MAX) == pytest.approx(tele)


# Interpolation ---------------------------------------------------------------------


def test_interpolation_is_exact_at_the_entries():
    for entry in TABLE.entries:
        camera = TABLE.camera_at(entry.zoom)
        assert (camera.fx, camera.fy, camera.cx, camera.cy) == (entry.fx, entry.fy, entry.cx,
                                                                entry.cy)
        assert tuple(camera.D) == entry.d


def test_interpolation_between_entries(tmp_path):
    table = ZoomTable.load(write(tmp_path, GOOD))
    camera = table.camera_at(300)                       # half way
    assert camera.name == 'test_cam'
    assert camera.fx == pytest.approx(1600.0)           # geometric mean: log space
    assert camera.fy == pytest.approx(math.sqrt(810.0 * 3240.0))
    assert (camera.cx, camera.cy) == pytest.approx((325.0, 235.0))
    np.testing.assert_allclose(camera.D, [-0.02, 0.02, 0, 0, 0])
    assert table.camera_at(199.5).fx == pytest.approx(800.0 * 4.0 ** (99.5 / 400.0))


def test_focal_length_grows_with_zoom():
    fx = [TABLE.camera_at(z).fx for z in range(ZOOM_MAX + 1)]
    assert np.all(np.diff(fx) > 0)


def test_zoom_outside_the_table_is_clamped(tmp_path):
    table = ZoomTable.load(write(tmp_path, GOOD))
    assert table.camera_at(0).fx == table.camera_at(-20).fx == 800.0
    assert table.camera_at(1023).fx == table.camera_at(1e6).fx == 3200.0
    assert TABLE.camera_at(-1).fx == TABLE.entries[0].fx
    assert TABLE.camera_at(5000).fx == TABLE.entries[-1].fx
    with pytest.raises(ValueError, match='finite'):
        TABLE.camera_at(float('nan'))


def test_zoom_for_focal_inverts_camera_at(tmp_path):
    for zoom in range(ZOOM_MAX + 1):
        assert TABLE.zoom_for_focal(TABLE.camera_at(zoom).fx) == zoom
    assert TABLE.zoom_for_focal(100.0) == 0
    assert TABLE.zoom_for_focal(1e5) == ZOOM_MAX
    table = ZoomTable.load(write(tmp_path, GOOD))
    assert table.zoom_for_focal(1600.0) == 300
    assert table.zoom_for_focal(10.0) == 100 and table.zoom_for_focal(1e4) == 500
    with pytest.raises(ValueError, match='positive'):
        TABLE.zoom_for_focal(0.0)


def test_a_single_entry_is_a_fixed_camera():
    entry = ZoomEntry(400, 1000.0, 1000.0, 320.0, 240.0, (0.0, 0.0, 0.0, 0.0, 0.0))
    table = ZoomTable(640, 480, (entry,))
    assert table.camera_at(0).fx == table.camera_at(1023).fx == 1000.0
    assert table.zoom_for_focal(500.0) == 400


# Validation -------------------------------------------------------------------------


def entry(zoom, fx=800.0, **extra):
    fields = {'zoom': zoom, 'fx': fx, 'fy': fx, 'cx': 320, 'cy': 240, 'd': '[0, 0, 0, 0, 0]'}
    fields.update(extra)
    return '  - {' + ', '.join(f'{k}: {v}' for k, v in fields.items()) + '}\n'


HEAD = 'image_width: 640\nimage_height: 480\nentries:\n'


@pytest.mark.parametrize('text, message', [
    (HEAD + entry(500) + entry(100, 900.0), 'zoom 100 after 500: entries must be sorted'),
    (HEAD + entry(100) + entry(100, 900.0), 'zoom 100 after 100'),
    (HEAD + entry(100, 0.0), 'zoom 100: fx must be positive'),
    (HEAD + entry(100, fy=-5.0), 'zoom 100: fy must be positive'),
    (HEAD + entry(100) + entry(200, 700.0), 'the focal length must grow with the zoom'),
    (HEAD + entry(1024), 'entry 1: zoom 1024 outside 0..1023'),
    (HEAD + entry(-1), 'entry 1: zoom -1 outside 0..1023'),
    (HEAD + entry(2.5), 'entry 1: zoom must be an integer'),
    (HEAD + entry(100, cx='.nan'), 'zoom 100: cx must be a finite number'),
    (HEAD + entry(100, d='[a, 0, 0, 0, 0]'), "zoom 100: d must be a finite number, got 'a'"),
    (HEAD + entry(100, d='3'), 'zoom 100: d must be a list'),
    (HEAD + entry(100) + entry(200, 900.0, d='[0, 0, 0, 0]'), 'same number of distortion'),
    (HEAD + entry(100, d='[0, 0]'), 'distortion coefficients'),
    (HEAD + '  - {zoom: 5, fx: 800, fy: 800, cx: 320, d: [0, 0, 0, 0, 0]}\n',
     'entry 1: missing cy'),
    (HEAD + entry(100, f=3), "entry 1: unknown key 'f'"),
    ('image_width: 640\nentries: []\n', 'missing image_height'),
    ('image_width: 640\nimage_height: 480\n', 'missing entries'),
    (HEAD.replace('640', '0') + entry(100), 'image_width 0 outside >= 1'),
    (HEAD, 'entries must be a list'),
    ('image_width: 640\nimage_height: 480\nentries: []\n', 'at least one zoom position'),
    (HEAD + '  - 5\n', 'entry 1: expected a mapping'),
    ('distortion_model: fisheye\n' + HEAD + entry(100), "distortion model 'fisheye' not"),
    (HEAD + 'zoom_units: 3\n', "unknown key 'zoom_units'"),
    ('- 1\n- 2\n', 'expected a mapping'),
    ('image_width: 640\nentries: [\n', 'malformed YAML'),
])
def test_bad_tables_are_refused_with_one_line(tmp_path, text, message):
    path = write(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        ZoomTable.load(path)
    text = str(info.value)
    assert message in text
    assert text.startswith(str(path)) and '\n' not in text


def test_missing_file(tmp_path):
    with pytest.raises(ConfigError, match='cannot read the zoom table'):
        ZoomTable.load(tmp_path / 'nope.yaml')
