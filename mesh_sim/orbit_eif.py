"""skymesh's centralized bearing-only tracker run on the bearings of spec 004's flights, beside Andreetto et al.'s
consensus estimator (Electronics 2018; :mod:`mesh_sim.orbit_experiments`).

The UAVs fly 004's orbits unchanged: the static or dynamic algorithm moves the orbit centres, and the camera
readings it uses are recorded (:class:`mesh_sim.orbit_experiments.BearingLog`). This module feeds every UAV's
bearing of every step to one extended information filter (EIF) — what skymesh's ``flood`` policy computes in
every agent (README: "every agent runs the centralized tracker on the fleet's detections") — so the two
estimators are compared on the same measurements. The EIF is an observer only: it never steers a UAV.

**Model.** State ``x = [p; ṗ]`` (4,) on the paper's ground plane (Merino (3.54) ordering). Motion: a
:mod:`fusion.motion` model, by default :func:`matched_model`, skymesh's white-noise-acceleration
:class:`~fusion.motion.ConstantVelocity` (Merino (3.58)-(3.59)) with spectral density ``q = σ_a² Δt``, the
density whose velocity variance per step, ``q Δt``, equals that of 004's KCF model ``σ_a² G Gᵀ``,
``G = [Δt²/2 I; Δt I]`` (:class:`tasking.consensus.DoubleIntegrator`): both filters assume the same target
motion. Measurement: the azimuth of the line of sight from the UAV's GPS position ``s_i``,

    ``z_i = atan2(p_y - s_y, p_x - s_x) + v_i``,  ``v_i ~ N(0, σ²)``,  ``σ² = σ_η² + σ_ψ²``,

i.e. :class:`fusion.measurement.Bearing2D` with the sensor at ``s_i``; the measured ``z_i`` is the magnetometer
axis heading plus the camera bearing, ``ψ_i + η_i`` (004 §1.1). GPS noise (σ = 2 cm) is not modelled: at the
orbit radius of 30 m it moves the bearing by 0.04°, a 0.15 % addition to ``σ²``.

**One step** at the sampling instant ``t``, every run of a Monte Carlo batch at once
(:class:`fusion.batch.GaussianBatch`):

1. prediction, Merino Alg. 3.2 (3.11)-(3.13), giving ``N(μ(t|t−1), P(t|t−1))`` (none at the first step);
2. the extended information update of every UAV that sees the target, Merino (3.52), each linearised at the
   predicted mean ``μ̄ = μ(t|t−1)`` (the bearings of one instant are one measurement vector):

       ``Y ← Y + Σ_i H_iᵀ σ⁻² H_i``,  ``y ← y + Σ_i H_iᵀ σ⁻² [z_i − h_i(μ̄) + H_i μ̄]``,
       ``H_i = [−Δy, Δx, 0, 0] / (Δx² + Δy²)``,  ``(Δx, Δy) = μ̄_p − s_i``

   (:meth:`fusion.batch.GaussianBatch.eif_update_bearing2d`); a UAV that does not see the target contributes
   ``R⁻¹ = 0``, i.e. nothing.

**Initiation** (chosen here). skymesh starts a track at the geolocated ground point of its first ray, close to
the target, so (3.52)'s linearisation is good from the start. 004's world is planar: a bearing has no ground
point, and the prior below is 18 m off. Linearised that far from the target, a bearing's information
``1 / (ρ² σ²)`` is taken at the wrong range ``ρ`` and in the wrong direction; the EIF then becomes overconfident
in the first steps and, with the small process noise of E2 (which forgets slowly), some runs keep a metre-size
error for tens of seconds (measured: with n = 3, 40 runs, a steady-state NEES of thousands in a few runs). So
while a run's predicted position standard deviation ``sqrt(tr P_pp / 2)`` exceeds :data:`ITERATE_ABOVE` (1 m),
its step is the *iterated* EIF update (Bell & Cathey 1993: the iterated Kalman update is Gauss-Newton on
``J(x) = (x − μ̄)ᵀ Ȳ (x − μ̄) + Σ_i (z_i − h_i(x))² / σ²``, ``(μ̄, Ȳ⁻¹)`` the prediction): :data:`PASSES`
passes, pass ``j`` linearising every bearing at ``x_j`` (``x_0 = μ̄``) and giving the posterior mean ``x̂_j``; the
next point is the best of ``x_j + α (x̂_j − x_j)``, ``α ∈ {1, ½, ¼, ⅛, 1/16, 0}``, by ``J`` (a line search:
two short-baseline, nearly parallel first rays make the full Gauss-Newton step overshoot by hundreds of metres,
measured). The result is the maximum a posteriori point of the prior and the first bearings — their
pseudo-intersection — and the update is linearised there. Once the track is within a metre, one pass per step:
Merino (3.52) as is.

**Prior** (chosen here, stated): ``N([c_0; 0], diag(σ_p², σ_p², σ_v², σ_v²))`` with ``c_0`` the team's orbit
centre at ``t = 0`` (the start of 004's approaching stage, 004 §6.1.1, which the team knows), ``σ_p = 18 m``
(004's initial offset of that centre from the target) and ``σ_v = 8 m/s`` (the top of 004's E2 speed range,
per axis).

**Estimates.** ``μ(t|t)`` estimates ``p(t)`` from the bearings up to ``t``; ``μ(t|t−1)`` from those up to ``t − 1``.
004's error (Eq. (1) at the sampling instant, :mod:`mesh_sim.orbit_experiments`) uses the centre computed from
the bearings up to ``t − 1`` without a prediction, so for a moving target it includes a one-step lag ``|v| Δt``
that neither EIF estimate has.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from fusion.batch import GaussianBatch
from fusion.information_filter import discretised
from fusion.measurement import wrap_angle
from fusion.motion import ConstantVelocity
from mesh_sim.orbit_experiments import SimResult

PRIOR_POSITION_STD = 18.0  # [m] chosen here: 004's initial offset of the team's centre from the target
PRIOR_VELOCITY_STD = 8.0  # [m/s] chosen here: the top of 004's E2 speed range, per axis
ITERATE_ABOVE = 1.0  # [m] chosen here: iterate the update while the predicted position std exceeds this
PASSES = 5  # chosen here: Gauss-Newton passes of the iterated update
STEPS = np.array([1.0, 0.5, 0.25, 0.125, 0.0625, 0.0])  # the line search's step lengths α


@dataclass(frozen=True)
class EifResult:
    """The EIF's estimates per run and step: posterior ``μ(t|t)`` ``(R, T, 4)`` and ``P(t|t)`` ``(R, T, 4, 4)``,
    prior ``μ(t|t−1)`` and ``P(t|t−1)`` (the initial prior at the first step), and the truth ``p(t)`` ``(R, T, 2)``.

    :attr:`centre_error` has the shape of :attr:`mesh_sim.orbit_experiments.SimResult.centre_error` (one estimate
    per run), so that module's metrics (``steady_rmse``, ``steady_state_time``, ``error_rms``) apply."""

    times: np.ndarray
    mean: np.ndarray
    cov: np.ndarray
    predicted_mean: np.ndarray
    predicted_cov: np.ndarray
    target: np.ndarray

    @property
    def error(self) -> np.ndarray:
        """``μ_p(t|t) − p(t)`` ``(R, T, 2)``."""
        return self.mean[..., :2] - self.target

    @property
    def centre_error(self) -> np.ndarray:
        """:attr:`error` as ``(R, T, 1, 2)``."""
        return self.error[:, :, None, :]

    def position_nees(self) -> np.ndarray:
        """``eᵀ P_pp⁻¹ e`` ``(R, T)`` with ``e`` = :attr:`error` and ``P_pp`` the position block of ``P(t|t)``:
        χ² with 2 degrees of freedom if the filter is consistent."""
        e = self.error[..., None]
        return (np.swapaxes(e, -1, -2) @ np.linalg.solve(self.cov[..., :2, :2], e))[..., 0, 0]

    def predicted(self) -> EifResult:
        """The same run read one step earlier: ``μ(t|t−1)``, ``P(t|t−1)`` in place of the posterior."""
        return replace(self, mean=self.predicted_mean, cov=self.predicted_cov)

    def select(self, runs: np.ndarray) -> EifResult:
        """The runs picked by ``runs`` (a boolean mask or indices over the run axis)."""
        return replace(
            self,
            mean=self.mean[runs],
            cov=self.cov[runs],
            predicted_mean=self.predicted_mean[runs],
            predicted_cov=self.predicted_cov[runs],
            target=self.target[runs],
        )


