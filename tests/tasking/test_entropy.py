"""Entropy-greedy exploration, Merino (4.21)-(4.24): the information gain against a hand computation,
brute-force mutual information and closed forms; the planner's choices; bad input."""

from __future__ import annotations

import itertools
import math
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import integrate, stats
from scipy.special import digamma

from tasking.base import MapView
from tasking.entropy import (
    MOVES,
    EntropyPlanner,
    EntropyPlannerConfig,
    bernoulli_entropy,
    beta_entropy,
    beta_expected_entropy_reduction,
    expected_entropy_reduction,
    explored_share,
    move_cost,
)

AREA = (0.0, 300.0, 0.0, 300.0)
CELL = 10.0


def centres(rows=30, cols=30, cell=CELL, origin=(0.0, 0.0)) -> np.ndarray:
    n = origin[0] + (np.arange(rows) + 0.5) * cell
    e = origin[1] + (np.arange(cols) + 0.5) * cell
    return np.stack(np.meshgrid(n, e, indexing="ij"), axis=-1)


def brute_mutual_information(p: float, pd: float, pf: float, looks: int) -> float:
    """I(X; Z_1..Z_n) from the joint table over every detection sequence (2^n outcomes)."""
    total = 0.0
    for z in itertools.product((0, 1), repeat=looks):
        joint = {}
        for x, prior, rate in ((1, p, pd), (0, 1.0 - p, pf)):
            joint[x] = prior * math.prod(rate if zi else 1.0 - rate for zi in z)
        pz = joint[0] + joint[1]
        for x, prior in ((1, p), (0, 1.0 - p)):
            if joint[x] > 0:
                total += joint[x] * math.log(joint[x] / (prior * pz))
    return total


# ------------------------------------------------------------------------------ information gain


def test_gain_at_half_by_hand():
    # p = 0.5, P_D = 0.9, P_F = 0.05: P(d) = 0.475, p_d = 0.45 / 0.475, p_nd = 0.05 / 0.525.
    h = lambda q: -q * math.log(q) - (1 - q) * math.log(1 - q)  # noqa: E731
    by_hand = math.log(2) - (0.475 * h(0.45 / 0.475) + 0.525 * h(0.05 / 0.525))
    assert by_hand == pytest.approx(0.4300976, abs=1e-7)  # 0.693147 - (0.475 * 0.206192 + 0.525 * 0.314492)
    assert float(expected_entropy_reduction(0.5, 0.9, 0.05)) == pytest.approx(by_hand, rel=1e-12)
    assert float(bernoulli_entropy(0.5)) == pytest.approx(math.log(2), rel=1e-15)


@pytest.mark.parametrize("looks", [1, 2, 3])
def test_gain_matches_brute_force_mutual_information(looks):
    rng = np.random.default_rng(looks)
    for _ in range(20):
        p, pd, pf = rng.uniform(size=3)
        got = float(expected_entropy_reduction(p, pd, pf, looks))
        assert got == pytest.approx(brute_mutual_information(p, pd, pf, looks), abs=1e-12)


@settings(max_examples=200, deadline=None)
@given(st.floats(0.0, 1.0), st.floats(0.0, 1.0), st.floats(0.0, 1.0), st.integers(0, 3))
def test_gain_is_non_negative(p, pd, pf, looks):
    assert float(expected_entropy_reduction(p, pd, pf, looks)) >= 0.0


def test_gain_zero_at_certainty_and_for_an_uninformative_sensor():
    np.testing.assert_array_equal(expected_entropy_reduction([0.0, 1.0], 0.9, 0.05), [0.0, 0.0])
    np.testing.assert_array_equal(expected_entropy_reduction([0.0, 1.0], 1.0, 0.0), [0.0, 0.0])
    p = np.linspace(0.0, 1.0, 11)
    np.testing.assert_allclose(expected_entropy_reduction(p, 0.3, 0.3), 0.0, atol=1e-15)
    assert np.all(expected_entropy_reduction(p, 0.3, 0.3, looks=3) <= 1e-15)
    np.testing.assert_array_equal(expected_entropy_reduction(p, 0.9, 0.05, looks=0), 0.0)


