"""Which alarm this UAV watches: the monitoring phase of a fire mission, decided by every agent alike.

Merino's COMETS missions run detect → confirm → monitor (spec 001b §2.8, §4.4: an alarm is confirmed by a UAV
sent to it, then watched), with the allocation at a control centre. Here each agent solves the same small
assignment from what it knows, with no message of its own:

* the alarms where its map reports them (``k`` (north, east) positions: the alarms' tracks, Merino Ch. 8);
* the agents: itself and the peers whose positions it heard lately (the grid messages carry the sender's);
* the cost of a pair: the horizontal distance from the agent to the alarm;
* ``explorers`` zero-cost free columns (a free column means "keep exploring").

The least-cost one-to-one matching (:func:`tasking.matching.least_cost_pairs`) of the ``n`` agents to the
``k + explorers`` columns then watches every alarm while ``k <= n - explorers`` (a matching of the rows takes every
column when there are more rows; otherwise the agents nearest to the alarms watch them) and never more than
``n - explorers`` of them, so ``explorers`` agents go on exploring. An agent that won an alarm hovers over it,
where the down-looking thermal camera keeps the whole fire in its frame and the alarm's track is fed every
frame: a fire that spreads is located where it is now, not where it was when the explorer passed.

Agents that know slightly different positions or alarm lists may disagree for a while (two watch one alarm);
once watchers hover over their alarms the matching is stable: an agent at an alarm costs 0 for it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from tasking.matching import least_cost_pairs

__all__ = ["watched_alarm"]


def watched_alarm(position, peers: Mapping[str, np.ndarray], alarms: Sequence[np.ndarray],
                  explorers: int) -> int | None:
    """The index in ``alarms`` this agent watches, or ``None`` (it explores). ``position``: this agent's
    (north, east[, down]); ``peers``: the others' (north, east) by id; ``alarms``: (north, east) positions."""
    if not alarms:
        return None
    agents = [np.asarray(position, float)[:2]] + [np.asarray(peers[p], float)[:2] for p in sorted(peers)]
    targets = np.asarray(alarms, float).reshape(-1, 2)
    distance = np.linalg.norm(np.stack(agents)[:, None, :] - targets[None, :, :], axis=-1)  # (n, k) m
    cost = np.hstack([distance, np.zeros((len(agents), explorers))])
    for row, column in least_cost_pairs(cost.tolist()):
        if row == 0:
            return column if column < len(targets) else None
    return None
