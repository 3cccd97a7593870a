"""tasking.standoff: the collocation set-point for stand-off tracking, replanned on a worker thread and adopted at a
fixed simulation-time delay (spec 002 §2.7)."""

from __future__ import annotations

import threading
from types import SimpleNamespace

import numpy as np
import pytest

from tasking.assignment import AssignmentConfig, AssignmentPlanner
from tasking.base import AssignmentView, TrackView
from tasking.collocation import VehicleLimits
from tasking.registry import PlanningContext, check_tasking, planner_from_config
from tasking.standoff import StandoffPilot, vehicle_limits
from tasking.tasks import Task

AREA = (-200.0, 200.0, -200.0, 200.0)
WING = {"kind": "fixed_wing", "airspeed": 18.0, "max_bank_deg": 35.0}


def _state(north=-150.0, east=0.0):
    return SimpleNamespace(position=np.array([north, east, -60.0]), velocity=np.array([18.0, 0.0, 0.0]), yaw=0.0)


def _context(**kw):
    return PlanningContext(0, 2, AREA, 60.0, 1, frozenset({"tasks", "track"}), vehicle=WING, max_speed=18.0, **kw)


def _pilot(**kw):
    return StandoffPilot(vehicle_limits(WING, 18.0), 60.0, **kw)


def test_the_hook_picks_collocation_only_when_configured():
    circle = planner_from_config({"planner": "assignment"}, _context())
    assert circle.standoff is None and circle.metrics() == {}
    planned = planner_from_config({"planner": "assignment", "standoff": "collocation"}, _context(lockstep=True))
    try:
        assert isinstance(planned.standoff, StandoffPilot) and planned.standoff.wait is None
        assert planned.standoff.planner.limits == VehicleLimits.fixed_wing(18.0, np.radians(35.0), speed_band=0.05)
        assert set(planned.metrics()["standoff"]) >= {"requested", "adopted", "late", "solve_ms_p95"}
    finally:
        planned.close()
    live = planner_from_config({"planner": "assignment", "standoff": "collocation"}, _context())
    live.close()
    assert live.standoff.wait is not None  # live: a bounded wait


@pytest.mark.parametrize(("options", "key"), [({"standoff": "zigzag"}, "tasking.standoff"),
                                              ({"adopt_after": -0.1}, "tasking.adopt_after"),
                                              ({"adopt_after": 2.0}, "tasking.adopt_after"),
                                              ({"standoff": 3}, "tasking.standoff")])
def test_bad_values_are_refused_with_the_key(options, key):
    with pytest.raises(ValueError, match=key):
        check_tasking({"planner": "assignment", **options})


def test_the_plan_is_adopted_at_the_fixed_delay_and_its_setpoint_is_flown():
    pilot = _pilot(wait=None)
    try:
        mean, still = np.zeros(2), np.zeros(2)
        assert pilot.goal(0.0, _state(), "track:a", mean, still) is None  # requested at t = 0
        pilot._pending[1].result()  # the solve is done, but it is not adopted before t = 0.6
        assert pilot.goal(0.4, _state(), "track:a", mean, still) is None
        for t in (0.6, 1.0, 1.8):
            goal = pilot.goal(t, _state(), "track:a", mean, still)
            point = pilot.planner.sample(t)
            np.testing.assert_allclose(goal.position, point.position)
            np.testing.assert_allclose(goal.velocity, point.velocity[:2])
        assert pilot.planner.plan.t0 == 0.0 and pilot.adopted == 1
        assert np.linalg.norm(pilot.goal(1.0, _state(), "track:a", mean, still).position
                              - pilot.goal(1.8, _state(), "track:a", mean, still).position) > 10.0  # it moves
        pilot.goal(2.0, _state(), "track:a", mean, still)  # the next replanning is requested at t = 2 ...
        assert pilot.requested == 2 and pilot.planner.plan.t0 == 0.0  # ... and the old plan flown until 2.6
        pilot.goal(2.6, _state(), "track:a", mean, still)
        assert pilot.planner.plan.t0 == 2.0 and pilot.adopted == 2 and pilot.late == 0
        assert pilot.metrics()["solve_ms_median"] > 0
    finally:
        pilot.close()


def test_a_late_solve_keeps_the_old_plan_is_counted_and_holds_back_the_next_request():
    pilot = _pilot(wait=None)
    release = threading.Event()
    try:
        mean, still = np.zeros(2), np.zeros(2)
        pilot.goal(0.0, _state(), "track:a", mean, still)
        pilot.goal(0.6, _state(), "track:a", mean, still)
        first = pilot.planner.plan
        solve = pilot.planner.solve
        pilot.planner.solve = lambda *a: (release.wait(10), solve(*a))[1]  # a solve that overruns
        pilot.wait = 0.01
        pilot.goal(2.0, _state(), "track:a", mean, still)
        goal = pilot.goal(2.6, _state(), "track:a", mean, still)
        assert pilot.late == 1 and pilot.planner.plan is first
        np.testing.assert_allclose(goal.position, first.sample(2.6)[:2].tolist() + [-60.0])
        pilot.goal(4.0, _state(), "track:a", mean, still)  # the late solve still runs: no request queued behind it
        assert pilot.skipped == 1 and pilot.requested == 2 and pilot._pending is None
    finally:
        release.set()
        pilot.close()
    assert len(pilot.late_replannings) == 1 and pilot.late_replannings[0].wall > 0.01  # timed when it ended
    assert len(pilot.metrics()["solve_ms"]) == 2


def test_the_worker_stops_at_close():
    pilot = _pilot(wait=None)
    pilot.goal(0.0, _state(), "track:a", np.zeros(2), np.zeros(2))
    threads = list(pilot._worker._threads)
    assert threads and all(t.is_alive() for t in threads)
    pilot.close()
    assert not any(t.is_alive() for t in threads)


def _view(task):
    return {"tasks": AssignmentView(task, False, np.zeros(2), {}),
            "track": TrackView([("a", np.array([0.0, 0.0, 0.0]))], {"a": np.array([1.0, 0.5])})}


def test_the_assignment_planner_flies_the_circle_then_the_plan_and_releases_it_off_track():
    config = AssignmentConfig(standoff="collocation", min_separation=0.0)
    planner = AssignmentPlanner(config, AREA, 60.0, 0.2, 18.0, _pilot(wait=None))
    task = Task("track:a#0", np.zeros(2), 10.0, "track")
    try:
        goals = [planner.plan(_state(), _view(task)) for _ in range(5)]  # t = 0 .. 0.8
        assert all(g.is_orbit for g in goals[:3]) and not goals[3].is_orbit  # adopted at t = 0.6
        assert goals[3].velocity is not None and planner.standoff._target == "track:a"
        np.testing.assert_allclose(planner.standoff.replannings[0].solves[0].states[0][:2], [-150.0, 0.0])
        planner.plan(_state(), _view(Task("search:0:0", np.zeros(2), 1.0, "search")))
        assert planner.standoff._target is None
    finally:
        planner.close()
