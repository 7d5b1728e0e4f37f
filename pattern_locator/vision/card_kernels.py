"""
Compiled kernels of the cards, code and dots stages.

The work of the cards and code stages is many small sums and comparisons
over a few dozen blobs or dots per candidate, and the dots stage has a
few small passes round OpenCV's segmentation: in numpy it is the fixed
cost of a few thousand small calls a frame, not arithmetic. Here each
step is one call of a loop compiled by numba. The method and its reasons
are documented where it is orchestrated (:mod:`.cards`,
:mod:`.code_reading`, :mod:`.dots`); these kernels do the same
arithmetic, in the same order where a decision depends on it.

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

# Compiled once per installation (cached beside the module), with numpy's
# arithmetic: a division by zero gives inf or NaN as in the numpy code these
# kernels replace, not Python's ZeroDivisionError. They keep the GIL, as the
# centres' kernels do (spot_kernels.py says why: a kernel that lets it go
# waits to get it back from the node's other threads).
_kernel = numba.njit(cache=True, nogil=False, error_model='numpy')

_SLOT_ANGLE = math.pi / 4          # 45 degrees between ring slots
_TWO_PI = 2 * math.pi


@_kernel
def _wrap(a):
    """Angle wrapped to [-pi, pi) (``%`` as Python's and numpy's: the divisor's sign)."""
    return (a + math.pi) % _TWO_PI - math.pi


@_kernel
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


@_kernel
def _matrix_function(f_small, f_big, ex, ey):
    """Symmetric 2x2 map with eigenvalues f_small, f_big; (ex, ey) the f_big direction."""
    out = np.empty((2, 2))
    d = f_big - f_small
    out[0, 0] = f_small + d * ex * ex
    out[0, 1] = d * ex * ey
    out[1, 0] = out[0, 1]
    out[1, 1] = f_small + d * ey * ey
    return out


@_kernel
def blob_covariance(labels, box, label, scale):
    """
    Second central moments (image pixels^2) of one component: (xx, xy, yy).

    OpenCV's moments of the component's mask (the tests' reference), plus
    a pixel's own 1/12, from integer sums over its box, clipped to the
    label image.
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


@_kernel
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
    dslot = np.empty(n)
    term = np.empty(n)
    for i in range(n):
        phase = ang[i]
        # Off the nearest slot: the same for every ring this neighbour is taken on.
        for j in range(n):
            d = _wrap(ang[j] - phase)
            dslot[j] = abs(d - np.rint(d / _SLOT_ANGLE) * _SLOT_ANGLE)
        for r in range(n_rings):
            scale = rho[i] / ring_rho[r]
            if not (scale > 0.55 and scale < 1.6):
                continue
            count = 0
            for j in range(n):
                term[j] = 0.0
                if not dslot[j] < 0.3:
                    continue
                dr = abs(rho[j] / (scale * ring_rho[0]) - 1.0)
                for rr in range(1, n_rings):
                    dr = min(dr, abs(rho[j] / (scale * ring_rho[rr]) - 1.0))
                if dr < 0.2:
                    count += 1
                    qs, qr = dslot[j] / 0.15, dr / 0.1
                    term[j] = math.exp(-(qs * qs) - qr * qr)
            # Summed in numpy's order: a symmetric card's opposite dots make
            # near-equal proposals, told apart by the last bits.
            value = _pairwise_sum(term, n) - 0.5 * abs(math.log(scale))
            if not found or value > best:
                found = True
                best, best_count, best_scale, best_phase = value, count, scale, phase
    if not found or best_count < RING_POINTS - 2:
        return False, 0.0, 0.0
    return True, best_scale, best_phase


@_kernel
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
    # Cheapest first (a stable insertion sort: a few dozen neighbours, and
    # no library sort to compile).
    by_cost = np.empty(m, dtype=np.intp)
    n_ok = 0
    for i in range(m):
        if ok[i]:
            j = n_ok
            while j > 0 and cost[by_cost[j - 1]] > cost[i]:
                by_cost[j] = by_cost[j - 1]
                j -= 1
            by_cost[j] = i
            n_ok += 1
    slot_blob[:, :] = -1
    for i in by_cost[:n_ok]:
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


@_kernel
def group_slots(u, v, area, box, label, labels, scale, ci, ring_rho, min_fill, far_max_area,
                second):
    """
    Slot assignment round centre blob ``ci``: (status, slot_blob).

    ``slot_blob`` (rings, 8) holds a blob index per ring slot, -1 for none.
    ``status`` 0: no card can be there (whichever way the rings are made
    circles); 1: an assignment worth verifying; 2: none this way, try the
    other. The first way (``second`` False) maps the centre blob's own
    ellipse to the unit circle; the second, the neighbours' second
    moments to circles of the rings' radii (points spread evenly on a
    circle of radius R have R^2 / 2 along any axis): a small centre blob,
    a far card's, is a poor guide to its own shape.
    """
    slot_blob = np.empty((ring_rho.shape[0], RING_POINTS), dtype=np.intp)
    slot_blob[:, :] = -1
    status = _group_into(u, v, area, box, label, labels, scale, ci, ring_rho, min_fill,
                         far_max_area, second, slot_blob)
    return status, slot_blob


@_kernel
def _group_into(u, v, area, box, label, labels, scale, ci, ring_rho, min_fill, far_max_area,
                second, slot_blob):
    """Do :func:`group_slots`'s work into ``slot_blob``; return its status."""
    n = u.shape[0]
    n_rings = ring_rho.shape[0]
    if ci < 0 or ci >= n or n_rings < 1 or v.shape[0] < n or area.shape[0] < n \
            or box.shape[0] < n or box.shape[1] < 4 or label.shape[0] < n:
        return 0
    cxx, cxy, cyy = blob_covariance(labels, box[ci], np.int64(label[ci]), scale)
    small, big, ex, ey = _eig2(cxx, cxy, cyy)
    if not small > 0.0:
        return 0
    semi0, semi1 = 2.0 * math.sqrt(small), 2.0 * math.sqrt(big)
    if semi0 < 0.8:
        return 0
    fill = area[ci] / (math.pi * semi0 * semi1)
    if not (min_fill <= fill and fill <= 1.4):
        return 0
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
        return 0
    near = near[:n_near]
    ox = np.empty(n_near)
    oy = np.empty(n_near)
    for i in range(n_near):
        ox[i] = u[near[i]] - uc
        oy[i] = v[near[i]] - vc
    if not second:
        to_unit = _matrix_function(1.0 / semi0, 1.0 / semi1, ex, ey)
        return 1 if _assign(ox, oy, near, to_unit, ring_rho, slot_blob) else 2
    sxx = sxy = syy = 0.0
    for i in range(n_near):
        sxx += ox[i] * ox[i]
        sxy += ox[i] * oy[i]
        syy += oy[i] * oy[i]
    small, big, ex, ey = _eig2(sxx / n_near, sxy / n_near, syy / n_near)
    if not small > 0.0:
        return 0
    mean_sq = 0.0
    for r in range(n_rings):
        mean_sq += ring_rho[r] * ring_rho[r]
    target = math.sqrt(mean_sq / n_rings / 2.0)
    to_unit = _matrix_function(target / math.sqrt(small), target / math.sqrt(big), ex, ey)
    return 1 if _assign(ox, oy, near, to_unit, ring_rho, slot_blob) else 0


@_kernel
def slot_points(slot_blob, u, v, ci):
    """
    Gather the assigned blobs' centres, the centre blob's last: (rows, points).

    ``rows`` indexes the slot-ordered plane points (ring r slot k at
    ``r * 8 + k``, the centre at ``rings * 8``), ``points`` (N, 2) the
    blobs' (u, v).
    """
    flat = slot_blob.ravel()
    n = 0
    for k in range(flat.shape[0]):
        n += flat[k] >= 0
    rows = np.empty(n + 1, dtype=np.intp)
    points = np.empty((n + 1, 2))
    m = 0
    for k in range(flat.shape[0]):
        j = flat[k]
        if j >= 0 and j < u.shape[0]:
            rows[m] = k
            points[m, 0], points[m, 1] = u[j], v[j]
            m += 1
    rows[m] = flat.shape[0]
    points[m, 0] = points[m, 1] = np.nan          # no such blob: no fit (a NaN centre)
    if ci >= 0 and ci < u.shape[0]:
        points[m, 0], points[m, 1] = u[ci], v[ci]
    return rows[:m + 1], points[:m + 1]


