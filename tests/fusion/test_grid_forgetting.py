"""Forgetting on a common clock (fusion.grid_forgetting): the closed form, the tick protocol, and exact
decentralized fusion on a tree against a centralized map that forgets every frame by its own age."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fusion.channel_filter import ChannelFilter
from fusion.grid import BetaGrid, LogOddsGrid
from fusion.grid_forgetting import Forgetting
from fusion.grid_geometry import GridGeometry
from fusion.grid_intersect import chernoff_intersect

GEOM = GridGeometry((0.0, 0.0), 1.0, (6, 7))
FORGET = Forgetting(half_life=4.0, tick=0.5)


def test_factor_and_epoch_are_the_closed_form():
    assert FORGET.factor(0) == 1.0
    assert FORGET.factor(8) == pytest.approx(0.5)  # 8 ticks of 0.5 s = one half-life
    assert FORGET.factor(3) == pytest.approx(math.exp(-1.5 * math.log(2) / 4.0))
    # a time a rounding error short of a tick boundary (0.1 * 10 steps of 0.1 s) lands on it
    assert [FORGET.epoch_of(t) for t in (0.0, 0.49, 0.5, 1.0 - 1e-12, 0.99, 7.3)] == [0, 0, 1, 2, 1, 14]


@pytest.mark.parametrize("kwargs, match", [
    ({"half_life": 0.0}, "half_life"), ({"half_life": -3.0}, "half_life"), ({"half_life": math.inf}, "half_life"),
    ({"half_life": "10"}, "half_life"), ({"half_life": True}, "half_life"), ({"half_life": 5.0, "tick": 0.0}, "tick"),
])
def test_bad_forgetting_is_a_clear_error(kwargs, match):
    with pytest.raises(ValueError, match=match):
        Forgetting(**kwargs)


@pytest.mark.parametrize("call, match", [
    (lambda: FORGET.factor(-1), "ticks"), (lambda: FORGET.factor(1.5), "ticks"),
    (lambda: FORGET.epoch_of(math.nan), "time"),
    (lambda: LogOddsGrid(GEOM, epoch=3), "static grid"),
    (lambda: LogOddsGrid(GEOM, forgetting=FORGET, epoch=-1), "epoch"),
    (lambda: BetaGrid(GEOM, forgetting="fast"), "Forgetting"),
    (lambda: LogOddsGrid.uniform(GEOM, forgetting=FORGET, epoch=5).advanced_to(4), "only forward"),
])
def test_bad_ticks_are_clear_errors(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_advancing_multiplies_log_odds_evidence_and_beta_counts_and_keeps_the_prior():
    rng = np.random.default_rng(0)
    e = rng.normal(0.0, 3.0, GEOM.shape)
    grid = LogOddsGrid(GEOM, e, prior=0.3, forgetting=FORGET, epoch=2).advanced_to(10)
    assert grid.epoch == 10 and np.allclose(grid.evidence, 0.5 * e)
    assert LogOddsGrid.uniform(GEOM, 0.3, forgetting=FORGET).advanced_to(99).allclose(
        LogOddsGrid.uniform(GEOM, 0.3, forgetting=FORGET, epoch=99))
    a, b = rng.uniform(0, 5, GEOM.shape), rng.uniform(0, 5, GEOM.shape)
    beta = BetaGrid(GEOM, a, b, forgetting=FORGET).advanced_to(16)
    assert np.allclose(beta.alpha, 0.25 * a) and np.allclose(beta.beta, 0.25 * b)
    static = LogOddsGrid(GEOM, e)
    assert static.advanced_to(50) is static and static.epoch is None


def test_grids_combine_only_at_one_tick_but_kl_reads_at_the_newer():
    a = LogOddsGrid(GEOM, np.ones(GEOM.shape), forgetting=FORGET, epoch=0)
    b = LogOddsGrid(GEOM, np.ones(GEOM.shape), forgetting=FORGET, epoch=8)
    with pytest.raises(ValueError, match="epoch mismatch"):
        a.fuse(b)
    assert a.kl_divergence(b) == pytest.approx(a.advanced_to(8).kl_divergence(b))
    assert a.kl_divergence(b) > 0.0  # a forgot half of its evidence by b's tick: they differ


def _centralized(frames, epoch, kind):
    """The centralized forgetting map in closed form: every frame's evidence times ``factor(age)``."""
    grid = LogOddsGrid.uniform(GEOM) if kind == "log-odds" else BetaGrid.uniform(GEOM)
    for k, values in frames:
        grid = grid.update(*(FORGET.factor(epoch - k) * v for v in values))
    return grid


def _exchange(beliefs, filters, seqs, epoch):
    """Every node on the line broadcasts its grid at ``epoch``; each neighbour fuses it. All send before
    anyone receives, so a message acknowledges the receiver's previous round (``None`` in the first)."""
    sent = [b.advanced_to(epoch) for b in beliefs]
    for i, belief in enumerate(sent):
        seqs[i] += 1
        filters[i].on_send(belief, seqs[i])
    methods = set()
    for i in range(len(beliefs)):
        for j in (i - 1, i + 1):
            if 0 <= j < len(beliefs):
                acked = seqs[j] - 1 or None
                out = filters[j].on_receive(i, beliefs[j].advanced_to(epoch), sent[i], acked, seqs[i])
                beliefs[j] = out.fused
                methods.add(out.method)
    return methods


@pytest.mark.parametrize("kind", ["log-odds", "beta"])
def test_on_a_tree_channel_filters_with_forgetting_equal_the_centralized_forgetting_map(kind):
    """Nodes on a line observe at their own ticks and exchange; each grid forgets, the channel filters
    advance the common information alike: every map equals the closed-form centralized map."""
    rng = np.random.default_rng(4)
    n, grid_type = 4, LogOddsGrid if kind == "log-odds" else BetaGrid
    beliefs = [grid_type.uniform(GEOM, forgetting=FORGET) for _ in range(n)]
    filters = [ChannelFilter(grid_type.uniform(GEOM, forgetting=FORGET), "exact", chernoff_intersect)
               for _ in range(n)]
    frames, seqs, epoch = [], [0] * n, 0
    for _ in range(12):
        epoch += int(rng.integers(1, 4))
        for i in range(n):
            seen = rng.random(GEOM.shape) < 0.5
            values = ((np.where(seen, rng.normal(0, 2, GEOM.shape), 0.0),) if kind == "log-odds" else
                      tuple(np.where(seen, rng.uniform(0, 1, GEOM.shape), 0.0) for _ in range(2)))
            beliefs[i] = beliefs[i].advanced_to(epoch).update(*values)
            frames.append((epoch, values))
        assert _exchange(beliefs, filters, seqs, epoch) == {"exact"}
    for _ in range(n):  # let everything travel the line, nobody observing
        epoch += 1
        assert _exchange(beliefs, filters, seqs, epoch) == {"exact"}
    oracle = _centralized(frames, epoch, kind)
    static = _centralized([(epoch, v) for _, v in frames], epoch, kind)  # the same evidence, never forgotten
    for belief in beliefs:
        assert belief.epoch == epoch
        assert np.allclose(belief.probability(), oracle.probability(), atol=1e-9)
        assert not np.allclose(belief.probability(), static.probability(), atol=1e-3)  # forgetting did act
