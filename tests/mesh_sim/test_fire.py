"""The true fire: config validation, the step rule against brute force and binomial statistics, wind
and slope, firebreaks, reproducibility, coverage of another grid, regions, and the wire round trip."""

from __future__ import annotations

import math

import msgpack
import numpy as np
import pytest

from agent.net import wire
from agent.net.fire_truth import BURNING, BURNT, UNBURNT, decode_fire
from mesh_sim.fire import NEIGHBOURS, FireConfig, FireWorld
from perception.terrain import FlatTerrain, HillsTerrain

AREA = (0.0, 100.0, 0.0, 100.0)  # 20 x 20 cells of 5 m


class Plane:
    """A tilted plane ``h = slope_n n + slope_e e`` (a terrain for the slope tests)."""

    def __init__(self, slope_n: float, slope_e: float):
        self.slope = (slope_n, slope_e)

    def height(self, north, east):
        return self.slope[0] * np.asarray(north, float) + self.slope[1] * np.asarray(east, float)


def config(**kw) -> FireConfig:
    return FireConfig.from_dict({"ignitions": [[50.0, 50.0]], **kw}, AREA)


def extent(state: np.ndarray, axis: int, centre: int) -> tuple[int, int]:
    """How far (in cells) the affected (burning or burnt) cells reach below and above ``centre`` along ``axis``."""
    idx = np.nonzero(state != UNBURNT)[axis]
    return centre - int(idx.min()), int(idx.max()) - centre


# ------------------------------------------------------------------------------------------ config


def test_config_defaults_geometry_and_area_override():
    c = config()
    assert (c.cell, c.rate, c.burn_time, c.wind, c.step, c.temperature_K) == (5.0, 0.02, 120.0, (0.0, 0.0), 1.0, 800.0)
    assert c.area == AREA and c.shape == (20, 20) and c.origin == (0.0, 0.0)
    assert c.cell_of(50.0, 50.0) == (10, 10) and c.cell_of(100.0, 0.0) == (19, 0)  # far edge: the last cell
    own = FireConfig.from_dict({"ignitions": [[10, 10]], "area": [0, 52, -10, 10], "cell": 10}, AREA)
    assert own.area == (0.0, 52.0, -10.0, 10.0) and own.shape == (6, 2)  # ceil(52 / 10) rows


@pytest.mark.parametrize(
    "table, match",
    [
        ({"ignitions": [[50, 50]], "spread": 1.0}, "unknown key"),  # unknown key
        ({"ignitions": [[50, 50]], "seed": 3}, "unknown key"),  # the seed comes from the caller
        ({"rate": 0.1}, "missing key 'ignitions'"),  # no ignitions
        ({"ignitions": []}, "at least one"),  # empty ignition list
        ({"ignitions": [[150, 50]]}, "outside the area"),  # ignition outside the area
        ({"ignitions": [[50, 50, 0]]}, "ignitions"),  # ignition of 3 numbers
        ({"ignitions": [[50, 50]], "rate": -0.1}, "rate must be >= 0"),  # negative rate
        ({"ignitions": [[50, 50]], "cell": 0}, "cell must be > 0"),  # zero cell
        ({"ignitions": [[50, 50]], "burn_time": -5}, "burn_time must be > 0"),  # negative burn time
        ({"ignitions": [[50, 50]], "step": math.nan}, "step must be finite"),  # NaN step
        ({"ignitions": [[50, 50]], "wind": [1.0]}, "wind"),  # wind of one number
        ({"ignitions": [[50, 50]], "wind": [math.inf, 0]}, "wind"),  # infinite wind
        ({"ignitions": [[50, 50]], "temperature_K": 0}, "temperature_K"),  # zero temperature
        ({"ignitions": [[50, 50]], "wind_gain": -1}, "wind_gain"),  # negative wind gain
        ({"ignitions": [[50, 50]], "firebreaks": [[10, 5, 0, 100]]}, "min < max"),  # inverted firebreak
        ({"ignitions": [[50, 50]], "firebreaks": [[200, 300, 0, 100]]}, "does not overlap"),  # firebreak outside
        ({"ignitions": [[50, 50]], "firebreaks": [[48, 52, 0, 100]]}, "lies in a cell of firebreaks"),
        ({"ignitions": [[50, 50]], "area": [0, 100, 100, 0]}, "min < max"),  # empty area
        ({"ignitions": [[50, 50]], "cell": 0.05}, "exceeds"),  # 2000 x 2000 cells
        ({"ignitions": [[50, 50]], "rate": True}, "number"),  # a bool, not a number
    ],
)
def test_config_errors_are_clear(table, match):
    with pytest.raises(ValueError, match=match):
        FireConfig.from_dict(table, AREA)


