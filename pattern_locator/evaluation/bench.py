"""
``pattern-locator bench``: accuracy and speed against AprilTag and ArUco.

Every scene is rendered three times from the same camera pose, light and
noise: with our colour-dot card, with an AprilTag 36h11 card and with an
ArUco 6x6 card of the same size (the tags' black square is 80 % of the card).
Each locator is timed single-threaded on the same frame (grey conversion
and pose included), and its camera position is compared with the truth.

Both pose pipelines get the same knowledge to resolve the planar flip: the
direction of "up" in the camera frame (a robot knows its head's tilt), with
a few degrees of error. The flip counts without it are printed too.

Tables: per camera and distance bin, detection rate, wrong ids, median and
mean position error (mm and % of distance), median rotation error, median
time per frame and its ratio to AprilTag's in the same run; time per frame
per camera (median, mean, p99, max) with the ratios; the Cramer-Rao bound of
the position for the measured dot-centre noise; partial occlusion; and the
paper's Table 1 setup with both of our estimators. Plots (matplotlib, under
``out/`` by default): position error against distance per marker on log
scales, and the distribution of time per frame; each run kind has its own
file names (``bench_*``, ``bench_quick_*``, ``bench_stress_*``), so one never
overwrites another's. ``--quick`` is a smoke test of the machinery, and says
so.
"""

from dataclasses import dataclass, field, replace
import gc
import math
import time
from typing import Dict, List, Optional, Sequence, Tuple

import cv2
import numpy as np

from .baselines import make_locator, square_pose_solutions, tag_card_bitmap
from .demo import PAPER_TABLE1
from ..card.pattern import Ids, load_pattern_config, PatternConfig
from ..localization.gates import flip_unsure, MAX_FLIP_PROBABILITY
from ..sim.paper_setup import paper_camera
from ..sim.render import (BitmapCardTexture, card_pose_facing, CardPlacement, DotCardTexture,
                          Occluder, render_scene, RenderOptions)
from ..vision.camera import CameraModel
from ..vision.geometry import Pose, rodrigues, rotation_angle
from ..vision.locate import CardLocator
from ..vision.pose_exact import (ellipse_centres, estimate_exact, paper_angles, pose_covariance,
                                 PosePrior)

DISTANCE_BINS = ((1.25, 2.0), (2.0, 3.0), (3.0, 4.5), (4.5, 6.0), (6.0, 8.0))
MARKERS = ('dots', 'apriltag', 'aruco')
PRIOR_SIGMA_DEG = 3.0
FLIP_FRACTION = 0.05      # a flip: error above 5 % of D, and the other solution half as far off


def bench_cameras() -> Dict[str, CameraModel]:
    return {
        '640x480 fx=1000': CameraModel.from_focal(640, 480, 1000.0, name='vga'),
        '1280x720 70deg barrel': CameraModel.from_fov(
            1280, 720, 70.0, D=[-0.25, 0.07, 0.0005, -0.0003, 0.0], name='hd_wide'),
    }


@dataclass(frozen=True)
class Scene:
    """One rendered situation, shared by the three markers."""

    camera_name: str
    bin_index: int
    distance: float
    view_angle: float
    azimuth: float
    roll: float
    offset_px: Tuple[float, float]
    options: RenderOptions
    ids: Ids
    tag_id: int
    aruco_id: int
    prior_tilt: np.ndarray = field(repr=False)   # small rotation: the prior's error


@dataclass
class Outcome:
    """What one locator did on one scene."""

    found: bool = False
    wrong_ids: int = 0
    position_error: float = math.nan     # metres
    rotation_error: float = math.nan     # degrees
    time_ms: float = math.nan
    flipped: bool = False
    flipped_without_prior: bool = False
    # Ours: the other planar solution at least the localizer's flip gate's
    # probability (so a locator would not take the pose without a decider).
    flip_unsure: bool = False
    crb_samples: Optional[np.ndarray] = None
    dot_noise_px: float = math.nan


