"""``skymesh bench geolocation-latency``: Ross et al.'s GPS latency and its compensation (spec 002 §2.5, §4.2).

Ross et al. flew a UAV with a fixed down-looking webcam over a stationary target (two red balls) several
times from several directions. The autopilot's GPS was about 0.43 s late, so every observation appeared
*behind* the target along the flight path; georeferencing each image with the GPS position "430 ms into
the future" clustered the points and reduced the absolute error "by a factor of approximately two" (about
4 m -> 2 m, spec 002 §4.2). This benchmark reproduces that experiment in simulation:

* a fixed-wing UAV flies straight, level overflights of the target at ``airspeed`` and ``ALTITUDE_M``, from
  ``len(headings)`` directions, each pass offset sideways at random; between passes the target is out of
  view for ``GAP_S`` (the filter coasts, as in Ross Figs. 13-16);
* every ``1 / RATE_HZ`` s (Ross's localizer rate, 4 Hz) the synthetic camera renders the two 75 cm red balls
  from the *true* pose; the colour-blob detector (:class:`perception.blobs.ColorBlobDetector`) finds them and
  the pairing rule (:func:`perception.blobs.pair_detections`) accepts the pair; its midpoint pixel is
  georeferenced (ray cast on the plane of the ball centres) with a pose taken from a
  :class:`perception.pose_buffer.PoseBuffer` fed by the telemetry stream;
* the telemetry (``TELEMETRY_HZ``) carries the true pose plus slowly varying errors (first-order
  Gauss-Markov, :data:`ATTITUDE_SIGMA_DEG`, :data:`POSITION_SIGMA_M`: the paper's "other error sources",
  spec 002 §2.6) and is, in three conditions *of the same run* (same frames, same detections, same errors):

  ``baseline``     not late (zero latency);
  ``late``         0.43 s late, used as if current (Ross's raw observations, Fig. 11a);
  ``compensated``  0.43 s late, each report stored 0.43 s earlier (Ross's correction, Fig. 11b);

* per condition: the per-frame ground-point error (and its along-track part: negative = behind the
  target) and the error of Ross's linear Kalman filter (Eqs. 2-7, literal: ``x = [n, e, v_n, v_e]``,
  ``Δt = 0.25`` s, ``σ_a = 0.1`` m/s², ``R = diag(25, 25)``, ``P0 = diag(5, 5, 0.1, 0.1)``, state at
  the first observation) over every tick after its first update, and right after each pass.

The paper gives neither the airspeed nor the altitude nor the camera (spec 002 §6): they are chosen here
(a Kadet Senior trainer cruises at roughly 12-15 m/s; a QuickCam has a field of view of about 60°). The
latency bias is ``0.43 s × airspeed`` along track, so the ratio late / compensated depends on the
airspeed and on the size of the other errors; the full run sweeps the airspeed.
"""

from __future__ import annotations

import math
import time

import numpy as np

from mesh_sim.bench import common
from perception.blobs import ColorBlobDetector, pair_detections
from perception.camera import Intrinsics
from perception.pose import CameraPose, Gimbal
from perception.pose_buffer import PoseBuffer
from perception.projection import pixel_to_ground
from perception.render import default_ground, render_frame
from perception.scene import Target
from perception.terrain import FlatTerrain

NAME = "geolocation-latency"

