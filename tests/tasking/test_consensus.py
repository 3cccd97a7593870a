"""Metropolis weights, the Xiao–Boyd–Lall consensus WLS and the Kalman-consensus filter (spec 004 §2.3, §2.6),
against centralized oracles."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tasking.consensus import (
    DoubleIntegrator,
    components,
    consensus_round,
    kcf_step,
    lossy_weights,
    metropolis_weights,
    wls_consensus,
    wls_estimate,
    wls_information,
)


def _random_graph(rng, n, p):
    upper = np.triu(rng.random((n, n)) < p, 1)
    return upper | upper.T


def _connected_graph(rng, n, p=0.3):
    while True:
        adj = _random_graph(rng, n, p)
        if len(components(adj)) == 1:
            return adj


def _random_spd(rng, d):
    a = rng.normal(size=(d, d))
    return a @ a.T + 0.5 * np.eye(d)


@settings(max_examples=100, deadline=None)
@given(n=st.integers(1, 15), p=st.floats(0, 1), seed=st.integers(0, 2**32 - 1))
def test_metropolis_weights_symmetric_doubly_stochastic(n, p, seed):
    adj = _random_graph(np.random.default_rng(seed), n, p)
    W = metropolis_weights(adj)
    np.testing.assert_allclose(W, W.T, atol=0)
    np.testing.assert_allclose(W.sum(axis=0), 1.0, atol=1e-12)
    np.testing.assert_allclose(W.sum(axis=1), 1.0, atol=1e-12)
    assert np.all(W >= 0)
    assert np.all((W > 0)[~np.eye(n, dtype=bool)] == adj[~np.eye(n, dtype=bool)])  # support = the graph


def _centralized_wls(y, infos, valid):
    P = sum(infos[i] for i in range(len(y)) if valid[i])
    q = sum(infos[i] @ y[i] for i in range(len(y)) if valid[i])
    return np.linalg.solve(P, q)  # (Σ Σ_i⁻¹)⁻¹ Σ Σ_i⁻¹ y_i, A_i = I


def test_wls_consensus_converges_to_the_centralized_wls():
    rng = np.random.default_rng(7)
    n = 12
    adj = _connected_graph(rng, n)
    W = metropolis_weights(adj)
    y = rng.normal(size=(n, 2)) * 5
    infos = np.stack([_random_spd(rng, 2) for _ in range(n)])
    valid = rng.random(n) < 0.7
    valid[0] = True
    oracle = _centralized_wls(y, infos, valid)
    P0, q0 = wls_information(y, infos, valid)
    P, q = wls_consensus(W, P0, q0, 500, require_connected=True)
    x, informed = wls_estimate(P, q, np.zeros((n, 2)))
    assert informed.all()
    np.testing.assert_allclose(x, np.broadcast_to(oracle, (n, 2)), atol=1e-9)


def test_five_iterations_on_a_complete_graph_are_exact_and_on_a_ring_close():
    """Measured here: on a complete graph one Metropolis round is already the centralized WLS; on a ring of 8
    nodes five rounds leave the worst node 0.155 from it (the measurements spread 1.53 around it, so 10 %), and
    60 rounds 1e-6 — the paper's "negligible after five iterations" needs good connectivity."""
    rng = np.random.default_rng(1)
    n = 8
    y = rng.normal(size=(n, 2))
    infos = np.broadcast_to(np.eye(2), (n, 2, 2))
    oracle = y.mean(axis=0)
    complete = ~np.eye(n, dtype=bool)
    P, q = wls_consensus(metropolis_weights(complete), *wls_information(y, infos), 1)
    np.testing.assert_allclose(wls_estimate(P, q, y)[0], np.broadcast_to(oracle, (n, 2)), atol=1e-12)
    ring = np.roll(np.eye(n, dtype=bool), 1, axis=1)
    ring = ring | ring.T
    P, q = wls_consensus(metropolis_weights(ring), *wls_information(y, infos), 5)
    error = np.abs(wls_estimate(P, q, y)[0] - oracle).max()
    assert error < 0.2 and error < 0.15 * np.abs(y - oracle).max()
    P, q = wls_consensus(metropolis_weights(ring), *wls_information(y, infos), 60)
    assert np.abs(wls_estimate(P, q, y)[0] - oracle).max() < 1e-3 * error


def test_intermediate_estimates_are_unbiased():
    """Monte Carlo (2000 draws): after 2 rounds every node's estimate averages to the truth within 4 standard
    errors, although it is not yet the centralized WLS."""
    rng = np.random.default_rng(11)
    n, draws, truth = 6, 2000, np.array([3.0, -2.0])
    adj = _connected_graph(rng, n, 0.4)
    W = metropolis_weights(adj)
    infos = np.stack([_random_spd(rng, 2) for _ in range(n)])
    covs = np.linalg.inv(infos)
    noise = np.stack([rng.multivariate_normal(np.zeros(2), covs[i], size=draws) for i in range(n)], axis=1)
    y = truth + noise  # (draws, n, 2)
    P, q = wls_consensus(np.broadcast_to(W, (draws, n, n)), *wls_information(y, infos), 2)
    x, _ = wls_estimate(P, q, y)
    mean, sem = x.mean(axis=0), x.std(axis=0) / np.sqrt(draws)
    assert np.all(np.abs(mean - truth) < 4 * sem)


