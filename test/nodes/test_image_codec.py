"""
sensor_msgs/Image <-> numpy conversion, against encodings made by the tests.

Every encoding is produced here from a synthetic BGR scene of flat colour
patches (channel swaps, alpha, grey, 16-bit words, YUV 4:2:2 by the BT.601
formula, Bayer mosaics by picking one channel per pixel), so a decoder that
reads a pattern or a byte order the wrong way round gets the colours wrong.
"""

import array
import math
from types import SimpleNamespace

import cv2
from hypothesis import given, HealthCheck, settings, strategies as st
import numpy as np
from pattern_locator.errors import CameraError, ImageError
from pattern_locator.nodes.image_codec import (camera_from_info, decode_image, encode_image,
                                               fill_camera_info, fill_msg, image_from_msg,
                                               SUPPORTED_ENCODINGS)
from pattern_locator.vision.camera import CameraModel
import pytest

FUZZ = settings(max_examples=100, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow])

H, W = 48, 64
PATCH_H, PATCH_W = 12, 16          # even, so YUV pairs and Bayer blocks never straddle patches
# BGR colours, each with distinct R, G and B so that any channel swap shows.
COLOURS = np.array([
    (30, 60, 220), (40, 200, 90), (210, 70, 20), (20, 220, 230),
    (200, 40, 190), (230, 210, 40), (128, 128, 128), (250, 250, 250),
    (10, 10, 10), (90, 160, 240), (170, 100, 50), (60, 30, 120),
    (140, 230, 180), (20, 120, 60), (240, 150, 100), (100, 20, 30),
], dtype=np.uint8)

BAYER_PATTERNS = {                 # ROS name -> channel letters of the top-left 2x2 block
    'bayer_rggb8': 'RGGB',
    'bayer_bggr8': 'BGGR',
    'bayer_gbrg8': 'GBRG',
    'bayer_grbg8': 'GRBG',
}


def make_scene() -> np.ndarray:
    """Return a 48x64 BGR image of 4x4 flat colour patches."""
    scene = np.empty((H, W, 3), np.uint8)
    for i, colour in enumerate(COLOURS):
        row, col = divmod(i, 4)
        scene[row * PATCH_H:(row + 1) * PATCH_H, col * PATCH_W:(col + 1) * PATCH_W] = colour
    return scene


SCENE = make_scene()
GREY = cv2.cvtColor(SCENE, cv2.COLOR_BGR2GRAY)


def interior_mask(margin: int) -> np.ndarray:
    """Return True where a pixel is at least ``margin`` pixels inside its patch."""
    ys = np.arange(H) % PATCH_H
    xs = np.arange(W) % PATCH_W
    inside_y = (ys >= margin) & (ys < PATCH_H - margin)
    inside_x = (xs >= margin) & (xs < PATCH_W - margin)
    return inside_y[:, None] & inside_x[None, :]


def packed(encoding: str, pixels: np.ndarray):
    """Return decode_image's arguments for tightly packed ``pixels`` bytes."""
    h, w = pixels.shape[:2]
    data = np.ascontiguousarray(pixels).tobytes()
    return h, w, encoding, 0, len(data) // h, data


def pad_rows(args, extra: int = 5):
    """Return ``args`` with ``extra`` junk bytes appended to each row."""
    h, w, encoding, big, step, data = args
    rows = np.frombuffer(data, np.uint8).reshape(h, step)
    junk = np.random.default_rng(1).integers(0, 256, (h, extra), dtype=np.uint8)
    return h, w, encoding, big, step + extra, np.hstack([rows, junk]).tobytes()


def rgb_to_yuv(bgr: np.ndarray) -> np.ndarray:
    """Return Y, U, V planes (H, W, 3) by BT.601 limited range, as OpenCV's 4:2:2 expects."""
    b, g, r = (bgr[..., k].astype(np.float64) / 255.0 for k in range(3))
    y = 16 + 65.481 * r + 128.553 * g + 24.966 * b
    u = 128 - 37.797 * r - 74.203 * g + 112.0 * b
    v = 128 + 112.0 * r - 93.786 * g - 18.214 * b
    return np.clip(np.rint(np.stack([y, u, v], axis=-1)), 0, 255).astype(np.uint8)


