"""The camera sensor (agent.sensors.camera): geometry of its bearings, its covariance, detection through the
rendered frame, GPS latency and its compensation, bad frames and old poses, external video sources, and the
whole camera pipeline in lockstep and live runs."""

from __future__ import annotations

import math
import subprocess
import sys
import uuid
from collections import Counter

import cv2
import numpy as np
import pytest

from agent.agent import Agent
from agent.net import wire
from agent.net.bus import InMemoryBus
from agent.net.keys import Keys
from agent.sensors.bearing import BearingSensorConfig, GeometricBearingSensor
from agent.sensors.camera import CameraSensor
from agent.sensors.camera_config import CameraSensorConfig
from agent.sensors.video_source import VideoSource
from agent.vehicles.base import VehicleState
from fusion.measurement import azel_to_los
from mesh_sim.cli import main as skymesh
from mesh_sim.lockstep import run_lockstep
from mesh_sim.scenario import load
from perception.camera import Intrinsics
from perception.pose import CameraPose, Gimbal
from perception.pose_buffer import PoseSample
from perception.render import render_frame
from perception.scene import Target

D = math.radians
F = 320.0  # focal length [px] of the default 640 x 480, 90 degree camera: (640 / 2) / tan(45 deg)


def state(t: float, position=(0.0, 0.0, -80.0), yaw=0.0, roll=0.0, pitch=0.0, velocity=(0.0, 0.0, 0.0)):
    return VehicleState(t, np.array(position, float), np.array(velocity, float), yaw, roll, pitch)


def ground_point(bearing) -> np.ndarray:
    """Where the bearing's ray meets the flat ground z = 0."""
    los = azel_to_los(bearing.azel)
    return bearing.sensor + (-bearing.sensor[2] / los[2]) * los


# --------------------------------------------------------------------------------------------- geometry


def nadir_pose(yaw=0.0) -> PoseSample:
    return PoseSample(0.0, [0.0, 0.0, -80.0], 0.0, 0.0, yaw, 0.0, -math.pi / 2)


def test_bearing_of_the_image_centre_is_straight_down():
    sensor = CameraSensor(CameraSensorConfig(), seed=0)
    b = sensor.bearing(nadir_pose(), (319.5, 239.5), 0.0)
    assert b.azel[1] == pytest.approx(-math.pi / 2)
    assert np.allclose(b.sensor, [0.0, 0.0, -80.0])


def test_bearing_hand_checked_offsets():
    # Looking down with yaw 0, image right is body right = east and image up is body forward = north.
    # A pixel f tan(10 deg) right of the centre sees 10 deg off nadir towards the east: az 90, el -80.
    sensor = CameraSensor(CameraSensorConfig(), seed=0)
    off = F * math.tan(D(10.0))
    right = sensor.bearing(nadir_pose(), (319.5 + off, 239.5), 0.0)
    assert np.allclose(right.azel, [D(90.0), D(-80.0)], atol=1e-9)
    up = sensor.bearing(nadir_pose(), (319.5, 239.5 - off), 0.0)
    assert np.allclose(up.azel, [0.0, D(-80.0)], atol=1e-9)
    # yawed 90 deg (facing east), image up is east
    up_east = sensor.bearing(nadir_pose(D(90.0)), (319.5, 239.5 - off), 0.0)
    assert np.allclose(up_east.azel, [D(90.0), D(-80.0)], atol=1e-9)
    # rolled 10 deg right wing down, the camera looks 10 deg to the left (west): the centre pixel sees az -90
    rolled = PoseSample(0.0, [0.0, 0.0, -80.0], D(10.0), 0.0, 0.0, 0.0, -math.pi / 2)
    assert np.allclose(sensor.bearing(rolled, (319.5, 239.5), 0.0).azel, [D(-90.0), D(-80.0)], atol=1e-9)


def test_first_order_covariance_matches_monte_carlo():
    config = CameraSensorConfig(pixel_sigma=1.5, attitude_sigma=D(0.5))
    sensor = CameraSensor(config, seed=0)
    pose = PoseSample(0.0, [0.0, 0.0, -80.0], D(5.0), D(-3.0), D(40.0), 0.0, -math.pi / 2)
    pixel = np.array([520.0, 110.0])
    R = sensor.bearing(pose, pixel, 0.0).R
    rng = np.random.default_rng(3)
    n = 4000
    draws = []
    for du, dv, dr, dp, dy in rng.standard_normal((n, 5)) * [1.5, 1.5, D(0.5), D(0.5), D(0.5)]:
        p = PoseSample(0.0, pose.position, pose.roll + dr, pose.pitch + dp, pose.yaw + dy, 0.0, -math.pi / 2)
        draws.append(sensor.bearing(p, pixel + [du, dv], 0.0).azel)
    empirical = np.cov(np.array(draws).T)
    assert np.allclose(np.sqrt(np.diag(empirical)), np.sqrt(np.diag(R)), rtol=0.06)
    corr = lambda c: c[0, 1] / math.sqrt(c[0, 0] * c[1, 1])  # noqa: E731
    assert corr(empirical) == pytest.approx(corr(R), abs=0.05)


