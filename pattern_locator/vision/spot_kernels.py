"""
Compiled per-pixel passes of the sub-pixel centres (:mod:`.centres`).

The centres stage measures a card's 17 dots in windows of some 25 x 25
pixels. As numpy calls over all of a card's windows at once, its time was
the fixed cost of a few hundred small calls per card, not the pixels; here
each pass over a group of windows is a loop over the windows, then their
pixels, and :func:`measure` runs all the passes of a card's spots in one
call. What is measured, and why, is :mod:`.centres`'s documentation; these
kernels only do its arithmetic.

The per-pixel quantities are computed in float32 in the same order as the
numpy code they replace (so that a pixel on an ellipse's edge or a
threshold falls on the same side), the sums over a window in float64.

The kernels keep the GIL (``nogil=False``): each lasts a fraction of a
millisecond, and one that lets it go must get it back from the node's
other threads (the executor taking images and joint states), up to the
interpreter's switch interval (5 ms) each time, a dozen times a frame: in
the closed-loop demo under load that cost a third of the locations.

numba checks no bounds: every index computed here is tested against the
window's size or clipped to the image's shape before use. The caller
validates the geometry (finite, windows no bigger than a quarter of the
image) before calling.
"""

import numba
import numpy as np

from .card_kernels import _h_jacobian, _map_point, _median, bilinear as _bilinear

_F32 = np.float32
# The paper round a dot, between these many of its own radii (clear of its
# blur and of the next dot of either ring, the marks' edges a minority),
# is its white where the local white grid (a max filter) lies above it by
# more than _FLANK: on the flank of a highlight (a glossy card under a
# lamp) the grid's white is the brighter paper nearer the highlight, and
# the paper round the dot then read as ink. Flat light leaves the two
# within a few per cent, and nothing changes.
_PAPER_RING = (1.6, 2.2)
_FLANK = 0.08
_MIN_PAPER_PIXELS = 12
# A highlight's flank also tilts the paper across a dot, and a dot's
# darkness below a level white is then heavier on its darker side: its
# centroid moves towards it (a tenth of a pixel where the light added
# changes by 2-6 % of the paper's across the dot, half a pixel at 20-60 %:
# on a glossy card, poses whose covariance did not cover their error).
# Where a plane fitted to the dot's own paper changes by more than _TILT
# of its level across the dot, by more than _TILT_NOISE times the noise,
# with a slope _TILT_SURE (a chi-square) clear of its own uncertainty,
# and the paper lies on it (_TILT_FIT), the dot's darkness is taken below
# the plane (:func:`_paper_tilt`). Samples more than _TILT_OUTLIER of the
# level below a first fit (an object) are left out of the second. Dots
# under _TILT_MIN_SEMI_AXIS source pixels keep a level white: their rings
# hold their neighbours' blur.
_TILT = 0.02
_TILT_NOISE = 2.0
_TILT_SURE = 25.0
_TILT_FIT = 0.015
_TILT_OUTLIER = 0.06
_TILT_MIN_SEMI_AXIS = 2.5
# Colour channels shifted against each other (a cheap lens, composite
# video): a dot's darkest channel is dark where any of its dark channels'
# images is, darker where the darkest ink channel's is, so its centroid
# lies nearer that channel's image than the channels' mean (a green dot,
# dark in red and less in blue, 0.14-0.19 px towards red per pixel of
# shift: far near-frontal poses 10-20 cm and 8 sigmas off). Beyond this
# shift (pixels), each dot's centre is its channels' own centroids, each
# less its shift, where the dot is big enough that its window holds
# every channel's image whole: a semi-minor axis of _OWN_CHANNELS_SIZE
# shifts (smaller dots, cut, came out up to 0.6 px off).
_OWN_CHANNELS_FROM = 0.25
_OWN_CHANNELS_SIZE = 2.5
# A far card's dots are a pixel or two across, and their colour is greyed
# at its peak: JPEG and 4:2:0 video keep colour at half resolution, and
# composite video blurs it along the line, so a dot's colour is spread
# round it (its luminance is not). Summed over the dot grown by
# _VOLUME_GROW pixels (in its cell, apart from other dark regions), each
# channel keeps its darkness, and the colour's direction is the ink's
# again. A card whose dots' median radius (the geometric mean of their
# semi-axes, image pixels) is below _VOLUME_BELOW gets these colours too,
# every dot's alike (the inks are represented by the ring's own dots, so
# the centre must be measured as they are), each with its peak's
# strength; the detector reads them where the peaks give no whole code
# (they take in a neighbour's spread colour, which the peaks do not). On
# 400 far frames (5.5-8 m), sums over the dot grown by 1, 1.5 and 2
# pixels found 9, 11 and 8 more cards than the peaks (375) when read
# instead of them; by 3 pixels, 2 more.
_VOLUME_GROW = 1.5
_VOLUME_BELOW = 2.5
# A glossy card's highlight adds light over ink and paper alike, so its
# dots' colours, read against the card's one white, fade towards grey: a
# black centre under it read 0.6 dark in every channel, the black dots
# beside it 0.92, and the card gave no code. Where the paper round a dot
# (the upper quartile of its darkest channel between _PAPER_RING of its
# radii) is brighter than the card's white (its darkest channel) by
# _LIFT_FROM or more in linear light, the light added there is added back
# to the dot's darkness, channel by channel: the excess of that paper's
# upper quartile over the card's white, in linear light, which cancels a
# highlight's light where it is even across the dot. Only dots that pass
# every test of a dot (an object beside one would tell nothing of the
# light); the detector reads these colours only where the peaks give no
# whole code (:func:`lifted_peaks`). In dim, noisy light the upper quartile
# of plain paper lies well above its median: the paper must also be
# _LIFT_NOISE of its noise above the white.
_LIFT_FROM = 0.1
_LIFT_NOISE = 3.0


@numba.njit(cache=True, nogil=False)
def _ellipse_origin(axes, k, c0, c1):
    """Window point (c0, c1) along window ``k``'s ellipse axes, float32 (as the numpy code)."""
    ca = _F32(np.float64(axes[k, 0, 0]) * c0 + np.float64(axes[k, 1, 0]) * c1)
    cb = _F32(np.float64(axes[k, 0, 1]) * c0 + np.float64(axes[k, 1, 1]) * c1)
    return ca, cb


@numba.njit(cache=True, nogil=False)
def _inverse_squares(s0, s1):
    """1 / semi-axis^2 along both axes, float32."""
    return _F32(1.0 / (s0 * s0)), _F32(1.0 / (s1 * s1))


@numba.njit(cache=True, nogil=False)
def _ellipse_at(axes, k, x, y, ca, cb, sa, sb):
    """Normalised squared radius (1 on the edge) of pixel (x, y) of window ``k``."""
    xf, yf = _F32(x), _F32(y)
    a = axes[k, 0, 0] * xf + axes[k, 1, 0] * yf - ca
    b = axes[k, 0, 1] * xf + axes[k, 1, 1] * yf - cb
    return a * a * sa + b * b * sb


@numba.njit(cache=True, nogil=False)
def _span(axes, k, c0, c1, s0, s1, size):
    """
    Pixel ranges (x from, x to, y from, y to; ends excluded) holding an ellipse.

    The ellipse of semi-axes (s0, s1) along window ``k``'s axes round (c0,
    c1), with a pixel to spare (the float32 radius is tested on each pixel
    of the span as on every pixel of the window): loops over it instead of
    the whole window.
    """
    ex = np.sqrt((s0 * axes[k, 0, 0]) ** 2 + (s1 * axes[k, 0, 1]) ** 2) + 1.0
    ey = np.sqrt((s0 * axes[k, 1, 0]) ** 2 + (s1 * axes[k, 1, 1]) ** 2) + 1.0
    return (_start(c0 - ex, size), _stop(c0 + ex, size),
            _start(c1 - ey, size), _stop(c1 + ey, size))


@numba.njit(cache=True, nogil=False)
def _start(v, size):
    """First index of a range from ``v`` (at least 0; all of it if ``v`` is NaN)."""
    if not v > 0.0:
        return 0
    return size if v >= size else int(v)


@numba.njit(cache=True, nogil=False)
def _stop(v, size):
    """End (excluded) of a range up to ``v`` (at most ``size``; all of it if ``v`` is NaN)."""
    if not v < size - 1.0:
        return size
    return 0 if v < -1.0 else int(v) + 2


@numba.njit(cache=True, nogil=False)
def ellipse(axes, c, semi, size):
    """
    Normalised squared radius (K, S, S) of every pixel of every window.

    ``axes`` (K, 2, 2) float32: each window's ellipse axes as columns;
    ``c`` (K, 2): centres (window coordinates); ``semi`` (K, 2): semi-axes.
    """
    k_count = axes.shape[0]
    out = np.empty((k_count, size, size), dtype=np.float32)
    for k in range(k_count):
        ca, cb = _ellipse_origin(axes, k, c[k, 0], c[k, 1])
        sa, sb = _inverse_squares(semi[k, 0], semi[k, 1])
        for y in range(size):
            for x in range(size):
                out[k, y, x] = _ellipse_at(axes, k, x, y, ca, cb, sa, sb)
    return out


@numba.njit(cache=True, nogil=False)
def _plane_at(to_plane, k, x, y, ax0, ay0, qx0, qy0):
    """Card-plane position (float32) of pixel (x, y); window point (ax0, ay0) is (qx0, qy0)."""
    dx = _F32(x) - ax0
    dy = _F32(y) - ay0
    qx = qx0 + to_plane[k, 0, 0] * dx + to_plane[k, 0, 1] * dy
    qy = qy0 + to_plane[k, 1, 0] * dx + to_plane[k, 1, 1] * dy
    return qx, qy


@numba.njit(cache=True, nogil=False)
def _owned(owner, spot, qx, qy, half, resolution):
    """Whether card-plane point (qx, qy) lies in the raster cell of layout spot ``spot``."""
    n = owner.shape[0]
    col = (qx + half) / resolution
    row = (half - qy) / resolution
    # The numpy code truncated towards zero: inside when -1 < value < n.
    # (NaN compares false: outside.) Only then is the value an index.
    if not (col > -1.0 and col < n and row > -1.0 and row < n):
        return False
    return owner[int(row), int(col)] == spot


