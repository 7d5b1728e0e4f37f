"""
What the head's camera sees of a floor: rendering with walls, motion blur and fields.

ROS-free. :class:`FloorScene` renders the cards of a
:class:`~.floor_world.FloorWorld` seen from camera poses in the building
frame, with :class:`~.fast_render.BoxRenderer`:

* a card is drawn only from its printed side, and what walls, door jambs,
  lintels and obstacles hide of it is painted over in the wall's colour
  (``FloorWorld.occluders``); a card hidden whole is not drawn at all;
* **motion blur**: each field (or the progressive frame) is given the
  camera's pose at the start, middle and end of its exposure; a card is
  drawn at the middle pose and smeared along the straight line between
  where its centre images at the start and at the end (the motion during a
  20 ms exposure is that line to well under a pixel);
* **interlace**: two fields, each with its own poses, drawn into the even
  and the odd rows.

The truth of a view (:class:`CardView`) says which cards are in the image
and how much of each the walls and the image border leave.
"""

from dataclasses import dataclass
import math
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from .fast_render import (BoxCard, BoxRenderer, distortion_margin, field_camera, pixel_box,
                          UncodedFace)
from .floor_world import FloorWorld, WorldCard
from .render import DotCardTexture, NEAR_PLANE, RenderOptions
from .world import SIM_RENDER_OPTIONS
from ..card.pattern import Ids
from ..errors import ConfigError
from ..localization.head import HeadGeometry
from ..vision.camera import CameraModel
from ..vision.geometry import Pose

IdsKey = Tuple[int, int, int]
# Looks (render options) a scene keeps renderers for: a few shutters' worth.
MAX_LOOKS = 4


@dataclass(frozen=True)
class CardView:
    """
    One card in the image: how much of it can be seen, from where, how blurred.

    ``dots_visible``: its dots whose centres are in the image and not hidden
    by a wall (of ``dots_total``); ``complete`` when all are. ``distance_m``:
    camera centre to card centre. ``view_angle_deg``: the angle between the
    card's normal and the line to the camera (method.md's tilt phi).
    ``centre_px``: where its centre images. ``off_axis_deg``: the angle
    between the optical axis and the line to the card's centre.
    """

    ids: Ids
    dots_visible: int
    dots_total: int
    complete: bool
    distance_m: float
    view_angle_deg: float
    centre_px: Tuple[float, float]
    off_axis_deg: float


@dataclass(frozen=True)
class Field:
    """The camera's pose (``T_building_camera``) at the start, middle and end of an exposure."""

    start: Pose
    middle: Pose
    end: Pose

    @staticmethod
    def still(pose: Pose) -> 'Field':
        """Return the exposure of a camera that does not move."""
        return Field(pose, pose, pose)


