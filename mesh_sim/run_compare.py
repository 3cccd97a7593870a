"""Exact comparison of run folders: did a change (a refactoring) alter what a lockstep run computes?

``skymesh compare BEFORE AFTER`` compares two run folders (or two folders that each hold exactly one run
folder, as ``skymesh run --out DIR`` leaves them): ``metrics.json``, every ``agent-*.json``,
``oracle.json`` and ``fire_maps.npz``. JSON is compared recursively and exactly: a float must be equal bit
for bit (``0.1 + 0.2`` is not ``0.3``; ``1`` is not ``1.0``), a list element by element, a dict key by key
in any order. Arrays are compared with numpy: same dtype, same shape, same bytes.
``skymesh compare --tree BEFORE_ROOT AFTER_ROOT`` pairs the sub-folders of two roots by name and prints
one line per pair.

Volatile fields differ between two lockstep runs of the same scenario and seed on the same code (found
by running every shipped scenario twice and diffing), so they are removed before comparing:

* keys, wherever they are: see :data:`VOLATILE_KEYS` (process id, CPU and wall time, memory);
* ``config.speed`` of ``metrics.json`` (:data:`VOLATILE_PATHS`): a lockstep run's speed factor is its
  simulated duration over its wall time;
* strings (values and keys) naming the run: the run folder's own path, a run-folder name
  (``NAME-YYYYMMDD-HHMMSS-xxxx``, :func:`mesh_sim.launcher.new_run_dir`) and a fleet name with its random
  suffix (``NAME-xxxxxxxx``, the Zenoh key root of a run) are replaced by ``<run>`` and ``<fleet>``.
  Today's lockstep files hold none of them; the masking keeps the comparison meaningful if one appears.

A *snapshot* (:func:`snapshot`) is the same content in a small, JSON-serialisable form: the stripped
``metrics.json`` in full, the other JSON files (copies of parts of ``metrics.json``) and every array as a
SHA-256 digest beside its sum and sum of squares. The golden-run regression test
(``tests/mesh_sim/test_golden_runs.py``) stores one per run and checks a fresh run against it with :func:`diff`.

``diff(..., rtol=r)`` (``skymesh compare --rtol R``) accepts floats equal to a relative (and absolute)
tolerance ``r`` instead of bit for bit, and then compares arrays by their sums, not their digests: a new
numpy, SciPy or OpenCV release changes the last bits of a run (sums in another order, another BLAS
kernel), which is not a change of behaviour; a digest cannot say how far apart two arrays are.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

#: Keys removed wherever they appear, and why they vary from one run to the next.
VOLATILE_KEYS: dict[str, str] = {
    "pid": "the process id of the agent (lockstep: of the harness)",
    "cpu_per_step_ms": "CPU time per step (lockstep: the run's wall time / agent steps)",
    "wall_s": "wall-clock seconds the run took (oracle.json)",
    "rss_mb": "peak resident memory of a live process",
}
#: ``(file, key, key, ...)`` paths removed, and why.
VOLATILE_PATHS: dict[tuple[str, ...], str] = {
    ("metrics.json", "config", "speed"): "lockstep: simulated duration / wall time of the run",
}
RUN_FOLDER = re.compile(r"\b[\w.]+-\d{8}-\d{6}-[0-9a-f]{4}\b")  # mesh_sim.launcher.new_run_dir
FLEET = re.compile(r"\b[\w.]+-[0-9a-f]{8}\b")  # f"{scenario.name}-{uuid4().hex[:8]}": launcher, lockstep
JSON_FILES = ("metrics.json", "oracle.json")
ARRAYS = "fire_maps.npz"
MISSING = "(missing)"


class RunFolderError(ValueError):
    """A path that is not a run folder (nor a folder holding exactly one)."""


@dataclass(frozen=True)
class Difference:
    """One difference: where (``file: key.path[index]``), and what it was before and after (for display)."""

    path: str
    before: str
    after: str


def resolve_run(path: str | Path) -> Path:
    """``path`` itself if it holds ``metrics.json``, else its only sub-folder that does."""
    path = Path(path)
    if not path.is_dir():
        raise RunFolderError(f"{path}: no such folder")
    if (path / "metrics.json").is_file():
        return path
    runs = [p for p in path.iterdir() if p.is_dir() and (p / "metrics.json").is_file()]
    if len(runs) != 1:
        found = "none" if not runs else ", ".join(sorted(p.name for p in runs))
        raise RunFolderError(f"{path}: not a run folder (no metrics.json) and not a folder holding exactly one "
                             f"run folder (found {found})")
    return runs[0]


def load_run(run_dir: str | Path) -> dict[str, Any]:
    """Every compared file of a run folder, volatile fields removed: ``{file name: content}``, arrays as
    ``{name: numpy array}``."""
    run_dir = resolve_run(run_dir)
    names = [*JSON_FILES, *sorted(p.name for p in run_dir.glob("agent-*.json"))]
    files: dict[str, Any] = {}
    for name in names:
        if (run_dir / name).is_file():
            files[name] = strip(json.loads((run_dir / name).read_text()), (name,), run_dir)
    if (run_dir / ARRAYS).is_file():
        with np.load(run_dir / ARRAYS, allow_pickle=False) as data:
            files[ARRAYS] = {key: data[key] for key in data.files}
    return files


def snapshot(run_dir: str | Path) -> dict[str, Any]:
    """:func:`load_run` in a small JSON-serialisable form: ``metrics.json`` in full; the other JSON files
    (which ``metrics.json`` embeds) and every array as SHA-256 digests (arrays with dtype and shape)."""
    return digested(load_run(run_dir))


def digested(files: dict[str, Any]) -> dict[str, Any]:
    """:func:`snapshot` of an already loaded run (canonical JSON: sorted keys, floats in full precision)."""
    out: dict[str, Any] = {}
    for name, content in files.items():
        if name == ARRAYS:
            out[name] = {key: {"dtype": str(a.dtype), "shape": list(a.shape),
                               "sha256": hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest(),
                               **_sums(a)}
                         for key, a in content.items()}
        elif name == "metrics.json":
            out[name] = content
        else:
            canonical = json.dumps(content, sort_keys=True, separators=(",", ":"))
            out[name] = {"sha256": hashlib.sha256(canonical.encode()).hexdigest()}
    return out


def _sums(a: np.ndarray) -> dict[str, float]:
    """An array's sum and sum of squares (float64), which a tolerant :func:`diff` compares (numbers only)."""
    if a.dtype.kind not in "biuf":
        return {}
    values = a.astype(float)
    return {"sum": float(values.sum()), "sum_squares": float((values * values).sum())}


