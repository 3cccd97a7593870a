"""One vehicle's sortie under the health model: flying, going home, refuelling, lost (thesis 000 §2.7.4-2.7.5).

:class:`Sortie` steps a :class:`tasking.health.VehicleHealth` on the agent's clock and decides, every
cycle (spec 000 §2.7.5, "flight-experiment health logic"):

* **flying** → **home** when the flight time left at the *current* burn rate no longer covers the way home
  plus a reserve, or the camera has failed (:meth:`tasking.health.VehicleHealth.must_return`);
* **home** → **refuelling** once within ``landing_radius`` of the base (the vehicle lands: no fuel burnt);
* **refuelling** → **flying** when the tank is full and any failure repaired (``refuel_time``);
* any airborne state → **lost** when the fuel runs out in the air.

While it flies, the vehicle's :meth:`capability` carries its reach ``r = v_max · f / k`` (the pruning of
(4.1)'s petals, §2.7.4) and its camera quality ``q``; in every other state it bids for nothing, so the
consensus hands its task to another vehicle.
"""

from __future__ import annotations

import math

import numpy as np

from tasking.health import VehicleHealth
from tasking.tasks import Capability

STATES = ("flying", "home", "refuelling", "lost")


class Sortie:
    """The state machine of the module docstring around ``health``; ``speed`` is the travel speed of the
    assignment's estimates [m/s], ``reserve`` the flight time kept in hand [s]."""

    def __init__(self, health: VehicleHealth, speed: float, reserve: float, landing_radius: float):
        for name, value in (("speed", speed), ("landing_radius", landing_radius)):
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"sortie {name} must be a positive number, got {value}")
        if not (math.isfinite(reserve) and reserve >= 0):
            raise ValueError(f"sortie reserve must be ≥ 0 s, got {reserve}")
        self.health, self.speed, self.reserve, self.landing_radius = health, speed, reserve, landing_radius
        self.state = "flying"
        self.returns = 0  # times sent home
        self.lost_at: float | None = None
        self._last: float | None = None

    def update(self, t: float, position_ne, base_ne, video_quality: float | None = None,
               camera_failed: bool = False, battery: float | None = None, failed: bool = False) -> str:
        """Advance the health to ``t`` and take this cycle's decision; returns the new state. ``battery`` (0-1)
        and ``failed``: what a real vehicle reports (:meth:`tasking.health.VehicleHealth.observe_vehicle`)."""
        dt = 0.0 if self._last is None else max(0.0, t - self._last)
        self._last = t
        if self.state == "lost":
            return self.state
        if video_quality is not None:
            self.health.observe_camera(video_quality, camera_failed)
        self.health.step(dt, flying=self.state != "refuelling")
        if battery is not None or failed:
            self.health.observe_vehicle(battery, failed)
        if self.health.lost:
            self.state, self.lost_at = "lost", t
            return self.state
        home = float(np.hypot(*(np.asarray(position_ne, float) - np.asarray(base_ne, float))))
        if self.state == "flying" and self.health.must_return(home, self.speed, self.reserve):
            self.state, self.returns = "home", self.returns + 1
        if self.state == "home" and home <= self.landing_radius:
            self.state = "refuelling"
            self.health.start_refuel()
        if self.state == "refuelling" and not self.health.refuelling:
            self.state = "flying"
        return self.state

    def capability(self, position_ne, base_ne) -> Capability:
        """What the assignment may ask of the vehicle now: its reach at the current burn rate, its camera."""
        return Capability(position_ne, self.speed, base_ne, self.health.reach(self.speed), self.health.quality)

    def metrics(self) -> dict:
        return {"state": self.state, "fuel": self.health.fuel, "failures": self.health.failures,
                "returns": self.returns, "lost_at": self.lost_at}
