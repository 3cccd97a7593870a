"""``Trajectory.state(offset)``: the marginal of one state of the window — from a Cholesky factor of the window
with that state last, or, when the window's information is singular, by block-tridiagonal elimination from
both ends (Merino (3.31)-(3.32)) — equals the dense Schur complement (Merino App. A) of the whole window, and a
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


def _unobserved_position(seed: int) -> Trajectory:
    """Velocity measurements only: the window's information is singular (its position is unknown), so the
    Cholesky path fails, while the velocity part of each state's marginal exists."""
    rng = np.random.default_rng(seed)
    belief = Trajectory.prior(MODEL, 5)
    for _ in range(6):
        H = np.hstack([np.zeros((3, 3)), np.eye(3)])
        belief = belief.update(H, np.eye(3), rng.normal(size=3), int(rng.integers(0, 8)))
    return belief


@pytest.mark.parametrize("offset", [0, 3, MODEL.window - 1])
def test_a_singular_window_is_eliminated_state_by_state_to_the_same_marginal(offset):
    """The two ways agree where both exist, and on a singular window the marginal still comes out (its
    position block empty of information), as the dense Schur complement of the other states says."""
    k = MODEL.window - 1 - offset
    observed = _observed(1)
    cholesky, chain = observed._marginal(k), observed._chain_marginal(k)
    np.testing.assert_allclose(cholesky.Y, chain.Y, rtol=1e-9, atol=1e-9 * np.abs(chain.Y).max())
    np.testing.assert_allclose(cholesky.y, chain.y, rtol=1e-9, atol=1e-9 * np.abs(chain.y).max())
    singular = _unobserved_position(2)
    assert np.linalg.matrix_rank(singular.Y) < MODEL.dim
    n = MODEL.state_dim
    dense = Gaussian(singular.y, singular.Y).marginal(range(k * n, (k + 1) * n))
    got = singular.state(offset)
    np.testing.assert_allclose(got.Y, dense.Y, rtol=1e-9, atol=1e-9 * np.abs(dense.Y).max())
    assert np.allclose(got.Y[:3, :3], 0.0, atol=1e-9 * np.abs(got.Y).max())  # the position: no information


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


def test_several_measurements_added_at_once_equal_one_update_each():
    """Trajectory.add_information (one copy for all) against Trajectory.update per measurement (Merino
    (3.29)-(3.30)), on position blocks of different states, two on the same state; bad terms are refused."""
    rng = np.random.default_rng(3)
    belief = _observed(3)
    offsets = [0, 2, 2, 7]
    H = np.hstack([np.eye(3), np.zeros((3, 3))])
    infos, vectors, sequential = [], [], belief
    for offset in offsets:
        A = rng.normal(size=(3, 3))
        R_inv = A @ A.T + np.eye(3)
        z = rng.normal(size=3)
        infos.append(R_inv)
        vectors.append(R_inv @ z)
        sequential = sequential.update(H, R_inv, z, offset)
    at_once = belief.add_information(offsets, np.array(infos), np.array(vectors))
    assert at_once.allclose(sequential, rtol=1e-12, atol=1e-12)
    assert belief.allclose(_observed(3))  # the belief itself is unchanged
    with pytest.raises(ValueError, match="outside the window"):
        belief.add_information([MODEL.window], np.array(infos[:1]), np.array(vectors[:1]))
    with pytest.raises(ValueError, match="non-finite"):
        belief.add_information([0], np.full((1, 3, 3), np.nan), np.array(vectors[:1]))
