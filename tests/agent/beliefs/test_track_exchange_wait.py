"""A hybrid track message over a link whose place in the graph is not known yet waits for that knowledge
(agent/beliefs/tracks.py, ``EDGE_WAIT_S``) instead of being intersected at once.

Two real track exchanges of the ``partition`` scenario (hybrid): uav0 confirms a parked car from clean
bearings and sends its tracks; uav1 hears uav0 before uav0's topology report has arrived — what every merge
of a partition looks like (measured on the 4-agent line: 0.2-0.6 s of incomplete knowledge at each end of
the healed link, where every channel used to fall back to intersection and then re-synchronise).
"""

from __future__ import annotations

from collections import Counter

import numpy as np

from agent.beliefs import EXCHANGES, ExchangeContext
from agent.beliefs.tracks import EDGE_WAIT_S
from agent.fusion_log import FusionLog
from agent.net.sending import SendScheduler
from agent.net.topology import Topology
from agent.sensors.bearing import BearingSensorConfig, GeometricBearingSensor
from fusion.resync import Edge
from mesh_sim.scenario import load
from perception.terrain import FlatTerrain

CAR = [{"id": "car", "position": np.array([10.0, -5.0, 0.0])}]
CAMERA = np.array([0.0, 0.0, -80.0])


class NoSimulator:
    """The host's channel to the simulator's oracles: not part of what is tested here."""

    def to_simulator(self, kind: str, t: float, payload: dict) -> None:
        pass


def exchange(me: str, topology: Topology, fusions: FusionLog):
    sc = load("partition").agent
    ctx = ExchangeContext(me, sc, FlatTerrain(0.0), 7, SendScheduler(sc.sending, None), NoSimulator(), Counter(),
                          topology, fusions=fusions)
    return EXCHANGES["track"](ctx)


def a_message_from_uav0() -> tuple[float, dict]:
    """uav0's first message with a confirmed track of the car (its time and payload)."""
    sender = exchange("uav0", Topology("uav0"), FusionLog(6.0))
    sensor = GeometricBearingSensor(BearingSensorConfig(p_detect=1.0, false_alarms=0.0), 3)
    for k in range(40):
        t = 0.2 * k
        sender.absorb(t, {"bearings": sensor.detect(t, CAMERA + [2.0 * k, 0.0, 0.0], CAR)})
        message = sender.outgoing(t, ["uav1"])
        if message is not None:
            return t, message.payload
    raise AssertionError("uav0 never confirmed the car")


def receiver():
    topology, fusions = Topology("uav1"), FusionLog(6.0)
    return exchange("uav1", topology, fusions), topology, fusions


def test_a_message_waits_for_the_links_place_in_the_graph_then_fuses_exactly():
    t, payload = a_message_from_uav0()
    uav1, topology, fusions = receiver()
    topology.heard("uav0", t)  # a new neighbour, its report not here yet
    assert topology.edge("uav0", t) is Edge.UNKNOWN
    assert uav1.receive("uav0", 1, t, payload, Edge.UNKNOWN, t) == []  # held, nothing fused
    assert not uav1.tracker.tracks and len(uav1.waiting) == 1
    uav1.settle(t + 0.4)  # still unknown, within the wait
    assert not uav1.tracker.tracks and not fusions.by_method
    topology.receive("uav0", {"uav0": [t + 0.5, ["uav1"]]}, t + 0.5)  # its report: the link is a bridge
    assert topology.edge("uav0", t + 0.6) is Edge.TREE
    uav1.settle(t + 0.6)
    assert dict(fusions.by_method) == {"exact": 1} and not fusions.by_cause  # exact, recorded by the host's log
    assert len(uav1.tracker.tracks) == 1 and not uav1.waiting
    estimate = uav1.tracker.estimates()[0][1]
    assert np.linalg.norm(estimate.mean[:2] - CAR[0]["position"][:2]) < 5.0


def test_a_message_that_waited_edge_wait_s_is_intersected_as_before():
    t, payload = a_message_from_uav0()
    uav1, topology, fusions = receiver()
    topology.heard("uav0", t)
    assert uav1.receive("uav0", 1, t, payload, Edge.UNKNOWN, t) == []
    uav1.settle(t + EDGE_WAIT_S - 0.2)
    assert uav1.waiting and not fusions.by_method
    topology.heard("uav0", t + EDGE_WAIT_S)  # still no report: the knowledge stays incomplete
    uav1.settle(t + EDGE_WAIT_S)
    assert dict(fusions.by_method) == {"ci": 1} and dict(fusions.by_cause) == {("ci", "not_tree_edge"): 1}
    assert not uav1.waiting and len(uav1.tracker.tracks) == 1


def test_only_the_newest_message_of_an_origin_waits():
    """Bad input as much as normal traffic: message after message from a peer whose link stays unknown. One waits
    per origin, the newest, from the time the first arrived: the wait is bounded by the fleet."""
    t, payload = a_message_from_uav0()
    uav1, topology, fusions = receiver()
    topology.heard("uav0", t)
    for seq in range(1, 40):
        uav1.receive("uav0", seq, t, payload, Edge.UNKNOWN, t + 0.02 * seq)
    assert list(uav1.waiting) == ["uav0"] and uav1.waiting["uav0"][:2] == (t + 0.02, 39)
    uav1.settle(t + 0.02 + EDGE_WAIT_S)
    assert dict(fusions.by_method) == {"ci": 1} and not uav1.waiting


def test_a_known_link_is_fused_on_arrival_and_a_restart_drops_what_waited():
    t, payload = a_message_from_uav0()
    uav1, topology, fusions = receiver()
    topology.heard("uav0", t)
    topology.receive("uav0", {"uav0": [t, ["uav1"]]}, t)
    assert [m for m, _ in uav1.receive("uav0", 1, t, payload, Edge.TREE, t)] == ["exact"]
    uav1, topology, fusions = receiver()
    topology.heard("uav0", t)
    uav1.receive("uav0", 1, t, payload, Edge.UNKNOWN, t)
    uav1.peer_restarted("uav0")  # its waiting message belongs to its old life
    uav1.settle(t + EDGE_WAIT_S)
    assert not uav1.waiting and not uav1.tracker.tracks and not fusions.by_method
