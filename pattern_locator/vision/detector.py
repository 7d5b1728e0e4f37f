"""
Find colour-dot cards in a BGR image: dots -> cards -> sub-pixel centres -> order and code.

Four stages, one module each:

1. **Dots** (:mod:`.dots`): dark blobs against the local white and noise,
   on the image decimated by two, in time linear in the pixels.
2. **Cards** (:mod:`.cards`): centre candidates ranked by evidence (blobs of
   ring-dot size within ring reach) and cut at a budget; for each, the
   rings' slots and a homography that verifies the geometry. A far card's
   small dots are segmented again at full resolution round its centre.
3. **Sub-pixel centres** (:mod:`.centres`): every dot measured at full
   resolution where the homography puts it, the homography refitted to
   the dots that pass.
4. **Order and code** (:mod:`.code_reading`): colours against the card's own
   white, point 1 (the black slot), the code, both rings agreeing; the
   handedness marks where the card carries them, so a mirror image never
   gives an id. Slots an object hides are filled from the known codes (a
   building map's) when one fits, else the few that fit are handed on as
   ``candidates`` for a localizer to choose among.

Where no card is read, a few small ink blobs are looked at again in windows
zoomed twice and sharpened (:mod:`.zoom`), through the same four stages: a
far card seen through a soft lens.

Nothing here grows faster than the pixels plus a fixed number of candidates:
bounded time and memory on any image.
"""

import dataclasses
from dataclasses import dataclass, field
import functools
from typing import Dict, Iterable, Iterator, List, NamedTuple, Optional, Tuple

import numpy as np

from . import card_kernels
from .camera import CameraModel
from .cards import (apply_h, CardGuess, far_candidates, fit_homography, group,
                    rank_candidates, rotation_about_z, zoom_spots)
from .centres import card_paper, measure_spots, Paper, plane_layout, SpotMeasures
from .code_reading import (code_table, handedness, partial_hypotheses, read_code, Reading,
                           sole_hypothesis)
from .detector_params import DetectorParams
from .dots import check_image, DotImage, segment
from .drawn_card import drawn_cards
from .stats import median
from .zoom import zoom_window, ZOOMED_PIXEL_SIGMA, ZoomedWindow
from ..card.pattern import Code, Ids, PatternConfig, RING_POINTS
from ..errors import CodeError

__all__ = ['CardDetection', 'Detector', 'DetectorParams']

# A candidate looked at again at full resolution goes on only when its centre
# blob there fills at least this much of its moment ellipse: centre dots fill
# 0.95-0.99 whatever the view, blur or light (an ellipse fills 1, a bar 0.95),
# three quarters of the clutter blobs whose card windows were wasted less.
_MIN_CENTRE_FILL = 0.8
# Blobs beyond which a found card's covered blobs are sought in a box first.
_FEW_BLOBS = 150
# Dots a homography is refitted to, the centre among them.
_REFIT_MIN = 7
# Ring dots it is refitted to without the centre. A centre dot that is there
# (its inner part clean enough to read) but fails the tests of a dot, as
# under a lamp's highlight across it or with an object at its rim, anchors
# no fit: three quarters of the ring must.
_RING_REFIT_MIN = 12
# A zoomed window's half side (image pixels), at most: a card at 5.5 m and beyond.
_ZOOM_MAX_HALF = 48
# The card's centre on its plane (metres).
_PLANE_ORIGIN = np.zeros((1, 2))
# 64 points round the unit circle: a found card's outer disc, for the box of
# the blobs it may cover (Detector._covered).
_UNIT_CIRCLE = np.column_stack([np.cos(np.linspace(0.0, 2 * np.pi, 64, endpoint=False)),
                                np.sin(np.linspace(0.0, 2 * np.pi, 64, endpoint=False))])


