"""
The simulator's fast renderer: only the pixel boxes that can show a card are rendered.

ROS-free. The background (painted wall, light gradient, colour cast, gamma)
is rendered once per image size and each frame only renders the boxes round
the cards, with ``render.render_scene`` and a camera cropped to the box
(exact: cropping shifts the principal point only, and the light gradient is
re-expressed for the box). Sensor noise outside the boxes comes from a
precomputed noise tile read at a random offset.

Beyond the plain view of cards, a :class:`BoxCard` may carry

* **occluders**: polygons in the card's plane painted in the wall's colour
  (a wall or door jamb between the camera and the card, projected onto the
  card from the camera's centre, is exactly such a polygon);
* **motion blur**: the card's image motion during the exposure (pixels); the
  box is rendered at the exposure's middle and smeared along that motion
  with ``render``'s linear motion-blur kernel, in linear light.

An interlaced frame is two fields from different instants: each field is
rendered with a half-height camera (rows of one parity) into that field's
rows of the frame (:meth:`BoxRenderer.render_fields`).
"""

from dataclasses import dataclass, replace
import functools
import math
from typing import Any, Dict, List, Optional, Sequence, Tuple

import cv2
import numpy as np

from .render import (CardPlacement, clip_in_front, DotCardTexture, Occluder, render_scene,
                     RenderOptions)
from ..errors import ConfigError, ImageError
from ..vision.camera import CameraModel
from ..vision.geometry import Pose

# A box bigger than this many sub-samples (a close card, a long focal length) gets
# fewer sub-samples per pixel, so that no frame takes much longer than the others;
# big cards need them least.
MAX_BOX_SAMPLES = 1 << 18
# Noise outside the boxes: a tile this much bigger than the image, read at a random offset.
_NOISE_PAD = 64
_NOISE_SEED = 20231114
# The linear reflectance of render.py's uniform backgrounds: the walls' paint.
BACKGROUND_REFLECTANCE = {'white': 0.85, 'black': 0.01}

Box = Tuple[int, int, int, int]


class UncodedFace:
    """
    A card's printed face that render_scene does not know as a coded card.

    So it skips the dot truth, the slowest part of a small render, which the
    simulator does not use.
    """

    def __init__(self, texture: DotCardTexture) -> None:
        self.size = texture.size
        self.reflectance = texture.reflectance


@dataclass(frozen=True, eq=False)
class BoxCard:
    """
    One card to draw: pose in the camera, face, what hides it and its motion blur.

    ``occluders``: (N, 2) polygons in the card frame (metres), painted in the
    wall's colour. ``blur_px``: the card's image motion (du, dv) in pixels of
    the camera it is drawn with, over the exposure.
    """

    T_camera_card: Pose
    face: UncodedFace
    occluders: Tuple[np.ndarray, ...] = ()
    blur_px: Tuple[float, float] = (0.0, 0.0)


@functools.lru_cache(maxsize=16)
def _distortion_margin(width: int, height: int, K: bytes, D: bytes, model: str) -> float:
    """Return the largest distance (px) between a pixel and its undistorted pixel."""
    camera = CameraModel(width, height, np.frombuffer(K).reshape(3, 3), np.frombuffer(D),
                         model)
    if not camera.has_distortion:
        return 0.0
    # Radial and tangential distortion peak on the border, at the corners.
    u = np.linspace(-0.5, width - 0.5, 33)
    v = np.linspace(-0.5, height - 0.5, 25)
    border = np.vstack([np.column_stack([u, np.full_like(u, v[0])]),
                        np.column_stack([u, np.full_like(u, v[-1])]),
                        np.column_stack([np.full_like(v, u[0]), v]),
                        np.column_stack([np.full_like(v, u[-1]), v])])
    inner = np.stack(np.meshgrid(u[::4], v[::4]), axis=-1).reshape(-1, 2)
    pixels = np.vstack([border, inner])
    return float(np.max(np.linalg.norm(camera.undistort_pixels(pixels) - pixels, axis=1)))


def distortion_margin(camera: CameraModel) -> float:
    """Return the largest distance (px) between a pixel and its undistorted pixel (cached)."""
    return _distortion_margin(camera.width, camera.height, camera.K.tobytes(),
                              camera.D.tobytes(), camera.distortion_model)


def field_camera(camera: CameraModel, parity: int) -> CameraModel:
    """
    Return the camera of one field: the rows ``parity``, ``parity + 2``, ... of the frame.

    Field row ``j`` is frame row ``2 j + parity``: fy and cy halve (cy after
    the shift), the rays and the distortion stay those of the frame's rows.
    """
    K = camera.K.copy()
    K[1, 1] = camera.fy / 2.0
    K[1, 2] = (camera.cy - parity) / 2.0
    return CameraModel(camera.width, (camera.height - parity + 1) // 2, K, camera.D,
                       camera.distortion_model, camera.name)


