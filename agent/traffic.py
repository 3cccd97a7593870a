"""What an agent sent over the radio: bytes per message kind over the run, and bytes and messages per time bin.

The bins (``[start_s, bytes, messages]`` per :data:`agent.evaluation.BIN_S` second of simulation time that saw a
send) are what ``plots/traffic.png`` draws as bytes/s and messages/s per agent (:mod:`mesh_sim.plots.traffic`);
they sum to ``bytes_tx``. One bin a second keeps the agent's metrics small (a few kB for a long run).
"""

from __future__ import annotations

from collections import Counter

from agent.evaluation import BIN_S
from fusion.trajectory import grid_epoch


class TrafficLog:
    """Counts the messages an agent sends, by kind and by time bin."""

    def __init__(self):
        self.by_kind: Counter = Counter()  # kind -> bytes
        self.bins: dict[int, list[int]] = {}  # bin index -> [bytes, messages]

    def sent(self, t: float, kind: str, size: int) -> None:
        """One message of ``size`` bytes and ``kind`` sent at simulation time ``t``."""
        self.by_kind[kind] += size
        sums = self.bins.setdefault(grid_epoch(t, BIN_S), [0, 0])
        sums[0] += size
        sums[1] += 1

    def metrics(self) -> dict:
        """``bytes_tx``, ``bytes_tx_by_kind`` and ``traffic_bins`` (``[start_s, bytes, messages]`` in time order)."""
        return {"bytes_tx": int(sum(self.by_kind.values())), "bytes_tx_by_kind": dict(self.by_kind),
                "traffic_bins": [[k * BIN_S, *sums] for k, sums in sorted(self.bins.items())]}
