"""The alarm hand-off (Merino Ch. 8, (8.1)): a grid alarm is reported where the tracker locates it."""

from __future__ import annotations

import itertools

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.beliefs.alarm_handoff import SEPARATE_CELLS, located_alarms
from agent.sensors.hot_spots import GATE, gate_distance
from fusion.gaussian import Gaussian
from fusion.grid_alarms import Alarm

CELL = 5.0


def _alarm(north, east) -> Alarm:
    return Alarm(np.array([north, east]), 4.0 * np.eye(2), 0.93, 2, 0.99)


def _track(north, east, std) -> Gaussian:
    """A 6-state track (position, velocity) at ``(north, east, 0)`` with horizontal standard deviation ``std``."""
    return Gaussian.from_moments(np.array([north, east, 0.0, 0.0, 0.0, 0.0]),
                                 np.diag([std**2, std**2, 1.0, 0.01, 0.01, 0.01]))


def test_an_alarm_takes_the_position_of_the_most_certain_track_in_its_gate():
    alarm = _alarm(10.0, 20.0)
    tracks = [(3, _track(11.0, 20.5, 2.0)),  # in the gate, but a stale duplicate
              (7, _track(10.4, 19.6, 0.3)),  # in the gate and recently measured
              (9, _track(60.0, 20.0, 0.1))]  # another fire
    (where,) = located_alarms([alarm], tracks, CELL)
    assert where["track"] == 7
    np.testing.assert_allclose(where["mean"], (10.4, 19.6))
    np.testing.assert_allclose(where["cov"], 0.09 * np.eye(2))
    assert where["probability"] == alarm.probability  # the class stays the grid's (Merino (8.1))


def test_an_alarm_no_track_reaches_keeps_the_grids_position():
    alarms = [_alarm(10.0, 20.0), _alarm(-40.0, 0.0), _alarm(80.0, 80.0)]
    tracks = [(1, _track(10.2, 20.1, 0.4)),  # locates the first
              (2, _track(-40.5, 0.5, 2.0))]  # the second, though it has grown uncertain
    located = located_alarms(alarms, tracks, CELL)
    assert [w["track"] for w in located] == [1, 2, None]
    np.testing.assert_allclose(located[2]["mean"], (80.0, 80.0))
    np.testing.assert_allclose(located[2]["cov"], alarms[2].cov)


def test_a_track_just_outside_the_gate_does_not_locate_the_alarm():
    alarm = _alarm(0.0, 0.0)
    # d^2 = r^2 / (4 + cell^2) = 9 on the gate's edge
    edge = 3.0 * np.sqrt(4.0 + CELL**2)
    assert located_alarms([alarm], [(1, _track(0.99 * edge, 0.0, 0.2))], CELL)[0]["track"] == 1
    assert located_alarms([alarm], [(1, _track(1.01 * edge, 0.0, 0.2))], CELL)[0]["track"] is None


def test_a_small_fires_track_inside_a_large_neighbours_gate_locates_only_its_own_alarm():
    """Two fires 18 m apart: the large one's alarm (4.20) is wide enough to hold the small one's track in its
    gate, but the track is deeper in its own alarm's gate; the large fire, with no track, keeps its grid mean."""
    large = Alarm(np.array([58.5, -72.3]), np.diag([60.0, 40.0]), 0.95, 21, 0.999)
    small = _alarm(72.5, -67.5)
    tracks = [(5, _track(75.0, -64.8, 0.35))]
    located = located_alarms([large, small], tracks, CELL)
    assert [w["track"] for w in located] == [None, 5]
    np.testing.assert_allclose(located[0]["mean"], large.mean)


def test_an_alarm_over_two_fires_is_located_at_both_and_a_duplicate_is_not():
    """Beta grids, seed 3 of the fire bench: one grid region held a 25-cell fire and a spot fire 18 m from its
    centre, and the alarm was reported at the spot's track alone (18 m from the large fire). Tracks of one alarm
    farther apart than SEPARATE_CELLS cells are separate fires; a grown duplicate near a track is not."""
    merged = Alarm(np.array([62.0, -70.0]), np.diag([90.0, 60.0]), 0.95, 27, 0.999)
    tracks = [(5, _track(75.0, -64.8, 0.35)),  # the spot fire
              (8, _track(57.6, -70.1, 0.4)),  # the large fire's centre
              (2, _track(58.4, -71.0, 1.5))]  # a stale duplicate of the large fire's track
    located = located_alarms([merged], tracks, CELL)
    assert [(w["track"], w["alarm"]) for w in located] == [(5, 0), (8, 0)]
    assert np.hypot(*(located[0]["mean"] - located[1]["mean"])) > SEPARATE_CELLS * CELL


@settings(max_examples=60, deadline=None, derandomize=True)
@given(st.lists(st.tuples(st.floats(-50, 50), st.floats(-50, 50), st.floats(0.5, 30.0)), min_size=1, max_size=5),
       st.lists(st.tuples(st.floats(-60, 60), st.floats(-60, 60), st.floats(0.05, 3.0)), max_size=6))
def test_every_track_locates_at_most_one_alarm_and_only_one_whose_gate_holds_it(alarm_specs, track_specs):
    alarms = [Alarm(np.array([n, e]), var * np.eye(2), 0.9, 1, 0.95) for n, e, var in alarm_specs]
    tracks = [(k, _track(n, e, std)) for k, (n, e, std) in enumerate(track_specs)]
    located = located_alarms(alarms, tracks, CELL)
    assert sorted({w["alarm"] for w in located}) == list(range(len(alarms)))  # every alarm is reported
    used = [w["track"] for w in located if w["track"] is not None]
    assert len(used) == len(set(used))
    for k, alarm in enumerate(alarms):
        entries = [w for w in located if w["alarm"] == k]
        if any(w["track"] is None for w in entries):  # no track: once, at the grid's mean
            assert len(entries) == 1
            np.testing.assert_array_equal(entries[0]["mean"], alarm.mean)
            continue
        for a, b in itertools.combinations(entries, 2):  # an alarm's tracks are separate fires
            assert np.hypot(*(a["mean"] - b["mean"])) > SEPARATE_CELLS * CELL
        for where in entries:  # each at its track, in this alarm's gate and deepest in it
            position = tracks[where["track"]][1].mean[:2]
            np.testing.assert_array_equal(where["mean"], position)
            assert gate_distance(position, alarm, CELL) <= GATE
            assert all(gate_distance(position, alarm, CELL) <= gate_distance(position, other, CELL)
                       for other in alarms)
