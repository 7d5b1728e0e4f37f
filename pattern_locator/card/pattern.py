"""
The colour-dot card: its geometry, its colour code and their configuration.

Pattern frame (method.md section 1): origin at the centre dot, x right, y up
(towards point 1), z out of the wall. Ring point ``k`` (1..8) sits at
``alpha_k = (k - 1) * 45 deg`` clockwise from +y as seen from the front.

Dot indices used everywhere (detector, estimators, renderer): 0 is the centre
dot; ring ``i`` (0 = outer, 1 = inner, ...) point ``k`` is ``1 + 8 * i + (k - 1)``.

Code text form: the centre letter, ``-``, then points 1..8, letters
``K R G B``, e.g. ``R-KRGBBGRG``.

Handedness marks: the ring is symmetric about the card's y axis, so a card
seen in a mirror (a glass door, the back of thin paper against the light)
shows the same dots in the other order, which is another valid code. Small
black dots printed at positions whose mirror images are blank paper tell the
two apart (:class:`HandednessMark`); the paper's cards have none.
"""

from dataclasses import dataclass
from pathlib import Path
import re
from typing import Dict, Iterator, List, Optional, Tuple, Union

import numpy as np

from ..errors import CodeError, ConfigError
from ..resources import config_path, read_yaml, UniqueKeyLoader

COLOURS = 'KRGB'
RING_POINTS = 8
FIELDS = ('floor', 'room', 'pattern')
CENTRE = 'centre'
_CODE_RE = re.compile(r'^([KRGB])-([KRGB]{8})$')


@dataclass(frozen=True)
class Code:
    """The colours of one card: ``centre`` letter and ``ring`` letters of points 1..8."""

    centre: str
    ring: str

    def __str__(self) -> str:
        return f'{self.centre}-{self.ring}'

    @staticmethod
    def parse(text: str) -> 'Code':
        """Parse the text form ``C-P1P2...P8``; raise CodeError naming the bad part."""
        text = str(text).strip().upper()
        match = _CODE_RE.match(text)
        if not match:
            raise CodeError(
                f'invalid code {text!r}: expected the centre colour, "-", then the 8 ring '
                f'colours, letters K R G B (e.g. R-KRGBBGRG)')
        code = Code(match.group(1), match.group(2))
        if code.ring[0] != 'K':
            raise CodeError(f'invalid code {text!r}: point 1 must be black (K), '
                            f'got {code.ring[0]!r}')
        bad = [f'point {k + 1} is K' for k, c in enumerate(code.ring) if k > 0 and c == 'K']
        if bad:
            raise CodeError(f'invalid code {text!r}: {", ".join(bad)}; only point 1 is black')
        return code

    def colour_of(self, dot: Union[str, int]) -> str:
        """Colour letter of ``'centre'`` or ring point 1..8."""
        return self.centre if dot == CENTRE else self.ring[int(dot) - 1]

    def mirrored(self) -> 'Code':
        """Return the code a mirror image of this card reads as (points 2..8 reversed)."""
        return Code(self.centre, self.ring[0] + self.ring[:0:-1])


@dataclass(frozen=True)
class Ids:
    """Where a card hangs: floor, room and card number in the room."""

    floor: int
    room: int
    pattern: int

    def as_tuple(self) -> Tuple[int, int, int]:
        return (self.floor, self.room, self.pattern)


@dataclass(frozen=True)
class CodeField:
    """One field of the code: its dots (most significant first) and first value."""

    name: str
    dots: Tuple[Union[str, int], ...]
    first: int

    def radices(self) -> List[int]:
        return [4 if d == CENTRE else 3 for d in self.dots]

    @property
    def count(self) -> int:
        return int(np.prod(self.radices()))


@dataclass(frozen=True)
class HandednessMark:
    """
    Black marks that a mirror moves, at ``angles_deg`` from point 1.

    Angles are measured like the ring points (clockwise from point 1 as
    seen from the front). Each mark's mirror image (x -> -x) falls on blank
    paper, so a mirror image of the card shows paper where the marks belong
    and marks where paper belongs. Two marks on opposite sides keep one in
    view when an object hides part of the card. ``radius`` and ``distance``
    (from the centre, metres) default to values that scale with the card:
    see :meth:`PatternConfig.mark_radius` and :meth:`PatternConfig.mark_distance`.
    """

    angles_deg: Tuple[float, ...] = (22.5, 202.5)
    radius: Optional[float] = None
    distance: Optional[float] = None


