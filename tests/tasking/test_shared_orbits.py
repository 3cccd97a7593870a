"""Shared orbits (``[tasking] orbit_slots``, spec 004 §2.8-2.9 in the fleet): slot tasks, their wire keys, the
partners a vehicle spaces itself against, and 004's set-point on the shared circle."""

import math

import numpy as np
import pytest

from agent.net import wire
from tasking.assignment import AssignmentConfig, AssignmentPlanner, fleet_tasks, search_cells, search_tasks, slot_of
from tasking.base import AssignmentView, TrackView
from tasking.circle_spacing import K_THETA, OMEGA_0
from tasking.registry import check_tasking
from tasking.tasks import Task
from tests.tasking.test_assignment import AREA, _exchange, _State, _talk


def test_every_track_is_k_slot_tasks_of_falling_value():
    config = AssignmentConfig(orbit_slots=3)
    tasks = fleet_tasks([(5, np.array([1.0, 2.0]))], search_tasks(search_cells(AREA, 120.0), config), config)
    slots = {k: t.value for k, t in tasks.items() if t.kind == "track"}
    assert slots == {"track:5": 10.0, "track:5#1": 5.0, "track:5#2": pytest.approx(10.0 / 3)}
    assert [slot_of(k) for k in sorted(slots)] == [("track:5", 0), ("track:5", 1), ("track:5", 2)]


@pytest.mark.parametrize("value, why", [(0, "no slot at all"), (2.5, "half a vehicle")])
def test_a_bad_slot_count_is_refused(value, why):
    with pytest.raises(ValueError, match="orbit_slots"):
        AssignmentConfig(orbit_slots=value)


def test_slot_count_must_be_an_integer_in_the_scenario():
    with pytest.raises(ValueError, match="wrong type"):
        check_tasking({"planner": "assignment", "orbit_slots": 2.0})


def test_three_agents_share_one_target_and_know_their_partners():
    """Each knows the target under its own id; after a few rounds all three hold a slot of it, and each sees
    the other two as partners (who won the other slots)."""
    agents = [_exchange(me, position, [(tid, np.array([0.0, 0.0]))], orbit_slots=3)
              for me, position, tid in (("a", (-40.0, 0.0), 1), ("b", (0.0, 40.0), 7), ("c", (40.0, 0.0), 3))]
    for step in range(12):
        for i, x in enumerate(agents):
            for y in agents[i + 1:]:
                _talk(x, y, 0.2 * step)
    for agent in agents:
        view = agent.view()
        assert view.task is not None and view.task.kind == "track"
        assert sorted(view.partners) == sorted({"a", "b", "c"} - {agent.me})
    assert len({slot_of(a.view().task.key)[1] for a in agents}) == 3  # three different slots


def test_a_slot_beyond_the_fleets_count_is_refused():
    a = _exchange("a", (0.0, 0.0), [(1, np.array([0.0, 0.0]))], orbit_slots=2)
    good = {"at": (0.0, 0.0), "stamps": {"b": 0.1}, "tasks": [["track#1", 0.0, 0.0, "b", 5.0]]}
    a.settle(0.2)
    a.receive("b", 1, 0.1, good, None, 0.2)
    assert a.cbba.winners.get("track:1#1") in ("a", "b")
    bad = {"at": (0.0, 0.0), "stamps": {"b": 0.2}, "tasks": [["track#2", 0.0, 0.0, "b", 5.0]]}  # slot 2 of 2
    with pytest.raises(wire.DecodeError) as err:
        a.receive("b", 2, 0.2, bad, None, 0.4)
    assert err.value.reason == "bad_field"


def _spaced_goal(own_deg, partners_deg, centre_velocity=(0.0, 0.0), radius=30.0):
    planner = AssignmentPlanner(AssignmentConfig(orbit_slots=3, orbit_radius=radius, min_separation=0.0), AREA, 40.0,
                                0.2, 13.0)  # no separation layer: its goal would replace the spaced one

    def on_circle(deg):
        return radius * np.array([math.cos(math.radians(deg)), math.sin(math.radians(deg))])

    partners = {f"p{i}": on_circle(d) for i, d in enumerate(partners_deg)}
    view = AssignmentView(Task("track:4#1", [0.0, 0.0], 5.0), False, np.zeros(2), partners, partners)
    tracks = TrackView([(4, np.zeros(2))], {4: np.asarray(centre_velocity, float)})
    own = on_circle(own_deg)
    return planner.plan(_State([*own, -40.0]), {"tasks": view, "track": tracks}), own


def test_the_set_point_is_on_the_circle_with_the_spacing_rate():
    """At phase 0 with the neighbour ahead at 150 deg and the one behind at 240 deg, 004's law gives
    θ̇ = ω + kθ (g⁺ - g⁻)/2 with g⁺ = 150°, g⁻ = 120° and the nominal ω = min(ω0, θ̇_max / 2), θ̇_max = (13 m/s -
    |ṗ̂|) / r (the speed the centre's motion leaves); the set-point is the vehicle's own point of the circle and
    the feed-forward is the centre's velocity plus r θ̇ along the tangent (east at phase 0)."""
    goal, own = _spaced_goal(0.0, [150.0, 240.0], centre_velocity=(2.0, -1.0))
    nominal = min(OMEGA_0, (13.0 - math.hypot(2.0, -1.0)) / 30.0 / 2)
    rate = nominal + K_THETA * (math.radians(150.0) - math.radians(120.0)) / 2
    assert goal.orbit_center is None and goal.position[:2] == pytest.approx(own)
    assert goal.position[2] == -40.0
    assert goal.velocity == pytest.approx([2.0, -1.0 + 30.0 * rate])


def test_a_vehicle_close_behind_its_neighbour_slows_and_one_far_behind_speeds_up():
    close, _ = _spaced_goal(0.0, [20.0, 200.0])
    far, _ = _spaced_goal(0.0, [170.0, 200.0])
    assert close.velocity[1] < far.velocity[1]
    assert close.velocity[1] >= 0.0  # never backwards: the rate is clipped at 0


def test_alone_on_its_target_a_vehicle_flies_the_plain_orbit():
    planner = AssignmentPlanner(AssignmentConfig(orbit_slots=3), AREA, 40.0)
    view = AssignmentView(Task("track:4", [10.0, 0.0], 10.0), False, np.zeros(2), {}, {})
    goal = planner.plan(_State([0.0, 0.0, -40.0]), {"tasks": view, "track": TrackView([(4, np.zeros(2))])})
    assert goal.is_orbit and goal.velocity is None