# numpy's arithmetic: a degenerate homography (a point on its line at
# infinity) gives inf or NaN, which the callers' checks refuse, not an
# exception.
@numba.njit(cache=True, nogil=False, error_model='numpy')
def plane_to_image(H, xy):
    """
    Where homography ``H`` maps plane points ``xy`` (N, 2), and its local linear map there.

    Returns the ideal-image points (N, 2), the map's Jacobian (N, 2, 2,
    pixels per metre) and the points with a pixel added along x and along y
    (3N, 2: the points, then those), the probes of the lens's local map.
    """
    n = xy.shape[0]
    pts = np.empty((n, 2))
    J = np.empty((n, 2, 2))
    probes = np.empty((3 * n, 2))
    for i in range(n):
        u, v, w = _map_point(H, xy[i, 0], xy[i, 1])
        pts[i, 0], pts[i, 1] = u, v
        J[i, 0, 0], J[i, 0, 1], J[i, 1, 0], J[i, 1, 1] = _h_jacobian(H, u, v, w)
        probes[i, 0], probes[i, 1] = u, v
        probes[n + i, 0], probes[n + i, 1] = u + 1.0, v
        probes[2 * n + i, 0], probes[2 * n + i, 1] = u, v + 1.0
    return pts, J, probes


@numba.njit(cache=True, nogil=False, error_model='numpy')
def through_lens(distorted, J):
    """
    Compose the lens's local linear map with ``J`` (N, 2, 2).

    ``distorted`` (3N, 2) is the lens's image of :func:`plane_to_image`'s
    probes: the points, and a pixel further along x and along y, whose
    differences are the lens's map by differences of one pixel. Returns
    the distorted points (N, 2) and the composed map.
    """
    n = J.shape[0]
    pts = np.empty((n, 2))
    out = np.empty((n, 2, 2))
    for i in range(n):
        pts[i, 0], pts[i, 1] = distorted[i, 0], distorted[i, 1]
        dx0 = distorted[n + i, 0] - distorted[i, 0]
        dx1 = distorted[n + i, 1] - distorted[i, 1]
        dy0 = distorted[2 * n + i, 0] - distorted[i, 0]
        dy1 = distorted[2 * n + i, 1] - distorted[i, 1]
        for c in range(2):
            out[i, 0, c] = dx0 * J[i, 0, c] + dy0 * J[i, 1, c]
            out[i, 1, c] = dx1 * J[i, 0, c] + dy1 * J[i, 1, c]
    return pts, out


@numba.njit(cache=True, nogil=False)
def spot_shapes(L, radii, margin, predicted, largest):
    """
    Each spot's image ellipse from the local linear map ``L`` (N, 2, 2, pixels per metre).

    The singular value decomposition of each 2x2 map in closed form (J.
    Blinn's): its left singular vectors are the ellipse's axes (major
    first), its singular values times the spot's radius its semi-axes. The
    window's semi-axes are 1.2 times those plus ``margin``. Returns the
    axes (N, 2, 2, as columns), major, minor, the windows' semi-axes (N, 2),
    the inverse maps (metres per pixel), and whether all is fit to measure:
    every window finite and no bigger than ``largest``, every map of full
    rank and every prediction finite (else the inverses are not computed).
    """
    n = L.shape[0]
    axes = np.empty((n, 2, 2))
    major = np.empty(n)
    minor = np.empty(n)
    semi = np.empty((n, 2))
    inverse = np.empty((n, 2, 2))
    fit = True
    for i in range(n):
        a, b, c, d = L[i, 0, 0], L[i, 0, 1], L[i, 1, 0], L[i, 1, 1]
        e, f, g, h = 0.5 * (a + d), 0.5 * (a - d), 0.5 * (c + b), 0.5 * (c - b)
        q, r = np.hypot(e, h), np.hypot(f, g)
        turn = 0.5 * (np.arctan2(h, e) + np.arctan2(g, f))
        cos, sin = np.cos(turn), np.sin(turn)
        axes[i, 0, 0], axes[i, 1, 0] = cos, sin
        axes[i, 0, 1], axes[i, 1, 1] = -sin, cos
        major[i] = (q + r) * radii[i]
        minor[i] = abs(q - r) * radii[i]
        semi[i, 0] = 1.2 * major[i] + margin
        semi[i, 1] = 1.2 * minor[i] + margin
        fit = fit and abs(q - r) > 0.0 and np.isfinite(semi[i, 0]) and np.isfinite(semi[i, 1]) \
            and semi[i, 0] <= largest and semi[i, 1] <= largest \
            and np.isfinite(predicted[i, 0]) and np.isfinite(predicted[i, 1])
    if fit:
        for i in range(n):
            a, b, c, d = L[i, 0, 0], L[i, 0, 1], L[i, 1, 0], L[i, 1, 1]
            det = a * d - b * c
            inverse[i, 0, 0], inverse[i, 0, 1] = d / det, -b / det
            inverse[i, 1, 0], inverse[i, 1, 1] = -c / det, a / det
    return axes, major, minor, semi, inverse, fit


@numba.njit(cache=True, nogil=False)
def windows(index, scale, predicted, axes, semi, inverse):
    """
    Lay out the windows of spots ``index`` on the image decimated by ``scale`` (1: the image).

    One size for all, from the largest semi-axis plus two pixels. Returns
    each window's origin (K, 2, integer source pixels), the size, the
    axes (float32), the predicted centre and the semi-axes in window
    coordinates, and the metres per source pixel (float32).
    """
    k_count = len(index)
    off = (scale - 1) / 2.0
    widest = 0.0
    for k in range(k_count):
        widest = max(widest, semi[index[k], 0] / scale)
    half = int(np.ceil(widest)) + 2
    base = np.empty((k_count, 2), dtype=np.int64)
    pred = np.empty((k_count, 2))
    window_semi = np.empty((k_count, 2))
    window_axes = np.empty((k_count, 2, 2), dtype=np.float32)
    to_plane = np.empty((k_count, 2, 2), dtype=np.float32)
    for k in range(k_count):
        i = index[k]
        for a in range(2):
            centre = (predicted[i, a] - off) / scale
            # Halves to even, as numpy's round; a window a billion pixels
            # away is as far off the image as any (and an integer).
            base[k, a] = int(min(max(np.rint(centre), -1e9), 1e9)) - half
            pred[k, a] = centre - base[k, a]
            window_semi[k, a] = semi[i, a] / scale
            for b in range(2):
                window_axes[k, a, b] = axes[i, a, b]
                to_plane[k, a, b] = inverse[i, a, b] * scale
    return base, 2 * half + 1, window_axes, pred, window_semi, to_plane


