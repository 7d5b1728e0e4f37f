"""
Find colour-dot cards in a BGR image: dots -> cards -> ordered points -> code.

1. **Dots.** Every dot, black or coloured, is dark in at least one channel
   against the white card whatever the light's colour, so the per-pixel
   minimum over B, G, R is thresholded against the local white (a max
   filter on a decimated image) and labelled in connected components.
2. **Cards.** A centre candidate is a blob with at least eight blobs of one
   size around it, on at least four sides. In the centre blob's own affine
   frame the rings are near circles of radii ``R / r_centre``; a vote gives
   their scale and the angle of the 45-degree slots. A homography fitted to
   the assigned dots (undistorted when the camera is known) verifies the
   card, drops dots off the fit or of the wrong size, recovers dots the
   first pass missed, and measures faint or merged dots of a distant card
   in windows where it predicts them. Dots cut by the image border are
   never used.
3. **Order and code.** Colours are read in linear light against the card's
   own white (sampled between the dots, which cancels coloured light):
   point 1 is the least chromatic slot, clearly so; every other dot takes
   the printed colour whose chromatic direction is nearest. Points follow
   clockwise as seen from the front (a card is never seen from behind).
   Both rings must agree; a card whose colours are unclear is rejected,
   never guessed.
4. **Sub-pixel centres.** Darkness-weighted centroids over each dot and a
   rim shared with its neighbours by distance: the centre of the dot's image
   ellipse, which the exact estimator corrects to the projected circle centre.
"""

from dataclasses import dataclass, field
from typing import List, Optional, Sequence, Tuple

import cv2
import numpy as np

from .camera import CameraModel
from ..card.pattern import Code, Ids, PatternConfig, RING_POINTS, srgb_to_linear
from ..errors import CodeError, ImageError


@dataclass(frozen=True)
class DetectorParams:
    """Tuning of the detector; the defaults suit 640x480 to 1920x1080 cameras."""

    dark_ratio: float = 0.72        # dot pixel: min channel below this fraction of local white
    min_white: int = 30             # ignore regions whose local white is darker than this
    white_window: int = 48          # local white: max filter over about this many pixels
    min_dot_area: int = 3           # pixels
    max_dot_area_fraction: float = 0.05   # of the image
    min_ellipse_fill: float = 0.55  # blob area / area of its moment ellipse (convex, round)
    max_homography_error: float = 0.25    # in units of the dot's image radius
    gamma: float = 2.2              # the camera's encoding; colours are compared in linear light
    max_black_chroma: float = 0.12  # chromatic part of a black dot's darkness, at most
    min_colour_chroma: float = 0.04     # a coloured dot's chromatic part, at least
    min_colour_chroma_ratio: float = 2.0    # ...and this many times the black's
    min_colour_margin: float = 0.2  # cosine to its colour minus cosine to the next
    min_black_centre: float = 0.8   # a black centre is at least this dark relative to point 1
    min_darkness: float = 0.25      # a dot darker than the card by less than this is unreadable
    min_window_darkness: float = 0.12   # a dot measured in a window must be this dark


@dataclass(frozen=True)
class CardDetection:
    """
    One card found in an image.

    ``points_px`` holds the sub-pixel dot centres in dot-index order
    (0 = centre, then ring 0 points 1..8, ring 1 points 1..8), NaN where a
    dot was not seen. ``code`` and ``ids`` are None for a grey image, where
    the ring order (point 1) is unknown too.
    """

    code: Optional[Code]
    ids: Optional[Ids]
    points_px: np.ndarray
    dot_areas_px: np.ndarray
    complete_rings: Tuple[int, ...]
    size_px: float                  # long semi-axis of the outermost complete ring, pixels
    homography: np.ndarray          # pattern plane (metres) -> undistorted pixels
    colour_margin: float            # how clearly the colours were read, 0..1
    ring_codes: Tuple[str, ...] = field(default=())   # per ring, the colours read

    @property
    def centre_px(self) -> np.ndarray:
        return self.points_px[0]

    @property
    def n_points(self) -> int:
        return int(np.count_nonzero(~np.isnan(self.points_px[:, 0])))


