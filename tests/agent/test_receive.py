"""The agent's receive path: a message is de-duplicated by (origin, kind, seq), and only a message that was
used moves that window — a rejected payload with a large sequence number cannot silence its sender
(reliability audit: "the sequence number is recorded before the payload is checked")."""

from __future__ import annotations

import uuid

import numpy as np
import pytest

from agent.agent import Agent
from agent.config import AgentScenario
from agent.net import wire
from agent.net.bus import InMemoryBus
from agent.net.gaussian_codec import encode_trajectory
from agent.net.keys import Keys
from fusion.trajectory import Trajectory


def setup():
    keys = Keys(f"rx-{uuid.uuid4().hex[:8]}")
    bus = InMemoryBus()
    subscribe = [f"{keys.root}/belief/**", keys.topology("*"), keys.telemetry("*"), keys.sim("truth")]
    agent = Agent("uav0", 0, AgentScenario(agents=2), bus.endpoint("uav0", subscribe), keys, seed=0)
    return agent, bus.endpoint("sender", []), keys


def introduce(endpoint, keys: Keys, t: float = 0.0) -> None:
    """uav1's topology report, as a real peer sends it: it hears uav0 only, so the link is a bridge and a hybrid
    track from uav1 is fused on arrival (an unknown link's message waits: agent.beliefs.tracks.EDGE_WAIT_S)."""
    send(endpoint, keys.topology("uav1"), "topology", "uav1", 1, {"reports": {"uav1": [t, ["uav0"]]}}, stamp=t)


def send(endpoint, key: str, kind: str, origin: str, seq: int, payload: dict, stamp: float = 0.0) -> None:
    endpoint.publish(key, wire.encode(wire.Envelope(kind=kind, origin=origin, seq=seq, stamp=stamp, payload=payload)))


def test_a_rejected_track_message_does_not_move_the_sequence_window():
    """Bad input: track payloads that are not lists, the first with sequence number 10**9."""
    agent, sender, keys = setup()
    send(sender, keys.belief("track", "uav1"), "track", "uav1", 10**9, {"tracks": "not a list"})
    send(sender, keys.belief("track", "uav1"), "track", "uav1", 5, {"tracks": 7})
    agent.step(0.0)
    assert agent.rejected == {"bad_type": 2}  # the 2nd is judged on its payload, not as a "duplicate"
    send(sender, keys.belief("track", "uav1"), "track", "uav1", 6, {"tracks": []})
    send(sender, keys.belief("track", "uav1"), "track", "uav1", 6, {"tracks": []})
    agent.step(0.2)
    assert agent.rejected == {"bad_type": 2, "duplicate": 1}  # a used message does move it


def test_a_rejected_truth_does_not_hide_the_next_one():
    """Bad input: a truth message whose fire state is not zlib data, with a huge sequence number."""
    agent, sender, keys = setup()
    bad_fire = {"origin": [0.0, 0.0], "cell": 5.0, "shape": [2, 2], "state": b"not zlib"}
    send(sender, keys.sim("truth"), "truth", "world", 10**9, {"fire": bad_fire})
    target = {"id": "car", "position": [1.0, 2.0, 0.0], "velocity": [0.0, 0.0, 0.0]}
    send(sender, keys.sim("truth"), "truth", "world", 3, {"targets": [target]})
    agent.step(0.0)
    assert agent.rejected == {"bad_fire": 1}
    assert [t["id"] for t in agent.world.targets_at(0.0)] == ["car"]


def test_a_track_whose_newest_state_is_not_observable_is_rejected_and_the_agent_goes_on():
    """Bad input (reliability audit: 763 of 763 crashed the agent): a track belief with an all-zero
    information matrix, and one scaled down to 1e-300 of a valid prior."""
    agent, sender, keys = setup()
    model = agent.exchanges["track"].tracker.model
    n = model.window * model.state_dim
    prior = Trajectory.prior(model, 0)
    for seq, belief in enumerate([Trajectory(np.zeros(n), np.zeros((n, n)), 0, model),
                                  Trajectory(prior.y * 1e-300, prior.Y * 1e-300, 0, model)], start=1):
        entry = {"id": 1, "belief": encode_trajectory(belief), "last_measured": 0.0, "acks": {}}
        send(sender, keys.belief("track", "uav1"), "track", "uav1", seq, {"tracks": [entry]})
        agent.step(0.2 * seq)
    assert agent.rejected == {"uninformative": 2}
    assert agent.exchanges["track"].tracker.tracks == {}
    assert agent.steps == 2