def yuv422(bgr: np.ndarray, order: str) -> np.ndarray:
    """Return (H, W, 2) bytes in ``order`` 'UYVY' or 'YUYV', chroma averaged per pair."""
    yuv = rgb_to_yuv(bgr).astype(np.int32)
    y0, y1 = yuv[:, 0::2, 0], yuv[:, 1::2, 0]
    u = (yuv[:, 0::2, 1] + yuv[:, 1::2, 1] + 1) // 2
    v = (yuv[:, 0::2, 2] + yuv[:, 1::2, 2] + 1) // 2
    planes = {'Y0': y0, 'Y1': y1, 'U': u, 'V': v}
    names = ['U', 'Y0', 'V', 'Y1'] if order == 'UYVY' else ['Y0', 'U', 'Y1', 'V']
    quads = np.stack([planes[n] for n in names], axis=-1).astype(np.uint8)
    return quads.reshape(bgr.shape[0], bgr.shape[1], 2)


def bayer_mosaic(bgr: np.ndarray, pattern: str) -> np.ndarray:
    """Return the one-channel mosaic of ``bgr`` for a pattern such as 'RGGB'."""
    channel = {'B': 0, 'G': 1, 'R': 2}
    mosaic = np.empty(bgr.shape[:2], np.uint8)
    for dy in range(2):
        for dx in range(2):
            letter = pattern[2 * dy + dx]
            mosaic[dy::2, dx::2] = bgr[dy::2, dx::2, channel[letter]]
    return mosaic


def mono16_bytes(words: np.ndarray, big_endian: bool) -> np.ndarray:
    """Return (H, W, 2) bytes of 16-bit ``words`` in the given byte order."""
    dtype = '>u2' if big_endian else '<u2'
    return words.astype(dtype).view(np.uint8).reshape(words.shape[0], words.shape[1], 2)


def make_args(encoding: str):
    """Return decode_image's arguments for SCENE encoded as ``encoding``."""
    if encoding in ('bgr8', '8UC3'):
        return packed(encoding, SCENE)
    if encoding == 'rgb8':
        return packed(encoding, SCENE[:, :, ::-1])
    if encoding in ('rgba8', 'bgra8'):
        alpha = np.full((H, W, 1), 77, np.uint8)     # not 255: alpha must be dropped, not mixed
        colour = SCENE[:, :, ::-1] if encoding == 'rgba8' else SCENE
        return packed(encoding, np.concatenate([colour, alpha], axis=2))
    if encoding in ('mono8', '8UC1'):
        return packed(encoding, GREY)
    if encoding == 'mono16':
        return packed(encoding, mono16_bytes(GREY.astype(np.uint16) * 256 + 0xAB, False))
    if encoding == 'yuv422':
        return packed(encoding, yuv422(SCENE, 'UYVY'))
    if encoding == 'yuv422_yuy2':
        return packed(encoding, yuv422(SCENE, 'YUYV'))
    return packed(encoding, bayer_mosaic(SCENE, BAYER_PATTERNS[encoding]))


def assert_one_line_error(excinfo, *fragments: str) -> None:
    """Check that an ImageError's message is one line and names the problem."""
    message = str(excinfo.value)
    assert '\n' not in message
    for fragment in fragments:
        assert fragment in message, message


def test_supported_encodings_listed():
    expected = {'rgb8', 'bgr8', 'rgba8', 'bgra8', 'mono8', 'mono16', 'yuv422', 'yuv422_yuy2',
                'bayer_rggb8', 'bayer_bggr8', 'bayer_gbrg8', 'bayer_grbg8', '8UC3', '8UC1'}
    assert set(SUPPORTED_ENCODINGS) == expected


@pytest.mark.parametrize('encoding', ['rgb8', 'bgr8', 'rgba8', 'bgra8', '8UC3'])
def test_colour_exact(encoding):
    out = decode_image(*make_args(encoding))
    assert out.dtype == np.uint8 and out.shape == (H, W, 3)
    np.testing.assert_array_equal(out, SCENE)


