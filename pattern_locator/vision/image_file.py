"""
Image files for the command line, read with bounded cost and one-line errors.

:func:`read_image` refuses what a bad file could do to a plain
``cv2.imread``: a FIFO or a directory (hang, odd error), a header declaring
a huge image (decoded in full, gigabytes, before any size check), a
truncated or corrupt file (decoded with grey or garbage where the data
ended) and the native libraries' messages on the terminal (libpng and
libjpeg write to file descriptor 2 themselves).

The file's header is parsed here for the formats whose size is easy to
read (PNG, JPEG, BMP, PBM/PGM/PPM, TIFF), so that the pixel count is known
before anything is decoded; other formats are refused. The decode itself
is OpenCV's, with fd 2 sent to a temporary file: a warning from a decoder
(libjpeg's "Corrupt JPEG data") means the image is not the file's, so it
is refused with the warning as the reason.
"""

import contextlib
from dataclasses import dataclass
import mmap
import os
from pathlib import Path
import re
import struct
import sys
import tempfile
import threading
from typing import Callable, Dict, Iterator, Optional, Tuple, Union
import zlib

import cv2
import numpy as np

from ..errors import ImageError
from ..resources import open_regular_file

DEFAULT_MAX_PIXELS = 25_000_000          # a 6000 x 4000 photo; the CLI has an option
FORMATS = ('PNG', 'JPEG', 'BMP', 'PNM', 'TIFF')
MESSAGE_CHARS = 120                      # a decoder's message is cut to this


@dataclass(frozen=True)
class ImageHeader:
    """What an image file's header declares: its format and size in pixels."""

    file_format: str
    width: int
    height: int

    @property
    def pixels(self) -> int:
        """Return width * height."""
        return self.width * self.height


def read_image(path: Union[str, Path], max_pixels: int = DEFAULT_MAX_PIXELS) -> np.ndarray:
    """
    Return an image file's pixels as the detector takes them; ImageError if not.

    BGR uint8 (H, W, 3) for colour files (alpha dropped), grey uint8 (H, W)
    for grey ones (the detector then finds geometry, no code); 16-bit files
    keep their high byte; EXIF orientation is not applied (the pixels are
    the sensor's, as the camera file describes them). Refused, before any
    decoding: anything but a regular file, an empty file, a format whose
    header is not read here, a header over ``max_pixels`` pixels, a file
    cut short (no PNG IEND chunk, a PNG chunk past the end or with a bad
    CRC, no JPEG end-of-image marker, BMP/PNM/TIFF pixel data past the
    end). Then refused: anything the decoder fails on or warns about.
    Every ImageError is one line starting with ``path``.
    """
    name = str(path)
    with _mapped(name) as data:
        header = read_header(data, name)
        if header.pixels > max_pixels:
            raise ImageError(f'{name}: image of {header.width}x{header.height} pixels is '
                             f'larger than the limit of {max_pixels} pixels')
        try:
            _CHECKS[header.file_format](data, name)
        except struct.error:
            raise _truncated(name, header.file_format, 'a field past the end') from None
        image, messages = _decode(data)
    if image is None:
        reason = f' ({messages})' if messages else ''
        raise ImageError(f'{name}: cannot decode the {header.file_format} image{reason}')
    if messages and header.file_format != 'TIFF':
        # libtiff warns about harmless things (unknown tags); the others only
        # warn when the data is corrupt.
        raise ImageError(f'{name}: corrupt {header.file_format} image ({messages})')
    return _as_detector_image(image, header, name)


def read_header(data: Union[bytes, mmap.mmap], name: str = 'image') -> ImageHeader:
    """Return the format and size an image file's bytes declare; ImageError if unknown."""
    try:
        return _read_header(data, name)
    except struct.error:
        raise ImageError(f'{name}: truncated or corrupt image header') from None


def _read_header(data: Union[bytes, mmap.mmap], name: str) -> ImageHeader:
    head = bytes(data[:16])
    if head.startswith(b'\x89PNG\r\n\x1a\n'):
        header = _png_header(data, name)
    elif head.startswith(b'\xff\xd8\xff'):
        header = _jpeg_header(data, name)
    elif head.startswith(b'BM'):
        header = _bmp_header(data, name)
    elif re.match(rb'P[1-6]\s', head):
        header = _pnm_header(data, name)[0]
    elif head[:4] in (b'II*\x00', b'MM\x00*'):
        header = _tiff_header(data, name)[0]
    else:
        raise ImageError(f'{name}: not an image file this reader knows (supported: '
                         f'{", ".join(FORMATS)})')
    if header.width <= 0 or header.height <= 0:
        raise ImageError(f'{name}: {header.file_format} header declares an empty image '
                         f'({header.width}x{header.height})')
    return header


