"""Pseudo-intersection of rays (thesis 000 (3.12)-(3.14)) and its covariance against Monte Carlo."""

from __future__ import annotations

import math

import numpy as np
import pytest

from perception.triangulation import (
    batch_pseudo_intersection,
    perturb_bearings,
    pseudo_intersection,
    pseudo_intersection_jacobians,
)


def test_two_skew_lines_by_hand():
    # Line 1 is the x axis; line 2 runs along y at z = 1. The closest points are (0,0,0) and (0,0,1).
    x = [[0.0, 0.0, 0.0], [0.0, 5.0, 1.0]]
    d = [[1.0, 0.0, 0.0], [0.0, 2.0, 0.0]]  # directions need not be unit
    assert np.allclose(pseudo_intersection(x, d).point, [0, 0, 0.5])
    # weights 3 : 1 minimise 3 z² + (z - 1)²  =>  z = 1/4
    assert np.allclose(pseudo_intersection(x, d, weights=[3.0, 1.0]).point, [0, 0, 0.25])
    est = pseudo_intersection_jacobians(x, d)
    assert np.allclose(est.A, np.diag([1.0, 1.0, 2.0]))  # (I - e_x e_xᵀ) + (I - e_y e_yᵀ)


def observers(target, n=3, radius=60.0, altitude=50.0, rng=None):
    angles = np.linspace(0.0, 2 * math.pi, n, endpoint=False) + (0.0 if rng is None else rng.uniform(0, 1))
    x = np.column_stack([radius * np.cos(angles), radius * np.sin(angles), np.full(n, -altitude)])
    d = target - x
    return x, d / np.linalg.norm(d, axis=1)[:, None]


def test_exact_rays_meet_at_the_target():
    target = np.array([3.0, -4.0, 0.0])
    x, d = observers(target, n=4)
    assert np.allclose(pseudo_intersection(x, d, weights=[1, 2, 3, 4]).point, target)
    assert np.allclose(batch_pseudo_intersection(x, d), target)


def test_jacobians_match_finite_differences():
    rng = np.random.default_rng(0)
    x, d = observers(np.zeros(3), n=3, rng=rng)
    x = x + rng.normal(0, 2, x.shape)  # rays that do not meet
    w = np.array([1.0, 2.0, 0.5])
    est = pseudo_intersection_jacobians(x, d, w)
    h = 1e-6
    for i in range(3):
        for k in range(3):
            dx = np.zeros_like(x)
            dx[i, k] = h
            num = (pseudo_intersection(x + dx, d, w).point - pseudo_intersection(x - dx, d, w).point) / (2 * h)
            assert np.allclose(num, est.J_x[i][:, k], atol=1e-6)
            dd = np.zeros_like(d)
            dd[i, k] = h  # the unnormalised direction: J_d acts on the raw perturbation δd
            num = (
                pseudo_intersection_jacobians(x, d + dd, w).point - pseudo_intersection_jacobians(x, d - dd, w).point
            ) / (2 * h)
            # pseudo_intersection normalises d, so compare on the perpendicular part of δd only
            P = np.eye(3) - np.outer(d[i], d[i])
            assert np.allclose(num, (est.J_d[i] @ P)[:, k], atol=1e-5)


