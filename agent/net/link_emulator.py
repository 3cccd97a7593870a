"""Link emulation inside every agent's transport: the receiver's decisions (DESIGN.md §6; anchors §9 and §12 item 9).

Each agent builds a :class:`LinkEmulator` for itself from the link plan (:class:`agent.net.link_plan.LinkPlan`,
where the parameters and their units are described) and asks it, for every message that arrives from a peer,
whether and when the message is delivered. A dropped message is never seen by the fusion code.

Determinism: every random decision is a hash of ``(seed, src, dst, seq, salt)`` (:func:`uniform`), so
the loss and the jitter of a message depend only on the run's seed, the directed link and the
sender's sequence number — not on which other messages the receiver saw, nor on their order. The
Gilbert–Elliott chain is the one exception that needs memory; see :class:`GilbertElliottChain` for how
it stays a function of ``(seed, src, dst, seq)`` all the same. The token bucket is deterministic given
the sequence of messages that reach it (it is evaluated at the message stamps, in arrival order).
"""

from __future__ import annotations

import hashlib
from collections import Counter, OrderedDict, deque
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np

from agent.net.link_plan import GilbertElliott, LinkParams, LinkPlan
from agent.net.plan_checks import check_number

_NORMAL = NormalDist()


# --------------------------------------------------------------------------------------------------
# Deterministic draws


def _prefix(seed: int, src: str, dst: str, salt: str) -> bytes:
    return repr((int(seed), str(src), str(dst), str(salt))).encode() + b"|"


def _to_unit(digest: bytes) -> float:
    # 53 random bits, centred in their cell: the result is in (0, 1), so an inverse CDF never sees 0 or 1.
    return ((int.from_bytes(digest, "little") >> 11) + 0.5) / 2.0**53


def uniform(seed: int, src: str, dst: str, seq: int, salt: str) -> float:
    """A deterministic draw in (0, 1) ⊂ [0, 1): BLAKE2b of ``(seed, src, dst, salt)`` and ``seq``.

    Different salts give independent draws for the same message (``"loss"``, ``"jitter"``, ...).
    """
    return _to_unit(hashlib.blake2b(_prefix(seed, src, dst, salt) + b"%d" % int(seq), digest_size=8).digest())


class _Draws:
    """:func:`uniform` for one (seed, src, dst, salt), with the prefix hashed once."""

    def __init__(self, seed: int, src: str, dst: str, salt: str):
        self._base = hashlib.blake2b(_prefix(seed, src, dst, salt), digest_size=8)

    def __call__(self, seq: int) -> float:
        h = self._base.copy()
        h.update(b"%d" % seq)
        return _to_unit(h.digest())



# --------------------------------------------------------------------------------------------------
# Mechanisms


class GilbertElliottChain:
    """The Gilbert–Elliott state of one directed link, as a function of the sender's sequence number.

    Message ``seq`` sees state s(seq); it is lost with probability 1-h in the bad state and 1-k in the
    good one (draw ``"loss"``), then the chain steps to s(seq+1) (draw ``"ge-step"``) — netem's order.
    Every sequence number steps the chain, whether or not the receiver ever sees that message (the
    sender's messages to others, messages lost on the way): to answer for ``seq`` the chain is advanced
    through every missing number with the same hash draws. So the state, and the loss decision, depend
    only on (seed, src, dst, seq), never on which messages this receiver saw or in which order.

    To keep the cost bounded for any ``seq`` (a peer that joins late, or a seq near 2**64), the chain is
    re-anchored every :attr:`BLOCK` numbers: s(k·BLOCK) is drawn from the stationary distribution
    (draw ``"ge-init"``). This keeps the loss marginal exact and breaks the burst correlation once per
    BLOCK messages. Each link keeps the states of the last few blocks it computed (last seq and state,
    plus the history needed to answer a late, reordered message without recomputing).
    """

    BLOCK = 4096
    KEEP_BLOCKS = 4

    def __init__(self, ge: GilbertElliott, seed: int, src: str, dst: str):
        self.ge = ge
        self._step = _Draws(seed, src, dst, "ge-step")
        self._init = _Draws(seed, src, dst, "ge-init")
        self._loss = _Draws(seed, src, dst, "loss")
        self._blocks: OrderedDict[int, bytearray] = OrderedDict()

    def bad(self, seq: int) -> bool:
        block, i = divmod(int(seq), self.BLOCK)
        states = self._blocks.get(block)
        if states is None:
            anchor = block * self.BLOCK
            states = self._blocks[block] = bytearray([self._init(anchor) < self.ge.stationary_bad])
            while len(self._blocks) > self.KEEP_BLOCKS:
                self._blocks.popitem(last=False)
        else:
            self._blocks.move_to_end(block)
        p, r, base = self.ge.p, self.ge.r, block * self.BLOCK
        while len(states) <= i:
            n = base + len(states) - 1
            u = self._step(n)
            states.append((u >= r) if states[-1] else (u < p))
        return bool(states[i])

    def lost(self, seq: int) -> bool:
        prob = self.ge.one_minus_h if self.bad(seq) else self.ge.one_minus_k
        return self._loss(seq) < prob


