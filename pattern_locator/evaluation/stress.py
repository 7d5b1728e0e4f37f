"""
``pattern-locator bench --stress``: the detector at the edges a real building has.

One row per condition, each on seeded frames of both bench cameras, every
frame rendered twice from the same pose, light, optics and background: with
our colour-dot card and with an AprilTag 36h11 card of the same size. Each
row gives our detection rate (right ids found), wrong ids, time per frame
(median, mean, p99, max; pose included, single thread) and peak extra memory
per frame, next to AprilTag 3 with ``quad_decimate=2`` on the same frames
(``far`` and ``far soft`` add AprilTag with ``quad_decimate=1``, the
target's reference).

The conditions (all procedural, nothing downloaded):

* ``textures``: the card over fine texture (carpet, gravel, foliage: noise
  blurred by 0.6-1.2 px), the frames that made thousands of blobs;
* ``dark noisy``: a dark scene at gain 0.1-0.3 with strong sensor noise;
* ``photos``: a cluttered room (textured patches, polka dots, shapes, text);
* ``light <name>``: 14 coloured lights with per-channel gains 0.7-1.4
  (magenta, red and sodium among them) at gains 0.3-1.3; half of the cards
  have the code class that a weak green channel used to misread (a green
  centre and no green dot on the ring);
* ``chromatic``: red and blue images shifted 0-2 px from the green one, a
  lens's lateral colour and composite video's narrow chroma band;
* ``mirror``: the card seen in a mirror, or from behind thin paper against
  the light (faded): every id read there is wrong;
* ``dim``: gain 0.3-0.4, warm light, sensor noise;
* ``blur``: motion blur of 3-7 px;
* ``occlusion``: an object in front of 10-30 % of the card;
* ``interlace``: both fields of a panning camera (2-10 px apart);
* ``far``: 5.5-8 m;
* ``yuv422`` and ``bayer``: what a frame grabber or a raw sensor sends, the
  ordinary frames encoded as YUV 4:2:2 (chroma halved along the rows) or as
  a Bayer mosaic (one channel a pixel) and decoded by the locator node's own
  decoder (:mod:`..nodes.image_codec`);
* ``mottled``: coloured blotches of the dots' own sizes behind the card (a
  patterned carpet, gravel or leaves seen close, a busy poster): hundreds
  of blobs that have neighbours all round, as a card's centre has;
* ``glare``: a lamp's highlight on a glossy or laminated card (the same on
  the AprilTag card), over the rings, from a sheen to a peak that clips the
  paper;
* ``far soft``: 5.5-8 m through a soft lens (defocus 1-1.5 px against the
  others' 0.3-1: an analog camera such as the EVI-D31, a lens focused
  nearer), where a far card's dots, a few pixels across, fade and merge.

Cards are at 1.25-4 m unless the condition says otherwise, tilted up to 60
degrees, anywhere in the image. Our locator is given a building map per
condition (:func:`stress_map`: the frames' cards and decoys one or two slots
away), as the robot's locator is given its building's, so a card partly
hidden by an object is completed only when exactly one mapped code fits.
What the robot's localizer, following a card, makes of such cards is
measured after the table (:mod:`.stress_follow`).
"""

from dataclasses import dataclass, field, replace
import functools
import gc
import math
import re
import time
from typing import Callable, Dict, List, Optional, Sequence, Tuple, TYPE_CHECKING

import cv2
import numpy as np

from .baselines import AprilTagLocator, tag_card_bitmap
from .bench import bench_cameras, time_stats
from ..card.pattern import Code, Ids, PatternConfig
from ..localization.gates import flip_unsure
from ..nodes.image_codec import decode_image, encode_image
from ..sim.render import (_in_polygon, BitmapCardTexture, card_pose_facing, CardPlacement,
                          DotCardTexture, GlossyTexture, MirroredTexture, Occluder,
                          render_scene, RenderOptions)
from ..vision.camera import CameraModel
from ..vision.geometry import Pose
from ..vision.locate import CardLocator, LocatedCard

if TYPE_CHECKING:      # stress_follow imports this module
    from .stress_follow import FollowCounts

# Lights as (R, G, B) gains relative to white light.
LIGHTS = (
    ('neutral', (1.0, 1.0, 1.0)),
    ('tungsten', (1.4, 1.0, 0.7)),
    ('warm LED', (1.3, 1.05, 0.8)),
    ('sodium', (1.4, 0.9, 0.7)),
    ('magenta', (1.3, 0.7, 1.3)),
    ('weak green', (1.30, 1.04, 1.22)),
    ('red wall', (1.4, 0.8, 0.8)),
    ('purple', (1.1, 0.7, 1.4)),
    ('daylight', (0.85, 1.0, 1.25)),
    ('blue LED', (0.7, 0.9, 1.4)),
    ('cyan', (0.7, 1.2, 1.3)),
    ('fluorescent', (0.9, 1.2, 0.95)),
    ('yellow', (1.3, 1.3, 0.7)),
    ('green', (0.8, 1.4, 0.8)),
)