# ---------------------------------------------------------------------------------- rendered detection


def test_a_target_below_is_detected_labelled_and_located():
    sensor = CameraSensor(CameraSensorConfig(), seed=1)
    truth = [{"id": "car", "position": [12.0, -7.0, 0.0]}, {"id": "far", "position": [500.0, 0.0, 0.0]}]
    bearings = sensor.detect(0.0, state(0.0), truth)
    assert len(bearings) == 1
    (b,) = bearings
    assert b.truth_id == "car" and b.t == 0.0
    assert np.linalg.norm(ground_point(b)[:2] - [12.0, -7.0]) < 0.3
    m = sensor.metrics()
    assert m["detection_rate"] == 1.0 and m["false_detections"] == 0 and m["outcomes"] == {}
    assert 0.0 < m["video_quality"] < 0.05  # clean video (thesis 000 §2.4: clean imagery ~0.01-0.02)


def test_a_failed_video_link_detects_nothing_and_says_so_in_d():
    sensor = CameraSensor(CameraSensorConfig(failed="snow"), seed=1)
    for k in range(10):
        assert sensor.detect(0.2 * k, state(0.2 * k), [{"id": "car", "position": [0.0, 0.0, 0.0]}]) == []
    assert sensor.quality.failed and sensor.video_quality > 0.15
    assert sensor.metrics()["detection_rate"] == 0.0


def test_the_geometric_and_camera_sensors_share_the_interface():
    truth = [{"id": "car", "position": [5.0, 5.0, 0.0]}]
    for sensor in (GeometricBearingSensor(BearingSensorConfig(p_detect=1.0, false_alarms=0.0), 0),
                   CameraSensor(CameraSensorConfig(), 0)):
        (b,) = sensor.detect(1.0, state(1.0), truth)
        assert b.truth_id == "car" and b.R.shape == (2, 2)
        assert "outcomes" in sensor.metrics()
        sensor.close()
    # the geometric sensor still takes a bare camera position (older callers)
    geometric = GeometricBearingSensor(BearingSensorConfig(p_detect=1.0, false_alarms=0.0), 0)
    assert len(geometric.detect(1.0, np.array([0.0, 0.0, -80.0]), truth)) == 1


# -------------------------------------------------------------------------------------------- latency


def overflight(config: CameraSensorConfig, speed: float = 10.0, steps: int = 40):
    """Fly north at ``speed`` over a static target at (20, 0); return (bearing, step time) pairs."""
    sensor = CameraSensor(config, seed=2)
    out = []
    for k in range(steps):
        t = 0.2 * k
        for b in sensor.detect(t, state(t, (speed * t - 20.0, 0.0, -80.0), velocity=(speed, 0, 0)),
                                [{"id": "T", "position": [20.0, 0.0, 0.0]}]):
            out.append((b, t))
    return sensor, out


def test_gps_latency_puts_the_target_behind_and_compensation_removes_it():
    # 10 m/s, 0.43 s late: the camera is believed 4.3 m behind where it is, so every ground point is 4.3 m
    # south (behind) of the target (Ross et al., spec 002 §2.5).
    _, late = overflight(CameraSensorConfig(gps_latency=0.43, noise=0.0))
    errors = np.array([ground_point(b)[:2] - [20.0, 0.0] for b, _ in late])
    assert len(late) > 15
    assert errors[:, 0].mean() == pytest.approx(-4.3, abs=0.3)
    assert all(b.t == t for b, t in late)  # paired at once (with the wrong pose)
    sensor, fixed = overflight(CameraSensorConfig(gps_latency=0.43, latency_compensation=True, noise=0.0))
    errors = np.array([ground_point(b)[:2] - [20.0, 0.0] for b, _ in fixed])
    assert len(fixed) == len(late) - 1
    assert np.abs(errors).max() < 0.3
    # delayed pairing: each bearing is handed over 3 steps (0.6 s >= 0.43 s) after its capture, stamped then
    assert all(t - b.t == pytest.approx(0.6) for b, t in fixed)
    # the frame at t = 0 predates the first report (stamped 0.6 s, stored at 0.17 s): counted, not guessed
    assert sensor.metrics()["outcomes"] == {"pose_too_old": 1}


