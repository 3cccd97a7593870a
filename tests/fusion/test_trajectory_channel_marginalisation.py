"""Issue 11: marginalising the oldest state (Merino (3.31)-(3.32)) is not linear, so channel-filter
fusion of sliding-window trajectories (Merino (3.41)-(3.42)) is exact only while the information about
a state is common to the nodes (and to the stored channel beliefs) before that state leaves the window."""

import numpy as np
import pytest

from fusion.channel_filter import ChannelFilter
from fusion.motion import ConstantVelocity
from fusion.trajectory import Trajectory, TrajectoryModel

H = np.array([[1.0, 0.0]])
R_INV = np.array([[1.0 / 0.5**2]])


def _model(window):
    return TrajectoryModel(ConstantVelocity(1, 0.5), 1.0, window)


def test_marginalisation_does_not_commute_with_remove():
    model = _model(3)
    prior = Trajectory.prior(model, 2)
    vel = np.array([[0.0, 1.0]])
    c = prior.update(H, R_INV, [1.0], offset=2).update(vel, np.eye(1), [0.0], offset=2)  # common
    a = c.update(H, R_INV, [1.3], offset=2)  # c plus one more measurement on the oldest state
    # linear: a - c is the single measurement factor; after one slide it would still be prior-relative
    lhs = a.advanced_to(3).remove(c.advanced_to(3))
    rhs = prior.update(H, R_INV, [1.3], offset=2).advanced_to(3).remove(prior.advanced_to(3))
    assert not np.allclose(lhs.Y, rhs.Y)  # Schur complements are not linear: S(a) - S(c) != S(a - c)
    # and the difference of marginals is not the marginal of anything: it is not the "information a adds"
    assert np.max(np.abs(lhs.Y - rhs.Y)) > 1e-3


def _run_line(window, period, steps=40, seed=0):
    """Three nodes on a line A - B - C, each measuring a 1-D position every step; every ``period``
    steps A, B, C broadcast in that order (lossless, instantaneous). Returns the worst relative error of
    each node's newest-state marginal against the centralized filter, and the fallbacks."""
    rng = np.random.default_rng(seed)
    model = _model(window)
    nodes = ["A", "B", "C"]
    nbrs = {"A": ["B"], "B": ["A", "C"], "C": ["B"]}
    bel = {n: Trajectory.prior(model, 0) for n in nodes}
    cf = {n: ChannelFilter(Trajectory.prior(model, 0), "exact") for n in nodes}
    central = Trajectory.prior(model, 0)
    seq = {n: 0 for n in nodes}
    heard = {n: {} for n in nodes}  # heard[i][j] = last seq i received from j
    worst, fallbacks = 0.0, []
    truth = 0.0
    for k in range(1, steps):
        truth += 1.0
        central = central.advanced_to(k)
        for n in nodes:
            bel[n] = bel[n].advanced_to(k)
            z = truth + rng.normal(0, 0.5)
            bel[n] = bel[n].update(H, R_INV, [z])
            central = central.update(H, R_INV, [z])
        if k % period == 0:
            for n in nodes:
                seq[n] += 1
                msg, s = bel[n], seq[n]
                cf[n].on_send(msg, s)
                for j in nbrs[n]:
                    out = cf[j].on_receive(n, bel[j], msg, heard[n].get(j), seq=s)
                    if out.method != "exact":
                        fallbacks.append((k, n, j, out.reason))
                    bel[j] = out.fused
                    heard[j][n] = s
        if k % period == 0 and k > 2 * window:  # after a round B (the middle) holds every measurement
            c, g = central.current(), bel["B"].current()
            worst = max(worst, float(np.max(np.abs(g.Y - c.Y)) / np.max(np.abs(c.Y))),
                        float(np.max(np.abs(g.mean - c.mean))))
    return worst, fallbacks


@pytest.mark.parametrize("window,period", [(8, 1), (8, 2), (4, 2), (3, 3)])
def test_exact_when_information_becomes_common_inside_the_window(window, period):
    worst, fallbacks = _run_line(window=window, period=period)
    assert not fallbacks
    assert worst < 1e-9


@pytest.mark.parametrize("window,period", [(3, 4), (4, 5), (2, 3)])
def test_short_window_makes_exact_fusion_inexact(window, period):
    """A state leaves the window before the neighbours' information about it arrives: every term is
    marginalised with different information, and "exact" fusion no longer equals the centralized filter."""
    worst, fallbacks = _run_line(window=window, period=period)
    assert worst > 1e-4


def test_indefinite_bookkeeping_term_does_not_desynchronise_the_channel():
    """The neighbour's copy of our information ``A`` comes back slightly smaller in one direction (as
    marginalising at a different epoch does); ``m - A`` is then indefinite although the fused belief is
    fine: the channel must stay exact (it used to fall back to intersection for good)."""
    model = _model(3)
    prior = Trajectory.prior(model, 5)
    vel = np.array([[0.0, 1.0]])
    cf = ChannelFilter(prior, "exact")
    ours = prior.update(H, R_INV, [1.0], offset=0)  # our position information
    cf.on_send(ours, 1)
    theirs = prior.update(vel, np.eye(1), [0.5], offset=1)  # their velocity information only
    a_back = prior.update(H, 0.99 * R_INV, [0.99], offset=0)  # our information, as marginalised there
    m = theirs.fuse(a_back).remove(prior)
    with pytest.raises(ValueError):
        m.remove(ours.remove(prior))  # m - A is indefinite
    out = cf.on_receive("j", ours, m, acked_seq=1, seq=1)
    assert out.method == "exact" and cf.is_synchronized("j")
    assert np.allclose(out.fused.Y, m.Y) and np.allclose(out.fused.y, m.y)  # L + m - (B + A) with B = prior


def test_acknowledgement_of_a_message_sent_before_this_filter_existed_means_nothing_of_ours():
    """A node deletes a track and later starts a new one for the same target: the neighbour still
    acknowledges a message that carried the old track. The new filter sent nothing then, so the neighbour
    holds nothing of its belief (common information = B); an unknown later message stays a fallback."""
    model = _model(3)
    prior = Trajectory.prior(model, 5)
    theirs = prior.update(H, R_INV, [2.0])
    cf = ChannelFilter(prior, "exact")
    out = cf.on_receive("j", prior, theirs, acked_seq=7, seq=1)  # our message 7 carried another track
    assert out.method == "exact" and np.allclose(out.fused.Y, theirs.Y)
    cf.on_send(out.fused, 10)
    assert cf.on_receive("j", out.fused, theirs, acked_seq=8, seq=2).method == "exact"
    assert cf.on_receive("j", out.fused, theirs, acked_seq=11, seq=3).method == "ci"  # unknown: not ours
