"""``skymesh bench perception``: milliseconds per frame of the synthetic camera, the detectors and geolocation.

The budget that decides how many agents fit on a core. At 320×240 and 640×480 (the thesis 000 §2.2
raw and processed sizes), every operation timed in the same run, interleaved (see
:mod:`mesh_sim.bench.common`), median over repeats:

* **render** (:func:`perception.render.render_frame`): RGB only, thermal only, both, and both with
  banding noise (a degraded link), of a nadir view from 30 m over the shared procedural terrain with two
  balls and a fire cell;
* **detect**: colour blobs (:class:`~perception.blobs.ColorBlobDetector`, Ross et al.), dark blobs
  (:class:`~perception.blobs.DarkBlobDetector`, thesis 000 §2.2) alone and followed by the persistent
  object filter (:class:`~perception.persistence.PersistentDetector`, §2.3), the video-quality estimate
  (:class:`~perception.quality.VideoQuality`, §2.4), fire segmentation of the thermal frame (threshold)
  and of the RGB frame (colour histogram, :class:`~perception.fire_segmentation.FireSegmenter`);
* **geolocate** one pixel of a camera 80 m up, looking 60° below the horizon: pixel -> ground
  (:func:`perception.projection.pixel_to_ground`) on flat terrain and on a 30 m grid DEM
  (:class:`perception.dem.GridTerrain`, Ross et al. use a 30 m USGS DEM), and the unscented-transform
  geolocation of one detection with its covariance on that DEM (:func:`perception.geolocation.geolocate`,
  what an agent does to start a track or in ``measurement = "position"`` mode).

* **camera, whole frame vs ROI**: the camera sensor's pipeline (:class:`agent.sensors.camera.CameraSensor`, the
  default scenario's view: nadir from 80 m, 90° HFOV, three car-sized discs, two in view) drawn whole
  (:func:`perception.render.render_frame`, ``[sensor] render = "full"``) and as a preview plus windows
  (:func:`perception.roi_render.render_roi`, ``render = "roi"``): the render, the colour blobs (red discs over the
  terrain), the dark blobs (dark discs over the tiled floor), the video quality and the whole sensor step (render,
  D(t), colour blobs, bearings); each ROI row is also given as a ratio to its whole-frame row (a camera of at
  most 320×240 is drawn whole: there the two time the same work).

Baseline, measured in the same run on the same RGB frame: a bare OpenCV operation of comparable size,
``cv2.cvtColor(RGB -> gray)`` + ``cv2.threshold``; every operation is also given as a ratio to it.

OpenCV runs with **one thread** for the per-core budget (``cv2.setNumThreads(1)``, restored afterwards);
each operation is timed again with OpenCV's default thread count for reference.

**Agent step** (one frame of one simulated agent): render RGB + thermal, colour blobs, dark blobs +
persistence, video quality, fire (thermal) and fire (visual), and the UT geolocation of one detection.
*Agents per core at 5 Hz* = ``floor(200 ms / step ms)``; *perception only* drops the rendering (a real
agent gets its frames from a camera). Goal (chosen here): at least one simulated agent per core at the
agent rate at each size.

Paper figures: Ross et al. (spec 002 §4.3) report 0.086 s on average per target-geolocation run at 4 Hz
on the onboard ReadyBoard (with the planner sharing the CPU); thesis 000 gives no processing times.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from agent.sensors.bearing import bearing_covariance
from mesh_sim.bench import common

NAME = "perception"
SIZES = ((320, 240), (640, 480))
AGENT_RATE_HZ = 5.0  # DESIGN.md §4, mesh_sim/scenarios/default.toml rate_hz
PAPER_GEOLOCATION_MS = 86.0  # Ross et al. Sec. VI.D (spec 002 §4.3): mean time per geolocation run
ALTITUDE_M = 80.0  # geolocation scene: the default scenario's flight altitude
TILT_DEG = -60.0  # geolocation scene: gimbal tilt (0 = forward, -90 = nadir); chosen here
DEM_CELL_M = 30.0  # Ross et al.: a USGS DEM (30 m grid)
BEARING_SIGMA_DEG = 1.0  # agent.sensors.bearing.BearingSensorConfig default line-of-sight noise


@dataclass(frozen=True)
class Op:
    key: str
    label: str
    group: str  # "baseline", "render", "detect" or "geolocate"
    in_step: bool  # part of the agent step


OPS = [
    Op("baseline", "cv2 cvtColor + threshold", "baseline", False),
    Op("render_rgb", "render RGB", "render", False),
    Op("render_thermal", "render thermal", "render", False),
    Op("render_both", "render RGB + thermal", "render", True),
    Op("render_banding", "render RGB + thermal, banding", "render", False),
    Op("colour_blobs", "colour blobs (HSV)", "detect", True),
    Op("dark_blobs", "dark blobs", "detect", False),
    Op("dark_persistent", "dark blobs + persistence", "detect", True),
    Op("video_quality", "video quality D(t)", "detect", True),
    Op("fire_thermal", "fire, thermal threshold", "detect", True),
    Op("fire_visual", "fire, visual histogram", "detect", True),
    Op("geo_flat", "pixel -> ground, flat", "geolocate", False),
    Op("geo_dem", "pixel -> ground, grid DEM", "geolocate", False),
    Op("geo_ut", "UT geolocation of a detection (DEM)", "geolocate", True),
    *(
        Op(f"camera_{stage}_{render}", f"{label}, {'ROI' if render == 'roi' else 'whole frame'}", "camera", False)
        for stage, label in (("render", "camera render"), ("colour", "colour blobs"), ("dark", "dark blobs"),
                             ("quality", "video quality D(t)"), ("step", "camera sensor step"))
        for render in ("full", "roi")
    ),
]
#: The camera stages timed whole and as ROI (``camera_<stage>_full`` and ``camera_<stage>_roi``).
CAMERA_STAGES = ("render", "colour", "dark", "quality", "step")
CAMERA_ALTITUDE_M = 80.0  # the default scenario's flight altitude
CAMERA_TARGETS_NE = ((12.0, -7.0), (-30.0, 20.0), (200.0, 0.0))  # two in view of the 80 m camera, one far away
OP_BY_KEY = {op.key: op for op in OPS}
RENDER_KEYS = ("render_both",)


def jobs(width: int, height: int) -> dict[str, Callable[[], object]]:
    """The timed operations at one image size (key -> no-argument callable), built once per size."""
    import cv2

    from fusion.measurement import los_to_azel
    from perception.blobs import ColorBlobDetector, DarkBlobDetector
    from perception.camera import Intrinsics
    from perception.degradation import Degradation
    from perception.dem import GridTerrain
    from perception.evaluation import sequence
    from perception.fire_segmentation import FireSegmenter
    from perception.geolocation import geolocate
    from perception.persistence import PersistentDetector
    from perception.pinhole import PinholeView
    from perception.pose import CameraPose, Gimbal
    from perception.projection import pixel_to_ground, pixel_to_ray_world
    from perception.quality import VideoQuality
    from perception.render import Fire, Target, default_ground, render_frame
    from perception.terrain import FlatTerrain, HillsTerrain

    frames = sequence(4, width, height, "terrain", target_rgb=(210, 25, 30), n_fires=2, seed=1)
    view = PinholeView.look_at((0.0, 0.0, -30.0), (0.0, 0.0, 0.0), width, height, math.radians(60.0))
    targets = [Target((1.0, 2.0, -0.5), 0.5, (210, 25, 30)), Target((-3.0, 1.0, -0.5), 0.5, (30, 30, 30))]
    fires = [Fire((4.0, -3.0), 4.0, 800.0)]
    ground = default_ground()
    banding = Degradation(banding_prob=1.0)
    visual = FireSegmenter("histogram").fit([f.rgb for f in frames], [f.fire_mask for f in frames])
    thermal = FireSegmenter("threshold")
    rgb, th = frames[0].rgb, frames[0].thermal
    colour, dark = ColorBlobDetector(), DarkBlobDetector()
    persistent, quality = PersistentDetector(DarkBlobDetector()), VideoQuality()

    def render(**kw):
        return render_frame(view, width, height, targets, fires, ground=ground, **kw)

    def baseline():
        gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
        return cv2.threshold(gray, 128, 255, cv2.THRESH_BINARY)

    # geolocation: a camera 80 m up over hills, one detection right of and below the image centre
    intrinsics = Intrinsics.from_fov(width, height, 60.0)
    pose = CameraPose.from_vehicle([0.0, 0.0, -ALTITUDE_M], 0.02, -0.03, 0.3, Gimbal(0.0, math.radians(TILT_DEG)))
    pixel = np.array([0.6 * width, 0.55 * height])
    flat = FlatTerrain(0.0)
    dem = GridTerrain.sample(HillsTerrain(20.0, 300.0, seed=1), -1500.0, -1500.0, DEM_CELL_M, (101, 101))
    los = pixel_to_ray_world(pose, intrinsics, pixel)
    azel = los_to_azel(los)
    sigma = math.radians(BEARING_SIGMA_DEG)
    R_azel = bearing_covariance(azel[1], sigma)
    for terrain in (flat, dem):
        if pixel_to_ground(pose, intrinsics, terrain, pixel) is None:
            raise RuntimeError("geolocation scene: the pixel's ray misses the terrain")
    if geolocate(pose.centre, azel, R_azel, dem) is None:
        raise RuntimeError("geolocation scene: the UT geolocation missed the DEM")

    table = {
        "baseline": baseline,
        "render_rgb": lambda: render(thermal=False),
        "render_thermal": lambda: render(rgb=False),
        "render_both": render,
        "render_banding": lambda: render(degradation=banding),
        "colour_blobs": lambda: colour.detect(rgb),
        "dark_blobs": lambda: dark.detect(rgb),
        "dark_persistent": lambda: persistent.detect(rgb),
        "video_quality": lambda: quality.update(rgb),
        "fire_thermal": lambda: thermal.segment(th),
        "fire_visual": lambda: visual.segment(rgb),
        "geo_flat": lambda: pixel_to_ground(pose, intrinsics, flat, pixel),
        "geo_dem": lambda: pixel_to_ground(pose, intrinsics, dem, pixel),
        "geo_ut": lambda: geolocate(pose.centre, azel, R_azel, dem),
    }
    table.update(camera_jobs(width, height))
    assert list(table) == [op.key for op in OPS]
    return table


def camera_jobs(width: int, height: int) -> dict[str, Callable[[], object]]:
    """The camera stages, whole frame and ROI, at one image size (see the module docstring)."""
    import itertools

    from agent.sensors.camera import CameraSensor
    from agent.sensors.camera_config import CameraSensorConfig
    from agent.vehicles.base import VehicleState
    from perception.blobs import ColorBlobDetector, DarkBlobDetector
    from perception.camera import Intrinsics
    from perception.pose import CameraPose, Gimbal
    from perception.quality import VideoQuality
    from perception.render import Target, render_frame
    from perception.roi_frame import RoiFrame, whole_view
    from perception.roi_render import render_roi

    position = np.array([0.0, 0.0, -CAMERA_ALTITUDE_M])
    pose = CameraPose.from_vehicle(position, 0.02, -0.01, 0.3, Gimbal(0.0, -math.pi / 2))
    camera = (pose, Intrinsics.from_fov(width, height, 90.0))

    def scene(rgb):
        return [Target((n, e, 0.0), 1.5, rgb, shape="disc") for n, e in CAMERA_TARGETS_NE]

    red, dark = scene((200, 20, 20)), scene((28, 28, 32))

    def draw(render: str, targets, ground: str = "terrain"):
        """The frame the camera hands its detector: the whole RGB image, or a RoiFrame."""
        if render == "roi":
            frame = render_roi(camera, width, height, targets, ground=ground, seed=1)
            return frame if isinstance(frame, RoiFrame) else frame.rgb
        return render_frame(camera, width, height, targets, ground=ground, seed=1, thermal=False).rgb

    truth = [{"id": f"t{k}", "position": np.array([n, e, 0.0])} for k, (n, e) in enumerate(CAMERA_TARGETS_NE)]
    table = {}
    for render in ("full", "roi"):
        colour_frame, dark_frame = draw(render, red), draw(render, dark, "tiles")
        whole = whole_view(colour_frame)  # what D(t) is measured on
        colour, dark_blobs, quality = ColorBlobDetector(), DarkBlobDetector(), VideoQuality()
        sensor = CameraSensor(CameraSensorConfig(width=width, height=height, render=render), seed=1)
        steps = itertools.count()

        def step(sensor=sensor, steps=steps):
            t = 0.2 * next(steps)
            return sensor.detect(t, VehicleState(t, position, np.zeros(3), 0.3, 0.02, -0.01), truth)

        table[f"camera_render_{render}"] = lambda render=render: draw(render, red)
        table[f"camera_colour_{render}"] = lambda d=colour, f=colour_frame: d.detect(f)
        table[f"camera_dark_{render}"] = lambda d=dark_blobs, f=dark_frame: d.detect(f)
        table[f"camera_quality_{render}"] = lambda q=quality, f=whole: q.update(f)
        table[f"camera_step_{render}"] = step
    return {f"camera_{stage}_{render}": table[f"camera_{stage}_{render}"] for stage in CAMERA_STAGES
            for render in ("full", "roi")}


def _check_sizes(sizes) -> tuple[tuple[int, int], ...]:
    out = []
    for size in sizes:
        try:
            w, h = (int(v) for v in size)
        except (TypeError, ValueError):
            raise ValueError(f"sizes must be (width, height) pairs, got {size!r}") from None
        if w < 32 or h < 24:
            raise ValueError(f"image size must be at least 32x24, got {w}x{h}")
        out.append((w, h))
    if not out:
        raise ValueError("sizes must not be empty")
    return tuple(out)


def run(
    quick: bool = False,
    repeats: int | None = None,
    *,
    sizes: Sequence[tuple[int, int]] | None = None,
    default_threads: bool = True,
) -> dict:
    """Run the benchmark; returns ``{"benchmark", "settings", "environment", "rows", "steps", "goals"}``.

    ``sizes`` (keyword-only, for tests) replaces the image sizes; ``default_threads=False`` skips the
    reference timings with OpenCV's default thread count."""
    import cv2

    settings = common.Settings.create(quick, repeats)
    sizes = _check_sizes(SIZES if sizes is None else sizes)
    saved = cv2.getNumThreads()
    thread_modes = [1] + ([saved] if default_threads and saved != 1 else [])
    rows = []
    try:
        with common.progress(len(sizes) * len(thread_modes), NAME) as advance:
            for width, height in sizes:
                table = jobs(width, height)
                for threads in thread_modes:
                    advance(f"{width}x{height}, {threads} thread(s)")
                    cv2.setNumThreads(threads)
                    timings = common.time_calls(table, settings)
                    base = timings["baseline"].median_us
                    for op in OPS:
                        t = timings[op.key]
                        rows.append({
                            "size": f"{width}x{height}", "width": width, "height": height, "threads": threads,
                            "op": op.key, "label": op.label, "group": op.group, "in_step": op.in_step,
                            "ms": t.median_us / 1e3, "best_ms": t.best_us / 1e3,
                            "ratio_to_baseline": t.median_us / base, "repeats": t.repeats, "number": t.number,
                        })
    finally:
        cv2.setNumThreads(saved)
    steps = _steps(rows, sizes)
    roi = _roi(rows, sizes)
    goals = {
        "one_agent_per_core": {
            "description": f"at least one simulated agent (render + perceive) per core at {AGENT_RATE_HZ:g} Hz",
            "results": [{"size": s["size"], "agents_per_core": s["agents_per_core"], "pass": s["agents_per_core"] >= 1}
                        for s in steps],
        }
    }
    goals["one_agent_per_core"]["pass"] = all(r["pass"] for r in goals["one_agent_per_core"]["results"])
    return {
        "benchmark": NAME,
        "settings": {"quick": settings.quick, "repeats": settings.repeats, "min_time_s": settings.min_time,
                     "sizes": [f"{w}x{h}" for w, h in sizes], "threads": thread_modes,
                     "agent_rate_hz": AGENT_RATE_HZ, "step_ops": [op.key for op in OPS if op.in_step]},
        "environment": common.environment(("numpy", "scipy", "opencv-python-headless")),
        "rows": rows,
        "steps": steps,
        "roi": roi,
        "goals": goals,
    }


