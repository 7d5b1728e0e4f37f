"""
Compiled kernels of the cards and code stages (:mod:`.cards`, :mod:`.code_reading`).

The work of these stages is many small sums and comparisons over a few
dozen blobs or dots per candidate: in numpy it is the fixed cost of a
few thousand small calls a frame, not arithmetic. Here each step is one
call of a loop compiled by numba. The method and its reasons are
documented where it is orchestrated (:mod:`.cards`, :mod:`.code_reading`);
these kernels do the same arithmetic, in the same order where a decision
depends on it.

numba does not check bounds: every index a kernel computes is clipped or
tested against its array's shape here, and the callers pass contiguous
arrays of fixed dtypes (float64 values, int32 labels and boxes, intp
indices) so that each kernel compiles once (``cache=True``: once per
installation, then loaded).
"""

import math

import numba
import numpy as np

from ..card.pattern import RING_POINTS

_SLOT_ANGLE = math.pi / 4          # 45 degrees between ring slots
_TWO_PI = 2 * math.pi


@numba.njit(cache=True, nogil=True)
def _wrap(a):
    """Angle wrapped to [-pi, pi) (``%`` as Python's and numpy's: the divisor's sign)."""
    return (a + math.pi) % _TWO_PI - math.pi


@numba.njit(cache=True, nogil=True)
def _eig2(a, b, c):
    """
    Eigenvalues (ascending) of [[a, b], [b, c]] and the unit eigenvector of the larger.

    The smaller eigenvalue is taken from the product (as LAPACK's 2x2 solver
    does), not from the difference of two near-equal numbers.
    """
    sm = a + c
    rt = math.hypot(a - c, 2.0 * b)
    big = 0.5 * (sm + rt)
    small = 0.5 * (sm - rt)
    if sm > 0.0 and big > 0.0:
        acmx, acmn = (a, c) if abs(a) > abs(c) else (c, a)
        small = (acmx / big) * acmn - (b / big) * b
    # Two expressions of the same eigenvector: the longer is the accurate one.
    x1, y1 = big - c, b
    x2, y2 = b, big - a
    if x1 * x1 + y1 * y1 >= x2 * x2 + y2 * y2:
        ex, ey = x1, y1
    else:
        ex, ey = x2, y2
    norm = math.hypot(ex, ey)
    if norm > 0.0:
        ex, ey = ex / norm, ey / norm
    else:
        ex, ey = 1.0, 0.0
    return small, big, ex, ey


@numba.njit(cache=True, nogil=True)
def _matrix_function(f_small, f_big, ex, ey):
    """Symmetric 2x2 map with eigenvalues f_small, f_big; (ex, ey) the f_big direction."""
    out = np.empty((2, 2))
    d = f_big - f_small
    out[0, 0] = f_small + d * ex * ex
    out[0, 1] = d * ex * ey
    out[1, 0] = out[0, 1]
    out[1, 1] = f_small + d * ey * ey
    return out


@numba.njit(cache=True, nogil=True)
def blob_covariance(labels, box, label, scale):
    """
    Second central moments (image pixels^2) of one component: (xx, xy, yy).

    As :meth:`.dots.Blobs.covariance` (OpenCV's moments of the component's
    mask, plus a pixel's own 1/12) from integer sums over its box, clipped
    to the label image.
    """
    h, w = labels.shape
    x0 = min(max(int(box[0]), 0), w)
    y0 = min(max(int(box[1]), 0), h)
    x1 = min(max(x0 + int(box[2]), x0), w)
    y1 = min(max(y0 + int(box[3]), y0), h)
    m00 = m10 = m01 = m20 = m11 = m02 = 0
    for y in range(y0, y1):
        yy = y - y0
        for x in range(x0, x1):
            if labels[y, x] == label:
                xx = x - x0
                m00 += 1
                m10 += xx
                m01 += yy
                m20 += xx * xx
                m11 += xx * yy
                m02 += yy * yy
    inv = 1.0 / m00 if m00 > 0 else 0.0
    cx, cy = m10 * inv, m01 * inv
    mu20 = m20 - m10 * cx
    mu11 = m11 - m10 * cy
    mu02 = m02 - m01 * cy
    a = max(float(m00), 1.0)
    s2 = float(scale * scale)
    return s2 * (mu20 / a + 1 / 12), s2 * (mu11 / a), s2 * (mu02 / a + 1 / 12)


