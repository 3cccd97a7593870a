"""A bad value given on the command line is blamed on its flag, a bad scenario file on the file (issue 18, item 6).
Each test names the bad input; ``skymesh run --lockstep`` shows its progress."""

from __future__ import annotations

import io

import pytest
from rich.console import Console

from mesh_sim import cli, sim_progress
from mesh_sim.lockstep import run_lockstep
from mesh_sim.scenario import load


@pytest.mark.parametrize(("argv", "error"), [
    (["--duration", "0"], "--duration 0.0: duration must be a positive number, got 0.0"),
    (["--loss", "1.5"], "--loss 1.5: radio: loss: must be <= 1, got 1.5"),
    (["--agents", "3", "--latency", "-5"], "--latency -5.0: radio: delay_ms: must be >= 0, got -5"),
])
def test_a_bad_flag_value_names_the_flag_not_the_file(tmp_path, capsys, argv, error):
    code = cli.main(["run", "--lockstep", "--rerun", "off", "--out", str(tmp_path), *argv])
    assert code == 2 and capsys.readouterr().err == f"skymesh run: {error}\n"
    assert list(tmp_path.iterdir()) == []


def test_a_bad_scenario_file_still_names_the_file(tmp_path, capsys):
    """Bad input: a scenario file saying ``duration = 0``, with a good ``--loss`` flag."""
    path = tmp_path / "bad.toml"
    path.write_text(load("default").path.read_text().replace("duration = 60.0", "duration = 0.0"))
    assert "duration = 0.0" in path.read_text()
    code = cli.main(["run", "--lockstep", "--scenario", str(path), "--loss", "0.1", "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err
    assert code == 2 and err == f"skymesh run: {path}: duration must be a positive number, got 0.0\n"


def test_lockstep_reports_every_step_to_its_progress(tmp_path):
    seen: list[float] = []
    run_lockstep(load("default", agents=1, duration=1.0), tmp_path, advance=seen.append)
    assert seen == pytest.approx([0.2 * k for k in range(6)])


def test_the_progress_bar_shows_simulation_time_clipped_to_the_duration():
    out = io.StringIO()
    with sim_progress.sim_progress(Console(file=out, force_terminal=True, width=100), "run", 60.0) as advance:
        advance(99.0)  # past the end: shown as the end
    assert "t=60/60 s" in out.getvalue()


def test_skymesh_run_lockstep_shows_a_progress_bar_to_the_duration(tmp_path, monkeypatch):
    shown: list[tuple[str, float]] = []
    real = sim_progress.sim_progress

    def spy(console, description, duration):
        shown.append((description, duration))
        return real(console, description, duration)

    monkeypatch.setattr(sim_progress, "sim_progress", spy)
    assert cli.main(["run", "--lockstep", "--agents", "1", "--duration", "1", "--rerun", "off",
                     "--out", str(tmp_path)]) == 0
    assert shown == [("default: 1 agents (lockstep)", 1.0)]
