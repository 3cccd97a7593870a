"""Fire maps scored per window: a hand-built grid with a known alarm against a known fire and decoy, and the
grid oracle closing windows against the truth of their time."""

from __future__ import annotations

import numpy as np
import pytest

from agent.beliefs.grid_config import GridConfig
from agent.net import wire
from fusion.grid_geometry import GridGeometry
from mesh_sim.fire_windows import FireWindows
from mesh_sim.grid_oracle import GridOracle

GEOMETRY = GridGeometry(origin=(0.0, 0.0), shape=(10, 10), cell=10.0)
FIRE = {"centroid": (28.0, 35.0), "cells": 1, "area_m2": 100.0}  # the alarm below is 3 m from it
DECOY = [75.0, 75.0, 0.5]


def _map(*hot_cells) -> np.ndarray:
    probability = np.full(GEOMETRY.shape, 0.5)
    for cell in hot_cells:
        probability[cell] = 0.9
    return probability


def test_a_window_before_the_first_detection_is_reported_as_such():
    windows = FireWindows(GEOMETRY, threshold=0.8, length=10.0)
    assert not windows.due(9.8) and windows.due(10.0)
    first = windows.record(10.0, _map(), {"uav0": _map(), "uav1": _map()}, [FIRE], [DECOY])
    assert first["before_first_detection"] and (first["start"], first["end"]) == (0.0, 10.0)
    assert first["agents"]["uav0"]["detection_rate"] == 0.0 and first["agents"]["uav0"]["localisation_error_m"] is None
    assert first["agents"]["uav0"]["false_alarm_rejection"] == 1.0


def test_detection_decoy_and_localisation_come_out_per_window():
    windows = FireWindows(GEOMETRY, threshold=0.8, length=10.0)
    windows.record(10.0, _map(), {"uav0": _map()}, [FIRE], [DECOY])
    # cell (2, 3) is centred at (25, 35): 3 m from the fire; cell (7, 7) at (75, 75): on the decoy
    second = windows.record(20.0, _map((2, 3)), {"uav0": _map((2, 3), (7, 7))}, [FIRE], [DECOY])
    assert not second["before_first_detection"] and (second["start"], second["end"]) == (10.0, 20.0)
    agent = second["agents"]["uav0"]
    assert agent["detection_rate"] == 1.0 and agent["localisation_error_m"] == pytest.approx(3.0)
    assert agent["decoys_rejected"] == 0 and agent["false_alarm_rejection"] == 0.0
    assert agent["other_false_alarms"] == 0 and agent["threshold"] == 0.8
    assert second["central"]["false_alarm_rejection"] == 1.0 and second["central"]["detection_rate"] == 1.0
    # once an agent has detected, later windows are after the first detection even if the alarm is lost
    third = windows.score(25.0, _map(), {"uav0": _map((5, 5))}, [FIRE], [DECOY])
    assert not third["before_first_detection"] and third["agents"]["uav0"]["detection_rate"] == 0.0
    assert third["agents"]["uav0"]["other_false_alarms"] == 1
    assert windows.pending(25.0) and not windows.pending(20.0)
    assert [w["end"] for w in windows.series] == [10.0, 20.0]  # score() leaves the partial window open


def test_a_window_length_that_is_not_positive_is_an_error():
    with pytest.raises(ValueError, match=r"window length must be positive, got 0.0 s"):
        FireWindows(GEOMETRY, threshold=0.8, length=0.0)


def test_the_grid_oracle_scores_each_window_against_the_truth_of_its_time():
    asked = []

    def truth(t):
        asked.append(t)
        return [{**FIRE, "centroid": (28.0 + t / 10.0, 35.0)}], [DECOY]

    oracle = GridOracle(GridConfig(cell=10.0), (0.0, 100.0, 0.0, 100.0), None, truth)
    index = np.ravel_multi_index((2, 3), GEOMETRY.shape)
    evidence = {"index": [int(index)], "llr": [5.0]}
    oracle.add_evidence(wire.Envelope(kind="grid_evidence", origin="uav0", seq=1, stamp=0.0, payload=evidence))
    for k in range(0, 351):
        oracle.evaluate(k * 0.2)
    assert asked == pytest.approx([30.0, 60.0])  # the window ends, not every step
    summary = oracle.summary(*truth(70.0))
    ends = [(w["start"], w["end"]) for w in summary["windows"]]
    assert np.allclose(ends, [(0.0, 30.0), (30.0, 60.0), (60.0, 70.0)])  # the last one partial, at the run's end
    errors = [w["central"]["localisation_error_m"] for w in summary["windows"]]
    assert errors == pytest.approx([6.0, 9.0, 10.0])  # the true centroid moved; the alarm stayed at (25, 35)
    assert all(w["before_first_detection"] for w in summary["windows"])  # no agent map was broadcast


def test_alarms_where_the_agents_report_them_are_scored_per_window_and_bad_reports_change_nothing():
    """The hand-off (Merino Ch. 8): the positions in each agent's telemetry are scored like the grid's alarms."""
    oracle = GridOracle(GridConfig(cell=10.0), (0.0, 100.0, 0.0, 100.0), None, lambda t: ([FIRE], [DECOY]))
    oracle.add_located("uav0", [{"mean": np.array([28.5, 35.0]), "cov": np.eye(2), "track": 4}])
    oracle.add_located("uav1", [{"mean": [27.0, 34.0]}, {"mean": list(DECOY[:2])}])  # a decoy reported as a fire
    for bad in ([{"mean": [np.nan, 1.0]}],  # a NaN position
                [{"cov": np.eye(2)}],  # no position
                [{"mean": [1.0, 2.0, 3.0]}],  # three coordinates
                "alarms"):  # not a list of alarms
        oracle.add_located("uav0", bad)
    assert oracle.rejected == 4
    for k in range(0, 151):
        oracle.evaluate(k * 0.2)
    (window,) = oracle.windows.series
    assert window["located"]["uav0"]["localisation_error_m"] == pytest.approx(0.5)  # the good report stood
    assert window["located"]["uav0"]["decoys_rejected"] == 1
    assert window["located"]["uav1"]["localisation_error_m"] == pytest.approx(np.hypot(1.0, 1.0))
    assert window["located"]["uav1"]["decoys_rejected"] == 0
    assert oracle.summary([FIRE], [DECOY])["located"]["uav0"]["detected"] == 1