@dataclass(frozen=True)
class CardDetection:
    """
    One card found in an image.

    ``points_px`` holds the sub-pixel dot centres in dot-index order
    (0 = centre, then ring 0 points 1..8, ring 1 points 1..8), NaN where a
    dot was not seen. ``code`` and ``ids`` are None for a grey image, where
    the ring order (point 1) is unknown too.
    """

    code: Optional[Code]
    ids: Optional[Ids]
    points_px: np.ndarray
    dot_areas_px: np.ndarray
    complete_rings: Tuple[int, ...]
    size_px: float                  # long semi-axis of the card's outer ring, pixels
    homography: np.ndarray          # pattern plane (metres) -> undistorted pixels
    colour_margin: float            # how clearly the colours were read, 0..1
    ring_codes: Tuple[str, ...] = field(default=())   # per ring, the colours read
    # Slots hidden by an object and filled from the known codes (the map):
    # such an id is only as sure as the map is complete, so the localizer
    # takes it only where its last fix already puts the robot.
    slots_from_map: int = 0
    # Hidden slots that several known codes fill: code and ids are None, and
    # these are the hypotheses (each whole: code, point 1, points in its dot
    # order) that the localizer chooses among by its last fix.
    candidates: Tuple['CardDetection', ...] = ()

    # Where the fit puts the centre (image pixels) when its dot is not among
    # the points (there, but not measured well enough for the pose).
    fitted_centre_px: Optional[np.ndarray] = None
    # A floor (image pixels) of the dots' noise that the pose counts, above
    # what the fit's residuals say: a zoomed window's dots (vision.zoom) fit
    # their pose closely but carry errors of a tenth of a pixel or two, the
    # same for neighbours, that its residuals do not show.
    min_pixel_sigma: float = 0.0

    @property
    def centre_px(self) -> np.ndarray:
        """Return the card centre's pixel: its dot's, else where the fit puts it."""
        if self.fitted_centre_px is not None and np.isnan(self.points_px[0, 0]):
            return self.fitted_centre_px
        return self.points_px[0]

    @property
    def n_points(self) -> int:
        return int(np.count_nonzero(~np.isnan(self.points_px[:, 0])))


