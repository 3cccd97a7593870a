"""``skymesh bench fuzz``: fuzzed inputs of every message kind against the decoder and the agent's receive path.

Issue 16 item 3. Per kind (:data:`mesh_sim.bench.fuzz_seeds.CASES`: every kind an agent receives), a valid
seed message from a real run is mutated (:mod:`mesh_sim.bench.fuzz_mutate`: random bytes; truncated,
bit-flipped and type-confused envelopes; NaN/inf/huge/negative-definite matrices; huge and deeply nested
payloads; wrong origins; replays; far stamps and epochs; huge sequence numbers), and every input goes to two
targets:

* ``agent.net.wire.decode`` alone — it must raise nothing but ``DecodeError``;
* :meth:`agent.agent.Agent.receive` of a real agent (the capture run's ``uav0``, copied per case) — it
  must never raise and must finish each input within :data:`HANG_S` of CPU time (the thread's: on a machine
  shared with other work the wall clock also counts the time spent waiting for a core, up to 2-3x the CPU
  time at a load of 7 on 2 cores; the slowest wall time is reported too. A receive path that *blocks* would
  not show in CPU time: the agent's never does, it holds no lock and does no I/O).

Twice: without a fleet key, and with one (the agent checks MACs; the structural mutations are signed, so they
reach the payload checks; a byte-level mutation of a signed message must fail its MAC).

Detected: *crashes* (an exception; its type, family and the first :data:`EXAMPLES` inputs as hex), *hangs*
(an input taking more than :data:`HANG_S` of CPU time), and *accepted invalid* inputs: an input its mutation
made invalid (:attr:`mesh_sim.bench.fuzz_mutate.Input.invalid`) that did not grow the agent's rejected counters although
the agent's state digest (:meth:`AgentTarget.digest`: its exchanges, world truth and topology) changed.
Also measured: inputs per second, the receive time of a valid message (the baseline, measured in the same run:
the slowest input is reported as a ratio to it) and the growth of the process's peak resident memory.

Goals (issue 16): ≥ 10⁵ inputs per kind (full run), 0 crashes, 0 hangs, 0 invalid inputs accepted.
"""

from __future__ import annotations

import copyreg
import hashlib
import io
import logging
import pickle
import resource
import time
import warnings
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from agent.net import wire
from agent.net.keys import Incoming
from mesh_sim.bench import common
from mesh_sim.bench.fuzz_mutate import FAMILIES, Input, Mutator
from mesh_sim.bench.fuzz_seeds import CASES, Case, cases

NAME = "fuzz"
FULL_INPUTS, FULL_KEYED = 100_000, 10_000  # per kind, without and with a fleet key
QUICK_INPUTS, QUICK_KEYED = 1_000, 200  # within a minute (issue 16 suggests ~2,000: a minute holds ~1,200)
GOAL_INPUTS = 100_000  # per kind (issue 16)
HANG_S = 0.050  # an input taking more CPU time hangs the agent (issue 16)
BASELINE_REPEATS = 30  # valid messages received for the baseline time
EXAMPLES = 3  # inputs kept per crash or hang kind
EXAMPLE_BYTES = 1 << 16  # hex of at most this many bytes of an example
FLEET_KEY = hashlib.sha256(b"skymesh bench fuzz").digest()  # the keyed pass's fleet key (fixed: reproducible)
SEED = 20261127


