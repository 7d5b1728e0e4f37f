"""
Detection over every frame of the bags, in a process pool, with a progress bar.

Detection is the survey's cost and is independent per frame, so frames go to
``jobs`` worker processes (default: all cores), a bounded number in flight
(memory stays bounded on a 100k-frame bag), results back in order. Each
worker decodes the image, runs the same locator as the node
(``CardLocator``, exact estimator: pose and Fisher covariance) and returns
small :class:`~.sightings.Sighting` values, less the poses whose other
planar solution is more likely than the locator's flip gate allows, or lies
in one shallow valley of the fit with it (counted in
``DetectionStats.unsure_flips``). With ``jobs == 1`` everything runs in this
process.
"""

from collections import deque
from dataclasses import dataclass
import multiprocessing
import os
import time
from typing import Iterable, List, Optional, Sequence, Tuple, TYPE_CHECKING

import numpy as np

from .bagio import BagData, camera_on_base, decode_image, iter_images, Mount
from .sightings import Sighting
from ..card.pattern import PatternConfig
from ..errors import PatternLocatorError
from ..localization.gates import flip_unsure
from ..vision.camera import CameraModel
from ..vision.pose_exact import PosePrior

if TYPE_CHECKING:       # the detector's compiled passes load in the workers only
    from ..vision.locate import LocatedCard

# Frames in flight per worker: enough to keep the workers busy, few enough to bound memory.
IN_FLIGHT_PER_JOB = 4


@dataclass(frozen=True)
class DetectionStats:
    """What detection did: frames, sightings, frames it could not use and why, its time."""

    frames: int
    sightings: int
    frames_with_cards: int
    bad_frames: int
    first_problem: str
    wall_s: float
    cpu_s: float            # summed over the workers' frames (detection, decoding included)
    jobs: int
    # Poses left out because their planar flip was unsure (gates.flip_unsure:
    # a card far away and nearly face on).
    unsure_flips: int = 0


_LOCATOR = None


def _init_worker(pattern: PatternConfig) -> None:
    global _LOCATOR
    from ..vision.locate import CardLocator
    # The graph's floor factors hold the keyframes upright already: up only
    # chooses between the planar solutions here, not in the pose's fit.
    _LOCATOR = CardLocator(pattern, estimator='exact', fit_prior=False)


def sightings_of(located: Sequence['LocatedCard'], bag: int, frame: int, stamp: int
                 ) -> Tuple[List[Sighting], int]:
    """
    Return a frame's sightings from its located cards, and how many were unsure flips.

    A card with no pose or a non-finite covariance is no sighting; nor is
    one whose other planar pose is more likely than the locator's flip gate
    allows, or lies in one shallow valley of the fit with it (as the
    locator's flip gate): its covariance does not know that pose, a metre off
    at 6 m, and one such sighting, or several at the fold, would pull the
    card's place.
    """
    out: List[Sighting] = []
    unsure = 0
    for card in located:
        if card.T_camera_pattern is None or card.covariance is None:
            continue
        if not np.all(np.isfinite(card.covariance)):
            continue
        if flip_unsure(card.other_probability, card.flip_barrier):
            unsure += 1
            continue
        det = card.detection
        out.append(Sighting(bag, frame, stamp, str(det.code), det.ids.as_tuple(),
                            card.T_camera_pattern, np.asarray(card.covariance, dtype=float),
                            float(card.reprojection_rms_px),
                            float(card.ambiguity if card.ambiguity is not None else np.inf),
                            int(det.n_points), np.asarray(det.points_px, dtype=float)))
    return out, unsure


def _detect(task) -> Tuple[int, int, int, List[Sighting], Optional[str], float, int]:
    """
    Locate the cards of one frame.

    Return (bag, frame, stamp, sightings, problem, seconds, poses left out
    as unsure planar flips).
    """
    bag, frame, stamp, raw, camera, up = task
    start = time.process_time()
    try:
        image = decode_image(raw)
        if image.shape[1] != camera.width or image.shape[0] != camera.height:
            raise PatternLocatorError(f'image is {image.shape[1]}x{image.shape[0]} but its '
                                      f'camera_info says {camera.width}x{camera.height}')
        prior = PosePrior(up_in_camera=up) if up is not None else None
        located = _LOCATOR.locate(image, camera, prior)
    except PatternLocatorError as exc:
        return bag, frame, stamp, [], str(exc), time.process_time() - start, 0
    out, unsure = sightings_of(located, bag, frame, stamp)
    return bag, frame, stamp, out, None, time.process_time() - start, unsure


def _tasks(bags: Sequence[BagData], mounts: Sequence[Mount]) -> Iterable[tuple]:
    for b, (bag, mount) in enumerate(zip(bags, mounts)):
        for frame, stamp, raw in iter_images(bag):
            camera: CameraModel = bag.camera_at(stamp)
            up = None
            if mount.source != 'camera':
                T_base_camera = camera_on_base(bag, mount, stamp)
                if T_base_camera is not None:
                    # The base stands upright: the world's up seen from the camera.
                    up = T_base_camera.R.T @ np.array([0.0, 0.0, 1.0])
            yield b, frame, stamp, raw, camera, up


def default_jobs() -> int:
    """Return the cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:          # not on Linux
        return max(1, os.cpu_count() or 1)


def detect_bags(bags: Sequence[BagData], mounts: Sequence[Mount], pattern: PatternConfig,
                jobs: Optional[int] = None, progress: bool = True
                ) -> Tuple[List[Sighting], DetectionStats]:
    """Detect the cards in every frame of the bags; return the sightings (in order) and stats."""
    from tqdm import tqdm
    jobs = default_jobs() if jobs is None else int(jobs)
    if jobs < 1:
        raise PatternLocatorError(f'survey: --jobs must be at least 1, got {jobs}')
    total = sum(b.n_images for b in bags)
    bar = tqdm(total=total, unit='frame', desc='detect', disable=None if progress else True)
    sightings: List[Sighting] = []
    frames = with_cards = bad = unsure = 0
    first_problem = ''
    cpu = 0.0
    start = time.perf_counter()

    def take(result) -> None:
        nonlocal frames, with_cards, bad, first_problem, cpu, unsure
        _, _, _, found, problem, seconds, flips = result
        frames += 1
        cpu += seconds
        unsure += flips
        if problem is not None:
            bad += 1
            first_problem = first_problem or problem
        if found:
            with_cards += 1
            sightings.extend(found)
        bar.update(1)

    try:
        if jobs == 1:
            _init_worker(pattern)
            for task in _tasks(bags, mounts):
                take(_detect(task))
        else:
            context = multiprocessing.get_context('spawn')
            with context.Pool(jobs, initializer=_init_worker, initargs=(pattern,)) as pool:
                pending = deque()
                for task in _tasks(bags, mounts):
                    pending.append(pool.apply_async(_detect, (task,)))
                    while len(pending) >= jobs * IN_FLIGHT_PER_JOB:
                        take(pending.popleft().get())
                while pending:
                    take(pending.popleft().get())
    finally:
        bar.close()
    stats = DetectionStats(frames, len(sightings), with_cards, bad, first_problem,
                           time.perf_counter() - start, cpu, jobs, unsure)
    return sightings, stats