def _imaging(rng: np.random.Generator, seed: int) -> RenderOptions:
    """Realistic indoor imaging: blur, noise, gamma, colour casts, some JPEG."""
    casts = [(1.0, 1.0, 1.0), (1.2, 1.0, 0.75), (0.9, 1.0, 1.15), (1.0, 1.08, 0.95),
             (1.1, 0.95, 1.05)]
    cast = np.array(casts[rng.integers(len(casts))]) * rng.uniform(0.95, 1.05, 3)
    return RenderOptions(
        supersample=3,
        gain=float(rng.uniform(0.55, 1.15)),
        colour_cast=tuple(float(c) for c in cast),
        gradient=float(rng.uniform(0.0, 0.25)),
        gradient_angle_deg=float(rng.uniform(0.0, 360.0)),
        defocus_sigma_px=float(rng.uniform(0.3, 1.1)),
        motion_blur_px=float(rng.choice([0.0, 0.0, rng.uniform(1.0, 3.0)])),
        motion_blur_angle_deg=float(rng.uniform(0.0, 180.0)),
        noise_sigma=float(rng.uniform(1.0, 3.5)),
        gamma=2.2,
        jpeg_quality=int(rng.integers(80, 96)) if rng.random() < 0.3 else None,
        background='clutter' if rng.random() < 0.5 else 'wall',
        seed=seed)


def make_scenes(config: PatternConfig, per_bin: int, seed: int,
                occluded: bool = False) -> List[Scene]:
    """Seeded scenes: every camera, every distance bin, ``per_bin`` each."""
    rng = np.random.default_rng(seed + (1000 if occluded else 0))
    ranges = config.id_ranges()
    scenes = []
    for camera_name, camera in bench_cameras().items():
        for b, (near, far) in enumerate(DISTANCE_BINS):
            for _ in range(per_bin):
                distance = float(rng.uniform(near, far))
                view = float(rng.uniform(0.0, 70.0))
                # Keep the whole card in the image: its half-size in pixels.
                half = 0.5 * config.card_size * camera.fx / distance * 1.2 + 8
                max_u = max(0.0, camera.width / 2 - half)
                max_v = max(0.0, camera.height / 2 - half)
                offset = (float(rng.uniform(-max_u, max_u)), float(rng.uniform(-max_v, max_v)))
                options = _imaging(rng, int(rng.integers(1 << 30)))
                if occluded:
                    options = replace(options, occluders=(_edge_occluder(config, rng),))
                ids = Ids(int(rng.choice(ranges['floor'])), int(rng.choice(ranges['room'])),
                          int(rng.choice(ranges['pattern'])))
                tilt = rodrigues(np.radians(rng.normal(0.0, PRIOR_SIGMA_DEG / 1.5, 3)))
                scenes.append(Scene(camera_name, b, distance, view,
                                    float(rng.uniform(0.0, 360.0)),
                                    float(rng.uniform(-20.0, 20.0)), offset, options, ids,
                                    int(rng.integers(0, 587)), int(rng.integers(0, 250)),
                                    tilt))
    return scenes


def _edge_occluder(config: PatternConfig, rng: np.random.Generator) -> Occluder:
    """Make a band over one edge of the card, 10-20 % of its size: it hides outer-ring dots."""
    half = config.card_size / 2
    depth = float(rng.uniform(0.10, 0.20)) * config.card_size
    band = np.array([[-half - 0.05, half - depth], [half + 0.05, half - depth],
                     [half + 0.05, half + 0.05], [-half - 0.05, half + 0.05]])
    angle = float(rng.choice([0.0, 90.0, 180.0, 270.0]) + rng.uniform(-20.0, 20.0))
    c, s = math.cos(math.radians(angle)), math.sin(math.radians(angle))
    return Occluder(0, band @ np.array([[c, s], [-s, c]]))


def _render(scene: Scene, camera: CameraModel, config: PatternConfig, marker: str):
    T = card_pose_facing(scene.distance, scene.view_angle, scene.azimuth, roll_deg=scene.roll,
                         offset_px=scene.offset_px, camera=camera)
    if marker == 'dots':
        code = config.encode(*scene.ids.as_tuple())
        placement = CardPlacement(T, DotCardTexture(config, code), code=code, config=config)
    else:
        tag_id = scene.tag_id if marker == 'apriltag' else scene.aruco_id
        bitmap = tag_card_bitmap(marker, tag_id, cells_per_side_px=8)
        placement = CardPlacement(T, BitmapCardTexture(bitmap, config.card_size))
    return render_scene(camera, [placement], scene.options), T