LATENCY_S = 0.43  # [PAPER] measured GPS latency (Sec. VI.C)
RATE_HZ = 4.0  # [PAPER] localizer / KF rate (Sec. IV, VI.D)
TELEMETRY_HZ = 20.0  # chosen here: autopilot telemetry rate
ALTITUDE_M = 60.0  # chosen here (not in the paper)
AIRSPEED_MS = 13.0  # chosen here: Kadet Senior cruise (not in the paper); the full run sweeps it
FULL_AIRSPEEDS = (10.0, 13.0, 18.0)
WIDTH, HEIGHT, HFOV_DEG = 640, 480, 60.0  # chosen here: a QuickCam-like webcam (not in the paper)
BALL_RADIUS_M = 0.375  # [PAPER] two red balls, 75 cm diameter
BALL_SEPARATION_M = 3.0  # chosen here ("a set distance apart", not given)
BALL_RGB = (200, 25, 25)
PASS_HALF_LENGTH_M = 35.0  # along-track half length of a pass around the target (footprint ± ~26 m)
LATERAL_OFFSET_SD_M = 8.0  # chosen here: passes do not all cross the target exactly
GAP_S = 20.0  # chosen here: time out of view between passes (turnaround)
QUICK_HEADINGS_DEG = (0.0, 180.0, 90.0, 270.0, 45.0, 225.0)
FULL_HEADINGS_DEG = tuple(float(h) for h in range(0, 360, 30))
ATTITUDE_SIGMA_DEG = (1.0, 1.0, 2.0)  # chosen here: roll, pitch, yaw error (AHRS without magnetometer)
POSITION_SIGMA_M = 0.5  # chosen here: GPS position error per axis
ERROR_TAU_S = 2.0  # chosen here: correlation time of the telemetry errors
QUICK_REPEATS, FULL_REPEATS = 5, 10
PAPER_RATIO = 2.0  # [PAPER] "reduced by a factor of approximately two" (Fig. 12)
GOAL_MIN_RATIO = 1.5  # chosen here: compensation must cut the per-frame error by at least this factor
CONDITIONS = ("baseline", "late", "compensated")

# Ross's linear KF (spec 002 §2.4, Eqs. 2-7, literal).
KF_DT = 1.0 / RATE_HZ
KF_F = np.array([[1, 0, KF_DT, 0], [0, 1, 0, KF_DT], [0, 0, 1, 0], [0, 0, 0, 1]], float)
KF_G = np.array([[0, 0], [0, 0], [KF_DT, 0], [0, KF_DT]], float)
KF_Q = KF_G @ np.diag([0.1**2, 0.1**2]) @ KF_G.T
KF_H = np.hstack([np.eye(2), np.zeros((2, 2))])
KF_R = np.diag([25.0, 25.0])
KF_P0 = np.diag([5.0, 5.0, 0.1, 0.1])


class RossKF:
    """Ross et al. Eqs. 2-7: predict every tick, update when the target is observed."""

    def __init__(self):
        self.x: np.ndarray | None = None
        self.P = KF_P0.copy()

    def predict(self) -> None:
        if self.x is not None:
            self.x = KF_F @ self.x
            self.P = KF_F @ self.P @ KF_F.T + KF_Q

    def update(self, z: np.ndarray) -> None:
        if self.x is None:  # the local origin / initial state: the first observation, zero velocity
            self.x = np.array([z[0], z[1], 0.0, 0.0])
            return
        S = KF_H @ self.P @ KF_H.T + KF_R
        K = self.P @ KF_H.T @ np.linalg.inv(S)
        self.x = self.x + K @ (z - KF_H @ self.x)
        self.P = (np.eye(4) - K @ KF_H) @ self.P


def _gauss_markov(rng: np.random.Generator, n: int, dt: float, sigma) -> np.ndarray:
    """``n`` samples of a stationary first-order Gauss-Markov process per column (``sigma`` per column)."""
    sigma = np.atleast_1d(np.asarray(sigma, float))
    a = math.exp(-dt / ERROR_TAU_S)
    out = np.empty((n, sigma.size))
    out[0] = sigma * rng.standard_normal(sigma.size)
    for k in range(1, n):
        out[k] = a * out[k - 1] + math.sqrt(1.0 - a * a) * sigma * rng.standard_normal(sigma.size)
    return out


