"""Placeholder tasking: lawnmower coverage and lanes, waypoint cycling, talk-free target choice, planner modes."""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tasking.orbit import Goal, choose_target, goto_goal, orbit_setpoint
from tasking.planner import PlaceholderPlanner
from tasking.search import RandomPatrol, WaypointFollower, lane_area, lawnmower_waypoints


def distance_to_path(points: np.ndarray, path: np.ndarray) -> np.ndarray:
    """Horizontal distance from each of ``points`` (P, 2) to the polyline ``path`` (K, >=2)."""
    path = path[:, :2]
    if len(path) == 1:
        return np.linalg.norm(points - path[0], axis=1)
    a, b = path[:-1], path[1:]
    ab = b - a
    length2 = np.maximum(np.sum(ab * ab, axis=1), 1e-300)
    ap = points[:, None, :] - a[None, :, :]
    s = np.clip(np.sum(ap * ab[None], axis=2) / length2[None], 0.0, 1.0)
    closest = a[None] + s[..., None] * ab[None]
    return np.min(np.linalg.norm(points[:, None, :] - closest, axis=2), axis=1)


def grid(area, n: int = 41) -> np.ndarray:
    north = np.linspace(area[0], area[1], n)
    east = np.linspace(area[2], area[3], n)
    nn, ee = np.meshgrid(north, east, indexing="ij")
    return np.column_stack([nn.ravel(), ee.ravel()])


areas = st.tuples(st.floats(-500.0, 500.0), st.floats(1.0, 400.0), st.floats(-500.0, 500.0), st.floats(1.0, 400.0)).map(
    lambda a: (a[0], a[0] + a[1], a[2], a[2] + a[3])
)


@settings(max_examples=60, deadline=None)
@given(area=areas, spacing=st.floats(2.0, 150.0), altitude=st.floats(5.0, 120.0))
def test_lawnmower_covers_the_area(area, spacing, altitude):
    path = lawnmower_waypoints(area, spacing, altitude)
    assert path.shape[1] == 3
    np.testing.assert_allclose(path[:, 2], -altitude)
    assert np.all(distance_to_path(grid(area), path) <= spacing / 2 + 1e-9)
    # waypoints stay inside the area, legs run north-south and alternate direction
    assert np.all((path[:, 0] >= area[0]) & (path[:, 0] <= area[1]))
    assert np.all((path[:, 1] >= area[2]) & (path[:, 1] <= area[3]))
    legs = path.reshape(-1, 2, 3)
    np.testing.assert_allclose(legs[:, 0, 1], legs[:, 1, 1])
    assert np.all(np.sign(legs[:, 1, 0] - legs[:, 0, 0]) == [(-1) ** i for i in range(len(legs))])


def test_lawnmower_hand_checked_case():
    path = lawnmower_waypoints((0.0, 100.0, 0.0, 40.0), spacing=20.0, altitude=30.0)
    expected = [(0, 10, -30), (100, 10, -30), (100, 30, -30), (0, 30, -30)]
    np.testing.assert_allclose(path, expected)