class Detector:
    """Detect colour-dot cards; one instance per pattern configuration."""

    def __init__(self, config: PatternConfig, params: DetectorParams = DetectorParams(),
                 known_codes: Optional[Iterable[Code]] = None):
        """
        Prepare for ``config``'s cards.

        ``known_codes``: the codes that exist (a building map's). With them, a
        card with up to ``params.max_hidden_slots`` slots hidden by an object
        is given the one known code that fits what is seen, when no other
        known code comes within one seen slot of it
        (:func:`~.code_reading.resolve_partial`). When 2 to
        ``params.max_code_candidates`` known codes remain
        (:func:`~.code_reading.partial_hypotheses`), the card comes with no
        code and those the handedness marks allow as its ``candidates``, for
        a localizer to choose among by where the robot is. Without known
        codes, only a hidden point 1 is completed (the one black slot, when
        seven coloured ones are seen).
        """
        self.config = config
        self.params = params
        self._codes = sorted(set(known_codes), key=str) if known_codes is not None else []
        self._code_table = code_table(self._codes)
        model = config.model_points()[:, :2]
        # Slot-ordered plane points: slot k of ring r taken as point k + 1.
        self._model = model
        self._radii = config.dot_radii()
        self._paper_xy = _paper_points(config)
        self._paper_room = _paper_clearance(config, self._paper_xy)
        self._rho_out = config.ring_radii[0] / config.centre_dot_radius
        # Per card found, made once: slot order -> dot order for each slot of
        # point 1, and the outer ring's plane points.
        self._orders = [_dot_order(config, point1) for point1 in range(RING_POINTS)]
        self._turns = [rotation_about_z(point1 * np.pi / 4) for point1 in range(RING_POINTS)]
        # Each code's ids once (None: not a valid code). At most one entry per
        # code the configuration has: bounded, whatever the uptime.
        self._ids: Dict[Code, Optional[Ids]] = {}
        self._outer = config.model_points()[1:1 + RING_POINTS, :2]
        # The outer ring's dots' outer edges, and a dot's width beyond: a zoomed
        # window that holds all of these holds the whole card.
        self._outer_rim = self._outer * (
            1.0 + 3.0 * config.ring_dot_radius / config.ring_radii[0])
        half = config.card_size / 2
        # How the card's plane is shared between the windows of its dots: before
        # point 1 is known, with every place a mark may be; after, with the
        # marks and where a mirror would show them.
        self._dots = np.arange(config.n_dots)
        places = _mark_places(config) if config.handedness_mark is not None else np.zeros((0, 2))
        self._dot_layout = plane_layout(np.vstack([model, places]), np.concatenate(
            [self._radii, np.full(len(places), config.mark_radius)]), half)
        if config.handedness_mark is not None:
            marks = np.vstack([config.mark_points(), config.mark_points(mirrored=True)])
            self._mark_layout = plane_layout(np.vstack([model, marks]), np.concatenate(
                [self._radii, np.full(len(marks), config.mark_radius)]), half)
            self._marks = config.n_dots + np.arange(len(marks))

    def detect(self, image: np.ndarray, camera: Optional[CameraModel] = None
               ) -> List[CardDetection]:
        """Every card in ``image`` (BGR uint8, or grey for geometry only)."""
        image = check_image(image)
        scan = self._detect(image, camera)
        cards, dot_image, claimed = scan.cards, scan.dot_image, scan.claimed
        if any(card.ids is not None for card in cards) or dot_image.grey_only:
            return cards
        # No card read: a far card through a soft lens may be where the small
        # ink blobs are. Each window zoomed and sharpened goes through every
        # stage again (at most params.zoom_tries windows of bounded size).
        # First the far candidates: a ring showed round them at the image's
        # scale (cards.far_candidates), too soft to read there whole (a card
        # found there with slots it could not read claims them, and the zoom
        # may read it whole). Then small blobs that faint spots ring, then the
        # darkest ink blobs (cards.zoom_spots). None in a card read whole and
        # seen in a mirror: its dots were sharp enough, and a zoom sees the
        # same mirror (three windows on a glass door's card cost 10-20 ms at
        # 1280x720).
        blobs = dot_image.blobs
        in_mirror = np.zeros(len(blobs), dtype=bool)
        for H in scan.mirrored:
            in_mirror |= self._covered(H, blobs, camera)
        tries = self.params.zoom_tries
        order = [int(j) for j in scan.far if not in_mirror[j]]
        order += [int(j) for j in zoom_spots(dot_image, self.config, claimed | in_mirror, tries)
                  if int(j) not in order]
        zoomed = np.zeros(len(blobs), dtype=bool)     # blobs of the cards the windows read
        for j in order[:tries]:
            if zoomed[j]:
                continue
            radius = max(blobs.extent(int(j)), float(np.sqrt(blobs.area[j] / np.pi)))
            half = int(min(_ZOOM_MAX_HALF, 2.2 * self._rho_out * radius + 8))
            window = zoom_window(image, camera, float(blobs.u[j]), float(blobs.v[j]), half)
            if window is None:
                continue
            for card in self._detect(window.image, window.camera).cards:
                # Only the card whose centre was zoomed on, read whole, or
                # with slots from the map only where the window holds all of
                # it: the window's edge may hide part of any other (a near
                # card's ring dot is as small as a far centre), and what an
                # edge hides is not a hidden slot.
                if card.ids is None or card.candidates or (
                        card.slots_from_map and not self._held(card, window)):
                    continue
                card = _in_image(card, window.to_image())
                if np.hypot(*(card.centre_px - (blobs.u[j], blobs.v[j]))) > radius:
                    continue
                # It replaces the card the image's scale found there unread.
                cards = [k for k in cards if k.ids is not None
                         or not self._covered(k.homography, blobs, camera)[j]]
                zoomed |= self._covered(card.homography, blobs, camera)
                cards.append(card)
        return cards

    def _held(self, card: CardDetection, window: ZoomedWindow) -> bool:
        """Tell whether a card found in ``window`` lies wholly inside it, a dot's width in."""
        rim = _plane_pixels(card.homography, self._outer_rim, window.camera)
        h, w = window.image.shape[:2]
        return bool(np.all(np.isfinite(rim)) and np.all(rim >= 0.0)
                    and np.all(rim[:, 0] <= w - 1) and np.all(rim[:, 1] <= h - 1))

    def _detect(self, image: np.ndarray, camera: Optional[CameraModel]) -> '_Scan':
        """Find the cards at the image's own scale (:class:`_Scan`)."""
        dot_image = segment(image, self.params)
        blobs = dot_image.blobs
        claimed = np.zeros(len(blobs), dtype=bool)
        cards: List[CardDetection] = []
        mirrored: List[np.ndarray] = []
        ranked = rank_candidates(blobs, self.config, self.params,
                                 dot_image.noise_at(blobs.u, blobs.v))

        far = np.zeros(0, dtype=np.intp)    # the far candidates, kept for the zoom

        def candidates() -> Iterator[int]:
            nonlocal far
            yield from ranked
            # Then far cards whose ring dots decimation lost (bounded; see cards.py).
            far = far_candidates(dot_image, self.config, ranked, claimed)
            yield from far

        for ci in candidates():
            if claimed[ci]:
                continue
            card = hidden = None
            for guess in self._guesses(dot_image, int(ci), camera):
                card = self._measure_and_read(dot_image, guess, camera, mirrored)
                if card is not None and card.candidates:
                    # Several codes fit: a finer grouping may yet read the slot.
                    hidden, card = hidden or card, None
                    continue
                if card is not None:
                    break
            card = card or hidden
            if card is None:
                continue
            claimed |= self._covered(card.homography, blobs, camera)
            cards.append(card)
        return _Scan(cards, dot_image, claimed, mirrored, far)

    def warm_up(self) -> int:
        """
        Read a drawn image of two cards; return how many were read right (2 when all is well).

        A node calls this at start: its first camera frame then finds every
        pass ready (the compiled ones are loaded when their modules are
        imported; the rest build their caches on a first call), and it learns
        whether the detector reads its own cards (a pattern configuration
        that does not match the detector's parameters would not). The card
        drawn is one of the known codes (else any code) with the most
        colours, so that every colour is read.
        """
        codes = self._codes or [code for _, code in self.config.all_codes()]
        code = max(codes, key=lambda c: (len(set(c.ring + c.centre)), c.centre != 'K', str(c)))
        cards = self.detect(drawn_cards(self.config, code))
        return sum(1 for card in cards if card.code == code)

    # Cards -----------------------------------------------------------------

    def _guesses(self, dot_image: DotImage, ci: int, camera: Optional[CameraModel]
                 ) -> Iterator[CardGuess]:
        """
        Ways of grouping round candidate ``ci``, cheapest first.

        On the decimated blobs when the centre is big enough there; for a
        small centre, or a middling one whose grouping did not hold, on
        blobs segmented again at full resolution round it (a far or steeply
        tilted card's dots are a few pixels across and merge when
        decimated).
        """
        blobs = dot_image.blobs
        radius = np.sqrt(blobs.area[ci] / np.pi)
        if blobs.scale == 1 or radius >= 6.0:
            guess = group(blobs, ci, self.config, self.params, camera)
            if guess is not None:
                yield guess
            # A middling round centre with nothing card-like round it: no card
            # there. A steep view (an elongated centre), a crowd of dot-sized
            # blobs that would not group (shifted colour channels distort
            # decimated blobs) and a grouping whose dots then fail: again at
            # full resolution.
            w, h = blobs.box[ci, 2], blobs.box[ci, 3]
            steep = max(w, h) >= 1.8 * min(w, h)
            if blobs.scale == 1 or radius >= 12.0 or (
                    guess is None and not steep and not self._crowded(blobs, ci)):
                return
        extent = max(blobs.extent(ci), radius)
        u, v = int(round(blobs.u[ci])), int(round(blobs.v[ci]))
        # The centre alone first: a blob that is not an ellipse at full
        # resolution (a clutter shape, a texture's speck) is no centre dot,
        # and the card's window round it would cost more than all the rest
        # of a card (most candidates that reach here are such blobs).
        near = int(2 * extent + 6)
        centre = dot_image.blobs_in(u - near, v - near, u + near + 1, v + near + 1)
        j = _centre_blob(centre, blobs.u[ci], blobs.v[ci], radius)
        if j is None or _ellipse_fill(centre, j) < _MIN_CENTRE_FILL:
            return
        reach = int(1.9 * self._rho_out * extent + 8)
        fine = dot_image.blobs_in(u - reach, v - reach, u + reach + 1, v + reach + 1)
        if len(fine) < RING_POINTS:
            return
        j = _centre_blob(fine, blobs.u[ci], blobs.v[ci], radius)
        if j is None:
            return
        guess = group(fine, j, self.config, self.params, camera)
        if guess is not None:
            yield guess

    def _crowded(self, blobs, ci: int) -> bool:
        """Tell whether ring-dot-sized blobs crowd round blob ``ci`` as a card's would."""
        reach = 1.6 * self._rho_out * blobs.extent(ci) + 2
        ratio = blobs.area / blobs.area[ci]
        near = (np.abs(blobs.u - blobs.u[ci]) < reach) & (np.abs(blobs.v - blobs.v[ci]) < reach) \
            & (ratio > 0.12) & (ratio < 0.9)
        return int(np.count_nonzero(near)) >= 10

    def _covered(self, H: np.ndarray, blobs, camera: Optional[CameraModel]) -> np.ndarray:
        """Blobs inside the outer ring of the card of homography ``H`` (no candidates)."""
        reach = self.config.ring_radii[0] + 2 * self.config.ring_dot_radius
        if len(blobs) <= _FEW_BLOBS:
            return self._in_disc(H, blobs.u, blobs.v, reach, camera)
        # Only blobs in the image's box round that disc can be in it: a
        # cluttered frame has thousands of blobs, and undistorting them all
        # cost milliseconds. The box is the disc's edge, seen through the
        # homography and the lens at 64 points, grown by a twentieth (the
        # edge between two points bulges out by a thousandth of its size).
        edge = _plane_pixels(H, reach * _UNIT_CIRCLE, camera)
        if not np.isfinite(edge).all():
            return self._in_disc(H, blobs.u, blobs.v, reach, camera)
        lo, hi = edge.min(axis=0), edge.max(axis=0)
        pad = 0.05 * float(np.max(hi - lo)) + 2.0
        index = np.flatnonzero((blobs.u >= lo[0] - pad) & (blobs.u <= hi[0] + pad)
                               & (blobs.v >= lo[1] - pad) & (blobs.v <= hi[1] + pad))
        covered = np.zeros(len(blobs), dtype=bool)
        covered[index] = self._in_disc(H, blobs.u[index], blobs.v[index], reach, camera)
        return covered

    @staticmethod
    def _in_disc(H: np.ndarray, u: np.ndarray, v: np.ndarray, reach: float,
                 camera: Optional[CameraModel]) -> np.ndarray:
        """Whether image points (u, v) lie within ``reach`` of the centre of plane ``H``."""
        pts = np.column_stack([u, v])
        if camera is not None and len(pts):
            pts = camera.undistort_pixels(pts)
        return card_kernels.in_disc(np.ascontiguousarray(H, dtype=np.float64),
                                    np.ascontiguousarray(pts, dtype=np.float64), float(reach))

    # Centres and code --------------------------------------------------------

    def _measure_and_read(self, dot_image: DotImage, guess: CardGuess,
                          camera: Optional[CameraModel], mirrored: List[np.ndarray]
                          ) -> Optional[CardDetection]:
        """
        Measure, read and check the card of ``guess``; None if it is no card with a code.

        A card read whole whose marks show a mirror image is refused, and
        its homography appended to ``mirrored``.
        """
        card, refit = self._read_at(dot_image, guess.homography, camera, mirrored)
        if refit is not None and (card is None or card.ids is None):
            # No id read: the dots were measured where the grouping put them,
            # and a far card's dots are a few pixels across (a soft card in a
            # zoomed window): a few tenths of a pixel off biases a small dot's
            # colour (point 1's black read as green) and centre (the refit
            # drops it). Measured again, once, where the homography refitted
            # to the sub-pixel centres puts them; taken only if it then gives
            # an id (every check of a reading applies again). Marks that show
            # a mirror there refuse the card, even the codes the first read
            # left to choose among.
            seen_in_mirror = len(mirrored)
            again, _ = self._read_at(dot_image, refit, camera, mirrored)
            if len(mirrored) > seen_in_mirror:
                return None
            if again is not None and again.ids is not None:
                return again
        return card

    def _read_at(self, dot_image: DotImage, H: np.ndarray, camera: Optional[CameraModel],
                 mirrored: List[np.ndarray]
                 ) -> Tuple[Optional[CardDetection], Optional[np.ndarray]]:
        """
        Measure, read and check the card where ``H`` puts it (see :meth:`_measure_and_read`).

        Also return the refitted homography, unless none was fitted or the
        card was refused as a mirror image (then None).
        """
        cfg, params = self.config, self.params
        n_rings = cfg.n_rings
        paper = card_paper(dot_image, camera, H, self._paper_xy, self._paper_room)
        if paper is None:
            return None, None
        spots = measure_spots(dot_image, camera, H, self._dot_layout, self._dots, paper,
                              colour=not dot_image.grey_only, min_valid=_REFIT_MIN)
        H, valid = self._refit(spots, camera)
        if H is None:
            return None, None
        if dot_image.grey_only:
            ring_valid = valid[1:].reshape(n_rings, RING_POINTS)
            if not any(np.all(ring_valid[r]) for r in range(n_rings)):
                return None, None
            return self._card(dot_image, camera, H, paper, spots, valid, 0, None, 0.0, ()), None
        # Colours of the dots kept by the refit, and of those whose inner part
        # is clean though their rim is not (an object beside them).
        readable = valid | (spots.readable & ~spots.valid)
        read = functools.partial(read_code, valid=readable, n_rings=n_rings, config=cfg,
                                 params=params, white=paper.colour,
                                 max_hidden=params.max_hidden_slots if self._codes else 1,
                                 partial=spots.partial, known_codes=bool(self._codes))
        reading = read(spots.colour)
        for other in (spots.far_colour, spots.glare_colour):
            if other is not None and (reading is None or reading.code is None):
                reading = _second_reading(reading, read(other))
        if reading is None:
            return None, H
        valid[list(reading.not_dots)] = False
        handed: Dict[int, str] = {}

        def mirror_safe(point1: int) -> bool:
            """Tell whether the marks, read with point 1 in ``point1``, show no mirror."""
            if cfg.handedness_mark is None:
                return True
            if point1 not in handed:
                H_turned = H @ self._turns[point1]
                handed[point1] = self._handed(dot_image, camera, H_turned, paper, spots, valid,
                                              point1)
            return handed[point1] == 'ok'

        if reading.code is not None:
            if not mirror_safe(reading.point1_slot):
                if handed[reading.point1_slot] == 'mirror':
                    mirrored.append(H)
                    return None, None
                return None, H
            return self._card(dot_image, camera, H, paper, spots, valid, reading.point1_slot,
                              reading.code, reading.margin, reading.ring_codes), H
        # Slots hidden by an object: the one known code that fits, else the
        # few that the slots seen cannot tell apart, for the localizer to
        # choose among by where its last fix puts the robot.
        fitting, doubtful = partial_hypotheses(reading, self._codes, self._code_table,
                                               params.decisive_margin)
        from_map = reading.slot_letters.count('?')
        resolved = sole_hypothesis(reading, fitting, doubtful)
        if resolved is not None:
            fitting, doubtful = (resolved,), ()
        elif not fitting or len(fitting) + len(doubtful) > params.max_code_candidates:
            return None, H
        options, fits = [], 0
        for k, (code, point1) in enumerate(fitting + doubtful):
            if not mirror_safe(point1):
                continue
            turned = tuple(r[point1:] + r[:point1] for r in reading.ring_codes)
            card = self._card(dot_image, camera, H, paper, spots, valid, point1, code,
                              reading.margin, turned, from_map)
            if card is not None:
                options.append(card)
                fits += k < len(fitting)
        if resolved is not None:
            return (options[0] if options else None), H
        if fits == 0:
            return None, H
        # One left is still no id: the marks that dropped the others (each
        # with point 1 in another slot) may only have been hidden. But those
        # would turn the card by 45 degrees or more, which the localizer's
        # gates tell, so it goes on as the one candidate. The card itself:
        # ring order unknown, in slot order as a grey image's.
        hidden = self._card(dot_image, camera, H, paper, spots, valid, 0, None, reading.margin,
                            reading.ring_codes, from_map)
        return dataclasses.replace(hidden, candidates=tuple(options)), H

    def _card(self, dot_image: DotImage, camera: Optional[CameraModel], H: np.ndarray,
              paper: Paper, spots: SpotMeasures, valid: np.ndarray, point1: int,
              code: Optional[Code], margin: float, ring_codes: Tuple[str, ...],
              from_map: int = 0) -> Optional[CardDetection]:
        """Return the detection with ``code``, point 1 in slot ``point1``; None if undecodable."""
        cfg = self.config
        ids = None
        if code is not None:
            ids = self._ids_of(code)
            if ids is None:
                return None
        H_final = H @ self._turns[point1]
        # Slot order -> dot order (point 1 first).
        order = self._orders[point1 % RING_POINTS]
        points = np.where(valid[order, None], spots.points[order], np.nan)
        areas = np.where(valid[order], spots.area[order], np.nan)
        ring_valid = valid[1:].reshape(cfg.n_rings, RING_POINTS)
        complete = np.flatnonzero(ring_valid.all(axis=1)).tolist()
        if complete:
            first = complete[0]
            ring_px = points[1 + first * RING_POINTS:1 + (first + 1) * RING_POINTS]
        else:
            ring_px = _plane_pixels(H_final, self._outer, camera)
        # Half the largest distance between two of the outer ring's points.
        between = ring_px[:, None] - ring_px[None]
        size = 0.5 * float(np.sqrt(np.max(np.sum(between * between, axis=2))))
        fitted_centre = None
        if not valid[0]:
            fitted_centre = _plane_pixels(H_final, _PLANE_ORIGIN, camera)[0]
        return CardDetection(code, ids, points, areas, tuple(complete), size, H_final,
                             float(margin), tuple(ring_codes), from_map,
                             fitted_centre_px=fitted_centre)

    def _ids_of(self, code: Code) -> Optional[Ids]:
        """Return the ids ``code`` stands for (None if it stands for none), decoded once."""
        if code not in self._ids:
            try:
                self._ids[code] = self.config.decode(code)
            except CodeError:
                self._ids[code] = None
        return self._ids[code]

    def _refit(self, spots: SpotMeasures, camera: Optional[CameraModel]):
        """Homography refitted to the measured dots; drops those off it. (None, None) if lost."""
        valid = spots.valid.copy()
        if not _refittable(valid, bool(spots.readable[0])):
            return None, None
        anchored = bool(valid[0])
        idx = np.flatnonzero(valid)
        if anchored:
            # The centre last: fit_homography insists on it.
            idx = np.append(idx[1:], 0)
        img = spots.points[idx]
        if camera is not None:
            img = camera.undistort_pixels(img)
        H, inliers = fit_homography(self._model[idx], img, self._radii[idx],
                                    self.params.max_homography_error,
                                    min_points=6 if anchored else _RING_REFIT_MIN,
                                    anchored=anchored)
        if H is None:
            return None, None
        valid[idx[~inliers]] = False
        return H, valid

    def _handed(self, dot_image: DotImage, camera: Optional[CameraModel], H_final: np.ndarray,
                paper: Paper, spots: SpotMeasures, valid: np.ndarray, point1: int) -> str:
        """Return what the handedness marks show: ``'ok'``, ``'mirror'`` or ``'unsure'``."""
        cfg = self.config
        rows = 1 + point1 + RING_POINTS * np.arange(cfg.n_rings)
        black = spots.peak[rows][valid[rows]]
        if len(black) == 0:
            # Point 1 hidden: the ring's inks are as dark in their darkest
            # channel as black is.
            ring = valid[1:]
            black = spots.peak[1:][ring]
            if len(black) < 5:
                return 'unsure'
        black_peak = float(median(black))
        # A mark counts when at least half as dark as point 1 (handedness):
        # that, not the dots' fixed bar, is the bar for its window too. A far
        # card's marks, smaller than its dots, are paler than the bar when
        # its point 1 is less than twice as dark; the same bar at the
        # mirror images' places keeps the test symmetric.
        marks = measure_spots(dot_image, camera, H_final, self._mark_layout, self._marks, paper,
                              colour=False, core_margin=1.0, refine=False,
                              min_darkness=min(self.params.min_window_darkness,
                                               0.5 * black_peak))
        return handedness(marks, black_peak)


