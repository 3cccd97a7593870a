"""Certainty grids (Merino Ch. 4): geometry, the belief algebra, the read-outs and the intersection rules.

Oracles are written independently of the code under test: Bayes' rule on odds (4.2), ``scipy.stats``
for Bernoulli and Beta entropies and moments, numerical Bayes on a fine grid for the conjugate update,
explicitly normalised weighted exponential products, and ``scipy.optimize`` for the Chernoff point.
"""

from __future__ import annotations

import json

import msgpack
import numpy as np
import pytest
import scipy.optimize
import scipy.stats
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.special import betaln

from fusion.grid import BetaGrid, LogOddsGrid
from fusion.grid_geometry import GridGeometry, GridGeometryError
from fusion.grid_intersect import chernoff_intersect, chernoff_weights, half_intersect, max_intersect
from fusion.network import FilterNetwork
from tests.fusion.builders import complete, random_tree, ring

SETTINGS = settings(max_examples=50, deadline=None)
GEOM = GridGeometry((100.0, -50.0), 10.0, (3, 4), height=-2.0)
SHAPE = GEOM.shape


def evidence(bound: float = 20.0):
    return arrays(np.float64, SHAPE, elements=st.floats(-bound, bound, allow_nan=False, allow_infinity=False))


def counts(bound: float = 50.0):
    return arrays(np.float64, SHAPE, elements=st.floats(0.0, bound, allow_nan=False, allow_infinity=False))


def log_odds_grid(e) -> LogOddsGrid:
    return LogOddsGrid(GEOM, e)


# -- geometry ------------------------------------------------------------------------------------------
def test_centres_by_hand():
    c = GEOM.centres()
    assert c.shape == (3, 4, 2)
    np.testing.assert_array_equal(c[0, 0], [105.0, -45.0])
    np.testing.assert_array_equal(c[2, 3], [125.0, -15.0])  # row = north, col = east


def test_centres_ned_row_major_with_height():
    ned = GEOM.centres_ned()
    assert ned.shape == (12, 3)
    np.testing.assert_array_equal(ned[1], [105.0, -35.0, -2.0])  # second cell: same row, next column
    np.testing.assert_array_equal(ned[4], [115.0, -45.0, -2.0])  # first cell of the second row
    np.testing.assert_array_equal(ned[:, :2], GEOM.centres().reshape(-1, 2))


def test_cell_of_inside_on_far_edge_and_centres():
    assert GEOM.cell_of(100.0, -50.0) == (0, 0)
    assert GEOM.cell_of(119.999, -30.0) == (1, 2)
    assert GEOM.cell_of(130.0, -10.0) == (2, 3)  # the far edges belong to the last row and column
    for (r, c), centre in np.ndenumerate(GEOM.centres()[..., 0]):
        assert GEOM.cell_of(centre, GEOM.centres()[r, c, 1]) == (r, c)


@pytest.mark.parametrize("point", [(99.999, -40.0), (130.001, -40.0), (110.0, -50.1), (110.0, -9.9)],
                         ids=["south-of-grid", "north-of-grid", "west-of-grid", "east-of-grid"])
def test_cell_of_rejects_point_outside(point):
    with pytest.raises(GridGeometryError, match="outside the grid"):
        GEOM.cell_of(*point)


def test_cell_of_rejects_nan_point():
    with pytest.raises(GridGeometryError, match="north must be finite"):
        GEOM.cell_of(float("nan"), 0.0)


@pytest.mark.parametrize("north,east,cell,shape", [
    ((0.0, 100.0), (0.0, 30.0), 10.0, (10, 3)),
    ((0.0, 101.0), (0.0, 30.0), 10.0, (11, 3)),
    ((0.0, 1.1), (0.0, 0.3), 0.1, (11, 3)),  # 1.1 / 0.1 = 11.000000000000002 must not give 12
    ((5.0, 5.0), (0.0, 0.0), 2.0, (1, 1)),
])
def test_covering(north, east, cell, shape):
    g = GridGeometry.covering(north, east, cell)
    assert g.shape == shape and g.origin == (north[0], east[0])
    g.cell_of(north[1], east[1])  # the far corner is on the grid
    assert g.shape[0] == 1 or g.origin[0] + (g.shape[0] - 1) * cell < north[1]  # and no row is spare


def test_covering_rejects_reversed_range():
    with pytest.raises(GridGeometryError, match="north range is reversed"):
        GridGeometry.covering((10.0, 0.0), (0.0, 1.0), 1.0)