# Files -----------------------------------------------------------------------------

@contextlib.contextmanager
def _mapped(name: str) -> Iterator[mmap.mmap]:
    """Map a regular file read-only (pages are read only when touched)."""
    fd, info = open_regular_file(name, 'the image', ImageError)
    try:
        if info.st_size == 0:
            raise ImageError(f'{name}: the image file is empty')
        try:
            data = mmap.mmap(fd, 0, access=mmap.ACCESS_READ)
        except (OSError, ValueError) as exc:
            raise ImageError(f'{name}: cannot read the image ({exc})') from None
    finally:
        os.close(fd)
    try:
        yield data
    finally:
        try:
            data.close()
        except BufferError:
            pass           # an error's traceback still holds a view: closed when freed


_stderr_lock = threading.Lock()
_OPENCV_LOG_PREFIX = re.compile(r'^\s*\[[^\]]*\]\s*(global\s+\S+:\d+\s+\S+\s+)?')


@contextlib.contextmanager
def _stderr_to_file() -> Iterator[Callable[[], str]]:
    """
    Send file descriptor 2 to a temporary file; yield a function that reads it.

    The native decoders write their messages there themselves. The lock
    keeps two decodes from swapping fd 2 under each other; anything another
    thread writes to stderr meanwhile lands in the file too (a CLI has no
    such thread). If fd 2 cannot be duplicated, nothing is captured.
    """
    with _stderr_lock, tempfile.TemporaryFile() as sink:
        try:
            sys.stderr.flush()
        except (AttributeError, OSError, ValueError):
            pass
        try:
            saved = os.dup(2)
        except OSError:
            yield lambda: ''
            return
        try:
            os.dup2(sink.fileno(), 2)

            def captured() -> str:
                sink.seek(0)
                return sink.read(64 * 1024).decode('utf-8', 'replace')
            yield captured
        finally:
            os.dup2(saved, 2)
            os.close(saved)


def _decode(data: mmap.mmap) -> Tuple[Optional[np.ndarray], str]:
    """Return OpenCV's decode of the bytes and what the decoder printed (one line)."""
    with _stderr_to_file() as captured:
        image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
        text = captured()
    # OpenCV's own log lines start "[ERROR:0@0.069] global file.cpp:117 Function".
    lines = [_OPENCV_LOG_PREFIX.sub('', line).strip() for line in text.splitlines()]
    message = '; '.join(line for line in lines if line)
    if len(message) > MESSAGE_CHARS:
        message = message[:MESSAGE_CHARS - 3] + '...'
    return image, message


def _as_detector_image(image: np.ndarray, header: ImageHeader, name: str) -> np.ndarray:
    """Return BGR or grey uint8 as the detector takes it; ImageError for other pixels."""
    if image.shape[:2] != (header.height, header.width):
        raise ImageError(f'{name}: decoded {image.shape[1]}x{image.shape[0]} pixels, but the '
                         f'header declares {header.width}x{header.height}')
    if image.dtype == np.uint16:
        image = (image >> 8).astype(np.uint8)
    if image.dtype != np.uint8:
        raise ImageError(f'{name}: unsupported pixel type {image.dtype} (use 8 or 16 bits)')
    if image.ndim == 3:
        channels = image.shape[2]
        if channels == 4:
            image = cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
        elif channels in (1, 2):
            image = np.ascontiguousarray(image[:, :, 0])      # grey (and alpha)
        elif channels != 3:
            raise ImageError(f'{name}: unsupported image with {channels} channels')
    return image


# Headers and completeness, per format --------------------------------------------------

def _u16(data, offset: int, order: str = '>') -> int:
    return struct.unpack_from(order + 'H', data, offset)[0]


def _u32(data, offset: int, order: str = '>') -> int:
    return struct.unpack_from(order + 'I', data, offset)[0]


def _truncated(name: str, fmt: str, detail: str) -> ImageError:
    return ImageError(f'{name}: truncated or corrupt {fmt} file ({detail})')


def _png_header(data, name: str) -> ImageHeader:
    if len(data) < 33 or bytes(data[12:16]) != b'IHDR' or _u32(data, 8) != 13:
        raise _truncated(name, 'PNG', 'no IHDR chunk')
    return ImageHeader('PNG', _u32(data, 16), _u32(data, 20))


