"""``skymesh bench rumor``: the ANEES interval against Monte Carlo, the pooled row figures against hand sums, the
channels' return to exact fusion, the goals, the method table (unavailable methods are reported, not run) and
the partition plan — fast, on synthetic run outcomes; then, slow-marked, real lockstep runs (the divergence
guard and the smallest benchmark)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mesh_sim.bench import rumor, rumor_jobs, rumor_stats
from mesh_sim.scenario import load
from tests.processes import assert_no_children_left

STEP = 0.2


def _t(target: str, rmse: float, anees: float, samples: int) -> dict:
    return {"target": target, "rmse": rmse, "anees": anees, "samples": samples}


def _outcome(job: dict, agents: list[list[dict]], oracle: list[dict], fusions=None, radio_bytes=0,
             t_end=20.0, channels=None, edges=None, imm=None, in_flight=()) -> dict:
    """A run's outcome as :func:`rumor_jobs.run_job` returns it; the IMM oracle scores as ``oracle`` unless given."""
    out = {
        "job": job, "step": STEP, "agents_n": len(agents), "t_end": t_end, "diverged_at": None, "max_tracks": 3,
        "crashed_at": None, "error": None,
        "agents": [{"id": f"uav{i}", "targets": ts, "channels": (channels or {}).get(f"uav{i}", {})}
                   for i, ts in enumerate(agents)],
        "oracle_targets": oracle, "imm_targets": oracle if imm is None else imm, "in_flight_targets": list(in_flight),
        "fusions": fusions or {}, "radio_bytes": radio_bytes,
    }
    if edges is not None:
        out["edges"] = edges
    return out


def test_the_anees_interval_covers_a_consistent_estimator_95_percent_of_the_time():
    lo, hi = rumor_stats.anees_interval(5)
    rng = np.random.default_rng(0)
    anees = rng.chisquare(6 * 5, size=20000) / (6 * 5)  # ANEES of a consistent 6-D estimator over 5 samples
    assert np.mean((anees >= lo) & (anees <= hi)) == pytest.approx(0.95, abs=0.01)
    lo36, hi36 = rumor_stats.anees_interval(36)
    assert lo < lo36 < 1.0 < hi36 < hi  # more samples, narrower interval


def test_independent_samples_count_one_per_target_and_decorrelation_block():
    # 40 s tracked at 0.2 s steps = 200 samples -> 4 blocks of 10 s; a target seen once still counts once
    assert rumor_stats.independent_samples({"a": 200, "b": 1, "c": 0}, STEP) == 5