@_kernel
def _map_point(H, x, y):
    """Homography image of plane point (x, y): (u, v, w), w the projective divisor."""
    pu = x * H[0, 0] + y * H[0, 1] + H[0, 2]
    pv = x * H[1, 0] + y * H[1, 1] + H[1, 2]
    w = x * H[2, 0] + y * H[2, 1] + H[2, 2]
    return pu / w, pv / w, w


@_kernel
def _h_jacobian(H, u, v, w):
    """Return the local linear map (j00, j01, j10, j11; px per metre) where H gives (u, v)."""
    return ((H[0, 0] - u * H[2, 0]) / w, (H[0, 1] - u * H[2, 1]) / w,
            (H[1, 0] - v * H[2, 0]) / w, (H[1, 1] - v * H[2, 1]) / w)


@_kernel
def _local_scale(H, u, v, w):
    """Image scale (pixels per metre, geometric mean of the axes) where the map gives (u, v)."""
    j00, j01, j10, j11 = _h_jacobian(H, u, v, w)
    return math.sqrt(abs(j00 * j11 - j01 * j10))


@_kernel
def h_scales(H, xy):
    """Local image scale of the homography at plane points (N, 2)."""
    out = np.empty(xy.shape[0])
    for i in range(xy.shape[0]):
        u, v, w = _map_point(H, xy[i, 0], xy[i, 1])
        out[i] = _local_scale(H, u, v, w)
    return out


@_kernel
def homography_inliers(H, obj, img, radii, max_error, min_tolerance, tol, inliers, first):
    """
    Points on the homography: (ok, now, count, same).

    A point is on it when its distance from the map of its plane point is
    below its tolerance: ``max_error`` times its dot's image radius
    (``radii`` in metres times the local scale), at least
    ``min_tolerance`` pixels. The tolerances are set (in ``tol``) on the
    ``first`` fit and kept after. ``ok`` False when ``H`` is not finite;
    ``count`` the points on it, ``same`` whether they are ``inliers``.
    """
    n = obj.shape[0]
    now = np.zeros(n, dtype=np.bool_)
    finite = True
    for r in range(3):
        for c in range(3):
            finite = finite and abs(H[r, c]) < np.inf
    count = 0
    same = True
    for i in range(n if finite else 0):
        u, v, w = _map_point(H, obj[i, 0], obj[i, 1])
        du, dv = u - img[i, 0], v - img[i, 1]
        err = math.sqrt(du * du + dv * dv)
        if first:
            t = max_error * _local_scale(H, u, v, w) * radii[i]
            # NaN stays NaN (as numpy's maximum): such a point is no inlier.
            tol[i] = t if (t != t or t > min_tolerance) else min_tolerance
        now[i] = err < tol[i]
        count += now[i]
        same = same and now[i] == inliers[i]
    return finite, now, count, same and finite


@_kernel
def _count_true(flags):
    """Count the True values (numpy's count_nonzero, without compiling it)."""
    count = 0
    for k in range(flags.shape[0]):
        count += flags[k]
    return count


@_kernel
def _median(values):
    """
    Median of values (the middle one, or the mean of the two middle ones), as numpy's.

    A selection on a copy (:func:`_median_in_place`): no library sort to
    compile (numba compiles numpy's sorts anew for every kernel that uses
    them, seconds each). NaN gives NaN, as numpy's median; so does no value.
    """
    n = values.shape[0]
    s = values.copy()
    for k in range(n):
        if s[k] != s[k]:
            return s[k]
    return _median_in_place(s, n)