def test_lossy_weights_keep_the_lost_weight_on_the_receiver():
    rng = np.random.default_rng(4)
    adj = _connected_graph(rng, 7, 0.5)
    W = metropolis_weights(adj)
    np.testing.assert_array_equal(lossy_weights(W, adj), W)  # nothing lost: Metropolis as is
    received = adj & (rng.random((7, 7)) > 0.4)  # directed losses
    Wl = lossy_weights(W, received)
    np.testing.assert_allclose(Wl.sum(axis=-1), 1.0, atol=1e-12)  # still an average at every receiver
    assert np.all(Wl >= 0)
    off = ~np.eye(7, dtype=bool)
    np.testing.assert_array_equal((Wl > 0)[off], received[off])
    np.testing.assert_allclose(np.diag(Wl), np.diag(W) + np.where(adj & ~received, W, 0).sum(axis=-1))
    with pytest.raises(ValueError, match="diagonal"):
        lossy_weights(W, received | np.eye(7, dtype=bool))


def _lossy_rounds(rng, W, adj, P, q, rounds, loss):
    for _ in range(rounds):
        received = adj & (rng.random(adj.shape) >= loss)
        P, q = consensus_round(lossy_weights(W, received), P, q)
    return P, q


@pytest.mark.parametrize("loss", [0.1, 0.3])
def test_intermediate_estimates_stay_unbiased_under_message_loss(loss):
    """004 §3.2's "even the intermediate estimates ... are unbiased", with Bernoulli loss on every directed message:
    Monte Carlo (2000 draws, independent losses per draw, 3 rounds): every node's mean error within 4 standard
    errors of 0."""
    rng = np.random.default_rng(12)
    n, draws, truth = 6, 2000, np.array([3.0, -2.0])
    adj = np.broadcast_to(_connected_graph(rng, n, 0.4), (draws, n, n))
    infos = np.stack([_random_spd(rng, 2) for _ in range(n)])
    covs = np.linalg.inv(infos)
    y = truth + np.stack([rng.multivariate_normal(np.zeros(2), covs[i], size=draws) for i in range(n)], axis=1)
    W = metropolis_weights(adj)
    x, _ = wls_estimate(*_lossy_rounds(rng, W, adj, *wls_information(y, infos), 3, loss), y)
    mean, sem = x.mean(axis=0), x.std(axis=0) / np.sqrt(draws)
    assert np.all(np.abs(mean - truth) < 4 * sem)


def test_lossy_rounds_on_a_connected_graph_reach_consensus():
    """004 §3.2: consensus holds if the graphs are "jointly connected ... infinitely often": 30 % loss on every
    message of a ring, 300 rounds: all nodes agree (to 1e-6) on a point inside the measurements' hull, near the
    centralized WLS (the lost weights tilt it; chosen bound 0.5 of the measurements' spread)."""
    rng = np.random.default_rng(8)
    n = 8
    ring = np.roll(np.eye(n, dtype=bool), 1, axis=1)
    ring = ring | ring.T
    y = rng.normal(size=(n, 2)) * 3
    P, q = _lossy_rounds(rng, metropolis_weights(ring), ring, *wls_information(y, np.eye(2)), 300, 0.3)
    x, _ = wls_estimate(P, q, y)
    assert np.ptp(x, axis=0).max() < 1e-6
    assert np.all((x >= y.min(axis=0)) & (x <= y.max(axis=0)))
    assert np.linalg.norm(x[0] - y.mean(axis=0)) < 0.5 * y.std(axis=0).max()


def test_node_without_information_keeps_its_fallback():
    P, q = wls_information(np.ones((3, 2)), np.eye(2), np.array([True, False, False]))
    W = metropolis_weights(np.array([[0, 1, 0], [1, 0, 0], [0, 0, 0]]))
    x, informed = wls_estimate(*wls_consensus(W, P, q, 1), fallback=np.full((3, 2), 7.0))
    np.testing.assert_array_equal(informed, [True, True, False])
    np.testing.assert_allclose(x[2], [7.0, 7.0])


def test_disconnected_weights_raise_when_connectivity_is_required():
    W = metropolis_weights(np.array([[0, 1, 0, 0], [1, 0, 0, 0], [0, 0, 0, 1], [0, 0, 1, 0]]))
    P, q = wls_information(np.zeros((4, 2)), np.eye(2))
    with pytest.raises(ValueError, match=r"disconnected graph with components \[\[0, 1\], \[2, 3\]\]"):
        wls_consensus(W, P, q, 5, require_connected=True)


