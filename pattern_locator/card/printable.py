"""
Printable cards at true millimetre scale: SVG, PDF and PNG.

The layout is computed once as simple primitives in millimetres (page
coordinates: origin at the sheet's top-left corner, x right, y down) and each
format only draws those primitives, so the three outputs agree exactly.

Poster coordinates (used while laying out, and recoverable from any sheet as
``page - CardSheet.origin_mm``): origin at the centre dot, x right, y *down*,
millimetres. The pattern frame's y (up, towards point 1) is the poster's -y,
so point 1 is printed at the top.

One sheet holds the whole card when the dots, the "UP" mark and the label
fit inside the sheet's printable area (5 mm from every edge); the card square
itself (``card_size``) may be larger than the sheet, and its edge lines are
then only drawn where they fall on the sheet. Otherwise the card is tiled
over several sheets (portrait or landscape, whichever needs fewer) that
overlap by :data:`OVERLAP_MM`. A dashed cut line runs along the middle of
every overlap and registration crosshairs centred on it are printed on both
tiles: trim one tile along its dashed line, lay it on its neighbour so the
crosshair arms continue across the cut, and tape.

File names: a PDF holds every sheet as one page each. SVG and PNG write one
file per sheet; a tiled card ``card.svg`` becomes ``card-tile1.svg``,
``card-tile2.svg``, ... (see :func:`tile_paths`).
"""

from dataclasses import dataclass, replace
import math
from pathlib import Path
import re
import struct
from typing import Dict, List, Optional, Sequence, Tuple, Union
from xml.sax.saxutils import escape
import zlib

import cv2
import numpy as np

from .pattern import Ids, PatternConfig
from ..errors import ConfigError, PrintError

PAPER_SIZES_MM = {
    'a3': (297.0, 420.0),
    'tabloid': (279.4, 431.8),
    'a4': (210.0, 297.0),
    'letter': (215.9, 279.4),
}
MARGIN_MM = 5.0          # most printers cannot print this close to the edge
OVERLAP_MM = 20.0        # tiles overlap this much; the cut line is in its middle
MAX_TILES = 30           # beyond this a bigger paper is the sane answer
MAX_PIXELS = 120e6       # a PNG larger than this is a mistake (A3 at 600 dpi is 70 Mpx)
MM_PER_INCH = 25.4
PT_PER_MM = 72.0 / MM_PER_INCH

RGB = Tuple[int, int, int]
Box = Tuple[float, float, float, float]   # x0, y0, x1, y1 in mm

BLACK: RGB = (0, 0, 0)
WHITE: RGB = (255, 255, 255)
EDGE_GREY: RGB = (150, 150, 150)
CUT_GREY: RGB = (110, 110, 110)

UP_GAP_MM = 5.0          # white between the dots and the UP mark
UP_HEIGHT_MM = 8.0
LABEL_GAP_MM = 4.0       # white between the dots and the label block
EDGE_GAP_MM = 2.0        # white between an annotation and the card edge
LABEL_SIZE_MM = 3.5
SCALE_LENGTH_MM = 100.0
SMALL_TEXT_MM = 3.0
MARK_ARM_MM = 5.0        # registration crosshair: arms of +-5 mm, circle of 3 mm
MARK_RADIUS_MM = 3.0
FONT_FAMILY = 'Helvetica, Arial, sans-serif'


# Primitives -----------------------------------------------------------------


@dataclass(frozen=True)
class Circle:
    """A circle; filled when ``fill`` is set, outlined when ``stroke`` is set."""

    cx: float
    cy: float
    r: float
    fill: Optional[RGB] = None
    stroke: Optional[RGB] = None
    stroke_width: float = 0.0
    name: str = ''
    role: str = ''


@dataclass(frozen=True)
class Rect:
    """A filled axis-aligned rectangle, top-left corner ``(x, y)``."""

    x: float
    y: float
    w: float
    h: float
    fill: RGB = BLACK
    name: str = ''
    role: str = ''


@dataclass(frozen=True)
class Line:
    """A straight stroke with butt ends; ``dash`` = (on, off) lengths or empty."""

    x1: float
    y1: float
    x2: float
    y2: float
    width: float
    colour: RGB = BLACK
    dash: Tuple[float, ...] = ()
    name: str = ''
    role: str = ''

    @property
    def length(self) -> float:
        return math.hypot(self.x2 - self.x1, self.y2 - self.y1)


@dataclass(frozen=True)
class Text:
    """One line of Helvetica text; ``(x, y)`` is on the baseline at ``anchor``."""

    x: float
    y: float
    text: str
    size: float
    colour: RGB = BLACK
    anchor: str = 'start'   # 'start', 'middle' or 'end'
    name: str = ''
    role: str = ''

    def box(self) -> Box:
        width = text_width_mm(self.text, self.size)
        x0 = self.x - {'start': 0.0, 'middle': width / 2, 'end': width}[self.anchor]
        return (x0, self.y - 0.75 * self.size, x0 + width, self.y + 0.25 * self.size)


Item = Union[Circle, Rect, Line, Text]


@dataclass(frozen=True)
class CardSheet:
    """
    One printed page: its size and what is drawn on it, in page millimetres.

    ``origin_mm`` is where the centre dot (the poster origin) lies on this
    page, so ``page - origin_mm`` gives poster coordinates on every tile.
    ``window_mm`` (x, y, width, height) is the area this page prints; tiles
    clip their content to it (``clip``).
    """

    paper: str
    width_mm: float
    height_mm: float
    origin_mm: Tuple[float, float]
    window_mm: Tuple[float, float, float, float]
    items: Tuple[Item, ...]
    code: str
    ids: Ids
    tile: int = 1
    tiles: int = 1
    row: int = 1
    column: int = 1
    clip: bool = False

    @property
    def tiled(self) -> bool:
        return self.tiles > 1

    def with_role(self, role: str) -> List[Item]:
        """Return the items of one role ('dot', 'label', 'scale-bar', 'registration', ...)."""
        return [item for item in self.items if item.role == role]


# Helvetica advance widths (1/1000 em), ASCII 32..126, from the standard AFM.
_HELVETICA_WIDTHS = (
    278, 278, 355, 556, 556, 889, 667, 191, 333, 333, 389, 584, 278, 333, 278, 278,
    556, 556, 556, 556, 556, 556, 556, 556, 556, 556, 278, 278, 584, 584, 584, 556,
    1015, 667, 667, 722, 722, 667, 611, 778, 722, 278, 500, 667, 556, 833, 722, 778,
    667, 778, 722, 667, 611, 722, 667, 944, 667, 667, 611, 278, 278, 278, 469, 556,
    333, 556, 556, 500, 556, 556, 278, 556, 556, 222, 222, 500, 222, 833, 556, 556,
    556, 556, 333, 500, 278, 556, 500, 722, 500, 500, 500, 334, 260, 334, 584)


