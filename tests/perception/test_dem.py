"""ArcInfo ASCII grids, GridTerrain heights and the exact / Ross Eq. 1 ray intersections."""

from __future__ import annotations

import math

import numpy as np
import pytest

from perception.dem import GridTerrain, format_ascii_grid, parse_ascii_grid, read_ascii_grid
from perception.raycast import moller_trumbore, ross_eq1, ross_intersect
from perception.terrain import HillsTerrain, intersect_ray

# 3 rows x 4 columns; the first row is the NORTHERNMOST. Values increase to the east along a row.
SMALL = """ncols 4
nrows 3
xllcorner 1000.0
yllcorner 2000.0
cellsize 10
NODATA_value -9999
1 2 3 4
5 6 7 8
9 10 11 12
"""


def small(**kw):
    return parse_ascii_grid(SMALL, origin_easting=1000.0, origin_northing=2000.0, **kw)


# ------------------------------------------------------------------------------------- the loader


def test_ascii_grid_axes_map_to_ned_by_hand():
    g = small()
    # xllcorner: the SW node is half a cell in from the corner, at easting 1005, northing 2005.
    assert (g.north0, g.east0, g.cellsize) == (5.0, 5.0, 10.0)
    assert g.extent == (5.0, 25.0, 5.0, 35.0)
    assert g.height(5.0, 5.0) == 9.0  # SW node: last file row, first column
    assert g.height(25.0, 5.0) == 1.0  # NW node: first file row
    assert g.height(5.0, 35.0) == 12.0  # SE node
    assert g.height(15.0, 35.0) == 8.0
    assert g.height(10.0, 10.0) == pytest.approx((5 + 6 + 9 + 10) / 4)  # cell centre, bilinear
    assert g.height(5.0, 10.0) == pytest.approx(9.5)  # heights grow to the EAST (NED y)
    assert g.height(20.0, 5.0) == pytest.approx(3.0)  # and to the SOUTH (file rows go down)
    assert math.isnan(g.height(4.0, 10.0)) and math.isnan(g.height(10.0, 36.0))
    assert g.height_bounds == (1.0, 12.0)


def test_xllcenter_origin_height_and_case_insensitive_keys():
    text = SMALL.replace("xllcorner 1000.0", "XLLCENTER 1000.0").replace("yllcorner", "YllCenter")
    g = parse_ascii_grid(text, origin_easting=990.0, origin_northing=2000.0, origin_height=1.0)
    assert (g.north0, g.east0) == (0.0, 10.0)
    assert g.height(0.0, 10.0) == 8.0  # 9 - origin_height


def test_file_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    g = GridTerrain(rng.uniform(100, 200, (5, 7)), 30.0, north0=-60.0, east0=15.0, interpolation="triangles")
    path = tmp_path / "dem.asc"
    path.write_text(format_ascii_grid(g, origin_easting=500000.0, origin_northing=4e6, origin_height=50.0))
    back = read_ascii_grid(
        path, origin_easting=500000.0, origin_northing=4e6, origin_height=50.0, interpolation="triangles"
    )
    assert np.allclose(back.heights, g.heights) and back.extent == pytest.approx(g.extent)
    n, e = rng.uniform(-60, 60, 20), rng.uniform(15, 195, 20)
    assert np.allclose(back.height(n, e), g.height(n, e))


def test_nodata_modes():
    text = SMALL.replace("5 6 7 8", "5 -9999 7 8")
    with pytest.raises(ValueError, match=r"1 NODATA value\(s\), first at data row 2, column 2"):
        parse_ascii_grid(text)
    holes = parse_ascii_grid(text, nodata="hole", origin_easting=1000.0, origin_northing=2000.0)
    assert math.isnan(holes.heights[1, 1]) and holes.height_bounds == (1.0, 12.0)
    assert math.isnan(holes.height(12.0, 12.0))  # a cell touching the hole
    assert holes.height(5.0, 35.0) == 12.0  # a cell away from it
    filled = parse_ascii_grid(text, nodata=0.0)
    assert filled.heights[1, 1] == 0.0
    with pytest.raises(ValueError, match="nodata must be"):
        parse_ascii_grid(text, nodata="zero")
    with pytest.raises(ValueError, match="every value is NODATA"):
        parse_ascii_grid(
            "ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\nNODATA_value -1\n-1 -1\n-1 -1\n", nodata="hole"
        )