def _overlap(a: Box, b: Box) -> bool:
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]


def merge_boxes(items: List[Tuple[Box, Any]]) -> List[Tuple[Box, List[Any]]]:
    """Group cards whose boxes overlap (one render each, so the nearest card wins)."""
    groups = [(box, [card]) for box, card in items]
    merged = True
    while merged:
        merged = False
        for i in range(len(groups)):
            for j in range(i + 1, len(groups)):
                (a, cards_a), (b, cards_b) = groups[i], groups[j]
                if _overlap(a, b):
                    groups[i] = ((min(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]),
                                  max(a[3], b[3])), cards_a + cards_b)
                    del groups[j]
                    merged = True
                    break
            if merged:
                break
    return groups


def pixel_box(camera: CameraModel, T_camera_card: Pose, half: float, margin: float
              ) -> Optional[Box]:
    """
    Return the pixels (x0, y0, x1, y1), ends exclusive, that may show the card.

    The ideal (distortion-free) pixels of the card's visible outline,
    widened by ``margin``, which covers the distortion and the blur.
    """
    corners = np.array([[-half, half, 0.0], [half, half, 0.0], [half, -half, 0.0],
                        [-half, -half, 0.0]])
    front = clip_in_front(T_camera_card.apply(corners))
    if len(front) < 3:
        return None
    ideal = (front[:, :2] / front[:, 2:]) @ camera.K[:2, :2].T + camera.K[:2, 2]
    low = np.floor(ideal.min(axis=0) - margin)
    high = np.ceil(ideal.max(axis=0) + margin) + 1
    x0, y0 = (int(max(v, 0)) for v in low)
    x1, y1 = int(min(high[0], camera.width)), int(min(high[1], camera.height))
    return (x0, y0, x1, y1) if x0 < x1 and y0 < y1 else None