class TokenBucket:
    """Tokens (bytes) refill at ``rate`` per second up to ``burst``; the bucket starts full.

    ``admit(size, t)`` refills up to time ``t`` and admits the message if ``size`` tokens are there
    (taking them). A message larger than ``burst`` is never admitted. A time earlier than the last one
    seen refills nothing (the clock does not run backwards). Deterministic: the outcome is a function of
    the sequence of calls. Admitted bytes over any interval [t0, t1] never exceed burst + rate·(t1 - t0).
    """

    def __init__(self, rate: float, burst: float):
        self.rate = check_number("rate", rate)
        self.burst = check_number("burst", burst)
        if self.rate <= 0:
            raise ValueError(f"rate: a token bucket needs rate > 0, got {rate!r}")
        if self.burst <= 0:
            raise ValueError(f"burst: must be > 0, got {burst!r}")
        self.tokens = self.burst
        self.last: float | None = None

    def _refill(self, t: float) -> None:
        """Tokens earned up to ``t``: ``min(burst, tokens + rate · (t − last))``; an earlier ``t`` earns nothing."""
        if self.last is not None and t > self.last:
            self.tokens = min(self.burst, self.tokens + self.rate * (t - self.last))
        if self.last is None or t > self.last:
            self.last = t

    def admit(self, size: float, t: float) -> bool:
        self._refill(t)
        if size <= self.tokens:
            self.tokens -= size
            return True
        return False


class Shaper(TokenBucket):
    """A token bucket with a first-in first-out queue of ``queue`` bytes: Linux ``tc-tbf(8)``'s ``rate``,
    ``burst`` and ``limit``, and netem's ``rate``, which queue where :class:`TokenBucket` polices.

    ``depart(size, t)`` is the time the message arriving at ``t`` leaves the bucket, or None when it is dropped.
    A message leaves at once when nothing waits and ``size`` tokens are there (then it is exactly
    :meth:`TokenBucket.admit`). Otherwise it waits behind the messages already waiting, if their bytes plus
    ``size`` fit the queue (tbf's byte FIFO counts every packet not yet sent), and leaves when the bucket
    has earned its tokens: with ``s = max(t, d_prev)``, the departure of the message ahead,
    ``d = s + max(0, size − tokens(s)) / rate`` and the bucket is left empty at ``d``. A message that does not
    fit the queue is dropped; so with ``queue`` 0 a shaper is the policer :class:`TokenBucket`. Departures are
    non-decreasing, so a link keeps its order; the long-run throughput is still ``rate``.
    """

    def __init__(self, rate: float, burst: float, queue: float = 0.0):
        super().__init__(rate, burst)
        self.queue = check_number("queue", queue, lo=0.0)
        self._waiting: deque[tuple[float, float]] = deque()  # (departure, bytes) of the messages not yet sent
        self._waiting_bytes = 0.0

    def depart(self, size: float, t: float) -> float | None:
        while self._waiting and self._waiting[0][0] <= t:
            self._waiting_bytes -= self._waiting.popleft()[1]
        if not self._waiting and self.admit(size, t):
            return t
        if size > self.burst or self._waiting_bytes + size > self.queue:
            return None
        start = max(t, self.last)
        self._refill(start)
        departure = start + max(0.0, size - self.tokens) / self.rate
        self.tokens = max(0.0, self.tokens - size)
        self.last = departure
        self._waiting.append((departure, size))
        self._waiting_bytes += size
        return departure



# --------------------------------------------------------------------------------------------------
# The receive-side gate


