"""Image files for the CLI: header before decoding, truncation, silence, one-line errors."""

import os
import struct
import threading
import zlib

import cv2
from hypothesis import given, HealthCheck, settings, strategies as st
import numpy as np
from pattern_locator.errors import ImageError
from pattern_locator.vision import image_file
from pattern_locator.vision.image_file import read_header, read_image
import pytest

FUZZ = settings(max_examples=120, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow,
                                       HealthCheck.function_scoped_fixture])
RNG = np.random.default_rng(3)
COLOUR = RNG.integers(0, 256, (24, 40, 3), dtype=np.uint8)
GREY = np.ascontiguousarray(COLOUR[:, :, 1])
EXTENSIONS = ('.png', '.jpg', '.bmp', '.ppm', '.tif')


def encoded(ext, image=COLOUR):
    ok, data = cv2.imencode(ext, image)
    assert ok
    return data.tobytes()


FILES = {ext: encoded(ext) for ext in EXTENSIONS}
FILES['.pgm'] = encoded('.pgm', GREY)


def write(tmp_path, data, name='image.bin'):
    path = tmp_path / name
    path.write_bytes(data)
    return path


def png_chunk(kind, payload):
    return struct.pack('>I', len(payload)) + kind + payload + struct.pack(
        '>I', zlib.crc32(kind + payload))


def png_declaring(width, height):
    """Return a PNG with a valid header for width x height and no pixels."""
    ihdr = struct.pack('>IIBBBBB', width, height, 8, 2, 0, 0, 0)
    return (b'\x89PNG\r\n\x1a\n' + png_chunk(b'IHDR', ihdr) + png_chunk(b'IDAT', b'')
            + png_chunk(b'IEND', b''))


def one_line_error(path, words, **kwargs):
    with pytest.raises(ImageError, match=words) as error:
        read_image(path, **kwargs)
    message = str(error.value)
    assert '\n' not in message and message.startswith(str(path))
    return message


@pytest.mark.parametrize('ext', sorted(FILES))
def test_each_format_reads_as_the_detector_takes_it(tmp_path, ext):
    image = read_image(write(tmp_path, FILES[ext], 'image' + ext))
    expected = GREY if ext == '.pgm' else COLOUR
    assert image.shape == expected.shape and image.dtype == np.uint8
    if ext != '.jpg':
        np.testing.assert_array_equal(image, expected)
    header = read_header(FILES[ext])
    assert (header.width, header.height) == (40, 24)


def test_sixteen_bits_and_alpha_become_what_the_detector_takes(tmp_path):
    words = COLOUR.astype(np.uint16) * 257
    image = read_image(write(tmp_path, encoded('.png', words), 'deep.png'))
    np.testing.assert_array_equal(image, COLOUR)
    bgra = np.dstack([COLOUR, GREY])
    image = read_image(write(tmp_path, encoded('.png', bgra), 'alpha.png'))
    np.testing.assert_array_equal(image, COLOUR)


def test_header_bomb_is_refused_before_decoding(tmp_path, monkeypatch):
    # Seen: a PNG declaring 100000x100000 gave a traceback, and a 20000x20000
    # PNG was decoded (2.4 GB) before the size check.
    def no_decode(*args):
        raise AssertionError('the decoder ran')
    monkeypatch.setattr(image_file.cv2, 'imdecode', no_decode)
    path = write(tmp_path, png_declaring(100000, 100000), 'bomb.png')
    one_line_error(path, '100000x100000 pixels is larger than the limit of 25000000')
    path = write(tmp_path, png_declaring(20000, 20000), 'big.png')
    one_line_error(path, 'larger than the limit of 1000000', max_pixels=1_000_000)
    one_line_error(write(tmp_path, FILES['.jpg'], 'x.jpg'), 'limit of 100 pixels',
                   max_pixels=100)