@dataclass(frozen=True)
class PatternConfig:
    """Card geometry (metres) and code layout; load with :func:`load_pattern_config`."""

    card_size: float = 0.300
    ring_radii: Tuple[float, ...] = (0.113, 0.072)
    ring_dot_radius: float = 0.014
    centre_dot_radius: float = 0.024
    colours_rgb: Tuple[Tuple[str, Tuple[int, int, int]], ...] = (
        ('K', (0, 0, 0)), ('R', (224, 16, 26)), ('G', (32, 176, 80)), ('B', (16, 64, 208)))
    ring_digits: Tuple[Tuple[str, int], ...] = (('R', 0), ('G', 1), ('B', 2))
    centre_digits: Tuple[Tuple[str, int], ...] = (('K', 0), ('R', 1), ('G', 2), ('B', 3))
    fields: Tuple[CodeField, ...] = (
        CodeField('floor', (CENTRE, 8), 0),
        CodeField('room', (2, 3, 4, 5), 1),
        CodeField('pattern', (6, 7), 1),
    )
    handedness_mark: Optional[HandednessMark] = HandednessMark()
    # The inks as printed (sRGB against the sheet's paper), measured with
    # `pattern-locator inks`; None: as ``colours_rgb`` asks. The detector
    # reads dots by these; the printer prints ``colours_rgb``.
    inks_rgb: Optional[Tuple[Tuple[str, Tuple[int, int, int]], ...]] = None

    def __post_init__(self) -> None:
        _validate(self)

    # Geometry -------------------------------------------------------------

    @property
    def n_rings(self) -> int:
        return len(self.ring_radii)

    @property
    def n_dots(self) -> int:
        return 1 + RING_POINTS * self.n_rings

    @staticmethod
    def dot_index(ring: int, point: int) -> int:
        """Index of ring ``ring`` (0 = outer) point ``point`` (1..8)."""
        return 1 + RING_POINTS * ring + (point - 1)

    def dot_ring_point(self, index: int) -> Tuple[Optional[int], Optional[int]]:
        """``(ring, point)`` of a dot index; ``(None, None)`` for the centre."""
        if index == 0:
            return None, None
        return (index - 1) // RING_POINTS, (index - 1) % RING_POINTS + 1

    def model_points(self) -> np.ndarray:
        """(n_dots, 3) dot centres in the pattern frame, in dot-index order."""
        points = [np.zeros(3)]
        alphas = np.deg2rad(45.0 * np.arange(RING_POINTS))
        for radius in self.ring_radii:
            ring = np.column_stack([radius * np.sin(alphas), radius * np.cos(alphas),
                                    np.zeros(RING_POINTS)])
            points.extend(ring)
        return np.array(points)

    def dot_radii(self) -> np.ndarray:
        """(n_dots,) dot radii in dot-index order."""
        return np.array([self.centre_dot_radius] + [self.ring_dot_radius] * (
            RING_POINTS * self.n_rings))

    def dot_colours(self, code: Code) -> List[str]:
        """Colour letter of every dot, in dot-index order."""
        return [code.centre] + list(code.ring) * self.n_rings

    def colour_rgb(self, letter: str) -> Tuple[int, int, int]:
        """Return the sRGB colour the card's file asks the printer for."""
        return dict(self.colours_rgb)[letter]

    def ink_rgb(self, letter: str) -> Tuple[int, int, int]:
        """Return the ink as printed (``inks_rgb``, measured), else as asked (``colours_rgb``)."""
        return dict(self.inks_rgb if self.inks_rgb is not None else self.colours_rgb)[letter]

    # Handedness marks --------------------------------------------------------

    @property
    def mark_radius(self) -> float:
        """Radius (m) of the handedness marks: given, or 0.85 ring-dot radii."""
        mark = self.handedness_mark
        if mark is not None and mark.radius is not None:
            return float(mark.radius)
        return 0.85 * self.ring_dot_radius

    @property
    def mark_distance(self) -> float:
        """
        Distance (m) of the marks from the centre.

        Given, or halfway between the two outer rings as far as the nearest
        dots go: between slots (22.5 degrees off a point) the distance to
        a dot of either ring is the same at ``(R0 + R1) / (2 cos 22.5)``.
        With one ring, 0.6 of its radius (inside it).
        """
        mark = self.handedness_mark
        if mark is not None and mark.distance is not None:
            return float(mark.distance)
        if len(self.ring_radii) >= 2:
            return (self.ring_radii[0] + self.ring_radii[1]) / (2 * np.cos(np.pi / 8))
        return 0.6 * self.ring_radii[0]

    def mark_points(self, mirrored: bool = False) -> np.ndarray:
        """(m, 2) mark centres in the pattern plane; ``mirrored``: where a mirror shows them."""
        if self.handedness_mark is None:
            return np.zeros((0, 2))
        a = np.deg2rad(np.asarray(self.handedness_mark.angles_deg, dtype=float))
        d = self.mark_distance
        x = d * np.sin(a)
        return np.column_stack([-x if mirrored else x, d * np.cos(a)])

    # Code -----------------------------------------------------------------

    def field(self, name: str) -> CodeField:
        return {f.name: f for f in self.fields}[name]

    def id_ranges(self) -> Dict[str, range]:
        return {f.name: range(f.first, f.first + f.count) for f in self.fields}

    def encode(self, floor: int, room: int, pattern: int) -> Code:
        """Colour code of a card; CodeError if an id is out of range."""
        ids = {'floor': floor, 'room': room, 'pattern': pattern}
        colours: Dict[Union[str, int], str] = {1: 'K'}
        ring_letters = {d: c for c, d in self.ring_digits}
        centre_letters = {d: c for c, d in self.centre_digits}
        for f in self.fields:
            value = ids[f.name]
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
                raise CodeError(f'{f.name} must be an integer, got {value!r}')
            if not f.first <= value < f.first + f.count:
                raise CodeError(f'{f.name} {value} out of range '
                                f'{f.first}..{f.first + f.count - 1} for this code layout')
            rest = int(value) - f.first
            for dot, radix in reversed(list(zip(f.dots, f.radices()))):
                digit = rest % radix
                rest //= radix
                colours[dot] = (centre_letters if dot == CENTRE else ring_letters)[digit]
        ring = ''.join(colours[k] for k in range(1, RING_POINTS + 1))
        return Code(colours[CENTRE], ring)

    def decode(self, code: Union[Code, str]) -> Ids:
        """(floor, room, pattern) of a code; CodeError naming the bad part if invalid."""
        if not isinstance(code, Code):
            code = Code.parse(code)
        else:
            code = Code.parse(str(code))
        ring_digit = dict(self.ring_digits)
        centre_digit = dict(self.centre_digits)
        values = {}
        for f in self.fields:
            value = 0
            for dot, radix in zip(f.dots, f.radices()):
                letter = code.colour_of(dot)
                table = centre_digit if dot == CENTRE else ring_digit
                if letter not in table:
                    raise CodeError(f'invalid code {code}: colour {letter} not allowed on '
                                    f'{"the centre" if dot == CENTRE else f"point {dot}"}')
                value = value * radix + table[letter]
            values[f.name] = value + f.first
        return Ids(values['floor'], values['room'], values['pattern'])

    def all_codes(self) -> Iterator[Tuple[Ids, Code]]:
        """Every valid (ids, code) pair of this layout."""
        ranges = self.id_ranges()
        for floor in ranges['floor']:
            for room in ranges['room']:
                for pattern in ranges['pattern']:
                    yield Ids(floor, room, pattern), self.encode(floor, room, pattern)