@pytest.mark.parametrize(
    "edit, match",
    [
        (lambda s: s.replace("ncols 4\n", ""), "missing header key 'ncols'"),
        (lambda s: s.replace("cellsize 10\n", ""), "missing header key 'cellsize'"),
        (lambda s: s.replace("xllcorner 1000.0\n", ""), "exactly one of 'xllcorner' and 'xllcenter'"),
        (lambda s: s.replace("yllcorner 2000.0", "yllcorner 2000.0\nyllcenter 2005"), "exactly one of 'yllcorner'"),
        (lambda s: s.replace("cellsize 10", "dx 10"), "unknown header key 'dx'"),
        (lambda s: s.replace("nrows 3", "nrows 3\nnrows 3"), "duplicate header key"),
        (lambda s: s.replace("ncols 4", "ncols 4 5"), "'key value'"),
        (lambda s: s.replace("ncols 4", "ncols 3.5"), "ncols must be an integer"),
        (lambda s: s.replace("nrows 3", "nrows 1"), "nrows must be >= 2"),
        (lambda s: s.replace("cellsize 10", "cellsize 0"), "cellsize must be > 0"),
        (lambda s: s.replace("cellsize 10", "cellsize -5"), "cellsize must be > 0"),
        (lambda s: s.replace("9 10 11 12\n", ""), "expected 3 data rows"),
        (lambda s: s + "13 14 15 16\n", "expected 3 data rows"),
        (lambda s: s.replace("5 6 7 8", "5 6 7"), "data row 2 has 3 values, expected 4"),
        (lambda s: s.replace("5 6 7 8", "5 6 7 8 9"), "data row 2 has 5 values"),
        (lambda s: s.replace("5 6 7 8", "5 6 x 8"), "'x' is not a number"),
        (lambda s: s.replace("5 6 7 8", "5 6 1e999 8"), "not finite"),
        (lambda s: s.replace("xllcorner 1000.0", "xllcorner east"), "not a number"),
        (lambda s: "", "missing header key 'ncols'"),
    ],
)
def test_malformed_grids(edit, match):
    with pytest.raises(ValueError, match=match):
        parse_ascii_grid(edit(SMALL), source="bad.asc")


def test_malformed_file_on_disk(tmp_path):
    path = tmp_path / "bad.asc"
    path.write_bytes(b"ncols 2\nnrows 2\n\xff\xfe")
    with pytest.raises(ValueError, match="non-ASCII"):
        read_ascii_grid(path)
    path.write_text(SMALL.replace("9 10 11 12\n", ""))
    with pytest.raises(ValueError, match=r"bad\.asc: expected 3 data rows"):
        read_ascii_grid(path)


def test_bad_grid_terrain_arguments():
    with pytest.raises(ValueError, match="2x2"):
        GridTerrain(np.zeros((1, 5)), 1.0)
    with pytest.raises(ValueError, match="inf"):
        GridTerrain([[0, 1], [np.inf, 0]], 1.0)
    with pytest.raises(ValueError, match="all NODATA"):
        GridTerrain(np.full((2, 2), np.nan), 1.0)
    with pytest.raises(ValueError, match="cellsize"):
        GridTerrain(np.zeros((2, 2)), 0.0)
    with pytest.raises(ValueError, match="interpolation"):
        GridTerrain(np.zeros((2, 2)), 1.0, interpolation="cubic")
    with pytest.raises(ValueError, match="no triangle"):
        GridTerrain(np.zeros((2, 2)), 1.0).triangle(1, 0, 0)


# ------------------------------------------------------------------------------ surfaces, slopes


def test_triangle_and_bilinear_interpolation_by_hand():
    # One cell: SW 0, SE 1, NW 2, NE 4 (heights[i, j], i north, j east).
    H = [[0.0, 1.0], [2.0, 4.0]]
    tri = GridTerrain(H, 1.0, interpolation="triangles")
    bil = GridTerrain(H, 1.0)
    assert tri.height(0.25, 0.5) == pytest.approx(0.5 * 1 + 0.25 * 3)  # SW-SE-NE triangle (east of diagonal)
    assert tri.height(0.5, 0.25) == pytest.approx(0.5 * 2 + 0.25 * 2)  # SW-NW-NE triangle
    assert bil.height(0.25, 0.5) == pytest.approx(0.75 * 0.5 * 1 + 0.25 * 0.5 * 2 + 0.25 * 0.5 * 4)
    assert tri.triangle_at(0.25, 0.5) == (0, 0, 0) and tri.triangle_at(0.5, 0.25) == (0, 0, 1)
    assert np.allclose(tri.triangle(0, 0, 0), [[0, 0, 0], [0, 1, -1], [1, 1, -4]])
    assert tri.triangle_at(2.0, 0.0) is None


