"""A self-contained simulation of the feature-following mission of spec 003 (Lee, Kaminer, Dobrokhodov and
Jones, NPS 2010, §1.1 and §5): a fixed wing follows the flight path optimised for an operator's feature
polyline (a river or a road), a gimbaled camera keeps the feature at the image centre, and the cascaded
navigation filter feeds both, while a GPS receiver may develop a fault.

One run, at the dead-reckoning rate ``nav_rate`` (20 Hz, chosen here; the vehicle model integrates in 0.02 s
sub-steps within it):

1. plan: :func:`tasking.feature_path.fit_feature`, :func:`tasking.feature_following.optimise_flight_path`
   (Eqs. 1-17); the vehicle (:class:`agent.vehicles.fixed_wing.FixedWingModel` at the optimised speed) gets
   the :class:`tasking.feature_following.PathFollower` goal at the agent rate (5 Hz), computed from the
   *estimated* position;
2. sense: the attitude filter's output is the true quaternion plus N(0, 𝒫_q) (the paper's steady-state
   assumption), the speed is the airspeed plus N(0, σ_V²) (no wind is simulated, so airspeed is ground speed),
   the specific force is the true mean acceleration over the step minus gravity, in body axes, plus N(0, σ_a²);
   GPS position and velocity arrive at ``gps_rate`` (10 Hz, spec 003 Eq. 26) from ``receivers`` receivers,
   receiver 0 carrying the fault (a step of ``fault_size`` m north, or a drift of ``fault_size`` m/s north,
   from ``fault_time``);
3. estimate: :class:`fusion.navigation.NavigationFilter`, wrapped in :class:`fusion.navigation.GpsFaultIsolation`
   when ``isolation`` is on (else every GPS datum is used, the baseline);
4. point: :func:`tasking.gimbal.point_at` from the estimated pose to the feature point abeam (chosen at the
   guidance rate: along a line feature its drift between choices does not move the line off-centre), then
   :func:`tasking.gimbal.slew` at the servo rate limits;
5. measure (at ``metric_rate``, 5 Hz): the true camera (:class:`perception.pose.CameraPose`, 640x480, 30° FOV,
   :mod:`perception.projection`) images the true feature; the *centring error* is the pixel distance from the
   principal point to the imaged feature polyline (a line feature is centred when it crosses the centre) and
   its angle ``atan(r / f)``; the cross-track error of the true vehicle from the optimised path; the
   navigation error ``‖p - p̂‖``.

Not simulated (spec 003 leaves them open or they are not needed here): wind, the loiter/bridge phases (the
vehicle starts on the path), the attitude filter's dynamics, servo quantisation and image processing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from agent.vehicles.base import GRAVITY, goal_to_setpoint
from agent.vehicles.fixed_wing import FixedWingModel
from fusion.navigation import GpsFaultIsolation, NavigationFilter, NavigationNoise
from perception.camera import Intrinsics
from perception.pose import CameraPose, Gimbal
from perception.projection import world_to_pixel
from tasking.feature_following import FlightPath, PathFollower, optimise_flight_path
from tasking.feature_path import fit_feature
from tasking.gimbal import GimbalAngles, GimbalLimits, VehiclePose, point_at, rotation_ned_from_frd, slew

#: A meandering river, (north, east) metres (chosen here): about 2.4 km with bends of 250-600 m radius.
RIVER = (
    (0.0, 0.0), (300.0, 80.0), (600.0, 20.0), (900.0, 150.0), (1200.0, 350.0),
    (1450.0, 600.0), (1600.0, 900.0), (1900.0, 1050.0), (2200.0, 1000.0),
)
FAULT_KINDS = (None, "step", "drift")
#: Half-length (m) of the stretch of feature projected around the abeam point when measuring centring.
FEATURE_WINDOW = 150.0


@dataclass(frozen=True)
class MissionConfig:
    """One run's settings (all chosen here unless stated; spec 003 gives none of them)."""

    feature: tuple = RIVER
    altitude: float = 200.0  # m above the feature
    nav_rate: float = 20.0  # Hz
    gps_rate: float = 10.0  # Hz ("ds = 10 Hz", spec 003 Eq. 26)
    guidance_rate: float = 5.0  # Hz, the agent rate (DESIGN §4)
    metric_rate: float = 5.0  # Hz
    receivers: int = 1  # the paper's aircraft has one (Piccolo) GPS
    gps_std: float = 2.0  # m per axis
    gps_velocity_std: float = 0.1  # m/s per axis
    noise: NavigationNoise = field(default_factory=NavigationNoise.from_std)
    speed_std: float = 0.5  # m/s, the airspeed error actually drawn (the filter's 𝒫_v also covers cross axes)
    fault: str | None = "step"
    fault_size: float = 25.0  # m (step) or m/s (drift), north
    fault_time: float = 40.0  # s
    isolation: bool = True
    camera: Intrinsics = field(default_factory=lambda: Intrinsics.from_fov(640, 480, 30.0))
    gimbal: GimbalLimits = field(default_factory=GimbalLimits)
    seed: int = 0

    def __post_init__(self):
        if self.fault not in FAULT_KINDS:
            raise ValueError(f"fault must be one of {FAULT_KINDS}, got {self.fault!r}")
        for name in ("altitude", "nav_rate", "gps_rate", "guidance_rate", "metric_rate", "gps_std",
                     "gps_velocity_std", "speed_std"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value}")
        for name in ("gps_rate", "guidance_rate", "metric_rate"):
            ratio = self.nav_rate / getattr(self, name)
            if abs(ratio - round(ratio)) > 1e-9:
                raise ValueError(f"nav_rate ({self.nav_rate} Hz) must be a multiple of {name} "
                                 f"({getattr(self, name)} Hz)")
        if isinstance(self.receivers, bool) or not isinstance(self.receivers, int) or self.receivers < 1:
            raise ValueError(f"receivers must be a positive integer, got {self.receivers!r}")
        if not (math.isfinite(self.fault_size) and math.isfinite(self.fault_time) and self.fault_time >= 0):
            raise ValueError(f"fault_size and fault_time must be finite (time >= 0), got {self.fault_size}, "
                             f"{self.fault_time}")


