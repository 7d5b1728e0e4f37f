"""
A printed card's inks, measured from a photo or scan of it (``pattern-locator inks``).

The detector tells inks apart by the direction of each dot's darkness
against the card's paper (:mod:`.code_reading`), and knows the inks'
directions from the pattern configuration. A printer does not print the
colours it is asked for: an office printer's blue (cyan and magenta) comes
out a dark violet, nearer black than blue by that direction, and inks far
enough off read as other inks, consistently, dot after dot, which no
margin can catch: a wrong id. So the inks are measured once per printer
and written into the configuration (``inks:``), which the detector then
reads by.

The card is found by its geometry alone (the image in grey: its inks are
not trusted yet); the user names the card (its ids are printed on the
sheet), so every dot's ink is known once point 1 is: the turn (and side)
of the ring whose dots of one ink agree best. Each dot is measured over
the inner half of its radius, against the paper between the centre dot and
the inner ring, in the detector's own terms (the camera's gamma against
the paper); the dots of one ink are averaged over every image given.
"""

from dataclasses import dataclass
import math
from typing import List, Optional, Sequence, Tuple

import cv2
import numpy as np

from . import card_kernels
from .camera import CameraModel
from .cards import apply_h
from .code_reading import ink_darkness, LETTERS
from .detector import Detector
from .detector_params import DetectorParams
from ..card.pattern import Code, Ids, PatternConfig, RING_POINTS
from ..errors import ConfigError, ImageError

# A measured ink "matches" its configured one when the detector's nearest
# configured ink is the same with at least this margin (code_reading's:
# 1 on the ink, 0 halfway to the next). The detector's own fit of the
# camera's colour response absorbs much more than this (pure 255/0/0 inks
# read as well as the configured ones); it cannot absorb an ink nearer
# another's direction than its own.
MIN_MATCH_MARGIN = 0.5
# Ring dots must be at least this many pixels in radius: the inner half of
# a smaller dot is a couple of pixels, mixed with paper by any blur.
MIN_DOT_RADIUS_PX = 5.0
# The ring's turn must fit clearly better than any other: its dots' spread
# (summed squared distance from their ink's mean) at most this share of
# the next best turn's.
_TURN_RATIO = 0.5
# The dots of one ink may differ among themselves by this much (degrees of
# darkness direction) before the measurement is refused: more says uneven
# light, glare, or other ids than the card's.
MAX_SPREAD_DEG = 12.0
# Images larger than this (a scan) are searched for the card at a smaller
# size, then at half that and so on down to _SMALLEST_SIDE; the inks are
# measured at full size.
_SEARCH_SIDE = 1600
_SMALLEST_SIDE = 320


@dataclass(frozen=True)
class InkMeasure:
    """One ink as measured, against the configured one."""

    letter: str
    measured_rgb: Tuple[int, int, int]      # sRGB against the paper (white = 255)
    configured_rgb: Tuple[int, int, int]    # the configuration's ink (or colour)
    angle_deg: float                        # between their darkness directions
    read_as: str                            # the configured ink nearest the measured
    margin: float                           # with this margin (1 on it, 0 halfway)
    dots: int                               # dots averaged, over every image
    spread_deg: float                       # largest angle of a dot from their mean

    @property
    def matches(self) -> bool:
        return self.read_as == self.letter and self.margin >= MIN_MATCH_MARGIN


@dataclass(frozen=True)
class InkReport:
    """The four inks of a printed card, from one or more images."""

    code: Code
    inks: Tuple[InkMeasure, ...]
    images: int
    dot_radius_px: float                    # smallest ring dot radius seen, pixels

    @property
    def matches(self) -> bool:
        """Tell whether the detector reads these inks as configured."""
        return all(ink.matches for ink in self.inks)

    def yaml_block(self) -> str:
        """Return the ``inks:`` block for the pattern configuration."""
        lines = ['inks:'] + [f"  {ink.letter}: '#{ink.measured_rgb[0]:02x}"
                             f"{ink.measured_rgb[1]:02x}{ink.measured_rgb[2]:02x}'"
                             for ink in self.inks]
        return '\n'.join(lines)

    def table(self) -> str:
        """One line per ink: configured, measured, their angle, what the detector reads."""
        rows = ['ink  configured  measured  angle  read as (margin)  dots  spread']
        for ink in self.inks:
            rows.append(f'{ink.letter:<4} {_hex(ink.configured_rgb):<11} '
                        f'{_hex(ink.measured_rgb):<9} {ink.angle_deg:5.1f}  '
                        f'{ink.read_as} ({ink.margin:4.2f}){"" if ink.matches else " !":<8}  '
                        f'{ink.dots:4d}  {ink.spread_deg:5.1f}')
        return '\n'.join(rows)


