"""A self-contained simulator of Andreetto, Pacher, Macii, Palopoli and Fontanelli (Electronics 2018; spec 004
§6, §8) and its experiments E1-E3, vectorised over Monte Carlo runs.

**World** (spec 004 §3, §8). ``n`` point-mass quadrotors at one altitude, speed capped at 13 m/s, each
following its set-point (:mod:`tasking.circle_spacing`) taken one step ahead, ``ξ^d(t + Δt)``, with the
dead-beat follower ``ξ ← ξ + Δt cap((ξ^d(t + Δt) - ξ) / Δt)`` (chosen here in place of the Mahony et al.
quadrotor model and its trajectory controller). A downward camera, gimballed so its axis points at the UAV's orbit
centre, sees the target in the triangular FOV ``|η| <= η_max = 30°``, range ``<= R_max``; the bearing has
Gaussian noise (σ = 1°), the axis heading comes from the magnetometer (σ = 0.5° in 6.2; 0 in 6.1, where the
paper's 1° "also comprises the magnetometer uncertainty") and positions from GPS (σ = 2 cm). A searching UAV
points its camera along its direction of flight and takes the point ``r`` ahead as its provisional centre.
Communication is the disk graph ``‖ξ_i - ξ_j‖ < C_r`` in synchronous rounds without loss (spec 004 §6), or, with
``message_loss = p``, each directed message of an estimation round (the three rounds below) lost independently
with probability ``p``: a receiver keeps a lost neighbour's Metropolis weight on itself
(:func:`tasking.consensus.lossy_weights`, which says why) and the KCF sums what it received. The rendezvous
telling and the spacing law's neighbour phases keep the disk graph (their loss is not modelled).

**One step** (spec 004 §2.7; three rounds = the paper's 3 messages per UAV per step):

1. every UAV that sees the target forms ``m_i`` (004 Eq. (2)) with ``r`` the GPS distance to its centre;
2. rounds 1..f of the consensus WLS with Metropolis weights on ``(P, q) = (I, m_i)`` (equal weights: the
   paper's centroid), every UAV taking part (the ones without a measurement relay zero information);
3. the KCF (round 2) at every tracking UAV with ``z_i`` = its round-1 WLS estimate of the *reflected* measures
   (:func:`tasking.centre_measure.reflected_measures`, sent with ``m_i`` in round 1; chosen here: the centroid
   of Eq. (2) is biased towards the current centre by ``(1 - β/2) e``, which a filter with ``H = [I 0]`` reads as
   the target, settles on a wrong velocity and drifts); on entering the stage the filter starts at
   ``[p̂_i, v̂_i]`` with ``v̂_i`` the least-squares slope of the centre over the last ``approach_readings`` steps
   (the approaching stage's centre moves with the target once it has converged; chosen here);
4. one WLS round (round 3) on the KCF posteriors, information-weighted (``M_i⁻¹``);
5. centres (004 Eq. (4)): a UAV in the approaching stage takes the round-``f`` WLS estimate, one in the tracking stage
   the round-3 estimate, ``[p̂_i(t+1); ṗ̂_i(t+1)] = x̂_{i,ML}(t)`` (004 §2.7 step 5 as written: the centre is the
   estimate of ``p(t)``, a one-step lag ``|v| Δt`` at the next sampling instant — which with the paper's noise floor
   gives its dynamic E2 figures, sqrt(0.25² + (8√2 · 0.05)²) = 0.62 m at v = 8; the velocity is the translation's
   feed-forward, §2.8); a UAV told a circle (:mod:`tasking.rendezvous` case 1) takes the mean centre of the
   orbiting UAVs it hears that have target information this step (a blind circle recruits nobody); a UAV with no
   information keeps its centre (and keeps rotating);
6. set-points: rotation with equal spacing on the circle plus translation with the centre (§2.8): each UAV
   keeps its phase on the circle it was orbiting and that circle moves to the new centre
   (:func:`tasking.circle_spacing.spacing_setpoint`), or the next random patrol point for a searching UAV
   (§2.9, 200 x 200 m).

The error of Eq. (1) is taken at the sampling instants, ``e_p(t) = p̂(t) - p(t)`` with ``p̂(t)`` the centre the
UAVs orbit while measuring at ``t``. Every UAV's reading of every step (GPS position, measured azimuth ``ψ_i + η_i``,
visibility) is kept in :class:`BearingLog`, so another estimator can run on the same bearings
(:mod:`mesh_sim.orbit_eif`: skymesh's centralized EIF).

``f = 3`` by default, so the static algorithm also sends 3 messages per step (the paper: "after five
iterations the difference ... is negligible"; 3 is its message budget in Sec. 6).

**Parameters the paper does not give** (chosen here; :class:`OrbitConfig`): ``κ = 6`` (the paper's κ > 5)
and ``Λ = 1`` — the saturation binds and every ``m_i`` lands on its line of sight. In 6.1, ``r = 30 m``: 6.2
gives ``r = 15 m`` with ``C_r = 30 m`` (two UAVs anywhere on one circle hear each other), and the same
``r = C_r / 2`` with 6.1's 60 m is 30 m. For equally spaced UAVs and exact consensus the static error obeys
``e ← (1 - Λ/2) e + noise``, whose stationary RMSE is ``r σ_η sqrt(Λ / (n (1 - Λ/4)))``; with ``r = 30 m`` the
paper's own static figure at v = 0 (0.27 m at n = 5) gives ``Λ = 0.998``, so ``(r, Λ)`` rest on that one number
and on ``C_r``, and every other figure is a prediction; ``R_max = ∞`` in 6.1 (not
given; with the 30° FOV the 18 m initial offset is then visible from the far side of the circle). KCF:
``R = (sqrt(2) r σ)² I`` with ``σ² = σ_η² + σ_ψ²`` (0.74 m at r = 30 m: a reflected measure's noise ``2 r σ`` along
``l_⊥``, halved in variance over two axes; the one-step WLS averages ~n measures and ``S_i`` adds ~n such
averages back, which cancel), ``P0 = diag(5 m, 5 m,
8 m/s, 8 m/s)²``, ``ε = 0.5``, σ_a = 0.01 m/s² (the paper; E1 passes its own value, see
:mod:`mesh_sim.bench.tasking_orbit`); approaching stage of 20 readings; ω_0 = 0.2 rad/s, k_θ = 0.5 1/s.

**Targets** (spec 004 §4): static; the closed-form figure-8 ``p(t) = d [sin(4πωt), sin(2πωt)]``, ``d = 20 m``,
``ω = 0.0285 Hz``; constant velocity ``[v, v]``; Singer "man-like" with exact discretisation
(:func:`mesh_sim.orbit_targets.man_like_paths`: α̃ = 10², x(0) = [0, 0, 1, 1, 1, 1], σ_w = 0.1). Truth for
every step is computed before the run.

**Experiments**: E1 RMSE vs ``n`` on the figure-8, static vs dynamic (dt = 0.05 s, C_r = 60 m, initial centre
18 m from the target, RMSE over t > 20 s, steady-state time); E2 constant-velocity target, ``n = 5``,
v = 0..8 m/s; E3 rendezvous on a static target (dt = 1 s, r = 15 m, R_max = 30 m, C_r = 30 m, random patrol in
200 x 200 m): each UAV's distance to the target circle ``|‖ξ_i - p‖ - r|``; E4 the same with the man-like target
(:func:`run_rendezvous` with ``target="singer"``).

**Metrics** (004 §6.1.1: "The performance index is the average steady-state estimation uncertainty, i.e., the
steady state Root Mean Squared Error (RMSE). This is obtained by averaging the results of 50 different
simulations"): each run's RMSE, averaged over the runs (:func:`steady_rmse`, :func:`error_rms`); the steady-state
time is read on that averaged curve (:func:`steady_state_time`); a run whose error exceeds ``r`` in the
steady-state window lost the target and is counted apart (:func:`kept_runs`).

**Why E1 misses "less than 4 s for n = 3"** (measured; no parameter was changed for it). ``r = 30 m`` and the 18 m
offset leave 37.5 % of the initial circle blind (``|η| > 30°`` between the phases where ``sin η = 18 / 30`` nears
its 36.9° peak). In a few per cent of random starts exactly one UAV sees the target, nearly on its axis (``η ≈ 0``,
e.g. from the far side), and the other two sit in the blind arcs. That UAV's measure moves the centre across its
line of sight only (Eq. (2): ``m_i = p̂_i`` when the target is on the axis); as it turns, the centre stays on its
line of sight and the whole formation turns rigidly about the target, the other two UAVs staying blind. This is the
singular configuration of 004's Corollary 1, "``η_1(t) = 0`` from different locations on the circle", which the
paper says "at least 3 different measures per revolution" avoid. At dt = 0.05 s they do not: a step turns the line
of sight by ``α ≈ ω_0 Δt r / (r + e)`` (0.006 rad), the error decays by ``cos α`` per step, and the 1° bearing noise
(0.8 m at 48 m) grows it faster (a static target stays 18-23 m off for 20 s; the test
``test_one_collinear_seer_traps_a_team_of_three_behind_the_fov_limit``). Without the FOV limit (Theorem 1's
assumption) the same start converges in under a second. With ``n = 4`` equal spacing puts the fourth UAV on the same
line (measured, 50 runs: 8.5 s static, 10.3 s dynamic; the paper states no bound for n = 4); from ``n = 5`` on some
UAV sees the target from another direction (1.7 s / 1.05 s at n = 5). The figure-8 (8 m/s at ``t = 0``) either frees
such a run after seconds or escapes it for good (2 of 50 runs at n = 3).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from mesh_sim.orbit_targets import man_like_paths
from mesh_sim.targets import ConstantVelocityTarget, Figure8Target, StaticTarget
from tasking.centre_measure import (
    ETA_MAX,
    bearing,
    centre_measures,
    heading,
    reflected_measures,
    reflected_noise_std,
    visible,
    wrap_angle,
)
from tasking.circle_spacing import K_THETA, MAX_SPEED, OMEGA_0, cap_speed, circle_gaps, spacing_rate, spacing_setpoint
from tasking.consensus import (
    DoubleIntegrator,
    consensus_round,
    kcf_step,
    lossy_weights,
    metropolis_weights,
    wls_estimate,
    wls_information,
)
from tasking.rendezvous import Stage, StageRules, StageState, next_stage

PATROL_AREA = (-100.0, 100.0, -100.0, 100.0)  # 004 §2.9: 200 x 200 m, target at the centre
STEADY_STATE_FROM = 20.0  # 004 §5.1: RMSE over t > 20 s
ROUNDS = 3  # 004 §6.1.1: "each UAV sends 3 messages" per step (rounds 1-3 of the module docstring)


@dataclass(frozen=True)
class OrbitConfig:
    """One simulated configuration; defaults are the tracking simulations of spec 004 §6.1."""

    n: int = 5
    dt: float = 0.05
    duration: float = 60.0
    dynamic: bool = False  # False: static algorithm only; True: approaching then tracking stage
    radius: float = 30.0  # chosen here (6.1 does not give it): C_r / 2, as in 6.2 (module docstring)
    kappa: float = 6.0  # chosen here: κ > 5 (004 §2.6)
    Lambda: float = 1.0  # chosen here, 0 < Λ < 2: from the paper's 0.27 m static figure (module docstring)
    eta_max: float = ETA_MAX
    range_max: float = math.inf  # chosen here for 6.1 (not given there): no range limit
    comm_range: float = 60.0
    wls_iterations: int = 3
    approach_readings: int = 20
    track_patience: float = 0.5  # [s], chosen here; converted to whole steps (at least 1)
    lost_patience: float = 30.0  # [s], chosen here
    sigma_bearing: float = math.radians(1.0)
    sigma_yaw: float = 0.0
    sigma_gps: float = 0.02
    sigma_a: float = 0.01
    kcf_R_std: float | None = None  # None: the reflected measure's own noise (module docstring)
    kcf_P0_std: tuple[float, float] = (5.0, 8.0)
    epsilon: float = 0.5
    omega_0: float = OMEGA_0
    k_theta: float = K_THETA
    max_speed: float = MAX_SPEED
    initial_offset: float = 18.0  # 004 §6.1.1: initial centre 18 m from the target
    message_loss: float = 0.0  # Bernoulli loss of each directed estimation message (004 §6: none; module docstring)

    def __post_init__(self):
        if isinstance(self.n, bool) or int(self.n) != self.n or self.n < 1:
            raise ValueError(f"n must be a positive number of UAVs, got {self.n}")
        if not 0 <= self.message_loss < 1:
            raise ValueError(f"message_loss must be a probability in [0, 1), got {self.message_loss}")
        for name in ("dt", "duration", "radius", "comm_range", "max_speed"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be positive, got {value}")

    @property
    def steps(self) -> int:
        return int(round(self.duration / self.dt))

    @property
    def kcf_R(self) -> float:
        """The KCF's per-axis measurement std [m]: ``kcf_R_std``, or the reflected measure's
        ``sqrt(2) r sqrt(σ_η² + σ_ψ²)`` (:func:`tasking.centre_measure.reflected_noise_std`)."""
        if self.kcf_R_std is not None:
            return self.kcf_R_std
        return reflected_noise_std(self.radius, math.hypot(self.sigma_bearing, self.sigma_yaw))

    @property
    def rules(self) -> StageRules:
        track, lost = (max(1, math.ceil(s / self.dt - 1e-9)) for s in (self.track_patience, self.lost_patience))
        return StageRules(self.approach_readings if self.dynamic else None, track, lost)


@dataclass(frozen=True)
class BearingLog:
    """What every UAV's camera measured at every step, for an estimator that watches the same flight
    (:mod:`mesh_sim.orbit_eif`): the GPS position of the sensor ``(R, T, n, 2)``, the measured azimuth of the line
    of sight ``ψ_i + η_i`` (axis heading from the magnetometer plus the camera bearing, the angle from the first
    axis towards the second, as :func:`fusion.measurement.Bearing2D`) ``(R, T, n)``, whether the target was in
    the FOV ``(R, T, n)`` (the azimuth means nothing where it was not), its standard deviation
    ``sqrt(σ_η² + σ_ψ²)`` [rad], and the truth ``p(t)`` ``(R, T, 2)``."""

    sensors: np.ndarray
    azimuth: np.ndarray
    visible: np.ndarray
    sigma: float
    target: np.ndarray


@dataclass(frozen=True)
class SimResult:
    """``times (T,)``; per run, step and UAV: the centre error ``p̂_i - p`` ``(R, T, n, 2)``, the distance to
    the target circle ``(R, T, n)`` and the stage ``(R, T, n)``; the bearings measured (``None`` for a result
    assembled from parts)."""

    times: np.ndarray
    centre_error: np.ndarray
    circle_distance: np.ndarray
    stage: np.ndarray
    bearings: BearingLog | None = None


# ----------------------------------------------------------------------------------------- targets
def target_paths(kind: str, runs: int, times: np.ndarray, speed: float = 0.0, seed: int = 0) -> np.ndarray:
    """Ground truth ``(R, T, 2)`` at ``times`` for ``kind`` in static / figure8 / cv / singer (spec 004 §4)."""
    if kind == "singer":  # 004 §4.4 (Eqs. (16)-(17)), exactly discretised: mesh_sim.orbit_targets
        return man_like_paths(runs, times, seed)
    models = {
        "static": lambda: StaticTarget((0.0, 0.0)),
        "figure8": lambda: Figure8Target((0.0, 0.0)),
        "cv": lambda: ConstantVelocityTarget((0.0, 0.0), (speed, speed)),
    }
    if kind not in models:
        raise ValueError(f"target kind must be one of {sorted([*models, 'singer'])}, got {kind!r}")
    target = models[kind]()
    path = np.array([target.state(float(t))[0][:2] for t in times])
    return np.broadcast_to(path, (runs, *path.shape)).copy()


# ------------------------------------------------------------------------------------- simulation
def simulate(
    config: OrbitConfig,
    paths: np.ndarray,
    positions: np.ndarray,
    centres: np.ndarray,
    stage: Stage,
    rng: np.random.Generator,
) -> SimResult:
    """Run ``config`` on truth ``paths (R, T, 2)`` from UAV ``positions`` and ``centres`` ``(R, n, 2)``, every
    UAV starting in ``stage`` (``SEARCH`` patrols, ``APPROACH`` orbits its centre)."""
    c = config
    runs, n = positions.shape[:2]
    steps = paths.shape[1]
    eye = np.eye(n, dtype=bool)
    model = DoubleIntegrator(c.dt, c.sigma_a)
    R_kcf = c.kcf_R**2 * np.eye(2)
    P0 = np.diag(np.repeat(np.square(c.kcf_P0_std), 2))
    xi, centre = positions.astype(float).copy(), centres.astype(float).copy()
    state = StageState.start((runs, n), stage)
    kcf_mean, kcf_cov = np.zeros((runs, n, 4)), np.broadcast_to(P0, (runs, n, 4, 4)).copy()
    waypoint = _patrol_points(rng, (runs, n))
    window = max(2, c.approach_readings)  # the centre history the KCF's velocity starts from
    history = np.broadcast_to(centre[:, None], (runs, window, n, 2)).copy()
    errors = np.empty((runs, steps, n, 2))
    circle = np.empty((runs, steps, n))
    stages = np.empty((runs, steps, n), dtype=np.int8)
    sensors, azimuth, seen = np.empty((runs, steps, n, 2)), np.empty((runs, steps, n)), np.empty((runs, steps, n), bool)
    for k in range(steps):
        p = paths[:, k, None, :]  # (R, 1, 2)
        orbiting, stage_before = state.orbiting, state.stage
        errors[:, k] = centre - p  # 004 Eq. (1): e_p(t) = p̂(t) - p(t), the centres the UAVs orbit during step t
        # --- communication graph and camera
        adjacency = (np.linalg.norm(xi[:, :, None] - xi[:, None, :], axis=-1) < c.comm_range) & ~eye
        W = metropolis_weights(adjacency)
        heard, weights = _rounds(W, adjacency, c.message_loss, max(c.wls_iterations, ROUNDS), rng)
        flight = _unit(waypoint - xi)
        look_at = np.where(orbiting[..., None], centre, xi + c.radius * flight)  # the (provisional) centre
        axis = heading(look_at - xi)
        eta = bearing(xi, axis, p)
        sees = visible(eta, np.linalg.norm(p - xi, axis=-1), c.eta_max, c.range_max)
        # --- 1. centre measures from noisy sensors (004 Eq. (2))
        eta_measured = eta + c.sigma_bearing * rng.standard_normal((runs, n))
        axis_measured = axis + c.sigma_yaw * rng.standard_normal((runs, n))
        gps = xi + c.sigma_gps * rng.standard_normal((runs, n, 2))
        m = centre_measures(
            look_at, axis_measured, eta_measured, np.linalg.norm(look_at - gps, axis=-1), c.kappa, c.Lambda
        )
        reflected = reflected_measures(look_at, m, c.kappa, c.Lambda)
        sensors[:, k], azimuth[:, k], seen[:, k] = gps, wrap_angle(axis_measured + eta_measured), sees
        # --- 2. consensus WLS rounds
        P, q = wls_information(m, np.eye(2), sees)
        for round_weights in weights[: c.wls_iterations]:
            P, q = consensus_round(round_weights, P, q)
        static_estimate, informed = wls_estimate(P, q, look_at)
        if c.dynamic:  # the KCF's measure: one round on the reflected measures, sent with m_i in round 1
            P1, q1 = consensus_round(weights[0], *wls_information(reflected, np.eye(2), sees))
            one_step, informed_one = wls_estimate(P1, q1, look_at)
        # --- rendezvous: who hears an orbiting UAV that has target information, and the circle it is told
        orbit_links = adjacency & (orbiting & informed)[:, None, :]
        hears_orbit = orbit_links.any(axis=-1)
        told = (orbit_links[..., None] * centre[:, None, :, :]).sum(axis=2) / np.maximum(orbit_links.sum(axis=-1), 1)[
            ..., None
        ]
        state = next_stage(state, informed | (hears_orbit & ~orbiting), c.rules)
        new_centre = np.where(informed[..., None], static_estimate, np.where(hears_orbit[..., None], told, centre))
        active = state.orbiting
        velocity = np.zeros_like(centre)  # the static algorithm translates with the centre only
        # --- 3.-4. KCF at the tracking UAVs (started at [p̂_i, 0], P0 on entering the stage), then one WLS round
        tracking = state.stage == Stage.TRACK
        if c.dynamic and tracking.any():
            entering = (tracking & ~(stage_before == Stage.TRACK))[..., None]
            warm = np.concatenate([centre, _slope(history, c.dt)], -1)  # [p̂_i, LS velocity of the approach]
            kcf_mean = np.where(entering, warm, kcf_mean)
            kcf_cov = np.where(entering[..., None], P0, kcf_cov)
            kcf = kcf_step(
                model,
                kcf_mean,
                kcf_cov,
                heard[1] & tracking[:, :, None] & tracking[:, None, :],
                one_step,
                informed_one & tracking,
                R_kcf,
                c.epsilon,
            )
            info = np.where(tracking[..., None, None], np.linalg.inv(kcf.cov), 0.0)
            P4, q4 = consensus_round(weights[2], info, (info @ kcf.mean[..., None])[..., 0])
            x_ml, _ = wls_estimate(P4, q4, kcf.mean)
            new_centre = np.where(tracking[..., None], x_ml[..., :2], new_centre)  # [p̂_i(t+1); ṗ̂_i(t+1)] = x̂_{i,ML}(t)
            velocity = np.where(tracking[..., None], x_ml[..., 2:], velocity)
            kcf_mean, kcf_cov = kcf.next_mean, kcf.next_cov
        phase_centre = np.where(orbiting[..., None], centre, new_centre)  # the circle each UAV was on (§2.8)
        centre = np.where(active[..., None], new_centre, centre)
        history = np.concatenate([history[:, 1:], centre[:, None]], axis=1)
        circle[:, k] = np.abs(np.linalg.norm(xi - p, axis=-1) - c.radius)
        stages[:, k] = state.stage
        # --- set-points and motion
        theta, ahead, behind = circle_gaps(phase_centre, xi, adjacency & active[:, :, None] & active[:, None, :])
        rate = spacing_rate(
            ahead, behind, c.radius, c.dt, np.linalg.norm(velocity, axis=-1), c.omega_0, c.k_theta, c.max_speed
        )
        orbit = spacing_setpoint(centre, velocity, theta, rate, c.radius, c.max_speed, lead=c.dt)
        reached = np.linalg.norm(waypoint - xi, axis=-1) < c.max_speed * c.dt
        waypoint = np.where(reached[..., None], _patrol_points(rng, (runs, n)), waypoint)
        goal = np.where(active[..., None], orbit.position, waypoint)  # where to be at t + Δt
        xi = xi + c.dt * cap_speed((goal - xi) / c.dt, c.max_speed)
    log = BearingLog(sensors, azimuth, seen, math.hypot(c.sigma_bearing, c.sigma_yaw), paths.copy())
    return SimResult(np.arange(steps) * c.dt, errors, circle, stages, log)


def _rounds(W: np.ndarray, adjacency: np.ndarray, loss: float, rounds: int, rng: np.random.Generator):
    """Per round of a step, who received whose message ``(R, n, n)`` and the weights that round averages with: each
    directed message lost independently with probability ``loss`` (:func:`tasking.consensus.lossy_weights`);
    without loss, the disk graph and ``W`` (the RNG is not drawn)."""
    if loss == 0:
        return [adjacency] * rounds, [W] * rounds
    heard = list(adjacency & (rng.random((rounds, *adjacency.shape)) >= loss))
    return heard, [lossy_weights(W, round_heard) for round_heard in heard]


def _slope(history: np.ndarray, dt: float) -> np.ndarray:
    """Least-squares velocity ``(R, n, 2)`` of the centre history ``(R, W, n, 2)`` (oldest first) sampled every
    ``dt``: ``Σ_j (t_j - t̄) p̂(t_j) / Σ_j (t_j - t̄)²``."""
    offsets = (np.arange(history.shape[1]) - (history.shape[1] - 1) / 2.0) * dt  # t_j - t̄
    return np.tensordot(offsets / np.sum(offsets**2), history, axes=(0, 1))


def _unit(vectors: np.ndarray) -> np.ndarray:
    norm = np.linalg.norm(vectors, axis=-1, keepdims=True)
    return np.where(norm > 1e-9, vectors / np.maximum(norm, 1e-9), np.array([1.0, 0.0]))


def _patrol_points(rng: np.random.Generator, shape) -> np.ndarray:
    north_min, north_max, east_min, east_max = PATROL_AREA
    return np.stack([rng.uniform(north_min, north_max, shape), rng.uniform(east_min, east_max, shape)], axis=-1)


# ------------------------------------------------------------------------------------ experiments
def tracking_start(config: OrbitConfig, paths: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """004 §6.1.1: every team's common centre ``initial_offset`` from the target in a random direction, the UAVs at
    random phases on that circle. Returns ``(positions, centres)``, each ``(R, n, 2)``."""
    runs = paths.shape[0]
    direction = rng.uniform(0, 2 * np.pi, runs)
    centre = paths[:, 0] + config.initial_offset * np.stack([np.cos(direction), np.sin(direction)], -1)
    phases = rng.uniform(0, 2 * np.pi, (runs, config.n))
    positions = centre[:, None] + config.radius * np.stack([np.cos(phases), np.sin(phases)], -1)
    return positions, np.broadcast_to(centre[:, None], positions.shape).copy()


def run_tracking(config: OrbitConfig, target: str, runs: int, seed: int, speed: float = 0.0) -> SimResult:
    """E1/E2: a team starting on a common orbit 18 m off the target, in the approaching stage."""
    rng = np.random.default_rng(seed)
    times = np.arange(config.steps) * config.dt
    paths = target_paths(target, runs, times, speed, seed)
    positions, centres = tracking_start(config, paths, rng)
    return simulate(config, paths, positions, centres, Stage.APPROACH, rng)


def rendezvous_config(**changes) -> OrbitConfig:
    """E3 settings, spec 004 §6.2.1: dt = 1 s, r = 15 m, R_max = 30 m, C_r = 30 m, magnetometer σ = 0.5°."""
    base = OrbitConfig(
        n=5, dt=1.0, duration=900.0, radius=15.0, range_max=30.0, comm_range=30.0, sigma_yaw=math.radians(0.5)
    )
    return replace(base, **changes)


def run_rendezvous(config: OrbitConfig, runs: int, seed: int, target: str = "static") -> SimResult:
    """E3 (``target="static"``) and E4 (``"singer"``, the man-like target): UAVs deployed uniformly in the
    200 x 200 m area, all searching; the target starts at the origin."""
    rng = np.random.default_rng(seed)
    times = np.arange(config.steps) * config.dt
    paths = target_paths(target, runs, times, 0.0, seed)
    positions = _patrol_points(rng, (runs, config.n))
    return simulate(config, paths, positions, positions.copy(), Stage.SEARCH, rng)


# ------------------------------------------------------------------------------------------ metrics
def run_rms(result: SimResult) -> np.ndarray:
    """One simulation's RMSE curve: ``sqrt(mean over UAVs of ‖p̂_i(t) - p(t)‖²)`` per run and step ``(R, T)``."""
    return np.sqrt(np.mean(np.sum(result.centre_error**2, axis=-1), axis=2))


