"""How a fleet shares an orbit, seen from the world's truth (``[tasking] orbit_slots`` > 1; spec 004 §5.3).

At every truth step the watch takes the UAVs' reported positions and the targets' true positions. A UAV is
*on the circle* of a target when its horizontal distance to it is within ``tolerance`` of the orbit radius.
The fleet has *met* (004's rendezvous) at the first step at which every UAV is on the circle of one target.
From then on the watch records, per step, whether all are still on it, and the spacing error: the largest
deviation of a gap between angular neighbours from the equal gap ``2π / n`` (004 §2.8's goal), in degrees.

Summary: ``rendezvous_s`` (``None``: never met), ``on_circle_share`` (share of the steps since meeting with
every UAV on the circle), ``spacing_error_deg`` (median and 95th percentile over those steps) and
``steady_spacing_error_deg`` (the same from ``SETTLE_S`` after meeting: the spacing law needs a while to spread
UAVs that arrive bunched). Chosen here: the tolerance, a quarter of the radius, and ``SETTLE_S`` = 10 s.
"""

from __future__ import annotations

import math

import numpy as np

SETTLE_S = 10.0  # s after meeting from which the spacing counts as steady (chosen here)


class OrbitWatch:
    def __init__(self, radius: float, agents: int, tolerance: float | None = None):
        if not (math.isfinite(radius) and radius > 0):
            raise ValueError(f"orbit radius must be positive, got {radius}")
        self.radius, self.agents = float(radius), int(agents)
        self.tolerance = radius / 4.0 if tolerance is None else float(tolerance)
        self.met_at: float | None = None
        self.steps_since = 0
        self.all_on = 0
        self.errors: list[tuple[float, float]] = []  # (t, spacing error [rad]) at the steps with all on the circle

    def observe(self, t: float, uavs: dict[str, list], targets: list[dict]) -> None:
        """One truth step: ``uavs`` name -> NED position, ``targets`` the truth snapshot's target dicts."""
        if len(uavs) < self.agents or not targets:
            return
        positions = np.array(list(uavs.values()), float)[:, :2]
        on, error = False, math.nan
        for target in targets:
            relative = positions - np.asarray(target["position"], float)[:2]
            if np.all(np.abs(np.hypot(*relative.T) - self.radius) <= self.tolerance):
                on, error = True, spacing_error(relative)
                break
        if self.met_at is None:
            if not on:
                return
            self.met_at = t
        self.steps_since += 1
        self.all_on += on
        if on:
            self.errors.append((t, error))

    def summary(self) -> dict:
        steady = [e for t, e in self.errors if t >= self.met_at + SETTLE_S] if self.errors else []
        return {
            "rendezvous_s": self.met_at,
            "on_circle_share": self.all_on / self.steps_since if self.steps_since else None,
            "spacing_error_deg": _percentiles([e for _, e in self.errors]),
            "steady_spacing_error_deg": _percentiles(steady),
            "radius_m": self.radius,
        }


def _percentiles(errors: list[float]) -> dict | None:
    if not errors:
        return None
    degrees = np.degrees(errors)
    return {"median": float(np.median(degrees)), "p95": float(np.percentile(degrees, 95))}


def spacing_error(relative: np.ndarray) -> float:
    """The largest ``|g - 2π/n|`` over the gaps ``g`` between angular neighbours of the ``(n, 2)`` offsets."""
    phases = np.sort(np.arctan2(relative[:, 1], relative[:, 0]))
    gaps = np.diff(np.append(phases, phases[0] + 2.0 * np.pi))
    return float(np.max(np.abs(gaps - 2.0 * np.pi / len(relative))))
