"""``Trajectory.state(offset)``: the marginal of one state of the window by block-tridiagonal elimination from
both ends (Merino (3.31)-(3.32)) equals the dense Schur complement (Merino App. A) of the whole window, and a
belief computes each marginal once."""

import numpy as np
import pytest

from fusion.gaussian import Gaussian, UninformativeBeliefError
from fusion.motion import DampedVelocity
from fusion.trajectory import Trajectory, TrajectoryModel

MODEL = TrajectoryModel(DampedVelocity(3, 2.0, 10.0, 0.3), 0.2, 8)


def _observed(seed: int) -> Trajectory:
    rng = np.random.default_rng(seed)
    belief = Trajectory.prior(MODEL, 5)
    for _ in range(20):
        H = rng.normal(size=(2, 6))
        belief = belief.update(H, np.diag(rng.uniform(0.5, 4.0, 2)), rng.normal(size=2), int(rng.integers(0, 8)))
    return belief


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("offset", range(MODEL.window))
def test_each_state_marginal_equals_the_dense_schur_complement(seed, offset):
    belief = _observed(seed)
    n, k = MODEL.state_dim, MODEL.window - 1 - offset
    dense = Gaussian(belief.y, belief.Y).marginal(range(k * n, (k + 1) * n))
    banded = belief.state(offset)
    np.testing.assert_allclose(banded.Y, dense.Y, rtol=1e-9, atol=1e-9 * np.abs(dense.Y).max())
    np.testing.assert_allclose(banded.mean, dense.mean, rtol=1e-9, atol=1e-9)


def test_a_marginal_is_computed_once_per_belief():
    belief = _observed(0)
    assert belief.state(3) is belief.state(3)
    assert belief.current() is belief.state(0)
    assert belief.update(np.eye(6)[:2], np.eye(2), [0.0, 0.0], 3).state(3) is not belief.state(3)


def test_an_offset_outside_the_window_and_a_singular_state_are_errors():
    belief = _observed(0)
    with pytest.raises(ValueError, match="outside the window"):
        belief.state(MODEL.window)
    singular = Trajectory(np.zeros(MODEL.dim), np.zeros((MODEL.dim, MODEL.dim)), 0, MODEL)  # no information
    with pytest.raises(UninformativeBeliefError, match="singular information"):
        singular.state(2)
