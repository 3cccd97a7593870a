"""``fusion.imm_window``: an IMM window that receives its measurements out of order, up to ``window`` epochs
late, equals the recursive IMM (``fusion.imm.ImmBelief``) that received each on time — the independent
oracle here is the plain predict/update loop in time order. (Two measurements of one epoch are applied in
the order they arrive: extended-Kalman updates do not commute, their linearization point moves.)"""

import numpy as np
import pytest

from fusion.imm import ImmBelief, ImmModel
from fusion.imm_window import ImmWindow, ImmWindowModel
from fusion.measurement import Bearing3D
from fusion.motion import ConstantVelocity

STEP, WINDOW = 0.2, 6
IMM = ImmModel.two_modes(ConstantVelocity(3, 0.0, 0.0), ConstantVelocity(3, 3.0, 0.0), 0.95)
MODEL = ImmWindowModel(IMM, STEP, WINDOW)
START_MEAN = np.array([10.0, 5.0, 0.0, 1.0, 0.0, 0.0])
START_COV = np.diag([4.0, 4.0, 1.0, 4.0, 4.0, 0.1])
PROBS = np.array([0.5, 0.5])


def _measurements(seed: int, epochs: int):
    """Per epoch, one or two bearings of a target moving at (1, 0.5) m/s from cameras at 80 m."""
    rng = np.random.default_rng(seed)
    out = {}
    for k in range(epochs):
        truth = np.array([10.0 + k * STEP, 5.0 + 0.5 * k * STEP, 0.0])
        out[k] = []
        for _ in range(int(rng.integers(1, 3))):
            sensor = np.array([rng.uniform(-40, 40), rng.uniform(-40, 40), -80.0])
            model = Bearing3D(6, sensor, np.diag([1e-4, 1e-4]))
            out[k].append((model, model.h(np.concatenate([truth, np.zeros(3)])) + rng.normal(0, 0.01, 2)))
    return out


def _on_time(measurements, epochs: int) -> ImmBelief:
    belief = ImmBelief.start(START_MEAN, START_COV, PROBS)
    for k in range(epochs):
        if k:
            belief = belief.predict(IMM, STEP)
        for model, z in measurements[k]:
            belief = belief.update(model, z)
    return belief


@pytest.mark.parametrize("seed", range(6))
def test_late_measurements_give_the_on_time_imm(seed):
    epochs = 25
    measurements = _measurements(seed, epochs)
    rng = np.random.default_rng(100 + seed)
    late = {k: int(rng.integers(0, WINDOW)) for k in range(epochs)}  # an epoch's measurements travel together:
    delay = {(k, i): late[k] for k in range(epochs) for i in range(len(measurements[k]))}  # EKF updates don't commute
    window = ImmWindow.start(MODEL, 0, START_MEAN, START_COV, PROBS)
    for now in range(epochs + WINDOW):
        window = window.advanced_to(now)
        arriving = sorted((k, i) for (k, i), d in delay.items() if k + d == now)  # one epoch's in arrival order
        for k, i in arriving:
            model, z = measurements[k][i]
            window = window.eif_update(model, z, offset=now - k)
        if now < epochs:
            window.current()  # ask for marginals in between, as a tracker does (caches must stay right)
    reference = _on_time(measurements, epochs)
    for _ in range(epochs, epochs + WINDOW):
        reference = reference.predict(IMM, STEP)
    got = window.belief_at(window.epoch)
    np.testing.assert_allclose(got.probs, reference.probs, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(got.means, reference.means, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(got.covs, reference.covs, rtol=1e-9, atol=1e-12)


def test_a_past_state_is_the_filtered_belief_of_its_epoch():
    measurements = _measurements(7, 10)
    window = ImmWindow.start(MODEL, 0, START_MEAN, START_COV, PROBS)
    for k in range(10):
        window = window.advanced_to(k)
        for model, z in measurements[k]:
            window = window.eif_update(model, z)
    past = window.state(3)
    expected = _on_time(measurements, 7).combined()
    np.testing.assert_allclose(past.mean, expected.mean, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(past.cov, expected.cov, rtol=1e-9, atol=1e-12)
    assert window.state(3) is past  # computed once per window


def test_bad_input_is_rejected():
    window = ImmWindow.start(MODEL, 0, START_MEAN, START_COV, PROBS).advanced_to(20)
    model = Bearing3D(6, np.array([0.0, 0.0, -80.0]), np.diag([1e-4, 1e-4]))
    with pytest.raises(ValueError, match="outside the IMM window"):
        window.eif_update(model, [0.1, -1.2], offset=WINDOW)  # older than the window
    with pytest.raises(ValueError, match="outside the IMM window"):
        window.state(-1)  # the future
    with pytest.raises(ValueError, match="backwards"):
        window.advanced_to(19)
    with pytest.raises(ValueError, match="measurement z"):
        window.eif_update(model, [0.1, float("nan")])
    with pytest.raises(ValueError, match="cannot start"):
        ImmWindow.start(MODEL, 0, np.zeros(4), np.eye(4), PROBS)
    for step, size in ((0.0, 4), (0.2, 0)):
        with pytest.raises(ValueError, match="step|window"):
            ImmWindowModel(IMM, step, size)