def test_gain_is_largest_for_uncertain_cells():
    p = np.array([0.01, 0.1, 0.3, 0.5])
    g = expected_entropy_reduction(p, 0.9, 0.05)
    assert np.all(np.diff(g) > 0)


def test_beta_entropy_matches_scipy():
    for a, b in [(1.0, 1.0), (2.5, 0.7), (30.0, 4.0), (0.3, 0.3)]:
        assert float(beta_entropy(a, b)) == pytest.approx(stats.beta(a, b).entropy(), rel=1e-10, abs=1e-12)


def test_beta_gain_one_look_closed_form():
    """I(X; Z) = h(μ) - E[h(X)] with E[-X ln X] = μ (ψ(a+b+1) - ψ(a+1)) (a route other than H(a, b) differences)."""
    for a, b in [(1.0, 1.0), (2.0, 5.0), (0.5, 3.0), (40.0, 12.0)]:
        mu = a / (a + b)
        closed = (float(bernoulli_entropy(mu)) - mu * (digamma(a + b + 1) - digamma(a + 1))
                  - (1 - mu) * (digamma(a + b + 1) - digamma(b + 1)))
        assert float(beta_expected_entropy_reduction(a, b)) == pytest.approx(closed, rel=1e-9, abs=1e-13)


@pytest.mark.parametrize("looks", [2, 3])
def test_beta_gain_several_looks_by_quadrature(looks):
    """I(X; C) = H(C) - E_X[H(Bin(n, X))], C ~ BetaBinomial(n, a, b), by numerical integration."""
    a, b = 1.5, 2.5
    pmf = stats.betabinom(looks, a, b).pmf(np.arange(looks + 1))
    h_c = -np.sum(pmf * np.log(pmf))
    h_given, _ = integrate.quad(lambda x: stats.binom(looks, x).entropy() * stats.beta(a, b).pdf(x), 0, 1)
    assert float(beta_expected_entropy_reduction(a, b, looks)) == pytest.approx(h_c - h_given, rel=1e-6)


@settings(max_examples=100, deadline=None)
@given(st.floats(0.05, 200.0), st.floats(0.05, 200.0))
def test_beta_gain_non_negative_and_falls_with_evidence(a, b):
    g = float(beta_expected_entropy_reduction(a, b))
    assert g >= 0.0
    assert float(beta_expected_entropy_reduction(4 * a, 4 * b)) <= g + 1e-12  # same mean, more evidence


@pytest.mark.parametrize("looks", [1, 4, 20])
@pytest.mark.parametrize("evidence", [1e6, 1e9, 1e12])
def test_beta_gain_with_huge_counts_meets_its_large_evidence_limit(evidence, looks):
    """A cell with ``a + b`` counts (a naive-fusion rumour makes them huge) is a near-point mass: n looks give
    ``I ~ n / (2 (a + b + 1))`` (the Gaussian channel limit ``0.5 ln(1 + n Var X / (μ (1 - μ)))``). The route through
    differential entropies gave 32 nats for one look at a = b = 1e15."""
    a, b = 0.3 * evidence, 0.7 * evidence
    limit = 0.5 * math.log1p(looks * (a * b / ((a + b) ** 2 * (a + b + 1))) / (0.3 * 0.7))
    assert float(beta_expected_entropy_reduction(a, b, looks)) == pytest.approx(limit, rel=1e-3)


@pytest.mark.parametrize("looks", [1, 3, 20])
def test_beta_gain_of_a_two_point_cell_is_one_bit(looks):
    """Beta(ε, ε), ε -> 0, puts its mass on 0 and 1: every look tells which, so ``I = H(C) = ln 2``."""
    assert float(beta_expected_entropy_reduction(1e-9, 1e-9, looks)) == pytest.approx(math.log(2.0), rel=1e-6)


