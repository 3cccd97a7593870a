"""Alarms from grids (Merino §4.2.2, (4.20)) and Merino's rumor example (§4.1.3).

The weighted moments are recomputed here with explicit loops over the region's cells."""

from __future__ import annotations

import numpy as np
import pytest

from fusion.gaussian import Gaussian
from fusion.grid import LogOddsGrid
from fusion.grid_alarms import Alarm, extract_alarms
from fusion.grid_geometry import GridGeometry, GridGeometryError
from fusion.grid_intersect import chernoff_intersect, half_intersect, max_intersect

GEOM = GridGeometry((0.0, 0.0), 10.0, (5, 6))


def _background(value: float = 0.1) -> np.ndarray:
    return np.full(GEOM.shape, value)


def _hand_moments(cells: dict[tuple[int, int], float], cell: float = 10.0) -> tuple[np.ndarray, np.ndarray]:
    """(4.20) with loops, centres ``(index + 1/2) * cell`` from the origin (0, 0), plus cell^2/12."""
    total = sum(cells.values())
    mean = sum(p * np.array([(r + 0.5) * cell, (c + 0.5) * cell]) for (r, c), p in cells.items()) / total
    cov = np.zeros((2, 2))
    for (r, c), p in cells.items():
        d = np.array([(r + 0.5) * cell, (c + 0.5) * cell]) - mean
        cov += p * np.outer(d, d)
    return mean, cov / total + cell**2 / 12.0 * np.eye(2)


def test_single_blob_has_the_weighted_moments_of_4_20():
    blob = {(1, 1): 0.9, (1, 2): 0.85, (2, 1): 0.95}
    p = _background()
    for k, v in blob.items():
        p[k] = v
    (alarm,) = extract_alarms(p, GEOM)
    mean, cov = _hand_moments(blob)
    np.testing.assert_allclose(alarm.mean, [50.0 / 2.7, 49.0 / 2.7], rtol=1e-12)  # by hand
    np.testing.assert_allclose(alarm.mean, mean, rtol=1e-12)
    np.testing.assert_allclose(alarm.cov, cov, rtol=1e-12)
    assert alarm.cells == 3 and alarm.peak == 0.95 and alarm.probability == pytest.approx(0.9)


def test_one_cell_region_has_the_within_cell_variance():
    p = _background()
    p[4, 5] = 0.99
    (alarm,) = extract_alarms(p, GEOM)
    np.testing.assert_array_equal(alarm.mean, [45.0, 55.0])
    np.testing.assert_allclose(alarm.cov, 100.0 / 12.0 * np.eye(2))


def test_two_separated_blobs_give_two_alarms_sorted_by_probability():
    p = _background()
    p[0, 0], p[0, 1] = 0.85, 0.9
    p[3, 4], p[4, 4], p[4, 5] = 0.99, 0.95, 0.97
    alarms = extract_alarms(p, GEOM)
    assert [a.cells for a in alarms] == [3, 2]
    assert alarms[0].probability == pytest.approx(0.97) and alarms[1].probability == pytest.approx(0.875)
    np.testing.assert_allclose(alarms[1].mean, _hand_moments({(0, 0): 0.85, (0, 1): 0.9})[0])
    np.testing.assert_allclose(alarms[0].cov, _hand_moments({(3, 4): 0.99, (4, 4): 0.95, (4, 5): 0.97})[1])


def test_diagonal_pair_is_one_region_with_8_connectivity_and_two_with_4():
    p = _background()
    p[1, 1], p[2, 2] = 0.9, 0.9
    assert [a.cells for a in extract_alarms(p, GEOM, connectivity=8)] == [2]
    assert [a.cells for a in extract_alarms(p, GEOM, connectivity=4)] == [1, 1]


def test_threshold_is_strict_and_min_cells_drops_small_regions():
    p = _background()
    p[0, 0] = 0.8
    assert extract_alarms(p, GEOM, threshold=0.8) == []
    p[2, 2], p[2, 3] = 0.9, 0.9
    p[4, 0] = 0.95
    assert [a.cells for a in extract_alarms(p, GEOM, min_cells=2)] == [2]
    assert len(extract_alarms(p, GEOM, threshold=0.5)) == 3


def test_alarm_from_a_log_odds_grid():
    grid = LogOddsGrid.uniform(GridGeometry((-100.0, 200.0), 5.0, (8, 8)))
    llr = np.zeros((8, 8))
    llr[3:5, 5:7] = 3.0
    (alarm,) = extract_alarms(grid.update(llr).probability(), grid.geometry)
    np.testing.assert_allclose(alarm.mean, [-100 + 20.0, 200 + 30.0])  # the centre of the 2x2 block
    assert alarm.probability == pytest.approx(1 / (1 + np.exp(-3.0)))


