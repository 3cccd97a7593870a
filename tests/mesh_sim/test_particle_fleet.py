"""The ambiguous scenario in lockstep (skymesh issue 15, item 1): with the particle exchange every agent
gets a unimodal belief within 2 m of both look-alike cars, within 1.5x the centralized particle filter's
time and sooner than alone, for particle messages within 3x the track messages' bytes."""

from __future__ import annotations

import math

import pytest

from mesh_sim.bench import common, particles, particles_fleet

pytestmark = pytest.mark.slow  # two lockstep runs of 30 s


@pytest.fixture(scope="module")
def rows():
    return particles_fleet.run(quick=True)


def by_variant(rows, variant):
    [row] = [r for r in rows if r["variant"] == variant]
    return row


def test_with_the_exchange_every_agent_resolves_both_cars(rows):
    row = by_variant(rows, "exchange")
    assert sorted(row["targets"]) == ["car_a", "car_b"]
    for target in row["targets"].values():
        assert len(target["agents"]) == 3 and None not in target["agents"].values(), target
        assert target["oracle_s"] is not None and target["fleet_s"] >= target["oracle_s"] > 0
    assert row["fusions"]["bayes"] > 0 and row["fusions"]["lop"] == 0  # a line: every link a tree edge


def test_the_exchange_is_what_makes_the_goal(rows):
    on, off = by_variant(rows, "exchange"), by_variant(rows, "alone")
    worst_on = max(t["ratio"] for t in on["targets"].values())
    worst_off = max(math.inf if t["ratio"] is None else t["ratio"] for t in off["targets"].values())
    assert worst_on <= particles_fleet.RATIO_GOAL < worst_off
    assert off["particle_bytes_per_s"] == 0 and off["fusions"] == {"bayes": 0, "lop": 0}


def test_particle_messages_stay_within_three_times_the_track_messages(rows):
    on = by_variant(rows, "exchange")
    assert 0 < on["particle_bytes_per_s"] <= particles_fleet.BYTES_GOAL * on["track_bytes_per_s"]
    goals = particles_fleet.goals(rows)
    assert goals["fleet_resolved"]["pass"] is True and goals["fleet_bytes"]["pass"] is True


def test_the_fleet_table_prints(rows):
    console = common.make_console()
    with console.capture() as capture:
        particles_fleet.report(rows, console)
    assert "ambiguous scenario" in capture.get() and "car_a" in capture.get()
    assert particles.particles_fleet is particles_fleet