@dataclass
class MissionResult:
    """Time series (at the metric rate) and the fault events of one run."""

    flight: FlightPath
    times: np.ndarray
    centring_px: np.ndarray  # distance of the imaged feature from the principal point (NaN: not in front)
    centring_angle: np.ndarray  # atan(r / f), rad
    cross_track: np.ndarray  # m, true vehicle vs optimised path
    nav_error: np.ndarray  # m, ‖p - p̂‖
    fault_time: float | None
    isolated_at: dict[str, float | None]
    rejection_rate: dict[str, float]

    @property
    def detection_delay(self) -> float:
        """Isolation of the faulty receiver minus the fault onset (s); NaN if none or not isolated."""
        at = self.isolated_at.get("gps0")
        return at - self.fault_time if at is not None and self.fault_time is not None else math.nan


def _distance_to_polyline(point: np.ndarray, polyline: np.ndarray) -> float:
    """Euclidean distance from ``point`` (2,) to the polyline (K, 2), NaN rows dropped."""
    poly = polyline[np.all(np.isfinite(polyline), axis=1)]
    if len(poly) < 2:
        return math.nan
    a, b = poly[:-1], poly[1:]
    ab = b - a
    s = np.clip(np.sum((point - a) * ab, axis=1) / np.maximum(np.sum(ab * ab, axis=1), 1e-300), 0.0, 1.0)
    return float(np.min(np.linalg.norm(a + s[:, None] * ab - point, axis=1)))


def _fault_bias(config: MissionConfig, t: float) -> np.ndarray:
    if config.fault is None or t < config.fault_time:
        return np.zeros(3)
    size = config.fault_size if config.fault == "step" else config.fault_size * (t - config.fault_time)
    return np.array([size, 0.0, 0.0])


def plan(config: MissionConfig) -> FlightPath:
    """The optimised flight path of the configured feature (spec 003 Eqs. 1-17)."""
    return optimise_flight_path(fit_feature(np.asarray(config.feature, dtype=float)), config.altitude)