class _Scan(NamedTuple):
    """What :meth:`Detector._detect` found at an image's own scale."""

    cards: List[CardDetection]
    dot_image: DotImage
    claimed: np.ndarray             # blobs inside a card found
    mirrored: List[np.ndarray]      # homographies of cards read whole but seen in a mirror
    far: np.ndarray                 # the far candidates looked at (cards.far_candidates)


def _plane_pixels(H: np.ndarray, xy: np.ndarray, camera: Optional[CameraModel]) -> np.ndarray:
    """Return the image pixels of plane points ``xy`` (N, 2) through ``H`` and the lens."""
    px = apply_h(H, xy)
    if camera is not None and camera.has_distortion:
        px = camera.distort_pixels(px)
    return px


def _in_image(card: CardDetection, to_image: np.ndarray) -> CardDetection:
    """Return a card found in a zoomed window (:mod:`.zoom`) in the image's pixels."""
    scale = float(to_image[0, 0])

    def moved(points: np.ndarray) -> np.ndarray:
        return points * scale + to_image[:2, 2]

    return dataclasses.replace(
        card, min_pixel_sigma=max(card.min_pixel_sigma, ZOOMED_PIXEL_SIGMA),
        points_px=moved(card.points_px), dot_areas_px=card.dot_areas_px * scale ** 2,
        size_px=card.size_px * scale, homography=to_image @ card.homography,
        fitted_centre_px=None if card.fitted_centre_px is None
        else moved(card.fitted_centre_px),
        candidates=tuple(_in_image(c, to_image) for c in card.candidates))