def test_max_slope_bounds_the_gradient():
    rng = np.random.default_rng(4)
    for kind in ("bilinear", "triangles"):
        g = GridTerrain(rng.normal(0, 5, (12, 9)), 7.0, interpolation=kind)
        n, e = rng.uniform(0, 77, 4000), rng.uniform(0, 56, 4000)
        step = 1e-4
        gn = (g.height(n + step, e) - g.height(n - step, e)) / (2 * step)
        ge = (g.height(n, e + step) - g.height(n, e - step)) / (2 * step)
        assert np.nanmax(np.hypot(gn, ge)) <= g.max_slope * (1 + 1e-6)


# ---------------------------------------------------------------------------- ray intersection


def test_moller_trumbore_equals_ross_eq1():
    rng = np.random.default_rng(5)
    for _ in range(50):
        o, d, v0, v1, v2 = rng.normal(size=(5, 3))
        t, u, v = moller_trumbore(o, d, v0, v1, v2)
        t1, u1, v1_ = ross_eq1(o, o + d, v0, v1, v2)
        assert np.allclose([t, u, v], [t1, u1, v1_], atol=1e-9)
        assert np.allclose(o + t * d, v0 + u * (v1 - v0) + v * (v2 - v0), atol=1e-9)
    # hand-checked: the plane z = 1 spanned by a unit right triangle, a ray straight along +z
    t, u, v = moller_trumbore([0.25, 0.5, 0.0], [0, 0, 2.0], [0, 0, 1.0], [1, 0, 1.0], [0, 1, 1.0])
    assert (t, u, v) == pytest.approx((0.5, 0.25, 0.5))
    t, _, _ = moller_trumbore([0, 0, 0], [1, 0, 0], [0, 0, 1.0], [1, 0, 1.0], [0, 1, 1.0])
    assert math.isnan(t)  # parallel
    assert ross_eq1([0, 0, 0], [1, 0, 0], [0, 0, 1.0], [1, 0, 1.0], [0, 1, 1.0]) is None


def plane_grid(kind):
    """The plane h = 5 + 0.5 north on a 10 m grid, north and east in [-200, 200]."""
    n = -200.0 + 10.0 * np.arange(41)
    return GridTerrain(np.repeat((5.0 + 0.5 * n)[:, None], 41, axis=1), 10.0, -200.0, -200.0, kind)


@pytest.mark.parametrize("kind", ["bilinear", "triangles"])
def test_hand_checked_plane(kind):
    g = plane_grid(kind)
    # From 105 m up, 45° down towards the north: 105 - s = 5 + 0.5 s  =>  s = 200/3.
    o, d = np.array([0.0, 0.0, -105.0]), np.array([1.0, 0.0, 1.0])
    expected = [200 / 3, 0.0, -(5 + 100 / 3)]
    assert np.allclose(g.intersect(o, d), expected, atol=1e-9)
    assert np.allclose(intersect_ray(g, o, d, tol=1e-7), expected, atol=1e-6)
    hit, iterations = ross_intersect(g, o, d)
    assert np.allclose(hit, expected, atol=1e-9) and iterations <= 2  # a plane: one solve, one check
    # Straight down at a node, along a grid line, through the nodes of a diagonal:
    assert np.allclose(g.intersect([10.0, 20.0, -50.0], [0, 0, 1]), [10.0, 20.0, -10.0])
    assert np.allclose(g.intersect([0.0, 20.0, -105.0], [1, 0, 1]), [200 / 3, 20.0, -(5 + 100 / 3)])
    t = 100.0 / (0.5 + math.sqrt(2.0))  # 105 - √2 t = 5 + 0.5 t along north = east = t
    assert np.allclose(g.intersect([0.0, 0.0, -105.0], [1, 1, math.sqrt(2)]), [t, t, -(5 + 0.5 * t)])