def test_dict_round_trip_through_json_and_msgpack():
    for codec in (lambda d: json.loads(json.dumps(d)), lambda d: msgpack.unpackb(msgpack.packb(d))):
        assert GridGeometry.from_dict(codec(GEOM.to_dict())) == GEOM


@pytest.mark.parametrize("d,match", [
    ({"origin": [0, 0], "cell": 1.0}, "missing"),
    ({"origin": [0, 0], "cell": 1.0, "shape": [2, 2], "colour": 1}, "unknown"),
    ({"origin": [0], "cell": 1.0, "shape": [2, 2]}, "origin must be a pair"),
    ({"origin": {"n": 0, "e": 0}, "cell": 1.0, "shape": [2, 2]}, "origin must be a pair"),
    ({"origin": [0, 0], "cell": 1.0, "shape": "ab"}, "shape must be a pair"),
    ({"origin": [0, 0], "cell": "1", "shape": [2, 2]}, "cell size must be a real number"),
    ({"origin": [0, 0], "cell": 1.0, "shape": [2.0, 2]}, "rows must be an integer"),
    ({"origin": [0, 0], "cell": 1.0, "shape": [2, 2], "height": None}, "height must be a real number"),
    ([1, 2, 3], "must be a mapping"),
], ids=["missing-shape", "unknown-key", "short-origin", "dict-origin", "string-shape", "string-cell", "float-rows",
        "null-height", "list"])
def test_from_dict_rejects(d, match):
    with pytest.raises(GridGeometryError, match=match):
        GridGeometry.from_dict(d)


@pytest.mark.parametrize("kwargs,match", [
    ({"cell": 0.0}, "cell size must be positive"),
    ({"cell": -1.0}, "cell size must be positive"),
    ({"cell": float("nan")}, "cell size must be finite"),
    ({"shape": (0, 3)}, "rows must be at least 1"),
    ({"shape": (3, -1)}, "cols must be at least 1"),
    ({"shape": (3,)}, "shape must be a pair"),
    ({"shape": (True, 3)}, "rows must be an integer"),
    ({"shape": (5000, 5000)}, "exceeds MAX_CELLS"),
    ({"origin": (float("inf"), 0.0)}, "origin\\[0\\] must be finite"),
    ({"height": float("nan")}, "height must be finite"),
], ids=["zero-cell", "negative-cell", "nan-cell", "zero-rows", "negative-cols", "1d-shape", "bool-rows",
        "huge-grid", "inf-origin", "nan-height"])
def test_geometry_rejects(kwargs, match):
    args = {"origin": (0.0, 0.0), "cell": 1.0, "shape": (2, 2)} | kwargs
    with pytest.raises(GridGeometryError, match=match):
        GridGeometry(**args)


@pytest.mark.parametrize("other,field", [
    (GridGeometry((100.0, -50.0), 10.0, (3, 5), -2.0), "shape"),
    (GridGeometry((100.0, -50.0), 5.0, (3, 4), -2.0), "cell"),
    (GridGeometry((100.0, -40.0), 10.0, (3, 4), -2.0), "origin"),
    (GridGeometry((100.0, -50.0), 10.0, (3, 4), 0.0), "height"),
])
def test_check_same_names_the_difference(other, field):
    GEOM.check_same(GridGeometry.from_dict(GEOM.to_dict()))
    with pytest.raises(GridGeometryError, match=f"mismatch: {field}"):
        GEOM.check_same(other)


# -- log-odds grid: read-outs against independent oracles ---------------------------------------------
def test_update_is_bayes_on_odds():
    """Alg. 4.2 after two detections and one miss equals Bayes' rule (4.2) on the odds of each cell."""
    rng = np.random.default_rng(0)
    pd, pf = rng.uniform(0.6, 0.95, SHAPE), rng.uniform(0.05, 0.4, SHAPE)
    prior = 0.3
    grid = LogOddsGrid.uniform(GEOM, prior)
    odds = np.full(SHAPE, prior / (1 - prior))
    for detected in (True, False, True):
        lz = (pd, pf) if detected else (1 - pd, 1 - pf)
        grid = grid.update(np.log(lz[0]) - np.log(lz[1]))
        odds = odds * lz[0] / lz[1]
    np.testing.assert_allclose(grid.probability(), odds / (1 + odds), rtol=1e-12)


def test_update_cells_accumulates_repeated_indices():
    index = np.array([0, 5, 5, 11, 0, 5])
    llr = np.array([0.5, 1.0, -0.25, 2.0, 0.5, 0.125])
    expected = np.zeros(GEOM.size)
    for k, v in zip(index, llr, strict=True):
        expected[k] += v
    grid = LogOddsGrid.uniform(GEOM).update_cells(index, llr)
    np.testing.assert_array_equal(grid.evidence, expected.reshape(SHAPE))
    np.testing.assert_array_equal(LogOddsGrid.uniform(GEOM).update(expected.reshape(SHAPE)).evidence, grid.evidence)


