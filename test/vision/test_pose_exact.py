"""The exact estimator on synthetic projections with known truth."""

import math

import numpy as np
from pattern_locator.card.pattern import PatternConfig
from pattern_locator.errors import EstimationError
from pattern_locator.vision.camera import CameraModel
from pattern_locator.vision.geometry import look_at, Pose, rotation_angle
from pattern_locator.vision.pose_exact import (ellipse_centres, estimate_exact, paper_angles,
                                               pose_covariance, PosePrior)
import pytest

CFG = PatternConfig()


def pose_from(distance, phi_deg, theta_deg, roll_deg=0.0):
    """T_camera_pattern for a camera aimed at the centre from (phi, theta, D)."""
    phi, theta = math.radians(phi_deg), math.radians(theta_deg)
    c = distance * np.array([math.sin(phi) * math.sin(theta), math.sin(phi) * math.cos(theta),
                             math.cos(phi)])
    T_pattern_camera = look_at(c, np.zeros(3), up=(0.0, 1.0, 0.0), roll=math.radians(roll_deg))
    return T_pattern_camera.inverse()


def ellipse_observations(camera, T, rng=None, sigma=0.0):
    """Image-ellipse centres (what a detector measures), distorted, plus noise."""
    model = CFG.model_points()
    ideal = ellipse_centres(T, model[:, :2], CFG.dot_radii(), camera.K)
    rays = np.column_stack([(ideal - [camera.cx, camera.cy]) / [camera.fx, camera.fy],
                            np.ones(len(ideal))])
    px = camera.project(rays)
    if rng is not None:
        px = px + rng.normal(0.0, sigma, px.shape)
    return px


def test_ellipse_centre_is_the_centroid_of_the_projected_disc():
    camera = CameraModel.from_focal(640, 480, 1000.0)
    T = pose_from(1.3, 60.0, 20.0)
    centre = np.array([[0.0, 0.113]])
    radius = np.array([0.014])
    # Sample the disc densely, project, take the area centroid of the image.
    r = np.sqrt(np.linspace(0, 1, 400))[:, None] * radius
    a = np.linspace(0, 2 * np.pi, 400, endpoint=False)[None, :]
    # Area-weighted sample: project small quads via the Jacobian determinant.
    xs = (centre[0, 0] + r * np.cos(a)).ravel()
    ys = (centre[0, 1] + r * np.sin(a)).ravel()
    cam = np.column_stack([xs, ys, np.zeros_like(xs)]) @ T.R.T + T.t
    w = 1.0 / cam[:, 2] ** 3        # image area element of a plane patch ~ 1 / z^3
    uv = cam[:, :2] / cam[:, 2:3] * 1000.0 + [camera.cx, camera.cy]
    centroid = (uv * w[:, None]).sum(0) / w.sum()
    predicted = ellipse_centres(T, centre, radius, camera.K)[0]
    projected = camera.project((T.apply(np.array([[0.0, 0.113, 0.0]]))))[0]
    assert np.linalg.norm(predicted - centroid) < 0.01
    assert np.linalg.norm(predicted - projected) > 0.05   # the bias is real at this range


@pytest.mark.parametrize('distance, phi, theta, roll', [
    (1.25, 40.0, 10.0, 0.0), (3.0, 60.0, 200.0, 30.0), (6.0, 20.0, 90.0, -80.0),
    (2.0, 70.0, 300.0, 180.0),
])
def test_exact_pose_from_noise_free_points(distance, phi, theta, roll):
    camera = CameraModel.from_fov(1280, 720, 70.0, D=[-0.25, 0.07, 0.0, 0.0, 0.0])
    T = pose_from(distance, phi, theta, roll)
    est = estimate_exact(ellipse_observations(camera, T), camera, CFG)
    assert np.linalg.norm(est.camera_in_pattern - T.inverse().t) < 1e-4 * distance
    assert rotation_angle(est.T_camera_pattern.R, T.R) < 1e-4
    psi, phi_est, theta_est, d_est = paper_angles(est.T_camera_pattern, camera, CFG)
    assert phi_est == pytest.approx(phi, abs=1e-3)
    assert (theta_est - theta + 180) % 360 - 180 == pytest.approx(0.0, abs=1e-2)
    assert d_est == pytest.approx(distance, rel=1e-5)