class BoxRenderer:
    """
    Renders frames of cards on a uniform wall, box by box (see the module docstring).

    ``options``: the look of the images; its seed is ignored (each render
    takes one). The background must be uniform (``white`` or ``black``), with
    a light gradient below 1, no occluders of its own and no shot noise: the
    background is rendered once per image size; motion blur comes from each
    card's own motion. Not thread-safe (per-size caches).
    """

    def __init__(self, options: RenderOptions) -> None:
        if options.background not in BACKGROUND_REFLECTANCE:
            raise ConfigError(f'sim: the background must be white or black, got '
                              f'{options.background!r}')
        if options.occluders or options.shot_noise:
            raise ConfigError('sim: occluders and shot noise are not simulated')
        if options.motion_blur_px:
            raise ConfigError('sim: motion blur comes from the motion of each card (BoxCard.'
                              'blur_px); set motion_blur_px to 0')
        if not (math.isfinite(options.gradient) and abs(options.gradient) < 1.0):
            raise ConfigError(f'sim: gradient must be in (-1, 1), got {options.gradient!r}')
        self.options = options
        reflectance = BACKGROUND_REFLECTANCE[options.background]
        # Walls are painted like the background: what a wall hides looks like the wall.
        self.wall_rgb = (reflectance, reflectance, reflectance)
        self._frames: Dict[Tuple[int, int], Tuple[np.ndarray, np.ndarray, np.ndarray]] = {}

    def render(self, camera: CameraModel, cards: Sequence[BoxCard], seed: int) -> np.ndarray:
        """Return the BGR uint8 image of ``cards`` (deterministic for a seed)."""
        rng = np.random.default_rng(seed)
        frame = self._noisy_background(camera.width, camera.height, rng)
        self._draw(frame, camera, cards, rng, camera.width, camera.height, 1, 0)
        return self._finish(frame)

    def render_fields(self, camera: CameraModel, fields: Sequence[Sequence[BoxCard]],
                      seed: int) -> np.ndarray:
        """
        Return an interlaced frame: ``fields[p]`` drawn into the rows of parity ``p``.

        Each field's cards are posed (and blurred) for the camera of
        :func:`field_camera` ``(camera, p)``.
        """
        if len(fields) != 2:
            raise ConfigError(f'sim: an interlaced frame has 2 fields, got {len(fields)}')
        rng = np.random.default_rng(seed)
        frame = self._noisy_background(camera.width, camera.height, rng)
        for parity, cards in enumerate(fields):
            self._draw(frame[parity::2], field_camera(camera, parity), cards, rng,
                       camera.width, camera.height, 2, parity)
        return self._finish(frame)

    def _finish(self, frame: np.ndarray) -> np.ndarray:
        if self.options.jpeg_quality is not None:
            ok, data = cv2.imencode('.jpg', frame,
                                    [cv2.IMWRITE_JPEG_QUALITY, self.options.jpeg_quality])
            if not ok:
                raise ImageError('sim: JPEG encoding failed')
            frame = cv2.imdecode(data, cv2.IMREAD_COLOR)
        return frame

    def _draw(self, frame: np.ndarray, camera: CameraModel, cards: Sequence[BoxCard],
              rng: np.random.Generator, width: int, height: int, row_scale: int,
              row_offset: int) -> None:
        """Render the boxes of ``cards`` into ``frame`` (a view of the rows ``camera`` sees)."""
        # Room for the blur around a card (OpenCV's float kernels reach 4 sigma).
        margin = distortion_margin(camera) + 4.0 * self.options.defocus_sigma_px + 2.0
        items = []
        for card in cards:
            blur = math.hypot(*card.blur_px)
            box = pixel_box(camera, card.T_camera_card, card.face.size / 2.0,
                            margin + blur / 2.0 + (1.0 if blur > 0 else 0.0))
            if box is not None:
                items.append((box, card))
        for box, group in merge_boxes(items):
            x0, y0, x1, y1 = box
            frame[y0:y1, x0:x1] = self._render_box(camera, box, group,
                                                   int(rng.integers(1 << 31)), width, height,
                                                   row_scale, row_offset)

    def _render_box(self, camera: CameraModel, box: Box, cards: List[BoxCard], seed: int,
                    width: int, height: int, row_scale: int, row_offset: int) -> np.ndarray:
        """Render the cards in a box of the image, as if the whole image were rendered."""
        x0, y0, x1, y1 = box
        w, h = x1 - x0, y1 - y0
        K = camera.K.copy()
        K[0, 2] -= x0
        K[1, 2] -= y0
        crop = CameraModel(w, h, K, camera.D, camera.distortion_model, camera.name)
        options = self.options
        # The light gradient is linear in the frame's pixel position: re-express
        # it about the box's centre and over the box's reach. A field's row j is
        # the frame's row row_scale * j + row_offset.
        angle = math.radians(options.gradient_angle_deg)
        ca, sa = math.cos(angle), math.sin(angle)
        reach = max(abs(ca) * (width - 1) / 2.0 + abs(sa) * (height - 1) / 2.0, 1e-9)
        offset = (ca * (x0 + (w - 1) / 2.0 - (width - 1) / 2.0)
                  + sa * (row_scale * (y0 + (h - 1) / 2.0) + row_offset - (height - 1) / 2.0))
        light = 1.0 + options.gradient * offset / reach
        box_angle = math.atan2(sa * row_scale, ca)
        cb, sb = math.cos(box_angle), math.sin(box_angle)
        box_reach = abs(cb) * (w - 1) / 2.0 + abs(sb) * (h - 1) / 2.0
        gradient = options.gradient * box_reach * math.hypot(ca, sa * row_scale) / (light * reach)
        s = int(options.supersample)
        while s > 1 and w * h * s * s > MAX_BOX_SAMPLES:
            s -= 1
        # One blur per box: the nearest card's (cards share a box only where they overlap).
        nearest = min(cards, key=lambda c: float(np.linalg.norm(c.T_camera_card.t)))
        du, dv = nearest.blur_px
        occluders = tuple(Occluder(index, polygon, self.wall_rgb)
                          for index, card in enumerate(cards) for polygon in card.occluders)
        box_options = replace(options, supersample=s, gain=options.gain * light,
                              gradient=gradient, gradient_angle_deg=math.degrees(box_angle),
                              motion_blur_px=math.hypot(du, dv),
                              motion_blur_angle_deg=math.degrees(math.atan2(dv, du)),
                              occluders=occluders, jpeg_quality=None, seed=seed)
        placements = [CardPlacement(card.T_camera_card, card.face) for card in cards]
        return render_scene(crop, placements, box_options).image

    def _noisy_background(self, width: int, height: int, rng: np.random.Generator
                          ) -> np.ndarray:
        """Return a new image of the background with sensor noise."""
        key = (width, height)
        if key not in self._frames:
            blank = CameraModel.from_focal(width, height, 1000.0)
            clean = render_scene(blank, [], replace(self.options, noise_sigma=0.0,
                                                    jpeg_quality=None, seed=0)).image
            noise = np.rint(np.random.default_rng(_NOISE_SEED).normal(
                0.0, self.options.noise_sigma, (height + _NOISE_PAD, width + _NOISE_PAD, 3)))
            # Saturating uint8 add and subtract: the cheapest way to add noise per frame.
            self._frames[key] = (clean, np.clip(noise, 0, 255).astype(np.uint8),
                                 np.clip(-noise, 0, 255).astype(np.uint8))
        clean, up, down = self._frames[key]
        frame = clean.copy()
        if self.options.noise_sigma > 0:
            dy, dx = (int(v) for v in rng.integers(0, _NOISE_PAD + 1, 2))
            cv2.add(frame, up[dy:dy + height, dx:dx + width], dst=frame)
            cv2.subtract(frame, down[dy:dy + height, dx:dx + width], dst=frame)
        return frame
