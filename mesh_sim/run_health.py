"""Is a completed run what it claims? A run whose agents fell behind or lost their sensor still completes, but it
says so: status ``completed with warnings`` and one line per agent and problem, read from the collected metrics.

* an agent that missed more than :data:`DEADLINE_MISS_LIMIT` of its steps' deadlines (``deadline_misses`` of
  ``steps``): its loop could not keep up with the simulated time (``skymesh bench scale`` reports the same
  share, against the same 1 %);
* an agent whose video source failed (the camera's ``video_failed_at``, :mod:`agent.sensors.camera`): its
  bearings stopped there.
"""

from __future__ import annotations

from pathlib import Path

from agent.runtime import write_json

DEADLINE_MISS_LIMIT = 0.01  # share of an agent's steps; the 1 % that bench scale counts as keeping up (issue 18)
WITH_WARNINGS = "completed with warnings"


def _percent(share: float) -> str:
    return f"{100 * share:.0f} %" if share >= 0.1 else f"{100 * share:.1f} %"


def warnings(metrics: dict) -> list[str]:
    """One line per agent and problem, e.g. ``uav2 missed 12 % of its deadlines (18 of 151 steps)``."""
    found = []
    for agent in metrics["agents"]:
        steps, misses = agent.get("steps") or 0, agent.get("deadline_misses") or 0
        if steps and misses / steps > DEADLINE_MISS_LIMIT:
            found.append(f"{agent['id']} missed {_percent(misses / steps)} of its deadlines ({misses} of {steps} "
                         "steps)")
        failed_at = agent.get("sensor", {}).get("video_failed_at")
        if failed_at is not None:
            found.append(f"{agent['id']}'s video source failed at t = {failed_at:.1f} s; no bearings from it since")
    return found


def judge(run_dir: Path, metrics: dict) -> dict:
    """``metrics`` with its warnings (``"warnings"``, only when there are some) and, for a completed run that has
    some, the status ``completed with warnings``; ``metrics.json`` in ``run_dir`` is rewritten to say the same."""
    found = warnings(metrics)
    if not found:
        return metrics
    judged = {**metrics, "warnings": found,
              "status": WITH_WARNINGS if metrics["status"] == "completed" else metrics["status"]}
    write_json(run_dir / "metrics.json", judged)
    return judged