def matched_model(sigma_a: float, dt: float) -> ConstantVelocity:
    """skymesh's constant-velocity model in the plane with ``q = σ_a² Δt``: the velocity variance it adds per
    step, ``q Δt``, is the ``σ_a² Δt²`` of 004's KCF model (module docstring)."""
    return ConstantVelocity(spatial_dims=2, q=sigma_a**2 * dt)


def approach_prior(
    result: SimResult, position_std: float = PRIOR_POSITION_STD, velocity_std: float = PRIOR_VELOCITY_STD
) -> tuple[np.ndarray, np.ndarray]:
    """The stated prior (module docstring) for every run of ``result``: mean ``[c_0; 0]`` ``(R, 4)`` with ``c_0``
    the orbit centre of the first UAV at ``t = 0`` (004's tracking runs start on one common centre), and
    covariance ``diag(σ_p², σ_p², σ_v², σ_v²)`` ``(4, 4)``."""
    centre = result.centre_error[:, 0, 0] + result.bearings.target[:, 0]  # p̂(0) = e_p(0) + p(0)
    mean = np.concatenate([centre, np.zeros_like(centre)], axis=-1)
    return mean, np.diag([position_std**2] * 2 + [velocity_std**2] * 2)


def track(result: SimResult, model, prior_mean: np.ndarray, prior_cov: np.ndarray, sigma: float | None = None):
    """Run the centralized EIF (module docstring) on every bearing of ``result`` (a
    :func:`mesh_sim.orbit_experiments.simulate` result), every run at once.

    ``model`` is a :mod:`fusion.motion` model of a 4-D planar state (e.g. :func:`matched_model`, or the agents'
    ``DampedVelocity(spatial_dims=2, ...)``); ``prior_mean`` ``(R, 4)``, ``prior_cov`` ``(4, 4)`` or ``(R, 4, 4)``;
    ``sigma`` the bearing standard deviation the filter assumes [rad], by default the one the bearings were drawn
    with (pass one for noise-free bearings). Returns an :class:`EifResult`."""
    log = result.bearings
    sigma = log.sigma if sigma is None else sigma
    if not (np.isfinite(sigma) and sigma > 0):
        raise ValueError(f"the filter needs a positive bearing standard deviation, got {sigma}")
    if model.dim != 4:
        raise ValueError(f"the planar EIF needs a 4-D motion model [p; v], got dimension {model.dim}")
    runs, steps, n = log.azimuth.shape
    F, Q, F_inv = discretised(model, float(result.times[1] - result.times[0]))
    Y0 = np.broadcast_to(np.linalg.inv(prior_cov), (runs, 4, 4))
    belief = GaussianBatch((Y0 @ prior_mean[..., None])[..., 0], Y0)  # y = P⁻¹ μ, Y = P⁻¹ (Merino (3.7)-(3.8))
    weights = np.where(log.visible, sigma**-2, 0.0)  # R⁻¹ (R, T, n): no information from a UAV that does not see
    R_inv = weights[..., None, None]
    shape = (runs, steps, 4)
    mean, predicted_mean = np.empty(shape), np.empty(shape)
    cov, predicted_cov = np.empty((*shape, 4)), np.empty((*shape, 4))
    for k in range(steps):
        if k:
            belief = belief.predict(F, Q, F_inv)  # Merino Alg. 3.2
        prior = belief
        predicted_cov[:, k] = np.linalg.inv(prior.Y)
        predicted_mean[:, k] = point = (predicted_cov[:, k] @ prior.y[..., None])[..., 0]
        loose = np.trace(predicted_cov[:, k, :2, :2], axis1=-2, axis2=-1) > 2 * ITERATE_ABOVE**2
        passes = PASSES if loose.any() else 1
        for done in range(1, passes + 1):
            belief = prior
            for i in range(n):  # Merino (3.52), every bearing of this instant linearised at one point
                belief = belief.eif_update_bearing2d(
                    log.sensors[:, k, i], R_inv[:, k, i], log.azimuth[:, k, i, None], point
                )
            if done == passes:
                break
            step = _line_search(
                point,
                belief.means(),
                predicted_mean[:, k],
                prior.Y,
                log.sensors[:, k],
                log.azimuth[:, k],
                weights[:, k],
            )
            point = np.where(loose[:, None], step, point)
        cov[:, k] = np.linalg.inv(belief.Y)
        mean[:, k] = (cov[:, k] @ belief.y[..., None])[..., 0]
    return EifResult(result.times, mean, cov, predicted_mean, predicted_cov, log.target)


