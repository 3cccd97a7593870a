"""Link emulation (agent/net/link_emulator.py): statistics against closed forms, determinism, the gate, errors.

Statistical tests use fixed seeds; every tolerance is derived from the sampling distribution (a
binomial 99.9 % interval, or about 4.5 standard errors), so each test fails if the claim is false.
"""

import math
import random

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from agent.net.link_emulator import GilbertElliottChain, LinkEmulator, Shaper, TokenBucket, Verdict, uniform
from agent.net.link_plan import GilbertElliott, LinkPlan

AGENTS = ["uav0", "uav1", "uav2", "uav3"]


def plan(default=None, seed=7, **extra):
    return {"agents": AGENTS, "seed": seed, "default": default or {}, **extra}


def losses(default, n, seed=7, src="uav1", me="uav0", start=0):
    """Loss indicators for seqs start..start+n-1 on src -> me (no rate, always up)."""
    em = LinkEmulator(me, plan(default, seed))
    return np.array([em.admit(src, s, 100, 0.0).cause == "loss" for s in range(start, start + n)])


def runs(lost: np.ndarray) -> np.ndarray:
    """Lengths of the runs of consecutive losses."""
    padded = np.concatenate([[0], lost.astype(int), [0]])
    edges = np.flatnonzero(np.diff(padded))
    return edges[1::2] - edges[0::2]


# ---- Bernoulli loss --------------------------------------------------------------------------------


@pytest.mark.parametrize("p", [0.0014, 0.1, 0.3])
def test_bernoulli_loss_within_binomial_interval(p):
    n = 20_000
    lost = losses({"loss": p}, n).sum()
    lo, hi = stats.binom.interval(0.999, n, p)
    assert lo <= lost <= hi, (lost / n, p)


def test_no_loss_and_certain_loss():
    assert not losses({"loss": 0.0}, 2000).any()
    assert losses({"loss": 1.0}, 2000).all()


# ---- Gilbert–Elliott ---------------------------------------------------------------------------------


def ge_loss_std(ge: GilbertElliott, n: int) -> float:
    """Standard error of the mean loss of a stationary GE chain over n messages (exact for a 2-state chain).

    Losses are independent given the states, so cov(l_i, l_{i+k}) = Δ² π_b π_g λ^k with Δ = (1-h) - (1-k)
    and λ = 1 - p - r.
    """
    m, pb = ge.mean_loss, ge.stationary_bad
    lam = 1.0 - ge.p - ge.r
    delta = ge.one_minus_h - ge.one_minus_k
    var = m * (1 - m) + 2 * delta**2 * pb * (1 - pb) * lam / (1 - lam)
    return math.sqrt(var / n)


@pytest.mark.parametrize(
    "ge",
    [GilbertElliott(p=0.05, r=0.25), GilbertElliott(p=0.02, r=0.10, one_minus_h=0.7, one_minus_k=0.02)],
)
def test_gilbert_elliott_mean_loss_matches_closed_form(ge):
    n = 50_000
    lost = losses({"ge": ge.to_dict()}, n)
    expected = ge.stationary_bad * ge.one_minus_h + (1 - ge.stationary_bad) * ge.one_minus_k
    assert ge.mean_loss == pytest.approx(expected)
    assert abs(lost.mean() - expected) < 4.5 * ge_loss_std(ge, n), (lost.mean(), expected)


def test_gilbert_elliott_mean_burst_is_one_over_r():
    ge = GilbertElliott(p=0.05, r=0.25)  # 1-h = 1, 1-k = 0: a bad period is a loss burst
    n = 50_000
    bursts = runs(losses({"ge": ge.to_dict()}, n))
    expected = 1 / ge.r
    se = math.sqrt((1 - ge.r) / ge.r**2 / len(bursts))  # geometric(r) lengths
    assert abs(bursts.mean() - expected) < 4.5 * se, (bursts.mean(), expected, len(bursts))
    # bursty, unlike Bernoulli at the same mean loss (mean run 1/(1-m) = 1.2)
    bern = runs(losses({"loss": ge.mean_loss}, n))
    assert bern.mean() < 1.3 < bursts.mean()


def test_gilbert_elliott_never_leaves_good_state_with_p_zero():
    assert not losses({"ge": {"p": 0.0, "r": 0.0}}, 5000).any()
    assert GilbertElliott(0.0, 0.0).mean_loss == 0.0