@pytest.mark.parametrize('ext', sorted(FILES))
def test_truncated_files_are_refused(tmp_path, ext):
    # Seen: truncated JPEGs and PNGs were processed with exit 0.
    data = FILES[ext]
    for cut in (len(data) // 2, len(data) - 2):
        one_line_error(write(tmp_path, data[:cut], 'cut' + ext), 'truncated|corrupt|cannot')


def test_corrupt_data_is_refused_and_the_decoders_stay_quiet(tmp_path, capfd):
    # Seen: libpng and libjpeg lines on the terminal. A JPEG whose entropy data
    # is broken decodes "fine" with a warning: the warning is the refusal.
    jpeg = bytearray(FILES['.jpg'])
    middle = len(jpeg) // 2
    jpeg[middle] ^= 0xFF
    jpeg[middle + 1] = 0xFF
    message = one_line_error(write(tmp_path, bytes(jpeg), 'bad.jpg'), 'corrupt JPEG')
    assert 'Corrupt JPEG data' in message
    # A PNG with valid chunks but a broken filter byte: libpng's own message.
    raw = zlib.compress(b''.join(b'\x07' + COLOUR[y].tobytes() for y in range(24)))
    ihdr = struct.pack('>IIBBBBB', 40, 24, 8, 2, 0, 0, 0)
    png = (b'\x89PNG\r\n\x1a\n' + png_chunk(b'IHDR', ihdr) + png_chunk(b'IDAT', raw)
           + png_chunk(b'IEND', b''))
    one_line_error(write(tmp_path, png, 'filter.png'), 'libpng error')
    # A flipped byte inside a chunk: its CRC says so before any decoding.
    png = bytearray(FILES['.png'])
    png[60] ^= 0x55
    one_line_error(write(tmp_path, bytes(png), 'crc.png'), 'CRC error')
    out, err = capfd.readouterr()
    assert out == '' and err == ''


def test_stderr_is_restored_after_a_decode(tmp_path, capfd):
    read_image(write(tmp_path, FILES['.png'], 'ok.png'))
    os.write(2, b'still here\n')
    assert capfd.readouterr().err == 'still here\n'


def test_not_regular_files_are_refused(tmp_path):
    one_line_error(tmp_path, 'is a directory')
    one_line_error(tmp_path / 'missing.png', 'No such file')
    one_line_error(write(tmp_path, b'', 'empty.png'), 'is empty')
    fifo = tmp_path / 'fifo.png'
    os.mkfifo(fifo)
    outcome = []

    def read():
        try:
            read_image(fifo)
        except ImageError as exc:
            outcome.append(str(exc))

    thread = threading.Thread(target=read, daemon=True)
    thread.start()
    thread.join(timeout=10.0)
    assert not thread.is_alive(), 'reading a FIFO blocked'
    assert outcome and 'is a FIFO' in outcome[0]


@pytest.mark.parametrize('data, words', [
    (b'GIF89a' + bytes(100), 'not an image file this reader knows'),
    (b'RIFF\x00\x00\x00\x00WEBPVP8 ', 'not an image file'),
    (b'\x89PNG\r\n\x1a\n' + bytes(8), 'no IHDR'),
    (png_declaring(0, 10), 'empty image'),
    (b'\xff\xd8\xff\xd9', 'truncated'),
    (b'BM' + bytes(40), 'unknown header|empty image'),
    (b'P6\n10 10\n70000\n', 'maxval'),
    (b'P5 x', 'header is not'),
    (b'II*\x00\x08\x00\x00\x00\x00\x00', 'no image width'),
])
def test_bad_headers_are_named(tmp_path, data, words):
    one_line_error(write(tmp_path, data), words)


def mutated_files():
    base = st.sampled_from(sorted(FILES)).map(FILES.get)
    cut = st.tuples(base, st.floats(0.0, 1.0)).map(lambda v: v[0][:int(len(v[0]) * v[1])])
    flipped = st.tuples(base, st.floats(0.0, 1.0), st.integers(1, 255)).map(
        lambda v: v[0][:int((len(v[0]) - 1) * v[1])] + bytes([v[0][int((len(v[0]) - 1) * v[1])]
                                                              ^ v[2]])
        + v[0][int((len(v[0]) - 1) * v[1]) + 1:])
    magic = st.tuples(st.sampled_from([b'\x89PNG\r\n\x1a\n', b'\xff\xd8\xff', b'BM', b'P6\n',
                                       b'P1 ', b'II*\x00', b'MM\x00*']),
                      st.binary(max_size=200)).map(lambda v: v[0] + v[1])
    return st.one_of(cut, flipped, magic, st.binary(max_size=100))


@FUZZ
@given(data=mutated_files())
def test_any_bytes_give_an_image_or_an_image_error(tmp_path, capfd, data):
    path = write(tmp_path, data, 'fuzz.img')
    try:
        image = read_image(path, max_pixels=1_000_000)
    except ImageError as exc:
        assert '\n' not in str(exc) and len(str(exc)) < 300 + len(str(path))
    else:
        header = read_header(data)
        assert image.dtype == np.uint8 and image.shape[:2] == (header.height, header.width)
        assert image.ndim == 2 or image.shape[2] == 3
    assert capfd.readouterr().err == ''
