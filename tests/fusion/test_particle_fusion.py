"""Decentralized particle fusion (Merino Alg. 5.2, Alg. 5.3, (2.27)-(2.28)): weights against brute force, and
fusion over a tree against the closed-form centralized posterior."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from fusion.mixture import GaussianMixture
from fusion.particle_fusion import ParticleChannelFilter, UniformBox, fuse_bayes, fuse_lop
from fusion.particles import ParticleSet
from fusion.resampling import optimal_bandwidth

NAN = float("nan")


def kde_density(ps: ParticleSet, x: np.ndarray) -> np.ndarray:
    """The corrected (5.25) by brute force, one scipy Gaussian per particle."""
    h = optimal_bandwidth(ps.n_eff(), ps.dim)
    return sum(w * multivariate_normal(m, h * h * ps.cov()).pdf(x) for w, m in zip(ps.weights, ps.states, strict=True))


def small_sets(rng):
    local = ParticleSet.from_unnormalised(rng.normal(size=(30, 2)), rng.random(30) + 0.1)
    received = ParticleSet.from_states(rng.normal(size=(20, 2)) + [0.5, 0.0])
    return local, received


# -- Alg. 5.2 weights -------------------------------------------------------------------------------------
def test_bayes_pool_weights_are_the_density_ratios_of_alg_5_2():
    rng = np.random.default_rng(1)
    local, received = small_sets(rng)
    common = GaussianMixture(np.ones(1), np.zeros((1, 2)), 4.0 * np.eye(2)[None])
    pool = fuse_bayes(local, received, common, None, resample=False)
    c = multivariate_normal(np.zeros(2), 4.0 * np.eye(2))
    w_j = received.n * received.weights * kde_density(local, received.states) / c.pdf(received.states)
    w_i = local.n * local.weights * kde_density(received, local.states) / c.pdf(local.states)
    expected = np.r_[w_j, w_i]
    np.testing.assert_allclose(pool.states, np.r_[received.states, local.states])
    np.testing.assert_allclose(pool.weights, expected / expected.sum(), rtol=1e-9)


def test_bayes_with_a_flat_common_belief_uses_the_other_density_only():
    rng = np.random.default_rng(2)
    local, received = small_sets(rng)
    pool = fuse_bayes(local, received, None, None, resample=False)
    expected = np.r_[received.n * received.weights * kde_density(local, received.states),
                     local.n * local.weights * kde_density(received, local.states)]
    np.testing.assert_allclose(pool.weights, expected / expected.sum(), rtol=1e-9)
    fused = fuse_bayes(local, received, None, rng)
    assert fused.n == local.n and fused.n_eff() == pytest.approx(local.n)
    assert fuse_bayes(local, received, None, rng, n=7).n == 7


def test_uniform_box_common_belief_cancels_inside_and_zeroes_particles_outside():
    rng = np.random.default_rng(3)
    local, received = small_sets(rng)
    box = UniformBox([-1.0, -5.0], [5.0, 5.0])
    inside = box.logpdf(np.array([[0.0, 0.0], [-1.0, 5.0]]))
    np.testing.assert_allclose(inside, -np.log(60.0))
    assert box.logpdf(np.array([[-1.01, 0.0]]))[0] == -np.inf
    boxed = fuse_bayes(local, received, box, None, resample=False)
    flat = fuse_bayes(local, received, None, None, resample=False)
    outside = np.r_[received.states[:, 0], local.states[:, 0]] < -1.0
    assert outside.any() and np.all(boxed.weights[outside] == 0.0)
    kept = flat.weights[~outside]
    np.testing.assert_allclose(boxed.weights[~outside], kept / kept.sum(), rtol=1e-9)
    assert box.sample(rng, 50).states.min(axis=0)[0] >= -1.0


@pytest.mark.parametrize(("lower", "upper", "match"), [
    ([0.0, 0.0], [1.0, 0.0], "exceed"), ([0.0], [1.0, 1.0], "same length"), ([NAN, 0.0], [1.0, 1.0], "non-finite"),
], ids=["box-empty-axis", "box-bounds-different-lengths", "box-nan-bound"])
def test_uniform_box_rejects(lower, upper, match):
    with pytest.raises(ValueError, match=match):
        UniformBox(lower, upper)


def test_fusion_rejects_bad_input():
    rng = np.random.default_rng(4)
    local, received = small_sets(rng)
    three = ParticleSet.from_states(rng.normal(size=(10, 3)))
    with pytest.raises(ValueError, match="dimension mismatch"):
        fuse_bayes(local, three, None, rng)  # received set of another dimension
    with pytest.raises(ValueError, match="common belief 3-D"):
        fuse_bayes(local, received, UniformBox([0, 0, 0], [1, 1, 1]), rng)  # common belief of another dimension
    with pytest.raises(ValueError, match="logpdf"):
        fuse_bayes(local, received, "flat", rng)  # common belief that is not a density
    with pytest.raises(ValueError, match="ParticleSet"):
        fuse_bayes(local.states, received, None, rng)  # local belief that is not a particle set
    with pytest.raises(ValueError, match="random generator"):
        fuse_bayes(local, received, None, None)  # resampling without an rng
    with pytest.raises(ValueError, match="positive integer"):
        fuse_bayes(local, received, None, rng, n=0)  # zero fused particles
    with pytest.raises(ValueError, match="alpha_local"):
        fuse_lop(local, received, 1.5, rng)  # LOP weight above 1
    with pytest.raises(ValueError, match="alpha_local"):
        fuse_lop(local, received, NAN, rng)  # LOP weight NaN
    with pytest.raises(ValueError, match="random generator"):
        fuse_lop(local, received, 0.5)  # LOP resampling without an rng
    with pytest.raises(ValueError, match="dimension mismatch"):
        fuse_lop(local, three, 0.5, rng)  # LOP of sets of different dimensions


# -- Alg. 5.3 ---------------------------------------------------------------------------------------------
def test_lop_pool_is_the_weighted_union_of_5_27():
    rng = np.random.default_rng(5)
    local, received = small_sets(rng)
    pool = fuse_lop(local, received, 0.3, resample=False)
    np.testing.assert_allclose(pool.weights, np.r_[0.3 * local.weights, 0.7 * received.weights], rtol=1e-12)
    np.testing.assert_allclose(pool.mean(), 0.3 * local.mean() + 0.7 * received.mean(), rtol=1e-12)
    fused = fuse_lop(local, received, 0.3, rng)
    assert fused.n == local.n
    only_local = fuse_lop(local, received, 1.0, resample=False)
    assert np.all(only_local.weights[local.n :] == 0.0)


# -- the channel filter's bookkeeping ------------------------------------------------------------------------
def test_channel_filter_records_bel_ij_on_send_and_on_receive():
    rng = np.random.default_rng(6)
    local, received = small_sets(rng)
    prior = UniformBox([-9.0, -9.0], [9.0, 9.0])
    cf = ParticleChannelFilter(prior)
    assert cf.common("b") is prior and cf.neighbours() == []
    cf.on_send(local)  # no channel yet: nothing recorded
    assert cf.neighbours() == []
    cf.add_neighbour("b")
    cf.on_send(local)  # (2.28): bel_ij <- bel_i
    np.testing.assert_array_equal(cf.common("b").means, local.states)
    cf.on_receive("c", local, received, rng)  # (2.27): bel_ij <- bel_j
    np.testing.assert_array_equal(cf.common("c").means, received.states)
    np.testing.assert_array_equal(cf.common("b").means, local.states)  # other channels untouched
    cf.on_send(received, ["b"])
    np.testing.assert_array_equal(cf.common("b").means, received.states)
    cf.reset("b")
    assert cf.common("b") is prior
    cf.on_receive("d", local, received, rng, method="lop")  # the record is kept whatever the method
    np.testing.assert_array_equal(cf.common("d").means, received.states)


def test_channel_filter_compresses_the_stored_common_belief():
    rng = np.random.default_rng(7)
    local, received = small_sets(rng)
    cf = ParticleChannelFilter(common_components=4)
    cf.on_receive("b", local, received, rng)
    assert cf.common("b").k <= 4
    np.testing.assert_allclose(cf.common("b").cov(), GaussianMixture.kde(received).cov(), rtol=1e-9)
    cf.add_neighbour("c")
    with pytest.raises(ValueError, match="random generator"):
        cf.on_send(local)  # compression needs an rng


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"method": "max"}, "method"), ({"alpha_local": -0.1}, "alpha_local"), ({"bandwidth": 0.0}, "bandwidth"),
    ({"common_components": 0}, "common_components"), ({"initial_common": 3.0}, "logpdf"),
], ids=["unknown-method", "alpha-negative", "bandwidth-zero", "zero-common-components", "common-not-a-density"])
def test_channel_filter_rejects_bad_settings(kwargs, match):
    with pytest.raises(ValueError, match=match):
        ParticleChannelFilter(**kwargs)


def test_receiving_the_same_information_twice_does_not_count_it_twice():
    """b receives a's set, then the same set again: the channel filter divides it out (bel_ij = bel_a); with a
    flat bel_ij (no bookkeeping) the second copy shrinks b's covariance as if it were new evidence."""
    rng = np.random.default_rng(8)
    a = ParticleSet.from_states(rng.multivariate_normal([0.0, 0.0], np.eye(2), size=800))
    b0 = ParticleSet.from_states(rng.multivariate_normal([0.0, 0.0], np.eye(2), size=800))
    cf = ParticleChannelFilter(shrink=True)
    b1 = cf.on_receive("a", b0, a, rng)
    b2 = cf.on_receive("a", b1, a, rng)
    naive = fuse_bayes(b1, a, None, rng, shrink=True)
    ratio = np.linalg.det(b2.cov()) / np.linalg.det(b1.cov())
    assert ratio == pytest.approx(1.0, abs=0.2)
    assert np.linalg.det(naive.cov()) / np.linalg.det(b1.cov()) < 0.6  # two copies: about (2/3)^2


