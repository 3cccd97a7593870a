"""Least-cost matching by enumeration (tasking/matching.py) against scipy's Hungarian method."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import linear_sum_assignment

from tasking.matching import ENUMERATE_UP_TO, least_cost_pairs


@settings(max_examples=300, deadline=None)
@given(st.integers(1, ENUMERATE_UP_TO + 2), st.integers(1, ENUMERATE_UP_TO + 2), st.integers(0, 2**32 - 1))
def test_the_pairs_are_scipys_on_random_costs(rows, cols, seed):
    """Continuous random costs (no ties): the same pairs, in the same order, as linear_sum_assignment — by
    enumeration up to ENUMERATE_UP_TO a side, by scipy itself beyond."""
    cost = np.random.default_rng(seed).uniform(0.0, 100.0, (rows, cols))
    r, c = linear_sum_assignment(cost)
    assert least_cost_pairs(cost.tolist()) == list(zip(r.tolist(), c.tolist(), strict=True))


def test_ties_still_give_a_least_total():
    """Equal costs (two targets at the same distance): any least assignment, and its total is scipy's."""
    cost = [[1.0, 1.0, 5.0], [1.0, 1.0, 5.0]]
    pairs = least_cost_pairs(cost)
    r, c = linear_sum_assignment(np.array(cost))
    assert len(pairs) == 2 and sum(cost[i][j] for i, j in pairs) == pytest.approx(np.array(cost)[r, c].sum())


def test_nothing_to_match():
    assert least_cost_pairs([]) == [] and least_cost_pairs([[]]) == []