# ---- delay and jitter ---------------------------------------------------------------------------------


def delays_ms(default, n, seed=7):
    em = LinkEmulator("uav0", plan(default, seed))
    out = []
    for s in range(n):
        v = em.admit("uav1", s, 100, 10.0)
        out.append((v.deliver_at - 10.0) * 1000.0)
    return np.array(out)


def test_delay_mean_and_std_match_delay_and_jitter():
    n, delay, jitter = 20_000, 50.0, 10.0
    d = delays_ms({"delay_ms": delay, "jitter_ms": jitter}, n)
    assert abs(d.mean() - delay) < 4.5 * jitter / math.sqrt(n), d.mean()
    assert abs(d.std(ddof=1) - jitter) < 4.5 * jitter / math.sqrt(2 * n), d.std(ddof=1)
    assert stats.kstest((d - delay) / jitter, "norm").pvalue > 1e-3  # normal, not uniform


def test_jitter_clipped_at_zero():
    n = 20_000
    d = delays_ms({"delay_ms": 1.0, "jitter_ms": 5.0}, n)
    assert d.min() >= 0.0
    at_zero = int((d == 0.0).sum())
    lo, hi = stats.binom.interval(0.999, n, stats.norm.cdf(-1.0 / 5.0))
    assert lo <= at_zero <= hi


def test_fixed_delay_without_jitter():
    em = LinkEmulator("uav0", plan({"delay_ms": 2.0}))
    assert em.admit("uav1", 1, 10, 3.0) == Verdict(3.002, None)
    assert LinkEmulator("uav0", plan()).admit("uav1", 1, 10, 3.0).deliver_at == 3.0


# ---- token bucket ----------------------------------------------------------------------------------


def offered_load(rate, seconds, overload, seed=3):
    rng = np.random.default_rng(seed)
    sizes = rng.integers(200, 1500, size=int(2 * overload * rate * seconds / 850))
    gaps = rng.exponential(sizes.mean() / (overload * rate), size=len(sizes))
    t = np.cumsum(gaps)
    keep = t <= seconds
    return t[keep], sizes[keep]


def test_token_bucket_throughput_equals_rate_and_never_exceeds_envelope():
    rate, burst, seconds = 100_000.0, 20_000.0, 200.0
    t, sizes = offered_load(rate, seconds, overload=2.0)
    bucket = TokenBucket(rate, burst)
    ok = np.array([bucket.admit(int(s), float(x)) for s, x in zip(sizes, t, strict=True)])
    admitted = np.where(ok, sizes, 0).astype(float)
    cum = np.cumsum(admitted)
    # over every interval [t_j, t_i] (j <= i): admitted bytes <= burst + rate * (t_i - t_j)
    before = cum - admitted  # admitted strictly before message j
    worst_start = np.maximum.accumulate(rate * t - before)
    excess = cum - rate * t + worst_start - burst
    assert excess.max() <= 1e-6
    throughput = (cum[-1] - burst) / (t[-1] - t[0])
    assert throughput == pytest.approx(rate, rel=0.03), throughput
    assert cum[-1] / sizes.sum() < 0.6  # it really was overloaded (2x the rate offered)


def test_token_bucket_message_larger_than_burst_never_passes():
    bucket = TokenBucket(rate=1000.0, burst=2000.0)
    assert not any(bucket.admit(2001, t) for t in np.linspace(0, 1e6, 50))
    assert bucket.admit(2000, 1e6 + 1)


def test_token_bucket_refill_and_clock_not_backwards():
    bucket = TokenBucket(rate=1000.0, burst=2000.0)
    assert bucket.admit(2000, 0.0)
    assert not bucket.admit(1, 0.0)
    assert not bucket.admit(500, -5.0)  # an earlier stamp refills nothing
    assert bucket.admit(500, 0.5)
    assert not bucket.admit(1, 0.5)


def test_emulator_rate_drops_and_counters():
    p = plan({"rate": 10_000, "burst": 5_000})
    em = LinkEmulator("uav0", p)
    verdicts = [em.admit("uav1", s, 1000, 0.0) for s in range(10)]
    assert [v.cause for v in verdicts] == [None] * 5 + ["rate"] * 5
    assert em.admit("uav1", 10, 1000, 0.1).delivered  # 0.1 s refills 1000 bytes
    assert em.delivered["uav1"] == 6 and em.bytes_delivered["uav1"] == 6000
    assert em.drops[("uav1", "rate")] == 5
    assert em.admit("uav2", 0, 1000, 0.0).delivered  # each link has its own bucket



