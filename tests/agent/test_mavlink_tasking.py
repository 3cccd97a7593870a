"""What the MAVLink vehicle's health does to the agent: a vehicle whose autopilot falls silent bids for nothing,
so the consensus gives its task to a peer; its reported battery drives the sortie home; and the agent does not
sense with a stale pose."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from agent.agent import Agent
from agent.beliefs.assignment import AssignmentExchange
from agent.config import AgentScenario
from agent.net.bus import InMemoryBus
from agent.net.keys import Keys
from agent.plugins import Views
from agent.vehicles import vehicle_from_config
from tasking.assignment import AssignmentConfig
from tests.agent.mavlink_peer import (
    SCENARIO_ORIGIN,
    flying_vehicle,
    wait_for,
)
from tests.tasking.test_assignment import AREA, _Picture, _talk

TARGET = np.array([110.0, -60.0])  # near the MAVLink vehicle's take-off point (120, -80) in the scenario


@pytest.fixture
def flying():
    with flying_vehicle() as (peer, vehicle):
        yield peer, vehicle


def exchange(me: str, vehicle, **config) -> AssignmentExchange:
    return AssignmentExchange(me, AssignmentConfig(**config), AREA, vehicle.state().position,
                              Views({"track": _Picture([(0, TARGET)])}), vehicle)


def test_a_vehicle_whose_autopilot_falls_silent_hands_its_task_to_a_peer(flying):
    peer, vehicle = flying
    a = exchange("a", vehicle)
    b = exchange("b", vehicle_from_config({"kind": "multirotor"}, [-100.0, 100.0, -80.0]))
    for step in range(5):
        _talk(a, b, 0.2 * step)
    assert a.view().task.key == "track:0" and b.cbba.winners["track:0"] == "a"  # the nearer one serves
    peer.silent.set()  # the autopilot's heartbeat stops
    wait_for(lambda: not vehicle.healthy, timeout=4.0)
    for step in range(5, 10):
        _talk(a, b, 0.2 * step)
    assert a.cbba.bundle == [] and a.view().task is None
    assert b.view().task.kind == "track" and b.cbba.winners["track:0"] == "b"


def test_the_reported_battery_is_the_sortie_fuel_and_sends_the_vehicle_home(flying):
    peer, vehicle = flying
    # 600 s on a full battery; 200 s kept in hand: 80 % (480 s) flies on, 30 % (180 s) must go home
    a = exchange("a", vehicle, flight_time=600.0, reserve=200.0, failure_rate=0.0)
    a.base = np.array([-100.0, 100.0])  # 280 m away
    a.settle(0.0)
    assert a.sortie.state == "flying" and a.sortie.health.fuel == pytest.approx(0.8)
    peer.battery = 30
    wait_for(lambda: vehicle.battery == 0.3, timeout=3.0)
    a.settle(0.2)
    assert vehicle.healthy  # above the vehicle's own 20 % reserve: it is the sortie that calls it home
    assert a.sortie.state == "home" and a.view().home and a.cbba.bundle == []


def test_a_reported_failure_is_a_failure_of_the_health_model(flying):
    peer, vehicle = flying
    a = exchange("a", vehicle, flight_time=600.0, failure_rate=0.0)
    peer.fault = 1  # BATTERY_STATUS fault_bitmask: MAV_BATTERY_FAULT_DEEP_DISCHARGE
    wait_for(lambda: vehicle.failed, timeout=3.0)
    a.settle(0.0)
    assert a.sortie.health.failed and a.sortie.health.failures == 1


def _agent_on(peer) -> Agent:
    """An agent whose scenario's vehicle is the scripted autopilot ``peer``."""
    scenario = AgentScenario.from_dict({
        "agents": 1, "origin": dict(zip(("lat", "lon", "alt"), SCENARIO_ORIGIN, strict=True)),
        "vehicle": {"kind": "mavlink", "url": f"udpin:127.0.0.1:{peer.address[1]}", "takeoff_altitude": 3.0}})
    keys = Keys("mavlink-test")
    return Agent("uav0", 0, scenario, InMemoryBus().endpoint("uav0", keys.agent_subscriptions()), keys, seed=1)


def test_the_agent_does_not_sense_with_a_stale_pose(flying):
    peer, vehicle = flying
    vehicle.close()  # the agent builds its own vehicle on the same autopilot
    agent = _agent_on(peer)
    try:
        measured = []
        measure = agent.sensor.measure
        agent.sensor.measure = lambda t, state: measured.append(state.fresh) or measure(t, state)
        wait_for(lambda: agent.vehicle.healthy)
        agent.step(0.0)
        assert measured == [True]
        peer.silent.set()
        wait_for(lambda: not agent.vehicle.state().fresh, timeout=4.0)
        agent.step(0.2)
        assert measured == [True]  # no measurement with the stale pose
        metrics = agent.metrics()
        assert metrics["vehicle"]["stale_steps"] == 1 and not metrics["vehicle"]["healthy"]
    finally:
        agent.close()


def test_the_planners_look_at_reaches_the_autopilots_gimbal(flying):
    """A goal with ``look_at`` (the feature planner's, spec 003) points the camera through the gimbal protocol:
    the agent hands it to the vehicle as to its sensors."""
    peer, vehicle = flying
    vehicle.close()
    agent = _agent_on(peer)
    try:
        wait_for(lambda: agent.vehicle.healthy)
        plan = agent.planner.plan
        here = agent.vehicle.state().position
        agent.planner.plan = lambda state, views: replace(plan(state, views), look_at=here + [0.0, 0.0, 50.0])
        agent.step(0.0)
        wait_for(lambda: peer.received["GIMBAL_MANAGER_SET_PITCHYAW"])
        assert peer.messages("GIMBAL_MANAGER_SET_PITCHYAW")[-1].pitch == pytest.approx(-math.pi / 2)  # straight down
    finally:
        agent.close()
