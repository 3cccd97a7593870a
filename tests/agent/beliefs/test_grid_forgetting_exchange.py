"""Forgetting grids over the real exchange (absorb with stamps, codec messages, channel filters) against the
simulator's centralized map (mesh_sim.grid_oracle), which forgets on the same clock: equal on a tree,
never more confident on a loop under the hybrid rule, overconfident there under naive fusion."""

from __future__ import annotations

import types

import numpy as np
import pytest

from agent.beliefs.grid_config import GridConfig
from agent.beliefs.grids import GridExchange
from agent.net import wire
from mesh_sim.grid_oracle import GridOracle
from perception.terrain import FlatTerrain

AREA = (-50.0, 50.0, -50.0, 50.0)
STEP = 0.5  # s between frames; grid messages every period = 2 s


class Simulator:
    """The outbox of every node: frame evidence goes to the centralized map as the world would deliver it."""

    def __init__(self, oracle: GridOracle, name: str):
        self.oracle, self.name, self.seq = oracle, name, 0

    def to_simulator(self, kind: str, t: float, payload: dict) -> None:
        self.seq += 1
        self.oracle.add_evidence(wire.Envelope(kind=kind, origin=self.name, seq=self.seq, stamp=t, payload=payload))


def _run(config: GridConfig, edges, tree: bool, seconds=30.0, positive=False, seed=0, observe_until=20.0):
    """Every node observes every frame (30 random cells until ``observe_until``, none after), and broadcasts
    every period until ``seconds``."""
    rng = np.random.default_rng(seed)
    oracle = GridOracle(config, AREA, FlatTerrain(), truth=lambda t: ([], []))  # no fire to score: maps only
    names = sorted({n for e in edges for n in e})
    nodes = {n: GridExchange(n, config, AREA, FlatTerrain(), 1, Simulator(oracle, n)) for n in names}
    neighbours = {n: sorted({b for a, b in edges if a == n} | {a for a, b in edges if b == n}) for n in names}
    seqs = dict.fromkeys(names, 0)
    size = oracle.geometry.size
    for k in range(int(seconds / STEP) + 1):
        t = k * STEP
        seen = 30 if t <= observe_until else 0
        for node in nodes.values():
            index = rng.choice(size, size=seen, replace=False)
            llr = rng.uniform(0.1, 1.0, seen) if positive else rng.normal(0.0, 1.0, seen)
            evidence = types.SimpleNamespace(index=index, llr=llr, m=np.abs(llr), n=np.abs(llr[::-1]))
            node.absorb(t, {"fire_evidence": evidence})
        sent = {}
        for name, node in nodes.items():
            message = node.outgoing(t, neighbours[name])
            if message is not None:
                seqs[name] += 1
                node.sent(seqs[name], message)
                sent[name] = message.payload
        for name, payload in sent.items():
            for peer in neighbours[name]:
                nodes[peer].receive(name, seqs[name], t, payload, tree, t)
    return nodes, oracle


@pytest.mark.parametrize("belief", ["logodds", "beta"])
def test_on_a_tree_every_forgetting_map_equals_the_forgetting_centralized_map(belief):
    config = GridConfig(belief=belief, cell=10.0, half_life=6.0)
    nodes, oracle = _run(config, [("a", "b"), ("b", "c"), ("b", "d")], tree=True)
    static, _ = _run(GridConfig(belief=belief, cell=10.0), [("a", "b"), ("b", "c"), ("b", "d")], tree=True)
    for name, node in nodes.items():
        assert node.fusions == {"exact": node.fusions["exact"]}
        assert node.grid.epoch == oracle.central.epoch == 30
        layers = config.layers(oracle.geometry)
        diff = layers.to_layers(node.grid) - layers.to_layers(oracle.central)
        assert np.max(np.abs(diff)) < 1e-4  # float32 on the wire; the algebra itself is exact
        assert not np.allclose(node.grid.probability(), static[name].grid.probability(), atol=1e-3)


def test_on_a_loop_hybrid_forgetting_maps_are_conservative_and_naive_ones_are_not():
    edges = [("a", "b"), ("b", "c"), ("c", "a")]
    excess = {}
    for policy in ("hybrid", "naive"):
        config = GridConfig(policy=policy, cell=10.0, half_life=6.0)
        nodes, oracle = _run(config, edges, tree=False, positive=True, seed=5)
        excess[policy] = max(float(np.max(n.grid.evidence - oracle.central.evidence)) for n in nodes.values())
    assert excess["hybrid"] <= 1e-4
    assert excess["naive"] > 1.0


@pytest.mark.parametrize("bad", [{"half_life": -1.0}, {"half_life": "30"}, {"half_life": float("inf")},
                                 {"half_life": True}])
def test_bad_half_lives_are_clear_errors(bad):
    with pytest.raises(ValueError, match="grid.half_life"):
        GridConfig.from_dict(bad)


def test_a_grid_from_a_peer_whose_clock_is_ahead_moves_ours_on_and_what_we_send_is_read_at_that_tick():
    config = GridConfig(cell=10.0, half_life=6.0)
    oracle = GridOracle(config, AREA, FlatTerrain(), truth=lambda t: ([], []))  # no fire to score: maps only
    ahead, behind = (GridExchange(n, config, AREA, FlatTerrain(), 1, Simulator(oracle, n)) for n in ("a", "b"))
    nothing = types.SimpleNamespace(index=np.zeros(0, int), llr=np.zeros(0), m=np.zeros(0), n=np.zeros(0))
    ahead.absorb(9.0, {"fire_evidence": types.SimpleNamespace(index=np.array([3]), llr=np.array([2.0]),
                                                               m=np.array([2.0]), n=np.array([0.0]))})
    message = ahead.outgoing(9.0, ["b"])
    ahead.sent(1, message)
    behind.absorb(5.0, {"fire_evidence": nothing})
    behind.receive("a", 1, 9.0, message.payload, True, 5.0)
    assert behind.grid.epoch == behind.beliefs.epoch == 9
    assert behind.beliefs.from_layers(behind.beliefs.to_layers(behind.grid)).epoch == 9
    behind.absorb(6.0, {"fire_evidence": nothing})  # its own clock catches up: nothing goes back
    assert behind.grid.epoch == 9 and behind.grid.evidence.ravel()[3] == pytest.approx(2.0, abs=1e-6)
