"""What to broadcast, and when, within the link budget (agent/net/sending.py).

Tracks are small fakes exposing what the scheduler reads (``id`` and ``estimate()``, a real Gaussian). The
trigger's divergence is computed here independently — explicit inverses and ``slogdet`` instead of the
implementation's Cholesky — and the budget is checked against the token-bucket envelope: admitted bytes by
time T never exceed burst + rate · (T - T0).
"""

import math

import numpy as np
import pytest

from agent.net.sending import SendConfig, SendScheduler, divergence
from fusion.gaussian import Gaussian
from fusion.motion import ConstantVelocity, Static

ENTRY = 1000  # bytes charged per track
STILL = Static(dim=2)  # the receiver predicts no motion: the divergence is between two Gaussians as they stand


class FakeTrack:
    def __init__(self, track_id: int, mean, cov):
        self.id = track_id
        self.set(mean, cov)

    def set(self, mean, cov) -> None:
        self.mean, self.cov = np.asarray(mean, float), np.asarray(cov, float)

    def estimate(self) -> Gaussian:
        return Gaussian.from_moments(self.mean, self.cov)


def kl(mean, cov, sent_mean, sent_cov, F=None, Q=None) -> float:
    """The oracle: D(N(mean, cov) || N(F sent_mean, F sent_cov F^T + Q)) by explicit inverse and slogdet."""
    n = len(mean)
    F = np.eye(n) if F is None else F
    Q = np.zeros((n, n)) if Q is None else Q
    m, S = F @ sent_mean, F @ sent_cov @ F.T + Q
    S_inv = np.linalg.inv(S)
    d = mean - m
    return 0.5 * (np.trace(S_inv @ cov) + d @ S_inv @ d - n + np.linalg.slogdet(S)[1] - np.linalg.slogdet(cov)[1])


def random_spd(rng, dim=2) -> np.ndarray:
    a = rng.normal(size=(dim, dim))
    return a @ a.T + 0.1 * np.eye(dim)


def still_track(track_id: int, rng=None, dim: int = 2) -> FakeTrack:
    rng = rng or np.random.default_rng(track_id)
    return FakeTrack(track_id, rng.normal(size=dim), random_spd(rng, dim))


# ---- the divergence ------------------------------------------------------------------------------------


def test_divergence_is_the_gaussian_kl_of_the_prediction():
    rng = np.random.default_rng(1)
    for _ in range(100):
        motion = ConstantVelocity(spatial_dims=int(rng.integers(1, 4)), q=float(rng.uniform(0.01, 2.0)))
        n, dt = motion.dim, float(rng.choice([0.2, 0.4, 1.0, 3.0]))
        mean, cov, sent_mean, sent_cov = rng.normal(size=n), random_spd(rng, n), rng.normal(size=n), random_spd(rng, n)
        expected = kl(mean, cov, sent_mean, sent_cov, motion.transition(dt), motion.noise(dt))
        got = divergence(Gaussian.from_moments(mean, cov), sent_mean, sent_cov, motion, dt)
        assert got == pytest.approx(expected, rel=1e-9, abs=1e-9)
        assert got >= 0.0


def test_divergence_is_zero_when_the_estimate_is_the_receivers_prediction():
    motion = ConstantVelocity(spatial_dims=3, q=0.5)
    rng = np.random.default_rng(2)
    sent_mean, sent_cov = rng.normal(size=6), random_spd(rng, 6)
    F, Q = motion.transition(1.0), motion.noise(1.0)
    predicted = Gaussian.from_moments(F @ sent_mean, F @ sent_cov @ F.T + Q)
    assert divergence(predicted, sent_mean, sent_cov, motion, 1.0) == pytest.approx(0.0, abs=1e-9)


def test_divergence_of_an_estimate_with_an_unobserved_direction_is_zero():
    unobserved = Gaussian.from_info(np.zeros(2), np.diag([1.0, 0.0]))
    assert divergence(unobserved, np.zeros(2), np.eye(2), STILL, 1.0) == 0.0


# ---- the information trigger ------------------------------------------------------------------------