@dataclass(frozen=True)
class Frame:
    """One stress frame: where the card is, how it is imaged, what it says."""

    condition: str
    camera_name: str
    distance: float
    view_angle: float
    azimuth: float
    roll: float
    offset_px: Tuple[float, float]
    options: RenderOptions
    ids: Ids
    tag_id: int
    mirror_contrast: Optional[float] = None     # a mirror image (1 = a real mirror)
    expected: bool = True                       # False: no id may be read here
    encoding: Optional[str] = None              # sent as this sensor_msgs encoding
    # A lamp's highlight on a glossy card: centre x, y and sigma (card-frame
    # metres) and peak level (reflectance units; the paper is 0.85).
    glare: Optional[Tuple[float, float, float, float]] = None


@dataclass
class Result:
    """What one locator did on one frame."""

    found: bool = False
    wrong_ids: int = 0
    # Not found, but handed on as one of the few mapped codes that fit a
    # partly hidden card, the right one among them (for a localizer's last
    # fix to choose).
    among_candidates: bool = False
    time_ms: float = math.nan
    peak_mb: float = math.nan
    # The right card's pose against the truth: the camera position's error
    # (cm), that error in the pose's own sigmas (its covariance) and whether
    # the pose was sure of its planar side (not localization.gates.flip_unsure).
    error_cm: float = math.nan
    sigmas: float = math.nan
    side_sure: bool = False


@dataclass
class Row:
    """Everything measured for one condition."""

    condition: str
    frames: List[Frame] = field(default_factory=list)
    dots: List[Result] = field(default_factory=list)
    april: List[Result] = field(default_factory=list)
    april_d1: List[Result] = field(default_factory=list)


# Frames -----------------------------------------------------------------------------

def _imaging(rng: np.random.Generator, **overrides) -> RenderOptions:
    """Ordinary indoor imaging; a condition overrides what it is about."""
    options = RenderOptions(
        supersample=2,
        gain=float(rng.uniform(0.6, 1.1)),
        colour_cast=tuple(float(c) for c in rng.uniform(0.95, 1.05, 3)),
        gradient=float(rng.uniform(0.0, 0.25)),
        gradient_angle_deg=float(rng.uniform(0.0, 360.0)),
        defocus_sigma_px=float(rng.uniform(0.3, 1.0)),
        noise_sigma=float(rng.uniform(1.0, 3.0)),
        shot_noise=float(rng.uniform(0.0, 0.01)),
        crosstalk=float(rng.uniform(0.0, 0.3)),
        jpeg_quality=int(rng.integers(80, 96)) if rng.random() < 0.3 else None,
        background=str(rng.choice(['wall', 'clutter'])),
        seed=int(rng.integers(1 << 30)))
    return replace(options, **overrides)


def _risky_code(config: PatternConfig, rng: np.random.Generator) -> Ids:
    """Ids whose code has a green centre and no green dot on the ring, if the layout allows."""
    ranges = config.id_ranges()
    for _ in range(200):
        ids = Ids(int(rng.choice(ranges['floor'])), int(rng.choice(ranges['room'])),
                  int(rng.choice(ranges['pattern'])))
        code = config.encode(*ids.as_tuple())
        if code.centre == 'G' and 'G' not in code.ring:
            return ids
    return ids


def card_occluder(config: PatternConfig, rng: np.random.Generator) -> Occluder:
    """Make an object over 10-30 % of the card: a band from an edge, a corner, a round thing."""
    half = config.card_size / 2
    target = float(rng.uniform(0.10, 0.30))
    grid = np.linspace(-half, half, 48)
    gx, gy = np.meshgrid(grid, grid)
    kind = int(rng.integers(3))
    angle = float(rng.uniform(0.0, 2 * math.pi))
    direction = np.array([math.sin(angle), math.cos(angle)])
    normal = np.array([-direction[1], direction[0]])

    def polygon(depth: float) -> np.ndarray:
        if kind == 0:       # a band over the edge on the side of `direction`
            far = 0.3
            edge = direction * (half * 1.5 - depth)
            return np.array([edge + normal * far, edge - normal * far,
                             edge - normal * far + direction * far,
                             edge + normal * far + direction * far])
        if kind == 1:       # a corner
            corner = np.sign(direction + 1e-9) * half
            leg = depth * 2.0
            return np.array([corner, corner - [np.sign(corner[0]) * leg, 0.0],
                             corner - [0.0, np.sign(corner[1]) * leg]])
        # a round object (a hand, a head) entering from one side
        radius = 0.12
        centre = direction * (half + radius - depth)
        t = np.linspace(0.0, 2 * math.pi, 24, endpoint=False)
        return centre + radius * np.column_stack([np.cos(t), np.sin(t)])

    def covered(depth: float) -> float:
        return float(np.mean(_in_polygon(gx, gy, polygon(depth))))

    lo, hi = 0.0, config.card_size * 1.2
    for _ in range(24):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if covered(mid) < target else (lo, mid)
    colours = [(0.35, 0.3, 0.28), (0.6, 0.45, 0.38), (0.05, 0.05, 0.06), (0.8, 0.8, 0.78)]
    return Occluder(0, polygon(0.5 * (lo + hi)), colours[int(rng.integers(len(colours)))])