def test_beta_gain_of_extreme_counts_is_finite_bounded_and_quiet():
    """Bad input for the old route: counts from 1e-300 to 1e300 overflowed ``exp`` in the planner (a RuntimeWarning in
    ``skymesh bench fire``'s naive Beta runs). Now no floating-point warning, and ``0 <= I <= H(C) <= ln(n + 1)``."""
    counts = np.array([1e-300, 1e-8, 1.0, 1e8, 1e15, 1e300])
    a, b = np.meshgrid(counts, counts)
    for looks in (1, 5, 20):
        with np.errstate(over="raise", divide="raise", invalid="raise"):  # underflow to 0 is harmless
            g = beta_expected_entropy_reduction(a, b, looks)
        assert np.all(np.isfinite(g)) and np.all(g >= 0.0) and np.all(g <= math.log(looks + 1) + 1e-12)


def test_move_cost_by_hand():
    assert move_cost((0.0, 0.0), (20.0, 0.0), 20.0, 1.0) == 0.0  # stay: no path, no turn term
    assert move_cost((20.0, 0.0), (20.0, 0.0), 20.0, 1.0) == pytest.approx(1.0)  # straight on
    assert move_cost((0.0, 20.0), (20.0, 0.0), 20.0, 1.0) == pytest.approx(2.0)  # 90 degree turn
    assert move_cost((-20.0, 0.0), (20.0, 0.0), 20.0, 0.5) == pytest.approx(2.0)  # reverse: 1 + 0.5 * 2
    assert move_cost((20.0, 20.0), (20.0, 0.0), 20.0, 1.0) == pytest.approx(math.sqrt(2) + 1 - math.sqrt(0.5))
    assert move_cost((20.0, 20.0), (0.0, 0.0), 20.0, 1.0) == pytest.approx(math.sqrt(2))  # from rest


# ----------------------------------------------------------------------------------------- planner


def planner(**overrides) -> EntropyPlanner:
    return EntropyPlanner(EntropyPlannerConfig(**overrides), AREA, 30.0)


def test_planner_heads_for_the_unexplored_side():
    c = centres()
    for unexplored_east in (True, False):
        p = np.full((30, 30), 0.01)
        if unexplored_east:
            p[:, 15:] = 0.5
        else:
            p[:, :15] = 0.5
        pl = planner()
        goal = pl.goal_for(np.array([150.0, 150.0, -30.0]), p, c)
        assert goal.position[2] == -30.0
        seen = np.sum((c - goal.position[:2]) ** 2, axis=-1) <= 40.0**2  # the footprint disc at the goal
        assert pl.last_gain == pytest.approx(float(np.sum(expected_entropy_reduction(p[seen], 0.9, 0.05))))
        np.testing.assert_allclose(pl.last_move, goal.position[:2] - 150.0)
        assert abs(goal.position[0] - 150.0) <= 20.0 + 1e-9
        assert (goal.position[1] > 150.0) == unexplored_east and goal.position[1] != 150.0


def test_planner_stays_when_nothing_is_left_to_learn():
    goal = planner().goal_for(np.array([150.0, 150.0]), np.zeros((30, 30)), centres())
    np.testing.assert_allclose(goal.position, [150.0, 150.0, -30.0])


def test_planner_never_leaves_the_area_even_for_unexplored_cells_outside():
    """The grid is larger than the area and unexplored outside it; the agent sits on the area's corner."""
    c = centres(40, 40, origin=(-50.0, -50.0))  # cells from -50 to 350
    p = np.full((40, 40), 0.01)
    outside = (c[..., 0] < 0) | (c[..., 1] < 0)
    p[outside] = 0.5
    pl = planner()
    position = np.array([0.0, 0.0, -30.0])
    for _ in range(5):
        goal = pl.goal_for(position, p, c)
        assert AREA[0] <= goal.position[0] <= AREA[1] and AREA[2] <= goal.position[1] <= AREA[3]
        position = goal.position


@settings(max_examples=40, deadline=None)
@given(st.floats(0.0, 300.0), st.floats(0.0, 300.0), st.integers(0, 2**31 - 1), st.integers(1, 2))
def test_planner_goal_is_inside_the_area_and_one_move_away(north, east, seed, horizon):
    p = np.random.default_rng(seed).uniform(size=(30, 30))
    goal = planner(horizon=horizon).goal_for(np.array([north, east, -30.0]), p, centres())
    n, e = goal.position[:2]
    assert -1e-9 <= n <= 300.0 + 1e-9 and -1e-9 <= e <= 300.0 + 1e-9
    move = np.round((goal.position[:2] - [north, east]) / 20.0, 9)
    assert tuple(move) in {tuple(map(float, m)) for m in MOVES}