def run_mission(config: MissionConfig, flight: FlightPath | None = None) -> MissionResult:
    """Fly one mission (module docstring); ``flight`` reuses a plan of the same feature and altitude."""
    flight = plan(config) if flight is None else flight
    rng = np.random.default_rng(config.seed)
    follower = PathFollower(flight)
    dt = 1.0 / config.nav_rate
    every = {name: round(config.nav_rate / getattr(config, f"{name}_rate")) for name in ("gps", "guidance", "metric")}
    path = flight.uav_path
    tangent = path.derivative(0.0, 1)
    vehicle = FixedWingModel(path.position(0.0), heading=math.atan2(tangent[1], tangent[0]), airspeed=flight.speed)
    truth = vehicle.state()
    chol_q = np.linalg.cholesky(config.noise.quaternion)
    R_p, R_v = config.gps_std**2 * np.eye(3), config.gps_velocity_std**2 * np.eye(3)
    nav = NavigationFilter(truth.position + config.gps_std * rng.standard_normal(3), R_p,
                           truth.velocity + config.gps_velocity_std * rng.standard_normal(3), R_v, config.noise)
    names = [f"gps{i}" for i in range(config.receivers)]
    bank = GpsFaultIsolation(nav, names) if config.isolation else None
    angles = GimbalAngles(0.0, -0.5 * math.pi)
    f_px = config.camera.fx
    centre_px = np.array([config.camera.cx, config.camera.cy])
    series: dict[str, list[float]] = {"t": [], "px": [], "angle": [], "xt": [], "nav": []}
    k, t_max = 0, 3.0 * path.tau_f / flight.speed
    finished = False
    while not finished and k * dt < t_max:
        if k % every["guidance"] == 0:
            vehicle.set_setpoint(goal_to_setpoint(follower.goal(nav.position)))
            target = follower.feature_point(nav.position)
        # Z-Y-X Euler -> scalar-last quaternion, the convention of perception.rotations (scipy: intrinsic "ZYX")
        q_true = Rotation.from_euler("ZYX", [truth.yaw, truth.pitch, truth.roll]).as_quat()
        C_true = rotation_ned_from_frd(truth.roll, truth.pitch, truth.yaw)
        vehicle.step(dt)
        after = vehicle.state()
        accel = (after.velocity - truth.velocity) / dt  # the mean acceleration over the step
        f_body = C_true.T @ (accel - [0.0, 0.0, GRAVITY])  # f^b = C_n^b (a - g)
        q_hat = q_true + chol_q @ rng.standard_normal(4)
        speed_hat = flight.speed + config.speed_std * rng.standard_normal()
        f_hat = f_body + math.sqrt(config.noise.specific_force[0, 0]) * rng.standard_normal(3)
        (bank or nav).predict(q_hat, speed_hat, f_hat, dt)
        truth, k = after, k + 1
        t = k * dt
        if k % every["gps"] == 0:
            for i, name in enumerate(names):
                bias = _fault_bias(config, t) if i == 0 else 0.0
                z = truth.position + bias + config.gps_std * rng.standard_normal(3)
                if bank:
                    bank.update_position(name, z, R_p, t)
                else:
                    nav.update_position(z, R_p)
            nav.update_velocity(truth.velocity + config.gps_velocity_std * rng.standard_normal(3), R_v)
        yaw, pitch, roll = Rotation.from_quat(q_hat).as_euler("ZYX")  # the attitude filter's output
        desired = point_at(VehiclePose(nav.position, roll, pitch, yaw), target, config.gimbal, current=angles)
        angles = slew(angles, desired, config.gimbal, dt)
        if k % every["metric"] == 0:
            tau, _, cross_track = follower.abeam(truth.position)
            finished = tau >= path.tau_f - follower.sample_spacing
            camera = CameraPose.from_vehicle(truth.position, truth.roll, truth.pitch, truth.yaw,
                                             Gimbal(angles.pan, angles.tilt, config.gimbal.pan, config.gimbal.tilt))
            window = np.linspace(max(0.0, tau - FEATURE_WINDOW), min(path.tau_f, tau + FEATURE_WINDOW), 61)
            pixels = world_to_pixel(camera, config.camera, flight.feature.position(window))
            r = _distance_to_polyline(centre_px, pixels)
            series["t"].append(t)
            series["px"].append(r)
            series["angle"].append(math.atan(r / f_px) if math.isfinite(r) else math.nan)
            series["xt"].append(abs(cross_track))
            series["nav"].append(float(np.linalg.norm(truth.position - nav.position)))
    monitors = bank.monitors if bank else {}
    return MissionResult(
        flight=flight,
        times=np.array(series["t"]),
        centring_px=np.array(series["px"]),
        centring_angle=np.array(series["angle"]),
        cross_track=np.array(series["xt"]),
        nav_error=np.array(series["nav"]),
        fault_time=config.fault_time if config.fault else None,
        isolated_at={name: monitors[name].isolated_at if name in monitors else None for name in names},
        rejection_rate={name: monitors[name].rejection_rate for name in monitors},
    )
