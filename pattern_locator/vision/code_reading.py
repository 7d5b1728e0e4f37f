"""
Order and code: which slot is point 1, which ink every dot is, and whether it is a mirror.

Each dot's colour is its per-channel darkness in linear light against the
card's own white (1 - colour / white), which cancels the light's colour.
Blur mixes a dot with paper, which scales the darkness but keeps its
direction, so dots are compared by direction. The four inks' directions
are known from the configuration; the camera's own colour response (channel
gains, and the overlap of its colour filters that makes colours greyer) is
fitted to the ring's dots, and every ink seen on the ring is then
represented by its own dots. Every dot takes the nearest ink; both rings
must agree (a slot they read differently is unknown, filled only from a
map of the codes that exist, as a hidden slot is), and each slot (its dots
of both rings together) and the centre must be clearly nearer to their ink
than to the next: a margin measured as a fraction of the way from the
midpoint between the two inks to the nearest one. Point 1 is the one
black slot; black must also be as dark as ink (a grey object is not). A
card whose colours are unclear is rejected, never guessed.

A mirror shows the ring in the other order, which reads as another valid
code; the handedness marks (:class:`~pattern_locator.card.pattern.HandednessMark`)
are where the card's marks must be dark and their mirror images paper.
"""

from dataclasses import dataclass
import functools
from typing import Dict, Iterable, Optional, Sequence, Tuple

import numpy as np

from . import card_kernels
from .centres import SpotMeasures
from .detector_params import DetectorParams
from .per_config import made_once
from ..card.pattern import Code, PatternConfig, RING_POINTS, srgb_to_linear
from ..errors import CodeError

LETTERS = 'KRGB'
# Crosstalk values tried when fitting the camera's colour response. Up to
# 0.6 (2/3 is grey): besides a sensor's overlapping filters, JPEG's colour
# at half resolution greys a far card's dots of a few pixels as much. In
# steps of 0.05: greyer inks are closer together, and a coarser grid left
# the response that explains such dots between two of its values.
_CROSSTALK = np.linspace(0.0, 0.6, 13)


@dataclass(frozen=True)
class Reading:
    """The colours read from one card."""

    point1_slot: int                # -1 while unknown (a partial reading)
    code: Optional[Code]            # None: some slots hidden, see ``slot_letters``
    margin: float                   # the smallest colour margin, 0..1
    ring_codes: Tuple[str, ...]     # per ring, the colours read ('?' = not seen)
    not_dots: Tuple[int, ...] = ()  # rows that were grey objects, not ink
    # Per slot the letter read (K R G B), '?' where hidden; then the centre's.
    slot_letters: str = ''
    centre_letter: str = ''
    slot_margins: Tuple[float, ...] = ()    # per slot (NaN where hidden), then the centre's


def ink_darkness(config: PatternConfig) -> np.ndarray:
    """(4, 3) linear darkness (BGR) of the inks K, R, G, B against the paper."""
    return np.array([1.0 - srgb_to_linear(np.array(config.ink_rgb(c))[::-1])
                     for c in LETTERS])