@pytest.mark.parametrize(
    ("adjacency", "message"),
    [
        (np.array([[0, 1], [0, 0]]), "symmetric"),  # a directed link
        (np.array([[1, 0], [0, 0]]), "diagonal"),  # a self-loop
        (np.array([[0, 2], [2, 0]]), "0/1"),  # a weight where a link flag belongs
    ],
)
def test_bad_adjacency_raises(adjacency, message):
    with pytest.raises(ValueError, match=message):
        metropolis_weights(adjacency)


def test_bad_weights_raise():
    with pytest.raises(ValueError, match="sum to 1"):  # rows of a non-stochastic matrix
        wls_consensus(np.full((2, 2), 0.3), np.zeros((2, 2, 2)), np.zeros((2, 2)), 1)


# ------------------------------------------------------------------------------------------------- KCF
def _central_kf(model, mean, cov, zs, R):
    """Standard covariance-form KF with all nodes' measurements stacked (the oracle)."""
    H = np.vstack([model.H] * len(zs))
    big_R = np.kron(np.eye(len(zs)), R)
    S = H @ cov @ H.T + big_R
    K = cov @ H.T @ np.linalg.inv(S)
    post = mean + K @ (np.concatenate(zs) - H @ mean)
    post_cov = (np.eye(4) - K @ H) @ cov
    return post, post_cov, model.A @ post, model.A @ post_cov @ model.A.T + model.Q


@pytest.mark.parametrize("epsilon", [0.0, 1e-6])
def test_kcf_on_a_complete_graph_matches_the_centralized_kf(epsilon):
    rng = np.random.default_rng(5)
    n, model, R = 4, DoubleIntegrator(0.1, sigma_a=0.5), np.diag([0.3, 0.5])
    complete = ~np.eye(n, dtype=bool)
    truth = np.array([0.0, 0.0, 2.0, -1.0])
    mean, cov = np.array([1.0, 1.0, 0.0, 0.0]), np.diag([4.0, 4.0, 9.0, 9.0])
    node_mean, node_cov = np.tile(mean, (n, 1)), np.tile(cov, (n, 1, 1))
    for _ in range(40):
        zs = truth[:2] + rng.multivariate_normal(np.zeros(2), R, size=n)
        post, post_cov, mean, cov = _central_kf(model, mean, cov, zs, R)
        step = kcf_step(model, node_mean, node_cov, complete, zs, np.ones(n, bool), R, epsilon)
        np.testing.assert_allclose(step.mean, np.tile(post, (n, 1)), atol=1e-6)
        np.testing.assert_allclose(step.cov, np.tile(post_cov, (n, 1, 1)), atol=1e-9)
        node_mean, node_cov = step.next_mean, step.next_cov
        truth = model.A @ truth


def test_kcf_consensus_term_reduces_disagreement():
    """On a ring with different priors and no measurements, ε > 0 pulls the estimates together."""
    rng = np.random.default_rng(2)
    n, model = 6, DoubleIntegrator(0.05)
    ring = np.roll(np.eye(n, dtype=bool), 1, axis=1)
    ring = ring | ring.T
    means = rng.normal(size=(n, 4)) * 3
    covs = np.tile(np.eye(4), (n, 1, 1))
    no_z = np.zeros(n, bool)

    def spread(x):
        return float(np.sum((x - x.mean(axis=0)) ** 2))

    without = kcf_step(model, means, covs, ring, np.zeros((n, 2)), no_z, np.eye(2), 0.0)
    with_consensus = kcf_step(model, means, covs, ring, np.zeros((n, 2)), no_z, np.eye(2), 1.0)
    assert spread(without.mean) == pytest.approx(spread(means))
    assert spread(with_consensus.mean) < 0.8 * spread(means)


@pytest.mark.parametrize(
    ("kwargs", "named"),
    [({"epsilon": -1.0}, "epsilon"), ({"R": -np.eye(2)}, "R")],  # negative gain; a non-PD covariance
)
def test_kcf_bad_inputs(kwargs, named):
    args = dict(
        model=DoubleIntegrator(0.1),
        prior_mean=np.zeros((2, 4)),
        prior_cov=np.tile(np.eye(4), (2, 1, 1)),
        adjacency=np.array([[0, 1], [1, 0]]),
        z=np.zeros((2, 2)),
        has_z=np.ones(2, bool),
        R=np.eye(2),
        epsilon=0.5,
    )
    args.update(kwargs)
    with pytest.raises(ValueError, match=named):
        kcf_step(**args)


def test_double_integrator_rejects_a_bad_step():
    with pytest.raises(ValueError, match="dt"):
        DoubleIntegrator(-0.1)  # negative time step
