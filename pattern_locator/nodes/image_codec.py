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

import array
import collections
import operator
import threading
from typing import Any, Dict, Optional, Tuple

import cv2
import numpy as np

from ..errors import CameraError, ImageError
from ..resources import quote
from ..vision.camera import camera_from_calibration, CameraModel, MAX_IMAGE_SIDE, NAME_CHARS

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

ENCODE_ENCODINGS: Tuple[str, ...] = ('bgr8', 'rgb8', 'mono8', 'mono16', 'yuv422',
                                     'yuv422_yuy2', 'bayer_rggb8', 'bayer_bggr8',
                                     'bayer_gbrg8', 'bayer_grbg8')

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

# The other way, for a camera that sends them (the stress bench, a simulated
# frame grabber): OpenCV's BGR to YUV 4:2:2 (BT.601, each pair of pixels
# sharing one U and V), and a Bayer mosaic keeping each pixel's own channel.
_YUV_FROM_BGR: Dict[str, int] = {
    'yuv422': cv2.COLOR_BGR2YUV_UYVY,
    'yuv422_yuy2': cv2.COLOR_BGR2YUV_YUY2,
}
# BGR channel of the pixels (0, 0), (0, 1), (1, 0), (1, 1) of each 2 x 2 block.
_BAYER_CHANNELS: Dict[str, Tuple[int, int, int, int]] = {
    'bayer_rggb8': (2, 1, 1, 0),
    'bayer_bggr8': (0, 1, 1, 2),
    'bayer_gbrg8': (1, 0, 2, 1),
    'bayer_grbg8': (1, 2, 0, 1),
}

_ENCODED_FROM_BGR = ('bgr8', 'rgb8', *_YUV_FROM_BGR, *_BAYER_CHANNELS)

_MSG_FIELDS = ('height', 'width', 'encoding', 'is_bigendian', 'step', 'data')


def _short(number: int) -> str:
    """Return an integer for a message, at most ~20 characters."""
    return str(number) if abs(number) < 10 ** 18 else f'(an integer of {number.bit_length()} bits)'


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
            values = np.array(data)
        except (OverflowError, TypeError, ValueError):
            values = None
        if values is not None and values.size == 0:
            return np.zeros(0, np.uint8)
        if (values is None or values.ndim != 1 or values.dtype.kind not in 'iu'
                or values.min() < 0 or values.max() > 255):
            raise ImageError('image data must be a flat sequence of integers 0..255')
        return values.astype(np.uint8)
    try:
        view = memoryview(data)
    except TypeError:
        raise ImageError('image data must be bytes, bytearray, memoryview or '
                         f"array.array('B'), got {type(data).__name__}") from None
    if not view.c_contiguous:
        raise ImageError('image data must be a contiguous buffer')
    if view.nbytes == 0:
        return np.zeros(0, np.uint8)
    # Casting to 'B' reads any buffer (e.g. array.array('H')) as its raw bytes.
    try:
        flat = view.cast('B') if view.format != 'B' or view.ndim != 1 else view
    except (TypeError, ValueError) as exc:
        raise ImageError(f'image data cannot be read as bytes: {exc}') from None
    return np.frombuffer(flat, dtype=np.uint8)