@numba.njit(cache=True, nogil=True)
def _vote_slots(rho, ang, ring_rho):
    """
    Scale of the rings and angle of slot 0 by voting; (found, scale, phase).

    Every neighbour, taken as a dot of every ring, proposes a scale and a
    slot angle; the proposal that puts most neighbours on a ring and a
    45-degree slot, softly weighted (a card's dots sit on their rings and
    slots to within a few percent and degrees, a textured floor's blobs
    only roughly), wins; among equal scores the scale the centre's own
    size predicts. The first best proposal in (neighbour, ring) order.
    """
    n = rho.shape[0]
    n_rings = ring_rho.shape[0]
    best = -np.inf
    best_count = -1
    best_scale = best_phase = 0.0
    found = False
    for i in range(n):
        for r in range(n_rings):
            scale = rho[i] / ring_rho[r]
            if not (scale > 0.55 and scale < 1.6):
                continue
            phase = ang[i]
            count = 0
            fit = 0.0
            for j in range(n):
                d = _wrap(ang[j] - phase)
                dslot = abs(d - np.rint(d / _SLOT_ANGLE) * _SLOT_ANGLE)
                dr = abs(rho[j] / (scale * ring_rho[0]) - 1.0)
                for rr in range(1, n_rings):
                    dr = min(dr, abs(rho[j] / (scale * ring_rho[rr]) - 1.0))
                if dr < 0.2 and dslot < 0.3:
                    count += 1
                    qs, qr = dslot / 0.15, dr / 0.1
                    fit += math.exp(-(qs * qs) - qr * qr)
            value = fit - 0.5 * abs(math.log(scale))
            if not found or value > best:
                found = True
                best, best_count, best_scale, best_phase = value, count, scale, phase
    if not found or best_count < RING_POINTS - 2:
        return False, 0.0, 0.0
    return True, best_scale, best_phase


@numba.njit(cache=True, nogil=True)
def _assign(ox, oy, near, to_unit, ring_rho, slot_blob):
    """
    Give the neighbours their (ring, slot) in ``slot_blob`` (filled with -1); False if few.

    ``ox, oy``: the neighbours' offsets from the centre (pixels), mapped by
    ``to_unit`` to the frame where the rings are circles of radii
    ``ring_rho``. Each neighbour goes to the ring and 45-degree slot
    nearest its position, each slot to its cheapest neighbour.
    """
    n = ox.shape[0]
    n_rings = ring_rho.shape[0]
    rho = np.empty(n)
    ang = np.empty(n)
    idx = np.empty(n, dtype=np.intp)
    m = 0
    for i in range(n):
        x = ox[i] * to_unit[0, 0] + oy[i] * to_unit[0, 1]
        y = ox[i] * to_unit[1, 0] + oy[i] * to_unit[1, 1]
        r = math.hypot(x, y)
        if r > 0.55 * ring_rho[n_rings - 1] and r < 1.6 * ring_rho[0]:
            rho[m] = r
            ang[m] = math.atan2(y, x)
            idx[m] = near[i]
            m += 1
    if m < RING_POINTS - 2:
        return False
    rho, ang, idx = rho[:m], ang[:m], idx[:m]
    found, scale, phase = _vote_slots(rho, ang, ring_rho)
    if not found:
        return False
    # Each neighbour to (ring, slot) by its predicted position, best first.
    slot = np.empty(m, dtype=np.intp)
    ring = np.empty(m, dtype=np.intp)
    cost = np.empty(m)
    ok = np.zeros(m, dtype=np.bool_)
    for i in range(m):
        k = int(np.rint(_wrap(ang[i] - phase) / _SLOT_ANGLE)) % RING_POINTS
        dang = abs(_wrap(ang[i] - (phase + k * math.pi / 4)))
        best_r = 0
        best_dr = abs(rho[i] / (scale * ring_rho[0]) - 1.0)
        for r in range(1, n_rings):
            dr = abs(rho[i] / (scale * ring_rho[r]) - 1.0)
            if dr < best_dr:
                best_r, best_dr = r, dr
        slot[i], ring[i] = k, best_r
        cost[i] = best_dr + dang
        ok[i] = best_dr < 0.25 and dang < 0.35
    candidates = np.flatnonzero(ok)
    by_cost = candidates[np.argsort(cost[candidates], kind='mergesort')]
    slot_blob[:, :] = -1
    for i in by_cost:
        if slot_blob[ring[i], slot[i]] < 0:
            slot_blob[ring[i], slot[i]] = idx[i]
    total = 0
    most = 0
    for r in range(n_rings):
        count = 0
        for k in range(RING_POINTS):
            count += slot_blob[r, k] >= 0
        total += count
        most = max(most, count)
    return total >= 8 and most >= 5


