"""
Convert between ``sensor_msgs/Image`` fields and numpy images, without cv_bridge.

The core (``decode_image``, ``encode_image``) takes and returns plain values,
so it is tested without ROS; ``image_from_msg`` and ``fill_msg`` only read and
write a message's attributes (duck typing), so this module imports no ROS
package either.

Decoded images are what ``Detector.detect`` takes: BGR uint8 (H, W, 3) for
colour encodings, grey uint8 (H, W) for mono8 and mono16 (mono16 keeps its
high byte). For bgr8, mono8, 8UC3 and 8UC1 the result is a view of ``data``
(no copy): it is read-only when ``data`` is ``bytes`` and it changes if
``data`` does, so copy it before drawing on it.
"""

import operator
from typing import Any, Dict, Tuple

import cv2
import numpy as np

from ..errors import ImageError
from ..vision.camera import CameraModel

# Bytes per pixel of each encoding the decoder reads (the bytes in one row of
# ``width`` pixels is ``width * bpp``; YUV 4:2:2 is 2 bytes per pixel on average).
_BYTES_PER_PIXEL: Dict[str, int] = {
    'rgb8': 3,
    'bgr8': 3,
    'rgba8': 4,
    'bgra8': 4,
    'mono8': 1,
    'mono16': 2,
    'yuv422': 2,
    'yuv422_yuy2': 2,
    'bayer_rggb8': 1,
    'bayer_bggr8': 1,
    'bayer_gbrg8': 1,
    'bayer_grbg8': 1,
    '8UC3': 3,
    '8UC1': 1,
}

SUPPORTED_ENCODINGS: Tuple[str, ...] = tuple(_BYTES_PER_PIXEL)

ENCODE_ENCODINGS: Tuple[str, ...] = ('bgr8', 'rgb8', 'mono8', 'mono16')

# ROS names the Bayer pattern by its top-left 2x2 block read row by row
# (bayer_rggb8: R G / G B). OpenCV's legacy names follow the second row's
# 2nd and 3rd pixels instead, so the names look swapped: RGGB is
# COLOR_BayerBG2BGR (OpenCV 5 also calls it COLOR_BayerRGGB2BGR, same value).
# The tests mosaic a coloured scene per pattern and check the colours.
_BAYER_CODES: Dict[str, int] = {
    'bayer_rggb8': cv2.COLOR_BayerBG2BGR,
    'bayer_bggr8': cv2.COLOR_BayerRG2BGR,
    'bayer_gbrg8': cv2.COLOR_BayerGR2BGR,
    'bayer_grbg8': cv2.COLOR_BayerGB2BGR,
}

# ROS 'yuv422' is UYVY (U0 Y0 V0 Y1); 'yuv422_yuy2' is YUYV (Y0 U0 Y1 V0).
_YUV_CODES: Dict[str, int] = {
    'yuv422': cv2.COLOR_YUV2BGR_UYVY,
    'yuv422_yuy2': cv2.COLOR_YUV2BGR_YUY2,
}

_MSG_FIELDS = ('height', 'width', 'encoding', 'is_bigendian', 'step', 'data')


def _as_int(value: Any, name: str) -> int:
    """Return ``value`` as an int, or raise ImageError if it is not an integer."""
    if isinstance(value, bool):
        raise ImageError(f'{name} must be an integer, got {value!r}')
    try:
        return operator.index(value)
    except TypeError:
        raise ImageError(f'{name} must be an integer, got {type(value).__name__}') from None


def _as_bytes(data: Any) -> np.ndarray:
    """Return ``data`` as a flat uint8 array, sharing its memory where it can."""
    if isinstance(data, np.ndarray):
        if data.dtype != np.uint8:
            raise ImageError(f'image data must be uint8 bytes, got a {data.dtype} array')
        return data.reshape(-1)
    if isinstance(data, (list, tuple)):
        # rclpy never gives these, but a hand-built message may.
        try:
            return np.array(data, dtype=np.uint8)
        except (OverflowError, TypeError, ValueError) as exc:
            raise ImageError(f'image data must be a sequence of bytes 0..255: {exc}') from None
    try:
        view = memoryview(data)
    except TypeError:
        raise ImageError('image data must be bytes, bytearray, memoryview or '
                         f"array.array('B'), got {type(data).__name__}") from None
    if not view.c_contiguous:
        raise ImageError('image data must be a contiguous buffer')
    # Casting to 'B' reads any buffer (e.g. array.array('H')) as its raw bytes.
    return np.frombuffer(view.cast('B') if view.format != 'B' else view, dtype=np.uint8)


