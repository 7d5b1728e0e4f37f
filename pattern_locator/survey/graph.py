"""
The survey's factor graph: card and camera poses from sightings and odometry, with GTSAM.

Variables: one pose per card ``L(j)`` (building <- card) and one per frame
that saw a card ``X(i)`` (building <- base; the base is the camera itself
when the bag has no odometry or no mount). Factors:

* per sighting, a pose-graph factor ``X(i) -> L(j)`` measuring ``T_base_card
  = T_base_camera @ T_camera_card`` with the sighting's covariance, under a
  robust kernel (Huber by default), so that a bad sighting cannot drag the
  map; after each round, sightings far beyond the kernel are dropped;
* odometry between consecutive frames of one bag (never across bags), from
  the bag's odometry corrected for a per-bag **scale error** and **yaw bias**
  (rad per metre travelled); the two are estimated by alternating with the
  graph: given the poses they are a small least-squares fit, given them the
  poses are the graph's optimum; a few rounds converge;
* a **vertical** prior per card (its normal horizontal; switchable);
* an optional **nominal height** per card above the floor of a base that saw it;
* the gauge: every anchor's given pose, exactly; without anchors, the first
  card fixes the building frame (its position and heading exactly, its tilt
  left to the vertical priors and the odometry).

Only what is connected to the gauge through sightings and odometry is
optimised; the rest is reported unconnected. After the optimisation the
sightings' and the odometry's noise are re-scaled by their a-posteriori
variance factors (so that the covariances say what the residuals show), and
each card's covariance is its marginal in the building frame.
"""

from dataclasses import dataclass, field
import heapq
import math
import time
from typing import Dict, List, Optional, Sequence, Tuple

import gtsam
import numpy as np

from .factors import building_covariance, from_gtsam, to_gtsam
from .mapfile import MapCard
from .sightings import Sighting, tangent_covariances
from ..errors import ConfigError
from ..localization.building import wall_card_rotation
from ..vision.geometry import Pose, rodrigues

MAX_ODOM_GAP_S = 0.5
# Sightings whose whitened error is beyond this chi-square (6 dof, p = 1e-4) are dropped.
OUTLIER_CHI2 = 27.86
EXACT_SIGMA = 1e-6


def X(i: int) -> int:
    """Return the key of frame ``i``'s base pose."""
    return gtsam.symbol('x', i)


def L(j: int) -> int:
    """Return the key of card ``j``'s pose."""
    return gtsam.symbol('l', j)


@dataclass(frozen=True)
class SurveyOptions:
    """
    How the survey weighs what it knows.

    Odometry noise after calibration, a random walk: translation ``odom_sd_m
    + odom_sd_per_sqrt_m * sqrt(d)`` and heading ``odom_sd_yaw_rad +
    odom_sd_yaw_per_sqrt_m * sqrt(d)`` for a step of length d, isotropic in 3D
    when the odometry is the camera's own. ``rescale_noise``: the odometry's
    noise is then scaled (within ``odom_scale_bounds``) so that its residuals
    weigh like the sightings'.
    ``planar_sd``: z (m) and roll/pitch (rad) of a base's odometry step (loose:
    the floor below holds them).
    ``merge_m``, ``merge_s``: consecutive frames of a bag within this much
    odometry and time share one pose variable (a keyframe): the graph stays
    small at any frame rate, and every sighting is kept.
    ``level_floor``: the bases of a bag (with odometry and a known camera
    mount) stand on one floor plane, level within ``floor_level_sd_rad``
    (gravity: what keeps a long map from tilting), each base upright on it
    within ``base_tilt_sd_rad`` and at its height within ``base_height_sd_m``
    (an uneven floor does not accumulate, unlike odometry).
    """

    use_odometry: bool = True
    calibrate_odometry: bool = True
    vertical_prior: bool = True
    vertical_sd_rad: float = math.radians(0.3)
    card_height_m: Optional[float] = None
    card_height_sd_m: float = 0.02
    huber_k: float = 3.5
    odom_sd_m: float = 0.0002
    odom_sd_per_sqrt_m: float = 0.005
    odom_sd_yaw_rad: float = math.radians(0.005)
    odom_sd_yaw_per_sqrt_m: float = math.radians(0.2)
    planar_sd: float = 0.01
    merge_m: float = 0.25
    merge_s: float = 1.0
    level_floor: bool = True
    floor_level_sd_rad: float = math.radians(0.1)
    base_tilt_sd_rad: float = math.radians(0.2)
    base_height_sd_m: float = 0.003
    rescale_noise: bool = True
    odom_scale_bounds: Tuple[float, float] = (0.05, 20.0)
    max_rounds: int = 8
    first_card_tilt_sd_rad: float = math.radians(5.0)


@dataclass(frozen=True, eq=False)
class BagMotion:
    """
    What the graph needs of one bag besides its sightings.

    ``odom_*``: the raw odometry ``T_odom_base`` samples (None: no odometry).
    ``mounts``: ``T_base_camera`` per frame index (frames missing or None:
    the camera's place on the base is unknown then, so the frame stands
    alone). ``mount_source``: as ``bagio.Mount.source``; ``camera`` means
    the odometry, if any, is the camera's own (3D noise model).
    """

    name: str
    mount_source: str
    mounts: Dict[int, Optional[Pose]]
    odom_stamps_ns: Optional[np.ndarray] = None
    odom_R: Optional[np.ndarray] = None
    odom_p: Optional[np.ndarray] = None

    @property
    def has_odometry(self) -> bool:
        """Return True when the bag has odometry samples."""
        return self.odom_stamps_ns is not None and len(self.odom_stamps_ns) > 1


@dataclass(frozen=True, eq=False)
class SurveyResult:
    """
    The optimised map and what the optimisation found out on the way.

    ``card_position_covariance`` gives the joint covariance of several cards'
    positions (what a comparison that removes the frame needs).
    """

    cards: List[MapCard]
    frame_note: str
    # bag -> (scale, yaw bias rad/m) of the bags whose odometry was calibrated
    calibration: Dict[int, Tuple[float, float]]
    camera_paths: Dict[int, np.ndarray]                 # bag -> (N, 3) camera positions
    residuals: np.ndarray                               # whitened sighting residual norms
    sighting_variance_factor: float
    odometry_scale: Tuple[float, float]         # (translation, heading) on the model's sd
    outliers: int
    used_sightings: int
    frames: int
    rounds: int
    timings: Dict[str, float] = field(default_factory=dict)
    values: Optional[gtsam.Values] = None
    marginals: Optional[gtsam.Marginals] = None
    card_index: Dict[Tuple[int, int, int], int] = field(default_factory=dict)
    frame_keys: Dict[Tuple[int, int], int] = field(default_factory=dict)

    def card_position_covariance(self, ids: Sequence[Tuple[int, int, int]]) -> np.ndarray:
        """Return the joint (3N, 3N) covariance of cards' positions about the building axes."""
        keys = [L(self.card_index[i]) for i in ids]
        joint = self.marginals.jointMarginalCovariance(gtsam.KeyVector(keys)).fullMatrix()
        n = len(keys)
        A = np.zeros((3 * n, 6 * n))
        for k, key in enumerate(keys):
            A[3 * k:3 * k + 3, 6 * k + 3:6 * k + 6] = self.values.atPose3(key).rotation().matrix()
        return A @ joint @ A.T * self.sighting_variance_factor