def _ascii(text: str) -> str:
    # The PDF uses the standard Helvetica font with a Latin encoding and the
    # PNG uses Hershey fonts: keep to printable ASCII everywhere.
    return ''.join(c if 32 <= ord(c) < 127 else '?' for c in str(text))


def text_width_mm(text: str, size: float) -> float:
    """Return the width of ``text`` set in Helvetica at ``size`` mm."""
    return sum(_HELVETICA_WIDTHS[ord(c) - 32] for c in _ascii(text)) * size / 1000.0


# Geometry helpers -------------------------------------------------------------


def _union(*boxes: Box) -> Box:
    return (min(b[0] for b in boxes), min(b[1] for b in boxes),
            max(b[2] for b in boxes), max(b[3] for b in boxes))


def _grow(box: Box, d: float) -> Box:
    return (box[0] - d, box[1] - d, box[2] + d, box[3] + d)


def _boxes_meet(a: Box, b: Box) -> bool:
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]


def _box_meets_circle(box: Box, circle: Circle, clearance: float) -> bool:
    dx = max(box[0] - circle.cx, 0.0, circle.cx - box[2])
    dy = max(box[1] - circle.cy, 0.0, circle.cy - box[3])
    return math.hypot(dx, dy) < circle.r + clearance


def _inside(inner: Box, outer: Box, eps: float = 1e-6) -> bool:
    return (inner[0] >= outer[0] - eps and inner[1] >= outer[1] - eps
            and inner[2] <= outer[2] + eps and inner[3] <= outer[3] + eps)


def _item_box(item: Item) -> Box:
    if isinstance(item, Circle):
        r = item.r + item.stroke_width / 2
        return (item.cx - r, item.cy - r, item.cx + r, item.cy + r)
    if isinstance(item, Rect):
        return (item.x, item.y, item.x + item.w, item.y + item.h)
    if isinstance(item, Line):
        h = item.width / 2
        return (min(item.x1, item.x2) - h, min(item.y1, item.y2) - h,
                max(item.x1, item.x2) + h, max(item.y1, item.y2) + h)
    return item.box()


def _shift(item: Item, dx: float, dy: float) -> Item:
    if isinstance(item, Circle):
        return replace(item, cx=item.cx + dx, cy=item.cy + dy)
    if isinstance(item, Rect):
        return replace(item, x=item.x + dx, y=item.y + dy)
    if isinstance(item, Line):
        return replace(item, x1=item.x1 + dx, y1=item.y1 + dy, x2=item.x2 + dx, y2=item.y2 + dy)
    return replace(item, x=item.x + dx, y=item.y + dy)


def _free_spans(lo: float, hi: float, blocked: List[Tuple[float, float]],
                shortest: float = 0.5) -> List[Tuple[float, float]]:
    """Return the parts of ``[lo, hi]`` outside every blocked interval."""
    spans, cur = [], lo
    for a, b in sorted(blocked):
        if b <= cur:
            continue
        if a >= hi:
            break
        if a > cur:
            spans.append((cur, a))
        cur = max(cur, b)
    if cur < hi:
        spans.append((cur, hi))
    return [(a, b) for a, b in spans if b - a >= shortest]


def _axis_line(vertical: bool, at: float, lo: float, hi: float, circles: Sequence[Circle],
               boxes: Sequence[Box], clearance: float, **style) -> List[Line]:
    """
    Draw an axis-aligned line at ``at`` from ``lo`` to ``hi``, broken around obstacles.

    Keeps guide lines (card edges, cut lines) off the dots and the text.
    """
    blocked = []
    for c in circles:
        d = abs(at - (c.cx if vertical else c.cy))
        r = c.r + clearance
        if d < r:
            half = math.sqrt(r * r - d * d)
            mid = c.cy if vertical else c.cx
            blocked.append((mid - half, mid + half))
    for b in boxes:
        b = _grow(b, clearance)
        if vertical and b[0] < at < b[2]:
            blocked.append((b[1], b[3]))
        elif not vertical and b[1] < at < b[3]:
            blocked.append((b[0], b[2]))
    if vertical:
        return [Line(at, a, at, b, **style) for a, b in _free_spans(lo, hi, blocked)]
    return [Line(a, at, b, at, **style) for a, b in _free_spans(lo, hi, blocked)]


# Poster: the card's content in poster coordinates ------------------------------


@dataclass(frozen=True)
class _Poster:
    dots: Tuple[Circle, ...]
    notes: Tuple[Item, ...]            # UP mark and label block
    note_boxes: Tuple[Box, ...]
    label_box: Box
    essential: Box                     # must be printed: dots, UP mark, label
    card: Box                          # the card square
    code: str
    ids: Ids


def _up_mark(tip: float) -> Tuple[List[Item], Box]:
    """Draw an upward arrow with "UP" beside it; the arrow's tip at ``(0, tip)``."""
    style = {'width': 0.5, 'colour': BLACK, 'role': 'up-mark'}
    items: List[Item] = [
        Line(0.0, tip + UP_HEIGHT_MM, 0.0, tip, name='up-arrow', **style),
        Line(0.0, tip, -2.2, tip + 3.0, **style),
        Line(0.0, tip, 2.2, tip + 3.0, **style),
        Text(3.0, tip + 6.5, 'UP', LABEL_SIZE_MM, name='up-text', role='up-mark'),
    ]
    box = _union(*(_item_box(item) for item in items))
    return items, box


def _label_block(top: float, label: str) -> Tuple[List[Item], Box]:
    """Draw the ids/code line, and below it a 100 mm scale bar with 10 mm ticks."""
    half = SCALE_LENGTH_MM / 2
    baseline = top + 0.75 * LABEL_SIZE_MM
    bar_y = baseline + 0.25 * LABEL_SIZE_MM + 2.5
    items: List[Item] = [
        Text(0.0, baseline, label, LABEL_SIZE_MM, anchor='middle', name='label', role='label'),
        Line(-half, bar_y, half, bar_y, 0.3, name='scale-bar', role='scale-bar'),
    ]
    for k in range(11):
        x = -half + 10.0 * k
        length = 3.0 if k in (0, 5, 10) else 1.8
        # Ticks hang from the bar's centre line so the end ticks mark its ends.
        items.append(Line(x, bar_y, x, bar_y + length, 0.25, name=f'scale-tick-{k}',
                          role='scale-tick'))
    items.append(Text(half + 2.5, bar_y + 2.6, f'{SCALE_LENGTH_MM:.0f} mm', SMALL_TEXT_MM,
                      name='scale-text', role='scale-text'))
    box = _union(*(_item_box(item) for item in items))
    return items, box


