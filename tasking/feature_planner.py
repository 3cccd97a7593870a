"""The feature-following planner, ``[tasking] planner = "feature"``: the mission of Lee, Kaminer, Dobrokhodov and
Jones (NPS 2010, spec 003 §1.1) behind the planner seam (:class:`tasking.base.Planner`).

When it is built (once per agent, when the scenario starts):

1. the operator's polyline ``path`` of (north, east) points becomes the feature path ``p_T(τ)``, a C² piecewise
   quintic in the chord length τ (Eqs. 1-2, :func:`tasking.feature_path.fit_feature`), on the ground of the
   origin (``down = 0``: the feature lies at the level of the local origin, as on flat terrain);
2. the UAV flight path is optimised for it (Eqs. 14-17, :func:`tasking.feature_following.optimise_flight_path`):
   ``min ε`` over the speed ``v`` and the lateral offset ``d`` subject to ``|φ_UAV| <= φ_max``,
   ``|φ̇_UAV| <= φ̇_max``, ``|λ - (φ_G - φ_UAV)| <= ε < θ/2`` and ``a_p <= a_max``, at the agent's
   altitude above the feature. A constant-airspeed vehicle cannot pick its speed, so unless ``min_speed`` and
   ``max_speed`` open a range the path is optimised at the vehicle's own top speed (its airspeed), which makes
   the bank and roll-rate checks (Eqs. 5, 7) hold for the speed it will actually fly.

Every agent cycle :meth:`FeaturePlanner.plan` returns the path follower's set-point
(:meth:`tasking.feature_following.PathFollower.goal`: the vector-field carrot, spec 003 §2.5's substitute
for the paper's ref. [2]; once the path is flown, the loiter circle around its end, §1.1 step 7) with a
gimbal command ``look_at`` (spec 003 §2.9, the GNC computer's gimbal reference):

* ``look_at = "feature"`` (default): the feature point abeam, ``p_T(τ*)`` with ``τ*`` the UAV-path parameter
  closest to the vehicle, which the camera's gimbal puts at the image centre (Eq. 12, ``e = 0``);
* ``look_at = "target"``: the nearest confirmed track (the agent's fused ``"track"`` view) within
  ``target_range`` of the vehicle, at the feature's depth (targets move on the road), else the feature point.

Metrics (``"feature"``): the cross-track error of the vehicle from the optimised path (mean, p95, max: the
paper's Fig. 17 quantity, spec 003 §4.1) over the *following* phase — from the first cycle within
:data:`CAPTURE_DISTANCE` of the path (the end of the bridge, spec 003 §1.1 step 7) until the path is flown —,
the cycles spent on the bridge and looking at a target, and the optimised path's speed, offset and ``ε``.
The pointing (centring) error is the camera's to measure: it knows where its optical axis is
(:mod:`agent.sensors.camera`, ``[sensor] gimbal = "steered"``).

Without a ``path`` the feature is the planning area's north-south centre line (chosen here: the line the
agents' start positions face, so a scenario without a polyline still flies something sensible).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields, replace
from numbers import Real

import numpy as np

from tasking.base import VehicleStateLike
from tasking.feature_following import FlightPath, FlightPathLimits, PathFollower, optimise_flight_path
from tasking.feature_path import PolynomialPath, fit_feature
from tasking.orbit import Goal

LOOK_AT = ("feature", "target")
#: A vehicle within this distance (m) of the optimised path has left the bridge and follows it. Chosen here.
CAPTURE_DISTANCE = 10.0


def feature_from_path(path) -> PolynomialPath:
    """The feature path through the operator's ``path`` (a list of ``[north, east]`` points, m), at the origin's
    level. ``ValueError`` naming ``tasking.path`` for fewer than 2 points, a repeated consecutive point, a
    non-finite or non-numeric value."""
    points_ok = isinstance(path, list | tuple) and all(
        isinstance(p, list | tuple) and len(p) == 2 and all(isinstance(x, Real) and not isinstance(x, bool) for x in p)
        for p in path)
    if not points_ok:
        raise ValueError(f"tasking.path must be a list of [north, east] points in metres, got {path!r}")
    try:
        return fit_feature(np.array(path, dtype=float).reshape(-1, 2))  # an empty list too: (0, 2)
    except ValueError as err:
        raise ValueError(f"tasking.path: {err}") from None


@dataclass(frozen=True)
class FeaturePlannerConfig:
    """The ``[tasking]`` options of ``planner = "feature"`` (angles in degrees, as in the scenario file).

    The flight-path limits default to those of :class:`tasking.feature_following.FlightPathLimits` (the paper's
    35° bank, the rest chosen there) and the guidance to :class:`tasking.feature_following.PathFollower`'s."""

    path: tuple | None = None  # the operator's polyline [[north, east], ...] (m); None: the area's centre line
    look_at: str = "feature"  # "feature" or "target"
    target_range: float = 400.0  # m: a track farther than this from the vehicle is not looked at (chosen here)
    min_speed: float | None = None  # m/s: a speed range to optimise over (both or neither);
    max_speed: float | None = None  # None: the vehicle's top speed
    max_bank_deg: float = math.degrees(FlightPathLimits.max_bank)
    max_roll_rate_deg: float = math.degrees(FlightPathLimits.max_roll_rate)
    max_acceleration: float = FlightPathLimits.max_acceleration  # m/s²
    look_min_deg: float = math.degrees(FlightPathLimits.look_range[0])  # lateral gimbal angle range
    look_max_deg: float = math.degrees(FlightPathLimits.look_range[1])
    field_of_view_deg: float = math.degrees(FlightPathLimits.field_of_view)  # θ of Eq. 13
    max_offset: float = FlightPathLimits.max_offset  # m
    carrot_distance: float = PathFollower.carrot_distance  # m
    loiter_radius: float = PathFollower.loiter_radius  # m
    cross_track_gain: float = PathFollower.cross_track_gain  # 1/m

    def __post_init__(self):
        if self.path is not None:
            feature_from_path(self.path)
            object.__setattr__(self, "path", tuple(tuple(float(x) for x in p) for p in self.path))
        if self.look_at not in LOOK_AT:
            raise ValueError(f"tasking.look_at must be one of {LOOK_AT}, got {self.look_at!r}")
        if (self.min_speed is None) != (self.max_speed is None):
            raise ValueError("tasking.min_speed and tasking.max_speed go together (a speed range), or neither "
                             f"(the vehicle's speed); got {self.min_speed}, {self.max_speed}")
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name in ("path", "look_at", "look_min_deg", "look_max_deg") or value is None:
                continue  # the look range may be negative (left of the track): FlightPathLimits checks it
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"tasking.{f.name} must be a positive number, got {value!r}")
        try:
            self.limits(None)
        except ValueError as err:
            raise ValueError(f"tasking: {err}") from None

    @classmethod
    def from_options(cls, options: Mapping[str, object]) -> FeaturePlannerConfig:
        return cls(**options)

    def limits(self, vehicle_speed: float | None) -> FlightPathLimits:
        """The constraints of Eqs. 15-17; the speed range is the options' or ``(v, v)`` at the vehicle's speed
        (``None``: the default range of :class:`~tasking.feature_following.FlightPathLimits`)."""
        if self.min_speed is not None:
            speeds = (self.min_speed, self.max_speed)
        elif vehicle_speed is not None:
            speeds = (vehicle_speed, vehicle_speed)
        else:
            speeds = FlightPathLimits.speed_range
        return FlightPathLimits(
            max_bank=math.radians(self.max_bank_deg), max_roll_rate=math.radians(self.max_roll_rate_deg),
            speed_range=speeds, max_acceleration=self.max_acceleration,
            look_range=(math.radians(self.look_min_deg), math.radians(self.look_max_deg)),
            field_of_view=math.radians(self.field_of_view_deg), max_offset=self.max_offset)