@numba.njit(cache=True, nogil=True)
def group_slots(u, v, area, box, label, labels, scale, ci, ring_rho, min_fill, far_max_area):
    """
    Slot assignments round centre blob ``ci``, best guess first: (slots, ok).

    ``slots`` (2, rings, 8) holds blob indices per ring slot (-1 none) for
    each way of making the rings circles, ``ok`` which of the two gave an
    assignment worth verifying. The first way is the centre blob's own
    ellipse mapped to the unit circle; the second, the neighbours' second
    moments mapped back to circles of the rings' radii (points spread
    evenly on a circle of radius R have R^2 / 2 along any axis): a small
    centre blob, a far card's, is a poor guide to its own shape.
    """
    n = u.shape[0]
    n_rings = ring_rho.shape[0]
    slots = np.full((2, n_rings, RING_POINTS), -1, dtype=np.intp)
    ok = np.zeros(2, dtype=np.bool_)
    if ci < 0 or ci >= n or n_rings < 1:
        return slots, ok
    cxx, cxy, cyy = blob_covariance(labels, box[ci], label[ci], scale)
    small, big, ex, ey = _eig2(cxx, cxy, cyy)
    if not small > 0.0:
        return slots, ok
    semi0, semi1 = 2.0 * math.sqrt(small), 2.0 * math.sqrt(big)
    if semi0 < 0.8:
        return slots, ok
    fill = area[ci] / (math.pi * semi0 * semi1)
    if not (min_fill <= fill and fill <= 1.4):
        return slots, ok
    # Only blobs within reach of the outer ring: O(blobs) per candidate.
    reach = 1.7 * ring_rho[0] * semi1
    uc, vc, ac = u[ci], v[ci], area[ci]
    near = np.empty(n, dtype=np.intp)
    within = np.empty(n, dtype=np.intp)
    n_near = n_within = 0
    for j in range(n):
        ratio = area[j] / ac
        if abs(u[j] - uc) < reach and abs(v[j] - vc) < reach and ratio < 1.2:
            within[n_within] = j
            n_within += 1
            if ratio > 0.08:
                near[n_near] = j
                n_near += 1
    n_faint = n_within - n_near
    if ac <= far_max_area * scale * scale and n_faint > 0 \
            and n_within <= 3 * RING_POINTS * n_rings:
        # A far card's pale ring dots: any blob at all, unless crowded.
        near, n_near = within, n_within
    if n_near < RING_POINTS - 2:
        return slots, ok
    near = near[:n_near]
    ox = np.empty(n_near)
    oy = np.empty(n_near)
    for i in range(n_near):
        ox[i] = u[near[i]] - uc
        oy[i] = v[near[i]] - vc
    to_unit = _matrix_function(1.0 / semi0, 1.0 / semi1, ex, ey)
    ok[0] = _assign(ox, oy, near, to_unit, ring_rho, slots[0])
    sxx = sxy = syy = 0.0
    for i in range(n_near):
        sxx += ox[i] * ox[i]
        sxy += ox[i] * oy[i]
        syy += oy[i] * oy[i]
    small, big, ex, ey = _eig2(sxx / n_near, sxy / n_near, syy / n_near)
    if small > 0.0:
        mean_sq = 0.0
        for r in range(n_rings):
            mean_sq += ring_rho[r] * ring_rho[r]
        target = math.sqrt(mean_sq / n_rings / 2.0)
        to_unit = _matrix_function(target / math.sqrt(small), target / math.sqrt(big), ex, ey)
        ok[1] = _assign(ox, oy, near, to_unit, ring_rho, slots[1])
    return slots, ok


@numba.njit(cache=True, nogil=True)
def _map_point(H, x, y):
    """Homography image of plane point (x, y): (u, v, w), w the projective divisor."""
    pu = x * H[0, 0] + y * H[0, 1] + H[0, 2]
    pv = x * H[1, 0] + y * H[1, 1] + H[1, 2]
    w = x * H[2, 0] + y * H[2, 1] + H[2, 2]
    return pu / w, pv / w, w


