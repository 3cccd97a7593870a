"""Geolocation error propagation through the camera: UT, linearisation and Monte Carlo (Merino §3.7.1).

A ground point seen at a pixel depends non-linearly on the vehicle pose, the pixel and the terrain:
``z = f(p, φ, θ, ψ, u, v, δh)`` (pin-hole (3.57) back-projected and cast on the DEM, Merino §3.6).
The measurement covariance ``S_t`` of (3.60) is obtained by propagating

    δ = (δn, δe, δd, δφ, δθ, δψ, δu, δv, δh) ~ N(0, Σ)     (position m, attitude rad, pixel px, DEM m)

through ``f``, three ways:

* :func:`propagate_ut` — the unscented transform, Merino Alg. 3.5 (``fusion.unscented``);
* :func:`propagate_linear` — first order, ``J Σ Jᵀ`` with a central-difference Jacobian (as an EKF);
* :func:`propagate_monte_carlo` — sampling, the reference.

The DEM error ``δh`` raises the whole terrain; it is applied by lowering the camera by ``δh`` and raising
the hit back, which is exact for any terrain. :func:`viewing_angle_study` is Merino's comparison:
object at the image centre, a planar scene, camera 40 m from the plane, viewing angle varied, with the
Kullback-Leibler divergence of each approximation to the Monte Carlo estimate (Merino Fig. 3.9).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from fusion.unscented import unscented_transform
from perception.camera import MERINO_IR_CAMERA, Intrinsics
from perception.pose import CameraMount, CameraPose, Gimbal, camera_rotation
from perception.projection import DEFAULT_MAX_RANGE, cast_ray, cast_rays_on_raised, pixel_to_ray_world
from perception.rotations import rotation_from_euler
from perception.terrain import FlatTerrain, Terrain

__all__ = [
    "INPUTS",
    "GeolocationNoise",
    "Observation",
    "Estimate",
    "geolocation_map",
    "propagate_ut",
    "propagate_linear",
    "propagate_monte_carlo",
    "gaussian_kl",
    "STUDY_NOISE",
    "StudyRow",
    "viewing_angle_study",
    "format_study",
]

INPUTS = ("north", "east", "down", "roll", "pitch", "yaw", "u", "v", "terrain")


def _sigmas(value, size: int, name: str) -> np.ndarray:
    arr = (
        np.broadcast_to(np.asarray(value, dtype=float), (size,)).copy()
        if np.ndim(value) == 0
        else (np.asarray(value, dtype=float))
    )
    if arr.shape != (size,) or not np.all(np.isfinite(arr)) or np.any(arr < 0):
        raise ValueError(f"{name} must be a non-negative number or {size} of them, got {value!r}")
    return arr


@dataclass(frozen=True)
class GeolocationNoise:
    """Standard deviations of the independent error sources. The defaults are chosen here (Merino
    gives none): a GPS-grade position (1 m per NED axis), an AHRS-grade attitude (1° roll, 1° pitch,
    2° yaw), 1 px of detection noise and 1 m of DEM error."""

    position_sigma: float | tuple[float, float, float] = 1.0
    attitude_sigma: float | tuple[float, float, float] = (math.radians(1.0), math.radians(1.0), math.radians(2.0))
    pixel_sigma: float | tuple[float, float] = 1.0
    terrain_sigma: float = 1.0

    def __post_init__(self):
        object.__setattr__(self, "position_sigma", tuple(_sigmas(self.position_sigma, 3, "position_sigma")))
        object.__setattr__(self, "attitude_sigma", tuple(_sigmas(self.attitude_sigma, 3, "attitude_sigma")))
        object.__setattr__(self, "pixel_sigma", tuple(_sigmas(self.pixel_sigma, 2, "pixel_sigma")))
        object.__setattr__(self, "terrain_sigma", float(_sigmas(self.terrain_sigma, 1, "terrain_sigma")[0]))

    @property
    def sigmas(self) -> np.ndarray:
        """The 9 standard deviations in :data:`INPUTS` order."""
        return np.array([*self.position_sigma, *self.attitude_sigma, *self.pixel_sigma, self.terrain_sigma])

    @property
    def covariance(self) -> np.ndarray:
        return np.diag(self.sigmas**2)


@dataclass(frozen=True)
class Observation:
    """The nominal geometry: vehicle position (NED) and attitude (rad), gimbal, mount, camera and pixel."""

    position_ned: np.ndarray
    roll: float
    pitch: float
    yaw: float
    intrinsics: Intrinsics
    pixel: np.ndarray
    gimbal: Gimbal = field(default_factory=Gimbal)
    mount: CameraMount = field(default_factory=CameraMount)

    def __post_init__(self):
        object.__setattr__(self, "position_ned", np.asarray(self.position_ned, dtype=float))
        object.__setattr__(self, "pixel", np.asarray(self.pixel, dtype=float))
        CameraPose.from_vehicle(self.position_ned, self.roll, self.pitch, self.yaw, self.gimbal, self.mount)
        if self.pixel.shape != (2,) or not np.all(np.isfinite(self.pixel)):
            raise ValueError(f"observation pixel must be a finite (u, v) pair, got {self.pixel!r}")

    def pose(self, delta=None) -> CameraPose:
        dx = np.zeros(9) if delta is None else np.asarray(delta, dtype=float)
        return CameraPose.from_vehicle(
            self.position_ned + dx[:3], self.roll + dx[3], self.pitch + dx[4], self.yaw + dx[5], self.gimbal, self.mount
        )


@dataclass(frozen=True)
class Estimate:
    """Mean (3,) and covariance (3, 3) of the geolocated point (NED) by ``method``; ``misses`` counts
    Monte Carlo samples whose ray missed the terrain (they are left out)."""

    mean: np.ndarray
    cov: np.ndarray
    method: str
    misses: int = 0


def geolocation_map(obs: Observation, terrain: Terrain, max_range: float = DEFAULT_MAX_RANGE):
    """``f(δ)``: errors (..., 9) in :data:`INPUTS` order -> ground points (..., 3), NaN where the ray
    misses. Vectorised in closed form on :class:`FlatTerrain`; a loop over :func:`cast_ray` otherwise."""

    def flat(delta: np.ndarray) -> np.ndarray:
        R_nb = rotation_from_euler(obs.roll + delta[:, 3], obs.pitch + delta[:, 4], obs.yaw + delta[:, 5])
        R = camera_rotation(
            obs.roll + delta[:, 3], obs.pitch + delta[:, 4], obs.yaw + delta[:, 5], obs.gimbal, obs.mount
        )
        centre = obs.position_ned + delta[:, :3] + R_nb @ obs.mount.offset
        d = (R @ obs.intrinsics.ray(obs.pixel + delta[:, 6:8])[..., None])[..., 0]
        return cast_rays_on_raised(terrain, centre, d, delta[:, 8], max_range)

    def generic(delta: np.ndarray) -> np.ndarray:
        out = np.full((len(delta), 3), np.nan)
        for k, dx in enumerate(delta):
            pose = obs.pose(dx)
            shift = np.array([0.0, 0.0, dx[8]])
            hit = cast_ray(
                terrain, pose.centre + shift, pixel_to_ray_world(pose, obs.intrinsics, obs.pixel + dx[6:8]), max_range
            )
            if hit is not None:
                out[k] = hit - shift
        return out

    impl = flat if isinstance(terrain, FlatTerrain) else generic

    def f(delta) -> np.ndarray:
        delta = np.asarray(delta, dtype=float)
        if delta.shape[-1:] != (9,):
            raise ValueError(f"geolocation errors must have shape (..., 9), got {delta.shape}")
        flat_delta = delta.reshape(-1, 9)
        return impl(flat_delta).reshape(delta.shape[:-1] + (3,))

    return f


def propagate_ut(
    obs: Observation,
    terrain: Terrain,
    noise: GeolocationNoise,
    kappa: float | None = None,
    max_range: float = DEFAULT_MAX_RANGE,
) -> Estimate | None:
    """Unscented transform (Merino Alg. 3.5, ``fusion.unscented``) over the ``n`` inputs with non-zero
    sigma. ``None`` if a sigma point's ray misses.

    ``kappa`` defaults to ``3 - n`` (Julier and Uhlmann's choice: ``κ + n = 3`` matches the Gaussian's
    fourth moment along every axis, so the sigma points sit at ``±√3 σ``; Merino gives no value). With
    ``fusion.unscented``'s own default ``max(3 - n, 0) = 0`` for ``n = 9`` the points sit at ``±3 σ``
    and over-state the spread of the ``tan``-like ground range at oblique views (see
    :func:`viewing_angle_study`). A negative ``κ`` makes the centre weight negative; if the covariance
    then comes out indefinite, ``κ = 0`` is used instead."""
    f = geolocation_map(obs, terrain, max_range)
    sig = noise.sigmas
    active = np.flatnonzero(sig > 0)
    if active.size == 0:
        point = f(np.zeros(9))
        return None if not np.all(np.isfinite(point)) else Estimate(point, np.zeros((3, 3)), "ut")

    def g(x):
        delta = np.zeros(9)
        delta[active] = x
        return f(delta)

    n = active.size
    try:
        mean, cov = unscented_transform(g, np.zeros(n), np.diag(sig[active] ** 2), 3.0 - n if kappa is None else kappa)
        if kappa is None and np.linalg.eigvalsh(cov)[0] < -1e-12 * max(1.0, float(np.abs(cov).max())):
            mean, cov = unscented_transform(g, np.zeros(n), np.diag(sig[active] ** 2), max(3.0 - n, 0.0))
    except ValueError:
        return None
    return Estimate(mean, cov, "ut")


def propagate_linear(
    obs: Observation,
    terrain: Terrain,
    noise: GeolocationNoise,
    rel_step: float = 1e-4,
    max_range: float = DEFAULT_MAX_RANGE,
) -> Estimate | None:
    """First order: mean ``f(0)``, covariance ``J Σ Jᵀ`` with ``J`` by central differences of step
    ``rel_step · σ_i`` per input. ``None`` if the nominal ray (or a difference step) misses."""
    f = geolocation_map(obs, terrain, max_range)
    sig = noise.sigmas
    active = np.flatnonzero(sig > 0)
    steps = np.zeros((2 * active.size + 1, 9))
    for k, i in enumerate(active):
        steps[1 + 2 * k, i] = rel_step * sig[i]
        steps[2 + 2 * k, i] = -rel_step * sig[i]
    Y = f(steps)
    if not np.all(np.isfinite(Y)):
        return None
    J = np.zeros((3, 9))
    for k, i in enumerate(active):
        J[:, i] = (Y[1 + 2 * k] - Y[2 + 2 * k]) / (2.0 * rel_step * sig[i])
    cov = J @ noise.covariance @ J.T
    return Estimate(Y[0], 0.5 * (cov + cov.T), "linear")


def propagate_monte_carlo(
    obs: Observation,
    terrain: Terrain,
    noise: GeolocationNoise,
    n_samples: int = 100_000,
    rng: np.random.Generator | None = None,
    max_range: float = DEFAULT_MAX_RANGE,
) -> Estimate:
    """Sample mean and covariance of ``f(δ)`` over ``n_samples`` draws; misses are dropped and counted.
    Raises :class:`ValueError` if fewer than 10 samples hit the terrain."""
    if int(n_samples) < 10:
        raise ValueError(f"n_samples must be >= 10, got {n_samples}")
    rng = np.random.default_rng(0) if rng is None else rng
    delta = rng.normal(size=(int(n_samples), 9)) * noise.sigmas
    Y = geolocation_map(obs, terrain, max_range)(delta)
    hit = np.all(np.isfinite(Y), axis=1)
    if hit.sum() < 10:
        raise ValueError(f"only {int(hit.sum())} of {n_samples} Monte Carlo rays hit the terrain")
    Y = Y[hit]
    return Estimate(Y.mean(axis=0), np.cov(Y, rowvar=False), "monte_carlo", int((~hit).sum()))


def gaussian_kl(mean_p, cov_p, mean_q, cov_q) -> float:
    """``KL(p || q)`` between Gaussians (Merino (A.5) for two normals):
    ``½ [tr(Σ_q⁻¹ Σ_p) + (μ_q - μ_p)ᵀ Σ_q⁻¹ (μ_q - μ_p) - k + ln(det Σ_q / det Σ_p)]``."""
    mp, mq = np.atleast_1d(np.asarray(mean_p, float)), np.atleast_1d(np.asarray(mean_q, float))
    Sp, Sq = np.atleast_2d(np.asarray(cov_p, float)), np.atleast_2d(np.asarray(cov_q, float))
    k = mp.shape[0]
    Lq = np.linalg.cholesky(Sq)  # raises LinAlgError if not positive definite
    Lp = np.linalg.cholesky(Sp)
    dm = np.linalg.solve(Lq, mq - mp)
    M = np.linalg.solve(Lq, Lp)
    logdet = 2.0 * (np.sum(np.log(np.diag(Lq))) - np.sum(np.log(np.diag(Lp))))
    return float(0.5 * (np.sum(M * M) + dm @ dm - k + logdet))


#: Noise of the viewing-angle study (chosen here; Merino gives none): the defaults of
#: :class:`GeolocationNoise` but 3° of error on every attitude angle, a small UAV's attitude under
#: vibration, large enough for the non-linearity to show against Monte Carlo noise.
STUDY_NOISE = GeolocationNoise(attitude_sigma=math.radians(3.0))


@dataclass(frozen=True)
class StudyRow:
    """One viewing angle of :func:`viewing_angle_study`: the three estimates, the relative Frobenius
    error ``|Σ - Σ_MC|_F / |Σ_MC|_F`` of UT and linearisation, and ``KL(MC || ·)`` on the horizontal
    (north, east) marginal, which Merino plots (Figs. 3.8-3.9)."""

    angle_deg: float
    ut: Estimate
    linear: Estimate
    mc: Estimate
    cov_error_ut: float
    cov_error_linear: float
    kl_ut: float
    kl_linear: float


def viewing_angle_study(
    angles_deg=(0.0, 20.0, 40.0, 60.0),
    distance: float = 40.0,
    noise: GeolocationNoise | None = None,
    intrinsics: Intrinsics = MERINO_IR_CAMERA,
    n_samples: int = 200_000,
    seed: int = 0,
    kappa: float | None = None,
    slant: bool = False,
) -> list[StudyRow]:
    """Merino §3.7.1: a level vehicle heading north, ``distance`` metres above flat ground (or, with
    ``slant=True``, at ``distance`` along the optical axis), the gimbal tilted so that the optical axis is
    ``angle`` off nadir (towards north), the object at the principal point. Angles in degrees (an edge:
    this is a study driver)."""
    noise = STUDY_NOISE if noise is None else noise
    rng = np.random.default_rng(seed)
    terrain = FlatTerrain(0.0)
    rows = []
    for angle_deg in angles_deg:
        angle = math.radians(float(angle_deg))
        if not 0.0 <= angle < 0.5 * math.pi:
            raise ValueError(f"viewing angle must be in [0, 90) degrees off nadir, got {angle_deg}")
        altitude = distance * math.cos(angle) if slant else distance
        obs = Observation(
            [0.0, 0.0, -altitude],
            0.0,
            0.0,
            0.0,
            intrinsics,
            [intrinsics.cx, intrinsics.cy],
            gimbal=Gimbal(0.0, angle - 0.5 * math.pi),
        )
        ut = propagate_ut(obs, terrain, noise, kappa)
        lin = propagate_linear(obs, terrain, noise)
        mc = propagate_monte_carlo(obs, terrain, noise, n_samples, rng)
        if ut is None or lin is None:
            raise ValueError(f"at {angle_deg}° a sigma point or the nominal ray misses the ground")
        norm = np.linalg.norm(mc.cov)
        rows.append(
            StudyRow(
                float(angle_deg),
                ut,
                lin,
                mc,
                float(np.linalg.norm(ut.cov - mc.cov) / norm),
                float(np.linalg.norm(lin.cov - mc.cov) / norm),
                gaussian_kl(mc.mean[:2], mc.cov[:2, :2], ut.mean[:2], ut.cov[:2, :2]),
                gaussian_kl(mc.mean[:2], mc.cov[:2, :2], lin.mean[:2], lin.cov[:2, :2]),
            )
        )
    return rows


def format_study(rows: list[StudyRow]) -> str:
    """A plain-text table of a study (for logs and notes)."""
    lines = [
        f"{'angle':>6} {'sd_n MC':>8} {'sd_n UT':>8} {'sd_n lin':>8} {'sd_e MC':>8} {'|dS|UT':>7} "
        f"{'|dS|lin':>7} {'KL UT':>9} {'KL lin':>9}"
    ]
    for r in rows:
        sd = [math.sqrt(e.cov[0, 0]) for e in (r.mc, r.ut, r.linear)]
        lines.append(
            f"{r.angle_deg:6.1f} {sd[0]:8.3f} {sd[1]:8.3f} {sd[2]:8.3f} {math.sqrt(r.mc.cov[1, 1]):8.3f} "
            f"{r.cov_error_ut:7.3f} {r.cov_error_linear:7.3f} {r.kl_ut:9.2e} {r.kl_linear:9.2e}"
        )
    return "\n".join(lines)