def _posters(config: PatternConfig, ids: Ids) -> List[_Poster]:
    """
    Lay the card out two ways: notes inside/outside the card square, or hugging the dots.

    The first keeps the label on the card when there is room between the
    dots and the card's edge; the second is for cards larger than the sheet.
    """
    code = config.encode(ids.floor, ids.room, ids.pattern)
    points = config.model_points() * 1000.0
    radii = config.dot_radii() * 1000.0
    letters = config.dot_colours(code)
    dots = []
    for index, (point, radius, letter) in enumerate(zip(points, radii, letters)):
        ring, number = config.dot_ring_point(index)
        name = 'dot-centre' if ring is None else f'dot-r{ring}-p{number}'
        dots.append(Circle(float(point[0]), float(-point[1]), float(radius),
                           fill=config.colour_rgb(letter), name=name, role='dot'))
    # Handedness marks: black like point 1, where a mirror image shows paper.
    for k, (x, y) in enumerate(config.mark_points() * 1000.0):
        dots.append(Circle(float(x), float(-y), config.mark_radius * 1000.0,
                           fill=config.colour_rgb('K'), name=f'mark-{k + 1}', role='mark'))
    dot_box = _union(*(_item_box(d) for d in dots))
    half = config.card_size * 500.0
    card = (-half, -half, half, half)
    label = f'floor {ids.floor}  room {ids.room}  card {ids.pattern}   code {code}'

    posters = []
    for hug in (False, True):
        tip = dot_box[1] - UP_GAP_MM - UP_HEIGHT_MM
        if not hug and tip < card[1] + EDGE_GAP_MM:
            tip = card[1] - EDGE_GAP_MM - UP_HEIGHT_MM     # above the card's top edge
        up_items, up_box = _up_mark(tip)
        label_items, label_box = _label_block(dot_box[3] + LABEL_GAP_MM, label)
        if not hug and not _inside(label_box, _grow(card, -EDGE_GAP_MM)):
            # Below the card's bottom edge, so cutting the card never cuts the bar.
            label_items, label_box = _label_block(card[3] + EDGE_GAP_MM, label)
        poster = _Poster(tuple(dots), tuple(up_items + label_items), (up_box, label_box),
                         label_box, _union(dot_box, up_box, label_box), card, str(code), ids)
        if not posters or poster.essential != posters[0].essential:
            posters.append(poster)
    return posters


# Sheets ---------------------------------------------------------------------


def _paper_size(paper: str) -> Tuple[str, float, float]:
    key = str(paper).strip().lower()
    if key in PAPER_SIZES_MM:
        return (key, *PAPER_SIZES_MM[key])
    match = re.fullmatch(r'(\d+(?:\.\d*)?)\s*x\s*(\d+(?:\.\d*)?)(?:\s*mm)?', key)
    if match:
        width, height = float(match.group(1)), float(match.group(2))
        if min(width, height) <= 2 * MARGIN_MM + OVERLAP_MM:
            raise ConfigError(f'paper {paper!r} is too small to print on')
        return key, width, height
    raise ConfigError(f'unknown paper {paper!r}: use one of {", ".join(PAPER_SIZES_MM)} '
                      f'or WIDTHxHEIGHT in millimetres (e.g. 300x400)')


def _sheet(poster: _Poster, paper: str, size: Tuple[float, float], window: Box,
           extra_lines: Sequence[Line] = (), extra: Sequence[Item] = (),
           clip: bool = False, **tile) -> CardSheet:
    """Place the poster window ``window`` (poster coords) at the printable area of a page."""
    width, height = size
    dx, dy = MARGIN_MM - window[0], MARGIN_MM - window[1]
    edge_style = {'width': 0.2, 'colour': EDGE_GREY, 'role': 'card-edge'}
    x0, y0, x1, y1 = poster.card
    edges = []
    # The card's edges, only where they fall on this page, broken around notes.
    for vertical, at, lo, hi in ((False, y0, x0, x1), (False, y1, x0, x1),
                                 (True, x0, y0, y1), (True, x1, y0, y1)):
        lo_w, hi_w = (window[1], window[3]) if vertical else (window[0], window[2])
        at_lo, at_hi = (window[0], window[2]) if vertical else (window[1], window[3])
        if at_lo <= at <= at_hi and max(lo, lo_w) < min(hi, hi_w):
            edges += _axis_line(vertical, at, max(lo, lo_w), min(hi, hi_w), poster.dots,
                                poster.note_boxes, EDGE_GAP_MM, **edge_style)
    content: List[Item] = edges + list(extra_lines) + list(poster.dots) + list(poster.notes)
    content += list(extra)
    # Tiles keep only what touches their window (the rest is clipped anyway).
    items = tuple(_shift(item, dx, dy) for item in content
                  if not clip or _boxes_meet(_item_box(item), window))
    return CardSheet(paper, width, height, (dx, dy),
                     (MARGIN_MM, MARGIN_MM, window[2] - window[0], window[3] - window[1]),
                     items, poster.code, poster.ids, clip=clip, **tile)


def _place_text(text: str, size: float, window: Box, circles: Sequence[Circle],
                boxes: Sequence[Box], avoid: Optional[Box], role: str,
                outside_only: bool = False, bottom_first: bool = False) -> Optional[Text]:
    """
    Put a line of text in the first free spot nearest the window's top or bottom edge.

    Spots off the card square (``avoid``) come first, so the cut card stays clean.
    """
    width = text_width_mm(text, size)
    x0, y0, x1, y1 = _grow(window, -1.5)
    if width > x1 - x0:
        return None
    baselines = np.arange(y0 + 0.75 * size, y1 - 0.25 * size, 1.0)
    if len(baselines) == 0:
        return None
    order = sorted(baselines, key=lambda y: (min(y - baselines[0], baselines[-1] - y),
                                             -y if bottom_first else y))
    starts = ((x0 + x1 - width) / 2, x0, x1 - width)
    for outside in ((True,) if outside_only or avoid is None else (True, False)):
        for y in order:
            for x in starts:
                candidate = Text(float(x), float(y), text, size, role=role)
                box = candidate.box()
                if outside and avoid is not None and _boxes_meet(box, avoid):
                    continue
                if any(_boxes_meet(box, _grow(b, 1.5)) for b in boxes):
                    continue
                if any(_box_meets_circle(box, c, 2.0) for c in circles):
                    continue
                return candidate
    return None