def test_config_table_must_be_a_table():
    with pytest.raises(ValueError, match="table"):
        FireConfig.from_dict([["ignitions"]], AREA)  # a list, not a table


def test_world_rejects_bad_seed_terrain_and_times():
    with pytest.raises(ValueError, match="seed"):
        FireWorld(config(), None, -1)  # negative seed
    with pytest.raises(ValueError, match="terrain"):
        FireWorld(config(), object(), 0)  # no height method
    world = FireWorld(config(), None, 0)
    for t in (-1.0, math.nan, 1e9):  # negative, NaN, beyond the horizon
        with pytest.raises(ValueError, match="time|outside"):
            world.state_at(t)
    with pytest.raises(ValueError, match="shape"):
        world.coverage((0.0, 0.0), 5.0, (0, 4), 0.0)  # zero rows
    with pytest.raises(ValueError, match="cell"):
        world.coverage((0.0, 0.0), -5.0, (4, 4), 0.0)  # negative cell
    with pytest.raises(ValueError, match="geometry_origin"):
        world.coverage((0.0, math.nan), 5.0, (4, 4), 0.0)  # NaN origin


# ----------------------------------------------------------------------------------------- the rule


def brute_ignition(world: FireWorld, state: np.ndarray) -> np.ndarray:
    """1 - Π_q (1 - p_q), p_q = 1 - exp(-dt rate w s), cell by cell and neighbour by neighbour."""
    c = world.config
    rows, cols = world.shape
    out = np.zeros(world.shape)
    for i in range(rows):
        for j in range(cols):
            if state[i, j] != UNBURNT or world.firebreak[i, j]:
                continue
            survive = 1.0
            for di, dj in NEIGHBOURS:
                qi, qj = i - di, j - dj  # source q; k = q + (di, dj)
                if not (0 <= qi < rows and 0 <= qj < cols) or state[qi, qj] != BURNING:
                    continue
                dist = c.cell * math.hypot(di, dj)
                u = np.array([di, dj]) / math.hypot(di, dj)
                w = math.exp(c.wind_gain * float(np.dot(c.wind, u)))
                s = math.exp(c.slope_gain * math.atan((world.heights[i, j] - world.heights[qi, qj]) / dist))
                survive *= 1.0 - (1.0 - math.exp(-c.step * c.rate * w * s))
            out[i, j] = 1.0 - survive
    return out


def test_ignition_probability_matches_brute_force_noisy_or():
    c = config(wind=[2.0, -3.0], rate=0.05, step=2.0, firebreaks=[[0, 100, 70, 75]])
    world = FireWorld(c, HillsTerrain(amplitude=8.0, wavelength=60.0, seed=4), 0)
    rng = np.random.default_rng(0)
    state = rng.choice(np.array([0, 1, 2], np.int8), size=world.shape, p=[0.6, 0.3, 0.1])
    np.testing.assert_allclose(world.ignition_probability(state), brute_ignition(world, state), rtol=1e-12, atol=0)


def test_one_step_ignitions_are_binomial():
    """Burning cells 3 apart: every neighbour has one burning neighbour, p = 1 - exp(-dt rate)."""
    points = [[2.5 + 15.0 * i, 2.5 + 15.0 * j] for i in range(1, 6) for j in range(1, 6)]
    c = FireConfig.from_dict({"ignitions": points, "rate": 0.1, "step": 1.0}, AREA)
    p = -math.expm1(-0.1)
    trials = 25 * 8
    states = [FireWorld(c, None, seed).state_at(1.0) for seed in range(20)]
    # new fires = burning now - the 25 sources + the sources that burnt out during the step
    ignited = np.array([np.sum(s == BURNING) - 25 + np.sum(s == BURNT) for s in states])
    mean, sd = trials * p, math.sqrt(trials * p * (1 - p) / 20)
    assert abs(ignited.mean() - mean) < 4 * sd


def test_burn_out_is_binomial_and_every_cell_ends_burnt():
    """No spread (rate 0), 400 burning cells: after k steps ~ Binomial(400, exp(-k dt / burn_time)) still burn."""
    points = [[2.5 + 5 * i, 2.5 + 5 * j] for i in range(20) for j in range(20)]
    world = FireWorld(FireConfig.from_dict({"ignitions": points, "rate": 0.0, "burn_time": 50.0}, AREA), None, 3)
    for t in (20.0, 50.0, 100.0):
        q = math.exp(-t / 50.0)
        burning = int(np.sum(world.state_at(t) == BURNING))
        assert abs(burning - 400 * q) < 4 * math.sqrt(400 * q * (1 - q))
    assert np.all(world.state_at(2000.0) == BURNT)


