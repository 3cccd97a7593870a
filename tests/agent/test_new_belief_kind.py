"""A belief kind the host has never heard of joins by one registry line: a toy exchange (each agent counts
its steps and keeps the largest count a peer reported) is registered, and agents over the in-memory bus
send, receive, dispatch, reject and report it without a change to the host."""

from __future__ import annotations

import uuid

import pytest

from agent import beliefs
from agent.agent import Agent
from agent.config import AgentScenario
from agent.net import wire
from agent.net.bus import InMemoryBus
from agent.net.keys import Keys
from agent.plugins import Outgoing
from fusion.resync import Edge


class CountExchange:
    kind = "count"
    needs_edge = False  # a maximum is the same on any graph

    def __init__(self):
        self.steps, self.largest, self.edges = 0, {}, []

    def sensors(self):
        return []

    def planning_hints(self):
        return {}

    def absorb(self, t, observations):
        self.steps += 1

    def outgoing(self, t, neighbours):
        return Outgoing({"count": self.steps})

    def sent(self, seq, message):
        pass

    def thinned(self, message):
        pass

    def settle(self, t):
        pass

    def receive(self, origin, seq, stamp, payload, edge, t):
        self.edges.append(edge)
        if not isinstance(payload.get("count"), int):
            raise wire.DecodeError("bad_field", "count must be an integer")
        self.largest[origin] = max(payload["count"], self.largest.get(origin, 0))
        return [("count_max", None)]

    def view(self):
        return dict(self.largest)

    def telemetry(self):
        return {}

    def evaluate(self, t, truth):
        pass

    def metrics(self):
        return {"count": {"steps": self.steps, "largest": dict(self.largest)}}


@pytest.fixture
def fleet(monkeypatch):
    monkeypatch.setitem(beliefs.EXCHANGES, "count", lambda ctx: CountExchange())
    scenario = AgentScenario(agents=3, duration=2.0)
    keys = Keys(f"count-{uuid.uuid4().hex[:8]}")
    bus = InMemoryBus()
    subscribe = [f"{keys.root}/belief/**", keys.telemetry("*"), keys.sim("truth")]
    agents = [Agent(f"uav{i}", i, scenario, bus.endpoint(f"uav{i}", subscribe), keys, seed=i) for i in range(3)]
    return agents, bus.endpoint("intruder", []), keys


def test_a_registered_belief_kind_is_exchanged_and_reported(fleet):
    agents, _, _ = fleet
    for k in range(10):
        for agent in agents:
            agent.step(0.2 * k)
    for agent in agents:
        metrics = agent.metrics()
        assert metrics["count"]["steps"] == 10
        peers = {a.id for a in agents} - {agent.id}
        assert set(metrics["count"]["largest"]) == peers
        assert all(n >= 9 for n in metrics["count"]["largest"].values())
        assert metrics["fusions"]["count_max"] >= 18
        assert metrics["bytes_tx_by_kind"]["count"] > 0


@pytest.mark.parametrize("needs_edge", [False, True])
def test_the_topology_is_asked_about_a_link_only_for_a_kind_that_reads_the_answer(fleet, monkeypatch, needs_edge):
    """The bridge test costs a graph rebuild (O(N^2)) whenever the known graph changed: a kind that fuses the same
    way on any graph gets ``edge=None`` and costs the topology nothing."""
    agents, _, _ = fleet
    monkeypatch.setattr(CountExchange, "needs_edge", needs_edge)
    asked = []
    for agent in agents:
        real = agent.topology.edge
        monkeypatch.setattr(agent.topology, "edge", lambda peer, t, real=real: asked.append(peer) or real(peer, t))
    for k in range(5):
        for agent in agents:
            agent.step(0.2 * k)
    edges = [edge for agent in agents for edge in agent.exchanges["count"].edges]
    assert len(edges) >= 8
    if needs_edge:
        assert len(asked) >= len(edges) and all(isinstance(edge, Edge) for edge in edges)
    else:
        assert asked == [] and set(edges) == {None}


def test_a_malformed_message_of_the_new_kind_is_rejected_by_reason(fleet):
    """Bad input: a "count" message whose count is a string."""
    agents, intruder, keys = fleet
    bad = wire.Envelope(kind="count", origin="uav2", seq=1, stamp=0.0, payload={"count": "many"})
    intruder.publish(keys.belief("count", "uav2"), wire.encode(bad, kinds=wire.KINDS | {"count"}))
    agents[0].step(0.0)
    assert agents[0].metrics()["rejected_by_reason"] == {"bad_field": 1}
    assert agents[0].exchanges["count"].largest == {}