class AgentTarget:
    """The agent of a case as the fuzzer drives it: its receive path, its rejected count, its state digest."""

    def __init__(self, case: Case):
        self.case, self.agent = case, case.agent
        opaque = (self.agent, self.agent.terrain, self.agent.vehicle, self.agent.planner, self.agent.sensor)
        self._by_reference = {**copyreg.dispatch_table, **{type(part): _reference for part in opaque}}

    def decode(self, inp: Input) -> None:
        """The decoder alone, with the agent's origin, key and kinds (not its fleet roster nor the Zenoh encoding,
        which the agent checks around it: :meth:`receive` goes through those)."""
        origin = None if self.case.spec.kind == "truth" else inp.key.rsplit("/", 1)[-1]
        wire.decode(inp.data, expected_origin=origin, key=self.case.fleet_key, kinds=self.agent.kinds)

    def receive(self, inp: Input) -> None:
        self.agent.receive(Incoming(inp.key, inp.data, 0.0), self.case.now)

    def rejected(self) -> int:
        return self.agent.rejected.total()

    def digest(self) -> bytes:
        """The agent's beliefs as bytes: its exchanges, its world truth and its topology, pickled (equal bytes, equal
        beliefs; compared as they are, not hashed: a grid agent holds tens of MB, and hashing them cost more than
        pickling). The agent itself, its terrain, vehicle, planner and sensor are references, not content: they
        pickle as their type's name (looked up by type in C, not by a Python call per pickled object)."""
        buf = io.BytesIO()
        pickler = pickle.Pickler(buf, protocol=5)
        pickler.dispatch_table = self._by_reference
        pickler.dump((self.agent.exchanges, vars(self.agent.world), self.agent.topology))
        return buf.getvalue()


def _reference(part) -> tuple:
    """How :meth:`AgentTarget.digest` pickles a part of the agent that is not its beliefs: by its type's name."""
    return str, (type(part).__qualname__,)


@dataclass
class Faults:
    """What one target did wrong: crashes by (exception, family), hangs by family, the first examples."""

    crashes: Counter = field(default_factory=Counter)
    hangs: Counter = field(default_factory=Counter)
    examples: list = field(default_factory=list)
    slowest_s: float = 0.0  # CPU time of the slowest input
    slowest_wall_s: float = 0.0
    busy_s: float = 0.0

    def timed(self, fn, inp: Input, allowed: tuple[type[Exception], ...] = ()) -> None:
        """Call ``fn(inp)``: an exception but the ``allowed`` ones is a crash, a call over :data:`HANG_S` of CPU time
        a hang."""
        started, cpu = time.perf_counter(), time.thread_time()
        try:
            fn(inp)
        except allowed:
            pass
        except Exception as exc:  # noqa: BLE001 - any exception is the finding
            self._note("crash", type(exc).__name__, inp)
        took, took_cpu = time.perf_counter() - started, time.thread_time() - cpu
        self.busy_s += took
        self.slowest_wall_s = max(self.slowest_wall_s, took)
        self.slowest_s = max(self.slowest_s, took_cpu)
        if took_cpu > HANG_S:
            self._note("hang", f"{1e3 * took_cpu:.0f} ms", inp)

    def _note(self, what: str, detail: str, inp: Input) -> None:
        (self.crashes if what == "crash" else self.hangs)[f"{detail} ({inp.family})" if what == "crash"
                                                           else inp.family] += 1
        if sum(1 for e in self.examples if e["what"] == what) < EXAMPLES:
            self.examples.append({"what": what, "detail": detail, "family": inp.family, "key": inp.key,
                                  "bytes": len(inp.data), "hex": inp.data[:EXAMPLE_BYTES].hex()})

    def summary(self) -> dict:
        return {"crashes": int(self.crashes.total()), "crashes_by_kind": dict(self.crashes),
                "hangs": int(self.hangs.total()), "hangs_by_family": dict(self.hangs), "examples": self.examples,
                "slowest_ms": 1e3 * self.slowest_s, "slowest_wall_ms": 1e3 * self.slowest_wall_s, "busy_s": self.busy_s}