def _second_reading(peaks: Optional[Reading], second: Optional[Reading]) -> Optional[Reading]:
    """
    Read a card by its dots' peaks, else by a second measure of their colours.

    The second measures: a far card's darkness summed round each dot (JPEG
    and video spread a dot of a pixel or two's colour round it, which
    greys its peak: ``SpotMeasures.far_colour``), and a glossy card's
    peaks with a highlight's light added back (``glare_colour``). They are
    read when the peaks give no whole code. The sums in turn take in a
    neighbour's spread colour and JPEG's ringing, which the peaks do not
    (a black dot read as green), and a lift stands on the paper round a
    dot, not on the dot: so neither overrules a slot the peaks read. The
    second reading completes a partial one only where it agrees with every
    slot and the centre the peaks read.
    """
    if second is None or peaks is None:
        return peaks or second
    if second.code is None or peaks.centre_letter != second.centre_letter or any(
            a not in ('?', b) for a, b in zip(peaks.slot_letters, second.slot_letters)):
        return peaks
    return second


def _centre_blob(fine, u: float, v: float, radius: float) -> Optional[int]:
    """Return the biggest of ``fine``'s blobs within ``radius`` (>= 2 px) of (u, v), or None."""
    if len(fine) == 0:
        return None
    d = np.hypot(fine.u - u, fine.v - v)
    j = int(np.argmax(fine.area - 1e9 * (d > max(2.0, radius))))
    return j if d[j] <= max(2.0, radius) else None