def test_entropy_and_kl_match_scipy():
    rng = np.random.default_rng(1)
    a, b = LogOddsGrid(GEOM, rng.normal(0, 2, SHAPE), prior=0.2), LogOddsGrid(GEOM, rng.normal(0, 2, SHAPE), prior=0.2)
    pa, pb = a.probability(), b.probability()
    np.testing.assert_allclose(a.entropy(), scipy.stats.bernoulli(pa).entropy(), rtol=1e-12)
    kl = sum(scipy.stats.entropy([p, 1 - p], [q, 1 - q]) for p, q in zip(pa.ravel(), pb.ravel(), strict=True))
    assert a.kl_divergence(b) == pytest.approx(kl, rel=1e-12)
    assert a.kl_divergence(a) == 0.0


def test_clamp_applies_on_read_but_the_algebra_stays_exact():
    big = LogOddsGrid(GEOM, np.full(SHAPE, 50.0))
    small = LogOddsGrid(GEOM, np.full(SHAPE, 0.25))
    assert big.probability().max() == pytest.approx(0.999, abs=1e-15)  # clamped when read
    assert big.log_odds().max() == pytest.approx(np.log(999.0))
    assert big.evidence.max() == 50.0  # but stored as is
    back = small.fuse(big).remove(big)
    np.testing.assert_array_equal(back.evidence, small.evidence)
    assert np.isfinite(big.entropy()).all() and big.entropy().min() > 0.0
    assert np.isfinite(big.kl_divergence(LogOddsGrid.uniform(GEOM)))


def test_intersect_is_the_normalised_weighted_exponential_product():
    rng = np.random.default_rng(2)
    a, b = LogOddsGrid(GEOM, rng.normal(0, 2, SHAPE), 0.4), LogOddsGrid(GEOM, rng.normal(0, 2, SHAPE), 0.4)
    w = rng.uniform(0, 1, SHAPE)
    pa, pb = a.probability(), b.probability()
    num = pa**w * pb ** (1 - w)
    wep = num / (num + (1 - pa) ** w * (1 - pb) ** (1 - w))
    np.testing.assert_allclose(a.intersect(b, w).probability(), wep, rtol=1e-12)


def test_grids_are_immutable_and_static():
    a = LogOddsGrid.uniform(GEOM)
    with pytest.raises(ValueError, match="read-only"):
        a.evidence[0, 0] = 1.0
    assert a.epoch is None and a.advanced_to(7) is a
    source = np.zeros(SHAPE)
    b = LogOddsGrid(GEOM, source)
    source[0, 0] = 5.0
    assert b.evidence[0, 0] == 0.0  # copied on construction


# -- property tests of the algebra --------------------------------------------------------------------
@SETTINGS
@given(evidence(), evidence(), evidence())
def test_log_odds_fuse_commutative_associative_and_remove_inverts(ea, eb, ec):
    a, b, c = (log_odds_grid(e) for e in (ea, eb, ec))
    assert a.fuse(b).allclose(b.fuse(a), atol=0.0)
    assert a.fuse(b).fuse(c).allclose(a.fuse(b.fuse(c)), atol=1e-12)
    assert a.fuse(b).remove(b).allclose(a, atol=1e-12)
    assert a.intersect(b, 1.0).allclose(a, atol=0.0) and a.intersect(b, 0.0).allclose(b, atol=0.0)


@SETTINGS
@given(evidence(), evidence(), st.floats(0.0, 1.0))
def test_log_odds_decay_commutes_with_fuse_and_remove(ea, eb, factor):
    a, b = log_odds_grid(ea), log_odds_grid(eb)
    assert a.fuse(b).decayed(factor).allclose(a.decayed(factor).fuse(b.decayed(factor)), atol=1e-12)
    assert a.remove(b).decayed(factor).allclose(a.decayed(factor).remove(b.decayed(factor)), atol=1e-12)
    assert a.decayed(1.0).allclose(a, atol=0.0) and not a.decayed(0.0).evidence.any()


