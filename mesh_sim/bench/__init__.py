"""Benchmarks run by ``skymesh bench NAME`` (see :mod:`mesh_sim.cli`).

To add a benchmark, write a module in this package that defines

* ``run(quick: bool = False, repeats: int | None = None) -> dict`` — a JSON-serialisable result with at
  least ``"benchmark"`` (its name), ``"rows"`` (one dict per measurement) and ``"goals"``; ``quick``
  must finish in well under a minute, ``repeats`` (``--repeats N``) overrides the number of timed
  repeats — fewer, so that tests can make it quicker still (:class:`mesh_sim.bench.common.Settings` does this),
  or more, where one run says little (``bench scale`` pools its runs per team size);
* ``report(result: dict, console=None) -> None`` — print the tables for a result,

and add a :class:`Benchmark` entry to :data:`BENCHMARKS`. Modules are imported only when their
benchmark runs, so ``skymesh bench --list`` stays fast.

A benchmark that takes more of the ``skymesh bench`` options (``--sizes``, ``--sensor``, ``--seeds``: see
:data:`mesh_sim.cli.BENCH_OPTIONS`) names them in its entry's ``options``; its ``run`` receives them as keyword
arguments when they are given, and the command line refuses them for any other benchmark.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass


@dataclass(frozen=True)
class Benchmark:
    name: str
    module: str  # dotted path of the module that defines run() and report()
    description: str
    options: tuple[str, ...] = ()  # the extra keyword options of its run() that the command line may pass

    def load(self):
        return importlib.import_module(self.module)

    def run(self, quick: bool = False, repeats: int | None = None, **options) -> dict:
        unknown = sorted(set(options) - set(self.options))
        if unknown:
            raise TypeError(f"benchmark {self.name} takes no option {', '.join(unknown)}")
        return self.load().run(quick=quick, repeats=repeats, **options)

    def report(self, result: dict, console=None) -> None:
        self.load().report(result, console)


BENCHMARKS: dict[str, Benchmark] = {
    b.name: b
    for b in [
        Benchmark(
            "fusion-ops",
            "mesh_sim.bench.fusion_ops",
            "µs per fusion operation (IF, bearing EIF, CI, fast CI, channel filter) vs bare numpy, filterpy and "
            "Stone Soup; GaussianBatch vs per-track loops over 100 tracks",
        ),
        Benchmark(
            "scale",
            "mesh_sim.bench.scale",
            "live runs of the default scenario with the bearing sensor (N = 8, 16, 32, 40, 48) and the camera "
            "(N = 4, 8, 16, 24): missed deadlines, CPU per step, memory, start-up, belief latency; per sensor the "
            "largest N at 5 Hz with < 1 % misses (--sensor bearing|camera, --sizes N,N,...)",
            options=("sizes", "sensor"),
        ),
        Benchmark(
            "testbed",
            "mesh_sim.bench.testbed",
            "one host vs a Linux network namespace and Zenoh router per agent (root): RMSE ratio, missed steps, bytes "
            "per agent vs the veths' kernel counters; full (8 agents): also the emulated radio's rate cap vs tbf "
            "(--quick: 4 agents, no caps)",
        ),
        Benchmark(
            "transport",
            "mesh_sim.bench.transport",
            "per-hop round trip and throughput of the agent transport (Zenoh + wire format) vs bare Zenoh pub/sub",
        ),
        Benchmark(
            "perception",
            "mesh_sim.bench.perception",
            "ms per frame for render, detect and geolocate at 320x240 and 640x480; agents per core at 5 Hz",
        ),
        Benchmark(
            "geolocation-latency",
            "mesh_sim.bench.geolocation_latency",
            "Ross et al.: geolocation error with 430 ms of pose latency, without and with compensation",
        ),
        Benchmark(
            "coop-vs-single",
            "mesh_sim.bench.coop_vs_single",
            "thesis 000 Table 3.1: spread of the target estimate from one observer vs two cooperating observers",
        ),
        Benchmark(
            "rumor",
            "mesh_sim.bench.rumor",
            "issue 11 goals, lockstep Monte Carlo of the default scenario: topology x loss x fusion method, the "
            "make-demo and partition/merge rows: RMSE ratio to the oracle, ANEES intervals, exact share, bytes/agent",
        ),
        Benchmark(
            "stress",
            "mesh_sim.bench.stress",
            "live runs under topology churn with a per-link bandwidth cap swept downward: where tracking breaks",
        ),
        Benchmark(
            "grid-ops",
            "mesh_sim.bench.grid_ops",
            "cells per second for grid update, fuse and delta-encode on 256x256 and 1024x1024 grids vs a plain-numpy "
            "bound",
        ),
        Benchmark(
            "fire",
            "mesh_sim.bench.fire",
            "whole fire missions (120 s, 5 seeds), lockstep: per 30 s window, alarm detection, decoy rejection and "
            "localisation of every agent's map, log-odds and Beta, hybrid / naive / tree / ring; grid bytes delta vs "
            "keyframe (--seeds N)",
            options=("seeds",),
        ),
        Benchmark(
            "tasking",
            "mesh_sim.bench.tasking",
            "issue 13's tasking benchmarks in one run: tasking-fleet, tasking-health, tasking-orbit, "
            "tasking-rendezvous, tasking-paths, tasking-feature, tasking-standoff (and their goals)",
        ),
        Benchmark(
            "tasking-fleet",
            "mesh_sim.bench.tasking_fleet",
            "default scenario, lockstep: consensus assignment vs the placeholder planner (per-target oracle RMSE, "
            "fleet ÷ oracle, coverage) and assignment agreement under 30 % loss",
        ),
        Benchmark(
            "tasking-health",
            "mesh_sim.bench.tasking_health",
            "thesis 000 §4.4: nominal vs health-extended RHTA, 20 vehicles, Poisson failures, 20 Monte-Carlo missions "
            "(median/mean service time, vehicles lost)",
        ),
        Benchmark(
            "tasking-orbit",
            "mesh_sim.bench.tasking_orbit",
            "coordinated orbits (Andreetto et al., spec 004): E1 RMSE and steady-state time vs n (static vs dynamic), "
            "E2 constant-velocity target, E3 rendezvous — beside the paper's figures",
        ),
        Benchmark(
            "tasking-rendezvous",
            "mesh_sim.bench.tasking_rendezvous",
            "spec 004 in the running fleet, lockstep: the orbit and rendezvous scenarios with shared, equally spaced "
            "orbits vs one orbiter (time to meet, share on the circle, spacing error, oracle RMSE)",
        ),
        Benchmark(
            "tasking-paths",
            "mesh_sim.bench.tasking_paths",
            "collocation planner (Ross et al., spec 002): solve time cold/warm vs the 0.5 s budget, stand-off "
            "information vs a circle and a straight pass; separation layer over crossing swarms of 8 and 16",
        ),
        Benchmark(
            "tasking-standoff",
            "mesh_sim.bench.tasking_standoff",
            "standoff scenario, lockstep: fixed wings on collocation plans (Ross et al., spec 002) vs the loiter "
            "circle on the same seeds (per-target oracle RMSE and ratio, fleet ÷ oracle, solve time vs 0.5 s, CPU)",
        ),
        Benchmark(
            "tasking-feature",
            "mesh_sim.bench.tasking_feature",
            "feature following (Lee et al., spec 003): centring error, cross-track error, navigation RMSE with and "
            "without GPS fault isolation, fault detection delay",
        ),
        Benchmark(
            "mavlink",
            "mesh_sim.bench.mavlink",
            "the PX4-like autopilot simulator under a pymavlink client: setpoint response vs the bare pymavlink UDP "
            "round trip, telemetry rates achieved vs requested, CPU per simulator process",
        ),
        Benchmark(
            "mavlink-fleet",
            "mesh_sim.bench.mavlink_fleet",
            "the default scenario live over MAVLink (a skymesh autopilot per agent) vs the kinematic run of the same "
            "seed (fleet ÷ oracle, CPU per step), and one autopilot frozen: detection and reassignment times",
        ),
        Benchmark(
            "fuzz",
            "mesh_sim.bench.fuzz",
            "issue 16: >= 1e5 fuzzed inputs per message kind (random, truncated, bit-flipped, type-confused, bad "
            "matrices, huge, nested, wrong origin, replays, far stamps) to the decoder and an agent's receive path: "
            "crashes, hangs > 50 ms, peak memory, invalid inputs accepted (--kinds track,grid,...: only those)",
            options=("kinds",),
        ),
        Benchmark(
            "particles",
            "mesh_sim.bench.particles",
            "particle fusion (Merino Alg. 5.2 GMM and Alg. 5.3 LOP) time and accuracy vs particle count 200/500/2000",
        ),
    ]
}