def error_rms(result: SimResult) -> np.ndarray:
    """The RMSE curve of 004 §6.1.1 ``(T,)``: each simulation's :func:`run_rms` averaged over the simulations
    ("This is obtained by averaging the results of 50 different simulations"), not one RMS pooled over them (in
    which a single slow run dominates: one run at 25 m among 50 weighs 3.5 m pooled, 0.5 m averaged)."""
    return run_rms(result).mean(axis=0)


def steady_rmse(result: SimResult, start: float = STEADY_STATE_FROM) -> float:
    """The steady-state RMSE of 004 §6.1.1-6.1.2: each run's RMSE over UAVs and every step with ``t > start``,
    averaged over the runs ("the steady state Root Mean Squared Error (RMSE). This is obtained by averaging the
    results of 50 different simulations")."""
    late = result.times > start
    per_run = np.sqrt(np.mean(np.sum(result.centre_error[:, late] ** 2, axis=-1), axis=(1, 2)))
    return float(per_run.mean())


def steady_state_time(result: SimResult, start: float = STEADY_STATE_FROM, window: float = 0.25) -> float:
    """When the RMSE "reaches the steady state" (004 §5.1; the paper gives no definition, chosen here): the first
    ``t`` from which the average of :func:`error_rms` over ``[t, t + window)`` is within the largest such average
    over ``t > start`` (the envelope of the steady-state oscillation, e.g. the lag at the figure-8's fastest point).
    The window looks ahead, so an error that settles at ``t`` is settled at ``t`` (a trailing window would report
    ``t + window``); it only smooths the step-to-step noise."""
    rms = error_rms(result)
    width = max(1, int(round(window / (result.times[1] - result.times[0]))))
    ahead = np.convolve(rms, np.ones(width) / width, mode="valid")  # mean of rms[k : k + width]
    times = result.times[: ahead.size]
    envelope = ahead[times > start].max()
    return float(times[np.flatnonzero(ahead <= envelope)[0]])


