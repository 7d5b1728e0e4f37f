"""
The survey's problem before it is a graph: keyframes, their sightings, odometry edges.

Consecutive frames of a bag within ``merge_m`` of odometry and ``merge_s`` of
time share one pose variable (a keyframe); the later ones (members) keep their
sightings, carried to the keyframe by the corrected odometry. A frame without
odometry stands alone and joins the graph only if it saw two cards or more.
:func:`first_poses` gives every reachable card and keyframe a first pose.
"""

from dataclasses import dataclass
import heapq
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from .model import BagMotion, SurveyOptions
from .odometry import Odometry, rz
from .sightings import Sighting
from ..vision.geometry import Pose


@dataclass
class Edge:
    bag: int
    a: int          # keyframe numbers
    b: int
    length: float


class Problem:
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
        self.odometry = {b: Odometry(m) for b, m in enumerate(self.motions)
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
        return rz(phi) @ raw, pos

    def _odometry_edges(self) -> List[Edge]:
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
                    edges.append(Edge(bag, m, n, float(length)))
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


def first_poses(problem: Problem, gauge: Dict[int, Pose],
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
