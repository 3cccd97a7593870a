"""Least-cost one-to-one matching of a few rows to a few columns: what ``scipy.optimize.linear_sum_assignment``
returns (Kuhn's Hungarian method), found by enumeration when both sides are small.

A peer's bid message names its track tasks by position, and every receiver matches them to its own targets
(:meth:`agent.beliefs.assignment.AssignmentExchange._match_tracks`): a fleet has a handful of targets, and for 3 x 3
the arrays and the scipy call cost several times the search itself, at every bid message of every peer (with 24
agents, ~12 messages per agent step). Up to :data:`ENUMERATE_UP_TO` a side, every injective assignment of the smaller
side is tried (at most 4!/0! = 24); beyond, scipy's.
"""

from __future__ import annotations

from itertools import permutations

import numpy as np
from scipy.optimize import linear_sum_assignment

ENUMERATE_UP_TO = 4  # rows or columns; chosen here


def least_cost_pairs(cost: list[list[float]]) -> list[tuple[int, int]]:
    """The ``(row, column)`` pairs, ``min(rows, columns)`` of them in row order, whose costs sum to the least."""
    rows = len(cost)
    cols = len(cost[0]) if rows else 0
    if rows == 0 or cols == 0:
        return []
    if max(rows, cols) > ENUMERATE_UP_TO:
        r, c = linear_sum_assignment(np.asarray(cost, float))
        return list(zip(r.tolist(), c.tolist(), strict=True))
    if rows <= cols:
        best = min(permutations(range(cols), rows), key=lambda p: sum(cost[i][j] for i, j in enumerate(p)))
        return list(enumerate(best))
    best = min(permutations(range(rows), cols), key=lambda p: sum(cost[i][j] for j, i in enumerate(p)))
    return sorted((i, j) for j, i in enumerate(best))
