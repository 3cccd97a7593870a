"""A restarted agent (agent.net.incarnation): its numbers are all newer than its old life's, its peers tell the
restart from the first message of the new incarnation and start their channels to it afresh, and its flooded
detections are applied, not dropped as already held."""

from __future__ import annotations

import uuid
from dataclasses import replace

import numpy as np
import pytest

from agent.agent import Agent
from agent.beliefs.tracking import Track
from agent.config import AgentScenario
from agent.net import wire
from agent.net.bus import InMemoryBus
from agent.net.flood_relay import FloodRelay
from agent.net.gaussian_codec import encode_trajectory
from agent.net.incarnation import MAX_INCARNATION, REPLAY_WINDOW_S, ReceiveWindow, first_number, incarnation_of
from agent.net.keys import Keys
from fusion.trajectory import Trajectory


def test_numbers_of_a_new_life_are_newer_than_every_number_of_the_old_one():
    assert first_number(0) == 0 and incarnation_of(first_number(0) + 12345) == 0
    assert first_number(1) > first_number(0) + 10**9  # 800 years of 5 Hz messages fit in one life
    assert incarnation_of(first_number(7) + 3) == 7
    assert first_number(MAX_INCARNATION) + (1 << 32) - 1 < 2**64  # still an envelope seq


@pytest.mark.parametrize("bad", [-1, MAX_INCARNATION + 1, 1.0, True, "2"])
def test_a_bad_incarnation_is_refused(bad):
    """Bad input: an incarnation that is not an integer in range."""
    with pytest.raises(ValueError, match="incarnation"):
        first_number(bad)


def test_the_window_tells_duplicates_restarts_and_replays_of_an_old_life():
    window = ReceiveWindow()
    assert window.admit("uav1", "track", 5, 0.0) is None  # the first life heard: no restart
    window.used("uav1", "track", 5)
    assert window.admit("uav1", "track", 5, 0.2) == "duplicate"
    assert window.admit("uav1", "track", first_number(1) + 1, 9.0) == "restarted"
    window.used("uav1", "track", first_number(1) + 1)
    assert window.admit("uav1", "grid", first_number(1) + 2, 9.2) is None  # the restart is told once
    assert window.admit("uav1", "track", 6, 9.4) == "duplicate"  # a replay of the old life
    assert window.metrics() == {"peer_restarts": [["uav1", 1, 9.0]]}


def test_a_receiver_that_restarted_refuses_a_replay_by_its_stamp():
    """The audit's case: a restarted receiver has forgotten every number, so a recorded 19-s-old message of a peer
    (validly signed) is refused by its stamp alone; a message delayed within the window is not."""
    fresh = ReceiveWindow()  # the receiver's new life: no numbers remembered
    assert fresh.admit("uav1", "track", 5, 20.0, stamp=1.0) == "stale"
    assert fresh.admit("uav1", "track", 5, 20.0, stamp=20.0 - REPLAY_WINDOW_S) is None
    assert fresh.admit("uav1", "track", 5, 20.0, stamp=19.6) is None


def test_an_agent_refuses_a_signed_replay_older_than_the_window():
    """Bad input: uav1's genuine, signed topology report recorded at t = 1 s and replayed to an agent whose clock
    reads 20 s (it restarted and remembers nothing): rejected as ``stale``, its content unused."""
    keys, key = Keys(f"inc-{uuid.uuid4().hex[:8]}"), b"k" * 32
    bus = InMemoryBus()
    uav0 = Agent("uav0", 0, AgentScenario(agents=2), bus.endpoint("uav0", keys.agent_subscriptions()), keys,
                 seed=0, fleet_key=key)
    report = wire.Envelope(kind="topology", origin="uav1", seq=3, stamp=1.0,
                           payload={"reports": {"uav1": [1.0, ["uav0"]]}})
    bus.endpoint("uav1", []).publish(keys.topology("uav1"), wire.encode(report, key))
    uav0.step(20.0)
    assert uav0.rejected["stale"] == 1 and uav0.topology.neighbours(20.0) == []


def test_a_rejected_restart_message_does_not_move_the_window():
    """Bad input: a message of the new life whose payload is then refused: the window keeps its place."""
    window = ReceiveWindow()
    assert window.admit("uav1", "track", 5, 0.0) is None
    window.used("uav1", "track", 5)
    assert window.admit("uav1", "track", first_number(1) + 1, 1.0) == "restarted"
    assert window.admit("uav1", "track", first_number(1) + 1, 1.2) is None  # not used: may come again