def _single_sheet(poster: _Poster, paper: str, size: Tuple[float, float]) -> Optional[CardSheet]:
    """Lay the card on one sheet; None when the essential content does not fit."""
    width, height = size
    room_w, room_h = width - 2 * MARGIN_MM, height - 2 * MARGIN_MM
    e, c = poster.essential, _union(poster.essential, poster.card)
    if e[2] - e[0] > room_w + 1e-9 or e[3] - e[1] > room_h + 1e-9:
        return None

    def start(lo: float, hi: float, pref_lo: float, pref_hi: float, room: float) -> float:
        # Centre the card square when it fits, else the essential content.
        if pref_hi - pref_lo <= room:
            return (pref_lo + pref_hi - room) / 2
        return (lo + hi - room) / 2

    wx = start(e[0], e[2], c[0], c[2], room_w)
    if c[2] - c[0] > room_w and max(-e[0], e[2]) <= room_w / 2:
        wx = -room_w / 2            # keep the dots centred on the sheet
    wy = start(e[1], e[3], c[1], c[3], room_h)
    window = (wx, wy, wx + room_w, wy + room_h)
    note = _place_text(f'pattern_locator card {poster.code}: print at actual size (100 %, '
                       f'no fit to page); the bar must measure {SCALE_LENGTH_MM:.0f} mm',
                       SMALL_TEXT_MM, window, poster.dots, poster.note_boxes, poster.card,
                       'note', outside_only=True, bottom_first=True)
    return _sheet(poster, paper, size, window, extra=[note] if note else [])


@dataclass(frozen=True)
class _Grid:
    count: int
    start: float       # poster coordinate of the first window's low edge
    cover: float       # length covered by the tiles together
    split: bool        # the label block is not wholly on one tile
    dots_cut: int      # dots crossed by a cut line
    uncovered: float   # length of the card square left off the tiles
    shift: float       # distance from the centred position


def _grid(essential: Tuple[float, float], card: Tuple[float, float],
          label: Tuple[float, float], dots: Sequence[Tuple[float, float]],
          room: float) -> _Grid:
    """
    Place tiles along one axis: how many, and where, to cover the essential span.

    Among the positions that cover it, prefer one that keeps the label (and
    its scale bar) on one tile, then one whose cut lines miss every dot (a
    dot taped from two halves is a worse target), then one that keeps the
    card's edges on paper, then the centred one.
    """
    e_lo, e_hi = essential
    step = room - OVERLAP_MM
    length = e_hi - e_lo
    count = 1 if length <= room + 1e-9 else math.ceil((length - OVERLAP_MM) / step - 1e-9)
    cover = count * room - (count - 1) * OVERLAP_MM
    if card[1] - card[0] <= cover:
        centred = (card[0] + card[1] - cover) / 2
    else:
        centred = (e_lo + e_hi - cover) / 2

    def grid(s: float) -> _Grid:
        whole = any(s + k * step <= label[0] + 1e-9 and label[1] <= s + k * step + room + 1e-9
                    for k in range(count))
        cuts = [s + (k + 1) * step + OVERLAP_MM / 2 for k in range(count - 1)]
        cut = sum(any(lo - 1.5 < x < hi + 1.5 for x in cuts) for lo, hi in dots)
        uncovered = max(0.0, s - card[0]) + max(0.0, card[1] - (s + cover))
        return _Grid(count, s, cover, not whole, cut, round(uncovered, 6), abs(s - centred))

    def rank(g: _Grid) -> Tuple:
        return (g.split, g.dots_cut, g.uncovered, g.shift)

    options = [grid(centred)]
    lo, hi = e_hi - cover, e_lo
    if count > 1 and hi > lo:
        options += [grid(float(s)) for s in np.append(np.arange(lo, hi, 0.5), hi)]
    return min(options, key=rank)


def _tiles(poster: _Poster, paper: str, size: Tuple[float, float],
           columns: _Grid, rows: _Grid) -> List[CardSheet]:
    width, height = size
    room_w, room_h = width - 2 * MARGIN_MM, height - 2 * MARGIN_MM
    step_x, step_y = room_w - OVERLAP_MM, room_h - OVERLAP_MM
    nx, ny = columns.count, rows.count
    windows = {(r, c): (columns.start + c * step_x, rows.start + r * step_y,
                        columns.start + c * step_x + room_w, rows.start + r * step_y + room_h)
               for r in range(ny) for c in range(nx)}
    cuts_x = [columns.start + (c + 1) * step_x + OVERLAP_MM / 2 for c in range(nx - 1)]
    cuts_y = [rows.start + (r + 1) * step_y + OVERLAP_MM / 2 for r in range(ny - 1)]

    # Registration crosshairs centred on each cut line, shared by the two tiles.
    marks: Dict[Tuple[int, int], List[Item]] = {key: [] for key in windows}
    mark_boxes: Dict[Tuple[int, int], List[Box]] = {key: [] for key in windows}
    number = 0
    seams = [(True, cuts_x[c], (r, c), (r, c + 1)) for r in range(ny) for c in range(nx - 1)]
    seams += [(False, cuts_y[r], (r, c), (r + 1, c)) for r in range(ny - 1) for c in range(nx)]
    for vertical, at, first, second in seams:
        w = windows[first]
        lo, hi = (w[1], w[3]) if vertical else (w[0], w[2])
        index = first[0] if vertical else first[1]
        count = ny if vertical else nx
        # Stay clear of the crossing overlaps, where a third tile lies on top.
        lo += (OVERLAP_MM if index > 0 else 0.0) + MARK_ARM_MM + 1.0
        hi -= (OVERLAP_MM if index < count - 1 else 0.0) + MARK_ARM_MM + 1.0
        for pos in _mark_positions(vertical, at, lo, hi, poster):
            number += 1
            x, y = (at, pos) if vertical else (pos, at)
            for key in (first, second):
                marks[key] += _crosshair(x, y, number)
                mark_boxes[key].append(_grow((x, y, x, y), MARK_ARM_MM))

    sheets = []
    total = nx * ny
    for (r, c), w in sorted(windows.items()):
        cut_style = {'width': 0.25, 'colour': CUT_GREY, 'dash': (3.0, 2.0), 'role': 'cut-line'}
        lines: List[Line] = []
        strips: List[Box] = []
        for k, x in enumerate(cuts_x):
            if k in (c - 1, c):
                lines += _axis_line(True, x, w[1], w[3], poster.dots, poster.note_boxes,
                                    1.5, **cut_style)
                strips.append((x - OVERLAP_MM / 2, w[1], x + OVERLAP_MM / 2, w[3]))
        for k, y in enumerate(cuts_y):
            if k in (r - 1, r):
                lines += _axis_line(False, y, w[0], w[2], poster.dots, poster.note_boxes,
                                    1.5, **cut_style)
                strips.append((w[0], y - OVERLAP_MM / 2, w[2], y + OVERLAP_MM / 2))
        index = r * nx + c + 1
        obstacles = list(poster.note_boxes) + mark_boxes[(r, c)] + strips
        note = None
        for text in (f'tile {index} of {total} (row {r + 1}, column {c + 1})  card '
                     f'{poster.code}: cut on the dashed line, match the crosshairs',
                     f'tile {index} of {total} (row {r + 1}, column {c + 1})  {poster.code}',
                     f'tile {index} of {total}'):
            note = _place_text(text, SMALL_TEXT_MM, w, poster.dots, obstacles, poster.card,
                               'tile-text')
            if note:
                break
        if note is None:    # nowhere free: still say which tile this is
            note = Text(w[0] + 1.5, w[1] + 1.5 + 0.75 * SMALL_TEXT_MM, f'tile {index} of '
                        f'{total}', SMALL_TEXT_MM, role='tile-text')
        note = replace(note, name='tile-text')
        sheets.append(_sheet(poster, paper, size, w, extra_lines=lines,
                             extra=marks[(r, c)] + [note], clip=True, tile=index,
                             tiles=total, row=r + 1, column=c + 1))
    return sheets


def _mark_positions(vertical: bool, at: float, lo: float, hi: float,
                    poster: _Poster) -> List[float]:
    """Find up to three free spots along a cut line, spread out, for crosshairs."""
    if hi < lo:
        return []
    free = []
    for pos in np.arange(lo, hi + 1e-9, 0.5):
        x, y = (at, pos) if vertical else (pos, at)
        box = _grow((x, y, x, y), MARK_ARM_MM)
        if any(_box_meets_circle(box, d, 4.0) for d in poster.dots):
            continue
        if any(_boxes_meet(box, _grow(b, 1.5)) for b in poster.note_boxes):
            continue
        free.append(float(pos))
    chosen: List[float] = []
    # The two ends first: marks far apart fix the tiles' rotation best.
    for target in (0.0, 1.0, 0.5):
        goal = lo + target * (hi - lo)
        options = [p for p in free if all(abs(p - q) >= 3 * MARK_ARM_MM for q in chosen)]
        if options:
            chosen.append(min(options, key=lambda p: abs(p - goal)))
    return sorted(chosen)


def _crosshair(x: float, y: float, number: int) -> List[Item]:
    style = {'width': 0.2, 'colour': BLACK, 'role': 'registration'}
    return [
        Circle(x, y, MARK_RADIUS_MM, stroke=BLACK, stroke_width=0.2, name=f'reg{number}',
               role='registration'),
        Line(x - MARK_ARM_MM, y, x + MARK_ARM_MM, y, name=f'reg{number}-h', **style),
        Line(x, y - MARK_ARM_MM, x, y + MARK_ARM_MM, name=f'reg{number}-v', **style),
    ]


_LABEL_ROLES = ('label', 'scale-bar', 'scale-tick', 'scale-text')


def _label_move(lo: float, hi: float, grid: _Grid, room: float,
                backwards: bool) -> Optional[float]:
    """Return the smallest move of ``[lo, hi]`` onto one tile, clear of the overlaps."""
    step = room - OVERLAP_MM
    cuts = [grid.start + (k + 1) * step + OVERLAP_MM / 2 for k in range(grid.count - 1)]
    if not any(lo < x < hi for x in cuts):
        return 0.0
    moves = []
    for k in range(grid.count):
        a = grid.start + k * step + (OVERLAP_MM if k > 0 else 0.0) + 1.0
        b = grid.start + k * step + room - (OVERLAP_MM if k < grid.count - 1 else 0.0) - 1.0
        if hi - lo > b - a:
            continue
        move = a - lo if lo < a else (b - hi if hi > b else 0.0)
        if move >= 0 or backwards:
            moves.append(move)
    return min(moves, key=abs) if moves else None


def _keep_label_whole(poster: _Poster, columns: _Grid, rows: _Grid,
                      size: Tuple[float, float]) -> _Poster:
    """
    Slide the label block off the cut lines so the scale bar prints on one tile.

    It sits below every dot, so it may move sideways or further down freely.
    """
    lab = poster.label_box
    dx = _label_move(lab[0], lab[2], columns, size[0] - 2 * MARGIN_MM, True)
    dy = _label_move(lab[1], lab[3], rows, size[1] - 2 * MARGIN_MM, False)
    dx, dy = dx or 0.0, dy or 0.0
    if dx == 0.0 and dy == 0.0:
        return poster
    notes = tuple(_shift(n, dx, dy) if n.role in _LABEL_ROLES else n for n in poster.notes)
    moved = (lab[0] + dx, lab[1] + dy, lab[2] + dx, lab[3] + dy)
    boxes = tuple(moved if b == lab else b for b in poster.note_boxes)
    essential = _union(*(_item_box(d) for d in poster.dots), *boxes)
    return replace(poster, notes=notes, note_boxes=boxes, label_box=moved, essential=essential)


def layout_card(config: PatternConfig, ids: Ids, paper: str = 'a3') -> List[CardSheet]:
    """
    Lay out one card: one sheet when it fits, else tiles with overlaps.

    ``paper``: a name of :data:`PAPER_SIZES_MM` or ``WIDTHxHEIGHT`` in mm
    (portrait dimensions). Raises ConfigError for an unknown paper or a card
    that would need more than :data:`MAX_TILES` tiles, and CodeError for ids
    outside the code layout.
    """
    name, width, height = _paper_size(paper)
    posters = _posters(config, ids)
    for poster in posters:
        sheet = _single_sheet(poster, name, (width, height))
        if sheet is not None:
            return [sheet]
    best = None
    for rank, poster in enumerate(posters):
        e, c, lab = poster.essential, _union(poster.essential, poster.card), poster.label_box
        dots = [_item_box(d) for d in poster.dots]
        for turn, size in enumerate(((width, height), (height, width))):
            room_w, room_h = size[0] - 2 * MARGIN_MM, size[1] - 2 * MARGIN_MM
            columns = _grid((e[0], e[2]), (c[0], c[2]), (lab[0], lab[2]),
                            [(d[0], d[2]) for d in dots], room_w)
            rows = _grid((e[1], e[3]), (c[1], c[3]), (lab[1], lab[3]),
                         [(d[1], d[3]) for d in dots], room_h)
            score = (columns.count * rows.count, columns.split or rows.split,
                     columns.dots_cut + rows.dots_cut, rank,
                     columns.uncovered + rows.uncovered, columns.shift + rows.shift, turn)
            if best is None or score < best[0]:
                best = (score, poster, size, columns, rows)
    score, poster, size, columns, rows = best
    if score[0] == 1:      # fits one landscape sheet
        sheet = _single_sheet(poster, name, size)
        if sheet is not None:
            return [sheet]
    if score[0] > MAX_TILES:
        e = poster.essential
        raise ConfigError(f'a card of {e[2] - e[0]:.0f} x {e[3] - e[1]:.0f} mm would need '
                          f'{score[0]} sheets of {name} paper (at most {MAX_TILES}); use '
                          f'larger paper')
    poster = _keep_label_whole(poster, columns, rows, size)
    return _tiles(poster, name, size, columns, rows)


