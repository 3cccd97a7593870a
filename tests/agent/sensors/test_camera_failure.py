"""A failed video source stops giving bearings (issue 18, item 5), and the run says which agent's source failed and
when. The bad input: a real MJPG file whose frames turn to banding (D(t) above its threshold: thesis 000 §2.4) and
that is cut off before its end (truncated), read through OpenCV."""

from __future__ import annotations

import json

import numpy as np
import pytest

from agent.sensors.camera import CameraSensor
from agent.sensors.camera_config import CameraSensorConfig
from agent.sensors.video_source import VideoSource
from mesh_sim import cli
from perception.quality import VideoQuality
from tests.agent.sensors.test_camera import good_frame, state, write_video

GOOD, BANDED = 8, 14  # frames of each kind in the file


def banded(frame: np.ndarray) -> np.ndarray:
    """``frame`` with bright 4-row bands above and below the target's rows (the disc at the centre stays whole, so
    the detector still finds it): D ≈ 0.26, over the 0.15 threshold."""
    out = frame.astype(float)
    rows = (np.arange(frame.shape[0]) // 4) % 2 == 1
    rows[200:280] = False
    out[rows] += (255 - out[rows]) * 0.6
    return out.astype(np.uint8)


@pytest.fixture(scope="module")
def failing_video(tmp_path_factory) -> str:
    """GOOD clean frames of a red disc, then BANDED banded ones, the file cut at 85 % of its bytes."""
    frame = good_frame()
    path = tmp_path_factory.mktemp("video") / "failing.avi"
    write_video(path, [frame] * GOOD + [banded(frame)] * BANDED)
    data = path.read_bytes()
    path.write_bytes(data[: int(0.85 * len(data))])
    return str(path)


def _fly(sensor: CameraSensor, steps: int) -> list:
    return [b for k in range(steps) for b in sensor.detect(0.2 * k, state(0.2 * k), [])]


def test_banded_frames_would_still_give_bearings_without_the_failure_rule(failing_video):
    """The control: with the threshold out of reach, the banded frames are detected (so the next test means
    something)."""
    sensor = CameraSensor(CameraSensorConfig(), seed=0, source=VideoSource(failing_video))
    sensor.quality = VideoQuality(threshold=10.0)
    bearings = _fly(sensor, GOOD + BANDED + 4)
    assert len(bearings) > GOOD + 3
    sensor.close()


def test_a_failed_video_source_gives_no_bearings_from_its_failure_on(failing_video):
    sensor = CameraSensor(CameraSensorConfig(), seed=0, source=VideoSource(failing_video))
    bearings = _fly(sensor, GOOD + BANDED + 4)
    m = sensor.metrics()
    failed_at = m["video_failed_at"]
    assert m["video_failed"] and GOOD * 0.2 <= failed_at < (GOOD + BANDED) * 0.2
    assert len(bearings) >= GOOD and all(b.t < failed_at for b in bearings)
    assert m["outcomes"]["video_failed"] >= 3 and m["outcomes"]["read_failed"] >= 1  # banded, then cut off
    sensor.close()


def test_a_camera_that_never_fails_reports_no_failure_time():
    sensor = CameraSensor(CameraSensorConfig(), seed=1)
    _fly(sensor, 3)
    assert "video_failed_at" not in sensor.metrics() and not sensor.metrics()["video_failed"]


def test_the_run_completes_with_a_warning_naming_the_agent_and_the_time(tmp_path, failing_video, capsys):
    code = cli.main(["run", "--lockstep", "--scenario", "default", "--agents", "2", "--duration", "6", "--rerun",
                     "off", "--out", str(tmp_path), "--camera", f"uav0={failing_video}"])
    out = " ".join(capsys.readouterr().out.split())
    (run_dir,) = tmp_path.iterdir()
    metrics = json.loads((run_dir / "metrics.json").read_text())
    failed_at = metrics["agents"][0]["sensor"]["video_failed_at"]
    warning = f"uav0's video source failed at t = {failed_at:.1f} s; no bearings from it since"
    assert code == 0 and metrics["status"] == "completed with warnings" and metrics["warnings"] == [warning]
    assert "completed with warnings" in out and f"warning: {warning}" in out