def _prior_up(scene: Scene, T: Pose) -> np.ndarray:
    """Return the card's up direction in the camera frame as a robot knows it (with error)."""
    return scene.prior_tilt @ T.R[:, 1]


def _choose(poses: Sequence[Pose], costs: Sequence[float], up: np.ndarray) -> int:
    """Index of the solution the up prior prefers among near-equal reprojections."""
    best = int(np.argmin(costs))
    if len(poses) < 2 or costs[1 - best] > 4.0 * costs[best] + 1e-12:
        return best
    sigma = math.radians(PRIOR_SIGMA_DEG)
    scores = [costs[i] / max(costs[best], 1e-12)
              + (math.acos(float(np.clip(p.R[:, 1] @ up, -1, 1))) / sigma) ** 2
              for i, p in enumerate(poses)]
    return int(np.argmin(scores))


def run_dots(locator: CardLocator, camera: CameraModel, scene: Scene, image: np.ndarray,
             T: Pose, truth_dots: np.ndarray, config: PatternConfig) -> Outcome:
    out = Outcome()
    prior = PosePrior(up_in_camera=_prior_up(scene, T),
                      up_sigma_rad=math.radians(PRIOR_SIGMA_DEG))
    start = time.perf_counter()
    located = locator.locate(image, camera, prior=prior)
    out.time_ms = (time.perf_counter() - start) * 1000.0
    for card in located:
        if card.detection.ids != scene.ids:
            out.wrong_ids += 1
            continue
        if card.T_camera_pattern is None or out.found:
            continue
        out.found = True
        truth_c = T.inverse().t
        est_c = card.camera_in_pattern
        out.position_error = float(np.linalg.norm(est_c - truth_c))
        out.rotation_error = math.degrees(rotation_angle(card.T_camera_pattern.R, T.R))
        # The flip: the chosen planar solution far off where the other was right.
        for use_prior in (True, False):
            est = estimate_exact(card.detection.points_px, camera, config,
                                 prior=prior if use_prior else None)
            flipped = _is_flip(est.T_camera_pattern, est.alternative, T, scene.distance)
            if use_prior:
                out.flipped = flipped
                out.flip_unsure = flip_unsure(est.other_probability, est.flip_barrier)
            else:
                out.flipped_without_prior = flipped
        # Dot-centre noise against the true ellipse centres, and the bound for it.
        seen = ~np.isnan(card.detection.points_px[:, 0])
        model = config.model_points()
        ideal = ellipse_centres(T, model[:, :2], config.dot_radii(), camera.K)
        rays = np.column_stack([(ideal - [camera.cx, camera.cy]) / [camera.fx, camera.fy],
                                np.ones(len(ideal))])
        true_centres = camera.project(rays)
        residual = card.detection.points_px[seen] - true_centres[seen]
        sigma = float(np.sqrt(np.mean(residual ** 2)))
        out.dot_noise_px = sigma
        cov = pose_covariance(T, model[seen], camera.K, sigma)[:3, :3]
        rng = np.random.default_rng(scene.options.seed)
        samples = rng.multivariate_normal(np.zeros(3), cov, size=64, method='cholesky')
        out.crb_samples = np.linalg.norm(samples, axis=1)
    return out


def run_tag(tag_locator, camera: CameraModel, scene: Scene, image: np.ndarray, T: Pose,
            marker: str, card_size: float) -> Outcome:
    out = Outcome()
    expected = scene.tag_id if marker == 'apriltag' else scene.aruco_id
    up = _prior_up(scene, T)
    start = time.perf_counter()
    detections = tag_locator.detect(image, camera)
    out.time_ms = (time.perf_counter() - start) * 1000.0
    # The up prior picks between the tag's two planar solutions (not timed:
    # the detector already computed its pose once).
    chosen = {}
    for det in detections:
        if det.tag_id == expected:
            solutions = square_pose_solutions(det.corners_px, marker, card_size, camera)
            if solutions:
                poses, costs = zip(*solutions)
                chosen[det.tag_id] = (_choose(poses, costs, up), poses)
    for det in detections:
        if det.tag_id != expected:
            out.wrong_ids += 1
    if expected in chosen:
        index, poses = chosen[expected]
        pose = poses[index]
        other = poses[1 - index] if len(poses) > 1 else None
        out.found = True
        out.position_error = float(np.linalg.norm(pose.inverse().t - T.inverse().t))
        out.rotation_error = math.degrees(rotation_angle(pose.R, T.R))
        out.flipped = _is_flip(pose, other, T, scene.distance)
        # Without the prior: the solution with the lower reprojection error.
        out.flipped_without_prior = _is_flip(poses[0], poses[1] if len(poses) > 1 else None,
                                             T, scene.distance)
    return out


