"""
From one image to the robot's place in the building (ROS-free core of the locator node).

For each image: find the cards, estimate the camera pose from each with
what the robot knows (the head's angles give "up" and the camera's height,
the last fix gives continuity), look the card up in the building map, and
compose the base pose: ``T_frame_base = T_frame_card T_card_camera
T_camera_base(pan, tilt)``. Each card's fix must pass the plausibility
gates (:mod:`.gates`: finite, positive definite, camera in front of the
card, base on the floor of its room); several cards in view: the paper's
rule (the biggest complete card) or a covariance-weighted fusion of them.
Given the image's stamp, the fix must also be continuous with the last one
(a jump waits for a second agreeing image; odometry since the last fix,
``odom.OdomBuffer.motion_between``, says how far the robot can have moved).
A fix's covariance is :mod:`.uncertainty`'s model, term by term
(``RobotFix.uncertainty``): the image's, the head's angles at the image's
stamp (pass ``head_motion`` from ``JointStateBuffer.motion_at`` and the
base's twist), the map's own; ``uncertainty=None`` gives the estimator's
Fisher covariance alone, as before issue 12. A :class:`FrameResult` without
a fix says why (``no_fix_reason``) and which gates refused what
(``rejections``); :meth:`RobotLocalizer.rejection_counts` counts them.
"""

import dataclasses
from dataclasses import dataclass
import math
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from .building import BuildingMap, MappedCard
from .gates import BaseMotion, FixGates, FLIP_VALLEY_BARRIER, GateParameters, Rejection
from .head import base_pose_from_camera, covariance_to_base, HeadGeometry, HeadMotion, up_in_camera
from .odom import BaseTwist
from .uncertainty import fix_covariance, FixCovariance, UncertaintyParameters
from ..card.pattern import Ids, PatternConfig
from ..errors import CodeError, ConfigError
from ..vision.camera import CameraModel
from ..vision.detector import CardDetection
from ..vision.geometry import Pose, rodrigues, rotation_vector
from ..vision.locate import CardLocator, LocatedCard
from ..vision.pose_exact import PosePrior

OUTPUT_FRAMES = ('room', 'building')
FUSION_MODES = ('biggest', 'fused')


@dataclass(frozen=True)
class RobotFix:
    """The robot base's pose from one image, with what it came from."""

    ids: Ids                       # the card used (the biggest one when fused)
    frame_id: str                  # room frame name, or the building frame
    T_frame_base: Pose
    covariance: np.ndarray         # 6x6: base position (m), rotation about the frame's axes (rad)
    T_camera_card: Pose
    target_pan: float              # head motion that would centre the card (rad, + = left)
    target_tilt: float             # (rad, + = up)
    size_px: float                 # the card's apparent size (outer ring semi-axis, px)
    ambiguity: float
    cards_used: int
    # The covariance term by term (uncertainty.TERMS), None when the
    # estimator's own covariance is used (``uncertainty=None``) or fused.
    uncertainty: Optional[FixCovariance] = None


@dataclass(frozen=True)
class FrameResult:
    """Everything one image gave: the fix (if any), targets, and why cards were not used."""

    fix: Optional[RobotFix]
    cards_seen: int
    problems: Tuple[str, ...]
    target: Optional[Tuple[float, float, float]]   # pan, tilt, size of the biggest card seen
    detections: Tuple[CardDetection, ...] = ()
    # Reasons (gates.REASONS) of the gates that refused a fix in this image.
    rejections: Tuple[str, ...] = ()
    # Without a fix: why, in one line ('' when there is a fix).
    no_fix_reason: str = ''