def strip(value: Any, path: tuple[str, ...], run_dir: Path | None = None) -> Any:
    """``value`` without :data:`VOLATILE_KEYS` and :data:`VOLATILE_PATHS`, run and fleet names masked."""
    if isinstance(value, dict):
        return {_mask(k, run_dir): strip(v, (*path, k), run_dir) for k, v in value.items()
                if k not in VOLATILE_KEYS and (*path, k) not in VOLATILE_PATHS}
    if isinstance(value, list):
        return [strip(v, path, run_dir) for v in value]
    return _mask(value, run_dir) if isinstance(value, str) else value


def _mask(text: Any, run_dir: Path | None) -> Any:
    if not isinstance(text, str):
        return text
    if run_dir is not None:
        text = text.replace(str(run_dir.resolve()), "<run>").replace(str(run_dir), "<run>")
    return FLEET.sub("<fleet>", RUN_FOLDER.sub("<run>", text))


def diff(before: dict[str, Any], after: dict[str, Any], rtol: float = 0.0) -> list[Difference]:
    """Every difference between two :func:`load_run` (or two :func:`snapshot`) results; paths read
    ``metrics.json: agents[0].targets[2].rmse``. Exact with ``rtol = 0``; otherwise floats within ``rtol``
    (relative, or absolute near zero) are equal, and digests (``sha256``) and the raw arrays of a
    :func:`load_run` are compared by their sums (:func:`_sums`)."""
    if not (math.isfinite(rtol) and rtol >= 0):
        raise ValueError(f"the tolerance must be a finite number >= 0, got {rtol!r}")
    if rtol > 0:
        before, after = _tolerant_view(before), _tolerant_view(after)
    out: list[Difference] = []
    for name in [*before, *(k for k in after if k not in before)]:
        if name not in after:
            out.append(Difference(name, "present", MISSING))
        elif name not in before:
            out.append(Difference(name, MISSING, "present"))
        else:
            out.extend(_walk(before[name], after[name], f"{name}:", rtol))
    return out


def _tolerant_view(files: dict[str, Any]) -> dict[str, Any]:
    """What a tolerant :func:`diff` compares: arrays as their sums, digests left out."""
    def view(value: Any) -> Any:
        if isinstance(value, np.ndarray):
            return {"dtype": str(value.dtype), "shape": list(value.shape), **_sums(value)}
        if isinstance(value, dict):
            return {k: view(v) for k, v in value.items() if k != "sha256"}
        return value

    return {name: view(content) for name, content in files.items()}


def _walk(a: Any, b: Any, path: str, rtol: float = 0.0) -> Iterator[Difference]:
    if isinstance(a, dict) and isinstance(b, dict):
        for key in [*a, *(k for k in b if k not in a)]:
            sub = f"{path} {key}" if path.endswith(":") else f"{path}.{key}"
            if key not in b:
                yield Difference(sub, _show(a[key]), MISSING)
            elif key not in a:
                yield Difference(sub, MISSING, _show(b[key]))
            else:
                yield from _walk(a[key], b[key], sub, rtol)
    elif isinstance(a, list) and isinstance(b, list):
        for i in range(max(len(a), len(b))):
            sub = f"{path}[{i}]"
            if i >= len(b):
                yield Difference(sub, _show(a[i]), MISSING)
            elif i >= len(a):
                yield Difference(sub, MISSING, _show(b[i]))
            else:
                yield from _walk(a[i], b[i], sub, rtol)
    elif isinstance(a, np.ndarray) and isinstance(b, np.ndarray):
        if a.dtype != b.dtype or a.shape != b.shape:
            yield Difference(path, _show(a), _show(b))
        elif np.ascontiguousarray(a).tobytes() != np.ascontiguousarray(b).tobytes():
            yield Difference(path, _show(a), _array_change(a, b))
    elif not _same(a, b, rtol):
        yield Difference(path, _show(a), _show(b))


