"""Shared builders for the fusion tests: graphs and noisy position sensors."""

from __future__ import annotations

import numpy as np

from fusion.measurement import PositionMeasurement


def random_tree(n: int, rng: np.random.Generator) -> list[tuple[int, int]]:
    """A uniformly shaped random tree: node i attaches to a random earlier node."""
    return [(i, int(rng.integers(0, i))) for i in range(1, n)]


def ring(n: int) -> list[tuple[int, int]]:
    return [(i, (i + 1) % n) for i in range(n)]


def complete(n: int) -> list[tuple[int, int]]:
    return [(i, j) for i in range(n) for j in range(i + 1, n)]


def position_update(state_dim: int, spatial_dims: int, truth_position, sigma: float, rng: np.random.Generator):
    """A function belief -> belief that applies one noisy position measurement of ``truth_position``."""
    model = PositionMeasurement(state_dim, sigma**2 * np.eye(spatial_dims), spatial_dims=spatial_dims)
    z = np.asarray(truth_position, float) + sigma * rng.standard_normal(spatial_dims)
    return lambda belief: belief.update(model.H, model.R_inv, z)
