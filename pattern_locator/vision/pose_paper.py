"""
The paper's pose estimator ("paper" method): ellipse, swing, tilt, pan, distance.

A faithful implementation of section 3.1 of the source paper (IFAC 2002), as
re-derived in ``method.md`` section 3. Frames and angles (method.md 1-2):
pattern frame x right, y up (towards point 1), z out of the wall; camera
optical frame x right, y down, z forward. ``phi`` (tilt) is the angle between
the pattern normal and the line from the pattern centre to the camera,
``theta`` (pan) the azimuth of that line on the pattern plane from +y towards
+x, ``psi`` (swing) the angle of the ellipse's long axis to the image's
horizontal, and ``D`` the distance from the optical centre to the pattern
centre. The camera sits at ``C = D (sin phi sin theta, sin phi cos theta,
cos phi)``. The paper reports ``D' = D + f_mm`` (image plane to pattern
centre); ``distance_m`` here is ``D``.

Steps per ring (8 points, all needed): conic fit with F = -1 (eq. 1), swing
from the conic (eq. 2, with atan2, then the long axis), the conic in the frame
rotated by psi (eq. 3-4), ellipse centre and semi-axes (eq. 5-7), tilt from
``cos phi = b / a`` (eq. 12), pan from points 1, 3, 5, 7 (eq. 15-17 as
re-derived in method.md, averaged on the circle) and ``D = f R / a``
(eq. 11).

Virtual rotation. The paper assumes the optical axis passes through the
pattern centre: its pan/tilt head tracks the card. Our images may show the
card anywhere, so the camera is first turned *virtually* about its optical
centre, by the smallest rotation ``Q`` that brings the ray of the centre dot
onto the optical axis. A pure rotation about the optical centre is an exact
homography for a calibrated camera: each dot's undistorted ray ``d`` becomes
``Q d``, and the virtual image is ``f_x * (Q d)_xy / (Q d)_z`` with the
principal point at the origin. This is exactly what the tracking head does
physically. The paper's method runs in that virtual image (where the centre
dot is the origin, like the paper's computer frame O_s) and the pose is
rotated back: ``R_cam = Q^T R_virtual``. With a centred card ``Q`` is the
identity. When the centre dot is not seen, the ray of the outer usable ring's
conic centre is used instead (twice, so that the conic centre lands on the
virtual axis); then, for each 180-degree branch, the camera is re-aimed at the
image of the circle's centre, the pole of the plane's vanishing line with
respect to the ring's image conic (the normal comes from that branch's
angles), and the method is run again. Without that correction the aim is off
by the ellipse-centre bias, which is as large as the perspective cue that
tells the branches apart, and the branch choice becomes a coin toss.

Exactness. With the camera aimed at the centre, the swing and the pan
formulas are exact under full perspective (the image is symmetric about the
image of the plane holding the normal and the line of sight, and the per-point
scale ``f R / depth_k`` cancels in each pan formula, so pan is exact given the
tilt). Only the tilt
(``cos phi = b / a``) and the distance (``a = f R / D``) rely on weak
perspective, ``R sin phi << D``; their errors are of second order in
``R sin phi / D``.

Orientation. Let ``m = (sin theta, cos theta, 0)`` (towards the camera, in
the pattern plane), ``l = (cos theta, -sin theta, 0)`` and ``w = cos phi m -
sin phi z``; ``l`` and ``w`` are perpendicular to the line of sight ``n =
C / D``. A ring point is ``R (sin(alpha - theta) l + cos(alpha - theta) m)``
and is seen, in the image axes rotated by psi, at ``u' = k sin(alpha -
theta)`` along ``l`` and ``v' = -k cos phi cos(alpha - theta)`` along ``-w``
(method.md step 6). The psi-rotated axes are ``e_u = (cos psi, sin psi)``
and ``e_v = (-sin psi, cos psi)`` in pixels, so the camera axes in the
pattern frame are ``x_c = cos psi l + sin psi w``, ``y_c = sin psi l - cos
psi w`` and ``z_c = -n`` (a right-handed frame; checked by the tests).

The 180-degree branch. ``(psi, theta)`` and ``(psi + 180, theta + 180)``
explain the same image. Under weak perspective they are the two mirror
solutions of a planar target (the "Necker" pair): the camera axes have the
same components in the pattern plane and opposite components along the
normal, and the camera positions are mirrored about the normal, ``C ->
(-C_x, -C_y, C_z)``. Both cameras are upright (the upright camera below the
card and the upright camera above it, looking down, see the same ellipse with
point 1 at the top), so "keep the branch whose camera down axis points along
the pattern's -y" cannot decide: that dot product is the same for both. The
only evidence in one image is perspective (the near half of the ring images
larger, so the ring's points are not where weak perspective puts them), so
both poses are reprojected through the full camera model and the one with
the smaller reprojection error is kept. ``ambiguity_ratio`` (the other
branch's RMS over the kept one's) says how clear the choice was: near 1 at
long range or nearly frontal views, where noise decides, and the mirrored
pose (``alternative_T_camera_pattern``) is returned for the caller to decide
with what it knows (head tilt, camera height, continuity).

Two rings. Each complete ring is fitted on its own (the paper's method, ring
by ring) and the results are combined with weights ``R_i^2``: with the same
pixel noise on both rings, the errors of ``b / a``, of the pan formulas and
of ``da / a`` (so of ``dD / D``) scale as ``1 / a_i``, proportional to
``1 / R_i``, and inverse-variance weights are ``R_i^2``. Angles are averaged
on the circle after bringing each ring's swing to the outer ring's branch.

Rejection. The paper rejects views with ``phi < 25 deg`` (low eccentricity,
unreliable swing and pan); ``min_tilt_deg`` (default 0 = off) applies that
rule and a rejected view raises :class:`EstimationError` saying why, like
every other failure (no complete ring, a conic that is not an ellipse).
"""

