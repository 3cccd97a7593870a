"""Beta grids raise the alarms log-odds grids raise: the same thermal frames, read as Merino (4.29)-(4.31)
counts and as Alg. 4.2 log-likelihood ratios, give the same alarm cells (fusion.grid.BetaGrid's fire
probability ``P(X > x*)``), where the Beta mean (4.28) at the alarm threshold misses burning cells."""

from __future__ import annotations

import types

import numpy as np
import pytest

from agent.beliefs.grid_config import GridConfig
from agent.sensors.fire_camera import FireCamera
from fusion.grid import BetaGrid, detection_boundary
from mesh_sim.scenario import load
from perception.scene import Fire
from perception.terrain import FlatTerrain

AREA = (-40.0, 40.0, -40.0, 40.0)
OLD_FIRE, NEW_FIRE = (2.5, 2.5), (12.5, -7.5)  # a cell burning from the start; one that ignites later


def _frames(config: GridConfig, count: int, ignite_at: int, seed: int):
    """Real thermal frames (render, segment, cell evidence) from a UAV at 60 m drifting over the fires."""
    geometry = config.geometry(AREA, FlatTerrain())
    camera = FireCamera(config.camera, config.detection, config.pose_noise, seed)
    rng = np.random.default_rng(seed)
    for k in range(count):
        fires = [Fire(OLD_FIRE, 5.0, 800.0)] + ([Fire(NEW_FIRE, 5.0, 800.0)] if k >= ignite_at else [])
        north, east = rng.uniform(-10.0, 10.0, 2)
        state = types.SimpleNamespace(position=np.array([north, east, -60.0]), roll=0.0, pitch=0.0, yaw=0.0)
        mask, pose = camera.look(state, fires, [])
        yield camera.cell_evidence(mask, pose, geometry.centres_ned(), geometry.cell)


def _fire_config() -> GridConfig:
    """The fire scenario's ``[grid]``: its camera, detector and pose noise."""
    return load("fire").agent.grid


def _maps(config: GridConfig, count=60, ignite_at=15, seed=3):
    layers = {b: GridConfig(belief=b, detection=config.detection).layers(config.geometry(AREA, FlatTerrain()))
              for b in ("logodds", "beta")}
    log_odds, beta = layers["logodds"].uniform(), layers["beta"].uniform()
    for ev in _frames(config, count, ignite_at, seed):
        log_odds = log_odds.update_cells(ev.index, ev.llr)
        beta = beta.update_cells(ev.index, ev.m, ev.n)
    return config.geometry(AREA, FlatTerrain()), log_odds, beta


def test_a_burning_cell_is_seen_as_only_partly_fire_by_the_blurred_camera():
    """The premise of the fix: a lone burning cell's fire fraction per look is about the alarm threshold
    (0.80 measured), which a Beta mean ``(1 + 0.8 k) / (2 + k)`` only approaches from below."""
    config = _fire_config()
    cell = np.ravel_multi_index(config.geometry(AREA, FlatTerrain()).cell_of(*OLD_FIRE), (16, 16))
    fractions = [ev.p_fire[ev.index == cell] for ev in _frames(config, 20, 99, 1)]
    assert 0.7 < float(np.mean(fractions)) < 0.9


@pytest.mark.parametrize("seed", [3, 4])
def test_beta_and_log_odds_grids_alarm_the_same_cells_where_the_beta_mean_misses_some(seed):
    config = _fire_config()
    geometry, log_odds, beta = _maps(config, seed=seed)
    alarms_log_odds = log_odds.probability() > config.alarm_threshold
    alarms_beta = beta.probability() > config.alarm_threshold
    fires = {geometry.cell_of(*OLD_FIRE), geometry.cell_of(*NEW_FIRE)}
    assert set(zip(*np.nonzero(alarms_log_odds), strict=True)) == fires
    assert np.array_equal(alarms_beta, alarms_log_odds)
    assert not (beta.mean() > config.alarm_threshold)[geometry.cell_of(*NEW_FIRE)]  # the old reading missed it


def test_the_boundary_is_where_one_look_is_no_evidence_and_the_probability_is_the_posterior_tail():
    pd, pf = 0.9, 0.05
    x = detection_boundary(pd, pf)
    assert x * np.log(pd / pf) + (1 - x) * np.log((1 - pd) / (1 - pf)) == pytest.approx(0.0, abs=1e-12)
    grid = BetaGrid.uniform(GridConfig().geometry(AREA, FlatTerrain()), boundary=x)
    grid = grid.update(np.full(grid.geometry.shape, 6.0), np.full(grid.geometry.shape, 2.0))
    samples = np.random.default_rng(0).beta(7.0, 3.0, 200_000)  # Monte Carlo of Beta(1 + 6, 1 + 2)
    assert grid.probability()[0, 0] == pytest.approx(np.mean(samples > x), abs=3e-3)


@pytest.mark.parametrize("pd, pf, match", [(0.05, 0.9, "pd must exceed pf"), (1.0, 0.05, "pd"), (0.9, 0.0, "pf")])
def test_bad_detectors_are_clear_errors(pd, pf, match):
    with pytest.raises(ValueError, match=match):
        detection_boundary(pd, pf)
