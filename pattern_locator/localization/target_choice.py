"""
The card the head's tracking loop should centre, and where it is in the image's frame.

ROS-free: what the locator node publishes on ``pattern_locator/target``.
The locator has the map, the fix, the odometry since and the head's
geometry; the camera driver has none of them and centres whatever target
it is given. Per image, :meth:`TargetChooser.choose` takes the cards seen
in it (:class:`SeenCard`: ids and centre in the optical frame), the base's
pose at the image's stamp (the last fix carried forward by odometry,
``odom.OdomBridge``; None without one), the head's angles at the stamp and
the base's twist, and returns a :class:`TargetChoice`:

* **no pose** (no odometry, no fix yet): the biggest card seen, as before
  the planner (``reason`` ``'no pose'``; :func:`biggest_seen`, also the
  rule with the planner switched off); none seen: no target;
* with a pose, the :class:`~.gaze.GazePlanner` chooses among the cards
  predicted visible, the card targeted last being the current one (the
  biggest card seen when there was none): while it keeps that card
  (``'keep'``) the target is the card **as seen**; at a **handover** (the
  current card leaves the view within the planner's lookahead), a much
  better card (``'better'``) or a first choice (``'new'``), the target is
  the planner's card: as seen when it is in the image, else its centre
  **predicted** in the optical frame from the pose, the map and the head's
  angles at the image's stamp (``source 'predicted'``); so the head turns
  to the next card before the current one leaves the view;
* no card predicted visible now: the card seen (``'unpredicted'``: the
  map-based planner is conservative, e.g. a card seen through a door);
  none seen: the planner's card that will be visible ``lookahead_s``
  ahead (``'ahead'``, predicted: the head turns to where it will appear,
  e.g. through the door the robot drives to; not counted missing), else
  **no target** (``'none predicted'``): the driver searches.

A predicted card that should be well inside the image but is not detected
in ``missing_frames`` images running (hidden by something the map does not
know) is left out of the planner's choice for ``exclude_s``.

A predicted centre can lie behind the image plane (the card more than 90
degrees off the optical axis): it is still the card's centre in the
optical frame, and the head's turn to it is ``-atan2(x, z)``.
"""

from dataclasses import dataclass
import math
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from .building import BuildingMap
from .gaze import GazeParameters, GazePlanner
from .head import HeadGeometry
from .odom import BaseTwist
from ..errors import ConfigError, PatternLocatorError
from ..vision.camera import CameraModel
from ..vision.geometry import Pose

IdsKey = Tuple[int, int, int]
SOURCES = ('seen', 'predicted', 'none')
# Why the target is what it is: the planner's reasons (gaze.REASONS) and these.
OWN_REASONS = ('no pose', 'unpredicted', 'none predicted', 'gaze off')


@dataclass(frozen=True)
class SeenCard:
    """
    A card detected in the image.

    ``ids``: its (floor, room, pattern) when it is in the building map, else
    None (a grey image, a code the map does not know). ``centre``: its
    centre in the optical frame (m): from its pose when located, else from
    its plane homography.
    """

    ids: Optional[IdsKey]
    centre: Tuple[float, float, float]


@dataclass(frozen=True)
class TargetChoice:
    """
    What to publish as the target of one image.

    ``point``: the card's centre in the image's optical frame (m), or None
    (no target: the driver searches). ``ids``: its card (None when unknown
    or no target). ``source``: ``'seen'`` (measured in this image),
    ``'predicted'`` (from the pose and the map) or ``'none'``. ``reason``:
    the planner's (``new``, ``keep``, ``better``, ``handover``) or one of
    :data:`OWN_REASONS`. ``visible_ahead``: the planner predicts the card
    visible over its lookahead too.
    """

    point: Optional[Tuple[float, float, float]]
    ids: Optional[IdsKey]
    source: str
    reason: str
    visible_ahead: bool = False


@dataclass(frozen=True)
class TargetParameters:
    """
    When a predicted card counts as missing.

    ``missing_frames``: images running in which it should have been seen
    (its predicted centre inside the image by ``edge_margin``, a fraction
    of the image's size) but was not; ``exclude_s``: how long it is then
    left out of the choice.
    """

    missing_frames: int = 5
    exclude_s: float = 5.0
    edge_margin: float = 0.15

    def __post_init__(self) -> None:
        if isinstance(self.missing_frames, bool) or not isinstance(self.missing_frames, int) \
                or self.missing_frames < 1:
            raise ConfigError(f'target: missing_frames must be an integer >= 1, got '
                              f'{self.missing_frames!r}')
        for name in ('exclude_s', 'edge_margin'):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not (
                    math.isfinite(value) and value >= 0.0):
                raise ConfigError(f'target: {name} must be a number >= 0, got {value!r}')
        if self.edge_margin >= 0.5:
            raise ConfigError('target: edge_margin must be below 0.5')