# SVG ------------------------------------------------------------------------


def _num(value: float) -> str:
    text = f'{value:.4f}'.rstrip('0').rstrip('.')
    return '0' if text in ('-0', '') else text


def _hex(rgb: RGB) -> str:
    return '#{:02x}{:02x}{:02x}'.format(*rgb)


def _svg_attrs(item: Item) -> str:
    attrs = ''
    if item.name:
        attrs += f' id="{escape(item.name)}"'
    if item.role:
        attrs += f' class="{escape(item.role)}"'
    return attrs


def _svg_item(item: Item) -> str:
    if isinstance(item, Circle):
        fill = _hex(item.fill) if item.fill is not None else 'none'
        stroke = ''
        if item.stroke is not None:
            stroke = f' stroke="{_hex(item.stroke)}" stroke-width="{_num(item.stroke_width)}"'
        return (f'<circle{_svg_attrs(item)} cx="{_num(item.cx)}" cy="{_num(item.cy)}" '
                f'r="{_num(item.r)}" fill="{fill}"{stroke}/>')
    if isinstance(item, Rect):
        return (f'<rect{_svg_attrs(item)} x="{_num(item.x)}" y="{_num(item.y)}" '
                f'width="{_num(item.w)}" height="{_num(item.h)}" fill="{_hex(item.fill)}"/>')
    if isinstance(item, Line):
        dash = ''
        if item.dash:
            dash = f' stroke-dasharray="{" ".join(_num(d) for d in item.dash)}"'
        return (f'<line{_svg_attrs(item)} x1="{_num(item.x1)}" y1="{_num(item.y1)}" '
                f'x2="{_num(item.x2)}" y2="{_num(item.y2)}" stroke="{_hex(item.colour)}" '
                f'stroke-width="{_num(item.width)}"{dash}/>')
    return (f'<text{_svg_attrs(item)} x="{_num(item.x)}" y="{_num(item.y)}" '
            f'font-family="{FONT_FAMILY}" font-size="{_num(item.size)}" '
            f'fill="{_hex(item.colour)}" text-anchor="{item.anchor}">'
            f'{escape(_ascii(item.text))}</text>')


def svg_document(sheet: CardSheet) -> str:
    """Return one sheet as an SVG document; one user unit is one millimetre."""
    w, h = _num(sheet.width_mm), _num(sheet.height_mm)
    title = f'pattern_locator card {sheet.code}'
    if sheet.tiled:
        title += f', tile {sheet.tile} of {sheet.tiles}'
    out = ['<?xml version="1.0" encoding="UTF-8"?>',
           f'<svg xmlns="http://www.w3.org/2000/svg" version="1.1" width="{w}mm" '
           f'height="{h}mm" viewBox="0 0 {w} {h}">',
           f'<title>{escape(title)}</title>',
           f'<rect id="background" x="0" y="0" width="{w}" height="{h}" fill="#ffffff"/>']
    if sheet.clip:
        x, y, cw, ch = sheet.window_mm
        out += ['<defs><clipPath id="window">'
                f'<rect x="{_num(x)}" y="{_num(y)}" width="{_num(cw)}" height="{_num(ch)}"/>'
                '</clipPath></defs>',
                '<g clip-path="url(#window)">']
    out += [_svg_item(item) for item in sheet.items]
    if sheet.clip:
        out.append('</g>')
    out.append('</svg>')
    return '\n'.join(out) + '\n'


# PDF ------------------------------------------------------------------------

_KAPPA = 4.0 * (math.sqrt(2.0) - 1.0) / 3.0   # cubic Bezier quarter circle


def _pdf_string(text: str) -> str:
    return '(' + _ascii(text).replace('\\', '\\\\').replace('(', '\\(').replace(')', '\\)') + ')'


def _pdf_colour(rgb: RGB) -> str:
    return ' '.join(_num(v / 255.0) for v in rgb)


def _pdf_circle(cx: float, cy: float, r: float) -> str:
    k = _KAPPA * r
    pts = [(cx + r, cy + k, cx + k, cy + r, cx, cy + r),
           (cx - k, cy + r, cx - r, cy + k, cx - r, cy),
           (cx - r, cy - k, cx - k, cy - r, cx, cy - r),
           (cx + k, cy - r, cx + r, cy - k, cx + r, cy)]
    path = [f'{_num(cx + r)} {_num(cy)} m']
    path += [' '.join(_num(v) for v in p) + ' c' for p in pts]
    return '\n'.join(path) + '\nh'


def _pdf_item(item: Item) -> str:
    if isinstance(item, Circle):
        ops = []
        if item.fill is not None:
            ops.append(f'{_pdf_colour(item.fill)} rg')
        if item.stroke is not None:
            ops.append(f'{_pdf_colour(item.stroke)} RG {_num(item.stroke_width)} w [] 0 d')
        paint = {(True, False): 'f', (False, True): 'S', (True, True): 'B'}.get(
            (item.fill is not None, item.stroke is not None), 'n')
        return '\n'.join(ops + [_pdf_circle(item.cx, item.cy, item.r), paint])
    if isinstance(item, Rect):
        return (f'{_pdf_colour(item.fill)} rg {_num(item.x)} {_num(item.y)} {_num(item.w)} '
                f'{_num(item.h)} re f')
    if isinstance(item, Line):
        dash = ' '.join(_num(d) for d in item.dash)
        return (f'{_pdf_colour(item.colour)} RG {_num(item.width)} w 0 J [{dash}] 0 d\n'
                f'{_num(item.x1)} {_num(item.y1)} m {_num(item.x2)} {_num(item.y2)} l S')
    x = item.box()[0]
    # The page is flipped (y down), so flip the text matrix back to stay upright.
    return (f'BT /F1 {_num(item.size)} Tf {_pdf_colour(item.colour)} rg '
            f'1 0 0 -1 {_num(x)} {_num(item.y)} Tm {_pdf_string(item.text)} Tj ET')