def fuzz_case(case: Case, inputs: int, rng: np.random.Generator, target: AgentTarget | None = None) -> dict:
    """Feed ``inputs`` mutated messages of ``case`` to the decoder and to ``target`` (default: the case's agent)."""
    target = target or AgentTarget(case)
    mutator = Mutator(case, rng)
    baseline = []
    for _ in range(BASELINE_REPEATS):
        valid = Input("valid", case.key_for(mutator.origin), mutator.seal(mutator.fresh()), False)
        started = time.thread_time()
        target.receive(valid)
        baseline.append(time.thread_time() - started)
        mutator.used(valid)
    decoder, agent = Faults(), Faults()
    accepted_invalid: Counter = Counter()
    examples, invalid, families = [], 0, Counter()
    digest = None  # the agent's digest, while no input was used since it was taken
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    started = time.perf_counter()
    for i in range(inputs):
        inp = mutator.make(FAMILIES[i % len(FAMILIES)])
        families[inp.family] += 1
        decoder.timed(target.decode, inp, (wire.DecodeError,))
        if inp.invalid:
            invalid += 1
            digest = digest or target.digest()
        before = target.rejected()
        agent.timed(target.receive, inp)
        if target.rejected() != before:
            continue
        mutator.used(inp)
        if inp.invalid and target.digest() != digest:
            accepted_invalid[inp.family] += 1
            if len(examples) < EXAMPLES:
                examples.append({"family": inp.family, "key": inp.key, "bytes": len(inp.data),
                                 "hex": inp.data[:EXAMPLE_BYTES].hex()})
        digest = None
    wall = time.perf_counter() - started
    return {
        "kind": case.spec.name, "wire_kind": case.spec.kind, "keyed": case.fleet_key is not None, "inputs": inputs,
        "invalid_inputs": invalid, "families": dict(families), "wall_s": wall, "inputs_per_s": inputs / wall,
        "baseline_us": 1e6 * float(np.median(baseline)),
        "slowest_ratio": agent.slowest_s / float(np.median(baseline)),
        "rejected_by_reason": dict(case.agent.rejected),
        "peak_rss_growth_mb": (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss) / 1024,
        "decoder": decoder.summary(), "agent": agent.summary(),
        "accepted_invalid": int(accepted_invalid.total()), "accepted_invalid_by_family": dict(accepted_invalid),
        "accepted_invalid_examples": examples,
    }