def test_bias_correction_matters_at_short_range():
    camera = CameraModel.from_focal(640, 480, 1000.0)
    T = pose_from(1.25, 55.0, 30.0)
    obs = ellipse_observations(camera, T)
    with_fix = estimate_exact(obs, camera, CFG)
    without = estimate_exact(obs, camera, CFG, bias_correction=False)
    truth = T.inverse().t
    err_with = np.linalg.norm(with_fix.camera_in_pattern - truth)
    err_without = np.linalg.norm(without.camera_in_pattern - truth)
    assert err_with < 1e-5
    assert err_without > 20 * err_with


def test_covariance_matches_the_scatter_of_noisy_estimates():
    camera = CameraModel.from_focal(640, 480, 1000.0)
    T = pose_from(3.0, 45.0, 20.0)
    rng = np.random.default_rng(3)
    sigma = 0.2
    errors = []
    for _ in range(200):
        est = estimate_exact(ellipse_observations(camera, T, rng, sigma), camera, CFG,
                             pixel_sigma=sigma)
        errors.append(est.camera_in_pattern - T.inverse().t)
    errors = np.array(errors)
    crb = pose_covariance(T, CFG.model_points(), camera.K, sigma)[:3, :3]
    # The estimator is efficient: its scatter matches the Cramer-Rao bound.
    ratio = np.trace(np.cov(errors.T)) / np.trace(crb)
    assert 0.75 < ratio < 1.3
    # And its own covariance is close to the bound.
    assert np.trace(est.covariance[:3, :3]) / np.trace(crb) == pytest.approx(1.0, rel=0.3)


def test_one_ring_and_missing_dots():
    camera = CameraModel.from_focal(640, 480, 1000.0)
    T = pose_from(2.0, 50.0, 120.0)
    obs = ellipse_observations(camera, T)
    obs[1:9] = np.nan         # outer ring occluded
    est = estimate_exact(obs, camera, CFG)
    assert est.n_points == 9
    assert np.linalg.norm(est.camera_in_pattern - T.inverse().t) < 1e-4
    obs[9:15] = np.nan
    with pytest.raises(EstimationError, match='at least 6 dots'):
        estimate_exact(obs, camera, CFG)


def test_prior_resolves_the_flip_and_ambiguity_is_reported():
    # Far away and nearly frontal the two planar solutions explain the image
    # almost equally well.
    camera = CameraModel.from_focal(640, 480, 1000.0)
    T = pose_from(8.0, 12.0, 180.0)
    rng = np.random.default_rng(5)
    obs = ellipse_observations(camera, T, rng, 0.3)
    est = estimate_exact(obs, camera, CFG)
    assert est.ambiguity < 2.0 and est.alternative is not None
    up_in_camera = T.R[:, 1]
    prior = PosePrior(up_in_camera=up_in_camera)
    with_prior = estimate_exact(obs, camera, CFG, prior=prior)
    assert rotation_angle(with_prior.T_camera_pattern.R, T.R) < math.radians(3.0)
    wrong_prior = PosePrior(up_in_camera=with_prior.alternative.R[:, 1])
    flipped = estimate_exact(obs, camera, CFG, prior=wrong_prior)
    # The prior picked the other branch (refined, so not bit-identical to it).
    branches_apart = rotation_angle(with_prior.alternative.R, with_prior.T_camera_pattern.R)
    assert rotation_angle(flipped.T_camera_pattern.R, with_prior.alternative.R) < (
        0.25 * branches_apart)


