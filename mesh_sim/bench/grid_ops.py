"""``skymesh bench grid-ops``: cells per second of grid updates, fusion and the delta codec, vs plain numpy.

Operations, on ``N x N`` grids (full run: N = 256 and 1024; quick run: 256 and 512), each timed in the
same run as its plain-numpy bound, interleaved (see :mod:`mesh_sim.bench.common`):

* ``LogOddsGrid.update(llr)`` with a full-grid llr (Merino Alg. 4.2, (4.2)) — bound ``np.add(e, llr,
  out=buf)`` into a preallocated array;
* ``LogOddsGrid.fuse`` (Merino (4.4), Alg. 4.3: ``e_a + e_b``) — bound ``np.add(e_a, e_b, out=buf)``;
* ``BetaGrid.update(m, n)`` (Merino Alg. 4.4, (4.29)-(4.30)) — bound two ``np.add`` into buffers;
* ``encode_grid`` (:mod:`agent.net.grid_codec`): a delta with 1 % and 10 % of the cells changed since the
  baseline, and a keyframe — bound for deltas ``idx = np.flatnonzero(a != b)`` and
  ``a.ravel()[idx].astype(float32).tobytes()``; for the keyframe ``zlib.compress(float32 bytes)`` at the
  codec's level (no numpy-only way to make a compressed keyframe);
* ``decode_grid`` of the same three messages — bound the same decoding without any validation: for
  deltas ``zlib.decompress`` of the gaps, ``cumsum``, a copy of the baseline and one scatter; for the
  keyframe ``zlib.decompress`` and a float64 conversion.

Every figure is given in cells per second (``N^2 / time``; the same cell count for the bound) and as a
ratio to its bound. Each operation's result is checked against its bound's before timing.

Grids (chosen here): a half-explored log-odds grid — a random half of the cells hold N(0, 2^2) evidence,
the rest the prior 0 — and a Beta grid with Exp(2) counts in the same cells; a "change" adds N(0, 1) to
a random fraction of the cells. The codec works on ``L = 1`` (log-odds); message sizes are reported for
``L = 1`` and ``L = 2`` (Beta counts), and for the 10 % change on ``L = 1`` also as a deadband ``step`` delta
at the fire scenario's ``delta_tolerance`` (:data:`STEP_TOLERANCE`).

Goals (chosen here): every operation within :data:`SPEED_GOAL` x of its bound, except the 10 % delta
encode (reported, not a goal: it also checks whether a keyframe would be smaller — see
:data:`agent.net.grid_codec.KEYFRAME_PROBE_FRACTION` — which the bound does not); and a delta for 1 % of
the cells changed below :data:`BYTES_GOAL` of the keyframe's bytes.
"""

from __future__ import annotations

import zlib
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from agent.net import grid_codec as codec
from agent.net import wire
from fusion.grid import BetaGrid, LogOddsGrid
from fusion.grid_geometry import GridGeometry
from mesh_sim.bench import common

NAME = "grid-ops"
FULL_SIZES = (256, 1024)
QUICK_SIZES = (256, 512)
SPEED_GOAL = 3.0  # operation time / plain-numpy bound, at most (chosen here)
BYTES_GOAL = 0.10  # delta bytes for 1 % of cells changed / keyframe bytes, at most (chosen here)
EXPLORED_FRACTION = 0.5  # cells holding evidence in the benchmark grids (chosen here)
EVIDENCE_STD = 2.0  # log-odds evidence of an explored cell ~ N(0, 2^2) (chosen here)
BETA_COUNT_MEAN = 2.0  # Beta counts of an explored cell ~ Exp(2) (chosen here)
CHANGES = {"1": 0.01, "10": 0.10}  # fractions of cells changed between baseline and message
STEP_TOLERANCE = 0.02  # the deadband of the step delta's size row: the fire scenario's grid.delta_tolerance
STEP_KIND = "step delta 10 %"
CELL_M = 5.0  # geometry cell size [m]; irrelevant to the timings (chosen here)
SEED = 20240611