@pytest.mark.parametrize('encoding', ['mono8', '8UC1', 'mono16'])
def test_grey_exact(encoding):
    out = decode_image(*make_args(encoding))
    assert out.dtype == np.uint8 and out.shape == (H, W)
    np.testing.assert_array_equal(out, GREY)


@pytest.mark.parametrize('big_endian', [False, True])
def test_mono16_byte_order(big_endian):
    # High and low bytes differ everywhere, so a missing or extra swap shows.
    words = (GREY.astype(np.uint16) << 8) | (255 - GREY).astype(np.uint16)
    args = packed('mono16', mono16_bytes(words, big_endian))
    out = decode_image(args[0], args[1], 'mono16', int(big_endian), args[4], args[5])
    np.testing.assert_array_equal(out, GREY)


def test_mono16_big_endian_known_value():
    out = decode_image(1, 2, 'mono16', 1, 4, bytes([0x12, 0x34, 0xFE, 0x01]))
    np.testing.assert_array_equal(out, [[0x12, 0xFE]])
    out = decode_image(1, 2, 'mono16', 0, 4, bytes([0x12, 0x34, 0xFE, 0x01]))
    np.testing.assert_array_equal(out, [[0x34, 0x01]])


@pytest.mark.parametrize('encoding', ['yuv422', 'yuv422_yuy2'])
def test_yuv422(encoding):
    out = decode_image(*make_args(encoding))
    assert out.dtype == np.uint8 and out.shape == (H, W, 3)
    inside = interior_mask(1)
    diff = np.abs(out.astype(int) - SCENE.astype(int))[inside]
    assert diff.max() <= 3, diff.max()


def test_yuv422_byte_orders_differ():
    # Reading UYVY bytes as YUY2 must not give the scene: the two orders are really told apart.
    h, w, _, big, step, data = make_args('yuv422')
    wrong = decode_image(h, w, 'yuv422_yuy2', big, step, data)
    assert np.abs(wrong.astype(int) - SCENE.astype(int)).max() > 50


@pytest.mark.parametrize('encoding', sorted(BAYER_PATTERNS))
def test_bayer_colours(encoding):
    out = decode_image(*make_args(encoding))
    assert out.dtype == np.uint8 and out.shape == (H, W, 3)
    inside = interior_mask(2)
    diff = np.abs(out.astype(int) - SCENE.astype(int))[inside]
    assert diff.max() <= 2, diff.max()
    # And per patch: the mean colour of each flat patch comes back.
    for i, colour in enumerate(COLOURS):
        row, col = divmod(i, 4)
        patch = out[row * PATCH_H + 3:(row + 1) * PATCH_H - 3,
                    col * PATCH_W + 3:(col + 1) * PATCH_W - 3]
        np.testing.assert_allclose(patch.reshape(-1, 3).mean(axis=0), colour, atol=1.5)


@pytest.mark.parametrize('encoding', sorted(BAYER_PATTERNS))
def test_bayer_pure_red_and_blue(encoding):
    # The most direct check of the pattern mapping: a red scene stays red, a blue one blue.
    for bgr in [(0, 0, 255), (255, 0, 0)]:
        scene = np.zeros((8, 8, 3), np.uint8)
        scene[:] = bgr
        mosaic = bayer_mosaic(scene, BAYER_PATTERNS[encoding])
        out = decode_image(8, 8, encoding, 0, 8, mosaic.tobytes())
        np.testing.assert_array_equal(out[2:6, 2:6].reshape(-1, 3).mean(axis=0), bgr)


@pytest.mark.parametrize('encoding', SUPPORTED_ENCODINGS)
def test_step_padding_ignored(encoding):
    args = make_args(encoding)
    plain = decode_image(*args)
    for extra in (1, 3, 16):
        np.testing.assert_array_equal(decode_image(*pad_rows(args, extra)), plain)


@pytest.mark.parametrize('encoding', ['bgr8', 'mono8', 'rgb8', 'mono16', 'yuv422'])
def test_data_types(encoding):
    h, w, enc, big, step, data = pad_rows(make_args(encoding), 2)
    expected = decode_image(h, w, enc, big, step, data)
    for wrapped in (bytearray(data), memoryview(data), array.array('B', data),
                    np.frombuffer(data, np.uint8), list(data)):
        np.testing.assert_array_equal(decode_image(h, w, enc, big, step, wrapped), expected)