class FloorScene:
    """
    The floor as the head's camera sees it (see the module docstring).

    ``options``: the look of the images (default ``world.SIM_RENDER_OPTIONS``,
    no motion blur of its own: blur comes from the motion). Not thread-safe.
    """

    def __init__(self, world: FloorWorld, head: Optional[HeadGeometry] = None,
                 options: RenderOptions = SIM_RENDER_OPTIONS) -> None:
        self.world = world
        self.head = head or HeadGeometry()
        self.options = options
        # One renderer per look (a shutter's gain changes it): each caches its
        # background and noise per image size, so only the few looks in use.
        self._renderers: Dict[RenderOptions, BoxRenderer] = {options: BoxRenderer(options)}
        # Card textures are built once, when a card is first drawn.
        self._faces: Dict[IdsKey, UncodedFace] = {}
        self._centres = np.array([c.T_building_card.t for c in world.cards]).reshape(-1, 3)
        self._normals = np.array([c.T_building_card.R[:, 2] for c in world.cards]
                                 ).reshape(-1, 3)
        self._dots = world.pattern.model_points()
        self._half = float(world.pattern.card_size) / 2.0

    # Head and truth -------------------------------------------------------------------

    def true_camera_pose(self, T_building_base: Pose, pan: float, tilt: float) -> Pose:
        """Return ``T_building_camera`` of the optical frame at these head angles (rad)."""
        return T_building_base @ self.head.T_base_camera(pan, tilt)

    def card_angles(self, T_building_base: Pose, pan: float, tilt: float,
                    ids: IdsKey) -> Tuple[float, float]:
        """
        Return the head motion (pan, tilt, rad) that puts the card's centre on the optical axis.

        REP 103 signs: + pan = turn left, + tilt = look up; wrapped to
        [-pi, pi). Exact for the head's offsets; not clipped to the travel.
        """
        centre = self.world.card(ids).T_building_card.t
        aim_pan, aim_tilt = self.head.aim_angles(T_building_base.inverse().apply(centre[None])[0])
        return _wrap(aim_pan - pan), _wrap(aim_tilt - tilt)

    def oracle_gaze(self, T_building_base: Pose, max_distance_m: float = 8.0,
                    max_view_deg: float = 65.0) -> Optional[Tuple[IdsKey, float, float]]:
        """
        Return the nearest card the head could look at whole, and the (pan, tilt) aiming at it.

        An oracle from the truth (for benchmarks, tests and survey walks, not
        a driver): a card whose every dot is in sight of the camera aimed at
        it, within ``max_distance_m`` and ``max_view_deg`` of its normal,
        with head angles inside the travel limits. None if there is none.
        """
        best = None
        base_eye = T_building_base.apply(np.array([self.head.base_to_pan_xyz]))[0]
        rel = self._centres - base_eye
        distance = np.linalg.norm(rel, axis=1)
        cos_view = -np.einsum('ij,ij->i', rel, self._normals) / np.maximum(distance, 1e-9)
        limit = math.cos(math.radians(max_view_deg))
        for k in np.argsort(distance):
            if distance[k] > max_distance_m:
                break
            if cos_view[k] < limit:
                continue
            card = self.world.cards[int(k)]
            key = card.ids.as_tuple()
            try:
                pan, tilt = self.card_angles(T_building_base, 0.0, 0.0, key)
            except ValueError:
                continue
            if not self.head.within_limits(pan, tilt):
                continue
            eye = self.true_camera_pose(T_building_base, pan, tilt).t
            if self.world.visible_dots(card, eye).all():
                best = (key, pan, tilt)
                break
        return best

    def candidates(self, T_building_camera: Pose, camera: CameraModel,
                   margin_px: float = 0.0) -> List[WorldCard]:
        """Return the cards printed side towards the camera whose square may be in the image."""
        eye = T_building_camera.t
        facing = np.einsum('ij,ij->i', eye - self._centres, self._normals) > 1e-3
        # A cone test first (cheap, for all cards at once): the card's centre
        # within the field of view widened by the card's own angular size.
        local = (self._centres - eye) @ T_building_camera.R
        reach = self._half * math.sqrt(2.0)
        slack = 1.5 + distortion_margin(camera) / min(camera.fx, camera.fy)
        tan_x = slack * (max(camera.cx, camera.width - camera.cx) + margin_px) / camera.fx
        tan_y = slack * (max(camera.cy, camera.height - camera.cy) + margin_px) / camera.fy
        depth = local[:, 2] + reach
        near = ((depth > 0.0) & (np.abs(local[:, 0]) - reach <= tan_x * depth)
                & (np.abs(local[:, 1]) - reach <= tan_y * depth))
        T_camera_building = T_building_camera.inverse()
        out = []
        for k in np.flatnonzero(facing & near):
            card = self.world.cards[int(k)]
            T_camera_card = T_camera_building @ card.T_building_card
            if pixel_box(camera, T_camera_card, self._half, margin_px) is not None:
                out.append(card)
        return out

    def views(self, T_building_camera: Pose, camera: CameraModel,
              occluders: Optional[Dict[IdsKey, List[np.ndarray]]] = None) -> List[CardView]:
        """
        Return the cards with at least one dot in the image and in sight, by ids.

        ``occluders``: the walls' shadows per card from this camera's centre,
        if already computed (:meth:`occluders_for`).
        """
        eye = T_building_camera.t
        T_camera_building = T_building_camera.inverse()
        out = []
        for card in self.candidates(T_building_camera, camera):
            key = card.ids.as_tuple()
            shadows = (occluders[key] if occluders is not None and key in occluders
                       else self.world.occluders(card, eye))
            seen = self.world.visible_dots(card, eye, shadows)
            dots = (T_camera_building @ card.T_building_card).apply(self._dots)
            in_front = dots[:, 2] > NEAR_PLANE
            pixels = np.full((len(dots), 2), np.nan)
            if in_front.any():
                pixels[in_front] = camera.project(dots[in_front])
            inside = in_front & (pixels[:, 0] >= -0.5) & (pixels[:, 0] < camera.width - 0.5) \
                & (pixels[:, 1] >= -0.5) & (pixels[:, 1] < camera.height - 0.5)
            visible = int(np.count_nonzero(seen & inside))
            if visible == 0:
                continue
            rel = eye - card.T_building_card.t
            distance = float(np.linalg.norm(rel))
            cos_view = float(rel @ card.T_building_card.R[:, 2]) / distance
            centre = T_camera_building.apply(card.T_building_card.t[None])[0]
            off_axis = math.degrees(math.acos(min(1.0, centre[2] / np.linalg.norm(centre))))
            out.append(CardView(card.ids, visible, len(dots), visible == len(dots), distance,
                                math.degrees(math.acos(min(1.0, cos_view))),
                                (float(pixels[0, 0]), float(pixels[0, 1])), off_axis))
        return out

    def occluders_for(self, T_building_camera: Pose, camera: CameraModel
                      ) -> Dict[IdsKey, List[np.ndarray]]:
        """Return the walls' shadows on every candidate card from this camera's centre."""
        eye = T_building_camera.t
        return {c.ids.as_tuple(): self.world.occluders(c, eye)
                for c in self.candidates(T_building_camera, camera)}

    # Images ---------------------------------------------------------------------------

    def render(self, camera: CameraModel, fields: Sequence[Field], seed: int = 0,
               blur: bool = True, options: Optional[RenderOptions] = None
               ) -> Tuple[np.ndarray, Dict[IdsKey, float]]:
        """
        Return the BGR uint8 image and each drawn card's motion blur (pixels, frame rows).

        One field: a progressive frame; two: an interlaced frame, field ``p``
        in the rows of parity ``p``. ``blur=False`` draws every card sharp at
        its field's middle pose. ``options``: this frame's look (e.g. a
        shutter's gain and noise, ``Exposure.image_options``), else the
        scene's. Deterministic for a seed.
        """
        if len(fields) not in (1, 2):
            raise ConfigError(f'sim: a frame has 1 or 2 fields, got {len(fields)}')
        renderer = self._renderer(options if options is not None else self.options)
        blurs: Dict[IdsKey, float] = {}
        if len(fields) == 1:
            cards = self._box_cards(camera, fields[0], blur, blurs, 1.0)
            return renderer.render(camera, cards, seed), blurs
        drawn = [self._box_cards(field_camera(camera, parity), f, blur, blurs, 2.0)
                 for parity, f in enumerate(fields)]
        return renderer.render_fields(camera, drawn, seed), blurs

    def _renderer(self, options: RenderOptions) -> BoxRenderer:
        if options not in self._renderers:
            if len(self._renderers) >= MAX_LOOKS:
                # Bounded: a camera stepping through shutters keeps the newest looks.
                del self._renderers[next(k for k in self._renderers if k != self.options)]
            self._renderers[options] = BoxRenderer(options)
        return self._renderers[options]

    def render_still(self, T_building_camera: Pose, camera: CameraModel, seed: int = 0
                     ) -> np.ndarray:
        """Return the image of a camera standing still at ``T_building_camera``."""
        return self.render(camera, [Field.still(T_building_camera)], seed)[0]

    def _face(self, card: WorldCard) -> UncodedFace:
        key = card.ids.as_tuple()
        if key not in self._faces:
            self._faces[key] = UncodedFace(DotCardTexture(self.world.pattern, card.code))
        return self._faces[key]

    def _box_cards(self, camera: CameraModel, exposure: Field, blur: bool,
                   blurs: Dict[IdsKey, float], row_scale: float) -> List[BoxCard]:
        """Return the cards to draw for one field, each with its shadows and its blur."""
        eye = exposure.middle.t
        T_middle = exposure.middle.inverse()
        T_start, T_end = exposure.start.inverse(), exposure.end.inverse()
        out = []
        margin = 4.0 * self.options.defocus_sigma_px + 2.0
        for card in self.candidates(exposure.middle, camera, margin):
            shadows = self.world.occluders(card, eye)
            if self.world.hidden(card, shadows):
                continue
            motion = (0.0, 0.0)
            if blur:
                ends = np.array([T_start.apply(card.T_building_card.t[None])[0],
                                 T_end.apply(card.T_building_card.t[None])[0]])
                if np.all(ends[:, 2] > NEAR_PLANE):
                    a, b = camera.project(ends)
                    motion = (float(b[0] - a[0]), float(b[1] - a[1]))
            key = card.ids.as_tuple()
            length = math.hypot(motion[0], motion[1] * row_scale)
            blurs[key] = max(blurs.get(key, 0.0), length)
            out.append(BoxCard(T_middle @ card.T_building_card, self._face(card),
                               tuple(shadows), motion))
        return out


def _wrap(angle: float) -> float:
    """Return the angle in [-pi, pi)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi
