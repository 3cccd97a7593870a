"""The particle exchange: candidates compressed on the wire, matched by position and fused — Bayes (Merino
Alg. 5.2) on a tree edge equals the centralized posterior and an echo is not counted twice; the linear
opinion pool (Alg. 5.3) on loops never shrinks the spread without new evidence; bad messages change nothing."""

from __future__ import annotations

import numpy as np
import pytest

from agent.beliefs.particle_init import Candidate, ParticleInitConfig
from agent.beliefs.particle_match import match
from agent.beliefs.particle_resolution import ResolutionClock
from agent.beliefs.particles import ParticleExchange
from agent.beliefs.tracking import Tracker
from agent.beliefs.tracking_config import TrackerConfig
from agent.net.wire import DecodeError
from fusion.mixture import GaussianMixture
from fusion.particles import ParticleSet
from fusion.resync import Edge
from perception.terrain import FlatTerrain

N = 1500
MU = np.array([40.0, 10.0, 0.0])


def exchange(seed: int, share: bool = True) -> ParticleExchange:
    config = TrackerConfig(initiation="particles", particle_init={"exchange": share, "particles": N})
    return ParticleExchange(config.particle_init, Tracker(config, 0.2, FlatTerrain(), seed=seed), seed)


def hold(ex: ParticleExchange, mean, cov, seed: int, cid: int = 0) -> None:
    states = np.random.default_rng(seed).multivariate_normal(mean, cov, size=N)
    ex.tracker.initiator.candidates.append(Candidate(cid, ParticleSet.from_states(states), 0.0, 1, None))


def send(source: ParticleExchange, target: ParticleExchange, origin: str, edge: Edge, seq: int = 1,
         to: str = "uav1") -> list:
    """``source`` (named ``origin``) broadcasts to its neighbour ``to``, which is ``target``."""
    message = source.outgoing(float(seq), [to])
    source.sent(seq, message)
    return target.receive(origin, seq, float(seq), message.payload, edge, float(seq))


def candidate(ex: ParticleExchange) -> ParticleSet:
    [c] = ex.tracker.initiator.candidates
    return c.particles


def product(P_a, mu_a, P_b, mu_b):
    """The centralized posterior of two independent Gaussian beliefs with a flat prior (information sum)."""
    Y = np.linalg.inv(P_a) + np.linalg.inv(P_b)
    P = np.linalg.inv(Y)
    return P @ (np.linalg.solve(P_a, mu_a) + np.linalg.solve(P_b, mu_b)), P


def assert_matches(particles: ParticleSet, mu, P, sigmas=0.35, ratio=(0.7, 1.3)):
    e = particles.mean() - mu
    assert float(np.sqrt(e @ np.linalg.solve(P, e))) < sigmas
    spread = np.diag(particles.cov()) / np.diag(P)
    assert np.all((ratio[0] < spread) & (spread < ratio[1])), spread


# two rays' worth of anisotropy: one belief long along north, the other along east
P_A, P_B = np.diag([60.0, 1.0, 2.0]), np.diag([1.0, 60.0, 2.0])
MU_A, MU_B = MU + [3.0, 0.0, 0.0], MU + [0.0, -3.0, 0.5]


def test_bayes_on_a_tree_edge_equals_the_centralized_posterior_and_an_echo_is_not_counted_twice():
    a, b = exchange(1), exchange(2)
    hold(a, MU_A, P_A, 11)
    hold(b, MU_B, P_B, 12)
    mu, P = product(P_A, MU_A, P_B, MU_B)
    assert send(a, b, "uav0", Edge.TREE) == [("particles_bayes", None)]
    assert_matches(candidate(b), mu, P)
    # b's fused candidate comes back to a: a divides by what it sent (bel_ij), so its own half counts once
    send(b, a, "uav1", Edge.TREE, seq=2, to="uav0")
    assert_matches(candidate(a), mu, P)
    assert a.metrics()["particles"]["fusions"] == {"bayes": 1}


def test_without_the_common_belief_the_echo_would_be_counted_twice():
    """The test above can fail: a's channel reset to flat before b's reply over-counts a's own half."""
    a, b = exchange(1), exchange(2)
    hold(a, MU_A, P_A, 11)
    hold(b, MU_B, P_B, 12)
    send(a, b, "uav0", Edge.TREE)
    a.channels[0].reset("uav1")
    send(b, a, "uav1", Edge.TREE, seq=2, to="uav0")
    mu, P = product(P_A, MU_A, P_B, MU_B)
    twice, P2 = product(P_A / 2, MU_A, P_B, MU_B)
    assert np.diag(candidate(a).cov())[1] < 0.75 * P[1, 1]  # a's east direction counted twice
    assert_matches(candidate(a), twice, P2)


def test_lop_on_loop_edges_never_shrinks_the_spread_without_new_evidence():
    nodes = [exchange(seed) for seed in range(3)]
    for i, node in enumerate(nodes):
        hold(node, MU, P_A, 20 + i)
    for seq in range(1, 7):  # the cycle 0 -> 1 -> 2 -> 0, twice around
        src = (seq - 1) % 3
        assert send(nodes[src], nodes[(src + 1) % 3], f"uav{src}", Edge.LOOP, seq, f"uav{(src + 1) % 3}") == [
            ("particles_lop", "not_tree_edge")]
    for node in nodes:
        assert np.all(np.diag(candidate(node).cov()) > 0.8 * np.diag(P_A))


def test_bayes_around_the_same_cycle_would_shrink_it():
    """What the pool prevents: Bayes on a loop multiplies the same information in again and again."""
    nodes = [exchange(seed) for seed in range(3)]
    for i, node in enumerate(nodes):
        hold(node, MU, P_A, 20 + i)
    for seq in range(1, 7):
        src = (seq - 1) % 3
        send(nodes[src], nodes[(src + 1) % 3], f"uav{src}", Edge.TREE, seq, f"uav{(src + 1) % 3}")
    assert min(float(np.diag(candidate(node).cov())[0]) for node in nodes) < 0.6 * P_A[0, 0]


def test_unknown_edges_are_treated_as_loops():
    a, b = exchange(1), exchange(2)
    hold(a, MU_A, P_A, 11)
    hold(b, MU_B, P_B, 12)
    assert send(a, b, "uav0", Edge.UNKNOWN) == [("particles_lop", "not_tree_edge")]


def test_a_candidate_far_from_all_of_ours_is_not_fused():
    a, b = exchange(1), exchange(2)
    hold(a, MU, P_B, 11)
    hold(b, MU + [0.0, 0.0, 80.0], P_B, 12)
    before = candidate(b)
    assert send(a, b, "uav0", Edge.TREE) == []
    assert candidate(b) is before and b.metrics()["particles"]["unmatched"] == 1


def test_a_bad_message_raises_and_changes_nothing():
    b = exchange(2)
    hold(b, MU_B, P_B, 12)
    before = candidate(b)
    with pytest.raises(DecodeError) as err:
        b.receive("uav0", 1, 0.0, {"candidates": [{"id": 0, "b": {"f": "set"}}]}, Edge.TREE, 0.0)
    assert err.value.reason == "bad_field" and candidate(b) is before


def test_nothing_is_sent_with_the_exchange_off_or_without_candidates():
    off, empty = exchange(1, share=False), exchange(2)
    hold(off, MU, P_A, 1)
    assert off.outgoing(0.0, ["uav1"]) is None
    assert empty.outgoing(0.0, ["uav1"]) is None


def test_messages_come_once_per_period_and_each_candidate_costs_its_mixture():
    a = exchange(1)
    hold(a, MU_A, P_A, 11, cid=0)
    hold(a, MU_B, P_B, 12, cid=1)
    first = a.outgoing(0.0, ["uav1"])
    assert a.outgoing(0.5, ["uav1"]) is None and a.outgoing(1.0, ["uav1"]) is not None
    assert [e["id"] for e in first.payload["candidates"]] == [0, 1]
    assert all(e["b"]["k"] == a.config.components for e in first.payload["candidates"])


def test_matching_pairs_each_remote_candidate_with_the_overlapping_local_one():
    rng = np.random.default_rng(3)
    local = {7: ParticleSet.from_states(rng.multivariate_normal(MU, P_A, 500)),
             9: ParticleSet.from_states(rng.multivariate_normal(MU + [0, 40, 0], P_A, 500))}
    remote = {1: GaussianMixture(np.ones(1), (MU + [0, 40, 0])[None], P_B[None]),
              2: GaussianMixture(np.ones(1), MU[None], P_B[None]),
              3: GaussianMixture(np.ones(1), (MU + [0, 0, 90])[None], P_B[None])}
    assert match(local, remote, {}) == {1: 9, 2: 7}
    assert match(local, remote, {2: 9}) == {1: 9, 2: 7}  # a stale label outside the gate is dropped


def test_a_ray_crossing_two_peer_candidates_alike_waits_and_a_clear_winner_is_fused():
    """Two look-alike targets: our long ray (north) crosses two of a peer's candidates equally well —
    fusing either would be a coin toss between the target and a ghost."""
    rng = np.random.default_rng(4)
    ray = {0: ParticleSet.from_states(rng.multivariate_normal(MU, np.diag([400.0, 1.0, 1.0]), 2000))}
    twins = {1: GaussianMixture(np.ones(1), (MU + [-10, 0, 0])[None], np.eye(3)[None]),
             2: GaussianMixture(np.ones(1), (MU + [10, 0, 0])[None], np.eye(3)[None])}
    assert match(ray, twins, {}) == {}
    off_ray = {**twins, 2: GaussianMixture(np.ones(1), (MU + [10, 4, 0])[None], np.eye(3)[None])}
    assert match(ray, off_ray, {}) == {1: 0}  # 4 m off our ray: far less likely than the twin on it


def test_the_resolution_clock_keeps_the_first_time_a_target_is_within_the_radius():
    clock = ResolutionClock(2.0)
    targets = [{"id": "a", "position": [0.0, 0.0, 0.0]}, {"id": "b", "position": [10.0, 0.0, 0.0]}]
    clock.record(1.0, targets, [np.array([2.5, 0.0, 0.0])])
    clock.record(2.0, targets, [np.array([1.9, 0.0, 0.0])])
    clock.record(3.0, targets, [])
    assert clock.summary() == {"a": 2.0, "b": None}
    with pytest.raises(ValueError, match="radius"):
        ResolutionClock(0.0)


@pytest.mark.parametrize("key, value", [("exchange", "yes"), ("components", 0), ("components", 2.5),
                                        ("exchange_period", -1.0)])
def test_bad_exchange_settings_name_the_key(key, value):
    with pytest.raises(ValueError, match=key):
        ParticleInitConfig(**{key: value})


def test_a_restarted_peer_is_back_to_the_initial_common_belief():
    """After a's candidate went to b (b's bel_ab is a's mixture), a restarts (agent.net.incarnation): b forgets
    a's candidate labels and a's channel is back to the flat initial belief, so a's new life is not divided by
    what its old life sent."""
    a, b = exchange(1), exchange(2)
    hold(a, MU_A, P_A, 11)
    hold(b, MU_B, P_B, 12)
    send(a, b, "uav0", Edge.TREE)
    (channel,) = b.channels.values()
    assert channel.common("uav0") is not None and b.labels["uav0"]
    b.peer_restarted("uav0")
    assert channel.common("uav0") is channel.initial_common and "uav0" not in b.labels
