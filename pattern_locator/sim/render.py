"""
Synthetic camera images of flat printed cards, with exact ground truth.

Used by the tests, the benchmark and the simulator. Cards are rendered by
inverse mapping: every sub-sample of every pixel gets its undistorted ray from
the camera model, the ray is intersected with each card plane (z-buffered,
nearest wins) and the card's texture is sampled there. Sub-samples are
averaged in linear light, then the scene light, optics, gamma, sensor noise
and JPEG are applied in that order.

Conventions:

* card frame: centred on the card, x right, y up, z out of the card towards
  the viewer (the pattern frame of ``pattern.py``);
* pixel (u, v) is the centre of pixel column u, row v (OpenCV), so the image
  covers u in [-0.5, width - 0.5];
* reflectances and light are linear; printed sRGB colours become
  ``black_ink + (paper_white - black_ink) * linear(sRGB)``;
* image angles (light gradient, motion blur) are measured from the image +x
  axis (right) towards +y (down).

Truth is computed from the model, not from the image: dot and corner pixels
are ``camera.project`` of the 3D points (NaN behind the camera) and the dot
visibility samples each dot disc with the same visibility rules as the
renderer.
"""

from dataclasses import dataclass, replace
import functools
import math
from typing import List, Optional, Protocol, Sequence, Tuple

import cv2
import numpy as np

from ..card.pattern import Code, Ids, PatternConfig, srgb_to_linear
from ..card.printable import Circle, layout_card, MM_PER_INCH, png_image
from ..errors import CodeError, ConfigError, ImageError
from ..vision.camera import CameraModel
from ..vision.geometry import look_at, Pose, rodrigues

BACKGROUNDS = ('wall', 'clutter', 'black', 'white', 'texture', 'night', 'photo', 'mottled')
# Surfaces closer than this to the camera plane (metres) are not rendered.
NEAR_PLANE = 1e-3
# Linear reflectance of a card seen from behind (plain paper back).
BACK_REFLECTANCE = 0.7
# Sub-samples processed at once per card: bounds memory, keeps arrays in cache.
_CHUNK_SAMPLES = 1 << 18
# Points per dot disc for the visible-fraction truth (sunflower spiral).
_DISC_SAMPLES = 1024


def ink_reflectance(srgb: np.ndarray, paper_white: float = 0.85,
                    black_ink: float = 0.03) -> np.ndarray:
    """Linear reflectance of an sRGB colour printed on paper (white = paper, black = ink)."""
    return black_ink + (paper_white - black_ink) * srgb_to_linear(srgb)


def _finite(value: object) -> bool:
    try:
        return math.isfinite(float(value))
    except (TypeError, ValueError):
        return False


def _check_paper(paper_white: float, black_ink: float) -> None:
    if not 0.0 <= black_ink < paper_white <= 1.0:
        raise ConfigError(f'render: need 0 <= black_ink < paper_white <= 1, got black_ink='
                          f'{black_ink}, paper_white={paper_white}')


# Textures --------------------------------------------------------------------

class CardTexture(Protocol):
    """What the renderer needs of a card's printed face."""

    size: float

    def reflectance(self, xy: np.ndarray) -> np.ndarray:
        """(N, 3) linear RGB reflectance at (N, 2) card-frame points (metres)."""
        ...


class DotCardTexture:
    """
    The colour-dot card of ``pattern.py``: white paper, dots in the code's colours.

    Dot discs are exact (a point is inside or outside each circle). A grid of
    small cells over the card labels each cell paper, inside one dot, or on a
    dot's edge; only points in edge cells are tested against their circles.
    """

    def __init__(self, config: PatternConfig, code: Code, paper_white: float = 0.85,
                 black_ink: float = 0.03) -> None:
        _check_paper(paper_white, black_ink)
        if len(code.ring) != 8:
            raise CodeError(f'render: code {code} must have 8 ring colours')
        try:
            # The inks as printed (the configuration's measured inks, if any).
            rgb = [config.ink_rgb(letter) for letter in config.dot_colours(code)]
        except KeyError as exc:
            raise CodeError(f'render: code {code} uses colour {exc} that the pattern '
                            f'configuration does not define') from None
        self.config = config
        self.code = code
        self.size = float(config.card_size)
        centres = config.model_points()[:, :2]
        radii = config.dot_radii()
        if config.handedness_mark is not None:
            # The handedness marks are printed in black ink like point 1.
            marks = config.mark_points()
            centres = np.vstack([centres, marks])
            radii = np.append(radii, np.full(len(marks), config.mark_radius))
            rgb = rgb + [config.ink_rgb('K')] * len(marks)
        # Row k is circle k's ink (dots, then marks), the last row is the paper.
        self._colours = np.vstack([ink_reflectance(np.array(rgb, dtype=float), paper_white,
                                                   black_ink), np.full(3, paper_white)]
                                  ).astype(np.float32)
        # Candidate lists are padded with the paper's index, whose circle is empty.
        self._centres = np.vstack([centres, np.zeros(2)])
        self._r2 = np.append(radii ** 2, -1.0)
        self._build_grid(radii)

    def _build_grid(self, radii: np.ndarray) -> None:
        paper = len(radii)
        self._cell = cell = float(radii.min()) / 4.0
        # One paper cell of margin round the card: clipped indices stay paper.
        self._low = low = -self.size / 2.0 - cell
        n = int(np.ceil((self.size + 2.0 * cell) / cell))
        edges = low + cell * np.arange(n + 1)
        x0, y0 = np.meshgrid(edges[:-1], edges[:-1])
        labels = np.full((n, n), paper, dtype=np.intp)
        edge_dots: List[np.ndarray] = []
        for index, ((cx, cy), radius) in enumerate(zip(self._centres, radii)):
            nearest = np.hypot(np.clip(cx, x0, x0 + cell) - cx, np.clip(cy, y0, y0 + cell) - cy)
            farthest = np.hypot(np.maximum(np.abs(x0 - cx), np.abs(x0 + cell - cx)),
                                np.maximum(np.abs(y0 - cy), np.abs(y0 + cell - cy)))
            labels[farthest <= radius] = index
            edge_dots.append((nearest <= radius) & (farthest > radius))
        # Edge cells get label -1 and up to `depth` candidate dots.
        counts = np.sum(edge_dots, axis=0)
        candidates = np.full((n, n, max(1, int(counts.max()))), paper, dtype=np.intp)
        filled = np.zeros((n, n), dtype=np.intp)
        for index, edge in enumerate(edge_dots):
            rows, cols = np.nonzero(edge)
            candidates[rows, cols, filled[rows, cols]] = index
            filled[rows, cols] += 1
        labels[counts > 0] = -1
        self._labels, self._candidates = labels, candidates

    def reflectance(self, xy: np.ndarray) -> np.ndarray:
        """(N, 3) linear RGB reflectance at (N, 2) card-frame points (metres)."""
        xy = np.asarray(xy).reshape(-1, 2)
        x, y = xy[:, 0], xy[:, 1]
        n = self._labels.shape[0]
        ix = np.clip(((x - self._low) * (1.0 / self._cell)).astype(np.int32), 0, n - 1)
        iy = np.clip(((y - self._low) * (1.0 / self._cell)).astype(np.int32), 0, n - 1)
        cells = iy * n + ix
        labels = np.take(self._labels.ravel(), cells)
        edge = np.flatnonzero(labels < 0)
        labels[edge] = len(self._r2) - 1
        ex, ey = x[edge], y[edge]
        for dots in np.take(self._candidates.reshape(n * n, -1), cells[edge], axis=0).T:
            d2 = (ex - self._centres[dots, 0]) ** 2 + (ey - self._centres[dots, 1]) ** 2
            inside = d2 <= self._r2[dots]
            labels[edge[inside]] = dots[inside]
        return np.take(self._colours, labels, axis=0)