@numba.njit(cache=True, nogil=False)
def first_pass(source, scale, base, size, index, axes, pred, semi, to_plane, spots, plane_xy,
               owner, half, resolution, major, minor, linv, white_level, quiet, gamma,
               core_margin, min_darkness, points, valid, peak, area, inside, lift_level,
               lifted):
    """
    Gather each window's pixels, take the first, generous centroid and test the dots.

    ``source`` (h, w, C) uint8 is the image or the image decimated by
    ``scale`` (C = 3, or 1 for grey); window ``k`` covers its pixels
    ``base[k] .. base[k] + size - 1`` (x, y), clipped to the image. Window
    ``k`` is spot ``index[k]``: ``pred`` its predicted centre (window
    coordinates), ``semi`` the window's semi-axes along ``axes``,
    ``to_plane`` metres per source pixel; ``spots``, ``plane_xy``,
    ``major``, ``minor`` (image pixels) and ``linv`` (metres per image
    pixel) are per spot, ``spots`` indexing the layout's ``owner`` raster
    (``half``, ``resolution``: its geometry). ``white_level`` (float32,
    per spot) is the image's local white at the spot's predicted centre
    (the paper round the spot instead where that is well below it:
    :func:`_paper_level`, which also tilts it with the paper there);
    ``quiet`` is the source's noise; ``gamma`` the camera's encoding.

    Writes the centre (image pixels), the tests, the peak darkness and the
    area into ``points``, ``valid``, ``peak``, ``area`` and ``inside`` at
    ``index``, and into ``lifted`` whether the paper round the spot is at
    least ``lift_level`` (``_LIFT_FROM``); returns pixels, in_image, raw
    (darkness below the floor, 0 off the image), weight (raw in the spot's
    cell), cell, window, on_card (on the card or within the spot's own
    ellipse), centres (K, 2, window coordinates), top (the peak 3x3 mean
    darkness round the prediction) and spread (K, 3: xx, xy, yy second
    moments, image pixels^2).
    """
    k_count = base.shape[0]
    h, w, channels = source.shape
    shape = (k_count, size, size)
    pixels = np.empty((k_count, size, size, channels), dtype=np.uint8)
    in_image = np.empty(shape, dtype=np.bool_)
    raw = np.empty(shape, dtype=np.float32)
    weight = np.empty(shape, dtype=np.float32)
    cell = np.empty(shape, dtype=np.bool_)
    window = np.zeros(shape, dtype=np.bool_)
    on_card = np.empty(shape, dtype=np.bool_)
    centres = np.empty((k_count, 2))
    top = np.zeros(k_count, dtype=np.float32)
    spread = np.empty((k_count, 3))
    half32, resolution32 = _F32(half), _F32(resolution)
    off = (scale - 1) / 2.0
    plane_x = np.empty((size, size), dtype=np.float32)
    plane_y = np.empty((size, size), dtype=np.float32)
    paper = np.empty(size * size, dtype=np.uint8)
    ring = np.empty((size * size, 3))
    for k in range(k_count):
        i = index[k]
        bx, by = base[k, 0], base[k, 1]
        # Darkness below the local white, less a floor that keeps paper
        # noise out.
        ax0, ay0 = _F32(pred[k, 0]), _F32(pred[k, 1])
        qx0, qy0 = _F32(plane_xy[i, 0]), _F32(plane_xy[i, 1])
        level, tilt_x, tilt_y, lifted[i] = _paper_level(
            source, bx, by, size, axes, k, pred[k, 0], pred[k, 1], major[i] / scale,
            minor[i] / scale, white_level[i], quiet, paper, to_plane, qx0, qy0, owner,
            spots[i], half32, resolution32, ring, lift_level)
        floor = max(_F32(0.04) * level, _F32(2.0) * quiet)
        clear = level - floor
        # A tilted paper (a highlight's flank): its light is added to ink
        # and paper alike, which cancels in linear light, not in the
        # camera's encoding (a dot would be darker where less is added). So
        # the darkness is linear there, scaled to match the encoded one for
        # black ink (and near the white, gamma times it: the floor too).
        tilted = tilt_x != 0.0 or tilt_y != 0.0
        gx, gy = _F32(tilt_x), _F32(tilt_y)
        to_linear = _F32(level / _linear(level, gamma)) if tilted else _F32(1.0)
        floor_linear = _F32(gamma) * floor
        # On the card, inside its edge by two image pixels...
        room_x = _F32(half - 2.0 * np.hypot(linv[i, 0, 0], linv[i, 0, 1]))
        room_y = _F32(half - 2.0 * np.hypot(linv[i, 1, 0], linv[i, 1, 1]))
        # ...or within the spot's own ellipse grown by a pixel and a half.
        ca, cb = _ellipse_origin(axes, k, pred[k, 0], pred[k, 1])
        oa, ob = _inverse_squares(major[i] / scale + 1.5, minor[i] / scale + 1.5)
        for y in range(size):
            v = by + y
            vc = min(max(v, 0), h - 1)
            for x in range(size):
                u = bx + x
                uc = min(max(u, 0), w - 1)
                darkest = np.uint8(255)
                for ch in range(channels):
                    p = source[vc, uc, ch]
                    pixels[k, y, x, ch] = p
                    darkest = min(darkest, p)
                seen = (u >= 0) & (u < w) & (v >= 0) & (v < h)
                in_image[k, y, x] = seen
                if tilted:
                    white_here = level + gx * (_F32(x) - ax0) + gy * (_F32(y) - ay0)
                    r = max(to_linear * (_linear(white_here, gamma) - _linear(darkest, gamma))
                            - floor_linear, _F32(0.0))
                else:
                    r = max(clear - _F32(darkest), _F32(0.0))
                raw[k, y, x] = r if seen else _F32(0.0)
                qx, qy = _plane_at(to_plane, k, x, y, ax0, ay0, qx0, qy0)
                plane_x[y, x] = qx
                plane_y[y, x] = qy
                on_card[k, y, x] = ((abs(qx) < room_x) & (abs(qy) < room_y)) \
                    | (_ellipse_at(axes, k, x, y, ca, cb, oa, ob) <= 1.0)
        # The spot's share of the plane in a loop of its own: its raster
        # look-up kept the loop above from being compiled to vector
        # instructions.
        spot = spots[i]
        for y in range(size):
            for x in range(size):
                mine = in_image[k, y, x] and on_card[k, y, x] and _owned(
                    owner, spot, plane_x[y, x], plane_y[y, x], half32, resolution32)
                cell[k, y, x] = mine
                weight[k, y, x] = raw[k, y, x] if mine else _F32(0.0)
        # The centroid twice, in the window round the latest centre.
        c0, c1 = pred[k, 0], pred[k, 1]
        for _ in range(2):
            c0, c1 = _centroid(weight[k], axes, k, c0, c1, semi[k, 0], semi[k, 1])
        centres[k, 0], centres[k, 1] = c0, c1
        # Peak: the largest 3x3 mean within the core round the prediction.
        reach = major[i] / scale + core_margin / scale
        core = min(reach * reach / (semi[k, 0] * semi[k, 0]), 1.0)
        sa, sb = _inverse_squares(semi[k, 0], semi[k, 1])
        x0, x1, y0, y1 = _span(axes, k, pred[k, 0], pred[k, 1], np.sqrt(core) * semi[k, 0],
                               np.sqrt(core) * semi[k, 1], size)
        best = _F32(0.0)
        for y in range(y0, y1):
            for x in range(x0, x1):
                if _ellipse_at(axes, k, x, y, ca, cb, sa, sb) <= core:
                    best = max(best, _box3_at(weight[k], x, y))
        top[k] = best
        rim_sum, rim_count, mass, out = 0.0, 0, 0.0, False
        sxx, sxy, syy = 0.0, 0.0, 0.0
        fc0, fc1 = _F32(c0), _F32(c1)
        ea, eb = _ellipse_origin(axes, k, c0, c1)
        x0, x1, y0, y1 = _span(axes, k, c0, c1, semi[k, 0], semi[k, 1], size)
        for y in range(y0, y1):
            for x in range(x0, x1):
                e = _ellipse_at(axes, k, x, y, ea, eb, sa, sb)
                if not e <= 1.0:
                    continue
                window[k, y, x] = True
                out = out or not in_image[k, y, x]
                wd = weight[k, y, x]
                mass += wd
                if e > _F32(0.6) and cell[k, y, x]:
                    rim_sum += wd
                    rim_count += 1
                dx = _F32(x) - fc0
                dy = _F32(y) - fc1
                sxx += wd * dx * dx
                sxy += wd * dx * dy
                syy += wd * dy * dy
        # The tests of a dot: dark enough against the paper and its noise,
        # its darkness inside the window (paper round it), not much bigger
        # than a dot, and the window inside the image (a spot cut by the
        # border has a false centre).
        equivalent = mass / max(np.float64(best), np.float64(_F32(1e-6))) * scale * scale
        relative = best / max(level, _F32(1.0))
        dark_enough = relative >= _F32(min_darkness) and best >= _F32(4.0) * quiet
        isolated = rim_sum / max(rim_count, 1) <= _F32(0.3) * best
        sized = equivalent <= 3.0 * (np.pi * major[i] * minor[i]) + 8.0 * (major[i] + 1.0)
        inside[i] = not out
        valid[i] = not out and dark_enough and isolated and sized
        points[i, 0], points[i, 1] = (c0 + bx) * scale + off, (c1 + by) * scale + off
        peak[i] = relative
        area[i] = equivalent
        total = max(mass, 1e-6)
        spread[k, 0] = sxx / total * (scale * scale)
        spread[k, 1] = sxy / total * (scale * scale)
        spread[k, 2] = syy / total * (scale * scale)
    return pixels, in_image, raw, weight, cell, window, on_card, centres, top, spread


@numba.njit(cache=True, nogil=False)
def _paper_ring(axes, k, c0, c1, major, minor, size):
    """
    Lay out the paper ring round a dot: between ``_PAPER_RING`` of its semi-axes.

    ``major``, ``minor`` (source pixels) along ``axes[k]`` round (``c0``,
    ``c1``) in a window of ``size``. Returns the ellipses' origin, the
    inner and outer inverse squared semi-axes and the ring's span in the
    window (:func:`_in_paper_ring` tests a pixel of it).
    """
    ca, cb = _ellipse_origin(axes, k, c0, c1)
    ia, ib = _inverse_squares(_PAPER_RING[0] * major, _PAPER_RING[0] * minor)
    oa, ob = _inverse_squares(_PAPER_RING[1] * major, _PAPER_RING[1] * minor)
    x0, x1, y0, y1 = _span(axes, k, c0, c1, _PAPER_RING[1] * major, _PAPER_RING[1] * minor,
                           size)
    return ca, cb, ia, ib, oa, ob, x0, x1, y0, y1


@numba.njit(cache=True, nogil=False)
def _in_paper_ring(axes, k, x, y, ca, cb, ia, ib, oa, ob):
    """Tell whether window pixel (x, y) lies in the ring :func:`_paper_ring` laid out."""
    return not (_ellipse_at(axes, k, x, y, ca, cb, oa, ob) > 1.0
                or _ellipse_at(axes, k, x, y, ca, cb, ia, ib) <= 1.0)


@numba.njit(cache=True, nogil=False)
def _paper_level(source, bx, by, size, axes, k, c0, c1, major, minor, grid_white, quiet,
                 buffer, to_plane, qx0, qy0, owner, spot, half, resolution, samples,
                 lift_level):
    """
    Return a dot's white at its centre, the paper's tilt, and whether that paper is lifted.

    ``(level, gx, gy, lifted)``; ``lifted``: the paper's upper quartile
    (its darkest channel) is at least ``lift_level`` (see ``_LIFT_FROM``).

    The paper: the darkest channel over the ring between ``_PAPER_RING`` of
    the dot's semi-axes (``major``, ``minor``, source pixels, along
    ``axes[k]``) round (``c0``, ``c1``) in the window whose origin is
    (``bx``, ``by``), within the image; ``buffer`` holds at least ``size *
    size`` values, ``samples`` as many rows of three; ``quiet`` is the
    source's noise. Where a plane fits the part of that paper that is the
    dot's own (``owner``'s cell ``spot``, plane positions from
    ``to_plane``, window point (``c0``, ``c1``) at (``qx0``, ``qy0``): not
    a neighbour's blur) and tilts clearly (:func:`_paper_tilt`), the
    plane: its value at the centre and its slopes (grey levels per source
    pixel, x and y). Otherwise no tilt, and the grid's white, or the
    paper's upper quartile where that lies more than ``_FLANK`` below it.
    """
    h, w, channels = source.shape
    ca, cb, ia, ib, oa, ob, x0, x1, y0, y1 = _paper_ring(axes, k, c0, c1, major, minor, size)
    below = (_F32(1.0) - _F32(_FLANK)) * grid_white
    count = 0
    bright = 0
    high = 0
    # The dot's own part of the ring, for its tilt (big enough dots only).
    tilts = minor >= _TILT_MIN_SEMI_AXIS
    own = 0
    ax0, ay0 = _F32(c0), _F32(c1)
    for y in range(y0, y1):
        v = by + y
        if v < 0 or v >= h:
            continue
        for x in range(x0, x1):
            u = bx + x
            if u < 0 or u >= w or not _in_paper_ring(axes, k, x, y, ca, cb, ia, ib, oa, ob):
                continue
            darkest = np.uint8(255)
            for ch in range(channels):
                darkest = min(darkest, source[v, u, ch])
            buffer[count] = darkest
            count += 1
            bright += _F32(darkest) >= below
            high += _F32(darkest) >= lift_level
            if tilts:
                qx, qy = _plane_at(to_plane, k, x, y, ax0, ay0, qx0, qy0)
                if _owned(owner, spot, qx, qy, half, resolution):
                    samples[own, 0] = x - c0
                    samples[own, 1] = y - c1
                    samples[own, 2] = np.float64(darkest)
                    own += 1
    if count < _MIN_PAPER_PIXELS:
        return grid_white, 0.0, 0.0, False
    # The upper quartile (numpy's, interpolated between the sorted values
    # at and after 0.75 (count - 1)) is at least a level when both those
    # values are: when at most that many values lie below it. No sort.
    quartile = int(0.75 * (count - 1))
    lifted = count - high <= quartile
    if tilts:
        tilted, a, gx, gy = _paper_tilt(samples, own, major, quiet)
        if tilted:
            return _F32(a), gx, gy, lifted
    # The upper quartile: an object beside the dot darkens part of the
    # ring. When it is at least `below` (the usual case, flat light), the
    # grid's white.
    if count - bright <= quartile:
        return grid_white, 0.0, 0.0, lifted
    ring = _F32(np.quantile(buffer[:count], 0.75))
    return (ring if ring < below else grid_white), 0.0, 0.0, lifted