def test_a_row_pools_runs_by_samples_and_scores_each_agent_on_its_own():
    job = {"overrides": {"seed": 1}}
    runs = [
        _outcome(job, [[_t("a", 2.0, 0.6, 100)], [_t("a", 4.0, 3.0, 100)]], [_t("a", 1.0, 1.0, 100)],
                 fusions={"exact": 3, "ci": 1, "stale": 4}, radio_bytes=8000,
                 in_flight=[_t("a", 2.0, 1.0, 100), _t("a", 3.0, 1.0, 100)]),
        _outcome({"overrides": {"seed": 2}}, [[_t("a", 2.0, 0.6, 50)], [_t("a", 2.0, 0.6, 50)]],
                 [_t("a", 1.0, 0.9, 100)], radio_bytes=8000, imm=[_t("a", 1.5, 0.5, 100)],
                 in_flight=[_t("a", 2.0, 1.0, 50), _t("a", 2.0, 1.0, 50)]),
    ]
    r = rumor_stats.summarise(runs)
    assert r["seeds"] == [1, 2]
    fleet = math.sqrt((100 * 4 + 100 * 16 + 50 * 4 + 50 * 4) / 300)  # sample-weighted RMSE
    oracle = math.sqrt((100 + 100) / 200)
    assert r["rmse"] == pytest.approx(fleet) and r["rmse_ratio"] == pytest.approx(fleet / oracle)
    assert r["anees"] == pytest.approx((60 + 300 + 30 + 30) / 300)
    in_flight = math.sqrt((100 * 4 + 100 * 9 + 50 * 4 + 50 * 4) / 300)  # each agent's own reference, pooled
    assert r["in_flight_ratio"] == pytest.approx(fleet / in_flight)
    assert r["oracle_anees"] == pytest.approx(0.75)  # consistency is judged on the IMM oracle
    assert r["same_model_oracle_anees"] == pytest.approx(0.95)
    assert r["independent_samples"] == 2 + 1 and r["oracle_independent_samples"] == 2 + 2  # 20 s, 10 s; 20 s, 20 s
    assert (r["anees_lo"], r["anees_hi"]) == pytest.approx(rumor_stats.anees_interval(3))
    a0, a1 = r["agents_anees"]["uav0"], r["agents_anees"]["uav1"]
    assert a0["anees"] == pytest.approx(0.6) and a0["ok"]
    assert a1["anees"] == pytest.approx((300 + 30) / 150) and not a1["ok"]  # above its upper bound
    assert (r["agents_anees_min"], r["agents_consistent"], r["agents"]) == (pytest.approx(0.6), 1, 2)
    assert r["exact_share"] == pytest.approx(3 / 4)  # stale messages are not fusions
    assert r["bytes_per_agent_s"] == pytest.approx(16000 / (2 * 20 + 2 * 20))


def test_recovery_times_after_a_merge_per_directed_tree_channel():
    channels = {
        "uav0": {"uav1": {"exact_spans_s": [[1.0, 12.0], [25.0, 40.0]]}},  # silent over the partition
        "uav1": {"uav0": {"exact_spans_s": [[1.0, 30.0]]}, "uav2": {"exact_spans_s": [[5.0, 40.0]]}},  # across
        "uav2": {"uav1": {"exact_spans_s": [[1.0, 10.0]]}},  # never exact again
    }
    out = _outcome({"overrides": {"seed": 3}}, [[], [], []], [], channels=channels,
                   edges=[["uav0", "uav1"], ["uav1", "uav2"]])
    got = {(c["agent"], c["peer"]): c["exact_after_s"] for c in rumor_stats.recovery(out, 20.0)}
    assert got == {("uav0", "uav1"): 5.0, ("uav1", "uav0"): 0.0, ("uav1", "uav2"): 0.0, ("uav2", "uav1"): None}


def _row(kind="cell", topology="tree", loss=0.0, method="hybrid", ratio=1.0, anees=1.0, **more) -> dict:
    base = {"kind": kind, "topology": topology, "loss": loss, "method": method, "name": f"{topology} {method}",
            "rmse_ratio": ratio, "in_flight_ratio": more.pop("in_flight", ratio), "anees": anees, "anees_lo": 0.7,
            "anees_hi": 1.3, "oracle_anees": 1.0,
            "oracle_anees_lo": 0.7, "oracle_anees_hi": 1.3, "agents_consistent": 4, "agents": 4,
            "agents_anees_min": 0.9, "agents_anees_max": 1.1, "diverged_runs": 0, "crashed_runs": 0}
    return base | more