def _array_change(a: np.ndarray, b: np.ndarray) -> str:
    equal = a == b
    if a.dtype.kind in "fc":
        equal |= np.isnan(a) & np.isnan(b)
    n = int(np.count_nonzero(~equal))
    if n == 0:  # equal values, different bits: -0.0 against 0.0, or NaN payloads
        return "same values, different bits (signed zeros or NaN payloads)"
    if a.dtype.kind in "biuf":
        delta = np.abs(a.astype(float) - b.astype(float))[~equal]
        return f"{n} of {a.size} elements differ, max |delta| {np.nanmax(delta):.3g}"
    return f"{n} of {a.size} elements differ"


def _same(a: Any, b: Any, rtol: float = 0.0) -> bool:
    """Equal and of the same type; floats bit for bit (so NaN equals the same NaN, -0.0 is not 0.0), or
    within ``rtol`` when it is positive."""
    if type(a) is not type(b):
        return False
    if isinstance(a, float):
        if rtol > 0 and math.isclose(a, b, rel_tol=rtol, abs_tol=rtol):
            return True
        return struct.pack("<d", a) == struct.pack("<d", b)
    return a == b


def _show(value: Any, width: int = 80) -> str:
    """A short display: JSON for dicts and lists (cut at ``width``), dtype[shape] for arrays, else repr
    (full float precision)."""
    if isinstance(value, dict | list):
        text = json.dumps(value, default=repr)
        return text if len(text) <= width else text[: width - 3] + "..."
    if isinstance(value, np.ndarray):
        return f"{value.dtype}{list(value.shape)}"
    return repr(value)


def compare(before: str | Path, after: str | Path, rtol: float = 0.0) -> list[Difference]:
    """The differences between two run folders (:class:`RunFolderError` if either is not one); see :func:`diff`."""
    return diff(load_run(before), load_run(after), rtol)


@dataclass(frozen=True)
class Pair:
    """One pair of ``--tree`` mode: its name and differences, or why it could not be compared."""

    name: str
    differences: list[Difference]
    error: str | None = None

    @property
    def identical(self) -> bool:
        return self.error is None and not self.differences

    def summary(self) -> str:
        if self.error is not None:
            return f"{self.name}: not compared: {self.error}"
        n = len(self.differences)
        return f"{self.name}: identical" if n == 0 else f"{self.name}: {n} difference{'s' if n > 1 else ''}"


def compare_tree(before_root: str | Path, after_root: str | Path, rtol: float = 0.0) -> list[Pair]:
    """Pair the sub-folders of two roots by name and compare each pair (a name on one side only, or a
    sub-folder that is not a run folder, is a pair that could not be compared)."""
    roots = [Path(before_root), Path(after_root)]
    for root in roots:
        if not root.is_dir():
            raise RunFolderError(f"{root}: no such folder")
    names = [{p.name for p in root.iterdir() if p.is_dir()} for root in roots]
    if not names[0] | names[1]:
        raise RunFolderError(f"{roots[0]} and {roots[1]} hold no folders to pair")
    pairs = []
    for name in sorted(names[0] | names[1]):
        if name not in names[1] or name not in names[0]:
            side = "AFTER" if name not in names[1] else "BEFORE"
            pairs.append(Pair(name, [], f"missing in {side} ({roots[side == 'AFTER']})"))
            continue
        try:
            pairs.append(Pair(name, compare(roots[0] / name, roots[1] / name, rtol)))
        except (RunFolderError, OSError, ValueError) as err:
            pairs.append(Pair(name, [], str(err)))
    return pairs


def difference_table(differences: list[Difference], title: str, limit: int | None = None):
    """A rich table of (path, before, after), at most ``limit`` rows plus a line saying how many more."""
    from rich.table import Table

    table = Table(title=title, title_justify="left")
    for column in ("path", "before", "after"):
        table.add_column(column, overflow="fold")
    shown = differences if limit is None else differences[:limit]
    for d in shown:
        table.add_row(d.path, d.before, d.after)
    if len(shown) < len(differences):
        table.add_row(f"... and {len(differences) - len(shown)} more", "", "")
    return table


def difference_lines(differences: list[Difference], limit: int | None = None) -> list[str]:
    """``path  before X  after Y``, one line each (floats in full precision)."""
    shown = differences if limit is None else differences[:limit]
    lines = [f"{d.path}  before {d.before}  after {d.after}" for d in shown]
    if len(shown) < len(differences):
        lines.append(f"... and {len(differences) - len(shown)} more")
    return lines