# Odometry ---------------------------------------------------------------------------


def _rz(angles: np.ndarray) -> np.ndarray:
    c, s = np.cos(angles), np.sin(angles)
    out = np.zeros(angles.shape + (3, 3))
    out[..., 0, 0], out[..., 0, 1] = c, -s
    out[..., 1, 0], out[..., 1, 1] = s, c
    out[..., 2, 2] = 1.0
    return out


class _Odometry:
    """A bag's raw odometry and its correction for a scale error and a yaw bias."""

    def __init__(self, motion: BagMotion) -> None:
        self.stamps = np.asarray(motion.odom_stamps_ns, dtype=np.int64)
        self.R = np.asarray(motion.odom_R, dtype=float)
        self.p = np.asarray(motion.odom_p, dtype=float)
        self.dp = np.diff(self.p, axis=0)
        self.d = np.linalg.norm(self.dp, axis=1)
        self.along = np.concatenate([[0.0], np.cumsum(self.d)])
        gaps = np.diff(self.stamps) * 1e-9 > MAX_ODOM_GAP_S
        self.gaps_before = np.concatenate([[0], np.cumsum(gaps)])

    def locate(self, stamp_ns: int) -> Optional[Tuple[int, float]]:
        """Return (segment, weight) of a stamp in the samples; None outside or in a gap."""
        i = int(np.searchsorted(self.stamps, stamp_ns, side='right')) - 1
        if i < 0 or i >= len(self.stamps):
            return None
        if i == len(self.stamps) - 1:
            return (i - 1, 1.0) if self.stamps[i] == stamp_ns and i > 0 else None
        if (self.stamps[i + 1] - self.stamps[i]) * 1e-9 > MAX_ODOM_GAP_S:
            return None
        w = (stamp_ns - self.stamps[i]) / (self.stamps[i + 1] - self.stamps[i])
        return i, float(w)

    def corrected(self, scale: float, yaw_bias: float, where: np.ndarray, weights: np.ndarray
                  ) -> Tuple[np.ndarray, np.ndarray]:
        """
        Correct the odometry and return the heading correction and position at the stamps.

        Each raw step's displacement is scaled by ``1 + scale`` and turned
        about the vertical by the yaw error accumulated before it
        (``yaw_bias`` per metre travelled); the orientations turn with it.
        """
        phi = yaw_bias * self.along
        steps = (1.0 + scale) * np.einsum('nij,nj->ni', _rz(phi[:-1]), self.dp)
        p = np.vstack([self.p[:1], self.p[:1] + np.cumsum(steps, axis=0)])
        w = weights[:, None]
        pos = p[where] * (1.0 - w) + p[where + 1] * w
        phi_at = phi[where] * (1.0 - weights) + phi[where + 1] * weights
        return phi_at, pos

    def raw_rotation(self, where: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """Return the raw orientation interpolated at located stamps (N, 3, 3)."""
        a, b = self.R[where], self.R[where + 1]
        step = _so3_log(np.einsum('nji,njk->nik', a, b)) * np.asarray(weights)[:, None]
        return a @ _so3_exp(step)


def _so3_log(R: np.ndarray) -> np.ndarray:
    """Return the rotation vectors of rotations (N, 3, 3) below about 170 degrees."""
    cos = np.clip((np.trace(R, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    angle = np.arccos(cos)
    vee = np.stack([R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]],
                   axis=1)
    sin = np.sin(angle)
    factor = np.where(angle < 1e-6, 0.5 + angle ** 2 / 12.0, angle / (2.0 * np.where(
        sin == 0.0, 1.0, sin)))
    return vee * factor[:, None]


def _so3_exp(v: np.ndarray) -> np.ndarray:
    """Return the rotations (N, 3, 3) of rotation vectors (N, 3)."""
    angle = np.linalg.norm(v, axis=1)
    K = np.zeros((len(v), 3, 3))
    K[:, 0, 1], K[:, 0, 2] = -v[:, 2], v[:, 1]
    K[:, 1, 0], K[:, 1, 2] = v[:, 2], -v[:, 0]
    K[:, 2, 0], K[:, 2, 1] = -v[:, 1], v[:, 0]
    small = angle < 1e-6
    safe = np.where(small, 1.0, angle)
    a = np.where(small, 1.0 - angle ** 2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - angle ** 2 / 24.0, (1.0 - np.cos(safe)) / safe ** 2)
    return np.eye(3)[None] + a[:, None, None] * K + b[:, None, None] * (K @ K)


@dataclass
class _Edge:
    bag: int
    a: int          # keyframe numbers
    b: int
    length: float


# The problem --------------------------------------------------------------------------


class _Problem:
    """The sightings, keyframes and odometry edges of a survey, ready to become a graph."""

    def __init__(self, sightings: Sequence[Sighting], motions: Sequence[BagMotion],
                 options: SurveyOptions) -> None:
        self.options = options
        self.motions = list(motions)
        codes: Dict[Tuple[int, int, int], str] = {}
        counts: Dict[Tuple[int, int, int], int] = {}
        for s in sightings:
            codes[s.ids] = s.code
            counts[s.ids] = counts.get(s.ids, 0) + 1
        self.codes = codes
        self.counts = counts
        self.card_ids = sorted(codes)
        self.card_index = {ids: j for j, ids in enumerate(self.card_ids)}
        # Frames: (bag, frame) -> keyframe number, in time order per bag.
        by_frame: Dict[Tuple[int, int], List[Sighting]] = {}
        for s in sightings:
            by_frame.setdefault((s.bag, s.frame), []).append(s)
        self.odometry = {b: _Odometry(m) for b, m in enumerate(self.motions)
                         if m.has_odometry and options.use_odometry}
        keys = sorted(by_frame, key=lambda k: (k[0], by_frame[k][0].stamp_ns))
        # Keyframes: consecutive frames of one bag within ``merge_m`` of odometry and
        # ``merge_s`` of time share one pose variable; the later ones' sightings are
        # carried to it by the (short, corrected) odometry between them.
        self.frames: List[Tuple[int, int]] = []
        self.frame_stamp: List[int] = []
        self.frame_mount: List[Pose] = []
        self.frame_odom: List[Optional[Tuple[int, float]]] = []
        self.frame_sightings: List[List[Sighting]] = []
        self.sighting_member: List[List[int]] = []
        self.members: List[List[Tuple[int, Pose, Optional[Tuple[int, float]]]]] = []
        for key in keys:
            bag = key[0]
            found = by_frame[key]
            stamp = found[0].stamp_ns
            motion = self.motions[bag]
            mount = motion.mounts.get(key[1])
            odom = self.odometry.get(bag)
            located = odom.locate(stamp) if (odom is not None and mount is not None) else None
            if located is None:
                mount = Pose.identity() if mount is None or odom is None else mount
                # A frame that cannot join odometry only helps if it links two cards.
                if len({s.ids for s in found}) < 2:
                    continue
            elif self.frames and self.frames[-1][0] == bag and self.frame_odom[-1] is not None:
                i0, w0 = self.frame_odom[-1]
                i1, w1 = located
                travelled = (odom.along[i1] + w1 * odom.d[i1]) - (odom.along[i0] + w0 * odom.d[i0])
                if (odom.gaps_before[i1] == odom.gaps_before[i0]
                        and (stamp - self.frame_stamp[-1]) * 1e-9 <= options.merge_s
                        and travelled <= options.merge_m):
                    self.sighting_member[-1].extend([len(self.members[-1])] * len(found))
                    self.members[-1].append((stamp, mount, located))
                    self.frame_sightings[-1].extend(found)
                    continue
            self.frames.append(key)
            self.frame_stamp.append(stamp)
            self.frame_mount.append(mount)
            self.frame_odom.append(located)
            self.frame_sightings.append(list(found))
            self.sighting_member.append([0] * len(found))
            self.members.append([(stamp, mount, located)])
        self.frame_number = {key: n for n, key in enumerate(self.frames)}
        self._located: Dict[object, tuple] = {}
        self._numbers: Dict[int, np.ndarray] = {}
        self.edges = self._odometry_edges()

    def base_to_card(self, n: int, k: int, steps: Dict[Tuple[int, int], Tuple[Pose, float]]
                     ) -> Pose:
        """Return ``T_base_card`` of keyframe n's k-th sighting (a later member's: carried)."""
        s = self.frame_sightings[n][k]
        m = self.sighting_member[n][k]
        stamp, mount, _ = self.members[n][m]
        Y = mount @ s.T_camera_card
        return Y if m == 0 else steps[(n, m)][0] @ Y

    def member_steps(self, calibration: Dict[int, Tuple[float, float]]
                     ) -> Dict[Tuple[int, int], Tuple[Pose, float]]:
        """Return (corrected odometry keyframe -> member, its length) of every later member."""
        pairs, R, t, lengths, _ = self.member_step_arrays(calibration)
        return {pair: (Pose(R[k], t[k]), float(lengths[k])) for k, pair in enumerate(pairs)}

    def member_step_arrays(self, calibration: Dict[int, Tuple[float, float]]):
        """Return (pairs (n, m), step R, step t, lengths, bags) of the later members."""
        pairs_all, R_all, t_all, len_all, bag_all = [], [], [], [], []
        for bag, odom in self.odometry.items():
            pairs = [(n, m) for n, (b, _) in enumerate(self.frames) if b == bag
                     for m in range(1, len(self.members[n]))]
            if not pairs:
                continue
            kf_located = [self.frame_odom[n] for n, _ in pairs]
            member_located = [self.members[n][m][2] for n, m in pairs]
            scale, bias = calibration.get(bag, (0.0, 0.0))
            Ra, pa = self._corrected_at(('kf', bag), bag, kf_located, scale, bias)
            Rb, pb = self._corrected_at(('member', bag), bag, member_located, scale, bias)
            i0 = np.array([w[0] for w in kf_located])
            w0 = np.array([w[1] for w in kf_located])
            i1 = np.array([w[0] for w in member_located])
            w1 = np.array([w[1] for w in member_located])
            pairs_all += pairs
            R_all.append(np.einsum('nji,njk->nik', Ra, Rb))
            t_all.append(np.einsum('nji,nj->ni', Ra, pb - pa))
            len_all.append((odom.along[i1] + w1 * odom.d[i1]) - (odom.along[i0] + w0 * odom.d[i0]))
            bag_all += [bag] * len(pairs)
        if not pairs_all:
            return [], np.zeros((0, 3, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros(0, int)
        return (pairs_all, np.concatenate(R_all), np.concatenate(t_all),
                np.concatenate(len_all), np.array(bag_all))

    def _corrected_at(self, cache_key, bag: int, located: Sequence[Tuple[int, float]],
                      scale: float, yaw_bias: float) -> Tuple[np.ndarray, np.ndarray]:
        if cache_key not in self._located:
            where = np.array([w[0] for w in located], dtype=int)
            weights = np.array([w[1] for w in located], dtype=float)
            self._located[cache_key] = (where, weights,
                                        self.odometry[bag].raw_rotation(where, weights))
        where, weights, raw = self._located[cache_key]
        phi, pos = self.odometry[bag].corrected(scale, yaw_bias, where, weights)
        return _rz(phi) @ raw, pos

    def _odometry_edges(self) -> List[_Edge]:
        edges = []
        previous: Dict[int, int] = {}
        for n, (bag, _) in enumerate(self.frames):
            located = self.frame_odom[n]
            if located is None:
                continue
            odom = self.odometry[bag]
            if bag in previous:
                m = previous[bag]
                i0, w0 = self.frame_odom[m]
                i1, w1 = located
                if odom.gaps_before[i1] == odom.gaps_before[i0]:
                    length = (odom.along[i1] + w1 * odom.d[i1]) - (odom.along[i0]
                                                                   + w0 * odom.d[i0])
                    edges.append(_Edge(bag, m, n, float(length)))
            previous[bag] = n
        return edges

    # Odometry under a calibration ---------------------------------------------------

    def corrected_arrays(self, bag: int, scale: float, yaw_bias: float
                         ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return (keyframe numbers, R (N, 3, 3), p (N, 3)) of a bag's corrected odometry."""
        numbers = self._numbers.get(bag)
        if numbers is None:
            numbers = self._numbers[bag] = np.array(
                [n for n, (b, _) in enumerate(self.frames)
                 if b == bag and self.frame_odom[n] is not None], dtype=int)
        if not len(numbers):
            return numbers, np.zeros((0, 3, 3)), np.zeros((0, 3))
        R, p = self._corrected_at(('frames', bag), bag, [self.frame_odom[n] for n in numbers],
                                  scale, yaw_bias)
        return numbers, R, p

    def corrected_poses(self, calibration: Dict[int, Tuple[float, float]]
                        ) -> Dict[int, Pose]:
        """Return the corrected odometry pose of every keyframe that has odometry."""
        out: Dict[int, Pose] = {}
        for bag in self.odometry:
            numbers, R, p = self.corrected_arrays(bag, *calibration.get(bag, (0.0, 0.0)))
            for k, n in enumerate(numbers):
                out[int(n)] = Pose(R[k], p[k])
        return out

    def odometry_sigmas(self, bag: int, lengths: np.ndarray,
                        scale: Tuple[float, float] = (1.0, 1.0)) -> np.ndarray:
        """
        Return the sigmas (rotation xyz, translation xyz) of a bag's odometry edges.

        ``scale``: (translation, heading) factors on the model's noise; a base's
        planar components (z, roll, pitch) are a constraint, not scaled.
        """
        o = self.options
        root = np.sqrt(np.maximum(lengths, 0.0))
        trans = (o.odom_sd_m + o.odom_sd_per_sqrt_m * root) * scale[0]
        yaw = (o.odom_sd_yaw_rad + o.odom_sd_yaw_per_sqrt_m * root) * scale[1]
        if self.motions[bag].mount_source == 'camera':
            return np.column_stack([yaw, yaw, yaw, trans, trans, trans])
        flat = np.full(len(root), o.planar_sd)
        return np.column_stack([flat, flat, yaw, trans, trans, flat])


def _pose_graph_init(problem: _Problem, gauge: Dict[int, Pose],
                     corrected: Dict[int, Pose]) -> Tuple[Dict[int, Pose], Dict[int, Pose]]:
    """
    Return first poses of the cards and frames reachable from the gauge cards.

    Dijkstra over sightings (cost: the sighting's position variance) and
    odometry edges (cost: growing with their length): each card and frame is
    placed from the most certain chain that reaches it.
    """
    cards: Dict[int, Pose] = {}
    frames: Dict[int, Pose] = {}
    by_card: Dict[int, List[Tuple[int, int]]] = {}
    for n, found in enumerate(problem.frame_sightings):
        for k, s in enumerate(found):
            by_card.setdefault(problem.card_index[s.ids], []).append((n, k))
    neighbours: Dict[int, List[Tuple[int, float]]] = {}
    for e in problem.edges:
        neighbours.setdefault(e.a, []).append((e.b, e.length))
        neighbours.setdefault(e.b, []).append((e.a, e.length))
    cost_of = [[float(np.trace(s.covariance[:3, :3])) + 1e-9 for s in found]
               for found in problem.frame_sightings]
    steps = problem.member_steps({})
    # Entries: (cost, tie-break, is_frame, index, parent index, how); poses are made on pop.
    heap: List[tuple] = [(0.0, j, False, j, -1, None) for j in gauge]
    heapq.heapify(heap)
    counter = len(heap)
    while heap:
        cost, _, is_frame, index, parent, how = heapq.heappop(heap)
        if is_frame:
            if index in frames:
                continue
            if how[0] == 'card':
                frames[index] = cards[parent] @ problem.base_to_card(index, how[1],
                                                                     steps).inverse()
            else:
                frames[index] = frames[parent] @ (corrected[parent].inverse()
                                                  @ corrected[index])
            for k, s in enumerate(problem.frame_sightings[index]):
                j = problem.card_index[s.ids]
                if j not in cards:
                    counter += 1
                    heapq.heappush(heap, (cost + cost_of[index][k], counter, False, j, index,
                                          k))
            for m, length in neighbours.get(index, []):
                if m not in frames:
                    counter += 1
                    heapq.heappush(heap, (cost + 1e-4 * (1.0 + length) ** 2, counter, True, m,
                                          index, ('odom',)))
        else:
            if index in cards:
                continue
            if parent < 0:
                cards[index] = gauge[index]
            else:
                cards[index] = frames[parent] @ problem.base_to_card(parent, how, steps)
            for n, k in by_card.get(index, []):
                if n not in frames:
                    counter += 1
                    heapq.heappush(heap, (cost + cost_of[n][k], counter, True, n, index,
                                          ('card', k)))
    return cards, frames


# Fitting the odometry's calibration ----------------------------------------------------


def _fit_calibration(problem: _Problem, values: gtsam.Values,
                     calibration: Dict[int, Tuple[float, float]],
                     noise_scale: Tuple[float, float], fitted_bags: set
                     ) -> Dict[int, Tuple[float, float]]:
    """
    Return each bag's (scale, yaw bias) that best explains the optimised frame poses.

    A bag with fewer than five odometry edges keeps its calibration (and is
    not added to ``fitted_bags``).
    """
    out = dict(calibration)
    for bag in problem.odometry:
        numbers, _, _ = problem.corrected_arrays(bag, 0.0, 0.0)
        position = {int(n): k for k, n in enumerate(numbers)}
        edges = [e for e in problem.edges if e.bag == bag and values.exists(X(e.a))
                 and values.exists(X(e.b))]
        if len(edges) < 5:
            continue
        ia = np.array([position[e.a] for e in edges])
        ib = np.array([position[e.b] for e in edges])
        opt = [values.atPose3(X(int(n))).matrix() if values.exists(X(int(n))) else np.eye(4)
               for n in numbers]
        opt = np.array(opt)
        Ro, po = opt[:, :3, :3], opt[:, :3, 3]
        rel_R = np.einsum('nji,njk->nik', Ro[ia], Ro[ib])
        rel_t = np.einsum('nji,nj->ni', Ro[ia], po[ib] - po[ia])
        sig = problem.odometry_sigmas(bag, np.array([e.length for e in edges]), noise_scale)
        params = np.array(out.get(bag, (0.0, 0.0)), dtype=float)

        def residual(p: np.ndarray) -> np.ndarray:
            _, R, t = problem.corrected_arrays(bag, p[0], p[1])
            step_R = np.einsum('nji,njk->nik', R[ia], R[ib])
            step_t = np.einsum('nji,nj->ni', R[ia], t[ib] - t[ia])
            dR = np.einsum('nji,njk->nik', step_R, rel_R)
            r = np.empty((len(edges), 6))
            r[:, 0] = 0.5 * (dR[:, 2, 1] - dR[:, 1, 2])
            r[:, 1] = 0.5 * (dR[:, 0, 2] - dR[:, 2, 0])
            r[:, 2] = 0.5 * (dR[:, 1, 0] - dR[:, 0, 1])
            r[:, 3:] = np.einsum('nji,nj->ni', step_R, rel_t - step_t)
            return (r / sig).ravel()

        for _ in range(5):
            r0 = residual(params)
            J = np.empty((len(r0), 2))
            for d, h in ((0, 1e-5), (1, 1e-6)):
                q = params.copy()
                q[d] += h
                J[:, d] = (residual(q) - r0) / h
            # Huber weights keep an odometry glitch from bending the fit.
            w = np.sqrt(np.minimum(1.0, 3.0 / np.maximum(np.abs(r0), 1e-12)))
            step = np.linalg.lstsq(J * w[:, None], -r0 * w, rcond=None)[0]
            params += step
            if abs(step[0]) < 1e-7 and abs(step[1]) < 1e-9:
                break
        out[bag] = (float(params[0]), float(params[1]))
        fitted_bags.add(bag)
    return out


# The optimisation ------------------------------------------------------------------------


def optimise(sightings: Sequence[Sighting], motions: Sequence[BagMotion],
             anchors: Optional[Dict[Tuple[int, int, int], Pose]] = None,
             options: SurveyOptions = SurveyOptions()) -> SurveyResult:
    """Map the cards: build the graph, optimise, re-weigh, return cards with covariances."""
    timings: Dict[str, float] = {}
    start = time.perf_counter()
    problem = _Problem(sightings, motions, options)
    anchors = dict(anchors or {})
    if not problem.card_ids:
        raise ConfigError('survey: no card was seen in the bags')
    seen_anchors = {problem.card_index[ids]: T for ids, T in anchors.items()
                    if ids in problem.card_index}
    if anchors and not seen_anchors:
        raise ConfigError('survey: none of the anchors was seen in the bags (anchors: '
                          + ', '.join(f'floor {f} room {r} card {p}'
                                      for f, r, p in sorted(anchors)) + ')')
    calibration = {bag: (0.0, 0.0) for bag in problem.odometry}
    if seen_anchors:
        gauge = seen_anchors
        frame_note = ('building frame from the anchors: '
                      + ', '.join(f'floor {f} room {r} card {p}' for f, r, p in sorted(
                          problem.card_ids[j] for j in seen_anchors)))
    else:
        twice = [j for j, ids in enumerate(problem.card_ids) if problem.counts[ids] >= 2]
        first = twice[0] if twice else 0
        gauge = {first: Pose(wall_card_rotation(0.0), np.zeros(3))}
        f, r, p = problem.card_ids[first]
        frame_note = (f'no anchors: the building frame sits on the first card, floor {f} '
                      f'room {r} card {p} (origin at its centre, x out of its wall, z up)')
    init_cards, init_frames = _pose_graph_init(problem, gauge,
                                               problem.corrected_poses(calibration))
    active = set(init_frames)
    values = gtsam.Values()
    for j, T in init_cards.items():
        values.insert(L(j), to_gtsam(T))
    for n, T in init_frames.items():
        values.insert(X(n), to_gtsam(T))
    huber = gtsam.noiseModel.mEstimator.Huber.Create(options.huber_k)
    keys = [(n, k) for n in sorted(active) for k in range(len(problem.frame_sightings[n]))]
    tangent = dict(zip(keys, tangent_covariances(
        [problem.frame_sightings[n][k] for n, k in keys])))
    group = {key: problem.frame_sightings[key[0]][key[1]].group for key in keys}
    # A keyframe's own sightings change only with their group's noise; its later
    # members' also with the odometry.
    own_Y = {}
    later = []
    for key in keys:
        n, k = key
        m = problem.sighting_member[n][k]
        Y = problem.members[n][m][1] @ problem.frame_sightings[n][k].T_camera_card
        if m == 0:
            own_Y[key] = Y
        else:
            later.append((key, Y))
    sighting_scale = np.ones(9)

    def own_factors() -> Dict[Tuple[int, int], gtsam.BetweenFactorPose3]:
        return {key: _between(problem, key, Y, tangent[key] * sighting_scale[group[key]],
                              huber) for key, Y in own_Y.items()}

    own = own_factors()
    carried = _Carried(problem, later, tangent, group) if later else None
    fixed = gtsam.NonlinearFactorGraph()
    _add_gauge(fixed, gauge, seen_anchors, options)
    floors = _on_floor(problem, active) if options.level_floor else {}
    for bag, numbers in floors.items():
        first = values.atPose3(X(numbers[0]))
        t = first.translation()
        values.insert(F(bag), gtsam.Pose3(_flat(first).rotation(),
                                          np.array([t[0], t[1], t[2]])))
    edges = [e for e in problem.edges if e.a in active and e.b in active]
    timings['setup_s'] = time.perf_counter() - start

    dropped: set = set()
    noise_scale = (1.0, 1.0)
    rounds = 0
    build = t_opt = t_weigh = 0.0
    marginals = None
    factors: Dict[str, Optional[float]] = {}
    vce_rounds = 0
    vce_done = False
    scaled_any = False
    fractions: Dict[object, float] = {}
    fitted_bags: set = set()
    while True:
        rounds += 1
        last = rounds >= options.max_rounds
        t0 = time.perf_counter()
        graph = gtsam.NonlinearFactorGraph()
        graph.push_back(fixed)
        sighting_factors = dict(own)
        if carried is not None:
            sighting_factors.update(carried.factors(calibration, noise_scale, huber,
                                                    sighting_scale))
        for key, factor in sighting_factors.items():
            if key not in dropped:
                graph.add(factor)
        odometry = _odometry_factors(problem, edges, calibration, noise_scale, huber)
        for _, factor in odometry:
            graph.add(factor)
        for factor in _re_anchored_priors(problem, values, init_cards, active, gauge, options):
            graph.add(factor)
        for factor in _floor_factors(problem, values, floors, options):
            graph.add(factor)
        build += time.perf_counter() - t0
        t0 = time.perf_counter()
        params = gtsam.LevenbergMarquardtParams()
        params.setRelativeErrorTol(1e-6 if vce_done or vce_rounds else 1e-4)
        params.setAbsoluteErrorTol(1e-9)
        params.setMaxIterations(50)
        values = gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()
        t_opt += time.perf_counter() - t0
        t0 = time.perf_counter()
        # Re-weigh (outliers, the noise levels) after the first round, and again once
        # the odometry's calibration has settled (a miscalibrated odometry looks noisy);
        # then one last round with the final weights.
        settled = True
        if problem.odometry and options.calibrate_odometry:
            fitted = _fit_calibration(problem, values, calibration, noise_scale, fitted_bags)
            # Moving a frame by more than 0.1 mm per metre or heading 1e-5 rad per metre.
            moved = max((max(abs(fitted[b][0] - calibration[b][0]) / 1e-4,
                             abs(fitted[b][1] - calibration[b][1]) / 1e-5) for b in fitted),
                        default=0.0)
            calibration = fitted
            settled = moved <= 1.0
        # The sightings' noise per bin is judged from the first round; the odometry's
        # once its calibration has settled. Each is re-judged until it holds still.
        weigh = not vce_done and (rounds == 1 or settled or vce_rounds == 0)
        final = settled and vce_done
        if weigh:
            marginals = _marginals(graph, values)
            factors = _variance_factors(problem, values, marginals, sighting_factors,
                                        dropped, odometry, group, fractions,
                                        reuse=vce_rounds >= 2)
            dropped |= _outliers(problem, sighting_factors, values, dropped, factors,
                                 group)
            steady = True
            if options.rescale_noise:
                vce_rounds += 1
                for g in range(9):
                    f = factors.get(('sight', g))
                    if f is not None:
                        scaled_any = True
                        steady = steady and abs(math.log(f)) < 0.2
                        sighting_scale[g] = min(max(sighting_scale[g] * f, 1e-2), 1e3)
                own = own_factors()
                if settled and factors['odom_xy'] is not None:
                    lo, hi = options.odom_scale_bounds
                    scaled = tuple(min(max(old * math.sqrt(factors[name]), lo), hi)
                                   for old, name in zip(noise_scale, ('odom_xy', 'odom_yaw')))
                    steady = steady and max(abs(math.log(a / b)) for a, b in
                                            zip(scaled, noise_scale)) < 0.1
                    noise_scale = scaled
            vce_done = settled and (steady or vce_rounds >= 4)
        t_weigh += time.perf_counter() - t0
        if final or last:
            break
    t0 = time.perf_counter()
    marginals = _marginals(graph, values)
    t_weigh += time.perf_counter() - t0
    timings['build_s'] = build
    timings['optimise_s'] = t_opt
    timings['weigh_s'] = t_weigh

    t0 = time.perf_counter()
    residuals = np.array([float(np.linalg.norm(sighting_factors[k].whitenedError(values)))
                          for k in sighting_factors if k not in dropped])
    # The bins' noise is already scaled; what is left is the sightings' overall factor.
    variance_factor = 1.0
    if options.rescale_noise and not scaled_any and factors.get('sightings') is not None:
        variance_factor = factors['sightings']
    cards: List[MapCard] = []
    for j, ids in enumerate(problem.card_ids):
        if j not in init_cards:
            cards.append(MapCard(ids, problem.codes[ids], None, None, problem.counts[ids],
                                 False))
        elif j in seen_anchors:
            cards.append(MapCard(ids, problem.codes[ids], seen_anchors[j], np.zeros((6, 6)),
                                 problem.counts[ids], True, True))
        else:
            T = from_gtsam(values.atPose3(L(j)))
            cov = building_covariance(T, marginals.marginalCovariance(L(j))) * variance_factor
            cards.append(MapCard(ids, problem.codes[ids], T, cov, problem.counts[ids], True))
    paths: Dict[int, List[np.ndarray]] = {}
    for n in sorted(active):
        T = from_gtsam(values.atPose3(X(n))) @ problem.frame_mount[n]
        paths.setdefault(problem.frames[n][0], []).append(T.t)
    timings['marginals_s'] = time.perf_counter() - t0
    return SurveyResult(
        cards=cards, frame_note=frame_note,
        calibration={b: c for b, c in calibration.items() if b in fitted_bags},
        camera_paths={b: np.array(p) for b, p in paths.items()}, residuals=residuals,
        sighting_variance_factor=variance_factor,
        odometry_scale=noise_scale,
        outliers=len(dropped), used_sightings=len(sighting_factors) - len(dropped),
        frames=len(active), rounds=rounds, timings=timings, values=values,
        marginals=marginals,
        card_index=problem.card_index,
        frame_keys={problem.frames[n]: n for n in active})


def _between(problem: _Problem, key: Tuple[int, int], Y: Pose, cov: np.ndarray, huber
             ) -> gtsam.BetweenFactorPose3:
    """Return the factor keyframe base -> card measuring ``Y`` with covariance ``cov``."""
    n, k = key
    noise = gtsam.noiseModel.Robust.Create(huber, gtsam.noiseModel.Gaussian.Covariance(cov))
    return gtsam.BetweenFactorPose3(X(n), L(problem.card_index[problem.frame_sightings[n][k].ids]),
                                    to_gtsam(Y), noise)


class _Carried:
    """
    The sightings of keyframes' later members, carried to the keyframe by odometry.

    A member's sighting ``Y = T_base_card`` becomes ``step @ Y`` with ``step``
    the corrected odometry from the keyframe to the member; the step's
    uncertainty joins the sighting's, moved into the card's frame by the
    adjoint of ``Y^-1``. Rebuilt each round (the calibration moves the steps).
    """

    def __init__(self, problem: _Problem, later: List[Tuple[Tuple[int, int], Pose]],
                 tangent: Dict[Tuple[int, int], np.ndarray], group: Dict) -> None:
        self.problem = problem
        self.group = np.array([group[key] for key, _ in later], dtype=int)
        self.keys = [key for key, _ in later]
        self.YR = np.array([Y.R for _, Y in later])
        self.Yt = np.array([Y.t for _, Y in later])
        self.adjoint = np.array([to_gtsam(Y).inverse().AdjointMap() for _, Y in later])
        self.tangent = np.array([tangent[key] for key in self.keys])
        self.cards = [L(problem.card_index[problem.frame_sightings[n][k].ids])
                      for n, k in self.keys]
        self.members = [(n, problem.sighting_member[n][k]) for n, k in self.keys]

    def factors(self, calibration, noise_scale, huber, sighting_scale
                ) -> Dict[Tuple[int, int], object]:
        """Return the carried sightings' factors under a calibration and odometry noise."""
        pairs, R, t, lengths, bags = self.problem.member_step_arrays(calibration)
        index = {pair: i for i, pair in enumerate(pairs)}
        at = np.array([index[m] for m in self.members])
        sigmas = np.zeros((len(pairs), 6))
        for bag in set(bags.tolist()):
            mine = bags == bag
            sigmas[mine] = self.problem.odometry_sigmas(int(bag), lengths[mine], noise_scale)
        A = self.adjoint
        cov = self.tangent * sighting_scale[self.group][:, None, None] + np.einsum(
            'nij,nj,nkj->nik', A, sigmas[at] ** 2, A)
        ZR = R[at] @ self.YR
        Zt = np.einsum('nij,nj->ni', R[at], self.Yt) + t[at]
        out = {}
        for i, key in enumerate(self.keys):
            noise = gtsam.noiseModel.Robust.Create(
                huber, gtsam.noiseModel.Gaussian.Covariance(cov[i]))
            out[key] = gtsam.BetweenFactorPose3(X(key[0]), self.cards[i],
                                                gtsam.Pose3(gtsam.Rot3(ZR[i]), Zt[i]), noise)
        return out


def _marginals(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values) -> gtsam.Marginals:
    """Return the marginals; QR when Cholesky finds the system too poorly conditioned."""
    try:
        return gtsam.Marginals(graph, values)
    except RuntimeError:
        return gtsam.Marginals(graph, values, gtsam.Marginals.Factorization.QR)


def _odometry_factors(problem: _Problem, edges: Sequence[_Edge],
                      calibration: Dict[int, Tuple[float, float]],
                      noise_scale: Tuple[float, float], huber
                      ) -> List[Tuple[int, gtsam.BetweenFactorPose3]]:
    """Return the odometry factors of the edges under a calibration and noise scale."""
    out = []
    for bag in problem.odometry:
        mine = [e for e in edges if e.bag == bag]
        if not mine:
            continue
        numbers, R, p = problem.corrected_arrays(bag, *calibration.get(bag, (0.0, 0.0)))
        position = {int(n): k for k, n in enumerate(numbers)}
        ia = np.array([position[e.a] for e in mine])
        ib = np.array([position[e.b] for e in mine])
        step_R = np.einsum('nji,njk->nik', R[ia], R[ib])
        step_t = np.einsum('nji,nj->ni', R[ia], p[ib] - p[ia])
        sigmas = problem.odometry_sigmas(bag, np.array([e.length for e in mine]), noise_scale)
        for e, Rs, ts, sig in zip(mine, step_R, step_t, sigmas):
            noise = gtsam.noiseModel.Robust.Create(huber, gtsam.noiseModel.Diagonal.Sigmas(sig))
            out.append((bag, gtsam.BetweenFactorPose3(X(e.a), X(e.b),
                                                      gtsam.Pose3(gtsam.Rot3(Rs), ts), noise)))
    return out


def _add_gauge(graph: gtsam.NonlinearFactorGraph, gauge: Dict[int, Pose],
               anchors: Dict[int, Pose], options: SurveyOptions) -> None:
    for j, T in gauge.items():
        if anchors:
            sigmas = np.full(6, EXACT_SIGMA)
        else:
            # Position and heading exact; the tilt (about the card's x) and the turn on
            # the wall (about its normal) are left to the vertical priors and odometry.
            tilt = options.first_card_tilt_sd_rad
            sigmas = np.array([tilt, EXACT_SIGMA, tilt, EXACT_SIGMA, EXACT_SIGMA,
                               EXACT_SIGMA])
        graph.add(gtsam.PriorFactorPose3(L(j), to_gtsam(T),
                                         gtsam.noiseModel.Diagonal.Sigmas(sigmas)))


def F(bag: int) -> int:
    """Return the key of a bag's floor plane."""
    return gtsam.symbol('f', bag)


def _on_floor(problem: _Problem, active: set) -> Dict[int, List[int]]:
    """Return each bag's keyframes that stand on its floor (odometry and a known mount)."""
    out: Dict[int, List[int]] = {}
    for n in sorted(active):
        bag = problem.frames[n][0]
        if problem.frame_odom[n] is not None and problem.motions[bag].mount_source != 'camera':
            out.setdefault(bag, []).append(n)
    return out


def _flat(T: gtsam.Pose3) -> gtsam.Pose3:
    """Return a pose made level: its heading and x, y kept, z = 0, no roll or pitch."""
    R = T.rotation().matrix()
    t = T.translation()
    return gtsam.Pose3(gtsam.Rot3.Yaw(math.atan2(R[1, 0], R[0, 0])),
                       np.array([t[0], t[1], 0.0]))


def _floor_factors(problem: _Problem, values: gtsam.Values, floors: Dict[int, List[int]],
                   options: SurveyOptions) -> List:
    """
    Return the floor factors, linearised about the current estimate.

    Per bag a floor plane (a pose whose x-y plane is the floor) with a prior
    that it is level; per keyframe a between factor plane -> base holding the
    base upright on the plane at height 0, free in x, y and heading.
    """
    out = []
    free = 1e4
    level = gtsam.noiseModel.Diagonal.Sigmas(np.array(
        [options.floor_level_sd_rad, options.floor_level_sd_rad, free, free, free, free]))
    on = gtsam.noiseModel.Diagonal.Sigmas(np.array(
        [options.base_tilt_sd_rad, options.base_tilt_sd_rad, free, free, free,
         options.base_height_sd_m]))
    for bag, numbers in floors.items():
        plane = values.atPose3(F(bag))
        out.append(gtsam.PriorFactorPose3(F(bag), _flat(plane), level))
        for n in numbers:
            relative = plane.between(values.atPose3(X(n)))
            out.append(gtsam.BetweenFactorPose3(F(bag), X(n), _flat(relative), on))
    return out


def _re_anchored_priors(problem: _Problem, values: gtsam.Values, cards: Dict[int, Pose],
                        active: set, gauge: Dict[int, Pose], options: SurveyOptions
                        ) -> List:
    """
    Return the vertical and height priors, linearised about the current estimate.

    Both are partial priors made of GTSAM's own factors (fast, unlike Python
    ones): a prior whose mean is the card's current pose with its normal
    made horizontal, tight only on that tilt (about the card's x) and with
    no weight elsewhere; and a between factor from a base to the card
    holding the card's height above the base, tight only along the card's
    up (its y). They are rebuilt each round, so the approximation follows
    the estimate.
    """
    out = []
    free = 1e4
    if options.vertical_prior:
        noise = gtsam.noiseModel.Diagonal.Sigmas(np.array(
            [options.vertical_sd_rad, free, free, free, free, free]))
        for j in cards:
            if j in gauge:
                continue
            T = from_gtsam(values.atPose3(L(j)))
            out.append(gtsam.PriorFactorPose3(L(j), to_gtsam(_made_vertical(T)), noise))
    if options.card_height_m is not None:
        noise = gtsam.noiseModel.Diagonal.Sigmas(np.array(
            [free, free, free, free, options.card_height_sd_m, free]))
        best: Dict[int, Tuple[float, int]] = {}
        for n in active:
            if problem.frame_odom[n] is None:
                continue
            for s in problem.frame_sightings[n]:
                j = problem.card_index[s.ids]
                if j in cards and (j not in best or s.distance_m < best[j][0]):
                    best[j] = (s.distance_m, n)
        for j, (_, n) in best.items():
            base = values.atPose3(X(n))
            relative = base.between(values.atPose3(L(j)))
            t = relative.translation().copy()
            t[2] = options.card_height_m
            out.append(gtsam.BetweenFactorPose3(X(n), L(j),
                                                gtsam.Pose3(relative.rotation(), t), noise))
    return out


def _made_vertical(T: Pose) -> Pose:
    """Return the card pose turned about its own x so that its normal is horizontal."""
    normal = T.R[:, 2]
    horizontal = np.array([normal[0], normal[1], 0.0])
    if np.linalg.norm(horizontal) < 1e-6:
        return T
    horizontal /= np.linalg.norm(horizontal)
    x = T.R[:, 0]
    angle = math.atan2(float(np.cross(normal, horizontal) @ x), float(normal @ horizontal))
    return Pose(T.R @ rodrigues(np.array([angle, 0.0, 0.0])), T.t)


def _outliers(problem: _Problem, sighting_factors, values, dropped,
              factors: Dict[object, Optional[float]], group: Dict) -> set:
    """Return the sightings far beyond the robust kernel (chi-square 6 dof, p < 1e-4)."""
    norms = {}
    for key, factor in sighting_factors.items():
        if key not in dropped:
            w = np.asarray(factor.whitenedError(values))
            norms[key] = float(w @ w)
    if not norms:
        return set()
    # Against each bin's own variance factor: the covariances may be pessimistic.
    overall = factors.get('sightings') or 1.0
    out = {key for key, q in norms.items()
           if q / max(factors.get(('sight', group[key])) or overall, 0.05) > OUTLIER_CHI2}
    # Never drop a card's last sightings: its map pose would go with them.
    per_card: Dict[Tuple[int, int, int], int] = {}
    for key in norms:
        ids = problem.frame_sightings[key[0]][key[1]].ids
        per_card[ids] = per_card.get(ids, 0) + 1
    keep = set()
    for key in sorted(out):
        ids = problem.frame_sightings[key[0]][key[1]].ids
        per_card[ids] -= 1
        if per_card[ids] < 2:
            keep.add(key)
            per_card[ids] += 1
    return out - keep


# How many factors of a group to sample for its redundancy, and the fewest a group needs
# for a variance factor of its own.
REDUNDANCY_SAMPLES = {'sight': 12, 'odom': 30}
MIN_GROUP = 20


def _variance_factors(problem: _Problem, values, marginals, sighting_factors, dropped,
                      odometry, group: Dict, fractions: Dict[object, float],
                      reuse: bool) -> Dict[object, Optional[float]]:
    """
    Return the a-posteriori variance factors of the sightings and of the odometry.

    A group's factor is its whitened chi-square over its redundancy, the
    part of its dimensions not used up by the estimate: ``sum_i (d_i -
    tr(A_i Sigma_i A_i^T))`` with A_i a factor's whitened Jacobian and
    Sigma_i the joint marginal of its variables, estimated from a seeded
    sample of the group's factors (``fractions`` keeps each group's estimate;
    with ``reuse`` a group already estimated is not sampled again: the
    weights move little between the last rounds). Groups: the keyframes' own
    sightings per bin of distance and view angle (``('sight', g)``; a later
    member's sighting also carries odometry and is left out), the odometry's
    translation (``odom_xy``) and heading (``odom_yaw``); a base's z, roll
    and pitch are held by the floor, not counted. ``sightings``: all the
    sightings' bins together.
    """
    rng = np.random.default_rng(rounds_seed(fractions))
    planar = [np.array([3, 4]), np.array([2])]
    full = [np.array([3, 4, 5]), np.array([0, 1, 2])]
    own = [k for k in sighting_factors if k not in dropped
           and problem.sighting_member[k[0]][k[1]] == 0]
    groups: List[Tuple[object, list]] = []
    for g in range(9):
        groups.append((('sight', g), [(sighting_factors[k], np.arange(6)) for k in own
                                      if group[k] == g]))
    for name, which in (('odom_xy', 0), ('odom_yaw', 1)):
        groups.append((name, [(f, (full if problem.motions[bag].mount_source == 'camera'
                                   else planar)[which]) for bag, f in odometry]))
    out: Dict[object, Optional[float]] = {'sightings': None}
    total_chi2 = total_redundancy = 0.0
    for name, items in groups:
        out[name] = None
        if not items:
            continue
        chi2 = dims = 0.0
        for f, rows in items:
            w = np.asarray(f.whitenedError(values))[rows]
            chi2 += float(w @ w)
            dims += len(rows)
        if len(items) >= MIN_GROUP and not (reuse and name in fractions):
            samples = REDUNDANCY_SAMPLES['sight' if isinstance(name, tuple) else 'odom']
            picks = rng.choice(len(items), min(samples, len(items)), replace=False)
            used = []
            for i in picks:
                f, rows = items[i]
                A = f.linearize(values).jacobian()[0][rows]
                sigma = marginals.jointMarginalCovariance(gtsam.KeyVector(list(f.keys()))
                                                          ).fullMatrix()
                used.append(float(np.trace(A @ sigma @ A.T)) / len(rows))
            fractions[name] = max(1.0 - float(np.mean(used)), 0.02)
        if name in fractions:
            redundancy = fractions[name] * dims
            if len(items) >= MIN_GROUP:
                out[name] = chi2 / redundancy
            if isinstance(name, tuple):
                total_chi2 += chi2
                total_redundancy += redundancy
    if total_redundancy > 0.0:
        out['sightings'] = total_chi2 / total_redundancy
    return out


def rounds_seed(fractions: Dict[object, float]) -> int:
    """Return a seed that changes as groups get estimated (new picks each time)."""
    return len(fractions)