@SETTINGS
@given(counts(), counts(), counts(), counts(), st.floats(0.0, 1.0), st.floats(0.0, 1.0))
def test_beta_algebra_and_counts_never_negative(aa, ab, ba, bb, w, factor):
    a, b = BetaGrid(GEOM, aa, ba), BetaGrid(GEOM, ab, bb)
    results = [a.fuse(b), a.fuse(b).remove(b), a.fuse(b).remove(a), a.intersect(b, w), a.decayed(factor),
               a.scaled(w), a.fuse(b).decayed(factor).remove(b.decayed(factor)), max_intersect(a, b),
               chernoff_intersect(a, b), half_intersect(a, b)]
    for r in results:
        assert r.alpha.min() >= 0.0 and r.beta.min() >= 0.0
    assert a.fuse(b).allclose(b.fuse(a), atol=0.0)
    assert a.fuse(b).remove(b).allclose(a, atol=1e-12)
    assert a.intersect(b, 1.0).allclose(a, atol=0.0) and a.intersect(b, 0.0).allclose(b, atol=0.0)
    assert a.fuse(b).decayed(factor).allclose(a.decayed(factor).fuse(b.decayed(factor)), atol=1e-12)


def test_beta_fuse_is_merino_434_in_full_parameters():
    rng = np.random.default_rng(3)
    a0, b0 = 2.0, 0.5
    a = BetaGrid(GEOM, rng.uniform(0, 5, SHAPE), rng.uniform(0, 5, SHAPE), a0, b0)
    b = BetaGrid(GEOM, rng.uniform(0, 5, SHAPE), rng.uniform(0, 5, SHAPE), a0, b0)
    (alpha_i, beta_i), (alpha_j, beta_j) = a.shape_parameters(), b.shape_parameters()
    fused = a.fuse(b).shape_parameters()
    np.testing.assert_allclose(fused[0], alpha_i + alpha_j - a0, rtol=1e-14)
    np.testing.assert_allclose(fused[1], beta_i + beta_j - b0, rtol=1e-14)


def test_beta_remove_rejects_more_than_held_but_rounds_tiny_negatives():
    a = BetaGrid(GEOM, np.full(SHAPE, 1.0), np.full(SHAPE, 1.0))
    more = BetaGrid(GEOM, np.full(SHAPE, 1.0), np.where(np.arange(12).reshape(SHAPE) < 2, 1.5, 1.0))
    with pytest.raises(ValueError, match="removing more beta evidence than the grid holds in 2 cells"):
        a.remove(more)
    tiny = BetaGrid(GEOM, np.full(SHAPE, 1.0 + 1e-12), np.full(SHAPE, 1.0))
    assert a.remove(tiny).alpha.min() == 0.0


# -- Beta read-outs ------------------------------------------------------------------------------------
def test_beta_moments_and_entropy_match_scipy():
    rng = np.random.default_rng(4)
    g = BetaGrid(GEOM, rng.uniform(0, 20, SHAPE), rng.uniform(0, 20, SHAPE), 1.5, 0.7)
    dist = scipy.stats.beta(*g.shape_parameters())
    np.testing.assert_allclose(g.mean(), dist.mean(), rtol=1e-12)
    np.testing.assert_allclose(g.probability(), dist.mean(), rtol=1e-12)
    np.testing.assert_allclose(g.variance(), dist.var(), rtol=1e-12)
    np.testing.assert_allclose(g.entropy(), dist.entropy(), rtol=1e-9, atol=1e-12)
    other = BetaGrid(GEOM, rng.uniform(0, 20, SHAPE), rng.uniform(0, 20, SHAPE), 1.5, 0.7)
    p, q = g.mean().ravel(), other.mean().ravel()
    kl = sum(scipy.stats.entropy([x, 1 - x], [y, 1 - y]) for x, y in zip(p, q, strict=True))
    assert g.kl_divergence(other) == pytest.approx(kl, rel=1e-12)


def test_beta_update_is_conjugate_bayes_on_a_fine_grid():
    """Alg. 4.4: uniform prior x X^m (1-X)^n, normalised numerically, has the Beta grid's mean and variance."""
    m, n = np.full(SHAPE, 3.0), np.full(SHAPE, 1.5)
    m[0, 0], n[0, 0] = 0.25, 7.0
    g = BetaGrid.uniform(GEOM).update(m, n)
    x = np.linspace(0.0, 1.0, 200_001)
    for cell in [(0, 0), (1, 1)]:
        post = x ** m[cell] * (1 - x) ** n[cell]
        post /= np.trapezoid(post, x)
        mean = np.trapezoid(x * post, x)
        assert g.mean()[cell] == pytest.approx(mean, rel=1e-5)  # x^0.25 is not smooth at 0: trapezoid error
        assert g.variance()[cell] == pytest.approx(np.trapezoid((x - mean) ** 2 * post, x), rel=1e-5)