@numba.njit(cache=True, nogil=False)
def _paper_tilt(samples, count, major, quiet):
    """
    Fit a plane to a dot's paper: ``(tilted, a, gx, gy)``.

    ``samples``' first ``count`` rows are (dx, dy, grey level) round the
    dot's centre (source pixels; :func:`_paper_level`'s ring, the dot's
    own part). Fitted twice, the second time without the samples more
    than ``_TILT_OUTLIER`` of the level below the first plane (an object,
    a neighbour's blur); the second fit only where the first tilts by
    half the bar. Tilted when the plane changes by more than ``_TILT`` of
    its level across the dot (``major``: its semi-major axis; and by
    ``_TILT_NOISE`` times the noise ``quiet``), and the paper kept lies on
    it (residuals' RMS at most ``_TILT_FIT`` of the level, or twice the
    noise): a highlight's smooth flank, not an object's edge.
    """
    a, gx, gy = 0.0, 0.0, 0.0
    for rounds in range(2):
        floor = _TILT_OUTLIER * a
        n = 0
        sxx = sxy = syy = sx = sy = 0.0
        sv = sxv = syv = svv = 0.0
        for j in range(count):
            dx, dy, value = samples[j, 0], samples[j, 1], samples[j, 2]
            if rounds == 1 and value < a + gx * dx + gy * dy - floor:
                continue
            n += 1
            sx += dx
            sy += dy
            sxx += dx * dx
            sxy += dx * dy
            syy += dy * dy
            sv += value
            sxv += dx * value
            syv += dy * value
            svv += value * value
        if n < _MIN_PAPER_PIXELS:
            return False, 0.0, 0.0, 0.0
        ok, a, gx, gy = _plane(n, sx, sy, sxx, sxy, syy, sv, sxv, syv)
        if not (ok and a > 0.0):
            return False, 0.0, 0.0, 0.0
        if rounds == 0 and not np.hypot(gx, gy) * 2.0 * major > 0.5 * _TILT * a:
            return False, 0.0, 0.0, 0.0
    # The residuals' sum of squares from the sums: sum (v - a - gx dx - gy dy)^2.
    rss = (svv - 2.0 * (a * sv + gx * sxv + gy * syv) + a * a * n + gx * gx * sxx
           + gy * gy * syy + 2.0 * (a * gx * sx + a * gy * sy + gx * gy * sxy))
    rms = np.sqrt(max(rss, 0.0) / n)
    change = np.hypot(gx, gy) * 2.0 * major
    # The slope against its own uncertainty (chi-square of the two slopes,
    # the residuals' RMS for the noise): a plane that noise or a
    # neighbour's blur tilts by chance is not a highlight.
    mx, my = sx / n, sy / n
    cxx, cxy, cyy = sxx - n * mx * mx, sxy - n * mx * my, syy - n * my * my
    sure = (gx * gx * cxx + 2.0 * gx * gy * cxy + gy * gy * cyy) \
        > _TILT_SURE * max(rms, 0.5 * quiet, 0.5) ** 2
    tilted = change > _TILT * a and change > _TILT_NOISE * quiet and sure \
        and rms <= max(_TILT_FIT * a, 2.0 * quiet)
    return tilted, a, gx, gy


@numba.njit(cache=True, nogil=False)
def _linear(level, gamma):
    """Linear light (float32, 255 for white) of an encoded grey level."""
    return _F32(255.0 * (max(np.float64(level), 0.0) / 255.0) ** gamma)


@numba.njit(cache=True, nogil=False)
def _plane(n, sx, sy, sxx, sxy, syy, sv, sxv, syv):
    """Least-squares plane a + gx dx + gy dy from its sums: ``(ok, a, gx, gy)``."""
    # Centred sums: the plane's slopes, then its value at the origin.
    mx, my, mv = sx / n, sy / n, sv / n
    cxx, cxy, cyy = sxx - n * mx * mx, sxy - n * mx * my, syy - n * my * my
    cxv, cyv = sxv - n * mx * mv, syv - n * my * mv
    det = cxx * cyy - cxy * cxy
    if not det > 1e-9 * (cxx * cyy + 1e-12):
        return False, 0.0, 0.0, 0.0
    gx = (cyy * cxv - cxy * cyv) / det
    gy = (cxx * cyv - cxy * cxv) / det
    return True, mv - gx * mx - gy * my, gx, gy


@numba.njit(cache=True, nogil=False)
def _centroid(weight, axes, k, c0, c1, s0, s1):
    """Weighted centroid of one window's ``weight`` within the ellipse (s0, s1) about (c0, c1)."""
    size = weight.shape[0]
    ca, cb = _ellipse_origin(axes, k, c0, c1)
    sa, sb = _inverse_squares(s0, s1)
    x0, x1, y0, y1 = _span(axes, k, c0, c1, s0, s1, size)
    total, sx, sy = 0.0, 0.0, 0.0
    for y in range(y0, y1):
        for x in range(x0, x1):
            if _ellipse_at(axes, k, x, y, ca, cb, sa, sb) <= 1.0:
                wv = weight[y, x]
                total += wv
                sx += wv * x
                sy += wv * y
    if total > 0.0:
        return sx / total, sy / total
    return c0, c1


@numba.njit(cache=True, nogil=False)
def _box3_at(a, x, y):
    """3x3 mean of (S, S) ``a`` at (x, y), the window's edge pixels repeated beyond it."""
    size = a.shape[0]
    total = 0.0
    for dy in range(-1, 2):
        yy = min(max(y + dy, 0), size - 1)
        for dx in range(-1, 2):
            xx = min(max(x + dx, 0), size - 1)
            total += a[yy, xx]
    # As OpenCV's box filter: a double sum times 1/9, rounded to float32.
    return _F32(total * (1.0 / 9.0))