class MirroredTexture:
    """
    A card seen in a mirror: its face flipped left to right (x -> -x).

    Rendering it where the mirror image of the card appears (behind the
    mirror) gives what the camera sees. ``contrast`` below 1 fades the print
    towards the paper, as a card seen from behind through thin paper with
    light behind it.
    """

    def __init__(self, texture: CardTexture, contrast: float = 1.0,
                 paper_white: float = 0.85) -> None:
        if not (_finite(contrast) and 0.0 < contrast <= 1.0):
            raise ConfigError(f'render: mirror contrast must be in (0, 1], got {contrast!r}')
        self.texture = texture
        self.size = float(texture.size)
        self.contrast = float(contrast)
        self.paper_white = float(paper_white)

    def reflectance(self, xy: np.ndarray) -> np.ndarray:
        """(N, 3) linear RGB reflectance at (N, 2) card-frame points (metres)."""
        xy = np.array(xy, dtype=np.float64).reshape(-1, 2)
        xy[:, 0] = -xy[:, 0]
        out = self.texture.reflectance(xy)
        if self.contrast < 1.0:
            out = self.paper_white - self.contrast * (self.paper_white - out)
        return out


class GlossyTexture:
    """
    A glossy or laminated card under a lamp: the lamp's highlight on it.

    A specular highlight is light the surface's gloss reflects, added to
    what its print reflects and the same over ink and paper: ``level``
    (reflectance units, the paper is about 0.85) at its peak, falling off as
    a Gaussian of ``sigma`` metres round ``centre`` (card-frame metres). It
    is lit as the print is, and the sensor clips it (rendered through the
    optics first, as a real highlight's bloom is).
    """

    def __init__(self, texture: CardTexture, centre: Tuple[float, float], sigma: float,
                 level: float) -> None:
        if not (_finite(sigma) and sigma > 0.0):
            raise ConfigError(f'render: glare sigma must be positive metres, got {sigma!r}')
        if not (_finite(level) and level >= 0.0):
            raise ConfigError(f'render: glare level must be >= 0, got {level!r}')
        if not (len(centre) == 2 and all(_finite(c) for c in centre)):
            raise ConfigError(f'render: glare centre must be two finite numbers, got {centre!r}')
        self.texture = texture
        self.size = float(texture.size)
        self.centre = (float(centre[0]), float(centre[1]))
        self.sigma = float(sigma)
        self.level = float(level)

    def reflectance(self, xy: np.ndarray) -> np.ndarray:
        """(N, 3) linear RGB reflectance at (N, 2) card-frame points (metres)."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        d2 = (xy[:, 0] - self.centre[0]) ** 2 + (xy[:, 1] - self.centre[1]) ** 2
        gloss = self.level * np.exp(-d2 / (2.0 * self.sigma ** 2))
        return self.texture.reflectance(xy) + gloss[:, None]


class BitmapCardTexture:
    """
    A bitmap covering the whole card (AprilTag, ArUco...), nearest-neighbour sampled.

    ``image`` is (H, W) or (H, W, 3) uint8 sRGB in RGB order; row 0 is the top
    of the card (+y), column 0 its left edge (-x).
    """

    def __init__(self, image: np.ndarray, size: float, paper_white: float = 0.85,
                 black_ink: float = 0.03) -> None:
        _check_paper(paper_white, black_ink)
        image = np.asarray(image)
        if image.ndim == 3 and image.shape[2] == 1:
            image = image[:, :, 0]
        if image.dtype != np.uint8 or image.ndim not in (2, 3) or (
                image.ndim == 3 and image.shape[2] != 3) or image.size == 0:
            raise ImageError(f'render: card bitmap must be a non-empty (H, W) or (H, W, 3) '
                             f'uint8 image, got {image.dtype} {image.shape}')
        if not (_finite(size) and size > 0):
            raise ConfigError(f'render: card size must be positive, got {size!r}')
        if image.ndim == 2:
            image = np.repeat(image[:, :, None], 3, axis=2)
        lut = ink_reflectance(np.arange(256), paper_white, black_ink)
        self.size = float(size)
        self._texels = lut.astype(np.float32)[image]

    def reflectance(self, xy: np.ndarray) -> np.ndarray:
        """(N, 3) linear RGB reflectance at (N, 2) card-frame points (metres)."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        rows, cols = self._texels.shape[:2]
        col = np.floor((xy[:, 0] / self.size + 0.5) * cols).astype(np.intp)
        row = np.floor((0.5 - xy[:, 1] / self.size) * rows).astype(np.intp)
        return self._texels[np.clip(row, 0, rows - 1), np.clip(col, 0, cols - 1)]


def printed_card_texture(config: PatternConfig, ids: Ids, dpi: float = 150.0,
                         inks: Optional[Sequence[Tuple[str, Tuple[int, int, int]]]] = None
                         ) -> BitmapCardTexture:
    """
    Return the card's square of its printed sheet as a texture: the card printer's own raster.

    Not the renderer's drawing of a card: what ``make-pattern`` writes, with
    its label and scale bar beside the card cut off by the card's edge.
    ``inks`` (sRGB per letter) prints the dots as a printer that makes
    those of the configured colours would (default: the colours).
    """
    printer = config if inks is None else replace(config, colours_rgb=tuple(inks))
    sheet = layout_card(printer, ids, 'a3')[0]
    image = png_image(sheet, dpi=dpi)
    centre = max((item for item in sheet.items if isinstance(item, Circle)), key=lambda c: c.r)
    px_per_mm = dpi / MM_PER_INCH
    half = config.card_size * 1000.0 / 2 * px_per_mm
    side = int(round(2 * half))
    shift = np.float32([[1, 0, half - centre.cx * px_per_mm],
                        [0, 1, half - centre.cy * px_per_mm]])
    square = cv2.warpAffine(image, shift, (side, side), flags=cv2.INTER_AREA,
                            borderValue=(255, 255, 255))
    return BitmapCardTexture(np.ascontiguousarray(square[:, :, ::-1]), config.card_size)


# Scene description -------------------------------------------------------------

@dataclass(frozen=True)
class CardPlacement:
    """
    One card in the scene: its pose, its face and (for the truth) its code.

    For a :class:`DotCardTexture`, ``code`` and ``config`` default to the
    texture's own; other textures get dot truth only if ``config`` is given.
    """

    T_camera_card: Pose
    texture: CardTexture
    code: Optional[Code] = None
    config: Optional[PatternConfig] = None


@dataclass(frozen=True)
class Occluder:
    """
    A flat object painted over a card, in the card's plane; may extend beyond it.

    ``colour_rgb`` is a linear reflectance, lit like the card. Seen from
    behind the card, only the parts outside the card show.
    """

    card_index: int
    polygon_xy: np.ndarray
    colour_rgb: Tuple[float, float, float] = (0.35, 0.3, 0.28)


