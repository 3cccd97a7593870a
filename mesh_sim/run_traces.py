"""What a run's map and link plots draw, recorded by the world from what it already receives: once a
:data:`agent.evaluation.BIN_S` second, the true targets' and each UAV's position and each agent's track estimates
(its telemetry's ``tracks``), and every change of the neighbours an agent reports (its telemetry's ``neighbours``:
the peers its topology tracker heard within the neighbour timeout, :mod:`agent.net.topology`).

``summary()`` is ``oracle.json``'s ``traces``: ``{"truth": {target: [[t, n, e], ...]}, "uavs": {agent: [[t, n, e,
d], ...]}, "tracks": {agent: [[t, track, n, e], ...]}, "neighbours": {agent: [[t, [peer, ...]], ...]}}``, NED
metres and simulation seconds. Downsampled to one row per agent per bin, a 10-minute run of 8 agents holds some
thousands of rows.
"""

from __future__ import annotations

import math

import numpy as np

from agent.evaluation import BIN_S


def finite_position(payload: dict) -> np.ndarray | None:
    """A telemetry payload's ``position`` (north, east, down) if it is three finite numbers, else ``None``."""
    position = np.asarray(payload.get("position", ()), float)
    return position if position.shape == (3,) and np.all(np.isfinite(position)) else None


class RunTraces:
    """Downsampled paths, track estimates and neighbour changes of a run (see the module docstring)."""

    def __init__(self, every_s: float = BIN_S):
        self.every_s = every_s
        self.truth: dict[str, list] = {}
        self.uavs: dict[str, list] = {}
        self.tracks: dict[str, list] = {}
        self.neighbours: dict[str, list] = {}
        self._last_bin: dict[str, int] = {}  # "truth" or agent -> the last bin a row was kept for

    def _due(self, who: str, t: float) -> bool:
        k = math.floor(t / self.every_s + 1e-9)
        if self._last_bin.get(who) == k:
            return False
        self._last_bin[who] = k
        return True

    def on_truth(self, t: float, targets: list[dict]) -> None:
        """The true targets (``{"id", "position"}``) at ``t``."""
        if self._due("truth", t):
            for target in targets:
                n, e, _ = np.asarray(target["position"], float)
                self.truth.setdefault(str(target["id"]), []).append([t, float(n), float(e)])

    def on_telemetry(self, agent: str, t: float, payload: dict) -> None:
        """One agent's telemetry at ``t``: its neighbours on every change, its position and tracks once a bin."""
        peers = sorted(str(p) for p in payload.get("neighbours", []) if p != agent)
        history = self.neighbours.setdefault(agent, [])
        if not history or history[-1][1] != peers:
            history.append([t, peers])
        if not self._due(f"agent/{agent}", t):
            return
        position = finite_position(payload)
        if position is not None:
            self.uavs.setdefault(agent, []).append([t, *map(float, position)])
        rows = self.tracks.setdefault(agent, [])
        for track in payload.get("tracks", []):
            mean = np.asarray(track.get("mean", ()), float)
            if mean.size >= 2 and np.all(np.isfinite(mean[:2])):
                rows.append([t, str(track.get("id")), float(mean[0]), float(mean[1])])

    def summary(self) -> dict:
        return {"truth": self.truth, "uavs": self.uavs, "tracks": self.tracks, "neighbours": self.neighbours}