def _is_flip(chosen: Pose, other: Optional[Pose], T: Pose, distance: float) -> bool:
    """Tell whether the chosen planar solution is far off (> 5 % of D) and the other right."""
    if other is None:
        return False
    truth = T.inverse().t
    err = float(np.linalg.norm(chosen.inverse().t - truth))
    err_other = float(np.linalg.norm(other.inverse().t - truth))
    return err > FLIP_FRACTION * distance and err_other < 0.5 * err


def run_scenes(scenes: Sequence[Scene], config: PatternConfig, progress: bool = True,
               label: str = 'scenes') -> Dict[str, List[Tuple[Scene, Outcome]]]:
    """Render every scene for every marker and run its locator; a progress bar on a terminal."""
    from tqdm import tqdm

    cameras = bench_cameras()
    ours = CardLocator(config)
    tags = {m: make_locator(m, config.card_size) for m in MARKERS[1:]}
    results: Dict[str, List[Tuple[Scene, Outcome]]] = {m: [] for m in MARKERS}
    # What is made up to here out of the cyclic collector, as in the stress
    # bench (stress.run_frames): a full collection then scans only what the
    # scenes made since, not the whole process, inside a timed call.
    gc.freeze()
    for scene in tqdm(scenes, desc=label, unit='scene', leave=False,
                      disable=None if progress else True):
        camera = cameras[scene.camera_name]
        for marker in MARKERS:
            rendered, T = _render(scene, camera, config, marker)
            if marker == 'dots':
                outcome = run_dots(ours, camera, scene, rendered.image, T,
                                   rendered.truth[0].dot_pixels, config)
            else:
                outcome = run_tag(tags[marker], camera, scene, rendered.image, T, marker,
                                  config.card_size)
            results[marker].append((scene, outcome))
    return results


# Tables ----------------------------------------------------------------------

def _median(values) -> float:
    values = [v for v in values if not math.isnan(v)]
    return float(np.median(values)) if values else math.nan


def _mean(values) -> float:
    values = [v for v in values if not math.isnan(v)]
    return float(np.mean(values)) if values else math.nan


def _fmt(value: float, digits: int = 1, width: int = 8) -> str:
    return f'{"-":>{width}}' if math.isnan(value) else f'{value:>{width}.{digits}f}'


def accuracy_table(results: Dict[str, List[Tuple[Scene, Outcome]]], camera_name: str) -> str:
    lines = [f'\n### {camera_name}: detection, accuracy and time per frame (single thread)',
             f'{"bin (m)":<10}{"marker":<9}{"det %":>7}{"wrong":>6}{"med mm":>8}{"mean mm":>8}'
             f'{"med %D":>8}{"rot deg":>8}{"flips":>6}{"ms":>7}{"x April":>8}'
             f'{"CRB mm":>8}{"/CRB":>6}']
    for b, (near, far) in enumerate(DISTANCE_BINS):
        rows = {m: [o for s, o in results[m] if s.camera_name == camera_name
                    and s.bin_index == b] for m in MARKERS}
        april_ms = _median([o.time_ms for o in rows['apriltag']])
        for m in MARKERS:
            outs = rows[m]
            if not outs:
                continue
            found = [o for o in outs if o.found]
            dists = [s.distance for s, o in results[m] if s.camera_name == camera_name
                     and s.bin_index == b and o.found]
            med_mm = _median([o.position_error * 1000 for o in found])
            rel = _median([o.position_error / d * 100 for o, d in zip(found, dists)])
            ms = _median([o.time_ms for o in outs])
            crb = math.nan
            if m == 'dots' and found:
                crb = float(np.median(np.concatenate([o.crb_samples for o in found]))) * 1000
            lines.append(
                f'{f"{near:g}-{far:g}":<10}{m:<9}{100 * len(found) / len(outs):>7.0f}'
                f'{sum(o.wrong_ids for o in outs):>6}{_fmt(med_mm)}'
                f'{_fmt(_mean([o.position_error * 1000 for o in found]))}{_fmt(rel, 2)}'
                f'{_fmt(_median([o.rotation_error for o in found]), 2)}'
                f'{sum(o.flipped for o in found):>6}{_fmt(ms, 2, 7)}'
                f'{_fmt(ms / april_ms, 2)}{_fmt(crb)}'
                f'{_fmt(med_mm / crb if crb else math.nan, 2, 6)}')
    return '\n'.join(lines)


