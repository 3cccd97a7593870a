"""Grid messages that respect bandwidth: deltas against what every neighbour acknowledged.

A certainty grid is mostly unchanged between two broadcasts (a camera sees a few hundred cells of
thousands), so a message carries only the cells that changed since a *baseline*: an earlier message of
ours that every current neighbour has acknowledged decoding (:mod:`agent.net.grid_codec`). Receivers keep
the last messages they decoded from each origin, so they can rebuild the full grid from the baseline.

* **Sender** (:class:`GridSender`): remembers the quantized layers of its recent messages and, per
  neighbour, which of them that neighbour acknowledged. The baseline of a broadcast is the newest message
  that *every* current neighbour acknowledged (the oldest of their latest acknowledgements whenever each
  of them acknowledged that message); a keyframe is sent when there is none still in the history, and every
  ``keyframe_every`` messages so that late joiners and observers catch up. An acknowledgement of a newer
  message is no proof of an older one: with independent losses, a neighbour that acknowledged message 3
  may have missed message 2, the one another neighbour acknowledged last.
* **Receiver** (:class:`GridReceiver`): per origin, the layers of the messages it decoded (for the next
  deltas) and the newest one it decoded — the acknowledgement it gives back in its own grid messages.

Losing a message loses no update: every message carries the sender's whole current state (as a delta
against something the receiver provably holds; with a deadband ``tolerance`` q, every cell within
``q max(1, |b|)`` of it, :mod:`agent.net.grid_codec`), so the next one that arrives brings everything. A
delta on a baseline the receiver does not hold is rejected (``grid_missing_baseline``) and costs one
period, never a wrong grid.

"Provably holds" needs a receiver history at least as long as the sender's (both are :data:`HISTORY`):
a baseline is still among the sender's last ``history`` messages, so fewer than ``history`` messages
followed it, and a receiver that decoded it (its acknowledgement says so) keeps its last ``history``
decoded ones. With a shorter receiver history, lost acknowledgements can keep the sender on a baseline
the receiver has since dropped: its deltas are rejected until an acknowledgement gets through or the
baseline leaves the sender's history (a keyframe follows).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from agent.net import wire
from agent.net.grid_codec import GridHistory, check_tolerance, decode_grid, encode_grid

KEYFRAME_EVERY = 10  # messages between forced keyframes (chosen here: a late joiner waits at most this many)
HISTORY = 16  # messages remembered per origin, on both sides (chosen here)


class GridSender:
    """The sending side of one grid belief."""

    def __init__(self, keyframe_every: int = KEYFRAME_EVERY, delta: bool = True, history: int = HISTORY,
                 tolerance: float = 0.0):
        if keyframe_every < 1:
            raise ValueError(f"keyframe_every must be at least 1, got {keyframe_every}")
        self.keyframe_every = keyframe_every
        self.delta = delta
        self.tolerance = check_tolerance(tolerance, "tolerance")
        self.sent = GridHistory(history)
        self.held: dict[str, set[int]] = {}  # neighbour -> our messages in self.sent it acknowledged decoding
        self._since_keyframe = keyframe_every  # the first message is a keyframe

    def acknowledge(self, peer: str, seq: int) -> None:
        """``peer`` says it decoded our message ``seq``."""
        if self.sent.get(seq) is not None:
            self.held.setdefault(peer, set()).add(seq)

    def baseline(self, neighbours: Iterable[str]) -> tuple[int, np.ndarray] | None:
        """The newest message every neighbour acknowledged, so holds, that is still in the history, or ``None``."""
        if not self.delta or self._since_keyframe + 1 >= self.keyframe_every:
            return None
        neighbours = list(neighbours)
        if not neighbours or any(p not in self.held for p in neighbours):
            return None
        common = set.intersection(*(self.held[p] for p in neighbours))
        base = max((seq for seq in common if self.sent.get(seq) is not None), default=None)
        return None if base is None else (base, self.sent.get(base))

    def encode(self, layers: np.ndarray, neighbours: Iterable[str]) -> tuple[dict, np.ndarray]:
        """The codec payload of ``layers`` for the current neighbours, and the layers the receivers will
        reconstruct (what the caller must record as sent): decoded here from the payload and the baseline
        by the receivers' own function, so the two sides agree bit for bit. Within the deadband
        (``tolerance``) a cell keeps the baseline's value, so these differ from ``quantize(layers)``."""
        base = self.baseline(neighbours)
        if base is None:
            payload = encode_grid(layers, None, None)
        else:
            payload = encode_grid(layers, base[1], base[0], self.tolerance)
        held = decode_grid(payload, layers.shape[1:], layers.shape[0], {} if base is None else {base[0]: base[1]}.get)
        return payload, held

    def sent_as(self, seq: int, quantized: np.ndarray, payload: dict) -> None:
        """Record that message ``seq`` left with ``payload`` (call only for messages actually sent)."""
        self.sent.put(seq, quantized)
        for peer, held in self.held.items():  # forget acknowledgements of messages that left the history
            self.held[peer] = {s for s in held if self.sent.get(s) is not None}
        self._since_keyframe = 0 if payload.get("mode") == "key" else self._since_keyframe + 1


class GridReceiver:
    """The receiving side: rebuilds every origin's grid from keyframes and deltas."""

    def __init__(self, shape: tuple[int, int], layers: int, history: int = HISTORY):
        self.shape = tuple(shape)
        self.layers = layers
        self.history = history
        self._origins: dict[str, GridHistory] = {}

    def decode(self, origin: str, seq: int, payload) -> np.ndarray:
        """The full (quantized) layers of message ``seq`` from ``origin``; raises
        :class:`agent.net.wire.DecodeError` (nothing is stored then)."""
        store = self._origins.setdefault(origin, GridHistory(self.history))
        latest = store.latest()
        if latest is not None and seq <= latest[0]:
            raise wire.DecodeError("grid_stale", f"grid message {seq} is not newer than {latest[0]}")
        layers = decode_grid(payload, self.shape, self.layers, store.get)
        store.put(seq, layers)
        return layers

    def acks(self) -> dict[str, int]:
        """Origin -> the newest of its messages decoded here (what our grid messages acknowledge)."""
        out = {}
        for origin, store in self._origins.items():
            latest = store.latest()
            if latest is not None:
                out[origin] = latest[0]
        return out
