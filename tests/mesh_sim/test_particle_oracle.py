"""The centralized particle filter of the ambiguous scenario and the fleet-vs-oracle comparison."""

from __future__ import annotations

import numpy as np

from agent.beliefs.particle_init import ParticleInitConfig
from agent.net import wire
from agent.sensors.bearing import bearing_covariance
from fusion.measurement import los_to_azel
from mesh_sim.particle_oracle import ParticleOracle, fleet_resolution
from mesh_sim.target_set import targets_from_config
from perception.terrain import FlatTerrain

TARGET = np.array([30.0, 7.0, 0.0])


def measurement(t: float, sensors, rng, truth="car") -> wire.Envelope:
    entries = []
    for sensor in sensors:
        los = TARGET - sensor
        azel = los_to_azel(los / np.linalg.norm(los)) + rng.normal(0.0, np.deg2rad(0.5), 2)
        entries.append({"t": t, "sensor": sensor, "azel": azel, "R": bearing_covariance(azel[1], np.deg2rad(0.5)),
                        "truth": truth})
    return wire.Envelope(kind="measurement", origin="uav0", seq=1, stamp=t, payload={"bearings": entries})


def test_two_viewpoints_resolve_a_target_and_one_ray_alone_does_not():
    rng = np.random.default_rng(4)
    targets = [{"id": "car", "kind": "static", "position": TARGET[:2].tolist()}]
    sensors = [np.array([-30.0, -20.0, -60.0]), np.array([-30.0, 20.0, -60.0])]
    alone, both = ParticleOracle(ParticleInitConfig(), 1), ParticleOracle(ParticleInitConfig(), 1)
    for k in range(10):
        alone.add(measurement(0.2 * k, sensors[:1], rng))
        both.add(measurement(0.2 * k, sensors, rng))
    world = targets_from_config(targets, FlatTerrain())
    alone.evaluate(world, 2.0)
    both.evaluate(world, 2.0)
    assert alone.summary()["resolved_s"] == {"car": None}
    assert both.summary()["resolved_s"] == {"car": 2.0}
    assert np.linalg.norm(both.sets["car"].mean() - TARGET) < 2.0 and both.summary()["bearings"] == 20


def test_clutter_is_left_out_and_a_malformed_message_is_counted():
    oracle = ParticleOracle(ParticleInitConfig(), 1)
    oracle.add(measurement(0.0, [np.array([0.0, 0.0, -60.0])], np.random.default_rng(1), truth=None))
    oracle.add(wire.Envelope(kind="measurement", origin="uav0", seq=2, stamp=0.0,
                             payload={"bearings": [{"sensor": [0, 0], "azel": [0, 0], "R": np.eye(2), "truth": "x"}]}))
    assert oracle.sets == {} and oracle.summary()["rejected"] == 1


def test_the_fleet_time_is_the_last_agents_and_missing_times_give_no_ratio():
    oracle = {"particles": {"resolved_s": {"a": 10.0, "b": 8.0}}}
    agents = [{"id": "uav0", "particles": {"resolved_s": {"a": 12.0, "b": 9.0}}},
              {"id": "uav1", "particles": {"resolved_s": {"a": 14.0, "b": None}}}]
    out = fleet_resolution(agents, oracle)
    assert out["a"] == {"agents": {"uav0": 12.0, "uav1": 14.0}, "fleet_s": 14.0, "oracle_s": 10.0, "ratio": 1.4}
    assert out["b"]["fleet_s"] is None and out["b"]["ratio"] is None