class RobotLocalizer:
    """Locate the robot base from images, a building map and the head's geometry."""

    def __init__(self, pattern: PatternConfig, building: BuildingMap, head: HeadGeometry,
                 estimator: str = 'exact', output_frame: str = 'room',
                 fusion: str = 'biggest', min_tilt_deg: float = 0.0,
                 max_reprojection_px: float = 1.5, camera_height_sigma: float = 0.15,
                 up_sigma_deg: float = 5.0, gates: Optional[GateParameters] = None,
                 uncertainty: Optional[UncertaintyParameters] = UncertaintyParameters()):
        if output_frame not in OUTPUT_FRAMES:
            raise ConfigError(f'output frame must be one of {", ".join(OUTPUT_FRAMES)}, '
                              f'got {output_frame!r}')
        if fusion not in FUSION_MODES:
            raise ConfigError(f'fusion must be one of {", ".join(FUSION_MODES)}, got {fusion!r}')
        self.pattern = pattern
        self.building = building
        self.head = head
        # The map's codes let the detector complete a card partly hidden by an
        # object when exactly one mapped code fits what is seen.
        self.locator = CardLocator(pattern, estimator=estimator, min_tilt_deg=min_tilt_deg,
                                   known_codes=[card.code for card in building.cards()])
        self.output_frame = output_frame
        self.fusion = fusion
        self.max_reprojection_px = max_reprojection_px
        self.camera_height_sigma = camera_height_sigma
        self.up_sigma = math.radians(up_sigma_deg)
        self.gates = FixGates(building, gates)
        # None: the estimator's Fisher covariance alone (as before issue 12).
        self.uncertainty = uncertainty
        self._model_points = pattern.model_points()
        self.last_fix: Optional[RobotFix] = None

    def rejection_counts(self) -> Dict[str, int]:
        """Return how many fixes each gate refused so far (every reason of gates.REASONS)."""
        return self.gates.counts()

    @property
    def last_fix_stamp(self) -> Optional[float]:
        """Return the stamp of the last fix returned: odometry is measured from it."""
        return self.gates.last_stamp

    def reset(self) -> None:
        """Forget the last fix (continuity and the pose prior start over)."""
        self.gates.reset()
        self.last_fix = None

    def process(self, image: np.ndarray, camera: CameraModel, pan: float, tilt: float,
                stamp_s: Optional[float] = None, odometry: Optional[BaseMotion] = None,
                head_motion: Optional[HeadMotion] = None,
                base_twist: Optional[BaseTwist] = None) -> FrameResult:
        """
        Locate the robot in one image taken with the head at ``pan``, ``tilt`` (rad).

        ``stamp_s``: the image's time (seconds); without it the continuity
        gate is off (nothing to judge motion by) and every fix that passes
        the static gates is returned. ``odometry``: the base's motion since
        :attr:`last_fix_stamp`, for the continuity gate (else the maximum
        speed and yaw rate of the gate parameters bound the motion).
        ``head_motion``: the head's rates at the stamp
        (``JointStateBuffer.motion_at``; its angles are ``pan``, ``tilt``);
        ``base_twist``: the base's (``OdomBuffer.twist_at``). Both feed the
        covariance (:mod:`.uncertainty`); without them the head and the base
        are taken as still.
        """
        motion = HeadMotion.still(pan, tilt) if head_motion is None else HeadMotion(
            float(pan), float(tilt), head_motion.pan_rate, head_motion.tilt_rate,
            head_motion.rate_change, head_motion.interval_s, head_motion.hold_s)
        detections = sorted(self.locator.detector.detect(image, camera),
                            key=lambda d: -d.size_px)
        problems: List[str] = []
        rejections: List[str] = []
        target = None
        fixes: List[RobotFix] = []
        T_base_camera = self.head.T_base_camera(pan, tilt)
        for det in detections:
            if target is None:
                target = (*_head_motion(camera, det.centre_px), det.size_px)
            if det.ids is None and det.candidates:
                fix, rejection = self._choose(det, camera, T_base_camera, motion, base_twist,
                                              stamp_s, odometry)
                if rejection is not None:
                    problems.append(rejection.message)
                    rejections.append(rejection.reason)
                else:
                    fixes.append(fix)
                continue
            if det.ids is None:
                problems.append('grey image: cards have no code, so no location')
                continue
            try:
                mapped = self.building.card(det.ids)
            except CodeError as exc:
                problems.append(str(exc))
                continue
            prior = self._prior(mapped, T_base_camera, pan, tilt)
            located = self.locator.pose_of(det, camera, prior)
            if located.T_camera_pattern is None:
                problems.append(f'card {det.code}: {located.problem}')
                continue
            if self._too_rough(located):
                problems.append(f'card {det.code}: reprojection error '
                                f'{located.reprojection_rms_px:.2f} px above the limit '
                                f'{self.max_reprojection_px:.2f} px')
                continue
            fix, rejection = self._fix(det, mapped, located, camera, motion, base_twist)
            if rejection is None:
                flip = self._unsure_flip(det, mapped, located, fix, camera, motion, base_twist,
                                         stamp_s, odometry)
                if flip is not None:
                    rejection = self.gates.count(Rejection('planar_flip', flip))
            if rejection is None and det.slots_from_map:
                rejection = self.gates.check_partial(fix.T_frame_base, fix.covariance,
                                                     fix.frame_id, stamp_s, odometry,
                                                     f'card {det.code}')
            if rejection is not None:
                problems.append(f'card {det.code}: {rejection.message}')
                rejections.append(rejection.reason)
                continue
            fixes.append(fix)

        def without_fix(reason: str) -> FrameResult:
            return FrameResult(None, len(detections), tuple(problems), target,
                               tuple(detections), tuple(rejections), reason)

        if not fixes:
            return without_fix(problems[0] if problems else 'no card seen')
        if self.fusion == 'fused' and len(fixes) > 1:
            fix = _fuse(fixes)
            rejection = self.gates.check(fix.T_frame_base, fix.covariance, fix.frame_id,
                                         self._room(fix))
            if rejection is not None:
                problems.append(f'fused fix: {rejection.message}')
                rejections.append(rejection.reason)
                return without_fix(problems[-1])
        else:
            # The paper's rule: the biggest complete card (detections are biggest first).
            fix = fixes[0]
        rejection = self.gates.check_continuity(fix.T_frame_base, fix.covariance, fix.frame_id,
                                                stamp_s, odometry)
        if rejection is not None:
            problems.append(rejection.message)
            rejections.append(rejection.reason)
            return without_fix(rejection.message)
        self.last_fix = fix
        return FrameResult(fix, len(detections), tuple(problems), target, tuple(detections),
                           tuple(rejections))

    def _choose(self, det: CardDetection, camera: CameraModel, T_base_camera: Pose,
                motion: HeadMotion, twist: Optional[BaseTwist], stamp_s: Optional[float],
                odometry: Optional[BaseMotion]) -> Tuple[Optional[RobotFix], Optional[Rejection]]:
        """
        Return the fix of the one hypothesis of a partly hidden card that fits the last fix.

        The slots an object hides leave several mapped codes (``det.candidates``,
        each with its own point 1). Each is located and its fix measured
        against where the last fix puts the robot (the jump test), nothing
        counted. The card gives a fix only when exactly one hypothesis is
        within the jump limit and it passes the static gates; every other must
        be shown to be elsewhere, so one that has no pose, or a gate refuses
        (it may still be where the robot is), blocks the answer. Cards that
        share the slots seen hang in other places (a room's other cards, the
        next floor's card of the same number, a turn of the card's own code),
        so at most one of them puts the robot where it can be; with no last
        fix there is nothing to judge by.
        """
        label = f'card with {det.slots_from_map} slot(s) hidden'
        limit = self.gates.parameters.max_jump_mahalanobis
        near: List[Tuple[Optional[RobotFix], bool]] = []
        for option in det.candidates:
            try:
                mapped = self.building.card(option.ids)
            except CodeError:
                continue           # not in this map (the detector's codes are the map's)
            prior = self._prior(mapped, T_base_camera, motion.pan, motion.tilt)
            located = self.locator.pose_of(option, camera, prior)
            if located.T_camera_pattern is None:
                near.append((None, False))      # not shown to be elsewhere
                continue
            fix, rejection = self._fix(option, mapped, located, camera, motion, twist,
                                       counted=False)
            usable = rejection is None and not self._too_rough(located) and (
                self._unsure_flip(option, mapped, located, fix, camera, motion, twist, stamp_s,
                                  odometry) is None)
            covariance = fix.covariance
            if covariance is None or np.shape(covariance) != (6, 6) or \
                    not np.all(np.isfinite(covariance)):
                covariance = np.zeros((6, 6))   # the jump test's floors alone
            distance = self.gates.distance_from_last(fix.T_frame_base, covariance,
                                                     fix.frame_id, stamp_s, odometry)
            if distance is None:
                return None, self.gates.count(Rejection(
                    'partial_code', f'{label}: {len(det.candidates)} mapped codes fit the '
                    'slots seen; chosen only by a last fix of the last '
                    f'{self.gates.parameters.partial_code_max_age_s:g} s, and there is none'))
            if not distance > limit:            # NaN: not shown to be elsewhere
                near.append((fix, usable))
        if len(near) == 1 and near[0][1]:
            return near[0][0], None
        return None, self.gates.count(Rejection(
            'partial_code', f'{label}: {len(near)} of the {len(det.candidates)} mapped codes '
            'that fit the slots seen may be where its last fix puts the robot (one needed, '
            'passing the gates)'))

    def _unsure_flip(self, det: CardDetection, mapped: MappedCard, located: LocatedCard,
                     fix: RobotFix, camera: CameraModel, motion: HeadMotion,
                     twist: Optional[BaseTwist], stamp_s: Optional[float],
                     odometry: Optional[BaseMotion]) -> Optional[str]:
        """
        Return why a fix rests on an unsure choice between the card's two planar poses, or None.

        Far away and nearly face on, a card fits its dots almost as well
        turned the other way about an axis in its plane (the planar flip).
        About a horizontal axis the head's "up" and the camera's height tell
        the two apart; about the card's vertical axis nothing the robot
        knows does, and the wrong one, a metre off with a covariance of
        centimetres, wins often enough to matter. Nearer face on the two
        lie in one shallow valley of the fit, or merge into one pose, whose
        turn the dots' sub-pixel errors set (half a metre off at 5.8 m,
        four to eight sigmas, as the card's image shifts by fractions of a
        pixel). So in one valley (``flip_barrier`` below
        :data:`FLIP_VALLEY_BARRIER`) there is no fix, even where up and
        height choose the side: the valley runs on around the card's normal
        too, where neither tells anything (a card 1 m above the camera, 8 m
        away: poses a metre off sideways at 4-9 sigmas). Else, when the
        other pose is not ruled out by the image and the prior
        (``other_probability`` above ``max_flip_probability``), the fix
        stands only if a static gate refuses the other pose (outside the
        room, behind the card, ...) or the last fix makes it that unlikely
        (the jump test's distances of the two as likelihoods). Nothing is
        counted here.
        """
        p = self.gates.parameters
        if located.alternative is None:
            return None
        if not located.flip_barrier >= FLIP_VALLEY_BARRIER:
            # One shallow valley: its floor sets the pose, whichever side.
            return (f'planar flip unsure: the card lies in one shallow valley of the fit with '
                    f'its other pose (barrier {located.flip_barrier:.2g}; seen this far and '
                    'this nearly face on, it does not show which way it is turned): no fix')
        if located.other_probability <= p.max_flip_probability:
            return None
        other_located = dataclasses.replace(located, T_camera_pattern=located.alternative,
                                            prior_information=None)
        other, refused = self._fix(det, mapped, other_located, camera, motion, twist,
                                   counted=False)
        if refused is not None and refused.reason not in ('not_finite', 'covariance'):
            return None                         # the other pose is not where a robot can be
        metres = float(np.linalg.norm(other.T_frame_base.t - fix.T_frame_base.t))
        # One leading phrase for every message: the node counts problems by it.
        chance = (f'planar flip unsure: the other pose {100.0 * located.other_probability:.2g} '
                  f'% likely ({metres:.2f} m away)')
        if refused is not None:
            return f'{chance}, and its fix has no usable covariance'
        # Any age: as the last fix ages, odometry's covariance or the speed
        # limits make the two distances alike, and then they decide nothing.
        chosen = self.gates.distance_from_last(fix.T_frame_base, fix.covariance, fix.frame_id,
                                               stamp_s, odometry, math.inf)
        rival = self.gates.distance_from_last(other.T_frame_base, other.covariance,
                                              other.frame_id, stamp_s, odometry, math.inf)
        if chosen is None:
            return (f'{chance}, and no last fix to choose by: no fix until a view or the '
                    'last fix decides')
        # Continuity's evidence: the jump test's distances as likelihoods.
        probability = _posterior(located.other_probability, chosen, rival)
        if probability <= p.max_flip_probability:
            return None
        return (f'{chance}; {100.0 * probability:.2g} % with the last fix (Mahalanobis '
                f'{chosen:.3g} and {rival:.3g} from it): no fix')

    def _too_rough(self, located) -> bool:
        """Tell whether a located card's reprojection error is above the limit."""
        return located.reprojection_rms_px is not None and (
            located.reprojection_rms_px > self.max_reprojection_px)

    def _room(self, fix: RobotFix):
        """Return the room of the card a fix came from."""
        return self.building.room(fix.ids.floor, fix.ids.room)

    def _prior(self, mapped: MappedCard, T_base_camera: Pose, pan: float, tilt: float
               ) -> Optional[PosePrior]:
        """Return what the robot knows before the image: up, camera height, last position."""
        card_up = mapped.T_building_card.R[:, 1]
        upright = card_up[2] > math.cos(math.radians(5.0))
        up = up_in_camera(self.head, pan, tilt) if upright else None
        height = None
        if upright:
            # Base on the room's floor: the camera's height relative to the card.
            height = float(T_base_camera.t[2] - mapped.T_room_card.t[2])
        previous = None
        if self.last_fix is not None and self.last_fix.ids == mapped.ids:
            previous = self.last_fix.T_camera_card.inverse().t
        if up is None and height is None and previous is None:
            return None
        return PosePrior(up_in_camera=up, up_sigma_rad=self.up_sigma, camera_height=height,
                         height_sigma=self.camera_height_sigma,
                         previous_camera_in_pattern=previous)

    def _fix(self, det, mapped: MappedCard, located, camera: CameraModel, motion: HeadMotion,
             twist: Optional[BaseTwist], counted: bool = True
             ) -> Tuple[Optional[RobotFix], Optional[Rejection]]:
        """Return the base's fix from one card and why the gates refuse it (or None: use it)."""
        pan, tilt = motion.pan, motion.tilt
        T_camera_card = located.T_camera_pattern
        if self.output_frame == 'room':
            T_frame_card, frame_id = mapped.T_room_card, mapped.room_frame
        else:
            T_frame_card, frame_id = mapped.T_building_card, self.building.frame
        T_frame_base = base_pose_from_camera(T_frame_card, T_camera_card, self.head, pan, tilt)
        covariance = None
        terms = None
        if self.uncertainty is not None and located.reprojection_rms_px is not None:
            seen = ~np.isnan(np.asarray(det.points_px, dtype=float)).any(axis=1)
            with np.errstate(all='ignore'):
                try:
                    terms = fix_covariance(self.uncertainty, camera, self._model_points, seen,
                                           located.reprojection_rms_px, T_camera_card,
                                           T_frame_card, T_frame_base, mapped, self.head,
                                           motion, twist, located.prior_information)
                    covariance = terms.total
                except (ValueError, np.linalg.LinAlgError):
                    covariance = None      # the covariance gate says so
        elif located.covariance is not None and np.shape(located.covariance) == (6, 6):
            with np.errstate(all='ignore'):
                covariance = covariance_to_base(located.covariance, T_frame_card,
                                                T_camera_card, self.head, pan, tilt)
        room = self.building.room(mapped.ids.floor, mapped.ids.room)
        rejection = self.gates.check(T_frame_base, covariance, frame_id, room, T_camera_card,
                                     counted)
        pan_to, tilt_to = _head_motion_from_pose(T_camera_card)
        # Returned with its rejection too: a hypothesis refused by a gate may
        # still be where the robot is (_choose).
        return RobotFix(det.ids, frame_id, T_frame_base, covariance, T_camera_card, pan_to,
                        tilt_to, det.size_px, float(located.ambiguity or math.inf), 1,
                        terms), rejection