def test_zero_latency_pairs_at_once_with_or_without_compensation():
    _, a = overflight(CameraSensorConfig(noise=0.0), steps=25)
    _, b = overflight(CameraSensorConfig(noise=0.0, latency_compensation=True), steps=25)
    assert len(a) == len(b) > 5
    for (x, tx), (y, ty) in zip(a, b, strict=True):
        assert tx == x.t and ty == y.t and np.allclose(x.azel, y.azel)


# ---------------------------------------------------------------------------------------- bad input


class ScriptedSource:
    """A video source that hands over a fixed list of frames (then fails to read)."""

    name = "scripted"
    size = (640, 480)

    def __init__(self, frames):
        self.frames = list(frames)
        self.closed = False

    def read(self):
        return self.frames.pop(0) if self.frames else None

    def close(self):
        self.closed = True


def good_frame(target=(3.0, 2.0, 0.0)) -> np.ndarray:
    pose = CameraPose.from_vehicle([0.0, 0.0, -80.0], 0.0, 0.0, 0.0, Gimbal(0.0, -math.pi / 2))
    return render_frame((pose, Intrinsics.from_fov(640, 480, 90.0)), 640, 480, [Target(target, 1.5, shape="disc")],
                        seed=0, thermal=False).rgb


BAD_FRAMES = [None, np.zeros((0, 0, 3), np.uint8), np.zeros((100, 100, 3), np.uint8), b"\x00garbage",
              np.zeros((480, 640, 3), np.float32), np.zeros((480, 640, 4), np.uint8)]


def test_bad_frames_are_counted_by_reason_and_never_raise():
    source = ScriptedSource([good_frame(), *BAD_FRAMES])  # good first: after the bad ones the source has failed
    sensor = CameraSensor(CameraSensorConfig(), seed=0, source=source)
    out = [sensor.detect(0.2 * k, state(0.2 * k), []) for k in range(len(BAD_FRAMES) + 2)]
    assert all(not bearings for bearings in out[1:])
    assert len(out[0]) == 1 and out[0][0].truth_id is None  # the good frame: a detection, no truth label
    assert sensor.outcomes == Counter({"read_failed": 2, "frame_empty": 1, "frame_wrong_shape": 2,
                                       "frame_corrupt": 1, "frame_wrong_dtype": 1})
    assert sensor.metrics()["frames_ok"] == 1
    sensor.close()
    assert source.closed


def test_a_capture_older_than_the_pose_buffer_is_counted():
    sensor = CameraSensor(CameraSensorConfig(pose_buffer=8), seed=0)
    truth = [{"id": "T", "position": [0.0, 0.0, 0.0]}]
    for k in range(11):
        assert len(sensor.detect(0.2 * k, state(0.2 * k), truth)) == 1
    # a frame stamped 0.5 s reaches the sensor after 2 s of poses (a stalled capture): its pose is gone
    assert sensor.detect(0.5, state(0.5), truth) == []
    assert sensor.outcomes["pose_too_old"] == 1


def test_a_pose_that_never_arrives_times_out():
    sensor = CameraSensor(CameraSensorConfig(gps_latency=0.43, latency_compensation=True), seed=0)
    truth = [{"id": "T", "position": [0.0, 0.0, 0.0]}]
    sensor.detect(0.0, state(0.0), truth)  # no report yet at t = 0 (the first is 0.43 s late)
    # the vehicle state stops being valid (NaN): no telemetry, so the waiting frame's pose never comes
    for k in range(1, 12):
        sensor.detect(0.2 * k, state(0.2 * k, (np.nan, 0.0, -80.0)), truth)
    assert sensor.outcomes["pose_timeout"] >= 1 and sensor.outcomes["bad_vehicle_state"] == 11


def test_the_agent_counts_bad_frames_in_its_metrics(tmp_path):
    scenario = load("default", agents=1, duration=2.0).agent
    keys = Keys(f"t-{uuid.uuid4().hex[:8]}")
    bus = InMemoryBus()
    agent = Agent("uav0", 0, scenario, bus.endpoint("uav0", keys.agent_subscriptions()), keys, seed=0,
                  camera=ScriptedSource(BAD_FRAMES))
    for k in range(len(BAD_FRAMES)):
        agent.step(0.2 * k)
    outcomes = agent.metrics()["sensor_outcomes"]
    assert outcomes["frame_wrong_shape"] == 2 and outcomes["read_failed"] == 1 and outcomes["frame_corrupt"] == 1
    assert agent.steps == len(BAD_FRAMES)


# ------------------------------------------------------------------------------------ external video


