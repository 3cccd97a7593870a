"""The agent's fire map over the exchange protocol: exact on a tree, conservative on loops, safe on bad input.

The mappers exchange real grid messages (codec payloads, acknowledgements, channel filters); only the
camera is bypassed: each node's local evidence is random per-cell log-likelihood ratios, and the
centralized map is their plain sum (Merino (4.4)).
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from agent.beliefs.grid_config import GridConfig
from agent.beliefs.grids import PEER_FRESH, GridExchange
from agent.net import wire
from perception.terrain import FlatTerrain

AREA = (-50.0, 50.0, -50.0, 50.0)


class Node:
    def __init__(self, name: str, config: GridConfig):
        self.name = name
        self.mapper = GridExchange(name, config, AREA, FlatTerrain(), seed=1, outbox=None)
        self.seq = 0

    def observe(self, rng, central, positive: bool = False):
        """Local evidence in a patch of cells; adds it to the centralized map too."""
        index = rng.choice(self.mapper.geometry.size, size=40, replace=False)
        llr = rng.uniform(0.1, 1.0, size=40) if positive else rng.normal(0.0, 1.0, size=40)
        if self.mapper.config.belief == "logodds":
            self.mapper.grid = self.mapper.grid.update_cells(index, llr)
            return central.update_cells(index, llr)
        m, n = np.abs(llr), np.abs(llr[::-1])
        self.mapper.grid = self.mapper.grid.update_cells(index, m, n)
        return central.update_cells(index, m, n)

    def send(self, neighbours: list[str]) -> tuple[int, dict]:
        message = self.mapper.outgoing(self.seq * self.mapper.config.period, neighbours)  # a broadcast is due
        self.seq += 1
        self.mapper.sent(self.seq, message)
        return self.seq, message.payload


def _exchange(nodes: dict, edges, rounds: int, rng, central, tree: bool, positive=False, observe_rounds=None):
    neighbours = {n: sorted({b for a, b in edges if a == n} | {a for a, b in edges if b == n}) for n in nodes}
    observe_rounds = rounds if observe_rounds is None else observe_rounds
    for r in range(rounds):
        if r < observe_rounds:
            for node in nodes.values():
                central = node.observe(rng, central, positive)
        for name, node in nodes.items():
            seq, payload = node.send(neighbours[name])
            for peer in neighbours[name]:
                nodes[peer].mapper.receive(name, seq, 0.0, payload, tree, 0.0)
    return central


@pytest.mark.parametrize("belief", ["logodds", "beta"])
def test_on_a_tree_every_map_equals_the_centralized_map(belief):
    rng = np.random.default_rng(2)
    config = GridConfig(belief=belief, policy="hybrid", cell=10.0)
    nodes = {n: Node(n, config) for n in "abcd"}
    central = nodes["a"].mapper.beliefs.uniform()
    edges = [("a", "b"), ("b", "c"), ("b", "d")]
    central = _exchange(nodes, edges, 12, rng, central, tree=True, observe_rounds=8)
    for node in nodes.values():
        assert node.mapper.fusions == {"exact": node.mapper.fusions["exact"]}
        diff = node.mapper.beliefs.to_layers(node.mapper.grid) - node.mapper.beliefs.to_layers(central)
        assert np.max(np.abs(diff)) < 1e-5  # float32 on the wire; the algebra itself is exact


def test_on_a_loop_the_chernoff_rule_never_exceeds_the_centralized_confidence_while_naive_does():
    edges = [("a", "b"), ("b", "c"), ("c", "a")]
    peaks = {}
    for policy in ("hybrid", "naive"):
        rng = np.random.default_rng(5)
        config = GridConfig(policy=policy, cell=10.0)
        nodes = {n: Node(n, config) for n in "abc"}
        central = _exchange(nodes, edges, 10, rng, nodes["a"].mapper.beliefs.uniform(), tree=False, positive=True)
        excess = max(np.max(node.mapper.grid.evidence - central.evidence) for node in nodes.values())
        peaks[policy] = excess
    assert peaks["hybrid"] <= 1e-5
    assert peaks["naive"] > 1.0  # rumours: the same evidence counted again and again


def _message(belief="logodds", **changes):
    node = Node("a", GridConfig(belief=belief, cell=10.0))
    node.observe(np.random.default_rng(0), node.mapper.beliefs.uniform())
    seq, payload = node.send([])
    return seq, {**payload, **changes}


@pytest.mark.parametrize("bad, reason", [
    ({"belief": "beta"}, "grid_geometry"),  # a Beta grid sent to a log-odds agent
    ({"geometry": {"origin": [0.0, 0.0], "cell": 7.0, "shape": [3, 3], "height": 0.0}}, "grid_geometry"),
    ({"geometry": "not a geometry"}, "grid_geometry"),
    ({"acks": {"b": -1}}, "bad_field"),  # a negative acknowledgement
    ({"grid": {"mode": "key", "layers": b"\x00\x01"}}, None),  # garbage codec payload
    ({"position": [float("nan"), 1.0]}, "bad_field"),  # the sender's position with a NaN
    ({"position": [1.0, 2.0, 3.0]}, "bad_field"),  # three coordinates
    ({"position": ["north", "east"]}, "bad_field"),  # words, not numbers
    ({"position": [True, 1.0]}, "bad_field"),  # a bool, not a number
    ({"position": 7.0}, "bad_field"),  # a number, not a pair
])
def test_bad_grid_messages_are_rejected_and_change_nothing(bad, reason):
    _rejected(bad, reason)


@pytest.mark.parametrize("belief", [np.array([1.0, np.nan]), ["logodds"], None])
def test_a_belief_type_that_is_no_string_is_rejected(belief):
    """Bad input (skymesh bench fuzz: an array crashed the agent, ValueError from ``array != str``)."""
    seq, payload = _message()
    _rejected({**payload, "belief": belief}, "grid_geometry", seq)


def _rejected(bad: dict, reason: str | None, seq: int | None = None):
    """``bad`` (changes to a valid message, or with ``seq`` a whole payload) is rejected and changes nothing."""
    receiver = Node("b", GridConfig(cell=10.0))
    before = receiver.mapper.grid.evidence.copy()
    seq, payload = _message(**bad) if seq is None else (seq, bad)
    with pytest.raises(wire.DecodeError) as err:
        receiver.mapper.receive("a", seq, 0.0, payload, True, 0.0)
    if reason is not None:
        assert err.value.reason == reason
    assert err.value.reason in wire.REASONS
    np.testing.assert_array_equal(receiver.mapper.grid.evidence, before)
    assert not receiver.mapper.fusions and not receiver.mapper.peers


def test_a_grid_message_tells_where_its_sender_is_and_a_silent_peer_drops_out_of_the_view():
    """The watch assignment (tasking/alarm_watch.py) needs the peers' positions: each grid message carries its
    sender's (north, east); the receiver's view holds it until PEER_FRESH grid periods pass without a message."""
    sender, receiver = Node("a", GridConfig(cell=10.0)), Node("b", GridConfig(cell=10.0))
    sender.mapper.vehicle = SimpleNamespace(state=lambda: SimpleNamespace(position=np.array([12.0, -7.0, -60.0])))
    seq, payload = sender.send(["b"])
    assert payload["position"] == [12.0, -7.0]
    receiver.mapper.receive("a", seq, 0.0, payload, True, 1.0)
    receiver.mapper.now = 1.0
    np.testing.assert_array_equal(receiver.mapper.view().peers["a"], [12.0, -7.0])
    receiver.mapper.now = 1.0 + PEER_FRESH * receiver.mapper.config.period + 0.1
    assert receiver.mapper.view().peers == {}
    assert "position" not in receiver.send([])[1]  # no vehicle (a bare exchange): nothing to tell


def test_negative_beta_counts_on_the_wire_are_rejected():
    """A Beta grid whose keyframe carries a negative count."""
    from agent.net.grid_codec import encode_grid

    receiver = Node("b", GridConfig(belief="beta", cell=10.0))
    seq, payload = _message(belief="beta")
    layers = np.zeros((2, *receiver.mapper.geometry.shape))
    layers[0, 0, 0] = -3.0
    payload["grid"] = encode_grid(layers, None, None)
    with pytest.raises(wire.DecodeError) as err:
        receiver.mapper.receive("a", seq, 0.0, payload, True, 0.0)
    assert err.value.reason == "grid_bad_values"


def test_the_explorer_plans_on_a_predicted_spread_but_the_shared_map_stays_static():
    """An explored map (p = 0.01) with one fire cell and one unexplored cell (p = 0.5)."""
    node = Node("a", GridConfig(cell=10.0, plan_spread=0.2, plan_steps=3))
    shape = node.mapper.geometry.shape
    llr = np.full(shape, np.log(0.01 / 0.99))
    llr[5, 5], llr[1, 1] = 8.0, 0.0  # the fire, and a cell nobody has seen
    node.mapper.grid = node.mapper.grid.update(llr)
    before = node.mapper.grid.evidence.copy()
    planned, shared = node.mapper.planning_probability(), node.mapper.probability()
    assert planned[5, 6] > shared[5, 6] + 0.3  # a neighbour of the fire may be burning by now
    assert planned[5, 1] == pytest.approx(shared[5, 1], abs=1e-12)  # far from the fire: no change
    assert planned[1, 1] == pytest.approx(0.5) and planned[1, 2] == pytest.approx(0.01)  # unexplored is no fire
    np.testing.assert_array_equal(node.mapper.grid.evidence, before)
    off = Node("b", GridConfig(cell=10.0))
    np.testing.assert_array_equal(off.mapper.planning_probability(), off.mapper.probability())


@pytest.mark.parametrize("bad", [{"belief": "gaussian"}, {"policy": "bogus"}, {"cell": -1.0}, {"alarm_threshold": 1.5},
                                 {"keyframe_every": 0}, {"intersect": "min"}, {"colour": "red"}, {"pd": 0.01},
                                 {"plan_spread": 1.5}, {"plan_steps": 0}, {"handoff": "yes"}, {"handoff": 1}])
def test_bad_grid_settings_are_clear_errors(bad):
    with pytest.raises(ValueError):
        GridConfig.from_dict(bad)


def test_a_hand_off_without_a_tracker_is_a_clear_error():
    """``[grid] handoff`` locates alarms with the agent's tracker: an exchange built without one cannot."""
    with pytest.raises(ValueError, match="handoff needs the agent's tracker"):
        GridExchange("uav0", GridConfig(handoff=True), AREA, FlatTerrain(), seed=1, outbox=None)