def test_a_track_from_far_in_the_past_or_future_is_rejected_without_stalling_the_agent():
    """Bad input (reliability audit: a track stamped far in the past stalled the agent for seconds): track
    beliefs at epoch 0 sent to an agent at epoch 10**5, and at epoch 10**5 + 51."""
    agent, sender, keys = setup()
    tracker = agent.exchanges["track"].tracker
    agent.step(0.0)
    tracker.epoch = 10**5
    for seq, epoch in enumerate([0, 10**5 + 51], start=1):
        belief = Trajectory.prior(tracker.model, epoch)
        belief = belief.update(np.hstack([np.eye(3), np.zeros((3, 3))]), np.eye(3), np.zeros(3))
        entry = {"id": 1, "belief": encode_trajectory(belief), "last_measured": 0.0, "acks": {}}
        send(sender, keys.belief("track", "uav1"), "track", "uav1", seq, {"tracks": [entry]},
             stamp=10**5 * tracker.model.step)  # a fresh envelope: its payload's epochs are the fault
    agent.step(10**5 * tracker.model.step)
    assert agent.rejected == {"past_epoch": 1, "future_epoch": 1}
    assert tracker.tracks == {}


def test_bad_resync_or_fresh_fields_are_rejected_and_change_nothing():
    """The re-sync flags ({peer: seq}) and freshness of a track entry (fusion.resync) are checked before any
    track is touched (by the wire's schema: a wrong type; by the exchange: a value out of range); the same
    entry with valid ones is fused."""
    agent, sender, keys = setup()
    model = agent.exchanges["track"].tracker.model
    n = model.window * model.state_dim
    prior = Trajectory.prior(model, 0)
    belief = encode_trajectory(Trajectory(prior.y, prior.Y + np.eye(n), 0, model))
    bad = [{"resync": {"uav0": -1}}, {"resync": {"uav0": "3"}}, {"resync": {"uav0": True}}, {"resync": [3]},
           {"fresh": 3}, {"fresh": True}, {"fresh": "2"}]
    for seq, extra in enumerate(bad, start=1):
        send(sender, keys.belief("track", "uav1"), "track", "uav1", seq,
             {"tracks": [{"id": 1, "belief": belief, "last_measured": 0.0, "acks": {}, **extra}]})
        agent.step(0.2 * seq)
        assert agent.rejected.total() == seq and set(agent.rejected) <= {"bad_field", "bad_type"}, extra
        assert agent.exchanges["track"].tracker.tracks == {}, extra
    seq = len(bad) + 1
    introduce(sender, keys, 0.2 * seq)
    send(sender, keys.belief("track", "uav1"), "track", "uav1", seq, {"tracks": [
        {"id": 1, "belief": belief, "last_measured": 0.0, "acks": {}, "resync": {"uav0": 0}, "fresh": 2}]})
    agent.step(0.2 * seq)
    assert len(agent.exchanges["track"].tracker.tracks) == 1