def _hex(rgb: Sequence[int]) -> str:
    return '#{:02x}{:02x}{:02x}'.format(*rgb)


def linear_to_srgb(linear: np.ndarray) -> np.ndarray:
    """Return 8-bit sRGB values of linear values in [0, 1] (the inverse of ``srgb_to_linear``)."""
    c = np.clip(np.asarray(linear, dtype=np.float64), 0.0, 1.0)
    srgb = np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)
    return np.round(255.0 * srgb).astype(int)


def measure_inks(images: Sequence[Tuple[str, np.ndarray]], config: PatternConfig, ids: Ids,
                 camera: Optional[CameraModel] = None,
                 params: DetectorParams = DetectorParams()) -> InkReport:
    """
    Measure the inks of card ``ids`` in ``images`` ((name, BGR uint8) each, one card in view).

    ``camera`` (optional) undoes the lens; without it the images are taken
    as undistorted. Raises :class:`ImageError` naming the image when the
    card is not found, its dots are too small, or its dots do not fit the
    card's inks clearly (other ids, uneven light).
    """
    code = config.encode(*ids.as_tuple())
    absent = [letter for letter in LETTERS if letter not in code.centre + code.ring]
    if absent:
        example = _card_with_every_ink(config)
        raise ConfigError(f'card floor {ids.floor} room {ids.room} card {ids.pattern} (code '
                          f'{code}) has no {", ".join(absent)} dot: measure a card that shows '
                          f'every ink'
                          + (f', e.g. floor {example.floor} room {example.room} card '
                             f'{example.pattern}' if example is not None else ''))
    if not images:
        raise ConfigError('measure_inks: no images given')
    detector = Detector(config, params)
    per_letter: dict = {letter: [] for letter in LETTERS}
    smallest = math.inf
    for name, image in images:
        image = np.asarray(image)
        if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
            raise ImageError(f'{name}: the inks need a colour image (8-bit BGR), got '
                             f'{image.dtype} {image.shape}')
        reflectance, radius = _dot_reflectances(name, image, config, code, camera, detector,
                                                params.gamma)
        smallest = min(smallest, radius)
        for letter, values in reflectance.items():
            per_letter[letter].extend(values)
    configured = ink_darkness(config)[:, ::-1]                   # RGB rows, K R G B
    references = configured / np.linalg.norm(configured, axis=1, keepdims=True)
    inks = []
    for k, letter in enumerate(LETTERS):
        values = np.array(per_letter[letter])                    # (n, 3) RGB reflectance
        mean = values.mean(axis=0)
        darkness = 1.0 - mean
        unit = darkness / max(float(np.linalg.norm(darkness)), 1e-9)
        read, margin = card_kernels._classify_one(unit[0], unit[1], unit[2], references)
        spread = max(_angle_deg(1.0 - v, darkness) for v in values)
        if spread > MAX_SPREAD_DEG:
            raise ImageError(f'the images disagree on ink {letter} by up to {spread:.0f} deg: '
                             f'are they of the same card, under even light?')
        inks.append(InkMeasure(letter, tuple(int(c) for c in linear_to_srgb(mean)),
                               config.ink_rgb(letter), _angle_deg(darkness, configured[k]),
                               LETTERS[read], float(margin), len(values), spread))
    return InkReport(code, tuple(inks), len(images), smallest)


def _card_with_every_ink(config: PatternConfig) -> Optional[Ids]:
    """Return the first ids whose card shows all four inks (None if no card does)."""
    for ids, code in config.all_codes():
        if set(code.centre + code.ring) == set(LETTERS):
            return ids
    return None


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    cos = float(np.dot(a, b) / max(np.linalg.norm(a) * np.linalg.norm(b), 1e-12))
    return math.degrees(math.acos(min(1.0, max(-1.0, cos))))