# -- fusion over a tree vs the centralized posterior ---------------------------------------------------------
P0 = 4.0 * np.eye(2)
RS = [np.array([[1.0, 0.0], [0.0, 9.0]]), np.array([[4.0, 1.0], [1.0, 4.0]]), np.array([[9.0, 0.0], [0.0, 1.0]])]
ZS = [np.array([1.3, -0.2]), np.array([0.4, -1.1]), np.array([1.1, 0.3])]


def gaussian_posterior(nodes):
    """Prior N(0, P0) times the Gaussian likelihoods of ``nodes`` (information form, closed form)."""
    Y = np.linalg.inv(P0) + sum(np.linalg.inv(RS[i]) for i in nodes)
    P = np.linalg.inv(Y)
    return P @ sum(np.linalg.inv(RS[i]) @ ZS[i] for i in nodes), P


def run_line_tree(seed, n, initial_common, shrink):
    """a - b - c; each node's set samples its own posterior (common prior N(0, P0) times its own Gaussian
    likelihood); messages a->b, b->c, c->b, b->a through channel filters. Returns the three final sets."""
    rng = np.random.default_rng(seed)
    sets = [ParticleSet.from_states(rng.multivariate_normal(*gaussian_posterior([i]), size=n)) for i in range(3)]
    cfs = [ParticleChannelFilter(initial_common, shrink=shrink) for _ in range(3)]

    def exchange(src, dst):
        cfs[src].on_send(sets[src], [dst])
        sets[dst] = cfs[dst].on_receive(src, sets[dst], sets[src], rng)

    for src, dst in ((0, 1), (1, 2), (2, 1), (1, 0)):
        exchange(src, dst)
    return sets