from dataclasses import dataclass
import math
from typing import List, Optional, Tuple

import numpy as np

from .camera import CameraModel
from .geometry import Pose, rodrigues
from ..card.pattern import PatternConfig, RING_POINTS
from ..errors import EstimationError


@dataclass(frozen=True)
class PaperEstimate:
    """Result of :func:`estimate_paper` (angles in degrees, lengths in metres)."""

    psi_deg: float
    phi_deg: float
    theta_deg: float
    # D, optical centre to pattern centre; the paper reports D' = D + f_mm.
    distance_m: float
    T_camera_pattern: Pose
    camera_in_pattern: np.ndarray
    rings_used: Tuple[int, ...]
    # Outer ring used: centre u, v (px, virtual image), a, b (px), psi (rad).
    ellipse: Tuple[float, float, float, float, float]
    reprojection_rms_px: float
    # Other 180-degree branch (the mirrored pose) and its RMS over the kept one's.
    ambiguity_ratio: float = float('nan')
    alternative_T_camera_pattern: Optional[Pose] = None


@dataclass(frozen=True)
class RingView:
    """The paper's viewing parameters from one ring (radians, pixels)."""

    psi: float
    phi: float
    theta: float
    a: float
    b: float
    u0: float
    v0: float


def fit_conic(points: np.ndarray) -> np.ndarray:
    """
    Least-squares conic ``A u^2 + B u v + C v^2 + D u + E v = 1`` (eq. 1, F = -1).

    Returns ``(A, B, C, D, E)``. The origin must not lie on the conic (in the
    paper's frame it is the centre dot, inside the ellipse).
    """
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    if len(pts) < 5 or not np.all(np.isfinite(pts)):
        raise EstimationError(f'conic fit needs at least 5 finite points, got {len(pts)}')
    # Scaling the coordinates leaves this least-squares problem unchanged (each
    # coefficient scales with its monomial) but keeps it well conditioned.
    scale = float(np.sqrt(np.mean(np.sum(pts ** 2, axis=1))))
    if scale <= 0.0:
        raise EstimationError('degenerate conic: all ring points at the origin')
    u, v = pts[:, 0] / scale, pts[:, 1] / scale
    M = np.column_stack([u * u, u * v, v * v, u, v])
    sv = np.linalg.svd(M, compute_uv=False)
    if sv[-1] < 1e-9 * sv[0]:
        raise EstimationError('degenerate conic: the ring points do not fix a conic '
                              '(collinear or repeated points)')
    coef, *_ = np.linalg.lstsq(M, np.ones(len(pts)), rcond=None)
    return coef / np.array([scale ** 2, scale ** 2, scale ** 2, scale, scale])


