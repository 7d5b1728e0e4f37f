"""
``pattern-locator survey --check building.yaml BAG``: does the map still agree with the walk.

The bag is surveyed on its own (no anchors), then laid onto the map by the
rigid transform that fits the most cards (:func:`.align.robust_rigid`), so
a card that was moved, knocked or rehung cannot pull the others. Each card
seen in the bag is then compared with its map pose: a card is **moved** when
its position or its orientation differs by more than its tolerance,
``K_SIGMA`` times the combined standard deviation (the survey's, and the
map's own ``std_dev`` when it has one), and at least ``MIN_POSITION_M`` and
``MIN_ANGLE_DEG`` (what a careful hand-measured map can promise).
"""

from dataclasses import dataclass
import math
from typing import List, Optional, Sequence

import numpy as np

from .align import apply, robust_rigid
from .bagio import SurveyTopics
from .graph import SurveyOptions
from .run import run_survey
from ..card.pattern import load_pattern_config
from ..errors import ConfigError
from ..localization.building import load_building
from ..vision.geometry import rotation_angle

K_SIGMA = 4.0
MIN_POSITION_M = 0.01
MIN_ANGLE_DEG = 1.0


@dataclass(frozen=True)
class CardCheck:
    """One card of the map against the walk."""

    ids: tuple
    status: str                     # 'ok', 'moved', 'not seen', 'not in the map', 'unplaced'
    offset_m: Optional[float] = None
    angle_deg: Optional[float] = None
    tolerance_m: Optional[float] = None
    tolerance_deg: Optional[float] = None
    offset_xyz_m: Optional[np.ndarray] = None


def check_map(map_path: str, bag_paths: Sequence[str], topics: SurveyTopics = SurveyTopics(),
              jobs: Optional[int] = None, camera_mount=None,
              options: SurveyOptions = SurveyOptions()) -> List[CardCheck]:
    """Return the check of every card of the map and of every card the walk saw."""
    pattern = load_pattern_config()
    building = load_building(map_path, pattern)
    run = run_survey(bag_paths, topics, None, jobs, camera_mount, options, pattern)
    surveyed = {c.ids: c for c in run.result.cards}
    mapped = {c.ids.as_tuple(): c for c in building.cards()}
    common = sorted(ids for ids, c in surveyed.items() if ids in mapped and c.placed)
    out: List[CardCheck] = []
    if len(common) < 3:
        raise ConfigError(f'survey --check: the walk placed {len(common)} card(s) of the map; '
                          'at least three are needed to lay it onto the map and tell which '
                          'moved')
    source = np.array([surveyed[i].T_building_card.t for i in common])
    target = np.array([mapped[i].T_building_card.t for i in common])
    sd = np.array([_position_sd(surveyed[i], mapped[i]) for i in common])
    T, inliers = robust_rigid(source, target, np.maximum(K_SIGMA * sd, MIN_POSITION_M))
    # A card's offset after the fit is uncertain by its position relative to the fitted
    # cards, not to the survey's own frame: project the frame's motions out, and fit
    # again with those tolerances until the cards held stay the same.
    for _ in range(4):
        position_sd = _residual_sd(run.result, common, source, inliers, mapped,
                                   options.card_floor_sd_m)
        tolerance = np.maximum(K_SIGMA * np.array([position_sd[i] for i in common]),
                               MIN_POSITION_M)
        T, held = robust_rigid(source, target, tolerance)
        if np.array_equal(held, inliers):
            break
        inliers = held
    for ids in sorted(set(mapped) | set(surveyed)):
        if ids not in mapped:
            out.append(CardCheck(ids, 'not in the map'))
            continue
        if ids not in surveyed:
            out.append(CardCheck(ids, 'not seen'))
            continue
        card = surveyed[ids]
        if not card.placed:
            out.append(CardCheck(ids, 'unplaced'))
            continue
        moved_to = apply(T, 1.0, card.T_building_card.t[None])[0]
        offset = moved_to - mapped[ids].T_building_card.t
        angle = math.degrees(rotation_angle(T.R @ card.T_building_card.R,
                                            mapped[ids].T_building_card.R))
        tol_m = max(K_SIGMA * position_sd[ids], MIN_POSITION_M)
        tol_deg = max(K_SIGMA * _angle_sd_deg(card, mapped[ids]), MIN_ANGLE_DEG)
        distance = float(np.linalg.norm(offset))
        status = 'moved' if distance > tol_m or angle > tol_deg else 'ok'
        out.append(CardCheck(ids, status, distance, angle, tol_m, tol_deg, offset))
    return out


