"""What to broadcast, and when, within the link budget (agent/net/sending.py).

Tracks are small fakes exposing what the scheduler reads (``id`` and ``estimate().Y``). The information of a
track is computed here independently as 1/2 Σ log λ_i over the eigenvalues of Y, and the budget is checked
against the token-bucket envelope: admitted bytes by time T never exceed burst + rate · (T - T0).
"""

import math
from dataclasses import dataclass

import numpy as np
import pytest

from agent.net.sending import SendConfig, SendScheduler, information

ENTRY = 1000  # bytes charged per track


@dataclass
class Estimate:
    Y: np.ndarray


class FakeTrack:
    def __init__(self, track_id: int, Y):
        self.id = track_id
        self.Y = np.asarray(Y, float)

    def estimate(self) -> Estimate:
        return Estimate(self.Y)


def half_logdet(Y) -> float:
    """The oracle: 1/2 log det Y from the eigenvalues of the symmetric positive-definite Y."""
    return 0.5 * float(np.sum(np.log(np.linalg.eigvalsh(Y))))


def track_with_information(track_id: int, nats: float, dim: int = 2) -> FakeTrack:
    """A track whose 1/2 log det Y is ``nats``: Y = exp(2 nats / dim) I."""
    return FakeTrack(track_id, math.exp(2.0 * nats / dim) * np.eye(dim))


def random_spd(rng, dim=3) -> np.ndarray:
    a = rng.normal(size=(dim, dim))
    return a @ a.T + 0.1 * np.eye(dim)


def test_information_is_half_logdet():
    rng = np.random.default_rng(1)
    for _ in range(50):
        Y = random_spd(rng)
        assert information(FakeTrack(0, Y)) == pytest.approx(half_logdet(Y), abs=1e-9)
    assert information(FakeTrack(0, np.diag([1.0, -1.0]))) == -np.inf  # not positive definite
    assert information(FakeTrack(0, np.zeros((2, 2)))) == -np.inf


# ---- the information trigger ------------------------------------------------------------------------


def test_information_trigger_against_half_logdet_gain():
    """A track sent once is sent again (before max_silence) iff 1/2 log det Y_now - 1/2 log det Y_sent >= info_gain."""
    config = SendConfig(period=1.0, info_gain=0.1, max_silence=100.0)
    rng = np.random.default_rng(2)
    checked = {True: 0, False: 0}
    for k in range(300):
        Y0 = random_spd(rng)
        Y1 = Y0 + rng.uniform(0.0, 0.08) * random_spd(rng)  # more (or about as much) information
        gain = half_logdet(Y1) - half_logdet(Y0)
        if abs(gain - config.info_gain) < 1e-9:
            continue  # too close to call in floating point
        sched = SendScheduler(config, budget=None)
        track = FakeTrack(k, Y0)
        assert sched.choose(0.0, [track], ENTRY) == [track]  # never sent: sent
        track.Y = Y1
        sent = sched.choose(1.0, [track], ENTRY) == [track]
        assert sent == (gain >= config.info_gain), (gain, sent)
        checked[sent] += 1
    assert min(checked.values()) > 30  # both outcomes were exercised


def test_gain_is_measured_from_the_last_send_not_the_last_round():
    sched = SendScheduler(SendConfig(info_gain=0.1, max_silence=100.0), budget=None)
    track = track_with_information(1, 0.0)
    assert sched.choose(0.0, [track], ENTRY) == [track]
    for t, nats in ((1.0, 0.06), (2.0, 0.09)):  # small steps: not sent, but they add up
        track.Y = track_with_information(1, nats).Y
        assert sched.choose(t, [track], ENTRY) == []
    track.Y = track_with_information(1, 0.12).Y
    assert sched.choose(3.0, [track], ENTRY) == [track]
    assert sched.choose(4.0, [track], ENTRY) == []  # gain now counted from 0.12


def test_max_silence_resends_a_track_without_new_information():
    sched = SendScheduler(SendConfig(period=1.0, info_gain=0.1, max_silence=3.0), budget=None)
    track = track_with_information(7, 1.0)
    sent_at = [t for t in np.arange(0.0, 10.0, 1.0) if sched.choose(float(t), [track], ENTRY)]
    assert sent_at == [0.0, 3.0, 6.0, 9.0]
    track.Y = track_with_information(7, 0.0).Y  # information lost (negative gain): still re-sent on silence
    assert sched.choose(11.0, [track], ENTRY) == []
    assert sched.choose(12.0, [track], ENTRY) == [track]


def test_due_follows_the_period():
    sched = SendScheduler(SendConfig(period=1.0), budget=None)
    assert [sched.due(t) for t in (0.0, 0.5, 0.999_999_999_5, 1.5, 2.0, 2.2, 3.1)] == [
        True, False, True, False, True, False, True,
    ]


# ---- priorities and the budget -----------------------------------------------------------------------


def priority(sent: dict, track, t: float, max_silence: float) -> float:
    """The documented order: never sent first, then largest gain (plus the silence as a fraction of max_silence)."""
    if track.id not in sent:
        return math.inf
    when, then = sent[track.id]
    return max(half_logdet(track.Y) - then, 0.0) + (t - when) / max_silence