def test_array_array_read_without_copy():
    h, w, enc, big, step, data = make_args('bgr8')
    buffer = array.array('B', data)
    out = decode_image(h, w, enc, big, step, buffer)
    assert np.shares_memory(out, np.frombuffer(buffer, np.uint8))
    np.testing.assert_array_equal(out, SCENE)


def test_decoded_image_feeds_detector_contract():
    # Padded rows give a strided view; OpenCV and the detector must accept it as it is.
    out = decode_image(*pad_rows(make_args('bgr8'), 7))
    assert out.shape == (H, W, 3) and out.dtype == np.uint8
    np.testing.assert_array_equal(cv2.cvtColor(out, cv2.COLOR_BGR2GRAY), GREY)


def test_unknown_encoding():
    with pytest.raises(ImageError) as excinfo:
        decode_image(2, 2, 'bgr16', 0, 12, bytes(24))
    assert_one_line_error(excinfo, "'bgr16'", 'bgr8', 'bayer_grbg8', 'yuv422_yuy2')


def test_encoding_not_a_string():
    with pytest.raises(ImageError) as excinfo:
        decode_image(2, 2, None, 0, 6, bytes(12))
    assert_one_line_error(excinfo, 'encoding')


@pytest.mark.parametrize('height, width', [(0, 4), (4, 0), (-1, 4), (4, -2)])
def test_bad_size(height, width):
    with pytest.raises(ImageError) as excinfo:
        decode_image(height, width, 'mono8', 0, 4, bytes(16))
    assert_one_line_error(excinfo, 'size', f'{width}x{height}')


def test_non_integer_size():
    with pytest.raises(ImageError) as excinfo:
        decode_image(4.0, 4, 'mono8', 0, 4, bytes(16))
    assert_one_line_error(excinfo, 'height')


def test_step_too_small():
    with pytest.raises(ImageError) as excinfo:
        decode_image(2, 4, 'bgr8', 0, 11, bytes(22))
    assert_one_line_error(excinfo, 'step 11', '12')


def test_data_too_short():
    with pytest.raises(ImageError) as excinfo:
        decode_image(4, 4, 'bgr8', 0, 12, bytes(47))
    assert_one_line_error(excinfo, '47 bytes', 'expected', '48')


def test_data_too_long():
    with pytest.raises(ImageError) as excinfo:
        decode_image(4, 4, 'bgr8', 0, 12, bytes(60))
    assert_one_line_error(excinfo, '60 bytes', '48')


@pytest.mark.parametrize('encoding', ['yuv422', 'yuv422_yuy2'])
def test_yuv_odd_width(encoding):
    with pytest.raises(ImageError) as excinfo:
        decode_image(2, 3, encoding, 0, 6, bytes(12))
    assert_one_line_error(excinfo, 'even width', '3')


def test_bayer_too_small():
    with pytest.raises(ImageError) as excinfo:
        decode_image(1, 4, 'bayer_rggb8', 0, 4, bytes(4))
    assert_one_line_error(excinfo, '2x2')


def test_bad_data_type():
    with pytest.raises(ImageError) as excinfo:
        decode_image(1, 1, 'mono8', 0, 1, 'a')
    assert_one_line_error(excinfo, 'str')
    with pytest.raises(ImageError) as excinfo:
        decode_image(1, 1, 'mono8', 0, 1, np.zeros(1, np.float32))
    assert_one_line_error(excinfo, 'float32')
    with pytest.raises(ImageError) as excinfo:
        decode_image(1, 1, 'mono8', 0, 1, [300])
    assert_one_line_error(excinfo, '0..255')


@pytest.mark.parametrize('encoding', ['bgr8', 'rgb8', 'mono8', 'mono16'])
def test_encode_round_trip(encoding):
    image = GREY if encoding.startswith('mono') else SCENE
    height, width, enc, big, step, data = encode_image(image, encoding)
    assert (height, width, enc, big) == (H, W, encoding, 0)
    assert isinstance(data, bytes) and len(data) == height * step
    np.testing.assert_array_equal(decode_image(height, width, enc, big, step, data), image)