@settings(max_examples=40, deadline=None)
@given(area=areas, spacing=st.floats(2.0, 100.0), lanes=st.integers(1, 7))
def test_lanes_partition_the_area(area, spacing, lanes):
    strips = [lane_area(area, k, lanes) for k in range(lanes)]
    assert strips[0][2] == area[2] and strips[-1][3] == area[3]
    for left, right in zip(strips, strips[1:], strict=False):
        assert left[3] == right[2]  # contiguous, no gap and no overlap
    for strip in strips:
        assert strip[:2] == area[:2] and strip[2] < strip[3]
    points = grid(area)
    inside = np.array([(points[:, 1] >= s[2]) & (points[:, 1] <= s[3]) for s in strips])
    strictly = np.array([(points[:, 1] > s[2]) & (points[:, 1] < s[3]) for s in strips])
    assert np.all(inside.sum(axis=0) >= 1)  # every point belongs to a lane
    assert np.all(strictly.sum(axis=0) <= 1)  # lanes share at most their boundary
    for k, strip in enumerate(strips):
        path = lawnmower_waypoints(area, spacing, 50.0, lane_index=k, lanes=lanes)
        assert np.all((path[:, 1] >= strip[2] - 1e-9) & (path[:, 1] <= strip[3] + 1e-9))
        mine = points[inside[k]]
        assert np.all(distance_to_path(mine, path) <= spacing / 2 + 1e-9)


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: lawnmower_waypoints((0, 0, 0, 10), 5.0, 10.0), "area"),
        (lambda: lawnmower_waypoints((0, 10, 0, 10, 3), 5.0, 10.0), "area"),
        (lambda: lawnmower_waypoints((0, 10, 0, 10), 0.0, 10.0), "spacing"),
        (lambda: lawnmower_waypoints((0, 10, 0, 10), 5.0, float("nan")), "altitude"),
        (lambda: lawnmower_waypoints((0, 10, 0, 10), 5.0, 10.0, lane_index=2, lanes=2), "lane_index"),
        (lambda: lawnmower_waypoints((0, 10, 0, 10), 5.0, 10.0, lanes=0), "lanes"),
        (lambda: WaypointFollower(np.zeros((0, 3)), 1.0), "waypoints"),
        (lambda: WaypointFollower([[0.0, 0.0]], 0.0), "acceptance_radius"),
        (lambda: RandomPatrol((5, 1, 0, 1)), "area"),
    ],
)
def test_search_input_errors(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_waypoint_follower_cycles():
    waypoints = np.array([[0.0, 0.0, -10.0], [100.0, 0.0, -10.0], [100.0, 50.0, -10.0]])
    follower = WaypointFollower(waypoints, acceptance_radius=2.0)
    far = np.array([-500.0, -500.0, -10.0])
    np.testing.assert_allclose(follower.current(far), waypoints[0])
    np.testing.assert_allclose(follower.current(far), waypoints[0])  # not reached: holds
    visited = []
    position = far
    for _ in range(7):
        target = follower.current(position)
        visited.append(follower.index)
        position = target + np.array([1.0, -1.0, 30.0])  # within 2 m horizontally, altitude ignored
    assert visited == [0, 1, 2, 0, 1, 2, 0]
    assert follower.laps == 2
    # a radius that covers every waypoint cannot loop forever: at most one cycle per call
    greedy = WaypointFollower(waypoints, acceptance_radius=1e4)
    greedy.current(far)
    assert greedy.laps == 1 and greedy.index == 0


def test_random_patrol_is_reproducible_and_inside():
    area = (-100.0, 100.0, -100.0, 100.0)
    first, second = RandomPatrol(area, seed=3), RandomPatrol(area, seed=3)
    points = np.array([first.next_point() for _ in range(200)])
    np.testing.assert_array_equal(points, [second.next_point() for _ in range(200)])
    assert np.all(np.abs(points) <= 100.0)
    assert not np.array_equal(points, [RandomPatrol(area, seed=4).next_point() for _ in range(200)])


def test_goals_and_orbit_setpoint():
    goal = orbit_setpoint([10.0, -5.0], radius=15.0, altitude=30.0, direction=-1, speed=6.0)
    assert goal.is_orbit
    np.testing.assert_allclose(goal.position, [10.0, -5.0, -30.0])
    np.testing.assert_allclose(goal.orbit_center, [10.0, -5.0])
    assert (goal.orbit_radius, goal.orbit_direction, goal.speed) == (15.0, -1, 6.0)
    goal = goto_goal([1.0, 2.0], altitude=20.0)
    assert not goal.is_orbit and goal.orbit_radius is None
    np.testing.assert_allclose(goal.position, [1.0, 2.0, -20.0])
    with pytest.raises(ValueError, match="orbit_radius"):
        orbit_setpoint([0.0, 0.0], radius=0.0, altitude=10.0)
    with pytest.raises(ValueError, match="orbit_direction"):
        orbit_setpoint([0.0, 0.0], radius=5.0, altitude=10.0, direction=2)
    with pytest.raises(ValueError, match="orbit_center"):
        Goal(position=[0.0, 0.0, 0.0], orbit_radius=5.0)


positions = st.tuples(st.floats(-1e3, 1e3), st.floats(-1e3, 1e3))


@settings(max_examples=60, deadline=None)
@given(
    n_agents=st.integers(1, 12),
    targets=st.lists(positions, min_size=1, max_size=6, unique_by=lambda p: p[0]),
    data=st.data(),
)
def test_choose_target_is_deterministic_and_spreads_agents(n_agents, targets, data):
    tracks = [(f"track-{i}", np.array([north, east, 0.0])) for i, (north, east) in enumerate(targets)]
    shuffled = data.draw(st.permutations(tracks))
    choices = [choose_target(k, tracks)[0] for k in range(n_agents)]
    # every agent sorting the same estimates, in whatever order they arrived, makes the same choice
    assert choices == [choose_target(k, shuffled)[0] for k in range(n_agents)]
    counts = Counter(choices)
    m = len(tracks)
    assigned = [counts.get(track_id, 0) for track_id, _ in tracks]
    assert sum(assigned) == n_agents
    assert all(n_agents // m <= c <= math.ceil(n_agents / m) for c in assigned)


def test_choose_target_hand_checked_order_and_errors():
    tracks = [("b", (5.0, 0.0)), ("a", (-3.0, 9.0)), ("c", (-3.0, 1.0))]
    assert [choose_target(k, tracks)[0] for k in range(4)] == ["c", "a", "b", "c"]
    np.testing.assert_allclose(choose_target(1, tracks)[1], [-3.0, 9.0])
    assert choose_target(0, []) is None
    with pytest.raises(ValueError, match="agent_index"):
        choose_target(-1, tracks)
    with pytest.raises(ValueError, match="track"):
        choose_target(0, [("x", (float("nan"), 0.0))])


AREA = (0.0, 200.0, 0.0, 200.0)


def test_planner_switches_from_search_to_orbit_and_back():
    planner = PlaceholderPlanner(1, 3, AREA, altitude=30.0, search="lawnmower", spacing=20.0, orbit_radius=15.0)
    lane = lane_area(AREA, 1, 3)
    position = np.array([0.0, 0.0, -30.0])
    goal = planner.goal_for(position, [])
    assert planner.mode == "search" and planner.target_id is None and not goal.is_orbit
    assert lane[2] <= goal.position[1] <= lane[3] and goal.position[2] == -30.0
    # fly the lane for a few waypoints
    for _ in range(3):
        position = goal.position.copy()
        goal = planner.goal_for(position, [])
    resume = goal.position.copy()
    tracks = [(7, np.array([150.0, 40.0, 0.0])), (3, np.array([20.0, 120.0, 0.0]))]
    goal = planner.goal_for(position, tracks)
    assert planner.mode == "orbit" and planner.target_id == 7  # sorted by north: [3, 7]; agent 1 -> 7
    assert goal.is_orbit and goal.orbit_radius == 15.0
    np.testing.assert_allclose(goal.orbit_center, [150.0, 40.0])
    np.testing.assert_allclose(goal.position, [150.0, 40.0, -30.0])
    # the orbit follows the fused estimate
    goal = planner.goal_for(position, [(7, np.array([152.0, 41.0, 0.0])), tracks[1]])
    np.testing.assert_allclose(goal.orbit_center, [152.0, 41.0])
    # tracks gone: back to searching, from where the search was left
    goal = planner.goal_for(np.array([150.0, 40.0, -30.0]), [])
    assert planner.mode == "search" and planner.target_id is None and not goal.is_orbit
    np.testing.assert_allclose(goal.position, resume)


def test_planner_lanes_cover_the_area_together():
    n = 4
    for k in range(n):
        planner = PlaceholderPlanner(k, n, AREA, altitude=25.0, spacing=25.0)
        lane = lane_area(AREA, k, n)
        position = np.array([100.0, 100.0, -25.0])
        for _ in range(10):
            goal = planner.goal_for(position, [])
            assert lane[2] <= goal.position[1] <= lane[3]
            position = goal.position


def test_planner_patrol_moves_point_to_point():
    planner = PlaceholderPlanner(0, 2, AREA, altitude=20.0, search="patrol", spacing=20.0, seed=5)
    other = PlaceholderPlanner(1, 2, AREA, altitude=20.0, search="patrol", spacing=20.0, seed=5)
    start = np.array([-1000.0, -1000.0, -20.0])
    first = planner.goal_for(start, []).position
    assert not np.allclose(first, other.goal_for(start, []).position)  # agents patrol differently
    np.testing.assert_allclose(planner.goal_for(start, []).position, first)  # holds until reached
    second = planner.goal_for(first, []).position  # reached: a new point
    assert not np.allclose(first, second)
    for point in (first, second):
        assert 0.0 <= point[0] <= 200.0 and 0.0 <= point[1] <= 200.0 and point[2] == -20.0
    again = PlaceholderPlanner(0, 2, AREA, altitude=20.0, search="patrol", spacing=20.0, seed=5)
    np.testing.assert_allclose(again.goal_for(start, []).position, first)  # reproducible


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"agent_index": 3, "n_agents": 3}, "agent_index"),
        ({"n_agents": 0}, "n_agents"),
        ({"search": "spiral"}, "search"),
        ({"spacing": -1.0}, "spacing"),
        ({"orbit_radius": 0.0}, "orbit_radius"),
        ({"area": (0, 10, 10, 0)}, "area"),
        ({"acceptance_radius": 0.0}, "acceptance_radius"),
    ],
)
def test_planner_input_errors(kwargs, match):
    arguments = {"agent_index": 0, "n_agents": 2, "area": AREA, "altitude": 30.0} | kwargs
    with pytest.raises(ValueError, match=match):
        PlaceholderPlanner(**arguments)
