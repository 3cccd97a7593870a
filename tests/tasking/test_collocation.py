"""tasking.collocation: Hermite–Simpson defects against closed forms, the bearing information against a numerical
Jacobian, analytic derivatives against finite differences, constraint satisfaction, the stand-off behaviour,
warm starts, the receding horizon, bad inputs; and a smoke run of the benchmark."""

from __future__ import annotations

import io
import math

import numpy as np
import pytest
from rich.console import Console
from scipy.optimize import approx_fprime

from mesh_sim.bench import tasking_paths
from tasking.collocation import (
    CollocationProblem,
    PlannerConfig,
    RecedingHorizonPlanner,
    VehicleLimits,
    accumulated_information,
    bearing_information,
    cold_guess,
    hermite_midpoints,
    hermite_simpson_defects,
    plan,
    unicycle_state,
)

FW, MR, CFG = VehicleLimits.fixed_wing(), VehicleLimits.multirotor(), PlannerConfig()
ORIGIN = np.zeros(2)


@pytest.fixture(scope="module", autouse=True)
def one_blas_thread():
    """SLSQP's BLAS on one thread, as in an agent process (see mesh_sim.bench.tasking_paths)."""
    with tasking_paths.scipy_blas_threads(1):
        yield


# -- Hermite–Simpson defects ---------------------------------------------------------------------------------------
def test_defects_vanish_for_a_straight_path_with_constant_acceleration():
    """n, e are quadratic in t, V linear, ψ constant: the cubic Hermite represents them exactly."""
    t = np.linspace(0.0, 20.0, 7)
    psi, v0, a, wind = 0.7, 12.0, 0.4, np.array([1.5, -2.0])
    along = v0 * t + 0.5 * a * t**2
    states = np.column_stack([3.0 + along * math.cos(psi) + wind[0] * t, -4.0 + along * math.sin(psi) + wind[1] * t,
                              np.full_like(t, psi), v0 + a * t])
    controls = np.column_stack([np.full_like(t, a), np.zeros_like(t)])
    np.testing.assert_allclose(hermite_simpson_defects(states, controls, t[1] - t[0], wind), 0.0, atol=1e-12)


def arc(step: float, nodes: int = 7, speed: float = 15.0, omega: float = 0.3, psi0: float = 0.4, wind=(0.0, 0.0)):
    """A constant-turn arc sampled analytically at the nodes: ψ = ψ0 + ω t, n = (V/ω)(sin ψ - sin ψ0) + w_n t, ..."""
    t = step * np.arange(nodes, dtype=float)
    psi = psi0 + omega * t
    states = np.column_stack([speed / omega * (np.sin(psi) - math.sin(psi0)) + wind[0] * t,
                              -speed / omega * (np.cos(psi) - math.cos(psi0)) + wind[1] * t,
                              psi, np.full_like(t, speed)])
    controls = np.column_stack([np.zeros_like(t), np.full_like(t, omega)])
    return states, controls


@pytest.mark.parametrize("wind", [(0.0, 0.0), (2.0, -3.0)])
def test_defects_of_a_constant_turn_arc_match_the_closed_form(wind):
    """With θ = ω τ / 2 and ψ_m the mid-segment heading, derived by hand from the midpoint formulas:
    Δ_(n, e) = V (1 + cos θ / 2 - 3 sin θ / (2 θ)) (cos ψ_m, sin ψ_m) = V θ^4 / 120 + O(θ^6); Δ_ψ = Δ_V = 0."""
    speed, omega, step = 15.0, 0.3, 20.0 / 6
    states, controls = arc(step, speed=speed, omega=omega, wind=wind)
    defects = hermite_simpson_defects(states, controls, step, np.array(wind))
    theta = omega * step / 2
    psi_mid = 0.5 * (states[:-1, 2] + states[1:, 2])
    magnitude = speed * (1 + math.cos(theta) / 2 - 1.5 * math.sin(theta) / theta)
    np.testing.assert_allclose(defects[:, 0], magnitude * np.cos(psi_mid), rtol=1e-6, atol=1e-13)
    np.testing.assert_allclose(defects[:, 1], magnitude * np.sin(psi_mid), rtol=1e-6, atol=1e-13)
    np.testing.assert_allclose(defects[:, 2:], 0.0, atol=1e-13)
    assert magnitude == pytest.approx(speed * theta**4 / 120, rel=theta**2)