def _ellipse_fill(blobs, j: int) -> float:
    """Blob ``j``'s area over the area of the ellipse of its second moments (1 for an ellipse)."""
    # Semi-axes twice the moments' standard deviations: pi * 4 * sqrt(det).
    xx, xy, yy = card_kernels.blob_covariance(blobs.labels, blobs.box[j], int(blobs.label[j]),
                                              int(blobs.scale))
    det = xx * yy - xy * xy
    return float(blobs.area[j] / (4.0 * np.pi * np.sqrt(det))) if det > 0.0 else 0.0


def _dot_order(config: PatternConfig, point1: int) -> np.ndarray:
    """Return, per dot index, the slot-ordered row holding it when slot ``point1`` is point 1."""
    order = np.zeros(config.n_dots, dtype=int)
    for r in range(config.n_rings):
        for k in range(RING_POINTS):
            order[config.dot_index(r, (k - point1) % RING_POINTS + 1)] = 1 + r * RING_POINTS + k
    order.flags.writeable = False
    return order


def _refittable(valid: np.ndarray, centre_readable: bool = False) -> bool:
    """
    Tell whether measured dots (``valid``, centre first) are enough to refit the homography.

    With the centre, :data:`_REFIT_MIN` dots; without it, a centre dot that
    is there (``centre_readable``) and :data:`_RING_REFIT_MIN` ring dots.
    """
    if valid[0]:
        return np.count_nonzero(valid) >= _REFIT_MIN
    return centre_readable and np.count_nonzero(valid[1:]) >= _RING_REFIT_MIN