def _condition_makers() -> Dict[str, Callable]:
    """Return, per condition, a function (rng, config) -> (frame overrides, options)."""

    def plain(rng, config):
        return {}, _imaging(rng)

    def textures(rng, config):
        return {}, _imaging(rng, background='texture')

    def dark(rng, config):
        return {}, _imaging(rng, background='night', gain=float(rng.uniform(0.1, 0.3)),
                            noise_sigma=float(rng.uniform(3.0, 6.0)),
                            shot_noise=float(rng.uniform(0.02, 0.05)), jpeg_quality=None)

    def photos(rng, config):
        return {}, _imaging(rng, background='photo')

    def light(gains):
        def make(rng, config):
            extra = {'ids': _risky_code(config, rng)} if rng.random() < 0.5 else {}
            cast = np.asarray(gains) * rng.uniform(0.97, 1.03, 3)
            return extra, _imaging(rng, gain=float(rng.uniform(0.3, 1.3)),
                                   colour_cast=tuple(float(c) for c in cast))
        return make

    def chromatic(rng, config):
        shift = float(rng.uniform(0.0, 2.0))
        angle = float(rng.uniform(0.0, 2 * math.pi))
        return {}, _imaging(rng, channel_shift_px=(shift * math.cos(angle),
                                                   shift * math.sin(angle)),
                            lateral_ca=float(rng.uniform(-0.003, 0.003)),
                            chroma_blur_px=float(rng.choice([0.0, rng.uniform(0.5, 2.0)])))

    def mirror(rng, config):
        contrast = 1.0 if rng.random() < 0.6 else float(rng.uniform(0.3, 0.6))
        return {'mirror_contrast': contrast, 'expected': False}, _imaging(rng)

    def dim(rng, config):
        warm = np.array([1.25, 1.0, 0.75]) * rng.uniform(0.95, 1.05, 3)
        return {}, _imaging(rng, gain=float(rng.uniform(0.3, 0.4)),
                            colour_cast=tuple(float(c) for c in warm),
                            noise_sigma=float(rng.uniform(2.0, 4.0)),
                            shot_noise=float(rng.uniform(0.01, 0.02)))

    def blur(rng, config):
        return {}, _imaging(rng, motion_blur_px=float(rng.uniform(3.0, 7.0)),
                            motion_blur_angle_deg=float(rng.uniform(0.0, 180.0)))

    def occlusion(rng, config):
        return {}, _imaging(rng, occluders=(card_occluder(config, rng),))

    def interlace(rng, config):
        shift = float(rng.uniform(2.0, 10.0)) * (1 if rng.random() < 0.5 else -1)
        # The head pans during each field's exposure too. An analog camera's
        # frame grabber delivers YUV 4:2:2 (chroma halved along the rows),
        # not JPEG: JPEG would mix the two fields' colours in its 2x2 chroma.
        return {}, _imaging(rng, interlace_shift_px=shift,
                            motion_blur_px=abs(shift) * float(rng.uniform(0.2, 0.5)),
                            motion_blur_angle_deg=0.0, jpeg_quality=None,
                            chroma_blur_px=float(rng.choice([0.0, 1.0])))

    def far(rng, config):
        return {'distance': float(rng.uniform(5.5, 8.0))}, _imaging(rng)

    # Raw formats are not compressed.
    def yuv422(rng, config):
        return {'encoding': str(rng.choice(['yuv422', 'yuv422_yuy2']))}, _imaging(
            rng, jpeg_quality=None)

    def bayer(rng, config):
        pattern = str(rng.choice(['bayer_rggb8', 'bayer_bggr8', 'bayer_gbrg8', 'bayer_grbg8']))
        return {'encoding': pattern}, _imaging(rng, jpeg_quality=None)

    def mottled(rng, config):
        return {}, _imaging(rng, background='mottled')

    def glare(rng, config):
        # A lamp mirrored in a glossy or laminated card, somewhere over its
        # rings: from a sheen to a peak that clips the paper.
        outer = config.ring_radii[0] + config.ring_dot_radius
        centre = rng.uniform(-0.6 * outer, 0.6 * outer, 2)
        return {'glare': (float(centre[0]), float(centre[1]),
                          float(rng.uniform(0.1, 0.6) * outer),
                          float(rng.uniform(0.05, 1.0)))}, _imaging(rng)

    def far_soft(rng, config):
        return {'distance': float(rng.uniform(5.5, 8.0))}, _imaging(
            rng, defocus_sigma_px=float(rng.uniform(1.0, 1.5)))

    makers = {'plain': plain, 'textures': textures, 'dark noisy': dark, 'photos': photos}
    makers.update({f'light {name}': light(gains) for name, gains in LIGHTS})
    makers.update({'chromatic': chromatic, 'mirror': mirror, 'dim': dim, 'blur': blur,
                   'occlusion': occlusion, 'interlace': interlace, 'far': far,
                   'yuv422': yuv422, 'bayer': bayer, 'mottled': mottled, 'glare': glare,
                   # Last: the conditions before it keep their seeded frames.
                   'far soft': far_soft})
    return makers