@_kernel
def _median_in_place(values, n):
    """
    Median of ``values[:n]`` (no NaN), as numpy's; reorders them.

    Hoare's selection of the middle value (and, for even ``n``, the largest
    below it): linear time on average; :func:`_median` on a copy, and
    :func:`ring_evidence` on its many short lists.
    """
    if n <= 0:
        return np.nan
    k = n // 2
    lo, hi = 0, n - 1
    while lo < hi:
        pivot = values[(lo + hi) // 2]
        i, j = lo, hi
        while i <= j:
            while values[i] < pivot:
                i += 1
            while values[j] > pivot:
                j -= 1
            if i <= j:
                values[i], values[j] = values[j], values[i]
                i += 1
                j -= 1
        if k <= j:
            hi = j
        elif k >= i:
            lo = i
        else:
            break
    middle = values[k]
    if n % 2:
        return middle
    below = values[0]
    for t in range(1, k):
        below = max(below, values[t])
    return (below + middle) / 2


@_kernel
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
    if v.shape[0] < n or area.shape[0] < n or box.shape[0] < n or box.shape[1] < 4:
        raise ValueError('blobs: u, v, area and box (N, 4) must be as long')
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


# A candidate centre's bare paper (ring_evidence): from beyond its own blurred
# edge, in its moment ellipse's radii; each blob there costs this much of a
# card's 34 points (16 ring dots and 2 marks, 8 octants twice).
_CLEAR_FROM = 1.15
_CLEAR_WEIGHT = 6.0
# Centres of fewer decimated pixels than this: their shape is no guide.
_FUZZY_PIXELS = 9


@_kernel
def ring_evidence(u, v, area, box, label, labels, scale, idx, reach, min_neighbours, most,
                  clear_rho, ring_rho, cell, budget):
    """
    How much the blobs round each candidate ``idx`` look like a card's rings.

    Looked at in the candidate's own frame, where its moment ellipse
    (semi-axes twice the standard deviations) is the unit circle and a
    card's rings are near circles of radii ``R / r_centre``. Between
    ``clear_rho`` and ``ring_rho`` (the rings' zone, on the card's paper),
    the neighbours of a ring dot's size (0.12 to 0.9 times the centre's
    area) that are of one size (within a factor 1.6 of their median): their
    number (at most ``most``, a card's dots and marks) plus twice the
    octants round the centre they cover. Less, for what a card does not
    have: ``_CLEAR_WEIGHT`` for each blob of any dot-like size (0.03 to 1.5
    times the centre's area) between the centre's own blurred edge
    (``_CLEAR_FROM``) and ``clear_rho``, where a card has bare paper, and
    one for each such blob in the rings' zone beyond ``most``: a texture's
    blob has neighbours all round at every distance, more than a card has.
    A centre of fewer than ``_FUZZY_PIXELS`` pixels (``scale`` squared image
    pixels each) is taken as a circle as wide as its longer side, with no
    bare-paper test. 0 with fewer than ``min_neighbours`` ring-sized
    neighbours or no ellipse; only blobs within ``reach`` (a square) count.
    The blobs are sorted into ``cell``-pixel grid cells first, so each
    candidate costs the blobs in its own zone; the candidates are taken in
    ``idx``'s order until ``budget`` cells and blobs have been looked at,
    and those left score -inf: bounded work whatever the clutter.
    """
    n = u.shape[0]
    score = np.zeros(idx.shape[0])
    if n == 0 or v.shape[0] < n or area.shape[0] < n or reach.shape[0] < n \
            or box.shape[0] < n or box.shape[1] < 4 or label.shape[0] < n or cell < 1:
        return score
    # Blobs by grid cell (a counting sort): members[start[c]:start[c + 1]].
    gw = gh = 1
    for j in range(n):
        if not (abs(u[j]) < 1e7 and abs(v[j]) < 1e7):
            return score
        gw = max(gw, int(max(u[j], 0.0)) // cell + 1)
        gh = max(gh, int(max(v[j], 0.0)) // cell + 1)
    start = np.zeros(gw * gh + 1, dtype=np.intp)
    cell_of = np.empty(n, dtype=np.intp)
    for j in range(n):
        c = (int(max(v[j], 0.0)) // cell) * gw + int(max(u[j], 0.0)) // cell
        cell_of[j] = c
        start[c + 1] += 1
    for c in range(gw * gh):
        start[c + 1] += start[c]
    # Each cell's blobs side by side (read in turn, not scattered).
    fill = start[:-1].copy()
    members = np.empty(n, dtype=np.intp)
    cu, cv, ca = np.empty(n), np.empty(n), np.empty(n)
    for j in range(n):
        k = fill[cell_of[j]]
        members[k], cu[k], cv[k], ca[k] = j, u[j], v[j], area[j]
        fill[cell_of[j]] += 1
    near_area = np.empty(n)
    near_x = np.empty(n)
    near_y = np.empty(n)
    sizes = np.empty(n)
    octants = np.zeros(8, dtype=np.bool_)
    clear2, from2, ring2 = clear_rho * clear_rho, _CLEAR_FROM * _CLEAR_FROM, ring_rho * ring_rho
    visits = 0
    for i in range(idx.shape[0]):
        if visits > budget:
            score[i:] = -np.inf
            break
        ci = idx[i]
        if ci < 0 or ci >= n:
            continue
        uc, vc, ac = u[ci], v[ci], area[ci]
        # A centre of a few pixels (a far card's) is no guide to its own
        # shape: a circle as big as its longer side, and no bare-paper test
        # (a tilted card's inner ring comes that close along its short axis).
        fuzzy = ac < _FUZZY_PIXELS * scale * scale
        if fuzzy:
            semi_long = semi_short = max(0.5 * scale * max(box[ci, 2], box[ci, 3]),
                                         math.sqrt(ac / math.pi))
            ex, ey = 1.0, 0.0
        else:
            cxx, cxy, cyy = blob_covariance(labels, box[ci], np.int64(label[ci]), scale)
            small, big, ex, ey = _eig2(cxx, cxy, cyy)
            if not small > 0.0:
                continue
            semi_long, semi_short = 2.0 * math.sqrt(big), 2.0 * math.sqrt(small)
        if not semi_short > 0.0:
            continue
        # The rings' zone, an ellipse: its box, within the square reach.
        ru = min(reach[ci], ring_rho * math.hypot(semi_long * ex, semi_short * ey))
        rv = min(reach[ci], ring_rho * math.hypot(semi_long * ey, semi_short * ex))
        x0 = min(max(int((uc - ru) // cell), 0), gw - 1)
        x1 = min(max(int((uc + ru) // cell), 0), gw - 1)
        y0 = min(max(int((vc - rv) // cell), 0), gh - 1)
        y1 = min(max(int((vc + rv) // cell), 0), gh - 1)
        # Unit vectors along the ellipse's axes, over its semi-axes.
        lx, ly = ex / semi_long, ey / semi_long
        sx, sy = -ey / semi_short, ex / semi_short
        m = 0
        crowd = 0
        inside = 0
        for gy in range(y0, y1 + 1):
            for gx in range(x0, x1 + 1):
                c = gy * gw + gx
                visits += 1 + start[c + 1] - start[c]
                for k in range(start[c], start[c + 1]):
                    du, dv = cu[k] - uc, cv[k] - vc
                    if not (abs(du) < ru and abs(dv) < rv) or members[k] == ci:
                        continue
                    ratio = ca[k] / ac
                    if not (ratio > 0.03 and ratio < 1.5):
                        continue
                    x = du * lx + dv * ly
                    y = du * sx + dv * sy
                    q2 = x * x + y * y
                    if q2 < clear2 and not fuzzy:
                        crowd += q2 > from2
                    elif q2 < ring2 and q2 > from2:
                        inside += 1
                        if ratio > 0.12 and ratio < 0.9:
                            near_area[m] = ca[k]
                            near_x[m] = x
                            near_y[m] = y
                            m += 1
        if m < min_neighbours:
            continue
        for k in range(m):
            sizes[k] = near_area[k]
        typical = _median_in_place(sizes, m)
        octants[:] = False
        alike = 0
        for k in range(m):
            if near_area[k] > typical / 1.6 and near_area[k] < typical * 1.6:
                alike += 1
                x, y = near_x[k], near_y[k]
                # The octant, 45 degrees each from the -x axis (atan2's).
                octants[(0 if y < 0.0 else 4) + (
                    (0 if x < 0.0 and -y < -x else 1 if x < 0.0 else 2 if -y > x else 3)
                    if y < 0.0 else
                    (0 if x > 0.0 and y < x else 1 if x > 0.0 else 2 if y > -x else 3))] = True
        score[i] = min(alike, most) + 2 * _count_true(octants) - _CLEAR_WEIGHT * crowd \
            - max(inside - most, 0)
    return score


@_kernel
def in_disc(H, pts, reach):
    """
    Whether ideal-image points ``pts`` (N, 2) lie within ``reach`` of the plane's origin.

    ``H`` maps the plane to the ideal image; its adjugate maps back (the
    inverse up to scale, which the division takes away).
    """
    a00 = H[1, 1] * H[2, 2] - H[1, 2] * H[2, 1]
    a01 = H[0, 2] * H[2, 1] - H[0, 1] * H[2, 2]
    a02 = H[0, 1] * H[1, 2] - H[0, 2] * H[1, 1]
    a10 = H[1, 2] * H[2, 0] - H[1, 0] * H[2, 2]
    a11 = H[0, 0] * H[2, 2] - H[0, 2] * H[2, 0]
    a12 = H[0, 2] * H[1, 0] - H[0, 0] * H[1, 2]
    a20 = H[1, 0] * H[2, 1] - H[1, 1] * H[2, 0]
    a21 = H[0, 1] * H[2, 0] - H[0, 0] * H[2, 1]
    a22 = H[0, 0] * H[1, 1] - H[0, 1] * H[1, 0]
    n = pts.shape[0]
    out = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        u, v = pts[i, 0], pts[i, 1]
        w = a20 * u + a21 * v + a22
        x = (a00 * u + a01 * v + a02) / w
        y = (a10 * u + a11 * v + a12) / w
        out[i] = math.hypot(x, y) < reach
    return out


@_kernel
def ring_of_spots(spots, radius, reach, min_spots):
    """
    Whether faint spots (offsets (N, 2) from a small centre) look like its rings.

    The spots between 1.5 centre radii and ``reach``: at least ``min_spots``
    of them, in at least four of the eight directions (a steep far card's
    rings, their dots merged or too pale in some directions, showed four),
    their mean near the centre (within 0.4 times their median distance).
    Returns ``(ring-like, number of ring spots)``.
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
    ring_like = m >= min_spots
    if ring_like:
        octants = np.zeros(8, dtype=np.bool_)
        sx = sy = 0.0
        for k in range(m):
            x, y = spots[keep[k], 0], spots[keep[k], 1]
            octants[int((math.atan2(y, x) + math.pi) * (8 / (2 * math.pi))) % 8] = True
            sx += x
            sy += y
        ring_like = _count_true(octants) >= 4 \
            and not math.hypot(sx / m, sy / m) > 0.4 * _median(rho[:m])
    return ring_like, m


# Code reading ------------------------------------------------------------------------

@_kernel
def _clip(x, lo, hi):
    """``x`` clipped to [lo, hi]; NaN stays NaN (as numpy's clip)."""
    if x < lo:
        return lo
    if x > hi:
        return hi
    return x


@_kernel
def _before(a, b):
    """Sort order of numpy's sorts: ascending, NaN last."""
    return a < b or (b != b and a == a)


@_kernel
def _classify_one(x0, x1, x2, refs):
    """
    Nearest ink (row of ``refs``) of a unit vector and its margin: (ink, margin).

    The margin is how far past the bisector between the nearest ink and
    the next the vector lies, as a fraction of the way to the nearest
    ink: 1 on the ink, 0 on the bisector. Angles as numpy's stable sort
    orders them (ties to the first ink, NaN last).
    """
    angle = np.empty(4)
    for c in range(4):
        angle[c] = math.acos(_clip(x0 * refs[c, 0] + x1 * refs[c, 1] + x2 * refs[c, 2],
                                   -1.0, 1.0))
    best = 0
    for c in range(1, 4):
        if _before(angle[c], angle[best]):
            best = c
    second = -1
    for c in range(4):
        if c != best and (second < 0 or _before(angle[c], angle[second])):
            second = c
    dot = refs[best, 0] * refs[second, 0] + refs[best, 1] * refs[second, 1] \
        + refs[best, 2] * refs[second, 2]
    between = math.acos(_clip(dot, -1.0, 1.0))
    if not between != between:
        between = max(between, 1e-9)
    return best, (angle[second] - angle[best]) / between


@_kernel
def _dot3(x, y):
    """Dot product of two 3-vectors, summed left to right (as numpy sums three terms)."""
    return (x[0] * y[0] + x[1] * y[1]) + x[2] * y[2]


@_kernel
def _solve(M, b):
    """Solve the square system M x = b (Gaussian elimination, partial pivoting): (ok, x)."""
    n = b.shape[0]
    A = M.copy()
    x = b.copy()
    for col in range(n):
        pivot = col
        for r in range(col + 1, n):
            if abs(A[r, col]) > abs(A[pivot, col]):
                pivot = r
        if not abs(A[pivot, col]) > 1e-300:
            return False, x
        if pivot != col:
            for c in range(n):
                A[col, c], A[pivot, c] = A[pivot, c], A[col, c]
            x[col], x[pivot] = x[pivot], x[col]
        for r in range(col + 1, n):
            f = A[r, col] / A[col, col]
            for c in range(col, n):
                A[r, c] -= f * A[col, c]
            x[r] -= f * x[col]
    for col in range(n - 1, -1, -1):
        total = x[col]
        for c in range(col + 1, n):
            total -= A[col, c] * x[c]
        x[col] = total / A[col, col]
    return True, x


@_kernel
def fit_response(darkness, inks, light, crosstalk):
    """
    Fit the camera's colour response to dots' darkness (N, 3): (white_error, unit inks).

    The model and its reasons are in :mod:`.code_reading`: for
    each crosstalk ``t`` the sensor's mixing ``M(t)`` (weighted by the
    light, undone on the paper's colour), each dot given its nearest ink,
    blur ``a`` per dot and white error ``w`` per channel (free only when
    three inks are on the ring) by alternating least squares, twice; the
    ``t`` with the least squared error wins (the first of equal ones).
    """
    n = darkness.shape[0]
    n_t = crosstalk.shape[0]
    if n_t == 0 or inks.shape[0] < 4 or inks.shape[1] < 3 or light.shape[0] < 3 \
            or darkness.shape[1] < 3:
        return np.ones(3), np.zeros((4, 3))          # malformed: no response to undo
    lit = 1.0 - darkness
    light_max = max(light[0], max(light[1], light[2]))
    mixed = np.empty((n_t, 4, 3))
    unit_inks = np.empty((n_t, 4, 3))
    mix = np.empty((3, 3))
    for t in range(n_t):
        tt = crosstalk[t]
        for i in range(3):
            for j in range(3):
                mix[i, j] = tt / 2.0 + (1.0 - 1.5 * tt if i == j else 0.0)
        # Singular only at t = 2/3 (its eigenvalues are 1 and 1 - 1.5 t); the
        # callers' crosstalks stop at 0.6.
        solved, lights = _solve(mix, light)
        if not solved:
            lights = light.copy()
        for j in range(3):
            lights[j] = max(lights[j], 0.05 * light_max)
        for i in range(3):
            for j in range(3):
                mix[i, j] *= lights[j]
            s = (mix[i, 0] + mix[i, 1]) + mix[i, 2]
            for j in range(3):
                mix[i, j] /= s
        for k in range(4):
            for d in range(3):
                mixed[t, k, d] = inks[k, 0] * mix[d, 0] + inks[k, 1] * mix[d, 1] \
                    + inks[k, 2] * mix[d, 2]
            norm = math.sqrt(_dot3(mixed[t, k], mixed[t, k]))
            for d in range(3):
                unit_inks[t, k, d] = mixed[t, k, d] / norm
    w = np.ones((n_t, 3))
    seen = np.empty((n, 3))
    p = np.empty((n, 3))
    a = np.empty(n)
    squares = np.empty(3 * n)
    unit = np.empty(3)
    err = np.zeros(n_t)
    for t in range(n_t):
        for step in range(2):
            used = np.zeros(4, dtype=np.bool_)
            for i in range(n):
                for c in range(3):
                    seen[i, c] = 1.0 - lit[i, c] / w[t, c]
                norm = math.sqrt(_dot3(seen[i], seen[i]))
                if not norm != norm:
                    norm = max(norm, 1e-9)
                for c in range(3):
                    unit[c] = seen[i, c] / norm
                best, best_dot = 0, -np.inf
                for k in range(4):
                    dot = _dot3(unit, unit_inks[t, k])
                    if k == 0 or dot > best_dot:
                        best, best_dot = k, dot
                used[best] = True
                for c in range(3):
                    p[i, c] = mixed[t, best, c]
            # The white's error needs three inks on the ring to be told from
            # the inks' own colours.
            free = _count_true(used) >= 3
            for _ in range(2):
                for i in range(n):
                    ps = p[i, 0] * seen[i, 0] + p[i, 1] * seen[i, 1] + p[i, 2] * seen[i, 2]
                    pp = p[i, 0] * p[i, 0] + p[i, 1] * p[i, 1] + p[i, 2] * p[i, 2]
                    a[i] = _clip(ps / pp, 0.05, 1.2)
                for c in range(3):
                    lq = qq = 0.0
                    for i in range(n):
                        q = 1.0 - a[i] * p[i, c]
                        lq += lit[i, c] * q
                        qq += q * q
                    fitted = lq / (qq if qq != qq or qq > 1e-9 else 1e-9)
                    w[t, c] = _clip(fitted, 0.5, 3.0) if free else 1.0
                for i in range(n):
                    for c in range(3):
                        seen[i, c] = 1.0 - lit[i, c] / w[t, c]
        for i in range(n):
            for c in range(3):
                r = lit[i, c] - w[t, c] * (1.0 - a[i] * p[i, c])
                squares[3 * i + c] = r * r
        err[t] = _pairwise_sum(squares, 3 * n)
    # The first least error (numpy's argmin: the first NaN if any).
    best = 0
    for t in range(1, n_t):
        if err[best] != err[best]:
            break
        if err[t] != err[t] or err[t] < err[best]:
            best = t
    return w[best].copy(), unit_inks[best].copy()


@_kernel
def _pairwise_block(x, lo, n):
    """Sum of ``x[lo:lo + n]``, n <= 128, in numpy's order (eight accumulators)."""
    if n < 8:
        res = 0.0
        for i in range(lo, lo + n):
            res += x[i]
        return res
    r = np.empty(8)
    for j in range(8):
        r[j] = x[lo + j]
    i = 8
    while i < n - n % 8:
        for j in range(8):
            r[j] += x[lo + i + j]
        i += 8
    res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
    while i < n:
        res += x[lo + i]
        i += 1
    return res


@_kernel
def _pairwise_sum(x, n):
    """
    Sum of ``x[:n]`` in numpy's order (pairwise, eight accumulators).

    Where a decision compares sums of many terms, the same order gives the
    same decision as numpy's ``sum``. numpy halves a long run (to a
    multiple of 8) until the halves are at most 128 long: the same here
    with a stack instead of recursion (a recursive kernel is not safely
    cached: numba issue 6061, a segfault when loaded from the cache).
    """
    start = n - n          # not the literal 0: one compiled signature, not two
    if n <= 128:
        return _pairwise_block(x, start, n)
    depth = 64
    f_lo = np.empty(depth, dtype=np.intp)
    f_n = np.empty(depth, dtype=np.intp)
    f_stage = np.zeros(depth, dtype=np.intp)
    f_left = np.zeros(depth)
    f_lo[0], f_n[0] = start, n
    top = 1
    result = 0.0
    while top > 0:
        t = top - 1
        m = f_n[t]
        half = m // 2 - (m // 2) % 8
        value = 0.0
        done = False
        if m <= 128:
            value, done = _pairwise_block(x, f_lo[t], m), True
        elif f_stage[t] == 0:
            f_stage[t] = 1
            f_lo[top], f_n[top], f_stage[top] = f_lo[t], half, 0
            top += 1
        elif f_stage[t] == 1:
            f_stage[t] = 2
            f_lo[top], f_n[top], f_stage[top] = f_lo[t] + half, m - half, 0
            top += 1
        else:
            value, done = f_left[t] + f_left[t + 1], True
        if done:
            top -= 1
            if top == 0:
                result = value
            elif f_stage[top - 1] == 1:
                f_left[top - 1] = value
            else:
                f_left[top] = value
    return result


@_kernel
def _nan_max3(x):
    """Largest of three values; NaN if any is NaN (as numpy's max)."""
    m = x[0]
    for c in range(1, 3):
        if x[c] != x[c] or x[c] > m:
            m = x[c]
        if m != m:
            return m
    return m


@_kernel
def _hidden_slots(ring_valid):
    """Slots (columns of ``ring_valid``, rings x 8) where no ring's dot is seen."""
    count = 0
    for k in range(ring_valid.shape[1]):
        shown = False
        for r in range(ring_valid.shape[0]):
            shown = shown or ring_valid[r, k]
        count += not shown
    return count


@_kernel
def read_colours(colour, valid, partial, n_rings, inks, light, crosstalk, min_darkness,
                 max_hidden, known_codes, min_margin, decisive_margin):
    """
    Ink of every slot and of the centre, with margins; the numeric part of ``read_code``.

    ``colour`` (1 + rings * 8, 3): each dot's darkness, the centre first
    then ring r slot k; ``valid`` which were measured, ``partial`` which
    were read from the part an object left uncovered. Returns ``(ok,
    centre, agreed, slot_letter, margins, grey, black)``: ``ok`` False
    when the reading must be rejected (the reasons are in
    :func:`.code_reading.read_code`); ``agreed`` (8) the letter index per
    slot (-1 hidden), ``slot_letter`` (rings, 8) per ring (-1 unseen),
    ``margins`` (9) per slot (NaN hidden) then the centre's, ``grey``
    (rings, 8) the dots that were grey objects, ``black`` the one black
    slot (-1 none).
    """
    agreed = np.empty(RING_POINTS, dtype=np.intp)
    agreed[:] = -1
    slot_letter = np.empty((n_rings, RING_POINTS), dtype=np.intp)
    slot_letter[:, :] = -1
    margins = np.empty(RING_POINTS + 1)
    margins[:] = np.nan
    grey = np.zeros((n_rings, RING_POINTS), dtype=np.bool_)
    found = np.empty(2, dtype=np.intp)
    found[0], found[1] = 0, -1
    # One exit: each return of a large tuple costs numba compile time.
    ok = _read_into(colour, valid, partial, n_rings, inks, light, crosstalk, min_darkness,
                    max_hidden, known_codes, min_margin, decisive_margin, agreed, slot_letter,
                    margins, grey,
                    found)
    return ok, found[0], agreed, slot_letter, margins, grey, found[1]


# A centre read as black must be black ink: a dark colour (a green printed
# too dark, or seen under light that leaves little of it) is nearer black
# than its configured ink, yet still unlike black in one channel. Black is
# grey (every channel within this of the channels' mean: the dark greens
# read black were 0.041 or more off)...
_BLACK_GREY = 0.02
# ...or, where the light or a clipped white makes it less so, the colour of
# point 1 on the same card: each channel over the channels' mean within this
# of point 1's...
_BLACK_AS_POINT1 = 0.03
# ...or within this many times the scatter between the ring's dots of one
# ink (noise, JPEG, blur), whichever is more. Black centres came within
# 0.029 of point 1 in 675 readings of 4,400 stress frames (as measured);
# green centres printed dark (sRGB 10, 100, 40) and read black came 0.038
# or more as measured, but as little as 0.025 against the white fitted to
# such inks: both must pass.
_BLACK_SCATTERS = 2.5


@_kernel
def _channel_mean(colours, i):
    """Mean of row ``i``'s three channels (summed in numpy's order)."""
    return ((colours[i, 0] + colours[i, 1]) + colours[i, 2]) / 3


@_kernel
def _grey(colours, i):
    """Tell whether row ``i`` is grey: each channel within _BLACK_GREY of the channels' mean."""
    mean = _channel_mean(colours, i)
    if not mean > 0.0:
        return False
    worst = 0.0
    for c in range(3):
        worst = max(worst, abs(colours[i, c] / mean - 1.0))
    return worst <= _BLACK_GREY


@_kernel
def _unlike_point1(unit, ring_valid, slot_letter, black, n_rings):
    """
    Tell whether the centre's colour (row 0) differs from point 1's beyond noise.

    ``unit`` (1 + rings * 8, 3): the dots' colours, the centre first, in any
    scale (each is compared over its channels' mean).
    """
    point1 = np.zeros(3)
    for r in range(n_rings):
        if ring_valid[r, black]:
            for c in range(3):
                point1[c] += unit[1 + r * RING_POINTS + black, c]
    p_mean = ((point1[0] + point1[1]) + point1[2]) / 3
    c_mean = _channel_mean(unit, 0)
    if not (p_mean > 0.0 and c_mean > 0.0):
        return True
    apart = 0.0
    for c in range(3):
        apart = max(apart, abs(unit[0, c] / c_mean - point1[c] / p_mean))
    if apart <= _BLACK_AS_POINT1:
        return False            # the ring's scatter can only allow more
    return not apart <= _BLACK_SCATTERS * _ink_scatter(unit, ring_valid, slot_letter, n_rings)


@_kernel
def _ink_dot(slot_letter, shape, j, ink):
    """Tell whether ring dot ``j`` (ring-major) is of ``ink`` and counted (``shape`` not NaN)."""
    return slot_letter[j // RING_POINTS, j % RING_POINTS] == ink and shape[j, 0] == shape[j, 0]


@_kernel
def _ink_scatter(unit, ring_valid, slot_letter, n_rings):
    """
    RMS over the ring's dots of their colour's largest channel difference from their ink's mean.

    Colours as :func:`_unlike_point1` compares them (each channel over the
    channels' mean); inks with one dot only give nothing; 0 when none has two.
    """
    # Each ring dot's colour over its channels' mean, once (NaN: not counted).
    n_dots = n_rings * RING_POINTS
    shape = np.full((n_dots, 3), np.nan)
    for r in range(n_rings):
        for k in range(RING_POINTS):
            i = 1 + r * RING_POINTS + k
            m = _channel_mean(unit, i)
            if ring_valid[r, k] and m > 0.0:
                for c in range(3):
                    shape[i - 1, c] = unit[i, c] / m
    total, count = 0.0, 0
    mean = np.empty(3)
    for ink in range(4):
        mean[:] = 0.0
        n = 0
        for j in range(n_dots):
            if _ink_dot(slot_letter, shape, j, ink):
                for c in range(3):
                    mean[c] += shape[j, c]
                n += 1
        if n < 2:
            continue
        for c in range(3):
            mean[c] /= n
        for j in range(n_dots):
            if _ink_dot(slot_letter, shape, j, ink):
                worst = 0.0
                for c in range(3):
                    worst = max(worst, abs(shape[j, c] - mean[c]))
                total += worst * worst
                count += 1
    return math.sqrt(total / count) if count else 0.0


# A far card's coloured dot of two or three pixels can lose its colour to
# JPEG's half-resolution chroma and read black in one ring, while the other
# ring reads the slot's colour. It cannot be point 1 when every ring reads
# point 1 black in another slot (a ring has one black dot), and it is no
# black dot when it is lighter than that point 1 by this factor (over its
# channels: a colour ink absorbs in two channels, black in all three). What
# colour it keeps must lean to the other ring's: such chroma can also turn
# the other ring's dot to a wrong colour, and then the two disagree still.
_GREYED_LIGHTER = 0.95


@_kernel
def _hue_of(unit, i, refs):
    """
    Return the colour ink (1-3) whose hue row ``i``'s direction has; 0 when it has none.

    Hue: the part of a direction across black's (``refs[0]``). Row ``i``'s
    must lie within 60 degrees of that ink's (the three inks' are about
    120 degrees apart), however little of it there is.
    """
    across = np.empty(3)
    along = _dot3(unit[i], refs[0])
    for c in range(3):
        across[c] = unit[i, c] - along * refs[0, c]
    size = math.sqrt(_dot3(across, across))
    if not size > 1e-9:
        return 0
    best, best_cos = 0, 0.5
    ink_across = np.empty(3)
    for ink in range(1, 4):
        ink_along = _dot3(refs[ink], refs[0])
        for c in range(3):
            ink_across[c] = refs[ink, c] - ink_along * refs[0, c]
        ink_size = math.sqrt(_dot3(ink_across, ink_across))
        if not ink_size > 1e-9:
            continue
        cos = _dot3(across, ink_across) / (size * ink_size)
        if cos > best_cos:
            best, best_cos = ink, cos
    return best


@_kernel
def _drop_greyed(colour, unit, refs, ring_valid, letter, margin, partial, n_rings, min_margin):
    """
    Leave unseen the dots read black that are a greyed coloured slot (see above).

    Only where point 1 is one slot that every ring reads black, the slot's
    other dots agree on one colour, each with ``min_margin`` and whole (not
    read from the part an object left uncovered), the greyed dot's direction
    (``unit``) keeping that ink's hue (``refs``: the inks' directions); and
    only when every other slot is seen by every ring. The slot is then read
    from the other dots, as a slot that one ring sees. ``ring_valid``
    (rings, 8) is changed in place.
    """
    black = -1
    for k in range(RING_POINTS):
        every = True
        for r in range(n_rings):
            i = 1 + r * RING_POINTS + k
            every = every and ring_valid[r, k] and letter[i] == 0
        if every:
            if black >= 0:
                return          # two black slots: nothing here is sure
            black = k
    if black < 0:
        return
    drop = np.zeros((n_rings, RING_POINTS), dtype=np.bool_)
    for k in range(RING_POINTS):
        if k == black:
            continue
        ink, sure = 0, True
        for r in range(n_rings):
            i = 1 + r * RING_POINTS + k
            if ring_valid[r, k] and letter[i] > 0:
                sure = sure and (ink == 0 or ink == letter[i]) and margin[i] >= min_margin \
                    and not partial[i]
                ink = letter[i]
        if ink == 0 or not sure:
            continue
        for r in range(n_rings):
            i = 1 + r * RING_POINTS + k
            drop[r, k] = ring_valid[r, k] and letter[i] == 0 and _channel_mean(colour, i) \
                < _GREYED_LIGHTER * _channel_mean(colour, 1 + r * RING_POINTS + black) \
                and _hue_of(unit, i, refs) == ink
    # Every other slot seen by every ring: a chroma that greys one dot can
    # turn another to a wrong colour, which only the other ring then shows.
    for k in range(RING_POINTS):
        any_drop, every = False, True
        for r in range(n_rings):
            any_drop = any_drop or drop[r, k]
            every = every and ring_valid[r, k]
        if not any_drop and not every:
            return
    for r in range(n_rings):
        for k in range(RING_POINTS):
            if drop[r, k]:
                ring_valid[r, k] = False


@_kernel
def _read_into(colour, valid, partial, n_rings, inks, light, crosstalk, min_darkness,
               max_hidden, known_codes, min_margin, decisive_margin, agreed, slot_letter,
               margins, grey,
               found):
    """Do :func:`read_colours`'s work into its arrays (``found``: centre, black); False: reject."""
    n_ring_dots = n_rings * RING_POINTS
    n = 1 + n_ring_dots
    if colour.shape[0] < n or valid.shape[0] < n or partial.shape[0] < n or colour.shape[1] != 3 \
            or inks.shape[0] != 4 or inks.shape[1] != 3 or light.shape[0] != 3 \
            or crosstalk.shape[0] == 0:
        return False
    ring_valid = np.zeros((n_rings, RING_POINTS), dtype=np.bool_)
    for r in range(n_rings):
        for k in range(RING_POINTS):
            ring_valid[r, k] = valid[1 + r * RING_POINTS + k]

    if not valid[0] or _hidden_slots(ring_valid) > max_hidden:
        return False
    darkness = np.empty((n, 3))
    strength = np.empty(n)
    for i in range(n):
        strength[i] = np.nan
        for c in range(3):
            darkness[i, c] = np.nan
    n_ring_rows = 0
    for i in range(n):
        if valid[i]:
            for c in range(3):
                darkness[i, c] = colour[i, c]
            strength[i] = _nan_max3(darkness[i])
            if strength[i] < min_darkness:
                return False
            n_ring_rows += i > 0
    ring_rows = np.empty(n_ring_rows, dtype=np.intp)
    m = 0
    for i in range(1, n):
        if valid[i]:
            ring_rows[m] = i
            m += 1
    white_error, refs = fit_response(darkness[ring_rows], inks, light, crosstalk)
    # Every dot's colour direction against the true white (blur left in).
    unit = np.empty((n, 3))
    for i in range(n):
        for c in range(3):
            unit[i, c] = 1.0 - (1.0 - darkness[i, c]) / white_error[c]
        norm = math.sqrt(_dot3(unit[i], unit[i]))
        if not norm != norm:
            norm = max(norm, 1e-9)
        for c in range(3):
            unit[i, c] /= norm
    # Inks seen on the ring are represented by their own dots.
    first = np.empty(n_ring_rows, dtype=np.intp)
    for m in range(n_ring_rows):
        i = ring_rows[m]
        first[m] = _classify_one(unit[i, 0], unit[i, 1], unit[i, 2], refs)[0]
    refs = refs.copy()
    for ink in range(4):
        mean = np.zeros(3)
        count = 0
        for m in range(n_ring_rows):
            if first[m] == ink:
                for c in range(3):
                    mean[c] += unit[ring_rows[m], c]
                count += 1
        if count:
            for c in range(3):
                mean[c] /= count
            norm = math.sqrt(_dot3(mean, mean))
            for c in range(3):
                refs[ink, c] = mean[c] / norm
    letter = np.zeros(n, dtype=np.intp)
    margin = np.empty(n)
    for i in range(n):
        letter[i], margin[i] = _classify_one(unit[i, 0], unit[i, 1], unit[i, 2], refs)
    # A grey object over a dot is no black dot: black is as dark as the
    # ring's coloured dots are in their darkest channel.
    coloured = np.empty(n_ring_dots)
    n_coloured = 0
    for r in range(n_rings):
        for k in range(RING_POINTS):
            i = 1 + r * RING_POINTS + k
            if ring_valid[r, k] and letter[i] > 0:
                coloured[n_coloured] = strength[i]
                n_coloured += 1
    ink_dark = _median(coloured[:n_coloured]) if n_coloured else 0.0
    for r in range(n_rings):
        for k in range(RING_POINTS):
            i = 1 + r * RING_POINTS + k
            mean_colour = _channel_mean(colour, i)
            if ring_valid[r, k] and letter[i] == 0 and mean_colour < 0.7 * ink_dark:
                grey[r, k] = True
                ring_valid[r, k] = False
    if _hidden_slots(ring_valid) > max_hidden:
        return False
    _drop_greyed(colour, unit, refs, ring_valid, letter, margin, partial, n_rings, min_margin)
    # Both rings must agree, slot by slot: never guess. A slot they read
    # differently is unknown; with a map of the codes that exist
    # (``known_codes``) it is read as a hidden slot is, from the map, else
    # the card is rejected. (A far card's dots of two or three pixels, their
    # colour greyed by JPEG's half-resolution chroma, can tip one ring's dot
    # over: to black, _drop_greyed has already left it unseen where that is
    # sure.)
    for r in range(n_rings):
        for k in range(RING_POINTS):
            if ring_valid[r, k]:
                slot_letter[r, k] = letter[1 + r * RING_POINTS + k]
                agreed[k] = max(agreed[k], slot_letter[r, k])
    black = -1
    n_black = n_shown = 0
    # (A slot that no ring read black cannot be taken for point 1.)
    no_black = -1
    for k in range(RING_POINTS):
        disagree = any_black = False
        for r in range(n_rings):
            disagree = disagree or (ring_valid[r, k] and slot_letter[r, k] != agreed[k])
            any_black = any_black or (ring_valid[r, k] and slot_letter[r, k] == 0)
        if disagree:
            if not known_codes:
                return False
            for r in range(n_rings):
                ring_valid[r, k] = False
                slot_letter[r, k] = -1
            agreed[k] = -1
            if not any_black:
                no_black = k
    if _hidden_slots(ring_valid) > max_hidden:
        return False
    for k in range(RING_POINTS):
        n_shown += agreed[k] >= 0
        if agreed[k] == 0:
            n_black += 1
            if black < 0:
                black = k
    if n_black > 1 or (n_black == 0 and n_shown == RING_POINTS):
        return False
    # Seven coloured slots make the eighth point 1 (read_code): not one the
    # rings read as two colours.
    if n_black == 0 and n_shown == RING_POINTS - 1 and no_black >= 0:
        return False
    # Each slot decided on the evidence of both rings: their dots' colour
    # directions summed, with a margin.
    for k in range(RING_POINTS):
        if agreed[k] < 0:
            continue
        total = np.zeros(3)
        sure = False
        for r in range(n_rings):
            i = 1 + r * RING_POINTS + k
            if ring_valid[r, k]:
                for c in range(3):
                    total[c] += unit[i, c]
                sure = sure or not partial[i]
        norm = math.sqrt(_dot3(total, total))
        pick, margins[k] = _classify_one(total[0] / norm, total[1] / norm, total[2] / norm, refs)
        if pick != agreed[k] or margins[k] < min_margin:
            return False
        if not sure and margins[k] < decisive_margin:
            return False
    margins[RING_POINTS] = margin[0]
    if margin[0] < min_margin:
        return False
    centre = letter[0]
    if black >= 0:
        values = np.empty(3 * n_rings)
        count = 0
        for r in range(n_rings):
            if ring_valid[r, black]:
                for c in range(3):
                    values[count] = darkness[1 + r * RING_POINTS + black, c]
                    count += 1
        k_dark = _pairwise_sum(values, count) / count
        centre_dark = _channel_mean(darkness, 0)
        if centre == 0 and centre_dark < 0.8 * k_dark:
            return False
        # Grey as measured, or as point 1 both as measured and against the
        # fitted white (a fit thrown by inks unlike the configured ones can
        # move a dark colour towards black).
        if centre == 0 and not _grey(darkness, 0) and (
                _unlike_point1(darkness, ring_valid, slot_letter, black, n_rings)
                or _unlike_point1(unit, ring_valid, slot_letter, black, n_rings)):
            return False
    elif centre == 0:
        return False         # a black centre needs point 1 to compare with
    found[0], found[1] = centre, black
    return True


# Dots stage ---------------------------------------------------------------------
# Small passes of :mod:`.dots` (grid look-ups, the comb test, the components'
# dot tests, the threshold, a far candidate's faint spots): a handful of
# numpy calls on a few dozen values each, several times a frame. The same
# arithmetic in the same order (float64, float32 grids widened as numpy
# widens them), so the results are the numpy code's to the bit.

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
    tiles = cols // 4
    t1 = np.zeros(tiles, dtype=np.int64)
    t2 = np.zeros(tiles, dtype=np.int64)
    # The sampled pixels of five consecutive rows, in a ring: each row is read
    # once and in order (reading the five rows round each row in turn cost
    # twice as much, on a frame not yet in the cache).
    ring = np.empty((5, cols), dtype=np.int64)
    for q in range(4):
        for j in range(cols):
            ring[q, j] = image[q, 16 * j, ch]
    for r0 in range(2, 2 + rows, tile_rows):
        for r in range(r0, r0 + tile_rows):
            below2 = (r + 2) % 5
            for j in range(cols):
                ring[below2, j] = image[r + 2, 16 * j, ch]
            _comb_row(ring, r, cols, t1, t2)
        count = _combed_count(t1, t2, tiles, pixels, count)
        if count >= 2:
            return count
    return count


@_kernel
def _comb_row(ring, r, cols, t1, t2):
    """Add row ``r``'s curvatures over one row and over two (ring of five rows) to its tiles."""
    above2, above1, mid_row, below1, below2 = (r - 2) % 5, (r - 1) % 5, r % 5, (r + 1) % 5, \
        (r + 2) % 5
    # A tile's four columns together (no division per column).
    for tile in range(cols // 4):
        one = 0
        two = 0
        for j in range(4 * tile, 4 * tile + 4):
            mid = 2 * ring[mid_row, j]
            one += abs(mid - ring[above1, j] - ring[below1, j])
            two += abs(mid - ring[above2, j] - ring[below2, j])
        t1[tile] += one
        t2[tile] += two


@_kernel
def _combed_count(t1, t2, tiles, pixels, count):
    """Add the tiles whose rows disagree as a comb's to ``count`` (up to two); zero the sums."""
    for t in range(tiles):
        if count < 2 and t1[t] > 6 * pixels and t1[t] > 3 * t2[t]:
            count += 1
        t1[t] = 0
        t2[t] = 0
    return count


@_kernel
def darkest_in(image, x0, y0, x1, y1):
    """
    Return the darkest channel (H, W uint8) of a BGR image's window [x0, x1) x [y0, y1).

    One pass from the image itself: the window of a full image is not
    contiguous, and OpenCV's erosion along the interleaved rows needed a
    contiguous copy first and a strided slice after (the same minimum).
    The window is clipped to the image.
    """
    h, w = image.shape[0], image.shape[1]
    x0, y0 = min(max(x0, 0), w), min(max(y0, 0), h)
    x1, y1 = min(max(x1, x0), w), min(max(y1, y0), h)
    out = np.empty((y1 - y0, x1 - x0), dtype=np.uint8)
    for y in range(y0, y1):
        for x in range(x0, x1):
            out[y - y0, x - x0] = min(image[y, x, 0], image[y, x, 1], image[y, x, 2])
    return out


@_kernel
def halve(image, comb_tile_rows):
    """
    Halve a BGR frame (H, W, 3) and, on the way, count its combed tiles: (halved, darkest, tiles).

    The halved frame is OpenCV's area resize by two to the bit (each 2 x 2
    block's mean per channel, rounded half up; a last odd row or column
    left out) and ``darkest`` its per-pixel minimum over B, G, R, the
    segmentation's ``_min_channel``. With ``comb_tile_rows`` > 0, the
    interlace comb test of :func:`combed_tiles` (same tiles, same sums,
    counting stops at two) rides on the same pass; with 0 it is not made
    (``tiles`` 0). One pass over the frame: the comb test, the resize and
    the erosion that took the minimum, with its copy, each read the frame or
    the halved frame apart from memory that the frame's other work (its
    rendering, its message) had left cold. Rows are read flat, so that each
    pixel's three channels compile to plain loads.
    """
    h, w = image.shape[0], image.shape[1]
    h2, w2 = h // 2, w // 2
    small = np.empty((h2, w2, 3), dtype=np.uint8)
    darkest = np.empty((h2, w2), dtype=np.uint8)
    flat = image.reshape(h, w * 3)
    out = small.reshape(h2, w2 * 3)
    # The comb test's geometry, as combed_tiles': tiles of comb_tile_rows
    # rows and four sampled columns (every sixteenth, green), rows 2 to
    # 2 + rows, each row's curvature over one row and over two.
    cols = (w + 15) // 16 // 4 * 4
    last = (h - 4) // 2 * 2
    comb = comb_tile_rows >= 1 and last >= 2 * comb_tile_rows
    rows = last // comb_tile_rows * comb_tile_rows if comb else 0
    tiles = cols // 4
    pixels = comb_tile_rows * 4
    t1 = np.zeros(max(tiles, 1), dtype=np.int64)
    t2 = np.zeros(max(tiles, 1), dtype=np.int64)
    ring = np.empty((5, max(cols, 1)), dtype=np.int64)
    count = 0
    # Each pair of rows summed per byte first (a plain loop over the flat
    # rows, compiled to vector instructions), then each 2 x 2 block's sum
    # from the pair sums: twice as fast as summing four bytes per channel.
    pair = np.empty(6 * w2, dtype=np.uint16)
    for q in range(h):
        row_q = flat[q]
        if comb and count < 2 and q < rows + 4:
            # Row q's samples; then row r = q - 2, whose rows r - 2 .. r + 2
            # are all in the ring now.
            for j in range(cols):
                ring[q % 5, j] = row_q[48 * j + 1]
            r = q - 2
            if r >= 2:
                _comb_row(ring, r, cols, t1, t2)
                if (r - 2) % comb_tile_rows == comb_tile_rows - 1:
                    count = _combed_count(t1, t2, tiles, pixels, count)
        if q % 2 == 1 and q // 2 < h2:
            y = q // 2
            r0 = flat[q - 1]
            for i in range(6 * w2):
                pair[i] = np.uint16(r0[i]) + np.uint16(row_q[i])
            o = out[y]
            d = darkest[y]
            for x in range(w2):
                i = 6 * x
                blue = np.uint8((pair[i] + pair[i + 3] + 2) >> 2)
                green = np.uint8((pair[i + 1] + pair[i + 4] + 2) >> 2)
                red = np.uint8((pair[i + 2] + pair[i + 5] + 2) >> 2)
                o[3 * x] = blue
                o[3 * x + 1] = green
                o[3 * x + 2] = red
                d[x] = min(blue, min(green, red))
    return small, darkest, count


@_kernel
def _root(parent, i):
    """Root of run ``i`` in the union-find forest ``parent``, compressing the path."""
    r = i
    while parent[r] != r:
        r = parent[r]
    while parent[i] != r:
        up = parent[i]
        parent[i] = r
        i = up
    return r


@_kernel
def label_components(mask):
    """
    Label a mask's 8-connected components: (labels, stats, centroids), as OpenCV's.

    ``mask`` (H, W uint8): nonzero is foreground. The result is that of
    ``cv2.connectedComponentsWithStatsWithAlgorithm(mask, 8, CV_32S,
    CCL_GRANA)`` to the bit: ``labels`` (H, W int32, 0 the background),
    ``stats`` (n, 5 int32) as (x, y, width, height, area) and ``centroids``
    (n, 2) the mean pixel (x, y), the background's row left zero. It labels
    runs of a row and joins those that touch a run of the row above
    (union-find), then numbers the components in the order of their first
    2 x 2 block in scan order, which is Grana's order (its provisional
    labels come in that order and each component keeps its smallest). One
    pass over the pixels and one over the runs: a third faster than
    OpenCV's labelling with our statistics pass, and half its cost with
    OpenCV's own statistics.
    """
    h, w = mask.shape
    cap = h * ((w + 1) // 2) + 1           # at most one run every two pixels
    start = np.empty(cap, dtype=np.int32)
    end = np.empty(cap, dtype=np.int32)
    parent = np.empty(cap, dtype=np.int32)
    row_first = np.empty(h + 1, dtype=np.int64)
    runs = 0
    for y in range(h):
        row_first[y] = runs
        x = 0
        while x < w:
            if mask[y, x] != 0:
                start[runs] = x
                x += 1
                while x < w and mask[y, x] != 0:
                    x += 1
                end[runs] = x - 1
                parent[runs] = runs
                runs += 1
            x += 1
        if y > 0:
            # Runs of this row and the row above touch (8-connected) where
            # they overlap with one pixel to spare; walk both rows once.
            i, above_end, j = row_first[y - 1], row_first[y], row_first[y]
            while i < above_end and j < runs:
                if end[i] + 1 < start[j]:
                    i += 1
                elif end[j] + 1 < start[i]:
                    j += 1
                else:
                    a = _root(parent, i)
                    b = _root(parent, j)
                    if a < b:
                        parent[b] = a
                    elif b < a:
                        parent[a] = b
                    if end[i] <= end[j]:
                        i += 1
                    else:
                        j += 1
    row_first[h] = runs
    # Each component's first 2 x 2 block in scan order (all foreground in a
    # block is one component, so no two components share a block).
    blocks_x = (w + 1) // 2
    first = np.full(((h + 1) // 2) * blocks_x, -1, dtype=np.int32)
    for y in range(h):
        base = (y // 2) * blocks_x
        for k in range(row_first[y], row_first[y + 1]):
            r = _root(parent, k)
            parent[k] = r
            key = base + start[k] // 2
            if first[key] < 0:
                first[key] = r
    number = np.zeros(max(runs, 1), dtype=np.int32)
    n = 1
    for key in range(first.shape[0]):
        r = first[key]
        if r >= 0 and number[r] == 0:
            number[r] = n
            n += 1
    labels = np.zeros((h, w), dtype=np.int32)
    stats = np.zeros((n, 5), dtype=np.int32)
    centroids = np.zeros((n, 2))
    sx = np.zeros(n, dtype=np.int64)
    sy = np.zeros(n, dtype=np.int64)
    x1 = np.full(n, -1, dtype=np.int32)
    y1 = np.full(n, -1, dtype=np.int32)
    for label in range(1, n):
        stats[label, 0] = w
        stats[label, 1] = h
    for y in range(h):
        for k in range(row_first[y], row_first[y + 1]):
            label = number[parent[k]]
            s, e = start[k], end[k]
            for x in range(s, e + 1):
                labels[y, x] = label
            length = e - s + 1
            stats[label, 4] += length
            sx[label] += (s + e) * length // 2      # (s + e) * length is even
            sy[label] += y * length
            stats[label, 0] = min(stats[label, 0], s)
            stats[label, 1] = min(stats[label, 1], y)
            x1[label] = max(x1[label], e)
            y1[label] = max(y1[label], y)
    for label in range(1, n):
        stats[label, 2] = x1[label] - stats[label, 0] + 1
        stats[label, 3] = y1[label] - stats[label, 1] + 1
        centroids[label, 0] = sx[label] / stats[label, 4]
        centroids[label, 1] = sy[label] / stats[label, 4]
    return labels, stats, centroids


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
    Find the faint spots of :func:`faint_rings` from their connected components.

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


@_kernel
def faint_rings(small, us, vs, reach, max_area, white, noise, radius, scale, faint_ratio,
                min_white, min_spots):
    """
    Tell, for each small centre blob, whether faint spots ring it as a far card's dots would.

    :func:`.cards.far_candidates`' look at each of its blobs in one call.
    For blob ``k`` at image point (``us[k]``, ``vs[k]``): the window of the
    decimated image ``small`` (H, W, C uint8; ``scale`` image pixels a
    side per pixel) within ``reach[k]``; its pixels whose darkest channel
    is below the local white ``white[k]`` by a margin more lenient than the
    segmentation's (``faint_ratio`` of the white, or 5 sigmas of the full
    resolution's ``noise[k]`` once decimated, at least 2 levels; none where
    the white is below ``min_white``); their 8-connected components of at
    most ``max_area[k]`` image pixels (:func:`faint_components`, the one at
    the centre left out); and whether those ring the centre
    (:func:`ring_of_spots` with the centre's ``radius[k]``). Returns per
    blob (ring-like, number of ring spots, area of the component at its
    centre in image pixels, 0 if none).
    """
    n = us.shape[0]
    ring_like = np.zeros(n, dtype=np.bool_)
    n_ring = np.zeros(n, dtype=np.int64)
    own_area = np.zeros(n)
    h, w, channels = small.shape
    none = np.zeros((0, 2))
    for k in range(n):
        u, v, r = us[k], vs[k], reach[k]
        x0, y0 = max(0, int((u - r) / scale)), max(0, int((v - r) / scale))
        x1 = min(w, int((u + r) / scale) + 2)
        y1 = min(h, int((v + r) / scale) + 2)
        spots = none
        if x1 - x0 >= 3 and y1 - y0 >= 3 and not white[k] < min_white:
            margin = max(faint_ratio * white[k], 5.0 * noise[k] / scale, 2.0)
            limit = white[k] - margin
            mask = np.empty((y1 - y0, x1 - x0), dtype=np.uint8)
            for y in range(y0, y1):
                for x in range(x0, x1):
                    darkest = small[y, x, 0]
                    for c in range(1, channels):
                        darkest = min(darkest, small[y, x, c])
                    mask[y - y0, x - x0] = 255 if darkest < limit else 0
            labels, stats, centroids = label_components(mask)
            # int64, not the labels' int32: the signature warm_up compiles for
            # faint_components, not a second one for this call.
            own = np.int64(labels[min(int(v / scale), y1 - 1) - y0,
                                  min(int(u / scale), x1 - 1) - x0])
            spots, own_area[k] = faint_components(
                stats, centroids, own, max_area[k], scale, (x0 + 0.5) * scale - 0.5 - u,
                (y0 + 0.5) * scale - 0.5 - v)
        ring_like[k], n_ring[k] = ring_of_spots(spots, radius[k], r, min_spots)
    return ring_like, n_ring, own_area


def warm_up() -> float:
    """
    Compile (or load from the cache) every kernel with the argument types the detector uses.

    The first call of a kernel compiles it (tens of seconds for all of them,
    once per installation: then it is loaded from the cache in seconds'
    tenths). A process that must answer its first frame in time (a node)
    or a test run on a fresh checkout calls this first. Returns the
    seconds it took.
    """
    import time
    start = time.perf_counter()
    f8, i4 = np.float64, np.int32
    n = 8
    u = np.linspace(10.0, 80.0, n)
    area = np.full(n, 12.0)
    box = np.tile(np.array([0, 0, 2, 2], dtype=i4), (n, 1))
    label = np.arange(1, n + 1, dtype=i4)
    labels = np.zeros((4, 4), dtype=i4)
    ring_rho = np.array([4.7, 3.0])
    idx, _, reach = centre_evidence(u, u, area, box, 2.0, 4.7, 10.0, 6, 16)
    ring_evidence(u, u, area, box, label, labels, 2, np.arange(2), reach, 6, 18, 2.0, 6.0, 16,
                  1000)
    ring_of_spots(np.zeros((3, 2)), 1.0, 5.0, 6)
    in_disc(np.eye(3), np.zeros((2, 2)), 1.0)
    status, slot_blob = group_slots(u, u, area, box, label, labels, 2, 0, ring_rho, 0.5, 64.0,
                                    False)
    slot_points(slot_blob, u, u, 0)
    homography_inliers(np.eye(3), np.zeros((3, 2)), np.zeros((3, 2)), np.ones(3), 1.0, 1.0,
                       np.empty(3), np.ones(3, dtype=np.bool_), True)
    h_scales(np.eye(3), np.zeros((3, 2)))
    rows = 1 + 2 * RING_POINTS
    inks = np.eye(4, 3, dtype=f8) + 0.1
    read_colours(np.full((rows, 3), 0.5), np.ones(rows, dtype=np.bool_),
                 np.zeros(rows, dtype=np.bool_), 2, inks, np.ones(3), np.linspace(0.0, 0.45, 7),
                 0.2, 1, False, 0.35, 0.6)
    grid = np.zeros((2, 2), dtype=np.float32)
    bilinear(grid, np.zeros(1), np.zeros(1), 8)
    threshold(grid, grid, np.float32(0.25), np.float32(10.0), 24)
    image = np.zeros((40, 40, 3), dtype=np.uint8)
    image.flags.writeable = False
    combed_tiles(image, 16)
    darkest_in(image, 0, 0, 4, 4)
    halve(image, 16)
    label_components(np.zeros((3, 3), dtype=np.uint8))
    blob_covariance(labels, box[0], 1, 2)
    dot_components(np.zeros((2, 5), dtype=i4), np.zeros((2, 2)), 2, 0, 0, 10.0, 4, 4)
    faint_components(np.zeros((2, 5), dtype=i4), np.zeros((2, 2)), 0, 10.0, 2, 0.0, 0.0)
    one = np.ones(1)
    faint_rings(image, one, one, one, one, one, one, one, 2, 0.12, 24, 6)
    return time.perf_counter() - start


# Every kernel compiled, or loaded from the cache, when the module is imported:
# a node's first frame must not wait for it (a closed loop that starts
# tracking 0.4 s late misses its settling time). From the cache this takes
# 0.4 s; the first import after installing compiles them all (about 25 s of
# one core, once).
warm_up()
