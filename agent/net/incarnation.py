"""Sequence numbers that survive a restart: an agent's life is an *incarnation*.

An agent that crashes and is started again has lost every counter it kept. If it numbered its messages
from 0 again, its peers would take them for old ones (duplicates, replays) until the count passed where it
was — for minutes — and its flooded detections, numbered the same way, would be dropped as already applied.
So a number carries the incarnation in its top bits::

    seq = incarnation * 2**32 + count        (count < 2**32: 800 years of messages at 5 Hz per kind)

The launcher gives a restarted agent the next incarnation (``python -m agent --incarnation K``): every number
of its new life is larger than every number of the old one, so the existing "newer than the last one" rules
(the receive window, grid baselines, flood acknowledgements) accept the new life and never a replay of the
old, and a receiver tells a restart from the first number of a higher incarnation. The envelope format is
unchanged (``"s"`` is an unsigned 64-bit integer, :mod:`agent.net.wire`).

The numbers protect a receiver only as long as it remembers them: a receiver that restarted has forgotten
every peer's last number, and would take a recorded message of a peer's (signed with the fleet key) for a new
one. So a message is also refused when its stamp is more than :data:`REPLAY_WINDOW_S` older than the
receiver's clock (``"stale"``): envelopes are stamped when they are sent (a relayed detection travels in a
new envelope), and the fleet shares one simulation clock, so only a replay or a badly skewed clock is older.
"""

from __future__ import annotations

import logging

log = logging.getLogger("skymesh.agent")

INCARNATION_SHIFT = 32  # bits of the per-incarnation count (chosen here)
MAX_INCARNATION = (1 << (64 - INCARNATION_SHIFT)) - 1  # seq stays below 2**64
REPLAY_WINDOW_S = 5.0  # s a message's stamp may lag the receiver's clock; chosen here (links delay ms, not s)


def first_number(incarnation: int) -> int:
    """The first sequence (or increment) number of an incarnation. Raises ``ValueError`` for one that is not an
    integer in ``[0, MAX_INCARNATION]``."""
    if isinstance(incarnation, bool) or not isinstance(incarnation, int) or not 0 <= incarnation <= MAX_INCARNATION:
        raise ValueError(f"incarnation must be an integer in [0, {MAX_INCARNATION}], got {incarnation!r}")
    return incarnation << INCARNATION_SHIFT


def incarnation_of(number: int) -> int:
    """The incarnation a sequence number belongs to."""
    return number >> INCARNATION_SHIFT


class ReceiveWindow:
    """What a receiver has used from each origin: per ``(origin, kind)`` the last sequence number (a message
    not newer is a duplicate or a replay), and per origin its incarnation (a higher one is a restart)."""

    def __init__(self):
        self._last: dict[tuple[str, str], int] = {}
        self._incarnation: dict[str, int] = {}
        self.restarts: list[tuple[str, int, float]] = []  # (origin, incarnation, t) each time a peer came back

    def admit(self, origin: str, kind: str, seq: int, t: float, stamp: float | None = None) -> str | None:
        """``"stale"`` for a message stamped more than :data:`REPLAY_WINDOW_S` before ``t``; ``"duplicate"`` for
        one not newer than the last one of its kind used from ``origin``; ``"restarted"`` for the first message
        of a newer incarnation of an origin heard before (recorded then); ``None`` otherwise. Nothing moves the
        window: :meth:`used` does, once the message was applied."""
        if stamp is not None and stamp < t - REPLAY_WINDOW_S:
            return "stale"
        last = self._last.get((origin, kind))
        if last is not None and seq <= last:
            return "duplicate"
        new, known = incarnation_of(seq), self._incarnation.get(origin)
        if known is not None and new <= known:
            return None
        self._incarnation[origin] = new
        if known is None:
            return None
        self.restarts.append((origin, new, t))
        log.warning("%s restarted (incarnation %d): its channels start afresh", origin, new)
        return "restarted"

    def used(self, origin: str, kind: str, seq: int) -> None:
        """Message ``seq`` of ``kind`` from ``origin`` was applied: only a used message moves the window, so a
        rejected payload with a huge number cannot silence its sender."""
        self._last[(origin, kind)] = seq

    def metrics(self) -> dict:
        return {"peer_restarts": [list(restart) for restart in self.restarts]}