# ---- shaper (a token bucket with a queue: tc-tbf) ------------------------------------------------------


def tbf_by_time_steps(rate, burst, queue, arrivals, dt=1e-4):
    """An independent tbf: time advances in steps of ``dt``; each step the bucket earns ``rate · dt`` (up to
    ``burst``), arrivals of the step join the FIFO if it has room (else are dropped), and the head leaves while the
    bucket holds its size. Returns each message's departure (None when dropped), within ``dt``."""
    tokens, fifo, out = burst, [], [None] * len(arrivals)
    order = sorted(range(len(arrivals)), key=lambda i: arrivals[i][1])
    step, k, end = 0, 0, max(t for _, t in arrivals) + 2 * (queue + burst) / rate + 1.0
    while step * dt <= end:
        now = step * dt
        while k < len(order) and arrivals[order[k]][1] <= now:
            i = order[k]
            size = arrivals[i][0]
            if not fifo and size <= tokens:
                tokens -= size
                out[i] = now
            elif sum(arrivals[j][0] for j in fifo) + size <= queue and size <= burst:
                fifo.append(i)
            k += 1
        while fifo and arrivals[fifo[0]][0] <= tokens:
            tokens -= arrivals[fifo[0]][0]
            out[fifo.pop(0)] = now
        tokens = min(burst, tokens + rate * dt)
        step += 1
    return out


def test_shaper_departures_match_a_time_stepped_tbf():
    rng = np.random.default_rng(5)
    rate, burst, queue = 2000.0, 3000.0, 1600.0
    t = np.round(np.cumsum(rng.exponential(0.25, size=60)), 4)  # ~1.4x the rate offered, on the oracle's grid
    sizes = rng.integers(100, 900, size=len(t))
    arrivals = list(zip(sizes.tolist(), t.tolist(), strict=True))
    shaper = Shaper(rate, burst, queue)
    got = [shaper.depart(size, at) for size, at in arrivals]
    want = tbf_by_time_steps(rate, burst, queue, arrivals)
    assert [g is None for g in got] == [w is None for w in want]
    assert 3 <= sum(g is None for g in got) and sum(g is not None and g > at for g, (_, at) in zip(got, arrivals,
                                                                                                    strict=True)) >= 5
    assert max(abs(g - w) for g, w in zip(got, want, strict=True) if g is not None) < 2e-4


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(1, 2500), st.floats(0.0, 0.5)), min_size=1, max_size=40))
def test_shaper_without_queue_is_the_policer(messages):
    """Bad input for a shaper with no queue: any message that finds too few tokens must be dropped, never held."""
    shaper, bucket, t = Shaper(1000.0, 2000.0, 0.0), TokenBucket(1000.0, 2000.0), 0.0
    for size, gap in messages:
        t += gap
        assert (shaper.depart(size, t) == t) is bucket.admit(size, t)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(1, 1500), st.floats(0.0, 0.3)), min_size=1, max_size=60))
def test_shaper_keeps_order_its_queue_and_the_envelope(messages):
    rate, burst, queue = 1000.0, 2000.0, 1600.0
    shaper, t, sent = Shaper(rate, burst, queue), 0.0, []
    for size, gap in messages:
        t += gap
        waiting = sum(s for s, d in sent if d > t)
        d = shaper.depart(size, t)
        if d is None:
            assert waiting + size > queue or (size > burst)
            continue
        assert d >= t and (not sent or d >= sent[-1][1])  # in order, never before it arrived
        assert d - t <= (waiting + size) / rate + 1e-9  # waits at most for the bytes ahead of it and its own
        if d > t:
            assert waiting + size <= queue
        sent.append((size, d))
    # the bytes leaving over any window [d_j, d_i] stay within burst + rate · (d_i - d_j)
    for j in range(len(sent)):
        for i in range(j, len(sent)):
            assert sum(s for s, _ in sent[j:i + 1]) <= burst + rate * (sent[i][1] - sent[j][1]) + 1e-6


