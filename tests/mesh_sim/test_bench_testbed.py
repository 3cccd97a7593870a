"""``skymesh bench testbed`` (mesh_sim/bench/testbed.py): its ratios and goals, its error without namespaces, and
its smallest live run (root only: skipped with the reason otherwise), which leaves no process, folder or
namespace behind."""

from __future__ import annotations

import subprocess

import pytest

from mesh_sim import cli, netns
from mesh_sim.bench import testbed as bench
from tests.processes import assert_no_children_left


def _row(run: str, rmse_ratio: float, bytes_s: float, received: float, missed: float = 0.0) -> dict:
    return {"run": run, "status": "completed", "rmse": 1.0, "anees": 0.6, "rmse_ratio_to_oracle": rmse_ratio,
            "bytes_per_agent_per_s": bytes_s, "received_per_agent_per_s": received, "missed_steps": missed,
            "tbf_rate": None, "kernel_tx_per_host_per_s": None, "kernel_ratio": None, "payload_ratio": None,
            "unfanned_per_s": None}


def test_ratios_are_against_the_single_host_run_and_tbf_against_the_radio_cap_or_shaper(printed):
    rows = [_row("single host", 1.10, 3000, 9000), _row("testbed", 1.15, 3100, 9300, missed=0.01),
            _row("radio cap", 1.4, 1500, 4000), {**_row("testbed, udp", 1.1, 3000, 9000), "kernel_ratio": 1.16,
                                                 "payload_ratio": 1.07},
            {**_row("radio shaper", 1.5, 1500, 4200), "rmse": 1.25},
            _row("tbf cap", 1.68, 3000, 3800), _row("tbf cap, tcp", 2.0, 3000, 2000),
            {**_row("tbf per link", 1.5, 1500, 4300), "rmse": 1.2, "tbf_per_link": True}]
    bench._add_ratios(rows)
    by = {r["run"]: r for r in rows}
    assert by["testbed"]["rmse_ratio_vs"] == pytest.approx(1.15 / 1.10)
    assert by["testbed"]["bytes_ratio_vs"] == pytest.approx(3100 / 3000)
    assert by["tbf cap"]["against"] == "radio cap" and by["tbf cap"]["received_ratio_vs"] == pytest.approx(0.95)
    assert by["tbf cap"]["bytes_ratio_vs"] == pytest.approx(2.0)
    assert by["tbf cap, tcp"]["against"] == "radio cap" and by["tbf cap, tcp"]["received_ratio_vs"] == 0.5
    goals = bench._goals(rows)
    assert by["tbf cap"]["rmse_vs"] == 1.0  # fleet RMSE: the same here, although its ratio to the oracle's is not
    assert by["radio shaper"]["against"] == "single host"
    assert by["tbf per link"]["against"] == "radio shaper" and by["tbf per link"]["rmse_vs"] == pytest.approx(0.96)
    # judged: the kernel's bytes on the uncapped udp test bed, and the per-link cap against the same impairment emulated
    assert goals == {"testbed_rmse_ratio_within_10pct": True, "testbed_no_missed_steps": False,
                     "kernel_bytes_within_10pct_of_accounting": False,
                     "kernel_payload_within_10pct_of_accounting": True,
                     "tbf_vs_radio_received_bytes_within_10pct": True, "tbf_vs_radio_fleet_rmse_within_10pct": True}
    text = printed(bench, {"settings": {"agents": 4, "duration_s": 15.0, "seed": 1, "link_cap": 1500.0},
                           "rows": rows, "goals": goals})
    assert "single host" in text and "tbf cap" in text and "1.05x" in text
    quick = rows[:2]  # --quick: no caps, their goals not measured
    assert bench._goals(quick)["tbf_vs_radio_fleet_rmse_within_10pct"] is None