def test_the_goals_of_issue_11():
    rows = [
        _row(ratio=1.3, in_flight=1.04), _row(method="exact", ratio=1.06), _row(topology="ring", loss=0.3, ratio=1.2),
        _row(topology="ring", method="ci", ratio=1.6),  # no ratio goal for ci
        _row(topology="full", method="naive", ratio=1.3, anees=2.0), _row(topology="full", method="naive", anees=1.2),
        _row(kind="demo", topology="full", loss=None, ratio=1.3, agents_consistent=3, oracle_anees=0.5),
        _row(kind="partition", channels=[{"exact_after_s": 2.0}, {"exact_after_s": 12.0}]),
        {"kind": "cell", "topology": "tree", "loss": 0.0, "method": "ici", "name": "tree ici", "unavailable": "x"},
    ]
    goals = rumor_stats.goals(rows)
    verdicts = [(g["row"], g["goal"].split(" ")[0], g["pass"]) for g in goals if not g["goal"].startswith("oracle")]
    assert verdicts == [
        ("tree hybrid", "fleet", True), ("tree hybrid", "every", True), ("tree exact", "fleet", False),
        ("ring hybrid", "fleet", True), ("ring hybrid", "every", True),
        ("full naive", "naive", True), ("full naive", "naive", False),
        ("full hybrid", "fleet", False), ("full hybrid", "every", False),  # the demo row: 1.3 > 1.25, 3/4 agents
        ("tree hybrid", "every", True), ("tree hybrid", "every", False),  # partition: 12 s > 10 s
    ]
    assert [r.get("ratio_limit") for r in rows[:4]] == [1.05, 1.05, 1.25, None] and rows[6]["ratio_limit"] == 1.25
    assert rows[6]["oracle_pass"] is False and rows[0]["oracle_pass"] is True
    assert rows[7]["recovery_s"] == 12.0 and "ratio_pass" not in rows[8]
    never = [_row(kind="partition", channels=[{"exact_after_s": 1.0}, {"exact_after_s": None}])]
    assert rumor_stats.goals(never)[-1]["pass"] is False and never[0]["recovery_s"] == math.inf
    assert rumor_stats.goals([_row(ratio=1.0, diverged_runs=1)])[0]["pass"] is False  # a diverged run fails


def test_methods_the_code_rejects_are_unavailable_with_the_loaders_error(monkeypatch):
    assert rumor.unavailable(("naive", "exact", "ci", "hybrid")) == {}
    monkeypatch.setitem(rumor.METHODS, "bogus", {"tracking": {"policy": "bogus"}})
    monkeypatch.setitem(rumor.METHODS, "odd", {"tracking": {"no_such_setting": 1}})
    missing = rumor.unavailable(("bogus", "odd", "hybrid"))
    assert set(missing) == {"bogus", "odd"} and "bogus" in missing["bogus"] and "no_such_setting" in missing["odd"]


def test_the_partition_splits_the_team_in_halves_from_a_third_to_two_thirds_of_the_run():
    events = rumor.partition_events(7, 120.0)
    assert [(e["t"], e["kind"]) for e in events] == [(40.0, "partition"), (80.0, "merge")]
    assert events[0]["groups"] == [["uav0", "uav1", "uav2"], ["uav3", "uav4", "uav5", "uav6"]]
    plan = load("default", agents=7, duration=120.0, radio={"topology": "tree", "events": events}).agent.radio_plan
    halves = [set(g) for g in events[0]["groups"]]
    crossing = {e for e in plan.edges_at(0.0) if not any(e <= h for h in halves)}
    assert crossing and not crossing & plan.edges_at(50.0) and plan.edges_at(90.0) == plan.edges_at(0.0)


def _fake_runs(jobs, workers, title):
    """Synthetic outcomes for the jobs (no lockstep run): what run() sends out and how it builds rows."""
    out = []
    for job in jobs:
        channels = {"uav0": {"uav1": {"exact_spans_s": [[1.0, 30.0]]}}}
        edges = [["uav0", "uav1"]] if job.get("edges_at") is not None else None
        out.append(_outcome(job, [[_t("a", 2.0, 1.0, 100)], [_t("a", 2.0, 1.0, 100)]], [_t("a", 1.9, 1.0, 100)],
                            fusions={"exact": 1}, radio_bytes=4000, channels=channels, edges=edges))
    return out


