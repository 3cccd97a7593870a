"""``skymesh bench testbed``: the same team on one host and across network namespaces, and a rate cap emulated
by the radio against the kernel's.

Live runs of the default scenario with the geometric bearing sensor (the network is under test, not
perception; the camera's rendering does not fit 8 agents and 9 routers on a shared 2-core machine), one seed,
Rerun off; ``--quick``: the first two for 8 s with 4 agents (each live run is ~20 s of start-up on a loaded
machine), full: all eight for 40 s with 8 agents:

* **single host** — ``skymesh run``: one Zenoh router on loopback, every process its client. The baseline.
* **testbed** — ``skymesh testbed`` (:mod:`mesh_sim.testbed`): a namespace, a veth and a router per agent, the
  routers linked over TCP.
* **radio cap** — single host, the emulated radio's ``rate`` = :data:`LINK_CAP` bytes/s per directed link
  (bucket depth ``skymesh bench stress``'s ``BURST_S`` s of it, so that it binds within a run; without stress's
  16 KiB floor, which is for multi-track channel-filter messages: flooded bearings and bids stay far below it).
* **testbed, udp** — the testbed with the routers linked by Zenoh's UDP links (``--router-link udp``), uncapped.
* **radio shaper** — the radio cap with a queue (``[radio] queue``, :class:`agent.net.link_emulator.Shaper`) of
  what the kernel's per-link ``tbf`` holds, :data:`mesh_sim.netns.TBF_MIN_LIMIT` bytes at its rate, in the agents'
  bytes (÷ ``k``, below): the emulated radio running the kernel's impairment, a shaper, where the radio cap polices.
* **tbf cap** — that testbed with the same cap in the kernel: a ``tbf`` qdisc on every UAV host's veth at
  ``(LINK_CAP × (N − 1) + u) × k`` (:func:`_tbf_rate`): the N − 1 links a host's router sends a belief on, plus
  ``u``, the bytes per second only the ground receives (telemetry, the simulation's data: not capped by the
  emulated radio), ``k`` the kernel bytes per byte of agent accounting (``ratio`` of
  :func:`mesh_sim.testbed.bytes_check`: framing, Zenoh's own traffic); ``u`` and ``k`` measured by the uncapped
  run over the same links; the bucket ``BURST_S`` s deep, like the emulated links'. The agents are told the cap as
  a deployment would tell them its radio's, ``[sending] rate`` = :data:`LINK_CAP`
  (:class:`agent.net.sending.SendConfig`): the sender budget the emulated radio's plan gives the radio-capped
  agents. Datagram links because the emulated radio is one: it loses what exceeds the cap, where TCP retransmits
  it and every message behind it waits.
* **tbf cap, tcp** — the same over the TCP links (``u``, ``k`` from **testbed**), for comparison.
* **tbf per link** — the same impairment as the radio shaper's: each directed link between two UAV hosts capped
  with a bucket of its own (``--tbf-per-link``, :meth:`mesh_sim.netns.Network.cap_links`) at ``LINK_CAP × k``,
  ``BURST_S`` s deep, over UDP; what goes to the ground is not capped (the emulated radio does not cap it either).

Per run: fleet RMSE and its ratio to the oracle's, the ratio of that to the single-host run's (the issue's goal:
within 10 %), fleet ANEES, belief latency (the mean over received beliefs, ``belief_latency_s`` of the agents'
metrics), missed steps (steps late or skipped, over steps run: machine load), bytes per agent per
second by the agents' own accounting and its ratio to the single-host run's, and for testbed runs the kernel's
tx bytes per host per second with the comparison of :func:`mesh_sim.testbed.bytes_check`. The capped runs are
compared with the radio cap's on what got through — bytes *received* per agent per second (both thin what they
send to the same budget; the kernel, like the emulated radio, drops what still exceeds the cap) — and fleet RMSE,
tbf ÷ radio (the issue's goal, judged on **tbf per link** against the **radio shaper**, the same impairment:
within 10 %; the other tbf rows against the radio cap). Fleet RMSE, not its
ratio to the oracle's: the oracle's inputs (the agents' measurements, sent to the world on the ground host) share the
capped veth with the radio traffic under the aggregate tbf caps, and not under the emulated radio. The issue's byte
goal is judged on the uncapped **testbed, udp**: the kernel's bytes within 10 % of the expectation from the agents'
accounting, with the frame headers (``kernel ÷ E``) and without them (``payload ÷ E``: what Zenoh hands the kernel).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from rich.console import Console

from mesh_sim.bench import common
from mesh_sim.bench.common import fmt, fmt_ratio, ratio
from mesh_sim.bench.stress import BURST_S

NAME = "testbed"
SEED = 1
QUICK_AGENTS, FULL_AGENTS = 4, 8
QUICK_DURATION_S, FULL_DURATION_S = 8.0, 40.0  # chosen here: --quick is two start-ups (~20 s each) and 2 x 8 s
SENSOR = {"kind": "bearing"}
LINK_CAP = 1500.0  # bytes/s per directed link: below what an agent sends (~2-3 kB/s with bearings); chosen here
GOAL = 0.10  # the issue's: within 10 %
PAIRED_SEEDS = 3  # seeds 1..this of the radio shaper and tbf per link, pooled (the default of --repeats); chosen here:
#                   one saturated run of tbf per link scatters by ±10-20 % in fleet RMSE from run to run on one seed


def run(quick: bool = False, repeats: int | None = None, *, agents: int | None = None, duration: float | None = None,
        runs_dir: str | os.PathLike | None = None) -> dict:
    """Run the benchmark (``repeats``: the seeds, 1 to ``repeats``, of the radio shaper and tbf per link rows,
    pooled; default :data:`PAIRED_SEEDS`); ``agents`` and ``duration`` override the mode's. Run folders go to a
    temporary folder removed afterwards, or under ``runs_dir`` (kept)."""
    from mesh_sim import netns

    if (why := netns.unavailable()) is not None:
        raise OSError(f"skymesh bench testbed needs network namespaces: {why}")
    agents = int(agents or (QUICK_AGENTS if quick else FULL_AGENTS))
    duration = float(duration or (QUICK_DURATION_S if quick else FULL_DURATION_S))
    seeds = tuple(range(SEED, SEED + int(PAIRED_SEEDS if repeats is None else repeats)))
    if agents < 2 or not duration > 0 or not seeds:
        raise ValueError(f"bad settings: agents {agents} (at least 2), duration {duration} s (positive), "
                         f"repeats {repeats} (at least 1)")
    radio_cap = {"rate": LINK_CAP, "burst": BURST_S * LINK_CAP}
    rows = []
    with common.runs_folder(runs_dir, "skymesh-bench-testbed-") as base, \
            common.run_progress(NAME, 2 if quick else 6 + 2 * len(seeds)) as (console, advance):
        quiet = console if console.is_terminal else Console(stderr=True, quiet=True)

        def measure(label: str, hosts: bool, radio: dict | None = None, link: str = "tcp",
                    cap_like: dict | None = None, per_link: bool = False, on: tuple[int, ...] = (SEED,)) -> dict:
            """``cap_like``: the uncapped test-bed row whose overheads size the tbf cap (none: no cap); ``on``: the
            seeds, one run each, pooled into one row."""
            tbf = None if cap_like is None else _tbf_rate(cap_like, agents, per_link)
            runs = []
            for seed in on:
                advance(f"{label}, seed {seed} ({agents} agents, {duration:g} s)", 0)
                runs.append(_one_run(label, base, quiet, agents, duration, hosts, radio, tbf, link, per_link, seed))
                advance(f"{label}, seed {seed} done", 1)
            row = _pooled(runs)
            rows.append(row)
            return row

        measure("single host", hosts=False)
        bed = measure("testbed", hosts=True)
        if not quick:
            measure("radio cap", hosts=False, radio=radio_cap)
            udp = measure("testbed, udp", hosts=True, link="udp")
            measure("radio shaper", hosts=False, radio={**radio_cap, "queue": _kernel_queue(udp)}, on=seeds)
            measure("tbf cap", hosts=True, link="udp", cap_like=udp)
            measure("tbf cap, tcp", hosts=True, cap_like=bed)
            measure("tbf per link", hosts=True, link="udp", cap_like=udp, per_link=True, on=seeds)
    _add_ratios(rows)
    return {
        "benchmark": NAME,
        "settings": {"quick": quick, "agents": agents, "duration_s": duration, "seed": SEED,
                     "paired_seeds": list(seeds), "sensor": SENSOR,
                     "link_cap": LINK_CAP, "burst_s": BURST_S, "load_average_after": list(os.getloadavg())},
        "environment": common.environment(("numpy", "scipy", "eclipse-zenoh")),
        "rows": rows,
        "goals": _goals(rows),
    }


def _kernel_queue(bed: dict) -> float:
    """The bytes of agent accounting a per-link ``tbf`` queue holds: its :data:`mesh_sim.netns.TBF_MIN_LIMIT`
    kernel bytes ÷ the kernel bytes per byte of accounting of the uncapped test-bed run ``bed`` (its rate is
    scaled by the same factor, so the queue is the same time of the link's)."""
    from mesh_sim.netns import TBF_MIN_LIMIT

    return TBF_MIN_LIMIT / (bed["kernel_ratio"] or 1.0)


def _tbf_rate(bed: dict, agents: int, per_link: bool = False) -> float:
    """A UAV host's kernel cap for the emulated radio's: :data:`LINK_CAP` on each of the ``agents - 1`` links a
    belief leaves on, plus what only the ground receives — or, ``per_link``, :data:`LINK_CAP` for each link — times
    the kernel bytes per byte of agent accounting; both measured by the uncapped test-bed run ``bed`` over the same
    router links."""
    kernel_ratio = bed["kernel_ratio"] or 1.0
    if per_link:
        return LINK_CAP * kernel_ratio
    return (LINK_CAP * (agents - 1) + (bed["unfanned_per_s"] or 0.0)) * kernel_ratio


def _one_run(label: str, base: Path, console: Console, agents: int, duration: float, hosts: bool,
             radio: dict | None, tbf: float | None, link: str = "tcp", per_link: bool = False,
             seed: int = SEED) -> dict:
    from mesh_sim.launcher import Launcher, new_run_dir
    from mesh_sim.scenario import load
    from mesh_sim.testbed import TESTBED_FILE, run_testbed

    overrides = {"agents": agents, "duration": duration, "seed": seed, "sensor": dict(SENSOR)}
    if radio is not None:
        overrides["radio"] = radio
    if tbf is not None:  # told the cap, as the emulated radio's plan tells the radio-capped agents
        overrides["sending"] = {"rate": LINK_CAP}
    scenario = load("default", **overrides)
    run_dir = new_run_dir(base, f"{NAME}-{label.replace(' ', '-')}-seed{seed}")
    options = {"rerun": "off", "console": console}
    tbf_burst = None if tbf is None else BURST_S * tbf  # the emulated links' depth: BURST_S seconds of the rate
    outcome = (run_testbed(scenario, run_dir, tbf_rate=tbf, tbf_burst=tbf_burst, router_link=link,
                           tbf_per_link=per_link, **options) if hosts
               else Launcher(scenario, run_dir, **options).run())
    if outcome.status == "interrupted":
        raise KeyboardInterrupt
    metrics = outcome.metrics
    fleet = metrics.get("fleet", {})
    team = [a for a in metrics.get("agents", []) if "steps" in a]
    missed, steps = common.missed_steps(team)
    row = {"run": label, "seeds": [seed], "status": outcome.status, "rmse": fleet.get("rmse"),
           "rmse_by_seed": [fleet.get("rmse")], "anees": fleet.get("anees"),
           "rmse_ratio_to_oracle": fleet.get("rmse_ratio_to_oracle"),
           "bytes_per_agent_per_s": fleet.get("bytes_per_agent_per_s"),
           "received_per_agent_per_s": _mean(a.get("bytes_rx") for a in team) / duration if team else None,
           "belief_latency_s": _latency(team),
           "missed_steps": missed / steps if steps else None, "radio_queue": (radio or {}).get("queue"),
           "tbf_rate": tbf, "tbf_per_link": per_link,
           "router_link": link if hosts else None,
           "kernel_tx_per_host_per_s": None, "kernel_ratio": None, "payload_ratio": None, "unfanned_per_s": None}
    if hosts and (run_dir / TESTBED_FILE).exists():
        checks = list(json.loads((run_dir / TESTBED_FILE).read_text())["bytes"].values())
        if checks:
            row["kernel_tx_per_host_per_s"] = _mean(c["kernel_tx"] for c in checks) / duration
            row["kernel_ratio"] = _mean(c["ratio"] for c in checks)
            row["payload_ratio"] = _mean(c["payload_ratio"] for c in checks)
            row["unfanned_per_s"] = _mean(c["unfanned_tx"] for c in checks) / duration
    return row


def _pooled(runs: list[dict]) -> dict:
    """One row for the runs of one setting over several seeds: each number the mean over the runs that have it,
    the seeds and their fleet RMSEs listed, the status the first that is not "completed" (else "completed")."""
    if len(runs) == 1:
        return runs[0]
    row = dict(runs[0])
    for key, value in row.items():
        if isinstance(value, float | int) and not isinstance(value, bool):
            row[key] = _mean(r[key] for r in runs)
    row["seeds"] = [seed for r in runs for seed in r["seeds"]]
    row["rmse_by_seed"] = [rmse for r in runs for rmse in r["rmse_by_seed"]]
    row["status"] = next((r["status"] for r in runs if r["status"] != "completed"), "completed")
    return row


def _latency(team: list[dict]) -> float | None:
    """Mean belief latency over the fleet's received beliefs: the agents' means weighted by their counts."""
    parts = [a["belief_latency_s"] for a in team if (a.get("belief_latency_s") or {}).get("count")]
    count = sum(p["count"] for p in parts)
    return sum(p["mean"] * p["count"] for p in parts) / count if count else None


def _mean(values) -> float | None:
    values = [v for v in values if v is not None]
    return sum(values) / len(values) if values else None


def _add_ratios(rows: list[dict]) -> None:
    """Each run against the single-host run; the tbf caps against the radio cap, per link against the shaper."""
    by = {r["run"]: r for r in rows}
    for row in rows:
        against = by["single host"]
        if row["run"].startswith("tbf"):
            against = by["radio shaper" if row.get("tbf_per_link") else "radio cap"]
        row["against"] = against["run"]
        row["rmse_vs"] = ratio(row["rmse"], against["rmse"])
        row["rmse_ratio_vs"] = ratio(row["rmse_ratio_to_oracle"], against["rmse_ratio_to_oracle"])
        row["bytes_ratio_vs"] = ratio(row["bytes_per_agent_per_s"], against["bytes_per_agent_per_s"])
        row["received_ratio_vs"] = ratio(row["received_per_agent_per_s"], against["received_per_agent_per_s"])


def _within(value: float | None) -> bool | None:
    return None if value is None else abs(value - 1.0) <= GOAL


def _goals(rows: list[dict]) -> dict:
    """The issue's goals; ``None`` (not measured) for the caps' under ``--quick``."""
    by = {r["run"]: r for r in rows}
    tbf, udp = by.get("tbf per link", {}), by.get("testbed, udp", {})
    return {
        "testbed_rmse_ratio_within_10pct": _within(by["testbed"]["rmse_ratio_vs"]),
        "testbed_no_missed_steps": by["testbed"]["missed_steps"] == 0,
        "kernel_bytes_within_10pct_of_accounting": _within(udp.get("kernel_ratio")),
        "kernel_payload_within_10pct_of_accounting": _within(udp.get("payload_ratio")),
        "tbf_vs_radio_received_bytes_within_10pct": _within(tbf.get("received_ratio_vs")),
        "tbf_vs_radio_fleet_rmse_within_10pct": _within(tbf.get("rmse_vs")),
    }


def report(result: dict, console=None) -> None:
    console = console or common.make_console()
    s = result["settings"]
    common.print_table(
        console, f"One host vs one namespace and router per agent — {s['agents']} agents, {s['duration_s']:g} s, "
                 f"seed {s['seed']}, bearing sensor",
        ["run", "status", "RMSE [m]", "vs", "÷ oracle", "vs", "ANEES", "latency [s]", "missed steps", "sent B/s", "vs",
         "received B/s", "vs", "kernel tx B/s/host", "kernel ÷ E", "payload ÷ E"],
        [(r["run"], r["status"], fmt(r["rmse"], ".2f"), fmt_ratio(r["rmse_vs"]), fmt(r["rmse_ratio_to_oracle"], ".2f"),
          fmt_ratio(r["rmse_ratio_vs"]), fmt(r["anees"], ".2f"), fmt(r.get("belief_latency_s"), ".3f"),
          fmt(r["missed_steps"], ".1%"),
          fmt(r["bytes_per_agent_per_s"], ",.0f"), fmt_ratio(r["bytes_ratio_vs"]),
          fmt(r["received_per_agent_per_s"], ",.0f"), fmt_ratio(r["received_ratio_vs"]),
          fmt(r["kernel_tx_per_host_per_s"], ",.0f"), fmt(r["kernel_ratio"], ".2f"), fmt(r["payload_ratio"], ".2f"))
         for r in result["rows"]],
        caption=f"\"vs\": the ratio to the single-host run (the tbf caps': to the radio cap's; per link: to the "
                f"radio shaper's). Caps: radio {s['link_cap']:g} B/s per link (the shaper's with a queue of one kernel "
                "frame); tbf per UAV host = (that × (N − 1) + what only the ground receives) "
                "× the uncapped testbed's kernel ÷ E over the same router links (udp, or tcp); tbf per link = that × "
                "kernel ÷ E on each directed link between UAV hosts. Sent/received: the "
                "agents' own accounting, per agent. E: the expected bytes of mesh_sim.testbed.bytes_check. Where the "
                "cap also starves the oracle's inputs (tbf), compare fleet RMSE, not ÷ oracle.")
    paired = [r for r in result["rows"] if len(r.get("seeds", ())) > 1]
    if paired:
        common.print_table(
            console, "Fleet RMSE [m] per seed: the rows above give the mean", ["seed", *(r["run"] for r in paired)],
            [(str(seed), *(fmt(r["rmse_by_seed"][i], ".2f") for r in paired))
             for i, seed in enumerate(paired[0]["seeds"])])
    common.print_table(console, "Goals (issue 17)", ["goal", "met"],
                       [(name, common.verdict(ok)) for name, ok in result["goals"].items()])