def srgb_to_linear(srgb: np.ndarray) -> np.ndarray:
    """Return linear values in [0, 1] of 8-bit sRGB values (the standard sRGB curve)."""
    c = np.asarray(srgb, dtype=np.float64) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _validate(cfg: PatternConfig) -> None:
    if not cfg.ring_radii:
        raise ConfigError('pattern: ring_radii must list at least one ring radius')
    if any(r <= 0 for r in cfg.ring_radii) or list(cfg.ring_radii) != sorted(
            cfg.ring_radii, reverse=True):
        raise ConfigError(f'pattern: ring_radii must be positive, outer first, got '
                          f'{list(cfg.ring_radii)}')
    if cfg.ring_dot_radius <= 0 or cfg.centre_dot_radius <= 0:
        raise ConfigError('pattern: dot radii must be positive')
    outer = cfg.ring_radii[0] + cfg.ring_dot_radius
    if outer > cfg.card_size / 2:
        raise ConfigError(f'pattern: the outer ring ({outer:.3f} m with its dots) does not fit '
                          f'on a card of {cfg.card_size:.3f} m')
    # Neighbouring dots must not touch (the detector needs them apart).
    pts = PatternConfig.model_points(cfg)
    radii = PatternConfig.dot_radii(cfg)
    for i in range(len(pts)):
        for j in range(i + 1, len(pts)):
            if np.linalg.norm(pts[i] - pts[j]) <= radii[i] + radii[j]:
                raise ConfigError(f'pattern: dots {i} and {j} overlap; reduce the dot radii '
                                  f'or separate the rings')
    if cfg.handedness_mark is not None:
        _validate_mark(cfg, pts[:, :2], radii)
    colours = dict(cfg.colours_rgb)
    if sorted(colours) != sorted(COLOURS):
        raise ConfigError(f'pattern: colours must define K, R, G, B, got {sorted(colours)}')
    if cfg.inks_rgb is not None and sorted(dict(cfg.inks_rgb)) != sorted(COLOURS):
        raise ConfigError(f'pattern: inks must define K, R, G, B, got '
                          f'{sorted(dict(cfg.inks_rgb))}')
    if sorted(dict(cfg.ring_digits)) != sorted('RGB') or sorted(
            dict(cfg.ring_digits).values()) != [0, 1, 2]:
        raise ConfigError('pattern: code.ring_digits must map R, G, B to 0, 1, 2')
    if sorted(dict(cfg.centre_digits)) != sorted(COLOURS) or sorted(
            dict(cfg.centre_digits).values()) != [0, 1, 2, 3]:
        raise ConfigError('pattern: code.centre_digits must map K, R, G, B to 0, 1, 2, 3')
    names = [f.name for f in cfg.fields]
    if sorted(names) != sorted(FIELDS):
        raise ConfigError(f'pattern: code.fields must be floor, room, pattern, got {names}')
    used = [d for f in cfg.fields for d in f.dots]
    expected = [CENTRE] + list(range(2, RING_POINTS + 1))
    for dot in used:
        if dot not in expected:
            raise ConfigError(f'pattern: code dot {dot!r} is not "centre" or a ring point 2..8')
    if sorted(map(str, used)) != sorted(map(str, expected)):
        missing = [d for d in expected if d not in used]
        twice = sorted({str(d) for d in used if used.count(d) > 1})
        raise ConfigError(f'pattern: code.fields must use the centre and points 2..8 exactly '
                          f'once (missing {missing}, repeated {twice})')