@dataclass(frozen=True)
class RenderOptions:
    """
    Light, optics, sensor and background of a render.

    Illumination is ``gain * colour_cast * (1 + gradient * p)`` with ``p``
    running from -1 to +1 across the image along ``gradient_angle_deg``;
    ``ambient`` is a veiling light added to the linear image after the optics
    (it lowers contrast). Noise: ``shot_noise`` is photon noise in linear
    units, standard deviation ``shot_noise * sqrt(signal)``; ``noise_sigma``
    is additive Gaussian read noise in 8-bit units after the gamma encoding.

    Colour optics and video: ``lateral_ca`` magnifies the red image by
    ``1 + lateral_ca`` and the blue one by ``1 - lateral_ca`` about the
    principal point (a cheap lens's lateral chromatic aberration);
    ``channel_shift_px`` displaces the red image by ``(dx, dy)`` pixels and the
    blue one by the opposite (misregistered channels, composite video);
    ``chroma_blur_px`` blurs the colour-difference signals along the rows
    (composite video's narrow chroma band). ``interlace_shift_px``: the odd
    rows (the second field of an interlaced frame) are exposed after the
    camera panned by this many pixels to the right. ``crosstalk``: the
    overlap of a real sensor's colour filters, which desaturates colours:
    each channel receives ``1 - crosstalk`` of its own light and
    ``crosstalk / 2`` of each other channel's (a cheap camera's colour
    matrix leaves some of it; 0.3 makes the printed green far greyer).

    Backgrounds: ``wall`` (grey, slightly blotchy, random shade), ``clutter``
    (the wall under random shapes, dots, lines and text), ``black`` (0.01),
    ``white`` (0.85, the same as the paper), ``texture`` (fine texture such
    as carpet, gravel or foliage: noise blurred by 0.6-1.2 px), ``night``
    (a dark scene, reflectance 0.002-0.02, a few small lamps), ``photo`` (a
    cluttered room: textured patches, polka dots, shapes, text and shading),
    ``mottled`` (coloured blotches of the dots' own size, 4-64 px: a
    patterned carpet, gravel or leaves seen close, a busy poster).
    """

    supersample: int = 3
    gain: float = 1.0
    colour_cast: Tuple[float, float, float] = (1.0, 1.0, 1.0)
    ambient: float = 0.0
    gradient: float = 0.0
    gradient_angle_deg: float = 0.0
    defocus_sigma_px: float = 0.0
    motion_blur_px: float = 0.0
    motion_blur_angle_deg: float = 0.0
    noise_sigma: float = 0.0
    shot_noise: float = 0.0
    gamma: float = 2.2
    jpeg_quality: Optional[int] = None
    lateral_ca: float = 0.0
    channel_shift_px: Tuple[float, float] = (0.0, 0.0)
    chroma_blur_px: float = 0.0
    interlace_shift_px: float = 0.0
    crosstalk: float = 0.0
    background: str = 'wall'
    occluders: Tuple[Occluder, ...] = ()
    seed: int = 0


@dataclass(frozen=True)
class CardTruth:
    """Ground truth of one card, in the order the cards were given."""

    T_camera_card: Pose
    code: Optional[Code]
    dot_pixels: Optional[np.ndarray]
    dot_visible: Optional[np.ndarray]
    corner_pixels: np.ndarray


@dataclass(frozen=True)
class RenderResult:
    """The rendered BGR image and the truth of every card."""

    image: np.ndarray
    truth: Tuple[CardTruth, ...]


# Card surfaces -----------------------------------------------------------------