def _posterior(other_probability: float, chosen_distance: float, rival_distance: float
               ) -> float:
    """
    Return the other planar pose's probability once the last fix's evidence is in.

    The odds from the image, up and height, times the likelihood ratio of
    the two poses' jump-test distances (Mahalanobis) from where the last
    fix puts the robot. Not finite: 1.0 (nothing shown).
    """
    if not (math.isfinite(chosen_distance) and math.isfinite(rival_distance)
            and 0.0 <= other_probability <= 1.0):
        return 1.0
    p = min(max(other_probability, 1e-300), 1.0 - 1e-16)
    log_odds = (math.log(p) - math.log1p(-p)
                - 0.5 * (rival_distance ** 2 - chosen_distance ** 2))
    return 1.0 / (1.0 + math.exp(min(-log_odds, 700.0)))


def _head_motion(camera: CameraModel, centre_px: np.ndarray) -> Tuple[float, float]:
    """Pan and tilt (rad, REP 103 signs) that bring a pixel onto the optical axis."""
    x, y = camera.normalize(np.asarray(centre_px, dtype=float)[None])[0]
    return -math.atan(x), -math.atan2(y, math.hypot(x, 1.0))


def _head_motion_from_pose(T_camera_card: Pose) -> Tuple[float, float]:
    x, y, z = T_camera_card.t
    return -math.atan2(x, z), -math.atan2(y, math.hypot(x, z))


def _fuse(fixes: Sequence[RobotFix]) -> RobotFix:
    """
    Combine fixes from several cards, weighting each by its information.

    All fixes must be in the same frame (the building frame, or one room);
    others are left out. Rotations are averaged as small corrections to the
    first fix's rotation.
    """
    base = fixes[0]
    same = [f for f in fixes if f.frame_id == base.frame_id]
    infos, means = [], []
    for f in same:
        info = np.linalg.pinv(f.covariance)
        delta_rot = rotation_vector(f.T_frame_base.R @ base.T_frame_base.R.T)
        infos.append(info)
        means.append(np.concatenate([f.T_frame_base.t, delta_rot]))
    total = np.sum(infos, axis=0)
    covariance = np.linalg.pinv(total)
    mean = covariance @ np.sum([i @ m for i, m in zip(infos, means)], axis=0)
    R = rodrigues(mean[3:]) @ base.T_frame_base.R
    return RobotFix(base.ids, base.frame_id, Pose(R, mean[:3]), covariance, base.T_camera_card,
                    base.target_pan, base.target_tilt, base.size_px, base.ambiguity, len(same))
