"""
Cards: which blobs could be a centre dot with its rings, and which dot is in which slot.

Work is bounded: every blob's evidence (the blobs of ring-dot size within
ring reach of it) is counted in one pass over a grid of counts, so the cost
grows with the pixels and the number of blobs, never with its square. The
best candidates by that evidence are examined, at most
``DetectorParams.max_candidates`` of them.

A candidate is examined in the centre blob's own affine frame, where the
rings are near circles of radii ``R / r_centre``: a vote over the
neighbours gives the rings' scale and the angle of the 45-degree slots,
each neighbour goes to its nearest slot, and a homography fitted to the
assigned dots (undistorted when the camera is known) verifies the card and
drops dots off the fit. Slot ``k`` is taken as point ``k + 1`` until the
colours say which slot holds point 1.
"""

from dataclasses import dataclass
import math
from typing import Dict, Optional, Tuple

import numpy as np

from . import card_kernels
from .camera import CameraModel
from .detector_params import DetectorParams
from .dots import Blobs, DotImage
from .fit_kernels import fit_homography_inliers
from .per_config import made_once
from ..card.pattern import PatternConfig, RING_POINTS

# Candidate centres: at least this big (image pixels), and this many neighbours.
MIN_CENTRE_AREA = 10.0
MIN_NEIGHBOURS = 6
# Grid cell (image pixels) of the evidence counts.
_CELL = 16
# Blobs looked at round the candidates when ranking a crowded frame, at most
# (card_kernels.ring_evidence; a few milliseconds on the worst frames).
_RING_EVIDENCE_BUDGET = 200_000
# Far cards whose ring dots vanished in the decimated image: centres up to
# this area (image pixels), this many tried, this many examined.
_FAR_MAX_AREA = 64.0
_FAR_MIN_AREA = 8.0
_FAR_TRIES = 8
_FAR_EXTRA = 3
_FAR_MIN_CONTRAST = 9.0     # noise sigmas
# ...or this fraction of the white, whatever the noise: ink is that dark.
_FAR_INK_DARKNESS = 0.4
# Of the tried, the darkest this many up to this area (image pixels) that
# show no ring decimated are looked at again at full resolution; blobs up
# to this area are the ones zoomed where no card was found (zoom_spots).
_FAR_FULL_TRIES = 2
_FAR_FULL_MAX_AREA = 32.0
# Of the small blobs looked at for a zoom (zoom_spots), those with at least
# this many faint spots round them (not a crowd, and no bigger dark thing
# under them) go first: a soft far card's ring shows as a few faint spots.
_ZOOM_MIN_RING = 3
# The small blobs looked at for a zoom: from this area (image pixels; a soft
# far centre can be one decimated pixel), the darkest this many surely ink
# and as many paler. A clutter's specks are often darker than a soft far
# centre (in far soft frames, its rank among them was 16-24th), and its
# faint ring is what tells it (scratch r26/zfeat.py); looking at 96 blobs
# costs about 1.3 ms (3 at most) in a cluttered frame where no card was read.
_ZOOM_MIN_AREA = 4.0
_ZOOM_LOOKS = 48


@dataclass(frozen=True)
class CardGuess:
    """A centre blob, the blobs assigned to the ring slots and the plane-to-image map."""

    centre: int                     # index in `blobs`
    slot_blob: np.ndarray           # (n_rings, 8) blob index per slot, -1 where none
    homography: np.ndarray          # slot-ordered pattern plane (m) -> undistorted pixels
    blobs: Blobs