def time_stats(values: Sequence[float]) -> Tuple[float, float, float, float]:
    """Median, mean, 99th percentile and max of the finite values (NaN when none)."""
    v = np.asarray([x for x in values if not math.isnan(x)], dtype=float)
    if v.size == 0:
        return (math.nan,) * 4
    return (float(np.median(v)), float(np.mean(v)), float(np.percentile(v, 99)),
            float(np.max(v)))


def time_table(results: Dict[str, List[Tuple[Scene, Outcome]]]) -> str:
    """Time per frame per camera and marker (median, mean, p99, max) and our ratios to AprilTag."""
    lines = ['\n### Time per frame over all scenes (ms, single thread, pose included)',
             f'{"camera":<24}{"marker":<10}{"median":>8}{"mean":>8}{"p99":>8}{"max":>8}'
             f'{"x April med":>12}{"mean":>6}{"p99":>6}{"max":>6}']
    for camera_name in list(bench_cameras()) + ['both cameras']:
        stats = {m: time_stats([o.time_ms for s, o in results[m]
                                if camera_name == 'both cameras' or s.camera_name == camera_name])
                 for m in MARKERS}
        for m in MARKERS:
            ratio = ''
            if m == 'dots':
                ratio = ''.join(_fmt(a / b if b > 0 else math.nan, 2, 12 if i == 0 else 6)
                                for i, (a, b) in enumerate(zip(stats['dots'], stats['apriltag'])))
            lines.append(f'{camera_name:<24}{m:<10}' + ''.join(_fmt(v, 2) for v in stats[m])
                         + ratio)
    return '\n'.join(lines)


def quick_table(results: Dict[str, List[Tuple[Scene, Outcome]]]) -> str:
    """One line per camera and marker, all distances together: the smoke test's summary."""
    lines = [f'{"camera":<24}{"marker":<10}{"det %":>7}{"wrong":>6}{"med mm":>8}'
             f'{"ms med":>8}{"mean":>7}{"max":>7}']
    for camera_name in bench_cameras():
        for m in MARKERS:
            outs = [o for s, o in results[m] if s.camera_name == camera_name]
            found = [o for o in outs if o.found]
            med, mean, _, top = time_stats([o.time_ms for o in outs])
            lines.append(f'{camera_name:<24}{m:<10}{100 * len(found) / max(len(outs), 1):>7.0f}'
                         f'{sum(o.wrong_ids for o in outs):>6}'
                         f'{_fmt(_median([o.position_error * 1000 for o in found]))}'
                         f'{_fmt(med, 2)}{_fmt(mean, 2, 7)}{_fmt(top, 2, 7)}')
    return '\n'.join(lines)


