"""The ground-station observer: covariance ellipsoids, in-process logging to an .rrd, and the process over Zenoh."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import numpy as np
import pytest
from rerun.chunk import RrdReader

from agent.net import wire
from agent.net.keys import Incoming, Keys
from agent.net.zenoh_transport import ZenohTransport, client_config
from fusion.measurement import azel_to_los
from mesh_sim.launcher import free_port
from mesh_sim.observer import Observer
from mesh_sim.observer_geometry import cov_to_ellipsoid, quat_xyzw_to_matrix, ray_end

REPO = Path(__file__).resolve().parents[2]
ORANGE_U32 = (255 << 24) | (150 << 16) | (0 << 8) | 255
GREEN_U32 = (40 << 24) | (200 << 16) | (60 << 8) | 255


# -- helpers -----------------------------------------------------------------------------------------
def _random_spd(rng, scale=1.0):
    a = rng.normal(size=(3, 3))
    return scale * (a @ a.T + 1e-3 * np.eye(3))


def _telemetry(agent: str, seq: int, stamp: float, neighbours: list[str], n_tracks: int = 2, n_bearings: int = 2,
               **extra) -> dict:
    rng = np.random.default_rng(seq + 1000 * int(agent[-1]))
    tracks = []
    for i in range(n_tracks):
        a = rng.normal(size=(6, 6))
        tracks.append({"id": i, "mean": rng.normal(size=6) * 50.0, "cov": a @ a.T + np.eye(6)})
    return {
        "position": np.array([10.0 * seq, 20.0 * int(agent[-1]), -80.0]),
        "velocity": np.array([10.0, 0.0, 0.0]),
        "yaw": 0.0,
        "bearings": np.column_stack([rng.uniform(-3, 3, n_bearings), rng.uniform(-1.2, -0.2, n_bearings)]),
        "neighbours": neighbours,
        "tracks": tracks,
        **extra,
    }


def _truth(stamp: float) -> dict:
    """The world's truth as docs/wire.md types it: string ids, positions and velocities as three numbers."""
    return {"targets": [{"id": str(i), "position": [5.0 * i + stamp, 3.0 * i, 0.0],
                         "velocity": [1.0, 0.0, 0.0]} for i in range(3)]}


def _envelope(kind: str, origin: str, seq: int, stamp: float, payload: dict) -> bytes:
    return wire.encode(wire.Envelope(kind=kind, origin=origin, seq=seq, stamp=stamp, payload=payload))


def _read_rrd(path) -> tuple[dict[str, int], dict[str, object]]:
    """Rows per entity path, and each entity's last chunk as a pyarrow record batch."""
    rows: dict[str, int] = {}
    last: dict[str, object] = {}
    for chunk in RrdReader(str(path)).stream():
        rows[chunk.entity_path] = rows.get(chunk.entity_path, 0) + chunk.num_rows
        last[chunk.entity_path] = chunk.to_record_batch()
    return rows, last


