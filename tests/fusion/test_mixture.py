"""Gaussian mixtures and the particle density estimate (Merino (5.18)-(5.25), corrected) against brute force,
quadrature, Monte Carlo and closed-form moments."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import multivariate_normal

from fusion import mixture as mixture_module
from fusion.mixture import GaussianMixture
from fusion.particles import ParticleSet
from fusion.resampling import optimal_bandwidth

NAN, INF = float("nan"), float("inf")


def brute_logpdf(gm: GaussianMixture, x: np.ndarray) -> np.ndarray:
    dens = sum(a * multivariate_normal(m, c).pdf(x) for a, m, c in zip(gm.weights, gm.means, gm.covs, strict=True))
    return np.log(np.atleast_1d(dens))


def random_mixture(rng, k=4, d=3, offset=0.0) -> GaussianMixture:
    A = rng.normal(size=(k, d, d))
    covs = A @ A.transpose(0, 2, 1) + 0.3 * np.eye(d)
    w = rng.random(k) + 0.1
    return GaussianMixture(w / w.sum(), rng.normal(size=(k, d)) * 3.0 + offset, covs)


def two_modes(rng, n=400) -> ParticleSet:
    x = rng.normal(size=(n, 2)) * 0.5
    x[: n // 2] += [6.0, 1.0]
    return ParticleSet.from_states(x)


# -- the density estimate -------------------------------------------------------------------------------
@pytest.mark.parametrize(("n", "d", "h"), [(200, 2, 0.4135), (500, 3, 0.3986)])
def test_kde_uses_the_bandwidth_of_5_24_and_the_corrected_kernel_h2_sigma(n, d, h):
    rng = np.random.default_rng(1)
    ps = ParticleSet.from_states(rng.normal(size=(n, d)) @ rng.normal(size=(d, d)))
    gm = GaussianMixture.kde(ps)
    assert optimal_bandwidth(ps.n_eff(), d) == pytest.approx(h, abs=5e-5)
    np.testing.assert_allclose(gm.covs, np.broadcast_to(optimal_bandwidth(n, d) ** 2 * ps.cov(), (n, d, d)))
    np.testing.assert_array_equal(gm.means, ps.states)
    np.testing.assert_array_equal(gm.weights, ps.weights)
    assert gm.shared_covariance


def test_kde_covariance_is_1_plus_h2_times_the_set_covariance():
    rng = np.random.default_rng(2)
    ps = ParticleSet.from_unnormalised(rng.normal(size=(300, 3)) * [1.0, 4.0, 0.5], rng.random(300))
    for h in (None, 0.2, 0.7):
        gm = GaussianMixture.kde(ps, h)
        hh = optimal_bandwidth(ps.n_eff(), 3) if h is None else h
        np.testing.assert_allclose(gm.mean(), ps.mean(), rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(gm.cov(), (1 + hh**2) * ps.cov(), rtol=1e-10)
        shrunk = GaussianMixture.kde(ps, h, shrink=True)  # Liu & West: the moments of the set itself
        np.testing.assert_allclose(shrunk.mean(), ps.mean(), rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(shrunk.cov(), ps.cov(), rtol=1e-10)


def test_kde_integrates_to_one_on_a_grid():
    rng = np.random.default_rng(3)
    gm = GaussianMixture.kde(two_modes(rng, 200))
    xs, ys = np.linspace(-4.0, 10.0, 281), np.linspace(-4.0, 5.0, 181)
    X, Y = np.meshgrid(xs, ys)
    dens = gm.pdf(np.c_[X.ravel(), Y.ravel()]).reshape(X.shape)
    total = np.trapezoid(np.trapezoid(dens, xs, axis=1), ys)
    assert total == pytest.approx(1.0, abs=2e-3)


def test_kde_integrates_to_one_by_monte_carlo_in_3d():
    rng = np.random.default_rng(4)
    ps = ParticleSet.from_states(rng.normal(size=(500, 3)) * [1.0, 2.0, 3.0] + 50.0)
    gm = GaussianMixture.kde(ps)
    proposal = multivariate_normal(ps.mean(), 4.0 * ps.cov())
    x = proposal.rvs(size=40000, random_state=rng)
    ratio = np.exp(gm.logpdf(x) - proposal.logpdf(x))
    se = ratio.std() / np.sqrt(ratio.size)
    assert abs(ratio.mean() - 1.0) < 4 * se


def test_kde_leaves_out_zero_weight_particles():
    ps = ParticleSet.from_states(np.array([[0.0, 0.0], [1.0, 0.5], [2.0, 3.0], [9.0, 9.0]]), [0.3, 0.3, 0.4, 0.0])
    gm = GaussianMixture.kde(ps, 0.5)
    assert gm.k == 3
    np.testing.assert_array_equal(gm.means, ps.states[:3])


@pytest.mark.parametrize(
    ("bandwidth", "shrink", "match"),
    [(0.0, False, "bandwidth"), (-0.3, False, "bandwidth"), (NAN, False, "bandwidth"), (INF, False, "bandwidth"),
     (1.0, True, "below 1")],
    ids=["bandwidth-zero", "bandwidth-negative", "bandwidth-nan", "bandwidth-inf", "shrunk-bandwidth-1"],
)
def test_kde_rejects_bad_bandwidth(bandwidth, shrink, match):
    ps = ParticleSet.from_states(np.random.default_rng(0).normal(size=(20, 2)))
    with pytest.raises(ValueError, match=match):
        GaussianMixture.kde(ps, bandwidth, shrink)


def test_kde_rejects_a_set_with_singular_covariance_and_non_particle_input():
    with pytest.raises(ValueError, match="singular"):
        GaussianMixture.kde(ParticleSet.from_states(np.ones((10, 2))))
    with pytest.raises(ValueError, match="ParticleSet"):
        GaussianMixture.kde(np.zeros((10, 2)))


# -- densities and moments -------------------------------------------------------------------------------
@pytest.mark.parametrize("offset", [0.0, 1000.0], ids=["near-origin", "far-from-origin"])
def test_logpdf_matches_brute_force_for_distinct_and_shared_covariances(offset):
    rng = np.random.default_rng(5)
    gm = random_mixture(rng, offset=offset)
    x = rng.normal(size=(50, 3)) * 4.0 + offset
    np.testing.assert_allclose(gm.logpdf(x), brute_logpdf(gm, x), rtol=1e-10, atol=1e-10)
    kde = GaussianMixture.kde(ParticleSet.from_states(rng.normal(size=(60, 3)) + offset))
    np.testing.assert_allclose(kde.logpdf(x[:10]), brute_logpdf(kde, x[:10]), rtol=1e-10, atol=1e-10)


def test_logpdf_in_chunks_equals_logpdf_at_once(monkeypatch):
    rng = np.random.default_rng(6)
    gm, kde = random_mixture(rng), GaussianMixture.kde(ParticleSet.from_states(rng.normal(size=(40, 3))))
    x = rng.normal(size=(37, 3))
    whole = gm.logpdf(x), kde.logpdf(x)
    monkeypatch.setattr(mixture_module, "LOGPDF_CHUNK", 50)
    np.testing.assert_allclose(gm.logpdf(x), whole[0], rtol=1e-13)
    np.testing.assert_allclose(kde.logpdf(x), whole[1], rtol=1e-13)


def test_mixture_moments_match_samples():
    rng = np.random.default_rng(7)
    gm = random_mixture(rng)
    sample = gm.sample(rng, 60000)
    np.testing.assert_allclose(sample.mean(), gm.mean(), atol=0.06)
    np.testing.assert_allclose(sample.cov(), gm.cov(), rtol=0.04, atol=0.1)


@pytest.mark.parametrize(
    ("points", "match"),
    [(np.zeros((4, 2)), r"shape \(M, 3\)"), (np.zeros(3), r"shape \(M, 3\)"), ([[0.0, NAN, 0.0]], "non-finite")],
    ids=["points-wrong-dimension", "points-1d", "nan-point"],
)
def test_logpdf_rejects(points, match):
    with pytest.raises(ValueError, match=match):
        random_mixture(np.random.default_rng(0)).logpdf(points)


@pytest.mark.parametrize(
    ("weights", "means", "covs", "match"),
    [
        ([0.5, 0.6], np.zeros((2, 2)), np.stack([np.eye(2)] * 2), "sum to one"),
        ([1.2, -0.2], np.zeros((2, 2)), np.stack([np.eye(2)] * 2), "non-negative"),
        ([NAN, 1.0], np.zeros((2, 2)), np.stack([np.eye(2)] * 2), "weights contain non-finite"),
        ([0.0, 0.0], np.zeros((2, 2)), np.stack([np.eye(2)] * 2), "all zero"),
        ([], np.zeros((0, 2)), np.zeros((0, 2, 2)), "non-empty"),
        ([0.5, 0.5], np.zeros((3, 2)), np.stack([np.eye(2)] * 2), "means must have shape"),
        ([0.5, 0.5], [[0.0, NAN], [0.0, 0.0]], np.stack([np.eye(2)] * 2), "means contain non-finite"),
        ([0.5, 0.5], np.zeros((2, 2)), np.stack([np.eye(3)] * 2), "covariances must have shape"),
        ([0.5, 0.5], np.zeros((2, 2)), [np.eye(2), [[1.0, NAN], [NAN, 1.0]]], "covariances contain non-finite"),
        ([0.5, 0.5], np.zeros((2, 2)), [np.eye(2), [[1.0, 0.5], [0.0, 1.0]]], "not symmetric"),
        ([0.5, 0.5], np.zeros((2, 2)), [np.eye(2), [[1.0, 2.0], [2.0, 1.0]]], "component 1 is not positive definite"),
        ([0.5, 0.5], np.zeros((2, 2)), np.zeros((2, 2, 2)), "not positive definite"),
    ],
    ids=["weights-sum-1.1", "negative-weight", "nan-weight", "all-zero-weights", "no-components",
         "means-wrong-count", "nan-mean", "covs-wrong-dimension", "nan-cov", "cov-non-symmetric",
         "cov-indefinite", "cov-zero"],
)
def test_mixture_construction_rejects(weights, means, covs, match):
    with pytest.raises(ValueError, match=match):
        GaussianMixture(weights, means, covs)


# -- compression -----------------------------------------------------------------------------------------
def test_compression_of_a_two_mode_set_keeps_both_modes():
    rng = np.random.default_rng(8)
    ps = two_modes(rng)
    two = GaussianMixture.kde(ps).compressed(2, rng)
    assert two.k == 2
    order = np.argsort(two.means[:, 0])
    np.testing.assert_allclose(two.means[order], [[0.0, 0.0], [6.0, 1.0]], atol=0.15)
    np.testing.assert_allclose(two.weights[order], [0.5, 0.5], atol=1e-12)
    # the compressed density follows the full estimate at both modes and in the valley between them
    points = np.array([[0.0, 0.0], [6.0, 1.0], [3.0, 0.5]])
    np.testing.assert_allclose(two.logpdf(points), GaussianMixture.kde(ps).logpdf(points), atol=0.2)
    assert two.pdf(points[2:])[0] < 0.15 * two.pdf(points[:2]).min()


def test_compression_preserves_the_moments_of_the_mixture_and_of_the_set():
    rng = np.random.default_rng(9)
    states = np.r_[rng.normal(size=(300, 3)), rng.normal(size=(200, 3)) + 5.0]
    ps = ParticleSet.from_unnormalised(states, rng.random(500))
    kde = GaussianMixture.kde(ps)
    for k in (1, 3, 8):
        c = kde.compressed(k, rng)
        assert c.k <= k
        np.testing.assert_allclose(c.mean(), kde.mean(), rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(c.cov(), kde.cov(), rtol=1e-9)
        exact = GaussianMixture.from_particles(ps, k, rng)  # the shrunk estimate: the set's own moments
        np.testing.assert_allclose(exact.mean(), ps.mean(), rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(exact.cov(), ps.cov(), rtol=1e-9)
    assert kde.compressed(kde.k, rng) is kde


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(2, 12), st.integers(1, 5), st.integers(1, 4))
def test_compression_preserves_moments_of_random_mixtures(seed, k_in, k_out, d):
    rng = np.random.default_rng(seed)
    gm = random_mixture(rng, k_in, d)
    c = gm.compressed(k_out, rng)
    assert c.k <= min(k_out, k_in)
    np.testing.assert_allclose(c.mean(), gm.mean(), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(c.cov(), gm.cov(), rtol=1e-8, atol=1e-9)


@pytest.mark.parametrize(("k", "max_iter"), [(0, 10), (-1, 10), (1.5, 10), (2, 0)],
                         ids=["k-zero", "k-negative", "k-fractional", "max-iter-zero"])
def test_compression_rejects_bad_k(k, max_iter):
    with pytest.raises(ValueError, match="k must be|max_iter"):
        random_mixture(np.random.default_rng(0)).compressed(k, np.random.default_rng(0), max_iter)


def test_sample_rejects_bad_count():
    with pytest.raises(ValueError, match="positive integer"):
        random_mixture(np.random.default_rng(0)).sample(np.random.default_rng(0), 0)
