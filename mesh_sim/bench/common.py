"""Shared plumbing for the benchmarks: timing, settings, tables, JSON output.

Timing: :func:`time_calls` runs every candidate implementation of one operation *interleaved* (repeat 1
of each, then repeat 2 of each, ...), so that slow drifts of the machine (frequency scaling, a
neighbour process) hit all candidates alike and their ratios stay meaningful. Each repeat times
``number`` back-to-back calls with :func:`time.perf_counter`, where ``number`` is calibrated so that
one repeat lasts at least ``min_time`` seconds; the per-call figure of a candidate is the median over
its repeats (``best_us``, the fastest repeat, is kept as well).
"""

from __future__ import annotations

import json
import math
import os
import platform
import sys
import tempfile
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from agent.runtime import atomic_file

#: Timing settings of the two modes (chosen here: quick finishes in seconds, full in about a minute).
QUICK_REPEATS, QUICK_MIN_TIME = 5, 0.004
FULL_REPEATS, FULL_MIN_TIME = 21, 0.03


@dataclass(frozen=True)
class Settings:
    """How hard to time: ``repeats`` timed repeats of at least ``min_time`` seconds each."""

    quick: bool
    repeats: int
    min_time: float

    @classmethod
    def create(cls, quick: bool, repeats: int | None = None) -> Settings:
        """The settings of a mode; ``repeats`` overrides the number of repeats (and, below 3, also
        shortens each repeat: the test suite uses it to make a quick run quicker still)."""
        base_repeats, min_time = (QUICK_REPEATS, QUICK_MIN_TIME) if quick else (FULL_REPEATS, FULL_MIN_TIME)
        if repeats is None:
            return cls(quick, base_repeats, min_time)
        if repeats < 1:
            raise ValueError(f"repeats must be at least 1, got {repeats}")
        return cls(quick, repeats, min_time if repeats >= 3 else min_time / 4)


@dataclass(frozen=True)
class Timing:
    """Microseconds per call: median and best over ``repeats`` repeats of ``number`` calls each."""

    median_us: float
    best_us: float
    repeats: int
    number: int

    def to_dict(self) -> dict:
        return asdict(self)


def _calibrate(fn: Callable[[], object], min_time: float) -> int:
    """Smallest ``number`` (1, 2, 5, 10, 20, ...) whose back-to-back calls take at least ``min_time``."""
    number = 1
    while True:
        start = time.perf_counter()
        for _ in range(number):
            fn()
        elapsed = time.perf_counter() - start
        if elapsed >= min_time:
            return number
        # jump close to the target, then round up to a 1-2-5 step
        wanted = number * min_time / max(elapsed, 1e-9)
        step = 10 ** math.floor(math.log10(max(wanted, 1.0)))
        number = next(m * step for m in (1, 2, 5, 10) if m * step >= wanted)


def time_calls(candidates: Mapping[str, Callable[[], object]], settings: Settings) -> dict[str, Timing]:
    """Time each zero-argument callable; returns microseconds per call per candidate name."""
    numbers = {name: _calibrate(fn, settings.min_time) for name, fn in candidates.items()}  # also warms up
    samples: dict[str, list[float]] = {name: [] for name in candidates}
    perf_counter = time.perf_counter
    for _ in range(settings.repeats):
        for name, fn in candidates.items():
            number = numbers[name]
            loop = range(number)
            start = perf_counter()
            for _ in loop:
                fn()
            samples[name].append((perf_counter() - start) / number * 1e6)
    return {
        name: Timing(_median(values), min(values), settings.repeats, numbers[name]) for name, values in samples.items()
    }


def _median(values: Sequence[float]) -> float:
    ordered = sorted(values)
    mid = len(ordered) // 2
    return ordered[mid] if len(ordered) % 2 else 0.5 * (ordered[mid - 1] + ordered[mid])


# -- output -----------------------------------------------------------------------------------------
def make_console(stderr: bool = False) -> Console:
    """A rich console; when the output is not a terminal, wide enough that tables do not wrap."""
    console = Console(stderr=stderr)
    if not console.is_terminal and "COLUMNS" not in os.environ:
        console = Console(stderr=stderr, width=180)
    return console


def print_table(
    console: Console,
    title: str,
    columns: Sequence[str | tuple[str, str]],
    rows: Iterable[Sequence[object]],
    caption: str | None = None,
) -> None:
    """Print a table; a column is a header or ``(header, justify)``; cells are converted with ``str``."""
    table = Table(title=title, caption=caption, caption_justify="left", header_style="bold", highlight=False)
    for column in columns:
        header, justify = (column, "right") if isinstance(column, str) else column
        table.add_column(header, justify=justify)
    for row in rows:
        table.add_row(*(str(cell) for cell in row))
    console.print(table)