def read_code(colour: np.ndarray, valid: np.ndarray, n_rings: int, config: PatternConfig,
              params: DetectorParams, white: Optional[np.ndarray] = None,
              max_hidden: int = 0, partial: Optional[np.ndarray] = None,
              known_codes: bool = False) -> Optional[Reading]:
    """
    Read the code from dot colours in slot order (row 0 the centre, then ring r slot k).

    ``colour`` holds each dot's per-channel darkness (:class:`SpotMeasures`
    ``colour``); ``valid`` which dots were measured; ``white`` the card's
    paper as the camera gave it (BGR), whose colour is the light's. None
    when unsure.

    Up to ``max_hidden`` slots may be unseen in both rings (an object over
    the card). With ``known_codes`` (a list of the codes that exist will
    complete a partial reading), a slot the two rings read differently
    counts as one of them; else it rejects the card (a far dot whose
    colour JPEG's chroma greyed to black is no disagreement where
    ``card_kernels._drop_greyed`` can tell). One hidden slot and
    seven coloured ones: the hidden one is point 1 (the one black; not a
    slot the rings read as two colours), and the code is whole. Otherwise the reading
    is partial (``code`` None, ``slot_letters`` with '?' where hidden, and
    ``point1_slot`` -1 when the black is hidden too): only a list of the
    codes that exist can complete it (:func:`resolve_partial`).

    ``partial`` marks dots whose colour was read from the part an object
    left uncovered: a slot read from such dots alone must be read with
    ``params.decisive_margin``, not the usual margin.
    """
    n_dots = 1 + n_rings * RING_POINTS
    colour = np.ascontiguousarray(colour, dtype=np.float64)
    valid = np.ascontiguousarray(valid, dtype=np.bool_)
    if colour.shape != (n_dots, 3) or valid.shape != (n_dots,):
        raise ValueError(f'read_code: colour must be ({n_dots}, 3) and valid ({n_dots},), '
                         f'got {colour.shape} and {valid.shape}')
    partial = np.zeros(n_dots, dtype=np.bool_) if partial is None else \
        np.ascontiguousarray(partial, dtype=np.bool_)
    light = np.ones(3)
    if white is not None and np.size(white) == 3:
        light = srgb_to_linear(np.clip(np.asarray(white, dtype=float), 1.0, 255.0))
        light = light / light.mean()
    # Kernel: card_kernels.read_colours; the method is in the module's and
    # _fit_response's documentation.
    ok, centre, agreed, slot_letter, margins, grey, black = card_kernels.read_colours(
        colour, valid, partial, n_rings, _inks(config), np.ascontiguousarray(light, np.float64),
        _CROSSTALK, float(params.min_darkness), int(max_hidden), bool(known_codes),
        float(params.min_colour_margin), float(params.decisive_margin))
    if not ok:
        return None
    shown = agreed >= 0
    black = [black] if black >= 0 else []
    hidden = np.flatnonzero(~shown)
    if len(black) == 0 and len(hidden) == 1:
        # Seven coloured slots: the hidden one is the black, point 1.
        black, agreed = [int(hidden[0])], np.where(shown, agreed, 0)
    letters = ''.join(LETTERS[a] if a >= 0 else '?' for a in agreed)
    margin = float(np.min(margins[np.append(shown, True)]))
    per_slot = tuple(float(m) for m in margins)
    rows = 1 + np.arange(n_rings * RING_POINTS).reshape(n_rings, RING_POINTS)
    not_dots = tuple(int(r) for r in rows[grey])
    if len(black) == 0 or np.any(agreed < 0):
        # Partial: the rings' letters in slot order (turned once point 1 is known).
        return Reading(black[0] if len(black) else -1, None, margin, ring_codes(slot_letter, 0),
                       not_dots, letters, LETTERS[centre], per_slot)
    point1 = black[0]
    slots = [(point1 + i) % RING_POINTS for i in range(RING_POINTS)]
    text = LETTERS[centre] + '-' + 'K' + ''.join(LETTERS[agreed[k]] for k in slots[1:])
    code = _parsed(text)
    if code is None:
        return None
    return Reading(point1, code, margin, ring_codes(slot_letter, point1), not_dots, letters,
                   LETTERS[centre], per_slot)


@functools.lru_cache(maxsize=None)
def _parsed(text: str) -> Optional[Code]:
    """Return the code written ``text`` (None if it is no valid code), parsed once per text."""
    # At most one entry per string of the letters K R G B in the code's
    # shape (4 x 4^7): bounded, whatever the uptime.
    try:
        return Code.parse(text)
    except CodeError:
        return None


def ring_codes(slot_letter: np.ndarray, point1: int) -> Tuple[str, ...]:
    """Per ring, the letters read (``slot_letter``: (rings, 8), -1 unseen) from point 1 on."""
    slots = [(point1 + i) % RING_POINTS for i in range(RING_POINTS)]
    return tuple(''.join(LETTERS[row[k]] if row[k] >= 0 else '?' for k in slots)
                 for row in np.asarray(slot_letter))