@dataclass(frozen=True)
class Op:
    key: str
    label: str
    bound: str  # what the plain-numpy bound does
    goal: bool  # part of the speed goal


OPS = [
    Op("logodds_update", "LogOddsGrid.update, full-grid llr", "np.add(e, llr, out=buf)", True),
    Op("logodds_fuse", "LogOddsGrid.fuse", "np.add(e_a, e_b, out=buf)", True),
    Op("beta_update", "BetaGrid.update(m, n)", "2 x np.add into buffers", True),
    Op("encode_delta_1", "encode_grid, delta 1 %", "flatnonzero(a != b) + float32 bytes", True),
    Op("encode_delta_10", "encode_grid, delta 10 %", "flatnonzero(a != b) + float32 bytes", False),
    Op("encode_key", "encode_grid, keyframe", "zlib.compress(float32 bytes)", True),
    Op("decode_delta_1", "decode_grid, delta 1 %", "inflate + cumsum + copy + scatter", True),
    Op("decode_delta_10", "decode_grid, delta 10 %", "inflate + cumsum + copy + scatter", True),
    Op("decode_key", "decode_grid, keyframe", "inflate + float64", True),
]


@dataclass
class Case:
    """One operation on one grid: the skymesh call, its bound, and their results for the agreement check."""

    run: Callable[[], object]
    bound: Callable[[], object]
    agrees: Callable[[], bool]


# -- grids and messages ------------------------------------------------------------------------------
def _explored(rng: np.random.Generator, n: int, layers: int) -> np.ndarray:
    mask = rng.random((n, n)) < EXPLORED_FRACTION
    out = np.zeros((layers, n, n))
    k = int(mask.sum())
    if layers == 1:
        out[0, mask] = rng.normal(0.0, EVIDENCE_STD, k)
    else:
        out[:, mask] = rng.exponential(BETA_COUNT_MEAN, (layers, k))
    return out


def _changed(rng: np.random.Generator, layers: np.ndarray, fraction: float) -> np.ndarray:
    out = layers.copy()
    mask = rng.random(layers.shape[1:]) < fraction
    out[:, mask] += np.abs(rng.normal(0.0, 1.0, (layers.shape[0], int(mask.sum()))))  # counts only grow
    return out


def _bound_delta_decode(payload: dict, base: np.ndarray) -> np.ndarray:
    dtype = codec.INDEX_DTYPES[payload["dtype"]]
    idx = np.cumsum(np.frombuffer(zlib.decompress(payload["index"]), dtype), dtype=np.int64) - 1
    out = base.copy()
    out.reshape(base.shape[0], -1)[:, idx] = np.frombuffer(payload["values"], "<f4").reshape(base.shape[0], -1)
    return out


def _bound_key_decode(payload: dict, shape: tuple[int, ...]) -> np.ndarray:
    return np.frombuffer(zlib.decompress(payload["values"]), "<f4").astype(np.float64).reshape(shape)


