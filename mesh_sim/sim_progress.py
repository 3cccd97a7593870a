"""A run's progress in simulation time: a rich progress bar (``t=12/60 s`` and the wall time left), shown while the
run goes and removed when it ends. The live launcher and ``skymesh run --lockstep`` show the same bar."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager

from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn


@contextmanager
def sim_progress(console: Console, description: str, duration: float) -> Iterator[Callable[[float], None]]:
    """A bar from 0 to ``duration`` simulated seconds on ``console``; yields ``advance(t)``, which moves it to
    simulation time ``t`` (clipped to the duration). A console that is not a terminal shows nothing."""
    progress = Progress(TextColumn("[bold]{task.description}"), BarColumn(),
                        TextColumn("t={task.completed:.0f}/{task.total:.0f} s"), TimeRemainingColumn(),
                        console=console, transient=True)
    with progress:
        task = progress.add_task(description, total=duration)
        yield lambda t: progress.update(task, completed=min(max(t, 0.0), duration))