def kept_runs(result: SimResult, radius: float, start: float = STEADY_STATE_FROM) -> np.ndarray:
    """Per run, whether the team kept the target: every centre within ``radius`` (the orbit radius) of it at
    every step with ``t > start`` ``(R,)``. A run that lost it (its error grew past the circle it orbits) is
    counted apart: the paper reports none, and one such run would dominate any average."""
    late = result.times > start
    return np.linalg.norm(result.centre_error[:, late], axis=-1).max(axis=(1, 2)) < radius


def final_circle_distances(result: SimResult, tail: float = 0.1) -> np.ndarray:
    """Each UAV's distance to the target circle averaged over the last ``tail`` of the run ``(R, n)``."""
    last = max(1, int(round(tail * result.times.size)))
    return result.circle_distance[:, -last:].mean(axis=1)


def rendezvous_time(result: SimResult, tolerance: float = 2.0) -> np.ndarray:
    """Per run, when every UAV is within ``tolerance`` m of the target circle for the rest of the run (nan:
    never). ``tolerance`` chosen here."""
    far = (result.circle_distance > tolerance).any(axis=-1)  # (R, T)
    times = np.full(far.shape[0], np.nan)
    for run, row in enumerate(far):
        if not row[-1]:
            above = np.flatnonzero(row)
            times[run] = 0.0 if above.size == 0 else result.times[min(above[-1] + 1, row.size - 1)]
    return times