def _one_run(seed: int, airspeed: float, headings) -> dict:
    """One flight (all passes) with the three pose pairings; per-frame errors and KF errors per condition."""
    rng = np.random.default_rng(seed)
    intrinsics = Intrinsics.from_fov(WIDTH, HEIGHT, HFOV_DEG)
    gimbal = Gimbal(0.0, -math.pi / 2)  # fixed, straight down (no gimbal in Ross et al.)
    ground = default_ground("terrain")
    detector = ColorBlobDetector()
    plane = FlatTerrain(BALL_RADIUS_M)  # georeference onto the plane of the ball centres
    target = np.zeros(2)
    half = BALL_SEPARATION_M / 2.0
    balls = [Target((0.0, -half, -BALL_RADIUS_M), BALL_RADIUS_M, BALL_RGB),
             Target((0.0, half, -BALL_RADIUS_M), BALL_RADIUS_M, BALL_RGB)]
    sep_px = intrinsics.fx * BALL_SEPARATION_M / ALTITUDE_M
    filters = {c: RossKF() for c in CONDITIONS}
    frames = {c: [] for c in CONDITIONS}  # (error vector (n, e), along-track unit vector)
    kf_errors = {c: [] for c in CONDITIONS}
    kf_pass_end = {c: [] for c in CONDITIONS}  # error right after each pass's last frame
    n_frames = n_pairs = 0
    duration = 2.0 * PASS_HALF_LENGTH_M / airspeed
    for heading_deg in headings:
        psi = math.radians(heading_deg)
        along = np.array([math.cos(psi), math.sin(psi)])
        offset = LATERAL_OFFSET_SD_M * rng.standard_normal() * np.array([-along[1], along[0]])

        def truth(s, along=along, offset=offset):  # position at pass time s (s = 0: start of the pass)
            ne = target + offset + (airspeed * s - PASS_HALF_LENGTH_M) * along
            return np.array([ne[0], ne[1], -ALTITUDE_M])

        # Telemetry from 2 s before the pass to 1 s after it (enough for the 0.43 s look-ahead).
        t_reports = np.arange(-2.0, duration + 1.0, 1.0 / TELEMETRY_HZ)
        att = np.radians(_gauss_markov(rng, len(t_reports), 1.0 / TELEMETRY_HZ, ATTITUDE_SIGMA_DEG))
        pos = _gauss_markov(rng, len(t_reports), 1.0 / TELEMETRY_HZ, [POSITION_SIGMA_M] * 3)
        buffers = {"baseline": PoseBuffer(maxlen=4096), "late": PoseBuffer(maxlen=4096),
                   "compensated": PoseBuffer(maxlen=4096, latency=LATENCY_S)}
        for t_r, e_att, e_pos in zip(t_reports, att, pos, strict=True):
            for name, buf in buffers.items():
                p = truth(t_r) if name == "baseline" else truth(t_r - LATENCY_S)
                buf.add(t_r, p + e_pos, e_att[0], e_att[1], psi + e_att[2], 0.0, -math.pi / 2)
        for k in range(int(duration * RATE_HZ) + 1):
            t = k / RATE_HZ
            pose = CameraPose.from_vehicle(truth(t), 0.0, 0.0, psi, gimbal)  # level, straight flight, no wind
            frame = render_frame((pose, intrinsics), WIDTH, HEIGHT, balls, ground=ground, seed=rng, thermal=False)
            n_frames += 1
            dets = detector.detect(frame.rgb).detections
            pairs = pair_detections(dets, (0.5 * sep_px, 1.6 * sep_px))
            for kf in filters.values():
                kf.predict()
            if pairs:
                i, j = pairs[0]
                pixel = 0.5 * (np.asarray(dets[i].center) + np.asarray(dets[j].center))
                n_pairs += 1
                for name, buf in buffers.items():
                    p = buf.at(t)
                    seen_from = CameraPose.from_vehicle(p.position, p.roll, p.pitch, p.yaw, Gimbal(p.pan, p.tilt))
                    hit = pixel_to_ground(seen_from, intrinsics, plane, pixel)
                    if hit is None:
                        continue
                    frames[name].append((hit[:2] - target, along))
                    filters[name].update(hit[:2])
            for name, kf in filters.items():
                if kf.x is not None:
                    kf_errors[name].append(float(np.linalg.norm(kf.x[:2] - target)))
        for name, kf in filters.items():
            if kf.x is not None:
                kf_pass_end[name].append(float(np.linalg.norm(kf.x[:2] - target)))
        for _ in range(int(GAP_S * RATE_HZ)):  # out of view: the filters coast
            for name, kf in filters.items():
                kf.predict()
                if kf.x is not None:
                    kf_errors[name].append(float(np.linalg.norm(kf.x[:2] - target)))
    out = {"frames": n_frames, "observations": n_pairs}
    for name in CONDITIONS:
        err = np.array([e for e, _ in frames[name]]).reshape(-1, 2)
        along = np.array([a for _, a in frames[name]]).reshape(-1, 2)
        out[name] = {
            "errors": np.linalg.norm(err, axis=1).tolist(),
            "along": np.sum(err * along, axis=1).tolist(),
            "kf": kf_errors[name],
            "kf_pass_end": kf_pass_end[name],
        }
    return out


