"""The live loop (agent.runtime.run_steps) on the wall clock: steps at their grid times shifted by the agent's phase,
deadline misses and skipped steps counted, and the phases that spread N agents over a step."""

from __future__ import annotations

import threading
import time

import pytest

from agent.runtime import SimClock, run_steps, staggered_phase

DT = 0.2  # simulation seconds per step
SPEED = 2.0  # a step every 100 ms of wall time: room for a loaded machine's scheduling jitter


def _run(phase: float, work: float = 0.0, duration: float = 2.0):
    clock = SimClock(time.time() + 0.05, SPEED)
    calls = []

    def step(t):
        calls.append((t, time.time()))
        time.sleep(work)

    stats = run_steps(step, clock, DT, duration, threading.Event(), phase=phase)
    return clock, calls, stats


@pytest.mark.parametrize("phase", [0.0, 0.05, 0.15])
def test_each_step_runs_at_its_grid_time_plus_the_phase(phase):
    clock, calls, stats = _run(phase)
    assert [t for t, _ in calls] == pytest.approx([k * DT for k in range(11)])
    for t, wall in calls:
        late = wall - clock.wall(t + phase)
        assert 0.0 <= late < 0.09, (t, late)  # never early (a phase ignored would be); late by the scheduler only
    assert stats.steps == 11 and stats.deadline_misses == 0 and stats.skipped_steps == 0


def test_a_slow_step_misses_its_deadline_and_the_loop_skips_ahead():
    _, calls, stats = _run(0.1, work=0.25)  # each step takes two and a half steps of wall time (100 ms each)
    assert stats.as_dict()["step_wall_ms_median"] >= 250.0  # the steps' own wall time
    assert stats.deadline_misses == stats.steps > 0
    assert stats.skipped_steps > 0 and stats.steps + stats.skipped_steps >= 10
    assert all(b - a >= DT - 1e-9 for (a, _), (b, _) in zip(calls, calls[1:], strict=False))


@pytest.mark.parametrize("phase", [-0.01, DT, 1.0])
def test_a_phase_outside_the_step_is_refused(phase):
    with pytest.raises(ValueError, match="phase must be in"):
        run_steps(lambda t: None, SimClock(time.time()), DT, 1.0, threading.Event(), phase=phase)


def test_staggered_phases_spread_the_agents_evenly_over_one_step():
    assert [staggered_phase(i, 4, DT) for i in range(4)] == pytest.approx([0.0, 0.05, 0.1, 0.15])
    assert staggered_phase(5, 4, DT) == pytest.approx(0.05)  # an index beyond the team wraps around
    assert staggered_phase(0, 1, DT) == 0.0
    for index, count in ((-1, 4), (0, 0)):
        with pytest.raises(ValueError, match="need 0 <= index and count >= 1"):
            staggered_phase(index, count, DT)


def test_a_process_started_mid_run_joins_the_present():
    """A restarted agent (skymesh run --restart) starts 30 simulated seconds into the run: its first step is at
    the present grid time, not at t = 0 followed by a jump, and nothing before it counts as skipped."""
    calls = []
    clock = SimClock(time.time() - 30.0 / SPEED, SPEED)
    stats = run_steps(calls.append, clock, DT, 30.0 + 3 * DT, threading.Event())
    assert 29.0 <= calls[0] <= 30.0 and calls[0] == pytest.approx(round(calls[0] / DT) * DT)
    assert stats.skipped_steps <= 1
