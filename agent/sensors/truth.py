"""The simulator's truth as an agent receives it: the intake for simulated sensors (DESIGN.md §1, §6).

The world publishes plain data on ``sim/truth`` (:mod:`mesh_sim.world`); the agent never imports the
simulator. :class:`WorldTruth` keeps the latest message — target states, the fire (decoded only when it
changed: it changes once per world step, the truth arrives at every agent step), the decoys and the
UAV positions the radio's range check uses — and hands simulated sensors a :class:`TruthSnapshot` at the
start of each step. A real deployment has no truth: the snapshot is then empty and only real sensors
(an external camera) produce observations.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from agent.net.fire_truth import decode_fire, decoy
from agent.net.wire import DecodeError, Envelope

TRUTH_MAX_AGE = 2.0  # s of simulation time; older truth is not extrapolated (chosen here)


@dataclass(frozen=True)
class TruthSnapshot:
    """What simulated sensors may see at one step: targets extrapolated to the step's time (``None``: no
    recent truth), and the fire as scene fires plus decoys (hot spot, probability of showing)."""

    targets: list[dict] | None = None
    fires: list = field(default_factory=list)
    decoys: list = field(default_factory=list)


class WorldTruth:
    """The latest truth message as agent ``me`` sees it; the fire is draped on ``terrain``."""

    def __init__(self, terrain, me: str):
        self.terrain = terrain
        self.me = me
        self._targets: tuple[float, list[dict]] | None = None
        self._fire: tuple[list, list] = ([], [])  # burning cells and decoys, as scene fires
        self._fire_payload = None  # the (fire, decoys) truth self._fire was decoded from
        self.uav_positions: dict[str, np.ndarray] = {}

    def accept(self, env: Envelope) -> None:
        """Take a truth message; raises :class:`agent.net.wire.DecodeError` on malformed targets or UAV
        positions (``bad_truth``: nothing of it is kept) or a malformed fire (``bad_fire``: the rest is kept)."""
        targets, uavs = env.payload.get("targets"), env.payload.get("uavs")
        if targets is not None:
            targets = [_target(entry) for entry in _of_type(targets, list, "targets")]
        if uavs is not None:  # the simulator's knowledge of where everyone is: the radio's range check
            self.uav_positions = _positions(_of_type(uavs, dict, "uavs"), self.me)
        if targets is not None:
            self._targets = (env.stamp, targets)
        fire_truth = (env.payload.get("fire"), env.payload.get("decoys", []))
        if fire_truth[0] is not None and fire_truth != self._fire_payload:
            fire = decode_fire(fire_truth[0], self.terrain)
            self._fire = (fire.scene_fires(self.terrain), _decoys(fire_truth[1]))
            self._fire_payload = fire_truth

    def targets_at(self, t: float) -> list[dict] | None:
        """The latest target states, extrapolated at constant velocity to ``t``."""
        if self._targets is None or abs(t - self._targets[0]) > TRUTH_MAX_AGE:
            return None
        stamp, targets = self._targets
        dt = t - stamp
        return [
            {"id": tg["id"], "position": tg["position"] + dt * tg["velocity"], "velocity": tg["velocity"]}
            for tg in targets
        ]

    def at(self, t: float) -> TruthSnapshot:
        return TruthSnapshot(self.targets_at(t), *self._fire)


def _of_type(value, kind: type, name: str):
    if not isinstance(value, kind):
        raise DecodeError("bad_truth", f"{name} must be a {kind.__name__}, got {type(value).__name__}")
    return value


def _vector(value, name: str) -> np.ndarray:
    """A finite NED 3-vector."""
    ok = isinstance(value, list | tuple | np.ndarray) and len(value) == 3 and all(
        isinstance(v, int | float | np.floating | np.integer) and not isinstance(v, bool) for v in value)
    out = np.asarray(value, float) if ok else None
    if out is None or out.shape != (3,) or not np.all(np.isfinite(out)):
        raise DecodeError("bad_truth", f"{name} must be 3 finite numbers, got {value!r:.60}")
    return out


def _positions(uavs: dict, me: str) -> dict[str, np.ndarray]:
    """Every other UAV's position, each checked as :func:`_vector` checks one, in one array (the truth brings N of
    them at every step); a malformed entry is named by the per-entry check. This agent's own entry is checked
    too (a truth with any malformed position is malformed), then left out."""
    names = [str(k) for k in uavs]
    values = list(uavs.values())
    try:
        table = np.array(values, dtype=float).reshape(len(values), 3)
        plain = all(isinstance(v, list | tuple) and all(type(x) in (float, int) for x in v) for v in values)
    except (TypeError, ValueError):
        table, plain = None, False
    if table is None or not plain or not np.isfinite(table).all():
        checked = {name: _vector(v, f"uavs.{name}") for name, v in zip(names, values, strict=True)}
    else:
        checked = dict(zip(names, table, strict=True))
    checked.pop(me, None)
    return checked


def _target(entry) -> dict:
    """One target of the truth: ``{"id": str, "position": NED, "velocity": NED}``."""
    entry = _of_type(entry, dict, "a target")
    if not isinstance(entry.get("id"), str):
        raise DecodeError("bad_truth", f"a target needs a string id, got {entry.get('id')!r:.60}")
    return {"id": entry["id"], "position": _vector(entry.get("position"), "target position"),
            "velocity": _vector(entry.get("velocity"), "target velocity")}


def _decoys(entries) -> list[tuple[float, float, float]]:
    """``[[north, east, probability], ...]`` from the truth: hot spots that show in a frame with that
    probability (malformed entries are ignored: advisory simulation data)."""
    parsed = [decoy(entry) for entry in (entries if isinstance(entries, list) else [])]
    return [d for d in parsed if d is not None]