def ellipse_from_conic(conic: np.ndarray) -> Tuple[float, float, float, float, float]:
    """
    Centre ``(u0, v0)``, semi-axes ``a >= b`` and swing ``psi`` (rad) of a conic.

    ``psi`` is the angle of the long axis to the image's u axis, in
    ``(-pi/2, pi/2]`` (the 180-degree branch is chosen later). Raises
    EstimationError if the conic is not a real ellipse.
    """
    A, B, C, D, E = (float(c) for c in conic)
    if B * B - 4.0 * A * C >= 0.0:
        raise EstimationError('degenerate conic: the ring points fit a hyperbola or a '
                              'parabola, not an ellipse')
    # Eq. 2 (psi = 1/2 atan(B / (A - C)), 45 deg if A = C), with atan2: this
    # gives the axis of the larger A', i.e. the short axis.
    psi = math.radians(45.0) if (A == C and B == 0.0) else 0.5 * math.atan2(B, A - C)

    def rotated(angle: float) -> Tuple[float, float, float, float]:
        # Eq. 3-4: the conic in the image frame rotated by psi (cross term 0).
        c, s = math.cos(angle), math.sin(angle)
        return (A * c * c + B * c * s + C * s * s, A * s * s - B * c * s + C * c * c,
                D * c + E * s, -D * s + E * c)

    Ar, Cr, Dr, Er = rotated(psi)
    if abs(Ar) > abs(Cr):
        # Long axis along u': turn by 90 degrees.
        psi += math.pi / 2.0
        Ar, Cr, Dr, Er = rotated(psi)
    # Eq. 5: M = D'^2 / (4 A') + E'^2 / (4 C') - F', F' = -1.
    M = Dr * Dr / (4.0 * Ar) + Er * Er / (4.0 * Cr) + 1.0
    if M / Ar <= 0.0 or M / Cr <= 0.0:
        raise EstimationError('degenerate conic: the fitted ellipse is imaginary')
    # Eq. 6-7: centre and semi-axes in the rotated frame, centre rotated back.
    ur, vr = -Dr / (2.0 * Ar), -Er / (2.0 * Cr)
    a, b = math.sqrt(M / Ar), math.sqrt(M / Cr)
    c, s = math.cos(psi), math.sin(psi)
    return ur * c - vr * s, ur * s + vr * c, a, b, _wrap(psi, math.pi)


def pan_from_points(ring_px: np.ndarray, psi: float, phi: float) -> float:
    """
    Pan theta (rad) from ring points 1, 3, 5, 7 (method.md step 6, eq. 15-17).

    ``ring_px`` holds the 8 ring points (point 1 first) relative to the image
    of the pattern centre, in pixels of the camera aimed at the centre.
    """
    pts = np.asarray(ring_px, dtype=float).reshape(RING_POINTS, 2)
    c, s = math.cos(psi), math.sin(psi)
    # Coordinates in the frame rotated by psi (long axis along u').
    u = pts[:, 0] * c + pts[:, 1] * s
    v = -pts[:, 0] * s + pts[:, 1] * c
    cphi = math.cos(phi)
    if cphi < 1e-9:
        raise EstimationError('tilt of 90 degrees: the ring is seen edge-on')
    thetas = [
        math.atan2(-u[0], -v[0] / cphi),
        math.atan2(-v[2] / cphi, u[2]),
        math.atan2(u[4], v[4] / cphi),
        math.atan2(v[6] / cphi, -u[6]),
    ]
    # The paper averages the four values; average them on the circle.
    return math.atan2(sum(map(math.sin, thetas)), sum(map(math.cos, thetas)))


def ring_view(ring_px: np.ndarray, centre_px: Tuple[float, float] = (0.0, 0.0)) -> RingView:
    """
    Compute the paper's psi, phi, theta and ellipse from one ring's 8 points (pixels).

    The points are in the image of a camera aimed at the pattern centre, whose
    image is ``centre_px`` (the paper's origin O_s). ``psi`` is the long-axis
    branch in ``(-pi/2, pi/2]``; ``theta`` goes with that branch.
    """
    pts = np.asarray(ring_px, dtype=float).reshape(RING_POINTS, 2)
    u0, v0, a, b, psi = ellipse_from_conic(fit_conic(pts))
    # Eq. 12: cos phi = b / a.
    phi = math.acos(min(1.0, b / a))
    theta = pan_from_points(pts - np.asarray(centre_px, dtype=float), psi, phi)
    return RingView(psi, phi, theta, a, b, u0, v0)


def camera_position(phi: float, theta: float, distance: float) -> np.ndarray:
    """Optical centre in the pattern frame (method.md section 2)."""
    return distance * np.array([math.sin(phi) * math.sin(theta),
                                math.sin(phi) * math.cos(theta), math.cos(phi)])


