"""The geometric bearing sensor: what a down-looking camera plus a detector would report.

It stands in for the camera pipeline (:class:`agent.sensors.camera.CameraSensor`, ``[sensor] kind =
"camera"``; both are a :class:`BearingSource`: ``detect(t, state, truth)``, ``metrics()``, ``video_quality``)
and produces :class:`Bearing` measurements — azimuth/elevation in NED with their covariance — from the
world truth it is given as plain data. Noise is isotropic on the line of sight with standard deviation
``sigma`` [rad]: perturbing the unit line of sight by a small rotation of ``sigma`` gives
``sigma_el = sigma`` and ``sigma_az = sigma / cos(el)`` (the azimuth of a near-vertical ray is poorly
defined, and says so in its covariance).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fusion.measurement import azel_to_los, los_to_azel


@dataclass(frozen=True)
class Bearing:
    """One detection: where the camera was, where it saw something, and how sure it is."""

    t: float
    sensor: np.ndarray  # camera position, NED [m]
    azel: np.ndarray  # azimuth, elevation [rad]
    R: np.ndarray  # 2x2 covariance of azel [rad^2]
    truth_id: str | None = None  # simulation label (None: false alarm or real sensor); never used by fusion


@dataclass(frozen=True)
class BearingSensorConfig:
    kind = "bearing"  # class attribute (not a field): the [sensor] kind, the key in agent.sensors.registry.SENSORS
    range: float = 250.0  # slant range limit [m]; chosen here for a small camera at 60-120 m altitude
    fov: float = np.deg2rad(90.0)  # full cone angle around nadir [rad]
    sigma: float = np.deg2rad(1.0)  # line-of-sight noise [rad] (Andreetto et al. use 1 degree)
    p_detect: float = 0.9  # chosen here
    false_alarms: float = 0.05  # mean number of false detections per frame (Poisson); chosen here

    def __post_init__(self):
        checks = {
            "range": self.range > 0, "fov": 0 < self.fov < np.pi, "sigma": self.sigma > 0,
            "p_detect": 0 <= self.p_detect <= 1, "false_alarms": self.false_alarms >= 0,
        }
        for name, ok in checks.items():
            if not (ok and np.isfinite(getattr(self, name))):
                raise ValueError(f"sensor.{name} = {getattr(self, name)!r} is out of range")

    @classmethod
    def from_dict(cls, d: dict) -> BearingSensorConfig:
        known = {"range", "fov_deg", "sigma_deg", "p_detect", "false_alarms", "kind"}
        unknown = set(d) - known
        if unknown:
            raise ValueError(f"unknown sensor settings: {sorted(unknown)}")
        kwargs = {k: float(d[k]) for k in ("range", "p_detect", "false_alarms") if k in d}
        if "fov_deg" in d:
            kwargs["fov"] = np.deg2rad(float(d["fov_deg"]))
        if "sigma_deg" in d:
            kwargs["sigma"] = np.deg2rad(float(d["sigma_deg"]))
        return cls(**kwargs)


def bearing_covariance(el: float, sigma: float) -> np.ndarray:
    """Azimuth/elevation covariance of isotropic line-of-sight noise ``sigma`` at elevation ``el``."""
    cos_el = max(abs(np.cos(el)), 1e-3)
    return np.diag([(sigma / cos_el) ** 2, sigma**2])


class BearingSource:
    """The sensor seam (:class:`agent.plugins.Sensor`) of a sensor that turns the targets it can see into
    :class:`Bearing` observations (``"bearings"``) through its ``detect(t, state, truth)``; the targets
    come from the step's simulated truth (none on a real vehicle)."""

    video_quality: float | None = None  # D(t) of thesis 000 §2.4 (None: no video)
    _targets: list[dict] | tuple = ()  # the targets of the latest truth (none before the first)

    def on_truth(self, truth) -> None:
        self._targets = truth.targets or []

    def measure(self, t: float, state) -> dict:
        bearings = self.detect(t, state, self._targets)
        return {"bearings": bearings} if self.video_quality is None else {"bearings": bearings,
                                                                          "video_quality": self.video_quality}

    def telemetry(self) -> dict:
        return {"video_quality": self.video_quality}

    def point(self, look_at) -> None:
        """A planner's gimbal command (``Goal.look_at``, NED, or ``None``): ignored by a sensor without a
        gimbal to steer."""


class GeometricBearingSensor(BearingSource):
    """Detects the targets inside a down-looking cone and within range, with noise, misses and clutter."""

    def __init__(self, config: BearingSensorConfig, seed: int):
        self.config = config
        self.rng = np.random.default_rng(seed)
        self.bearings = 0

    def metrics(self) -> dict:
        return {"kind": "bearing", "bearings": self.bearings, "outcomes": {}}

    def close(self) -> None:
        pass

    def in_view(self, sensor: np.ndarray, target: np.ndarray) -> bool:
        d = np.asarray(target, float) - sensor
        dist = float(np.linalg.norm(d))
        if dist <= 1e-6 or dist > self.config.range:
            return False
        off_nadir = np.arccos(np.clip(d[2] / dist, -1.0, 1.0))  # nadir is +z in NED
        return off_nadir <= self.config.fov / 2

    def detect(self, t: float, state, truth: list[dict]) -> list[Bearing]:
        """Bearings to the true targets (given as ``{"id", "position"}``) seen at ``t`` from ``state``: a
        :class:`agent.vehicles.base.VehicleState` (only its position matters) or a camera position (3,)."""
        sensor = np.asarray(getattr(state, "position", state), float)
        out = []
        for target in truth:
            pos = np.asarray(target["position"], float)
            if self.in_view(sensor, pos) and self.rng.random() < self.config.p_detect:
                out.append(self._noisy(t, sensor, pos - sensor, target["id"]))
        for _ in range(self.rng.poisson(self.config.false_alarms)):
            out.append(self._noisy(t, sensor, self._random_direction_in_cone(), None))
        self.rng.shuffle(out)
        self.bearings += len(out)
        return out

    def _noisy(self, t, sensor, line_of_sight, truth_id) -> Bearing:
        u = line_of_sight / np.linalg.norm(line_of_sight)
        # A small rotation of the line of sight: add isotropic noise in the plane normal to u.
        noise = self.config.sigma * self.rng.standard_normal(3)
        u = u + noise - (noise @ u) * u
        azel = los_to_azel(u)
        return Bearing(t, sensor.copy(), azel, bearing_covariance(azel[1], self.config.sigma), truth_id)

    def _random_direction_in_cone(self) -> np.ndarray:
        off_nadir = (self.config.fov / 2) * np.sqrt(self.rng.random())
        az = self.rng.uniform(-np.pi, np.pi)
        return azel_to_los([az, off_nadir - np.pi / 2])
