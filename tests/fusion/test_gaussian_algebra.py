"""Property tests of the information-form Gaussian algebra (DESIGN.md §2, Merino (3.7)-(3.9), App. A).

Every oracle here is written in covariance form with plain numpy/scipy (``np.linalg.inv``,
``np.linalg.solve``, ``scipy.stats``), never with the code under test.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.stats
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from fusion.gaussian import Gaussian, UninformativeBeliefError

SETTINGS = settings(max_examples=60, deadline=None)
FLOATS = st.floats(min_value=-3.0, max_value=3.0, allow_nan=False, allow_infinity=False)
EPS = 0.1  # ridge added to A A^T: keeps every covariance at condition number below ~1e4


@st.composite
def spd(draw, n: int) -> np.ndarray:
    """A random symmetric positive-definite matrix ``A A^T + eps I`` from a random ``A``."""
    A = draw(arrays(np.float64, (n, n), elements=FLOATS))
    return A @ A.T + EPS * np.eye(n)


@st.composite
def vectors(draw, n: int, bound: float = 10.0) -> np.ndarray:
    return draw(arrays(np.float64, (n,), elements=st.floats(-bound, bound, allow_nan=False, allow_infinity=False)))


@st.composite
def moments(draw, n: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    n = draw(st.integers(1, 6)) if n is None else n
    return draw(vectors(n)), draw(spd(n))


@st.composite
def moment_pairs(draw) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
    n = draw(st.integers(1, 6))
    return draw(moments(n)), draw(moments(n))


def assert_close(actual, expected, rtol=1e-8):
    """Element-wise closeness relative to the largest entry of ``expected`` (matrices mix scales)."""
    expected = np.asarray(expected, dtype=float)
    scale = max(1.0, float(np.max(np.abs(expected)))) if expected.size else 1.0
    np.testing.assert_allclose(actual, expected, rtol=rtol, atol=rtol * scale)


def min_eig(M: np.ndarray) -> float:
    return float(np.linalg.eigvalsh(M)[0])


# -- construction and moments ---------------------------------------------------------------------
@SETTINGS
@given(moments())
def test_from_moments_round_trip(m):
    mu, P = m
    g = Gaussian.from_moments(mu, P)
    Y = np.linalg.inv(P)
    assert_close(g.Y, Y, rtol=1e-7)
    assert_close(g.y, Y @ mu, rtol=1e-7)
    assert_close(g.mean, mu)
    assert_close(g.cov, P)


@SETTINGS
@given(moments())
def test_from_info_round_trip(m):
    mu, P = m
    Y = np.linalg.inv(P)
    Y = 0.5 * (Y + Y.T)
    g = Gaussian.from_info(Y @ mu, Y)
    assert_close(g.mean, mu, rtol=1e-6)
    assert_close(g.cov, P, rtol=1e-6)


# -- fuse / remove ---------------------------------------------------------------------------------
@SETTINGS
@given(moment_pairs())
def test_fuse_matches_covariance_form_product(pair):
    """Fusing independent evidence = the Kalman-form product of two Gaussians."""
    (ma, Pa), (mb, Pb) = pair
    fused = Gaussian.from_moments(ma, Pa).fuse(Gaussian.from_moments(mb, Pb))
    K = Pa @ np.linalg.inv(Pa + Pb)
    assert_close(fused.cov, Pa - K @ Pa, rtol=1e-6)
    assert_close(fused.mean, ma + K @ (mb - ma), rtol=1e-6)


@SETTINGS
@given(moment_pairs())
def test_fuse_then_remove_is_identity(pair):
    (ma, Pa), (mb, Pb) = pair
    a, b = Gaussian.from_moments(ma, Pa), Gaussian.from_moments(mb, Pb)
    back = a.fuse(b).remove(b)
    assert_close(back.Y, a.Y)
    assert_close(back.y, a.y)
    # and removing what was fused leaves the moments of a
    assert_close(back.mean, ma, rtol=1e-6)


@SETTINGS
@given(moment_pairs())
def test_fuse_result_symmetric_and_positive_definite(pair):
    (ma, Pa), (mb, Pb) = pair
    fused = Gaussian.from_moments(ma, Pa).fuse(Gaussian.from_moments(mb, Pb))
    np.testing.assert_array_equal(fused.Y, fused.Y.T)
    assert min_eig(fused.Y) > 0
    # the fused covariance is no larger than either input covariance
    assert min_eig(Pa - fused.cov) >= -1e-9 * np.max(np.abs(Pa))
    assert min_eig(Pb - fused.cov) >= -1e-9 * np.max(np.abs(Pb))


def test_fuse_with_zero_information_is_identity():
    a = Gaussian.from_moments([1.0, -2.0], [[2.0, 0.3], [0.3, 1.0]])
    b = a.fuse(Gaussian.zeros(2))
    np.testing.assert_array_equal(b.Y, a.Y)
    np.testing.assert_array_equal(b.y, a.y)


# -- intersect -------------------------------------------------------------------------------------
@SETTINGS
@given(moment_pairs(), st.floats(0.0, 1.0))
def test_intersect_symmetric_positive_definite(pair, omega):
    (ma, Pa), (mb, Pb) = pair
    c = Gaussian.from_moments(ma, Pa).intersect(Gaussian.from_moments(mb, Pb), omega)
    np.testing.assert_array_equal(c.Y, c.Y.T)
    assert min_eig(c.Y) > 0
    expected_Y = omega * np.linalg.inv(Pa) + (1 - omega) * np.linalg.inv(Pb)
    assert_close(c.Y, expected_Y, rtol=1e-7)
    expected_y = omega * np.linalg.solve(Pa, ma) + (1 - omega) * np.linalg.solve(Pb, mb)
    assert_close(c.y, expected_y, rtol=1e-7)


@pytest.mark.parametrize("omega", [-0.01, 1.01, float("nan")])
def test_intersect_rejects_omega_outside_unit_interval(omega):
    a = Gaussian.from_moments([0.0], [[1.0]])
    with pytest.raises(ValueError, match="omega must lie in"):
        a.intersect(a, omega)


# -- zero information ------------------------------------------------------------------------------
@pytest.mark.parametrize("dim", [1, 3, 6])
def test_zero_information_belief_is_legal_but_has_no_moments(dim):
    g = Gaussian.zeros(dim)
    assert not g.has_information
    assert g.dim == dim
    assert issubclass(UninformativeBeliefError, ValueError)
    with pytest.raises(UninformativeBeliefError, match="no information"):
        _ = g.mean
    with pytest.raises(UninformativeBeliefError, match="no information"):
        _ = g.cov
    # legal through the validated constructor as well
    Gaussian.from_info(np.zeros(dim), np.zeros((dim, dim)))


def test_singular_information_has_no_moments():
    """Information on one axis only: the other axis is unobserved."""
    g = Gaussian.from_info([1.0, 0.0], [[2.0, 0.0], [0.0, 0.0]])
    assert g.has_information
    with pytest.raises(UninformativeBeliefError, match="singular"):
        _ = g.mean
    with pytest.raises(ValueError, match="unobserved"):
        _ = g.cov


# -- marginal and conditional against covariance form (Merino App. A) ------------------------------
@st.composite
def moments_and_split(draw, min_dim=1):
    n = draw(st.integers(min_dim, 6))
    mu, P = draw(moments(n))
    perm = draw(st.permutations(range(n)))
    k = draw(st.integers(1, n - 1 if min_dim >= 2 else n))
    keep = list(perm[:k])
    return mu, P, keep


@SETTINGS
@given(moments_and_split())
def test_marginal_is_covariance_sub_block(args):
    mu, P, keep = args
    m = Gaussian.from_moments(mu, P).marginal(keep)
    assert m.dim == len(keep)
    assert_close(m.cov, P[np.ix_(keep, keep)], rtol=1e-6)
    assert_close(m.mean, mu[keep], rtol=1e-6)


@SETTINGS
@given(moments_and_split(min_dim=2), st.data())
def test_condition_matches_covariance_form(args, data):
    mu, P, keep = args
    rest = [i for i in range(len(mu)) if i not in keep]
    b = data.draw(vectors(len(rest)))
    c = Gaussian.from_moments(mu, P).condition(keep, b)
    a_, b_ = np.ix_(keep, keep), np.ix_(keep, rest)
    P_ab, P_bb = P[b_], P[np.ix_(rest, rest)]
    gain = P_ab @ np.linalg.inv(P_bb)
    expected_cov = P[a_] - gain @ P_ab.T
    expected_mean = mu[keep] + gain @ (b - mu[rest])
    assert_close(c.cov, expected_cov, rtol=1e-6)
    assert_close(c.mean, expected_mean, rtol=1e-6)


def test_condition_hand_checked_2d():
    """x ~ N(0, [[1, .5], [.5, 1]]): x0 | x1 = 2 is N(1, 0.75)."""
    c = Gaussian.from_moments([0.0, 0.0], [[1.0, 0.5], [0.5, 1.0]]).condition([0], [2.0])
    np.testing.assert_allclose(c.mean, [1.0], rtol=1e-12)
    np.testing.assert_allclose(c.cov, [[0.75]], rtol=1e-12)


# -- KL divergence ---------------------------------------------------------------------------------
@SETTINGS
@given(
    st.floats(-5, 5), st.floats(0.1, 5), st.floats(-5, 5), st.floats(0.1, 5),
)
def test_kl_1d_closed_form(m1, s1, m2, s2):
    p = Gaussian.from_moments([m1], [[s1**2]])
    q = Gaussian.from_moments([m2], [[s2**2]])
    expected = np.log(s2 / s1) + (s1**2 + (m1 - m2) ** 2) / (2 * s2**2) - 0.5
    assert p.kl_divergence(q) == pytest.approx(expected, rel=1e-9, abs=1e-12)


@SETTINGS
@given(moments())
def test_kl_of_identical_beliefs_is_zero(m):
    p = Gaussian.from_moments(*m)
    assert abs(p.kl_divergence(p)) < 1e-8


@SETTINGS
@given(moment_pairs())
def test_kl_is_non_negative_and_asymmetric_terms_consistent(pair):
    (ma, Pa), (mb, Pb) = pair
    p, q = Gaussian.from_moments(ma, Pa), Gaussian.from_moments(mb, Pb)
    assert p.kl_divergence(q) >= -1e-9
    assert q.kl_divergence(p) >= -1e-9


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_kl_matches_monte_carlo(seed):
    """``E_p[log p(x) - log q(x)]`` estimated with scipy logpdf, within 5 standard errors."""
    rng = np.random.default_rng(seed)
    n = 3
    A, B = rng.normal(size=(n, n)), rng.normal(size=(n, n))
    Pa, Pb = A @ A.T + 0.5 * np.eye(n), B @ B.T + 0.5 * np.eye(n)
    ma, mb = rng.normal(size=n), rng.normal(size=n)
    kl = Gaussian.from_moments(ma, Pa).kl_divergence(Gaussian.from_moments(mb, Pb))
    x = rng.multivariate_normal(ma, Pa, size=200_000)
    diff = scipy.stats.multivariate_normal(ma, Pa).logpdf(x) - scipy.stats.multivariate_normal(mb, Pb).logpdf(x)
    se = diff.std() / np.sqrt(diff.size)
    assert abs(kl - diff.mean()) < 5 * se + 1e-3
    assert kl > 0.05  # the two beliefs differ: the comparison is not trivially 0 == 0


# -- NEES ------------------------------------------------------------------------------------------
@SETTINGS
@given(moments(), st.data())
def test_nees_matches_direct_formula(m, data):
    mu, P = m
    x = data.draw(vectors(len(mu)))
    err = x - mu
    expected = float(err @ np.linalg.solve(P, err))
    assert Gaussian.from_moments(mu, P).nees(x) == pytest.approx(expected, rel=1e-6, abs=1e-9)


def test_nees_hand_checked():
    g = Gaussian.from_moments([1.0, 2.0], np.diag([4.0, 9.0]))
    assert g.nees([3.0, -1.0]) == pytest.approx(1.0 + 1.0, rel=1e-12)


# -- prediction in information form ---------------------------------------------------------------
@st.composite
def prediction_problems(draw):
    n = draw(st.integers(1, 6))
    mu, P = draw(moments(n))
    F = draw(arrays(np.float64, (n, n), elements=FLOATS)) + 4.0 * np.eye(n)
    assume(abs(np.linalg.det(F)) > 1e-2 and np.linalg.cond(F) < 1e4)
    B = draw(arrays(np.float64, (n, draw(st.integers(1, n))), elements=FLOATS))
    return mu, P, F, B @ B.T  # Q may be singular


@SETTINGS
@given(prediction_problems())
def test_predict_matches_covariance_form(problem):
    """Information-form prediction = ``N(F mu, F P F^T + Q)`` even with a singular ``Q``."""
    mu, P, F, Q = problem
    pred = Gaussian.from_moments(mu, P).predict(F, Q)
    assert_close(pred.cov, F @ P @ F.T + Q, rtol=1e-6)
    assert_close(pred.mean, F @ mu, rtol=1e-6)
    np.testing.assert_array_equal(pred.Y, pred.Y.T)