CONDITIONS = tuple(_condition_makers())
# The conditions whose target is AprilTag's rate with decimate 1, and how
# the targets table names each.
_FAR = {'far': '5.5-8 m', 'far soft': '5.5-8 m, soft lens'}


def make_frames(config: PatternConfig, per_camera: int, seed: int,
                conditions: Sequence[str] = CONDITIONS) -> List[Frame]:
    """Seeded frames: every condition, every bench camera, ``per_camera`` each."""
    makers = _condition_makers()
    ranges = config.id_ranges()
    frames = []
    for c, condition in enumerate(conditions):
        rng = np.random.default_rng([seed, c])
        for camera_name, camera in bench_cameras().items():
            for _ in range(per_camera):
                distance = float(rng.uniform(1.25, 4.0))
                view = float(rng.uniform(0.0, 60.0))
                ids = Ids(int(rng.choice(ranges['floor'])), int(rng.choice(ranges['room'])),
                          int(rng.choice(ranges['pattern'])))
                extra, options = makers[condition](rng, config)
                distance = extra.pop('distance', distance)
                half = 0.5 * config.card_size * camera.fx / distance * 1.3 + 8
                max_u = max(0.0, camera.width / 2 - half)
                max_v = max(0.0, camera.height / 2 - half)
                offset = (float(rng.uniform(-max_u, max_u)), float(rng.uniform(-max_v, max_v)))
                frames.append(Frame(condition, camera_name, distance, view,
                                    float(rng.uniform(0.0, 360.0)),
                                    float(rng.uniform(-30.0, 30.0)), offset, options,
                                    extra.pop('ids', ids), int(rng.integers(0, 587)), **extra))
    return frames


def stress_map(frames: Sequence[Frame], config: PatternConfig, seed: int = 1
               ) -> List[Code]:
    """
    Return the building map the stress bench's locator is given: frames' cards and decoys.

    The detector completes a card partly hidden by an object only from the
    codes that exist, and only when no other of them comes within one seen
    slot. A real building's rooms hold several cards that differ in the
    pattern digits (points 6, 7), its neighbouring rooms in a room digit and
    its floors in the centre or point 8; so each frame's card is mapped with
    decoys: five more cards of its room, the same card number in the rooms
    either side and on the floors above and below. They are codes one or two
    slots from the card's own, the hardest test of that rule.
    """
    ranges = config.id_ranges()
    rng = np.random.default_rng([seed, 9])
    ids = set()
    for frame in frames:
        f, r, p = frame.ids.as_tuple()
        ids.add((f, r, p))
        others = [q for q in ranges['pattern'] if q != p]
        for q in rng.choice(others, size=min(5, len(others)), replace=False):
            ids.add((f, r, int(q)))
        ids.update((f, r2, p) for r2 in (r - 1, r + 1) if r2 in ranges['room'])
        ids.update((f2, r, p) for f2 in (f - 1, f + 1) if f2 in ranges['floor'])
    return sorted({config.encode(*i) for i in ids}, key=str)


def _card_pose(frame: Frame, camera: CameraModel) -> Pose:
    return card_pose_facing(frame.distance, frame.view_angle, frame.azimuth, roll_deg=frame.roll,
                            offset_px=frame.offset_px, camera=camera)


def camera_position(frame: Frame, camera: CameraModel) -> np.ndarray:
    """Return the camera's true position in the card's frame (metres)."""
    T = _card_pose(frame, camera)
    return -T.R.T @ T.t


def render_frame(frame: Frame, camera: CameraModel, config: PatternConfig,
                 marker: str) -> np.ndarray:
    """Render the frame with our card (``'dots'``) or with an AprilTag card."""
    T = _card_pose(frame, camera)
    if marker == 'dots':
        texture = DotCardTexture(config, config.encode(*frame.ids.as_tuple()))
    else:
        texture = BitmapCardTexture(tag_card_bitmap('apriltag', frame.tag_id, 8),
                                    config.card_size)
    if frame.mirror_contrast is not None:
        texture = MirroredTexture(texture, frame.mirror_contrast)
    if frame.glare is not None:
        texture = GlossyTexture(texture, frame.glare[:2], frame.glare[2], frame.glare[3])
    image = render_scene(camera, [CardPlacement(T, texture)], frame.options).image
    if frame.encoding is not None:
        image = decode_image(*encode_image(image, frame.encoding))
    return image