def test_planner_outside_the_area_returns_to_its_nearest_point():
    goal = planner().goal_for(np.array([-100.0, 150.0, -30.0]), np.full((30, 30), 0.5), centres())
    np.testing.assert_allclose(goal.position, [0.0, 150.0, -30.0])


def test_beta_variant_prefers_cells_with_little_evidence():
    """Same mean 0.5 everywhere; west has a uniform prior (a = b = 1), east much evidence (a = b = 30)."""
    c = centres()
    p = np.full((30, 30), 0.5)
    alpha = np.full((30, 30), 30.0)
    alpha[:, :15] = 1.0
    goal = planner().goal_for(np.array([150.0, 150.0]), p, c, beta=(alpha, alpha.copy()))
    assert goal.position[1] < 150.0
    alpha = alpha[:, ::-1].copy()
    assert planner().goal_for(np.array([150.0, 150.0]), p, c, beta=(alpha, alpha.copy())).position[1] > 150.0


def test_turn_cost_keeps_the_heading_when_gains_tie():
    """Unexplored strips equally far north and south: the previous move decides."""
    c = centres()
    p = np.full((30, 30), 0.01)
    p[:10] = 0.5  # north of 100 m
    p[20:] = 0.5  # south of 200 m: both 55 m from the agent's cell row
    for heading in (1.0, -1.0):
        pl = planner()
        pl.last_move = np.array([heading * 20.0, 0.0])
        goal = pl.goal_for(np.array([150.0, 150.0]), p, c)
        np.testing.assert_allclose(goal.position[:2], [150.0 + heading * 20.0, 150.0])


def test_longer_horizon_sees_beyond_one_move():
    """All explored within reach of one move (60 m); an unexplored strip 70-90 m east."""
    c = centres()
    p = np.full((30, 30), 0.01)
    p[:, 22:25] = 0.5  # east 220-250, i.e. 70-100 m from the agent at east 150
    position = np.array([150.0, 150.0])
    assert planner(horizon=1).goal_for(position, p, c).position[1] == 150.0
    assert planner(horizon=2).goal_for(position, p, c).position[1] == 170.0


def test_horizon_two_matches_brute_force_enumeration():
    rng = np.random.default_rng(5)
    c = centres()
    p = rng.uniform(size=(30, 30))
    pl = planner(horizon=2, cost_weight=0.3)
    pl.last_move = np.array([0.0, 20.0])
    cfg = pl.config
    best, best_move = -np.inf, None
    here = np.array([100.0, 120.0])
    for a, b in itertools.product(MOVES, repeat=2):
        m1, m2 = np.array(a) * cfg.step, np.array(b) * cfg.step
        p1, p2 = here + m1, here + m1 + m2
        if not all(0 <= q[0] <= 300 and 0 <= q[1] <= 300 for q in (p1, p2)):
            continue
        looks = sum((np.sum((c - q) ** 2, axis=-1) <= cfg.footprint**2).astype(int) for q in (p1, p2))
        gain = sum(float(np.sum(expected_entropy_reduction(p[looks == n], cfg.pd, cfg.pf, n))) for n in (1, 2))
        previous = m1 if np.any(m1) else pl.last_move
        cost = (move_cost(m1, pl.last_move, cfg.step, cfg.turn_cost) + move_cost(m2, previous, cfg.step, cfg.turn_cost))
        score = gain - cfg.cost_weight * cost
        if score > best + 1e-12:
            best, best_move = score, m1
    goal = pl.goal_for(here, p, c)
    np.testing.assert_allclose(goal.position[:2], here + best_move)


def observe_nothing(p: np.ndarray, c: np.ndarray, where: np.ndarray, cfg: EntropyPlannerConfig) -> np.ndarray:
    """Bayes update of every cell in the footprint with a non-detection (there is no fire)."""
    seen = np.sum((c - where[:2]) ** 2, axis=-1) <= cfg.footprint**2
    out = p.copy()
    q = p[seen]
    out[seen] = (1 - cfg.pd) * q / ((1 - cfg.pd) * q + (1 - cfg.pf) * (1 - q))
    return out, seen