def _png_check(data, name: str) -> None:
    """Walk the chunks: each inside the file, each CRC right, an IEND at the end."""
    view = memoryview(data)
    try:
        pos, size = 8, len(data)
        while pos + 12 <= size:
            length = _u32(data, pos)
            kind = bytes(data[pos + 4:pos + 8])
            end = pos + 12 + length
            shown = kind.decode('latin-1').encode('unicode_escape').decode()
            if end > size:
                raise _truncated(name, 'PNG', f'chunk {shown} runs past the end')
            if zlib.crc32(view[pos + 4:end - 4]) != _u32(data, end - 4):
                raise _truncated(name, 'PNG', f'CRC error in chunk {shown}')
            if kind == b'IEND':
                return
            pos = end
        raise _truncated(name, 'PNG', 'no IEND chunk')
    finally:
        view.release()


# SOFn markers: every C0..CF but DHT (C4), JPG (C8) and DAC (CC).
_JPEG_SOF = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}


def _jpeg_sos(data, name: str) -> tuple:
    """Walk the segments before the first scan; return (header, offset after SOS)."""
    pos, size, header = 2, len(data), None
    while True:
        if pos + 4 > size:
            raise _truncated(name, 'JPEG', 'ends inside its header')
        if data[pos] != 0xFF:
            raise _truncated(name, 'JPEG', f'no marker at byte {pos}')
        while pos + 4 < size and data[pos + 1] == 0xFF:
            pos += 1                           # fill bytes before a marker
        marker = data[pos + 1]
        if marker == 0x01 or 0xD0 <= marker <= 0xD7:
            pos += 2
            continue
        if marker == 0xD9:
            raise _truncated(name, 'JPEG', 'end of image before any scan')
        length = _u16(data, pos + 2)
        if length < 2 or pos + 2 + length > size:
            raise _truncated(name, 'JPEG', f'segment at byte {pos} runs past the end')
        if marker in _JPEG_SOF:
            if length < 8:
                raise _truncated(name, 'JPEG', 'short frame header')
            header = ImageHeader('JPEG', _u16(data, pos + 7), _u16(data, pos + 5))
        if marker == 0xDA:
            if header is None:
                raise _truncated(name, 'JPEG', 'a scan before the frame header')
            return header, pos + 2 + length
        pos += 2 + length


def _jpeg_header(data, name: str) -> ImageHeader:
    header = _jpeg_sos(data, name)[0]
    if header.height == 0:
        raise ImageError(f'{name}: JPEG whose height comes after the image data (DNL) is not '
                         'supported')
    return header


def _jpeg_check(data, name: str) -> None:
    # In entropy-coded data 0xFF is always followed by 0x00 or a marker, and
    # EOI (FF D9) only ends the image: the first one after the scans is it.
    start = _jpeg_sos(data, name)[1]
    if data.find(b'\xff\xd9', start) < 0:
        raise _truncated(name, 'JPEG', 'no end-of-image marker')


