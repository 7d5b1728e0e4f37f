"""
Sub-pixel centres: each dot measured where the homography puts it.

Every dot (and every mark) gets a window round its predicted position: its
image ellipse, grown for blur, ending at the card's edge, and shared with
its neighbours by distance (a pixel counts for the nearest spot only). The
centre is the darkness-weighted centroid of the window (darkness below the
local white, less a floor that keeps paper noise out), recomputed with the
window and the sharing re-centred on the latest estimates. With the colour
channels shifted (a cheap lens, composite video) a dot's darkest channel
lies between the images of the channels its ink is dark in, elsewhere for
each ink: the card's channel shifts are measured and each centre is put
where its green image is. Once the blur is
known (from the spread of all the dots), a last centroid is taken in a
window just big enough for the dot and its blur, with any dark region not
connected to the dot left out: the centre of the dot's image ellipse, which
the exact estimator corrects to the projected circle centre. Big dots are
measured on the image decimated by two (area averaging keeps centroids);
the measurement does not depend on segmentation, so faint dots and dots
merged with a neighbour (a far, tilted card) are measured like the others.

A window is a dot when it is dark enough against the paper and its noise,
its darkness stays inside it (paper round the dot, not an object over it),
it is not much bigger than a dot, its centre stays near the prediction and
its darkness is point-symmetric (a dot's image is, blurred or not; a dot
partly hidden, or touched by an object, is not).

Colour: a cheap lens or composite video shifts the colour channels by a
pixel or two, so each channel is measured where its own image of the dot
is. The shift is the same for every dot of a card: the median, over the
dots dark in a channel, of that channel's centroid minus the dot's. Each
channel's darkness (linear light, against the card's white) is the mean
over the inner part of the dot at that shift, well clear of any neighbour.
"""

from dataclasses import dataclass
from typing import Optional

import numpy as np

from . import spot_kernels
from .camera import CameraModel
from .detector_params import DetectorParams
from .dots import DotImage
from .stats import median

# Spots at least this big (semi-minor axis, image pixels) are measured on the
# decimated image.
_DECIMATED_FROM = 6.0


@dataclass(frozen=True)
class SpotMeasures:
    """Measurements of dots (or marks) at plane points, one row per point."""

    points: np.ndarray      # (P, 2) measured centres, image pixels
    predicted: np.ndarray   # (P, 2) where the homography put them
    valid: np.ndarray       # (P,) measured and dot-like: its centre may be used
    readable: np.ndarray    # (P,) its colour may be read (valid, or a clean inner part)
    peak: np.ndarray        # (P,) darkest-channel peak darkness / local white (0..1)
    colour: np.ndarray      # (P, 3) per-channel darkness, linear, BGR (NaN if grey)
    area: np.ndarray        # (P,) equivalent area of the dot, pixels
    inside: np.ndarray      # (P,) window fully inside the image
    partial: Optional[np.ndarray] = None    # (P,) colour read from an uncovered part only
    # (P,) the first, generous centroid near where the homography put the
    # spot (as a dot's last centroid must be): a spot printed there, not
    # the edge of an object beside the place, whose darkness pulls it off.
    centred: Optional[np.ndarray] = None
    # (P, 3) a far card's colours, from each dot's darkness summed round it
    # (its colour spread by JPEG or video; spot_kernels.small_card_colours;
    # a dot that is not valid keeps ``colour``): read when the peaks in
    # ``colour`` give no whole code. None for a card whose dots are bigger.
    far_colour: Optional[np.ndarray] = None
    # (P, 3) a glossy card's colours, with the light a highlight added over
    # some dots added back to their darkness (spot_kernels.lifted_peaks; a
    # dot that is not valid keeps ``colour``): read when the peaks give no
    # whole code. None where no dot's paper is lifted.
    glare_colour: Optional[np.ndarray] = None

    def __post_init__(self) -> None:
        if self.partial is None:
            object.__setattr__(self, 'partial', np.zeros(len(self.valid), dtype=bool))
        if self.centred is None:
            object.__setattr__(self, 'centred', np.ones(len(self.valid), dtype=bool))


@dataclass(frozen=True)
class Paper:
    """The card's paper as the image shows it."""

    colour: np.ndarray      # (3,) BGR, or (1,) grey: the card's white
    sigma: float            # noise (grey levels, full resolution) of the darkest channel
    # The sensor's noise alone, where the paper has room (a far card: the
    # other points' neighbourhoods hold blurred dot edges, in `sigma`).
    # Whether a dot is dark enough is judged against it; the weights and
    # the shape tests keep `sigma`, which allows for the blur's structure.
    quiet: Optional[float] = None


