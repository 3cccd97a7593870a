"""A live run with the camera pipeline: real agent processes render, detect and track, one of them reading its
frames from a video file (``--camera``). Checks that no process it caused is left running (by PID)."""

from __future__ import annotations

import math

import cv2
import pytest

from mesh_sim.launcher import Launcher, new_run_dir
from mesh_sim.scenario import load
from perception.camera import Intrinsics
from perception.pose import CameraPose, Gimbal
from perception.render import render_frame
from perception.scene import Target
from tests.processes import assert_all_gone

pytestmark = pytest.mark.slow  # live multi-process runs: launcher, agent processes, Zenoh router

VIDEO_FRAMES = 20
DURATION = 15.0




@pytest.fixture(scope="module")
def camera_run(tmp_path_factory):
    """4 agents of the default scenario (cameras) for 15 s at real time; uav0 watches a video of a red target."""
    video = tmp_path_factory.mktemp("video") / "red.avi"
    pose = CameraPose.from_vehicle([0.0, 0.0, -80.0], 0.0, 0.0, 0.0, Gimbal(0.0, -math.pi / 2))
    frame = render_frame((pose, Intrinsics.from_fov(640, 480, 90.0)), 640, 480,
                         [Target((3.0, 2.0, 0.0), 1.5, shape="disc")], seed=0, thermal=False).rgb
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 5.0, (640, 480))
    for _ in range(VIDEO_FRAMES):
        writer.write(cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))
    writer.release()
    scenario = load("default", duration=DURATION, agents=4)
    run_dir = new_run_dir(tmp_path_factory.mktemp("runs"), scenario.name)
    outcome = Launcher(scenario, run_dir, speed=1.0, rerun="off", cameras={"uav0": str(video)}).run()
    return outcome, str(video)


def test_live_camera_run_completes_at_5_hz(camera_run):
    outcome, video = camera_run
    assert outcome.status == "completed", outcome.status
    agents = {a["id"]: a for a in outcome.metrics["agents"]}
    assert len(agents) == 4
    for agent in agents.values():
        assert agent["steps"] >= 0.9 * DURATION * 5, agent["id"]
        assert agent["deadline_misses"] <= agent["steps"] // 4, (agent["id"], agent["deadline_misses"])
        assert agent["sensor"]["kind"] == "camera"
        assert agent["sensor"]["frames"] == agent["steps"]
        assert agent["sensor"]["video_quality"] is not None
    print({a: (m["steps"], m["deadline_misses"], round(m["cpu_per_step_ms"], 1)) for a, m in agents.items()})


def test_live_camera_run_reads_the_video_file_for_one_agent(camera_run):
    outcome, video = camera_run
    uav0 = next(a for a in outcome.metrics["agents"] if a["id"] == "uav0")
    assert uav0["sensor"]["source"] == video
    assert uav0["sensor"]["detections"] == VIDEO_FRAMES  # one red target per frame of the file
    assert uav0["sensor_outcomes"]["read_failed"] == uav0["steps"] - VIDEO_FRAMES  # the file ended: counted
    others = [a for a in outcome.metrics["agents"] if a["id"] != "uav0"]
    assert all(a["sensor"]["source"] == "synthetic" for a in others)


def test_live_camera_run_leaves_no_process(camera_run):
    assert_all_gone(camera_run[0].pids.values())