def test_emulator_queue_delays_then_drops():
    """A 1,000-byte message finding the 5,000-byte bucket empty waits 0.1 s at 10 kB/s; the queue holds two."""
    em = LinkEmulator("uav0", plan({"rate": 10_000, "burst": 5_000, "queue": 2_000, "delay_ms": 2.0}))
    verdicts = [em.admit("uav1", s, 1000, 0.0) for s in range(8)]
    assert [v.cause for v in verdicts] == [None] * 7 + ["rate"]
    assert [v.deliver_at for v in verdicts[:7]] == pytest.approx([0.002] * 5 + [0.102, 0.202])
    assert em.admit("uav1", 8, 1000, 0.15).deliver_at == pytest.approx(0.302)  # behind the one still waiting
    assert em.drops[("uav1", "rate")] == 1


def test_sender_budget_is_tightest_outgoing_rate():
    links = [{"src": "uav0", "dst": "uav2", "rate": 5e5}, {"src": "uav3", "dst": "uav0", "rate": 1e3}]
    p = plan({"rate": 1e6}, links=links)
    em = LinkEmulator("uav0", p)
    assert em.sender_budget() == 5e5
    assert em.sender_budget("uav1") == 1e6
    assert LinkPlan.from_dict(plan()).sender_budget("uav0") is None


# ---- determinism ------------------------------------------------------------------------------------


def reference(default, seqs, seed=7):
    em = LinkEmulator("uav0", plan(default, seed))
    return {s: em.admit("uav1", s, 100, 1.0) for s in sorted(seqs)}


MIXED = {"loss": 0.2, "delay_ms": 20.0, "jitter_ms": 5.0}
GE = {"ge": {"p": 0.1, "r": 0.3, "one_minus_h": 0.9, "one_minus_k": 0.05}, "delay_ms": 5.0, "jitter_ms": 2.0}
SEQS = range(0, 10_000)  # spans several Gilbert–Elliott blocks
GE_REF = reference(GE, SEQS)


@pytest.mark.parametrize("default", [MIXED, GE], ids=["bernoulli", "gilbert-elliott"])
def test_verdict_independent_of_order_and_gaps(default):
    ref = reference(default, SEQS)
    rng = random.Random(11)
    for _ in range(3):
        subset = rng.sample(list(SEQS), 3000)  # gaps, and a random order
        em = LinkEmulator("uav0", plan(default))
        assert all(em.admit("uav1", s, 100, 1.0) == ref[s] for s in subset)
    em = LinkEmulator("uav0", plan(default))
    assert all(em.admit("uav1", s, 100, 1.0) == ref[s] for s in reversed(SEQS))


@settings(max_examples=40, deadline=None)
@given(st.lists(st.integers(0, 9_999), min_size=1, max_size=60))
def test_gilbert_elliott_verdicts_depend_on_seq_only(seqs):
    em = LinkEmulator("uav0", plan(GE))
    assert all(em.admit("uav1", s, 100, 1.0) == GE_REF[s] for s in seqs)


def test_huge_seq_is_cheap_and_deterministic():
    big = 2**63 + 12_345
    a = [LinkEmulator("uav0", plan(GE)).admit("uav1", big, 100, 1.0) for _ in range(2)]
    assert a[0] == a[1]


def test_seeds_and_links_are_independent():
    a = losses({"loss": 0.3}, 2000, seed=1)
    b = losses({"loss": 0.3}, 2000, seed=2)
    c = losses({"loss": 0.3}, 2000, seed=1, src="uav2")
    d = losses({"loss": 0.3}, 2000, seed=1, me="uav2", src="uav1")
    for other in (b, c, d):
        agree = (a == other).mean()
        assert abs(agree - (0.3**2 + 0.7**2)) < 0.05  # as independent draws agree, not identical
    ge_a = losses({"ge": GE["ge"]}, 2000, seed=1)
    ge_b = losses({"ge": GE["ge"]}, 2000, seed=2)
    assert (ge_a != ge_b).any()


def test_uniform_is_a_deterministic_hash():
    u = uniform(1, "a", "b", 5, "loss")
    assert 0.0 <= u < 1.0 and u == uniform(1, "a", "b", 5, "loss")
    assert len({uniform(1, "a", "b", 5, s) for s in ("loss", "jitter", "ge-step")}) == 3
    assert uniform(1, "a|b", "c", 5, "loss") != uniform(1, "a", "b|c", 5, "loss")
    draws = np.array([uniform(9, "x", "y", s, "loss") for s in range(20_000)])
    assert stats.kstest(draws, "uniform").pvalue > 1e-3