def test_a_track_in_steady_state_is_sent_once_the_receivers_prediction_is_stale():
    """The defect this trigger fixes: a track whose covariance no longer shrinks (new bearings only replace
    the process noise) gains no entropy, yet what a receiver predicts from the last message drifts away. With
    the entropy trigger it waited max_silence; the divergence sends it as soon as the receiver lacks info_gain."""
    motion = ConstantVelocity(spatial_dims=1, q=1.0)
    config = SendConfig(period=0.2, info_gain=0.5, max_silence=100.0)
    steady = np.array([[1.0, 0.3], [0.3, 0.6]])  # the same covariance at every send
    sched = SendScheduler(config, budget=None)
    track = FakeTrack(1, [0.0, 1.0], steady)
    assert sched.choose(0.0, [track], ENTRY, motion) == [track]
    last, sent_at = (0.0, np.array([0.0, 1.0])), []
    for k in range(1, 26):
        t = 0.2 * k
        track.set(motion.transition(t) @ [0.0, 1.0], steady)  # the mean the receiver predicts, a steady covariance
        dt = t - last[0]
        stale = kl(track.mean, steady, last[1], steady, motion.transition(dt), motion.noise(dt))
        sent = sched.choose(t, [track], ENTRY, motion) == [track]
        assert sent == (stale >= config.info_gain), (t, stale)
        if sent:
            last = (t, track.mean)
            sent_at.append(round(t, 1))
    # the entropy gain 1/2 log det Y_now - 1/2 log det Y_sent is 0 here: the old trigger sent nothing before 100 s
    assert sent_at == [1.8, 3.6], sent_at  # every 1.8 s, each time the prediction went stale


def test_information_trigger_against_the_kl_oracle():
    """A track sent once is sent again (before max_silence) iff the divergence of its estimate from the
    last-sent one predicted to now reaches info_gain."""
    motion = ConstantVelocity(spatial_dims=1, q=0.05)
    config = SendConfig(period=1.0, info_gain=1.0, max_silence=100.0)
    rng = np.random.default_rng(2)
    checked = {True: 0, False: 0}
    for k in range(300):
        mean0, cov0 = rng.normal(size=2), random_spd(rng)
        mean1 = motion.transition(1.0) @ mean0 + rng.normal(scale=0.4, size=2)
        cov1 = np.linalg.inv(np.linalg.inv(cov0) + rng.uniform(0.0, 1.0) * random_spd(rng))
        expected = kl(mean1, cov1, mean0, cov0, motion.transition(1.0), motion.noise(1.0))
        if abs(expected - config.info_gain) < 1e-9:
            continue  # too close to call in floating point
        sched = SendScheduler(config, budget=None)
        track = FakeTrack(k, mean0, cov0)
        assert sched.choose(0.0, [track], ENTRY, motion) == [track]  # never sent: sent
        track.set(mean1, cov1)
        sent = sched.choose(1.0, [track], ENTRY, motion) == [track]
        assert sent == (expected >= config.info_gain), (expected, sent)
        checked[sent] += 1
    assert min(checked.values()) > 30  # both outcomes were exercised


def test_divergence_is_measured_from_the_last_send_not_the_last_round():
    sched = SendScheduler(SendConfig(info_gain=0.5, max_silence=100.0), budget=None)
    track = FakeTrack(1, [0.0, 0.0], np.eye(2))
    assert sched.choose(0.0, [track], ENTRY, STILL) == [track]
    for t, shift in ((1.0, 0.5), (2.0, 0.8)):  # small drifts: not sent (kl 0.125, 0.32), but they add up
        track.set([shift, 0.0], np.eye(2))
        assert sched.choose(t, [track], ENTRY, STILL) == []
    track.set([1.1, 0.0], np.eye(2))  # kl 0.605 from what was sent
    assert sched.choose(3.0, [track], ENTRY, STILL) == [track]
    assert sched.choose(4.0, [track], ENTRY, STILL) == []  # now counted from [1.1, 0]


def test_max_silence_resends_a_track_without_new_information():
    sched = SendScheduler(SendConfig(period=1.0, info_gain=0.1, max_silence=3.0), budget=None)
    track = still_track(7)
    sent_at = [t for t in np.arange(0.0, 10.0, 1.0) if sched.choose(float(t), [track], ENTRY, STILL)]
    assert sent_at == [0.0, 3.0, 6.0, 9.0]


def test_a_neighbour_the_last_broadcast_missed_gets_the_track_at_once():
    """A partition's merge: ``uav2`` comes back as a neighbour of a track that has no news for the trigger (still,
    last sent at 0 s). It is sent to the new neighbour at the next round, then waits for the trigger or
    ``max_silence`` again; a neighbour that leaves asks for nothing."""
    sched = SendScheduler(SendConfig(period=1.0, info_gain=0.1, max_silence=10.0), budget=None)
    track = still_track(4)
    assert sched.choose(0.0, [track], ENTRY, STILL, ["uav0"]) == [track]
    assert sched.choose(1.0, [track], ENTRY, STILL, ["uav0"]) == []
    assert sched.choose(2.0, [track], ENTRY, STILL, ["uav0", "uav2"]) == [track]  # the merge
    assert sched.choose(3.0, [track], ENTRY, STILL, ["uav0", "uav2"]) == []
    assert sched.choose(4.0, [track], ENTRY, STILL, ["uav2"]) == []  # uav0 gone: it needs nothing from us