def camera_axes(psi: float, phi: float, theta: float) -> np.ndarray:
    """``R_pattern_camera``: columns x_c, y_c, z_c of the aimed camera, pattern frame."""
    m = np.array([math.sin(theta), math.cos(theta), 0.0])
    l_dir = np.array([math.cos(theta), -math.sin(theta), 0.0])
    w = math.cos(phi) * m - math.sin(phi) * np.array([0.0, 0.0, 1.0])
    n = camera_position(phi, theta, 1.0)
    # The long axis (image of l, u' = +e_u) and v' = -w along e_v (module docstring).
    x_c = math.cos(psi) * l_dir + math.sin(psi) * w
    y_c = math.sin(psi) * l_dir - math.cos(psi) * w
    return np.column_stack([x_c, y_c, -n])


def pose_from_angles(psi: float, phi: float, theta: float, distance: float) -> Pose:
    """``T_camera_pattern`` of a camera aimed at the pattern centre."""
    R_pc = camera_axes(psi, phi, theta)
    C = camera_position(phi, theta, distance)
    return Pose(R_pc.T, -R_pc.T @ C)


def estimate_paper(points_px: np.ndarray, camera: CameraModel, config: PatternConfig,
                   min_tilt_deg: float = 0.0) -> PaperEstimate:
    """
    Camera pose from the dots by the paper's method (see the module docstring).

    ``points_px`` is ``(n_dots, 2)``: detected dot centres in image pixels
    (distorted image), in dot-index order, with NaN rows for dots not seen. A
    ring is used only if all 8 of its points are seen. Raises EstimationError
    if no ring is complete, a conic is not an ellipse, or ``phi`` is below
    ``min_tilt_deg``.
    """
    pts = np.asarray(points_px, dtype=float)
    if pts.shape != (config.n_dots, 2):
        raise EstimationError(f'expected {config.n_dots} dot centres of shape '
                              f'({config.n_dots}, 2), got shape {pts.shape}')
    seen = np.all(np.isfinite(pts), axis=1)
    rings: List[int] = []
    counts = []
    for ring in range(config.n_rings):
        idx = _ring_indices(ring)
        counts.append(int(np.sum(seen[idx])))
        if counts[-1] == RING_POINTS:
            rings.append(ring)
    if not rings:
        have = ', '.join(f'ring {i}: {c}/{RING_POINTS}' for i, c in enumerate(counts))
        raise EstimationError(f'no complete ring: the method of the paper needs all '
                              f'{RING_POINTS} points of a ring ({have})')
    f = camera.fx
    rays = np.full((config.n_dots, 3), np.nan)
    rays[seen] = np.column_stack([camera.normalize(pts[seen]), np.ones(int(np.sum(seen)))])

    radii = [config.ring_radii[r] for r in rings]
    # Virtual rotation bringing the centre dot's ray onto the optical axis.
    if seen[0]:
        Q = _rotation_to_axis(rays[0])
    else:
        # No centre dot: aim at the outer ring's conic centre (twice, so that
        # it lands on the virtual axis); corrected per branch below.
        Q = np.eye(3)
        for _ in range(2):
            virt = _virtual_pixels(rays[_ring_indices(rings[0])], Q, f)
            u0, v0, *_ = ellipse_from_conic(fit_conic(virt))
            Q = _rotation_to_axis(np.array([u0 / f, v0 / f, 1.0])) @ Q
    views, (psi, phi, theta, distance) = _solve(rays, rings, radii, Q, f)

    # The two 180-degree branches (the mirror pair of weak perspective): keep
    # the one that reprojects better through the full camera model.
    model = config.model_points()
    candidates = []
    for hypothesis in (psi, psi + math.pi):
        Qb, vb = Q, views
        angles = (hypothesis, phi, theta + hypothesis - psi, distance)
        if not seen[0]:
            # The projected circle centre is not the ellipse centre: it is the
            # pole of the plane's vanishing line (the normal, in normalised
            # coordinates) with respect to the ring's image conic. Re-aim there.
            normal = pose_from_angles(*angles).R[:, 2]
            virt = _virtual_pixels(rays[_ring_indices(rings[0])], Qb, f) / f
            A, B, C, D, E = fit_conic(virt)
            conic = np.array([[A, B / 2, D / 2], [B / 2, C, E / 2], [D / 2, E / 2, -1.0]])
            pole = np.linalg.solve(conic, normal)
            if abs(pole[2]) > 1e-12:
                Qb = _rotation_to_axis(pole / pole[2]) @ Qb
                vb, (p2, phi2, t2, d2) = _solve(rays, rings, radii, Qb, f)
                if abs(_wrap(p2 - hypothesis, 2 * math.pi)) > math.pi / 2:
                    p2, t2 = p2 + math.pi, t2 + math.pi
                angles = (p2, phi2, t2, d2)
        virtual = pose_from_angles(*angles)
        pose = Pose(Qb.T @ virtual.R, Qb.T @ virtual.t)
        residual = camera.project(pose.apply(model[seen])) - pts[seen]
        rms = float(np.sqrt(np.mean(np.sum(residual ** 2, axis=1))))
        candidates.append((rms, angles, pose, vb[0]))
    best, other = sorted(candidates, key=lambda c: c[0])
    rms, (psi, phi, theta, distance), pose, first = best

    if math.degrees(phi) < min_tilt_deg:
        raise EstimationError(f'view rejected: tilt phi = {math.degrees(phi):.1f} deg is below '
                              f'min_tilt_deg = {min_tilt_deg:.1f} deg (the paper rejects '
                              f'near-frontal views, phi < 25 deg: low eccentricity makes psi '
                              f'and theta unreliable)')
    # The reported ellipse's psi follows the kept branch.
    ellipse_psi = first.psi
    if abs(_wrap(psi - first.psi, 2 * math.pi)) > math.pi / 2:
        ellipse_psi = _wrap(first.psi + math.pi, 2 * math.pi)
    return PaperEstimate(
        psi_deg=math.degrees(_wrap(psi, 2 * math.pi)), phi_deg=math.degrees(phi),
        theta_deg=math.degrees(theta) % 360.0, distance_m=distance,
        T_camera_pattern=pose, camera_in_pattern=camera_position(phi, theta, distance),
        rings_used=tuple(rings),
        ellipse=(first.u0, first.v0, first.a, first.b, ellipse_psi),
        reprojection_rms_px=rms,
        ambiguity_ratio=other[0] / max(rms, 1e-12),
        alternative_T_camera_pattern=other[2])