def _cases(n: int, rng: np.random.Generator) -> dict[str, Case]:
    geometry = GridGeometry(origin=(0.0, 0.0), cell=CELL_M, shape=(n, n))
    cases: dict[str, Case] = {}

    # log-odds update and fuse
    evidence = _explored(rng, n, 1)[0]
    grid = LogOddsGrid(geometry, evidence)
    other = LogOddsGrid(geometry, _explored(rng, n, 1)[0])
    llr = rng.normal(0.0, 1.0, (n, n))
    buf = np.empty((n, n))
    cases["logodds_update"] = Case(
        lambda: grid.update(llr), lambda: np.add(evidence, llr, out=buf),
        lambda: np.array_equal(grid.update(llr).evidence, evidence + llr))
    cases["logodds_fuse"] = Case(
        lambda: grid.fuse(other), lambda: np.add(evidence, other.evidence, out=buf),
        lambda: np.array_equal(grid.fuse(other).evidence, evidence + other.evidence))

    # Beta update
    counts = _explored(rng, n, 2)
    beta = BetaGrid(geometry, counts[0], counts[1])
    m, k = rng.exponential(1.0, (n, n)), rng.exponential(1.0, (n, n))
    buf2 = np.empty((n, n))

    def beta_bound():
        np.add(counts[0], m, out=buf)
        np.add(counts[1], k, out=buf2)

    def beta_agrees() -> bool:
        b = beta.update(m, k)
        return np.array_equal(b.alpha, counts[0] + m) and np.array_equal(b.beta, counts[1] + k)

    cases["beta_update"] = Case(lambda: beta.update(m, k), beta_bound, beta_agrees)

    # codec
    base = codec.quantize(_explored(rng, n, 1))
    history = {1: base}
    for tag, fraction in CHANGES.items():
        cur = _changed(rng, base, fraction)
        payload = codec.encode_grid(cur, base, 1)

        def bound_encode(cur=cur):
            idx = np.flatnonzero(cur != base)
            return cur.ravel()[idx].astype(np.float32).tobytes()

        cases[f"encode_delta_{tag}"] = Case(
            lambda cur=cur: codec.encode_grid(cur, base, 1), bound_encode,
            lambda cur=cur: np.array_equal(
                codec.decode_grid(codec.encode_grid(cur, base, 1), (n, n), 1, history.get), codec.quantize(cur)))
        cases[f"decode_delta_{tag}"] = Case(
            lambda payload=payload: codec.decode_grid(payload, (n, n), 1, history.get),
            lambda payload=payload: _bound_delta_decode(payload, base),
            lambda payload=payload, cur=cur: payload["mode"] == "delta" and np.array_equal(
                codec.decode_grid(payload, (n, n), 1, history.get), _bound_delta_decode(payload, base))
            and np.array_equal(_bound_delta_decode(payload, base), codec.quantize(cur)))
    key = codec.encode_grid(base, None, None)
    cases["encode_key"] = Case(
        lambda: codec.encode_grid(base, None, None),
        lambda: zlib.compress(base.astype("<f4").tobytes(), codec.ZLIB_LEVEL),
        lambda: codec.encode_grid(base, None, None)["values"]
        == zlib.compress(base.astype("<f4").tobytes(), codec.ZLIB_LEVEL))
    cases["decode_key"] = Case(
        lambda: codec.decode_grid(key, (n, n), 1, history.get),
        lambda: _bound_key_decode(key, base.shape),
        lambda: np.array_equal(codec.decode_grid(key, (n, n), 1, history.get), base))
    return cases


def _message_sizes(n: int, layers: int, rng: np.random.Generator) -> list[dict]:
    base = codec.quantize(_explored(rng, n, layers))
    key = codec.encode_grid(base, None, None)
    key_bytes = codec.encoded_size(key)
    rows = []

    def row(kind: str, payload: dict) -> dict:
        size = codec.encoded_size(payload)
        return {"size": f"{n}x{n}", "n": n, "layers": layers, "kind": kind, "mode": payload["mode"], "bytes": size,
                "raw_bytes": 4 * layers * n * n, "ratio_to_keyframe": size / key_bytes,
                "fits_wire": size <= wire.MAX_MESSAGE_BYTES}

    rows.append(row("keyframe", key))
    rows.append(row("keyframe, all prior", codec.encode_grid(np.zeros_like(base), None, None)))
    for tag, fraction in CHANGES.items():
        changed = _changed(rng, base, fraction)
        rows.append(row(f"delta {tag} %", codec.encode_grid(changed, base, 1)))
        if tag == "10" and layers == 1:  # Beta grids keep exact deltas (agent.beliefs.grid_config)
            rows.append(row(STEP_KIND, codec.encode_grid(changed, base, 1, tolerance=STEP_TOLERANCE)))
    rows.append(row("delta, no change", codec.encode_grid(base, base, 1)))
    return rows