def test_chain_block_anchor_keeps_stationary_marginal():
    ge = GilbertElliott(p=0.05, r=0.25)
    chain = GilbertElliottChain(ge, 3, "a", "b")
    anchors = np.array([chain.bad(k * chain.BLOCK) for k in range(4000)])
    lo, hi = stats.binom.interval(0.999, len(anchors), ge.stationary_bad)
    assert lo <= anchors.sum() <= hi


# ---- topology: phases, node loss, range -----------------------------------------------------------


def test_phases_and_node_loss_honoured_at_the_stamp():
    p = plan(
        phases=[
            {"t": 0.0, "edges": "all"},
            {"t": 10.0, "edges": [["uav0", "uav1"]]},
            {"t": 20.0, "edges": "all", "cut": [["uav2", "uav0"]]},
        ],
        down_nodes=[{"t": 25.0, "node": "uav3"}],
    )
    em = LinkEmulator("uav0", p)
    assert em.admit("uav2", 1, 10, 9.999).delivered
    assert em.admit("uav2", 2, 10, 10.0).cause == "down"
    assert em.admit("uav1", 1, 10, 15.0).delivered
    assert em.admit("uav2", 3, 10, 20.0).cause == "down"  # cut one way...
    assert LinkEmulator("uav2", p).admit("uav0", 1, 10, 20.0).delivered  # ...not the other
    assert em.admit("uav3", 1, 10, 24.9).delivered
    assert em.admit("uav3", 2, 10, 25.0).cause == "down"
    assert LinkEmulator("uav3", p).admit("uav1", 5, 10, 30.0).cause == "down"  # a lost node hears nothing
    assert em.drops[("uav2", "down")] == 2 and em.drops[("uav3", "down")] == 1
    lp = LinkPlan.from_dict(p)
    assert lp.edges_at(-1.0) == lp.edges_at(0.0) and len(lp.edges_at(0.0)) == 6
    assert lp.edges_at(12.0) == {frozenset(("uav0", "uav1"))}
    assert lp.edges_at(21.0) == lp.edges_at(0.0)  # a one-way cut keeps the edge
    assert all("uav3" not in e for e in lp.edges_at(26.0)) and len(lp.edges_at(26.0)) == 3
    assert lp.is_up("uav0", "uav2", 21.0) and not lp.is_up("uav2", "uav0", 21.0)


def test_range_check():
    p = plan(range=100.0)
    em = LinkEmulator("uav0", p)
    near = {"uav0": np.array([0.0, 0.0, 50.0]), "uav1": np.array([99.0, 0.0, 50.0])}
    far = {"uav0": np.array([0.0, 0.0, 0.0]), "uav1": np.array([60.0, 80.0, 1.0])}
    assert em.admit("uav1", 1, 10, 0.0, near).delivered
    assert em.admit("uav1", 2, 10, 0.0, far).cause == "range"
    assert em.admit("uav1", 3, 10, 0.0, {"uav0": np.zeros(3)}).delivered  # a position unknown: not checked
    assert em.admit("uav1", 4, 10, 0.0, None).delivered
    assert LinkEmulator("uav0", plan()).admit("uav1", 5, 10, 0.0, far).delivered  # no range in the plan
    assert em.drops[("uav1", "range")] == 1


def test_cause_order_down_before_range_before_loss():
    p = plan({"loss": 1.0}, range=10.0, phases=[{"t": 0.0, "edges": []}])
    far = {"uav0": [0.0, 0.0], "uav1": [100.0, 0.0]}
    assert LinkEmulator("uav0", p).admit("uav1", 1, 10, 0.0, far).cause == "down"
    p["phases"] = [{"t": 0.0, "edges": "all"}]
    assert LinkEmulator("uav0", p).admit("uav1", 1, 10, 0.0, far).cause == "range"
    assert LinkEmulator("uav0", p).admit("uav1", 1, 10, 0.0).cause == "loss"


def test_bad_admit_arguments():
    em = LinkEmulator("uav0", plan())
    with pytest.raises(ValueError, match="itself"):
        em.admit("uav0", 1, 10, 0.0)
    with pytest.raises(ValueError, match="not in the link plan"):
        em.admit("ghost", 1, 10, 0.0)
    with pytest.raises(ValueError, match="seq"):
        em.admit("uav1", -1, 10, 0.0)
    with pytest.raises(ValueError, match="not in the link plan"):
        LinkEmulator("ghost", plan())