def run(quick: bool = False, repeats: int | None = None) -> dict:
    """Run the benchmark; returns ``{"benchmark", "settings", "environment", "rows", "ratios", "goals"}``."""
    if repeats is not None and repeats < 1:
        raise ValueError(f"repeats must be at least 1, got {repeats}")
    n_runs = repeats if repeats is not None else (QUICK_REPEATS if quick else FULL_REPEATS)
    speeds = (AIRSPEED_MS,) if quick else FULL_AIRSPEEDS
    headings = QUICK_HEADINGS_DEG if quick else FULL_HEADINGS_DEG
    started = time.time()
    rows, ratios = [], []
    with common.progress(len(speeds) * n_runs, NAME) as advance:
        for speed in speeds:
            pooled = {c: {"errors": [], "along": [], "kf": [], "kf_pass_end": []} for c in CONDITIONS}
            frames = observations = 0
            for r in range(n_runs):
                one = _one_run(1000 + r, speed, headings)
                frames += one["frames"]
                observations += one["observations"]
                for c in CONDITIONS:
                    for key in ("errors", "along", "kf", "kf_pass_end"):
                        pooled[c][key] += one[c][key]
                advance(f"{speed:g} m/s, run {r + 1}")
            by_condition = {}
            for c in CONDITIONS:
                e, a = np.array(pooled[c]["errors"]), np.array(pooled[c]["along"])
                kf, end = np.array(pooled[c]["kf"]), np.array(pooled[c]["kf_pass_end"])
                row = {
                    "airspeed_ms": speed, "condition": c, "latency_s": 0.0 if c == "baseline" else LATENCY_S,
                    "compensated": c == "compensated", "runs": n_runs, "frames": frames, "observations": len(e),
                    "frame_error_mean_m": float(e.mean()) if e.size else None,
                    "frame_error_rms_m": float(np.sqrt(np.mean(e**2))) if e.size else None,
                    "frame_error_median_m": float(np.median(e)) if e.size else None,
                    "along_track_mean_m": float(a.mean()) if a.size else None,
                    "kf_error_mean_m": float(kf.mean()) if kf.size else None,
                    "kf_error_pass_end_m": float(end.mean()) if end.size else None,
                }
                rows.append(row)
                by_condition[c] = row
            late, comp, base = by_condition["late"], by_condition["compensated"], by_condition["baseline"]
            ratios.append({
                "airspeed_ms": speed,
                "expected_bias_m": -LATENCY_S * speed,
                "frame_late_over_compensated": _ratio(late["frame_error_mean_m"], comp["frame_error_mean_m"]),
                "kf_late_over_compensated": _ratio(late["kf_error_mean_m"], comp["kf_error_mean_m"]),
                "kf_pass_end_late_over_compensated": _ratio(late["kf_error_pass_end_m"], comp["kf_error_pass_end_m"]),
                "frame_compensated_over_baseline": _ratio(comp["frame_error_mean_m"], base["frame_error_mean_m"]),
                "pair_rate": observations / max(frames, 1),
            })
    frame_ratios = [r["frame_late_over_compensated"] for r in ratios]
    goals = {
        "compensation_halves_error": {
            "description": f"latency compensation cuts the mean per-frame geolocation error by >= {GOAL_MIN_RATIO:g}x "
                           f"(Ross et al.: about {PAPER_RATIO:g}x, ~4 m -> ~2 m)",
            "target_min_ratio": GOAL_MIN_RATIO,
            "results": [{"airspeed_ms": r["airspeed_ms"], "ratio": r["frame_late_over_compensated"],
                         "pass": r["frame_late_over_compensated"] is not None
                         and r["frame_late_over_compensated"] >= GOAL_MIN_RATIO} for r in ratios],
            "pass": all(x is not None and x >= GOAL_MIN_RATIO for x in frame_ratios),
        },
        "compensated_matches_baseline": {
            "description": "compensated error within 15 % of the zero-latency baseline (the correction is exact)",
            "results": [{"airspeed_ms": r["airspeed_ms"], "ratio": r["frame_compensated_over_baseline"],
                         "pass": _at_most(r["frame_compensated_over_baseline"], 1.15)} for r in ratios],
            "pass": all(_at_most(r["frame_compensated_over_baseline"], 1.15) for r in ratios),
        },
    }
    return {
        "benchmark": NAME,
        "settings": {
            "quick": quick, "runs": n_runs, "airspeeds_ms": list(speeds), "headings_deg": list(headings),
            "latency_s": LATENCY_S, "rate_hz": RATE_HZ, "telemetry_hz": TELEMETRY_HZ, "altitude_m": ALTITUDE_M,
            "camera": {"width": WIDTH, "height": HEIGHT, "hfov_deg": HFOV_DEG},
            "attitude_sigma_deg": list(ATTITUDE_SIGMA_DEG), "position_sigma_m": POSITION_SIGMA_M,
            "error_tau_s": ERROR_TAU_S, "ball_separation_m": BALL_SEPARATION_M, "gap_s": GAP_S,
            "wall_s": time.time() - started,
        },
        "environment": common.environment(("numpy", "opencv-python-headless")),
        "rows": rows,
        "ratios": ratios,
        "goals": goals,
    }