def rank_candidates(blobs: Blobs, config: PatternConfig, params: DetectorParams,
                    noise: Optional[np.ndarray] = None) -> np.ndarray:
    """
    Return candidate centre blobs (indices), strongest evidence first, max_candidates at most.

    Evidence is the number of blobs between 0.06 and 1 times a blob's area
    within reach of its outer ring (1.5 times the ring's radius for a centre
    of its extent, which covers tilts to 75 degrees), counted with summed
    area tables over a coarse grid, one per octave of blob area; counts
    beyond a card's are not more evidence, and ties go to the blob in the
    quietest surroundings (``noise``, per blob). When more remain than the
    budget, each is ranked first by how ring-like its neighbours are and how
    bare the paper round it is (:func:`.card_kernels.ring_evidence`).
    """
    n = len(blobs)
    if n < 1 + MIN_NEIGHBOURS or not np.any(blobs.area >= MIN_CENTRE_AREA):
        return np.zeros(0, dtype=np.intp)
    u, v, area = _f64(blobs.u), _f64(blobs.v), _f64(blobs.area)
    rho_out = config.ring_radii[0] / config.centre_dot_radius
    idx, evidence, reach = card_kernels.centre_evidence(
        u, v, area, _i32(blobs.box), float(blobs.scale), float(rho_out), MIN_CENTRE_AREA,
        MIN_NEIGHBOURS, _CELL)
    # A card's two rings and its marks make 18 neighbours: more say a crowd
    # (texture, foliage), not more card. Among the crowded, the quietest
    # surroundings first: a card's paper is smooth.
    most = 2 * RING_POINTS + 2
    quiet = np.zeros(len(idx)) if noise is None else np.asarray(noise, float)[idx]
    order = np.lexsort((-area[idx], quiet, -np.minimum(evidence, most)))
    if len(idx) <= params.max_candidates:
        return idx[order]
    # More than the budget (a textured floor, foliage, a busy poster): every
    # candidate is looked at in its own frame, where a card's ring dots are
    # alike in size and all round it and bare paper lies between it and its
    # inner ring (card_kernels.ring_evidence); the best first, the order
    # above breaking ties. A crowd's blob has neighbours at every distance,
    # and a near card's centre, its edge in the noise grid's cells, is not
    # the quietest place: by counts and quiet alone, a fine texture's
    # hundreds of candidates pushed a card out of the budget.
    idx, evidence, quiet = idx[order], evidence[order], quiet[order]
    score = card_kernels.ring_evidence(u, v, area, _i32(blobs.box), _i32(blobs.label),
                                       _i32(blobs.labels), int(blobs.scale), idx, reach,
                                       MIN_NEIGHBOURS, most, *_zones(config), _CELL,
                                       _RING_EVIDENCE_BUDGET)
    order = np.lexsort((-area[idx], quiet, -np.minimum(evidence, most), -score))
    return idx[order[:params.max_candidates]]


def far_candidates(dot_image: DotImage, config: PatternConfig, taken: np.ndarray,
                   claimed: np.ndarray) -> np.ndarray:
    """
    Return small centre blobs whose ring dots are too pale to be blobs once decimated.

    A far card's ring dots are two or three pixels across: decimated, they
    are paler than the segmentation's threshold, so the evidence count of
    :func:`rank_candidates` sees no ring. The darkest small blobs not yet
    examined (``taken``) nor inside a card found (``claimed``) are looked at
    again with a lenient threshold (:meth:`DotImage.faint_rings`: on the
    decimated image, and where no ring shows there, at full resolution);
    those with a ring's worth of faint spots round them are candidates. At most
    ``_FAR_TRIES`` windows are looked at (``_FAR_FULL_TRIES`` of them again
    at full resolution) and ``_FAR_EXTRA`` returned: the cost per image is
    bounded.
    """
    blobs = dot_image.blobs
    if blobs.scale == 1 or len(blobs) == 0:
        return np.zeros(0, dtype=np.intp)
    ok = (blobs.area >= _FAR_MIN_AREA) & (blobs.area <= _FAR_MAX_AREA) & ~claimed
    ok[np.asarray(taken, dtype=np.intp)] = False
    ci, white, noise = ink_spots(dot_image, ok, _FAR_TRIES)
    if len(ci) == 0:
        return np.zeros(0, dtype=np.intp)
    ring_like, n_ring, own = _faint_rings_round(dot_image, config, ci, white, noise)
    # Softly focused (an analog camera, a lens focused nearer), a far card's
    # dots merge once decimated into one ring-shaped spot: the darkest few
    # small ones that show no ring there are looked at again at full
    # resolution, where the dots are apart (four times the pixels a window:
    # few, and small, to keep the cost of a frame with none).
    again = np.flatnonzero(~ring_like & (blobs.area[ci] <= _FAR_FULL_MAX_AREA))[:_FAR_FULL_TRIES]
    if len(again):
        ring_like[again], n_ring[again], own[again] = _faint_rings_round(
            dot_image, config, ci[again], white[again], noise[again], decimated=False)
    # A centre dot is a dot, not the darkest part of a bigger dark thing,
    # and its rings' spots are all round it: in half the eight directions
    # or more, their mean near the centre. Darkest first; a crowd of faint
    # spots (more than a card's two rings and marks, and some) says
    # texture: last.
    found = ring_like & ~(own > 6.0 * blobs.area[ci])
    crowd = n_ring[found] > 3 * RING_POINTS
    return ci[found][np.argsort(crowd, kind='stable')[:_FAR_EXTRA]].astype(np.intp)


