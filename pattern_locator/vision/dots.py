"""
Dots: dark blobs against the local white, found in time linear in the pixels.

Every dot, black or coloured, is dark in at least one channel against the
white card whatever the light's colour, so the per-pixel minimum over B, G, R
is compared with the local white: a max filter on a decimated image. A pixel
belongs to a dot when it is darker than a fraction of that white *and*
darker by several times the local noise, so fine texture (carpet, gravel,
foliage) and the sensor noise of a dark frame do not make thousands of blobs.
The noise is the mean high-pass amplitude, taken where it is lowest nearby:
on a card that is the paper between the dots, in a textured area the texture.

The image is segmented once, decimated by two (as AprilTag does), into
connected components. A far card's small dots are segmented again at full
resolution in a window round its centre (:meth:`DotImage.blobs_in`).

An interlaced frame grabbed while the camera moved shows a comb: its two
fields were exposed a field apart. ``field='auto'`` notices the comb and
then uses one field, interpolating the other rows.
"""

from dataclasses import dataclass, field as dataclass_field
from typing import Optional, Tuple

import cv2
import numpy as np

from . import card_kernels
from .detector_params import DetectorParams
from ..errors import ImageError

# High-pass amplitude (|x - 3x3 mean|, averaged) of Gaussian noise, per sigma.
_HIGHPASS_PER_SIGMA = 0.75
# A far card's pale ring dots: darker than the paper by this fraction of it.
_FAINT_RATIO = 0.12
# Windows up to this many pixels take their darkest channel in one compiled
# pass (about 4x faster at 20 x 20, as fast at 100 x 100, slower beyond).
_COMPILED_DARKEST_PIXELS = 10000
# Rows of a tile of the interlace comb test (:func:`combed`).
_COMB_TILE_ROWS = 16


@dataclass(frozen=True)
class Blobs:
    """
    Connected components of a dot mask, in full-resolution pixel coordinates.

    ``labels`` is the label image they come from, one label pixel covering
    ``scale`` x ``scale`` image pixels from ``origin`` (x, y); ``box`` is
    (x, y, w, h) in label pixels and ``label`` each component's label.
    """

    u: np.ndarray
    v: np.ndarray
    area: np.ndarray        # image pixels
    box: np.ndarray
    label: np.ndarray
    labels: np.ndarray
    scale: int
    origin: Tuple[int, int]

    def __len__(self) -> int:
        return len(self.u)

    def extent(self, j: int) -> float:
        """Half the longer side of component ``j``'s box, image pixels."""
        return 0.5 * self.scale * float(max(self.box[j, 2], self.box[j, 3]))