class FeaturePlanner:
    """Follow the flight path optimised for a feature and point the camera at it (module docstring)."""

    def __init__(self, config: FeaturePlannerConfig, area: tuple[float, float, float, float], altitude: float,
                 vehicle_speed: float | None = None):
        self.config = config
        if config.path is None:
            n0, n1, e0, e1 = area
            path = ((n0, 0.5 * (e0 + e1)), (n1, 0.5 * (e0 + e1)))
        else:
            path = config.path
        limits = config.limits(vehicle_speed)
        self.flight: FlightPath = optimise_flight_path(feature_from_path(path), altitude, limits,
                                                       preferred_speed=vehicle_speed)
        self.follower = PathFollower(self.flight, cross_track_gain=config.cross_track_gain,
                                     carrot_distance=config.carrot_distance, loiter_radius=config.loiter_radius)
        self._cross_track: list[float] = []  # m, signed, over the following phase
        self._bridge_steps = 0
        self._target_steps = 0
        self._finished = False

    def plan(self, state: VehicleStateLike, views: Mapping[str, object]) -> Goal:
        """The follower's set-point for the vehicle's position, with ``look_at`` set (module docstring)."""
        position = np.asarray(state.position, dtype=float)
        tau, _, cross_track = self.follower.abeam(position)
        self._finished = tau >= self.flight.uav_path.tau_f - self.follower.sample_spacing
        if not self._cross_track and abs(cross_track) > CAPTURE_DISTANCE:
            self._bridge_steps += 1
        elif not self._finished:
            self._cross_track.append(cross_track)
        feature_point = self.flight.feature.position(tau)
        look_at = feature_point
        if self.config.look_at == "target":
            track = self._nearest_track(position, views["track"].positions)
            if track is not None:
                self._target_steps += 1
                look_at = np.array([track[0], track[1], feature_point[2]])
        return replace(self.follower.goal(position), look_at=look_at)

    def _nearest_track(self, position: np.ndarray, tracks: Sequence) -> np.ndarray | None:
        """(north, east) of the confirmed track nearest the vehicle horizontally, if within ``target_range``."""
        best, best_d = None, self.config.target_range
        for _, mean in tracks:
            ne = np.asarray(mean, dtype=float)[:2]
            d = float(np.hypot(*(ne - position[:2])))
            if d <= best_d:
                best, best_d = ne, d
        return best

    def metrics(self) -> dict:
        xt = np.abs(np.asarray(self._cross_track, dtype=float))
        return {"feature": {
            "speed": self.flight.speed, "offset_m": self.flight.offset,
            "epsilon_deg": math.degrees(self.flight.epsilon), "path_length_m": self.flight.feature.tau_f,
            "cross_track_m": {
                "mean": float(xt.mean()) if xt.size else None,
                "p95": float(np.percentile(xt, 95)) if xt.size else None,
                "max": float(xt.max()) if xt.size else None,
                "samples": int(xt.size),
            },
            "bridge_steps": self._bridge_steps, "target_steps": self._target_steps, "finished": self._finished,
        }}