class Detector:
    """Detect colour-dot cards; one instance per pattern configuration."""

    def __init__(self, config: PatternConfig, params: DetectorParams = DetectorParams()):
        self.config = config
        self.params = params
        self._model = config.model_points()[:, :2]
        self._radii = config.dot_radii()
        # Expected ring radii in units of the centre dot radius.
        self._ring_rho = np.array(config.ring_radii) / config.centre_dot_radius
        self._white_xy = _white_sample_points(config)
        # Plane position of slot k of ring r, slot k taken as point k + 1.
        self._slot_xy = self._model[1:].reshape(config.n_rings, RING_POINTS, 2)
        self._colour_directions = _colour_directions(config)

    # Public ----------------------------------------------------------------

    def detect(self, image: np.ndarray, camera: Optional[CameraModel] = None
               ) -> List[CardDetection]:
        """Every card in ``image`` (BGR uint8, or grey for geometry only)."""
        frame = self._segment(_check_image(image), camera)
        cards = []
        used = set()
        for centre in self._centre_candidates(frame):
            if centre in used:
                continue
            found = self._card_at(frame, centre)
            if found is None:
                continue
            card, members = found
            if members & used:
                continue
            used |= members
            cards.append(card)
        return cards

    # Dots ------------------------------------------------------------------

    def _segment(self, image: np.ndarray, camera: Optional[CameraModel]) -> '_Frame':
        """Dark blobs against the local white, as connected components."""
        p = self.params
        darkest = image if image.ndim == 2 else _min_channel(image)
        h, w = darkest.shape
        # Local white: max filter on a 4x decimated image, smoothed, scaled up.
        step = 4
        small = cv2.resize(darkest, (max(1, w // step), max(1, h // step)),
                           interpolation=cv2.INTER_AREA)
        k = max(3, int(p.white_window // step) | 1)
        small = cv2.dilate(small, cv2.getStructuringElement(cv2.MORPH_RECT, (k, k)))
        small = cv2.blur(small, (3, 3))
        threshold = np.where(small >= p.min_white, small * p.dark_ratio, 0).astype(np.uint8)
        threshold = cv2.resize(threshold, (w, h), interpolation=cv2.INTER_LINEAR)
        mask = cv2.compare(darkest, threshold, cv2.CMP_LT)
        # Grana's block-based labelling is about twice as fast as the default here.
        n, labels, stats, centroids = cv2.connectedComponentsWithStatsWithAlgorithm(
            mask, 8, cv2.CV_32S, cv2.CCL_GRANA)
        area = stats[:, cv2.CC_STAT_AREA]
        bw, bh = stats[:, cv2.CC_STAT_WIDTH], stats[:, cv2.CC_STAT_HEIGHT]
        # Round dots fill a good part of their box and are not long and thin
        # (a 75-degree tilt makes a dot about 4:1).
        x, y = stats[:, cv2.CC_STAT_LEFT], stats[:, cv2.CC_STAT_TOP]
        keep = ((area >= p.min_dot_area) & (area <= p.max_dot_area_fraction * h * w)
                & (area * 4 >= bw * bh) & (np.maximum(bw, bh) <= 6 * np.minimum(bw, bh) + 2)
                # A dot cut by the image border has a false centre.
                & (x > 0) & (y > 0) & (x + bw < w) & (y + bh < h))
        keep[0] = False
        idx = np.flatnonzero(keep)
        return _Frame(image, darkest, small, step, labels, n, camera, image.ndim == 2,
                      centroids[idx, 0].copy(), centroids[idx, 1].copy(),
                      area[idx].astype(float), stats[idx, :4].copy(), idx.astype(np.int32))

    # Cards -----------------------------------------------------------------

    def _centre_candidates(self, frame: '_Frame') -> List[int]:
        """Blobs with enough plausible ring dots around them, biggest first."""
        n = len(frame.area)
        if n < 1 + RING_POINTS:
            return []
        # A centre dot of equivalent radius r has its outer ring within
        # about rho_out * r / cos(tilt) of it; 2x covers tilts to 75 degrees.
        radius = 2.0 * self._ring_rho[0] * np.sqrt(frame.area / np.pi)
        du = frame.u[None, :] - frame.u[:, None]
        dv = frame.v[None, :] - frame.v[:, None]
        ratio = frame.area[None, :] / frame.area[:, None]
        close = ((du * du + dv * dv < (radius * radius)[:, None])
                 & (ratio > 0.06) & (ratio < 1.0))
        np.fill_diagonal(close, False)
        candidates = np.flatnonzero(close.sum(axis=1) >= RING_POINTS)
        # Ring dots surround their centre: they fall in at least four of the
        # eight octants around it, even seen edge-on (a row of letters: two).
        octant = (np.floor((np.arctan2(dv, du) + np.pi) / (np.pi / 4)).astype(int)) % 8
        surrounded = []
        for i in candidates:
            ring_areas = frame.area[close[i]]
            # Ring dots are all the same size (within blur and perspective).
            typical = np.partition(ring_areas, len(ring_areas) // 2)[len(ring_areas) // 2]
            alike = (ring_areas > 0.4 * typical) & (ring_areas < 2.5 * typical)
            if (np.count_nonzero(alike) >= RING_POINTS and np.count_nonzero(
                    np.bincount(octant[i][close[i]][alike], minlength=8)) >= 4):
                surrounded.append(i)
        return sorted(surrounded, key=lambda i: -frame.area[i])

    def _card_at(self, frame: '_Frame', ci: int):
        # Normalising map: the centre blob's ellipse -> unit circle (radius = centre dot).
        cov = frame.covariance(ci)
        evals, evecs = np.linalg.eigh(cov)
        if evals[0] <= 0:
            return None
        semi = 2.0 * np.sqrt(evals)                 # semi-axes of the centre dot, px
        if semi[0] < 0.8:
            return None
        fill = frame.area[ci] / (np.pi * semi[0] * semi[1])
        if not self.params.min_ellipse_fill <= fill <= 1.3:
            return None
        to_unit = evecs @ np.diag(1.0 / semi) @ evecs.T
        rel = np.column_stack([frame.u - frame.u[ci], frame.v - frame.v[ci]]) @ to_unit.T
        rho = np.hypot(rel[:, 0], rel[:, 1])
        r_out = self._ring_rho[0]
        r_in = self._ring_rho[-1]
        ratio = frame.area / frame.area[ci]
        near = np.flatnonzero((rho > 0.55 * r_in) & (rho < 1.6 * r_out)
                              & (ratio < 1.2) & (ratio > 0.04))
        near = near[near != ci]
        if len(near) < RING_POINTS:
            return None
        rho = rho[near]
        ang = np.arctan2(rel[near, 1], rel[near, 0])
        slots = self._vote_slots(rho, ang)
        if slots is None:
            return None
        scale, phase = slots
        # Assign each neighbour to (ring, slot) by its predicted position.
        n_rings = len(self._ring_rho)
        k = np.round(_wrap(ang - phase) / (np.pi / 4)).astype(int) % RING_POINTS
        dang = np.abs(_wrap(ang - (phase + k * np.pi / 4)))
        slot_blob = np.full((n_rings, RING_POINTS), -1, dtype=int)
        best_cost = np.full((n_rings, RING_POINTS), np.inf)
        for ring, r_model in enumerate(self._ring_rho):
            r_exp = scale * r_model
            dr = np.abs(rho / r_exp - 1.0)
            ok = (dr < 0.25) & (dang < 0.35)
            for i in np.flatnonzero(ok):
                cost = dr[i] + dang[i]
                if cost < best_cost[ring, k[i]]:
                    best_cost[ring, k[i]] = cost
                    slot_blob[ring, k[i]] = near[i]
        # The homography fitted next recovers dots this first pass missed; the
        # centre blob's shape is only a rough guide at long range or with blur.
        per_ring = np.count_nonzero(slot_blob >= 0, axis=1)
        if per_ring.sum() < 9 or per_ring.max() < 6:
            return None
        # Slot order k increases clockwise in the image (v down) = clockwise on the card
        # seen from the front; point 1 is found from the colours below.
        return self._verify_and_read(frame, ci, slot_blob)

    def _vote_slots(self, rho: np.ndarray, ang: np.ndarray) -> Optional[Tuple[float, float]]:
        """
        Scale of the rings and angle of slot 0, by voting over neighbours.

        Every neighbour, taken as a dot of every ring, proposes a scale and a
        slot angle; the proposal that puts most neighbours on a ring and a
        45-degree slot wins.
        """
        ring_rho = self._ring_rho
        scale = (rho[:, None] / ring_rho[None, :]).ravel()          # (A,)
        phase = np.repeat(ang, len(ring_rho))                          # (A,)
        ok_scale = (scale > 0.55) & (scale < 1.6)
        if not np.any(ok_scale):
            return None
        scale, phase = scale[ok_scale], phase[ok_scale]
        dang = _wrap(ang[None, :] - phase[:, None])                     # (A, N)
        dslot = np.abs(dang - np.round(dang / (np.pi / 4)) * (np.pi / 4))
        r_exp = scale[:, None, None] * ring_rho[None, None, :]          # (A, 1, R)
        on_ring = np.abs(rho[None, :, None] - r_exp) < 0.2 * r_exp      # (A, N, R)
        score = np.count_nonzero(on_ring.any(axis=2) & (dslot < 0.3), axis=1)
        best = int(np.argmax(score))
        if score[best] < RING_POINTS:
            return None
        return float(scale[best]), float(phase[best])

    def _verify_and_read(self, frame: '_Frame', ci: int, slot_blob: np.ndarray):
        cfg = self.config
        n_rings = slot_blob.shape[0]
        camera = frame.camera
        # Sub-pixel centres of the assigned dots.
        members = [ci] + slot_blob[slot_blob >= 0].tolist()
        centres = dict(zip(members, frame.centroids(members)))
        # Homography from slot-ordered model points (slot 0 taken as point 1 until
        # the colours say which is) to undistorted pixels, to verify the geometry.
        pos = [(ring, k) for ring in range(n_rings) for k in range(RING_POINTS)
               if slot_blob[ring, k] >= 0]
        obj = np.vstack([self._slot_xy[tuple(np.array(pos).T)], self._model[:1]])
        img = np.array([centres[slot_blob[ring, k]] for ring, k in pos] + [centres[ci]])
        und = camera.undistort_pixels(img) if camera is not None else img
        H, inliers = self._fit_homography(obj, und)
        if H is None:
            return None
        for (ring, k), ok in zip(pos, inliers[:-1]):
            if not ok:
                slot_blob[ring, k] = -1
        # Look again for missing dots where the homography puts them.
        self._fill_missing(frame, H, slot_blob, ci)
        if not self._sizes_fit(frame, H, slot_blob, ci):
            return None
        added = [j for j in slot_blob[slot_blob >= 0].tolist() if j not in centres]
        if added:
            centres.update(zip(added, frame.centroids(added)))
            self._check_added(frame, H, slot_blob, added, centres)
        # Dots still missing may be too faint to segment, or merged with their
        # neighbour on the other ring (far away, tilted): measure them in a
        # window where the homography puts them.
        windows = self._window_dots(frame, H, slot_blob) if np.any(slot_blob < 0) else {}
        if frame.grey_only:
            point1_slot, code, ids, margin, ring_codes = 0, None, None, 0.0, ()
        else:
            # If the colours do not add up, a window may have measured an object
            # over a dot, or an incomplete ring hold a stray blob: read again
            # without them before giving up.
            for attempt in range(3):
                if attempt == 1:
                    if not windows:
                        continue
                    windows = {}
                if attempt == 2:
                    partial = ~np.all(slot_blob >= 0, axis=1)
                    if not np.any(partial) or np.all(partial):
                        break
                    slot_blob[partial] = -1
                if not self._complete_rings(slot_blob, windows):
                    return None
                read = self._read_colours(frame, H, slot_blob, ci, windows)
                if read is not None:
                    break
            if read is None:
                return None
            point1_slot, code, margin, ring_codes = read
            try:
                ids = cfg.decode(code)
            except CodeError:
                return None
        complete = self._complete_rings(slot_blob, windows)
        if not complete:
            return None
        points = np.full((cfg.n_dots, 2), np.nan)
        areas = np.full(cfg.n_dots, np.nan)
        points[0] = centres[ci]
        areas[0] = frame.area[ci]
        for ring in range(n_rings):
            for k in range(RING_POINTS):
                d = cfg.dot_index(ring, (k - point1_slot) % RING_POINTS + 1)
                if (ring, k) in windows:
                    points[d], ys, _ = windows[ring, k]
                    areas[d] = len(ys)
                elif slot_blob[ring, k] >= 0:
                    points[d] = centres[slot_blob[ring, k]]
                    areas[d] = frame.area[slot_blob[ring, k]]
        # Homography in final dot order (point 1 up) for the callers.
        H_final = H @ _rotation_about_z(point1_slot * np.pi / 4)
        outer = complete[0]
        ring_px = points[[cfg.dot_index(outer, k) for k in range(1, RING_POINTS + 1)]]
        size = 0.5 * float(np.max(np.linalg.norm(ring_px[:, None] - ring_px[None], axis=2)))
        card = CardDetection(code, ids, points, areas, tuple(complete), size, H_final,
                             float(margin), tuple(ring_codes))
        return card, {ci} | set(slot_blob[slot_blob >= 0].tolist())

    def _fit_homography(self, obj: np.ndarray, img: np.ndarray):
        """Homography with outlier rejection; the centre (last point) must be an inlier."""
        if len(obj) < 6:
            return None, None
        tol_radius = np.full(len(obj), self.config.ring_dot_radius)
        tol_radius[-1] = self.config.centre_dot_radius
        inliers = np.ones(len(obj), dtype=bool)
        tol = None
        for _ in range(3):
            H, _ = cv2.findHomography(obj[inliers], img[inliers], 0)
            if H is None:
                return None, None
            err = np.linalg.norm(_apply_h(H, obj) - img, axis=1)
            if tol is None:
                # Tolerance relative to each dot's image radius.
                tol = np.maximum(self.params.max_homography_error * _h_scale(H, obj)
                                 * tol_radius, 0.75)
            now = err < tol
            if np.count_nonzero(now) < 6 or not now[-1]:
                return None, None
            if np.array_equal(now, inliers):
                break
            inliers = now
        return H, inliers

    def _check_added(self, frame: '_Frame', H: np.ndarray, slot_blob: np.ndarray,
                     added: List[int], centres: dict) -> None:
        """Drop recovered dots whose measured centre is off the homography (in place)."""
        for ring, k in np.argwhere(np.isin(slot_blob, added)):
            model = self._model[self.config.dot_index(int(ring), int(k) + 1)][None]
            centre = centres[slot_blob[ring, k]][None]
            if frame.camera is not None:
                centre = frame.camera.undistort_pixels(centre)
            tol = max(0.75, self.params.max_homography_error * float(_h_scale(H, model)[0])
                      * self.config.ring_dot_radius)
            if np.linalg.norm(_apply_h(H, model)[0] - centre[0]) > tol:
                slot_blob[ring, k] = -1

    @staticmethod
    def _complete_rings(slot_blob: np.ndarray, windows: dict) -> List[int]:
        filled = slot_blob >= 0
        for ring, k in windows:
            filled[ring, k] = True
        return [ring for ring in range(slot_blob.shape[0]) if np.all(filled[ring])]

    def _sizes_fit(self, frame: '_Frame', H: np.ndarray, slot_blob: np.ndarray,
                   ci: int) -> bool:
        """
        Drop ring dots whose blob is far from the size the homography predicts.

        A dark object over a dot, or a dot merged with a neighbour, is a blob
        too big for one dot: its centre and colour are not the dot's. Returns
        False when the centre blob itself does not fit (the card is rejected).
        """
        cfg = self.config
        assigned = slot_blob >= 0
        model = np.vstack([self._model[:1], self._slot_xy[assigned]])
        radius = _h_scale(H, model)
        radius[0] *= cfg.centre_dot_radius
        radius[1:] *= cfg.ring_dot_radius
        predicted = np.pi * radius ** 2
        ratio = frame.area[np.concatenate([[ci], slot_blob[assigned]])] / predicted
        # Small dots are left alone: blur and thresholding change their area most.
        judged = predicted >= 12.0
        if judged[0] and not 0.25 <= ratio[0] <= 2.0:
            return False
        misfit = judged[1:] & ((ratio[1:] > 2.4) | (ratio[1:] < 0.2))
        rows, cols = np.nonzero(assigned)
        slot_blob[rows[misfit], cols[misfit]] = -1
        return True

    def _fill_missing(self, frame: '_Frame', H: np.ndarray, slot_blob: np.ndarray,
                      ci: int) -> None:
        """Assign blobs found where the homography predicts a missing dot (in place)."""
        missing = np.argwhere(slot_blob < 0)
        if len(missing) == 0:
            return
        used = set(slot_blob[slot_blob >= 0].tolist()) | {ci}
        positions = np.column_stack([frame.u, frame.v])
        model = np.array([self._model[self.config.dot_index(int(r), int(k) + 1)]
                          for r, k in missing])
        pred = _apply_h(H, model)
        if frame.camera is not None and frame.camera.has_distortion:
            pred = frame.camera.distort_pixels(pred)
        tol = np.maximum(0.75, self.params.max_homography_error * _h_scale(H, model)
                         * self.config.ring_dot_radius)
        for (ring, k), p, t in zip(missing, pred, tol):
            d = np.hypot(positions[:, 0] - p[0], positions[:, 1] - p[1])
            j = int(np.argmin(d))
            if d[j] < t and j not in used:
                slot_blob[ring, k] = j
                used.add(j)

    def _window_dots(self, frame: '_Frame', H: np.ndarray, slot_blob: np.ndarray) -> dict:
        """
        Measure dots in windows where the homography predicts them.

        For every slot with a missing dot, both rings' dots of that slot are
        measured this way (a dot merged with its neighbour was assigned to one
        ring with a centre pulled towards the other). Each pixel counts for
        the nearest predicted dot only. Returns ``{(ring, k): (centre, ys, xs)}``
        with the pixels of each dot's core, for the ones dark enough.
        """
        cfg = self.config
        n_rings = slot_blob.shape[0]
        slots = [(ring, k) for ring in range(n_rings) for k in range(RING_POINTS)]
        model = np.array([self._model[cfg.dot_index(ring, k + 1)] for ring, k in slots]
                         + [self._model[0]])
        pred = _apply_h(H, model)
        radius = _h_scale(H, model) * cfg.ring_dot_radius
        if frame.camera is not None and frame.camera.has_distortion:
            pred = frame.camera.distort_pixels(pred)
        wanted = {k for ring, k in np.argwhere(slot_blob < 0)}
        out = {}
        h, w = frame.darkest.shape
        for i, (ring, k) in enumerate(slots):
            if k not in wanted:
                continue
            px, py = pred[i]
            r = max(1.5, radius[i] + 0.5)
            outer = 2.0 * r      # the paper around a dot must be lighter than the dot
            x0, x1 = int(px - outer), int(px + outer) + 2
            y0, y1 = int(py - outer), int(py + outer) + 2
            if x0 < 1 or y0 < 1 or x1 > w - 1 or y1 > h - 1:
                continue        # cut by the image border: its centre would be false
            yy, xx = np.mgrid[y0:y1, x0:x1]
            d2 = (xx - px) ** 2 + (yy - py) ** 2
            others = np.delete(pred, i, axis=0)
            near = others[np.hypot(others[:, 0] - px, others[:, 1] - py) < 2 * outer]
            voronoi = np.ones_like(d2, dtype=bool)
            for ox, oy in near:
                voronoi &= d2 < (xx - ox) ** 2 + (yy - oy) ** 2
            cell = voronoi & (d2 <= r * r)
            ring_cell = voronoi & (d2 > r * r) & (d2 <= outer * outer)
            level = 0.96 * float(frame.white_small[min(int(py) // frame.step,
                                                       frame.white_small.shape[0] - 1),
                                                   min(int(px) // frame.step,
                                                       frame.white_small.shape[1] - 1)])
            dark = np.clip(level - frame.darkest[y0:y1, x0:x1].astype(np.float32), 0.0, None)
            # A dot, not an occluder or a shadow: dark inside, paper around it.
            if not np.any(ring_cell) or dark[ring_cell].mean() > 0.5 * dark[cell].mean():
                continue
            dark = dark * cell
            total = float(dark.sum())
            if total <= 0 or dark.max() < self.params.min_window_darkness * level:
                continue
            cx = float((dark * xx).sum()) / total
            cy = float((dark * yy).sum()) / total
            tolerance = max(0.75, self.params.max_homography_error * radius[i])
            if np.hypot(cx - px, cy - py) > tolerance:
                continue
            core = cell & (dark >= dark[cell].mean())
            if np.any(core):
                out[ring, k] = (np.array([cx, cy]), yy[core], xx[core])
        return out

    # Colours ---------------------------------------------------------------

    def _read_colours(self, frame: '_Frame', H: np.ndarray, slot_blob: np.ndarray, ci: int,
                      windows: dict):
        """
        Return point 1's slot, the code, a margin and each ring's colours; None if unclear.

        Each dot's darkness (1 - colour / card white, per channel, linear
        light) is split into its mean and its chromatic part. White
        normalisation cancels coloured light; blur and JPEG chroma loss mix
        a dot with paper or grey, which shrinks the chromatic part but keeps
        its direction. Point 1 is the slot whose dots are the least chromatic
        (black), clearly less than any other slot; every other dot takes the
        printed colour whose chromatic direction is nearest, and must be
        clearly nearer to it than to the others. Both rings must agree.
        """
        p = self.params
        ref_white = self._card_white(frame, H)
        if ref_white is None:
            return None
        n_rings = slot_blob.shape[0]
        blob_slot = slot_blob >= 0
        for ring, k in windows:
            blob_slot[ring, k] = False
        measured = np.empty((1 + RING_POINTS * n_rings, 3))
        rows = np.full((n_rings, RING_POINTS), -1)
        rows[blob_slot] = np.arange(1, 1 + np.count_nonzero(blob_slot))
        measured[:1 + np.count_nonzero(blob_slot)] = frame.darkness(
            [ci] + slot_blob[blob_slot].tolist(), ref_white, p.gamma)
        row = 1 + np.count_nonzero(blob_slot)
        for (ring, k), (_, ys, xs) in windows.items():
            measured[row] = linear_darkness(frame.image[ys, xs], ref_white, p.gamma).mean(axis=0)
            rows[ring, k] = row
            row += 1
        assigned = rows >= 0
        measured = measured[np.concatenate([[0], rows[assigned]])]
        if np.any(measured.max(axis=1) < p.min_darkness):
            return None
        chroma = measured - measured.mean(axis=1, keepdims=True)
        strength = np.linalg.norm(chroma, axis=1) / measured.max(axis=1)
        # Slot of point 1: the least chromatic on average over the rings.
        slot_strength = np.zeros((n_rings, RING_POINTS))
        slot_strength[assigned] = strength[1:]
        count = assigned.sum(axis=0)
        if np.any(count == 0):
            return None
        point1 = int(np.argmin(slot_strength.sum(axis=0) / count))
        black = float(slot_strength[assigned[:, point1], point1].max())
        others = assigned.copy()
        others[:, point1] = False
        weakest_colour = float(slot_strength[others].min())
        if black > p.max_black_chroma or weakest_colour < p.min_colour_chroma_ratio * black \
                or weakest_colour < p.min_colour_chroma:
            return None
        # Colours of the chromatic dots: nearest printed direction, with a margin.
        cosine = (chroma / np.maximum(np.linalg.norm(chroma, axis=1, keepdims=True), 1e-9)
                  ) @ self._colour_directions.T                   # (m, 3) for R, G, B
        ranked = np.sort(cosine, axis=1)
        letter = np.argmax(cosine, axis=1)
        margin = ranked[:, -1] - ranked[:, -2]
        slot_letter = np.full((n_rings, RING_POINTS), -1)
        slot_letter[assigned] = letter[1:]
        slot_margin = np.full((n_rings, RING_POINTS), np.inf)
        slot_margin[assigned] = margin[1:]
        colour_slot = assigned.copy()
        colour_slot[:, point1] = False
        if np.any(slot_margin[colour_slot] < p.min_colour_margin):
            return None
        slot_letter[~colour_slot] = -1
        agreed = slot_letter.max(axis=0)
        if np.any((slot_letter >= 0) & (slot_letter != agreed[None, :])):
            return None                 # the rings disagree: never guess
        slots = [(point1 + i) % RING_POINTS for i in range(RING_POINTS)]
        letters = 'K' + ''.join('RGB'[agreed[k]] for k in slots[1:])
        margins = [weakest_colour - black] + slot_margin[colour_slot].tolist()
        # The centre: black if it is as grey as point 1 (nearer to it than to
        # the weakest colour), else its nearest colour.
        slot_top = np.zeros((n_rings, RING_POINTS))
        slot_top[assigned] = measured[1:].max(axis=1)
        if strength[0] <= 0.5 * (black + weakest_colour):
            # Black ink, not a grey object over the centre: as dark as point 1.
            if measured[0].max() < p.min_black_centre * slot_top[:, point1].max():
                return None
            centre_letter = 'K'
        elif margin[0] >= p.min_colour_margin and strength[0] >= p.min_colour_chroma:
            centre_letter = 'RGB'[letter[0]]
            margins.append(float(margin[0]))
        else:
            return None
        ring_codes = tuple('K' + ''.join('RGB'[slot_letter[ring, k]] if slot_letter[ring, k] >= 0
                                         else '?' for k in slots[1:])
                           for ring in range(n_rings))
        try:
            code = Code.parse(f'{centre_letter}-{letters}')
        except CodeError:
            return None
        return point1, code, float(min(margins)), ring_codes

    def _card_white(self, frame: '_Frame', H: np.ndarray) -> Optional[np.ndarray]:
        """Median colour of the card's paper at points between the dots."""
        pts = _apply_h(H, self._white_xy)
        if frame.camera is not None and frame.camera.has_distortion:
            pts = frame.camera.distort_pixels(pts)
        h, w = frame.image.shape[:2]
        inside = (pts[:, 0] >= 1) & (pts[:, 0] < w - 1) & (pts[:, 1] >= 1) & (pts[:, 1] < h - 1)
        pts = pts[inside]
        if len(pts) < 4:
            return None
        xs = np.round(pts[:, 0]).astype(int)
        ys = np.round(pts[:, 1]).astype(int)
        samples = np.sort(frame.image[ys, xs], axis=0)
        white = samples[len(samples) // 2].astype(np.float32)     # median per channel
        if np.max(white) < self.params.min_white:
            return None
        return np.maximum(white, 1.0)


class _Frame:
    """One image's segmentation: the kept connected components and their pixels."""

    def __init__(self, image, darkest, white_small, step, labels, n_labels, camera, grey_only,
                 u, v, area, box, label):
        self.image = image
        self.darkest = darkest
        self.white_small = white_small      # local white, decimated by `step`
        self.step = step
        self.labels = labels
        self.n_labels = n_labels
        self.camera = camera
        self.grey_only = grey_only
        self.u, self.v, self.area = u, v, area
        self.box = box          # x, y, w, h of each component
        self.label = label      # its label in `labels`

    def covariance(self, j: int) -> np.ndarray:
        """Second central moments of component ``j`` (with pixel quantisation)."""
        x, y, w, h = self.box[j]
        m = cv2.moments((self.labels[y:y + h, x:x + w] == self.label[j]).view(np.uint8),
                        binaryImage=True)
        a = max(m['m00'], 1.0)
        return np.array([[m['mu20'] / a + 1 / 12, m['mu11'] / a],
                         [m['mu11'] / a, m['mu02'] / a + 1 / 12]])

    def _card_roi(self, js: Sequence[int], margin: int):
        """Box around components ``js`` and a map of their pixels (1..m; 0 = none)."""
        box = self.box[np.asarray(js)]
        H, W = self.darkest.shape
        x0 = max(0, int(box[:, 0].min()) - margin)
        y0 = max(0, int(box[:, 1].min()) - margin)
        x1 = min(W, int((box[:, 0] + box[:, 2]).max()) + margin)
        y1 = min(H, int((box[:, 1] + box[:, 3]).max()) + margin)
        lab = self.labels[y0:y1, x0:x1]
        self._roi_origin = (x0, y0)
        lut = np.zeros(self.n_labels, np.uint8)
        lut[self.label[np.asarray(js)]] = np.arange(1, len(js) + 1)
        return x0, y0, x1, y1, lab, lut[lab]

    def centroids(self, js: Sequence[int]) -> np.ndarray:
        """Return the darkness-weighted centre, shape (m, 2), of each dot with a 2 px rim."""
        x0, y0, x1, y1, lab, own = self._card_roi(js, 2)
        # Background pixels next to a dot belong to the rim of the nearest dot
        # (blur spreads each dot; splitting shared rims by distance keeps the
        # neighbours' halos out symmetrically).
        region = own.copy()
        rim_y, rim_x = np.nonzero((cv2.dilate(own, np.ones((5, 5), np.uint8)) > 0) & (lab == 0))
        if len(rim_x):
            js_arr = np.asarray(js)
            du = (rim_x + x0)[:, None] - self.u[js_arr][None, :]
            dv = (rim_y + y0)[:, None] - self.v[js_arr][None, :]
            region[rim_y, rim_x] = np.argmin(du * du + dv * dv, axis=1) + 1
        # The paper's white, less a small floor so that paper noise in the rim
        # does not pull the centroid.
        py, px = np.nonzero(region)
        ids = region[py, px]
        level = 0.96 * self.white_small[
            np.minimum((py + y0) // self.step, self.white_small.shape[0] - 1),
            np.minimum((px + x0) // self.step, self.white_small.shape[1] - 1)]
        dark = np.clip(level - self.darkest[py + y0, px + x0], 0.0, None)
        m = len(js) + 1
        total = np.bincount(ids, dark, m)[1:]
        cx = np.bincount(ids, dark * px, m)[1:]
        cy = np.bincount(ids, dark * py, m)[1:]
        js_arr = np.asarray(js)
        out = np.column_stack([self.u[js_arr], self.v[js_arr]])
        ok = total > 0
        out[ok] = np.column_stack([x0 + cx[ok] / total[ok], y0 + cy[ok] / total[ok]])
        return out

    def darkness(self, js: Sequence[int], ref_white: np.ndarray, gamma: float) -> np.ndarray:
        """Return each dot's per-channel darkness, shape (m, 3): 1 - colour / white, linear."""
        _, _, _, _, _, own = self._card_roi(js, 0)
        x0, y0 = self._roi_origin
        pick = own > 0
        ids = own[pick].astype(np.intp) - 1
        pix = self.image[y0:y0 + own.shape[0], x0:x0 + own.shape[1]][pick]
        dark = linear_darkness(pix, ref_white, gamma)
        strength = dark.max(axis=1)
        m = len(js)
        # The core: each dot's pixels darker than its mean (blur mixes the rim
        # with paper).
        mean = np.bincount(ids, strength, m) / np.maximum(np.bincount(ids, minlength=m), 1)
        core = strength >= mean[ids]
        count = np.maximum(np.bincount(ids[core], minlength=m), 1)
        return np.column_stack([np.bincount(ids[core], dark[core, c], m) / count
                                for c in range(3)])


def linear_darkness(pixels: np.ndarray, white: np.ndarray, gamma: float) -> np.ndarray:
    """
    Return 1 - colour / white per channel in linear light, for uint8 pixels (N, 3).

    In linear light a blurred dot is a mix of ink and paper, so the ratios
    between the channels of its darkness do not depend on its size or blur.
    A lookup table per channel makes this cheap.
    """
    levels = np.arange(256, dtype=np.float32)[:, None] / np.asarray(white, np.float32)[None, :]
    table = 1.0 - np.clip(levels, 0.0, 1.0) ** gamma          # (256, 3)
    return np.column_stack([table[pixels[:, c], c] for c in range(3)])


def _colour_directions(config: PatternConfig) -> np.ndarray:
    """Return the unit chromatic directions (rows R, G, B; columns B, G, R) of the inks."""
    rows = []
    for letter in 'RGB':
        dark = 1.0 - srgb_to_linear(config.colour_rgb(letter)[::-1])
        chroma = dark - dark.mean()
        rows.append(chroma / np.linalg.norm(chroma))
    return np.array(rows)


def _white_sample_points(config: PatternConfig) -> np.ndarray:
    """Pattern-plane points on white paper: between ring dots and towards the corners."""
    pts = []
    mids = np.deg2rad(22.5 + 45.0 * np.arange(RING_POINTS))
    for radius in config.ring_radii:
        pts.extend(radius * np.column_stack([np.sin(mids), np.cos(mids)]))
    outer = config.ring_radii[0] + config.ring_dot_radius
    corner = 0.5 * (outer + config.card_size / 2 * np.sqrt(2))
    if corner > outer + 0.5 * config.ring_dot_radius:
        diag = np.deg2rad(45.0 + 90.0 * np.arange(4))
        pts.extend(corner * np.column_stack([np.sin(diag), np.cos(diag)]))
    return np.array(pts)


def _check_image(image: np.ndarray) -> np.ndarray:
    if not isinstance(image, np.ndarray):
        raise ImageError(f'image must be a numpy array, got {type(image).__name__}')
    if image.dtype != np.uint8:
        raise ImageError(f'image must be 8-bit (uint8), got {image.dtype}')
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    if image.ndim == 3 and image.shape[2] == 4:
        image = image[:, :, :3]
    if not (image.ndim == 2 or (image.ndim == 3 and image.shape[2] == 3)):
        raise ImageError(f'image must be HxW grey or HxWx3 BGR, got shape {image.shape}')
    if image.shape[0] < 16 or image.shape[1] < 16:
        raise ImageError(f'image too small: {image.shape[1]}x{image.shape[0]}')
    return np.ascontiguousarray(image)


def _min_channel(image: np.ndarray) -> np.ndarray:
    """Per-pixel minimum over B, G, R: an erosion along the interleaved row."""
    h, w = image.shape[:2]
    rows = cv2.erode(image.reshape(h, w * 3), np.ones((1, 3), np.uint8))
    return np.ascontiguousarray(rows[:, 1::3])


def _wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


def _apply_h(H: np.ndarray, xy: np.ndarray) -> np.ndarray:
    p = np.column_stack([xy[:, 0], xy[:, 1], np.ones(len(xy))]) @ H.T
    return p[:, :2] / p[:, 2:3]


def _h_scale(H: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Local image scale (px per metre) of the homography at plane points."""
    p = np.column_stack([xy[:, 0], xy[:, 1], np.ones(len(xy))]) @ H.T
    u, v, w = p[:, 0] / p[:, 2], p[:, 1] / p[:, 2], p[:, 2]
    # Jacobian of (u, v) with respect to (x, y), divided by w.
    a = H[0, 0] - u * H[2, 0]
    b = H[0, 1] - u * H[2, 1]
    c = H[1, 0] - v * H[2, 0]
    d = H[1, 1] - v * H[2, 1]
    return np.sqrt(np.abs(a * d - b * c)) / np.abs(w)


def _rotation_about_z(angle: float) -> np.ndarray:
    """
    Plane map taking final model coordinates to slot-ordered ones.

    Slot ``k`` holds point ``k - point1_slot + 1``; slot coordinates are the
    final ones turned clockwise (seen from the front) by ``point1_slot``
    steps of 45 degrees.
    """
    c, s = np.cos(angle), np.sin(angle)
    # Clockwise by `angle` in a frame with y up: (x, y) -> (x c + y s, -x s + y c).
    return np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