def _paper_points(config: PatternConfig) -> np.ndarray:
    """
    Pattern-plane points on white paper, whichever slot holds point 1.

    Between the inner ring's dots, between the centre and the inner ring,
    and towards the corners; away from where handedness marks may be.
    """
    pts = []
    mids = np.deg2rad(22.5 + 45.0 * np.arange(RING_POINTS))
    inner = config.ring_radii[-1]
    gap = 0.5 * (config.centre_dot_radius + inner - config.ring_dot_radius)
    for radius in (inner, gap):
        pts.extend(radius * np.column_stack([np.sin(mids), np.cos(mids)]))
    if config.handedness_mark is None:
        for radius in config.ring_radii[:-1]:
            pts.extend(radius * np.column_stack([np.sin(mids), np.cos(mids)]))
    outer = config.ring_radii[0] + config.ring_dot_radius
    corner = 0.5 * (outer + config.card_size / 2 * np.sqrt(2))
    if corner > outer + 0.5 * config.ring_dot_radius:
        diag = np.deg2rad(45.0 + 90.0 * np.arange(4))
        pts.extend(corner * np.column_stack([np.sin(diag), np.cos(diag)]))
    pts = np.array(pts)
    mark = config.handedness_mark
    if mark is not None:
        # Point 1 may be in any slot: keep clear of every place a mark can be.
        far = np.min(np.linalg.norm(pts[:, None] - _mark_places(config)[None], axis=2), axis=1)
        pts = pts[far > config.mark_radius + config.ring_dot_radius]
    return pts