def _validate_mark(cfg: PatternConfig, dots: np.ndarray, radii: np.ndarray) -> None:
    mark = cfg.handedness_mark
    r = PatternConfig.mark_radius.fget(cfg)
    if not (r > 0 and PatternConfig.mark_distance.fget(cfg) > 0 and len(mark.angles_deg) >= 1):
        raise ConfigError('pattern: handedness_mark needs a positive radius and distance and '
                          'at least one angle')
    marks = PatternConfig.mark_points(cfg)
    mirrored = PatternConfig.mark_points(cfg, mirrored=True)
    if np.max(np.abs(marks)) + r > cfg.card_size / 2:
        raise ConfigError('pattern: handedness_mark does not fit on the card')
    # A mark needs blank paper round it (one mark radius) to be seen apart
    # from the dots; so does its mirror image, where paper must be seen.
    for points, what in ((marks, 'a mark'), (mirrored, "a mark's mirror image")):
        gap = np.linalg.norm(points[:, None] - dots[None], axis=2) - radii[None] - r
        if np.min(gap) < r:
            raise ConfigError(f'pattern: {what} comes within {r * 1000:.0f} mm of a dot; '
                              f'move handedness_mark or make it smaller')
    # Chiral: every mirror image falls on paper, away from every mark.
    apart = np.linalg.norm(mirrored[:, None] - marks[None], axis=2)
    if np.min(apart) < 3 * r:
        raise ConfigError('pattern: handedness_mark angles are mirror-symmetric (a mirror image '
                          'would show a mark where one belongs); use e.g. 22.5 and 202.5')


def _parse_hex(letter: str, text: str) -> Tuple[int, int, int]:
    text = str(text).strip().lstrip('#')
    if not re.fullmatch(r'[0-9a-fA-F]{6}', text):
        raise ConfigError(f'pattern: colour {letter} must be "#rrggbb", got {text!r}')
    return tuple(int(text[i:i + 2], 16) for i in (0, 2, 4))


# The keys a pattern YAML may hold, per level: any other is a mistake (a
# misspelt `colors:` or a key indented under the wrong parent would
# otherwise leave its default in force without a word).
_KEYS = ('card_size', 'ring_radii', 'ring_dot_radius', 'centre_dot_radius', 'colours', 'inks',
         'code', 'handedness_mark')
_CODE_KEYS = ('ring_digits', 'centre_digits', 'fields')
_MARK_KEYS = ('angles_deg', 'radius', 'distance')
_FIELD_KEYS = ('dots', 'first')


def _known_keys(mapping: dict, allowed: Tuple[str, ...], where: str) -> None:
    unknown = [str(k) for k in mapping if k not in allowed]
    if unknown:
        raise ConfigError(f'{where}: unknown key {", ".join(map(repr, unknown))} (known: '
                          f'{", ".join(allowed)})')


