"""
Compiled small passes of the dots stage (:mod:`.dots`).

Each is a handful of numpy calls on a few dozen values, called several
times a frame: the fixed cost of the calls, not arithmetic. Here each is
one compiled loop doing the same arithmetic in the same order (float64,
the tables' float32 values widened as numpy widens them), so the results
are the numpy code's to the bit. The method is documented in :mod:`.dots`.

numba checks no bounds: every index computed here is clipped to its
array's shape. The kernels keep the GIL, as the other kernels do
(:mod:`.spot_kernels` says why), and compile once per installation
(``cache=True``), for the one argument signature the callers pass.
"""

import numba
import numpy as np

_kernel = numba.njit(cache=True, nogil=False, error_model='numpy')


@_kernel
def bilinear(table, u, v, step):
    """
    Bilinear look-up of a grid ``table`` (H, W float32) at image points ``u``, ``v`` (float64).

    Grid cell (i, j) is centred on image pixel ``step * (j + 0.5) - 0.5``
    (x) and likewise in y; points beyond the outer cells' centres take
    their values. NaN points give NaN (their indices are clipped into the
    table, the weights stay NaN).
    """
    th, tw = table.shape
    n = u.shape[0]
    out = np.empty(n)
    for i in range(n):
        gx = _clip((u[i] + 0.5) / step - 0.5, 0.0, tw - 1.0)
        gy = _clip((v[i] + 0.5) / step - 0.5, 0.0, th - 1.0)
        x0 = _cell(gx, tw)
        y0 = _cell(gy, th)
        fx = _clip(gx - x0, 0.0, 1.0)
        fy = _clip(gy - y0, 0.0, 1.0)
        x1 = min(x0 + 1, tw - 1)
        y1 = min(y0 + 1, th - 1)
        t00 = np.float64(table[y0, x0])
        t01 = np.float64(table[y0, x1])
        t10 = np.float64(table[y1, x0])
        t11 = np.float64(table[y1, x1])
        out[i] = ((1 - fy) * ((1 - fx) * t00 + fx * t01)
                  + fy * ((1 - fx) * t10 + fx * t11))
    return out


@_kernel
def _clip(x, lo, hi):
    """Clip one value as numpy does (NaN stays NaN)."""
    if x < lo:
        return lo
    if x > hi:
        return hi
    return x


@_kernel
def _cell(g, size):
    """Lower grid index of a clipped grid coordinate: in 0 .. size - 2 (0 for one cell, NaN)."""
    if size < 2 or not g >= 0.0:
        return 0
    return min(int(g), size - 2)