# Measuring --------------------------------------------------------------------------

def _memory_kb() -> Optional[Tuple[int, int]]:
    try:
        text = open('/proc/self/status').read()
        rss = int(re.search(r'VmRSS:\s+(\d+)', text).group(1))
        hwm = int(re.search(r'VmHWM:\s+(\d+)', text).group(1))
        return rss, hwm
    except (OSError, AttributeError):
        return None


# glibc's mallopt parameters, and the thresholds (bytes) the benchmark sets.
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_EXACT_BYTES = 128 * 1024
# A long-running process's thresholds: glibc raises the mmap threshold to the
# largest block freed (a camera frame, in a node), at most 32 MiB, and the
# trim threshold to twice that.
_STEADY_MMAP_BYTES = 32 * 1024 * 1024


@functools.lru_cache(maxsize=1)
def _libc():
    """Return glibc (its mallopt and malloc_trim), or None for another C library."""
    try:
        import ctypes

        libc = ctypes.CDLL('libc.so.6')
        libc.mallopt, libc.malloc_trim      # both, or neither is used
        return libc
    except (OSError, AttributeError):
        return None


def steady_allocator() -> None:
    """
    Give malloc the thresholds a long-running process settles at, for timing.

    A node's allocator soon keeps a frame's blocks in its heap and reuses
    them; a benchmark process that returned them to the system after each
    call would charge every frame the page faults of fresh memory (about a
    millisecond a frame here, for either detector). Both detectors are timed
    under these settings.
    """
    libc = _libc()
    if libc is not None:
        libc.mallopt(_M_MMAP_THRESHOLD, _STEADY_MMAP_BYTES)
        libc.mallopt(_M_TRIM_THRESHOLD, 2 * _STEADY_MMAP_BYTES)


def _exact_allocator(libc) -> None:
    # Every large block comes from and goes back to the system at once, and
    # the heap's free memory is returned first, so that a call's peak is its
    # own: glibc would otherwise serve it from blocks already resident.
    libc.mallopt(_M_MMAP_THRESHOLD, _EXACT_BYTES)
    libc.mallopt(_M_TRIM_THRESHOLD, _EXACT_BYTES)
    libc.malloc_trim(0)


def peak_extra_mb(run: Callable[[], object]) -> float:
    """
    Peak resident memory (MB) that ``run()`` adds to the process; NaN if unknown.

    Linux's high-water mark is reset (``/proc/self/clear_refs``) before the
    call and read after it, so native allocations (OpenCV, AprilTag) count.
    During the call malloc returns large blocks to the system at once (a
    reused resident block would not raise the mark); after it, malloc has
    the long-running thresholds of :func:`steady_allocator`.
    """
    libc = _libc()
    try:
        if libc is not None:
            _exact_allocator(libc)
        try:
            with open('/proc/self/clear_refs', 'w') as f:
                f.write('5')
        except OSError:
            return math.nan
        before = _memory_kb()
        run()
        after = _memory_kb()
    finally:
        steady_allocator()
    if before is None or after is None:
        return math.nan
    return max(0.0, (after[1] - before[0]) / 1024.0)


def score_located(located: Sequence[LocatedCard], frame: Frame,
                  truth: Optional[np.ndarray] = None) -> Result:
    """
    Return what our locator's cards on ``frame`` were: found, wrong ids, among candidates.

    ``truth``: the camera's true position in the card's frame, to score the
    right card's pose against (:func:`camera_position`).
    """
    out = Result()
    for card in located:
        if card.detection.ids is None:
            out.among_candidates |= frame.expected and any(
                c.ids == frame.ids for c in card.detection.candidates)
            continue
        if not frame.expected or card.detection.ids != frame.ids:
            out.wrong_ids += 1
        elif card.T_camera_pattern is not None:
            if truth is not None and not out.found and card.covariance is not None:
                error = np.asarray(card.camera_in_pattern) - truth
                out.error_cm = 100.0 * float(np.linalg.norm(error))
                try:
                    out.sigmas = float(np.sqrt(max(0.0, error @ np.linalg.solve(
                        card.covariance[:3, :3], error))))
                except np.linalg.LinAlgError:    # a covariance that claims too much
                    out.sigmas = math.inf
                out.side_sure = not flip_unsure(card.other_probability, card.flip_barrier)
            out.found = True
    return out


def _measured(run: Callable[[], object], score: Callable[[object], Result]) -> Result:
    """Score ``run()``'s output, with its time and (a second run) its peak extra memory."""
    start = time.perf_counter()
    output = run()
    elapsed = (time.perf_counter() - start) * 1000.0
    out = score(output)
    out.time_ms = elapsed
    out.peak_mb = peak_extra_mb(run)
    return out