def test_an_unobservable_track_is_sent_first_then_on_silence_only():
    class Unobservable:
        id = 3

        def estimate(self):
            return Gaussian.from_info(np.zeros(2), np.diag([1.0, 0.0]))

    sched = SendScheduler(SendConfig(period=1.0, info_gain=0.1, max_silence=3.0), budget=None)
    track = Unobservable()
    assert [t for t in range(8) if sched.choose(float(t), [track], ENTRY, STILL)] == [0, 3, 6]


def test_due_follows_the_period():
    sched = SendScheduler(SendConfig(period=1.0), budget=None)
    assert [sched.due(t) for t in (0.0, 0.5, 0.999_999_999_5, 1.5, 2.0, 2.2, 3.1)] == [
        True, False, True, False, True, False, True,
    ]


# ---- priorities and the budget -----------------------------------------------------------------------


def priority(sent: dict, track, t: float, max_silence: float) -> float:
    """The documented order: never sent first, then largest divergence plus the silence as a share of max_silence."""
    if track.id not in sent:
        return math.inf
    when, mean, cov = sent[track.id]
    return kl(track.mean, track.cov, mean, cov) + (t - when) / max_silence


def test_never_sent_first_then_largest_divergence():
    config = SendConfig(period=1.0, info_gain=0.1, max_silence=10.0)
    sched = SendScheduler(config, budget=1.0, burst=4 * ENTRY)  # four entries now, then 1 byte/s
    old = [FakeTrack(i, [0.0, 0.0], np.eye(2)) for i in range(4)]
    assert sched.choose(0.0, old, ENTRY, STILL) == old
    for track, shift in zip(old, (1.0, 0.6, 0.3, 1.4), strict=True):  # kl 0.5, 0.18, (0.045: not due), 0.98
        track.set([shift, 0.0], np.eye(2))
    new = FakeTrack(99, [0.0, 0.0], 1e6 * np.eye(2))  # never sent: first, whatever its information
    sched.bucket.tokens = 3 * ENTRY  # room for three of the four due tracks
    chosen = sched.choose(1.0, [*old, new], ENTRY, STILL)
    assert [t.id for t in chosen] == [99, 3, 0]
    assert sched.thinned == 1  # track 1 was due and did not fit; track 2 was not due


def test_order_matches_priority_oracle_on_random_tracks():
    rng = np.random.default_rng(4)
    config = SendConfig(period=1.0, info_gain=0.05, max_silence=4.0)
    for _ in range(50):
        sched = SendScheduler(config, budget=1e-3, burst=1e9)
        tracks = [still_track(i, rng) for i in range(8)]
        sent: dict[int, tuple] = {}
        for k in range(10):
            t = float(k)
            for track in tracks:
                u = rng.random()
                if u < 0.4:  # new information and a new mean
                    track.set(track.mean + rng.normal(scale=0.3, size=2),
                              np.linalg.inv(np.linalg.inv(track.cov) + rng.uniform(0, 0.5) * random_spd(rng)))
                elif u < 0.6:  # information lost
                    track.set(track.mean, track.cov / rng.uniform(0.3, 0.9))
            if k > 0:
                tracks.append(still_track(100 + k, rng))  # a new track every round
            due = [
                tr for tr in tracks
                if tr.id not in sent
                or kl(tr.mean, tr.cov, *sent[tr.id][1:]) >= config.info_gain
                or t - sent[tr.id][0] >= config.max_silence
            ]
            fit = int(rng.integers(0, len(due) + 1))
            sched.bucket.tokens = fit * ENTRY
            thinned = sched.thinned
            chosen = sched.choose(t, tracks, ENTRY, STILL)
            expected = sorted(due, key=lambda tr: -priority(sent, tr, t, config.max_silence))[:fit]
            assert [tr.id for tr in chosen] == [tr.id for tr in expected]
            assert sched.thinned - thinned == len(due) - fit
            for tr in chosen:
                sent[tr.id] = (t, tr.mean, tr.cov)