@pytest.mark.parametrize('encoding', sorted(BAYER_PATTERNS))
def test_encode_bayer_is_the_mosaic_and_decodes_to_the_scene(encoding):
    height, width, enc, big, step, data = encode_image(SCENE, encoding)
    assert (enc, step, len(data)) == (encoding, W, H * W)
    mosaic = np.frombuffer(data, np.uint8).reshape(H, W)
    np.testing.assert_array_equal(mosaic, bayer_mosaic(SCENE, BAYER_PATTERNS[encoding]))
    out = decode_image(height, width, enc, big, step, data)
    diff = np.abs(out.astype(int) - SCENE.astype(int))[interior_mask(2)]
    assert diff.max() <= 2, diff.max()


@pytest.mark.parametrize('encoding', ['yuv422', 'yuv422_yuy2'])
def test_encode_yuv422_decodes_to_the_scene(encoding):
    height, width, enc, big, step, data = encode_image(SCENE, encoding)
    assert (enc, step, len(data)) == (encoding, 2 * W, 2 * H * W)
    out = decode_image(height, width, enc, big, step, data)
    diff = np.abs(out.astype(int) - SCENE.astype(int))[interior_mask(1)]
    assert diff.max() <= 3, diff.max()
    # Two pixels share their chroma: a colour edge between them is mixed.
    edge = np.zeros((2, 2, 3), np.uint8)
    edge[:, 0] = (0, 0, 255)
    mixed = decode_image(*encode_image(edge, encoding))
    assert mixed[0, 0, 2] < 200 and mixed[0, 1, 2] > 50     # red paler, black reddish


def test_encode_byte_layout():
    pixel = np.array([[[10, 20, 30]]], np.uint8)           # B, G, R
    assert encode_image(pixel, 'bgr8')[4:] == (3, bytes([10, 20, 30]))
    assert encode_image(pixel, 'rgb8')[4:] == (3, bytes([30, 20, 10]))
    grey8 = np.array([[255, 1]], np.uint8)
    assert encode_image(grey8, 'mono16')[3:] == (0, 4, bytes([0xFF, 0xFF, 0x01, 0x01]))
    grey16 = np.array([[0x1234]], np.dtype('>u2'))         # any byte order in, little out
    assert encode_image(grey16, 'mono16')[3:] == (0, 2, bytes([0x34, 0x12]))
    assert encode_image(grey8[:, :, None], 'mono8')[4:] == (2, bytes([255, 1]))


def test_encode_non_contiguous():
    view = SCENE[::2, ::3]
    np.testing.assert_array_equal(decode_image(*encode_image(view)), view)


@pytest.mark.parametrize('image, encoding, fragment', [
    (SCENE.astype(np.float32), 'bgr8', 'float32'),
    (SCENE.astype(np.uint16), 'bgr8', 'uint16'),
    (GREY.astype(np.int32), 'mono16', 'int32'),
    (GREY, 'bgr8', 'HxWx3'),
    (SCENE, 'mono8', 'HxW grey'),
    (np.zeros((0, 4, 3), np.uint8), 'bgr8', 'positive'),
    (SCENE, 'rgba8', 'bgr8, rgb8, mono8, mono16, yuv422'),
    (SCENE[:, :5], 'yuv422', 'even width'),
    (GREY, 'bayer_rggb8', 'HxWx3'),
    (SCENE.tolist(), 'bgr8', 'numpy array'),
])
def test_encode_errors(image, encoding, fragment):
    with pytest.raises(ImageError) as excinfo:
        encode_image(image, encoding)
    assert_one_line_error(excinfo, fragment)


def test_image_from_msg_not_a_message():
    with pytest.raises(ImageError) as excinfo:
        image_from_msg(object())
    assert_one_line_error(excinfo, 'sensor_msgs/Image', 'height', 'data')


