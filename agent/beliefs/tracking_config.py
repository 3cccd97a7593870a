"""``[tracking]``: the tracker's settings — gates, confirmation, motion model, measurement form, trajectory
window, fusion policy and track initiation (see :mod:`agent.beliefs.tracking` for what each does)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from agent.beliefs.particle_init import ParticleInitConfig
from fusion.imm import ImmModel
from fusion.motion import ConstantVelocity
from fusion.trajectory import INTERSECTION_RULES

POLICIES = ("naive", "exact", "ci", "hybrid", "flood")
MOTIONS = ("damped", "constant_velocity", "imm")


@dataclass(frozen=True)
class ImmConfig:
    """``[tracking.imm]``: the interacting multiple model of ``motion = "imm"`` (:mod:`fusion.imm`). Two
    constant-velocity modes cover the shipped targets: a *quiet* one without process noise (static and
    constant-velocity targets are its special cases) and a *manoeuvring* one with the figure-8's acceleration.
    The shipped targets never change how they move, so by default the modes do not switch (``stay = 1``: the
    static multiple-model estimator, Bar-Shalom et al. §11.6.4, whose mode probabilities converge to the
    model that fits); a switching probability keeps a share of the manoeuvring mode on a parked car, whose
    velocity covariance then dominates the mixture's (measured: ANEES 0.45 with ``stay = 0.999``). Targets
    that do switch want ``stay < 1``. Every default is chosen here, from the shipped targets."""

    quiet_q: float = 0.0  # [m^2/s^3] static and constant-velocity targets: no acceleration at all
    manoeuvre_q: float = 3.0  # [m^2/s^3] the figure-8's 2.6 m/s^2 peak acceleration
    vertical_q: float = 0.0  # [m^2/s^3] both modes: ground targets on the shipped (flat) terrain never climb
    stay: float = 1.0  # probability of keeping the same mode from one step to the next (1: no switching)
    quiet_prior: float = 0.5  # probability of the quiet mode when a track starts

    def __post_init__(self):
        for name in ("quiet_q", "manoeuvre_q", "vertical_q"):
            if not (np.isfinite(getattr(self, name)) and getattr(self, name) >= 0):
                raise ValueError(f"tracking.imm.{name} must be a non-negative number, got {getattr(self, name)!r}")
        if not 0.0 < self.stay <= 1.0:
            raise ValueError(f"tracking.imm.stay must be in (0, 1], got {self.stay!r}")
        if not 0.0 < self.quiet_prior < 1.0:
            raise ValueError(f"tracking.imm.quiet_prior must be strictly between 0 and 1, got {self.quiet_prior!r}")

    def model(self) -> ImmModel:
        quiet = ConstantVelocity(3, self.quiet_q, self.vertical_q)
        manoeuvre = ConstantVelocity(3, self.manoeuvre_q, self.vertical_q)
        return ImmModel.two_modes(quiet, manoeuvre, self.stay)

    def start_probs(self) -> np.ndarray:
        return np.array([self.quiet_prior, 1.0 - self.quiet_prior])


@dataclass(frozen=True)
class TrackerConfig:
    gate: float = 9.0  # Merino (3.64) d^2 threshold for bearings
    track_gate: float = 16.27  # chi-square(3) 99.9 % for track-to-track on positions; chosen here
    confirm_hits: int = 3  # chosen here
    confirm_within: int = 8  # steps a tentative track has to reach confirm_hits; chosen here
    max_position_std: float = 40.0  # [m] delete a track whose position is this uncertain; chosen here
    motion: str = "damped"  # "damped" (integrated OU velocity), "constant_velocity" or "imm" (flood only)
    tau: float = 10.0  # damped: velocity correlation time [s]; chosen here
    q: float = 3.0  # constant velocity: acceleration spectral density [m^2/s^3]; covers the figure-8's 2.6 m/s^2
    vertical_q: float = 0.01  # constant velocity: ground targets hardly accelerate vertically; chosen here
    measurement: str = "bearing"  # "bearing" (EIF, Merino (3.52)) or "position" (geolocated, (3.60)-(3.61))
    stale_after: float = 6.0  # s since anyone measured a track before it is deleted; chosen here
    window: int = 8  # states in a trajectory belief; chosen here
    speed_std: float = 5.0  # horizontal speed standard deviation of targets [m/s]; chosen here
    vertical_speed_std: float = 0.3  # ground targets hardly climb [m/s]; chosen here
    terrain_sigma: float = 2.0  # DEM error [m]; chosen here
    sensor_sigma: float = 0.5  # camera position error [m] (GPS); chosen here
    policy: str = "hybrid"  # naive, exact, ci, hybrid (channel filters: agent.beliefs.tracks) or flood
    intersection: str = "ci"  # where the common information is unknown: "ci", "fast_ci" or "ici" (intersect_on_newest)
    #: detections a track needs to exist: 1 starts a tentative track at the first one outside every gate; 2 holds
    #: that one as a candidate until a detection of another scan falls in its gate (agent.beliefs.track_candidates)
    start_hits: int = 2
    initiation: str = "ray"  # "ray" (the ray's ground point) or "particles" (agent.beliefs.particle_init, Merino §5.3)
    particle_init: ParticleInitConfig = field(default_factory=ParticleInitConfig)  # [tracking.particle_init]
    imm: ImmConfig = field(default_factory=ImmConfig)  # [tracking.imm]: the modes of motion = "imm"

    def __post_init__(self):
        for name, kind in (("particle_init", ParticleInitConfig), ("imm", ImmConfig)):
            value = getattr(self, name)
            if isinstance(value, dict):
                unknown = set(value) - set(kind.__dataclass_fields__)
                if unknown:
                    raise ValueError(f"unknown tracking.{name} settings: {sorted(unknown)}")
                object.__setattr__(self, name, kind(**value))
        if self.start_hits not in (1, 2) or self.start_hits > self.confirm_hits:
            raise ValueError(f"tracking.start_hits must be 1 or 2 and at most confirm_hits ({self.confirm_hits}), "
                             f"got {self.start_hits!r}")
        if self.initiation not in ("ray", "particles"):
            raise ValueError(f"tracking.initiation must be ray or particles, got {self.initiation!r}")
        positive = ("gate", "track_gate", "max_position_std", "tau", "q", "vertical_q", "stale_after", "speed_std",
                    "vertical_speed_std")
        for name in positive:
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"tracking.{name} must be positive, got {value!r}")
        if self.confirm_hits < 1 or self.confirm_within < self.confirm_hits or self.window < 2:
            raise ValueError("tracking: need confirm_within >= confirm_hits >= 1 and window >= 2")
        if self.motion not in MOTIONS:
            raise ValueError(f"tracking.motion must be one of {', '.join(MOTIONS)}, got {self.motion!r}")
        if self.motion == "imm" and (self.policy != "flood" or self.measurement != "bearing"):
            raise ValueError("tracking.motion = \"imm\" needs policy = \"flood\" and measurement = \"bearing\": a "
                             "mixture cannot be fused by channel filters, and positions are not wired for it")
        if self.measurement not in ("bearing", "position"):
            raise ValueError(f"tracking.measurement must be bearing or position, got {self.measurement!r}")
        if self.policy not in POLICIES:
            raise ValueError(f"tracking.policy must be one of {', '.join(POLICIES)}, got {self.policy!r}")
        if self.intersection not in INTERSECTION_RULES:
            raise ValueError(
                f"tracking.intersection must be one of {', '.join(INTERSECTION_RULES)}, got {self.intersection!r}"
            )