def test_arc_defects_vanish_at_fourth_order_in_the_step():
    norms = []
    for step in (0.5, 0.25, 0.125):
        states, controls = arc(step, nodes=2)
        norms.append(np.linalg.norm(hermite_simpson_defects(states, controls, step)))
    assert norms[0] / norms[1] == pytest.approx(16.0, rel=0.01)
    assert norms[1] / norms[2] == pytest.approx(16.0, rel=0.01)


# -- the bearing information ---------------------------------------------------------------------------------------
def test_at_zero_altitude_the_information_is_the_2d_bearing_form():
    vehicle, target, sigma = np.array([3.0, -1.0]), np.array([-5.0, 7.0]), 0.02
    delta = target - vehicle
    rho2 = delta @ delta
    perp = np.array([-delta[1], delta[0]]) / math.sqrt(rho2)
    np.testing.assert_allclose(bearing_information(vehicle, target, sigma, 0.0),
                               np.outer(perp, perp) / (sigma**2 * rho2), rtol=1e-13)


@pytest.mark.parametrize("offset", [(40.0, -25.0), (0.0, 0.0), (-120.0, 5.0)])
def test_the_information_is_that_of_a_3d_line_of_sight_with_isotropic_angular_noise(offset):
    """Oracle: (1/σ^2) Gᵀ G with G = ∂ℓ/∂(target n, e) of the unit line of sight ℓ, by central differences."""
    sigma, height = 0.01, 60.0
    vehicle = np.array([10.0, 20.0])
    target = vehicle + np.array(offset)

    def line_of_sight(t):
        v = np.array([t[0] - vehicle[0], t[1] - vehicle[1], height])
        return v / np.linalg.norm(v)

    h = 1e-5
    g = np.column_stack([(line_of_sight(target + h * e) - line_of_sight(target - h * e)) / (2 * h) for e in np.eye(2)])
    np.testing.assert_allclose(bearing_information(vehicle, target, sigma, height), g.T @ g / sigma**2, rtol=1e-7)


def test_accumulated_information_is_the_rate_times_the_sum():
    path = np.array([[0.0, 50.0], [30.0, 40.0], [50.0, 0.0]])
    expected = sum(bearing_information(p, ORIGIN, CFG.bearing_sigma, CFG.altitude) for p in path) * 4.0 * 0.25
    np.testing.assert_allclose(accumulated_information(path, ORIGIN, 0.25, CFG), expected, rtol=1e-14)


# -- derivatives ---------------------------------------------------------------------------------------------------
def test_analytic_derivatives_match_finite_differences():
    problem = CollocationProblem([-150.0, 20.0, 0.3, 17.0], [[0.0, 0.0], [30.0, 10.0]], [[1.0, 0.5], [0.0, 0.0]],
                                 FW, CFG, wind=(1.0, -2.0))
    states, controls = cold_guess(problem.x0, FW, CFG)
    z = problem.pack(states, controls) + np.random.default_rng(0).normal(0.0, 0.3, 6 * 4 + 7 * 2)
    grad = problem.objective(z)[1]
    np.testing.assert_allclose(grad, approx_fprime(z, lambda x: problem.objective(x)[0], 1e-6), atol=2e-6)
    pairs = ((problem.defects, problem.defects_jacobian), (problem.limit_margins, problem.limit_margins_jacobian))
    for fun, jac in pairs:
        numeric = np.array([approx_fprime(z, lambda x, i=i, f=fun: f(x)[i], 1e-7) for i in range(len(fun(z)))])
        np.testing.assert_allclose(jac(z), numeric, atol=2e-6)


# -- solutions -----------------------------------------------------------------------------------------------------
START_STATES = [(-150.0, 40.0, 0.2), (30.0, 20.0, 2.5), (200.0, -100.0, -1.0)]