def flip_table(results: Dict[str, List[Tuple[Scene, Outcome]]]) -> str:
    lines = ['\n### Planar flips (the chosen solution > 5 % of D off, the other one at most '
             'half as far), with and without the up prior; dots: poses whose other '
             f'solution is > {MAX_FLIP_PROBABILITY:g} likely or in one shallow valley of the '
             'fit with it (unsure: the locator takes the first only when a gate or its last '
             'fix decides, the second never), and flips among them',
             f'{"marker":<9}{"bin (m)":<10}{"found":>6}{"with prior":>11}{"without":>9}'
             f'{"unsure":>8}{"unsure flips":>14}']
    for m in MARKERS:
        for b, (near, far) in enumerate(DISTANCE_BINS):
            found = [o for s, o in results[m] if s.bin_index == b and o.found]
            unsure = (f'{sum(o.flip_unsure for o in found):>8}'
                      f'{sum(o.flip_unsure and o.flipped for o in found):>14}'
                      if m == 'dots' else f'{"-":>8}{"-":>14}')
            lines.append(f'{m:<9}{f"{near:g}-{far:g}":<10}{len(found):>6}'
                         f'{sum(o.flipped for o in found):>11}'
                         f'{sum(o.flipped_without_prior for o in found):>9}{unsure}')
    return '\n'.join(lines)


def occlusion_table(results: Dict[str, List[Tuple[Scene, Outcome]]]) -> str:
    lines = ['\n### Partial occlusion: a band over one edge hides 10-20 % of the card',
             f'{"camera":<24}{"marker":<9}{"det %":>7}{"wrong":>6}{"med mm":>8}']
    for camera_name in bench_cameras():
        for m in MARKERS:
            outs = [o for s, o in results[m] if s.camera_name == camera_name]
            found = [o for o in outs if o.found]
            lines.append(f'{camera_name:<24}{m:<9}{100 * len(found) / max(len(outs), 1):>7.0f}'
                         f'{sum(o.wrong_ids for o in outs):>6}'
                         f'{_fmt(_median([o.position_error * 1000 for o in found]))}')
    return '\n'.join(lines)


# The paper's setup ---------------------------------------------------------------

def paper_table(config: PatternConfig, n: int, seed: int) -> str:
    """Table 1 form: f = 25 mm, 1.25-8 m, the camera aimed at the card, phi >= 25 deg."""
    camera = paper_camera()
    rng = np.random.default_rng(seed + 7)
    locators = {'exact': CardLocator(config), 'paper': CardLocator(config, 'paper')}
    errors: Dict[str, List[Dict[str, float]]] = {k: [] for k in locators}
    missed = dict.fromkeys(locators, 0)
    for i in range(n):
        distance = float(rng.uniform(1.25, 8.0))
        # Camera 1.05 m below the card (robot's mast vs. 2.15 m), in front of it.
        drop = 1.05
        phi_min = max(25.0, math.degrees(math.asin(min(1.0, drop / distance))))
        phi = float(rng.uniform(phi_min, 70.0))
        # Azimuth so that the camera is `drop` below the card's centre.
        cos_theta = -drop / (distance * math.sin(math.radians(phi)))
        theta = math.degrees(math.acos(max(-1.0, min(1.0, cos_theta))))
        theta = theta if rng.random() < 0.5 else 360.0 - theta
        pointing = rng.normal(0.0, 0.3, 2)           # the tracking loop's residual
        offset = (pointing[0] * math.pi / 180 * camera.fx, pointing[1] * math.pi / 180 * camera.fy)
        scene_opts = replace(_imaging(rng, int(rng.integers(1 << 30))),
                             background='wall', jpeg_quality=None, motion_blur_px=0.0,
                             colour_cast=(1.0, 1.0, 1.0), gain=float(rng.uniform(0.8, 1.1)))
        ids = Ids(1, 3, int(rng.integers(1, 7)))
        code = config.encode(*ids.as_tuple())
        T = card_pose_facing(distance, phi, theta, roll_deg=0.0, offset_px=offset,
                             camera=camera)
        image = render_scene(camera, [CardPlacement(T, DotCardTexture(config, code), code=code,
                                                    config=config)], scene_opts).image
        _, phi_t, theta_t, d_t = paper_angles(T, camera, config)
        truth_c = T.inverse().t
        for name, locator in locators.items():
            found = [c for c in locator.locate(image, camera)
                     if c.T_camera_pattern is not None and c.detection.ids == ids]
            if not found:
                missed[name] += 1
                continue
            c = found[0]
            est = c.camera_in_pattern
            errors[name].append({
                'phi (deg)': abs(c.phi_deg - phi_t),
                'theta (deg)': abs((c.theta_deg - theta_t + 180) % 360 - 180),
                "D' (cm)": abs(c.distance_m - d_t) * 100,
                'x (cm)': abs(est[0] - truth_c[0]) * 100,
                'y (cm)': abs(est[1] - truth_c[1]) * 100,
                'z (cm)': abs(est[2] - truth_c[2]) * 100,
            })
    keys = list(PAPER_TABLE1)
    lines = [f"\n### The paper's setup (f = 25 mm, 640x480, 1.25-8 m, phi >= 25 deg, "
             f'{n} images): absolute errors',
             f'{"":<28}' + ''.join(f'{k:>12}' for k in keys)]
    for name in locators:
        rows = errors[name]
        title = f'{name} estimator'
        for label, fn in (('mean', np.mean), ('std', np.std), ('max', np.max)):
            vals = [fn([r[k] for r in rows]) if rows else math.nan for k in keys]
            lines.append(f'{f"{title} {label}":<28}' + ''.join(_fmt(v, 2, 12) for v in vals))
        means = [np.mean([r[k] for r in rows]) if rows else math.nan for k in keys]
        lines.append(f'{f"{title} mean/Tab.1":<28}' + ''.join(
            _fmt(m / PAPER_TABLE1[k][0], 2, 12) for m, k in zip(means, keys)))
        lines.append(f'{f"{title} missed":<28}{missed[name]:>12}')
    for i, label in enumerate(('Table 1 mean', 'Table 1 std', 'Table 1 max')):
        lines.append(f'{label:<28}' + ''.join(f'{PAPER_TABLE1[k][i]:>12.2f}' for k in keys))
    return '\n'.join(lines)