def tree_statistics(n, initial_common, shrink, seeds):
    """Per node: the bias of the mean in units of its Monte Carlo standard error (estimated from the spread
    over seeds), the root-mean-square error of the mean in posterior standard deviations, and the mean and
    Monte Carlo standard error of the ratio sqrt(det cov / det P) to the centralized posterior."""
    mu, P = gaussian_posterior([0, 1, 2])
    results = [run_line_tree(seed, n, initial_common, shrink) for seed in seeds]
    err = np.array([[s.mean() - mu for s in sets] for sets in results])  # (seeds, nodes, 2)
    ratio = np.array([[np.sqrt(np.linalg.det(s.cov()) / np.linalg.det(P)) for s in sets] for sets in results])
    sd = err.std(axis=0, ddof=1)
    bias_z = err.mean(axis=0) / (sd / np.sqrt(len(seeds)))
    rms = np.sqrt(np.mean(err**2, axis=0)) / np.sqrt(np.diag(P))
    return bias_z, rms, ratio.mean(axis=0), ratio.std(axis=0, ddof=1) / np.sqrt(len(seeds)), P


GAUSSIAN_PRIOR = GaussianMixture(np.ones(1), np.zeros((1, 2)), P0[None])


def test_particle_fusion_on_a_tree_recovers_the_centralized_posterior():
    """Alg. 5.2 with on-send/on-receive bookkeeping and the common prior as the initial bel_ij: every node ends
    at the centralized posterior (prior x all three likelihoods) within Monte Carlo error, over 8 seeds."""
    bias_z, rms, ratio, ratio_se, _ = tree_statistics(800, GAUSSIAN_PRIOR, True, range(8))
    assert np.all(np.abs(bias_z) < 4.0), bias_z  # no systematic error of the mean
    assert np.all(rms < 0.2), rms  # and each run's mean within a fraction of the posterior spread
    assert np.all(np.abs(ratio - 1.0) < 4.0 * ratio_se + 0.02), (ratio, ratio_se)  # the right spread
    assert np.all(ratio_se < 0.05)