def _dot_reflectances(name: str, image: np.ndarray, config: PatternConfig, code: Code,
                      camera: Optional[CameraModel], detector: Detector, gamma: float):
    """Return each dot's reflectance (RGB, against the paper) per ink; and the dots' radius."""
    if camera is not None and (image.shape[1], image.shape[0]) != (camera.width, camera.height):
        raise ImageError(f'{name}: image is {image.shape[1]}x{image.shape[0]} but the camera '
                         f'file is for {camera.width}x{camera.height}')
    H = _find_card(name, image, camera, detector)
    # The dots in the detection's order: point 1 taken in slot 0 (a grey
    # image cannot tell), so the model's points are where the dots are.
    model = config.model_points()[:, :2]
    radii = config.dot_radii()
    to_px = _plane_to_pixels(H, camera)
    ring_px = _ring_dot_radius_px(to_px, model, radii)
    if ring_px < MIN_DOT_RADIUS_PX:
        raise ImageError(f'{name}: the ring dots are {2 * ring_px:.0f} px across; take the '
                         f'card closer (at least {2 * MIN_DOT_RADIUS_PX:.0f} px)')
    paper = _paper_level(name, image, config, to_px)
    levels = np.array([_disc_level(image, to_px, p, 0.5 * r) for p, r in zip(model, radii)])
    # The detector's darkness: the camera's gamma against the paper.
    reflectance = np.clip(levels / paper, 0.0, 1.0) ** gamma    # (n_dots, 3) BGR
    reflectance = reflectance[:, ::-1]
    letters = _dot_letters(name, reflectance, config, code)
    out: dict = {letter: [] for letter in LETTERS}
    for value, letter in zip(reflectance, letters):
        out[letter].append(value)
    for letter in LETTERS:
        if not out[letter]:
            continue
        values = np.array(out[letter])
        mean = values.mean(axis=0)
        spread = max(_angle_deg(1.0 - v, 1.0 - mean) for v in values)
        if spread > MAX_SPREAD_DEG:
            raise ImageError(f'{name}: the dots of ink {letter} differ by up to {spread:.0f} deg '
                             f'among themselves: light the card evenly, without glare, and '
                             f'check the ids')
    return out, ring_px


def _find_card(name: str, image: np.ndarray, camera: Optional[CameraModel],
               detector: Detector) -> np.ndarray:
    """Find the largest card by geometry; return its homography (plane m -> undistorted px)."""
    grey = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    # The detector finds cards up to some 230 px in outer-ring radius (its
    # local white is a max filter a few dozen pixels wide): a card filling
    # a photo or a scan is looked for at smaller sizes, down to 320 px.
    scale = min(1.0, _SEARCH_SIDE / max(grey.shape))
    while True:
        small = grey if scale == 1.0 else cv2.resize(grey, None, fx=scale, fy=scale,
                                                     interpolation=cv2.INTER_AREA)
        lens = camera if camera is None or scale == 1.0 else camera.scaled(scale)
        cards = detector.detect(small, lens)
        if cards or max(small.shape) < 2 * _SMALLEST_SIDE:
            break
        scale *= 0.5
    if not cards:
        raise ImageError(f'{name}: no card found: photograph or scan it whole, face-on, '
                         f'evenly lit')
    card = max(cards, key=lambda c: c.size_px)
    if card.n_points < len(card.points_px):
        raise ImageError(f"{name}: {len(card.points_px) - card.n_points} of the card's dots "
                         f'not seen: the whole card must be in view and uncovered')
    if scale == 1.0:
        return card.homography
    # Pixel centres: u_small + 0.5 = scale * (u + 0.5).
    shift = 0.5 * scale - 0.5
    to_small = np.array([[scale, 0.0, shift], [0.0, scale, shift], [0.0, 0.0, 1.0]])
    return np.linalg.solve(to_small, card.homography)


def _plane_to_pixels(H: np.ndarray, camera: Optional[CameraModel]):
    def to_px(xy: np.ndarray) -> np.ndarray:
        px = apply_h(H, xy)
        return camera.distort_pixels(px) if camera is not None else px
    return to_px


def _ring_dot_radius_px(to_px, model: np.ndarray, radii: np.ndarray) -> float:
    """Return the smallest ring dot's radius in pixels (its least extent across)."""
    smallest = math.inf
    angles = np.linspace(0.0, 2 * math.pi, 16, endpoint=False)
    ring = np.column_stack([np.cos(angles), np.sin(angles)])
    for p, r in zip(model[1:], radii[1:]):
        centre = to_px(p[None])[0]
        edge = to_px(p + r * ring)
        smallest = min(smallest, float(np.min(np.linalg.norm(edge - centre, axis=1))))
    return smallest


