"""RHTA (thesis 000 (4.1)-(4.4), §2.7.4): the petal table against tasks.petal_value / within_reach, the
selection solvers against brute-force enumeration, and the receding-horizon plan."""

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tasking.rhta import (
    EMPTY,
    PetalTable,
    enumerate_petals,
    petal_table,
    rhta,
    select_exact,
    select_greedy,
    selection_value,
)
from tasking.tasks import Capability, Task, petal_value, within_reach

coordinate = st.floats(-100.0, 100.0)
point = st.tuples(coordinate, coordinate)


@st.composite
def instances(draw, max_vehicles=3, max_tasks=4):
    """Vehicles (speed, range, camera quality) and tasks (value, kind, dwell) at random places."""
    tasks = [
        Task(f"t{i}", draw(point), draw(st.floats(0.1, 5.0)), kind=draw(st.sampled_from(["track", "loiter"])),
             duration=draw(st.sampled_from([0.0, 2.0])))
        for i in range(draw(st.integers(0, max_tasks)))
    ]
    vehicles = [
        Capability(draw(point), draw(st.floats(1.0, 10.0)), draw(point),
                   reach=draw(st.one_of(st.none(), st.floats(0.0, 600.0))), quality=draw(st.floats(0.0, 1.0)))
        for _ in range(draw(st.integers(1, max_vehicles)))
    ]
    return vehicles, tasks, draw(st.integers(1, 3)), draw(st.floats(0.5, 1.0))


def _petals(tasks, horizon):
    """Every ordered sequence of 1..horizon distinct tasks (independent of enumerate_petals)."""
    return [list(p) for k in range(1, horizon + 1) for p in itertools.permutations(tasks, k)]


def _brute_force(vehicles, tasks, horizon, discount):
    """max J (4.2) over all assignments of one petal (or none) per vehicle (4.4), tasks at most once (4.3),
    petals within reach (§2.7.4), valued by tasks.petal_value (4.1)."""
    options = [[[]] + [p for p in _petals(tasks, horizon) if within_reach(v, p)] for v in vehicles]
    best = 0.0
    for combo in itertools.product(*options):
        keys = [t.key for petal in combo for t in petal]
        if len(keys) == len(set(keys)):
            best = max(best, sum(petal_value(v, p, discount) for v, p in zip(vehicles, combo, strict=True)))
    return best


def _check_selection(table, choice):
    """(4.3)-(4.4): one petal or none per vehicle, feasible, no task twice."""
    assert choice.shape == (table.values.shape[0],)
    chosen = [p for p in choice if p != EMPTY]
    assert all(table.feasible[v, p] for v, p in enumerate(choice) if p != EMPTY)
    assert np.all(table.visits[chosen].sum(axis=0) <= 1)


def test_enumerate_petals_counts_and_orders():
    petals = enumerate_petals(4, 3)
    assert len(petals) == 4 + 4 * 3 + 4 * 3 * 2  # Σ_k 4!/(4-k)!
    assert [tuple(p) for p in petals[:5]] == [(0, -1, -1), (1, -1, -1), (2, -1, -1), (3, -1, -1), (0, 1, -1)]
    assert len({tuple(p) for p in petals}) == len(petals)
    assert enumerate_petals(2, 3).shape == (4, 3)  # no petal longer than the task list
    assert enumerate_petals(0, 2).shape == (0, 2)


@settings(max_examples=60, deadline=None)
@given(instances(max_tasks=4))
def test_table_values_are_4_1_and_pruning_is_exactly_the_range_test(instance):
    vehicles, tasks, horizon, discount = instance
    elapsed = np.arange(len(vehicles), dtype=float) * 3.0
    table = petal_table(vehicles, tasks, horizon, discount, elapsed)
    for v, vehicle in enumerate(vehicles):
        for p, row in enumerate(table.petals):
            petal = [tasks[i] for i in row if i != EMPTY]
            expected = discount ** elapsed[v] * petal_value(vehicle, petal, discount)  # λ^{t_v} S_vp
            assert table.values[v, p] == pytest.approx(expected, rel=1e-12, abs=1e-300)
            assert table.feasible[v, p] == within_reach(vehicle, petal)  # pruned <=> fails the test
            assert list(np.flatnonzero(table.visits[p])) == sorted(row[row != EMPTY])