@pytest.mark.parametrize('encoding', ['bgr8', 'mono8'])
def test_ros_message_round_trip(encoding):
    from sensor_msgs.msg import Image
    image = SCENE if encoding == 'bgr8' else GREY
    msg = Image()
    msg.header.frame_id = 'camera'
    fill_msg(msg, image, encoding)
    assert msg.header.frame_id == 'camera'
    assert (msg.height, msg.width, msg.encoding, msg.is_bigendian) == (H, W, encoding, 0)
    assert msg.step == W * (3 if encoding == 'bgr8' else 1)
    assert isinstance(msg.data, array.array)               # rclpy stores uint8[] as array('B')
    out = image_from_msg(msg)
    np.testing.assert_array_equal(out, image)


def test_ros_message_padded_rgb8():
    from sensor_msgs.msg import Image
    h, w, enc, big, step, data = pad_rows(make_args('rgb8'), 4)
    msg = Image(height=h, width=w, encoding=enc, is_bigendian=big, step=step, data=data)
    np.testing.assert_array_equal(image_from_msg(msg), SCENE)


def test_fill_msg_bad_image_leaves_message():
    from sensor_msgs.msg import Image
    msg = Image()
    fill_msg(msg, GREY, 'mono8')
    with pytest.raises(ImageError):
        fill_msg(msg, GREY.astype(np.float64), 'mono8')
    np.testing.assert_array_equal(image_from_msg(msg), GREY)


# Bounds and odd fields ----------------------------------------------------------

def test_max_pixels_refuses_before_reading_the_data():
    # The size fields alone say no: the data is not even looked at.
    with pytest.raises(ImageError) as excinfo:
        decode_image(100000, 100000, 'bgr8', 0, 300000, b'', max_pixels=4_000_000)
    assert_one_line_error(excinfo, '100000x100000', 'limit of 4000000 pixels')
    msg = SimpleNamespace(height=H, width=W, encoding='bgr8', is_bigendian=0, step=3 * W,
                          data=SCENE.tobytes())
    assert image_from_msg(msg, max_pixels=H * W).shape == (H, W, 3)
    with pytest.raises(ImageError, match='limit'):
        image_from_msg(msg, max_pixels=H * W - 1)


def test_odd_field_types_are_image_errors():
    with pytest.raises(ImageError, match='is_bigendian'):
        decode_image(1, 1, 'mono16', np.array([1, 0]), 2, bytes(2))
    # A boolean byte order is read as 0 / 1.
    words = decode_image(1, 1, 'mono16', True, 2, bytes([0x12, 0x34]))
    assert words[0, 0] == 0x12
    with pytest.raises(ImageError):
        decode_image(1, 2, 'mono8', 0, 2, array.array('d'))
    with pytest.raises(ImageError, match='flat sequence'):
        decode_image(1, 2, 'mono8', 0, 2, [1.5, 2.0])
    with pytest.raises(ImageError, match='flat sequence'):
        decode_image(1, 2, 'mono8', 0, 2, [True, False])
    with pytest.raises(ImageError) as excinfo:
        decode_image(2 ** 70, 1, 'mono8', 0, 1, b'\x00')
    assert len(str(excinfo.value)) < 200
    with pytest.raises(ImageError) as excinfo:
        decode_image(1, 1, 'x' * 10000, 0, 1, b'\x00')
    assert len(str(excinfo.value)) < 300


BYTES_PER_PIXEL = {'rgb8': 3, 'bgr8': 3, 'rgba8': 4, 'bgra8': 4, 'mono8': 1, 'mono16': 2,
                   'yuv422': 2, 'yuv422_yuy2': 2, 'bayer_rggb8': 1, 'bayer_bggr8': 1,
                   'bayer_gbrg8': 1, 'bayer_grbg8': 1, '8UC3': 3, '8UC1': 1}
GREY_ENCODINGS = ('mono8', 'mono16', '8UC1')