def _at_most(value, limit: float) -> bool:
    return value is not None and value <= limit


def _ratio(a, b):
    return None if a is None or b is None or b <= 0 else a / b


def _m(value) -> str:
    return "—" if value is None else f"{value:.2f}"


def report(result: dict, console=None) -> None:
    """Print the error table, the ratios and the goal verdicts of a :func:`run` result."""
    console = console or common.make_console()
    s = result["settings"]
    console.print(
        f"[bold]{NAME}[/bold]  {'quick' if s['quick'] else 'full'} run: {s['runs']} flights × {len(s['headings_deg'])} "
        f"overflights per airspeed, altitude {s['altitude_m']:g} m, {s['camera']['width']}×{s['camera']['height']} "
        f"camera ({s['camera']['hfov_deg']:g}° hfov, fixed nadir), localizer {s['rate_hz']:g} Hz, telemetry "
        f"{s['telemetry_hz']:g} Hz, GPS latency {s['latency_s']:g} s; telemetry errors σ = "
        f"{'/'.join(f'{a:g}' for a in s['attitude_sigma_deg'])}° (roll/pitch/yaw), {s['position_sigma_m']:g} m, "
        f"τ = {s['error_tau_s']:g} s.  {s['wall_s']:.0f} s",
        highlight=False,
    )
    rows = []
    for r in result["rows"]:
        rows.append([f"{r['airspeed_ms']:g}", r["condition"], f"{r['latency_s']:g}",
                     "yes" if r["compensated"] else "no", r["observations"], _m(r["frame_error_mean_m"]),
                     _m(r["frame_error_rms_m"]), _m(r["frame_error_median_m"]), _m(r["along_track_mean_m"]),
                     _m(r["kf_error_mean_m"]), _m(r["kf_error_pass_end_m"])])
    common.print_table(
        console, "Geolocation error of a static target (Ross et al. §VI.C)",
        ["airspeed [m/s]", ("condition", "left"), "latency [s]", "compensated", "observations", "frame mean [m]",
         "frame RMS [m]", "frame median [m]", "along-track [m]", "KF mean [m]", "KF pass end [m]"],
        rows,
        "frame: per-image ground point of the ball pair vs the truth; along-track: signed (negative = behind the "
        "target along the flight path); KF: Ross Eqs. 2-7 position error over every tick after its first update "
        "(including the coasting between passes), and right after the last image of each pass.",
    )
    common.print_table(
        console, "Late ÷ compensated",
        ["airspeed [m/s]", "expected bias [m]", "per-frame ratio", "KF ratio", "KF pass-end ratio",
         "compensated ÷ baseline", "pair rate"],
        [[f"{r['airspeed_ms']:g}", f"{r['expected_bias_m']:.2f}", common.fmt_ratio(r["frame_late_over_compensated"]),
          common.fmt_ratio(r["kf_late_over_compensated"]), common.fmt_ratio(r["kf_pass_end_late_over_compensated"]),
          common.fmt_ratio(r["frame_compensated_over_baseline"]),
          f"{r['pair_rate']:.0%}"] for r in result["ratios"]],
        f"Ross et al.: about {PAPER_RATIO:g}x (~4 m -> ~2 m); expected bias = -latency × airspeed. Pair rate: frames "
        "in which both balls were detected and paired (the rest are frames of a pass with the target out of view).",
    )
    for goal in result["goals"].values():
        measured = ", ".join(f"{g['airspeed_ms']:g} m/s {common.fmt_ratio(g['ratio'])}" for g in goal["results"])
        console.print(f"{common.verdict(goal['pass'])}  {goal['description']} (measured {measured})", highlight=False)
