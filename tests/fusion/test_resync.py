"""Re-synchronisation of channel filters (fusion.resync), against independent oracles.

* After channels lose their common information on a tree (merges, failed exact fusions), the agreement
  brings every one back to exact fusion: from then on each node gains exactly the information of every
  measurement taken afterwards (the centralized information filter's increment), to 1e-9.
* Monte Carlo NEES with random topology changes (links appear and disappear, loops form and break),
  Bernoulli loss, node restarts and desynchronised channels: the protocol is never overconfident
  (per-node ANEES below the chi-square bound), while the naive re-sync — each end taking the other's
  next message as its baseline on its own — is far above it on the same runs.
"""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest
from scipy.stats import chi2

from fusion import Gaussian
from fusion.channel_filter import ChannelFilter, Freshness, Received
from fusion.network import FilterNetwork
from fusion.resync import Edge
from tests.fusion.builders import position_update, random_tree


def _measure(net, rng, truth, share=1.0, oracle=None):
    for i in range(net.n):
        if rng.random() < share:
            update = position_update(3, 3, truth, sigma=float(rng.uniform(0.5, 3.0)), rng=rng)
            net.apply(i, update)
            oracle = None if oracle is None else update(oracle)
    return oracle


def test_desynchronised_tree_channels_resync_and_then_fuse_exactly():
    rng = np.random.default_rng(7)
    n, truth = 7, np.array([10.0, -4.0, 2.0])
    net = FilterNetwork(n, random_tree(n, rng), Gaussian.zeros(3), "hybrid")
    for _ in range(3):
        _measure(net, rng, truth)
        net.exchange()
    for i in (0, 3, 5):  # e.g. a duplicate-track merge at these nodes: all their channels lose sync
        net.beliefs[i] = net.beliefs[i].scaled(0.9)
        for j in net.filters[i].neighbours():
            net.filters[i].desynchronize(j)
    for _ in range(2 * n):
        _measure(net, rng, truth, share=0.5)
        net.exchange()
    assert net.methods["resync"] > 0
    for i in range(n):
        assert all(net.filters[i].is_synchronized(j) for j in net.filters[i].neighbours())
    for _ in range(n):  # no fusion is pending: nothing more changes
        net.exchange()
    before = list(net.beliefs)
    increment = _measure(net, rng, truth, oracle=Gaussian.zeros(3))  # the centralized filter of what follows
    for _ in range(n + 1):
        net.exchange()
    for belief, old in zip(net.beliefs, before, strict=True):
        assert np.allclose(belief.Y - old.Y, increment.Y, rtol=1e-9, atol=1e-9)
        assert np.allclose(belief.y - old.y, increment.y, rtol=1e-9, atol=1e-7)


def _random_graph(n, rng, p):
    return [(i, j) for i in range(n) for j in range(i + 1, n) if rng.random() < p]


class _NaiveResync(ChannelFilter):
    """Each end on its own: a desynchronised channel on a tree edge takes the neighbour's next message
    as the common information and is exact from then on."""

    def on_receive(self, neighbour, local, received, acked_seq, seq=None, tree_edge=True, resync=None, fresh=0):
        if neighbour in self.neighbours() and not self.is_synchronized(neighbour) and tree_edge is Edge.TREE:
            self.reset(neighbour)
            self._channels[neighbour].inbound = received
            return Received(local, "resync")
        return super().on_receive(neighbour, local, received, acked_seq, seq, tree_edge, fresh=fresh)


class _NaiveNetwork(FilterNetwork):
    def _filter(self, i):
        return _NaiveResync(self.prior, self.policy, self.intersect)


def _churn(network, rng, n=6, rounds=30, loss=0.2):
    """One run: random graphs replaced now and then (the filters themselves must see that a link that appears
    or returns opens a channel whose common information is unknown), loss, restarts and merge-like
    desynchronisations. Returns every node's NEES."""
    truth = rng.uniform(-50, 50, 3)
    net = network(n, _random_graph(n, rng, 0.4), Gaussian.zeros(3), "hybrid", loss=loss,
                  seed=int(rng.integers(1 << 31)))
    for _ in range(rounds):
        if rng.random() < 0.3:
            net.set_edges(_random_graph(n, rng, rng.uniform(0.2, 0.6)))
        if rng.random() < 0.05:
            net.restart(int(rng.integers(n)))
        if rng.random() < 0.1:
            i = int(rng.integers(n))
            for j in net.filters[i].neighbours():
                net.filters[i].desynchronize(j)
        _measure(net, rng, truth, share=0.5)
        net.exchange()
    _measure(net, rng, truth)  # every node informed, even one that has just restarted
    return [b.nees(truth) for b in net.beliefs], net.methods