def _in_polygon(px: np.ndarray, py: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Even-odd point-in-polygon test of arrays of points (any shape)."""
    shape = px.shape
    px, py = px.ravel(), py.ravel()
    inside = np.zeros(px.shape, dtype=bool)
    (xmin, ymin), (xmax, ymax) = polygon.min(axis=0), polygon.max(axis=0)
    # Only points in the polygon's bounding box can be inside: test those.
    near = np.flatnonzero((px >= xmin) & (px <= xmax) & (py >= ymin) & (py <= ymax))
    x, y = px[near], py[near]
    odd = np.zeros(near.shape, dtype=bool)
    for (xi, yi), (xj, yj) in zip(polygon.tolist(), np.roll(polygon, 1, axis=0).tolist()):
        if yi != yj:
            crosses = (yi > y) != (yj > y)
            odd ^= crosses & (x < (xj - xi) * (y - yi) / (yj - yi) + xi)
    inside[near] = odd
    return inside.reshape(shape)


def clip_in_front(points: np.ndarray) -> np.ndarray:
    """Clip a closed 3D polygon (camera frame) to z >= NEAR_PLANE."""
    out = []
    for a, b in zip(points, np.roll(points, -1, axis=0)):
        if a[2] >= NEAR_PLANE:
            out.append(a)
        if (a[2] >= NEAR_PLANE) != (b[2] >= NEAR_PLANE):
            out.append(a + (NEAR_PLANE - a[2]) / (b[2] - a[2]) * (b - a))
    return np.array(out).reshape(-1, 3)


class _Surface:
    """A card plane: the card square plus its occluders, as seen from the camera."""

    def __init__(self, placement: CardPlacement, occluders: Sequence[Occluder]) -> None:
        pose = placement.T_camera_card
        self.pose = pose
        self.texture = placement.texture
        self.half = float(placement.texture.size) / 2.0
        self.polygons = [np.asarray(o.polygon_xy, dtype=np.float64) for o in occluders]
        self.occluder_colours = np.array([o.colour_rgb for o in occluders],
                                         dtype=np.float64).reshape(-1, 3)
        # Card points map to the camera by the homography [r1 r2 t]; its
        # determinant is n . t, negative when the camera sees the printed face.
        H = np.column_stack([pose.R[:, 0], pose.R[:, 1], pose.t])
        det = float(np.dot(pose.R[:, 2], pose.t))
        self.facing = det < 0.0
        self.hinv = np.linalg.inv(H) if abs(det) > 1e-12 else None

    def outlines(self) -> List[np.ndarray]:
        """Card square and occluder polygons, card frame (N, 2) each."""
        h = self.half
        square = np.array([[-h, h], [h, h], [h, -h], [-h, -h]])
        return [square] + self.polygons

    def hit(self, x: np.ndarray, y: np.ndarray
            ) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Depth (inf = miss), card x, card y and occluder index (-1) of rays (x, y, 1)."""
        shape = np.broadcast_shapes(x.shape, y.shape)
        if self.hinv is None:
            return (np.full(shape, np.inf), np.zeros(shape), np.zeros(shape),
                    np.full(shape, -1, dtype=np.int16))
        # Python floats keep float32 rays in float32 (numpy scalars would not).
        h = self.hinv.tolist()
        w = h[2][0] * x + h[2][1] * y + h[2][2]
        with np.errstate(divide='ignore', invalid='ignore', over='ignore'):
            depth = 1.0 / w
            cx = (h[0][0] * x + h[0][1] * y + h[0][2]) * depth
            cy = (h[1][0] * x + h[1][1] * y + h[1][2]) * depth
        # w = 1 / depth: in front of the camera and beyond the near plane.
        front = (w > 0.0) & (w < 1.0 / NEAR_PLANE)
        on_card = front & (np.abs(cx) <= self.half) & (np.abs(cy) <= self.half)
        occluder = np.full(shape, -1, dtype=np.int16)
        for k, polygon in enumerate(self.polygons):
            occluder[front & _in_polygon(cx, cy, polygon)] = k
        if not self.facing:
            # Seen from behind, the card hides what is painted on its front.
            occluder[on_card] = -1
        depth[~(on_card | (occluder >= 0))] = np.inf
        return depth, cx, cy, occluder

    def pixel_box(self, camera: CameraModel) -> Optional[Tuple[int, int, int, int]]:
        """Pixel range (x0, y0, x1, y1), end exclusive, that may show this surface."""
        if self.hinv is None:
            return None
        normalised = []
        for outline in self.outlines():
            points = self.pose.apply(np.column_stack([outline, np.zeros(len(outline))]))
            front = clip_in_front(points)
            if len(front):
                normalised.append(front[:, :2] / front[:, 2:])
        if not normalised:
            return None
        normalised = np.concatenate(normalised)
        if camera.has_distortion:
            box = _box_distorted(camera, normalised)
        else:
            pixels = normalised @ camera.K[:2, :2].T + camera.K[:2, 2]
            box = (*np.floor(pixels.min(axis=0)), *np.ceil(pixels.max(axis=0)))
        if box is None:
            return None
        # One pixel of margin: a sub-sample can reach past the pixel centres.
        x0, y0 = max(int(box[0]) - 1, 0), max(int(box[1]) - 1, 0)
        x1, y1 = min(int(box[2]) + 2, camera.width), min(int(box[3]) + 2, camera.height)
        return (x0, y0, x1, y1) if x0 < x1 and y0 < y1 else None


# Rays ------------------------------------------------------------------------------

def _camera_key(camera: CameraModel) -> tuple:
    return (camera.width, camera.height, camera.K.tobytes(), camera.D.tobytes(),
            camera.distortion_model)


@functools.lru_cache(maxsize=4)
def _ray_map_for(key: tuple) -> np.ndarray:
    width, height, K, D, model = key
    camera = CameraModel(width, height, np.frombuffer(K).reshape(3, 3), np.frombuffer(D),
                         model)
    u, v = np.meshgrid(np.arange(-1, width + 1, dtype=np.float64),
                       np.arange(-1, height + 1, dtype=np.float64))
    rays = camera.normalize(np.column_stack([u.ravel(), v.ravel()]))
    rays = rays.reshape(height + 2, width + 2, 2)
    rays.setflags(write=False)
    return rays


def _ray_map(camera: CameraModel) -> np.ndarray:
    """
    Normalised rays of every pixel centre, with a one-pixel border (cached per camera).

    Undistorting millions of points is slow, so the renderer undistorts each
    pixel centre once per camera and interpolates the sub-samples between them.
    """
    return _ray_map_for(_camera_key(camera))


def _box_distorted(camera: CameraModel, normalised: np.ndarray
                   ) -> Optional[Tuple[float, float, float, float]]:
    """Pixel box of the pixels whose rays fall in the convex hull of normalised points."""
    hull = cv2.convexHull(normalised.astype(np.float32)).reshape(-1, 2).astype(np.float64)
    if len(hull) < 3:
        return None
    rays = _ray_map(camera)[1:-1, 1:-1]
    x, y = rays[:, :, 0], rays[:, :, 1]
    area = np.sum(hull[:, 0] * np.roll(hull[:, 1], -1) - np.roll(hull[:, 0], -1) * hull[:, 1])
    sign = 1.0 if area > 0 else -1.0
    # Half a pixel of slack so that edge pixels are never lost.
    slack = 0.5 / min(camera.fx, camera.fy)
    inside = np.ones(x.shape, dtype=bool)
    for a, b in zip(hull, np.roll(hull, -1, axis=0)):
        edge = b - a
        length = float(np.hypot(*edge))
        if length == 0.0:
            continue
        inside &= sign * (edge[0] * (y - a[1]) - edge[1] * (x - a[0])) >= -slack * length
    rows, cols = np.nonzero(inside)
    if rows.size == 0:
        return None
    return (cols.min(), rows.min(), cols.max(), rows.max())


def _subsample_rays(camera: CameraModel, s: int, x0: int, y0: int, x1: int, y1: int
                    ) -> Tuple[np.ndarray, np.ndarray]:
    """
    Normalised rays (x, y) of the s x s sub-samples of pixels [x0, x1) x [y0, y1).

    Returned as (h * s, w * s) arrays laid out so that reshaping to
    (h, s, w, s) groups the sub-samples of each pixel.
    """
    offsets = (np.arange(s) + 0.5) / s - 0.5
    h, w = y1 - y0, x1 - x0
    if not camera.has_distortion:
        u = (np.arange(x0, x1)[:, None] + offsets).ravel()
        v = (np.arange(y0, y1)[:, None] + offsets).ravel()
        ry = ((v - camera.cy) / camera.fy)[:, None]
        rx = (u[None, :] - camera.cx - camera.K[0, 1] * ry) / camera.fx
        shape = (h * s, w * s)
        return (np.broadcast_to(rx.astype(np.float32), shape),
                np.broadcast_to(ry.astype(np.float32), shape))
    rays = _ray_map(camera)
    out = np.empty((h, s, w, s, 2), dtype=np.float32)
    for ky, oy in enumerate(offsets):
        # Bilinear weights are the same for every pixel: interpolate by slicing.
        by, fy = (0, oy) if oy >= 0 else (-1, 1.0 + oy)
        r0 = slice(y0 + by + 1, y1 + by + 1)
        r1 = slice(y0 + by + 2, y1 + by + 2)
        for kx, ox in enumerate(offsets):
            bx, fx = (0, ox) if ox >= 0 else (-1, 1.0 + ox)
            c0 = slice(x0 + bx + 1, x1 + bx + 1)
            c1 = slice(x0 + bx + 2, x1 + bx + 2)
            out[:, ky, :, kx] = ((1 - fy) * ((1 - fx) * rays[r0, c0] + fx * rays[r0, c1])
                                 + fy * ((1 - fx) * rays[r1, c0] + fx * rays[r1, c1]))
    out = out.reshape(h * s, w * s, 2)
    return out[:, :, 0], out[:, :, 1]


# Rendering -------------------------------------------------------------------------

def _render_cards(camera: CameraModel, surfaces: List[_Surface], s: int
                  ) -> Tuple[np.ndarray, np.ndarray]:
    """Sum of visible card radiance and covered fraction per pixel (linear, unlit)."""
    shape = (camera.height, camera.width)
    total = np.zeros(shape + (3,), dtype=np.float32)
    coverage = np.zeros(shape, dtype=np.float32)
    boxes = [surface.pixel_box(camera) for surface in surfaces]
    for i, (surface, box) in enumerate(zip(surfaces, boxes)):
        if box is None:
            continue
        x0, y0, x1, y1 = box
        rows = max(1, _CHUNK_SAMPLES // ((x1 - x0) * s * s))
        for r0 in range(y0, y1, rows):
            r1 = min(y1, r0 + rows)
            rx, ry = _subsample_rays(camera, s, x0, r0, x1, r1)
            depth, cx, cy, occluder = surface.hit(rx, ry)
            for j, (other, other_box) in enumerate(zip(surfaces, boxes)):
                if j != i and other_box is not None:
                    _hide_behind(other, other_box, j < i, depth, rx, ry, (x0, r0, x1, r1), s)
            visible = np.isfinite(depth)
            if not visible.any():
                continue
            colour = np.zeros(depth.shape + (3,), dtype=np.float32)
            flat = colour.reshape(-1, 3)
            printed = np.flatnonzero(visible & (occluder < 0))
            if surface.facing:
                flat[printed] = surface.texture.reflectance(
                    np.column_stack([cx.ravel()[printed], cy.ravel()[printed]]))
            else:
                flat[printed] = BACK_REFLECTANCE
            if surface.polygons:
                painted = visible & (occluder >= 0)
                colour[painted] = surface.occluder_colours[occluder[painted]]
            # Area resampling by an integer factor is the s x s box average.
            size = (x1 - x0, r1 - r0)
            total[r0:r1, x0:x1] += cv2.resize(colour, size, interpolation=cv2.INTER_AREA)
            coverage[r0:r1, x0:x1] += cv2.resize(visible.astype(np.float32), size,
                                                 interpolation=cv2.INTER_AREA)
    return total, coverage


def _hide_behind(other: _Surface, other_box: Tuple[int, int, int, int], wins_ties: bool,
                 depth: np.ndarray, rx: np.ndarray, ry: np.ndarray,
                 box: Tuple[int, int, int, int], s: int) -> None:
    """Set ``depth`` to inf where ``other`` is nearer (the z-buffer test)."""
    x0, y0 = max(box[0], other_box[0]), max(box[1], other_box[1])
    x1, y1 = min(box[2], other_box[2]), min(box[3], other_box[3])
    if x0 >= x1 or y0 >= y1:
        return
    window = (slice((y0 - box[1]) * s, (y1 - box[1]) * s),
              slice((x0 - box[0]) * s, (x1 - box[0]) * s))
    mine = depth[window]
    theirs = other.hit(rx[window], ry[window])[0]
    hidden = (theirs < mine) | ((theirs == mine) & wins_ties)
    mine[hidden] = np.inf


def _background(kind: str, height: int, width: int, rng: np.random.Generator) -> np.ndarray:
    """(H, W, 3) linear reflectance of what is behind the cards."""
    if kind in ('black', 'white'):
        return np.full((height, width, 3), 0.01 if kind == 'black' else 0.85, dtype=np.float32)
    tint = (rng.uniform(0.45, 0.7) * (1.0 + rng.uniform(-0.04, 0.04, 3))).astype(np.float32)
    # Slight wall texture: smooth blotches plus fine grain.
    coarse = rng.standard_normal((height // 48 + 2, width // 48 + 2), dtype=np.float32)
    blotches = cv2.resize(coarse, (width, height), interpolation=cv2.INTER_CUBIC)
    grain = rng.standard_normal((height, width), dtype=np.float32)
    shade = 1.0 + 0.03 * blotches + 0.01 * grain
    if kind == 'wall':
        return shade[:, :, None] * tint
    if kind == 'texture':
        return _fine_texture(height, width, rng)
    if kind == 'night':
        return _night(height, width, rng)
    if kind == 'mottled':
        return _mottled(height, width, rng)
    # Clutter is drawn anti-aliased in 8 bits (cv2 anti-aliases 8-bit images
    # only) with a 2.2 gamma, then turned back into linear reflectance.
    to_gamma = np.float32(1 / 2.2)
    canvas = np.dstack([np.clip(255.0 * (shade * c) ** to_gamma, 0, 255).astype(np.uint8)
                        for c in tint])
    if kind == 'photo':
        _draw_photo(canvas, rng)
    else:
        _draw_clutter(canvas, rng)
    linear = ((np.arange(256, dtype=np.float32) / 255.0) ** 2.2)[canvas]
    if kind == 'photo':
        # Uneven light over the room: smooth shading from 0.4 to 1.2.
        coarse = rng.uniform(0.4, 1.2, (4, 5)).astype(np.float32)
        linear *= cv2.resize(coarse, (width, height), interpolation=cv2.INTER_CUBIC)[:, :, None]
    return linear


def _texture_patch(height: int, width: int, rng: np.random.Generator) -> np.ndarray:
    """(H, W, 3) linear reflectance of a fine texture: noise blurred by 0.6-1.2 px."""
    sigma = float(rng.uniform(0.6, 1.2))
    grey = rng.random() < 0.5
    noise = rng.standard_normal((height, width, 1 if grey else 3), dtype=np.float32)
    noise = cv2.GaussianBlur(noise, (0, 0), sigma).reshape(height, width, -1)
    noise /= max(float(noise.std()), 1e-6)
    mean = float(rng.uniform(0.08, 0.7))
    tint = (1.0 + rng.uniform(-0.25, 0.25, 3)).astype(np.float32)
    amplitude = float(rng.uniform(0.25, 0.7))
    return np.clip(mean * tint * (1.0 + amplitude * noise), 0.0, 1.0)


def _fine_texture(height: int, width: int, rng: np.random.Generator) -> np.ndarray:
    """Carpet, gravel or foliage over the whole view, under a gentle shading."""
    texture = _texture_patch(height, width, rng)
    coarse = rng.uniform(0.7, 1.1, (3, 4)).astype(np.float32)
    return texture * cv2.resize(coarse, (width, height),
                                interpolation=cv2.INTER_CUBIC)[:, :, None]


def _mottled(height: int, width: int, rng: np.random.Generator) -> np.ndarray:
    """Coloured blotches 4, 16 and 64 pixels across, summed: blobs of every dot size."""
    srgb = np.full((height, width, 3), rng.uniform(60.0, 180.0), dtype=np.float32)
    for cell in (4, 16, 64):
        coarse = rng.standard_normal((height // cell + 2, width // cell + 2, 3),
                                     dtype=np.float32)
        blotches = cv2.resize(coarse, (width, height), interpolation=cv2.INTER_CUBIC)
        srgb += float(rng.uniform(10.0, 40.0)) * blotches
    return (np.clip(srgb, 0.0, 255.0) / 255.0) ** 2.2


def _night(height: int, width: int, rng: np.random.Generator) -> np.ndarray:
    """Make a dark scene: reflectance 0.002-0.02, smooth, with a few small lamps."""
    level = float(rng.uniform(0.002, 0.02))
    coarse = rng.uniform(0.5, 1.5, (3, 4)).astype(np.float32)
    dark = level * cv2.resize(coarse, (width, height), interpolation=cv2.INTER_CUBIC)
    out = np.repeat(dark[:, :, None], 3, axis=2)
    for _ in range(int(rng.integers(0, 12))):
        x, y = int(rng.integers(width)), int(rng.integers(height))
        radius = int(rng.integers(1, 4))
        cv2.circle(out, (x, y), radius, tuple(float(v) for v in rng.uniform(0.5, 1.0, 3)), -1)
    return out


def _draw_photo(canvas: np.ndarray, rng: np.random.Generator) -> None:
    """Draw a cluttered room: textured patches, polka-dot fabric, then dense clutter."""
    height, width = canvas.shape[:2]
    scale = math.sqrt(height * width / (640 * 480))
    to_gamma = 1.0 / 2.2
    for _ in range(int(rng.integers(3, 9))):
        w = int(rng.uniform(0.1, 0.5) * width)
        h = int(rng.uniform(0.1, 0.5) * height)
        x, y = int(rng.integers(0, width - w)), int(rng.integers(0, height - h))
        patch = _texture_patch(h, w, rng)
        canvas[y:y + h, x:x + w] = np.clip(255.0 * patch ** to_gamma, 0, 255).astype(np.uint8)
    for _ in range(int(rng.integers(1, 4))):
        # Polka dots: a grid of round dots, each with 8 neighbours around it.
        w = int(rng.uniform(0.15, 0.4) * width)
        h = int(rng.uniform(0.15, 0.4) * height)
        x0, y0 = int(rng.integers(0, width - w)), int(rng.integers(0, height - h))
        radius = rng.uniform(2.0, 9.0) * scale
        pitch = radius * rng.uniform(2.5, 4.5)
        colour = _random_colour(rng)
        for gy in np.arange(y0, y0 + h, pitch):
            for gx in np.arange(x0, x0 + w, pitch):
                r = radius * rng.uniform(0.8, 1.25)
                cv2.circle(canvas, (int(gx), int(gy)), max(1, int(round(r))), colour, -1,
                           cv2.LINE_AA)
    for _ in range(3):
        _draw_clutter(canvas, rng)


def _random_colour(rng: np.random.Generator) -> Tuple[int, int, int]:
    palette = [(200, 20, 25), (20, 150, 60), (20, 60, 200), (15, 15, 15), (240, 240, 235),
               (230, 200, 30), (240, 120, 20), (140, 40, 160)]
    if rng.random() < 0.5:
        return palette[int(rng.integers(len(palette)))]
    return tuple(int(c) for c in rng.integers(0, 256, 3))


def _draw_clutter(canvas: np.ndarray, rng: np.random.Generator) -> None:
    """
    Distractors: rectangles, circles, round dots and short rows of dots, lines, text.

    Nothing here is arranged as a ring of eight dots, so no card can be found.
    """
    height, width = canvas.shape[:2]
    scale = math.sqrt(height * width / (640 * 480))
    aa = cv2.LINE_AA
    for _ in range(int(40 * scale * scale) + 10):
        kind = rng.integers(6)
        colour = _random_colour(rng)
        x, y = int(rng.integers(width)), int(rng.integers(height))
        if kind == 0:
            size = rng.uniform(10, 120, 2) * scale
            angle = rng.uniform(0, 180)
            corners = cv2.boxPoints(((x, y), tuple(size), angle))
            cv2.fillPoly(canvas, [np.round(corners).astype(np.int32)], colour, aa)
        elif kind == 1:
            radius = int(rng.uniform(8, 70) * scale)
            thickness = -1 if rng.random() < 0.5 else int(rng.integers(1, 6))
            cv2.circle(canvas, (x, y), radius, colour, thickness, aa)
        elif kind == 2:
            cv2.circle(canvas, (x, y), max(1, int(rng.uniform(2, 22) * scale)), colour, -1, aa)
        elif kind == 3:
            # A short row of equal dots, a partial pattern at most.
            radius = max(1, int(rng.uniform(3, 12) * scale))
            step = rng.uniform(2.5, 5.0) * radius * np.array(
                [math.cos(a := rng.uniform(0, math.pi)), math.sin(a)])
            for k in range(int(rng.integers(2, 5))):
                centre = (int(x + k * step[0]), int(y + k * step[1]))
                cv2.circle(canvas, centre, radius, _random_colour(rng), -1, aa)
        elif kind == 4:
            end = (int(rng.integers(width)), int(rng.integers(height)))
            cv2.line(canvas, (x, y), end, colour, int(rng.integers(1, 6)), aa)
        else:
            letters = 'ABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789 '
            text = ''.join(letters[i] for i in rng.integers(len(letters), size=8))
            cv2.putText(canvas, text, (x, y), cv2.FONT_HERSHEY_SIMPLEX,
                        rng.uniform(0.4, 1.8) * scale, colour, int(rng.integers(1, 4)), aa)


def _illumination(options: RenderOptions, height: int, width: int) -> np.ndarray:
    """(H, W, 3) light reaching the scene: gain, coloured light and a linear gradient."""
    cast = options.gain * np.asarray(options.colour_cast, dtype=np.float64)
    if options.gradient == 0.0:
        return np.broadcast_to(cast, (height, width, 3))
    angle = math.radians(options.gradient_angle_deg)
    ca, sa = math.cos(angle), math.sin(angle)
    u = np.arange(width) - (width - 1) / 2.0
    v = np.arange(height) - (height - 1) / 2.0
    along = ca * u[None, :] + sa * v[:, None]
    reach = abs(ca) * (width - 1) / 2.0 + abs(sa) * (height - 1) / 2.0
    light = np.maximum(1.0 + options.gradient * along / max(reach, 1e-9), 0.0)
    return light[:, :, None] * cast


def _motion_kernel(length: float, angle_deg: float) -> np.ndarray:
    """Normalised kernel of a straight motion blur of ``length`` pixels."""
    half = int(math.ceil(length / 2.0)) + 1
    kernel = np.zeros((2 * half + 1, 2 * half + 1))
    steps = np.linspace(-length / 2.0, length / 2.0, int(math.ceil(length)) * 8 + 1)
    angle = math.radians(angle_deg)
    x = half + steps * math.cos(angle)
    y = half + steps * math.sin(angle)
    # Bilinear splat keeps sub-pixel lengths and angles smooth.
    ix, iy = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - ix, y - iy
    np.add.at(kernel, (iy, ix), (1 - fx) * (1 - fy))
    np.add.at(kernel, (iy, ix + 1), fx * (1 - fy))
    np.add.at(kernel, (iy + 1, ix), (1 - fx) * fy)
    np.add.at(kernel, (iy + 1, ix + 1), fx * fy)
    return kernel / kernel.sum()


def _shifted(channel: np.ndarray, scale: float, dx: float, dy: float,
             centre: Tuple[float, float]) -> np.ndarray:
    """One image channel magnified by ``scale`` about ``centre``, then moved by (dx, dy)."""
    if scale == 1.0 and dx == 0.0 and dy == 0.0:
        return channel
    cx, cy = centre
    M = np.array([[scale, 0.0, cx * (1.0 - scale) + dx],
                  [0.0, scale, cy * (1.0 - scale) + dy]], dtype=np.float64)
    return cv2.warpAffine(channel, M, (channel.shape[1], channel.shape[0]),
                          flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)


def _colour_optics(image: np.ndarray, options: RenderOptions,
                   centre: Tuple[float, float]) -> np.ndarray:
    """Lateral chromatic aberration and misregistered channels (linear RGB)."""
    k = float(options.lateral_ca)
    dx, dy = (float(v) for v in options.channel_shift_px)
    if k == 0.0 and dx == 0.0 and dy == 0.0:
        return image
    red = _shifted(np.ascontiguousarray(image[:, :, 0]), 1.0 + k, dx, dy, centre)
    blue = _shifted(np.ascontiguousarray(image[:, :, 2]), 1.0 - k, -dx, -dy, centre)
    return np.dstack([red, image[:, :, 1], blue])


def _interlace(image: np.ndarray, shift_px: float) -> np.ndarray:
    """Replace the odd rows by the scene moved ``shift_px`` to the left (camera panned right)."""
    if shift_px == 0.0:
        return image
    M = np.array([[1.0, 0.0, -shift_px], [0.0, 1.0, 0.0]])
    later = cv2.warpAffine(image, M, (image.shape[1], image.shape[0]), flags=cv2.INTER_LINEAR,
                           borderMode=cv2.BORDER_REFLECT)
    out = image.copy()
    out[1::2] = later[1::2]
    return out


def _chroma_blur(image: np.ndarray, sigma: float) -> np.ndarray:
    """Blur the colour differences R - Y and B - Y along the rows (gamma-encoded RGB)."""
    if sigma <= 0:
        return image
    r, g, b = image[:, :, 0], image[:, :, 1], image[:, :, 2]
    y = 0.299 * r + 0.587 * g + 0.114 * b
    size = (2 * int(math.ceil(3 * sigma)) + 1, 1)
    cr = cv2.GaussianBlur(r - y, size, sigma, sigmaY=1e-6, borderType=cv2.BORDER_REFLECT)
    cb = cv2.GaussianBlur(b - y, size, sigma, sigmaY=1e-6, borderType=cv2.BORDER_REFLECT)
    r, b = y + cr, y + cb
    return np.dstack([r, (y - 0.299 * r - 0.114 * b) / 0.587, b])


def _finish(linear: np.ndarray, options: RenderOptions, rng: np.random.Generator,
            centre: Tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """Optics, veiling light, noise, gamma, quantisation and JPEG: linear RGB to BGR uint8."""
    image = linear.astype(np.float32)
    if options.defocus_sigma_px > 0:
        image = cv2.GaussianBlur(image, (0, 0), options.defocus_sigma_px,
                                 borderType=cv2.BORDER_REFLECT)
    if options.motion_blur_px > 0:
        kernel = _motion_kernel(options.motion_blur_px, options.motion_blur_angle_deg)
        image = cv2.filter2D(image, -1, kernel.astype(np.float32),
                             borderType=cv2.BORDER_REFLECT)
    image = _colour_optics(image, options, centre)
    image = _interlace(image, float(options.interlace_shift_px))
    image += np.float32(options.ambient)
    if options.shot_noise > 0:
        image += (options.shot_noise * np.sqrt(np.maximum(image, 0.0))
                  * rng.standard_normal(image.shape, dtype=np.float32))
    image = 255.0 * cv2.pow(np.clip(image, 0.0, 1.0), 1.0 / options.gamma)
    image = _chroma_blur(image, float(options.chroma_blur_px))
    if options.noise_sigma > 0:
        image += np.float32(options.noise_sigma) * rng.standard_normal(
            image.shape, dtype=np.float32)
    bgr = np.ascontiguousarray(np.clip(np.rint(image), 0, 255).astype(np.uint8)[:, :, ::-1])
    if options.jpeg_quality is not None:
        ok, data = cv2.imencode('.jpg', bgr, [cv2.IMWRITE_JPEG_QUALITY, options.jpeg_quality])
        if not ok:
            raise ImageError('render: JPEG encoding failed')
        bgr = cv2.imdecode(data, cv2.IMREAD_COLOR)
    return bgr


# Truth -----------------------------------------------------------------------------

def _project_front(camera: CameraModel, points: np.ndarray) -> np.ndarray:
    """Pixels of camera-frame points; NaN for points not in front of the camera."""
    pixels = np.full((len(points), 2), np.nan)
    front = points[:, 2] > NEAR_PLANE
    if front.any():
        pixels[front] = camera.project(points[front])
    return pixels


@functools.lru_cache(maxsize=1)
def _unit_disc() -> np.ndarray:
    """Evenly spread points of the unit disc (sunflower spiral), equal areas each."""
    k = np.arange(_DISC_SAMPLES) + 0.5
    radius = np.sqrt(k / _DISC_SAMPLES)
    angle = k * math.pi * (3.0 - math.sqrt(5.0))
    return np.column_stack([radius * np.cos(angle), radius * np.sin(angle)])


def _dot_visibility(camera: CameraModel, surfaces: List[_Surface], index: int,
                    config: PatternConfig) -> np.ndarray:
    """Visible fraction of each dot: in front, in the image, not occluded."""
    surface = surfaces[index]
    n_dots = config.n_dots
    if not surface.facing:
        return np.zeros(n_dots)
    disc = _unit_disc()
    xy = (config.model_points()[:, None, :2]
          + config.dot_radii()[:, None, None] * disc[None]).reshape(-1, 2)
    points = surface.pose.apply(np.column_stack([xy, np.zeros(len(xy))]))
    seen = points[:, 2] > NEAR_PLANE
    for polygon in surface.polygons:
        seen &= ~_in_polygon(xy[:, 0], xy[:, 1], polygon)
    candidates = np.flatnonzero(seen)
    if candidates.size == 0:
        return np.zeros(n_dots)
    pixels = camera.project(points[candidates])
    inside = ((pixels[:, 0] >= -0.5) & (pixels[:, 0] < camera.width - 0.5)
              & (pixels[:, 1] >= -0.5) & (pixels[:, 1] < camera.height - 0.5))
    rays = points[candidates, :2] / points[candidates, 2:]
    if camera.has_distortion and inside.any():
        # A distortion model can fold far-off-axis points back into the image;
        # those are not where the renderer (which undistorts pixels) shows them.
        back = camera.normalize(pixels[inside])
        inside[inside] = np.linalg.norm(back - rays[inside], axis=1) < 1e-6 * (
            1.0 + np.linalg.norm(rays[inside], axis=1)) + 1e-3 / camera.fx
    seen[candidates] = inside
    candidates = np.flatnonzero(seen)
    rays = points[candidates, :2] / points[candidates, 2:]
    for j, other in enumerate(surfaces):
        if j != index:
            theirs = other.hit(rays[:, 0], rays[:, 1])[0]
            seen[candidates[theirs < points[candidates, 2]]] = False
    return seen.reshape(n_dots, -1).mean(axis=1)


def _card_truth(camera: CameraModel, surfaces: List[_Surface], index: int,
                placement: CardPlacement) -> CardTruth:
    pose = placement.T_camera_card
    texture = placement.texture
    config = placement.config
    code = placement.code
    if isinstance(texture, DotCardTexture):
        config = config if config is not None else texture.config
        code = code if code is not None else texture.code
    h = float(texture.size) / 2.0
    corners = np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])
    dot_pixels = dot_visible = None
    if config is not None:
        dot_pixels = _project_front(camera, pose.apply(config.model_points()))
        dot_visible = _dot_visibility(camera, surfaces, index, config)
    return CardTruth(pose, code, dot_pixels, dot_visible,
                     _project_front(camera, pose.apply(corners)))


# Entry points ----------------------------------------------------------------------

def _validate(cards: Sequence[CardPlacement], options: RenderOptions) -> None:
    def bad(message: str) -> ConfigError:
        return ConfigError(f'render: {message}')

    s = options.supersample
    if isinstance(s, bool) or not isinstance(s, (int, np.integer)) or not 1 <= s <= 16:
        raise bad(f'supersample must be an integer 1..16, got {s!r}')
    if options.background not in BACKGROUNDS:
        raise bad(f'background must be one of {", ".join(BACKGROUNDS)}, '
                  f'got {options.background!r}')
    numbers = {'gain': options.gain, 'ambient': options.ambient,
               'defocus_sigma_px': options.defocus_sigma_px,
               'motion_blur_px': options.motion_blur_px, 'noise_sigma': options.noise_sigma,
               'shot_noise': options.shot_noise, 'chroma_blur_px': options.chroma_blur_px}
    for name, value in numbers.items():
        if not (_finite(value) and value >= 0):
            raise bad(f'{name} must be a finite number >= 0, got {value!r}')
    for name in ('gradient', 'gradient_angle_deg', 'motion_blur_angle_deg',
                 'interlace_shift_px'):
        if not _finite(getattr(options, name)):
            raise bad(f'{name} must be a finite number, got {getattr(options, name)!r}')
    if not (_finite(options.gamma) and options.gamma > 0):
        raise bad(f'gamma must be positive, got {options.gamma!r}')
    if not (_finite(options.crosstalk) and 0.0 <= options.crosstalk < 0.6):
        raise bad(f'crosstalk must be a number in [0, 0.6), got {options.crosstalk!r}')
    if not (_finite(options.lateral_ca) and abs(options.lateral_ca) < 0.1):
        raise bad(f'lateral_ca must be a number in (-0.1, 0.1), got {options.lateral_ca!r}')
    shift = np.asarray(options.channel_shift_px, dtype=np.float64)
    if shift.shape != (2,) or not np.all(np.isfinite(shift)):
        raise bad(f'channel_shift_px must be 2 finite numbers, got '
                  f'{options.channel_shift_px!r}')
    cast = np.asarray(options.colour_cast, dtype=np.float64)
    if cast.shape != (3,) or not np.all(np.isfinite(cast)) or np.any(cast < 0):
        raise bad(f'colour_cast must be 3 numbers >= 0, got {options.colour_cast!r}')
    quality = options.jpeg_quality
    if quality is not None and not (isinstance(quality, (int, np.integer))
                                    and 1 <= quality <= 100):
        raise bad(f'jpeg_quality must be 1..100, got {options.jpeg_quality!r}')
    for k, card in enumerate(cards):
        pose = card.T_camera_card
        R, t = np.asarray(pose.R, dtype=float), np.asarray(pose.t, dtype=float)
        if R.shape != (3, 3) or t.shape != (3,) or not np.all(np.isfinite(R)) or not np.all(
                np.isfinite(t)) or not np.allclose(R.T @ R, np.eye(3), atol=1e-6):
            raise bad(f'card {k}: T_camera_card needs a rotation matrix and a finite '
                      f'translation')
        size = getattr(card.texture, 'size', None)
        if not (_finite(size) and size > 0) or not hasattr(card.texture, 'reflectance'):
            raise bad(f'card {k}: texture needs a positive size and a reflectance() method')
    for occluder in options.occluders:
        if not 0 <= occluder.card_index < len(cards):
            raise bad(f'occluder card_index {occluder.card_index} out of range '
                      f'0..{len(cards) - 1}')
        polygon = np.asarray(occluder.polygon_xy, dtype=np.float64)
        if polygon.ndim != 2 or polygon.shape[1] != 2 or len(polygon) < 3 or not np.all(
                np.isfinite(polygon)):
            raise bad(f'occluder of card {occluder.card_index}: polygon_xy must be (N, 2) '
                      f'with N >= 3 finite points')
        if np.asarray(occluder.colour_rgb, dtype=np.float64).shape != (3,):
            raise bad(f'occluder of card {occluder.card_index}: colour_rgb needs 3 values')


def render_scene(camera: CameraModel, cards: Sequence[CardPlacement],
                 options: RenderOptions = RenderOptions()) -> RenderResult:
    """
    Render cards in front of a background; return the BGR image and the truth.

    Deterministic for a given ``options.seed`` (background and noise draw
    from separate streams, so changing one does not change the other).
    """
    cards = list(cards)
    _validate(cards, options)
    background_rng, noise_rng = (np.random.default_rng(seq) for seq in
                                 np.random.SeedSequence(options.seed).spawn(2))
    surfaces = [_Surface(card, [o for o in options.occluders if o.card_index == k])
                for k, card in enumerate(cards)]
    radiance, coverage = _render_cards(camera, surfaces, int(options.supersample))
    scene = _background(options.background, camera.height, camera.width, background_rng)
    scene = scene * (1.0 - coverage)[:, :, None] + radiance
    scene *= _illumination(options, camera.height, camera.width)
    if options.crosstalk > 0:
        k = float(options.crosstalk)
        mix = np.full((3, 3), k / 2.0) + np.eye(3) * (1.0 - 1.5 * k)
        scene = cv2.transform(scene.astype(np.float32), mix.astype(np.float32))
    image = _finish(scene, options, noise_rng, (camera.cx, camera.cy))
    truth = tuple(_card_truth(camera, surfaces, k, card) for k, card in enumerate(cards))
    return RenderResult(image, truth)


def card_pose_facing(distance: float, view_angle_deg: float, azimuth_deg: float,
                     roll_deg: float = 0.0, offset_px: Tuple[float, float] = (0.0, 0.0),
                     camera: Optional[CameraModel] = None) -> Pose:
    """
    ``T_camera_card`` of a card seen from ``distance`` at a given tilt and pan.

    The camera's optical centre is at ``distance`` from the card centre, at
    ``view_angle_deg`` (tilt, method.md phi) from the card normal and azimuth
    ``azimuth_deg`` (pan theta, from card +y towards +x). The camera is
    upright (card +y appears upwards), then turned by ``roll_deg`` about its
    optical axis (``geometry.look_at`` convention: positive turns the card
    counter-clockwise in the image), then turned about its centre so that the
    card centre appears ``offset_px`` from the principal point (needs
    ``camera``; lens distortion included). Turning the camera leaves the
    distance and the viewing angles unchanged.
    """
    if not (math.isfinite(distance) and distance > 0):
        raise ConfigError(f'render: distance must be positive, got {distance!r}')
    if not 0.0 <= view_angle_deg < 90.0:
        raise ConfigError(f'render: view_angle_deg must be in [0, 90) for the card to face '
                          f'the camera, got {view_angle_deg!r}')
    phi, theta = math.radians(view_angle_deg), math.radians(azimuth_deg)
    eye = distance * np.array([math.sin(phi) * math.sin(theta),
                               math.sin(phi) * math.cos(theta), math.cos(phi)])
    T_card_camera = look_at(eye, np.zeros(3), up=(0.0, 1.0, 0.0), roll=math.radians(roll_deg))
    R = T_card_camera.R
    if tuple(offset_px) != (0.0, 0.0):
        if camera is None:
            raise ConfigError('render: card_pose_facing needs the camera to place the card '
                              'at offset_px')
        pixel = np.array([[camera.cx + offset_px[0], camera.cy + offset_px[1]]])
        ray = np.append(camera.normalize(pixel)[0], 1.0)
        R = R @ _rotation_between(np.array([0.0, 0.0, 1.0]), ray / np.linalg.norm(ray)).T
    return Pose(R, eye).inverse()


def _rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Return the smallest rotation taking unit vector ``a`` to ``b`` (not opposite)."""
    axis = np.cross(a, b)
    sin = float(np.linalg.norm(axis))
    if sin < 1e-15:
        return np.eye(3)
    return rodrigues(axis / sin * math.atan2(sin, float(np.dot(a, b))))
