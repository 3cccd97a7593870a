"""The centralized references (mesh_sim.oracle): the in-flight oracle delays each bearing by its hop count."""

from __future__ import annotations

import numpy as np
import pytest

from agent.config import AgentScenario
from agent.net import wire
from fusion.network import hop_distances
from mesh_sim.oracle import InFlightOracle, Oracle

STEP = 0.2


def test_hop_distances_count_hops_and_leave_out_the_unreachable():
    edges = [frozenset(e) for e in (("a", "b"), ("b", "c"), ("c", "d"), ("x", "y"))]
    assert hop_distances(edges, "a") == {"a": 0, "b": 1, "c": 2, "d": 3}


class Line:
    """A radio plan's one query: uav0 - uav1 - uav2, uav3 cut off."""

    def edges_at(self, t):
        return {frozenset(("uav0", "uav1")), frozenset(("uav1", "uav2"))}


def bearings_of(origin: str, t: float) -> wire.Envelope:
    bearing = {"t": t, "sensor": np.array([0.0, 0.0, -80.0]), "azel": np.array([0.3, -1.2]),
               "R": np.eye(2) * 1e-4, "truth": "T"}
    return wire.Envelope(kind="measurement", origin=origin, seq=1, stamp=t, payload={"bearings": [bearing]})


def test_a_bearing_reaches_each_agent_one_step_per_hop_and_never_an_agent_out_of_reach():
    oracle = InFlightOracle(AgentScenario.from_dict({"agents": 4}))
    oracle.plan = Line()
    targets = []
    holders = []
    for k in range(4):
        t = k * STEP
        if k == 0:
            oracle.add(bearings_of("uav0", t), t)
        oracle.evaluate(targets, t)
        holders.append([name for name, o in oracle.oracles.items() if o.tracker.tracks])
    assert holders == [["uav0"], ["uav0", "uav1"], ["uav0", "uav1", "uav2"], ["uav0", "uav1", "uav2"]]


def test_without_a_radio_plan_every_agent_is_one_hop_away():
    oracle = InFlightOracle(AgentScenario.from_dict({"agents": 3}))
    oracle.add(bearings_of("uav2", 0.0), 0.0)
    oracle.evaluate([], 0.0)
    assert [n for n, o in oracle.oracles.items() if o.tracker.tracks] == ["uav2"]
    oracle.evaluate([], STEP)
    assert all(o.tracker.tracks for o in oracle.oracles.values())


BAD_BEARINGS = {
    "no bearings list": {},
    "a sensor of two coordinates": {"bearings": [{"t": 0.0, "sensor": [0.0, 0.0], "azel": [0.3, -1.2],
                                                  "R": np.eye(2) * 1e-4, "truth": "T"}]},
    "a NaN azimuth": {"bearings": [{"t": 0.0, "sensor": [0.0, 0.0, -80.0], "azel": [np.nan, -1.2],
                                    "R": np.eye(2) * 1e-4, "truth": "T"}]},
    "a covariance that is not positive definite": {"bearings": [{"t": 0.0, "sensor": [0.0, 0.0, -80.0],
                                                                 "azel": [0.3, -1.2], "R": -np.eye(2), "truth": "T"}]},
    "a time that is not a number": {"bearings": [{"t": "now", "sensor": [0.0, 0.0, -80.0], "azel": [0.3, -1.2],
                                                  "R": np.eye(2) * 1e-4, "truth": "T"}]},
}


@pytest.mark.parametrize("fault", sorted(BAD_BEARINGS))
def test_a_malformed_measurement_message_is_rejected_and_the_good_ones_of_its_tick_still_apply(fault):
    """The oracle holds a tick's messages and applies them together at ``evaluate``: a bad one is counted in
    ``rejected`` when it arrives and takes nothing else with it."""
    oracle = Oracle(AgentScenario.from_dict({"agents": 2}))
    bad = wire.Envelope(kind="measurement", origin="uav1", seq=1, stamp=0.0, payload=BAD_BEARINGS[fault])
    oracle.add(bad, 0.0)
    oracle.add(bearings_of("uav0", 0.0), 0.0)
    assert oracle.rejected == 1, fault
    assert not oracle.tracker.tracks  # held until the tick is scored
    oracle.evaluate([])
    assert len(oracle.tracker.tracks) == 1 and oracle.late == 0