def flips_and_other_probabilities(T, prior, sigma_px, draws=300):
    """Noisy views of one pose: (flipped, other_probability) each."""
    camera = CameraModel.from_focal(640, 480, 1000.0)
    truth = T.inverse().t
    distance = float(np.linalg.norm(truth))
    out = []
    for seed in range(draws):
        obs = ellipse_observations(camera, T, np.random.default_rng(seed), sigma_px)
        est = estimate_exact(obs, camera, CFG, prior=prior)
        error = np.linalg.norm(est.camera_in_pattern - truth)
        other = np.linalg.norm(est.alternative.inverse().t - truth)
        out.append((error > 0.05 * distance and other < 0.5 * error, est.other_probability))
    return out


def test_every_flip_that_up_cannot_decide_is_reported_unsure():
    # Nearly face on at 5.7 m, the camera off to the side: the two planar
    # solutions differ by a turn about the card's vertical axis, which
    # leaves "up" where it was. One noise draw in ten picks the wrong one,
    # more than a metre off; each such choice must say the other is likely.
    T = pose_from(5.7, 6.0, 90.0)
    prior = PosePrior(up_in_camera=T.R[:, 1], up_sigma_rad=math.radians(3.0))
    results = flips_and_other_probabilities(T, prior, 0.05)
    flipped = [p for flip, p in results if flip]
    assert len(flipped) >= 10                     # the case is exercised
    assert min(flipped) > 1e-3
    assert all(0.0 < p <= 0.5 for _, p in results)


def test_a_flip_that_up_decides_is_reported_sure():
    # Turned about the card's horizontal axis the two solutions disagree on
    # "up" by twice the view angle: the prior decides, and says so.
    T = pose_from(8.0, 12.0, 180.0)
    prior = PosePrior(up_in_camera=T.R[:, 1], up_sigma_rad=math.radians(3.0))
    results = flips_and_other_probabilities(T, prior, 0.3)
    assert not any(flip for flip, _ in results)
    assert np.mean([p <= 1e-3 for _, p in results]) > 0.9
    # An oblique view: the image alone rules the other solution out.
    camera = CameraModel.from_focal(640, 480, 1000.0)
    T = pose_from(3.0, 45.0, 30.0)
    est = estimate_exact(ellipse_observations(camera, T), camera, CFG, prior=prior)
    assert est.ambiguity > 2.0 and est.other_probability == 0.0


def test_the_flip_barrier_tells_one_valley_from_two_poses():
    # 2 deg off face on at 6 m the two solutions lie in one shallow valley
    # of the fit (or are one); 15 deg off, two poses with a ridge between.
    camera = CameraModel.from_focal(640, 480, 1000.0)
    prior = PosePrior(up_in_camera=np.array([0.0, -1.0, 0.0]))

    def barriers(phi):
        T = pose_from(6.0, phi, 90.0)
        out = []
        for seed in range(60):
            obs = ellipse_observations(camera, T, np.random.default_rng(seed), 0.08)
            est = estimate_exact(obs, camera, CFG, prior=PosePrior(up_in_camera=T.R[:, 1]))
            if est.other_probability > 1e-3:
                out.append(est.flip_barrier)
        return np.array(out)

    valley, ridge = barriers(2.0), barriers(15.0)
    assert len(valley) >= 50 and np.mean(valley < 9.0) > 0.9
    assert len(ridge) >= 20 and np.all(ridge >= 9.0)
    # Not a close call: no barrier to speak of.
    T = pose_from(3.0, 45.0, 30.0)
    est = estimate_exact(ellipse_observations(camera, T), camera, CFG, prior=prior)
    assert est.flip_barrier == math.inf