def hex_colours(table: Dict[str, str], what: str = 'colours', source: str = 'pattern'
                ) -> Tuple[Tuple[str, Tuple[int, int, int]], ...]:
    """Return a ``{letter: '#rrggbb'}`` table as ``colours_rgb``/``inks_rgb`` hold it."""
    if not isinstance(table, dict):
        raise ConfigError(f'{source}: {what} must map K, R, G, B to "#rrggbb"')
    return tuple((str(k), _parse_hex(k, v)) for k, v in table.items())


def pattern_config_from_dict(data: dict, source: str = 'pattern') -> PatternConfig:
    """Build a PatternConfig from parsed YAML; ConfigError names the bad key."""
    if not isinstance(data, dict):
        raise ConfigError(f'{source}: expected a mapping at the top level')
    _known_keys(data, _KEYS, source)
    defaults = PatternConfig()
    try:
        kwargs = {
            'card_size': float(data.get('card_size', defaults.card_size)),
            'ring_radii': tuple(float(r) for r in data.get('ring_radii', defaults.ring_radii)),
            'ring_dot_radius': float(data.get('ring_dot_radius', defaults.ring_dot_radius)),
            'centre_dot_radius': float(data.get('centre_dot_radius',
                                                defaults.centre_dot_radius)),
        }
    except (TypeError, ValueError) as exc:
        raise ConfigError(f'{source}: geometry values must be numbers in metres ({exc})')
    if 'colours' in data:
        kwargs['colours_rgb'] = hex_colours(data['colours'], 'colours', source)
    if data.get('inks') is not None:
        kwargs['inks_rgb'] = hex_colours(data['inks'], 'inks', source)
    code = data.get('code', {}) or {}
    if not isinstance(code, dict):
        raise ConfigError(f'{source}: code must be a mapping')
    _known_keys(code, _CODE_KEYS, f'{source}: code')
    for key in ('ring_digits', 'centre_digits'):
        if key in code:
            table = code[key]
            if not isinstance(table, dict):
                raise ConfigError(f'{source}: code.{key} must map colour letters to digits')
            kwargs[key] = tuple((str(k), int(v)) for k, v in table.items())
    if 'fields' in code:
        fields = []
        if not isinstance(code['fields'], dict):
            raise ConfigError(f'{source}: code.fields must map floor/room/pattern to dots')
        for name, spec in code['fields'].items():
            if not isinstance(spec, dict) or 'dots' not in spec:
                raise ConfigError(f'{source}: code.fields.{name} needs a "dots" list')
            _known_keys(spec, _FIELD_KEYS, f'{source}: code.fields.{name}')
            dots = tuple(d if d == CENTRE else int(d) for d in spec['dots'])
            fields.append(CodeField(str(name), dots, int(spec.get('first', 0))))
        kwargs['fields'] = tuple(fields)
    if 'handedness_mark' in data:
        kwargs['handedness_mark'] = _mark_from_dict(data['handedness_mark'], source)
    try:
        return PatternConfig(**kwargs)
    except ConfigError as exc:
        raise ConfigError(f'{source}: {str(exc).removeprefix("pattern: ")}') from None


def _mark_from_dict(spec, source: str) -> Optional[HandednessMark]:
    if spec is None or spec is False:
        return None
    if not isinstance(spec, dict):
        raise ConfigError(f'{source}: handedness_mark must be a mapping (angles_deg, and '
                          f'optionally radius, distance) or null for cards printed without it')
    _known_keys(spec, _MARK_KEYS, f'{source}: handedness_mark')
    default = HandednessMark()
    try:
        return HandednessMark(
            tuple(float(a) for a in spec.get('angles_deg', default.angles_deg)),
            None if spec.get('radius') is None else float(spec['radius']),
            None if spec.get('distance') is None else float(spec['distance']))
    except (TypeError, ValueError) as exc:
        raise ConfigError(f'{source}: handedness_mark values must be numbers ({exc})')


def load_pattern_config(path: Optional[Union[str, Path]] = None) -> PatternConfig:
    """Load a pattern YAML (default: the shipped ``config/pattern.yaml``)."""
    path = Path(path) if path is not None else config_path('pattern.yaml')
    data = read_yaml(path, 'pattern configuration', loader=UniqueKeyLoader)
    try:
        return pattern_config_from_dict(data, str(path))
    except (TypeError, ValueError, OverflowError) as exc:
        # A value of the wrong type where a number or a list is expected.
        raise ConfigError(f'{path}: invalid pattern configuration ({str(exc)[:80]})') from None