def write_video(path, frames) -> str:
    """``frames`` (RGB, 640 x 480) as an MJPG .avi at 5 frames per second; its path."""
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 5.0, (640, 480))
    assert writer.isOpened()
    for frame in frames:
        writer.write(cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))
    writer.release()
    return str(path)


@pytest.fixture(scope="module")
def red_target_video(tmp_path_factory) -> str:
    """An MJPG .avi of a nadir camera 80 m above a red disc at (3, 2): 12 frames, 640 x 480."""
    return write_video(tmp_path_factory.mktemp("video") / "red_target.avi", [good_frame()] * 12)


def test_a_video_file_replaces_the_synthetic_camera(red_target_video):
    source = VideoSource(red_target_video)
    assert source.size == (640, 480)
    sensor = CameraSensor(CameraSensorConfig(), seed=0, source=source)
    hits = []
    for k in range(14):
        hits.append(sensor.detect(0.2 * k, state(0.2 * k), truth=[{"id": "ignored", "position": [50, 50, 0]}]))
    assert all(len(h) == 1 for h in hits[:12])
    for (b,) in hits[:12]:
        assert b.truth_id is None  # an external camera has no truth labels
        assert np.linalg.norm(ground_point(b)[:2] - [3.0, 2.0]) < 0.5
    assert hits[12:] == [[], []] and sensor.outcomes["read_failed"] == 2  # end of the file: counted
    sensor.close()


def test_a_source_that_cannot_be_opened_is_a_clear_error(tmp_path):
    with pytest.raises(ValueError, match="cannot open camera source"):
        VideoSource(str(tmp_path / "missing.avi"))
    rc = skymesh(["run", "--camera", f"uav0={tmp_path / 'missing.avi'}", "--out", str(tmp_path), "--rerun", "off"])
    assert rc == 2
    rc = skymesh(["run", "--camera", "uav9=x.avi", "--agents", "2", "--out", str(tmp_path), "--rerun", "off"])
    assert rc == 2
    out = subprocess.run([sys.executable, "-m", "agent", "--id", "uav0", "--index", "0", "--fleet", "x",
                          "--scenario", str(load("default").path), "--connect", "tcp/127.0.0.1:9",
                          "--camera", str(tmp_path / "missing.avi")],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and "cannot open camera source" in out.stderr


def test_skymesh_run_lockstep_with_a_camera_file(tmp_path, red_target_video, capsys):
    rc = skymesh(["run", "--lockstep", "--scenario", "default", "--agents", "2", "--duration", "4", "--rerun", "off",
                  "--out", str(tmp_path), "--camera", f"uav0={red_target_video}"])
    assert rc == 0
    (run_dir,) = tmp_path.iterdir()
    import json

    uav0 = json.loads((run_dir / "agent-uav0.json").read_text())
    assert uav0["sensor"]["source"] == red_target_video
    assert uav0["sensor"]["detections"] == 12  # one per frame of the file
    assert uav0["sensor_outcomes"]["read_failed"] == 21 - 12  # 21 steps, 12 frames


# ------------------------------------------------------------------------------------- whole runs


def test_lockstep_run_with_the_camera_tracks_every_target(tmp_path):
    scenario = load("default", duration=45.0)
    metrics = run_lockstep(scenario, tmp_path)
    assert metrics["fleet"]["targets_tracked_by_every_agent"], [a["targets"] for a in metrics["agents"]]
    for agent in metrics["agents"]:
        s = agent["sensor"]
        assert s["kind"] == "camera" and s["frames"] == agent["steps"] == 226
        assert s["detection_rate"] > 0.85 and s["false_per_frame"] < 0.05, s
        assert agent["sensor_outcomes"] == {}
        for target in agent["targets"]:
            assert target["rmse"] < 10.0 and target["anees"] < 3.0, (agent["id"], target)
    assert metrics["fleet"]["rmse_ratio_to_oracle"] < 3.0


def test_telemetry_carries_the_video_quality():
    scenario = load("default", agents=1, duration=2.0).agent
    keys = Keys(f"t-{uuid.uuid4().hex[:8]}")
    bus = InMemoryBus()
    agent = Agent("uav0", 0, scenario, bus.endpoint("uav0", keys.agent_subscriptions()), keys, seed=0)
    watch = bus.endpoint("watch", [keys.telemetry("*")])
    for k in range(3):
        agent.step(0.2 * k)
    payloads = [wire.decode(item.data).payload for item in watch.drain()]
    assert len(payloads) == 3
    assert all(isinstance(p["video_quality"], float) and 0.0 < p["video_quality"] < 0.05 for p in payloads)