@pytest.mark.parametrize("limits", [FW, MR], ids=["fixed wing", "multirotor"])
@pytest.mark.parametrize("start", START_STATES)
def test_a_plan_satisfies_the_defects_and_every_limit(limits, start):
    state = np.array([*start, 0.5 * (limits.min_speed + limits.max_speed)])
    result = plan(state, [10.0, -5.0], [1.0, 0.0], limits, CFG)
    assert result.success and result.max_defect < 1e-4
    speed, (accel, turn) = result.states[:, 3], result.controls.T
    tol = 1e-6
    assert np.all((speed >= limits.min_speed - tol) & (speed <= limits.max_speed + tol))
    assert np.all(np.abs(accel) <= limits.max_accel + tol) and np.all(np.abs(turn) <= limits.max_turn_rate + tol)
    assert np.all(np.abs(turn * speed) <= limits.max_lateral_accel + tol)  # bank: ω V = g tan φ <= g tan φ_max
    x_c, u_c, _ = hermite_midpoints(result.states, result.controls, result.step)
    assert np.all((x_c[:, 3] >= limits.min_speed - tol) & (x_c[:, 3] <= limits.max_speed + tol))
    assert np.all(np.abs(u_c[:, 1] * x_c[:, 3]) <= limits.max_lateral_accel + tol)


def test_the_plan_beats_a_straight_fly_over_and_a_wide_circle_from_the_same_state():
    """Objective values of one solve against two feasible node trajectories from the same state: the straight
    line over the target and the constant turn of radius 3 r_fp (the cold guess is a gentle turn, not either)."""
    state = np.array([-100.0, 0.0, 0.0, FW.min_speed])  # heading straight for the target
    result = plan(state, ORIGIN, ORIGIN, FW, CFG)
    problem = CollocationProblem(state, ORIGIN, ORIGIN, FW, CFG)
    straight = arc(CFG.step, speed=FW.min_speed, omega=1e-9, psi0=0.0)
    wide = arc(CFG.step, speed=FW.min_speed, omega=FW.min_speed / (3 * CFG.footprint_radius), psi0=0.0)
    for states, controls in (straight, wide):
        states[:, 0] += state[0]
        assert result.objective < problem.objective(problem.pack(states, controls))[0] - 0.5


def fly(planner: RecedingHorizonPlanner, state, duration: float, target_velocity=ORIGIN, dt: float = 0.25):
    """Follow the plans exactly (the vehicle is where the plan says); positions every dt and target positions."""
    path, targets = [], []
    for t in np.arange(0.0, duration, dt):
        target = target_velocity * t
        planner.setpoint(float(t), state, target, target_velocity)
        path.append(state[:2].copy())
        targets.append(target)
        state = planner.plan.sample(t + dt)
    return np.array(path), np.array(targets)


def logdet(path, targets) -> float:
    return float(np.linalg.slogdet(accumulated_information(path, targets, 0.25, CFG))[1])


def test_about_a_stationary_target_the_fixed_wing_keeps_it_in_the_footprint_and_gathers_more_information():
    """Start on the circle a fixed wing flies for an orbit goal (loiter radius 1.2 v^2 / (g tan φ_max), 57 m;
    warm starts alone settle on a wider circle there): the plans keep the target in the footprint and gather
    more information than that circle, a circle of the wrong radius (2 r_fp) and a fly-over, all at cruise."""
    duration, cruise = 30.0, 18.0
    loiter = 1.2 * cruise**2 / FW.max_lateral_accel
    planner = RecedingHorizonPlanner(FW)
    assert planner.orbit_start  # a fixed wing cannot hover: second start on by default
    path, targets = fly(planner, np.array([loiter, 0.0, math.pi / 2, cruise]), duration)
    assert np.linalg.norm(path - targets, axis=1).max() <= CFG.footprint_radius
    t = np.arange(0.0, duration, 0.25)
    mine = logdet(path, targets)
    for radius in (loiter, 2 * CFG.footprint_radius):
        circle = radius * np.column_stack([np.cos(cruise / radius * t), np.sin(cruise / radius * t)])
        assert mine > logdet(circle, targets) + 0.5
    fly_over = np.column_stack([cruise * (t - duration / 2), np.zeros_like(t)])
    assert mine > logdet(fly_over, targets) + 1.0


