"""The run's terminal summary: 80 columns, units in the headers, a labelled fleet row, ANEES with its χ² interval
and a mark outside it, no empty tracking table when nothing is tracked (the fire scenario)."""

from __future__ import annotations

import io

import pytest
from rich.console import Console

from mesh_sim.phases import anees_interval
from mesh_sim.results import anees_cell, grid_table, summary_table

DURATION = 60.0


def target(name: str, rmse: float | None, anees: float | None, seconds: int = 60) -> dict:
    """A per-target score tracked for ``seconds`` one-second bins (six independent samples for 60 s)."""
    bins = [[float(k), 1.0, 6.0, 10, 3.0] for k in range(seconds)] if rmse is not None else []
    return {"target": name, "rmse": rmse, "anees": anees, "samples": 10 * len(bins), "time_to_first_track": 2.5,
            "bins": bins}


def agent(name: str, anees: float) -> dict:
    return {"id": name, "targets": [target("car", 1.0, anees), target("walker", 2.0, anees)], "bytes_tx": 600_000,
            "exact_share": 1.0, "radio_drops_by_cause": {"loss": 9, "rate": 3}, "msgs_rejected": 1,
            "deadline_misses": 0}


def metrics(agents: list[dict], fleet_anees: float | None = 0.3) -> dict:
    oracle_targets = [target("car", 0.9, 0.6), target("walker", 0.9, 0.6)]
    return {
        "status": "completed", "agents": agents, "config": {"duration": DURATION}, "phases": [], "losses": [],
        "oracle": {"targets": oracle_targets, "rmse": 0.9, "anees": 0.6},
        "fleet": {"rmse": 1.5, "anees": fleet_anees, "rmse_ratio_to_oracle": 1.67, "rmse_ratio_to_in_flight": 1.1,
                  "bytes_per_agent_per_s": 10_000.0, "targets_tracked_by_every_agent": True, "exact_share": 1.0},
    }


def render(renderable, width: int = 80) -> list[str]:
    out = io.StringIO()
    Console(file=out, width=width, color_system=None).print(renderable)
    return out.getvalue().splitlines()


def test_the_tables_fit_80_columns_and_nothing_is_cut():
    lines = render(summary_table(metrics([agent(f"uav{i}", 0.3) for i in range(8)])))
    assert max(len(line) for line in lines) <= 80
    text = "\n".join(lines)
    assert "…" not in text
    for header in ("RMSE [m]", "[B/s]", "[s]"):  # units, not swallowed as markup
        assert header in text
    assert "radio drops" in text and "12 (loss 9, rate 3)" in text  # the longest cell whole


def test_the_fleet_has_its_own_labelled_row():
    lines = render(summary_table(metrics([agent("uav0", 1.0)])))
    fleet = [line for line in lines if line.startswith("│") and "fleet" in line]
    assert len(fleet) == 2  # one row in the tracking table, one in the network table
    assert "1.67" in fleet[0] and "ratio" not in fleet[0]  # the fleet's ratio sits under "÷ oracle"
    assert "10,000" in fleet[1]


def test_anees_outside_its_interval_is_marked_and_the_legend_says_what_it_means():
    lo, hi = anees_interval(6)
    assert anees_cell(lo * 0.9, 6) == f"{lo * 0.9:.2f} ↓ [{lo:.2f}, {hi:.2f}]"
    assert anees_cell(hi * 1.1, 6) == f"{hi * 1.1:.2f} ↑ [{lo:.2f}, {hi:.2f}]"
    assert anees_cell(1.0, 6) == f"1.00 [{lo:.2f}, {hi:.2f}]"
    assert anees_cell(None, 6) == "-"
    text = " ".join(" ".join(render(summary_table(metrics([agent("uav0", 0.3)])))).split())
    two_targets = anees_interval(12)  # two targets tracked 60 s: six independent samples each
    assert f"0.30 ↓ [{two_targets[0]:.2f}, {two_targets[1]:.2f}]" in text
    lines = render(summary_table(metrics([agent("uav0", 0.3)])))
    assert any("↓ below" in line and "too large" in line and "too small" in line for line in lines)  # one line


def test_no_tracking_table_without_tracked_targets():
    fire = metrics([{**agent("uav0", 1.0), "targets": []}], fleet_anees=None)
    text = "\n".join(render(summary_table(fire)))
    assert "tracking" not in text and "ANEES" not in text
    assert "completed — network" in text


@pytest.mark.parametrize("width", [80, 120])
def test_the_fire_map_table_fits(width):
    roc = {"threshold": 0.8, "detected": 3, "fires": 3, "decoys_rejected": 3, "decoys": 3, "other_false_alarms": 0,
           "localisation_error_m": 2.73}
    fire = {**metrics([agent("uav0", 1.0)]), "config": {"duration": DURATION}}
    fire["oracle"]["grid"] = {"agents": {"uav0": {"roc": [roc], "kl_final": 40.0}}, "central": {"roc": [roc]},
                              "located": {"uav0": {**roc, "localisation_error_m": 0.42}}}
    fire["fleet"]["grid"] = {"threshold": 0.8}
    lines = render(grid_table(fire), width)
    assert max(len(line) for line in lines) <= width and "…" not in "\n".join(lines)
    text = "\n".join(lines)
    assert "0.42" in text and "2.73" in text  # where the agent reports its alarms, beside its grid's own