def test_flooded_increments_of_a_new_life_are_applied():
    """A relay that holds increments 0..9 of uav1's first life accepts the new life's first increment (the old
    numbering would have made it increment 0, held already)."""
    relay = FloodRelay("uav0", ack_timeout=1.0, horizon=10.0)
    for n in range(10):
        assert relay.accept("uav1", 1.0, "uav1", n, 1.0, b"")
    assert not relay.accept("uav1", 2.0, "uav1", 0, 2.0, b"")
    restarted = FloodRelay("uav1", ack_timeout=1.0, horizon=10.0, first=first_number(1))
    inc = restarted.originate(3.0, b"")
    assert inc.n == first_number(1) and relay.accept("uav1", 3.0, "uav1", inc.n, 3.0, b"")


def test_a_peer_that_restarts_gets_fresh_channels_and_its_new_life_is_heard():
    """uav0 (hybrid channel filters) fuses uav1's track, then uav1 comes back as incarnation 1 and sends its
    track 1 again (a new track of its new life). uav0 notices the restart at once, drops the old label and resets
    the channel to uav1 to the common prior before fusing; nothing of the new life is refused as a duplicate."""
    keys = Keys(f"inc-{uuid.uuid4().hex[:8]}")
    bus = InMemoryBus()
    scenario = AgentScenario(agents=2, tracking=replace(AgentScenario().tracking, policy="hybrid"))
    uav0 = Agent("uav0", 0, scenario, bus.endpoint("uav0", keys.agent_subscriptions()), keys, seed=0)
    sender = bus.endpoint("uav1", [])
    model = uav0.exchanges["track"].tracker.model
    belief = Trajectory.prior(model, 0).update(np.hstack([np.eye(3), np.zeros((3, 3))]), np.eye(3), np.zeros(3))
    entry = {"id": 1, "belief": encode_trajectory(belief), "last_measured": 0.0, "acks": {}}
    resets = []

    def send(seq: int, t: float) -> None:
        env = wire.Envelope(kind="track", origin="uav1", seq=seq, stamp=t, payload={"tracks": [entry]})
        sender.publish(keys.belief("track", "uav1"), wire.encode(env))
        uav0.step(t)

    report = wire.Envelope(kind="topology", origin="uav1", seq=1, stamp=0.0,
                           payload={"reports": {"uav1": [0.0, ["uav0"]]}})  # the link is a bridge: fused on arrival
    sender.publish(keys.topology("uav1"), wire.encode(report))
    send(40, 0.0)
    tracker = uav0.exchanges["track"].tracker
    assert ("uav1", 1) in tracker.labels  # the setting: uav1's track 1 fused
    for track in tracker.tracks.values():
        original = track.channels.reset
        track.channels.reset = lambda peer, original=original: (resets.append(peer), original(peer))[1]
    send(first_number(1) + 1, 0.2)
    assert uav0.window.metrics()["peer_restarts"] == [["uav1", 1, 0.2]]
    assert resets == ["uav1"] * len(tracker.tracks)
    assert ("uav1", 1) in tracker.labels and uav0.rejected.get("duplicate", 0) == 0
    send(39, 0.4)  # a replay of the old life
    assert uav0.rejected["duplicate"] == 1


def test_a_restart_under_flood_changes_nothing_but_the_labels():
    """Flood (the default policy) keeps no channel filters (a track's ``channels`` is None): a restarted peer only
    loses its track labels, and the tracks stay as they were (a live restart crashed here before)."""
    keys = Keys(f"inc-{uuid.uuid4().hex[:8]}")
    scenario = AgentScenario(agents=2, tracking=replace(AgentScenario().tracking, policy="flood"))
    uav0 = Agent("uav0", 0, scenario, InMemoryBus().endpoint("uav0", []), keys, seed=0)
    tracker = uav0.exchanges["track"].tracker
    tracker.tracks[7] = Track(7, Trajectory.prior(tracker.model, 0), None, 0)
    tracker.labels[("uav1", 3)] = 7
    tracker.labels[("uav2", 3)] = 7
    uav0.exchanges["track"].peer_restarted("uav1")
    assert tracker.labels == {("uav2", 3): 7} and list(tracker.tracks) == [7]