def test_a_message_from_an_origin_outside_the_fleet_is_rejected_before_any_state_is_kept():
    """Bad input (skymesh bench fuzz: the receive path slowed from ~800 to ~230 inputs/s over 6,000 inputs as
    senders under ever new names accumulated): valid track messages from ``uav2`` .. ``uav9`` (a fleet of two:
    ``uav0``, ``uav1``) and from a name that is no agent's. Each is counted as ``unknown_origin``; no track,
    receive window, topology entry or byte count is kept for them. The same message from ``uav1`` is used."""
    agent, sender, keys = setup()
    model = agent.exchanges["track"].tracker.model
    n = model.window * model.state_dim
    prior = Trajectory.prior(model, 0)
    entry = {"id": 1, "belief": encode_trajectory(Trajectory(prior.y, prior.Y + np.eye(n), 0, model)),
             "last_measured": 0.0, "acks": {}}
    strangers = [f"uav{i}" for i in range(2, 10)] + ["intruder"]
    for origin in strangers:
        send(sender, keys.belief("track", origin), "track", origin, 1, {"tracks": [entry]})
    agent.step(0.0)
    assert agent.rejected == {"unknown_origin": len(strangers)}
    assert agent.exchanges["track"].tracker.tracks == {} and agent.exchanges["track"].tracker.labels == {}
    assert agent.window.metrics() == {"peer_restarts": []} and not agent.window._last
    assert agent.topology.neighbours(0.0) == [] and not agent.bytes_rx
    introduce(sender, keys, 0.2)
    send(sender, keys.belief("track", "uav1"), "track", "uav1", 1, {"tracks": [entry]})
    agent.step(0.2)
    assert len(agent.exchanges["track"].tracker.tracks) == 1 and agent.rejected.total() == len(strangers)


def test_an_agent_named_outside_its_fleet_is_refused():
    """The fleet is ``uav0`` .. ``uav{agents-1}`` (agent.config.AgentScenario.fleet): an agent under another name
    would have every message it sends rejected by its peers, so it is refused at construction."""
    keys = Keys(f"rx-{uuid.uuid4().hex[:8]}")
    with pytest.raises(ValueError, match="fleet"):
        Agent("uav2", 2, AgentScenario(agents=2), InMemoryBus().endpoint("uav2", []), keys, seed=0)


def test_a_message_of_many_new_tracks_costs_the_gate_once_per_track_not_once_per_pair(monkeypatch):
    """Bad input (skymesh bench fuzz: the receive path slowed as tracks accumulated): a message adopting 64
    tracks 50 m apart. Matching each to the local tracks and merging duplicates tested the track-to-track gate
    pair by pair, one 3x3 solve each (~4,000 solves, ~0.25 s: a hang); the gate distances from one track to all
    others are now one batched solve, so the solves grow with the tracks, not with their pairs."""
    agent, sender, keys = setup()
    model = agent.exchanges["track"].tracker.model
    prior = Trajectory.prior(model, 0)
    seen = np.hstack([np.eye(3), np.zeros((3, model.state_dim - 3))])
    entries = [{"id": i, "belief": encode_trajectory(prior.update(seen, np.eye(3), np.array([50.0 * i, 0.0, 0.0]))),
                "last_measured": 0.0, "acks": {}} for i in range(64)]
    introduce(sender, keys)
    send(sender, keys.belief("track", "uav1"), "track", "uav1", 1, {"tracks": entries})
    solves, solve = [], np.linalg.solve
    monkeypatch.setattr(np.linalg, "solve", lambda *args: solves.append(1) or solve(*args))
    agent.step(0.0)
    assert len(agent.exchanges["track"].tracker.tracks) == 64 and not agent.rejected
    assert len(solves) <= 3 * 64


def test_a_member_naming_an_agent_outside_the_fleet_is_rejected_and_its_report_is_not_kept():
    """Bad input: uav1's topology report (a fleet of two) naming ``uav9`` as its neighbour, then a report from
    ``uav1`` about ``ghost``. Each is ``unknown_name`` (agent.net.roster), the topology graph keeps no node of
    theirs and the receive window does not move; uav1's next, valid report is used."""
    agent, sender, keys = setup()
    send(sender, keys.topology("uav1"), "topology", "uav1", 1, {"reports": {"uav1": [0.0, ["uav0", "uav9"]]}})
    send(sender, keys.topology("uav1"), "topology", "uav1", 2, {"reports": {"ghost": [0.0, ["uav1"]]}})
    agent.step(0.0)
    assert agent.rejected == {"unknown_name": 2}
    assert agent.topology.neighbours_of("uav1", 0.0) == frozenset() and not agent.window._last
    introduce(sender, keys, 0.2)
    agent.step(0.2)
    assert agent.topology.neighbours_of("uav1", 0.2) == {"uav0"} and agent.rejected.total() == 2