def test_other_probability_leaves_the_last_position_to_the_localizer():
    # A last position at the other solution makes the prior choose it; the
    # reported probability is the image's and up's alone, so the solution
    # the image prefers is then the likelier "other" one.
    camera = CameraModel.from_focal(640, 480, 1000.0)
    T = pose_from(5.7, 6.0, 90.0)
    obs = ellipse_observations(camera, T, np.random.default_rng(3), 0.05)
    alone = estimate_exact(obs, camera, CFG)
    assert alone.chosen_by == 'reprojection' and 0.0 < alone.other_probability < 0.5
    prior = PosePrior(previous_camera_in_pattern=alone.alternative.inverse().t,
                      previous_sigma=0.1)
    swayed = estimate_exact(obs, camera, CFG, prior=prior)
    assert swayed.chosen_by == 'prior'
    assert swayed.other_probability == pytest.approx(1.0 - alone.other_probability, abs=1e-6)


def test_the_prior_information_is_its_terms_linearised():
    # PosePrior.information against finite differences of the up and height
    # residuals, in pose_covariance's parameters (camera position, turn of
    # the camera about the pattern's axes: R' = R (I - [dtheta]x)).
    from pattern_locator.vision.geometry import rodrigues
    T = pose_from(4.0, 25.0, 130.0, roll_deg=10.0)
    prior = PosePrior(up_in_camera=np.array([0.1, -1.0, 0.05]), up_sigma_rad=0.07,
                      camera_height=0.3, height_sigma=0.2)
    up, up_weight, height, height_weight = prior.fit_terms()

    def residuals(delta):
        R = T.R @ rodrigues(-delta[3:])
        c = T.inverse().t + delta[:3]
        return np.concatenate([(R[:, 1] - up) * up_weight, [(c[1] - height) * height_weight]])

    h = 1e-6
    J = np.column_stack([(residuals(h * e) - residuals(-h * e)) / (2 * h) for e in np.eye(6)])
    assert np.allclose(prior.information(T), J.T @ J, rtol=1e-5, atol=1e-6)
    assert not PosePrior(previous_camera_in_pattern=np.zeros(3)).fits
    # What cannot weigh a term is left out, never a NaN in the fit.
    for broken in (PosePrior(up_in_camera=np.zeros(3)), PosePrior(camera_height=math.nan),
                   PosePrior(up_in_camera=np.array([0.0, 1.0, math.inf])),
                   PosePrior(camera_height=0.2, height_sigma=0.0),
                   PosePrior(up_in_camera=np.array([0.0, 1.0, 0.0]), up_sigma_rad=math.nan)):
        assert not broken.fits and not np.any(broken.information(T))
    camera = CameraModel.from_focal(640, 480, 1000.0)
    far = pose_from(6.0, 3.0, 180.0)
    obs = ellipse_observations(camera, far, np.random.default_rng(1), 0.08)
    broken = PosePrior(up_in_camera=np.zeros(3), camera_height=math.nan)
    est = estimate_exact(obs, camera, CFG, prior=broken)
    assert est.prior_information is None and np.all(np.isfinite(est.covariance))


