"""Ray casting of many rays at once and the unscented geolocation built on it (Merino §3.6, Alg. 3.5).

Oracles: :func:`perception.projection.cast_ray` ray by ray, and the generic root search
:func:`perception.terrain.intersect_ray` on a terrain raised by each sigma point's DEM error, one point at a
time — the way :func:`perception.geolocation.geolocate` computed it before the rays were cast together."""

from __future__ import annotations

import numpy as np
import pytest

from fusion.measurement import azel_to_los
from fusion.unscented import sigma_points, unscented_transform
from perception.geolocation import geolocate
from perception.projection import cast_ray, cast_rays, cast_rays_on_raised
from perception.terrain import FlatTerrain, HillsTerrain, intersect_ray

TERRAINS = {"flat": FlatTerrain(2.0), "hills": HillsTerrain(8.0, 200.0, seed=3)}


class _Raised:
    """``terrain`` raised by ``dh``: the per-sigma-point terrain of the reference geolocation."""

    def __init__(self, terrain, dh):
        self.terrain, self.dh = terrain, dh
        self.max_slope = terrain.max_slope  # the hints that let the root search take long safe steps
        self.height_bounds = tuple(h + dh for h in terrain.height_bounds)

    def height(self, north, east):
        return self.terrain.height(north, east) + self.dh


def _reference_geolocation(sensor, azel, R, terrain, sensor_sigma=0.5, terrain_sigma=2.0, max_range=2000.0):
    mean = np.concatenate([azel, np.zeros(4)])
    cov = np.zeros((6, 6))
    cov[:2, :2], cov[2, 2], cov[3:, 3:] = R, terrain_sigma**2, sensor_sigma**2 * np.eye(3)
    hits = []
    for p in sigma_points(mean, cov)[0]:
        hit = intersect_ray(_Raised(terrain, p[2]), sensor + p[3:], azel_to_los(p[:2]), max_range=max_range,
                            tol=1e-9)
        if hit is None:
            return None
        hits.append(hit)
    return unscented_transform(lambda p: hits.pop(0), mean, cov)


def _rays(rng, k):
    origins = np.column_stack([rng.uniform(-100, 100, k), rng.uniform(-100, 100, k), -rng.uniform(-5, 120, k)])
    directions = rng.normal(size=(k, 3)) * [1.0, 1.0, 2.0] + [0.0, 0.0, 0.5]
    return origins, directions


@pytest.mark.parametrize("name", sorted(TERRAINS))
def test_cast_rays_equals_cast_ray_ray_by_ray(name):
    terrain = TERRAINS[name]
    origins, directions = _rays(np.random.default_rng(1), 300)
    hits = cast_rays(terrain, origins, directions, max_range=400.0)
    missed = 0
    for o, d, hit in zip(origins, directions, hits, strict=True):
        one = cast_ray(terrain, o, d, max_range=400.0)
        if one is None:
            missed += 1
            assert np.all(np.isnan(hit))
        else:
            assert np.allclose(hit, one, rtol=0, atol=1e-9)
    assert 30 < missed < 270  # both kinds of ray are in the sample


def test_cast_rays_on_a_plane_by_hand():
    """Every case of the closed form on the plane at height 2 (z = -2): a hit, a ray starting on the plane, one
    starting below it, one pointing level, one pointing up, and one whose hit lies beyond the range."""
    o = np.array([[0, 0, -12.0], [5, 5, -2.0], [0, 0, 1.0], [0, 0, -12.0], [0, 0, -12.0], [0, 0, -12.0]])
    d = np.array([[3, 0, 4.0], [0, 0, -1.0], [0, 0, 1.0], [1, 0, 0.0], [0, 0, -1.0], [1, 0, 1e-3]])
    hits = cast_rays(FlatTerrain(2.0), o, d, max_range=1000.0)
    assert np.allclose(hits[0], [7.5, 0.0, -2.0]) and np.array_equal(hits[1], [5.0, 5.0, -2.0])
    assert np.all(np.isnan(hits[2:]))


@pytest.mark.parametrize(
    "origins, directions, match",
    [
        (np.zeros(3), np.ones(3), "shape \\(k, 3\\)"),  # one ray, not a batch
        (np.zeros((2, 3)), np.ones((3, 3)), "shape \\(k, 3\\)"),  # as many directions as origins
        (np.zeros((2, 2)), np.ones((2, 2)), "shape \\(k, 3\\)"),  # 2-D points
        (np.array([[0, 0, np.nan]]), np.ones((1, 3)), "finite"),  # a NaN origin
        (np.zeros((1, 3)), np.array([[0, np.inf, 1.0]]), "finite"),  # an infinite direction
        (np.zeros((2, 3)), np.array([[0, 0, 1.0], [0, 0, 0.0]]), "non-zero"),  # no direction at all
    ],
)
def test_cast_rays_refuses_bad_rays(origins, directions, match):
    with pytest.raises(ValueError, match=match):
        cast_rays(FlatTerrain(0.0), origins, directions)


@pytest.mark.parametrize("name", sorted(TERRAINS))
def test_geolocate_equals_casting_each_sigma_point_on_a_raised_terrain(name):
    terrain = TERRAINS[name]
    rng = np.random.default_rng(2)
    located = 0
    for _ in range(60):
        sensor = np.array([rng.uniform(-100, 100), rng.uniform(-100, 100), -rng.uniform(-5, 120)])
        azel = np.array([rng.uniform(-3, 3), rng.uniform(-1.6, 0.3)])
        R = np.diag(rng.uniform(1e-5, 1e-2, 2))
        got, want = geolocate(sensor, azel, R, terrain), _reference_geolocation(sensor, azel, R, terrain)
        assert (got is None) == (want is None)
        if got is not None:
            located += 1
            assert np.allclose(got[0], want[0], rtol=0, atol=1e-6)
            assert np.allclose(got[1], want[1], rtol=1e-6, atol=1e-8)
    assert 10 < located < 55  # hits and misses (a sigma point above the horizon, a camera below the ground)


def test_a_vectorized_transform_equals_the_point_by_point_one():
    mean, cov = np.array([1.0, -0.5]), np.array([[0.3, 0.1], [0.1, 0.2]])

    def polar(p):
        return np.array([p[0] * np.cos(p[1]), p[0] * np.sin(p[1]), p[0] ** 2])

    def polar_rows(P):
        return np.column_stack([P[:, 0] * np.cos(P[:, 1]), P[:, 0] * np.sin(P[:, 1]), P[:, 0] ** 2])

    one, many = unscented_transform(polar, mean, cov), unscented_transform(polar_rows, mean, cov, vectorized=True)
    assert np.allclose(one[0], many[0], rtol=0, atol=1e-14) and np.allclose(one[1], many[1], rtol=0, atol=1e-14)


def test_casting_on_a_raised_terrain_equals_casting_on_the_higher_plane():
    """Oracle: a flat terrain at height h + dh is the flat terrain at h raised by dh, ray by ray."""
    origins, directions = _rays(np.random.default_rng(4), 50)
    raised = np.random.default_rng(5).normal(0.0, 3.0, 50)
    hits = cast_rays_on_raised(FlatTerrain(2.0), origins, directions, raised, max_range=400.0)
    for o, d, dh, hit in zip(origins, directions, raised, hits, strict=True):
        want = cast_rays(FlatTerrain(2.0 + dh), o[None], d[None], max_range=400.0)[0]
        np.testing.assert_allclose(hit, want, rtol=0, atol=1e-9)
    assert 5 < np.isnan(hits[:, 0]).sum() < 45
