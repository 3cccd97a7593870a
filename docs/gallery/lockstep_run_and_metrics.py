"""Run a whole team from Python, in one process, and read what the run wrote.

``skymesh run --lockstep`` is this, from the command line: the same :class:`agent.agent.Agent` as a live run,
over an in-memory bus with the same radio model, stepped on simulation time (see
[how it works](../how-it-works.md#live-and-lockstep)). Here three UAVs fly the shipped ``default`` scenario
for 10 simulated seconds in a line (a tree, so every link is exact) with the ``hybrid`` policy. The run writes
an ordinary run folder; its ``metrics.json`` holds, per agent and for the fleet, the position RMSE, ANEES and
bytes, beside the centralized oracle that received every bearing.

Run: ``python docs/gallery/lockstep_run_and_metrics.py``
"""

import json
import tempfile
from pathlib import Path

from mesh_sim import scenario
from mesh_sim.lockstep import run_lockstep


def main() -> None:
    team = scenario.load("default", agents=3, duration=10.0, radio={"topology": "line"},
                         tracking={"policy": "hybrid"})
    with tempfile.TemporaryDirectory() as folder:
        run_lockstep(team, Path(folder))
        metrics = json.loads((Path(folder) / "metrics.json").read_text())
    fleet, oracle = metrics["fleet"], metrics["oracle"]
    print(f"status: {metrics['status']}")
    for agent in metrics["agents"]:
        fused = sum(agent["fusions"].values())
        print(f"  {agent['id']}: {fused} fusions ({agent['exact_share']:.0%} exact), {agent['bytes_tx']} bytes sent")
    print(f"fleet RMSE {fleet['rmse']:.2f} m (oracle {oracle['rmse']:.2f} m,"
          f" ratio {fleet['rmse_ratio_to_oracle']:.2f}), ANEES {fleet['anees']:.2f}")


if __name__ == "__main__":
    main()