def test_up_and_height_hold_a_far_pose_in_the_valley():
    # A card 1 m above the camera, 8 m away (7.5 deg off its normal), a wide
    # lens: the image alone leaves the card's turn in a shallow valley, up
    # and height (as a robot knows them, a few degrees and centimetres off)
    # take part in the fit, and its covariance is theirs together.
    camera = CameraModel.from_focal(640, 480, 554.0)
    T = pose_from(8.0, 7.5, 180.0)
    truth = T.inverse().t

    def errors(fit_prior=True):
        out = []
        for seed in range(80):
            rng = np.random.default_rng(seed)
            prior = PosePrior(up_in_camera=T.R[:, 1] + rng.normal(0.0, math.radians(2.0), 3),
                              up_sigma_rad=math.radians(5.0),
                              camera_height=truth[1] + rng.normal(0.0, 0.05), height_sigma=0.15)
            est = estimate_exact(ellipse_observations(camera, T, rng, 0.08), camera, CFG,
                                 prior=prior, fit_prior=fit_prior)
            out.append((float(np.linalg.norm(est.camera_in_pattern - truth)), est, prior))
        return out

    with_prior = errors()
    for _, est, prior in with_prior:
        # The information is the image's (some pixel sigma) plus the prior's.
        assert est.prior_information is not None
        image = np.linalg.inv(est.covariance) - est.prior_information
        unit = np.linalg.inv(pose_covariance(est.T_camera_pattern, CFG.model_points(),
                                             camera.K, 1.0))
        scale = image[0, 0] / unit[0, 0]
        assert np.allclose(image, scale * unit, rtol=1e-6, atol=1e-6 * np.abs(image).max())
        assert 0.05 - 1e-9 <= scale ** -0.5 <= 0.15      # floored at 0.05 px
        assert math.sqrt(est.covariance[1, 1]) < prior.height_sigma
    # The prior only choosing between the two (fit_prior False, as the
    # survey asks): the image's fit, which lies in the valley.
    image_only = errors(fit_prior=False)
    assert all(est.prior_information is None for _, est, _ in image_only)
    median_with = np.median([e for e, _, _ in with_prior])
    median_without = np.median([e for e, _, _ in image_only])
    assert median_with < 0.75 * median_without, (median_with, median_without)
    # Not a close call, the image's fit alone.
    near = estimate_exact(ellipse_observations(camera, pose_from(2.0, 40.0, 30.0)), camera,
                          CFG, prior=PosePrior(up_in_camera=T.R[:, 1], camera_height=0.0))
    assert near.prior_information is None


def test_wrong_shape_is_an_estimation_error():
    camera = CameraModel.from_focal(640, 480, 1000.0)
    with pytest.raises(EstimationError, match='expected 17 dot positions'):
        estimate_exact(np.zeros((9, 2)), camera, CFG)


def test_pose_helpers_are_consistent():
    T = pose_from(2.0, 30.0, 45.0)
    assert np.allclose((T @ T.inverse()).matrix(), np.eye(4))
    assert isinstance(T, Pose)


def test_another_estimators_pose_meets_the_flip_as_the_exact_estimator_sees_it():
    from pattern_locator.vision.locate import flip_as_exact_sees
    camera = CameraModel.from_focal(640, 480, 1000.0)
    # A close call: at either planar solution the other is the alternative,
    # the probabilities complementary, the barrier the same.
    T = pose_from(5.7, 6.0, 90.0)
    obs = ellipse_observations(camera, T, np.random.default_rng(3), 0.05)
    exact = estimate_exact(obs, camera, CFG)
    assert math.isfinite(exact.flip_barrier) and exact.other_probability > 1e-3
    other, p, barrier = flip_as_exact_sees(exact.T_camera_pattern, obs, camera, CFG)
    assert np.allclose(other.t, exact.alternative.t) and p == exact.other_probability
    assert barrier == exact.flip_barrier
    other, p, _ = flip_as_exact_sees(exact.alternative, obs, camera, CFG)
    assert np.allclose(other.t, exact.T_camera_pattern.t)
    assert p == pytest.approx(1.0 - exact.other_probability)
    # No close call: the solution the dots rule out is certainly wrong.
    T = pose_from(2.0, 40.0, 30.0)
    obs = ellipse_observations(camera, T, np.random.default_rng(3), 0.05)
    exact = estimate_exact(obs, camera, CFG)
    assert exact.flip_barrier == math.inf
    assert flip_as_exact_sees(exact.T_camera_pattern, obs, camera, CFG)[1:] == (0.0, math.inf)
    assert flip_as_exact_sees(exact.alternative, obs, camera, CFG)[1] == 1.0
    # Too few dots for the exact estimator: nothing to say.
    few = obs.copy()
    few[5:] = np.nan
    assert flip_as_exact_sees(T, few, camera, CFG) == (None, 0.0, math.inf)