def _run_dots(locator: CardLocator, image: np.ndarray, camera: CameraModel,
              frame: Frame) -> Result:
    truth = camera_position(frame, camera) if frame.expected else None
    return _measured(lambda: locator.locate(image, camera),
                     lambda located: score_located(located, frame, truth))


def _run_april(april: AprilTagLocator, image: np.ndarray, camera: CameraModel,
               frame: Frame) -> Result:
    def score(found) -> Result:
        out = Result()
        for det in found:
            if not frame.expected or det.tag_id != frame.tag_id:
                out.wrong_ids += 1
            else:
                out.found = True
        return out
    return _measured(lambda: april.detect(image, camera), score)


def run_frames(frames: Sequence[Frame], config: PatternConfig, progress: bool = True
               ) -> Dict[str, Row]:
    """Render and measure every frame; rows in condition order."""
    from tqdm import tqdm

    steady_allocator()
    cameras = bench_cameras()
    # One building per condition (its frames' cards and their decoys, a
    # building of a few hundred cards), whatever the conditions run.
    by_condition: Dict[str, List[Frame]] = {}
    for frame in frames:
        by_condition.setdefault(frame.condition, []).append(frame)
    ours = {name: CardLocator(config, known_codes=stress_map(group, config))
            for name, group in by_condition.items()}
    april = AprilTagLocator(config.card_size)
    april_d1 = AprilTagLocator(config.card_size, quad_decimate=1.0)
    rows: Dict[str, Row] = {}
    # What is made up to here (frames, maps, tables, imported modules) out
    # of the cyclic collector, as a node's start-up is (ros_helpers.run_node):
    # its full collections then scan only what the frames made since. In
    # this process they otherwise took 15-41 ms, inside a timed call.
    gc.freeze()
    for frame in tqdm(frames, desc='stress frames', unit='frame', leave=False,
                      disable=None if progress else True):
        camera = cameras[frame.camera_name]
        row = rows.setdefault(frame.condition, Row(frame.condition))
        row.frames.append(frame)
        row.dots.append(_run_dots(ours[frame.condition],
                                  render_frame(frame, camera, config, 'dots'), camera, frame))
        tag_image = render_frame(frame, camera, config, 'apriltag')
        row.april.append(_run_april(april, tag_image, camera, frame))
        if frame.condition in _FAR:
            row.april_d1.append(_run_april(april_d1, tag_image, camera, frame))
    return rows


# Tables -----------------------------------------------------------------------------

def _rate(results: Sequence[Result], frames: Sequence[Frame]) -> float:
    expected = [r for r, f in zip(results, frames) if f.expected]
    if not expected:
        return math.nan
    return 100.0 * sum(r.found for r in expected) / len(expected)


def _num(value: float, digits: int = 1, width: int = 7) -> str:
    return f'{"-":>{width}}' if math.isnan(value) else f'{value:>{width}.{digits}f}'


def stress_table(rows: Dict[str, Row]) -> str:
    """Return one line per condition: ours and AprilTag (decimate 2) side by side."""
    head = (f'{"condition":<20}{"n":>4} | {"det %":>6}{"wrong":>6}{"med ms":>7}{"mean":>7}'
            f'{"p99":>7}{"max":>7}{"MB":>6} | {"det %":>6}{"wrong":>6}{"med ms":>7}'
            f'{"mean":>7}{"p99":>7}{"max":>7}{"MB":>6} | {"med x":>6}{"mean x":>7}'
            f'{"p99 x":>6}{"max x":>6}')
    lines = ['\n### Stress conditions: ours (left) and AprilTag 3, decimate 2 (right), '
             'same frames, single thread',
             f'{"":<25}| {"colour dots (pose included)":^46}| '
             f'{"AprilTag 36h11 (pose included)":^46}| ratio ours / AprilTag',
             head]
    every: Row = Row('all conditions')
    for row in list(rows.values()) + [every]:
        if row is not every:
            every.frames += row.frames
            every.dots += row.dots
            every.april += row.april
        ours = time_stats([r.time_ms for r in row.dots])
        theirs = time_stats([r.time_ms for r in row.april])
        ratios = [a / b if b > 0 else math.nan for a, b in zip(ours, theirs)]
        lines.append(
            f'{row.condition:<20}{len(row.frames):>4} | {_num(_rate(row.dots, row.frames), 1, 6)}'
            f'{sum(r.wrong_ids for r in row.dots):>6}' + ''.join(_num(v, 1) for v in ours)
            + _num(max((r.peak_mb for r in row.dots), default=math.nan), 0, 6)
            + f' | {_num(_rate(row.april, row.frames), 1, 6)}'
            f'{sum(r.wrong_ids for r in row.april):>6}' + ''.join(_num(v, 1) for v in theirs)
            + _num(max((r.peak_mb for r in row.april), default=math.nan), 0, 6)
            + ' | ' + _num(ratios[0], 2, 6) + _num(ratios[1], 2, 7) + _num(ratios[2], 2, 6)
            + _num(ratios[3], 2, 6))
    for name in _FAR:
        far = rows.get(name)
        if far is None or not far.april_d1:
            continue
        # A far dot whose colour JPEG greyed is an unread slot, as a hidden one.
        more = sum(r.among_candidates and not r.found for r in far.dots)
        lines.append(f'{name}: AprilTag with decimate 1 finds '
                     f'{_rate(far.april_d1, far.frames):.1f} %'
                     f' ({sum(r.wrong_ids for r in far.april_d1)} wrong ids); ours: {more} more '
                     f'of {len(far.frames)} gave the card among the few mapped codes that fit '
                     f'the slots read (as for occlusion, below)')
    hidden = rows.get('occlusion')
    if hidden is not None and hidden.frames:
        more = sum(r.among_candidates and not r.found for r in hidden.dots)
        lines.append(f'occlusion: {more} more of {len(hidden.frames)} gave the card as one of '
                     f'the few mapped codes that fit the slots seen, the right one among them '
                     f'(not in det %: RobotLocalizer takes such a card only where exactly one of '
                     f'them puts the robot where its last fix allows)')
    lines.append('det % = right id with a pose, of the frames where one is expected (none in '
                 'mirror); wrong = ids read that are not the card (any id in a mirror); MB = '
                 'largest peak extra resident memory of one frame')
    return '\n'.join(lines)