def card_paper(dot_image: DotImage, camera: Optional[CameraModel], H: np.ndarray,
               paper_xy: np.ndarray, clearance: Optional[np.ndarray] = None
               ) -> Optional[Paper]:
    """
    Measure the card's white (median over plane points between the dots) and its noise.

    The noise is measured there too, from each point's 3x3 neighbourhood:
    next to a small card in a busy scene the image's local noise says more
    about the scene than about the card. ``clearance`` (metres, per point)
    is how far each point is from ink or the card's edge: on a far card
    most points' neighbourhoods hold a blurred dot's edge, whose slope is
    no noise, so the noise is taken where the image has room.
    """
    pts, J, _ = spot_kernels.plane_to_image(np.ascontiguousarray(H, dtype=np.float64),
                                            np.ascontiguousarray(paper_xy, dtype=np.float64))
    if clearance is not None:
        # Room in pixels: clearance times the map's smaller singular value.
        sq = np.einsum('nij,nij->n', J, J)
        det = J[:, 0, 0] * J[:, 1, 1] - J[:, 0, 1] * J[:, 1, 0]
        room = np.asarray(clearance) * np.sqrt(np.maximum(
            0.5 * (sq - np.sqrt(np.maximum(sq * sq - 4.0 * det * det, 0.0))), 0.0))
    if camera is not None and camera.has_distortion:
        pts = camera.distort_pixels(pts)
    h, w = dot_image.image.shape[:2]
    inside = (pts[:, 0] >= 2) & (pts[:, 0] < w - 2) & (pts[:, 1] >= 2) & (pts[:, 1] < h - 2)
    pts = pts[inside]
    if len(pts) < 4:
        return None
    roomy = np.ones(len(pts), dtype=bool)
    if clearance is not None:
        # A 3x3 patch and a blur of a pixel or so: 3 pixels from ink. At
        # least the four points with the most room.
        room = room[inside]
        roomy = room >= min(3.0, float(np.sort(room)[-4]))
    # Per point a 3x3 patch (compiled: spot_kernels.paper_noise): the white
    # is the median centre pixel; the noise the median of each patch's mean
    # |pixel - 3x3 mean| in the darkest channel, sqrt(8/9) sqrt(2/pi) = 0.75
    # sigma for white noise.
    white, spread, roomy_spread = spot_kernels.paper_noise(
        dot_image.kernel_view(decimated=False), np.ascontiguousarray(pts, dtype=np.float64),
        np.ascontiguousarray(roomy))
    if np.max(white) < dot_image.params.min_white:
        return None
    sigma = float(spread) / 0.75
    # Ink's or the background's slope only adds to the spread: the quieter
    # of all the points and those with room, and (a card too small for any
    # room) of the image's own noise there, measured where it is quietest.
    quiet = min(sigma, float(roomy_spread) / 0.75)
    if clearance is not None and not np.any(room[roomy] >= 3.0):
        quiet = min(quiet, float(median(dot_image.noise_at(pts[:, 0], pts[:, 1]))))
    # A few flat patches (JPEG quantises noise away) say little: at least a
    # grey level.
    return Paper(np.maximum(np.atleast_1d(white), 1.0), sigma, max(quiet, min(sigma, 1.0)))


@dataclass(frozen=True)
class PlaneLayout:
    """
    Spots on the card and how its plane is shared between them.

    ``owner`` is a raster over the card (``resolution`` metres a cell, from
    ``-half`` to ``+half``) holding, for every place, the spot whose edge is
    nearest (a power diagram), or -1 off the card. Windows are shared by it,
    so that a steep view, whose dots are long thin ellipses side by side,
    splits them as the card's own plane does.
    """

    points: np.ndarray          # (P, 2) metres
    radii: np.ndarray           # (P,) metres
    owner: np.ndarray           # (R, R) int16
    resolution: float
    half: float


