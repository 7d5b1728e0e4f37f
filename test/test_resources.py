"""YAML files with limits: what a bad file can cost (read_yaml and the loaders that use it)."""

import os
import threading

from hypothesis import given, HealthCheck, settings, strategies as st
from pattern_locator.card.pattern import load_pattern_config
from pattern_locator.errors import CameraError, ConfigError
from pattern_locator.localization.building import load_building
from pattern_locator.resources import (config_path, MAX_YAML_ALIASES, MAX_YAML_DEPTH, quote,
                                       read_yaml, UniqueKeyLoader)
from pattern_locator.visca.zoom_table import ZoomTable
from pattern_locator.vision.camera import load_camera
import pytest
import yaml

FUZZ = settings(max_examples=40, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow,
                                       HealthCheck.function_scoped_fixture])
PATTERN = load_pattern_config()
PATTERN_TEXT = config_path('pattern.yaml').read_text()
ZOOM_TEXT = config_path('evi_d31_zoom.yaml').read_text()
FEW = settings(FUZZ, max_examples=15)


def dump(data):
    return yaml.dump(data, Dumper=yaml.CSafeDumper)


def write(tmp_path, text, name='file.yaml'):
    path = tmp_path / name
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text)
    return path


def refused(path, words, **kwargs):
    with pytest.raises(ConfigError, match=words) as error:
        read_yaml(path, 'the test file', **kwargs)
    message = str(error.value)
    assert '\n' not in message and message.startswith(str(path))
    return message


def test_a_fifo_is_refused_at_once(tmp_path):
    # Seen: a FIFO as the camera file hung the CLI. Read it in a thread so
    # that a regression fails the test instead of hanging it.
    fifo = tmp_path / 'camera.yaml'
    os.mkfifo(fifo)
    outcome = []

    def read():
        try:
            load_camera(fifo)
        except CameraError as exc:
            outcome.append(str(exc))

    thread = threading.Thread(target=read, daemon=True)
    thread.start()
    thread.join(timeout=10.0)
    assert not thread.is_alive(), 'reading a FIFO blocked'
    assert outcome and 'is a FIFO' in outcome[0]


def test_a_directory_and_a_missing_file_are_refused(tmp_path):
    refused(tmp_path, 'is a directory')
    refused(tmp_path / 'missing.yaml', 'No such file')


def test_size_limit(tmp_path):
    path = write(tmp_path, 'x: ' + 'a' * 5000 + '\n')
    refused(path, 'too large .*the limit is 4096', max_bytes=4096)
    assert read_yaml(path, 'the test file', max_bytes=8192) == {'x': 'a' * 5000}


@pytest.mark.parametrize('text', [
    # Seen: 10,000-deep YAML gave a traceback (RecursionError); 3,000 levels
    # are past the recursion limit as well.
    '[' * 3000 + ']' * 3000,
    '{a: ' * 3000 + '1' + '}' * 3000,
    ''.join(' ' * i + '- \n' for i in range(300)),
])
def test_nesting_depth_limit(tmp_path, text):
    refused(write(tmp_path, text), f'nested deeper than {MAX_YAML_DEPTH} levels')


def test_nesting_within_the_limit_loads(tmp_path):
    text = '[' * (MAX_YAML_DEPTH - 1) + ']' * (MAX_YAML_DEPTH - 1)
    assert read_yaml(write(tmp_path, text), 'the test file') is not None


def billion_laughs(levels=9, fan=9):
    lines = ['a0: &a0 [' + ', '.join(['lol'] * fan) + ']']
    for level in range(1, levels + 1):
        lines.append(f'a{level}: &a{level} [' + ', '.join([f'*a{level - 1}'] * fan) + ']')
    return '\n'.join(lines) + '\n'


def test_alias_bomb_is_refused(tmp_path):
    # Seen: an alias bomb cost 24 s and 3 GB; now it stops while composing,
    # after a few thousand values.
    message = refused(write(tmp_path, billion_laughs()), 'more than 20000 values')
    assert 'line' in message
    # Few aliases, but each doubling the one before: the expansion counts.
    doubling = 'x0: &x0 [1, 2]\n' + ''.join(
        f'x{i}: &x{i} [*x{i - 1}, *x{i - 1}]\n' for i in range(1, 40))
    refused(write(tmp_path, doubling), 'more than 20000 values')


def test_alias_count_limit_and_recursive_alias(tmp_path):
    many = 'a: &a 1\nb: [' + ', '.join(['*a'] * (MAX_YAML_ALIASES + 1)) + ']\n'
    refused(write(tmp_path, many), f'more than {MAX_YAML_ALIASES} aliases')
    refused(write(tmp_path, '&a [1, *a]\n'), 'refers to a collection that contains it')
    # A few aliases are fine: they are ordinary YAML.
    few = 'base: &b {x: 1}\nrooms: [*b, *b, *b]\n'
    assert read_yaml(write(tmp_path, few), 'the test file')['rooms'] == [{'x': 1}] * 3


def test_long_flat_files_stop_at_the_value_limit(tmp_path):
    path = write(tmp_path, '[' + ', '.join(['1'] * 3000) + ']')
    refused(path, 'more than 2000 values', max_nodes=2000)
    assert len(read_yaml(path, 'the test file', max_nodes=4000)) == 3000