def test_run_builds_one_row_per_cell_the_demo_and_the_partition_and_skips_unavailable_methods(monkeypatch, printed):
    sent = []
    monkeypatch.setattr(rumor_jobs, "run_jobs", lambda jobs, w, t: sent.extend(jobs) or _fake_runs(jobs, w, t))
    monkeypatch.setitem(rumor.METHODS, "bogus", {"tracking": {"policy": "bogus"}})
    result = rumor.run(topologies=("ring",), losses=(0.0, 0.3), methods=("hybrid", "bogus"), seeds=2)
    assert [r["name"] for r in result["rows"]] == ["ring 0 % hybrid", "ring 0 % bogus", "ring 30 % hybrid",
                                                   "ring 30 % bogus", "demo (make demo)", "partition tree 0 % hybrid"]
    assert "bogus" in result["settings"]["unavailable"] and all(j["row"]["method"] != "bogus" for j in sent)
    demo = [j for j in sent if j["row"]["kind"] == "demo"]
    assert [j["overrides"] for j in demo] == [{"seed": 1}, {"seed": 2}]  # the shipped scenario, seed aside
    cell = next(j for j in sent if j["row"]["kind"] == "cell")
    assert cell["overrides"] == {"agents": 7, "duration": 120.0, "seed": 1, "radio": {"topology": "ring", "loss": 0.0},
                                 "tracking": {"policy": "hybrid"}}
    part = next(r for r in result["rows"] if r["kind"] == "partition")
    assert part["t_merge"] == 80.0 and len(part["channels"]) == 2 * 2  # 2 directed channels x 2 seeds
    ring = result["rows"][0]
    assert ring["rmse_ratio"] == pytest.approx(2.0 / 1.9) and ring["ratio_pass"] and ring["seeds"] == [1, 2]
    text = printed(rumor, result)
    assert "unavailable" in text and "bogus" in text and "PASS" in text and "FAIL" in text
    assert "Partition/merge (merge at 80.0 s)" in text


@pytest.mark.slow
def test_a_run_whose_tracks_explode_is_stopped_and_scored_until_then(monkeypatch):
    from mesh_sim import lockstep

    agent_cls, world_cls = lockstep.Agent, lockstep.World
    monkeypatch.setattr(rumor_jobs, "DIVERGED_TRACKS", 1)  # any second track counts as an explosion
    job = {"label": "ring naive", "scenario": "default",
           "overrides": {"agents": 3, "duration": 15.0, "seed": 1, "radio": {"topology": "ring"},
                         "tracking": {"policy": "naive"}}}
    out = rumor_jobs.run_job(job)
    assert (lockstep.Agent, lockstep.World) == (agent_cls, world_cls)  # restored
    assert out["diverged_at"] is not None and out["t_end"] == out["diverged_at"] < 15.0
    assert out["crashed_at"] is None and out["error"] is None and out["max_tracks"] >= 2


@pytest.mark.slow
def test_rumor_smallest_run(printed):
    result = rumor.run(quick=True, topologies=("full",), methods=("naive", "hybrid"), agents=3, duration=20.0,
                       workers=2, demo=False)
    assert_no_children_left()
    assert result["benchmark"] == "rumor"
    rows = {r["name"]: r for r in result["rows"]}
    assert set(rows) == {"full 0 % naive", "full 0 % hybrid", "partition tree 0 % hybrid"}
    for r in rows.values():
        assert r["rmse"] > 0 and r["oracle_rmse"] > 0 and math.isfinite(r["rmse_ratio"])
        assert r["bytes_per_agent_s"] > 0 and r["independent_samples"] >= 1
    # the rumor effect: naive fusion double-counts around the loops of the full mesh, hybrid (CI there) does not
    assert rows["full 0 % naive"]["anees"] > rows["full 0 % hybrid"]["anees"]
    assert rows["full 0 % hybrid"]["fusions"].get("ci", 0) > 0
    part = rows["partition tree 0 % hybrid"]
    assert len(part["channels"]) == 2 * 2 and all(c["exact_after_s"] is not None for c in part["channels"])
    text = printed(rumor, result)
    assert "naive" in text and "partition" in text