def plane_layout(points: np.ndarray, radii: np.ndarray, card_half: float,
                 resolution: float = 0.001) -> PlaneLayout:
    """Build the :class:`PlaneLayout` of spots on a card of half-size ``card_half``."""
    n = int(np.ceil(2 * card_half / resolution))
    axis = -card_half + resolution * (np.arange(n) + 0.5)
    x, y = np.meshgrid(axis, -axis)              # row 0 is the card's top (+y)
    best = np.full(x.shape, np.inf)
    owner = np.full(x.shape, -1, dtype=np.int16)
    for k, ((px, py), r) in enumerate(zip(points, radii)):
        d = np.hypot(x - px, y - py) - r
        nearer = d < best
        best[nearer] = d[nearer]
        owner[nearer] = k
    return PlaneLayout(np.asarray(points, float), np.asarray(radii, float), owner,
                       float(resolution), float(card_half))


class _Windows:
    """
    The windows of a group of spots, measured at once on one image.

    Coordinates are the source image's pixels relative to each window's
    integer origin; the source is the image (scale 1) or the image
    decimated by ``scale``, whose pixel (x, y) covers image pixels
    ``scale * x .. scale * x + scale - 1``. What the passes over them
    (:func:`.spot_kernels.measure`) leave for :func:`_uncovered_part`.
    """

    def __init__(self, index: np.ndarray, scale: int, size: int, axes: np.ndarray,
                 pred: np.ndarray, to_plane: np.ndarray, cell: np.ndarray, on_card: np.ndarray,
                 in_image: np.ndarray) -> None:
        self.index, self.scale, self.size = index, scale, size
        self.axes, self.pred, self.to_plane = axes, pred, to_plane
        self.cell, self.on_card, self.in_image = cell, on_card, in_image

    def ellipse(self, c: np.ndarray, semi: np.ndarray) -> np.ndarray:
        """Normalised squared radius (1 on the edge) from centres ``c``, semi-axes ``semi``."""
        return spot_kernels.ellipse(self.axes, np.ascontiguousarray(c, dtype=np.float64),
                                    np.ascontiguousarray(semi, dtype=np.float64), self.size)


def measure_spots(dot_image: DotImage, camera: Optional[CameraModel], H: np.ndarray,
                  layout: PlaneLayout, spots: np.ndarray, paper: Paper, colour: bool = True,
                  core_margin: Optional[float] = None, refine: bool = True,
                  min_valid: int = 0, min_darkness: Optional[float] = None) -> SpotMeasures:
    """
    Measure the spots ``spots`` (indices into ``layout``) where ``H`` puts them.

    ``H`` maps the plane (metres) to undistorted pixels. ``paper`` is the
    card's white and noise (:func:`card_paper`); ``colour``: measure the
    colours too (not for grey images). The peak darkness is measured within
    the spot's image ellipse grown by ``core_margin`` pixels round where it
    should be (default: the largest channel shift, plus one). ``refine=False``
    stops after the first, generous windows: enough to tell whether a spot
    is there (the handedness marks), not for a centre to fit to.
    ``min_valid`` (if above 0) stops there unless the first spot and at
    least ``min_valid`` spots are valid: the refinement only ever drops
    spots, so a caller that needs more than the first windows found needs
    nothing more.
    ``min_darkness`` (default ``params.min_window_darkness``): how much
    darker than the paper a spot must be (a fraction of the white).
    """
    params = dot_image.params
    if core_margin is None:
        core_margin = params.max_channel_shift_px + 1.0
    spots = np.ascontiguousarray(spots, dtype=np.int64)
    plane_xy, radii = layout.points[spots], layout.radii[spots]
    # Where the homography puts the spots, and its local linear map there
    # (n, 2, 2 pixels per metre).
    pred, L, probes = spot_kernels.plane_to_image(np.ascontiguousarray(H, dtype=np.float64),
                                                  np.ascontiguousarray(plane_xy, dtype=np.float64))
    if camera is not None and camera.has_distortion:
        # The lens's local linear map, by differences of one pixel (one call).
        pred, L = spot_kernels.through_lens(camera.distort_pixels(probes), L)
    # Window: the spot's ellipse, 1.2 times as big plus a margin for blur
    # and half the channel shift (the darkest channel is the union of the
    # channels' dots), along its own axes. A degenerate homography would
    # ask for windows bigger than the image: memory stays bounded by the
    # image, nothing is measured. Spots big enough are measured on the
    # decimated image. Then the passes below, in one compiled call
    # (spot_kernels.measure).
    h, w = dot_image.image.shape[:2]
    colour = bool(colour and dot_image.image.ndim == 3)
    rows, windows_1, windows_s = spot_kernels.measure(
        dot_image.kernel_view(decimated=False), dot_image.kernel_view(decimated=True),
        int(dot_image.scale), pred, L,
        np.ascontiguousarray(radii, dtype=np.float64), 2.0 + 0.5 * params.max_channel_shift_px,
        0.25 * max(h, w), _DECIMATED_FROM, spots, np.ascontiguousarray(plane_xy),
        layout.owner, layout.half, layout.resolution, dot_image.white, dot_image.grid_step,
        float(paper.sigma), np.nan if paper.quiet is None else float(paper.quiet),
        float(params.gamma),
        float(params.min_window_darkness if min_darkness is None else min_darkness),
        float(core_margin), bool(refine), int(min_valid), colour,
        _colour_table(paper.colour, params.gamma) if colour else _NO_TABLE,
        float(params.max_channel_shift_px),
        np.asarray(paper.colour, dtype=np.float64) if colour else _NO_WHITE)
    (_, points, valid, readable, peak, colours, area, inside, partial, centred, major,
     minor, far, far_colour, glared, glare_colour) = rows
    out = SpotMeasures(points, pred, valid, readable, peak, colours, area, inside, partial,
                       centred, far_colour if far else None, glare_colour if glared else None)
    for scale, (index, size, axes, window_pred, to_plane, cell, on_card, in_image, dark,
                uncover) in ((1, windows_1), (dot_image.scale, windows_s)):
        if uncover:
            g = _Windows(index, scale, size, axes, window_pred, to_plane, cell, on_card,
                         in_image)
            _uncovered_part(g, dark, major, minor, layout, spots, out)
    # A dot that is not valid (an object touches it) keeps its peaks, or what
    # its uncovered part gave: a sum round it would take in the object, and
    # the paper round it tells nothing of the light.
    touched = ~out.valid
    for other in (out.far_colour, out.glare_colour):
        if other is not None:
            other[touched] = out.colour[touched]
    return out