def _paper_clearance(config: PatternConfig, paper_xy: np.ndarray) -> np.ndarray:
    """Distance (metres) from each paper point to the nearest ink (dot, mark place) or edge."""
    ink = config.model_points()[:, :2]
    radii = config.dot_radii()
    if config.handedness_mark is not None:
        places = _mark_places(config)
        ink = np.vstack([ink, places])
        radii = np.concatenate([radii, np.full(len(places), config.mark_radius)])
    to_ink = np.linalg.norm(paper_xy[:, None] - ink[None], axis=2) - radii[None]
    to_edge = config.card_size / 2 - np.max(np.abs(paper_xy), axis=1)
    return np.minimum(to_ink.min(axis=1), to_edge)


def _mark_places(config: PatternConfig) -> np.ndarray:
    """Every plane point where a handedness mark or its mirror image can be, any point 1."""
    mark = config.handedness_mark
    angles = np.concatenate([np.asarray(mark.angles_deg, dtype=float),
                             -np.asarray(mark.angles_deg, dtype=float)])
    angles = np.deg2rad(np.add.outer(angles, 45.0 * np.arange(RING_POINTS)).ravel())
    places = config.mark_distance * np.column_stack([np.sin(angles), np.cos(angles)])
    # Each place once (the mirror images of some marks fall on other marks' places).
    keep = [i for i in range(len(places))
            if not np.any(np.linalg.norm(places[:i] - places[i], axis=1) < 1e-9)]
    return places[keep]
