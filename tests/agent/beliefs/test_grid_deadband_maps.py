"""Deadband deltas (``grid.delta_tolerance``) against full-grid exchange, through the whole fire-map exchange.

Four mappers exchange real grid messages (codec payloads, acknowledgements, channel filters, the Chernoff
rule on loops) with random local evidence (the harness of ``test_grids``), once with ``delta = false``
(every message a keyframe: the full-grid exchange) and once with deadband deltas, on the same evidence.
Oracles: the full-grid maps, and on a tree the centralized map (the plain sum of all evidence, Merino (4.4)).

Bounds, per cell, with ``M`` the largest magnitude of the cell's evidence among the maps compared: every
held copy is within ``q max(1, |b|)`` of its sender's value (agent.net.grid_codec); on a tree each of the
``N - 1`` links passes its sender's whole subtree through one held copy, so a map is within
``(N - 1) q max(1, M)`` of the centralized map. On loops the Chernoff rule is path dependent and has no such
a-priori bound; the test holds it to ``2 (N - 1) q max(1, M)`` (measured up to 4.9 q max(1, M) in these
runs at q = 0.05).
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

from agent.beliefs.grid_config import GridConfig
from tests.agent.beliefs.test_grids import Node, _exchange

RING = (("a", "b"), ("b", "c"), ("c", "d"), ("d", "a"))
FULL = (("a", "b"), ("a", "c"), ("a", "d"), ("b", "c"), ("b", "d"), ("c", "d"))
LINE = (("a", "b"), ("b", "c"), ("c", "d"))
STAR = (("a", "b"), ("b", "c"), ("b", "d"))


@functools.cache
def _run(edges: tuple, tree: bool, seed: int, **grid):
    """Every mapper's evidence after 20 rounds of observation and 10 of exchange only, the centralized
    evidence, the bytes sent and the fusion methods used (cached: the full-grid runs serve several tests)."""
    rng = np.random.default_rng(seed)
    nodes = {n: Node(n, GridConfig(policy="hybrid", cell=10.0, **grid)) for n in "abcd"}
    central = _exchange(nodes, edges, 30, rng, nodes["a"].mapper.beliefs.uniform(), tree=tree, observe_rounds=20)
    maps = np.array([node.mapper.grid.evidence for node in nodes.values()])
    sent = sum(sum(node.mapper.message_bytes) for node in nodes.values())
    methods = set().union(*(node.mapper.fusions for node in nodes.values()))
    return maps, central.evidence, sent, methods


@pytest.mark.parametrize("q", [0.01, 0.05])
@pytest.mark.parametrize("seed", [3, 4])
@pytest.mark.parametrize("name, edges", [("ring", RING), ("full", FULL)])
def test_on_loops_deadband_maps_stay_within_the_bound_of_full_grid_maps(name, edges, seed, q):
    deadband, _, deadband_bytes, methods = _run(edges, False, seed, delta_tolerance=q)
    full, _, full_bytes, _ = _run(edges, False, seed, delta=False)
    assert methods == {"ci"}  # the Chernoff rule on every loop link
    scale = q * np.maximum(1.0, np.maximum(np.abs(deadband), np.abs(full)).max(axis=0))
    deviation = np.abs(deadband - full) / scale
    assert 0.1 < deviation.max() <= 2 * (len("abcd") - 1)  # the deadband acts, and stays within the bound
    assert deadband_bytes < 0.6 * full_bytes


@pytest.mark.parametrize("q", [0.01, 0.05])
@pytest.mark.parametrize("name, edges", [("line", LINE), ("star", STAR)])
def test_on_a_tree_channel_filtered_deadband_maps_stay_within_the_bound_of_the_centralized_map(name, edges, q):
    for seed in (3, 4):
        maps, central, _, methods = _run(edges, True, seed, delta_tolerance=q)
        assert methods == {"exact"}  # the channel filters never fell back to intersection
        scale = q * np.maximum(1.0, np.maximum(np.abs(maps).max(axis=0), np.abs(central)))
        deviation = np.abs(maps - central) / scale
        assert 0.1 < deviation.max() <= len("abcd") - 1


@pytest.mark.parametrize("bad", [-0.1, 0.75, float("nan"), "0.05", True])
def test_a_bad_delta_tolerance_is_a_value_error_naming_the_key(bad):
    with pytest.raises(ValueError, match="grid.delta_tolerance"):
        GridConfig.from_dict({"delta_tolerance": bad})


def test_a_bad_delta_tolerance_in_a_scenario_names_the_key():
    from mesh_sim.scenario import load

    with pytest.raises(ValueError, match="grid.delta_tolerance"):
        load("fire", grid={"delta_tolerance": -0.02})


def test_beta_grids_refuse_a_deadband():
    """Counts held within a deadband make the tree's subtraction negative (measured: the exact filters fell
    back to intersection and a map strayed 84 q from the centralized one), so Beta grids keep q = 0."""
    with pytest.raises(ValueError, match="grid.delta_tolerance must be 0 for belief = 'beta'"):
        GridConfig(belief="beta", delta_tolerance=0.05)
    assert GridConfig(belief="beta").delta_tolerance == 0.0