def _colour_table(white: np.ndarray, gamma: float) -> np.ndarray:
    """Return each level's darkness per channel (256, 3), linear light against the card's white."""
    levels = np.arange(256, dtype=np.float32)[:, None] / np.asarray(white, np.float32)[None, :]
    return np.ascontiguousarray(1.0 - np.clip(levels, 0.0, 1.0) ** gamma, dtype=np.float32)


# The table and white of an image without colour (the kernels' arguments, not read).
_NO_TABLE = np.zeros((256, 3), dtype=np.float32)
_NO_WHITE = np.ones(3)


# What the passes of spot_kernels.measure measure, and why (the kernels do
# the arithmetic; this is their specification).
#
# First pass: a centroid in a generous window, and the tests of a dot. The
# darkness (below the local white, less a floor that keeps paper noise out)
# in the spot's share of the window, on the card inside its edge by two
# image pixels (blur carries what is beyond onto it) but never closer than
# a pixel and a half round the spot itself (a steep view brings the edge
# that close, and cutting the spot's own blur would pull its centre). Its
# peak (3x3 mean) is taken where the spot should be: a spot that is not
# there drifts off towards whatever is dark nearby. The noise of the
# decimated image is the image's over the scale (it averages scale^2
# pixels). Where the paper round the spot (its own part of the plane)
# tilts clearly, as on a glossy card's highlight, the darkness is taken
# below a plane fitted to that paper and in linear light, where the
# highlight's light, added to ink and paper alike, cancels: below a level
# white in the camera's encoding, a dot is darker where less light is
# added, and its centroid moves there.
#
# Blur, as a covariance (2x2, image pixels^2) from the dots' spread: a
# sharp ellipse of semi-axes a, b has second moments a^2/4, b^2/4 along its
# axes; blur adds its own covariance to every dot alike (defocus in all
# directions, motion along one). The median over the dots resists a few
# spoilt by neighbours or objects. Its eigenvalues are at least 0.1.
#
# Last pass: the centroid again in a window just big enough for the dot and
# the blur. The first windows were generous (the blur was unknown) and
# shared as the prediction put the spots; now they are shared about the
# measured centre. An object next to a dot, or the card's edge, would pull
# a centroid taken in a generous window. Dark things in the window apart
# from the dot (an object a pixel or two away, a neighbour's blur) are not
# the dot's: its own dark region is the connected one at its centre (dark:
# a quarter of its peak; the region with the darkest pixel within a pixel
# and a half of the centre). A dot's image is point-symmetric, blurred or
# not (and so is the union of its colour channels shifted opposite ways); a
# dot partly hidden, or touched by an object, is not. Its asymmetry is
# compared where both a pixel and its reflection through the centre
# (bilinear) belong to the spot, so that sharing pixels with a close
# neighbour cuts both sides alike: |w - reflected w| / (w + reflected w)
# summed, less what the pixel noise alone gives (|difference of two noisy
# pixels| is 1.13 sigma on average). A dot must also stay near its
# prediction, and its dark region must not reach beyond the dot and its
# blur (an object touching it).
#
# Colours: per-channel darkness of every spot, where that channel's image
# of it is. Each channel's darkness (linear light against the card's
# white) is averaged over 3x3 pixels and its peak taken within the dot's
# inner part grown by the largest channel shift: a channel displaced by a
# pixel or two has its peak displaced, not lowered. The window is shared
# with the neighbours as the card's plane is, and dark things not joined to
# the dot are left out, so no neighbour's or object's colour comes in. A
# dot read for its colour alone (not valid) must be even in every channel
# there, as the sure dots are: not half ink, half something else.
#
# Every dot's centre is then put where its green image is. With red and
# blue shifted against green (a cheap lens, composite video), the darkest
# channel's image of a dot lies between the images of the channels the ink
# is dark in: somewhere else for each ink, which the homography would take
# for error. The card's shifts (red and blue against green, the median
# over the dots dark in both) tell each dot's offset, which is taken away.
# The offset is not the mean of its dark channels' shifts: the darkest
# channel is darker where the darker channel's image is (a green dot, dark
# in red and less in blue, lies towards red). Shifted by more than a
# quarter of a pixel, a dot big enough for its window to hold every
# channel's image is put at its dark channels' own centroids, each less
# its shift; a smaller one moves by its channels' shifts weighted by
# their darkness in the camera's encoding. That moves centres only; the
# colours of dots partly covered by an object (_uncovered_part, after the
# call) read and write colours only.