def pose_table(rows: Dict[str, Row]) -> str:
    """
    Return, per condition, how far our right cards' poses are from the truth.

    Only the poses sure of their planar side count (a pose unsure of it is
    no fix without a last fix to choose by: localization.gates.flip_unsure).
    """
    lines = ['\n### Poses against the truth (ours; right cards sure of their planar side)',
             f'{"condition":<20}{"poses":>6}{"med cm":>8}{"p95 cm":>8}{"max cm":>8}'
             f'{"> 4 sigma":>10}{"max sigma":>10}']
    every: List[Result] = []
    for name, row in list(rows.items()) + [('all conditions', None)]:
        results = every if row is None else [r for r in row.dots if r.side_sure]
        if row is not None:
            every += results
        if not results:
            continue
        errors = np.array([r.error_cm for r in results])
        sigmas = np.array([r.sigmas for r in results])
        lines.append(f'{name:<20}{len(results):>6}' + _num(float(np.median(errors)), 2, 8)
                     + _num(float(np.quantile(errors, 0.95)), 2, 8)
                     + _num(float(errors.max()), 2, 8)
                     + f'{int(np.count_nonzero(sigmas > 4.0)):>10}'
                     + _num(float(sigmas.max()), 1, 10))
    lines.append('cm: the camera position error; sigma: that error in units of the pose '
                 'covariance (a pose whose covariance holds its error is rarely beyond 4)')
    return '\n'.join(lines)


def _conditions_matching(rows: Dict[str, Row], prefix: str) -> Row:
    merged = Row(prefix)
    for name, row in rows.items():
        if name == prefix or name.startswith(prefix + ' '):
            merged.frames += row.frames
            merged.dots += row.dots
            merged.april += row.april
            merged.april_d1 += row.april_d1
    return merged


