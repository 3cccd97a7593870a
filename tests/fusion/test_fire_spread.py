"""Fire prediction (Merino §6.3.1, (6.2)-(6.6), noisy-OR of 001b §2.6.2) and the two-layer fire belief.

The oracle for the transition is a Monte Carlo simulation of the binary stochastic process itself
(burning/burnt cells, independent ignitions by each burning neighbour), from random independent cells:
for one step the model's marginals are exact, so they must match the simulated frequencies."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.special import expit

from fusion.fire_spread import BURNT_PRIOR, FIRE_PRIOR, FireBelief, FireSpreadModel
from fusion.grid import LogOddsGrid
from fusion.grid_geometry import GridGeometry, GridGeometryError

SHAPE = (5, 5)
GEOM = GridGeometry((0.0, 0.0), 20.0, SHAPE)


def _one_fire(shape=SHAPE, at=(2, 2)) -> tuple[np.ndarray, np.ndarray]:
    f = np.zeros(shape)
    f[at] = 1.0
    return f, np.zeros(shape)


# -- closed forms ----------------------------------------------------------------------------------------
def test_one_burning_cell_ignites_each_neighbour_with_the_spread_probability():
    model = FireSpreadModel(burn=0.1, spread=0.07, neighbourhood=8)
    f, q = model.predict(*_one_fire())
    expected = np.zeros(SHAPE)
    expected[1:4, 1:4] = 0.07
    expected[2, 2] = 1.0  # (6.5): it keeps burning
    np.testing.assert_allclose(f, expected, rtol=1e-15, atol=0.0)
    np.testing.assert_allclose(q, 0.1 * expected, rtol=1e-15)  # (6.4): q' = beta f' from q = 0
    f4, _ = FireSpreadModel(spread=0.07, neighbourhood=4).predict(*_one_fire())
    assert f4[1, 2] == f4[3, 2] == f4[2, 1] == f4[2, 3] == pytest.approx(0.07)
    assert f4[1, 1] == f4[3, 3] == 0.0  # no diagonal spread with 4 neighbours


def test_two_sources_combine_by_noisy_or():
    f, q = np.zeros(SHAPE), np.zeros(SHAPE)
    f[2, 0], f[2, 2] = 0.6, 0.9
    q[2, 1] = 0.25
    w = 0.2
    out, _ = FireSpreadModel(burn=0.1, spread=w, neighbourhood=4).predict(f, q)
    assert out[2, 1] == pytest.approx((1 - 0.25) * (1 - (1 - w * 0.6) * (1 - w * 0.9)), rel=1e-14)


def test_wind_biases_spread_downwind():
    """Wind (0.5, 0) blows north: the cell north of the fire gets spread * 1.5, south spread * 0.5,
    and a diagonal neighbour spread * (1 + 0.5 / sqrt(2))."""
    model = FireSpreadModel(spread=0.1, wind=(0.5, 0.0))
    f, _ = model.predict(*_one_fire())
    assert f[3, 2] == pytest.approx(0.15) and f[1, 2] == pytest.approx(0.05)
    assert f[2, 1] == f[2, 3] == pytest.approx(0.1)
    assert f[3, 3] == pytest.approx(0.1 * (1 + 0.5 / math.sqrt(2)))
    east, _ = FireSpreadModel(spread=0.1, wind=(0.0, 2.0), neighbourhood=4).predict(*_one_fire())
    assert east[2, 3] == pytest.approx(0.3) and east[2, 1] == 0.0  # upwind clipped at zero


def test_burnt_cells_never_reignite():
    f, q = np.ones(SHAPE), np.zeros(SHAPE)
    q[:, 2] = 1.0  # a burnt firebreak in a burning field
    model = FireSpreadModel(burn=0.3, spread=0.9)
    for steps in (1, 5, 20):
        f2, q2 = model.predict(f, q, steps)
        assert np.all(f2[:, 2] == 0.0) and np.all(q2[:, 2] == 1.0)


def test_steps_compose_and_zero_steps_is_identity():
    model = FireSpreadModel(burn=0.2, spread=0.3, wind=(0.3, 0.3))
    rng = np.random.default_rng(1)
    f, q = rng.random(SHAPE), rng.random(SHAPE) * 0.5
    once = (f, q)
    for _ in range(3):
        once = model.predict(*once)
    np.testing.assert_allclose(model.predict(f, q, 3), once, rtol=1e-15)
    np.testing.assert_array_equal(model.predict(f, q, 0), (f, q))


@settings(max_examples=60, deadline=None)
@given(
    arrays(np.float64, (4, 6), elements=st.floats(0.0, 1.0)),
    arrays(np.float64, (4, 6), elements=st.floats(0.0, 1.0)),
    st.floats(0.0, 1.0), st.floats(0.0, 0.5), st.floats(-1.0, 1.0), st.floats(-1.0, 1.0),
    st.sampled_from([4, 8]), st.integers(1, 4),
)
def test_probabilities_stay_in_unit_interval_and_burnt_never_decreases(f, q, burn, spread, wn, we, hood, steps):
    model = FireSpreadModel(burn, spread, hood, (wn * 0.7, we * 0.7))  # |wind| < 1: spread * (1 + |w|) <= 1
    f2, q2 = model.predict(f, q, steps)
    assert f2.min() >= 0.0 and f2.max() <= 1.0 and q2.min() >= 0.0 and q2.max() <= 1.0
    assert np.all(q2 >= q - 1e-15)
    f1, _ = model.predict(f, q)
    assert np.all(f1 <= 1.0 - q + 1e-15)  # nothing burns in a burnt cell


# -- Monte Carlo oracle ------------------------------------------------------------------------------------
def _simulate_one_step(F, Q, model: FireSpreadModel, rng) -> tuple[np.ndarray, np.ndarray]:
    """The binary process of (6.4)-(6.6) for a batch of samples ``(S, rows, cols)``: each burning
    neighbour independently ignites an unburnt cell; a burning cell may then become burnt."""
    rows, cols = F.shape[1:]
    padded = np.pad(F, ((0, 0), (1, 1), (1, 1)))
    ignited = F.copy()
    for dr, dc, omega in model.neighbour_probabilities():
        neighbour = padded[:, 1 + dr : 1 + dr + rows, 1 + dc : 1 + dc + cols]
        ignited |= neighbour & (rng.random(F.shape) < omega)
    new_f = ignited & ~Q
    new_q = Q | (new_f & (rng.random(F.shape) < model.burn))
    return new_f, new_q


def test_one_step_prediction_matches_monte_carlo_of_the_binary_process():
    rng = np.random.default_rng(7)
    model = FireSpreadModel(burn=0.4, spread=0.3, neighbourhood=8, wind=(0.5, -0.3))
    f0, q0 = rng.uniform(0.0, 1.0, SHAPE), rng.uniform(0.0, 0.8, SHAPE)
    samples = 20_000
    F = rng.random((samples, *SHAPE)) < f0
    Q = rng.random((samples, *SHAPE)) < q0
    new_f, new_q = _simulate_one_step(F, Q, model, rng)
    f1, q1 = model.predict(f0, q0)
    for predicted, simulated in ((f1, new_f.mean(axis=0)), (q1, new_q.mean(axis=0))):
        se = np.sqrt(predicted * (1 - predicted) / samples) + 1e-12
        assert np.max(np.abs(simulated - predicted) / se) < 5.0
    # The literal reading of (6.3), q + (1 - q) beta f', is not the process's marginal:
    literal = q0 + (1 - q0) * model.burn * f1
    se = np.sqrt(literal * (1 - literal) / samples)
    assert np.max(np.abs(new_q.mean(axis=0) - literal) / se) > 10.0


# -- the two-layer belief ------------------------------------------------------------------------------------
def test_uniform_belief_reads_the_priors():
    belief = FireBelief.uniform(GEOM)
    np.testing.assert_allclose(belief.fire.probability(), FIRE_PRIOR)
    np.testing.assert_allclose(belief.burnt.probability(), BURNT_PRIOR)
    assert belief.geometry == GEOM


def test_belief_predict_is_the_model_on_the_read_probabilities():
    model = FireSpreadModel(burn=0.2, spread=0.1)
    llr = np.zeros(SHAPE)
    llr[2, 2] = 8.0
    belief = FireBelief.uniform(GEOM).update_fire(llr)
    assert belief.fire.probability()[2, 2] > 0.9 and belief.burnt.evidence.max() == 0.0
    f, q = model.predict(belief.fire.probability(), belief.burnt.probability(), 2)
    predicted = belief.predict(model, 2)
    np.testing.assert_allclose(predicted.fire.probability(), f, rtol=1e-12)
    np.testing.assert_allclose(predicted.burnt.probability(), q, rtol=1e-12)
    assert predicted.fire.prior == FIRE_PRIOR  # evidence stays relative to the layer's prior
    burnt = belief.update_burnt(np.full(SHAPE, 2.0))
    np.testing.assert_allclose(burnt.burnt.probability(), expit(np.log(0.01 / 0.99) + 2.0))


def test_prediction_does_not_commute_with_fusion():
    """Why FireBelief.predict is local: predicting two beliefs then fusing differs from fusing then
    predicting (the noisy-OR is nonlinear in the evidence), unlike the linear decay model."""
    model = FireSpreadModel(burn=0.2, spread=0.2)
    rng = np.random.default_rng(3)
    a = FireBelief.uniform(GEOM).update_fire(rng.normal(0, 2, SHAPE))
    b = FireBelief.uniform(GEOM).update_fire(rng.normal(0, 2, SHAPE))
    fused_then_predicted = FireBelief(a.fire.fuse(b.fire), a.burnt.fuse(b.burnt)).predict(model)
    predicted_then_fused = a.predict(model).fire.fuse(b.predict(model).fire)
    assert not fused_then_predicted.fire.allclose(predicted_then_fused, atol=1e-3)


# -- bad input -------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("kwargs,match", [
    ({"burn": -0.1}, "burn probability must be a probability"),
    ({"burn": 1.5}, "burn probability must be a probability"),
    ({"spread": float("nan")}, "spread probability must be a probability"),
    ({"spread": True}, "spread probability must be a probability"),
    ({"neighbourhood": 6}, "neighbourhood must be 4 or 8"),
    ({"wind": (float("nan"), 0.0)}, "wind must be two finite numbers"),
    ({"wind": (1.0,)}, "wind must be a \\(north, east\\) pair"),
    ({"spread": 0.6, "wind": (1.0, 0.0)}, "reaches 1.2 > 1"),
], ids=["negative-burn", "burn-above-1", "nan-spread", "bool-spread", "neighbourhood-6", "nan-wind", "1d-wind",
        "wind-makes-spread-above-1"])
def test_model_rejects(kwargs, match):
    with pytest.raises(ValueError, match=match):
        FireSpreadModel(**kwargs)


@pytest.mark.parametrize("args,match", [
    ((np.zeros((5, 5)), np.zeros((5, 4))), "differ in shape"),
    ((np.full((5, 5), np.nan), np.zeros((5, 5))), "fire contains non-finite"),
    ((np.zeros((5, 5)), np.full((5, 5), 1.5)), "burnt probabilities must lie in \\[0, 1\\]"),
    ((np.zeros(5), np.zeros(5)), "non-empty 2-D array"),
    ((np.zeros((5, 5)), np.zeros((5, 5)), -1), "steps must be a non-negative integer"),
    ((np.zeros((5, 5)), np.zeros((5, 5)), 1.5), "steps must be a non-negative integer"),
], ids=["layer-shape-mismatch", "nan-fire", "burnt-above-1", "1d-layers", "negative-steps", "float-steps"])
def test_model_predict_rejects(args, match):
    with pytest.raises(ValueError, match=match):
        FireSpreadModel().predict(*args)


def test_fire_belief_rejects_bad_layers_and_models():
    other = LogOddsGrid.uniform(GridGeometry((0.0, 0.0), 20.0, (5, 6)))
    with pytest.raises(GridGeometryError, match="geometry mismatch: shape"):
        FireBelief(LogOddsGrid.uniform(GEOM), other)
    with pytest.raises(ValueError, match="burnt layer must be a LogOddsGrid"):
        FireBelief(LogOddsGrid.uniform(GEOM), np.zeros(SHAPE))
    with pytest.raises(ValueError, match="model must be a FireSpreadModel"):
        FireBelief.uniform(GEOM).predict("spread")
    with pytest.raises(ValueError, match="prior must lie in \\(0, 1\\)"):
        FireBelief.uniform(GEOM, fire_prior=0.0)
    with pytest.raises(ValueError, match="llr must have shape"):
        FireBelief.uniform(GEOM).update_fire(np.zeros(3))
