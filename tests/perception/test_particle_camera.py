"""The particle filter's camera model (Merino §5.3): back-projection prior (Alg. 5.4), UT pixel likelihood (5.31)
against a per-particle loop, the two-view localisation, and ML association (5.34)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.special import logsumexp
from scipy.stats import multivariate_normal

from fusion.particles import ParticleSet, sir_update
from fusion.unscented import unscented_transform
from perception.camera import Intrinsics
from perception.particle_camera import CameraDetection, UncertainPose, associate, association_log_likelihoods
from perception.pose import CameraPose, Gimbal
from perception.projection import pixel_to_ray_world, world_to_pixel
from perception.triangulation import pseudo_intersection

NAN = float("nan")
K = Intrinsics.from_fov(640, 480, 60.0)
K_DISTORTED = Intrinsics(500.0, 505.0, 321.0, 238.0, 640, 480, (-0.12, 0.03, 0.001, -0.0005))
TRUTH = np.array([40.0, 10.0, 0.0])


def looking_at(centre, target=TRUTH) -> CameraPose:
    d = np.asarray(target, float) - centre
    yaw, tilt = math.atan2(d[1], d[0]), math.atan2(-d[2], math.hypot(d[0], d[1]))
    return CameraPose.from_vehicle(np.asarray(centre, float), 0.0, 0.0, yaw, Gimbal(0.0, tilt))


POSE_1 = looking_at([0.0, 0.0, -40.0])
POSE_2 = looking_at([40.0, 60.0, -40.0])


def detection(pose, intrinsics=K, position_sigma=0.5, attitude_deg=1.0, pixel_sigma=2.0, target=TRUTH, **kw):
    pixel = world_to_pixel(pose, intrinsics, np.asarray(target, float))
    uncertain = UncertainPose.from_sigmas(pose, position_sigma, math.radians(attitude_deg))
    return CameraDetection(pixel, intrinsics, uncertain, pixel_sigma**2 * np.eye(2), **kw)


def _along_and_across_the_ray(det, ps):
    """Each particle's distance along the detection's viewing ray from POSE_1, and its distance from it."""
    ray = pixel_to_ray_world(POSE_1, K, det.pixel)
    rel = ps.states - POSE_1.centre
    along = rel @ ray
    return along, np.linalg.norm(rel - along[:, None] * ray, axis=1)


# -- Alg. 5.4 ---------------------------------------------------------------------------------------------
def test_prior_without_pose_noise_lies_on_the_viewing_ray_between_d_min_and_d_max():
    det = detection(POSE_1, position_sigma=0.0, attitude_deg=0.0)
    ps = det.back_projection_prior(3000, np.random.default_rng(1), 10.0, 150.0)
    along, perpendicular = _along_and_across_the_ray(det, ps)
    assert np.all(perpendicular < 1e-9)
    assert along.min() >= 10.0 and along.max() <= 150.0
    assert np.mean(along) == pytest.approx(80.0, abs=3.0)  # uniform in range
    assert np.std(along) == pytest.approx(140.0 / math.sqrt(12.0), rel=0.05)
    np.testing.assert_array_equal(ps.weights, np.full(3000, 1 / 3000))


def test_prior_with_pose_noise_stays_close_to_the_ray_and_is_not_unimodal():
    det = detection(POSE_1, position_sigma=0.5, attitude_deg=1.0)
    ps = det.back_projection_prior(3000, np.random.default_rng(2), 10.0, 150.0)
    along, perpendicular = _along_and_across_the_ray(det, ps)
    assert np.all(perpendicular < 5 * (0.5 + along * math.radians(1.0)))  # a cone around the ray
    assert perpendicular.mean() > 0.1
    assert not ps.is_unimodal()  # a line ("banana") of particles


def test_second_view_makes_the_set_unimodal_and_close_to_the_triangulated_point():
    rng = np.random.default_rng(3)
    first, second = detection(POSE_1), detection(POSE_2)
    prior = first.back_projection_prior(4000, rng, 10.0, 150.0)
    assert not prior.is_unimodal()
    step = sir_update(prior, second.log_likelihood(prior.states), rng)
    assert step.resampled  # the second view keeps only a short piece of the ray
    post = step.particles
    assert post.is_unimodal()
    rays = np.array([pixel_to_ray_world(p, K, d.pixel) for p, d in ((POSE_1, first), (POSE_2, second))])
    triangulated = pseudo_intersection(np.array([POSE_1.centre, POSE_2.centre]), rays).point
    g = post.to_gaussian()
    err = g.mean - triangulated
    assert float(err @ np.linalg.solve(g.cov, err)) < 3.0**2
    assert np.linalg.norm(err) < 1.0
    assert np.sqrt(np.linalg.eigvalsh(g.cov)).max() < 3.0  # from a 140 m line to a metre-sized cloud


# -- (5.31) -------------------------------------------------------------------------------------------------
def loop_log_likelihood(det: CameraDetection, point: np.ndarray) -> float:
    """(5.31) for one particle: fusion.unscented over the 6-D pose error, world_to_pixel per sigma point."""

    def f(delta):
        R = Rotation.from_rotvec(delta[3:]).as_matrix() @ det.pose.pose.R_world_from_cam
        return world_to_pixel(CameraPose(R, det.pose.pose.centre + delta[:3]), det.intrinsics, point)

    mean, cov = unscented_transform(f, np.zeros(6), det.pose.cov, det.kappa)
    return float(multivariate_normal(mean, cov + det.pixel_cov).logpdf(det.pixel))


@pytest.mark.parametrize("intrinsics", [K, K_DISTORTED], ids=["pinhole", "distorted"])
@pytest.mark.parametrize("kappa", [None, 1.0], ids=["default-kappa", "kappa-1"])
def test_camera_likelihood_matches_a_per_particle_loop(intrinsics, kappa):
    rng = np.random.default_rng(4)
    det = detection(POSE_1, intrinsics, position_sigma=1.0, attitude_deg=2.0, kappa=kappa)
    points = TRUTH + rng.normal(size=(6, 3)) * [4.0, 4.0, 2.0]
    expected = [loop_log_likelihood(det, p) for p in points]
    np.testing.assert_allclose(det.log_likelihood(points), expected, rtol=1e-9, atol=1e-9)
    means, covs = det.pixel_moments(points)
    assert means.shape == (6, 2) and covs.shape == (6, 2, 2)


def test_without_pose_noise_the_likelihood_is_the_pixel_gaussian():
    det = detection(POSE_1, position_sigma=0.0, attitude_deg=0.0, pixel_sigma=3.0)
    points = TRUTH + np.random.default_rng(5).normal(size=(5, 3))
    expected = [multivariate_normal(world_to_pixel(POSE_1, K, p), 9.0 * np.eye(2)).logpdf(det.pixel) for p in points]
    np.testing.assert_allclose(det.log_likelihood(points), expected, rtol=1e-10)


def test_particle_behind_the_camera_has_zero_likelihood():
    det = detection(POSE_1)
    behind = POSE_1.centre - 20.0 * POSE_1.optical_axis
    ll = det.log_likelihood(np.array([TRUTH, behind]))
    assert np.isfinite(ll[0]) and ll[1] == -np.inf


def test_likelihood_peaks_at_the_true_point_along_the_ray_of_another_view():
    det = detection(POSE_2)
    ray = pixel_to_ray_world(POSE_1, K, world_to_pixel(POSE_1, K, TRUTH))
    ranges = np.linspace(20.0, 80.0, 601)
    ll = det.log_likelihood(POSE_1.centre + ranges[:, None] * ray)
    assert ranges[np.argmax(ll)] == pytest.approx(np.linalg.norm(TRUTH - POSE_1.centre), abs=0.3)


# -- (5.34) ---------------------------------------------------------------------------------------------------
def test_association_picks_the_detection_that_matches_the_track():
    rng = np.random.default_rng(6)
    ps = ParticleSet.from_states(TRUTH + rng.normal(size=(500, 3)) * 0.5)
    clutter = detection(POSE_2, target=TRUTH + [15.0, -10.0, 0.0])
    right = detection(POSE_2)
    values = association_log_likelihoods(ps, [clutter, right])
    brute = [logsumexp(np.log(ps.weights) + d.log_likelihood(ps.states)) for d in (clutter, right)]
    np.testing.assert_allclose(values, brute, rtol=1e-12)
    assert associate(ps, [clutter, right]) == 1
    with pytest.raises(ValueError, match="at least one"):
        associate(ps, [])  # no candidate detections


# -- bad input ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"pixel": [NAN, 1.0]}, "pixel contains non-finite"),
        ({"pixel": [1.0, 2.0, 3.0]}, "pixel must have length 2"),
        ({"pixel_cov": [[1.0, 0.0], [0.0, -1.0]]}, "not positive definite"),
        ({"pixel_cov": np.eye(3)}, "must be 2x2"),
        ({"intrinsics": "K"}, "Intrinsics"),
        ({"pose": POSE_1}, "UncertainPose"),
    ],
    ids=["nan-pixel", "pixel-3-values", "pixel-cov-indefinite", "pixel-cov-3x3", "intrinsics-wrong-type",
         "pose-without-uncertainty"],
)
def test_detection_rejects(kwargs, match):
    args = {"pixel": [320.0, 240.0], "intrinsics": K, "pose": UncertainPose.from_sigmas(POSE_1, 0.5, 0.01)} | kwargs
    with pytest.raises(ValueError, match=match):
        CameraDetection(**args)


@pytest.mark.parametrize(
    ("cov", "match"),
    [(np.eye(5), "6x6"), (-np.eye(6), "positive semi-definite"), (np.full((6, 6), NAN), "non-finite")],
    ids=["pose-cov-5x5", "pose-cov-negative", "pose-cov-nan"],
)
def test_uncertain_pose_rejects(cov, match):
    with pytest.raises(ValueError, match=match):
        UncertainPose(POSE_1, cov)


@pytest.mark.parametrize(("position", "attitude"), [(-1.0, 0.0), (0.0, NAN)], ids=["negative-sigma", "nan-sigma"])
def test_uncertain_pose_from_sigmas_rejects(position, attitude):
    with pytest.raises(ValueError, match="sigma"):
        UncertainPose.from_sigmas(POSE_1, position, attitude)


@pytest.mark.parametrize(
    ("n", "d_min", "d_max", "match"),
    [(0, 1.0, 10.0, "positive integer"), (10, -1.0, 10.0, "d_min"), (10, 5.0, 5.0, "d_min"),
     (10, 1.0, math.inf, "d_min")],
    ids=["zero-particles", "negative-d-min", "d-max-equals-d-min", "infinite-d-max"],
)
def test_prior_rejects(n, d_min, d_max, match):
    with pytest.raises(ValueError, match=match):
        detection(POSE_1).back_projection_prior(n, np.random.default_rng(0), d_min, d_max)


@pytest.mark.parametrize(
    ("points", "match"),
    [(np.zeros((4, 2)), r"shape \(N, 3\)"), ([[0.0, NAN, 0.0]], "non-finite")],
    ids=["2d-particles", "nan-particle"],
)
def test_likelihood_rejects(points, match):
    with pytest.raises(ValueError, match=match):
        detection(POSE_1).log_likelihood(points)