def _pdf_content(sheet: CardSheet) -> bytes:
    height_pt = sheet.height_mm * PT_PER_MM
    # Work in millimetres with y down, like SVG: scale and flip once.
    ops = ['q', f'{_num(PT_PER_MM)} 0 0 {_num(-PT_PER_MM)} 0 {_num(height_pt)} cm']
    if sheet.clip:
        x, y, w, h = sheet.window_mm
        ops.append(f'{_num(x)} {_num(y)} {_num(w)} {_num(h)} re W n')
    ops += [_pdf_item(item) for item in sheet.items]
    ops.append('Q')
    return ('\n'.join(ops) + '\n').encode('ascii')


def pdf_document(sheets: Sequence[CardSheet]) -> bytes:
    """Return all sheets as one PDF 1.4 document, one page per sheet, vector only."""
    sheets = list(sheets)
    if not sheets:
        raise PrintError('no sheets to write')
    objects: List[bytes] = []   # object n is objects[n - 1]
    n_pages = len(sheets)
    page_ids = [5 + 2 * i for i in range(n_pages)]
    title = f'pattern_locator card {sheets[0].code}'
    objects.append(b'<< /Type /Catalog /Pages 2 0 R >>')
    objects.append(f'<< /Type /Pages /Kids [{" ".join(f"{i} 0 R" for i in page_ids)}] '
                   f'/Count {n_pages} >>'.encode('ascii'))
    objects.append(b'<< /Type /Font /Subtype /Type1 /BaseFont /Helvetica '
                   b'/Encoding /WinAnsiEncoding >>')
    objects.append(f'<< /Title {_pdf_string(title)} /Producer (pattern_locator) >>'
                   .encode('ascii'))
    for page_id, sheet in zip(page_ids, sheets):
        box = f'0 0 {_num(sheet.width_mm * PT_PER_MM)} {_num(sheet.height_mm * PT_PER_MM)}'
        objects.append(f'<< /Type /Page /Parent 2 0 R /MediaBox [{box}] '
                       f'/Resources << /Font << /F1 3 0 R >> >> '
                       f'/Contents {page_id + 1} 0 R >>'.encode('ascii'))
        content = _pdf_content(sheet)
        objects.append(b'<< /Length %d >>\nstream\n' % len(content) + content
                       + b'endstream')
    out = bytearray(b'%PDF-1.4\n%\xe2\xe3\xcf\xd3\n')
    offsets = []
    for number, body in enumerate(objects, start=1):
        offsets.append(len(out))
        out += b'%d 0 obj\n' % number + body + b'\nendobj\n'
    xref = len(out)
    out += b'xref\n0 %d\n' % (len(objects) + 1)
    out += b'0000000000 65535 f \n'
    out += b''.join(b'%010d 00000 n \n' % offset for offset in offsets)
    out += (b'trailer\n<< /Size %d /Root 1 0 R /Info 4 0 R >>\nstartxref\n%d\n%%%%EOF\n'
            % (len(objects) + 1, xref))
    return bytes(out)


# PNG ------------------------------------------------------------------------


def _check_dpi(dpi: float) -> float:
    try:
        dpi = float(dpi)
    except (TypeError, ValueError):
        raise ConfigError(f'dpi must be a number, got {dpi!r}') from None
    if not math.isfinite(dpi) or dpi <= 0:
        raise ConfigError(f'dpi must be positive, got {dpi}')
    return dpi


def _blend(img: np.ndarray, x0: int, y0: int, alpha: np.ndarray, rgb: RGB) -> None:
    """Paint ``rgb`` over ``img[y0:, x0:]`` with coverage ``alpha`` (clipped to the image)."""
    h, w = alpha.shape
    ax0, ay0 = max(0, -x0), max(0, -y0)
    bx1, by1 = min(img.shape[1], x0 + w), min(img.shape[0], y0 + h)
    if bx1 <= x0 + ax0 or by1 <= y0 + ay0:
        return
    a = alpha[ay0:by1 - y0, ax0:bx1 - x0, None]
    region = img[y0 + ay0:by1, x0 + ax0:bx1]
    colour = np.array(rgb[::-1], dtype=float)
    region[...] = np.round(region * (1.0 - a) + colour * a).astype(np.uint8)


def _coverage_1d(lo: float, hi: float, start: int, n: int) -> np.ndarray:
    """Return the fraction of each pixel ``[i, i+1)`` (i = start..) inside ``[lo, hi]``."""
    edges = np.arange(start, start + n, dtype=float)
    return np.clip(np.minimum(edges + 1, hi) - np.maximum(edges, lo), 0.0, 1.0)


def _draw_box(img: np.ndarray, x0: float, y0: float, x1: float, y1: float, rgb: RGB) -> None:
    """Fill an axis-aligned rectangle in pixel units, exact area anti-aliasing."""
    if x1 <= x0 or y1 <= y0:
        return
    ix, iy = int(math.floor(x0)), int(math.floor(y0))
    nx, ny = int(math.ceil(x1)) - ix, int(math.ceil(y1)) - iy
    alpha = np.outer(_coverage_1d(y0, y1, iy, ny), _coverage_1d(x0, x1, ix, nx))
    _blend(img, ix, iy, alpha, rgb)


def _draw_circle(img: np.ndarray, item: Circle, scale: float) -> None:
    cx, cy, r = item.cx * scale, item.cy * scale, item.r * scale
    half = item.stroke_width * scale / 2 if item.stroke is not None else 0.0
    half = max(half, 0.5) if item.stroke is not None else 0.0
    reach = r + half + 1.0
    ix, iy = int(math.floor(cx - reach)), int(math.floor(cy - reach))
    n = int(math.ceil(2 * reach)) + 1
    # Distance from each pixel centre to the circle's centre: coverage of a
    # pixel is about how far inside the edge its centre lies (exact to ~1 %).
    xs = np.arange(ix, ix + n) + 0.5 - cx
    ys = np.arange(iy, iy + n) + 0.5 - cy
    dist = np.hypot(xs[None, :], ys[:, None])
    if item.fill is not None:
        _blend(img, ix, iy, np.clip(r - dist + 0.5, 0.0, 1.0), item.fill)
    if item.stroke is not None:
        _blend(img, ix, iy, np.clip(half - np.abs(dist - r) + 0.5, 0.0, 1.0), item.stroke)


def _dash_segments(item: Line) -> List[Tuple[float, float, float, float]]:
    if not item.dash or item.length == 0:
        return [(item.x1, item.y1, item.x2, item.y2)]
    on, off = item.dash[0], item.dash[1] if len(item.dash) > 1 else item.dash[0]
    ux, uy = (item.x2 - item.x1) / item.length, (item.y2 - item.y1) / item.length
    segments, t = [], 0.0
    while t < item.length:
        end = min(t + on, item.length)
        segments.append((item.x1 + ux * t, item.y1 + uy * t, item.x1 + ux * end,
                         item.y1 + uy * end))
        t += on + off
    return segments


