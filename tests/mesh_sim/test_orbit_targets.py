"""The exact discretisation of 004's man-like target (Eqs. (16)-(17)): closed forms and a fine-step Monte Carlo."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mesh_sim import orbit_targets as ot


@pytest.mark.parametrize("alpha", [100.0, 0.01])
def test_noise_free_man_like_target_matches_the_closed_form(alpha):
    """Without noise, ``a = e^{-α̃t}``, ``v = 1 + (1 - e^{-α̃t})/α̃``, ``p = t + t/α̃ - (1 - e^{-α̃t})/α̃²`` per axis
    (spec 004 §4.4), exactly at the 1 s rendezvous step (a trapezoidal update gives +0.5 m/s at α̃ = 100)."""
    times = np.arange(0.0, 30.0, 1.0)
    paths = ot.man_like_paths(2, times, seed=1, alpha=alpha, sigma_w=0.0)
    decay = -np.expm1(-alpha * times)
    expected = times + times / alpha - decay / alpha**2
    np.testing.assert_allclose(paths[0, :, 0], expected, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(paths[1, :, 1], expected, rtol=1e-9, atol=1e-9)
    Phi, _ = ot.singer_discretisation(alpha, 0.0, 1.0)
    velocity = (np.linalg.matrix_power(Phi, 29) @ [0.0, 1.0, 1.0])[1]
    assert velocity == pytest.approx(1.0 + decay[-1] / alpha, rel=1e-12)


def test_discrete_noise_matches_a_fine_euler_maruyama_simulation():
    """``Q`` against an independent oracle: 4000 paths of the SDE integrated with 1000 Euler-Maruyama sub-steps
    over one step; every entry of the sample covariance within 5 standard errors (plus 2 % for the scheme)."""
    alpha, q, dt, substeps, samples = 2.0, 0.04, 1.0, 1000, 4000
    _, Q = ot.singer_discretisation(alpha, q, dt)
    rng = np.random.default_rng(3)
    s = np.zeros((samples, 3))
    h = dt / substeps
    for _ in range(substeps):
        p, v, a = s.T
        s = np.stack([p + h * v, v + h * a, a - h * alpha * a + math.sqrt(q * h) * rng.standard_normal(samples)], -1)
    sample = np.cov(s.T)
    standard_error = np.sqrt((Q**2 + np.outer(np.diag(Q), np.diag(Q))) / samples)  # of a Gaussian covariance entry
    assert np.all(np.abs(sample - Q) < 5 * standard_error + 0.02 * np.abs(Q))
    assert Q[2, 2] == pytest.approx(q * -np.expm1(-2 * alpha * dt) / (2 * alpha), rel=1e-9)  # OU variance


def test_man_like_target_walks_at_the_papers_speed():
    """α̃ = 10², x(0) = [0, 0, 1, 1, 1, 1], σ_w = 0.1: about 1 m/s per axis (spec 004 §4.4, |v| ≈ 1.4 m/s)."""
    paths = ot.man_like_paths(20, np.arange(0.0, 200.0, 1.0), seed=2)
    speed = np.linalg.norm(paths[:, -1] - paths[:, 0], axis=-1) / 199.0
    assert speed.mean() == pytest.approx(math.sqrt(2) * 1.01, rel=0.05)
    with pytest.raises(ValueError, match="alpha"):
        ot.singer_discretisation(0.0, 0.01, 1.0)