def test_rays_that_miss_the_grid():
    g = plane_grid("triangles")
    assert g.intersect([0, 0, -100], [0, 0, -1]) is None  # up
    assert g.intersect([0, 0, -110], [1, 0, 0]) is None  # level above every summit (h_max = 105)
    assert g.intersect([0, 0, -100], [-1, 0, 0.01]) is None  # leaves the grid first (downhill, south)
    assert g.intersect([0, 0, -100], [1, 0, 1], max_range=50.0) is None  # beyond max_range
    assert g.intersect([0, 0, 0], [0, 0, 1]) is None  # starts below the surface (h = 5 there)
    assert g.intersect([300, 0, -3], [-1, 0, 0]) is None  # enters the grid underground from the north
    assert np.allclose(g.intersect([-300, 0, -3], [1, 0, 0]), [-4.0, 0.0, -3.0])  # level, from the low side
    s = 295.0 / 1.5  # from outside the grid: 150 - s = 5 + 0.5 (s - 300)
    assert np.allclose(g.intersect([-300, 0, -150], [1, 0, 1]), [-300 + s, 0, -(150 - s)])
    assert ross_intersect(g, [500, 0, -100], [0, 0, 1]) is None  # outside the grid
    assert ross_intersect(g, [0, 0, -100], [0, 0, -1]) is None  # pointing away
    with pytest.raises(ValueError, match="non-zero"):
        g.intersect([0, 0, -100], [0, 0, 0])
    with pytest.raises(ValueError, match="max_range"):
        g.intersect([0, 0, -100], [0, 0, 1], max_range=-1.0)


def test_rays_reaching_a_hole_give_none():
    H = np.zeros((11, 11))
    H[5, 8] = np.nan
    H[0, 0] = 200.0  # valid terrain up to 200 m: the hole is treated as no higher than that
    g = GridTerrain(H, 10.0)
    assert g.intersect([50.0, 0.0, -100.0], [0, 1, 1.0]) is None  # would land at east 100: the hole is on the way
    assert np.allclose(g.intersect([50.0, 0.0, -30.0], [0, 1, 1.0]), [50.0, 30.0, 0.0])  # lands before it
    assert math.isnan(g.height(50.0, 80.0))


HILLS = HillsTerrain(amplitude=30.0, wavelength=250.0, seed=7)


@pytest.mark.parametrize("kind", ["bilinear", "triangles"])
def test_exact_intersection_agrees_with_intersect_ray(kind):
    g = GridTerrain.sample(HILLS, -1000.0, -1000.0, 20.0, (101, 101), kind)
    rng = np.random.default_rng(11)
    checked = 0
    for _ in range(60):
        o = np.array([*rng.uniform(-600, 600, 2), -rng.uniform(60, 400)])
        az, dep = rng.uniform(-math.pi, math.pi), rng.uniform(0.15, 1.5)
        d = np.array([math.cos(dep) * math.cos(az), math.cos(dep) * math.sin(az), math.sin(dep)])
        exact = g.intersect(o, d, max_range=3000.0)
        generic = intersect_ray(g, o, d, max_range=3000.0, tol=1e-5)
        assert (exact is None) == (generic is None)
        if exact is not None:
            checked += 1
            assert np.linalg.norm(exact - generic) < 1e-3
            assert abs(-exact[2] - g.height(exact[0], exact[1])) < 1e-9
    assert checked > 40


def test_ross_iteration_converges_in_one_or_two_steps_on_gentle_terrain():
    gentle = HillsTerrain(amplitude=3.0, wavelength=400.0, seed=1)
    g = GridTerrain.sample(gentle, -1000.0, -1000.0, 30.0, (67, 67), "triangles")
    rng = np.random.default_rng(2)
    iterations = []
    for _ in range(30):
        o = np.array([*rng.uniform(-300, 300, 2), -rng.uniform(100, 300)])
        az, dep = rng.uniform(-math.pi, math.pi), rng.uniform(1.1, 1.5708)  # near-nadir, as in Ross et al.
        d = np.array([math.cos(dep) * math.cos(az), math.cos(dep) * math.sin(az), math.sin(dep)])
        hit, k = ross_intersect(g, o, d)
        assert np.allclose(hit, g.intersect(o, d), atol=1e-9)
        iterations.append(k)
    assert max(iterations) <= 4 and np.mean(iterations) <= 2.5