@dataclass(frozen=True)
class DotImage:
    """One image's segmentation and what later stages measure against."""

    image: np.ndarray           # BGR (or grey) uint8; one field interpolated if `field`
    grey_only: bool
    blobs: Blobs                # the decimated segmentation
    white: np.ndarray           # local white (darkest channel) on a grid, float32
    noise: np.ndarray           # local noise sigma of the darkest channel, same grid
    grid_step: int              # image pixels per grid cell
    field: Optional[str]        # 'even' or 'odd' when one field was used
    params: DetectorParams
    small: np.ndarray           # the image decimated by `scale` (area average)
    scale: int
    _cache: dict = dataclass_field(default_factory=dict, repr=False, compare=False)

    def _grid(self, table: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Bilinear look-up of a grid at image points (1-D, or any shape: the result's)."""
        u = np.asarray(u, dtype=np.float64)
        shape = u.shape
        v = np.asarray(v, dtype=np.float64)
        out = card_kernels.bilinear(table, np.ascontiguousarray(u.ravel()),
                                    np.ascontiguousarray(v.ravel()), self.grid_step)
        return out.reshape(shape)

    def _grid_threshold(self) -> np.ndarray:
        """Return the dot threshold on the grid (made once, when first needed)."""
        cached = self._cache.get('grid_threshold')
        if cached is None:
            # The same margin as the decimated segmentation: its noise is the
            # full resolution's only for white noise, and real noise (JPEG,
            # defocused sensor noise) is seldom white.
            cached = _threshold(self.white, self.noise / self.scale, self.params)
            self._cache['grid_threshold'] = cached
        return cached

    def _full_threshold(self) -> np.ndarray:
        """Return the dot threshold at full resolution (made once, when first needed)."""
        cached = self._cache.get('threshold')
        if cached is None:
            h, w = self.image.shape[:2]
            cached = cv2.resize(self._grid_threshold(), (w, h), interpolation=cv2.INTER_LINEAR)
            self._cache['threshold'] = cached
        return cached

    def _threshold_in(self, x0: int, y0: int, x1: int, y1: int) -> np.ndarray:
        """
        Return the full-resolution dot threshold in the window [x0, x1) x [y0, y1).

        The pixels of :meth:`_full_threshold` there, bit for bit; when the
        image is a whole number of grid cells (the usual sizes), by
        resizing only the cells round the window: a window is a small part
        of the image. Bilinear resizing by a whole factor maps each pixel
        from the same two cells with the same weights in the part as in
        the whole, away from the part's border (a cell kept beyond the
        window on every side).
        """
        grid = self._grid_threshold()
        h, w = self.image.shape[:2]
        gh, gw = grid.shape
        if w % gw or h % gh or x1 <= x0 or y1 <= y0:
            return self._full_threshold()[y0:y1, x0:x1]
        kx, ky = w // gw, h // gh
        c0, c1 = max(0, x0 // kx - 1), min(gw, (x1 - 1) // kx + 2)
        r0, r1 = max(0, y0 // ky - 1), min(gh, (y1 - 1) // ky + 2)
        part = cv2.resize(np.ascontiguousarray(grid[r0:r1, c0:c1]),
                          ((c1 - c0) * kx, (r1 - r0) * ky), interpolation=cv2.INTER_LINEAR)
        return part[y0 - r0 * ky:y1 - r0 * ky, x0 - c0 * kx:x1 - c0 * kx]

    def white_at(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Local white of the darkest channel at image points (bilinear on the grid)."""
        return self._grid(self.white, u, v)

    def noise_at(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Noise sigma of the darkest channel at full resolution, at image points."""
        return self._grid(self.noise, u, v)

    def darkest(self, ys: np.ndarray, xs: np.ndarray) -> np.ndarray:
        """Darkest channel of the image at integer pixels (any array shape)."""
        pixels = self.image[ys, xs]
        return pixels if self.grey_only else pixels.min(axis=-1)

    def peak_darkness(self, u: np.ndarray, v: np.ndarray,
                      white: Optional[np.ndarray] = None) -> np.ndarray:
        """Darkness (1 - darkest channel / local white) of the decimated image at image points."""
        s = self.scale
        h, w = self.small.shape[:2]
        x = np.clip((np.asarray(u) / s).astype(np.intp), 0, w - 1)
        y = np.clip((np.asarray(v) / s).astype(np.intp), 0, h - 1)
        pixels = self.small[y, x]
        dark = pixels if pixels.ndim == 1 else pixels.min(axis=-1)
        white = self.white_at(u, v) if white is None else white
        return 1.0 - dark / np.maximum(white, 1.0)

    def faint_rings(self, u: np.ndarray, v: np.ndarray, reach: np.ndarray,
                    max_area: np.ndarray, white: np.ndarray, noise: np.ndarray,
                    radius: np.ndarray, min_spots: int, decimated: bool = True
                    ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """
        Tell whether faint dark spots ring each of the small blobs at (u, v).

        On the decimated image, with a threshold more lenient than the
        segmentation's (12 % of the local white, or 5 noise sigmas): a far
        card's ring dots, a few pixels across, are too pale once decimated
        to be blobs, but still darker than the paper round them. Per blob:
        the spots (at most ``max_area`` image pixels) within ``reach`` of
        it, and whether at least ``min_spots`` of them ring it (beyond 1.5
        times its ``radius``, all round, their mean near it). ``white`` and
        ``noise`` are :meth:`white_at` and :meth:`noise_at` there. Returns
        per blob (ring-like, number of ring spots, area of the spot at the
        blob itself: 0 if it is not dark at this threshold). One compiled
        call for all (:func:`.card_kernels.faint_rings`). ``decimated=False``
        looks at the full-resolution image instead, with the full
        resolution's noise: a softly focused far card's dots, a pixel or two
        apart once decimated, merge there into one ring-shaped spot.
        """
        u, v, reach, max_area, white, noise, radius = (
            np.ascontiguousarray(a, dtype=np.float64)
            for a in (u, v, reach, max_area, white, noise, radius))
        return card_kernels.faint_rings(
            self.kernel_view(decimated=decimated), u, v, reach, max_area, white, noise, radius,
            int(self.scale) if decimated else 1, _FAINT_RATIO, int(self.params.min_white),
            int(min_spots))

    def kernel_view(self, decimated: bool) -> np.ndarray:
        """
        Return the image (or its decimation) as the kernels take it: (H, W, C), read-only.

        Grey as one channel, and read-only (a ROS image's buffer is): one
        signature for the kernels, not one compiled for each. Made once per
        image.
        """
        key = 'view_small' if decimated else 'view_image'
        view = self._cache.get(key)
        if view is None:
            view = _read_only(self.small if decimated else self.image)
            self._cache[key] = view
        return view

    def blobs_in(self, x0: int, y0: int, x1: int, y1: int) -> Blobs:
        """Segment the window [x0, x1) x [y0, y1) again at full resolution."""
        h, w = self.image.shape[:2]
        x0, y0, x1, y1 = max(0, x0), max(0, y0), min(w, x1), min(h, y1)
        darkest = _darkest_in(self.image, x0, y0, x1, y1)
        mask = cv2.compare(darkest, self._threshold_in(x0, y0, x1, y1), cv2.CMP_LT)
        # Components cut by the window's edge are dropped: not whole dots.
        return _components(mask, 1, (x0, y0), self.params.max_dot_area_fraction * h * w)


def check_image(image: np.ndarray) -> np.ndarray:
    """Return ``image`` as contiguous BGR or grey uint8; ImageError naming what is wrong."""
    if not isinstance(image, np.ndarray):
        raise ImageError(f'image must be a numpy array, got {type(image).__name__}')
    if image.dtype != np.uint8:
        raise ImageError(f'image must be 8-bit (uint8), got {image.dtype}')
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    if image.ndim == 3 and image.shape[2] == 4:
        image = image[:, :, :3]
    if not (image.ndim == 2 or (image.ndim == 3 and image.shape[2] == 3)):
        raise ImageError(f'image must be HxW grey or HxWx3 BGR, got shape {image.shape}')
    if image.shape[0] < 16 or image.shape[1] < 16:
        raise ImageError(f'image too small: {image.shape[1]}x{image.shape[0]}')
    return np.ascontiguousarray(image)


def segment(image: np.ndarray, params: DetectorParams) -> DotImage:
    """Segment a checked image (see :func:`check_image`) into dots."""
    field = params.field
    grey = image.ndim == 2
    h, w = image.shape[:2]
    s = params.decimate if min(h, w) >= 48 * params.decimate else 1
    halves = s == 2 and not grey
    halved = None
    if halves and field in ('auto', 'frame'):
        # Halved, its darkest channel and (field 'auto') the comb test in one
        # pass over the frame (card_kernels.halve: OpenCV's area resize, the
        # minimum over B, G, R and combed()'s tiles, to the bit).
        halved = card_kernels.halve(_read_only(image), _COMB_TILE_ROWS if field == 'auto' else 0)
        if field == 'auto':
            field = 'even' if halved[2] >= 2 else 'frame'
    elif field == 'auto':
        field = 'even' if combed(image) else 'frame'
    if field in ('even', 'odd'):
        # One field (set, or a comb found): the frame halved is not this image.
        image = one_field(image, field)
        halved = card_kernels.halve(_read_only(image), 0) if halves else None
    if halved is not None:
        small, coarse = halved[0], halved[1]
    elif s == 2:
        h2, w2 = h // 2, w // 2
        view = image[:2 * h2, :2 * w2]
        small = coarse = cv2.resize(view if view.flags['C_CONTIGUOUS']
                                    else np.ascontiguousarray(view), (w2, h2),
                                    interpolation=cv2.INTER_AREA)
    else:
        small = image
        coarse = small if grey else _min_channel(small)
    # Local white and noise on a grid four times coarser.
    ch, cw = coarse.shape
    gh, gw = max(1, ch // 4), max(1, cw // 4)
    grid = cv2.resize(coarse, (gw, gh), interpolation=cv2.INTER_AREA)
    step = 4 * s
    k = max(3, int(params.white_window // step) | 1)
    white = cv2.dilate(grid, cv2.getStructuringElement(cv2.MORPH_RECT, (k, k)))
    white = cv2.blur(white, (3, 3)).astype(np.float32)
    highpass = cv2.absdiff(coarse, cv2.blur(coarse, (3, 3)))
    noise = cv2.resize(highpass, (gw, gh), interpolation=cv2.INTER_AREA).astype(np.float32)
    # The quietest place nearby: the paper of a card, the texture of a carpet.
    noise = cv2.erode(noise, np.ones((5, 5), np.uint8)) / _HIGHPASS_PER_SIGMA
    # Coarse-image noise to full-resolution noise (decimation averages s*s pixels).
    noise *= s
    grid_threshold = _threshold(white, noise / s, params)
    threshold = cv2.resize(grid_threshold, (cw, ch), interpolation=cv2.INTER_LINEAR)
    mask = cv2.compare(coarse, threshold, cv2.CMP_LT)
    blobs = _components(mask, s, (0, 0), params.max_dot_area_fraction * h * w / (s * s))
    # The grid threshold kept: the full-resolution windows resize it
    # (DotImage._grid_threshold makes the same from white and noise).
    return DotImage(image, grey, blobs, white, noise, step,
                    field if field in ('even', 'odd') else None, params, small, s,
                    {'grid_threshold': grid_threshold})


def _threshold(white: np.ndarray, noise: np.ndarray, params: DetectorParams) -> np.ndarray:
    """Grey level below which a pixel is dot, from the local white and noise."""
    # Ink is at least half as dark as the paper is bright, whatever the
    # noise: a card next to a busy scene (where the noise is measured) keeps
    # its dots. The margin is the larger of (1 - dark_ratio) white and
    # noise_factor noise (at most half the white), at least 2 grey levels;
    # no dots where the white is below min_white (card_kernels.threshold).
    # float32, as the grids are (any shape: one kernel signature, 2-D).
    white = np.asarray(white, dtype=np.float32)
    noise = np.asarray(noise, dtype=np.float32)
    if white.shape != noise.shape:
        white, noise = np.broadcast_arrays(white, noise)
    shape = white.shape
    return card_kernels.threshold(
        np.ascontiguousarray(white.reshape(1, -1) if white.ndim != 2 else white),
        np.ascontiguousarray(noise.reshape(1, -1) if noise.ndim != 2 else noise),
        np.float32(1.0 - params.dark_ratio), np.float32(params.noise_factor),
        int(params.min_white)).reshape(shape)


def _components(mask: np.ndarray, scale: int, origin: Tuple[int, int],
                max_area: float) -> Blobs:
    """Label a mask's components that could be dots (round, whole, at most max_area)."""
    # OpenCV's labelling and statistics to the bit (Grana's numbering), in
    # half their time: its statistics pass cost three times its labelling.
    labels, stats, centroids = card_kernels.label_components(mask)
    h, w = mask.shape
    # Round dots fill a good part of their box and are not long and thin (a
    # 75-degree tilt makes a dot about 4:1); a dot cut by the border has a
    # false centre. (card_kernels.dot_components: the tests and the centres.)
    idx, u, v = card_kernels.dot_components(stats, centroids, int(scale), int(origin[0]),
                                            int(origin[1]), float(max_area), h, w)
    s = float(scale)
    return Blobs(u, v, stats[idx, cv2.CC_STAT_AREA].astype(float) * s * s, stats[idx, :4],
                 idx.astype(np.int32), labels, scale, origin)


def _darkest_in(image: np.ndarray, x0: int, y0: int, x1: int, y1: int) -> np.ndarray:
    """Darkest channel of the window [x0, x1) x [y0, y1) of a grey or BGR image."""
    if image.ndim == 2:
        return image[y0:y1, x0:x1]
    if (x1 - x0) * (y1 - y0) > _COMPILED_DARKEST_PIXELS:
        # OpenCV's vectorised erosion wins on big windows despite the copy.
        return _min_channel(np.ascontiguousarray(image[y0:y1, x0:x1]))
    # Read-only, as a ROS image's buffer is: one compiled signature.
    return card_kernels.darkest_in(_read_only(image), x0, y0, x1, y1)


def _min_channel(image: np.ndarray) -> np.ndarray:
    """Per-pixel minimum over B, G, R: an erosion along the interleaved row."""
    h, w = image.shape[:2]
    rows = cv2.erode(image.reshape(h, w * 3), np.ones((1, 3), np.uint8))
    return np.ascontiguousarray(rows[:, 1::3])


def combed(image: np.ndarray, tile_rows: int = _COMB_TILE_ROWS) -> bool:
    """
    Tell whether the image is an interlaced frame whose two fields disagree.

    In a progressive image a row is closer to its neighbours than to the rows
    two away (or as close, in noise); when the camera moved between the
    fields, the rows of one field disagree with the other field's in every
    moving area: the curvature over one row exceeds that over two, by far.
    Measured on every sixteenth column, in tiles, so that one small card
    moving against a still background is enough.
    """
    # Per tile of `tile_rows` rows and four sampled columns of the green
    # channel, the curvature over one row and over two, summed
    # (card_kernels.combed_tiles): a tile counts when its one-row curvature
    # is strong (6 levels a pixel on average) and three times its two-row
    # curvature. One argument type for the kernel (each compiles again, for
    # seconds): contiguous, 3-D and read-only (a ROS image's buffer is).
    return card_kernels.combed_tiles(_read_only(image), int(tile_rows)) >= 2


def _read_only(image: np.ndarray) -> np.ndarray:
    """Return ``image`` as the kernels take a frame: contiguous (H, W, C) and read-only."""
    image = np.ascontiguousarray(image)
    view = (image if image.ndim == 3 else image[:, :, None]).view()
    view.flags.writeable = False
    return view


def one_field(image: np.ndarray, field: str) -> np.ndarray:
    """Keep the ``even`` or ``odd`` rows of a frame, interpolating the other rows between them."""
    h = image.shape[0]
    first = 0 if field == 'even' else 1
    rows = np.ascontiguousarray(image[first::2])
    out = np.empty_like(image)
    out[first::2] = rows
    if len(rows) > 1:
        between = cv2.addWeighted(rows[:-1], 0.5, rows[1:], 0.5, 0.0)
        out[first + 1:first + 1 + 2 * len(between):2] = between
    # The row beyond the last (or before the first) kept row copies its neighbour.
    if first == 0 and h % 2 == 0:
        out[h - 1] = rows[-1]
    if first == 1:
        out[0] = rows[0]
        if h % 2 == 1:
            out[h - 1] = rows[-1]
    return out