def run_bench(scenes_per_bin: int = 40, seed: int = 1, quick: bool = False,
              output_dir: Optional[str] = 'out') -> int:
    """Run every table and print it, and plot; returns the exit status."""
    cv2.setNumThreads(1)      # single-threaded, like AprilTag with nthreads=1
    config = load_pattern_config()
    if quick:
        print('pattern_locator bench --quick: a SMOKE TEST (1 scene per distance bin and camera); '
              'its figures are noise, not a measurement: run `pattern-locator bench` for those.')
        results = run_scenes(make_scenes(config, 1, seed), config)
        print(quick_table(results))
        _plots(results, output_dir, 'bench_quick')
        return 0
    occluded_per_bin = max(4, scenes_per_bin // 4)
    paper_n = max(30, scenes_per_bin)
    print(f'pattern_locator bench: {scenes_per_bin} scenes per distance bin and camera, '
          f'seed {seed}, single-threaded')
    scenes = make_scenes(config, scenes_per_bin, seed)
    results = run_scenes(scenes, config)
    for camera_name in bench_cameras():
        print(accuracy_table(results, camera_name))
    print(time_table(results))
    print(flip_table(results))
    occluded = run_scenes(make_scenes(config, occluded_per_bin, seed, occluded=True), config,
                          label='occluded scenes')
    print(occlusion_table(occluded))
    print(paper_table(config, paper_n, seed))
    noise = [o.dot_noise_px for _, o in results['dots'] if o.found]
    print(f'\nmeasured dot-centre noise (RMS vs true ellipse centres): median '
          f'{_median(noise):.3f} px; columns: det % = right id found, wrong = detections '
          f'with an id not in the scene, x April = time / AprilTag time, CRB mm = median '
          f'position error an efficient estimator would have for that noise, /CRB = ratio')
    _plots(results, output_dir, 'bench')
    return 0


def _plots(results: Dict[str, List[Tuple[Scene, Outcome]]], output_dir: Optional[str],
           kind: str) -> None:
    if not output_dir:
        return
    from .bench_plots import error_plot, time_plot

    errors = {m: [(s.distance, o.position_error) for s, o in results[m] if o.found]
              for m in MARKERS}
    times = {f'{m}, {camera.split()[0]}': [o.time_ms for s, o in results[m]
                                           if s.camera_name == camera]
             for camera in bench_cameras() for m in MARKERS}
    paths = [error_plot(errors, output_dir, kind), time_plot(times, output_dir, kind)]
    print('plots: ' + ', '.join(str(p) for p in paths))