class TargetChooser:
    """
    The target of each image (module docstring). Not thread-safe: one worker calls it.

    ``building``: the map; ``head``: the head's geometry and travel;
    ``gaze``: the planner's parameters.
    """

    def __init__(self, building: BuildingMap, head: HeadGeometry,
                 gaze: Optional[GazeParameters] = None,
                 parameters: TargetParameters = TargetParameters()) -> None:
        self.building = building
        self.head = head
        self.parameters = parameters
        self.planner = GazePlanner(building, head, gaze)
        self._current: Optional[IdsKey] = None
        self._misses: Dict[IdsKey, int] = {}
        self._excluded: Dict[IdsKey, float] = {}        # ids -> excluded until (stamp)
        self._last_stamp: Optional[float] = None

    @property
    def current(self) -> Optional[IdsKey]:
        """Return the card targeted last (None: none yet, or the last image had no target)."""
        return self._current

    @property
    def excluded(self) -> Tuple[IdsKey, ...]:
        """Return the cards left out of the choice for now (found missing)."""
        return tuple(sorted(self._excluded))

    def set_gaze(self, gaze: GazeParameters) -> None:
        """Use new planner parameters from the next image on."""
        self.planner = GazePlanner(self.building, self.head, gaze)

    def reset(self) -> None:
        """Forget the current card and the missing ones."""
        self._current = None
        self._misses.clear()
        self._excluded.clear()
        self._last_stamp = None

    def choose(self, stamp_s: float, seen: Sequence[SeenCard],
               T_building_base: Optional[Pose], pan: float, tilt: float,
               twist: Optional[BaseTwist] = None, room_hint: Optional[Tuple[int, int]] = None,
               camera: Optional[CameraModel] = None) -> TargetChoice:
        """
        Return the target of the image taken at ``stamp_s`` (module docstring).

        ``seen``: the cards detected in it, biggest first; ``T_building_base``:
        the base's pose at ``stamp_s`` (None: no pose); ``pan``, ``tilt``: the
        head's angles at ``stamp_s`` (rad); ``twist``: the base's (for the
        lookahead); ``room_hint``: the last fix's (floor, room); ``camera``:
        the image's intrinsics (to tell a predicted card that should be in
        the image; without it no card is ever found missing).
        """
        stamp_s = float(stamp_s)
        if self._last_stamp is not None and stamp_s < self._last_stamp - 1.0:
            self.reset()                      # the clock went back (a replay)
        self._last_stamp = stamp_s
        for ids in [k for k, until in self._excluded.items() if until <= stamp_s]:
            del self._excluded[ids]
        by_ids = {s.ids: s for s in seen if s.ids is not None}
        for ids in by_ids:
            self._misses.pop(ids, None)
        if T_building_base is None:
            choice = biggest_seen(seen, 'no pose')
            self._current = choice.ids
            return choice
        current = self._current
        if current is None and by_ids:
            current = next(iter(by_ids))      # the biggest card seen that the map knows
        choice = self.planner.choose(T_building_base, current, twist, head_pan=pan,
                                     room_hint=room_hint, exclude=tuple(self._excluded))
        if choice is None or (choice.reason == 'ahead' and seen):
            # A card in the image gives fixes now; one ahead only once in sight.
            card = by_ids.get(current) if current is not None else None
            if card is None and seen:
                card = seen[0]
            if card is None:
                self._current = None
                return TargetChoice(None, None, 'none', 'none predicted')
            self._current = card.ids
            return TargetChoice(_point(card.centre), card.ids, 'seen', 'unpredicted')
        ids = choice.ids.as_tuple()
        self._current = ids
        if ids in by_ids:
            return TargetChoice(_point(by_ids[ids].centre), ids, 'seen', choice.reason,
                                choice.visible_ahead)
        point = self.predicted_centre(ids, T_building_base, pan, tilt)
        if choice.reason != 'ahead':          # not in sight yet: not missing
            self._count_miss(ids, point, camera, stamp_s)
        return TargetChoice(_point(point), ids, 'predicted', choice.reason,
                            choice.visible_ahead)

    def predicted_centre(self, ids: IdsKey, T_building_base: Pose, pan: float,
                         tilt: float) -> np.ndarray:
        """Return a card's centre in the optical frame for a base pose and head angles (m)."""
        T_building_camera = T_building_base @ self.head.T_base_camera(pan, tilt)
        centre = self.building.card(ids).T_building_card.t
        return T_building_camera.inverse().apply(np.asarray(centre, dtype=float)[None])[0]

    def _count_miss(self, ids: IdsKey, point: np.ndarray, camera: Optional[CameraModel],
                    stamp_s: float) -> None:
        """Count an image that should have shown the card and did not; exclude it after enough."""
        if camera is None or not _well_inside(point, camera, self.parameters.edge_margin):
            return
        misses = self._misses.get(ids, 0) + 1
        if misses >= self.parameters.missing_frames:
            self._misses.pop(ids, None)
            self._excluded[ids] = stamp_s + self.parameters.exclude_s
            self._current = None
        else:
            self._misses[ids] = misses


