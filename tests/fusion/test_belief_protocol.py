"""fusion.belief: every belief kind the channel filter serves declares the algebra, and one
ChannelFilter fuses each of them exactly on a two-node tree (the centralized result is the oracle)."""

from __future__ import annotations

import numpy as np
import pytest

from fusion.belief import Belief
from fusion.channel_filter import ChannelFilter
from fusion.gaussian import Gaussian
from fusion.grid import BetaGrid, LogOddsGrid
from fusion.grid_geometry import GridGeometry
from fusion.grid_intersect import chernoff_intersect
from fusion.motion import DampedVelocity
from fusion.trajectory import Trajectory, TrajectoryModel

GEOMETRY = GridGeometry.covering((0.0, 20.0), (0.0, 20.0), 5.0)


def _gaussian(rng):
    A = rng.standard_normal((3, 3))
    return Gaussian.from_info(rng.standard_normal(3), A @ A.T + 3 * np.eye(3))


def _trajectory(rng):
    model = TrajectoryModel(DampedVelocity(3, 5.0, 10.0, 0.3), 0.2, 4)
    prior = Trajectory.prior(model, 0)
    H = np.hstack([np.eye(3), np.zeros((3, 3))])
    return prior.update(H, np.eye(3), rng.standard_normal(3)), prior


KINDS = {
    "gaussian": lambda rng: (_gaussian(rng), Gaussian.from_info(np.zeros(3), np.eye(3) * 1e-3)),
    "trajectory": _trajectory,
    "logodds": lambda rng: (LogOddsGrid(GEOMETRY, rng.normal(size=GEOMETRY.shape)), LogOddsGrid.uniform(GEOMETRY)),
    "beta": lambda rng: (BetaGrid(GEOMETRY, rng.uniform(0, 3, GEOMETRY.shape), rng.uniform(0, 3, GEOMETRY.shape)),
                         BetaGrid.uniform(GEOMETRY)),
}


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_every_belief_kind_implements_the_algebra(kind):
    belief, prior = KINDS[kind](np.random.default_rng(1))
    assert isinstance(belief, Belief)
    assert isinstance(prior, Belief)


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_fuse_then_remove_is_the_identity(kind):
    rng = np.random.default_rng(2)
    a, _ = KINDS[kind](rng)
    b, _ = KINDS[kind](rng)
    back = a.fuse(b).remove(b)
    for name in ("y", "Y", "evidence", "alpha", "beta"):
        if hasattr(a, name):
            np.testing.assert_allclose(getattr(back, name), getattr(a, name), atol=1e-9)


def _values(belief) -> np.ndarray:
    parts = [getattr(belief, n) for n in ("y", "Y", "evidence", "alpha", "beta") if hasattr(belief, n)]
    return np.concatenate([np.ravel(p) for p in parts])


@pytest.mark.parametrize("kind", ["trajectory", "logodds", "beta"])
def test_one_channel_filter_is_exact_on_a_two_node_tree_for_every_kind(kind):
    """a and b each hold a prior plus their own evidence; a sends, b fuses, b sends back, a fuses: both
    end with the centralized belief prior + e_a + e_b (the oracle), the prior counted once."""
    rng = np.random.default_rng(3)
    first, prior = KINDS[kind](rng)
    second, _ = KINDS[kind](rng)
    a, b = first, second
    central = first.fuse(second).remove(prior)
    rule = chernoff_intersect if kind in ("logodds", "beta") else None
    fa, fb = ChannelFilter(prior, "exact", rule), ChannelFilter(prior, "exact", rule)
    fa.on_send(a, 1)
    out_b = fb.on_receive("a", b, a, None, 1)
    assert out_b.method == "exact"
    b = out_b.fused
    fb.on_send(b, 1)
    out_a = fa.on_receive("b", a, b, 1, 1)
    assert out_a.method == "exact"
    np.testing.assert_allclose(_values(out_a.fused), _values(central), atol=1e-9)
    np.testing.assert_allclose(_values(b), _values(central), atol=1e-9)


def test_an_object_without_the_algebra_is_not_a_belief():
    """Bad input: a plain array has no fuse/remove/epoch, so it does not pass as a Belief."""
    assert not isinstance(np.zeros(3), Belief)