@numba.njit(cache=True, nogil=False)
def last_pass(raw, on_card, first_weight, window, top, centres, pred, axes, base, scale, index,
              major, minor, blur, sigma, to_plane, spots, plane_xy, owner, half, resolution,
              points, predicted, valid, readable):
    """
    Centroid again in a tight window, the dark region joined to the dot alone; the dot tests.

    ``raw``, ``on_card``, ``first_weight``, ``window``, ``top`` and
    ``centres`` are :func:`first_pass`'s (and its other arguments as
    there); the windows are shared about ``centres`` now. The tight window
    is the dot and its ``blur`` (2.5 sigma, covariance in image pixels^2)
    plus a pixel; ``sigma`` the source's pixel noise.

    Writes each centre (image pixels) into ``points`` and the tests into
    ``valid`` and ``readable`` (``predicted``: where the homography put
    the spots); returns the centres (K, 2, window coordinates) and the
    mask (K, S, S) of the pixels not in a dark region apart from the dot's.
    """
    k_count, size = raw.shape[0], raw.shape[1]
    shape = (k_count, size, size)
    connected = np.empty(shape, dtype=np.bool_)
    out_c = np.empty((k_count, 2))
    steady = np.empty(k_count, dtype=np.bool_)
    exists = np.empty(k_count, dtype=np.bool_)
    relative = np.empty(k_count)
    half32, resolution32 = _F32(half), _F32(resolution)
    mine = np.empty((size, size), dtype=np.bool_)
    weight = np.empty((size, size), dtype=np.float32)
    dark = np.empty((size, size), dtype=np.bool_)
    region = np.empty((size, size), dtype=np.bool_)
    stack = np.empty(size * size, dtype=np.int64)
    rows = np.empty((size, size), dtype=np.float32)
    plane_x = np.empty((size, size), dtype=np.float32)
    plane_y = np.empty((size, size), dtype=np.float32)
    tight = np.empty(2)
    off = (scale - 1) / 2.0
    for k in range(k_count):
        i = index[k]
        # The blur's extent (2.5 sigma) along each of the dot's axes.
        for axis in range(2):
            ext = 0.0
            for r in range(2):
                for q in range(2):
                    ext += np.float64(axes[k, r, axis]) * blur[r, q] * np.float64(axes[k, q, axis])
            semi_axis = major[i] if axis == 0 else minor[i]
            tight[axis] = (semi_axis + 2.5 * np.sqrt(ext) + 1.0) / scale
        c0, c1 = centres[k, 0], centres[k, 1]
        ax0, ay0 = _F32(c0), _F32(c1)
        qx0, qy0 = _F32(plane_xy[i, 0]), _F32(plane_xy[i, 1])
        threshold = _F32(0.25) * max(top[k], _F32(1e-6))
        # Plane positions first, the raster look-ups after (as first_pass).
        for y in range(size):
            for x in range(size):
                plane_x[y, x], plane_y[y, x] = _plane_at(to_plane, k, x, y, ax0, ay0, qx0, qy0)
        spot = spots[i]
        for y in range(size):
            for x in range(size):
                m = _owned(owner, spot, plane_x[y, x], plane_y[y, x], half32, resolution32)
                mine[y, x] = m
                wv = raw[k, y, x] if m and on_card[k, y, x] else _F32(0.0)
                weight[y, x] = wv
                dark[y, x] = wv > threshold
                connected[k, y, x] = not dark[y, x]
        # Dark things apart from the dot are not the dot's: its own dark
        # region (8-connected) is the one with the darkest pixel within a
        # pixel and a half of the centre (the first such, row by row).
        # (Elsewhere the weight counts as 0: the first pixel when no pixel
        # near the centre has any.)
        best, best_value = 0, _F32(0.0)
        for y in range(_start(c1 - 1.5, size), _stop(c1 + 1.5, size)):
            for x in range(_start(c0 - 1.5, size), _stop(c0 + 1.5, size)):
                if abs(x - c0) <= 1.5 and abs(y - c1) <= 1.5 and weight[y, x] > best_value:
                    best, best_value = y * size + x, weight[y, x]
        if dark[best // size, best % size]:
            _flood(dark, connected[k], best, stack)
        for y in range(size):
            for x in range(size):
                if not connected[k, y, x]:
                    weight[y, x] = _F32(0.0)
        for _ in range(2):
            c0, c1 = _centroid(weight, axes, k, c0, c1, tight[0], tight[1])
        out_c[k, 0], out_c[k, 1] = c0, c1
        ca, cb = _ellipse_origin(axes, k, c0, c1)
        sa, sb = _inverse_squares(tight[0], tight[1])
        ga, gb = _inverse_squares(tight[0] + 1.0, tight[1] + 1.0)
        threshold = _F32(0.25) * top[k]
        n_stained, n_beyond = 0, 0
        for y in range(size):
            for x in range(size):
                if window[k, y, x] and mine[y, x] \
                        and _ellipse_at(axes, k, x, y, ca, cb, ga, gb) > 1.0:
                    n_beyond += 1
                    if weight[y, x] > threshold:
                        n_stained += 1
        region[:] = False
        span = _span(axes, k, c0, c1, tight[0], tight[1], size)
        for y in range(span[2], span[3]):
            for x in range(span[0], span[1]):
                region[y, x] = mine[y, x] and _ellipse_at(axes, k, x, y, ca, cb, sa, sb) <= 1.0
        asymmetry = _asymmetry(weight, region, span, c0, c1, sigma, rows)
        points[i, 0] = (c0 + base[k, 0]) * scale + off
        points[i, 1] = (c1 + base[k, 1]) * scale + off
        steady[k] = np.hypot(points[i, 0] - predicted[i, 0], points[i, 1] - predicted[i, 1]) \
            <= max(1.5, 0.3 * major[i] + 1.0)
        # Reflecting a dot a pixel or two thick by interpolation blurs it:
        # more room for thin dots. An object touching the dot joins its dark
        # region beyond the dot and its blur.
        grid = 0.15 / max(minor[i] / scale, 0.5)
        touched = n_stained > 0.1 * n_beyond + 1
        exists[k] = valid[i]
        valid[i] = valid[i] and steady[k] and asymmetry <= 0.08 + grid and not touched
        # The evenness of the first weight over the inner part round the
        # prediction (ink is even there).
        inner0 = (0.6 * major[i] + 0.7) / scale
        inner1 = (0.6 * minor[i] + 0.7) / scale
        ia, ib = _ellipse_origin(axes, k, pred[k, 0], pred[k, 1])
        sa, sb = _inverse_squares(inner0, inner1)
        x0, x1, y0, y1 = _span(axes, k, pred[k, 0], pred[k, 1], inner0, inner1, size)
        count, total, squares = 0, 0.0, 0.0
        for y in range(y0, y1):
            for x in range(x0, x1):
                if mine[y, x] and _ellipse_at(axes, k, x, y, ia, ib, sa, sb) <= 1.0:
                    wv = first_weight[k, y, x]
                    count += 1
                    total += wv
                    squares += wv * wv
        count = max(count, 1)
        mean = total / count
        relative[k] = np.sqrt(max(squares / count - mean * mean, 0.0)) / max(mean, 1e-6)
    # Its colour may still be read where the geometry may not (a dot
    # touched by an object, or with one over part of its rim): when its
    # inner part is as even as the dots' that passed everything (same blur,
    # same size). Too small a dot to tell: not read.
    typical = _median_where(relative, valid, index, 3)
    for k in range(k_count):
        i = index[k]
        even = relative[k] <= 1.3 * typical + 0.03 and minor[i] >= 2.5
        readable[i] = valid[i] or (exists[k] and steady[k] and even)
    return out_c, connected


@numba.njit(cache=True, nogil=False)
def _group_indices(minor, big_from, big):
    """Spots whose semi-minor axis is at least ``big_from`` (``big``) or below it (not ``big``)."""
    n = minor.shape[0]
    out = np.empty(n, dtype=np.int64)
    count = 0
    for i in range(n):
        if (minor[i] >= big_from) == big:
            out[count] = i
            count += 1
    return out[:count].copy()


@numba.njit(cache=True, nogil=False)
def _first_group(source, scale, index, pred, U, semi, Linv, spots, plane_xy, owner, half,
                 resolution, major, minor, white_level, paper_sigma, paper_quiet, gamma,
                 core_margin, min_darkness, points, valid, peak, area, inside, lift_level,
                 lifted):
    """Lay out one group's windows and take their first pass (:func:`first_pass`)."""
    base, size, axes, wpred, wsemi, to_plane = windows(index, scale, pred, U, semi, Linv)
    # Noise of the source image: decimation averages scale * scale pixels.
    sigma = _F32(paper_sigma / scale)
    quiet = sigma
    if not np.isnan(paper_quiet):
        quiet = min(sigma, _F32(paper_quiet / scale))
    (pixels, in_image, raw, weight, cell, window, on_card, centres, top,
     spread) = first_pass(source, scale, base, size, index, axes, wpred, wsemi, to_plane,
                          spots, plane_xy, owner, half, resolution, major, minor, Linv,
                          white_level, quiet, gamma, core_margin, min_darkness, points, valid,
                          peak, area, inside, lift_level, lifted)
    return (base, size, axes, wpred, to_plane, pixels, in_image, raw, weight, cell, window,
            on_card, centres, top, spread, sigma)


@numba.njit(cache=True, nogil=False)
def _uncover(index, minor, valid, readable, partial, inside):
    """
    Whether a group has dots whose colour may show in part (:func:`.centres._uncovered_part`).

    At least three sure dots, and one that is not readable or was read
    although touched, whole in the image and big enough (2.5 pixels).
    """
    sure = 0
    todo = False
    for k in range(index.shape[0]):
        i = index[k]
        sure += valid[i]
        fit = inside[i] and minor[i] >= 2.5
        todo = todo or (fit and (not readable[i] or (not valid[i] and not partial[i])))
    return sure >= 3 and todo


@numba.njit(cache=True, nogil=False)
def measure(image, small, small_scale, pred, L, radii, margin, largest, big_from, spots,
            plane_xy, owner, half, resolution, white_grid, grid_step, paper_sigma, paper_quiet,
            gamma, min_darkness, core_margin, refine, min_valid, colour, table, max_shift,
            card_white):
    """
    Measure spots where their predicted centres ``pred`` are: every pass, in one call.

    What :func:`.centres.measure_spots` orchestrates, which says why: the
    spots' image ellipses (:func:`spot_shapes`, from the local linear maps
    ``L``, the spots' ``radii`` and the windows' ``margin``; nothing is
    measured when a window would be bigger than ``largest``); the spots
    whose semi-minor axis is at least ``big_from`` measured on ``small``
    (the image decimated by ``small_scale``), the others on ``image``
    (both (H, W, C) uint8); the first pass (:func:`first_pass`, against
    the local white ``white_grid`` (float32, ``grid_step`` pixels a cell)
    and the paper's noise ``paper_sigma`` and ``paper_quiet`` (NaN: none),
    ``gamma`` the camera's encoding);
    then, when ``refine`` and (``min_valid`` > 0) the first spot and at
    least ``min_valid`` are valid, the blur (:func:`blur`) and the last
    pass (:func:`last_pass`); when ``colour``, the colours
    (:func:`colours`, with the darkness ``table``), the channels' shift
    (:func:`undo_channel_shift`) and, for a card of small dots
    (:func:`small_card`), its colours from each dot's darkness summed round
    it (:func:`small_card_colours`), and for a card whose paper round some
    dots is brighter than its white ``card_white`` (BGR, the card's paper;
    see ``_LIFT_FROM``), its colours with the light added there added back
    (:func:`lifted_peaks`).

    Returns ``(fit, points, valid, readable, peak, colour, area, inside,
    partial, centred, major, minor, far, far_colour, glared, lifted)``
    (:class:`.centres.SpotMeasures`' rows; ``far``: whether ``far_colour``
    holds a far card's colours, ``glared`` whether ``lifted`` holds the
    lifted ones) and, for the groups on the image and on
    ``small``, each window's ``(index, size, axes, pred, to_plane, cell,
    on_card, in_image, darkness, uncover)``: what
    :func:`.centres._uncovered_part` reads of a group whose ``uncover``
    (:func:`_uncover`) says it has work.
    """
    n = pred.shape[0]
    points = np.full((n, 2), np.nan)
    valid = np.zeros(n, dtype=np.bool_)
    readable = np.zeros(n, dtype=np.bool_)
    peak = np.zeros(n)
    colour_out = np.full((n, 3), np.nan)
    far_colour = np.full((n, 3), np.nan)
    far = False
    lifted_colour = np.full((n, 3), np.nan)
    glared = False
    lifted = np.zeros(n, dtype=np.bool_)
    # The darkest channel's level of the card's white lifted by _LIFT_FROM
    # in linear light, and by _LIFT_NOISE of the paper's noise (none for a
    # grey image, or a white with a channel at 0: no light to measure by).
    lift_level = _F32(np.inf)
    least = min(card_white[0], card_white[1], card_white[2])
    if colour and least > 0.0:
        lift_level = _F32(max(least * (1.0 + _LIFT_FROM) ** (1.0 / gamma),
                              least + _LIFT_NOISE * paper_sigma))
    area = np.zeros(n)
    inside = np.zeros(n, dtype=np.bool_)
    partial = np.zeros(n, dtype=np.bool_)
    centred = np.ones(n, dtype=np.bool_)
    U, major, minor, semi, Linv, fit = spot_shapes(L, radii, margin, pred, largest)
    if not fit:
        # Nothing measured: groups of no spots (their windows are empty).
        index1 = np.zeros(0, dtype=np.int64)
        index2 = np.zeros(0, dtype=np.int64)
    elif small_scale > 1:
        index1 = _group_indices(minor, big_from, False)
        index2 = _group_indices(minor, big_from, True)
    else:
        index1 = np.arange(n)
        index2 = np.zeros(0, dtype=np.int64)
    white_level = np.empty(n, dtype=np.float32)
    if fit:
        white = _bilinear(white_grid, pred[:, 0].copy(), pred[:, 1].copy(), grid_step)
        for i in range(n):
            white_level[i] = _F32(white[i])
    # The image's own scale as a variable, not the literal 1: numba compiles
    # a pass again for a literal argument, and the two groups' calls would
    # run two copies of each pass (compile time, and code to load per frame).
    full = np.int64(1)
    g1 = _first_group(image, full, index1, pred, U, semi, Linv, spots, plane_xy, owner, half,
                      resolution, major, minor, white_level, paper_sigma, paper_quiet, gamma,
                      core_margin, min_darkness, points, valid, peak, area, inside, lift_level,
                      lifted)
    g2 = _first_group(small, small_scale, index2, pred, U, semi, Linv, spots, plane_xy, owner,
                      half, resolution, major, minor, white_level, paper_sigma, paper_quiet,
                      gamma, core_margin, min_darkness, points, valid, peak, area, inside,
                      lift_level, lifted)
    # The tolerance of the last pass's test of a dot's centre (last_pass).
    for i in range(n if fit else 0):
        reach = 0.3 * major[i] + 1.0
        centred[i] = np.hypot(points[i, 0] - pred[i, 0], points[i, 1] - pred[i, 1]) \
            <= (reach if reach > 1.5 else 1.5)
    dark1 = np.zeros((0, g1[1], g1[1], 3), dtype=np.float32)
    dark2 = np.zeros((0, g2[1], g2[1], 3), dtype=np.float32)
    uncover1 = uncover2 = False
    count = 0
    for i in range(n):
        count += valid[i]
    enough = min_valid <= 0 or (n > 0 and valid[0] and count >= min_valid)
    if fit and refine and enough:
        spread = np.full((n, 3), np.nan)
        for k in range(index1.shape[0]):
            spread[index1[k]] = g1[14][k]
        for k in range(index2.shape[0]):
            spread[index2[k]] = g2[14][k]
        blurred = blur(spread, U, major, minor, valid)
        c1, connected1 = last_pass(g1[7], g1[11], g1[8], g1[10], g1[13], g1[12], g1[3], g1[2],
                                   g1[0], full, index1, major, minor, blurred, g1[15], g1[4],
                                   spots, plane_xy, owner, half, resolution, points, pred,
                                   valid, readable)
        c2, connected2 = last_pass(g2[7], g2[11], g2[8], g2[10], g2[13], g2[12], g2[3], g2[2],
                                   g2[0], small_scale, index2, major, minor, blurred, g2[15],
                                   g2[4], spots, plane_xy, owner, half, resolution, points,
                                   pred, valid, readable)
        if colour:
            channel_at = np.full((n, 3, 2), np.nan)
            strength = np.zeros((n, 3))
            volume = np.full((n, 3), np.nan)
            far = small_card(major, minor, valid)
            dark1 = colours(g1[5], table, g1[9], g1[10], connected1, g1[2], c1, g1[3], g1[0],
                            full, index1, major, minor, max_shift, valid, readable, colour_out,
                            channel_at, strength, far, volume)
            dark2 = colours(g2[5], table, g2[9], g2[10], connected2, g2[2], c2, g2[3], g2[0],
                            small_scale, index2, major, minor, max_shift, valid, readable,
                            colour_out, channel_at, strength, far, volume)
            # The shift moves centres only; the uncovered parts (after this
            # call) read and write colours only.
            undo_channel_shift(channel_at, strength, max_shift, valid, points, minor,
                               colour_out, gamma)
            if far:
                small_card_colours(colour_out, volume, readable, far_colour)
            lift = np.zeros((n, 3))
            glared = _paper_lift(image, full, index1, g1[0], g1[1], g1[2], g1[3], major,
                                 minor, lifted, valid, card_white, gamma, lift)
            glared = _paper_lift(small, small_scale, index2, g2[0], g2[1], g2[2], g2[3], major,
                                 minor, lifted, valid, card_white, gamma, lift) or glared
            if glared:
                raw = _raw_table(card_white, gamma)
                lifted_peaks(g1[5], raw, lift, g1[9], connected1, g1[2], c1, g1[3], full,
                             index1, major, minor, max_shift, valid, readable, colour_out,
                             lifted_colour)
                lifted_peaks(g2[5], raw, lift, g2[9], connected2, g2[2], c2, g2[3],
                             small_scale, index2, major, minor, max_shift, valid, readable,
                             colour_out, lifted_colour)
            uncover1 = _uncover(index1, minor, valid, readable, partial, inside)
            uncover2 = _uncover(index2, minor, valid, readable, partial, inside)
    return ((fit, points, valid, readable, peak, colour_out, area, inside, partial, centred,
             major, minor, far, far_colour, glared, lifted_colour),
            (index1, g1[1], g1[2], g1[3], g1[4], g1[9], g1[11], g1[6], dark1, uncover1),
            (index2, g2[1], g2[2], g2[3], g2[4], g2[9], g2[11], g2[6], dark2, uncover2))


@numba.njit(cache=True, nogil=False)
def _median_where(values, chosen, index, least):
    """
    Median of ``values[k]`` where ``chosen[index[k]]``; 0 when fewer than ``least`` are.

    As :func:`~.stats.median` (the middle value, or the mean of the two).
    """
    picked = np.empty(len(values))
    n = 0
    for k in range(len(values)):
        if chosen[index[k]]:
            picked[n] = values[k]
            n += 1
    if n < least or n == 0:
        return 0.0
    # Insertion sort: a card's few dozen values (and it compiles in a
    # fraction of the time np.sort takes).
    for a in range(1, n):
        v = picked[a]
        b = a - 1
        while b >= 0 and picked[b] > v:
            picked[b + 1] = picked[b]
            b -= 1
        picked[b + 1] = v
    m = n // 2
    return picked[m] if n % 2 else (picked[m - 1] + picked[m]) / 2


@numba.njit(cache=True, nogil=False)
def _flood(dark, keep, start, stack):
    """Set ``keep`` over the 8-connected region of ``dark`` holding flat index ``start``."""
    size = dark.shape[0]
    keep[start // size, start % size] = True
    stack[0] = start
    depth = 1
    while depth > 0:
        depth -= 1
        y, x = stack[depth] // size, stack[depth] % size
        for yy in range(max(y - 1, 0), min(y + 2, size)):
            for xx in range(max(x - 1, 0), min(x + 2, size)):
                # A pixel goes on the stack once (kept first): the stack
                # never holds more than the window's pixels.
                if dark[yy, xx] and not keep[yy, xx]:
                    keep[yy, xx] = True
                    stack[depth] = yy * size + xx
                    depth += 1


@numba.njit(cache=True, nogil=False)
def _asymmetry(weight, region, span, c0, c1, sigma, rows):
    """
    How far ``weight`` is from point-symmetric about (c0, c1), less the noise.

    Each pixel of ``region`` (within ``span``, as from :func:`_span`)
    whose reflection through (c0, c1), to the nearest pixel (halves
    rounded up), is in ``region`` too is compared with ``weight`` reflected
    there bilinearly (rows, then columns: the interpolation is separable;
    0 beyond the window). Returns |w - reflected w| / (w + reflected w)
    summed, less 1.13 ``sigma`` per pixel with weight over that sum.
    ``rows`` is scratch (S, S) float32.
    """
    size = weight.shape[0]
    x0, x1, y0, y1 = span
    _reflect_rows(weight, c1, rows, y0, y1)
    total, difference, count = 0.0, 0.0, 0
    for y in range(y0, y1):
        for x in range(x0, x1):
            if not region[y, x]:
                continue
            ny = _floor_index(2.0 * c1 - y + 0.5, size)
            nx = _floor_index(2.0 * c0 - x + 0.5, size)
            if ny < 0 or ny >= size or nx < 0 or nx >= size or not region[ny, nx]:
                continue
            own = weight[y, x]
            mirror = _reflect_column(rows, y, x, c0)
            total += own + mirror
            difference += abs(own - mirror)
            if own > 0.0:
                count += 1
    # Sums as float32 would hold them, then as the numpy code combined them.
    total = max(total, 1e-6)
    noise = np.float64(_F32(1.13) * sigma) * count / total
    return difference / total - noise


@numba.njit(cache=True, nogil=False)
def _reflect_rows(a, c1, rows, y0, y1):
    """Reflect rows ``y0 .. y1 - 1`` of (S, S) ``a`` through row ``c1`` (bilinear) to ``rows``."""
    size = a.shape[0]
    for y in range(y0, y1):
        pos = 2.0 * c1 - y
        b = np.floor(pos)
        f = _F32(pos - b)
        i = _floor_index(pos, size)
        for x in range(size):
            r0 = a[i, x] if 0 <= i < size else _F32(0.0)
            r1 = a[i + 1, x] if 0 <= i + 1 < size else _F32(0.0)
            rows[y, x] = (_F32(1.0) - f) * r0 + f * r1


@numba.njit(cache=True, nogil=False)
def _reflect_column(rows, y, x, c0):
    """Pixel (x, y) of the row-reflected ``rows`` reflected through column ``c0``, bilinear."""
    size = rows.shape[0]
    pos = 2.0 * c0 - x
    b = np.floor(pos)
    f = _F32(pos - b)
    i = _floor_index(pos, size)
    r0 = rows[y, i] if 0 <= i < size else _F32(0.0)
    r1 = rows[y, i + 1] if 0 <= i + 1 < size else _F32(0.0)
    return (_F32(1.0) - f) * r0 + f * r1


@numba.njit(cache=True, nogil=False)
def _floor_index(v, size):
    """floor(v) as an index, or -2 (off the window either way) when far outside ``0 .. size``."""
    return int(np.floor(v)) if -2.0 <= v <= size + 1.0 else -2


@numba.njit(cache=True, nogil=False)
def colours(pixels, table, cell, window, connected, axes, centres, pred, base, scale, index,
            major, minor, max_shift, valid, readable, colour, channel_at, strength, sums,
            volume):
    """
    Per-channel darkness of each window's dot: where each channel's image is, and its peak.

    ``pixels`` (K, S, S, 3) uint8 and ``table`` (256, 3) float32, each
    level's darkness per channel; ``cell``, ``window`` and ``connected``
    the windows' masks; the other arguments as :func:`last_pass`'s. Each
    channel's centroid is taken over its darkness above 0.1 in the window;
    the peak of the 3x3 mean darkness within the dot's inner part grown by
    the largest channel shift ``max_shift`` round its centre (for a dot
    not ``valid``: not grown, round its prediction), in its cell and not
    apart from it. A dot ``readable`` but not valid stays readable only if
    its darkness there is as even as the valid dots'.

    Writes ``colour`` (the peaks), ``channel_at`` (each channel's centroid,
    image pixels), ``strength`` (its darkness's sum) and, when ``sums``,
    ``volume`` (each channel's darkness summed over the dot's ellipse grown
    by ``_VOLUME_GROW`` pixels, in its cell and not apart from it) at
    ``index``, and updates ``readable``; returns the darkness (K, S, S, 3).
    """
    k_count, size = pixels.shape[0], pixels.shape[1]
    dark = np.empty((k_count, size, size, 3), dtype=np.float32)
    spread = np.empty(k_count)
    total = np.empty(3)
    sx = np.empty(3)
    sy = np.empty(3)
    mean = np.empty(3)
    squares = np.empty(3)
    off = (scale - 1) / 2.0
    for k in range(k_count):
        i = index[k]
        total[:] = 0.0
        sx[:] = 0.0
        sy[:] = 0.0
        for y in range(size):
            for x in range(size):
                for ch in range(3):
                    dark[k, y, x, ch] = table[pixels[k, y, x, ch], ch]
                if not (cell[k, y, x] and window[k, y, x] and connected[k, y, x]):
                    continue
                for ch in range(3):
                    wv = max(dark[k, y, x, ch] - _F32(0.1), _F32(0.0))
                    total[ch] += wv
                    sx[ch] += wv * x
                    sy[ch] += wv * y
        for ch in range(3):
            t = max(total[ch], 1e-6)
            strength[i, ch] = t
            channel_at[i, ch, 0] = (sx[ch] / t + base[k, 0]) * scale + off
            channel_at[i, ch, 1] = (sy[ch] / t + base[k, 1]) * scale + off
        a0, a1, ca, cb, sa, sb, x0, x1, y0, y1 = _peak_region(
            axes, k, centres, pred, major[i], minor[i], max_shift, valid[i], scale, size)
        count = 0
        mean[:] = 0.0
        squares[:] = 0.0
        for ch in range(3):
            colour[i, ch] = 0.0
        for y in range(y0, y1):
            for x in range(x0, x1):
                if not (cell[k, y, x] and connected[k, y, x]) \
                        or _ellipse_at(axes, k, x, y, ca, cb, sa, sb) > 1.0:
                    continue
                count += 1
                for ch in range(3):
                    colour[i, ch] = max(colour[i, ch], _box3_at(dark[k, :, :, ch], x, y))
                    d = dark[k, y, x, ch]
                    mean[ch] += d
                    squares[ch] += d * d
        count = max(count, 1)
        widest = 0.0
        for ch in range(3):
            m = mean[ch] / count
            widest = max(widest, np.sqrt(max(squares[ch] / count - m * m, 0.0)))
        spread[k] = widest
        if not sums:
            continue
        g0 = (major[i] + _VOLUME_GROW) / scale
        g1 = (minor[i] + _VOLUME_GROW) / scale
        sa, sb = _inverse_squares(g0, g1)
        x0, x1, y0, y1 = _span(axes, k, a0, a1, g0, g1, size)
        for ch in range(3):
            volume[i, ch] = 0.0
        for y in range(y0, y1):
            for x in range(x0, x1):
                if cell[k, y, x] and connected[k, y, x] \
                        and _ellipse_at(axes, k, x, y, ca, cb, sa, sb) <= 1.0:
                    for ch in range(3):
                        volume[i, ch] += dark[k, y, x, ch]
    # A dot read for its colour alone must be even in every channel there,
    # as the sure dots are: not half ink, half something else.
    typical = _median_where(spread, valid, index, 3)
    for k in range(k_count):
        i = index[k]
        if readable[i] and not valid[i]:
            readable[i] = spread[k] <= 1.3 * typical + 0.02
    return dark


@numba.njit(cache=True, nogil=False)
def _peak_region(axes, k, centres, pred, major, minor, max_shift, sure, scale, size):
    """
    Where a dot's colour peaks are taken (:func:`colours`), in window ``k``.

    Its inner part grown by the largest channel shift round its centre (a
    dot not ``sure``: not grown, round its prediction). Returns the centre,
    the ellipse's origin and inverse squared semi-axes, and its pixel span.
    """
    grow = max_shift if sure else 0.0
    g0 = (0.6 * major + 0.7 + grow) / scale
    g1 = (0.6 * minor + 0.7 + grow) / scale
    a0 = centres[k, 0] if sure else pred[k, 0]
    a1 = centres[k, 1] if sure else pred[k, 1]
    ca, cb = _ellipse_origin(axes, k, a0, a1)
    sa, sb = _inverse_squares(g0, g1)
    x0, x1, y0, y1 = _span(axes, k, a0, a1, g0, g1, size)
    return a0, a1, ca, cb, sa, sb, x0, x1, y0, y1


@numba.njit(cache=True, nogil=False)
def _paper_lift(source, scale, index, base, size, axes, pred, major, minor, lifted, valid,
                card_white, gamma, lift):
    """
    Write each lifted, ``valid`` dot's paper excess over the card's white into ``lift``.

    Per channel, in linear light: the upper quartile of the paper round
    the dot (between ``_PAPER_RING`` of its radii, within the image: the
    first pass's ring) over ``card_white``, less one; 0 where below it.
    Returns whether any dot has some.
    """
    h, w, channels = source.shape
    any_lift = False
    if channels != 3:
        return any_lift
    # The buffer only for a group with a lifted dot (seldom: a highlight).
    values = np.empty((0, 3), dtype=np.float32)
    for k in range(index.shape[0]):
        i = index[k]
        if not (lifted[i] and valid[i]):
            continue
        if values.shape[0] == 0:
            values = np.empty((size * size, 3), dtype=np.float32)
        c0, c1 = pred[k, 0], pred[k, 1]
        ca, cb, ia, ib, oa, ob, x0, x1, y0, y1 = _paper_ring(
            axes, k, c0, c1, major[i] / scale, minor[i] / scale, size)
        count = 0
        for y in range(y0, y1):
            v = base[k, 1] + y
            if v < 0 or v >= h:
                continue
            for x in range(x0, x1):
                u = base[k, 0] + x
                if u < 0 or u >= w \
                        or not _in_paper_ring(axes, k, x, y, ca, cb, ia, ib, oa, ob):
                    continue
                for ch in range(3):
                    values[count, ch] = source[v, u, ch]
                count += 1
        if count < _MIN_PAPER_PIXELS:
            continue
        for ch in range(3):
            top = np.quantile(values[:count, ch], 0.75)
            lift[i, ch] = max((top / card_white[ch]) ** gamma - 1.0, 0.0)
            any_lift = any_lift or lift[i, ch] > 0.0
    return any_lift


@numba.njit(cache=True, nogil=False)
def _raw_table(white, gamma):
    """Each level's darkness per channel (256, 3) against ``white``, linear, not clipped at 0."""
    table = np.empty((256, 3), dtype=np.float32)
    for ch in range(3):
        for level in range(256):
            table[level, ch] = _F32(1.0 - (level / white[ch]) ** gamma)
    return table


@numba.njit(cache=True, nogil=False)
def lifted_peaks(pixels, raw, lift, cell, connected, axes, centres, pred, scale, index, major,
                 minor, max_shift, valid, readable, colour, out):
    """
    Write each readable dot's colour peaks with its paper's ``lift`` added back into ``out``.

    Where :func:`colours` takes its peaks (:func:`_peak_region`), the 3x3
    mean of each channel's darkness against the card's white (``raw``,
    :func:`_raw_table`: a lifted pixel may be brighter than that white)
    plus the dot's lift in that channel (:func:`_paper_lift`), at least 0.
    A readable dot without lift keeps ``colour``; the others stay NaN.
    """
    k_count, size = pixels.shape[0], pixels.shape[1]
    dark = np.empty((size, size), dtype=np.float32)
    for k in range(k_count):
        i = index[k]
        if not readable[i]:
            continue
        if not (lift[i, 0] > 0.0 or lift[i, 1] > 0.0 or lift[i, 2] > 0.0):
            for ch in range(3):
                out[i, ch] = colour[i, ch]
            continue
        a0, a1, ca, cb, sa, sb, x0, x1, y0, y1 = _peak_region(
            axes, k, centres, pred, major[i], minor[i], max_shift, valid[i], scale, size)
        for ch in range(3):
            up = _F32(lift[i, ch])
            for y in range(size):
                for x in range(size):
                    dark[y, x] = max(raw[pixels[k, y, x, ch], ch] + up, _F32(0.0))
            best = _F32(0.0)
            for y in range(y0, y1):
                for x in range(x0, x1):
                    if cell[k, y, x] and connected[k, y, x] \
                            and _ellipse_at(axes, k, x, y, ca, cb, sa, sb) <= 1.0:
                        best = max(best, _box3_at(dark, x, y))
            out[i, ch] = best


@numba.njit(cache=True, nogil=False)
def small_card(major, minor, valid):
    """Tell whether the median over the ``valid`` dots of ``sqrt(major * minor)`` is small."""
    n = major.shape[0]
    return np.any(valid) and _median_where(np.sqrt(major * minor), valid, np.arange(n),
                                           1) < _VOLUME_BELOW


@numba.njit(cache=True, nogil=False)
def small_card_colours(colour, volume, readable, out):
    """
    Give a far card's colours: each dot's direction from its ``volume``, strength from its peak.

    Writes into ``out`` every ``readable`` dot's ``volume`` scaled so that
    its darkest channel keeps its peak's darkness (``colour``; see
    ``_VOLUME_GROW``), or its peaks where it has no darkness summed (no
    pixel of its cell in reach: a readable row is never left NaN); the
    others stay as they are (NaN).
    """
    for i in range(colour.shape[0]):
        if not readable[i]:
            continue
        top = max(colour[i, 0], colour[i, 1], colour[i, 2])
        most = max(volume[i, 0], volume[i, 1], volume[i, 2])
        for ch in range(3):
            out[i, ch] = volume[i, ch] / most * top if top == top and most > 0.0 \
                else colour[i, ch]


@numba.njit(cache=True, nogil=False)
def undo_channel_shift(channel_at, strength, limit, valid, points, minor, peak, gamma):
    """
    Move each point by its ink's channel shift (see :func:`~.centres._undo_channel_shift`).

    ``channel_at`` (N, 3, 2): each channel's centroid; ``strength`` (N, 3)
    its darkness. A channel is dark in a dot at 0.6 of its darkest
    channel's strength. The card's shifts of red and blue against green
    are the medians (clipped to ``limit``) over the ``valid`` dots dark in
    both. Shifted by more than ``_OWN_CHANNELS_FROM``, a dot whose
    semi-minor axis ``minor`` (image pixels) is ``_OWN_CHANNELS_SIZE``
    times the shift or more is where its dark channels' own images put
    it, each less its shift (weighted by their darkness); a smaller dot
    moves by the mean shift of its dark channels, each weighted by its
    ``peak`` darkness (linear, per channel) in the camera's encoding
    (``gamma``): the image's darkest channel is darker where the darker
    channel's image is. Shifted less: the plain mean of the dark channels'
    shifts.
    """
    n = strength.shape[0]
    dark = np.empty((n, 3), dtype=np.bool_)
    for i in range(n):
        most = max(strength[i, 0], strength[i, 1], strength[i, 2])
        for ch in range(3):
            dark[i, ch] = strength[i, ch] >= 0.6 * most
    shift = np.zeros((3, 2))
    moved = False
    offsets = np.empty(n)
    everyone = np.arange(n)
    for ch in (0, 2):
        both = np.empty(n, dtype=np.bool_)
        for i in range(n):
            both[i] = valid[i] and dark[i, ch] and dark[i, 1]
        for axis in range(2):
            for i in range(n):
                offsets[i] = channel_at[i, ch, axis] - channel_at[i, 1, axis]
            median = _median_where(offsets, both, everyone, 3)
            shift[ch, axis] = min(max(median, -limit), limit)
            moved = moved or shift[ch, axis] != 0.0
    if not moved:
        return
    largest = max(np.hypot(shift[0, 0], shift[0, 1]), np.hypot(shift[2, 0], shift[2, 1]))
    own = largest > _OWN_CHANNELS_FROM
    for i in range(n):
        if own and minor[i] >= _OWN_CHANNELS_SIZE * largest:
            weight, at_x, at_y = 0.0, 0.0, 0.0
            for ch in range(3):
                if dark[i, ch]:
                    weight += strength[i, ch]
                    at_x += strength[i, ch] * (channel_at[i, ch, 0] - shift[ch, 0])
                    at_y += strength[i, ch] * (channel_at[i, ch, 1] - shift[ch, 1])
            if weight > 0.0 and np.isfinite(at_x) and np.isfinite(at_y):
                points[i, 0], points[i, 1] = at_x / weight, at_y / weight
                continue
        weight = 0.0
        bias_x, bias_y = 0.0, 0.0
        for ch in range(3):
            if dark[i, ch]:
                encoded = 1.0
                if own and np.isfinite(peak[i, ch]):
                    encoded = 1.0 - (1.0 - min(max(peak[i, ch], 0.0), 1.0)) ** (1.0 / gamma)
                weight += encoded
                bias_x += encoded * shift[ch, 0]
                bias_y += encoded * shift[ch, 1]
        if weight > 0.0:
            points[i, 0] -= bias_x / weight
            points[i, 1] -= bias_y / weight


@numba.njit(cache=True, nogil=False)
def blur(spread, axes, major, minor, valid):
    """
    Estimate the image's defocus and motion as a covariance from the dots' second moments.

    The covariance is 2x2, in image pixels^2.

    See :func:`~.centres._blur`: the median over the ``valid`` dots of each
    dot's ``spread`` (xx, xy, yy) less its sharp ellipse's (semi-axes
    ``major``, ``minor`` halved, along ``axes``), its eigenvalues at least
    0.1; 0.25 in all directions from fewer than three dots.
    """
    n = spread.shape[0]
    out = np.empty((2, 2))
    if np.sum(valid) < 3:
        out[0, 0], out[0, 1], out[1, 0], out[1, 1] = 0.25, 0.0, 0.0, 0.25
        return out
    excess = np.empty((3, n))
    for i in range(n):
        c, s = axes[i, 0, 0], axes[i, 1, 0]                 # major axis direction
        a2, b2 = major[i] ** 2 / 4, minor[i] ** 2 / 4
        excess[0, i] = spread[i, 0] - (a2 * c * c + b2 * s * s)
        excess[1, i] = spread[i, 1] - (a2 - b2) * c * s
        excess[2, i] = spread[i, 2] - (a2 * s * s + b2 * c * c)
    everyone = np.arange(n)
    xx = _median_where(excess[0], valid, everyone, 1)
    xy = _median_where(excess[1], valid, everyone, 1)
    yy = _median_where(excess[2], valid, everyone, 1)
    # Eigenvalues of the symmetric 2x2, the smaller raised to 0.1.
    middle = 0.5 * (xx + yy)
    radius = np.hypot(0.5 * (xx - yy), xy)
    low, high = middle - radius, middle + radius
    if low >= 0.1:
        out[0, 0], out[0, 1], out[1, 0], out[1, 1] = xx, xy, xy, yy
        return out
    # Unit eigenvector of the larger eigenvalue.
    if radius == 0.0:
        vx, vy = 1.0, 0.0
    elif xx >= yy:
        vx, vy = high - yy, xy
    else:
        vx, vy = xy, high - xx
    norm = np.hypot(vx, vy)
    vx, vy = vx / norm, vy / norm
    high, low = max(high, 0.1), 0.1
    out[0, 0] = high * vx * vx + low * vy * vy
    out[0, 1] = out[1, 0] = (high - low) * vx * vy
    out[1, 1] = high * vy * vy + low * vx * vx
    return out


@numba.njit(cache=True, nogil=False)
def box3(a):
    """3x3 mean of each channel of one (S, S, C) float32 window, its edge pixels repeated."""
    size, channels = a.shape[0], a.shape[2]
    out = np.empty_like(a)
    for ch in range(channels):
        for y in range(size):
            for x in range(size):
                out[y, x, ch] = _box3_at(a[:, :, ch], x, y)
    return out


@numba.njit(cache=True, nogil=False)
def paper_pixels(size, pred, to_plane, q0, points, radii, half, in_image):
    """
    Tell which pixels of one (size, size) window should be paper (:func:`.centres._paper`).

    ``pred`` (2): the window point of the spot's centre ``q0`` (metres);
    ``to_plane`` (2, 2): metres per window pixel; ``points`` (P, 2) and
    ``radii`` (P) the card's spots; ``half`` the card's half side;
    ``in_image`` (size, size) bool. A pixel is paper when it is on the card
    and more than three window pixels (in the plane) from every spot's edge.
    Float64, in the order of the numpy code it replaced; a NaN anywhere
    makes no paper.
    """
    out = np.zeros((size, size), dtype=np.bool_)
    a00, a01 = np.float64(to_plane[0, 0]), np.float64(to_plane[0, 1])
    a10, a11 = np.float64(to_plane[1, 0]), np.float64(to_plane[1, 1])
    room = 3.0 * np.sqrt(abs(a00 * a11 - a01 * a10))
    n = points.shape[0]
    # Clear of a spot: its distance above radius + room, compared squared.
    reach = np.empty(n)
    for i in range(n):
        reach[i] = (radii[i] + room) * (radii[i] + room)
    for y in range(size):
        dy = np.float64(y) - pred[1]
        for x in range(size):
            if not in_image[y, x]:
                continue
            dx = np.float64(x) - pred[0]
            qx = q0[0] + a00 * dx + a01 * dy
            qy = q0[1] + a10 * dx + a11 * dy
            if not (half - abs(qx) > room and half - abs(qy) > room):
                continue
            clear = True
            for i in range(n):
                ex, ey = qx - points[i, 0], qy - points[i, 1]
                if not (ex * ex + ey * ey > reach[i]):
                    clear = False
                    break
            out[y, x] = clear
    return out


@numba.njit(cache=True, nogil=False)
def paper_noise(source, pts, roomy):
    """
    Measure the white and noise in 3x3 patches at paper points: (white, spread, roomy spread).

    ``source`` (h, w, C) uint8; ``pts`` (N, 2) image points at least 2 px
    inside it (rounded to the nearest pixel, half to even as numpy's);
    ``roomy`` (N) the points with room round them. ``white`` (C, float32)
    is the median over the points of each channel's centre pixel;
    ``spread`` the median over the points of the mean absolute deviation
    of the darkest channel from its patch mean, and ``roomy spread`` the
    same over the roomy points (:func:`.centres.card_paper` says why).
    """
    n = pts.shape[0]
    channels = source.shape[2]
    white = np.empty(channels, dtype=np.float32)
    pixels = np.empty(n)
    spread = np.empty(n)
    chosen = np.empty(n)
    patch = np.empty(9)
    xs = np.empty(n, dtype=np.intp)
    ys = np.empty(n, dtype=np.intp)
    for i in range(n):
        xs[i] = int(np.rint(pts[i, 0]))
        ys[i] = int(np.rint(pts[i, 1]))
    for ch in range(channels):
        for i in range(n):
            pixels[i] = source[ys[i], xs[i], ch]
        white[ch] = _median(pixels)
    count = 0
    for i in range(n):
        total = 0.0
        for dy in range(3):
            for dx in range(3):
                darkest = 255
                for ch in range(channels):
                    darkest = min(darkest, source[ys[i] + dy - 1, xs[i] + dx - 1, ch])
                patch[3 * dy + dx] = darkest
                total += darkest
        mean = total / 9.0
        deviation = 0.0
        for k in range(9):
            deviation += abs(patch[k] - mean)
        spread[i] = deviation / 9.0
        if roomy[i]:
            chosen[count] = spread[i]
            count += 1
    return white, _median(spread), _median(chosen[:count]) if count else np.nan