def test_without_the_orbit_start_warm_starts_settle_on_a_circle_wider_than_the_footprint():
    """Why the fixed wing gets a second start: the same flight as above, warm starts only."""
    loiter = 1.2 * 18.0**2 / FW.max_lateral_accel
    path, targets = fly(RecedingHorizonPlanner(FW, orbit_start=False), np.array([loiter, 0.0, math.pi / 2, 18.0]),
                        30.0)
    assert np.linalg.norm(path - targets, axis=1).max() > CFG.footprint_radius


def test_a_moving_target_stays_in_the_footprint():
    velocity = np.array([4.0, 3.0])
    path, targets = fly(RecedingHorizonPlanner(FW), np.array([-100.0, 0.0, 0.0, 18.0]), 30.0, velocity)
    assert np.linalg.norm(path[40:] - targets[40:], axis=1).max() <= CFG.footprint_radius


def test_a_fixed_wing_cannot_hover_over_the_target_but_a_multirotor_does():
    moving = plan(np.array([0.0, 0.0, 0.0, FW.min_speed]), ORIGIN, ORIGIN, FW, CFG)
    t = np.linspace(0.0, CFG.horizon, 401)
    length = np.sum(np.linalg.norm(np.diff(moving.sample(t)[:, :2], axis=0), axis=1))
    assert length >= 0.99 * FW.min_speed * CFG.horizon
    assert moving.states[:, 3].min() >= FW.min_speed - 1e-6
    hovering = plan(np.array([0.0, 0.0, 0.0, 0.0]), ORIGIN, ORIGIN, MR, CFG)
    assert hovering.states[:, 3].max() < 1.0
    assert not RecedingHorizonPlanner(MR).orbit_start  # hovering is found from the warm start alone


def test_warm_started_replanning_takes_fewer_iterations_than_cold_starts():
    planner = RecedingHorizonPlanner(FW, orbit_start=False)
    state, warm, cold = np.array([-150.0, 40.0, 0.2, 18.0]), [], []
    for t in np.arange(0.0, 16.0, 2.0):
        planner.setpoint(float(t), state, ORIGIN, ORIGIN)
        if t > 0:
            warm.append(planner.solves[-1].iterations)
            cold.append(plan(state, ORIGIN, ORIGIN, FW, CFG, t0=float(t)).iterations)
        state = planner.plan.sample(t + 2.0)
    assert sum(warm) < 0.8 * sum(cold)


# -- the receding horizon ------------------------------------------------------------------------------------------
def test_the_planner_replans_once_per_period_and_starts_each_plan_at_the_measured_state():
    planner = RecedingHorizonPlanner(MR, orbit_start=False)
    state = np.array([50.0, -20.0, 1.0, 4.0])
    for t in np.arange(0.0, 10.0, 0.2):
        setpoint = planner.setpoint(float(t), state, ORIGIN, ORIGIN)
        if abs(t - planner.plan.t0) < 1e-9:
            np.testing.assert_allclose(setpoint.position, [state[0], state[1], -CFG.altitude], atol=1e-9)
            np.testing.assert_allclose(setpoint.velocity[:2], state[3] * np.array([math.cos(state[2]),
                                                                                   math.sin(state[2])]), atol=1e-9)
        state = planner.plan.sample(t + 0.2)
    assert [p.t0 for p in planner.solves] == pytest.approx([0.0, 2.0, 4.0, 6.0, 8.0])


def test_a_failed_solve_keeps_the_previous_plan_until_it_runs_out():
    planner = RecedingHorizonPlanner(FW, PlannerConfig(max_iterations=1), orbit_start=False)
    state = np.array([-150.0, 40.0, 0.2, 18.0])
    planner.setpoint(0.0, state, ORIGIN, ORIGIN)  # fails, but there is nothing better
    assert not planner.plan.success
    planner.setpoint(2.0, planner.plan.sample(2.0), ORIGIN, ORIGIN)
    assert planner.plan.t0 == 0.0 and len(planner.solves) == 2
    planner.setpoint(21.0, planner.plan.sample(20.0), ORIGIN, ORIGIN)  # the old plan no longer covers t
    assert planner.plan.t0 == 21.0


