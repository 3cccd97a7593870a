"""Which alarm each UAV watches (tasking/alarm_watch.py): every agent decides alone, from the same positions and
alarms, and together they must form the least-distance watch of min(alarms, agents - explorers) alarms."""

from __future__ import annotations

from itertools import combinations, permutations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tasking.alarm_watch import watched_alarm


def decisions(positions: dict[str, np.ndarray], alarms: list[np.ndarray], explorers: int) -> dict[str, int | None]:
    """What every agent decides, each from its own point of view (itself + the others as peers)."""
    return {me: watched_alarm(here, {p: ne for p, ne in positions.items() if p != me}, alarms, explorers)
            for me, here in positions.items()}


def least_watch_distance(positions: list[np.ndarray], alarms: list[np.ndarray], watchers: int) -> float:
    """Brute force: the least total distance of ``watchers`` distinct agents to ``watchers`` distinct alarms."""
    best = np.inf
    for agents in combinations(range(len(positions)), watchers):
        for chosen in permutations(range(len(alarms)), watchers):
            best = min(best, sum(np.linalg.norm(positions[a] - alarms[k]) for a, k in zip(agents, chosen, strict=True)))
    return best


def test_no_alarm_means_everyone_explores():
    assert watched_alarm(np.zeros(3), {"b": np.ones(2)}, [], explorers=1) is None


def test_the_nearest_agent_watches_a_lone_alarm_and_the_others_explore():
    positions = {"a": np.array([0.0, 0.0]), "b": np.array([100.0, 0.0]), "c": np.array([0.0, 100.0])}
    assert decisions(positions, [np.array([90.0, 10.0])], explorers=1) == {"a": None, "b": 0, "c": None}


def test_explorers_are_kept_even_when_alarms_outnumber_the_agents():
    """4 agents, 6 alarms, 1 explorer: 3 agents watch 3 different alarms, one explores."""
    rng = np.random.default_rng(3)
    positions = {f"uav{i}": rng.uniform(-150, 150, 2) for i in range(4)}
    alarms = list(rng.uniform(-150, 150, (6, 2)))
    chosen = [k for k in decisions(positions, alarms, explorers=1).values() if k is not None]
    assert len(chosen) == 3 and len(set(chosen)) == 3
    assert sum(1 for k in decisions(positions, alarms, explorers=0).values() if k is not None) == 4


def test_an_agent_over_its_alarm_keeps_it():
    """Once a watcher hovers over its alarm (cost 0), an explorer passing closer to nothing changes nothing."""
    positions = {"w": np.array([50.0, 50.0]), "x": np.array([45.0, 40.0])}
    assert decisions(positions, [np.array([50.0, 50.0])], explorers=1) == {"w": 0, "x": None}


def test_a_three_dimensional_position_is_read_horizontally():
    assert watched_alarm(np.array([10.0, 10.0, -60.0]), {"b": np.array([200.0, 200.0])}, [np.array([10.0, 12.0])],
                         explorers=0) == 0


@settings(max_examples=150, deadline=None)
@given(st.integers(1, 5), st.integers(1, 4), st.integers(0, 2), st.integers(0, 2**32 - 1))
def test_the_agents_decisions_form_the_least_distance_watch(agents, alarms, explorers, seed):
    """Oracle: brute force over every choice of watchers and alarms. Random continuous positions (no ties): the
    decisions the agents make alone are one matching — distinct alarms, min(alarms, agents - explorers) of them
    watched — and its total distance is the least possible."""
    rng = np.random.default_rng(seed)
    positions = {f"uav{i}": rng.uniform(-150, 150, 2) for i in range(agents)}
    points = list(rng.uniform(-150, 150, (alarms, 2)))
    chosen = {me: k for me, k in decisions(positions, points, explorers).items() if k is not None}
    watchers = max(0, min(alarms, agents - explorers))
    assert len(chosen) == watchers and len(set(chosen.values())) == watchers
    total = sum(np.linalg.norm(positions[me] - points[k]) for me, k in chosen.items())
    assert total == pytest.approx(least_watch_distance(list(positions.values()), points, watchers))