@numba.njit(cache=True, nogil=True)
def _local_scale(H, u, v, w):
    """Image scale (pixels per metre, geometric mean of the axes) where the map gives (u, v)."""
    j00 = (H[0, 0] - u * H[2, 0]) / w
    j01 = (H[0, 1] - u * H[2, 1]) / w
    j10 = (H[1, 0] - v * H[2, 0]) / w
    j11 = (H[1, 1] - v * H[2, 1]) / w
    return math.sqrt(abs(j00 * j11 - j01 * j10))


@numba.njit(cache=True, nogil=True)
def h_scales(H, xy):
    """Local image scale of the homography at plane points (N, 2)."""
    out = np.empty(xy.shape[0])
    for i in range(xy.shape[0]):
        u, v, w = _map_point(H, xy[i, 0], xy[i, 1])
        out[i] = _local_scale(H, u, v, w)
    return out


@numba.njit(cache=True, nogil=True)
def homography_residuals(H, obj, img, radii, max_error, min_tolerance):
    """
    Each point's distance (pixels) off the homography and its tolerance: (err, tol).

    The tolerance is ``max_error`` times the dot's image radius (``radii``
    in metres times the local scale), at least ``min_tolerance``.
    """
    n = obj.shape[0]
    err = np.empty(n)
    tol = np.empty(n)
    for i in range(n):
        u, v, w = _map_point(H, obj[i, 0], obj[i, 1])
        du, dv = u - img[i, 0], v - img[i, 1]
        err[i] = math.sqrt(du * du + dv * dv)
        t = max_error * _local_scale(H, u, v, w) * radii[i]
        # NaN stays NaN (as numpy's maximum): such a point is no inlier.
        tol[i] = t if (t != t or t > min_tolerance) else min_tolerance
    return err, tol


@numba.njit(cache=True, nogil=True)
def _median_sorted(s):
    """Median of sorted values (the middle one, or the mean of the two middle ones)."""
    m = s.shape[0] // 2
    return s[m] if s.shape[0] % 2 else (s[m - 1] + s[m]) / 2


