"""The three conservative rules side by side: covariance intersection (CI, optimal weight), fast CI
(Niehsen 2002) and inverse covariance intersection (ICI, Noack et al. 2017).

Oracles: scalar closed forms, the matrix-convexity bound ``ICI(w) <= CI(1-w)`` checked on eigenvalues, and a
Monte Carlo of decentralized fusion where the two estimates share a common-information part of random size.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from fusion.covariance_intersection import ci, fast_ci
from fusion.gaussian import Gaussian
from fusion.inverse_covariance_intersection import ici
from fusion.motion import ConstantVelocity
from fusion.trajectory import Trajectory, TrajectoryModel, chain_projection, intersect_on_newest

ENTRIES = st.floats(min_value=-3.0, max_value=3.0, allow_nan=False, allow_infinity=False)


def scalar(mean, var):
    return Gaussian.from_moments([mean], [[var]])


def test_scalar_closed_forms():
    """1-D, ``p_a = 2``, ``p_b = 5``. CI (det or trace) and ICI keep the better estimate: ``P = min(p_a, p_b)``.
    Fast CI: ``w_a = p_b / (p_a + p_b)`` and ``1/P = w_a/p_a + (1-w_a)/p_b``, i.e. ``P = p_a p_b (p_a + p_b) /
    (p_a^2 + p_b^2)``, with ``x = P (w_a a/p_a + (1-w_a) b/p_b)``."""
    a, b = scalar(1.0, 2.0), scalar(-3.0, 5.0)
    for fused in (ci([a, b], "det"), ci([a, b], "trace"), ici(a, b, "det"), ici(a, b, "trace")):
        assert fused.cov[0, 0] == pytest.approx(2.0, rel=1e-9)
        assert fused.mean[0] == pytest.approx(1.0, rel=1e-9)
    w = 5.0 / 7.0
    P = 2.0 * 5.0 * 7.0 / (4.0 + 25.0)
    fused = fast_ci([a, b])
    assert fused.cov[0, 0] == pytest.approx(P, rel=1e-12)
    assert fused.mean[0] == pytest.approx(P * (w * 1.0 / 2.0 + (1 - w) * -3.0 / 5.0), rel=1e-12)


@st.composite
def pairs(draw):
    n = draw(st.integers(1, 5))
    covs = [draw(arrays(np.float64, (n, n), elements=ENTRIES)) for _ in range(2)]
    return [Gaussian.from_moments(np.zeros(n), M @ M.T + 0.05 * np.eye(n)) for M in covs]


def loewner_gap(P_big, P_small):
    """The smallest eigenvalue of ``P_big - P_small``, relative to the scale of ``P_big``."""
    return np.linalg.eigvalsh(P_big - P_small).min() / np.max(np.abs(P_big))


@settings(max_examples=80, deadline=None)
@given(pairs(), st.floats(0.0, 1.0))
def test_ici_is_never_looser_than_ci(pair, w):
    """For every weight, ``P_ICI(w) <= P_CI(1-w)`` in the Loewner order (``Gamma^-1 <= w Y_a + (1-w) Y_b`` by the
    matrix convexity of the inverse). Hence the optimal ICI beats the optimal CI on the objective both minimise.
    (The optimal ICI is *not* Loewner-below the optimal CI in general: the two optima use different weights.)"""
    a, b = pair
    assert loewner_gap(ci([a, b], [1.0 - w, w]).cov, ici(a, b, w).cov) >= -1e-9
    for objective, size in (("det", lambda P: np.linalg.slogdet(P)[1]), ("trace", np.trace)):
        best_ci, best_ici = ci([a, b], objective).cov, ici(a, b, objective).cov
        assert size(best_ici) <= size(best_ci) + 1e-6 * max(1.0, abs(size(best_ci)))


def decentralized_pair(rng, n):
    """Two estimates that fused a common-information part ``C`` of random size besides their own ``A``, ``B``:
    ``y_a = (A + C) x + alpha + gamma``, ``y_b = (B + C) x + beta + gamma`` with ``alpha ~ N(0, A)``,
    ``beta ~ N(0, B)``, ``gamma ~ N(0, C)`` independent (information-form measurements)."""
    A, B, C = (M @ M.T + 0.05 * np.eye(n) for M in rng.normal(size=(3, n, n)))
    C *= 10.0 ** rng.uniform(-1.0, 2.0)  # the common part: from a tenth to a hundred times the private parts
    x = rng.normal(scale=10.0, size=n)
    alpha, beta, gamma = (rng.multivariate_normal(np.zeros(n), M) for M in (A, B, C))
    a = Gaussian.from_info((A + C) @ x + alpha + gamma, A + C)
    b = Gaussian.from_info((B + C) @ x + beta + gamma, B + C)
    return x, a, b


def test_monte_carlo_nees_with_common_information():
    """Mean NEES of the fused estimate over random DDF pairs: CI, fast CI and ICI stay at or below the
    dimension (within three Monte Carlo standard errors); the naive product, which counts ``C`` twice, does not."""
    rng = np.random.default_rng(2024)
    n, trials = 3, 1000
    rules = {
        "ci": lambda a, b: ci([a, b], "det"),
        "fast_ci": lambda a, b: fast_ci([a, b]),
        "ici": lambda a, b: ici(a, b, "det"),
        "naive": lambda a, b: a.fuse(b),
    }
    nees = {name: [] for name in rules}
    for _ in range(trials):
        x, a, b = decentralized_pair(rng, n)
        for name, rule in rules.items():
            nees[name].append(rule(a, b).nees(x))
    for name, values in nees.items():
        mean, error = np.mean(values), 3.0 * np.std(values) / np.sqrt(trials)
        if name == "naive":
            assert mean > n + error, (name, mean)
        else:
            assert mean <= n + error, (name, mean)


# -- the rules on trajectories (the tracker's intersection) --------------------------------------------
def two_trajectories():
    """Two tracks of one 2-D target, one precise in x and the other in y (so every rule's weight is interior)."""
    model = TrajectoryModel(ConstantVelocity(2, q=0.5), step=1.0, window=4)
    rng = np.random.default_rng(8)
    H = np.hstack([np.eye(2), np.zeros((2, 2))])
    return tuple(
        Trajectory.prior(model, 5).update(H, np.diag(newest), rng.normal(size=2))
        .update(np.eye(4), np.diag(older), rng.normal(size=4), offset=2)
        for newest, older in (([6.0, 0.25], [0.1, 0.1, 0.1, 0.1]), ([0.5, 2.0], [3.0, 0.05, 0.3, 1.0]))
    )


def grid_argmin(f):
    """The minimiser of ``f`` on [0, 1] by two nested dense grids (resolution 1e-6)."""
    grid = np.linspace(0.0, 1.0, 1001)
    w0 = grid[int(np.argmin([f(w) for w in grid]))]
    fine = np.linspace(max(0.0, w0 - 1e-3), min(1.0, w0 + 1e-3), 2001)
    return fine[int(np.argmin([f(w) for w in fine]))]


def size_of(objective):
    return (lambda P: np.linalg.slogdet(P)[1]) if objective == "det" else np.trace


@pytest.mark.parametrize("objective", ["det", "trace"])
def test_intersect_on_newest_chooses_each_rules_weight_on_the_newest_state(objective):
    """The whole window is fused with the weight each rule chooses for the newest-state marginals: Niehsen's
    closed form for fast CI, and for CI and ICI the minimiser (dense grid) of the objective of the rule applied to
    the marginals. The weight of a CI result is read off ``Y = w Y_a + (1-w) Y_b``; the ICI result's newest state
    must be that of the covariance form of ICI over the whole window at the grid weight (to the grid's resolution),
    and its window must stay block-tridiagonal."""
    a, b = two_trajectories()
    m_a, m_b = a.current(), b.current()
    size = size_of(objective)

    def ci_weight_of(result):
        D = a.Y - b.Y
        return float(np.sum((result.Y - b.Y) * D) / np.sum(D * D))

    tr_a, tr_b = np.trace(m_a.cov), np.trace(m_b.cov)
    assert ci_weight_of(intersect_on_newest(a, b, "fast_ci")) == pytest.approx(tr_b / (tr_a + tr_b), rel=1e-9)
    w_ci = grid_argmin(lambda w: size(np.linalg.inv(w * m_a.Y + (1 - w) * m_b.Y)))
    assert ci_weight_of(intersect_on_newest(a, b, "ci", objective)) == pytest.approx(w_ci, abs=1e-5)
    inv = np.linalg.inv
    w_ici = grid_argmin(lambda w: size(inv(m_a.Y + m_b.Y - inv(w * m_a.cov + (1 - w) * m_b.cov))))
    fused = intersect_on_newest(a, b, "ici", objective)
    dense = inv(a.Y + b.Y - inv(w_ici * inv(a.Y) + (1 - w_ici) * inv(b.Y)))  # ICI's window covariance
    newest = slice(-a.model.state_dim, None)
    scale = np.max(np.abs(dense))
    np.testing.assert_allclose(fused.current().cov, dense[newest, newest], rtol=1e-5, atol=1e-12 * scale)
    assert_block_tridiagonal(fused.Y, a.model.state_dim)
    assert fused.epoch == a.epoch and fused.model == a.model


def assert_block_tridiagonal(Y, n):
    far = np.abs(np.subtract.outer(np.arange(Y.shape[0]) // n, np.arange(Y.shape[0]) // n)) > 1
    assert np.all(Y[far] == 0.0)


def test_chain_projection_keeps_a_chain():
    """A trajectory is already the maximum-entropy completion of its own band: projecting changes nothing."""
    a, _ = two_trajectories()
    np.testing.assert_allclose(chain_projection(a).Y, a.Y, rtol=1e-9, atol=1e-9 * np.max(np.abs(a.Y)))
    np.testing.assert_allclose(chain_projection(a).y, a.y, rtol=1e-9, atol=1e-9 * np.max(np.abs(a.y)))


def test_chain_projection_keeps_the_band_of_the_covariance_and_raises_the_entropy():
    """A dense belief over the window: the projection is block-tridiagonal, has the same mean, the same covariance
    blocks on the band (every single-state and consecutive-pair marginal), and the larger determinant (Dempster)."""
    a, _ = two_trajectories()
    n, m = a.model.state_dim, a.model.dim
    rng = np.random.default_rng(3)
    G = rng.normal(size=(m, m))
    dense = a.with_information(rng.normal(size=m), G @ G.T + 0.5 * np.eye(m))
    projected = chain_projection(dense)
    assert_block_tridiagonal(projected.Y, n)
    P, Q = np.linalg.inv(dense.Y), np.linalg.inv(projected.Y)
    band = np.abs(np.subtract.outer(np.arange(m) // n, np.arange(m) // n)) <= 1
    np.testing.assert_allclose(Q[band], P[band], rtol=1e-8, atol=1e-10 * np.max(np.abs(P)))
    np.testing.assert_allclose(Q @ projected.y, P @ dense.y, rtol=1e-8, atol=1e-10)
    assert np.linalg.slogdet(Q)[1] > np.linalg.slogdet(P)[1]


def test_intersect_on_newest_rejects_an_unknown_rule():
    a, b = two_trajectories()
    with pytest.raises(ValueError, match="intersection rule must be one of ci, fast_ci, ici"):
        intersect_on_newest(a, b, "covariance_union")