@pytest.mark.parametrize("shared", [True, False])
def test_shared_map_gives_implicit_coordination(shared):
    """Merino §4.3.1: two agents from the same place. Sharing the map, the second avoids what the first
    just covered; with private maps they fly the same path."""
    c = centres()
    cfg = EntropyPlannerConfig()
    agents = [planner(), planner()]
    positions = [np.array([150.0, 150.0]), np.array([150.0, 150.0])]
    maps = [np.full((30, 30), 0.5)] if shared else [np.full((30, 30), 0.5), np.full((30, 30), 0.5)]
    covered = [np.zeros((30, 30), bool), np.zeros((30, 30), bool)]
    for _ in range(12):
        for i, agent in enumerate(agents):
            m = 0 if shared else i
            positions[i] = agent.goal_for(positions[i], maps[m], c).position[:2]
            maps[m], seen = observe_nothing(maps[m], c, positions[i], cfg)
            covered[i] |= seen
    overlap = np.sum(covered[0] & covered[1]) / np.sum(covered[0] | covered[1])
    if shared:
        assert overlap < 0.3
        assert np.sum(covered[0] | covered[1]) > 1.5 * np.sum(covered[0])
    else:
        assert overlap == 1.0


# ------------------------------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    "kwargs",
    [
        {"pd": 0.05, "pf": 0.05},  # pd == pf: an uninformative sensor
        {"pd": 0.1, "pf": 0.5},  # pd < pf
        {"pd": 1.5},  # pd above 1
        {"pf": -0.1},  # pf below 0
        {"gain_weight": -1.0},  # negative weight
        {"cost_weight": -0.1},  # negative weight
        {"turn_cost": -1.0},  # negative turn cost
        {"step": 0.0},  # no move
        {"footprint": -5.0},  # negative footprint
        {"step": math.nan},  # NaN step
        {"horizon": 0},  # no look-ahead
        {"horizon": 4},  # beyond MAX_HORIZON
        {"horizon": 1.5},  # non-integer horizon
        {"cost_weight": True},  # a bool, not a number
        {"watch": 1},  # a number, not true or false
        {"explorers": -1},  # fewer than no explorers
        {"explorers": 1.5},  # half an explorer
        {"explorers": True},  # a bool, not a count
        {"watch_from": 1.2},  # a share above 1
        {"watch_from": math.nan},  # NaN share
        {"watch_from": "half"},  # a word, not a share (a TypeError before, not a clear ValueError)
    ],
)
def test_bad_config_raises(kwargs):
    with pytest.raises(ValueError):
        EntropyPlannerConfig(**kwargs)


def test_bad_planner_construction_raises():
    with pytest.raises(ValueError, match="area"):
        EntropyPlanner(EntropyPlannerConfig(), (10.0, 0.0, 0.0, 10.0), 30.0)  # empty area
    with pytest.raises(ValueError, match="altitude"):
        EntropyPlanner(EntropyPlannerConfig(), AREA, math.inf)  # infinite altitude
    with pytest.raises(ValueError, match="config"):
        EntropyPlanner({"step": 20.0}, AREA, 30.0)  # a dict, not a config


