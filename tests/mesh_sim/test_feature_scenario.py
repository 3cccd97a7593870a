"""The feature scenario end to end (lockstep): the fixed wing captures the path optimised for the road and follows
it, its steered camera keeps the road point abeam at the image centre, and the car driving on the road is tracked."""

from __future__ import annotations

import pytest

from mesh_sim.launcher import new_run_dir
from mesh_sim.lockstep import run_lockstep
from mesh_sim.scenario import load

pytestmark = pytest.mark.slow  # a lockstep run

#: Bounds stated here. Centring: the gimbal reaches the reference of each frame unless it slews (the first
#: acquisition), so the 95th percentile is far below a pixel's worth of angle (0.1° at f = 554 px). Cross-track:
#: the paper's flight test had a mean within 40 m and a maximum of about 50 m (spec 003 §4.1) in real wind;
#: the kinematic aircraft in still air does much better.
CENTRING_P95_DEG = 0.1
CROSS_TRACK_P95_M = 10.0


def test_the_uav_follows_the_road_with_the_road_centred_and_tracks_the_car(tmp_path):
    scenario = load("feature", duration=40.0)  # the bridge and the straight road, past the moving car
    metrics = run_lockstep(scenario, new_run_dir(tmp_path, "feature"))
    (agent,) = metrics["agents"]
    gimbal = agent["sensor"]["gimbal"]
    assert gimbal["pointing_error_deg"]["samples"] == 200 and gimbal["out_of_travel"] == 0
    assert gimbal["pointing_error_deg"]["p95"] < CENTRING_P95_DEG
    feature = agent["feature"]
    assert feature["speed"] == 20.0  # optimised at the aircraft's airspeed
    assert feature["cross_track_m"]["samples"] > 150 and feature["cross_track_m"]["p95"] < CROSS_TRACK_P95_M
    car = next(t for t in agent["targets"] if t["target"] == "car")
    assert car["time_to_first_track"] is not None and car["samples"] > 0 and car["rmse"] < 20.0, car