def _line_search(point, gauss_newton, prior_mean, prior_info, sensors, azimuth, weights) -> np.ndarray:
    """The best of ``x + α (x_GN − x)``, ``α`` in :data:`STEPS`, per run by the iterated update's objective
    ``J(x) = (x − μ̄)ᵀ Ȳ (x − μ̄) + Σ_i w_i wrap(z_i − atan2(p_y − s_y, p_x − s_x))²`` (module docstring).

    ``point``, ``gauss_newton``, ``prior_mean`` ``(R, 4)``, ``prior_info`` ``Ȳ`` ``(R, 4, 4)``, ``sensors``
    ``(R, n, 2)``, ``azimuth`` ``z`` and ``weights`` ``w = σ⁻²`` (0 unseen) ``(R, n)``."""
    candidates = point[:, None] + STEPS[:, None] * (gauss_newton - point)[:, None]  # (R, A, 4)
    d = candidates[:, :, None, :2] - sensors[:, None]  # (R, A, n, 2)
    residual = wrap_angle(azimuth[:, None] - np.arctan2(d[..., 1], d[..., 0]))  # z − h(x), h of Bearing2D
    offset = candidates - prior_mean[:, None]
    cost = np.einsum("rai,rij,raj->ra", offset, prior_info, offset) + np.sum(weights[:, None] * residual**2, -1)
    return candidates[np.arange(len(point)), np.argmin(cost, axis=1)]