def _draw_line(img: np.ndarray, item: Line, scale: float) -> None:
    half = max(item.width * scale, 1.0) / 2     # thinner than a pixel would vanish
    for x1, y1, x2, y2 in _dash_segments(item):
        x1, y1, x2, y2 = (v * scale for v in (x1, y1, x2, y2))
        if x1 == x2 or y1 == y2:
            _draw_box(img, min(x1, x2) - (half if x1 == x2 else 0.0),
                      min(y1, y2) - (half if y1 == y2 else 0.0),
                      max(x1, x2) + (half if x1 == x2 else 0.0),
                      max(y1, y2) + (half if y1 == y2 else 0.0), item.colour)
            continue
        length = math.hypot(x2 - x1, y2 - y1)
        nx, ny = -(y2 - y1) / length * half, (x2 - x1) / length * half
        quad = np.array([(x1 + nx, y1 + ny), (x2 + nx, y2 + ny), (x2 - nx, y2 - ny),
                         (x1 - nx, y1 - ny)]) - 0.5     # cv2 puts pixel centres on integers
        cv2.fillPoly(img, [np.round(quad * 16).astype(np.int32)], item.colour[::-1],
                     cv2.LINE_AA, 4)


def _draw_text(img: np.ndarray, item: Text, scale: float) -> None:
    font = cv2.FONT_HERSHEY_SIMPLEX
    text = _ascii(item.text)
    (w1, h1), _ = cv2.getTextSize(text, font, 1.0, 1)
    if w1 == 0 or h1 == 0:
        return
    x0, _, x1, _ = item.box()
    # Match Helvetica's cap height, but never run wider than the laid-out box.
    font_scale = min(0.718 * item.size * scale / h1, (x1 - x0) * scale / w1)
    thickness = max(1, int(round(0.08 * item.size * scale)))
    width = cv2.getTextSize(text, font, font_scale, thickness)[0][0]
    x = {'start': x0 * scale, 'middle': (x0 + x1) / 2 * scale - width / 2,
         'end': x1 * scale - width}[item.anchor]
    cv2.putText(img, text, (int(round(x)), int(round(item.y * scale))), font, font_scale,
                item.colour[::-1], thickness, cv2.LINE_AA)


def png_image(sheet: CardSheet, dpi: float = 300) -> np.ndarray:
    """Render one sheet at ``dpi`` as a BGR uint8 image (anti-aliased)."""
    dpi = _check_dpi(dpi)
    scale = dpi / MM_PER_INCH
    width, height = int(round(sheet.width_mm * scale)), int(round(sheet.height_mm * scale))
    if width * height > MAX_PIXELS or min(width, height) < 1:
        most = int(math.sqrt(MAX_PIXELS / (sheet.width_mm * sheet.height_mm)) * MM_PER_INCH)
        raise ConfigError(f'{dpi:g} dpi gives a {width} x {height} pixel image of a '
                          f'{sheet.paper} sheet; choose a dpi between 1 and {most}')
    img = np.full((height, width, 3), 255, dtype=np.uint8)
    for item in sheet.items:
        if isinstance(item, Circle):
            _draw_circle(img, item, scale)
        elif isinstance(item, Rect):
            _draw_box(img, item.x * scale, item.y * scale, (item.x + item.w) * scale,
                      (item.y + item.h) * scale, item.fill)
        elif isinstance(item, Line):
            _draw_line(img, item, scale)
        else:
            _draw_text(img, item, scale)
    if sheet.clip:
        x, y, w, h = (int(round(v * scale)) for v in sheet.window_mm)
        keep = np.zeros((height, width), dtype=bool)
        keep[max(0, y):y + h, max(0, x):x + w] = True
        img[~keep] = 255
    return img


def _png_chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack('>I', len(data)) + kind + data + struct.pack(
        '>I', zlib.crc32(kind + data) & 0xFFFFFFFF)


def png_bytes(image: np.ndarray, dpi: float) -> bytes:
    """Encode a BGR image as PNG with its resolution recorded (pHYs chunk)."""
    dpi = _check_dpi(dpi)
    ok, encoded = cv2.imencode('.png', image)
    if not ok:
        raise PrintError('OpenCV could not encode the PNG image')
    data = encoded.tobytes()
    # cv2 writes no pHYs: insert one right after IHDR (8-byte signature + 25-byte IHDR).
    chunks, pos = [], 8
    while pos < len(data):
        length, kind = struct.unpack('>I4s', data[pos:pos + 8])
        end = pos + 12 + length
        if kind != b'pHYs':
            chunks.append(data[pos:end])
        if kind == b'IHDR':
            per_metre = int(round(dpi / 0.0254))
            chunks.append(_png_chunk(b'pHYs', struct.pack('>IIB', per_metre, per_metre, 1)))
        pos = end
    return data[:8] + b''.join(chunks)


# Files ----------------------------------------------------------------------


def tile_paths(path: Union[str, Path], count: int) -> List[Path]:
    """Return file names for ``count`` sheets: ``path`` itself, or ``<stem>-tile<i><suffix>``."""
    path = Path(path)
    if count == 1:
        return [path]
    return [path.with_name(f'{path.stem}-tile{i}{path.suffix}') for i in range(1, count + 1)]


def _write(path: Path, data: bytes) -> None:
    try:
        path.write_bytes(data)
    except OSError as exc:
        raise PrintError(f'{path}: cannot write the card ({exc.strerror or exc})') from None


def write_card(path: Union[str, Path], config: PatternConfig, ids: Ids, paper: str = 'a3',
               dpi: float = 300) -> List[Path]:
    """
    Write a printable card; the format follows the suffix (.svg, .pdf, .png).

    A PDF holds every sheet; a tiled SVG or PNG is written as one file per
    tile (:func:`tile_paths`). Returns the files written. Raises PrintError
    for an unknown suffix or an unwritable path, ConfigError for a bad paper
    or dpi, CodeError for ids outside the code layout.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in ('.svg', '.pdf', '.png'):
        raise PrintError(f'{path}: unknown card format {suffix or "(no suffix)"!r}; '
                         f'use .svg, .pdf or .png')
    if suffix == '.png':
        _check_dpi(dpi)
    sheets = layout_card(config, ids, paper)
    if suffix == '.pdf':
        _write(path, pdf_document(sheets))
        return [path]
    paths = tile_paths(path, len(sheets))
    for target, sheet in zip(paths, sheets):
        if suffix == '.svg':
            _write(target, svg_document(sheet).encode('utf-8'))
        else:
            _write(target, png_bytes(png_image(sheet, dpi), dpi))
    return paths