def test_thinned_tracks_are_offered_again_not_queued():
    sched = SendScheduler(SendConfig(period=1.0), budget=10.0, burst=2 * ENTRY)  # 10 bytes/s: 100 s per entry
    tracks = [still_track(i) for i in range(5)]
    assert [t.id for t in sched.choose(0.0, tracks, ENTRY, STILL)] == [0, 1]
    assert sched.thinned == 3
    assert sched.choose(1.0, tracks, ENTRY, STILL) == []  # 10 bytes of tokens: still nothing fits
    assert sched.thinned == 6  # the three never-sent tracks were due again, and thinned again
    assert [t.id for t in sched.choose(201.0, tracks, ENTRY, STILL)] == [2, 3]  # 2000 bytes refilled


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_budget_never_exceeded_over_a_long_random_sequence(seed):
    rng = np.random.default_rng(seed)
    rate, burst = 4000.0, 6000.0
    sched = SendScheduler(SendConfig(period=0.5, info_gain=0.05, max_silence=2.0), budget=rate, burst=burst)
    tracks = [still_track(i, rng) for i in range(12)]
    t, admitted, offered = 0.0, 0.0, 0.0
    t0 = None  # the bucket starts full at the first message
    for _ in range(5000):
        t += float(rng.exponential(0.05))
        t0 = t if t0 is None else t0
        if rng.random() < 0.6:  # telemetry or a grid: an arbitrary message through the same bucket
            size = int(rng.integers(100, 3000))
            offered += size
            if sched.admit(size, t):
                admitted += size
        else:
            for track in tracks:
                if rng.random() < 0.3:
                    more = np.linalg.inv(track.cov) + rng.uniform(0, 0.3) * random_spd(rng)
                    track.set(track.mean, np.linalg.inv(more))
            if sched.due(t):
                admitted += ENTRY * len(sched.choose(t, tracks, ENTRY, STILL))
        assert admitted <= rate * (t - t0) + burst + 1e-6, (t, admitted)
    assert admitted >= 0.95 * rate * (t - t0)  # the bucket was the limit, and nearly all of it was used
    assert offered > 1.5 * rate * (t - t0)
    assert sched.thinned > 0


def test_unlimited_budget_admits_everything():
    sched = SendScheduler(SendConfig(), budget=None)
    assert sched.bucket is None
    assert all(sched.admit(10**9, 0.0) for _ in range(3))
    tracks = [still_track(i) for i in range(50)]
    assert sched.choose(0.0, tracks, 10**9, STILL) == tracks
    assert sched.thinned == 0


def test_default_burst_is_the_links():
    assert SendScheduler(SendConfig(), budget=1000.0).bucket.burst == 64 * 1024
    assert SendScheduler(SendConfig(), budget=1e7).bucket.burst == pytest.approx(1e6)
    assert SendScheduler(SendConfig(), budget=1000.0, burst=5000.0).bucket.burst == 5000.0
    assert SendScheduler(SendConfig(burst=3000.0), budget=1000.0).bucket.burst == 3000.0  # [sending] burst


# ---- configuration -----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"period": 0.0}, "sending.period must be positive"),
        ({"period": -1.0}, "sending.period must be positive"),
        ({"period": math.nan}, "sending.period must be positive"),
        ({"period": math.inf}, "sending.period must be positive"),
        ({"max_silence": 0.0}, "sending.max_silence must be positive"),
        ({"max_silence": math.inf}, "sending.max_silence must be positive"),
        ({"info_gain": -0.1}, "sending.info_gain must be non-negative"),
        ({"info_gain": math.nan}, "sending.info_gain must be non-negative"),
        ({"ack_delay": 0.6}, r"sending.ack_delay must be in \[0, ack_timeout = 0.6\)"),  # as long as the timeout
        ({"ack_delay": 1.0, "ack_timeout": 0.8}, "sending.ack_delay must be in"),  # longer than the timeout
        ({"ack_delay": -0.2}, "sending.ack_delay must be in"),
        ({"ack_delay": math.nan}, "sending.ack_delay must be in"),
        ({"rate": -1.0}, "sending.rate must be bytes per second >= 0"),
        ({"rate": math.nan}, "sending.rate must be bytes per second >= 0"),
        ({"rate": math.inf}, "sending.rate must be bytes per second >= 0"),  # unlimited is 0, not inf
        ({"rate": True}, "sending.rate must be bytes per second >= 0"),
        ({"burst": -1.0}, "sending.burst must be bytes >= 0"),
        ({"burst": math.inf}, "sending.burst must be bytes >= 0"),
    ],
)
def test_bad_config(kwargs, message):
    with pytest.raises(ValueError, match=message):
        SendConfig(**kwargs)


def test_zero_info_gain_is_allowed():
    assert SendConfig(info_gain=0.0).info_gain == 0.0


@pytest.mark.parametrize(("rate", "planned", "budget"), [
    (0.0, None, None),  # no radio plan, no rate: unlimited
    (0.0, 5e5, 5e5),  # the emulated radio's
    (2000.0, None, 2000.0),  # a real network: only what the agents are told
    (2000.0, 5e5, 2000.0),  # the tighter wins either way
    (5e6, 5e5, 5e5),
])
def test_the_budget_is_the_tighter_of_the_rate_and_the_radio_plans(rate, planned, budget):
    assert SendConfig(rate=rate).budget(planned) == budget