def test_paired_rows_pool_their_seeds(printed):
    runs = [{**_row("tbf per link", 1.2, 1500, 4000), "seeds": [seed], "rmse": rmse, "rmse_by_seed": [rmse],
             "status": status, "tbf_per_link": True}
            for seed, rmse, status in ((1, 3.0, "completed"), (2, 2.0, "completed"), (3, 4.0, "degraded"))]
    runs[2]["received_per_agent_per_s"] = 4300
    row = bench._pooled(runs)
    assert row["rmse"] == pytest.approx(3.0) and row["rmse_by_seed"] == [3.0, 2.0, 4.0] and row["seeds"] == [1, 2, 3]
    assert row["received_per_agent_per_s"] == pytest.approx(4100) and row["status"] == "degraded"
    assert row["tbf_per_link"] is True and bench._pooled(runs[:1]) is runs[0]
    text = printed(bench, {"settings": {"agents": 8, "duration_s": 40.0, "seed": 1, "link_cap": 1500.0},
                           "rows": [{**row, "rmse_vs": None, "rmse_ratio_vs": None, "bytes_ratio_vs": None,
                                     "received_ratio_vs": None}], "goals": {}})
    assert "per seed" in text and "4.00" in text


def test_bad_repeats_are_refused(monkeypatch):
    monkeypatch.setattr(netns, "unavailable", lambda: None)
    with pytest.raises(ValueError, match="repeats 0"):
        bench.run(repeats=0)


def test_without_namespaces_the_benchmark_says_why(monkeypatch, capsys):
    monkeypatch.setattr(netns, "unavailable", lambda: "network namespaces need root (ip netns add)")
    assert cli.main(["bench", "testbed", "--quick"]) == cli.EXIT_USAGE
    assert capsys.readouterr().err == ("skymesh bench testbed: skymesh bench testbed needs network namespaces: "
                                       "network namespaces need root (ip netns add)\n")


@pytest.mark.slow
@pytest.mark.skipif(netns.unavailable() is not None, reason=str(netns.unavailable()))
def test_smallest_live_run(private_tmp):
    before = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True).stdout
    result = bench.run(agents=2, duration=8.0, repeats=1)  # full: the caps too, the paired rows on one seed
    assert_no_children_left()
    assert list(private_tmp.iterdir()) == []
    assert subprocess.run(["ip", "netns", "list"], capture_output=True, text=True).stdout == before
    rows = {r["run"]: r for r in result["rows"]}
    assert list(rows) == ["single host", "testbed", "radio cap", "testbed, udp", "radio shaper", "tbf cap",
                          "tbf cap, tcp", "tbf per link"]
    assert all(r["status"] == "completed" and r["rmse"] is not None for r in rows.values()), rows
    bed = rows["testbed"]
    assert bed["kernel_tx_per_host_per_s"] > 0 and 1.0 < bed["payload_ratio"] < bed["kernel_ratio"]
    udp = rows["testbed, udp"]
    assert (bed["router_link"], udp["router_link"], rows["tbf cap"]["router_link"]) == ("tcp", "udp", "udp")
    assert rows["tbf cap"]["tbf_rate"] == pytest.approx((bench.LINK_CAP + udp["unfanned_per_s"]) * udp["kernel_ratio"])
    assert rows["tbf cap, tcp"]["tbf_rate"] == pytest.approx((bench.LINK_CAP + bed["unfanned_per_s"])
                                                             * bed["kernel_ratio"])
    assert rows["tbf per link"]["tbf_per_link"] and rows["tbf per link"]["router_link"] == "udp"
    assert rows["tbf per link"]["tbf_rate"] == pytest.approx(bench.LINK_CAP * udp["kernel_ratio"])
    assert rows["radio shaper"]["radio_queue"] == pytest.approx(netns.TBF_MIN_LIMIT / udp["kernel_ratio"])
    assert rows["radio cap"]["radio_queue"] is None and rows["tbf per link"]["against"] == "radio shaper"
    assert rows["single host"]["rmse_ratio_vs"] == 1.0
    assert all(0 < r["belief_latency_s"] < 5 for r in rows.values()), rows


def test_belief_latency_is_weighted_by_the_beliefs_received():
    team = [{"belief_latency_s": {"mean": 0.2, "count": 3}}, {"belief_latency_s": {"mean": 0.6, "count": 1}},
            {"belief_latency_s": {"mean": None, "count": 0}}]
    assert bench._latency(team) == pytest.approx(0.3)
    assert bench._latency([{}]) is None