def _roi(rows: list[dict], sizes) -> list[dict]:
    """Each camera stage drawn as ROI against the whole frame, per size, from the one-thread timings."""
    out = []
    for width, height in sizes:
        size = f"{width}x{height}"
        ms = {r["op"]: r["ms"] for r in rows if r["size"] == size and r["threads"] == 1}
        for stage in CAMERA_STAGES:
            full, roi = ms[f"camera_{stage}_full"], ms[f"camera_{stage}_roi"]
            label = OP_BY_KEY[f"camera_{stage}_full"].label.rsplit(",", 1)[0]
            out.append({"size": size, "stage": stage, "label": label, "full_ms": full, "roi_ms": roi,
                        "ratio": roi / full})
    return out


def _steps(rows: list[dict], sizes) -> list[dict]:
    """The agent-step budget per size, from the one-thread timings."""
    budget_ms = 1e3 / AGENT_RATE_HZ
    out = []
    for width, height in sizes:
        size = f"{width}x{height}"
        ms = {r["op"]: r["ms"] for r in rows if r["size"] == size and r["threads"] == 1}
        step = sum(ms[op.key] for op in OPS if op.in_step)
        render = sum(ms[k] for k in RENDER_KEYS)
        perceive = step - render
        out.append({
            "size": size, "step_ms": step, "render_ms": render, "perception_ms": perceive,
            "step_ratio_to_baseline": step / ms["baseline"],
            "agents_per_core": int(budget_ms // step), "agents_per_core_exact": budget_ms / step,
            "perception_agents_per_core": int(budget_ms // perceive), "budget_ms": budget_ms,
        })
    return out


# ==================================================================================================
# report
# ==================================================================================================
def report(result: dict, console=None) -> None:
    """Print the tables of a :func:`run` result."""
    console = console or common.make_console()
    s, env = result["settings"], result["environment"]
    console.print(
        f"[bold]{NAME}[/bold]  {'quick' if s['quick'] else 'full'} run, {s['repeats']} repeats; median ms per call. "
        f"{common.machine_line(env, {'numpy': 'numpy', 'OpenCV': 'opencv-python-headless'})}",
        highlight=False,
    )
    sizes = s["sizes"]
    multi = [t for t in s["threads"] if t != 1]
    by = {(r["size"], r["threads"], r["op"]): r for r in result["rows"]}
    rows = []
    for op in OPS:
        cells = [op.group, op.label + (" *" if op.in_step else "")]
        for size in sizes:
            r = by.get((size, 1, op.key))
            cells.append("—" if r is None else common.fmt_ms(r["ms"]))
            cells.append("—" if r is None else common.fmt_ratio(r["ratio_to_baseline"]))
            if multi:
                m = by.get((size, multi[0], op.key))
                cells.append("—" if m is None else common.fmt_ms(m["ms"]))
        rows.append(cells)
    columns = [("group", "left"), ("operation", "left")]
    for size in sizes:
        columns += [f"{size} ms", "÷ baseline"] + ([f"{size} ms, {multi[0]} thr"] if multi else [])
    common.print_table(
        console, "Milliseconds per frame (1 OpenCV thread; ratio to cv2 cvtColor + threshold on the same frame)",
        columns, rows,
        "* = part of the agent step. Render: nadir view from 30 m, 2 balls, 1 fire, procedural terrain. Geolocation: "
        f"camera {ALTITUDE_M:g} m up, tilt {TILT_DEG:g}°, {DEM_CELL_M:g} m grid DEM of hills; UT = 13 ray casts "
        f"(azimuth, elevation, DEM error, 3 camera-position errors).\nRoss et al. (spec 002 §4.3): "
        f"{PAPER_GEOLOCATION_MS:g} ms mean per geolocation run on the onboard ReadyBoard at 4 Hz (planner sharing the "
        "CPU); thesis 000 gives no processing times.",
    )
    step_rows = []
    for st in result["steps"]:
        step_rows.append([
            st["size"], *(common.fmt_ms(st[key]) for key in ("render_ms", "perception_ms", "step_ms")),
            common.fmt_ratio(st["step_ratio_to_baseline"]), f"{st['budget_ms']:.0f}",
            f"[bold]{st['agents_per_core']}[/bold] ({st['agents_per_core_exact']:.1f})",
            st["perception_agents_per_core"],
        ])
    common.print_table(
        console, f"Agent step budget at {s['agent_rate_hz']:g} Hz, one core",
        ["size", "render ms", "perceive ms", "step ms", "step ÷ baseline", "budget ms", "agents / core",
         "perception-only agents / core"],
        step_rows,
        "Step = " + " + ".join(OP_BY_KEY[k].label for k in s["step_ops"]) + ".\nAgents per core = floor(budget / "
        "step); perception-only drops the rendering (a real camera). The agent's fusion and messaging are not "
        "included (see skymesh bench fusion-ops / scale).",
    )
    roi = {(r["size"], r["stage"]): r for r in result["roi"]}
    roi_rows = []
    for stage in CAMERA_STAGES:
        cells = [roi[(sizes[0], stage)]["label"]]
        for size in sizes:
            r = roi[(size, stage)]
            cells += [common.fmt_ms(r["full_ms"]), common.fmt_ms(r["roi_ms"]), common.fmt_ratio(r["ratio"])]
        roi_rows.append(cells)
    columns = [("camera stage", "left")]
    for size in sizes:
        columns += [f"{size} whole ms", f"{size} ROI ms", "ROI ÷ whole"]
    common.print_table(
        console, "Camera: whole frame vs ROI (render = \"full\" vs \"roi\"; 1 OpenCV thread)", columns, roi_rows,
        f"The default scenario's view: nadir from {CAMERA_ALTITUDE_M:g} m, 90° HFOV, {len(CAMERA_TARGETS_NE)} discs "
        "of 1.5 m (two in view). ROI: a preview of the whole view at 320×240 plus full-resolution windows around "
        "the targets (perception.roi_render); a camera no larger than 320×240 is drawn whole.\nColour blobs: red "
        "discs over the terrain; dark blobs: dark discs over the tiled floor. Step: CameraSensor.detect (render, "
        "D(t), colour blobs, bearings).",
    )
    goal = result["goals"]["one_agent_per_core"]
    console.print(f"{common.verdict(goal['pass'])}  {goal['description']}", highlight=False)