def decode_image(height: int, width: int, encoding: str, is_bigendian: int, step: int,
                 data: Any, max_pixels: Optional[int] = None) -> np.ndarray:
    """
    Return the image held by a ``sensor_msgs/Image``'s fields as a numpy array.

    Colour encodings give BGR uint8 (H, W, 3), mono8 and mono16 give grey
    uint8 (H, W); mono16 keeps its high byte. ``data`` may be bytes,
    bytearray, memoryview or array.array('B') (what rclpy gives); it is read
    without a copy. Bytes past ``width * bytes_per_pixel`` in each row of
    ``step`` bytes are padding and ignored. ``max_pixels``: refuse a larger
    ``width * height`` before touching the data. Raise ImageError, with one
    line naming the problem, for anything that cannot be decoded exactly.
    """
    if not isinstance(encoding, str):
        raise ImageError(f'encoding must be a string, got {type(encoding).__name__}')
    bpp = _BYTES_PER_PIXEL.get(encoding)
    if bpp is None:
        raise ImageError(f'unsupported image encoding {quote(encoding)}; supported: '
                         + ', '.join(SUPPORTED_ENCODINGS))
    height = _as_int(height, 'height')
    width = _as_int(width, 'width')
    step = _as_int(step, 'step')
    if isinstance(is_bigendian, bool):
        is_bigendian = int(is_bigendian)
    is_bigendian = _as_int(is_bigendian, 'is_bigendian')
    if height <= 0 or width <= 0:
        raise ImageError(f'image size must be positive, got {_short(width)}x{_short(height)} '
                         '(width x height)')
    if max_pixels is not None and width * height > max_pixels:
        raise ImageError(f'image of {_short(width)}x{_short(height)} pixels is larger than the '
                         f'limit of {max_pixels} pixels')
    row_bytes = width * bpp
    if step < row_bytes:
        raise ImageError(f'step {_short(step)} is smaller than width * bytes per pixel = '
                         f'{width} * {bpp} = {row_bytes} for {encoding}')
    _check_yuv_width(encoding, width)
    if encoding in _BAYER_CODES and (width < 2 or height < 2):
        raise ImageError(f'{encoding} needs at least 2x2 pixels to demosaic, '
                         f'got {width}x{height}')
    buf = _as_bytes(data)
    expected = height * step
    # ROS defines len(data) == step * height; a different length means the
    # size fields do not describe the data, so any image read would be a guess.
    if buf.size != expected:
        raise ImageError(f'image data has {buf.size} bytes, expected height * step = '
                         f'{height} * {_short(step)} = {_short(expected)} for '
                         f'{width}x{height} {encoding}')

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

    ``image`` is BGR uint8 (H, W, 3) for bgr8, rgb8, the YUV 4:2:2 and the
    Bayer encodings (which lose what those formats lose: half the chroma
    along the rows, two of each pixel's three channels), grey uint8 (H, W)
    or (H, W, 1) for mono8 and mono16; mono16 also takes uint16 grey as is
    and scales uint8 by 257 (so 255 becomes 65535). Rows are packed (step =
    width * bytes per pixel) and 16-bit data is little-endian
    (is_bigendian = 0).
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
    if encoding in _ENCODED_FROM_BGR:
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

    _check_yuv_width(encoding, width)
    if encoding == 'rgb8':
        image = image[:, :, ::-1]
    elif encoding in _YUV_FROM_BGR:
        image = cv2.cvtColor(np.ascontiguousarray(image), _YUV_FROM_BGR[encoding])
    elif encoding in _BAYER_CHANNELS:
        mosaic = np.empty((height, width), np.uint8)
        for k, channel in enumerate(_BAYER_CHANNELS[encoding]):
            dy, dx = divmod(k, 2)
            mosaic[dy::2, dx::2] = image[dy::2, dx::2, channel]
        image = mosaic
    elif encoding == 'mono16':
        if image.dtype == np.uint8:
            image = image.astype(np.uint16) * 257
        image = image.astype('<u2', copy=False)
    packed = np.ascontiguousarray(image)
    step = width * _BYTES_PER_PIXEL[encoding]
    return height, width, encoding, 0, step, packed.tobytes()


def _check_yuv_width(encoding: str, width: int) -> None:
    """Raise ImageError for a YUV 4:2:2 image of odd width (two pixels share a U and a V)."""
    if encoding in _YUV_CODES and width % 2:
        raise ImageError(f'{encoding} (YUV 4:2:2) needs an even width, got {width}')


def image_from_msg(msg: Any, max_pixels: Optional[int] = None) -> np.ndarray:
    """Return the image of a ``sensor_msgs/Image`` (see ``decode_image``)."""
    missing = [name for name in _MSG_FIELDS if not hasattr(msg, name)]
    if missing:
        raise ImageError(f'not a sensor_msgs/Image ({type(msg).__name__[:40]}): missing '
                         'field(s) ' + ', '.join(missing))
    return decode_image(msg.height, msg.width, msg.encoding, msg.is_bigendian, msg.step,
                        msg.data, max_pixels)


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


_INFO_FIELDS = ('width', 'height', 'distortion_model', 'd', 'k')


_ODD = object()


def _float_bytes(values: Any) -> Any:
    """Return the bytes of a float64 array field (what rclpy gives), None, or _ODD."""
    if values is None:
        return None
    if isinstance(values, np.ndarray) and values.dtype == np.float64:
        return values.tobytes()
    if isinstance(values, array.array) and values.typecode == 'd':
        return values.tobytes()
    if isinstance(values, (list, tuple)) and len(values) <= 16 and all(
            type(v) is float for v in values):
        return np.array(values, dtype=np.float64).tobytes()
    return _ODD


def _info_key(msg: Any) -> Optional[tuple]:
    """Return a hashable copy of a CameraInfo's intrinsics fields, or None if they are odd."""
    try:
        roi = getattr(msg, 'roi', None)
        roi_key = None if roi is None else tuple(
            int(getattr(roi, f)) for f in ('x_offset', 'y_offset', 'width', 'height'))
        header = getattr(msg, 'header', None)
        frame = getattr(header, 'frame_id', '')
        arrays = tuple(_float_bytes(getattr(msg, f, None)) for f in ('k', 'd', 'r', 'p'))
        if any(a is _ODD for a in arrays):
            return None
        fields = (msg.width, msg.height, msg.distortion_model, getattr(msg, 'binning_x', 0),
                  getattr(msg, 'binning_y', 0), frame)
        if not all(type(v) in (int, str) for v in fields):
            return None
        return fields + arrays + (roi_key,)
    except (AttributeError, TypeError, ValueError, OverflowError):
        return None


_camera_cache: 'collections.OrderedDict[tuple, CameraModel]' = collections.OrderedDict()
_camera_cache_lock = threading.Lock()
CAMERA_CACHE_SIZE = 8


def camera_from_info(msg: Any) -> CameraModel:
    """
    Return the CameraModel of a ``sensor_msgs/CameraInfo``; CameraError if it is unusable.

    The calibration (width, height, K, D, R, P) is for the whole sensor and
    goes through :func:`~..vision.camera.camera_from_calibration`; the model
    returned is for the images that come with it: the region of interest
    ``roi`` (when its width and height are non-zero) and then binned by
    ``binning_x``, ``binning_y`` (0 = 1), as image_geometry reads them. An
    empty ``d`` means no distortion. The camera's name is
    ``header.frame_id``, cut to 80 characters. Repeated messages with the
    same fields are validated once (a small cache), since camera_info comes
    with every image.
    """
    key = _info_key(msg)
    if key is not None:
        with _camera_cache_lock:
            cached = _camera_cache.get(key)
            if cached is not None:
                _camera_cache.move_to_end(key)
                return cached
    camera = _camera_from_info(msg)
    if key is not None:
        with _camera_cache_lock:
            _camera_cache[key] = camera
            while len(_camera_cache) > CAMERA_CACHE_SIZE:
                _camera_cache.popitem(last=False)
    return camera


def _camera_from_info(msg: Any) -> CameraModel:
    missing = [f for f in _INFO_FIELDS if not hasattr(msg, f)]
    if missing:
        raise CameraError(f'not a sensor_msgs/CameraInfo ({type(msg).__name__[:40]}): missing '
                          'field(s) ' + ', '.join(missing))
    frame = getattr(getattr(msg, 'header', None), 'frame_id', '')
    name = frame[:NAME_CHARS] if isinstance(frame, str) and frame else 'camera'
    model = msg.distortion_model
    try:
        no_distortion = len(msg.d) == 0
    except TypeError:
        no_distortion = False           # camera_from_calibration names the problem
    if no_distortion:
        model = 'none'
    elif model == '':
        model = 'plumb_bob'
    full = camera_from_calibration(msg.width, msg.height, msg.k, msg.d, model,
                                   getattr(msg, 'r', None), getattr(msg, 'p', None),
                                   'camera_info', name)
    x0, y0, width, height = 0, 0, full.width, full.height
    roi = getattr(msg, 'roi', None)
    if roi is not None:
        values = [_camera_int(getattr(roi, f, 0), f'roi.{f}')
                  for f in ('x_offset', 'y_offset', 'width', 'height')]
        if values[2] and values[3]:
            x0, y0, width, height = values
            if x0 + width > full.width or y0 + height > full.height:
                raise CameraError(f'camera_info: roi {width}x{height} at ({x0}, {y0}) is not '
                                  f'inside the {full.width}x{full.height} image')
    bx, by = (max(1, _camera_int(getattr(msg, f, 0), f)) for f in ('binning_x', 'binning_y'))
    if (x0, y0, width, height, bx, by) == (0, 0, full.width, full.height, 1, 1):
        return full
    if width // bx < 1 or height // by < 1:
        raise CameraError(f'camera_info: binning {bx}x{by} leaves no pixel of the '
                          f'{width}x{height} image')
    K = full.K.copy()
    K[0, 2] -= x0
    K[1, 2] -= y0
    K[0] /= bx
    K[1] /= by
    return CameraModel(width // bx, height // by, K, full.D, full.distortion_model, full.name)


def _camera_int(value: Any, name: str) -> int:
    if isinstance(value, bool):
        raise CameraError(f'camera_info: {name} must be an integer, got {value!r}')
    try:
        number = operator.index(value)
    except TypeError:
        raise CameraError(f'camera_info: {name} must be an integer, got '
                          f'{type(value).__name__}') from None
    if not 0 <= number <= MAX_IMAGE_SIDE:
        raise CameraError(f'camera_info: {name} = {number} is out of range '
                          f'(0..{MAX_IMAGE_SIDE})')
    return number


def fill_camera_info(msg, camera: CameraModel) -> None:
    """Fill a sensor_msgs/CameraInfo's size, K, D, R and P from a CameraModel."""
    msg.width, msg.height = int(camera.width), int(camera.height)
    msg.distortion_model = 'plumb_bob' if camera.distortion_model == 'none' else \
        camera.distortion_model
    msg.k = [float(v) for v in camera.K.ravel()]
    msg.d = [float(v) for v in camera.D]
    msg.r = [float(v) for v in np.eye(3).ravel()]
    msg.p = [float(v) for v in np.hstack([camera.K, np.zeros((3, 1))]).ravel()]