def test_unicycle_state_takes_the_course_or_the_yaw_when_hovering():
    np.testing.assert_allclose(unicycle_state([1.0, 2.0, -30.0], [3.0, 4.0, 1.0], 0.3),
                               [1.0, 2.0, math.atan2(4.0, 3.0), 5.0])
    np.testing.assert_allclose(unicycle_state([1.0, 2.0, -30.0], [0.1, 0.1, 0.0], 0.3), [1.0, 2.0, 0.3, math.hypot(
        0.1, 0.1)])


# -- bad inputs ----------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("state", "mean", "velocity", "match"),
    [
        ([math.nan, 0.0, 0.0, 10.0], ORIGIN, ORIGIN, "initial_state"),  # NaN vehicle north
        ([0.0, 0.0, 0.0], ORIGIN, ORIGIN, "initial_state"),  # state without speed
        ([0.0, 0.0, 0.0, 10.0], [math.nan, 0.0], ORIGIN, "target_mean"),  # NaN target
        ([0.0, 0.0, 0.0, 10.0], [[0.0, 0.0], [5.0, 5.0]], ORIGIN, "target_velocity"),  # 2 means, 1 velocity
        ([0.0, 0.0, 0.0, 10.0], [1.0, 2.0, 3.0], ORIGIN, "target_mean"),  # 3-D target
    ],
)
def test_bad_plan_inputs_are_rejected(state, mean, velocity, match):
    with pytest.raises(ValueError, match=match):
        plan(state, mean, velocity, MR, CFG)


@pytest.mark.parametrize(
    ("build", "match"),
    [
        (lambda: VehicleLimits(10.0, 10.0, 1.0, 1.0, 1.0), "max_speed"),  # empty speed band
        (lambda: VehicleLimits(-1.0, 10.0, 1.0, 1.0, 1.0), "min_speed"),  # negative minimum speed
        (lambda: VehicleLimits(0.0, 10.0, 0.0, 1.0, 1.0), "max_accel"),  # no acceleration
        (lambda: VehicleLimits.fixed_wing(max_bank=math.radians(95.0)), "max_bank"),  # bank past vertical
        (lambda: PlannerConfig(nodes=1), "nodes"),  # one node: no segment
        (lambda: PlannerConfig(horizon=0.0), "horizon"),  # zero horizon
        (lambda: PlannerConfig(altitude=math.nan), "altitude"),  # NaN altitude
        (lambda: RecedingHorizonPlanner(MR, replan_period=30.0), "replan_period"),  # period beyond the horizon
    ],
)
def test_bad_settings_are_rejected(build, match):
    with pytest.raises(ValueError, match=match):
        build()


def test_a_nan_time_is_rejected():
    with pytest.raises(ValueError, match="t must be"):
        RecedingHorizonPlanner(MR).setpoint(math.nan, [0.0, 0.0, 0.0, 1.0], ORIGIN, ORIGIN)
    with pytest.raises(ValueError, match="t0"):
        plan([0.0, 0.0, 0.0, 1.0], ORIGIN, ORIGIN, MR, CFG, t0=math.inf)


# -- the benchmark -------------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_the_benchmark_runs_quick_with_finite_figures():
    result = tasking_paths.run(quick=True, repeats=1)
    assert result["benchmark"] == "tasking-paths" and result["part"] == "paths"
    sections = {r["section"] for r in result["rows"]}
    assert sections == {"solve time", "information", "separation"}
    for row in result["rows"]:
        for key, value in row.items():
            if isinstance(value, float):
                assert math.isfinite(value), (key, row)
    for goal in result["goals"]:
        assert set(goal) == {"name", "target", "measured", "met"} and isinstance(goal["met"], bool)
    out = io.StringIO()
    tasking_paths.report(result, Console(file=out, width=220))
    text = out.getvalue()
    assert "collocation solve time" in text and "separation" in text