@st.composite
def image_fields(draw):
    """Fields of an Image message: often consistent, often a little off, sometimes odd."""
    encoding = draw(st.one_of(st.sampled_from(sorted(BYTES_PER_PIXEL)),
                              st.text(max_size=8), st.none(), st.integers()))
    height = draw(st.one_of(st.integers(-2, 9), st.integers(), st.floats(), st.booleans()))
    width = draw(st.one_of(st.integers(-2, 9), st.integers(), st.floats(), st.none()))
    bpp = BYTES_PER_PIXEL.get(encoding, 1) if isinstance(encoding, str) else 1
    row = width * bpp if isinstance(width, int) and 0 < width < 100 else 4
    step = draw(st.one_of(st.just(row), st.integers(row - 2, row + 3), st.integers()))
    rows = height if isinstance(height, int) and 0 < height < 100 else 1
    size = step * rows if isinstance(step, int) and 0 <= step * rows < 10000 else 3
    size = draw(st.one_of(st.just(size), st.integers(0, 64)))
    raw = draw(st.binary(min_size=size, max_size=size))
    data = draw(st.sampled_from(['bytes', 'array', 'list', 'numpy', 'words', 'text']))
    if data == 'array':
        raw = array.array('B', raw)
    elif data == 'list':
        raw = list(raw) + draw(st.lists(st.integers(-300, 300), max_size=2))
    elif data == 'numpy':
        raw = np.frombuffer(raw, np.uint8)
    elif data == 'words':
        raw = array.array('H', raw[:len(raw) // 2 * 2])
    elif data == 'text':
        raw = raw.decode('latin-1')
    big = draw(st.one_of(st.integers(0, 1), st.booleans(), st.floats(), st.none()))
    return height, width, encoding, big, step, raw


@FUZZ
@given(fields=image_fields())
def test_any_image_fields_decode_to_their_shape_or_give_an_image_error(fields):
    height, width, encoding, _, _, _ = fields
    try:
        image = decode_image(*fields, max_pixels=10000)
    except ImageError as exc:
        assert '\n' not in str(exc) and len(str(exc)) < 400
        return
    assert image.dtype == np.uint8
    if encoding in GREY_ENCODINGS:
        assert image.shape == (height, width)
    else:
        assert image.shape == (height, width, 3)


# camera_info ---------------------------------------------------------------------

VGA = CameraModel.from_fov(640, 480, 60.0, D=[-0.1, 0.01, 0.0, 0.0, 0.0])


def info(camera=VGA, **changes):
    """Return a real sensor_msgs/CameraInfo of ``camera`` with some fields changed."""
    from sensor_msgs.msg import CameraInfo
    msg = CameraInfo()
    msg.header.frame_id = 'evi_d31'
    fill_camera_info(msg, camera)
    for name, value in changes.items():
        if isinstance(value, dict):
            values = list(getattr(msg, name))
            for index, v in value.items():
                values[index] = v
            value = values
        setattr(msg, name, value)
    return msg


def test_camera_info_round_trip():
    camera = camera_from_info(info())
    assert (camera.width, camera.height, camera.name) == (640, 480, 'evi_d31')
    assert np.array_equal(camera.K, VGA.K) and np.array_equal(camera.D, VGA.D)
    # No coefficients: no distortion.
    assert not camera_from_info(info(d=[])).has_distortion


@pytest.mark.parametrize('changes, words', [
    # Seen in fuzzing: K[2][2] = 0 gave "unexpected LinAlgError: Singular matrix".
    ({'k': {8: 0.0}}, 'last row'),
    ({'k': {6: 1.0, 7: 1.0}}, 'last row'),
    ({'k': {3: 4.0}}, 'K\\[1\\]\\[0\\]'),
    # Seen in fuzzing: finite but extreme fx, fy gave NaN poses.
    ({'k': {0: 1e-300}}, 'field of view'),
    ({'k': {4: 5e307}}, 'field of view'),
    ({'k': {0: 1500.0}}, 'fx / fy'),
    # Seen in fuzzing: the principal point far outside, D = 1e300 (poses 1.2 km off).
    ({'k': {2: 64000.0}}, 'principal point cx'),
    ({'d': {0: 1e300}}, 'out of range'),
    ({'d': {0: -3.0}}, 'cannot be undone'),
    ({'k': {0: math.nan}}, 'finite'),
    ({'k': {0: 0.0, 2: 0.0, 4: 0.0, 5: 0.0, 8: 0.0}}, 'all zeros'),
    ({'distortion_model': 'kannala_brandt'}, 'not supported'),
    ({'d': [0.1, 0.0]}, 'needs 4 or 5'),
    ({'r': {0: -1.0}}, 'not a rotation'),
    ({'p': {10: 0.0}}, 'not a valid P'),
    ({'width': 0}, 'image size'),
    ({'binning_x': 1000}, 'binning'),
])
def test_bad_camera_info_is_a_camera_error(changes, words):
    with pytest.raises(CameraError, match=words) as excinfo:
        camera_from_info(info(**changes))
    assert '\n' not in str(excinfo.value)
    assert str(excinfo.value).startswith('camera_info: ')


def test_camera_info_roi_and_binning():
    msg = info(binning_x=2, binning_y=2)
    camera = camera_from_info(msg)
    assert (camera.width, camera.height) == (320, 240)
    assert camera.fx == VGA.fx / 2 and camera.cx == VGA.cx / 2
    msg = info()
    msg.roi.x_offset, msg.roi.y_offset, msg.roi.width, msg.roi.height = 100, 50, 200, 100
    camera = camera_from_info(msg)
    assert (camera.width, camera.height) == (200, 100)
    assert (camera.cx, camera.cy) == (VGA.cx - 100, VGA.cy - 50)
    # A pixel of the region sees the same ray as the full image's pixel.
    ray = VGA.normalize(np.array([[150.0, 80.0]]))
    assert np.allclose(camera.normalize(np.array([[50.0, 30.0]])), ray)
    msg.roi.width = 600
    with pytest.raises(CameraError, match='roi'):
        camera_from_info(msg)


def test_camera_info_is_validated_once_per_content():
    first = camera_from_info(info())
    assert camera_from_info(info()) is first
    # Any changed field is checked again.
    with pytest.raises(CameraError):
        camera_from_info(info(d={0: 1e300}))
    assert camera_from_info(info()) is first


def test_not_a_camera_info():
    with pytest.raises(CameraError, match='missing field'):
        camera_from_info(object())
    long_name = SimpleNamespace(width=640, height=480, distortion_model='', d=[],
                                k=list(VGA.K.ravel()), header=SimpleNamespace(
                                    frame_id='x' * 100000))
    assert len(camera_from_info(long_name).name) == 80


odd = st.one_of(st.floats(), st.integers(), st.none(), st.text(max_size=3), st.booleans())


@settings(FUZZ, max_examples=60)
@given(width=st.one_of(st.just(640), odd), height=st.one_of(st.just(480), odd),
       model=st.one_of(st.sampled_from(['plumb_bob', 'rational_polynomial', 'equidistant', '']),
                       odd),
       k=st.one_of(st.just(list(VGA.K.ravel())), st.lists(st.floats(), min_size=9, max_size=9),
                   st.lists(odd, max_size=10), odd),
       d=st.one_of(st.lists(st.floats(-1, 1), max_size=9), st.lists(odd, max_size=9), odd),
       binning=st.one_of(st.integers(0, 4), odd),
       roi=st.one_of(st.none(), st.tuples(st.integers(-5, 700), st.integers(-5, 700),
                                          st.integers(-5, 700), st.integers(-5, 700))))
def test_any_camera_info_gives_a_valid_camera_or_a_camera_error(width, height, model, k, d,
                                                                binning, roi):
    msg = SimpleNamespace(width=width, height=height, distortion_model=model, d=d, k=k,
                          binning_x=binning, binning_y=1, header=SimpleNamespace(frame_id='c'))
    if roi is not None:
        msg.roi = SimpleNamespace(x_offset=roi[0], y_offset=roi[1], width=roi[2],
                                  height=roi[3])
    try:
        camera = camera_from_info(msg)
    except CameraError as exc:
        assert '\n' not in str(exc) and len(str(exc)) < 400
        return
    assert np.all(np.isfinite(camera.K)) and camera.width > 0 and camera.height > 0
    rays = camera.normalize(np.array([[0.0, 0.0], [camera.width - 1.0, camera.height - 1.0]]))
    assert np.all(np.isfinite(rays))
