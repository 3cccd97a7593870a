"""Terrain models and ray/terrain intersection (NED, z down; heights positive up)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.optimize
from hypothesis import given, settings
from hypothesis import strategies as st

from perception.terrain import FlatTerrain, HillsTerrain, intersect_ray, terrain_from_config, terrain_gradient

SETTINGS = settings(max_examples=60, deadline=None)


def clearance(terrain, points):
    """``f = -z - h(n, e)`` for points (..., 3)."""
    points = np.asarray(points, dtype=float)
    return -points[..., 2] - terrain.height(points[..., 0], points[..., 1])


def brute_first_crossing(terrain, origin, direction, length, spacing=0.01):
    """Smallest sampled λ (spacing metres apart) where the ray is at or below the surface."""
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    lam = np.arange(0.0, length, spacing)
    f = clearance(terrain, np.asarray(origin, float) + lam[:, None] * d)
    below = np.flatnonzero(f <= 0.0)
    return None if below.size == 0 else float(lam[below[0]])


class HeightOnly:
    """A terrain that exposes nothing but ``height``: a plane tilted up towards the north."""

    def __init__(self, slope, h0):
        self.slope, self.h0 = slope, h0

    def height(self, north, east):
        return self.h0 + self.slope * np.asarray(north, float) + 0.0 * np.asarray(east, float)


# ------------------------------------------------------------------------------------ height models


def test_flat_terrain_height_and_gradient_are_vectorised():
    t = FlatTerrain(height=12.5)
    assert t.height(3.0, -4.0) == 12.5 and isinstance(t.height(3.0, -4.0), float)
    grid = t.height(np.zeros((4, 5)), np.ones(5))
    assert grid.shape == (4, 5) and np.all(grid == 12.5)
    gn, ge = t.gradient(np.zeros(3), 0.0)
    assert np.all(gn == 0) and np.all(ge == 0)
    assert t == FlatTerrain(12.5) and t.level == 12.5 and FlatTerrain().level == 0.0
    with pytest.raises(AttributeError):
        t._level = 3.0


def test_hills_are_deterministic_bounded_and_smooth():
    t = HillsTerrain(amplitude=25.0, wavelength=250.0, seed=4, base=10.0)
    g = np.linspace(-800, 800, 321)
    N, E = np.meshgrid(g, g)
    H = t.height(N, E)
    assert H.shape == N.shape
    np.testing.assert_array_equal(H, HillsTerrain(25.0, 250.0, 4, 10.0).height(N, E))
    assert not np.allclose(H, HillsTerrain(25.0, 250.0, 5, 10.0).height(N, E))
    assert H.max() - H.min() > 10.0  # really hilly
    lo, hi = t.height_bounds
    assert lo <= H.min() and H.max() <= hi and hi - 10.0 <= 25.0 + 1e-9 and 10.0 - lo <= 25.0 + 1e-9
    # scalar calls agree with the vectorised call
    assert t.height(N[7, 9], E[7, 9]) == pytest.approx(H[7, 9], abs=1e-12)
    # the analytic gradient against central differences, and the slope bound
    gn, ge = t.gradient(N, E)
    step = 1e-4
    np.testing.assert_allclose(gn, (t.height(N + step, E) - t.height(N - step, E)) / (2 * step), atol=1e-6)
    np.testing.assert_allclose(ge, (t.height(N, E + step) - t.height(N, E - step)) / (2 * step), atol=1e-6)
    assert np.hypot(gn, ge).max() <= t.max_slope


def test_terrain_gradient_falls_back_to_finite_differences():
    gn, ge = terrain_gradient(HeightOnly(0.2, 5.0), np.array([1.0, 2.0]), np.array([0.0, 3.0]))
    np.testing.assert_allclose(gn, 0.2, atol=1e-9)
    np.testing.assert_allclose(ge, 0.0, atol=1e-9)


def test_terrain_from_config():
    assert terrain_from_config({"kind": "flat"}) == FlatTerrain(0.0)
    assert terrain_from_config({"kind": "flat", "height": 3}) == FlatTerrain(3.0)
    hills = terrain_from_config({"kind": "hills", "amplitude": 20, "wavelength": 300, "seed": 7})
    assert hills == HillsTerrain(20.0, 300.0, 7)


@pytest.mark.parametrize(
    "config, match",
    [
        ({"kind": "mountains"}, "kind"),
        ({"height": 3.0}, "kind"),
        ({"kind": "hills", "wavelength": 100}, "amplitude"),
        ({"kind": "hills", "amplitude": 10, "wavelength": -1}, "wavelength"),
        ({"kind": "hills", "amplitude": 10, "wavelength": 0}, "wavelength"),
        ({"kind": "hills", "amplitude": -10, "wavelength": 100}, "amplitude"),
        ({"kind": "hills", "amplitude": float("nan"), "wavelength": 100}, "amplitude"),
        ({"kind": "hills", "amplitude": 10, "wavelength": 100, "seed": 1.5}, "seed"),
        ({"kind": "hills", "amplitude": 10, "wavelength": 100, "seed": True}, "seed"),
        ({"kind": "hills", "amplitude": 10, "wavelength": 100, "roughness": 2}, "roughness"),
        ({"kind": "flat", "height": float("inf")}, "height"),
        ({"kind": "flat", "height": "10"}, "height"),
        ("flat", "table"),
    ],
)
def test_terrain_config_errors(config, match):
    with pytest.raises(ValueError, match=match):
        terrain_from_config(config)


# ------------------------------------------------------------------------------------ intersection


@SETTINGS
@given(
    h=st.floats(-50, 50),
    altitude=st.floats(1, 500),
    north=st.floats(-1000, 1000),
    east=st.floats(-1000, 1000),
    azimuth=st.floats(-math.pi, math.pi),
    depression=st.floats(0.05, math.pi / 2),
    scale=st.floats(0.1, 10),
)
def test_flat_hit_equals_closed_form(h, altitude, north, east, azimuth, depression, scale):
    terrain = FlatTerrain(h)
    origin = np.array([north, east, -(h + altitude)])  # z down: altitude above the plane
    unit = np.array(
        [math.cos(depression) * math.cos(azimuth), math.cos(depression) * math.sin(azimuth), math.sin(depression)]
    )
    lam = (-h - origin[2]) / unit[2]  # closed form, z down
    hit = intersect_ray(terrain, origin, scale * unit, max_range=1e6)
    assert hit is not None
    np.testing.assert_allclose(hit, origin + lam * unit, atol=1e-6 * max(1.0, lam))
    assert hit[2] == pytest.approx(-h, abs=1e-6)


def test_flat_nadir_ray_by_hand():
    hit = intersect_ray(FlatTerrain(10.0), [5.0, -3.0, -110.0], [0.0, 0.0, 1.0])
    np.testing.assert_allclose(hit, [5.0, -3.0, -10.0], atol=1e-9)
    hit = intersect_ray(FlatTerrain(0.0), [0.0, 0.0, -100.0], [1.0, 0.0, 1.0])  # 45 degrees down, north
    np.testing.assert_allclose(hit, [100.0, 0.0, 0.0], atol=1e-9)


UP_RAYS = [[0.0, 0.0, -1.0], [1.0, 0.5, -0.2], [-1.0, 0.0, -0.02]]  # z down: negative z climbs


@pytest.mark.parametrize("terrain", [FlatTerrain(0.0), HillsTerrain(30.0, 200.0, 1), HeightOnly(0.01, 0.0)])
@pytest.mark.parametrize("direction", [*UP_RAYS, [1.0, 0.0, 0.0]])
def test_upward_and_level_rays_from_above_every_summit_return_none(terrain, direction):
    if isinstance(terrain, HeightOnly) and direction[2] == 0.0:
        direction = [-1.0, 0.0, 0.0]  # level, away from the rising side of the plane
    assert intersect_ray(terrain, [0.0, 0.0, -200.0], direction, max_range=3000.0) is None


def test_beyond_max_range_returns_none():
    terrain = FlatTerrain(0.0)
    assert intersect_ray(terrain, [0, 0, -100.0], [1.0, 0.0, 0.01], max_range=5000.0) is None  # hit at ~10 km
    assert intersect_ray(terrain, [0, 0, -100.0], [1.0, 0.0, 0.01], max_range=20000.0) is not None
    assert intersect_ray(terrain, [0, 0, -100.0], [0, 0, 1.0], max_range=99.0) is None


def test_origin_below_or_on_the_surface():
    terrain = FlatTerrain(5.0)
    assert intersect_ray(terrain, [0, 0, -4.0], [0, 0, 1.0]) is None  # 1 m underground
    np.testing.assert_array_equal(intersect_ray(terrain, [1, 2, -5.0], [0, 0, 1.0]), [1, 2, -5.0])


def test_terrain_with_only_a_height_method_uses_fixed_steps():
    terrain = HeightOnly(0.1, 0.0)  # h = 0.1 n
    origin = np.array([0.0, 0.0, -50.0])
    hit = intersect_ray(terrain, origin, [1.0, 0.0, 0.0])  # level ray north: 50 = 0.1 n -> n = 500
    np.testing.assert_allclose(hit, [500.0, 0.0, -50.0], atol=1e-3)
    assert abs(clearance(terrain, hit)) < 1e-3


@pytest.mark.parametrize("seed", range(6))
def test_hills_hit_is_on_the_surface_and_first(seed):
    rng = np.random.default_rng(seed)
    terrain = HillsTerrain(amplitude=40.0, wavelength=200.0, seed=seed)
    for _ in range(5):
        origin = np.array([*rng.uniform(-300, 300, 2), -rng.uniform(60, 150)])
        az, dep = rng.uniform(-np.pi, np.pi), rng.uniform(0.05, 0.6)  # mostly shallow rays
        d = np.array([np.cos(dep) * np.cos(az), np.cos(dep) * np.sin(az), np.sin(dep)])
        hit = intersect_ray(terrain, origin, d, tol=1e-3)
        assert hit is not None
        assert abs(clearance(terrain, hit)) < 1e-3
        lam = float(np.linalg.norm(hit - origin))
        brute = brute_first_crossing(terrain, origin, d, lam + 1.0)
        assert brute is not None and abs(brute - lam) < 0.02


def test_hills_ray_grazing_a_summit_hits_its_near_side_first():
    terrain = HillsTerrain(amplitude=40.0, wavelength=200.0, seed=2)
    g = np.linspace(-400, 400, 201)
    N, E = np.meshgrid(g, g)
    H = terrain.height(N, E)
    k = np.unravel_index(np.argmax(H), H.shape)
    res = scipy.optimize.minimize(
        lambda x: -terrain.height(x[0], x[1]),
        [N[k], E[k]],
        jac=lambda x: -np.array(terrain.gradient(x[0], x[1])),
        method="BFGS",
    )
    summit_ne, summit_h = res.x, -res.fun
    # a shallow ray (2 degrees down, heading east-north-east) passing 5 cm below the summit
    dep, az = math.radians(2.0), math.radians(70.0)
    d = np.array([math.cos(dep) * math.cos(az), math.cos(dep) * math.sin(az), math.sin(dep)])
    through = np.array([*summit_ne, -(summit_h - 0.05)])
    origin = through - 612.5 * d  # so that 25 m steps from the origin straddle the summit
    assert clearance(terrain, origin) > 0
    # the ray dips under the summit only briefly, then flies on above lower ground before landing
    lam = np.arange(0.0, 3000.0, 0.01)
    f = clearance(terrain, origin + lam[:, None] * d)
    below = f <= 0
    entry = lam[np.argmax(below)]
    exit_ = lam[np.argmax(~below & (lam > entry))]
    assert 600.0 < entry < 612.5 < exit_ < 625.0 and np.any(below[lam > exit_])

    hit = intersect_ray(terrain, origin, d)
    assert hit is not None and abs(clearance(terrain, hit)) < 1e-3
    assert abs(np.linalg.norm(hit - origin) - entry) < 0.02
    assert np.hypot(*(hit[:2] - summit_ne)) < 10.0
    # a coarse fixed-step march (what a terrain without a slope bound gets) jumps over the nick
    coarse = intersect_ray(HeightOnlyWrapper(terrain), origin, d, step=25.0)
    assert coarse is not None and np.linalg.norm(coarse - origin) > exit_


class HeightOnlyWrapper:
    def __init__(self, terrain):
        self.terrain = terrain

    def height(self, north, east):
        return self.terrain.height(north, east)


@pytest.mark.parametrize(
    "origin, direction, kwargs",
    [
        ([0, 0], [0, 0, 1], {}),
        ([0, 0, -10], [0, 1], {}),
        ([0, 0, -10], [0, 0, 0], {}),
        ([0, 0, np.nan], [0, 0, 1], {}),
        ([0, 0, -10], [0, 0, 1], {"max_range": -1.0}),
        ([0, 0, -10], [0, 0, 1], {"tol": 0.0}),
    ],
)
def test_intersect_ray_rejects_bad_input(origin, direction, kwargs):
    with pytest.raises(ValueError):
        intersect_ray(FlatTerrain(), origin, direction, **kwargs)