@_kernel
def combed_tiles(image, tile_rows):
    """
    Count the tiles of an image (H, W, C uint8) whose rows disagree as a comb's.

    :func:`.dots.combed` says what is measured, on every sixteenth column
    of the green channel (the only one of a grey image): per tile of
    ``tile_rows`` rows and four such columns, the summed curvature over one
    row (``t1``) and over two (``t2``); a tile counts when ``t1 > 6 *
    pixels`` and ``t1 > 3 * t2``. Integer arithmetic, as the numpy code's
    (int16 pixels, int32 sums, both exact). Stops counting at two (enough
    to say combed).
    """
    rows_in, width, channels = image.shape
    ch = 1 if channels > 1 else 0
    cols_in = (width + 15) // 16
    h = (rows_in - 4) // 2 * 2
    if h < 2 * tile_rows or tile_rows < 1:
        return 0
    rows = h // tile_rows * tile_rows
    cols = cols_in // 4 * 4
    pixels = tile_rows * 4
    count = 0
    t1 = np.zeros(cols // 4, dtype=np.int64)
    t2 = np.zeros(cols // 4, dtype=np.int64)
    for r0 in range(2, 2 + rows, tile_rows):
        t1[:] = 0
        t2[:] = 0
        # Row by row (the image's order in memory), into the band's tiles.
        for r in range(r0, r0 + tile_rows):
            for j in range(cols):
                c = 16 * j
                mid = 2 * np.int64(image[r, c, ch])
                t1[j // 4] += abs(mid - np.int64(image[r - 1, c, ch])
                                  - np.int64(image[r + 1, c, ch]))
                t2[j // 4] += abs(mid - np.int64(image[r - 2, c, ch])
                                  - np.int64(image[r + 2, c, ch]))
        for t in range(cols // 4):
            if t1[t] > 6 * pixels and t1[t] > 3 * t2[t]:
                count += 1
                if count >= 2:
                    return count
    return count


@_kernel
def dot_components(stats, centroids, scale, ox, oy, max_area, h, w):
    """
    Keep the components of a (h, w) mask that could be dots; their centres in image pixels.

    ``stats`` (N, 5 int32) and ``centroids`` (N, 2 float64) are OpenCV's
    connected components (row 0 the background). Kept: at most
    ``max_area`` mask pixels, filling a quarter of their box, not longer
    than six times their width plus two, not touching the mask's border
    (:func:`.dots._components` says why). Returns the kept rows, and their
    centres mapped to the image (``scale`` image pixels a mask pixel, the
    mask's origin at image pixel (``ox``, ``oy``)).
    """
    n = stats.shape[0]
    keep = np.empty(n, dtype=np.intp)
    count = 0
    for i in range(1, n):
        x, y = stats[i, 0], stats[i, 1]
        bw, bh = stats[i, 2], stats[i, 3]
        area = stats[i, 4]
        if (area <= max_area and area * 4 >= bw * bh
                and max(bw, bh) <= 6 * min(bw, bh) + 2
                and x > 0 and y > 0 and x + bw < w and y + bh < h):
            keep[count] = i
            count += 1
    idx = keep[:count].copy()
    u = np.empty(count)
    v = np.empty(count)
    s = np.float64(scale)
    for k in range(count):
        i = idx[k]
        u[k] = ox + s * (centroids[i, 0] + 0.5) - 0.5
        v[k] = oy + s * (centroids[i, 1] + 0.5) - 0.5
    return idx, u, v


@_kernel
def threshold(white, noise, keep_ratio, noise_factor, min_white):
    """
    Grey level below which a pixel is dot, per grid cell (uint8), from the white and noise.

    :func:`.dots._threshold` says why. float32 throughout (``white``,
    ``noise`` float32 grids; ``keep_ratio`` = 1 - dark_ratio and
    ``noise_factor`` float32 scalars), as numpy computes it with Python
    scalars; truncated to uint8 after clipping to 0..255 (NaN gives 0).
    """
    h, w = white.shape
    out = np.empty((h, w), dtype=np.uint8)
    half = np.float32(0.5)
    two = np.float32(2.0)
    zero = np.float32(0.0)
    top = np.float32(255.0)
    for y in range(h):
        for x in range(w):
            wv = white[y, x]
            margin = max(keep_ratio * wv, min(noise_factor * noise[y, x], half * wv))
            margin = max(margin, two)
            t = wv - margin if wv >= min_white else zero
            t = min(max(t, zero), top)
            out[y, x] = np.uint8(t) if t == t else np.uint8(0)
    return out


@_kernel
def faint_components(stats, centroids, own, max_area, scale, dx, dy):
    """
    The spots of :meth:`.dots.DotImage.faint_spots` from their connected components.

    ``stats``, ``centroids``: OpenCV's (row 0 the background); ``own``: the
    label at the centre (0: none). Spots of at most ``max_area`` image
    pixels (``scale`` image pixels a side per component pixel), the own
    one left out; their centroids times ``scale`` plus (``dx``, ``dy``).
    Returns the spots (K, 2) and the own spot's area (0 if none).
    """
    n = stats.shape[0]
    xy = np.empty((max(n - 1, 0), 2))
    count = 0
    own_area = 0.0
    for i in range(1, n):
        area = np.float64(stats[i, 4]) * scale * scale
        if i == own:
            own_area = area
            continue
        if area <= max_area:
            xy[count, 0] = centroids[i, 0] * scale + dx
            xy[count, 1] = centroids[i, 1] * scale + dy
            count += 1
    return xy[:count].copy(), own_area


def warm_up() -> None:
    """Compile (or load from the cache) each kernel with the argument types :mod:`.dots` uses."""
    table = np.zeros((2, 2), dtype=np.float32)
    bilinear(table, np.zeros(1), np.zeros(1), 8)
    combed_tiles(np.zeros((40, 40, 3), dtype=np.uint8), 16)
    grid = np.zeros((2, 2), dtype=np.float32)
    threshold(grid, grid, np.float32(0.25), np.float32(10.0), 24)
    faint_components(np.zeros((2, 5), dtype=np.int32), np.zeros((2, 2)), 0, 10.0, 2, 0.0, 0.0)
    dot_components(np.zeros((2, 5), dtype=np.int32), np.zeros((2, 2)), 2, 0, 0, 10.0, 4, 4)


# Loaded at import, as the other kernels are: a node's first frame does not wait.
warm_up()