def _faint_rings_round(dot_image: DotImage, config: PatternConfig, ci: np.ndarray,
                       white: np.ndarray, noise: np.ndarray, decimated: bool = True
                       ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return :meth:`DotImage.faint_rings` round small blobs ``ci`` as a far card's centres."""
    blobs = dot_image.blobs
    rho_out = config.ring_radii[0] / config.centre_dot_radius
    # The reach of rank_candidates, half as big again: a centre this
    # small, pale at its rim, comes out smaller than it is.
    radius = np.sqrt(blobs.area[ci] / math.pi)
    extent = 0.5 * blobs.scale * np.max(blobs.box[ci, 2:4], axis=1).astype(np.float64)
    reach = 2.25 * rho_out * np.maximum(extent, radius) + 3.0
    max_area = 2.0 * blobs.area[ci] + 8.0
    return dot_image.faint_rings(blobs.u[ci], blobs.v[ci], reach, max_area, white, noise,
                                 radius, MIN_NEIGHBOURS, decimated=decimated)


def ink_spots(dot_image: DotImage, ok: np.ndarray, limit: int
              ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Return the blobs of ``ok`` that are surely ink, darkest first, at most ``limit``.

    With the local white and noise at each (:meth:`DotImage.white_at`,
    :meth:`DotImage.noise_at`).
    """
    idx = np.flatnonzero(ok)
    white, noise, dark, sure = _ink_measures(dot_image, idx)
    pick = np.flatnonzero(sure)[np.argsort(-dark[sure], kind='stable')[:limit]]
    return idx[pick], white[pick], noise[pick]


def _ink_measures(dot_image: DotImage, idx: np.ndarray
                  ) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Return blobs ``idx``'s local white, noise, peak darkness and whether each is surely ink."""
    blobs = dot_image.blobs
    # A centre dot is ink, the darkest thing on the card: clearly darker
    # than the noise round it (a speck of texture or of a dark noisy frame
    # is not), darkest first. The noise is measured where it is lowest
    # nearby, but a far card is too small to hold a quiet place: its own
    # dots' edges (and a busy background) make it. So a spot as dark as
    # ink is (at least 40 % below the white, blurred and decimated; the
    # segmentation's cap is half) is sure whatever that noise says, unless
    # such spots are more than could be tried: a texture's specks.
    u, v = blobs.u[idx], blobs.v[idx]
    white, noise = dot_image.white_at(u, v), dot_image.noise_at(u, v)
    dark = dot_image.peak_darkness(u, v, white)
    sure = dark * white >= _FAR_MIN_CONTRAST * noise
    inky = ~sure & (dark >= _FAR_INK_DARKNESS)
    if np.count_nonzero(inky) <= _FAR_TRIES:
        sure |= inky
    return white, noise, dark, sure


def zoom_spots(dot_image: DotImage, config: PatternConfig, claimed: np.ndarray, tries: int
               ) -> np.ndarray:
    """
    Return small blobs no card claimed, those a few faint spots ring first, at most ``tries``.

    Where :class:`~.detector.Detector` found no card, these are looked at
    again in a window zoomed and sharpened (:mod:`.zoom`): a far card seen
    through a soft lens, whose dots faded and merged at the image's own
    scale. Looked at: of the blobs from ``_ZOOM_MIN_AREA`` up, the darkest
    ``_ZOOM_LOOKS`` surely ink (:func:`ink_spots`' test), and those of the
    darkest ``_ZOOM_LOOKS`` that are not (a soft far centre is paler than
    ink). Of those, the few of before (from ``_FAR_MIN_AREA`` up, the
    darkest ``_FAR_TRIES`` of each kind) first: those with ``_ZOOM_MIN_RING``
    faint spots round them or more, but not a crowd (a ring too faint or
    broken for a far candidate), most first; then the others of the many
    that are so ringed, most first; then the few's others surely ink, darkest
    first; then the many's.
    """
    blobs = dot_image.blobs
    if len(blobs) == 0 or tries < 1:
        return np.zeros(0, dtype=np.intp)
    idx = np.flatnonzero((blobs.area >= _ZOOM_MIN_AREA) & (blobs.area <= _FAR_FULL_MAX_AREA)
                         & ~claimed)
    if len(idx) == 0:
        return np.zeros(0, dtype=np.intp)
    white, noise, dark, sure = _ink_measures(dot_image, idx)
    inked = np.flatnonzero(sure)[np.argsort(-dark[sure], kind='stable')[:_ZOOM_LOOKS]]
    darkest = np.argsort(-dark, kind='stable')[:_ZOOM_LOOKS]
    pick = np.concatenate([inked, darkest[~sure[darkest]]])
    ci = idx[pick]
    _, n_ring, own = _faint_rings_round(dot_image, config, ci, white[pick], noise[pick])
    ringed = (n_ring >= _ZOOM_MIN_RING) & (n_ring <= 3 * RING_POINTS) \
        & (own <= 6.0 * blobs.area[ci])
    # The few once looked at alone (from _FAR_MIN_AREA up, the darkest
    # _FAR_TRIES of each kind) that faint spots ring go first: the more blobs
    # looked at, the more a clutter holds one its specks ring more, which
    # pushed a ringed centre among the few out of the windows (seed 2's
    # frames). Then the others so ringed, then the rest surely ink, the few
    # first, darkest first.
    big = blobs.area[idx] >= _FAR_MIN_AREA
    few_ink = np.flatnonzero(sure & big)[np.argsort(-dark[sure & big], kind='stable')[:_FAR_TRIES]]
    few_dark = np.flatnonzero(big)[np.argsort(-dark[big], kind='stable')[:_FAR_TRIES]]
    few = np.isin(pick, np.concatenate([few_ink, few_dark[~sure[few_dark]]]))
    tier = np.where(ringed, np.where(few, 0, 1), np.where(few, 2, 3))
    looked = np.flatnonzero(ringed | sure[pick])
    order = looked[np.lexsort((np.where(ringed[looked], -n_ring[looked], 0), tier[looked]))]
    return ci[order[:tries]].astype(np.intp)


def group(blobs: Blobs, ci: int, config: PatternConfig, params: DetectorParams,
          camera: Optional[CameraModel]) -> Optional[CardGuess]:
    """
    Assign the blobs round centre blob ``ci`` to ring slots; None if no card is there.

    The centre blob's ellipse, mapped to the unit circle, makes the rings
    near circles of radii ``R / r_centre``; only blobs within reach of the
    outer ring and of a ring dot's size are looked at (any blob at all
    round a far card's small centre, whose ring dots are pale, unless
    crowded). A vote gives the rings' scale and the slots' angle, each
    neighbour goes to its nearest (ring, slot), and :func:`_verify` checks
    the homography. A small centre blob (a far card) is a poor guide to
    its own shape: when that fails, the neighbours' own second moments
    make the rings circles. (:func:`.card_kernels.group_slots`.)
    """
    if not 0 <= ci < len(blobs):
        return None
    args = (_f64(blobs.u), _f64(blobs.v), _f64(blobs.area), _i32(blobs.box), _i32(blobs.label),
            _i32(blobs.labels), int(blobs.scale), int(ci), _ring_rho(config),
            float(params.min_ellipse_fill), _FAR_MAX_AREA)
    for second in (False, True):
        status, slot_blob = card_kernels.group_slots(*args, second)
        if status == 0:
            return None
        if status == 1:
            guess = _verify(blobs, ci, slot_blob, config, params, camera)
            if guess is not None:
                return guess
    return None


def _verify(blobs: Blobs, ci: int, slot_blob: np.ndarray, config: PatternConfig,
            params: DetectorParams, camera: Optional[CameraModel]) -> Optional[CardGuess]:
    """Fit the plane-to-image homography to the assigned blobs; None if it does not hold."""
    # Slot order k increases clockwise in the image (v down) = clockwise on the
    # card seen from the front, unless the image is a mirror's (checked later).
    slot_xy, slot_radius = _slot_plane(config)
    pos, img = card_kernels.slot_points(slot_blob, _f64(blobs.u), _f64(blobs.v), ci)
    und = camera.undistort_pixels(img) if camera is not None else img
    # Blob centroids are rough (decimated, and a colour channel shifted by a
    # lens moves some inks' blobs): a first guess, checked again by the
    # measured centres.
    H, inliers = fit_homography(slot_xy[pos], und, slot_radius[pos],
                                1.6 * params.max_homography_error,
                                min_tolerance=0.75 * blobs.scale)
    if H is None:
        return None
    slot_blob.ravel()[pos[:-1][~inliers[:-1]]] = -1       # the kernel's own array
    seen = slot_blob >= 0
    if np.count_nonzero(seen) < 7 or np.count_nonzero(seen.any(axis=0)) < 5:
        return None
    return CardGuess(ci, slot_blob, H, blobs)


# Per pattern configuration, made once (per_config.made_once): ring radii in
# centre-dot radii, slot-ordered plane points (ring r slot k at row r * 8 + k,
# the centre last), their dots' radii, and the zones of _zones.
_PER_CONFIG: Dict[int, Tuple[PatternConfig, tuple]] = {}


def _ring_rho(config: PatternConfig) -> np.ndarray:
    """Return the rings' radii in centre-dot radii."""
    return _per_config(config)[0]


def _zones(config: PatternConfig) -> Tuple[float, float]:
    """Return how far round the centre its paper is bare, and its rings reach, in centre radii."""
    return _per_config(config)[3:5]


def _slot_plane(config: PatternConfig) -> Tuple[np.ndarray, np.ndarray]:
    """Return the slot-ordered plane points (the centre last) and their dots' radii."""
    return _per_config(config)[1:3]


def _per_config(config: PatternConfig) -> tuple:
    return made_once(_PER_CONFIG, config, _config_geometry)


def _config_geometry(config: PatternConfig) -> tuple:
    n_ring = config.n_rings * RING_POINTS
    return (np.array(config.ring_radii, dtype=np.float64) / config.centre_dot_radius,
            np.vstack([config.model_points()[1:, :2], [[0.0, 0.0]]]),
            np.append(np.full(n_ring, config.ring_dot_radius), config.centre_dot_radius),
            # Bare paper round the centre, in centre radii: most of the way
            # to the inner ring's dots' inner edges; the rings' zone: the
            # outer ring's dots and a dot's width beyond.
            0.8 * (config.ring_radii[-1] - config.ring_dot_radius) / config.centre_dot_radius,
            (config.ring_radii[0] + 2 * config.ring_dot_radius) / config.centre_dot_radius)


def _f64(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64)


def _i32(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.int32)


# Plane geometry -------------------------------------------------------------------

def fit_homography(obj: np.ndarray, img: np.ndarray, radii: np.ndarray, max_error: float,
                   min_tolerance: float = 0.75, min_points: int = 6, anchored: bool = True):
    """
    Homography from plane points to pixels with outlier rejection.

    A point is an outlier when it is off the fit by more than ``max_error``
    times its dot's image radius (``radii`` in metres), at least
    ``min_tolerance`` pixels. When ``anchored``, the last point (the
    centre) must be an inlier. Returns ``(H, inliers)`` or ``(None, None)``.
    """
    if len(obj) < min_points:
        return None, None
    # The rounds in one compiled call (fit_kernels.fit_homography_inliers).
    ok, H, inliers = fit_homography_inliers(_f64(obj), _f64(img), _f64(radii), float(max_error),
                                            float(min_tolerance), int(min_points),
                                            bool(anchored))
    return (H, inliers) if ok else (None, None)


def apply_h(H: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Map plane points (N, 2) by the homography."""
    p = np.column_stack([xy[:, 0], xy[:, 1], np.ones(len(xy))]) @ H.T
    return p[:, :2] / p[:, 2:3]


def h_jacobian(H: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Local linear map (N, 2, 2) of the homography at plane points (pixels per metre)."""
    p = np.column_stack([xy[:, 0], xy[:, 1], np.ones(len(xy))]) @ H.T
    w = p[:, 2]
    u, v = p[:, 0] / w, p[:, 1] / w
    J = np.empty((len(xy), 2, 2))
    J[:, 0, 0] = H[0, 0] - u * H[2, 0]
    J[:, 0, 1] = H[0, 1] - u * H[2, 1]
    J[:, 1, 0] = H[1, 0] - v * H[2, 0]
    J[:, 1, 1] = H[1, 1] - v * H[2, 1]
    return J / w[:, None, None]


def h_scale(H: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Local image scale (pixels per metre, geometric mean of the axes) at plane points."""
    return card_kernels.h_scales(_f64(H), _f64(xy))


def rotation_about_z(angle: float) -> np.ndarray:
    """
    Plane map taking final model coordinates to slot-ordered ones.

    Slot ``k`` holds point ``k - point1_slot + 1``; slot coordinates are the
    final ones turned clockwise (seen from the front) by ``point1_slot``
    steps of 45 degrees.
    """
    c, s = math.cos(angle), math.sin(angle)
    # Clockwise by `angle` in a frame with y up: (x, y) -> (x c + y s, -x s + y c).
    return np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
