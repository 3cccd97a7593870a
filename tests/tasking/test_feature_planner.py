"""tasking.feature_planner: the ``[tasking] planner = "feature"`` options are validated when the scenario is read,
a bad operator path is refused naming ``tasking.path``, and every goal carries the gimbal command ``look_at``:
the feature point abeam, or the nearest confirmed track within range when ``look_at = "target"``."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from agent.config import AgentScenario
from tasking.base import TrackView
from tasking.feature_planner import CAPTURE_DISTANCE, FeaturePlanner
from tasking.registry import PLANNERS, PlanningContext, check_tasking, planner_from_config

ROAD = [[0.0, 0.0], [300.0, 0.0], [600.0, 0.0]]  # a straight road north along east = 0
AREA = (-100.0, 700.0, -200.0, 200.0)
ALTITUDE = 100.0


def build(speed: float | None = 18.0, **options) -> FeaturePlanner:
    ctx = PlanningContext(0, 1, AREA, ALTITUDE, 3, frozenset({"track"}), {}, 0.2, speed)
    return planner_from_config({"planner": "feature", "path": ROAD, **options}, ctx)


def at(north: float, east: float) -> SimpleNamespace:
    return SimpleNamespace(position=np.array([north, east, -ALTITUDE]), velocity=np.array([18.0, 0.0, 0.0]))


NO_TRACKS = {"track": TrackView([])}


def test_a_good_section_is_accepted_and_builds_the_planner_at_the_vehicle_speed():
    name, options = check_tasking({"planner": "feature", "path": ROAD, "look_at": "target", "max_bank_deg": 30,
                                   "target_range": 250.0})
    assert name == "feature" and options["look_at"] == "target"
    planner = build(max_bank_deg=30)
    assert isinstance(planner, FeaturePlanner) and PLANNERS["feature"].needs == "track"
    assert planner.flight.speed == 18.0  # a constant-airspeed vehicle: the path is optimised at its speed
    assert np.all(np.abs(planner.flight.bank) <= math.radians(30.0))
    assert build(speed=None, min_speed=15.0, max_speed=15.0).flight.speed == 15.0  # an explicit range wins


@pytest.mark.parametrize("path, words", [
    ([[0.0, 0.0]], "at least 2 points"),
    ([], "at least 2 points"),
    ([[0.0, 0.0], [0.0, 0.0], [10.0, 0.0]], "repeats point 0"),
    ([[0.0, 0.0], [math.nan, 5.0]], "non-finite"),
    ([[0.0, 0.0], [math.inf, 5.0]], "non-finite"),
    ([[0.0, 0.0], [10.0, "east"]], "list of \\[north, east\\] points"),
    ([[0.0, 0.0], [10.0, 1.0, 2.0]], "list of \\[north, east\\] points"),
    ([[0.0, 0.0], [True, 1.0]], "list of \\[north, east\\] points"),
])
def test_a_bad_path_is_refused_naming_tasking_path_when_the_scenario_is_read(path, words):
    with pytest.raises(ValueError, match=f"tasking.path.*{words}"):
        check_tasking({"planner": "feature", "path": path})
    with pytest.raises(ValueError, match="tasking.path"):
        AgentScenario.from_dict({"tasking": {"planner": "feature", "path": path}})


@pytest.mark.parametrize("section, words", [
    ({"path": "north"}, "tasking.path has the wrong type"),
    ({"look_at": "sky"}, "tasking.look_at must be one of"),
    ({"look_at": 1}, "tasking.look_at has the wrong type"),
    ({"min_speed": 15.0}, "tasking.min_speed and tasking.max_speed go together"),
    ({"carrot_distance": -5.0}, "tasking.carrot_distance must be a positive number"),
    ({"target_range": math.nan}, "tasking.target_range must be a positive number"),
    ({"max_bank_deg": 95.0}, "max_bank must be below 90"),
    ({"look_min_deg": 50.0, "look_max_deg": 20.0}, "look_range"),
    ({"loiter": 100.0}, "unknown tasking settings"),
])
def test_bad_options_are_errors_naming_the_setting(section, words):
    with pytest.raises(ValueError, match=words):
        check_tasking({"planner": "feature", "path": ROAD, **section})


def test_the_goal_is_the_followers_with_the_feature_point_abeam_to_look_at():
    planner = build()
    state = at(200.0, -40.0)
    goal = planner.plan(state, NO_TRACKS)
    expected = planner.follower.goal(state.position)
    np.testing.assert_array_equal(goal.position, expected.position)
    assert goal.speed == expected.speed == 18.0
    # on a straight road the UAV path runs parallel to it: the point abeam is (200, 0) on the ground (down = 0)
    np.testing.assert_allclose(goal.look_at, [200.0, 0.0, 0.0], atol=1e-6)


def test_look_at_switches_to_the_nearest_confirmed_track_within_range():
    planner = build(look_at="target", target_range=300.0)
    state = at(200.0, -40.0)
    feature_point = planner.plan(state, NO_TRACKS).look_at  # no track yet: the feature
    np.testing.assert_allclose(feature_point, [200.0, 0.0, 0.0], atol=1e-6)
    tracks = TrackView([("far", np.array([420.0, 0.0])), ("near", np.array([260.0, 3.0]))])
    np.testing.assert_allclose(planner.plan(state, {"track": tracks}).look_at, [260.0, 3.0, 0.0])
    out_of_range = TrackView([("far", np.array([600.0, 0.0]))])  # 402 m away
    np.testing.assert_allclose(planner.plan(state, {"track": out_of_range}).look_at, feature_point)
    assert planner.metrics()["feature"]["target_steps"] == 1
    on_feature = build()  # look_at = "feature": a track does not move the gimbal
    np.testing.assert_allclose(on_feature.plan(state, {"track": tracks}).look_at, feature_point)


def test_at_the_end_of_the_path_it_loiters_looking_at_the_feature_end():
    planner = build()
    goal = planner.plan(at(700.0, -40.0), NO_TRACKS)
    assert goal.is_orbit and goal.orbit_radius == planner.follower.loiter_radius
    np.testing.assert_allclose(goal.look_at, [600.0, 0.0, 0.0], atol=1e-6)
    assert planner.metrics()["feature"]["finished"]


def test_cross_track_error_counts_from_the_capture_of_the_path():
    planner = build()
    offset = planner.flight.offset  # the UAV path is the road shifted sideways by this (right positive)
    planner.plan(at(100.0, offset + 3 * CAPTURE_DISTANCE), NO_TRACKS)  # still on the bridge
    planner.plan(at(150.0, offset + 2.0), NO_TRACKS)
    planner.plan(at(200.0, offset - 4.0), NO_TRACKS)
    m = planner.metrics()["feature"]
    assert m["bridge_steps"] == 1 and not m["finished"]
    assert m["cross_track_m"]["samples"] == 2
    assert m["cross_track_m"]["mean"] == pytest.approx(3.0, abs=1e-6)
    assert m["cross_track_m"]["max"] == pytest.approx(4.0, abs=1e-6)


def test_without_a_path_the_feature_is_the_areas_centre_line():
    ctx = PlanningContext(0, 1, AREA, ALTITUDE, 3, frozenset({"track"}), {}, 0.2, 18.0)
    planner = PLANNERS["feature"].build({}, ctx)
    np.testing.assert_allclose(planner.flight.feature.position(0.0), [-100.0, 0.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(planner.flight.feature.position(planner.flight.feature.tau_f), [700.0, 0.0, 0.0],
                               atol=1e-9)
