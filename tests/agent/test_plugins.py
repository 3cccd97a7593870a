"""agent.plugins: every registered implementation has the methods of its seam with the seam's parameters,
the host names none of them, and the in-process harness never loads Zenoh."""

from __future__ import annotations

import inspect
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest

from agent import plugins
from agent.beliefs import EXCHANGES, ExchangeContext
from agent.config import AgentScenario
from agent.net.bus import BusEndpoint
from agent.net.radio import RadioTransport
from agent.net.sending import SendScheduler
from agent.net.topology import Topology
from agent.net.zenoh_transport import ZenohTransport
from agent.plugins import Views
from agent.sensors.registry import SENSORS, sensor_from_config
from agent.vehicles import VEHICLES, vehicle_from_config
from agent.vehicles.base import Vehicle
from perception.terrain import FlatTerrain
from tasking.base import Planner
from tasking.registry import PLANNERS, PlanningContext

ROOT = Path(__file__).resolve().parents[2]


def protocol_methods(protocol) -> dict[str, list[str]]:
    """Public methods of a Protocol with their parameter names (after ``self``)."""
    out = {}
    for name, member in vars(protocol).items():
        if callable(member) and not name.startswith("_"):
            out[name] = list(inspect.signature(member).parameters)[1:]
    return out


def assert_implements(obj, protocol) -> None:
    for name, params in protocol_methods(protocol).items():
        method = getattr(obj, name, None)
        assert callable(method), f"{type(obj).__name__} lacks {protocol.__name__}.{name}"
        assert list(inspect.signature(method).parameters) == params, (type(obj).__name__, name)


def fire_scenario() -> AgentScenario:
    return AgentScenario.from_dict({"grid": {}, "tasking": {"planner": "entropy"}})


def test_every_registered_exchange_is_a_belief_exchange():
    built = {}
    for sc in (fire_scenario(), AgentScenario.from_dict({"tasking": {"planner": "assignment"}}),
               AgentScenario.from_dict({"tracking": {"initiation": "particles"}})):
        vehicle = vehicle_from_config(sc.vehicle, sc.start_position(0))
        ctx = ExchangeContext("uav0", sc, FlatTerrain(), 1, SendScheduler(sc.sending, None), None, Counter(),
                              Topology("uav0"), Views({}), vehicle)
        built.update((kind, ex) for kind, build in EXCHANGES.items() if (ex := build(ctx)) is not None)
    assert set(built) == set(EXCHANGES) == {"track", "grid", "tasks", "particles"}
    for kind, exchange in built.items():
        assert exchange.kind == kind
        assert isinstance(exchange.needs_edge, bool), kind
        assert_implements(exchange, plugins.BeliefExchange)
        for sensor in exchange.sensors():
            assert_implements(sensor, plugins.Sensor)


def test_an_exchange_the_scenario_does_not_ask_for_is_not_built():
    sc = AgentScenario()
    ctx = ExchangeContext("uav0", sc, FlatTerrain(), 1, SendScheduler(sc.sending, None), None, Counter(),
                          Topology("uav0"))
    assert EXCHANGES["grid"](ctx) is None
    assert EXCHANGES["particles"](ctx) is None  # [tracking] initiation = "ray": no particle candidates


@pytest.mark.parametrize("kind", sorted(SENSORS))
def test_every_registered_sensor_is_a_sensor(kind):
    sensor = sensor_from_config(SENSORS[kind].config_class(), 0, FlatTerrain())
    assert_implements(sensor, plugins.Sensor)
    sensor.close()


@pytest.mark.parametrize("kind", sorted(set(VEHICLES) - {"mavlink"}))  # it needs an autopilot: test_mavlink_vehicle
def test_every_registered_vehicle_is_a_vehicle(kind):
    assert_implements(VEHICLES[kind]({}, [0.0, 0.0, -50.0], 0.0), Vehicle)


@pytest.mark.parametrize("name", sorted(PLANNERS))
def test_every_registered_planner_is_a_planner(name):
    ctx = PlanningContext(0, 2, (-50.0, 50.0, -50.0, 50.0), 40.0, 0, frozenset({"track", "grid"}),
                          {"detection": (0.9, 0.05)})
    assert_implements(PLANNERS[name].build({}, ctx), Planner)


@pytest.mark.parametrize("cls", [BusEndpoint, ZenohTransport, RadioTransport])
def test_every_transport_is_a_transport(cls):
    for name, params in protocol_methods(plugins.Transport).items():
        assert list(inspect.signature(getattr(cls, name)).parameters)[1:] == params, (cls.__name__, name)


def test_the_host_names_no_implementation():
    """The goals of the plug-in host: short, and no belief-kind, planner-kind or fire-specific branch."""
    source = (ROOT / "agent" / "agent.py").read_text()
    assert len(source.splitlines()) <= 250
    for word in ("isinstance", "mapper", "fire", "grid", "Tracker", "EntropyPlanner", "Placeholder"):
        assert word not in source, word


def test_the_in_process_harness_never_loads_zenoh():
    """The lockstep harness (agent loop, bus, radio wrapper) runs without Zenoh imported."""
    code = ("import sys, agent.agent, agent.net.bus, agent.net.radio, mesh_sim.lockstep; "
            "sys.exit(1 if 'zenoh' in sys.modules else 0)")
    result = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr or "zenoh was imported"


def test_observations_of_one_name_from_two_sensors_are_joined_when_they_are_lists():
    """The [sensor] camera's bearings and the thermal camera's hot spots both go to the tracker."""
    step = {"bearings": ["camera"], "fire_evidence": "frame"}
    plugins.merge_observations(step, {"bearings": ["hot spot"], "clock": 1.0})
    assert step == {"bearings": ["camera", "hot spot"], "fire_evidence": "frame", "clock": 1.0}
    with pytest.raises(ValueError, match="'fire_evidence'"):  # two thermal frames cannot be added up
        plugins.merge_observations(step, {"fire_evidence": "another frame"})
    assert step["fire_evidence"] == "frame"