@pytest.mark.parametrize("n_rays, sigma_x, sigma_deg", [(2, 0.5, 1.0), (3, 1.0, 0.5), (5, 0.3, 2.0)])
def test_covariance_matches_monte_carlo(n_rays, sigma_x, sigma_deg):
    rng = np.random.default_rng(n_rays)
    target = np.array([10.0, -5.0, 0.0])
    x, d = observers(target, n=n_rays, radius=80.0, altitude=60.0, rng=rng)
    w = rng.uniform(0.5, 2.0, n_rays)
    sigma = math.radians(sigma_deg)
    est = pseudo_intersection(x, d, w, position_cov=sigma_x**2, bearing_sigma=sigma)
    m = 40_000
    noisy_x = x + rng.normal(0, sigma_x, (m, n_rays, 3))
    noisy_d = perturb_bearings(d, sigma, rng, m)
    q = batch_pseudo_intersection(noisy_x, noisy_d, w)
    mc = np.cov(q - target, rowvar=False)
    assert np.linalg.norm(est.cov - mc) / np.linalg.norm(mc) < 0.10
    ratio = np.linalg.eigvalsh(
        np.linalg.solve(np.linalg.cholesky(mc), np.linalg.solve(np.linalg.cholesky(mc), est.cov).T)
    )
    assert np.all(np.abs(ratio - 1.0) < 0.15)  # every direction within 15 %
    # The estimator is biased at second order (the dropped Â⁻¹ δA Â⁻¹ δb term of (3.23)): small, not zero.
    assert np.linalg.norm(q.mean(axis=0) - target) < 0.2 * math.sqrt(np.linalg.eigvalsh(mc)[0])


def test_noise_arguments():
    x, d = observers(np.zeros(3), n=3)
    a = pseudo_intersection(x, d, position_cov=0.25)
    b = pseudo_intersection(x, d, position_cov=[0.25, 0.25, 0.25])
    c = pseudo_intersection(x, d, position_cov=0.25 * np.eye(3))
    e = pseudo_intersection(x, d, position_cov=np.broadcast_to(0.25 * np.eye(3), (3, 3, 3)), bearing_sigma=0.0)
    assert np.allclose(a.cov, b.cov) and np.allclose(a.cov, c.cov) and np.allclose(a.cov, e.cov)
    only_bearing = pseudo_intersection(x, d, bearing_sigma=[0.01, 0.02, 0.01])
    assert np.all(np.linalg.eigvalsh(only_bearing.cov) >= -1e-15)
    assert pseudo_intersection(x, d).cov is None


@pytest.mark.parametrize(
    "x, d, kwargs, match",
    [
        ([[0, 0, 0]], [[1, 0, 0]], {}, "at least 2 rays"),
        ([[0, 0, 0], [0, 1, 0]], [[1, 0, 0], [1, 0, 0]], {}, "parallel"),
        ([[0, 0, 0], [10, 0, 0]], [[1, 0, 0], [-1, 0, 0]], {}, "parallel"),  # diametrically opposite
        ([[0, 0, 0], [0, 1, 0]], [[1, 0, 0], [1, 1e-7, 0]], {}, "parallel"),  # nearly
        ([[0, 0, 0], [0, 1, 0]], [[1, 0, 0], [0, 0, 0]], {}, "non-zero"),
        ([[0, 0, 0], [0, 1, 0]], [[1, 0, 0], [0, 0, 1]], {"weights": [1, 0]}, "weights"),
        ([[0, 0, 0], [0, 1, 0]], [[1, 0, 0], [0, 0, 1]], {"weights": [1]}, "weights"),
        ([[0, 0, 0], [0, 1, np.nan]], [[1, 0, 0], [0, 0, 1]], {}, "finite"),
        ([[0, 0, 0], [0, 1, 0]], [[1, 0, 0]], {}, "shape"),
        ([[0, 0, 0], [0, 1, 0]], [[1, 0, 0], [0, 0, 1]], {"position_cov": np.eye(2)}, "position_cov"),
        ([[0, 0, 0], [0, 1, 0]], [[1, 0, 0], [0, 0, 1]], {"position_cov": -np.eye(3)}, "semi-definite"),
        ([[0, 0, 0], [0, 1, 0]], [[1, 0, 0], [0, 0, 1]], {"bearing_sigma": -0.1}, "bearing_sigma"),
    ],
)
def test_degenerate_and_bad_inputs(x, d, kwargs, match):
    with pytest.raises(ValueError, match=match):
        pseudo_intersection(x, d, **kwargs)