@numba.njit(cache=True, nogil=True)
def centre_evidence(u, v, area, box, scale, rho_out, min_area, min_neighbours, cell):
    """
    Blobs that could be a card's centre and their evidence: (idx, evidence, reach).

    For every blob of at least ``min_area``, the blobs between 0.06 and 1
    times its area within ``reach`` of it (a square, on a grid of ``cell``
    pixels), counted with summed area tables, one per octave of blob area;
    those with at least ``min_neighbours``, in blob order. ``reach`` (per
    blob) is 1.5 times the outer ring's radius for a centre of the blob's
    extent, plus 2 pixels.
    """
    n = u.shape[0]
    reach = np.empty(n)
    gx = np.empty(n, dtype=np.intp)
    gy = np.empty(n, dtype=np.intp)
    octave = np.empty(n, dtype=np.intp)
    gw = gh = 1
    first, last = 0, 0
    for j in range(n):
        if not (abs(u[j]) < 1e7 and abs(v[j]) < 1e7 and area[j] >= 0.0):
            raise ValueError('blobs: centres and areas must be finite')
        half = 0.5 * scale * float(max(box[j, 2], box[j, 3]))
        reach[j] = 1.5 * rho_out * max(half, math.sqrt(area[j] / math.pi)) + 2.0
        gx[j] = int(max(u[j], 0.0)) // cell
        gy[j] = int(max(v[j], 0.0)) // cell
        octave[j] = int(math.floor(math.log2(max(area[j], 1.0))))
        gw, gh = max(gw, gx[j] + 1), max(gh, gy[j] + 1)
        if j == 0 or octave[j] < first:
            first = octave[j]
        if j == 0 or octave[j] > last:
            last = octave[j]
    levels = last - first + 1
    # table[k, y, x]: blobs of octave <= first + k - 1 in cells [0, y) x [0, x).
    table = np.zeros((levels + 1, gh + 1, gw + 1), dtype=np.int32)
    for j in range(n):
        table[min(max(octave[j] - first, 0), levels - 1) + 1,
              min(max(gy[j], 0), gh - 1) + 1, min(max(gx[j], 0), gw - 1) + 1] += 1
    for k in range(1, levels + 1):
        for y in range(1, gh + 1):
            for x in range(1, gw + 1):
                table[k, y, x] += table[k - 1, y, x] + table[k, y - 1, x] + table[k, y, x - 1] \
                    - table[k - 1, y - 1, x] - table[k - 1, y, x - 1] - table[k, y - 1, x - 1] \
                    + table[k - 1, y - 1, x - 1]
    idx = np.empty(n, dtype=np.intp)
    evidence = np.empty(n, dtype=np.intp)
    m = 0
    for j in range(n):
        if not area[j] >= min_area:
            continue
        lo = min(max(int(math.floor(math.log2(0.06 * area[j]))) - first, 0), levels)
        hi = min(max(octave[j] - first + 1, 0), levels)
        x0 = min(max(int((u[j] - reach[j]) // cell), 0), gw)
        x1 = min(max(int((u[j] + reach[j]) // cell) + 1, 0), gw)
        y0 = min(max(int((v[j] - reach[j]) // cell), 0), gh)
        y1 = min(max(int((v[j] + reach[j]) // cell) + 1, 0), gh)
        count = (table[hi, y1, x1] - table[hi, y0, x1] - table[hi, y1, x0] + table[hi, y0, x0]) \
            - (table[lo, y1, x1] - table[lo, y0, x1] - table[lo, y1, x0] + table[lo, y0, x0]) \
            - 1         # the blob itself
        if count >= min_neighbours:
            idx[m] = j
            evidence[m] = count
            m += 1
    return idx[:m], evidence[:m], reach


@numba.njit(cache=True, nogil=True)
def ring_evidence(u, v, area, idx, reach, min_neighbours, most):
    """
    How much the blobs round each candidate ``idx`` look like a card's rings.

    The neighbours within ``reach`` (found through the blobs sorted by
    column, so each candidate costs the blobs in its own reach) of a ring
    dot's size (0.12 to 0.9 times the centre's area) that are of one size
    (within a factor 1.6 of their median): their number (at most ``most``)
    plus twice the octants round the centre they cover; 0 with fewer than
    ``min_neighbours`` neighbours.
    """
    n = u.shape[0]
    order = np.argsort(u, kind='mergesort')
    su = u[order]
    score = np.zeros(idx.shape[0])
    near = np.empty(n, dtype=np.intp)
    for i in range(idx.shape[0]):
        ci = idx[i]
        if ci < 0 or ci >= n:
            continue
        r = reach[ci]
        lo = np.searchsorted(su, u[ci] - r)
        hi = np.searchsorted(su, u[ci] + r)
        m = 0
        for s in range(lo, hi):
            j = order[s]
            ratio = area[j] / area[ci]
            if abs(v[j] - v[ci]) < r and ratio > 0.12 and ratio < 0.9:
                near[m] = j
                m += 1
        if m < min_neighbours:
            continue
        a = np.empty(m)
        for k in range(m):
            a[k] = area[near[k]]
        typical = _median_sorted(np.sort(a))
        octants = np.zeros(8, dtype=np.bool_)
        alike = 0
        for k in range(m):
            j = near[k]
            if area[j] > typical / 1.6 and area[j] < typical * 1.6:
                alike += 1
                t = math.atan2(v[j] - v[ci], u[j] - u[ci])
                octants[int(math.floor((t + math.pi) / (math.pi / 4))) % 8] = True
        score[i] = min(alike, most) + 2 * np.count_nonzero(octants)
    return score


@numba.njit(cache=True, nogil=True)
def ring_of_spots(spots, radius, reach, min_spots):
    """
    Whether faint spots (offsets (N, 2) from a small centre) look like its rings.

    The spots between 1.5 centre radii and ``reach``: at least ``min_spots``
    of them, in at least five of the eight directions, their mean near
    the centre (within 0.4 times their median distance). Returns
    ``(ring-like, number of ring spots)``.
    """
    n = spots.shape[0]
    rho = np.empty(n)
    keep = np.empty(n, dtype=np.intp)
    m = 0
    for i in range(n):
        r = math.hypot(spots[i, 0], spots[i, 1])
        if r > 1.5 * radius and r < reach:
            rho[m] = r
            keep[m] = i
            m += 1
    if m < min_spots:
        return False, m
    octants = np.zeros(8, dtype=np.bool_)
    sx = sy = 0.0
    for k in range(m):
        x, y = spots[keep[k], 0], spots[keep[k], 1]
        octants[int((math.atan2(y, x) + math.pi) * (8 / (2 * math.pi))) % 8] = True
        sx += x
        sy += y
    if np.count_nonzero(octants) < 5:
        return False, m
    typical = _median_sorted(np.sort(rho[:m]))
    return not math.hypot(sx / m, sy / m) > 0.4 * typical, m