def test_tree_check_detects_double_counting_of_the_common_prior():
    """The same exchange with a flat initial bel_ij counts the common prior twice at every fusion: the oracle
    comparison above must fail (so it has teeth)."""
    bias_z, _, ratio, ratio_se, _ = tree_statistics(800, None, True, range(4))
    assert np.any(np.abs(bias_z) > 6.0) or np.any(np.abs(ratio - 1.0) > 4.0 * ratio_se + 0.02)
    assert np.all(ratio < 0.95)  # overconfident


def test_thesis_density_estimate_makes_tree_fusion_conservative():
    """With the thesis's unshrunk estimate (5.25) every density is widened by 1 + h^2, which divides the new
    information of every fusion by about 1 + h^2: the result is wider than the centralized posterior."""
    _, _, ratio, _, _ = tree_statistics(800, GAUSSIAN_PRIOR, False, range(4))
    h2 = optimal_bandwidth(800, 2) ** 2
    assert np.all(ratio > 1.0) and np.all(ratio < (1.0 + h2) ** 2)


def test_lop_is_more_conservative_than_bayes_fusion():
    rng = np.random.default_rng(9)
    a = ParticleSet.from_states(rng.multivariate_normal(*gaussian_posterior([0]), size=1000))
    b = ParticleSet.from_states(rng.multivariate_normal(*gaussian_posterior([2]), size=1000))
    bayes = fuse_bayes(b, a, GAUSSIAN_PRIOR, rng, shrink=True)
    lop = fuse_lop(b, a, 0.5, rng)
    _, P = gaussian_posterior([0, 2])
    assert np.linalg.det(lop.cov()) > 2.0 * np.linalg.det(bayes.cov())
    assert np.linalg.det(bayes.cov()) == pytest.approx(np.linalg.det(P), rel=0.25)
    # LOP's spread is at least that of the narrower input along every axis: it never gains information
    assert np.all(np.diag(lop.cov()) > 0.9 * np.minimum(np.diag(a.cov()), np.diag(b.cov())))


def test_on_send_records_the_belief_as_sent_and_rejects_one_of_another_dimension():
    rng = np.random.default_rng(8)
    local = ParticleSet.from_states(rng.normal(size=(300, 3)))
    sent = GaussianMixture.from_particles(local, 2, rng)
    cf = ParticleChannelFilter()
    cf.on_send(local, ["j"], sent=sent)
    assert cf.common("j") is sent
    with pytest.raises(ValueError, match="3-D GaussianMixture"):
        cf.on_send(local, ["j"], sent=GaussianMixture(np.ones(1), np.zeros((1, 2)), np.eye(2)[None]))


def test_on_receive_takes_the_received_density_as_bel_j_and_can_return_the_weighted_pool():
    rng = np.random.default_rng(9)
    local = ParticleSet.from_states(rng.normal(size=(300, 3)))
    density = GaussianMixture(np.ones(1), np.full((1, 3), 0.5), np.eye(3)[None])
    received = density.sample(rng, 300)
    for method in ("bayes", "lop"):
        cf = ParticleChannelFilter(method=method)
        pool = cf.on_receive("j", local, received, rng, received_belief=density, resample=False)
        assert pool.n == 600 and cf.common("j") is density