def test_cells_only_go_unburnt_to_burning_to_burnt():
    world = FireWorld(config(rate=0.05, burn_time=30.0), None, 7)
    previous = world.state_at(0.0)
    assert previous.sum() == BURNING  # the single ignition
    seen_burning = previous == BURNING
    for t in range(1, 300):
        state = world.state_at(float(t))
        assert np.all(state >= previous)
        seen_burning |= state == BURNING
        previous = state
    assert np.all(seen_burning[previous == BURNT])  # every burnt cell was burning at an earlier step
    assert np.sum(previous == BURNT) > 20


def test_firebreaks_never_burn_and_stop_the_fire():
    c = config(rate=0.5, burn_time=math.inf, firebreaks=[[0, 100, 70, 72]])  # column 14 of the 20
    world = FireWorld(c, None, 1)
    assert world.firebreak[:, 14].all() and world.firebreak.sum() == 20
    for t in (0.0, 50.0, 200.0, 600.0):
        state = world.state_at(t)
        assert np.all(state[world.firebreak] == UNBURNT)
        assert np.all(state[:, 15:] == UNBURNT)
    assert np.all(world.state_at(600.0)[:, :14] == BURNING)  # the near side burned out to the break


def test_wind_pushes_the_fire_downwind():
    """Wind from the west (blowing east): the fire reaches further east than west, on every seed."""
    c = FireConfig.from_dict({"ignitions": [[150, 150]], "wind": [0.0, 4.0], "burn_time": math.inf},
                             (0.0, 300.0, 0.0, 300.0))
    for seed in range(4):
        up, down = extent(FireWorld(c, None, seed).state_at(150.0), axis=1, centre=30)
        assert down > 1.5 * up
    calm = FireConfig.from_dict({"ignitions": [[150, 150]], "burn_time": math.inf}, (0.0, 300.0, 0.0, 300.0))
    ratios = [np.divide(*extent(FireWorld(calm, None, seed).state_at(150.0), 1, 30)[::-1]) for seed in range(4)]
    assert 0.6 < np.mean(ratios) < 1.6


def test_slope_pushes_the_fire_uphill():
    """Ground rising to the north (20 %): the fire reaches further north than south."""
    c = FireConfig.from_dict({"ignitions": [[150, 150]], "burn_time": math.inf}, (0.0, 300.0, 0.0, 300.0))
    for seed in range(4):
        down, up = extent(FireWorld(c, Plane(0.2, 0.0), seed).state_at(150.0), axis=0, centre=30)
        assert up > 1.5 * down


def test_reproducible_by_seed_and_independent_of_query_order():
    c = config(rate=0.05)
    a, b, other = FireWorld(c, None, 11), FireWorld(c, None, 11), FireWorld(c, None, 12)
    times = [0.0, 10.0, 75.5, 130.0, 300.0]
    forward = [a.state_at(t) for t in times]
    backward = [b.state_at(t) for t in reversed(times)][::-1]  # rewinds through the checkpoints
    for x, y in zip(forward, backward, strict=True):
        np.testing.assert_array_equal(x, y)
    np.testing.assert_array_equal(a.state_at(75.5), a.state_at(75.0))  # same step
    assert not np.array_equal(other.state_at(300.0), forward[-1])
    s = a.state_at(10.0)
    s[:] = BURNT  # a copy: the world is not changed
    np.testing.assert_array_equal(a.state_at(10.0), forward[1])


def test_a_fire_that_cannot_change_stops_stepping():
    c = config(burn_time=math.inf, firebreaks=[[40, 45, 40, 60], [55, 60, 40, 60], [45, 55, 40, 45],
                                               [45, 55, 55, 60]], rate=1.0)
    world = FireWorld(c, None, 0)
    final = world.state_at(500.0)
    assert np.sum(final == BURNING) == 4  # the 2 x 2 pocket inside the ring of firebreaks
    assert world.state_at(86_400.0).tolist() == final.tolist()


# -------------------------------------------------------------------------------- derived truth


def test_burning_cells_sit_on_the_terrain():
    hills = HillsTerrain(amplitude=10.0, wavelength=80.0, seed=1)
    world = FireWorld(config(rate=0.05), hills, 2)
    cells = world.burning_cells(60.0)
    assert cells.shape == (int(np.sum(world.state_at(60.0) == BURNING)), 3) and len(cells) > 1
    np.testing.assert_allclose(cells[:, 2], -hills.height(cells[:, 0], cells[:, 1]))
    np.testing.assert_allclose((cells[:, :2] - 2.5) % 5.0, 0.0, atol=1e-9)  # cell centres


