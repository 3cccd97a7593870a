"""The IMM filter (fusion.imm) against closed forms: the Kalman filter (one mode, or identical modes), the
mixing and mode-probability equations of Bar-Shalom et al. §11.6.6 written out by hand, and the moments of
a Gaussian mixture."""

import numpy as np
import pytest

from fusion.gaussian import Gaussian
from fusion.imm import ImmBelief, ImmModel
from fusion.measurement import PositionMeasurement
from fusion.motion import ConstantVelocity


def _kalman(mean, cov, motion, dt, meas, z):
    """The Kalman filter in information form (fusion.gaussian): an independent implementation."""
    g = Gaussian.from_moments(mean, cov).predict(motion.transition(dt), motion.noise(dt))
    return g.update(meas.H, meas.R_inv, z)


def _gauss(x, mean, cov):
    d = x - mean
    return float(np.exp(-0.5 * d @ np.linalg.solve(cov, d)) / np.sqrt(np.linalg.det(2 * np.pi * cov)))


MEAN = np.array([1.0, -2.0, 0.5, 0.3, -0.1, 0.0])
COV = np.diag([4.0, 3.0, 1.0, 1.0, 0.5, 0.1])
MEAS = PositionMeasurement(6, np.diag([0.5, 0.4, 0.9]))
Z = np.array([1.8, -1.5, 0.2])


def test_one_mode_is_the_kalman_filter():
    motion = ConstantVelocity(3, 0.7, 0.1)
    imm = ImmModel((motion,), np.eye(1))
    out = ImmBelief.start(MEAN, COV, [1.0]).predict(imm, 0.4).update(MEAS, Z).combined()
    ref = _kalman(MEAN, COV, motion, 0.4, MEAS, Z)
    np.testing.assert_allclose(out.mean, ref.mean, atol=1e-10)
    np.testing.assert_allclose(out.cov, ref.cov, atol=1e-10)


def test_identical_modes_keep_their_probabilities_and_equal_the_kalman_filter():
    motion = ConstantVelocity(3, 0.7, 0.1)
    imm = ImmModel.two_modes(motion, motion, stay=0.9)
    out = ImmBelief.start(MEAN, COV, [0.3, 0.7]).predict(imm, 0.4).update(MEAS, Z)
    np.testing.assert_allclose(out.probs, [0.3 * 0.9 + 0.7 * 0.1, 0.3 * 0.1 + 0.7 * 0.9], atol=1e-12)
    ref = _kalman(MEAN, COV, motion, 0.4, MEAS, Z)
    np.testing.assert_allclose(out.combined().mean, ref.mean, atol=1e-10)
    np.testing.assert_allclose(out.combined().cov, ref.cov, atol=1e-10)


def test_interaction_and_mode_probabilities_follow_the_imm_equations():
    """Two modes with different means and noises, one cycle, against §11.6.6 written out for r = 2."""
    quiet, manoeuvre = ConstantVelocity(3, 0.0, 0.0), ConstantVelocity(3, 3.0, 0.2)
    switch = np.array([[0.8, 0.2], [0.4, 0.6]])
    imm = ImmModel((quiet, manoeuvre), switch)
    mu = np.array([0.25, 0.75])
    x = [MEAN, MEAN + np.array([1.0, 0.5, 0.0, -0.4, 0.2, 0.0])]
    P = [COV, 2.0 * COV]
    belief = ImmBelief(np.array(x), np.array(P), mu)
    dt = 0.5
    predicted = belief.predict(imm, dt)
    c = np.array([switch[0, j] * mu[0] + switch[1, j] * mu[1] for j in range(2)])
    np.testing.assert_allclose(predicted.probs, c)
    for j, motion in enumerate((quiet, manoeuvre)):
        w = [switch[i, j] * mu[i] / c[j] for i in range(2)]
        x0 = w[0] * x[0] + w[1] * x[1]
        P0 = sum(w[i] * (P[i] + np.outer(x[i] - x0, x[i] - x0)) for i in range(2))
        F, Q = motion.transition(dt), motion.noise(dt)
        np.testing.assert_allclose(predicted.means[j], F @ x0, atol=1e-12)
        np.testing.assert_allclose(predicted.covs[j], F @ P0 @ F.T + Q, atol=1e-12)
    updated = predicted.update(MEAS, Z)
    like = [_gauss(Z, predicted.means[j][:3], predicted.covs[j][:3, :3] + MEAS.R) for j in range(2)]
    expected = np.array(like) * c / np.dot(like, c)
    np.testing.assert_allclose(updated.probs, expected, rtol=1e-9)


def test_combined_is_the_mixture_moments():
    rng = np.random.default_rng(3)
    means = rng.normal(size=(3, 2))
    covs = np.array([np.eye(2) * s for s in (0.5, 1.0, 2.0)])
    probs = np.array([0.2, 0.5, 0.3])
    g = ImmBelief(means, covs, probs).combined()
    mean = probs @ means
    second = sum(p * (c + np.outer(m, m)) for p, m, c in zip(probs, means, covs, strict=True))
    np.testing.assert_allclose(g.mean, mean, atol=1e-12)
    np.testing.assert_allclose(g.cov, second - np.outer(mean, mean), atol=1e-12)


def test_the_likelier_model_wins_on_a_static_target():
    """Static multiple model (stay = 1): noiseless position fixes of a static target make the quiet mode
    certain, exponentially in the evidence."""
    imm = ImmModel.two_modes(ConstantVelocity(3, 0.0, 0.0), ConstantVelocity(3, 3.0, 3.0), stay=1.0)
    rng = np.random.default_rng(0)
    belief = ImmBelief.start(np.zeros(6), np.diag([1.0, 1.0, 1.0, 0.1, 0.1, 0.1]), [0.5, 0.5])
    meas = PositionMeasurement(6, 0.01 * np.eye(3))
    for _ in range(50):
        belief = belief.predict(imm, 0.2).update(meas, 0.1 * rng.standard_normal(3))
    assert belief.probs[0] > 0.999


@pytest.mark.parametrize("kwargs, message", [
    ({"motions": (), "switch": np.eye(0)}, "at least one"),
    ({"motions": (ConstantVelocity(3), ConstantVelocity(2)), "switch": np.eye(2)}, "same state dimension"),
    ({"motions": (ConstantVelocity(3), ConstantVelocity(3)), "switch": np.array([[0.5, 0.6], [0.5, 0.5]])},
     "rows summing to 1"),
    ({"motions": (ConstantVelocity(3),), "switch": np.eye(2)}, "shape"),
])
def test_bad_models_are_rejected(kwargs, message):
    with pytest.raises(ValueError, match=message):
        ImmModel(**kwargs)


def test_bad_starts_are_rejected():
    with pytest.raises(ValueError, match="sum to 1"):
        ImmBelief.start(MEAN, COV, [0.5, 0.6])
    with pytest.raises(ValueError, match="positive definite"):
        ImmBelief.start(MEAN, -COV, [1.0])
    with pytest.raises(ValueError, match="staying"):
        ImmModel.two_modes(ConstantVelocity(3), ConstantVelocity(3), stay=0.0)