def test_beta_update_cells_accumulates():
    g = BetaGrid.uniform(GEOM).update_cells(np.array([3, 3, 7]), np.array([1.0, 0.5, 0.0]), np.array([0, 0, 2.0]))
    assert g.alpha.ravel()[3] == 1.5 and g.beta.ravel()[7] == 2.0 and g.alpha.sum() == 1.5 and g.beta.sum() == 2.0


def test_beta_intersect_is_the_weighted_exponential_product():
    """Beta_a^w Beta_b^(1-w), normalised on a fine grid, is the Beta with weighted counts."""
    a = BetaGrid(GEOM, np.full(SHAPE, 6.0), np.full(SHAPE, 1.0))
    b = BetaGrid(GEOM, np.full(SHAPE, 0.5), np.full(SHAPE, 9.0))
    w = 0.3
    x = np.linspace(1e-6, 1 - 1e-6, 200_001)
    (aa, ba), (ab, bb) = (g.shape_parameters() for g in (a, b))
    wep = scipy.stats.beta(aa[0, 0], ba[0, 0]).pdf(x) ** w * scipy.stats.beta(ab[0, 0], bb[0, 0]).pdf(x) ** (1 - w)
    wep /= np.trapezoid(wep, x)
    assert a.intersect(b, w).mean()[0, 0] == pytest.approx(np.trapezoid(x * wep, x), rel=1e-6)


# -- intersection rules --------------------------------------------------------------------------------
def _chernoff_oracle(log_coefficient) -> float:
    """The Chernoff point minimises log ∫ p_a^w p_b^(1-w) over [0, 1]."""
    return scipy.optimize.minimize_scalar(log_coefficient, bounds=(0, 1), method="bounded",
                                          options={"xatol": 1e-12}).x


def test_chernoff_weights_log_odds_match_the_minimum_of_the_chernoff_coefficient():
    rng = np.random.default_rng(5)
    a, b = LogOddsGrid(GEOM, rng.normal(0, 3, SHAPE), 0.1), LogOddsGrid(GEOM, rng.normal(0, 3, SHAPE), 0.1)
    pa, pb = 1 / (1 + 9 * np.exp(-a.evidence)), 1 / (1 + 9 * np.exp(-b.evidence))
    w = chernoff_weights(a, b)
    for k in np.ndindex(SHAPE):
        oracle = _chernoff_oracle(lambda t, k=k: np.log(pa[k] ** t * pb[k] ** (1 - t)
                                                        + (1 - pa[k]) ** t * (1 - pb[k]) ** (1 - t)))
        assert w[k] == pytest.approx(oracle, abs=1e-5)
    np.testing.assert_allclose(chernoff_intersect(a, b).evidence, a.intersect(b, w).evidence, rtol=0, atol=0)


def test_chernoff_weights_beta_match_the_minimum_of_the_chernoff_coefficient():
    rng = np.random.default_rng(6)
    a = BetaGrid(GEOM, rng.uniform(0, 30, SHAPE), rng.uniform(0, 30, SHAPE))
    b = BetaGrid(GEOM, rng.uniform(0, 30, SHAPE), rng.uniform(0, 30, SHAPE))
    (aa, ba), (ab, bb) = a.shape_parameters(), b.shape_parameters()
    w = chernoff_weights(a, b)
    for k in np.ndindex(SHAPE):
        def log_coefficient(t, k=k):
            return (betaln(t * aa[k] + (1 - t) * ab[k], t * ba[k] + (1 - t) * bb[k])
                    - t * betaln(aa[k], ba[k]) - (1 - t) * betaln(ab[k], bb[k]))
        assert w[k] == pytest.approx(_chernoff_oracle(log_coefficient), abs=1e-5)


def test_chernoff_point_equalises_the_two_divergences():
    """KL(p_w || p_a) = KL(p_w || p_b) cell by cell, with KL from scipy."""
    a = LogOddsGrid(GEOM, np.linspace(-6, 6, 12).reshape(SHAPE))
    b = LogOddsGrid(GEOM, np.linspace(3, -1, 12).reshape(SHAPE))
    pw, pa, pb = chernoff_intersect(a, b).probability(), a.probability(), b.probability()
    for k in np.ndindex(SHAPE):
        kl_a = scipy.stats.entropy([pw[k], 1 - pw[k]], [pa[k], 1 - pa[k]])
        kl_b = scipy.stats.entropy([pw[k], 1 - pw[k]], [pb[k], 1 - pb[k]])
        assert kl_a == pytest.approx(kl_b, abs=1e-10)


def test_chernoff_identical_inputs_give_the_input():
    a = LogOddsGrid(GEOM, np.linspace(-4, 4, 12).reshape(SHAPE))
    assert chernoff_intersect(a, a).allclose(a, atol=0.0)