def decode_image(height: int, width: int, encoding: str, is_bigendian: int, step: int,
                 data: Any) -> np.ndarray:
    """
    Return the image held by a ``sensor_msgs/Image``'s fields as a numpy array.

    Colour encodings give BGR uint8 (H, W, 3), mono8 and mono16 give grey
    uint8 (H, W); mono16 keeps its high byte. ``data`` may be bytes,
    bytearray, memoryview or array.array('B') (what rclpy gives); it is read
    without a copy. Bytes past ``width * bytes_per_pixel`` in each row of
    ``step`` bytes are padding and ignored. Raise ImageError, with one line
    naming the problem, for anything that cannot be decoded exactly.
    """
    if not isinstance(encoding, str):
        raise ImageError(f'encoding must be a string, got {type(encoding).__name__}')
    bpp = _BYTES_PER_PIXEL.get(encoding)
    if bpp is None:
        raise ImageError(f'unsupported image encoding {encoding!r}; supported: '
                         + ', '.join(SUPPORTED_ENCODINGS))
    height = _as_int(height, 'height')
    width = _as_int(width, 'width')
    step = _as_int(step, 'step')
    if height <= 0 or width <= 0:
        raise ImageError(f'image size must be positive, got {width}x{height} (width x height)')
    row_bytes = width * bpp
    if step < row_bytes:
        raise ImageError(f'step {step} is smaller than width * bytes per pixel = '
                         f'{width} * {bpp} = {row_bytes} for {encoding}')
    if encoding in _YUV_CODES and width % 2:
        raise ImageError(f'{encoding} (YUV 4:2:2) needs an even width, got {width}')
    if encoding in _BAYER_CODES and (width < 2 or height < 2):
        raise ImageError(f'{encoding} needs at least 2x2 pixels to demosaic, '
                         f'got {width}x{height}')
    buf = _as_bytes(data)
    expected = height * step
    # ROS defines len(data) == step * height; a different length means the
    # size fields do not describe the data, so any image read would be a guess.
    if buf.size != expected:
        raise ImageError(f'image data has {buf.size} bytes, expected height * step = '
                         f'{height} * {step} = {expected} for {width}x{height} {encoding}')

    rows = buf.reshape(height, step)[:, :row_bytes]
    if encoding == 'mono16':
        # 16-bit words in the message's byte order, whatever the host's.
        words = rows.view('>u2' if is_bigendian else '<u2')
        return (words >> 8).astype(np.uint8)
    if bpp == 1 and encoding not in _BAYER_CODES:
        return rows                                 # mono8, 8UC1
    pixels = rows.reshape(height, width, bpp)
    if encoding in ('bgr8', '8UC3'):
        return pixels
    try:
        if encoding == 'rgb8':
            return cv2.cvtColor(pixels, cv2.COLOR_RGB2BGR)
        if encoding == 'rgba8':
            return cv2.cvtColor(pixels, cv2.COLOR_RGBA2BGR)
        if encoding == 'bgra8':
            return cv2.cvtColor(pixels, cv2.COLOR_BGRA2BGR)
        if encoding in _YUV_CODES:
            return cv2.cvtColor(pixels, _YUV_CODES[encoding])
        return cv2.cvtColor(rows, _BAYER_CODES[encoding])
    except cv2.error as exc:
        # Not expected after the checks above; keep the error one line.
        message = str(exc).strip().splitlines()[-1]
        raise ImageError(f'cannot convert {encoding} to BGR: {message}') from None