def _sample(image: np.ndarray, px: np.ndarray) -> np.ndarray:
    """Bilinear samples (N, 3 float) of a BGR image at pixels (N, 2); NaN off the image."""
    h, w = image.shape[:2]
    x, y = px[:, 0], px[:, 1]
    inside = (x >= 0) & (x <= w - 1) & (y >= 0) & (y <= h - 1)
    out = np.full((len(px), 3), np.nan)
    if np.any(inside):
        # On the 8-bit image (a photo's float copy would be hundreds of MB):
        # the rounding of each sample averages out over a disc's hundreds.
        maps = px[inside].astype(np.float32).reshape(-1, 1, 2)
        values = cv2.remap(image, maps, None, cv2.INTER_LINEAR)
        out[inside] = values.reshape(-1, 3).astype(np.float64)
    return out


def _disc_points(centre: np.ndarray, radius: float, n: int = 12) -> np.ndarray:
    """Plane points filling a disc evenly (a square grid clipped to it)."""
    t = np.linspace(-1.0, 1.0, 2 * n + 1)
    gx, gy = np.meshgrid(t, t)
    keep = gx ** 2 + gy ** 2 <= 1.0
    return centre + radius * np.column_stack([gx[keep], gy[keep]])


def _trimmed_mean(values: np.ndarray, share: float = 0.1) -> np.ndarray:
    """Per channel, the mean of the values left when ``share`` at each end is dropped."""
    values = np.sort(values[~np.isnan(values).any(axis=1)], axis=0)
    cut = int(share * len(values))
    return values[cut:len(values) - cut].mean(axis=0)


def _disc_level(image: np.ndarray, to_px, centre: np.ndarray, radius: float) -> np.ndarray:
    """Return the level (BGR, 0-255) over a plane disc: print texture averaged."""
    return _trimmed_mean(_sample(image, to_px(_disc_points(centre, radius))))


def _paper_level(name: str, image: np.ndarray, config: PatternConfig, to_px) -> np.ndarray:
    """Return the paper's level (BGR) between the centre dot and the inner ring."""
    inner = config.centre_dot_radius
    outer = config.ring_radii[-1] - config.ring_dot_radius
    gap = outer - inner
    radii = np.linspace(inner + 0.25 * gap, outer - 0.25 * gap, 4)
    angles = np.linspace(0.0, 2 * math.pi, 72, endpoint=False)
    pts = np.array([[r * math.cos(a), r * math.sin(a)] for r in radii for a in angles])
    samples = _sample(image, to_px(pts))
    paper = np.nanmedian(samples, axis=0)
    if not np.all(paper >= 40.0):
        raise ImageError(f'{name}: the paper is too dark to measure against (level '
                         f'{np.nanmin(paper):.0f} of 255): light the card or expose longer')
    if np.any(paper >= 254.5):
        raise ImageError(f'{name}: the paper is clipped white: expose less (the inks are '
                         f'measured against it)')
    return paper


def _dot_letters(name: str, reflectance: np.ndarray, config: PatternConfig,
                 code: Code) -> List[str]:
    """
    Each dot's ink letter, once point 1 is found: the turn (or mirror) whose inks agree best.

    ``reflectance`` (n_dots, 3) in the detection's order, point 1 taken in
    slot 0. Every turn of the ring, and every turn of its mirror image (the
    ids would then be read wrongly, so a mirror is refused), gives each
    dot a letter; the turn whose dots of one letter lie closest together
    (log reflectance) is taken if it is clearly the best.
    """
    logs = np.log(np.clip(reflectance, 1e-3, 1.0))
    ring = code.ring
    options = {}
    for mirrored in (False, True):
        for turn in range(RING_POINTS):
            letters = [code.centre]
            for _ in range(config.n_rings):
                for slot in range(RING_POINTS):
                    point = ((slot - turn) if not mirrored else (turn - slot)) % RING_POINTS
                    letters.append(ring[point])
            # A ring symmetric about point 1 gives its mirror the same
            # letters: one option, seen directly.
            options.setdefault(tuple(letters), (_spread(logs, letters), mirrored, letters))
    options = sorted(options.values(), key=lambda o: o[0])
    (best, mirrored, letters), (second, _, _) = options[0], options[1]
    if not best <= _TURN_RATIO * second:
        raise ImageError(f'{name}: cannot tell point 1 from the inks (no turn of the ring fits '
                         f'{code} clearly): check --floor/--room/--pattern against the sheet')
    if mirrored:
        raise ImageError(f'{name}: the card is seen in a mirror (or from behind): photograph '
                         f'its front')
    return letters


def _spread(logs: np.ndarray, letters: Sequence[str]) -> float:
    """Sum the dots' squared distances from their letter's mean (log reflectance)."""
    letters = np.array(letters)
    total = 0.0
    for letter in set(letters.tolist()):
        rows = logs[letters == letter]
        total += float(np.sum((rows - rows.mean(axis=0)) ** 2))
    return total