def test_never_sent_first_then_largest_gain():
    config = SendConfig(period=1.0, info_gain=0.1, max_silence=10.0)
    sched = SendScheduler(config, budget=1.0, burst=4 * ENTRY)  # four entries now, then 1 byte/s
    old = [track_with_information(i, 0.0) for i in range(4)]
    assert sched.choose(0.0, old, ENTRY) == old
    for track, nats in zip(old, (0.5, 0.2, 0.05, 0.9), strict=True):  # gains 0.5, 0.2, (0.05: not due), 0.9
        track.Y = track_with_information(track.id, nats).Y
    new = track_with_information(99, -5.0)  # never sent: first, whatever its information
    sched.bucket.tokens = 3 * ENTRY  # room for three of the four due tracks
    chosen = sched.choose(1.0, [*old, new], ENTRY)
    assert [t.id for t in chosen] == [99, 3, 0]
    assert sched.thinned == 1  # track 1 was due and did not fit; track 2 was not due


def test_order_matches_priority_oracle_on_random_tracks():
    rng = np.random.default_rng(4)
    config = SendConfig(period=1.0, info_gain=0.05, max_silence=4.0)
    for _ in range(50):
        sched = SendScheduler(config, budget=1e-3, burst=1e9)
        tracks = [FakeTrack(i, random_spd(rng)) for i in range(8)]
        sent: dict[int, tuple[float, float]] = {}
        for k in range(10):
            t = float(k)
            for track in tracks:
                u = rng.random()
                if u < 0.4:  # new information
                    track.Y = track.Y + rng.uniform(0, 0.5) * random_spd(rng)
                elif u < 0.6:  # information lost (negative gain: due only by silence)
                    track.Y = track.Y * rng.uniform(0.3, 0.9)
            if k > 0:
                tracks.append(FakeTrack(100 + k, random_spd(rng)))  # a new track every round
            due = [
                tr for tr in tracks
                if tr.id not in sent
                or half_logdet(tr.Y) - sent[tr.id][1] >= config.info_gain
                or t - sent[tr.id][0] >= config.max_silence
            ]
            fit = int(rng.integers(0, len(due) + 1))
            sched.bucket.tokens = fit * ENTRY
            thinned = sched.thinned
            chosen = sched.choose(t, tracks, ENTRY)
            expected = sorted(due, key=lambda tr: -priority(sent, tr, t, config.max_silence))[:fit]
            assert [tr.id for tr in chosen] == [tr.id for tr in expected]
            assert sched.thinned - thinned == len(due) - fit
            for tr in chosen:
                sent[tr.id] = (t, half_logdet(tr.Y))


def test_thinned_tracks_are_offered_again_not_queued():
    sched = SendScheduler(SendConfig(period=1.0), budget=10.0, burst=2 * ENTRY)  # 10 bytes/s: 100 s per entry
    tracks = [track_with_information(i, 0.0) for i in range(5)]
    assert [t.id for t in sched.choose(0.0, tracks, ENTRY)] == [0, 1]
    assert sched.thinned == 3
    assert sched.choose(1.0, tracks, ENTRY) == []  # 10 bytes of tokens: still nothing fits
    assert sched.thinned == 6  # the three never-sent tracks were due again, and thinned again
    assert [t.id for t in sched.choose(201.0, tracks, ENTRY)] == [2, 3]  # 2000 bytes refilled


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_budget_never_exceeded_over_a_long_random_sequence(seed):
    rng = np.random.default_rng(seed)
    rate, burst = 4000.0, 6000.0
    sched = SendScheduler(SendConfig(period=0.5, info_gain=0.05, max_silence=2.0), budget=rate, burst=burst)
    tracks = [FakeTrack(i, random_spd(rng)) for i in range(12)]
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
                    track.Y = track.Y + rng.uniform(0, 0.3) * random_spd(rng)
            if sched.due(t):
                admitted += ENTRY * len(sched.choose(t, tracks, ENTRY))
        assert admitted <= rate * (t - t0) + burst + 1e-6, (t, admitted)
    assert admitted >= 0.95 * rate * (t - t0)  # the bucket was the limit, and nearly all of it was used
    assert offered > 1.5 * rate * (t - t0)
    assert sched.thinned > 0


def test_unlimited_budget_admits_everything():
    sched = SendScheduler(SendConfig(), budget=None)
    assert sched.bucket is None
    assert all(sched.admit(10**9, 0.0) for _ in range(3))
    tracks = [track_with_information(i, 0.0) for i in range(50)]
    assert sched.choose(0.0, tracks, 10**9) == tracks
    assert sched.thinned == 0


def test_default_burst_is_the_links():
    assert SendScheduler(SendConfig(), budget=1000.0).bucket.burst == 64 * 1024
    assert SendScheduler(SendConfig(), budget=1e7).bucket.burst == pytest.approx(1e6)
    assert SendScheduler(SendConfig(), budget=1000.0, burst=5000.0).bucket.burst == 5000.0


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
    ],
)
def test_bad_config(kwargs, message):
    with pytest.raises(ValueError, match=message):
        SendConfig(**kwargs)


def test_zero_info_gain_is_allowed():
    assert SendConfig(info_gain=0.0).info_gain == 0.0