def test_coverage_of_an_aligned_grid_is_the_block_mean():
    world = FireWorld(config(rate=0.05, burn_time=40.0), None, 5)
    state = world.state_at(200.0)
    burning, burnt = world.coverage((0.0, 0.0), 10.0, (10, 10), 200.0)  # 2 x 2 truth cells per cell
    blocks = lambda mask: mask.reshape(10, 2, 10, 2).mean(axis=(1, 3))  # noqa: E731
    np.testing.assert_allclose(burning, blocks(state == BURNING), atol=1e-12)
    np.testing.assert_allclose(burnt, blocks(state == BURNT), atol=1e-12)
    same, _ = world.coverage((0.0, 0.0), 5.0, (20, 20), 200.0)
    np.testing.assert_allclose(same, state == BURNING, atol=1e-12)


def test_coverage_of_a_misaligned_grid_matches_supersampling_and_conserves_area():
    world = FireWorld(config(rate=0.05, burn_time=40.0), None, 6)
    state = world.state_at(200.0)
    origin, cell, shape = (-7.3, -3.1), 7.7, (15, 15)  # covers the whole truth grid, and more
    burning, burnt = world.coverage(origin, cell, shape, 200.0)
    k = 40  # sample points per cell side
    offsets = (np.arange(k) + 0.5) / k * cell
    sampled = np.zeros(shape)
    for a in range(shape[0]):
        n = origin[0] + a * cell + offsets
        i = np.floor(n / 5.0).astype(int)
        for b in range(shape[1]):
            e = origin[1] + b * cell + offsets
            j = np.floor(e / 5.0).astype(int)
            ii, jj = np.meshgrid(i, j, indexing="ij")
            inside = (ii >= 0) & (ii < 20) & (jj >= 0) & (jj < 20)
            hit = np.zeros(ii.shape, bool)
            hit[inside] = state[ii[inside], jj[inside]] == BURNING
            sampled[a, b] = hit.mean()
    np.testing.assert_allclose(burning, sampled, atol=2.5 / k)
    assert np.sum(burning) * cell**2 == pytest.approx(np.sum(state == BURNING) * 25.0, rel=1e-12)
    assert np.sum(burnt) * cell**2 == pytest.approx(np.sum(state == BURNT) * 25.0, rel=1e-12)
    assert np.all((burning >= 0) & (burning + burnt <= 1 + 1e-12))


def test_fire_regions_are_8_connected_components():
    points = [[12.5, 12.5], [17.5, 17.5], [82.5, 82.5], [82.5, 87.5]]  # a diagonal pair, a side pair
    world = FireWorld(FireConfig.from_dict({"ignitions": points, "rate": 0.0, "burn_time": math.inf}, AREA), None, 0)
    regions = world.fire_regions(10.0)
    assert len(regions) == 2
    assert regions[0] == {"centroid": (15.0, 15.0), "cells": 2, "area_m2": 50.0}
    assert regions[1] == {"centroid": (82.5, 85.0), "cells": 2, "area_m2": 50.0}


def test_payload_round_trip_and_size():
    c = FireConfig.from_dict({"ignitions": [[250, 250], [100, 400]], "wind": [1.0, 2.0]}, (0.0, 500.0, 0.0, 500.0))
    world = FireWorld(c, HillsTerrain(amplitude=20.0, wavelength=200.0, seed=0), 3)
    assert world.shape == (100, 100)
    for t in (0.0, 200.0, 500.0, 900.0):
        env = wire.Envelope(kind="truth", origin="world", seq=1, stamp=t, payload={"fire": world.payload(t)})
        data = wire.encode(env)
        truth = decode_fire(wire.decode(data).payload["fire"], world.terrain)
        np.testing.assert_array_equal(truth.state, world.state_at(t))
        assert truth.origin == (0.0, 0.0) and truth.cell == 5.0 and truth.temperature_K == 800.0
        assert len(msgpack.packb(world.payload(t))) < 2000
        fires = truth.scene_fires()
        assert len(fires) == len(world.burning_cells(t))
        np.testing.assert_allclose([f.region for f in fires], world.burning_cells(t))
    assert np.sum(world.state_at(500.0) != UNBURNT) > 500  # a real fire, not an empty grid


def test_flat_terrain_default_gives_zero_heights():
    world = FireWorld(config(), None, 0)
    assert isinstance(world.terrain, FlatTerrain) and np.all(world.heights == 0.0)
    np.testing.assert_allclose(world.burning_cells(0.0), [[52.5, 52.5, 0.0]])


def test_flame_temperature_travels_in_the_payload():
    truth = decode_fire(FireWorld(config(temperature_K=950.0), None, 0).payload(0.0))
    assert truth.temperature_K == 950.0 and truth.scene_fires()[0].temperature_K == 950.0