def _solve(rays: np.ndarray, rings: List[int], radii: List[float], Q: np.ndarray,
           f: float) -> Tuple[List[RingView], Tuple[float, float, float, float]]:
    """Each ring's view in the virtual image of ``Q`` and their combination."""
    views = [ring_view(_virtual_pixels(rays[_ring_indices(r)], Q, f)) for r in rings]
    return views, _combine(views, radii, f)


def _combine(views: List[RingView], radii: List[float],
             f: float) -> Tuple[float, float, float, float]:
    """Psi, phi, theta (rad) and D of several rings, weights R_i^2."""
    weights = np.array(radii) ** 2
    psis, thetas = [], []
    for view in views:
        psi, theta = view.psi, view.theta
        # Bring each ring to the outer ring's 180-degree branch.
        if abs(_wrap(psi - views[0].psi, 2 * math.pi)) > math.pi / 2:
            psi, theta = psi + math.pi, theta + math.pi
        psis.append(psi)
        thetas.append(theta)
    phi = float(np.average([v.phi for v in views], weights=weights))
    # Eq. 11: a = f R / D.
    distance = float(np.average([f * r / v.a for v, r in zip(views, radii)], weights=weights))
    return _circular_mean(psis, weights), phi, _circular_mean(thetas, weights), distance


def _circular_mean(angles: List[float], weights: np.ndarray) -> float:
    return math.atan2(float(np.dot(weights, np.sin(angles))),
                      float(np.dot(weights, np.cos(angles))))


def _wrap(angle: float, period: float) -> float:
    """Angle in ``(-period / 2, period / 2]``."""
    out = math.remainder(angle, period)
    return out + period if out <= -period / 2 else out


def _ring_indices(ring: int) -> np.ndarray:
    return 1 + RING_POINTS * ring + np.arange(RING_POINTS)


def _rotation_to_axis(ray: np.ndarray) -> np.ndarray:
    """Smallest rotation Q with ``Q ray`` along +z (the virtual camera's axis)."""
    r = np.asarray(ray, dtype=float) / np.linalg.norm(ray)
    axis = np.cross(r, [0.0, 0.0, 1.0])
    sin_angle = float(np.linalg.norm(axis))
    if sin_angle < 1e-15:
        return np.eye(3)
    angle = math.atan2(sin_angle, float(r[2]))
    return rodrigues(axis / sin_angle * angle)


def _virtual_pixels(rays: np.ndarray, Q: np.ndarray, f: float) -> np.ndarray:
    """Pixels (principal point at 0) of rays (N, 3) seen by the rotated camera."""
    d = np.asarray(rays, dtype=float) @ Q.T
    if np.any(d[:, 2] <= 1e-9):
        raise EstimationError('a ring point is 90 degrees or more away from the centre ray')
    return f * d[:, :2] / d[:, 2:3]