def encode_image(image: np.ndarray, encoding: str = 'bgr8'
                 ) -> Tuple[int, int, str, int, int, bytes]:
    """
    Return ``(height, width, encoding, is_bigendian, step, data)`` for an image.

    ``image`` is BGR uint8 (H, W, 3) for bgr8 and rgb8, grey uint8 (H, W) or
    (H, W, 1) for mono8 and mono16; mono16 also takes uint16 grey as is and
    scales uint8 by 257 (so 255 becomes 65535). Rows are packed (step = width
    * bytes per pixel) and 16-bit data is little-endian (is_bigendian = 0).
    """
    if encoding not in ENCODE_ENCODINGS:
        raise ImageError(f'cannot encode to {encoding!r}; supported: '
                         + ', '.join(ENCODE_ENCODINGS))
    if not isinstance(image, np.ndarray):
        raise ImageError(f'image must be a numpy array, got {type(image).__name__}')
    allowed = (np.uint8, np.uint16) if encoding == 'mono16' else (np.uint8,)
    if image.dtype.type not in allowed:     # .type: any byte order of uint16
        raise ImageError(f'image for {encoding} must be '
                         + ' or '.join(np.dtype(t).name for t in allowed)
                         + f', got {image.dtype}')
    if encoding in ('bgr8', 'rgb8'):
        if image.ndim != 3 or image.shape[2] != 3:
            raise ImageError(f'image for {encoding} must be HxWx3 BGR, got shape {image.shape}')
    else:
        if image.ndim == 3 and image.shape[2] == 1:
            image = image[:, :, 0]
        if image.ndim != 2:
            raise ImageError(f'image for {encoding} must be HxW grey, got shape {image.shape}')
    height, width = image.shape[:2]
    if height == 0 or width == 0:
        raise ImageError(f'image size must be positive, got {width}x{height} (width x height)')

    if encoding == 'rgb8':
        image = image[:, :, ::-1]
    elif encoding == 'mono16':
        if image.dtype == np.uint8:
            image = image.astype(np.uint16) * 257
        image = image.astype('<u2', copy=False)
    packed = np.ascontiguousarray(image)
    step = width * _BYTES_PER_PIXEL[encoding]
    return height, width, encoding, 0, step, packed.tobytes()


def image_from_msg(msg: Any) -> np.ndarray:
    """Return the image of a ``sensor_msgs/Image`` (see ``decode_image``)."""
    missing = [name for name in _MSG_FIELDS if not hasattr(msg, name)]
    if missing:
        raise ImageError(f'not a sensor_msgs/Image ({type(msg).__name__}): missing field(s) '
                         + ', '.join(missing))
    return decode_image(msg.height, msg.width, msg.encoding, msg.is_bigendian, msg.step,
                        msg.data)


def fill_msg(msg: Any, image: np.ndarray, encoding: str = 'bgr8') -> None:
    """Fill a ``sensor_msgs/Image``'s fields but its header with ``image`` (see encode_image)."""
    height, width, encoding, is_bigendian, step, data = encode_image(image, encoding)
    # Encode first so that a bad image leaves the message untouched.
    msg.height = height
    msg.width = width
    msg.encoding = encoding
    msg.is_bigendian = is_bigendian
    msg.step = step
    msg.data = data


def camera_from_info(msg) -> CameraModel:
    """Build a CameraModel from a sensor_msgs/CameraInfo; CameraError if it is unusable."""
    K = np.asarray(msg.k, dtype=float).reshape(3, 3)
    model = msg.distortion_model or 'plumb_bob'
    D = np.asarray(msg.d, dtype=float)
    if not D.size:
        model, D = 'none', np.zeros(5)
    return CameraModel(int(msg.width), int(msg.height), K, D, model,
                       msg.header.frame_id or 'camera')


def fill_camera_info(msg, camera: CameraModel) -> None:
    """Fill a sensor_msgs/CameraInfo's size, K, D, R and P from a CameraModel."""
    msg.width, msg.height = int(camera.width), int(camera.height)
    msg.distortion_model = 'plumb_bob' if camera.distortion_model == 'none' else \
        camera.distortion_model
    msg.k = [float(v) for v in camera.K.ravel()]
    msg.d = [float(v) for v in camera.D]
    msg.r = [float(v) for v in np.eye(3).ravel()]
    msg.p = [float(v) for v in np.hstack([camera.K, np.zeros((3, 1))]).ravel()]