def test_max_and_half_rules_by_hand():
    a = LogOddsGrid(GEOM, np.array([[1.0, -2.0, 0.0, 3.0]] * 3))
    b = LogOddsGrid(GEOM, np.array([[2.0, -3.0, -1.0, 0.5]] * 3))
    np.testing.assert_array_equal(max_intersect(a, b).evidence, [[2.0, -2.0, 0.0, 3.0]] * 3)  # (4.5)
    np.testing.assert_array_equal(half_intersect(a, b).evidence, [[1.5, -2.5, -0.5, 1.75]] * 3)
    c = BetaGrid(GEOM, np.full(SHAPE, 2.0), np.full(SHAPE, 5.0))
    d = BetaGrid(GEOM, np.full(SHAPE, 4.0), np.full(SHAPE, 1.0))
    m = max_intersect(c, d)  # (4.39): alpha and beta maximised separately
    assert (m.alpha == 4.0).all() and (m.beta == 5.0).all()


# -- decentralized fusion over a network of channel filters (Merino Alg. 4.3, 4.5) ---------------------
def _local_update(kind: str, rng: np.random.Generator, sign: np.ndarray):
    """A random local observation of some cells: log-likelihood ratios whose sign per cell is ``sign``
    (log-odds), or detection/non-detection pseudo-counts (Beta). Returns belief -> belief."""
    seen = rng.random(SHAPE) < 0.6
    if kind == "log-odds":
        llr = np.where(seen, sign * rng.uniform(0.1, 1.5, SHAPE), 0.0)
        return lambda g: g.update(llr)
    m = np.where(seen, rng.uniform(0.0, 2.0, SHAPE), 0.0)
    n = np.where(seen, rng.uniform(0.0, 2.0, SHAPE), 0.0)
    return lambda g: g.update(m, n)


def _run_network(kind, n, edges, policy, rng, rounds=4, settle=None, intersect=None):
    """Every node observes every round, then the nodes exchange; the oracle applies every observation."""
    prior = LogOddsGrid.uniform(GEOM, 0.2) if kind == "log-odds" else BetaGrid.uniform(GEOM, 1.0, 2.0)
    net = FilterNetwork(n, edges, prior, policy, intersect=intersect)
    oracle, sign = prior, np.where(rng.random(SHAPE) < 0.5, -1.0, 1.0)
    for _ in range(rounds):
        for i in range(n):
            update = _local_update(kind, rng, sign)
            net.apply(i, update)
            oracle = update(oracle)
        net.exchange()
    for _ in range(n if settle is None else settle):
        net.exchange()
    return net, oracle


@pytest.mark.parametrize("kind", ["log-odds", "beta"])
@pytest.mark.parametrize("n", [4, 5, 6])
def test_tree_channel_filters_equal_the_centralized_grid(kind, n):
    rng = np.random.default_rng(10 + n)
    net, oracle = _run_network(kind, n, random_tree(n, rng), "exact", rng)
    for belief in net.beliefs:
        assert belief.allclose(oracle, atol=1e-12)
    assert net.methods["exact"] > 0 and net.methods["ci"] == 0


@pytest.mark.parametrize("kind", ["log-odds", "beta"])
def test_tree_before_propagation_is_not_yet_centralized(kind):
    """Guards the comparison above against a vacuous oracle: on a line, one exchange is not enough."""
    rng = np.random.default_rng(3)
    net, oracle = _run_network(kind, 5, [(i, i + 1) for i in range(4)], "exact", rng, rounds=1, settle=0)
    assert not net.beliefs[0].allclose(oracle, atol=1e-3)


def _excess(kind, belief, oracle) -> float:
    """How far a node is more confident than the centralized grid, maximised over cells (<= 0: never)."""
    if kind == "log-odds":
        return float(np.max(np.abs(belief.evidence) - np.abs(oracle.evidence)))
    return float(max(np.max(belief.alpha - oracle.alpha), np.max(belief.beta - oracle.beta)))