@settings(max_examples=60, deadline=None)
@given(instances(max_vehicles=3, max_tasks=4))
def test_exact_selection_equals_brute_force(instance):
    vehicles, tasks, horizon, discount = instance
    horizon = min(horizon, 2)  # keeps the brute force small
    table = petal_table(vehicles, tasks, horizon, discount)
    choice = select_exact(table)
    _check_selection(table, choice)
    assert selection_value(table, choice) == pytest.approx(_brute_force(vehicles, tasks, horizon, discount), rel=1e-9)


@settings(max_examples=60, deadline=None)
@given(instances(max_vehicles=3, max_tasks=4))
def test_greedy_selection_is_feasible_and_within_the_bound(instance):
    vehicles, tasks, horizon, discount = instance
    table = petal_table(vehicles, tasks, horizon, discount)
    choice = select_greedy(table)
    _check_selection(table, choice)
    best = selection_value(table, select_exact(table))
    greedy = selection_value(table, choice)
    assert best / (horizon + 1) - 1e-12 <= greedy <= best + 1e-12  # J_opt / (n_c + 1) ≤ J_greedy ≤ J_opt


@settings(max_examples=40, deadline=None)
@given(instances(max_vehicles=1, max_tasks=4))
def test_greedy_is_optimal_for_one_vehicle(instance):
    vehicles, tasks, horizon, discount = instance
    table = petal_table(vehicles, tasks, horizon, discount)
    assert selection_value(table, select_greedy(table)) == pytest.approx(selection_value(table, select_exact(table)))


def test_greedy_can_miss_the_optimum_that_exact_finds():
    """A: task 0 worth 10, task 1 worth 9; B: task 0 worth 9.5, task 1 worth 0.1. Greedy takes A->0 first
    (10 + 0.1); the optimum is A->1, B->0 (18.5)."""
    petals = np.array([[0], [1]])
    table = PetalTable(petals, np.eye(2, dtype=bool), np.array([[10.0, 9.0], [9.5, 0.1]]), np.ones((2, 2), bool))
    assert list(select_greedy(table)) == [0, 1] and selection_value(table, select_greedy(table)) == 10.1
    assert list(select_exact(table)) == [1, 0] and selection_value(table, select_exact(table)) == 18.5


@settings(max_examples=40, deadline=None)
@given(instances(max_vehicles=3, max_tasks=5), st.sampled_from(["greedy", "exact"]))
def test_rhta_plans_are_feasible_commitments(instance, solver):
    vehicles, tasks, horizon, discount = instance
    horizon = min(horizon, 2) if solver == "exact" else horizon  # keeps the exact search small
    fleet = {f"v{i}": v for i, v in enumerate(vehicles)}
    plans = rhta(fleet, tasks, horizon, discount, solver=solver)
    committed = [key for plan in plans.values() for key in plan.tasks]
    assert len(committed) == len(set(committed))  # each task at most once
    by_key = {t.key: t for t in tasks}
    for name, plan in plans.items():
        route = [by_key[key] for key in plan.tasks]
        assert not route or within_reach(fleet[name], route)  # the whole route, and home, fits the range
        assert not (plan.home and plan.tasks)
    if all(v.reach is None and v.quality > 0.1 for v in vehicles) and discount > 0.9:
        assert set(committed) == set(by_key)  # unlimited range, every task worth something: all assigned
    first_only = rhta(fleet, tasks, horizon, discount, solver=solver, first_only=True)
    assert {k: (p.tasks[:1], p.home) for k, p in first_only.items()} == \
           {k: (p.tasks[:1], p.home) for k, p in plans.items()}


def _vehicle(x=0.0, reach=None, speed=1.0):
    return Capability([x, 0.0], speed, [0.0, 0.0], reach=reach)


def test_one_vehicle_serves_a_line_of_tasks_in_order():
    tasks = [Task(k, [x, 0.0], 1.0) for k, x in (("c", 30.0), ("a", 10.0), ("b", 20.0))]
    assert rhta({"v": _vehicle()}, tasks, horizon=1, discount=0.9)["v"].tasks == ("a", "b", "c")


def test_the_discount_trades_value_against_time():
    near, far = Task("near", [10.0, 0.0], 1.0), Task("far", [-20.0, 0.0], 3.0)
    # λ = 0.9: near first (0.9^10 + 3·0.9^40 > 3·0.9^20 + 0.9^50); λ = 1: worth the same, first petal order
    assert rhta({"v": _vehicle()}, [near, far], horizon=2, discount=0.9)["v"].tasks == ("near", "far")
    assert rhta({"v": _vehicle()}, [near, far], horizon=2, discount=0.99)["v"].tasks == ("far", "near")