def code_table(codes: Iterable[Code]) -> np.ndarray:
    """
    Return known codes as letter indices (N, 8, 9): slots then centre, per point-1 slot.

    Row ``[n, p]`` is what the card of code ``n`` shows with point 1 in slot
    ``p``: slot ``k`` holds point ``(k - p) % 8 + 1``.
    """
    codes = sorted(set(codes), key=str)
    index = {c: i for i, c in enumerate(LETTERS)}
    letters = np.array([[index[c] for c in code.centre + code.ring] for code in codes],
                       dtype=np.int8).reshape(len(codes), RING_POINTS + 1)
    k = np.arange(RING_POINTS)
    table = np.empty((len(codes), RING_POINTS, RING_POINTS + 1), dtype=np.int8)
    for p in range(RING_POINTS):
        table[:, p, :RING_POINTS] = letters[:, 1 + (k - p) % RING_POINTS]
    table[:, :, RING_POINTS] = letters[:, :1]
    return table


def partial_hypotheses(reading: Reading, codes: Sequence[Code], table: np.ndarray,
                       decisive_margin: float = np.inf
                       ) -> Tuple[Tuple[Tuple[Code, int], ...], Tuple[Tuple[Code, int], ...]]:
    """
    Return the known codes a partial reading cannot rule out: (fitting, doubtful).

    A hypothesis is a known code with point 1 in one slot (``table``:
    :func:`code_table` of ``codes``, ``codes`` in its row order,
    ``sorted(set(codes), key=str)``), as (code, point-1 slot). ``fitting``
    agree with every seen slot and the centre (each read with the usual
    margin by :func:`read_code`); ``doubtful`` disagree in one seen slot
    only, read with less than ``decisive_margin`` (default: any margin), so
    that one misread slot would make them fit.
    """
    if not reading.slot_letters or len(table) == 0:
        return (), ()
    seen = np.array([LETTERS.index(c) if c != '?' else -1
                     for c in reading.slot_letters + reading.centre_letter])
    shown = seen >= 0
    wrong = (table != seen[None, None, :]) & shown[None, None, :]          # (N, 8, 9)
    differ = np.count_nonzero(wrong, axis=2)                                # (N, 8)
    fitting = tuple((codes[int(n)], int(p)) for n, p in np.argwhere(differ == 0))
    near = np.argwhere(differ == 1)
    doubtful: Tuple[Tuple[Code, int], ...] = ()
    if len(near):
        margins = np.nan_to_num(np.asarray(reading.slot_margins, dtype=float), nan=0.0)
        slot = np.argmax(wrong[near[:, 0], near[:, 1]], axis=1)
        weak = margins[slot] < decisive_margin
        doubtful = tuple((codes[int(n)], int(p)) for n, p in near[weak])
    return fitting, doubtful


def resolve_partial(reading: Reading, codes: Sequence[Code], table: np.ndarray,
                    decisive_margin: float = np.inf) -> Optional[Tuple[Code, int]]:
    """
    Complete a partial reading from the codes that exist; (code, point-1 slot) or None.

    One hypothesis (:func:`partial_hypotheses`) is taken only when:

    * it is the only one that agrees with every seen slot and the centre;
    * every other hypothesis (every other known code in every turn, and
      this code in any other turn) disagrees with the reading in at least
      two seen slots, or in one slot read with at least
      ``decisive_margin`` (default: two slots always): a single slot
      misread at the usual margin could then not have made the answer.
    """
    return sole_hypothesis(reading, *partial_hypotheses(reading, codes, table, decisive_margin))


def sole_hypothesis(reading: Reading, fitting: Sequence[Tuple[Code, int]],
                    doubtful: Sequence[Tuple[Code, int]]) -> Optional[Tuple[Code, int]]:
    """Return the one fitting hypothesis when there is no other and none in doubt, else None."""
    if len(fitting) != 1 or doubtful:
        return None
    code, p = fitting[0]
    if reading.point1_slot >= 0 and p != reading.point1_slot:
        return None
    return code, p