# -- run ---------------------------------------------------------------------------------------------
def run(quick: bool = False, repeats: int | None = None) -> dict:
    """Run the benchmark; returns ``{"benchmark", "settings", "environment", "rows", "messages", "goals"}``."""
    settings = common.Settings.create(quick, repeats)
    sizes = QUICK_SIZES if quick else FULL_SIZES
    rng = np.random.default_rng(SEED)
    rows, messages = [], []
    with common.progress(len(sizes) * (len(OPS) + 2), NAME) as advance:
        for n in sizes:
            cases = _cases(n, rng)
            for op in OPS:
                advance(f"{op.key} {n}x{n}")
                case = cases[op.key]
                agrees = bool(case.agrees())
                timings = common.time_calls({"skymesh": case.run, "numpy": case.bound}, settings)
                sky, bound = timings["skymesh"], timings["numpy"]
                cells = n * n
                rows.append({
                    "op": op.key, "label": op.label, "bound": op.bound, "size": f"{n}x{n}", "n": n, "cells": cells,
                    "us": sky.median_us, "best_us": sky.best_us, "cells_per_s": cells / (sky.median_us * 1e-6),
                    "bound_us": bound.median_us, "bound_best_us": bound.best_us,
                    "bound_cells_per_s": cells / (bound.median_us * 1e-6), "ratio": sky.median_us / bound.median_us,
                    "repeats": sky.repeats, "number": sky.number, "bound_number": bound.number, "agrees": agrees,
                    "goal": op.goal,
                })
            for layers in (1, 2):
                advance(f"message sizes {n}x{n} L={layers}")
                messages.extend(_message_sizes(n, layers, rng))
    return {
        "benchmark": NAME,
        "settings": {
            "quick": settings.quick, "repeats": settings.repeats, "min_time_s": settings.min_time,
            "sizes": [f"{n}x{n}" for n in sizes], "seed": SEED, "explored_fraction": EXPLORED_FRACTION,
            "evidence_std": EVIDENCE_STD, "beta_count_mean": BETA_COUNT_MEAN, "changes": dict(CHANGES),
            "zlib_level": codec.ZLIB_LEVEL, "keyframe_probe_fraction": codec.KEYFRAME_PROBE_FRACTION,
            "speed_goal": SPEED_GOAL, "bytes_goal": BYTES_GOAL,
        },
        "environment": common.environment(("numpy", "scipy", "msgpack")),
        "rows": rows,
        "messages": messages,
        "goals": _goals(rows, messages),
    }


def _goals(rows: list[dict], messages: list[dict]) -> list[dict]:
    speed = [{"op": r["op"], "size": r["size"], "ratio": r["ratio"], "pass": r["ratio"] <= SPEED_GOAL}
             for r in rows if r["goal"]]
    delta = [{"size": m["size"], "layers": m["layers"], "ratio": m["ratio_to_keyframe"],
              "pass": m["mode"] == "delta" and m["ratio_to_keyframe"] < BYTES_GOAL}
             for m in messages if m["kind"] == "delta 1 %"]
    return [
        {"name": "speed", "description": f"every operation (but the 10 % delta encode) within {SPEED_GOAL:g}x of its "
         "plain-numpy bound", "target_max_ratio": SPEED_GOAL, "results": speed, "pass": all(r["pass"] for r in speed)},
        {"name": "delta_bytes", "description": f"a delta for 1 % of the cells changed < {BYTES_GOAL:.0%} of the "
         "keyframe's bytes", "target_max_ratio": BYTES_GOAL, "results": delta, "pass": all(r["pass"] for r in delta)},
    ]


# -- report ------------------------------------------------------------------------------------------
def _mcells(value: float) -> str:
    return f"{value / 1e6:,.0f}" if value >= 1e8 else f"{value / 1e6:.3g}"


def _bytes(value: int) -> str:
    return f"{value:,}"