@pytest.mark.parametrize("kind", ["log-odds", "beta"])
@pytest.mark.parametrize("edges,n", [(ring(3), 3), (complete(4), 4)], ids=["ring3", "complete4"])
def test_loops_naive_overcounts_and_intersection_rules_never_exceed_centralized(kind, edges, n):
    naive, oracle = _run_network(kind, n, edges, "naive", np.random.default_rng(20))
    assert min(_excess(kind, b, oracle) for b in naive.beliefs) > 1.0  # every node double-counts
    for rule in (chernoff_intersect, half_intersect, max_intersect):
        net, same_oracle = _run_network(kind, n, edges, "ci", np.random.default_rng(20), intersect=rule)
        assert same_oracle.allclose(oracle, atol=0.0)  # the same observations as the naive run
        for belief in net.beliefs:
            assert _excess(kind, belief, oracle) <= 1e-12, rule.__name__
            if kind == "log-odds":  # and the evidence never changes sign
                assert np.all(belief.evidence * oracle.evidence >= -1e-12)
            # not vacuous: the node learned from the fleet (closer to the centralized grid than the prior)
            assert oracle.kl_divergence(belief) < 0.5 * oracle.kl_divergence(net.filters[0].prior)
        assert net.methods["ci"] > 0


# -- bad input -------------------------------------------------------------------------------------------
OTHER = GridGeometry((100.0, -50.0), 10.0, (3, 5))


@pytest.mark.parametrize("op", ["fuse", "remove", "intersect", "kl_divergence", "allclose", "chernoff", "max",
                                "half"])
@pytest.mark.parametrize("kind", ["log-odds", "beta"])
def test_binary_ops_reject_grids_of_different_geometry(op, kind):
    make = LogOddsGrid.uniform if kind == "log-odds" else BetaGrid.uniform
    a, b = make(GEOM), make(OTHER)
    call = {"intersect": lambda: a.intersect(b, 0.5), "chernoff": lambda: chernoff_intersect(a, b),
            "max": lambda: max_intersect(a, b), "half": lambda: half_intersect(a, b)}.get(op,
                                                                                      lambda: getattr(a, op)(b))
    with pytest.raises(GridGeometryError, match="geometry mismatch: shape"):
        call()


def test_binary_ops_reject_different_priors_and_types():
    with pytest.raises(ValueError, match="prior mismatch: 0.5 vs 0.3"):
        LogOddsGrid.uniform(GEOM).fuse(LogOddsGrid.uniform(GEOM, 0.3))
    with pytest.raises(ValueError, match="alpha0 mismatch"):
        BetaGrid.uniform(GEOM).remove(BetaGrid.uniform(GEOM, alpha0=2.0))
    with pytest.raises(ValueError, match="expected a LogOddsGrid, got BetaGrid"):
        LogOddsGrid.uniform(GEOM).fuse(BetaGrid.uniform(GEOM))
    with pytest.raises(ValueError, match="expected a LogOddsGrid or a BetaGrid"):
        chernoff_intersect(np.zeros(3), np.zeros(3))


@pytest.mark.parametrize("kwargs,match", [
    ({"evidence": np.full(SHAPE, np.nan)}, "evidence contains non-finite values"),
    ({"evidence": np.full(SHAPE, np.inf)}, "evidence contains non-finite values"),
    ({"evidence": np.zeros((4, 3))}, "evidence must have shape \\(3, 4\\)"),
    ({"evidence": "abc"}, "evidence must be numeric"),
    ({"prior": 0.0}, "prior must lie in \\(0, 1\\)"),
    ({"prior": 1.0}, "prior must lie in \\(0, 1\\)"),
    ({"prior": float("nan")}, "prior must be finite"),
    ({"prior": 0.0001}, "outside the clamp range"),
    ({"clamp": 0.5}, "clamp must lie in \\(0.5, 1\\)"),
    ({"clamp": 1.0}, "clamp must lie in \\(0.5, 1\\)"),
], ids=["nan-evidence", "inf-evidence", "transposed-evidence", "string-evidence", "prior-zero", "prior-one",
        "nan-prior", "prior-beyond-clamp", "clamp-half", "clamp-one"])
def test_log_odds_grid_rejects(kwargs, match):
    with pytest.raises(ValueError, match=match):
        LogOddsGrid(GEOM, **kwargs)


def test_log_odds_grid_rejects_a_non_geometry():
    with pytest.raises(GridGeometryError, match="geometry must be a GridGeometry"):
        LogOddsGrid((3, 4))