# Per pattern configuration (per_config.made_once), its inks' darkness.
_INKS: Dict[int, Tuple[PatternConfig, np.ndarray]] = {}


def _inks(config: PatternConfig) -> np.ndarray:
    """Return :func:`ink_darkness` of ``config``, made once."""
    return made_once(_INKS, config, lambda c: np.ascontiguousarray(ink_darkness(c),
                                                                   dtype=np.float64))


# The camera's colour response (card_kernels.fit_response), fitted to the
# ring's dots (darkness (N, 3), linear). Blur mixes a dot with paper:
# darkness ``a * d`` for the ink's ``d``. The sensor's colour filters
# overlap: each channel sees ``1 - t`` of its own light and ``t / 2`` of
# each other's, ``d -> M(t) d``, each weighted by the light's colour (the
# paper's linear BGR) since the overlap comes before white balance; the
# paper's colour as seen has been through the overlap too, and is undone.
# And the card's white, measured on the paper, may be off in a channel by a
# factor (clipped by a strong light in that channel, or lit unevenly): then
# the measured darkness is ``1 - w (1 - a M(t) d)``, which takes much of a
# light channel's darkness away (a blue dot's blue under blue light). For
# each ``t`` on a grid (_CROSSTALK), the dots are given their nearest ink,
# and ``a`` per dot and ``w`` per channel are fitted by alternating least
# squares; the white's error needs three inks on the ring to be told from
# the inks' own colours (a ring of one colour and black cannot). The ``t``
# that explains the dots best wins; its ``w`` is undone on every dot.
#
# Each dot then takes the nearest ink by angle, with a margin: how far past
# the bisector between the nearest ink and the next it lies, as a fraction
# of the way to the nearest ink (1 on the ink, 0 on the bisector).


# A far card's marks (a pixel or two at 7 m) fail the dot tests, yet each
# is still dark where it belongs: at least _FAINT_MARK of point 1's
# darkness, where every mirror image's place is paper (at most
# _BLANK_PLACE of it). A mirror shows its marks at those places instead.
# The ring's blur cannot make the difference: the ring is the same on
# either side of point 1, so it darkens a mark's place and its mirror
# image's alike. (On 400 far frames, 2 more cards read; on the same 400
# frames seen in a mirror, no id.)
_FAINT_MARK = 0.3
_BLANK_PLACE = 0.1


def handedness(marks: SpotMeasures, black_peak: float) -> str:
    """
    ``'ok'``, ``'mirror'`` or ``'unsure'`` from the marks and their mirror images.

    ``marks`` holds the m marks then their m mirror images. A position shows
    a mark when it holds a dark, isolated, dot-sized spot at least half as
    dark as point 1, centred where the mark belongs. A mark where one
    belongs and none at any mirror image says the card is seen directly;
    the reverse says a mirror. An object over some of these places only
    hides them; one beside a place (its edge a pixel or two from it) is
    dark there too, but its darkness is not centred on the place. Where no
    place shows a mark: every mark faint where it belongs and every mirror
    image's place paper, all in the image, also says the card is seen
    directly (a far card's marks; see ``_FAINT_MARK``).
    """
    m = len(marks.valid) // 2
    present = marks.valid & marks.centred & (marks.peak >= 0.5 * black_peak)
    if np.any(present[m:]):
        return 'unsure' if np.any(present[:m]) else 'mirror'
    if np.any(present[:m]):
        return 'ok'
    faint = np.all(marks.centred[:m] & (marks.peak[:m] >= _FAINT_MARK * black_peak))
    blank = np.all(marks.peak[m:] <= _BLANK_PLACE * black_peak)
    seen = m > 0 and black_peak > 0.0 and bool(np.all(marks.inside))
    return 'ok' if seen and faint and blank else 'unsure'