# -- run ---------------------------------------------------------------------------------------------
def run(quick: bool = False, repeats: int | None = None, inputs: tuple[int, int] | None = None,
        kinds: tuple[str, ...] | None = None) -> dict:
    """Run the benchmark; returns ``{"benchmark", "settings", "environment", "rows", "goals"}``. ``repeats`` is
    accepted for the command line's sake (nothing here is repeated); ``inputs`` (per kind, without and with a
    fleet key) overrides the mode's budget, for tests; ``kinds`` (names of :data:`CASES`) fuzzes only those
    (``--kinds``: a full run split over several processes, each writing its own JSON)."""
    del repeats
    plain, keyed = inputs or ((QUICK_INPUTS, QUICK_KEYED) if quick else (FULL_INPUTS, FULL_KEYED))
    started = time.perf_counter()
    all_cases = cases(_chosen(kinds), (None, FLEET_KEY))
    capture_s = time.perf_counter() - started
    rng = np.random.default_rng(SEED)
    rows = []
    agent_log = logging.getLogger("skymesh.agent")
    level, _ = agent_log.level, agent_log.setLevel(logging.ERROR)  # one warning per rejection reason: noise here
    with common.progress(len(all_cases), NAME) as advance, warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # numpy's overflow notes on huge matrices: expected here
        for case in all_cases:
            advance(f"{case.spec.name}{' (keyed)' if case.fleet_key else ''}")
            rows.append(fuzz_case(case, keyed if case.fleet_key else plain, rng))
    agent_log.setLevel(level)
    return {
        "benchmark": NAME,
        "settings": {"quick": quick, "kinds": [r["kind"] for r in rows if not r["keyed"]], "inputs_per_kind": plain,
                     "keyed_inputs_per_kind": keyed, "seed": SEED,
                     "hang_ms": 1e3 * HANG_S, "families": list(FAMILIES), "capture_s": capture_s,
                     "total_s": time.perf_counter() - started,
                     "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024},
        "environment": common.environment(("numpy", "msgspec")),
        "rows": rows,
        "goals": _goals(rows),
    }


def _chosen(kinds: tuple[str, ...] | None) -> list:
    """The cases named by ``kinds`` (all of them for ``None``); ``ValueError`` naming the known ones otherwise."""
    if kinds is None:
        return CASES
    unknown = set(kinds) - {spec.name for spec in CASES}
    if unknown:
        raise ValueError(f"unknown fuzz kinds {sorted(unknown)}; known: {', '.join(spec.name for spec in CASES)}")
    return [spec for spec in CASES if spec.name in kinds]


def _goals(rows: list[dict]) -> list[dict]:
    per_kind = Counter()
    for r in rows:
        per_kind[r["kind"]] += r["inputs"]
    crashes = sum(r["decoder"]["crashes"] + r["agent"]["crashes"] for r in rows)
    hangs = sum(r["decoder"]["hangs"] + r["agent"]["hangs"] for r in rows)
    accepted = sum(r["accepted_invalid"] for r in rows)
    return [
        {"name": "inputs", "description": f"≥ {GOAL_INPUTS:,} inputs per kind", "fewest": min(per_kind.values()),
         "pass": min(per_kind.values()) >= GOAL_INPUTS},
        {"name": "crashes", "description": "0 crashes (decoder: anything but DecodeError; agent: anything)",
         "value": crashes, "pass": crashes == 0},
        {"name": "hangs", "description": f"0 inputs taking > {1e3 * HANG_S:g} ms of CPU time", "value": hangs,
         "pass": hangs == 0},
        {"name": "accepted_invalid", "description": "0 invalid inputs accepted with a change of the agent's state",
         "value": accepted, "pass": accepted == 0},
    ]


# -- report ------------------------------------------------------------------------------------------
def report(result: dict, console=None) -> None:
    """Print the table and the goal verdicts of a :func:`run` result."""
    console = console or common.make_console()
    s = result["settings"]
    console.print(f"[bold]{NAME}[/bold]  {'quick' if s['quick'] else 'full'} run: {s['inputs_per_kind']:,} inputs "
                  f"per kind, {s['keyed_inputs_per_kind']:,} more with a fleet key; {s['total_s']:.0f} s; peak "
                  f"RSS {s['peak_rss_mb']:.0f} MB", highlight=False)
    common.print_table(
        console, "Fuzzed inputs: decoder and agent receive path",
        [("kind", "left"), "key", "inputs", "invalid", "decoder crashes", "agent crashes", "hangs",
         "accepted invalid", "inputs/s", "valid µs", "slowest ms", "slowest ÷ valid", "slowest wall ms",
         "peak RSS +MB"],
        [[r["kind"], "yes" if r["keyed"] else "no", f"{r['inputs']:,}", f"{r['invalid_inputs']:,}",
          r["decoder"]["crashes"], r["agent"]["crashes"], r["decoder"]["hangs"] + r["agent"]["hangs"],
          r["accepted_invalid"], f"{r['inputs_per_s']:,.0f}", f"{r['baseline_us']:.0f}",
          f"{r['agent']['slowest_ms']:.1f}", common.fmt_ratio(r["slowest_ratio"]),
          f"{r['agent']['slowest_wall_ms']:.1f}", f"{r['peak_rss_growth_mb']:.0f}"]
         for r in result["rows"]],
        caption="invalid: inputs whose mutation makes them invalid; accepted invalid: of those, the ones that grew no "
                "rejected counter and changed the agent's state; valid µs: receive of a valid message (baseline); "
                "slowest: CPU time of the slowest receive (a hang: > 50 ms), and its wall time",
    )
    for r in result["rows"]:
        for target in ("decoder", "agent"):
            for what, n in {**r[target]["crashes_by_kind"], **r[target]["hangs_by_family"]}.items():
                console.print(f"  {r['kind']}{' (keyed)' if r['keyed'] else ''}: {target} {what}: {n}", highlight=False)
        for family, n in r["accepted_invalid_by_family"].items():
            console.print(f"  {r['kind']}: accepted invalid ({family}): {n}", highlight=False)
    for goal in result["goals"]:
        value = goal.get("value", goal.get("fewest"))
        console.print(f"{common.verdict(goal['pass'])} {goal['description']}: {value:,}", highlight=False)