def targets_table(rows: Dict[str, Row], follow: Optional['FollowCounts'] = None) -> str:
    """
    Issue 9's targets, each with the figure measured here and met / not met.

    ``follow``: :func:`~.stress_follow.run_follow`'s counts, for the
    occlusion target as the robot meets it (following the card).
    """
    lines = ['\n### Targets (issue 9)', f'{"target":<58}{"measured":>26}  verdict']

    def add(text: str, value: str, ok: Optional[bool]) -> None:
        verdict = '-' if ok is None else ('met' if ok else 'NOT MET')
        lines.append(f'{text:<58}{value:>26}  {verdict}')

    wrong = sum(r.wrong_ids for row in rows.values() for r in row.dots)
    add('0 wrong ids in every condition', f'{wrong}', wrong == 0)
    ours = [r.time_ms for row in rows.values() for r in row.dots]
    theirs = [r.time_ms for row in rows.values() for r in row.april]
    a, b = time_stats(ours), time_stats(theirs)
    for name, i, limit in (('median', 0, 0.25), ('mean', 1, 0.35), ('p99', 2, 0.5),
                           ('max', 3, 1.0)):
        ratio = a[i] / b[i] if b[i] > 0 else math.nan
        add(f'time {name} <= {limit:g}x AprilTag (all stress frames)', f'{ratio:.2f}x',
            ratio <= limit if not math.isnan(ratio) else None)
        if name == 'median':
            # The median of both cameras' frames together lies between the
            # two cameras' times: each camera's own, for what it hides.
            for camera_name in bench_cameras():
                mine = [(r.time_ms, q.time_ms) for row in rows.values()
                        for f, r, q in zip(row.frames, row.dots, row.april)
                        if f.camera_name == camera_name]
                if mine:
                    c = time_stats([m for m, _ in mine])[0] / time_stats([t for _, t in mine])[0]
                    add(f'   median, {camera_name} frames alone', f'{c:.2f}x', None)
    hd = [r.peak_mb for row in rows.values() for f, r in zip(row.frames, row.dots)
          if f.camera_name.startswith('1280x720')]
    peak = max(hd, default=math.nan)
    add('peak extra memory <= 100 MB per frame at 1280x720', f'{peak:.0f} MB',
        None if math.isnan(peak) else peak <= 100.0)
    light = _conditions_matching(rows, 'light')
    for dim in ('dim',):
        if dim in rows:
            light.frames += rows[dim].frames
            light.dots += rows[dim].dots
    for text, row, limit in (
            ('>= 99 % in any light (gain 0.3-1.3, casts to 1.4x)', light, 99.0),
            ('>= 85 % with motion blur up to 7 px', rows.get('blur'), 85.0),
            ('>= 80 % with 10-30 % of the card occluded', rows.get('occlusion'), 80.0),
            ('>= 85 % on interlaced frames of a panning camera', rows.get('interlace'), 85.0)):
        if row is None or not row.frames:
            continue
        rate = _rate(row.dots, row.frames)
        low, high = _interval(row.dots, row.frames)
        add(text, f'{rate:.1f} % ({low:.0f}-{high:.0f})', rate >= limit)
        if text.startswith('>= 80 %') and follow is not None and follow.views:
            # Fixes from the hidden card itself, not from others in the image.
            rate = 100.0 * follow.fixes_of_card / follow.views
            low, high = wilson_interval(follow.fixes_of_card, follow.views)
            add('   the same, following the card (localizer, last fix)',
                f'{rate:.1f} % ({low:.0f}-{high:.0f})', rate >= limit and follow.wrong == 0)
    for name, text in _FAR.items():
        far = rows.get(name)
        if far is None or not far.april_d1:
            continue
        ours_far, d1 = _rate(far.dots, far.frames), _rate(far.april_d1, far.frames)
        # Ten points more than AprilTag, but no more than every frame.
        low, high = _interval(far.dots, far.frames)
        add(f'{text}: >= AprilTag decimate 1 + 10 points (max 100 %)',
            f'{ours_far:.1f} ({low:.0f}-{high:.0f}) vs {d1:.1f} %',
            ours_far >= min(d1 + 10.0, 100.0))
    lines.append('(a-b): the 95 % interval (Wilson) of a rate measured on this many frames; '
                 'the verdict is on the rate itself')
    return '\n'.join(lines)


def _interval(results: Sequence[Result], frames: Sequence[Frame]) -> Tuple[float, float]:
    """Return the Wilson 95 % interval (percent) of the detection rate."""
    return wilson_interval(sum(r.found for r, f in zip(results, frames) if f.expected),
                           sum(1 for f in frames if f.expected))


def wilson_interval(k: int, n: int) -> Tuple[float, float]:
    """Return the Wilson 95 % interval (percent) of a rate of ``k`` in ``n``."""
    if n == 0:
        return math.nan, math.nan
    p = k / n
    z = 1.96
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return 100.0 * max(0.0, centre - half), 100.0 * min(1.0, centre + half)


def run_stress(per_camera: int = 10, seed: int = 1, quick: bool = False,
               output_dir: Optional[str] = 'out') -> int:
    """Run every condition and print the table and the targets; returns the exit status."""
    from ..card.pattern import load_pattern_config

    cv2.setNumThreads(1)
    steady_allocator()
    config = load_pattern_config()
    n = 1 if quick else per_camera
    if quick:
        print(f'pattern_locator bench --stress --quick: a SMOKE TEST ({n} frame per condition '
              f'and camera); its figures are noise, not a measurement.')
    else:
        print(f'pattern_locator bench --stress: {n} frames per condition and camera, '
              f'seed {seed}, single-threaded')
    rows = run_frames(make_frames(config, n, seed), config)
    print(stress_table(rows))
    print(pose_table(rows))
    from .stress_follow import follow_table, run_follow

    follow = run_follow(per_card=1 if quick else 3, seed=seed)
    print(follow_table(follow))
    print(targets_table(rows, follow))
    if output_dir:
        from .bench_plots import time_plot

        times = {}
        for name, row in rows.items():
            times[f'{name}: dots'] = [r.time_ms for r in row.dots]
            times[f'{name}: AprilTag'] = [r.time_ms for r in row.april]
        kind = 'bench_stress_quick' if quick else 'bench_stress'
        path = time_plot(times, output_dir, kind, 'Time per frame under stress (single thread, '
                                                  'pose included)')
        print(f'\nplot: {path}')
    return 0


__all__ = ['card_occluder', 'CONDITIONS', 'Frame', 'LIGHTS', 'make_frames', 'peak_extra_mb',
           'render_frame', 'run_frames', 'run_stress', 'steady_allocator', 'stress_map',
           'stress_table', 'targets_table', 'wilson_interval']
