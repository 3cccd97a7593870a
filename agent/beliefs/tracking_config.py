"""``[tracking]``: the tracker's settings — gates, confirmation, motion model, measurement form, trajectory
window, fusion policy and track initiation (see :mod:`agent.beliefs.tracking` for what each does)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from agent.beliefs.particle_init import ParticleInitConfig
from fusion.trajectory import INTERSECTION_RULES

POLICIES = ("naive", "exact", "ci", "hybrid", "flood")


@dataclass(frozen=True)
class TrackerConfig:
    gate: float = 9.0  # Merino (3.64) d^2 threshold for bearings
    track_gate: float = 16.27  # chi-square(3) 99.9 % for track-to-track on positions; chosen here
    confirm_hits: int = 3  # chosen here
    confirm_within: int = 8  # steps a tentative track has to reach confirm_hits; chosen here
    max_position_std: float = 40.0  # [m] delete a track whose position is this uncertain; chosen here
    motion: str = "damped"  # "damped" (integrated OU velocity) or "constant_velocity"
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
    initiation: str = "ray"  # "ray" (the ray's ground point) or "particles" (agent.beliefs.particle_init, Merino §5.3)
    particle_init: ParticleInitConfig = field(default_factory=ParticleInitConfig)  # [tracking.particle_init]

    def __post_init__(self):
        if isinstance(self.particle_init, dict):
            unknown = set(self.particle_init) - set(ParticleInitConfig.__dataclass_fields__)
            if unknown:
                raise ValueError(f"unknown tracking.particle_init settings: {sorted(unknown)}")
            object.__setattr__(self, "particle_init", ParticleInitConfig(**self.particle_init))
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
        if self.motion not in ("damped", "constant_velocity"):
            raise ValueError(f"tracking.motion must be damped or constant_velocity, got {self.motion!r}")
        if self.measurement not in ("bearing", "position"):
            raise ValueError(f"tracking.measurement must be bearing or position, got {self.measurement!r}")
        if self.policy not in POLICIES:
            raise ValueError(f"tracking.policy must be one of {', '.join(POLICIES)}, got {self.policy!r}")
        if self.intersection not in INTERSECTION_RULES:
            raise ValueError(
                f"tracking.intersection must be one of {', '.join(INTERSECTION_RULES)}, got {self.intersection!r}"
            )