def _gone(pid: int) -> bool:
    """True if ``pid`` has exited (a zombie not reaped by a non-reaping init counts as exited)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] in ("Z", "X")
    except FileNotFoundError:
        return True


def _kill(pid: int) -> None:
    try:
        os.kill(pid, signal.SIGKILL)
    except ProcessLookupError:
        pass


# -- cov_to_ellipsoid ----------------------------------------------------------------------------------
@pytest.mark.parametrize("n_sigma", [1.0, 2.0, 3.0])
def test_cov_to_ellipsoid_reconstructs_random_spd(n_sigma):
    rng = np.random.default_rng(7)
    for k in range(500):
        cov = _random_spd(rng, scale=10.0 ** rng.uniform(-2, 3))
        if k % 50 == 0:
            cov = np.diag(rng.uniform(0.1, 10, 3))  # axis-aligned: the w ~ 1 / trace branch
        if k % 50 == 1:
            cov = np.diag([4.0, 4.0, 1.0])[[2, 0, 1]][:, [2, 0, 1]]  # repeated eigenvalues
        half, q = cov_to_ellipsoid(cov, n_sigma)
        assert half.shape == (3,) and np.all(half >= 0)
        assert abs(np.linalg.norm(q) - 1.0) < 1e-12
        r = quat_xyzw_to_matrix(q)
        assert np.allclose(r @ r.T, np.eye(3), atol=1e-12) and np.linalg.det(r) > 0
        rebuilt = r @ np.diag((half / n_sigma) ** 2) @ r.T
        assert np.max(np.abs(rebuilt - cov)) <= 1e-12 * max(1.0, np.max(np.abs(cov))), k


def test_cov_to_ellipsoid_rotations_through_every_quaternion_branch():
    rng = np.random.default_rng(3)
    for _ in range(200):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        r = quat_xyzw_to_matrix(q)
        cov = r @ np.diag([1.0, 4.0, 9.0]) @ r.T
        half, q2 = cov_to_ellipsoid(cov, 2.0)
        assert np.allclose(half, [2.0, 4.0, 6.0], atol=1e-12)
        assert np.allclose(quat_xyzw_to_matrix(q2) @ np.diag([1.0, 4.0, 9.0]) @ quat_xyzw_to_matrix(q2).T, cov,
                           atol=1e-12)


def test_cov_to_ellipsoid_rejects_bad_input():
    with pytest.raises(ValueError):
        cov_to_ellipsoid(np.eye(2))
    with pytest.raises(ValueError):
        cov_to_ellipsoid(np.full((3, 3), np.nan))


def test_ray_stops_at_flat_ground():
    pos = np.array([0.0, 0.0, -50.0])
    down45 = (0.0, -np.pi / 4)  # elevation below the horizon: the ray descends (NED z grows)
    end = ray_end(pos, down45, 150.0)
    assert abs(end[2]) < 1e-9 and np.allclose(end, pos + 50.0 * np.sqrt(2) * azel_to_los(down45))
    up = ray_end(pos, (1.0, 0.3), 150.0)
    assert np.isclose(np.linalg.norm(up - pos), 150.0)


# -- in process ------------------------------------------------------------------------------------------
def test_observer_logs_expected_entities_and_survives_bad_input(tmp_path):
    keys = Keys(f"t{uuid.uuid4().hex[:12]}")
    obs = Observer(keys, recording_id=f"rec-{uuid.uuid4().hex[:8]}")
    path = tmp_path / "obs.rrd"
    obs.save(path)
    accepted = []
    for k in range(1, 6):
        t = 0.2 * k
        accepted.append(obs.handle(Incoming(keys.sim("truth"), _envelope("truth", "world", k, t, _truth(t)), 0.0)))
        for agent, nbrs in (("uav0", ["uav1", "uav2"]), ("uav1", ["uav0"]), ("uav2", [])):
            payload = _telemetry(agent, k, t, nbrs, bytes_rx=100 * k)
            accepted.append(obs.handle(Incoming(keys.telemetry(agent), _envelope("telemetry", agent, k, t, payload),
                                                0.0)))
        accepted.append(obs.handle(Incoming(keys.belief("track", "uav0"),
                                            _envelope("track", "uav0", 100 + k, t, {"tracks": []}), 0.0)))
    assert all(accepted) and obs.accepted == 25

    bad = [
        Incoming(keys.telemetry("uav0"), b"\x93not an envelope", 0.0),  # an array, not an envelope map
        Incoming(keys.telemetry("uav1"), _envelope("telemetry", "uav0", 50, 2.0, _telemetry("uav0", 50, 2.0, [])),
                 0.0),  # origin differs from the key's agent
        Incoming(keys.telemetry("uav0"), _envelope("telemetry", "uav0", 51, 2.0, {"velocity": np.zeros(3)}), 0.0),
        Incoming(keys.telemetry("uav0"), _envelope("telemetry", "uav0", 52, 2.0,
                                                   _telemetry("uav0", 52, 2.0, []) | {"position": np.full(3, np.nan)}),
                 0.0),
        Incoming(keys.telemetry("uav0"), _envelope("telemetry", "uav0", 53, 2.0, _telemetry("uav0", 53, 2.0, []) | {
            "tracks": [{"id": 1, "mean": np.zeros(6), "cov": -np.eye(6)}]}), 0.0),  # indefinite covariance
        Incoming(keys.telemetry("uav0"), _envelope("telemetry", "uav0", 3, 2.0, _telemetry("uav0", 3, 2.0, [])),
                 0.0),  # an old sequence number
        Incoming("skymesh/other-fleet/telemetry/uav0", b"", 0.0),
        Incoming(keys.sim("truth"), _envelope("truth", "world", 60, 2.0, {"targets": [{"id": 0}]}), 0.0),
    ]
    assert not any(obs.handle(item) for item in bad)
    assert obs.rejected == {"bad_type": 1, "origin_mismatch": 1, "bad_field": 1, "non_finite": 1, "indefinite": 1,
                            "duplicate": 1, "bad_key": 1, "bad_truth": 1}  # a target without a position: the schema
    assert obs.accepted == 25
    obs.close()

    recordings = [(r.application_id, r.recording_id) for r in RrdReader(str(path)).recordings()]
    assert recordings == [("skymesh", obs.rec.get_recording_id())]
    rows, last = _read_rrd(path)
    for entity in ["/world", "/world/truth", "/world/links", "/metrics/tracks/uav0", "/metrics/bytes_rx/uav0",
                   "/metrics/bytes_seen/uav0"] + [
        f"/world/{sub}" for a in ("uav0", "uav1", "uav2")
        for sub in (f"uav/{a}", f"uav/{a}/path", f"agents/{a}/tracks", f"agents/{a}/rays")
    ]:
        assert rows.get(entity, 0) > 0, (entity, sorted(rows))
    assert rows["/world/uav/uav0"] == 5 and rows["/world/truth"] == 5

    tracks = last["/world/agents/uav0/tracks"]
    assert "sim_time" in tracks.schema.names
    assert len(tracks.column("Ellipsoids3D:centers").to_pylist()[-1]) == 2
    assert len(tracks.column("Ellipsoids3D:quaternions").to_pylist()[-1]) == 2
    # uav0-uav1 are reported by both ends (green), uav0-uav2 by uav0 only (orange)
    assert sorted(last["/world/links"].column("LineStrips3D:colors").to_pylist()[-1]) == sorted([GREEN_U32,
                                                                                                ORANGE_U32])
    path_strip = last["/world/uav/uav0/path"].column("LineStrips3D:strips").to_pylist()[-1]
    assert len(path_strip) == 1 and len(path_strip[0]) == 5
    assert path.stat().st_size > 0


def test_path_is_bounded():
    keys = Keys(f"t{uuid.uuid4().hex[:12]}")
    obs = Observer(keys, recording_id="bounded", path_points=10)
    for k in range(1, 30):
        assert obs.handle(Incoming(keys.telemetry("uav0"),
                                   _envelope("telemetry", "uav0", k, 0.2 * k, _telemetry("uav0", k, 0.2 * k, [])), 0.0))
    assert len(obs._paths["uav0"]) == 10
    obs.close()


# -- as a process over Zenoh -------------------------------------------------------------------------------
def _observer_cmd(fleet: str, endpoint: str, rrd: Path, duration: float) -> list[str]:
    return [sys.executable, "-m", "mesh_sim.observer", "--fleet", fleet, "--connect", endpoint, "--save", str(rrd),
            "--duration", str(duration)]


def _wait_for_subscriber(session, key: str, timeout: float = 15.0):
    pub = session.declare_publisher(key)
    deadline = time.monotonic() + timeout
    while not pub.matching_status.matching:
        assert time.monotonic() < deadline, "the observer never subscribed"
        time.sleep(0.05)
    return pub


@pytest.mark.slow
def test_observer_process_over_zenoh_stops_on_sigterm(zenoh_router, tmp_path):
    fleet = f"t{uuid.uuid4().hex[:12]}"
    keys = Keys(fleet)
    rrd = tmp_path / "fleet.rrd"
    log_file = open(tmp_path / "observer.log", "w")  # closed in the finally below
    proc = subprocess.Popen(_observer_cmd(fleet, zenoh_router, rrd, 30.0), cwd=REPO, stdout=log_file, stderr=log_file)
    client = ZenohTransport("tester", keys, client_config([zenoh_router]), subscribe=[], liveliness=False)
    try:
        _wait_for_subscriber(client.session, keys.telemetry("uav0")).undeclare()
        start, k = time.monotonic(), 0
        while time.monotonic() - start < 1.5:
            k += 1
            t = 0.2 * k
            client.publish(keys.sim("truth"), _envelope("truth", "world", k, t, _truth(t)))
            for agent, nbrs in (("uav0", ["uav1"]), ("uav1", ["uav0"])):
                data = _envelope("telemetry", agent, k, t, _telemetry(agent, k, t, nbrs))
                client.publish(keys.telemetry(agent), data)
            client.publish(keys.telemetry("uav1"), b"garbage")
            time.sleep(0.1)
        time.sleep(0.3)  # let the last samples arrive
        os.kill(proc.pid, signal.SIGTERM)
        assert proc.wait(timeout=20) == 0, (tmp_path / "observer.log").read_text()
    finally:
        client.close()
        if proc.poll() is None:
            _kill(proc.pid)
            proc.wait(timeout=10)
        log_file.close()
    text = (tmp_path / "observer.log").read_text()
    assert "rejected a message from uav1 (bad_type)" in text, text  # b"garbage": an int, not an envelope
    rows, _ = _read_rrd(rrd)
    for entity in ("/world/truth", "/world/uav/uav0", "/world/uav/uav1/path", "/world/agents/uav0/tracks",
                   "/world/agents/uav1/rays", "/world/links", "/metrics/tracks/uav1"):
        assert rows.get(entity, 0) > 0, (entity, sorted(rows))
    assert rows["/world/uav/uav0"] >= 5


@pytest.mark.slow
def test_observer_process_exits_when_its_parent_dies(zenoh_router, tmp_path):
    fleet = f"t{uuid.uuid4().hex[:12]}"
    rrd = tmp_path / "orphan.rrd"
    # a parent that starts the observer, reports its pid and dies after a second
    parent_code = (
        "import os, subprocess, sys, time\n"
        f"p = subprocess.Popen({_observer_cmd(fleet, zenoh_router, rrd, 60.0)!r} + ['--parent-pid', str(os.getpid())], "
        "stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)\n"
        "print(p.pid, flush=True)\n"
        "time.sleep(0.5)\n"
    )
    parent = subprocess.Popen([sys.executable, "-c", parent_code], cwd=REPO, stdout=subprocess.PIPE, text=True)
    pid = None
    try:
        pid = int(parent.stdout.readline())
        assert parent.wait(timeout=20) == 0
        deadline = time.monotonic() + 20
        while not _gone(pid):
            assert time.monotonic() < deadline, "the orphaned observer kept running"
            time.sleep(0.1)
    finally:
        if parent.poll() is None:
            _kill(parent.pid)
            parent.wait(timeout=10)
        parent.stdout.close()
        if pid is not None and not _gone(pid):
            _kill(pid)
    rows, _ = _read_rrd(rrd)  # closed properly: the file is readable
    assert rows.get("/world", 0) == 1


@pytest.mark.slow
def test_observer_process_without_a_router_fails_cleanly(tmp_path):
    cmd = _observer_cmd(f"t{uuid.uuid4().hex[:12]}", f"tcp/127.0.0.1:{free_port()}", tmp_path / "x.rrd", 5.0)
    proc = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=30, check=False)
    assert proc.returncode == 2 and "the Zenoh router could not be reached" in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr
    proc = subprocess.run([sys.executable, "-m", "mesh_sim.observer", "--fleet", "f", "--connect", "tcp/127.0.0.1:1"],
                          cwd=REPO, capture_output=True, text=True, timeout=30, check=False)
    assert proc.returncode == 2 and "nothing to do" in proc.stderr


def test_the_live_layout_grows_with_the_fleet_and_names_each_line(tmp_path):
    keys = Keys(f"t{uuid.uuid4().hex[:12]}")
    obs = Observer(keys, recording_id=f"rec-{uuid.uuid4().hex[:8]}")
    path = tmp_path / "obs.rrd"
    obs.save(path)
    for k in range(1, 4):
        for agent in ("uav0", "uav1"):
            payload = _telemetry(agent, k, 0.2 * k, [], bytes_rx=100 * k)
            assert obs.handle(Incoming(keys.telemetry(agent), _envelope("telemetry", agent, k, 0.2 * k, payload), 0.0))
    obs.close()
    reader = RrdReader(str(path))
    assert len(reader.blueprints()) == 2  # one layout as uav0 appeared, another as uav1 joined; none after
    names = {}
    for chunk in reader.stream():
        batch = chunk.to_record_batch()
        if "SeriesLines:names" in batch.schema.names:
            names[chunk.entity_path] = batch.column("SeriesLines:names").to_pylist()[-1]
    assert names["/metrics/tracks/uav1"] == ["uav1"] and names["/metrics/bytes_rx/uav0"] == ["uav0"]