def _uncovered_part(g: _Windows, dark: np.ndarray, major: np.ndarray, minor: np.ndarray,
                    layout: PlaneLayout, spots: np.ndarray, out: SpotMeasures) -> None:
    """
    Colour of dots partly covered by an object, from the part of them that shows.

    An object over the card hides part of some dots; their centres are lost
    but the ink that shows still has its colour. The object's own colour
    is what is dark where the card's paper should be round the dot; the
    dot's ink is what, inside the dot (its inner part, clear of its blurred
    rim), is as dark as the card's sure dots and far from that colour; of
    that, only the part farthest from the object's colour (the pixels that
    the blur has not mixed with it), and only when there is enough of it
    and it is even. Such dots are marked ``partial``: the code reading asks
    more of them (:func:`~.code_reading.read_code`).

    A dot touched by an object (not valid, but read for its colour since
    its inner part is even) may be even because the object covers it, and
    a partial reading may be the object's edge: a colour that is the
    object's is not the ink's. The object's colour for that is taken where
    paper should be anywhere in the window, not only in the dot's share
    (the neighbours' shares cut an object off), from its darker half (not
    its blurred edge). A black object over a coloured dot was read as
    black: a second point 1, or a wrong one.
    """
    idx = g.index
    sure = out.valid[idx]
    fit = out.inside[idx] & (minor[idx] >= 2.5)
    todo = ~out.readable[idx] & fit
    touched = out.readable[idx] & ~sure & ~out.partial[idx] & fit
    if np.count_nonzero(sure) < 3 or not np.any(todo | touched):
        return
    ink = float(median(out.colour[idx][sure].max(axis=1)))
    axes = np.column_stack([major[idx], minor[idx]]) / g.scale
    ellipse = g.ellipse(g.pred, axes)
    for j in np.flatnonzero(todo | touched):
        e, cell, b = ellipse[j], g.cell[j], axes[j, 1]
        # Inside the dot clear of its blurred rim (a pixel and a half).
        inner = cell & (e <= max((b - 1.5) / b, 0.4) ** 2)
        # Where paper should be: round the dot beyond its blur, on the card.
        ring = cell & g.on_card[j] & (e >= ((b + 2.0) / b) ** 2)
        pix = spot_kernels.box3(dark[j])                      # (S, S, 3) 3x3 mean darkness
        strength = pix.max(axis=2)
        obj = None
        if touched[j]:
            obj = _object_colour(pix, strength, ring | _paper(g, j, layout, spots))
            if obj is None or np.linalg.norm(out.colour[idx[j]] - obj) >= 0.3 * ink:
                continue
            # The object's colour, not the ink's: perhaps some ink shows.
            out.readable[idx[j]] = False
            out.colour[idx[j]] = np.nan
        if np.count_nonzero(inner) < 6:
            continue
        stain = ring & (strength > 0.15)
        candidate = inner & (strength >= 0.6 * ink)
        if np.count_nonzero(stain) >= 4:
            other = median(pix[stain], axis=0)
            away = np.linalg.norm(pix - other[None, None, :], axis=2)
            candidate &= away >= 0.3 * ink
            if np.any(candidate):
                candidate &= away >= 0.8 * away[candidate].max()
        n = np.count_nonzero(candidate)
        if n < max(4, 0.2 * np.count_nonzero(inner)):
            continue
        chosen = pix[candidate]
        mean = chosen.mean(axis=0)
        if np.max(chosen.std(axis=0)) > 0.05 + 0.1 * mean.max():
            continue
        if obj is None:
            obj = _object_colour(pix, strength, ring | _paper(g, j, layout, spots))
        if obj is not None and np.linalg.norm(mean - obj) < 0.3 * ink:
            continue
        out.colour[idx[j]] = mean
        out.readable[idx[j]] = True
        out.partial[idx[j]] = True