def test_bad_plan_inputs_raise():
    pl, c, p = planner(), centres(), np.full((30, 30), 0.5)
    here = np.array([150.0, 150.0, -30.0])
    with pytest.raises(ValueError, match="probability"):
        pl.goal_for(here, np.full((30, 30), 1.2), c)  # p above 1
    with pytest.raises(ValueError, match="probability"):
        pl.goal_for(here, np.full((30, 30), -0.1), c)  # p below 0
    with pytest.raises(ValueError, match="non-finite"):
        pl.goal_for(here, np.full((30, 30), np.nan), c)  # NaN p
    with pytest.raises(ValueError, match="probability"):
        pl.goal_for(here, np.full(30, 0.5), c)  # 1-D probability
    with pytest.raises(ValueError, match="centres"):
        pl.goal_for(here, p, c[:, :20])  # centres of another shape
    with pytest.raises(ValueError, match="centres"):
        pl.goal_for(here, p, c[..., 0])  # centres without the (north, east) axis
    with pytest.raises(ValueError, match="position"):
        pl.goal_for(np.array([150.0, np.nan, -30.0]), p, c)  # NaN position
    with pytest.raises(ValueError, match="position"):
        pl.goal_for(np.zeros(4), p, c)  # position of length 4
    with pytest.raises(ValueError, match="shape"):
        pl.goal_for(here, p, c, beta=(np.ones((30, 30)), np.ones((20, 30))))  # alpha and beta of different shapes
    with pytest.raises(ValueError, match="> 0"):
        pl.goal_for(here, p, c, beta=(np.zeros((30, 30)), np.ones((30, 30))))  # zero Beta counts
    with pytest.raises(ValueError, match="pair"):
        pl.goal_for(here, p, c, beta=np.ones((30, 30)))  # one array, not a pair


def test_bad_gain_inputs_raise():
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        expected_entropy_reduction([0.5, 1.5], 0.9, 0.05)  # p above 1
    with pytest.raises(ValueError, match="pd"):
        expected_entropy_reduction(0.5, 1.2, 0.05)  # pd above 1
    with pytest.raises(ValueError, match="looks"):
        expected_entropy_reduction(0.5, 0.9, 0.05, looks=-1)  # negative look count
    with pytest.raises(ValueError, match="> 0"):
        beta_expected_entropy_reduction(-1.0, 1.0)  # negative Beta count
    with pytest.raises(ValueError, match="non-finite"):
        beta_entropy(np.inf, 1.0)  # infinite Beta count


# ------------------------------------------------------------------------------------------- watch


def _watch_view(probability, alarms, peers):
    return {"grid": MapView(probability, centres(), None, tuple(np.asarray(a, float) for a in alarms), peers)}


def test_a_watcher_hovers_over_the_alarm_it_won_and_an_explorer_explores():
    """Two agents, one alarm at (200, 200): the nearer hovers over it at its altitude; the other, with the same
    map, makes the explorer's move (one step, as without the watch)."""
    p = np.full((30, 30), 0.5)
    state = SimpleNamespace(position=np.array([190.0, 190.0, -30.0]), velocity=np.zeros(3))
    near = planner(watch=True).plan(state, _watch_view(p, [(200.0, 200.0)], {"far": np.array([20.0, 20.0])}))
    np.testing.assert_allclose(near.position, [200.0, 200.0, -30.0])
    far_state = SimpleNamespace(position=np.array([20.0, 20.0, -30.0]), velocity=np.zeros(3))
    far = planner(watch=True).plan(far_state, _watch_view(p, [(200.0, 200.0)], {"near": np.array([190.0, 190.0])}))
    explore = planner().goal_for(far_state.position, p, centres())
    np.testing.assert_allclose(far.position, explore.position)


def test_the_watch_waits_until_the_area_is_explored_and_then_holds():
    """watch_from = 0.5, a lone agent: on an unexplored map (p = 0.5 everywhere) the agent explores past the
    alarm; once half the cells are settled it watches, and it keeps watching when the map's entropy rises again."""
    unexplored, half = np.full((30, 30), 0.5), np.full((30, 30), 0.5)
    half[:15] = 0.01
    state = SimpleNamespace(position=np.array([100.0, 100.0, -30.0]), velocity=np.zeros(3))
    pl = planner(watch=True, watch_from=0.5, explorers=0)  # a lone agent
    assert not np.allclose(pl.plan(state, _watch_view(unexplored, [(250.0, 250.0)], {})).position[:2], 250.0)
    np.testing.assert_allclose(pl.plan(state, _watch_view(half, [(250.0, 250.0)], {})).position[:2], 250.0)
    np.testing.assert_allclose(pl.plan(state, _watch_view(unexplored, [(250.0, 250.0)], {})).position[:2], 250.0)
    assert explored_share(half) == pytest.approx(0.5) and explored_share(unexplored) == 0.0
