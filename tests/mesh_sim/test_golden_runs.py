"""Golden lockstep runs: short runs of the shipped scenarios must reproduce what the code computed when their
golden files were written (``mesh_sim.run_compare``: every float to :data:`GOLDEN_RTOL`, volatile fields such
as pids and wall times aside; ``skymesh compare`` without ``--rtol`` checks a refactoring bit for bit on one
installation).

``golden/<scenario>-<seed>.json`` holds the settings of one run (scenario, seed, duration: the scenario
loader's overrides, as ``skymesh run --duration S --seed K`` applies them), the commit of the code that
wrote it, and a :func:`mesh_sim.run_compare.snapshot` of its run folder (``metrics.json`` in full,
``agent-*.json``, ``oracle.json`` and ``fire_maps.npz`` as SHA-256 digests). The durations are short (all
six runs take well under a minute) but each run does something: tracks form in default (the camera pipeline), grids
are exchanged and fused in fire, and partition crosses its t = 15 s partition event.

The files were written from the code before the agent package was restructured into net/, sensors/,
beliefs/ and vehicles/ (a pure refactoring), from a checkout of that code, with::

    .venv/bin/python -m tests.mesh_sim.test_golden_runs --write --code /path/to/pre-restructuring/checkout

A change that alters behaviour on purpose regenerates them from the current tree (and says so in its
commit)::

    .venv/bin/python -m tests.mesh_sim.test_golden_runs --write

Run only these tests: ``.venv/bin/pytest -q tests/mesh_sim/test_golden_runs.py``. They are marked
``slow`` (``pytest -m "not slow"`` skips them), except the fast checks of the comparison itself.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

from mesh_sim import cli
from mesh_sim.run_compare import compare, diff, difference_lines, resolve_run, snapshot

GOLDEN = Path(__file__).with_name("golden")
REPO = Path(__file__).resolve().parents[2]
#: (scenario, simulated seconds) of each golden run, at each of SEEDS.
DURATIONS = {"default": 10.0, "fire": 8.0, "partition": 18.0}
SEEDS = (1, 2)
#: Floats must agree to this relative tolerance, arrays by their sums (``mesh_sim.run_compare.diff``): a fresh
#: install in November 2026 (numpy 2.4.6, SciPy 1.17.1, OpenCV 5.0.0.93) moved the runs by ~1e-11 relative,
#: and the fire scenario's central map by its digest, from the versions that wrote the files; a change of
#: behaviour moves them by far more (a different association or detection: 1e-3 and up).
GOLDEN_RTOL = 1e-6
CASES = [(name, seed, duration) for name, duration in DURATIONS.items() for seed in SEEDS]


def run_argv(scenario: str, seed: int, duration: float, out: Path) -> list[str]:
    """``skymesh`` arguments of one golden run."""
    return ["run", "--lockstep", "--rerun", "off", "--scenario", scenario, "--seed", str(seed),
            "--duration", repr(duration), "--out", str(out)]


def golden_path(scenario: str, seed: int) -> Path:
    return GOLDEN / f"{scenario}-{seed}.json"


@pytest.mark.slow
@pytest.mark.parametrize(("scenario", "seed", "duration"), CASES, ids=[f"{s}-{k}" for s, k, _ in CASES])
def test_lockstep_run_reproduces_its_golden_file(scenario, seed, duration, tmp_path):
    golden = json.loads(golden_path(scenario, seed).read_text())
    assert (golden["scenario"], golden["seed"], golden["duration"]) == (scenario, seed, duration), (
        "the golden file was written with other settings: regenerate it (see the module docstring)")
    with contextlib.redirect_stdout(io.StringIO()):
        assert cli.main(run_argv(scenario, seed, duration, tmp_path)) == 0
    differences = diff(golden["snapshot"], snapshot(resolve_run(tmp_path)), rtol=GOLDEN_RTOL)
    assert not differences, (f"{scenario} seed {seed}: {len(differences)} differences from {golden['written_by']}:\n"
                             + "\n".join(difference_lines(differences, limit=40)))


# ------------------------------------------------------------------------------------------------------
# The comparison itself (fast)


def _fake_run(folder: Path, rmse: float = 1.5, pid: int = 11, wall: float = 2.0, fire=None) -> Path:
    folder.mkdir(parents=True)
    agent = {"pid": pid, "id": "uav0", "steps": 51, "cpu_per_step_ms": wall * 3, "rss_mb": pid / 7,
             "targets": [{"target": "car", "rmse": rmse, "samples": 40}]}
    oracle = {"targets": [], "wall_s": wall, "note": f"fleet demo-{pid:08x} in {folder}"}
    metrics = {"status": "completed", "agents": [agent], "oracle": oracle, "fleet": {"rmse": rmse},
               "config": {"name": "demo", "duration": 10.0, "speed": 10.0 / wall, "vehicle": {"max_speed": 12.0}}}
    for name, data in (("metrics.json", metrics), ("agent-uav0.json", agent), ("oracle.json", oracle)):
        (folder / name).write_text(json.dumps(data, indent=2))
    if fire is not None:
        np.savez_compressed(folder / "fire_maps.npz", central=fire, truth=(fire > 0.5).astype(np.int8))
    return folder


def test_volatile_fields_are_ignored_and_a_float_must_match_bit_for_bit(tmp_path):
    maps = np.linspace(0.0, 1.0, 12).reshape(3, 4)
    before = _fake_run(tmp_path / "a" / "demo-20260101-120000-abcd", fire=maps)
    after = _fake_run(tmp_path / "b" / "demo-20260101-120501-0f0f", pid=99, wall=3.5, fire=maps)
    assert compare(tmp_path / "a", after) == []  # a folder holding one run folder stands for it
    changed = _fake_run(tmp_path / "c", rmse=math.nextafter(1.5, 2.0), fire=np.where(maps > 0.95, 0.95, maps))
    paths = {d.path: d for d in compare(before, changed)}
    assert set(paths) == {"metrics.json: agents[0].targets[0].rmse", "metrics.json: fleet.rmse",
                          "agent-uav0.json: targets[0].rmse", "fire_maps.npz: central"}
    assert paths["metrics.json: fleet.rmse"].after == repr(math.nextafter(1.5, 2.0))
    assert "1 of 12 elements differ" in paths["fire_maps.npz: central"].after
    assert diff(snapshot(before), snapshot(after)) == []
    assert {d.path for d in diff(snapshot(before), snapshot(changed))} == {
        "metrics.json: agents[0].targets[0].rmse", "metrics.json: fleet.rmse", "agent-uav0.json: sha256",
        "fire_maps.npz: central.sha256", "fire_maps.npz: central.sum", "fire_maps.npz: central.sum_squares"}


def test_a_tolerance_accepts_rounding_and_still_sees_a_change(tmp_path):
    """The last bits a new numpy release may move pass with ``rtol``; a real change (1e-4 relative, one map
    cell changed by 0.05) does not, in a run folder or in its snapshot."""
    maps = np.linspace(0.0, 1.0, 12).reshape(3, 4)
    before = _fake_run(tmp_path / "a", fire=maps)
    rounded = _fake_run(tmp_path / "b", rmse=1.5 * (1 + 3e-12), fire=maps * (1 + 1e-13))
    assert {d.path for d in compare(before, rounded)} >= {"metrics.json: fleet.rmse", "fire_maps.npz: central"}
    assert compare(before, rounded, rtol=1e-6) == []
    assert diff(snapshot(before), snapshot(rounded), rtol=1e-6) == []
    changed = _fake_run(tmp_path / "c", rmse=1.5 * (1 + 1e-4), fire=np.where(maps > 0.95, 0.95, maps))
    assert {d.path for d in diff(snapshot(before), snapshot(changed), rtol=1e-6)} == {
        "metrics.json: agents[0].targets[0].rmse", "metrics.json: fleet.rmse",
        "fire_maps.npz: central.sum", "fire_maps.npz: central.sum_squares"}
    assert cli.main(["compare", "--rtol", "1e-6", str(before), str(rounded)]) == 0
    assert cli.main(["compare", "--rtol", "-1", str(before), str(rounded)]) == 2  # a negative tolerance


def test_types_missing_keys_and_files_are_differences(tmp_path):
    before = _fake_run(tmp_path / "a", fire=np.zeros((2, 2)))
    after = _fake_run(tmp_path / "b")
    metrics = json.loads((after / "metrics.json").read_text())
    metrics["fleet"] = {"rmse": 2, "extra": [1, 2]}
    (after / "metrics.json").write_text(json.dumps(metrics))
    found = {d.path: (d.before, d.after) for d in compare(before, after)}
    assert found == {"metrics.json: fleet.rmse": ("1.5", "2"), "metrics.json: fleet.extra": ("(missing)", "[1, 2]"),
                     "fire_maps.npz": ("present", "(missing)")}


def test_compare_command_exit_codes(tmp_path, capsys):
    before = _fake_run(tmp_path / "before" / "x")
    _fake_run(tmp_path / "after" / "x", pid=5, wall=9.0)
    assert cli.main(["compare", str(before), str(tmp_path / "after" / "x")]) == 0
    _fake_run(tmp_path / "other", rmse=2.5)
    assert cli.main(["compare", "--plain", str(before), str(tmp_path / "other")]) == 1
    out = capsys.readouterr().out
    assert "metrics.json: fleet.rmse  before 1.5  after 2.5" in out
    assert cli.main(["compare", str(tmp_path / "nowhere"), str(before)]) == 2
    (tmp_path / "empty").mkdir()
    assert cli.main(["compare", str(before), str(tmp_path / "empty")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 2 and "no such folder" in err and "not a run folder" in err


def test_compare_tree_prints_one_line_per_pair(tmp_path, capsys):
    _fake_run(tmp_path / "before" / "same" / "demo-20260101-120000-abcd")
    _fake_run(tmp_path / "after" / "same" / "demo-20260101-130000-dcba", pid=3)
    _fake_run(tmp_path / "before" / "changed")
    _fake_run(tmp_path / "after" / "changed", rmse=3.0)
    _fake_run(tmp_path / "before" / "gone")
    (tmp_path / "before" / "stray.log").write_text("not a folder: not paired")
    assert cli.main(["compare", "--tree", str(tmp_path / "before"), str(tmp_path / "after")]) == 1
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == "changed: 3 differences"
    assert lines[1].startswith("gone: not compared: missing in AFTER")
    assert lines[2:] == ["same: identical", "1 of 3 pairs identical"]


# ------------------------------------------------------------------------------------------------------
# Writing the golden files


def _commit(tree: Path) -> str:
    def git(*args: str) -> str:
        return subprocess.run(["git", "-C", str(tree), *args], capture_output=True, text=True).stdout.strip()

    head = git("rev-parse", "HEAD") or "unknown"
    return head + ("+uncommitted changes" if git("status", "--porcelain", "--untracked-files=no") else "")


def write_golden(code: Path) -> None:
    """Run every case with the code of the tree ``code`` (``python -m mesh_sim`` in that folder imports its
    own packages first) and write its golden file."""
    code = code.resolve()
    where = subprocess.run([sys.executable, "-c", "import agent, mesh_sim; print(agent.__file__, mesh_sim.__file__)"],
                           cwd=code, capture_output=True, text=True, check=True).stdout.split()
    if not all(Path(p).resolve().is_relative_to(code) for p in where):
        sys.exit(f"python -m mesh_sim in {code} imports {where}, not that tree's code")
    GOLDEN.mkdir(exist_ok=True)
    written_by = {"commit": _commit(code)}
    for scenario, seed, duration in CASES:
        with tempfile.TemporaryDirectory() as out:
            argv = run_argv(scenario, seed, duration, Path(out))
            subprocess.run([sys.executable, "-m", "mesh_sim", *argv], cwd=code, check=True, stdout=subprocess.DEVNULL)
            data = {"scenario": scenario, "seed": seed, "duration": duration, "written_by": written_by,
                    "snapshot": snapshot(resolve_run(out))}
        golden_path(scenario, seed).write_text(json.dumps(data, indent=1) + "\n")
        print(f"wrote {golden_path(scenario, seed).relative_to(REPO)}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description="Write the golden files of test_golden_runs.py.")
    parser.add_argument("--write", action="store_true", required=True, help="run every case and write its file")
    parser.add_argument("--code", type=Path, default=REPO, help="the source tree to run (default: this one)")
    write_golden(parser.parse_args().code)
