"""The ``skymesh bench`` command line: benchmark dispatch, JSON output, usage errors."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import pytest

from mesh_sim import cli
from mesh_sim.bench import BENCHMARKS, fusion_ops


def _skymesh(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "mesh_sim.cli", *args], capture_output=True, text=True, timeout=timeout, check=False
    )


@pytest.mark.slow  # a benchmark run in a subprocess
def test_bench_fusion_ops_quick_writes_complete_json(tmp_path):
    path = tmp_path / "out" / "fusion-ops.json"
    proc = _skymesh("bench", "fusion-ops", "--quick", "--json", str(path), "--repeats", "2")
    assert proc.returncode == 0, proc.stderr
    assert "Single operations" in proc.stdout and "Batched" in proc.stdout and "Two-input CI weight" in proc.stdout
    result = json.loads(path.read_text())
    assert result["benchmark"] == "fusion-ops"
    assert result["settings"]["quick"] is True

    rows = result["rows"]
    for row in rows:
        for key in ("us_per_call", "us_per_track", "best_us"):
            assert isinstance(row[key], float) and math.isfinite(row[key]) and row[key] > 0, (key, row)
        assert row["max_rel_diff"] < 1e-4, row  # every implementation computed the same thing
    impls = {}
    for r in rows:
        impls.setdefault((r["op"], r["n"]), set()).add(r["impl"])
    baseline = {"single": "numpy", "weights": "brent", "batched": "skymesh-loop"}
    for op in fusion_ops.OPS:
        for n in fusion_ops.SIZES:
            got = impls.get((op.key, n), set())
            assert {op.reference, baseline[op.section]} <= got, (op.key, n, got)
    weight_ratios = [c["brent_over_skymesh"] for c in result["comparisons"] if c["op"].startswith("ci_weight")]
    assert len(weight_ratios) == 2 * len(fusion_ops.SIZES)
    assert all(math.isfinite(r) and r > 0 for r in weight_ratios)
    for n in fusion_ops.SIZES:  # the test extras install filterpy and Stone Soup
        assert {"filterpy", "stonesoup", "stonesoup-info"} <= impls[("if_predict_update", n)]
        assert {"filterpy", "stonesoup"} <= impls[("bearing_eif", n)]
        assert "stonesoup-loop" in impls[("batch_if", n)] and "stonesoup-loop" in impls[("batch_bearing", n)]

    goals = result["goals"]
    assert set(goals) == {"single_op_vs_numpy", "batched_vs_stonesoup"}
    for goal in goals.values():
        assert isinstance(goal["pass"], bool) and goal["results"]
        assert all(math.isfinite(r["ratio"]) and r["ratio"] > 0 for r in goal["results"])


def test_unknown_benchmark_exits_2_and_lists_known_ones():
    proc = _skymesh("bench", "no-such-bench")
    assert proc.returncode == 2
    assert "unknown benchmark 'no-such-bench'" in proc.stderr
    assert "fusion-ops" in proc.stderr


def test_bench_without_name_is_a_usage_error(capsys):
    assert cli.main(["bench"]) == 2
    assert "fusion-ops" in capsys.readouterr().err


def test_bench_list(capsys):
    assert cli.main(["bench", "--list"]) == 0
    out = capsys.readouterr().out
    for name in BENCHMARKS:
        assert name in out


def test_python_dash_m_mesh_sim():
    proc = subprocess.run(
        [sys.executable, "-m", "mesh_sim", "bench", "--list"], capture_output=True, text=True, timeout=60, check=False
    )
    assert proc.returncode == 0, proc.stderr
    assert "fusion-ops" in proc.stdout


@pytest.mark.parametrize("argv", [["bench", "fusion-ops", "--repeats", "0"], ["frobnicate"]])
def test_bad_arguments_exit_2(argv):
    with pytest.raises(SystemExit) as excinfo:
        cli.main(argv)
    assert excinfo.value.code == 2


@pytest.mark.parametrize("argv, message", [
    (["bench", "scale", "--sizes", "0,8"], "--sizes: must be positive integers"),
    (["bench", "scale", "--sizes", "8,,16"], "--sizes: must be positive integers"),
    (["bench", "scale", "--sizes", "eight"], "--sizes: must be positive integers"),
    (["bench", "scale", "--sensor", "lidar"], "--sensor: invalid choice: 'lidar'"),
    (["bench", "fire", "--seeds", "0"], "--seeds: must be a positive integer, got 0"),
])
def test_bad_scale_options_exit_2_and_say_why(argv, message, capsys):
    with pytest.raises(SystemExit) as excinfo:
        cli.main(argv)
    assert excinfo.value.code == 2
    assert message in capsys.readouterr().err


def test_scale_options_are_refused_by_other_benchmarks(monkeypatch, capsys):
    monkeypatch.setattr(fusion_ops, "run", lambda **kwargs: pytest.fail("the benchmark must not run"))
    assert cli.main(["bench", "fusion-ops", "--quick", "--sizes", "2"]) == 2
    assert "--sizes is not an option of this benchmark (only of: scale)" in capsys.readouterr().err
    assert cli.main(["bench", "fusion-ops", "--quick", "--seeds", "2"]) == 2
    assert "--seeds is not an option of this benchmark (only of: fire)" in capsys.readouterr().err


def test_a_value_the_benchmark_refuses_exits_2_with_one_line(capsys):
    """Bad input: ``--kinds nope`` names no message kind of the fuzz benchmark (it was a traceback)."""
    assert cli.main(["bench", "fuzz", "--quick", "--kinds", "nope"]) == 2
    err = capsys.readouterr().err
    assert "unknown fuzz kinds ['nope']; known: track" in err and "Traceback" not in err


def test_the_seeds_option_reaches_the_fire_benchmark(monkeypatch):
    from mesh_sim.bench import fire

    seen = {}
    monkeypatch.setattr(fire, "run", lambda **kwargs: seen.update(kwargs) or {"benchmark": "fire", "rows": []})
    monkeypatch.setattr(fire, "report", lambda result, console=None: None)
    assert cli.main(["bench", "fire", "--seeds", "2"]) == 0
    assert seen == {"quick": False, "repeats": None, "seeds": 2}


def test_scale_options_reach_the_benchmark(monkeypatch, tmp_path):
    from mesh_sim.bench import scale

    seen = {}

    def fake_run(**kwargs):
        seen.update(kwargs)
        return {"benchmark": "scale", "rows": [], "goals": {}}

    monkeypatch.setattr(scale, "run", fake_run)
    monkeypatch.setattr(scale, "report", lambda result, console=None: None)
    path = tmp_path / "scale.json"
    assert cli.main(["bench", "scale", "--quick", "--sizes", "8,16,32,40,48", "--sensor", "bearing",
                     "--json", str(path)]) == 0
    assert seen == {"quick": True, "repeats": None, "sizes": (8, 16, 32, 40, 48), "sensor": "bearing"}
    assert json.loads(path.read_text())["benchmark"] == "scale"
    seen.clear()
    assert cli.main(["bench", "scale", "--quick"]) == 0
    assert seen == {"quick": True, "repeats": None}  # no option given: the benchmark's defaults (every sensor)
