"""Vehicle health for task assignment: fuel, Poisson failures, camera quality, return to base.

Thesis 000 Ch. 4 and §5.2.4 (spec 000 §2.7.2, §2.7.4, §2.7.5); MIT thesis supervised by J. P. How (the
author's name is lost in the source text, spec 000 header).

Fuel (§2.7.4). The fuel ``f`` of a vehicle decreases at a constant rate while it flies::

    df/dt = -k                     k = k_fuel before a failure, k_fuel,failure > k_fuel after it

and a vehicle whose fuel reaches 0 in the air crashes and is *lost*. Failures arrive as a Poisson process
of intensity ``p_f`` per second of flight: the flight time to the next failure is drawn ``~ Exp(p_f)``
(exact in continuous time, whatever the step ``dt``); a failure lasts until the vehicle is repaired.
What is left is a range ``r = v_max · f / k`` (:func:`tasking.tasks.operational_range`); the
health-aware assignment uses the *current* rate ``k`` (spec 000 §6 item 10), the thesis' nominal RHTA the
nominal ``k_fuel`` (it ignores failures).

Refuelling (chosen here, not in the thesis): a vehicle landed at base stays on the ground
``refuel_time`` seconds (default 20 s), after which its fuel is back to capacity and any failure is
repaired ("the mission system lands the UAV and schedules refuelling or maintenance", §2.7.5).

Camera (§2.7.2 "sensor state", §2.4). The agents publish the video-quality measure D(t) of
:mod:`perception.quality` and its ``failed`` flag; the assignment wants a quality ``q ∈ [0, 1]``
(:class:`tasking.tasks.Capability`). The mapping (chosen here; the thesis gives none, spec 000 §6
item 9) is the same linear ramp as :meth:`perception.quality.VideoQuality.weight`, with its defaults::

    q = clip((D_fail - D) / (D_fail - D_good), 0, 1),      D_good = 0.03, D_fail = 0.15

so ``q = 1`` for clean video, ``q = 0`` (and the camera counts as failed) at or above the failure level.

A real vehicle (:mod:`agent.vehicles.mavlink`) reports its battery and its failures; they replace the
modelled fuel and failures (:meth:`VehicleHealth.observe_vehicle`, chosen here: the battery's remaining charge
is the fuel, so the nominal burn rate turns it into flight time).

Return to base (§2.7.5): a vehicle must go home when (a) its remaining flight time at the current burn
rate, ``f / k``, no longer exceeds the time to fly home plus a reserve, or (b) its camera has failed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fusion.validation import positive
from tasking.tasks import operational_range

__all__ = ["HealthModel", "VehicleHealth", "camera_quality"]


def _non_negative(value: float, name: str) -> None:
    if not (math.isfinite(value) and value >= 0):
        raise ValueError(f"{name} must be ≥ 0, got {value}")


@dataclass(frozen=True)
class HealthModel:
    """The health parameters shared by a fleet (defaults chosen here; the thesis gives none, spec 000 §3).

    ``capacity``: full tank (fuel units; 1 = normalised); ``burn``: ``k_fuel`` per second of flight;
    ``burn_failed``: ``k_fuel,failure`` (> ``burn``); ``failure_rate``: ``p_f`` per second of flight;
    ``refuel_time``: seconds on the ground to refuel and repair; ``camera_good`` / ``camera_fail``: the
    D(t) levels of full and zero camera quality (those of :class:`perception.quality.VideoQuality`)."""

    capacity: float = 1.0
    burn: float = 1.0 / 600.0  # 10 min of flight on a full tank (the thesis' quad-rotors: ≈ 12 min, §5.2.4)
    burn_failed: float = 2.0 / 600.0  # a failure doubles the burn
    failure_rate: float = 1.0 / 500.0  # one failure per 500 s of flight on average
    refuel_time: float = 20.0
    camera_good: float = 0.03
    camera_fail: float = 0.15

    def __post_init__(self):
        positive("fuel capacity", self.capacity)
        positive("burn rate k_fuel", self.burn)
        if not (math.isfinite(self.burn_failed) and self.burn_failed > self.burn):
            raise ValueError(f"failure burn rate k_fuel,failure must exceed k_fuel = {self.burn}, "
                             f"got {self.burn_failed}")
        _non_negative(self.failure_rate, "failure rate p_f")
        _non_negative(self.refuel_time, "refuel time")
        _non_negative(self.camera_good, "camera good level D_good")
        if not (math.isfinite(self.camera_fail) and self.camera_fail > self.camera_good):
            raise ValueError(f"camera failure level D_fail must exceed D_good = {self.camera_good}, "
                             f"got {self.camera_fail}")


def camera_quality(video_quality: float, model: HealthModel) -> float:
    """``q = clip((D_fail - D) / (D_fail - D_good), 0, 1)`` from the published D(t) (module docstring)."""
    _non_negative(video_quality, "video quality D(t)")
    span = model.camera_fail - model.camera_good
    return float(np.clip((model.camera_fail - video_quality) / span, 0.0, 1.0))  # linear ramp D_good -> D_fail


class VehicleHealth:
    """Fuel, failure and camera state of one vehicle (§2.7.4), stepped by the simulation.

    ``rng`` (a seeded :class:`numpy.random.Generator`, one per vehicle) draws the failure times;
    ``fuel`` defaults to a full tank."""

    def __init__(self, model: HealthModel, rng: np.random.Generator, fuel: float | None = None):
        fuel = model.capacity if fuel is None else fuel
        if not (math.isfinite(fuel) and 0 <= fuel <= model.capacity):
            raise ValueError(f"fuel must be in [0, capacity = {model.capacity}], got {fuel}")
        self.model = model
        self.fuel = float(fuel)
        self.failed = False
        self.lost = False
        self.camera_failed = False
        self.quality = 1.0
        self.failures = 0  # failures so far (the Monte-Carlo check of p_f counts them)
        self._rng = rng
        self._refuel_left = 0.0
        self._until_failure = self._draw_failure_time()

    def _draw_failure_time(self) -> float:
        """Flight time to the next failure, ``~ Exp(p_f)`` (∞ when ``p_f = 0``)."""
        rate = self.model.failure_rate
        return float(self._rng.exponential(1.0 / rate)) if rate > 0 else math.inf

    @property
    def burn_rate(self) -> float:
        """The current burn rate ``k``: ``k_fuel,failure`` after a failure, else ``k_fuel``."""
        return self.model.burn_failed if self.failed else self.model.burn

    @property
    def refuelling(self) -> bool:
        return self._refuel_left > 0

    def flight_time(self, health_aware: bool = True) -> float:
        """Seconds of flight left, ``f / k`` (``k`` current if ``health_aware``, else nominal)."""
        return self.fuel / (self.burn_rate if health_aware else self.model.burn)

    def reach(self, speed: float, health_aware: bool = True) -> float:
        """``r = v_max · f / k`` [m] (§2.7.4): current ``k`` if ``health_aware``, nominal ``k_fuel`` if not."""
        return operational_range(self.fuel, speed, self.burn_rate if health_aware else self.model.burn)

    def step(self, dt: float, flying: bool) -> None:
        """Advance ``dt`` seconds: burn (and maybe fail) while ``flying``, refuel while on the ground."""
        _non_negative(dt, "time step dt")
        if self.lost:
            return
        if not flying:
            self._refuel(dt)
            return
        if self.refuelling:
            raise ValueError("a refuelling vehicle cannot fly")
        if self.failed or self._until_failure > dt:
            self._until_failure -= dt
            self._burn(dt)
            return
        before = self._until_failure
        self._burn(before)  # at k_fuel until the failure
        if not self.lost:
            self.failed, self.failures = True, self.failures + 1
            self._burn(dt - before)  # at k_fuel,failure afterwards

    def _burn(self, dt: float) -> None:
        if self.lost:
            return
        self.fuel -= self.burn_rate * dt  # f(t + dt) = f(t) - k dt
        if self.fuel <= 0:  # dry in the air: crashed
            self.fuel, self.lost = 0.0, True

    def start_refuel(self) -> None:
        """Landed at base: refuel and repair over ``refuel_time`` seconds of :meth:`step` on the ground."""
        if self.lost:
            raise ValueError("a lost vehicle cannot refuel")
        self._refuel_left = self.model.refuel_time
        if self._refuel_left == 0:
            self._finish_refuel()

    def _refuel(self, dt: float) -> None:
        if not self.refuelling:
            return
        self._refuel_left -= dt
        if self._refuel_left <= 0:
            self._finish_refuel()

    def _finish_refuel(self) -> None:
        self._refuel_left = 0.0
        self.fuel = self.model.capacity
        if self.failed:  # repaired: a new failure clock starts
            self.failed = False
            self._until_failure = self._draw_failure_time()

    def observe_camera(self, video_quality: float, failed: bool = False) -> None:
        """Take the agent's published D(t) and ``failed`` flag (§2.4): quality ``q`` and camera failure."""
        self.quality = camera_quality(video_quality, self.model)
        self.camera_failed = failed or video_quality >= self.model.camera_fail

    def observe_vehicle(self, battery: float | None, failed: bool) -> None:
        """What a real vehicle reports replaces the model: the remaining ``battery`` charge (0-1, ``None``:
        not reported) is the fuel, ``fuel = battery · capacity``; a reported failure is a failure (the burn rate
        becomes ``k_fuel,failure`` until the vehicle is repaired at base)."""
        if battery is not None:
            if not (math.isfinite(battery) and 0 <= battery <= 1):
                raise ValueError(f"battery must be a fraction in [0, 1], got {battery}")
            self.fuel = battery * self.model.capacity
        if failed and not self.failed:
            self.failed, self.failures = True, self.failures + 1

    def must_return(self, distance_home: float, speed: float, reserve: float = 0.0) -> bool:
        """§2.7.5: flight time ``f / k`` (current ``k``) ≤ time home + ``reserve`` [s], or a failed camera."""
        _non_negative(distance_home, "distance home")
        _non_negative(reserve, "reserve time")
        return self.camera_failed or self.flight_time() <= distance_home / speed + reserve