@contextmanager
def progress(total: int, description: str) -> Iterator[Callable[[str], None]]:
    """A transient progress bar on stderr (only on a terminal); yields ``advance(label)``.

    It redraws only when advanced (no refresh thread), so it does not disturb the timings."""
    console = make_console(stderr=True)
    columns = (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn())
    with Progress(
        *columns, console=console, transient=True, auto_refresh=False, disable=not console.is_terminal
    ) as bar:
        task = bar.add_task(description, total=total)

        def advance(label: str) -> None:
            bar.update(task, advance=1, description=f"{description}: {label}", refresh=True)

        yield advance


def fmt_us(value: float | None) -> str:
    """Microseconds with three significant figures ('—' for missing)."""
    if value is None or not math.isfinite(value):
        return "—"
    if value >= 1000:
        return f"{value:,.0f}"
    return f"{value:.3g}" if value < 100 else f"{value:.0f}"


def fmt(value, spec: str, suffix: str = "") -> str:
    """``format(value, spec)`` plus ``suffix``; '—' for a missing or non-finite value."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "—"
    return f"{format(value, spec)}{suffix}"


def fmt_ms(value: float | None) -> str:
    """Milliseconds: three decimals below 1, two below 100, none above ('—' for missing)."""
    if value is None or not math.isfinite(value):
        return "—"
    return f"{value:.3f}" if value < 1 else f"{value:.2f}" if value < 100 else f"{value:.0f}"


def ratio(a: float | None, b: float | None) -> float | None:
    """``a / b``, ``None`` when either is missing or ``b`` is zero (a figure against its same-run baseline)."""
    return None if a is None or not b else a / b


def missed_steps(agents: Iterable[Mapping]) -> tuple[int, int]:
    """``(missed, due)`` agent steps of a run's agents: late (``deadline_misses``) or skipped, over steps run plus
    skipped (:mod:`agent.runtime`); every agent given must report ``steps``."""
    missed = due = 0
    for a in agents:
        missed += a.get("deadline_misses", 0) + a.get("skipped_steps", 0)
        due += a["steps"] + a.get("skipped_steps", 0)
    return missed, due


def fmt_ratio(value: float | None) -> str:
    if value is None or not math.isfinite(value):
        return "—"
    return f"{value:.2f}x" if value < 10 else f"{value:.1f}x" if value < 100 else f"{value:.0f}x"


def verdict(ok: bool | None) -> str:
    if ok is None:
        return "—"
    return "[green]PASS[/green]" if ok else "[red]MISS[/red]"


def write_json(path: str | os.PathLike, result: Mapping) -> Path:
    """Write a benchmark result as JSON (creating parent folders); non-finite floats become null."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_file(path) as f:
        f.write(json.dumps(_finite(result), indent=2, sort_keys=False) + "\n")
    return path


def _finite(value):
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, Mapping):
        return {str(k): _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value


def environment(packages: Iterable[str] = ("numpy", "scipy")) -> dict:
    """Machine and library versions, recorded with every result."""
    from importlib import metadata

    versions = {}
    for name in packages:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    return {
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "machine": platform.machine(),
        "processor": _cpu_model(),
        "cpu_count": os.cpu_count(),
        "packages": versions,
    }


def machine_line(env: dict, packages: dict[str, str]) -> str:
    """``"<cpu> (<n> CPUs), Python x.y, numpy a.b, ..."`` for a report header; ``packages`` maps a label to
    its distribution name in ``env["packages"]``."""
    versions = ", ".join(f"{label} {env['packages'].get(name)}" for label, name in packages.items())
    return f"{env['processor']} ({env['cpu_count']} CPUs), Python {env['python']}, {versions}"


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor()


@contextmanager
def runs_folder(runs_dir, prefix: str) -> Iterator[Path]:
    """Where a benchmark's run folders go: ``runs_dir`` if given (kept), else a temporary folder
    (removed afterwards, so a benchmark leaves nothing behind)."""
    if runs_dir is not None:
        path = Path(runs_dir)
        path.mkdir(parents=True, exist_ok=True)
        yield path
        return
    with tempfile.TemporaryDirectory(prefix=prefix) as tmp:
        yield Path(tmp)


@contextmanager
def run_progress(name: str, total: int):
    """A transient bar over a benchmark's runs on stderr (only on a terminal); a launcher's own bar
    (simulation time of the current run) shares the console and shows below it. Yields
    ``(console, advance(label, steps))``."""
    console = make_console(stderr=True)
    columns = (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn())
    with Progress(*columns, console=console, transient=True, disable=not console.is_terminal) as bar:
        task = bar.add_task(name, total=total)

        def advance(label: str, steps: int) -> None:
            bar.update(task, advance=steps, description=f"{name}: {label}", refresh=True)

        yield console, advance