@pytest.mark.parametrize("call,match", [
    (lambda g: g.update(np.zeros(12)), "llr must have shape"),
    (lambda g: g.update(np.full(SHAPE, np.nan)), "llr contains non-finite"),
    (lambda g: g.update_cells(np.array([0, 12]), np.zeros(2)), "cell index out of range"),
    (lambda g: g.update_cells(np.array([-1]), np.zeros(1)), "cell index out of range"),
    (lambda g: g.update_cells(np.array([0.0, 1.0]), np.zeros(2)), "1-D integer array"),
    (lambda g: g.update_cells(np.array([0, 1]), np.zeros(3)), "one value per index"),
    (lambda g: g.update_cells(np.array([0]), np.array([np.nan])), "llr contains non-finite"),
    (lambda g: g.intersect(g, 1.5), "omega must lie in \\[0, 1\\]"),
    (lambda g: g.intersect(g, -0.1), "omega must lie in \\[0, 1\\]"),
    (lambda g: g.intersect(g, float("nan")), "omega must be finite"),
    (lambda g: g.intersect(g, np.full(SHAPE, 1.2)), "omega must lie in \\[0, 1\\] in every cell"),
    (lambda g: g.intersect(g, np.full(5, 0.5)), "omega must have shape"),
    (lambda g: g.decayed(1.1), "decay factor must lie in \\[0, 1\\]"),
    (lambda g: g.decayed(-0.1), "decay factor must lie in \\[0, 1\\]"),
    (lambda g: g.scaled(-1.0), "scale weight must be non-negative"),
], ids=["llr-wrong-shape", "llr-nan", "index-too-large", "index-negative", "index-float", "index-llr-length",
        "sparse-llr-nan", "omega-above-1", "omega-negative", "omega-nan", "omega-array-above-1",
        "omega-wrong-shape", "decay-above-1", "decay-negative", "negative-scale"])
def test_log_odds_operations_reject(call, match):
    with pytest.raises(ValueError, match=match):
        call(LogOddsGrid.uniform(GEOM))


def test_fuse_rejects_evidence_that_overflows_to_inf():
    huge = LogOddsGrid(GEOM, np.full(SHAPE, 1e308))
    with np.errstate(over="ignore"), pytest.raises(ValueError, match="evidence after adding .* contains non-finite"):
        huge.fuse(huge)


@pytest.mark.parametrize("kwargs,match", [
    ({"alpha": -np.eye(3, 4)}, "alpha has 3 negative cell counts"),
    ({"beta": np.full(SHAPE, -1.0)}, "beta has 12 negative cell counts"),
    ({"alpha": np.full(SHAPE, np.nan)}, "alpha contains non-finite"),
    ({"beta": np.zeros(12)}, "beta must have shape"),
    ({"alpha0": 0.0}, "Beta prior must be positive"),
    ({"beta0": -1.0}, "Beta prior must be positive"),
    ({"alpha0": float("inf")}, "alpha0 must be finite"),
], ids=["negative-alpha", "negative-beta", "nan-alpha", "beta-wrong-shape", "zero-alpha0", "negative-beta0",
        "inf-alpha0"])
def test_beta_grid_rejects(kwargs, match):
    with pytest.raises(ValueError, match=match):
        BetaGrid(GEOM, **kwargs)


@pytest.mark.parametrize("call,match", [
    (lambda g: g.update(-np.ones(SHAPE), np.zeros(SHAPE)), "m has 12 negative cell counts"),
    (lambda g: g.update(np.zeros(SHAPE), np.full(SHAPE, np.nan)), "n contains non-finite"),
    (lambda g: g.update(np.zeros(SHAPE), np.zeros((2, 2))), "n must have shape"),
    (lambda g: g.update_cells(np.array([1]), np.array([-1.0]), np.array([0.0])), "m has 1 negative"),
    (lambda g: g.update_cells(np.array([1]), np.array([1.0]), np.array([0.0, 1.0])), "one value per index"),
    (lambda g: g.intersect(g, 2.0), "omega must lie in"),
    (lambda g: g.decayed(2.0), "decay factor"),
], ids=["negative-m", "nan-n", "n-wrong-shape", "sparse-negative-m", "sparse-n-length", "omega-above-1",
        "decay-above-1"])
def test_beta_operations_reject(call, match):
    with pytest.raises(ValueError, match=match):
        call(BetaGrid.uniform(GEOM))


def test_beta_remove_forgives_float32_rounding_of_the_count_but_not_more():
    """Counts travel as float32: a count re-rounded on the wire may exceed the one held by ~6e-8 of itself."""
    held = BetaGrid(GEOM, np.full(SHAPE, 1000.0), np.full(SHAPE, 5.0))
    rounded = BetaGrid(GEOM, np.full(SHAPE, float(np.nextafter(np.float32(1000.0), np.float32(2000.0)))),
                       np.full(SHAPE, 5.0))  # one float32 step above
    assert rounded.alpha[0, 0] > 1000.0 + 1e-9
    assert held.remove(rounded).alpha.max() == 0.0
    with pytest.raises(ValueError, match="removing more alpha"):
        held.remove(BetaGrid(GEOM, np.full(SHAPE, 1000.01), np.full(SHAPE, 5.0)))