def _object_colour(pix: np.ndarray, strength: np.ndarray, paper: np.ndarray
                   ) -> Optional[np.ndarray]:
    """Return the colour of what is dark where ``paper`` should be (its darker half), or None."""
    stain = paper & (strength > 0.15)
    if np.count_nonzero(stain) < 4:
        return None
    s = strength[stain]
    return median(pix[stain][s >= median(s)], axis=0)


def _paper(g: _Windows, j: int, layout: PlaneLayout, spots: np.ndarray) -> np.ndarray:
    """Return window ``j``'s pixels that should be paper: on the card, 3 pixels from any ink."""
    # One compiled pass: as numpy arrays (every pixel against every spot)
    # it cost half a millisecond a window, and a frame whose dots an object
    # or a comb touches calls it for most of them.
    return spot_kernels.paper_pixels(
        int(g.size), np.ascontiguousarray(g.pred[j], dtype=np.float64),
        np.ascontiguousarray(g.to_plane[j], dtype=np.float64),
        np.ascontiguousarray(layout.points[spots[g.index[j]]], dtype=np.float64),
        np.ascontiguousarray(layout.points, dtype=np.float64),
        np.ascontiguousarray(layout.radii, dtype=np.float64), float(layout.half),
        np.ascontiguousarray(g.in_image[j]))


def _load_kernels() -> None:
    """
    Measure two spots of a small blank image once, so that the kernels are ready.

    numba compiles each kernel at its first call (or loads it from its cache
    beside the module: a few tenths of a second); done here, at import, a
    node's first frame is measured as fast as the others (a replayed bag's
    first images are not dropped; the head tracks the first card at once).
    """
    from .dots import segment
    image = np.full((48, 48, 3), 200, dtype=np.uint8)
    dot_image = segment(image, DetectorParams(field='frame'))
    layout = plane_layout(np.array([[-0.01, 0.0], [0.01, 0.0]]), np.full(2, 0.004), 0.02)
    H = np.array([[400.0, 0.0, 24.0], [0.0, -400.0, 24.0], [0.0, 0.0, 1.0]])
    measure_spots(dot_image, None, H, layout, np.arange(2), Paper(np.full(3, 200.0), 1.0, 1.0))
    spot_kernels.through_lens(np.zeros((6, 2)), np.zeros((2, 2, 2)))
    card_paper(dot_image, None, H, np.array([[-0.02, -0.02], [0.02, -0.02], [0.02, 0.02],
                                             [-0.02, 0.02], [0.0, 0.02]]), np.full(5, 0.01))
    # The three only a dot partly covered by an object needs.
    spot_kernels.box3(np.zeros((1, 1, 3), dtype=np.float32))
    spot_kernels.ellipse(np.zeros((1, 2, 2), dtype=np.float32), np.zeros((1, 2)),
                         np.ones((1, 2)), 1)
    spot_kernels.paper_pixels(1, np.zeros(2), np.eye(2), np.zeros(2), np.zeros((1, 2)),
                              np.zeros(1), 1.0, np.ones((1, 1), dtype=bool))


_load_kernels()