def test_to_gaussian_has_the_alarm_moments_in_2d_and_3d():
    p = _background()
    p[1, 1], p[1, 2], p[2, 2] = 0.9, 0.82, 0.97
    (alarm,) = extract_alarms(p, GEOM)
    g2 = alarm.to_gaussian()
    assert isinstance(g2, Gaussian) and g2.dim == 2
    np.testing.assert_allclose(g2.mean, alarm.mean, rtol=1e-12)
    np.testing.assert_allclose(g2.cov, alarm.cov, rtol=1e-12)
    g3 = alarm.to_gaussian(height=-3.0, vertical_variance=0.25)
    np.testing.assert_allclose(g3.mean, [*alarm.mean, -3.0], rtol=1e-12)
    expected = np.zeros((3, 3))
    expected[:2, :2], expected[2, 2] = alarm.cov, 0.25
    np.testing.assert_allclose(g3.cov, expected, rtol=1e-12, atol=1e-12)


def test_merino_rumor_example_double_counting_raises_a_false_alarm_intersection_does_not():
    """Merino §4.1.3: l = 0.847 (p ~ 0.7) counted twice is l = 1.694 (p ~ 0.845), above the alarm
    threshold 0.8; intersecting the two copies of the same information keeps p ~ 0.7."""
    one = LogOddsGrid.uniform(GEOM).update_cells(np.array([13]), np.array([0.847]))
    assert one.probability().ravel()[13] == pytest.approx(0.7, abs=1e-3)
    assert extract_alarms(one.probability(), GEOM, threshold=0.8) == []
    twice = one.fuse(one)
    assert twice.probability().ravel()[13] == pytest.approx(0.845, abs=1e-3)
    (alarm,) = extract_alarms(twice.probability(), GEOM, threshold=0.8)
    np.testing.assert_array_equal(alarm.mean, GEOM.centres().reshape(-1, 2)[13])
    for rule in (chernoff_intersect, half_intersect, max_intersect):
        kept = rule(one, one)
        assert kept.probability().ravel()[13] == pytest.approx(0.7, abs=1e-3)
        assert extract_alarms(kept.probability(), GEOM, threshold=0.8) == []


# -- bad input -------------------------------------------------------------------------------------------
@pytest.mark.parametrize("kwargs,error,match", [
    ({"probability": np.full((6, 5), 0.5)}, ValueError, "must have the grid's shape \\(5, 6\\)"),
    ({"probability": np.full((5, 6), np.nan)}, ValueError, "non-finite"),
    ({"probability": np.full((5, 6), 1.2)}, ValueError, "must lie in \\[0, 1\\]"),
    ({"probability": np.full((5, 6), -0.1)}, ValueError, "must lie in \\[0, 1\\]"),
    ({"threshold": 0.0}, ValueError, "threshold must lie in \\(0, 1\\)"),
    ({"threshold": 1.0}, ValueError, "threshold must lie in \\(0, 1\\)"),
    ({"threshold": float("nan")}, ValueError, "threshold must lie in \\(0, 1\\)"),
    ({"connectivity": 6}, ValueError, "connectivity must be 4 or 8"),
    ({"connectivity": True}, ValueError, "connectivity must be 4 or 8"),
    ({"min_cells": 0}, ValueError, "min_cells must be a positive integer"),
    ({"min_cells": 1.5}, ValueError, "min_cells must be a positive integer"),
    ({"geometry": (5, 6)}, GridGeometryError, "geometry must be a GridGeometry"),
], ids=["transposed-probability", "nan-probability", "probability-above-1", "negative-probability",
        "threshold-zero", "threshold-one", "threshold-nan", "connectivity-6", "connectivity-bool", "min-cells-zero",
        "min-cells-float", "geometry-tuple"])
def test_extract_alarms_rejects(kwargs, error, match):
    args = {"probability": _background(), "geometry": GEOM} | kwargs
    with pytest.raises(error, match=match):
        extract_alarms(**args)


@pytest.mark.parametrize("kwargs,match", [
    ({"mean": [1.0, np.nan]}, "mean must be a finite"),
    ({"mean": [1.0, 2.0, 3.0]}, "mean must be a finite"),
    ({"cov": [[1.0, 0.5], [0.0, 1.0]]}, "symmetric 2x2"),
    ({"cov": np.zeros((2, 2))}, "positive definite"),
    ({"probability": 1.5}, "probability must be a probability"),
    ({"peak": -0.1}, "peak must be a probability"),
    ({"cells": 0}, "cells must be a positive integer"),
], ids=["nan-mean", "3d-mean", "asymmetric-cov", "zero-cov", "probability-above-1", "negative-peak", "no-cells"])
def test_alarm_rejects(kwargs, match):
    args = {"mean": [1.0, 2.0], "cov": np.eye(2), "probability": 0.9, "cells": 1, "peak": 0.9} | kwargs
    with pytest.raises(ValueError, match=match):
        Alarm(**args)


@pytest.mark.parametrize("kwargs,match", [
    ({"height": float("nan")}, "height must be a finite number"),
    ({"height": 0.0, "vertical_variance": 0.0}, "vertical variance must be positive"),
    ({"height": 0.0, "vertical_variance": float("inf")}, "vertical variance must be positive"),
], ids=["nan-height", "zero-vertical-variance", "inf-vertical-variance"])
def test_to_gaussian_rejects(kwargs, match):
    alarm = Alarm([1.0, 2.0], np.eye(2), 0.9, 1, 0.9)
    with pytest.raises(ValueError, match=match):
        alarm.to_gaussian(**kwargs)