def report(result: dict, console=None) -> None:
    """Print the tables and the goal verdicts of a :func:`run` result."""
    console = console or common.make_console()
    s, env = result["settings"], result["environment"]
    console.print(
        f"[bold]{NAME}[/bold]  {'quick' if s['quick'] else 'full'} run, {s['repeats']} repeats; median per call. "
        f"{common.machine_line(env, {'numpy': 'numpy', 'msgpack': 'msgpack'})}",
        highlight=False,
    )
    table = []
    for r in result["rows"]:
        verdict = common.verdict(r["ratio"] <= s["speed_goal"]) if r["goal"] else "info"
        table.append([
            r["label"], r["size"], _mcells(r["cells_per_s"]), common.fmt_us(r["us"]), _mcells(r["bound_cells_per_s"]),
            r["bound"], common.fmt_ratio(r["ratio"]), verdict, "yes" if r["agrees"] else "[red]NO[/red]",
        ])
    common.print_table(
        console, "Grid operations: million cells per second (Mcells/s) vs a plain-numpy bound",
        [("operation", "left"), "grid", "Mcells/s", "µs / call", "bound Mcells/s", ("bound", "left"), "÷ bound",
         f"goal ≤{s['speed_goal']:g}x", "agrees"],
        table,
        f"Grids: {s['explored_fraction']:.0%} of cells explored (log-odds N(0, {s['evidence_std']:g}²), Beta counts "
        f"Exp({s['beta_count_mean']:g})); a delta changes a random fraction of cells. Codec: float32 values, zlib "
        f"level {s['zlib_level']}; a delta above {s['keyframe_probe_fraction']:.2%} of the raw keyframe is checked "
        "against a keyframe (that check is why the 10 % delta encode is not in the goal).\n'agrees': the operation's "
        "result equals its bound's (decoded messages equal the quantized grid).",
    )
    by = {}
    for m in result["messages"]:
        by.setdefault((m["size"], m["layers"]), {})[m["kind"]] = m

    def cell(m: dict | None, ratio: bool = True) -> str:
        if m is None:
            return "—"
        text = _bytes(m["bytes"]) + (f" ({m['ratio_to_keyframe']:.1%})" if ratio else "")
        text += "" if m["mode"] in ("delta", "step") or m["kind"].startswith("keyframe") else " key"
        return text + ("" if m["fits_wire"] else " [yellow]>1 MiB[/yellow]")

    msg_rows = []
    for (size, layers), kinds in by.items():
        msg_rows.append([
            size, f"{layers} ({'log-odds' if layers == 1 else 'Beta'})", _bytes(kinds["keyframe"]["raw_bytes"]),
            cell(kinds.get("keyframe"), False), cell(kinds.get("keyframe, all prior"), False),
            cell(kinds.get("delta 1 %")), cell(kinds.get("delta 10 %")), cell(kinds.get(STEP_KIND)),
            cell(kinds.get("delta, no change"), False),
        ])
    common.print_table(
        console, "Bytes per grid message (msgpack payload; in brackets: ÷ keyframe)",
        ["grid", ("layers", "left"), "raw float32", "keyframe", "keyframe, all prior", "delta 1 %", "delta 10 %",
         f"step 10 %, q = {STEP_TOLERANCE:g}", "empty delta"],
        msg_rows,
        "'key' = the codec sent a keyframe because it was smaller than the delta. 'step': the same change as a "
        "deadband delta (whole quanta, agent.net.grid_codec). '>1 MiB' = larger than the wire "
        f"format's message limit ({wire.MAX_MESSAGE_BYTES:,} bytes).",
    )
    for goal in result["goals"]:
        ratios = [r["ratio"] for r in goal["results"]]
        span = (f"{min(ratios):.3g} … {max(ratios):.3g}" if goal["name"] == "delta_bytes"
                else f"{common.fmt_ratio(min(ratios))} … {common.fmt_ratio(max(ratios))}") if ratios else "—"
        missed = [f"{r['op']} {r['size']}" for r in goal["results"] if not r["pass"] and "op" in r]
        extra = f"; missed: {', '.join(missed)}" if missed else ""
        console.print(f"{common.verdict(goal['pass'])}  {goal['description']} (measured {span}{extra})",
                      highlight=False)
