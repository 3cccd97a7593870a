"""The watch end to end (tasking/alarm_watch.py): in a lockstep fire mission the agents split into a watcher that
hovers over a fire and locates it, and an explorer — a split each makes alone, from the positions their grid
messages carry."""

from __future__ import annotations

import numpy as np
import pytest

from mesh_sim.launcher import new_run_dir
from mesh_sim.lockstep import run_lockstep
from mesh_sim.scenario import load


@pytest.fixture(scope="module")
def watched_run(tmp_path_factory):
    """Two agents on a line over ideal links for 40 s, watching from the start (``watch_from = 0``): one explorer
    (``explorers = 1``) leaves one watcher."""
    scenario = load("fire", agents=2, duration=40.0, tasking={"watch_from": 0.0},
                    radio={"topology": "line", "preset": "ideal"})
    run_dir = new_run_dir(tmp_path_factory.mktemp("runs"), scenario.name)
    return run_lockstep(scenario, run_dir)


def _last_seconds(metrics, agent: str, seconds: float) -> np.ndarray:
    """The agent's (north, east) trace over the run's last ``seconds``."""
    trace = np.array(metrics["oracle"]["traces"]["uavs"][agent])
    return trace[trace[:, 0] >= trace[-1, 0] - seconds][:, 1:3]


def test_one_agent_hovers_over_a_fire_and_locates_it_while_the_other_explores(watched_run):
    """Without the peer's position each agent would think itself alone, and with one explorer kept nobody would
    watch: the split shows the positions travelled. The watcher's last 5 s stay within a few metres of one of its
    located alarms, which sits on a true fire; the explorer keeps moving."""
    metrics = watched_run
    regions = metrics["oracle"]["grid"]["fire_regions"]
    watchers, explorers = [], []
    for agent in metrics["agents"]:
        path = _last_seconds(metrics, agent["id"], 5.0)
        located = np.array([a["mean"] for a in agent["grid"]["located_alarms"]]).reshape(-1, 2)
        near = np.linalg.norm(located - path[-1], axis=1) if len(located) else np.array([np.inf])
        if np.ptp(path, axis=0).max() < 5.0 and near.min() < 5.0:
            watchers.append(located[int(np.argmin(near))])
        elif np.ptp(_last_seconds(metrics, agent["id"], 10.0), axis=0).max() > 20.0:
            explorers.append(agent["id"])
    assert len(watchers) == 1 and len(explorers) == 1
    error = min(np.hypot(*(watchers[0] - np.asarray(r["centroid"]))) for r in regions)
    assert error < 2.0  # on the fire it watches (a fire of a few 5 m cells, its centre jumping as cells ignite)
