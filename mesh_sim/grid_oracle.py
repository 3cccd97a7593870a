"""The centralized fire map, and how far each agent's map is from it.

The centralized grid receives every agent's per-frame cell evidence without loss
(``sim/grid_evidence/<agent>``) and applies it as one node would (Merino (4.4): the sum of every
agent's log-likelihood ratios; for Beta grids the sum of the pseudo-counts): it is the reference that
decentralized grid fusion is judged against, as the tracking oracle is for targets. It also listens to
the agents' own grid messages (decoding their deltas like any receiver) to follow each agent's map, and
records ``KL(centralized || agent)`` (Merino (4.25), summed over cells) every ``EVAL_PERIOD`` seconds.
At the end of every scoring window (:mod:`mesh_sim.fire_windows`) it scores the centralized map and each
agent's at the alarm threshold against the truth of that time, which ``truth(t)`` (the world's) gives.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from agent.beliefs.grid_config import GridConfig
from agent.beliefs.grid_exchange import GridReceiver
from agent.net import wire
from agent.runtime import atomic_file
from mesh_sim.fire_scoring import roc, score_positions
from mesh_sim.fire_windows import FireWindows

#: ``truth(t) -> (fire regions, decoys)`` at simulation time ``t`` (:func:`mesh_sim.fire_scoring.score_alarms`)
Truth = Callable[[float], tuple[list[dict], list]]

__all__ = ["GridOracle", "EVAL_PERIOD", "grid_extent"]

EVAL_PERIOD = 2.0  # s between KL samples (chosen here)


class GridOracle:
    def __init__(self, config: GridConfig, area: tuple[float, float, float, float], terrain, truth: Truth):
        self.config = config
        self.geometry = config.geometry(area, terrain)
        self.beliefs = config.layers(self.geometry)
        self.central = self.beliefs.uniform()
        self.receiver = GridReceiver(self.geometry.shape, self.beliefs.layers)
        self.agents: dict[str, object] = {}  # agent -> its latest grid as broadcast
        self.located: dict[str, np.ndarray] = {}  # agent -> (k, 2) its alarms where its telemetry reports them
        self.kl: dict[str, list[tuple[float, float]]] = {}  # agent -> [(t, KL)]
        self.rejected = 0
        self._next_eval = 0.0
        self.truth = truth
        self.windows = FireWindows(self.geometry, config.alarm_threshold)
        self.now = 0.0

    def add_evidence(self, env: wire.Envelope) -> None:
        """One frame's evidence, at the tick of its stamp: the map is first advanced to that tick (forgetting,
        :mod:`fusion.grid_forgetting`, as every agent does), and a frame older than the map's tick enters
        already forgotten by the ticks it missed — the centralized map forgets exactly as the agents do."""
        p = env.payload
        try:
            index = np.asarray(p["index"], np.int64)
            values = [np.asarray(p[k], float) for k in (("llr",) if self.config.belief == "logodds" else ("m", "n"))]
            if self.central.epoch is not None:
                epoch = self.beliefs.epoch_of(env.stamp)
                self.central = self.central.advanced_to(max(epoch, self.central.epoch))
                late = self.config.forgetting.factor(self.central.epoch - epoch)
                values = [late * v for v in values]
            self.central = self.central.update_cells(index, *values)
        except (KeyError, TypeError, ValueError, IndexError):
            self.rejected += 1

    def add_grid(self, env: wire.Envelope) -> None:
        try:
            layers = self.receiver.decode(env.origin, env.seq, env.payload.get("grid"))
            self.agents[env.origin] = self.beliefs.from_layers(layers, self.beliefs.epoch_of(env.stamp))
        except (wire.DecodeError, ValueError, AttributeError):
            self.rejected += 1

    def add_located(self, agent: str, alarms) -> None:
        """An agent's alarms as its telemetry reports them (``[{"mean": (north, east), ...}]``, located by the
        hand-off of :mod:`agent.beliefs.alarm_handoff`). A malformed list is counted in ``rejected`` and
        changes nothing."""
        try:
            means = np.array([a["mean"] for a in alarms], float).reshape(-1, 2)
            if not np.isfinite(means).all():
                raise ValueError("non-finite alarm position")
        except (KeyError, TypeError, ValueError, IndexError):
            self.rejected += 1
            return
        self.located[agent] = means

    def evaluate(self, t: float) -> None:
        """KL samples every ``EVAL_PERIOD``; the window scores at the end of every window."""
        self.now = t
        if self.windows.due(t):
            self.windows.record(t, *self._maps(), *self.truth(t), self.located)
        if t + 1e-9 < self._next_eval:
            return
        self._next_eval = t + EVAL_PERIOD
        for agent, grid in self.agents.items():
            self.kl.setdefault(agent, []).append((t, self.central.kl_divergence(grid)))

    def save_maps(self, path, truth: np.ndarray | None = None, truth_extent=None) -> None:
        """The final maps as ``fire_maps.npz``: ``central`` and ``agent_<id>`` cell probabilities with their
        ``extent`` (north min/max, east min/max), and the ``truth`` state (0 unburnt, 1 burning, 2 burnt)
        with ``truth_extent``, for plots and users."""
        arrays = {"central": self.central.probability(), "extent": np.array(grid_extent(self.geometry.origin,
                                                                                   self.geometry.shape,
                                                                                   self.geometry.cell))}
        arrays.update({f"agent_{agent}": grid.probability() for agent, grid in self.agents.items()})
        if truth is not None:
            arrays["truth"], arrays["truth_extent"] = truth, np.array(truth_extent)
        with atomic_file(path, "wb") as f:
            np.savez_compressed(f, **arrays)

    def _maps(self) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Cell probabilities of the centralized map and of each agent's."""
        return self.central.probability(), {agent: grid.probability() for agent, grid in self.agents.items()}

    def summary(self, regions: list[dict], decoys: list) -> dict:
        """KL series per agent, the alarm scores (ROC) of the centralized map and of each agent's against the
        truth now (``regions``, ``decoys``), and the per-window scores (a last partial window up to now)."""
        windows = list(self.windows.series)
        if self.windows.pending(self.now):
            windows.append(self.windows.score(self.now, *self._maps(), regions, decoys, self.located))

        def scores(grid) -> list[dict]:
            return roc(grid.probability(), self.geometry, regions, decoys)

        located = {agent: score_positions(means, self.geometry.cell, regions, decoys)
                   for agent, means in sorted(self.located.items())}
        return {
            **({"located": located} if located else {}),
            "belief": self.config.belief,
            "cells": self.geometry.size,
            "rejected": self.rejected,
            "windows": windows,
            "central": {"roc": scores(self.central)},
            "agents": {
                agent: {"kl_series": self.kl.get(agent, []),
                        "kl_final": self.kl[agent][-1][1] if self.kl.get(agent) else None,
                        "roc": scores(grid)}
                for agent, grid in sorted(self.agents.items())
            },
        }


def grid_extent(origin, shape, cell) -> tuple[float, float, float, float]:
    """(north min, north max, east min, east max) of a grid."""
    return origin[0], origin[0] + shape[0] * cell, origin[1], origin[1] + shape[1] * cell