def _anees(network, runs, seed):
    rng = np.random.default_rng(seed)
    nees, methods = [], Counter()
    for _ in range(runs):
        run_nees, run_methods = _churn(network, rng)
        nees.append(run_nees)
        methods += run_methods
    return np.mean(nees, axis=0) / 3, methods


@pytest.mark.parametrize("runs", [15, pytest.param(60, marks=pytest.mark.slow)])
def test_monte_carlo_resync_under_churn_is_never_overconfident(runs):
    """Without the new-link rule (a channel opened on a link that appears or returns trusting the prior)
    the same runs give ANEES 3.2-3.5."""
    upper = chi2.ppf(0.995, runs * 3) / (runs * 3)
    anees, methods = _anees(FilterNetwork, runs, seed=1)
    assert methods["resync"] > runs // 3 and methods["lost"] > 0
    assert anees.max() < upper, f"ANEES {anees} above {upper:.2f}"


@pytest.mark.slow  # ~20 s
def test_monte_carlo_naive_resync_is_overconfident():
    runs = 60
    upper = chi2.ppf(0.995, runs * 3) / (runs * 3)
    anees, methods = _anees(_NaiveNetwork, runs, seed=1)
    assert methods["resync"] > 20
    assert anees.min() > upper, f"naive ANEES {anees} should be above {upper:.2f}"


def test_fresh_nodes_trust_the_prior_and_fuse_exactly_from_the_first_round():
    """Neither end has fused anything yet (both have sent): the new channel shares only the prior, so fusion
    is exact at once (the centralized filter, to 1e-9)."""
    rng = np.random.default_rng(3)
    truth = np.array([1.0, 2.0, 3.0])
    net = FilterNetwork(2, [(0, 1)], Gaussian.zeros(3), "hybrid")
    central = _measure(net, rng, truth, oracle=Gaussian.zeros(3))
    for _ in range(2):
        net.exchange()
    assert set(net.methods) == {"exact"}
    for belief in net.beliefs:
        assert np.allclose(belief.Y, central.Y, rtol=1e-9, atol=1e-9)


def test_a_link_between_informed_nodes_opens_desynchronised_and_resyncs():
    """Two trees that exchanged on their own are joined by a bridge: the new channel starts desynchronised
    (both ends may hold the same information from before), then returns to exact fusion by agreement."""
    rng = np.random.default_rng(5)
    truth = np.array([1.0, 2.0, 3.0])
    net = FilterNetwork(4, [(0, 1), (2, 3)], Gaussian.zeros(3), "hybrid")
    for _ in range(3):
        _measure(net, rng, truth)
        net.exchange()
    net.set_edges([(0, 1), (2, 3), (1, 2)])
    net.exchange()
    assert not net.filters[1].is_synchronized(2) and not net.filters[2].is_synchronized(1)
    for _ in range(6):
        _measure(net, rng, truth, share=0.5)
        net.exchange()
    assert net.methods["resync"] == 1
    assert net.filters[1].is_synchronized(2) and net.filters[2].is_synchronized(1)


def test_a_new_channel_trusts_the_prior_only_when_provably_nothing_else_is_shared():
    """Receiver fresh and silent (e.g. a track just adopted from the peer): exact. Receiver that has sent,
    from a peer that has fused something: it may hold ours by another path, so desynchronised."""
    prior, peer = Gaussian.zeros(3), Gaussian.zeros(3).fuse(Gaussian(np.ones(3), np.eye(3)))
    silent = ChannelFilter(prior, "hybrid", me="b")
    assert silent.on_receive("a", prior, peer, None, seq=1, tree_edge=Edge.TREE).method == "exact"
    spoke = ChannelFilter(prior, "hybrid", me="b")
    spoke.on_send(prior, 1)
    out = spoke.on_receive("a", prior, peer, None, seq=1, tree_edge=Edge.TREE)
    assert (out.method, out.cause) == ("ci", "common_unknown") and spoke.freshness is Freshness.INFORMED
    told = ChannelFilter(prior, "hybrid", me="b")
    told.on_send(prior, 1)
    assert told.on_receive("a", prior, peer, None, seq=1, tree_edge=Edge.TREE, fresh=Freshness.FRESH).method == "exact"
