"""Particle sets and the SIR filter (Merino §5.1, §5.3.3, (5.32), (5.35)) against closed forms and brute force."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.stats import multivariate_normal

from fusion.particles import RESAMPLE_THRESHOLD, InformationTrigger, ParticleSet, SIRConfig, sir_update
from fusion.resampling import DegenerateWeightsError, optimal_bandwidth, systematic_indices

NAN, INF = float("nan"), float("inf")
positive_weights = arrays(np.float64, st.integers(1, 60), elements=st.floats(0.0, 1.0)).filter(lambda w: w.sum() > 1e-3)


def cloud(rng, n=500, d=2, scale=1.0):
    return ParticleSet.from_states(rng.normal(size=(n, d)) * scale)


# -- construction and validation --------------------------------------------------------------------
def test_from_states_gives_equal_weights_and_read_only_arrays():
    ps = ParticleSet.from_states(np.arange(12.0).reshape(4, 3))
    assert (ps.n, ps.dim) == (4, 3)
    np.testing.assert_array_equal(ps.weights, np.full(4, 0.25))
    with pytest.raises(ValueError):
        ps.states[0, 0] = 1.0
    with pytest.raises(ValueError):
        ps.weights[0] = 1.0


def test_constructor_copies_its_input():
    x = np.zeros((3, 2))
    ps = ParticleSet.from_states(x)
    x[0, 0] = 5.0
    assert ps.states[0, 0] == 0.0


@pytest.mark.parametrize(
    ("states", "weights", "match"),
    [
        (np.zeros((3, 2)), [0.5, 0.5, 0.1], "must sum to one"),
        (np.zeros((3, 2)), [0.5, 0.5, 1e-8], "must sum to one"),
        (np.zeros((3, 2)), [0.6, 0.6, -0.2], "non-negative"),
        (np.zeros((3, 2)), [0.5, 0.5, NAN], "non-finite"),
        (np.zeros((3, 2)), [0.5, 0.5, INF], "non-finite"),
        (np.zeros((3, 2)), [0.5, 0.5], r"shape \(3,\)"),
        (np.zeros((3, 2)), [[0.5, 0.5, 0.0]], r"shape \(3,\)"),
        (np.zeros((0, 2)), [], "N = 0"),
        (np.zeros((3, 0)), [1 / 3] * 3, "d = 0"),
        (np.zeros(3), [1 / 3] * 3, r"shape \(N, d\)"),
        (np.zeros((3, 2, 1)), [1 / 3] * 3, r"shape \(N, d\)"),
        ([[0.0, NAN], [0.0, 0.0]], [0.5, 0.5], "states contain non-finite"),
        ([[0.0, INF], [0.0, 0.0]], [0.5, 0.5], "states contain non-finite"),
    ],
    ids=["weights-sum-1.1", "weights-sum-off-by-1e-8", "negative-weight", "nan-weight", "inf-weight",
         "weights-too-short", "weights-2d", "zero-particles", "zero-dimensions", "states-1d", "states-3d",
         "nan-state", "inf-state"],
)
def test_construction_rejects(states, weights, match):
    with pytest.raises(ValueError, match=match):
        ParticleSet.from_states(states, weights)


def test_all_zero_weights_raise_degenerate_weights():
    with pytest.raises(DegenerateWeightsError, match="all zero"):
        ParticleSet.from_states(np.zeros((3, 2)), [0.0, 0.0, 0.0])
    with pytest.raises(DegenerateWeightsError, match="all zero"):
        ParticleSet.from_unnormalised(np.zeros((3, 2)), [0.0, 0.0, 0.0])
    with pytest.raises(DegenerateWeightsError, match="all -inf"):
        ParticleSet.from_log_weights(np.zeros((2, 2)), [-INF, -INF])


@pytest.mark.parametrize(
    ("log_weights", "match"),
    [([0.0, NAN], "NaN"), ([0.0, INF], r"\+inf"), ([0.0], r"shape \(2,\)")],
    ids=["nan-log-weight", "plus-inf-log-weight", "log-weights-wrong-length"],
)
def test_from_log_weights_rejects(log_weights, match):
    with pytest.raises(ValueError, match=match):
        ParticleSet.from_log_weights(np.zeros((2, 2)), log_weights)


def test_from_unnormalised_and_log_weights_normalise():
    ps = ParticleSet.from_unnormalised(np.zeros((3, 1)), [1.0, 3.0, 0.0])
    np.testing.assert_allclose(ps.weights, [0.25, 0.75, 0.0])
    ps = ParticleSet.from_log_weights(np.zeros((3, 1)), [-1000.0, -1000.0 + math.log(3.0), -INF])
    np.testing.assert_allclose(ps.weights, [0.25, 0.75, 0.0])


# -- N_eff and moments ---------------------------------------------------------------------------------
@given(positive_weights)
def test_n_eff_is_inverse_sum_of_squared_normalised_weights(raw):
    ps = ParticleSet.from_unnormalised(np.zeros((raw.size, 1)), raw)
    w = raw / raw.sum()
    assert ps.n_eff() == pytest.approx(1.0 / np.sum(w**2), rel=1e-12)
    assert ps.n_eff() == pytest.approx(raw.sum() ** 2 / np.sum(raw**2), rel=1e-9)  # scale-free form
    assert 1.0 - 1e-9 <= ps.n_eff() <= raw.size + 1e-9


def test_n_eff_extremes():
    assert ParticleSet.from_states(np.zeros((7, 1))).n_eff() == pytest.approx(7.0)
    assert ParticleSet.from_states(np.zeros((7, 1)), np.eye(7)[2]).n_eff() == pytest.approx(1.0)


def test_mean_and_cov_match_numpy_weighted_moments():
    rng = np.random.default_rng(3)
    x = rng.normal(size=(50, 3))
    w = rng.random(50)
    ps = ParticleSet.from_unnormalised(x, w)
    np.testing.assert_allclose(ps.mean(), np.average(x, axis=0, weights=w), rtol=1e-12)
    np.testing.assert_allclose(ps.cov(), np.cov(x.T, aweights=w, bias=True), rtol=1e-10, atol=1e-14)


# -- reweighting ---------------------------------------------------------------------------------------
def test_reweighted_is_the_bootstrap_update_and_returns_the_log_weight_sum():
    rng = np.random.default_rng(4)
    prior = ParticleSet.from_unnormalised(rng.normal(size=(30, 2)), rng.random(30))
    ll = rng.normal(size=30) * 3.0
    post, log_sum = prior.reweighted(ll)
    unnormalised = prior.weights * np.exp(ll)
    np.testing.assert_allclose(post.weights, unnormalised / unnormalised.sum(), rtol=1e-12)
    assert log_sum == pytest.approx(math.log(unnormalised.sum()), rel=1e-12)
    # equal prior weights: the mean of the likelihoods, i.e. the estimate of p(z_t | z^{t-1}) of (5.35)
    flat, log_mean = ParticleSet.from_states(prior.states).reweighted(ll)
    assert log_mean == pytest.approx(math.log(np.mean(np.exp(ll))), rel=1e-12)


def test_reweighted_is_stable_for_very_small_likelihoods():
    ps = ParticleSet.from_states(np.zeros((3, 1)))
    post, log_sum = ps.reweighted(np.array([-5000.0, -5000.0 + math.log(2.0), -INF]))
    np.testing.assert_allclose(post.weights, [1 / 3, 2 / 3, 0.0])
    assert log_sum == pytest.approx(-5000.0 + math.log(1.0))


@pytest.mark.parametrize(
    ("ll", "error", "match"),
    [
        ([0.0, NAN, 0.0], ValueError, "NaN"),
        ([0.0, INF, 0.0], ValueError, r"\+inf"),
        ([0.0, 0.0], ValueError, r"shape \(3,\)"),
        ([-INF, -INF, -INF], DegenerateWeightsError, "all -inf"),
    ],
    ids=["nan-log-likelihood", "plus-inf-log-likelihood", "log-likelihood-wrong-length", "all-zero-likelihood"],
)
def test_reweighted_rejects(ll, error, match):
    with pytest.raises(error, match=match):
        ParticleSet.from_states(np.zeros((3, 1))).reweighted(ll)


# -- resampling ------------------------------------------------------------------------------------------
@settings(max_examples=200)
@given(positive_weights, st.integers(1, 200), st.integers(0, 2**32 - 1))
def test_systematic_resampling_counts_are_within_one_of_n_w(raw, n, seed):
    w = raw / raw.sum()
    idx = systematic_indices(w, n, np.random.default_rng(seed))
    counts = np.bincount(idx, minlength=w.size)
    assert idx.shape == (n,) and counts.sum() == n
    assert np.all(np.abs(counts - n * w) < 1.0 + 1e-9)
    assert np.all(counts[w == 0.0] == 0)  # a zero-weight particle is never copied


def test_resampled_set_has_equal_weights_and_copies_of_the_states():
    rng = np.random.default_rng(5)
    ps = ParticleSet.from_unnormalised(rng.normal(size=(40, 2)), rng.random(40))
    out = ps.resampled(rng, 25)
    assert out.n == 25
    np.testing.assert_array_equal(out.weights, np.full(25, 1 / 25))
    originals = {tuple(row) for row in ps.states}
    assert all(tuple(row) in originals for row in out.states)


@pytest.mark.parametrize("n", [0, -3, 2.5, True], ids=["n-zero", "n-negative", "n-fractional", "n-bool"])
def test_resampled_rejects_bad_count(n):
    with pytest.raises(ValueError, match="positive integer"):
        ParticleSet.from_states(np.zeros((3, 1))).resampled(np.random.default_rng(0), n)


def test_systematic_indices_rejects_empty_and_all_zero_weights():
    with pytest.raises(ValueError, match="non-empty"):
        systematic_indices(np.zeros(0), 3, np.random.default_rng(0))
    with pytest.raises(DegenerateWeightsError):
        systematic_indices(np.zeros(4), 3, np.random.default_rng(0))


# -- jitter ---------------------------------------------------------------------------------------------
def test_jitter_adds_noise_with_the_given_covariance():
    rng = np.random.default_rng(6)
    ps = ParticleSet.from_states(np.tile([1.0, -2.0], (20000, 1)))
    cov = np.array([[2.0, 0.6], [0.6, 0.5]])
    out = ps.jittered(rng, cov)
    np.testing.assert_allclose(out.mean(), [1.0, -2.0], atol=0.05)
    np.testing.assert_allclose(out.cov(), cov, rtol=0.05, atol=0.02)
    flat = ps.jittered(rng, np.zeros((2, 2)))  # a PSD (here zero) R_t is allowed
    np.testing.assert_array_equal(flat.states, ps.states)


@pytest.mark.parametrize(
    ("cov", "match"),
    [(np.eye(3), "2x2"), ([[1.0, 0.0], [0.0, -1.0]], "positive semi-definite"), ([[NAN, 0], [0, 1]], "non-finite"),
     ([[1.0, 0.5], [0.0, 1.0]], "not symmetric")],
    ids=["jitter-cov-wrong-size", "jitter-cov-indefinite", "jitter-cov-nan", "jitter-cov-non-symmetric"],
)
def test_jittered_rejects(cov, match):
    with pytest.raises(ValueError, match=match):
        ParticleSet.from_states(np.zeros((3, 2))).jittered(np.random.default_rng(0), cov)


def test_kernel_jitter_with_shrinkage_keeps_mean_and_covariance_and_without_inflates_by_1_plus_h2():
    rng = np.random.default_rng(7)
    base = ParticleSet.from_states(rng.normal(size=(40000, 2)) @ np.array([[2.0, 0.0], [0.7, 0.5]]))
    h = 0.5
    shrunk = base.kernel_jittered(rng, h, shrink=True)
    plain = base.kernel_jittered(rng, h, shrink=False)
    np.testing.assert_allclose(shrunk.mean(), base.mean(), atol=0.03)
    np.testing.assert_allclose(shrunk.cov(), base.cov(), rtol=0.04, atol=0.02)
    np.testing.assert_allclose(plain.cov(), (1 + h * h) * base.cov(), rtol=0.04, atol=0.02)


# -- bandwidth ----------------------------------------------------------------------------------------
@pytest.mark.parametrize(("n", "d", "h"), [(200, 2, 0.4135), (500, 2, 0.3550), (200, 3, 0.4544), (500, 3, 0.3986)])
def test_optimal_bandwidth_reproduces_the_spec_values(n, d, h):
    assert optimal_bandwidth(n, d) == pytest.approx(h, abs=5e-5)
    assert optimal_bandwidth(n, d) == pytest.approx((4 / (d + 2)) ** (1 / (d + 4)) * n ** (-1 / (d + 4)), rel=1e-15)


@pytest.mark.parametrize(("n", "d"), [(0, 2), (0.5, 2), (NAN, 2), (10, 0), (10, 1.5)],
                         ids=["n-zero", "n-below-one", "n-nan", "dim-zero", "dim-fractional"])
def test_optimal_bandwidth_rejects(n, d):
    with pytest.raises(ValueError):
        optimal_bandwidth(n, d)


# -- Gaussian hand-over and the shape test -------------------------------------------------------------
def test_to_gaussian_matches_the_weighted_moments():
    rng = np.random.default_rng(8)
    ps = ParticleSet.from_unnormalised(rng.normal(size=(100, 3)), rng.random(100))
    g = ps.to_gaussian()
    np.testing.assert_allclose(g.mean, ps.mean(), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(g.cov, ps.cov(), rtol=1e-9, atol=1e-12)


def test_to_gaussian_rejects_a_set_with_singular_covariance():
    with pytest.raises(ValueError, match="cannot hand the particle set over"):
        ParticleSet.from_states(np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]])).to_gaussian()


def test_compact_gaussian_cloud_is_unimodal():
    rng = np.random.default_rng(9)
    for d in (2, 3):
        ps = ParticleSet.from_states(rng.normal(size=(500, d)) @ rng.normal(size=(d, d)) + 100.0)
        assert ps.is_unimodal()
        assert np.all(np.abs(ps.bimodality_coefficients() - 1 / 3) < 0.08)


def test_a_line_a_banana_and_two_modes_are_not_unimodal():
    rng = np.random.default_rng(10)
    t = rng.uniform(0.0, 1.0, 400)
    ray = np.array([1.0, 2.0, -0.5]) / np.linalg.norm([1.0, 2.0, -0.5])
    line = ParticleSet.from_states(5.0 + (10.0 + 90.0 * t)[:, None] * ray + 0.2 * rng.normal(size=(400, 3)))
    assert not line.is_unimodal()
    assert line.bimodality_coefficients()[0] == pytest.approx(5 / 9, abs=0.03)  # uniform along the ray
    angle = rng.uniform(-1.2, 1.2, 400)
    radius = 10.0 + 0.3 * rng.normal(size=400)
    assert not ParticleSet.from_states(np.c_[radius * np.sin(angle), radius * np.cos(angle)]).is_unimodal()
    two = rng.normal(size=(400, 2))
    two[:200, 0] += 6.0
    assert not ParticleSet.from_states(two).is_unimodal()
    lopsided = rng.normal(size=(400, 2))
    lopsided[:60, 0] += 8.0
    assert not ParticleSet.from_states(lopsided).is_unimodal()


def test_shape_test_needs_enough_effective_particles_and_accepts_a_point_mass():
    rng = np.random.default_rng(11)
    few = ParticleSet.from_states(rng.normal(size=(20, 2)))
    assert few.n_eff() < 30 and not few.is_unimodal()
    assert ParticleSet.from_states(np.ones((50, 3))).is_unimodal()
    with pytest.raises(ValueError, match="max_bimodality"):
        few.is_unimodal(max_bimodality=0.0)


# -- the SIR step -------------------------------------------------------------------------------------
@pytest.mark.parametrize(("alive", "expect"), [(29, True), (30, False), (31, False)])
def test_sir_resamples_only_below_30_percent_of_n(alive, expect):
    """N = 100 particles of which ``alive`` have non-zero likelihood: N_eff = alive exactly."""
    assert RESAMPLE_THRESHOLD == 0.3
    rng = np.random.default_rng(12)
    ps = ParticleSet.from_states(rng.normal(size=(100, 2)))
    ll = np.full(100, -INF)
    ll[:alive] = 0.0
    step = sir_update(ps, ll, rng)
    assert step.n_eff == pytest.approx(alive)
    assert step.resampled is expect
    if expect:
        np.testing.assert_array_equal(step.particles.weights, np.full(100, 0.01))
        assert step.particles.n_eff() == pytest.approx(100.0)
    else:
        np.testing.assert_array_equal(step.particles.states, ps.states)  # reweighted only
        assert step.particles.n_eff() == pytest.approx(alive)


def test_sir_with_a_fixed_jitter_covariance():
    rng = np.random.default_rng(13)
    ps = ParticleSet.from_states(np.zeros((5000, 2)))
    ll = np.where(np.arange(5000) < 50, 0.0, -INF)
    step = sir_update(ps, ll, rng, SIRConfig(jitter_cov=np.diag([4.0, 0.25])))
    assert step.resampled
    np.testing.assert_allclose(step.particles.cov(), np.diag([4.0, 0.25]), rtol=0.1, atol=0.05)
    with pytest.raises(ValueError, match="3x3"):
        sir_update(ParticleSet.from_states(np.zeros((5, 3))), np.r_[0.0, [-INF] * 4], rng,
                   SIRConfig(jitter_cov=np.eye(2)))


@pytest.mark.parametrize("threshold", [0.0, -0.1, 1.5], ids=["threshold-zero", "threshold-negative", "threshold-1.5"])
def test_sir_config_rejects_bad_threshold(threshold):
    with pytest.raises(ValueError, match="resample_threshold"):
        SIRConfig(resample_threshold=threshold)


def test_sir_config_rejects_indefinite_jitter():
    with pytest.raises(ValueError, match="jitter covariance"):
        SIRConfig(jitter_cov=[[1.0, 0.0], [0.0, -1.0]])


def test_sir_filter_of_a_static_point_matches_the_kalman_posterior():
    """Five Gaussian position measurements of a static 2-D point: closed-form posterior as the oracle."""
    P0, R = np.diag([25.0, 16.0]), np.array([[2.0, 0.8], [0.8, 1.5]])
    truth = np.array([1.0, -2.0])
    errors, ratios = [], []
    for seed in range(4):
        rng = np.random.default_rng(100 + seed)
        zs = truth + rng.multivariate_normal(np.zeros(2), R, size=5)
        Y = np.linalg.inv(P0) + 5 * np.linalg.inv(R)
        P = np.linalg.inv(Y)
        mu = P @ (np.linalg.inv(R) @ zs.sum(axis=0))
        ps = ParticleSet.from_states(rng.multivariate_normal(np.zeros(2), P0, size=4000))
        for z in zs:
            ps = sir_update(ps, multivariate_normal(z, R).logpdf(ps.states), rng).particles
        err = ps.mean() - mu
        errors.append(float(err @ np.linalg.solve(P, err)))
        ratios.append(np.linalg.det(ps.cov()) ** 0.5 / np.linalg.det(P) ** 0.5)
    assert max(errors) < 0.1  # the mean within ~0.3 posterior standard deviations
    assert np.mean(ratios) == pytest.approx(1.0, abs=0.15)


# -- the transmission trigger (5.35) ----------------------------------------------------------------------
def test_information_trigger_never_fires_for_an_uninformative_likelihood():
    rng = np.random.default_rng(14)
    ps, trigger = cloud(rng), InformationTrigger()
    for _ in range(200):
        step = sir_update(ps, np.full(ps.n, -7.3), rng)  # constant: says nothing about the state
        assert step.log_evidence == pytest.approx(-7.3)  # the raw evidence depends on the units ...
        trigger.add(step.log_relative_evidence)  # ... the relative one does not
        ps = step.particles
        assert not trigger.due()
    assert trigger.log_product == pytest.approx(0.0, abs=1e-9) and trigger.steps == 200


def test_information_trigger_fires_for_informative_likelihoods_and_resets():
    rng = np.random.default_rng(15)
    ps, trigger = cloud(rng, scale=5.0), InformationTrigger()
    fired_at = None
    for t in range(20):
        step = sir_update(ps, multivariate_normal([1.0, 0.0], np.eye(2)).logpdf(ps.states), rng)
        trigger.add(step.log_relative_evidence)
        ps = step.particles
        if trigger.due(math.log(0.1)):
            fired_at = t
            break
    assert fired_at is not None and fired_at <= 2
    trigger.reset()
    assert trigger.log_product == 0.0 and trigger.steps == 0 and not trigger.due()


@pytest.mark.parametrize("value", [NAN, INF], ids=["nan-log-sum", "plus-inf-log-sum"])
def test_information_trigger_rejects_bad_log_sum(value):
    with pytest.raises(ValueError, match="log weight sum"):
        InformationTrigger().add(value)


def test_information_trigger_rejects_non_finite_threshold():
    with pytest.raises(ValueError, match="threshold"):
        InformationTrigger().due(-INF)
