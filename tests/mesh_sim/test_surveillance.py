"""The surveillance scenario end to end (lockstep): with a short tank every vehicle goes home, lands and
refuels while the others keep the targets in view, and no two vehicles come closer than the separation."""

from __future__ import annotations

import pytest

from mesh_sim.launcher import new_run_dir
from mesh_sim.lockstep import run_lockstep
from mesh_sim.scenario import load

pytestmark = pytest.mark.slow  # a lockstep run


def test_vehicles_return_refuel_and_the_targets_stay_served(tmp_path):
    scenario = load("surveillance", duration=45.0, agents=4,
                    tasking={"flight_time": 30.0, "failure_rate": 0.0, "refuel_time": 5.0})
    metrics = run_lockstep(scenario, new_run_dir(tmp_path, "surveillance"))
    health = [a["assignment"]["health"] for a in metrics["agents"]]
    assert all(h["returns"] >= 1 for h in health), health  # 30 s of fuel in a 45 s run
    assert not any(h["state"] == "lost" for h in health), health  # no failures: everybody made it home
    assert any(h["returns"] >= 2 for h in health), health  # a second return: it landed, refuelled and flew again
    assert metrics["oracle"]["separation"]["violations"] == 0
    served = {label for a in metrics["agents"] for _, m in a["assignment"]["timeline"] for label, w in m.items()
              if w == a["id"] and ":" not in label}
    assert served, "no target was ever served"
