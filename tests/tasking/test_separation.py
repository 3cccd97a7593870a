"""tasking.separation: the barrier potential in closed form, the reciprocal hard guarantee on crossing swarms,
head-on resolution, no effect from afar, and bad inputs."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import minimize

from tasking.separation import SeparationLayer, fly_swarm, separation_stats

D_MIN, V_MAX, DT = 5.0, 10.0, 0.1


def closest_approach_within_steps(trajectory: np.ndarray) -> float:
    """Brute-force oracle: the smallest pairwise distance over the run, including *between* samples, where
    each pair moves linearly: min over s in [0, 1] of |a + s b| with a the offset, b its change over the step."""
    n = trajectory.shape[1]
    best = math.inf
    for i in range(n):
        for j in range(i + 1, n):
            a = trajectory[:-1, i] - trajectory[:-1, j]
            b = (trajectory[1:, i] - trajectory[1:, j]) - a
            bb = np.sum(b * b, axis=1)
            s = np.clip(-np.sum(a * b, axis=1) / np.where(bb > 0, bb, 1.0), 0.0, 1.0)
            best = min(best, float(np.min(np.linalg.norm(a + s[:, None] * b, axis=1))))
    return best


def spread_points(rng: np.random.Generator, n: int, radius: float, spacing: float) -> np.ndarray:
    """n points in a disc, pairwise at least ``spacing`` apart (rejection sampling)."""
    points: list[np.ndarray] = []
    while len(points) < n:
        p = rng.uniform(-radius, radius, 2)
        if np.linalg.norm(p) <= radius and all(np.linalg.norm(p - q) >= spacing for q in points):
            points.append(p)
    return np.array(points)


# -- the potential ---------------------------------------------------------------------------------------
def test_potential_matches_the_barrier_formula_and_vanishes_from_the_influence_radius_on():
    layer = SeparationLayer(d_min=D_MIN, max_speed=V_MAX, influence_radius=12.0, gain=0.7)
    k = 2 * 0.7 * V_MAX * ((12.0 - D_MIN) / 2) ** 3  # k = 2 gain v_max δ^3
    assert layer.potential_gain == pytest.approx(k, rel=1e-14)
    d = np.array([5.5, 7.0, 9.0, 11.9])
    expected = 0.5 * k * (1 / (d - D_MIN) - 1 / (12.0 - D_MIN)) ** 2
    np.testing.assert_allclose(layer.potential(d), expected, rtol=1e-14)
    np.testing.assert_array_equal(layer.potential([12.0, 30.0]), [0.0, 0.0])
    np.testing.assert_array_equal(layer.potential([5.0, 1.0]), [np.inf, np.inf])
    # unbounded towards d_min, C1 at R (U and U' -> 0)
    assert layer.potential(D_MIN + 1e-6) > 1e12 * layer.potential(9.0)
    assert abs(layer.potential_derivative(12.0 - 1e-7)) < 1e-6 and layer.potential(12.0 - 1e-7) < 1e-12


def test_the_repulsion_halfway_through_the_band_is_gain_times_max_speed():
    layer = SeparationLayer(d_min=D_MIN, max_speed=V_MAX, gain=0.4)  # R = 2 d_min
    assert -layer.potential_derivative(1.5 * D_MIN) == pytest.approx(0.4 * V_MAX, rel=1e-12)


def test_potential_derivative_and_gradient_match_finite_differences():
    layer = SeparationLayer(d_min=D_MIN, max_speed=V_MAX, influence_radius=15.0)
    d = np.linspace(5.3, 14.7, 25)
    h = 1e-6
    fd = (layer.potential(d + h) - layer.potential(d - h)) / (2 * h)
    np.testing.assert_allclose(layer.potential_derivative(d), fd, rtol=1e-6)

    own = np.array([1.0, -2.0, 0.5])
    neighbours = np.array([[7.0, 1.0, 0.0], [-4.0, -6.0, 2.0], [2.0, 6.0, -3.0], [40.0, 0.0, 0.0]])

    def total(p):
        return float(np.sum(layer.potential(np.linalg.norm(p - neighbours, axis=1))))

    numeric = np.array([(total(own + h * e) - total(own - h * e)) / (2 * h) for e in np.eye(3)])
    np.testing.assert_allclose(layer.gradient(own, neighbours), numeric, rtol=1e-6)


# -- the hard projection -----------------------------------------------------------------------------------
def projection_only_layer() -> SeparationLayer:
    """A layer whose potential band is negligible, so only the hard projection acts beyond 1.0001 d_min."""
    return SeparationLayer(d_min=D_MIN, max_speed=V_MAX, influence_radius=D_MIN * 1.0001)


def test_one_neighbour_in_the_guard_band_caps_the_closing_speed_and_keeps_the_sideways_part():
    layer = projection_only_layer()
    d = D_MIN + 1.0  # inside the guard band d_min + 2 v_max dt = d_min + 2 m
    command = np.array([6.0, 8.0])  # 6 m/s closing, 8 m/s sideways
    v = layer.adjust([0.0, 0.0], command, [[d, 0.0]], DT)
    assert v[0] == pytest.approx((d - D_MIN) / (2 * DT), rel=1e-12)  # closing speed = s = (d - d_min) / (2 dt)
    assert v[1] == 8.0


def test_several_neighbours_give_the_euclidean_projection_onto_the_half_spaces():
    layer = projection_only_layer()
    own = np.array([0.0, 0.0])
    neighbours = np.array([[6.0, 0.0], [0.0, 6.2], [4.3, 4.3], [-6.5, 0.5]])
    command = np.array([7.0, 7.0])
    v = layer.adjust(own, command, neighbours, DT)
    normals = (own - neighbours) / np.linalg.norm(own - neighbours, axis=1)[:, None]
    slack = (np.linalg.norm(own - neighbours, axis=1) - D_MIN) / (2 * DT)
    oracle = minimize(lambda x: np.sum((x - command) ** 2), np.zeros(2), jac=lambda x: 2 * (x - command),
                      constraints=[{"type": "ineq", "fun": lambda x: normals @ x + slack, "jac": lambda x: normals}],
                      method="SLSQP", options={"ftol": 1e-14})
    np.testing.assert_allclose(v, oracle.x, atol=1e-6)
    assert np.all(normals @ v >= -slack - 1e-12)


def test_far_apart_the_command_is_returned_unchanged():
    layer = SeparationLayer(d_min=D_MIN, max_speed=V_MAX)
    command = np.array([3.0, -9.0])
    reach = max(layer.influence_radius, D_MIN + 2 * V_MAX * DT)
    neighbours = np.array([[reach + 0.01, 0.0], [0.0, -reach - 0.01], [-50.0, 20.0]])
    np.testing.assert_array_equal(layer.adjust([0.0, 0.0], command, neighbours, DT), command)
    np.testing.assert_array_equal(layer.adjust([0.0, 0.0], command, np.zeros((0, 2)), DT), command)


def test_a_command_above_max_speed_is_clipped_to_it():
    layer = SeparationLayer(d_min=D_MIN, max_speed=V_MAX)
    np.testing.assert_allclose(layer.adjust([0.0, 0.0], [30.0, 40.0], [], DT), [6.0, 8.0], rtol=1e-14)


# -- swarms ----------------------------------------------------------------------------------------------------
@settings(max_examples=25, deadline=None)
@given(n=st.integers(2, 8), seed=st.integers(0, 2**32 - 1), dt=st.sampled_from([0.05, 0.1, 0.2]),
       d_min=st.floats(2.0, 8.0))
def test_a_crossing_swarm_at_max_speed_never_comes_closer_than_d_min(n, seed, dt, d_min):
    """Agents start on a disc, at least d_min apart, and fly at max speed to goals across it (through each
    other); all apply the layer with the same step. The oracle includes the motion between samples."""
    rng = np.random.default_rng(seed)
    radius = 40.0
    starts = spread_points(rng, n, radius, d_min)
    goals = -starts + rng.normal(0.0, 3.0, starts.shape)
    layer = SeparationLayer(d_min=d_min, max_speed=V_MAX)
    steps = int(2.5 * 2 * radius / V_MAX / dt)
    trajectory = fly_swarm(starts, goals, V_MAX, dt, steps, layer)
    assert closest_approach_within_steps(trajectory) >= d_min
    speeds = np.linalg.norm(np.diff(trajectory, axis=0), axis=2) / dt
    assert speeds.max() <= V_MAX * (1 + 1e-12)


def test_without_the_layer_the_same_kind_of_swarm_collides():
    rng = np.random.default_rng(3)
    starts = spread_points(rng, 8, 40.0, D_MIN)
    goals = -starts
    trajectory = fly_swarm(starts, goals, V_MAX, DT, 100)
    assert separation_stats(trajectory, D_MIN).violations > 0


@pytest.mark.parametrize("dim", [2, 3])
def test_a_head_on_pair_passes_and_both_reach_their_goals(dim):
    starts = np.zeros((2, dim))
    starts[1, 0] = 100.0
    goals = starts[::-1].copy()
    layer = SeparationLayer(d_min=D_MIN, max_speed=V_MAX)
    straight_time = 100.0 / V_MAX
    steps = int(2 * straight_time / DT)  # within twice the undisturbed flight time
    trajectory = fly_swarm(starts, goals, V_MAX, DT, steps, layer)
    assert np.all(np.linalg.norm(trajectory[-1] - goals, axis=1) < 0.1)
    assert separation_stats(trajectory, D_MIN).min_separation >= D_MIN
    # they passed: their order along the line of travel swapped
    assert trajectory[-1, 0, 0] > trajectory[-1, 1, 0]


def test_four_agents_swapping_corners_pass_around_each_other():
    starts = np.array([[50.0, 0.0], [0.0, 50.0], [-50.0, 0.0], [0.0, -50.0]])
    goals = -starts
    layer = SeparationLayer(d_min=D_MIN, max_speed=V_MAX)
    trajectory = fly_swarm(starts, goals, V_MAX, DT, int(3 * 100.0 / V_MAX / DT), layer)
    assert np.all(np.linalg.norm(trajectory[-1] - goals, axis=1) < 0.1)
    assert separation_stats(trajectory, D_MIN).min_separation >= D_MIN


# -- the metric ----------------------------------------------------------------------------------------------
def test_separation_stats_against_a_hand_made_run():
    trajectory = np.array([
        [[0.0, 0.0], [10.0, 0.0], [0.0, 10.0]],
        [[0.0, 0.0], [4.0, 0.0], [0.0, 3.0]],  # pairs at 4 and 3 (two violations) and 5
        [[0.0, 0.0], [6.0, 0.0], [0.0, 7.0]],
    ])
    stats = separation_stats(trajectory, 4.5)
    assert stats.min_separation == pytest.approx(3.0)
    assert stats.violations == 2


# -- bad inputs -------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("d_min", [0.0, -1.0, math.nan, math.inf])
def test_a_non_positive_or_non_finite_d_min_is_rejected(d_min):
    with pytest.raises(ValueError, match="d_min"):
        SeparationLayer(d_min=d_min, max_speed=V_MAX)
    with pytest.raises(ValueError, match="d_min"):
        separation_stats(np.zeros((2, 2, 2)), d_min)


def test_an_influence_radius_not_beyond_d_min_is_rejected():
    with pytest.raises(ValueError, match="influence_radius"):
        SeparationLayer(d_min=D_MIN, max_speed=V_MAX, influence_radius=D_MIN)


@pytest.mark.parametrize(
    ("own", "command", "neighbours", "dt", "match"),
    [
        ([math.nan, 0.0], [1.0, 0.0], [[10.0, 0.0]], DT, "own_position"),  # NaN own position
        ([0.0, 0.0], [1.0, 0.0], [[math.nan, 0.0]], DT, "neighbours"),  # NaN neighbour position
        ([0.0, 0.0], [math.inf, 0.0], [[10.0, 0.0]], DT, "own_velocity_cmd"),  # infinite command
        ([0.0, 0.0], [1.0, 0.0], [[10.0, 0.0, 0.0]], DT, "neighbours"),  # 3-D neighbour, 2-D own position
        ([0.0, 0.0], [1.0, 0.0], [[10.0, 0.0]], 0.0, "dt"),  # zero step
        ([0.0, 0.0], [1.0, 0.0], [[0.0, 0.0]], DT, "coincides"),  # neighbour at the own position
    ],
)
def test_bad_adjust_inputs_are_rejected(own, command, neighbours, dt, match):
    layer = SeparationLayer(d_min=D_MIN, max_speed=V_MAX)
    with pytest.raises(ValueError, match=match):
        layer.adjust(own, command, neighbours, dt)


def test_a_nan_trajectory_is_rejected():
    trajectory = np.zeros((3, 2, 2))
    trajectory[1, 0, 0] = math.nan
    with pytest.raises(ValueError, match="non-finite"):
        separation_stats(trajectory, D_MIN)