@pytest.mark.parametrize('text, words', [
    (b'x: \xff\xfe\n', 'not UTF-8'),
    ('x: [1, 2\n', 'malformed YAML at line 2'),
    ('x: ' + '9' * 5000 + '\n', 'a value cannot be read'),
    ('x: 2024-13-45\n', 'a value cannot be read'),
    ('x: !!python/object:os.system {}\n', 'malformed YAML'),
])
def test_bad_content_is_one_line(tmp_path, text, words):
    refused(write(tmp_path, text), words)


def test_unique_key_loader_refuses_a_repeated_key(tmp_path):
    path = write(tmp_path, 'image_width: 640\nimage_width: 320\n')
    assert read_yaml(path, 'the test file') == {'image_width': 320}
    refused(path, "duplicate key 'image_width'", loader=UniqueKeyLoader)


def test_quote_cuts_foreign_text():
    assert quote('abc') == "'abc'"
    long = quote('x' * 1000)
    assert len(long) == 80 and long.endswith('...')


@FUZZ
@given(data=st.binary(max_size=300))
def test_any_bytes_give_data_or_a_config_error(tmp_path, data):
    try:
        read_yaml(write(tmp_path, data), 'the test file')
    except ConfigError as exc:
        assert '\n' not in str(exc)


yaml_values = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(-10 ** 30, 10 ** 30), st.text(max_size=8),
              st.floats(allow_nan=True, allow_infinity=True)),
    lambda inner: st.one_of(st.lists(inner, max_size=5),
                            st.dictionaries(st.one_of(st.text(max_size=6), st.sampled_from(
                                ['floors', 'floor', 'rooms', 'room', 'pose', 'cards',
                                 'pattern', 'position', 'rpy_deg', 'facing_deg', 'size'])),
                                inner, max_size=5)),
    max_leaves=25)


SMALL_MAP = """
floors:
  - floor: 1
    rooms:
      - room: 3
        pose: {position: [0.0, 0.0, 3.0], rpy_deg: [0, 0, 0]}
        size: [10.0, 5.0, 2.5]
        cards:
          - pattern: 1
            pose: {position: [0.0, 2.5, 2.15], facing_deg: 0}
          - pattern: 2
            pose: {position: [5.0, 5.0, 2.15], facing_deg: -90}
"""


def small_map_with(value, where):
    """Return a small building map's data with one part replaced by ``value``."""
    data = yaml.safe_load(SMALL_MAP)
    if where == 'top':
        return value
    floor = data['floors'][0]
    if where == 'floor':
        data['floors'][0] = value
    elif where == 'room':
        floor['rooms'][0] = value
    elif where == 'card':
        floor['rooms'][0]['cards'][0] = value
    else:
        floor['rooms'][0]['cards'][0]['pose'] = value
    return data


@FUZZ
@given(value=yaml_values, where=st.sampled_from(['top', 'floor', 'room', 'card', 'pose']))
def test_any_building_map_loads_or_gives_a_config_error(tmp_path, value, where):
    path = write(tmp_path, dump(small_map_with(value, where)))
    try:
        building = load_building(path, PATTERN)
    except ConfigError as exc:
        assert '\n' not in str(exc)
        return
    assert building.cards()


@pytest.mark.parametrize('text', [
    'code: {ring_digits: {R: .inf}}\n',
    'code: {fields: {floor: {dots: [x]}}}\n',
    'code: {fields: {floor: {dots: 5}}}\n',
])
def test_pattern_values_of_the_wrong_type_are_config_errors(tmp_path, text):
    # Found by the property test below: tracebacks (OverflowError, ValueError,
    # TypeError) before.
    path = write(tmp_path, text)
    with pytest.raises(ConfigError, match='invalid pattern configuration'):
        load_pattern_config(path)


@FEW
@given(key=st.sampled_from(['card_size', 'ring_radii', 'ring_dot_radius', 'colours', 'code',
                            'centre_dot_radius']),
       value=st.one_of(yaml_values, st.fixed_dictionaries({'fields': yaml_values}),
                       st.fixed_dictionaries({'ring_digits': yaml_values}),
                       st.fixed_dictionaries({'fields': st.fixed_dictionaries(
                           {'floor': st.fixed_dictionaries({'dots': yaml_values})})})))
def test_any_pattern_configuration_loads_or_gives_a_config_error(tmp_path, key, value):
    data = yaml.safe_load(PATTERN_TEXT)
    data[key] = value
    path = write(tmp_path, dump(data))
    try:
        load_pattern_config(path)
    except ConfigError as exc:
        assert '\n' not in str(exc)


@FEW
@given(key=st.sampled_from(['image_width', 'image_height', 'distortion_model', 'entries']),
       value=st.one_of(yaml_values, st.lists(st.dictionaries(st.sampled_from(
           ['zoom', 'fx', 'fy', 'cx', 'cy', 'd']), yaml_values), max_size=3)))
def test_any_zoom_table_loads_or_gives_a_config_error(tmp_path, key, value):
    data = yaml.safe_load(ZOOM_TEXT)
    data[key] = value
    path = write(tmp_path, dump(data))
    try:
        table = ZoomTable.load(path)
    except ConfigError as exc:
        assert '\n' not in str(exc)
        return
    table.camera_at(table.zoom_range[0])