def card_centre_from_homography(H: np.ndarray, camera: CameraModel) -> Optional[np.ndarray]:
    """
    Return a card centre's position in the optical frame (m) from its plane homography.

    ``H`` maps the card plane (metres, centre at the origin) to undistorted
    pixels: ``H ~ K [r1 r2 t]``, so ``t`` is ``K^-1 H``'s third column
    scaled by the mean norm of the first two. None if it is degenerate.
    """
    try:
        M = np.linalg.solve(camera.K, np.asarray(H, dtype=float))
    except (np.linalg.LinAlgError, ValueError):
        return None
    scale = 0.5 * (np.linalg.norm(M[:, 0]) + np.linalg.norm(M[:, 1]))
    if not (math.isfinite(scale) and scale > 0.0):
        return None
    t = M[:, 2] / scale
    if t[2] < 0.0:
        t = -t
    return t if bool(np.all(np.isfinite(t))) and t[2] > 0.0 else None


def seen_cards(result, camera: CameraModel, building: BuildingMap
               ) -> Tuple[List[SeenCard], bool]:
    """
    Return the cards a frame detected (biggest first) with their centres, and a flag.

    ``result``: a ``localizer.FrameResult``. A card's centre comes from its
    pose when the fix used it (``fix.T_camera_card``), else from its plane
    homography; ``ids`` only for cards in ``building`` (a partly hidden
    card's, when the fix took one of its candidates). Cards whose centre
    is not a finite point in front of the camera are left out; the flag
    says whether the biggest card was (a problem to report).
    """
    seen: List[SeenCard] = []
    biggest_lost = False
    fix = result.fix
    for k, det in enumerate(result.detections):
        if fix is not None and det.ids is None:
            # A partly hidden card: the fix names the one of its candidates it took.
            det = next((c for c in det.candidates
                        if c.ids == fix.ids and c.size_px == fix.size_px), det)
        if fix is not None and fix.ids == det.ids and fix.size_px == det.size_px:
            point = np.asarray(fix.T_camera_card.t, dtype=float)
        else:
            point = card_centre_from_homography(det.homography, camera)
        if point is None or not bool(np.all(np.isfinite(point))) or point[2] <= 0.0:
            biggest_lost = biggest_lost or k == 0
            continue
        ids = None
        if det.ids is not None:
            try:
                ids = building.card(det.ids).ids.as_tuple()
            except PatternLocatorError:
                ids = None                # not in the map: only the no-pose rule takes it
        seen.append(SeenCard(ids, _point(point)))
    return seen, biggest_lost


def biggest_seen(seen: Sequence[SeenCard], reason: str) -> TargetChoice:
    """Return the biggest card seen as the target (the rule before the planner), or none."""
    if not seen:
        return TargetChoice(None, None, 'none', reason)
    return TargetChoice(_point(seen[0].centre), seen[0].ids, 'seen', reason)


def _point(values) -> Tuple[float, float, float]:
    x, y, z = (float(v) for v in np.asarray(values, dtype=float).reshape(3))
    return (x, y, z)


def _well_inside(point: np.ndarray, camera: CameraModel, margin: float) -> bool:
    """Return whether a point in the optical frame projects inside the image by ``margin``."""
    x, y, z = (float(v) for v in point)
    if not z > 0.0:
        return False
    u = camera.fx * x / z + camera.cx
    v = camera.fy * y / z + camera.cy
    return (margin * camera.width <= u <= (1.0 - margin) * camera.width
            and margin * camera.height <= v <= (1.0 - margin) * camera.height)