def test_two_vehicles_split_tasks_and_commit_only_the_first_of_each_petal():
    tasks = [Task("east", [50.0, 0.0], 1.0), Task("west", [-50.0, 0.0], 1.0), Task("east2", [60.0, 0.0], 1.0)]
    plans = rhta({"e": _vehicle(40.0), "w": _vehicle(-40.0)}, tasks, horizon=2, discount=0.95)
    assert plans["e"].tasks == ("east", "east2") and plans["w"].tasks == ("west",)


def test_ties_are_broken_by_key_whatever_the_input_order():
    task = Task("t", [10.0, 0.0], 1.0)
    twins = {"b": _vehicle(), "a": _vehicle()}
    assert rhta(twins, [task])["a"].tasks == ("t",) and rhta(twins, [task])["b"].tasks == ()
    tasks = [Task(2, [10.0, 0.0], 1.0), Task(1, [-10.0, 0.0], 1.0)]  # equally far, equally worth
    assert rhta({"v": _vehicle()}, tasks, horizon=1)["v"].tasks == (1, 2)
    assert rhta({"v": _vehicle()}, tasks[::-1], horizon=1)["v"].tasks == (1, 2)


def test_a_vehicle_with_no_feasible_petal_is_sent_home():
    task = Task("t", [100.0, 0.0], 1.0)
    plans = rhta({"short": _vehicle(reach=150.0), "long": _vehicle(reach=250.0)}, [task])
    assert plans["short"] == plans["short"].__class__((), home=True)  # 100 out + 100 back > 150
    assert plans["long"].tasks == ("t",) and not plans["long"].home


def test_an_idle_vehicle_is_not_sent_home_when_it_has_a_feasible_petal():
    task = Task("t", [10.0, 0.0], 1.0)
    plans = rhta({"a": _vehicle(reach=100.0), "b": _vehicle(reach=100.0)}, [task])
    assert plans["a"].tasks == ("t",) and plans["b"].tasks == () and not plans["b"].home


def test_loiter_tasks_keep_healthy_vehicles_out():
    fleet = {"a": _vehicle(reach=500.0), "b": _vehicle(reach=500.0), "failed": _vehicle(reach=50.0)}
    assert all(plan.home for plan in rhta(fleet, []).values())  # no task: every petal "pruned", all home
    loiter = [Task(("loiter", i), [100.0, 50.0 * i], 0.1, kind="loiter") for i in range(2)]
    plans = rhta(fleet, loiter)
    assert not plans["a"].home and not plans["b"].home
    assert {plans["a"].tasks[0], plans["b"].tasks[0]} == {("loiter", 0), ("loiter", 1)}
    assert plans["failed"].home  # the loiter points are beyond its range: still recalled
    assert not any(plan.home for plan in rhta({"x": _vehicle(reach=None)}, []).values())  # no range model


def test_a_loiter_task_only_ends_a_petal():
    """At its loiter point, a vehicle's petal (loiter, task) would be worth the task's value plus the
    loiter's at T = 0 and keep it there; the loiter task may only come last, so it serves the task."""
    here = Task(("loiter", 0), [0.0, 0.0], 0.1, kind="loiter")
    task = Task("t", [30.0, 0.0], 1.0)
    assert rhta({"v": _vehicle()}, [here, task], horizon=2, discount=0.95)["v"].tasks == ("t", ("loiter", 0))


@pytest.mark.parametrize("bad, match", [
    (lambda: rhta({"v": _vehicle()}, [], horizon=0), "n_c"),         # n_c < 1
    (lambda: rhta({"v": _vehicle()}, [], horizon=1.5), "n_c"),       # n_c not an integer
    (lambda: rhta({"v": _vehicle()}, [], discount=0.0), "λ"),        # λ = 0
    (lambda: rhta({"v": _vehicle()}, [], discount=1.2), "λ"),        # λ > 1
    (lambda: rhta({"v": _vehicle()}, [], solver="milp"), "solver"),  # unknown solver
    (lambda: rhta({"v": _vehicle()}, [Task("t", [0, 0], 1.0)] * 2), "unique"),  # the same task twice
    (lambda: petal_table([_vehicle()], [], horizon=0), "n_c"),
])
def test_bad_input_is_refused(bad, match):
    with pytest.raises(ValueError, match=match):
        bad()