def _residual_sd(result, common, source: np.ndarray, inliers: np.ndarray, mapped,
                 floor_sd_m: float) -> dict:
    """
    Return each card's position sd after a rigid fit on the inliers.

    With x the cards' positions (joint covariance S) and G the rigid motions
    (``dx_j = t + w x p_j``), the fit's residual is ``(I - P) x`` with P the
    least-squares projection onto G over the inliers: its covariance is
    ``(I - P) S (I - P)^T``. The map's own ``std_dev`` and the survey's floor
    for what a card's sightings share add to it.
    """
    n = len(common)
    S = result.card_position_covariance(common)
    G = np.zeros((3 * n, 6))
    centre = source[inliers].mean(axis=0)
    for k, p in enumerate(source - centre):
        G[3 * k:3 * k + 3, :3] = np.eye(3)
        G[3 * k:3 * k + 3, 3:] = -np.array([[0.0, -p[2], p[1]], [p[2], 0.0, -p[0]],
                                            [-p[1], p[0], 0.0]])
    W = np.repeat(inliers.astype(float), 3)
    P = G @ np.linalg.pinv(G.T @ (G * W[:, None])) @ (G.T * W[None, :])
    M = np.eye(3 * n) - P
    C = M @ S @ M.T
    out = {}
    for k, ids in enumerate(common):
        var = float(np.max(np.linalg.eigvalsh(C[3 * k:3 * k + 3, 3 * k:3 * k + 3])))
        var += floor_sd_m ** 2
        if mapped[ids].std_dev is not None:
            var += max(mapped[ids].std_dev.position_m) ** 2
        out[ids] = math.sqrt(max(var, 0.0))
    return out


def _position_sd(card, mapped) -> float:
    """Return the largest position sd of a surveyed card and its map entry combined."""
    var = float(np.max(np.linalg.eigvalsh(card.covariance[:3, :3]))) if (
        card.covariance is not None) else 0.0
    if mapped.std_dev is not None:
        var += max(mapped.std_dev.position_m) ** 2
    return math.sqrt(max(var, 0.0))


def _angle_sd_deg(card, mapped) -> float:
    var = float(np.max(np.linalg.eigvalsh(card.covariance[3:, 3:]))) if (
        card.covariance is not None) else 0.0
    sd = math.degrees(math.sqrt(max(var, 0.0)))
    if mapped.std_dev is not None:
        sd = math.hypot(sd, max(mapped.std_dev.rotation_deg))
    return sd


def check_main(map_path: str, bag_paths: Sequence[str], **kwargs) -> int:
    """Print the check, one line per card; return 1 when a card moved, else 0."""
    results = check_map(map_path, bag_paths, **kwargs)
    moved = 0
    for r in results:
        f, room, p = r.ids
        label = f'floor {f} room {room} card {p}'
        if r.status in ('ok', 'moved'):
            word = 'MOVED' if r.status == 'moved' else 'ok'
            moved += r.status == 'moved'
            print(f'{label}: {word:5s} {r.offset_m * 1000:7.1f} mm {r.angle_deg:6.2f} deg '
                  f'(tolerance {r.tolerance_m * 1000:.1f} mm, {r.tolerance_deg:.2f} deg)')
        else:
            print(f'{label}: {r.status}')
    checked = sum(r.status in ('ok', 'moved') for r in results)
    print(f'{map_path}: {checked} cards checked, {moved} moved')
    return 1 if moved else 0