@dataclass(frozen=True)
class Verdict:
    deliver_at: float | None  # simulation seconds, or None when dropped
    cause: str | None  # "down", "range", "loss" or "rate" when dropped

    @property
    def delivered(self) -> bool:
        return self.deliver_at is not None



class LinkEmulator:
    """The link state as seen by receiver ``me``: one verdict per arriving message.

    Checks in order: ``down`` (no link src → me at the stamp, or either node lost), ``range`` (both
    positions known and farther apart than the plan's range), ``loss`` (Bernoulli or Gilbert–Elliott,
    deterministic in (seed, src, me, seq)), ``rate`` (the src → me :class:`Shaper` at the stamp: a policer
    without a ``queue``; only messages that got this far use tokens, as in netem where lost packets never
    reach the rate stage). Otherwise the message is delivered at its departure from the bucket (the stamp,
    unless it queued) + delay + jitter (seconds).
    """

    def __init__(self, me: str, plan: LinkPlan | dict):
        self.plan = LinkPlan.from_dict(plan)
        if me not in self.plan.agents:
            raise ValueError(f"agent {me!r} is not in the link plan {list(self.plan.agents)}")
        self.me = me
        self.drops: Counter = Counter()  # (src, cause) -> messages
        self.delivered: Counter = Counter()  # src -> messages
        self.bytes_delivered: Counter = Counter()  # src -> bytes
        self._buckets: dict[str, Shaper] = {}
        self._chains: dict[str, GilbertElliottChain] = {}
        self._loss_draws: dict[str, _Draws] = {}
        self._jitter_draws: dict[str, _Draws] = {}

    def sender_budget(self, me: str | None = None) -> float | None:
        return self.plan.sender_budget(self.me if me is None else me)

    def _lost(self, src: str, seq: int, params: LinkParams) -> bool:
        if params.ge is not None:
            chain = self._chains.get(src)
            if chain is None:
                chain = self._chains[src] = GilbertElliottChain(params.ge, self.plan.seed, src, self.me)
            return chain.lost(seq)
        if params.loss <= 0:
            return False
        draw = self._loss_draws.get(src)
        if draw is None:
            draw = self._loss_draws[src] = _Draws(self.plan.seed, src, self.me, "loss")
        return draw(seq) < params.loss

    def _delay(self, src: str, seq: int, params: LinkParams) -> float:
        delay = params.delay_ms
        if params.jitter_ms > 0:
            draw = self._jitter_draws.get(src)
            if draw is None:
                draw = self._jitter_draws[src] = _Draws(self.plan.seed, src, self.me, "jitter")
            delay = max(0.0, delay + params.jitter_ms * _NORMAL.inv_cdf(draw(seq)))
        return delay / 1000.0

    def _drop(self, src: str, cause: str) -> Verdict:
        self.drops[(src, cause)] += 1
        return Verdict(None, cause)

    def admit(self, src: str, seq: int, size: int, stamp: float, positions: dict | None = None) -> Verdict:
        """Whether and when the message ``seq`` of ``size`` bytes from ``src``, stamped ``stamp``, reaches me."""
        if src == self.me:
            raise ValueError(f"{src!r} -> {self.me!r}: an agent does not receive from itself over the radio")
        if src not in self.plan.agents:
            raise ValueError(f"sender {src!r} is not in the link plan")
        if isinstance(seq, bool) or not isinstance(seq, int | np.integer) or seq < 0:
            raise ValueError(f"seq must be an int >= 0, got {seq!r}")
        if size < 0:
            raise ValueError(f"size must be >= 0 bytes, got {size!r}")
        if not self.plan.is_up(src, self.me, stamp):
            return self._drop(src, "down")
        if self.plan.range is not None and positions is not None:
            a, b = positions.get(src), positions.get(self.me)
            if a is not None and b is not None:
                if float(np.linalg.norm(np.asarray(a, float) - np.asarray(b, float))) > self.plan.range:
                    return self._drop(src, "range")
        params = self.plan.params(src, self.me)
        if self._lost(src, int(seq), params):
            return self._drop(src, "loss")
        sent = stamp
        if params.rate is not None:
            bucket = self._buckets.get(src)
            if bucket is None:
                bucket = self._buckets[src] = Shaper(params.rate, params.bucket_depth, params.queue)
            sent = bucket.depart(size, stamp)
            if sent is None:
                return self._drop(src, "rate")
        self.delivered[src] += 1
        self.bytes_delivered[src] += size
        return Verdict(sent + self._delay(src, int(seq), params), None)