def _bmp_layout(data, name: str) -> tuple:
    """Return (header, pixel data offset, bytes per row, bits per pixel, compression)."""
    if len(data) < 26:
        raise _truncated(name, 'BMP', 'ends inside its header')
    offset, dib = _u32(data, 10, '<'), _u32(data, 14, '<')
    if dib == 12:
        width, height = _u16(data, 18, '<'), _u16(data, 20, '<')
        bpp, compression = _u16(data, 24, '<'), 0
    elif dib >= 40 and len(data) >= 34:
        width, height = struct.unpack_from('<ii', data, 18)
        bpp, compression = _u16(data, 28, '<'), _u32(data, 30, '<')
    else:
        raise _truncated(name, 'BMP', f'unknown header of {dib} bytes')
    header = ImageHeader('BMP', width, abs(height))
    return header, offset, ((bpp * max(width, 0) + 31) // 32) * 4, bpp, compression


def _bmp_header(data, name: str) -> ImageHeader:
    return _bmp_layout(data, name)[0]


def _bmp_check(data, name: str) -> None:
    header, offset, row, bpp, compression = _bmp_layout(data, name)
    if compression not in (0, 3, 6):           # BI_RGB, BI_BITFIELDS, BI_ALPHABITFIELDS
        raise ImageError(f'{name}: compressed BMP (compression {compression}) is not '
                         'supported')
    if bpp not in (1, 4, 8, 16, 24, 32):
        raise ImageError(f'{name}: BMP with {bpp} bits per pixel is not supported')
    if offset + row * header.height > len(data):
        raise _truncated(name, 'BMP', 'pixel data runs past the end')


_PNM_TOKEN = re.compile(rb'(?:\s|#[^\n\r]*)*(\d+)')


def _pnm_header(data, name: str) -> tuple:
    """Return (header, offset of the raster, channels, bytes per sample)."""
    kind = data[1] - ord('0')
    fields = 2 if kind in (1, 4) else 3
    values, pos = [], 2
    head = bytes(data[:4096])
    for _ in range(fields):
        match = _PNM_TOKEN.match(head, pos)
        if match is None:
            raise _truncated(name, 'PNM', 'header is not P<n> width height [maxval]')
        values.append(int(match.group(1)))
        pos = match.end()
    maxval = values[2] if fields == 3 else 1
    if not 0 < maxval < 65536:
        raise _truncated(name, 'PNM', f'maxval {maxval} is not 1..65535')
    channels = 3 if kind in (3, 6) else 1
    return (ImageHeader('PNM', values[0], values[1]), pos + 1, channels,
            1 if maxval < 256 else 2)


def _pnm_check(data, name: str) -> None:
    header, start, channels, width = _pnm_header(data, name)
    kind = data[1] - ord('0')
    samples = header.pixels * channels
    if kind == 4:
        needed = (header.width + 7) // 8 * header.height
    elif kind in (5, 6):
        needed = samples * width
    else:
        # Plain (text) formats: count digits (P1) or numbers (P2, P3).
        body = np.frombuffer(data, np.uint8)[start - 1:]
        if kind == 1:
            found = int(np.count_nonzero((body == ord('0')) | (body == ord('1'))))
        else:
            digit = (body >= ord('0')) & (body <= ord('9'))
            found = int(np.count_nonzero(digit[1:] & ~digit[:-1]))
        if found < samples:
            raise _truncated(name, 'PNM', f'{found} of {samples} samples')
        return
    if start + needed > len(data):
        raise _truncated(name, 'PNM', 'pixel data runs past the end')


_TIFF_SIZES = {1: 1, 3: 2, 4: 4, 16: 8}        # BYTE, SHORT, LONG, LONG8


def _tiff_entries(data, name: str) -> tuple:
    """Return (byte order, {tag: values}) of the first IFD (the page OpenCV reads)."""
    order = '<' if bytes(data[:2]) == b'II' else '>'
    if len(data) < 8:
        raise _truncated(name, 'TIFF', 'ends inside its header')
    ifd = _u32(data, 4, order)
    if ifd + 2 > len(data):
        raise _truncated(name, 'TIFF', 'directory past the end')
    count = _u16(data, ifd, order)
    if ifd + 2 + 12 * count > len(data):
        raise _truncated(name, 'TIFF', 'directory runs past the end')
    entries: Dict[int, list] = {}
    for i in range(count):
        at = ifd + 2 + 12 * i
        tag, kind, n = struct.unpack_from(order + 'HHI', data, at)
        size = _TIFF_SIZES.get(kind)
        if size is None or tag not in (256, 257, 273, 279, 324, 325):
            continue
        where = at + 8 if size * n <= 4 else _u32(data, at + 8, order)
        if n > 1 << 24 or where + size * n > len(data):
            raise _truncated(name, 'TIFF', f'tag {tag} values past the end')
        code = {1: 'B', 2: 'H', 4: 'I', 8: 'Q'}[size]
        entries[tag] = list(struct.unpack_from(f'{order}{n}{code}', data, where))
    return order, entries


def _tiff_header(data, name: str) -> tuple:
    entries = _tiff_entries(data, name)[1]
    if not entries.get(256) or not entries.get(257):
        raise _truncated(name, 'TIFF', 'no image width or length')
    return ImageHeader('TIFF', entries[256][0], entries[257][0]), entries


def _tiff_check(data, name: str) -> None:
    entries = _tiff_header(data, name)[1]
    for offsets, counts in ((273, 279), (324, 325)):
        if offsets in entries:
            starts, sizes = entries[offsets], entries.get(counts, [])
            if len(sizes) != len(starts):
                raise _truncated(name, 'TIFF', 'strip or tile sizes missing')
            if any(s + n > len(data) for s, n in zip(starts, sizes)):
                raise _truncated(name, 'TIFF', 'image data runs past the end')
            return
    raise _truncated(name, 'TIFF', 'no image data')


_CHECKS: Dict[str, Callable[..., None]] = {
    'PNG': _png_check, 'JPEG': _jpeg_check, 'BMP': _bmp_check, 'PNM': _pnm_check,
    'TIFF': _tiff_check,
}
