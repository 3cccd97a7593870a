"""agent.sensors.truth: the simulated-truth intake. Targets are extrapolated at constant velocity and
forgotten when stale; the fire is decoded once per change; a malformed fire is rejected by reason while
the rest of the message is kept."""

from __future__ import annotations

import numpy as np
import pytest

from agent.net import wire
from agent.net.fire_truth import encode_fire
from agent.sensors.truth import TRUTH_MAX_AGE, WorldTruth
from perception.terrain import FlatTerrain


def truth(stamp: float, **payload) -> wire.Envelope:
    return wire.Envelope(kind="truth", origin="world", seq=1, stamp=stamp, payload=payload)


def test_targets_are_extrapolated_at_constant_velocity_and_forgotten_when_stale():
    world = WorldTruth(FlatTerrain(), "uav0")
    assert world.at(0.0).targets is None  # nothing received yet
    world.accept(truth(1.0, targets=[{"id": "car", "position": [10.0, 0.0, 0.0], "velocity": [2.0, -1.0, 0.0]}]))
    (car,) = world.targets_at(1.5)
    np.testing.assert_allclose(car["position"], [11.0, -0.5, 0.0])
    assert world.targets_at(1.0 + TRUTH_MAX_AGE + 0.01) is None


def test_uav_positions_exclude_the_receiver():
    world = WorldTruth(FlatTerrain(), "uav0")
    world.accept(truth(0.0, uavs={"uav0": [0.0, 0.0, -80.0], "uav1": [5.0, 5.0, -80.0]}))
    assert set(world.uav_positions) == {"uav1"}


def test_the_fire_is_decoded_once_per_change_with_its_decoys():
    world = WorldTruth(FlatTerrain(), "uav0")
    state = np.zeros((4, 4), np.int8)
    state[1, 2] = 1  # one burning cell
    fire = encode_fire([0.0, 0.0], 5.0, state)
    world.accept(truth(0.0, fire=fire, decoys=[[3.0, 4.0, 0.5], ["bad"]]))
    first = world.at(0.0)
    assert len(first.fires) == 1 and first.decoys == [(3.0, 4.0, 0.5)]  # the malformed decoy is ignored
    world.accept(truth(0.2, fire=fire, decoys=[[3.0, 4.0, 0.5], ["bad"]]))
    assert world.at(0.2).fires is first.fires  # unchanged truth: not decoded again


def test_a_malformed_fire_is_rejected_and_the_rest_is_kept():
    """Bad input: a fire whose state bytes are not zlib data."""
    world = WorldTruth(FlatTerrain(), "uav0")
    bad = {"origin": [0.0, 0.0], "cell": 5.0, "shape": [2, 2], "state": b"not zlib"}
    with pytest.raises(wire.DecodeError) as err:
        world.accept(truth(0.0, fire=bad, targets=[], uavs={"uav1": [1.0, 2.0, 3.0]}))
    assert err.value.reason == "bad_fire"
    assert world.targets_at(0.0) == [] and set(world.uav_positions) == {"uav1"}
    assert world.at(0.0).fires == []


@pytest.mark.parametrize("payload, what", [
    ({"targets": {"car": [0, 0, 0]}}, "targets as a map, not a list"),
    ({"targets": [["car", [0, 0, 0]]]}, "a target as a list"),
    ({"targets": [{"id": 7, "position": [0, 0, 0], "velocity": [0, 0, 0]}]}, "a numeric target id"),
    ({"targets": [{"id": "car", "position": [0, 0], "velocity": [0, 0, 0]}]}, "a 2-D position"),
    ({"targets": [{"id": "car", "position": [0, 0, float("nan")], "velocity": [0, 0, 0]}]}, "a NaN position"),
    ({"targets": [{"id": "car", "position": [0, 0, 0]}]}, "a missing velocity"),
    ({"targets": [{"id": "car", "position": ["a", 0, 0], "velocity": [0, 0, 0]}]}, "a string coordinate"),
    ({"targets": [{"id": "car", "position": [True, 0, 0], "velocity": [0, 0, 0]}]}, "a bool coordinate"),
    ({"uavs": [[0, 0, 0]]}, "uavs as a list"),
    ({"uavs": {"uav1": [0, 0, float("inf")]}}, "an infinite UAV position"),
    ({"uavs": {"uav0": [0, 0, float("inf")], "uav1": [0, 0, 0]}}, "the receiver's own position infinite (bench fuzz)"),
    ({"uavs": {"uav1": "north"}}, "a UAV position as a string"),
    ({"uavs": {"uav1": ["1", "2", "3"]}}, "coordinates as strings of digits"),
    ({"uavs": {"uav1": [1.0, 2.0, True]}}, "a bool coordinate of a UAV"),
    ({"uavs": {"uav1": [1.0, 2.0, 3.0], "uav2": [1.0, 2.0], "uav3": [0.0, 0.0, 0.0]}}, "one UAV of three 2-D"),
])
def test_malformed_target_states_or_uav_positions_are_rejected_and_nothing_is_kept(payload, what):
    """Bad input (reliability audit: 1,067 malformed truths crashed agents): {what}."""
    world = WorldTruth(FlatTerrain(), "uav0")
    good = {"targets": [{"id": "car", "position": [1.0, 2.0, 0.0], "velocity": [0.0, 0.0, 0.0]}],
            "uavs": {"uav1": [5.0, 5.0, -80.0]}}
    world.accept(truth(0.0, **good))
    with pytest.raises(wire.DecodeError) as err:
        world.accept(truth(0.2, **{**good, **payload}))
    assert err.value.reason == "bad_truth", what
    np.testing.assert_allclose(world.targets_at(0.0)[0]["position"], [1.0, 2.0, 0.0])
    np.testing.assert_allclose(world.uav_positions["uav1"], [5.0, 5.0, -80.0])


def test_uav_positions_leave_out_this_agent_and_keep_every_other_one():
    world = WorldTruth(FlatTerrain(), "uav0")
    uavs = {"uav0": [9.0, 9.0, 9.0], "uav1": [1, 2, -80], "uav2": [0.5, -4.0, -60.0]}
    world.accept(truth(0.0, targets=[], uavs=uavs))
    assert set(world.uav_positions) == {"uav1", "uav2"}
    np.testing.assert_array_equal(world.uav_positions["uav1"], [1.0, 2.0, -80.0])
    np.testing.assert_array_equal(world.uav_positions["uav2"], [0.5, -4.0, -60.0])
