"""A bad environment — an unwritable or full output folder, a port in use, a missing camera, a dead router, an
agent index the scenario has not — is one clear line on stderr and exit code 2, with no traceback and nothing
half-written (issue 16, item 5). Each test names the bad input it gives.

The folder tests mount small tmpfs file systems (read-only, or full): they need root, and are skipped without.
"""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest

from agent.__main__ import main as agent_main
from agent.runtime import atomic_file
from mesh_sim import cli, launcher
from mesh_sim.autopilot.process import free_udp_ports
from mesh_sim.launcher import free_port, open_router
from mesh_sim.scenario import load
from mesh_sim.world import main as world_main

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture
def tmpfs(tmp_path):
    """``tmpfs(name, options)`` mounts a tmpfs at ``tmp_path/name`` and returns it; every mount is unmounted after
    the test (skipped where mounting is not allowed)."""
    mounted: list[Path] = []

    def mount(name: str, options: str) -> Path:
        path = tmp_path / name
        path.mkdir()
        done = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(path)], capture_output=True,
                              text=True, check=False)
        if done.returncode != 0:
            pytest.skip(f"cannot mount a tmpfs here (root needed): {done.stderr.strip()}")
        mounted.append(path)
        return path

    try:
        yield mount
    finally:
        for path in mounted:
            subprocess.run(["umount", str(path)], check=True)


@pytest.fixture
def taken_port():
    """A loopback TCP port that a listening socket holds for the test."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        yield s.getsockname()[1]


def _one_line(err: str) -> str:
    """The single line of ``err``, asserting it is one and no traceback."""
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    return err.strip()


def _run(capsys, out: Path, *args: str) -> tuple[int, str]:
    """``skymesh run --lockstep --rerun off --duration 2 --out OUT ARGS``: its exit code and its one stderr line."""
    code = cli.main(["run", "--lockstep", "--rerun", "off", "--duration", "2", "--out", str(out), *args])
    return code, _one_line(capsys.readouterr().err)


# -- writing results -------------------------------------------------------------------------------------------
def test_atomic_file_leaves_the_old_file_and_no_temporary_when_the_write_fails(tmp_path):
    """Bad input: a write that raises half-way (here a ValueError after some text)."""
    path = tmp_path / "metrics.json"
    path.write_text("old")
    with pytest.raises(ValueError), atomic_file(path) as f:
        f.write("half of the new")
        raise ValueError("the disk went away")
    assert path.read_text() == "old" and sorted(p.name for p in tmp_path.iterdir()) == ["metrics.json"]
    with atomic_file(path) as f:
        f.write("new")
    assert path.read_text() == "new" and sorted(p.name for p in tmp_path.iterdir()) == ["metrics.json"]


def test_atomic_file_on_a_full_disk_names_the_file_and_leaves_nothing(tmpfs):
    """Bad input: 64 KiB written to a 16 KiB tmpfs."""
    disk = tmpfs("full", "size=16k")
    with pytest.raises(OSError) as caught, atomic_file(disk / "oracle.json") as f:
        f.write("x" * 65536)
        f.flush()
    assert caught.value.filename == str(disk / "oracle.json") and "No space left" in caught.value.strerror
    assert list(disk.iterdir()) == []


def test_atomic_file_in_a_read_only_folder_names_the_file(tmpfs):
    """Bad input: a result file in a read-only tmpfs (the temporary file cannot even be created)."""
    folder = tmpfs("ro", "ro,size=16k")
    with pytest.raises(OSError) as caught, atomic_file(folder / "metrics.json") as f:
        f.write("{}")
    assert caught.value.filename == str(folder / "metrics.json") and caught.value.strerror == "Read-only file system"



# -- the output folder -----------------------------------------------------------------------------------------
def test_a_read_only_output_folder_is_one_line_naming_it(tmpfs, capsys):
    """Bad input: ``--out`` inside a read-only tmpfs."""
    out = tmpfs("ro", "ro,size=64k") / "runs"
    code, line = _run(capsys, out)
    assert code == 2
    assert line == f"skymesh run: {out}: cannot create a run folder here: Read-only file system"


def test_an_output_folder_under_a_regular_file_is_one_line_naming_it(tmp_path, capsys):
    """Bad input: ``--out FILE/runs`` where FILE is a regular file."""
    (tmp_path / "a-file").write_text("")
    out = tmp_path / "a-file" / "runs"
    code, line = _run(capsys, out)
    assert code == 2 and line == f"skymesh run: {out}: cannot create a run folder here: Not a directory"


@pytest.mark.slow  # a lockstep run of 2 s
def test_a_full_disk_is_one_line_and_leaves_no_half_written_run(tmpfs, capsys):
    """Bad input: ``--out`` on a 32 KiB tmpfs: the agents' and the world's JSON fit, metrics.json does not.
    The line names the file; the run folder is removed, with no partial metrics.json or temporary file."""
    out = tmpfs("full", "size=32k")
    code, line = _run(capsys, out)
    assert code == 2
    assert line.startswith(f"skymesh run: {out}/default-") and line.endswith("/metrics.json: No space left on device")
    assert list(out.iterdir()) == []


def test_a_benchmark_json_that_cannot_be_written_is_one_line_exit_2(tmpfs, capsys, monkeypatch):
    """Bad input: ``skymesh bench fire --json RO/fire.json`` in a read-only tmpfs (the benchmark itself faked)."""
    from mesh_sim.bench import fire

    monkeypatch.setattr(fire, "run", lambda **kwargs: {"benchmark": "fire", "rows": []})
    monkeypatch.setattr(fire, "report", lambda result, console=None: None)
    path = tmpfs("ro", "ro,size=16k") / "fire.json"
    assert cli.main(["bench", "fire", "--json", str(path)]) == 2
    assert _one_line(capsys.readouterr().err) == f"skymesh bench fire: {path}: Read-only file system"


# -- a camera --------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("source, why", [
    ("does-not-exist.avi", "no such file"),
    ("junk.avi", "not a video file OpenCV can read"),
    (".", "a folder, not a video file"),
])
def test_a_camera_that_is_not_a_video_is_one_line_naming_it_and_no_run_starts(tmp_path, capsys, monkeypatch,
                                                                              source, why):
    """Bad input: ``--camera uav0=SOURCE`` for a missing file, a file of random bytes, a folder."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "junk.avi").write_bytes(bytes(range(256)) * 20)
    code, line = _run(capsys, tmp_path / "runs", "--camera", f"uav0={source}")
    assert code == 2 and line == f"skymesh run: --camera uav0: cannot open camera source {source!r} ({why})"
    assert not (tmp_path / "runs").exists()


# -- Zenoh: ports and routers ----------------------------------------------------------------------------------
def test_the_launchers_router_tries_another_port_when_its_port_was_taken(monkeypatch, taken_port):
    """Bad input: the port the launcher picked is taken before its router listens (a race, forced here)."""
    ports = iter([taken_port, free_port()])
    monkeypatch.setattr(launcher, "free_port", lambda: next(ports))
    router, endpoint = open_router()
    router.close()
    assert endpoint != f"tcp/127.0.0.1:{taken_port}"


def test_a_router_that_cannot_listen_is_one_line_exit_2_and_no_folder(tmp_path, capsys, monkeypatch, taken_port):
    """Bad input: every port the launcher picks for its router is taken (``skymesh run``, live)."""
    monkeypatch.setattr(launcher, "free_port", lambda: taken_port)
    code = cli.main(["run", "--duration", "1", "--rerun", "off", "--out", str(tmp_path / "runs")])
    line = _one_line(capsys.readouterr().err)
    assert code == 2 and line.startswith("skymesh run: cannot open the Zenoh session (Can not create a new TCP "
                                         f"listener bound to tcp/127.0.0.1:{taken_port}")
    assert "Address already in use" in line and list((tmp_path / "runs").iterdir()) == []


def _scenario_file(tmp_path: Path) -> str:
    path = tmp_path / "scenario.json"
    path.write_text(json.dumps(load("default").raw))
    return str(path)


def test_an_agent_listening_on_a_taken_port_is_one_line_exit_2(tmp_path, capsys, taken_port):
    """Bad input: ``python -m agent --zenoh-config FILE`` whose ``listen`` endpoint is a port in use."""
    config = tmp_path / "zenoh.json5"
    config.write_text(json.dumps({"mode": "peer", "listen": {"endpoints": [f"tcp/127.0.0.1:{taken_port}"]},
                                  "scouting": {"multicast": {"enabled": False}}}))
    code = agent_main(["--id", "uav0", "--index", "0", "--fleet", "f", "--scenario", _scenario_file(tmp_path),
                       "--zenoh-config", str(config), "--out", str(tmp_path)])
    line = _one_line(capsys.readouterr().err)
    assert code == 2 and line.startswith("agent uav0: cannot open the Zenoh session") and "in use" in line


@pytest.mark.parametrize("index", [4, -1])
def test_an_agent_index_outside_the_team_is_one_line_exit_2(tmp_path, capsys, index):
    """Bad input: ``python -m agent --index 4`` (and -1) for the default scenario's 4 agents."""
    code = agent_main(["--id", "uav0", "--index", str(index), "--fleet", "f", "--scenario", _scenario_file(tmp_path),
                       "--connect", f"tcp/127.0.0.1:{free_port()}", "--out", str(tmp_path)])
    assert code == 2
    assert _one_line(capsys.readouterr().err) == \
        f"agent uav0: --index {index} is not an agent of this scenario: it has 4 (0..3)"


@pytest.mark.slow  # each waits for Zenoh to give up on the endpoint (about a second)
@pytest.mark.parametrize("prog", ["agent", "world"])
def test_a_process_whose_router_is_dead_is_one_line_exit_2(tmp_path, capsys, prog):
    """Bad input: ``--connect tcp/127.0.0.1:PORT`` where nothing listens (agent and world, in this process)."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    common = ["--fleet", "f", "--scenario", _scenario_file(tmp_path), "--connect", endpoint, "--out", str(tmp_path)]
    started = time.monotonic()
    code = (agent_main(["--id", "uav0", "--index", "0", *common]) if prog == "agent"
            else world_main([*common, "--duration", "1"]))
    line = _one_line(capsys.readouterr().err)
    assert code == 2 and time.monotonic() - started < 10
    name = "agent uav0" if prog == "agent" else "world"
    assert line == f"{name}: the Zenoh router could not be reached (Unable to connect to any of [Single({endpoint})]!)"
    assert list(tmp_path.iterdir()) == [tmp_path / "scenario.json"]


@pytest.mark.slow  # processes that wait for Zenoh to give up on the endpoint
@pytest.mark.parametrize("command", [["mesh_sim.observer"], ["mesh_sim.cli", "view"]])
def test_an_observer_whose_router_is_dead_is_one_line_exit_2_and_writes_no_recording(tmp_path, command):
    """Bad input: ``python -m mesh_sim.observer`` / ``skymesh view`` ``--connect tcp/127.0.0.1:PORT`` where nothing
    listens, saving to x.rrd: no recording file is created."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    proc = subprocess.run([sys.executable, "-m", *command, "--fleet", f"t{uuid.uuid4().hex[:12]}", "--connect",
                           endpoint, "--save", str(tmp_path / "x.rrd"), "--duration", "5"],
                          cwd=REPO, capture_output=True, text=True, timeout=60, check=False)
    assert proc.returncode == 2
    assert _one_line(proc.stderr) == ("observer: the Zenoh router could not be reached "
                                      f"(Unable to connect to any of [Single({endpoint})]!)")
    assert not (tmp_path / "x.rrd").exists()


@pytest.mark.slow  # a process
def test_an_autopilot_whose_port_is_taken_is_one_line_on_stderr_naming_it():
    """Bad input: ``skymesh autopilot --offboard-port P`` where a UDP socket holds P. The line goes to stderr (its
    stdout carries JSON lines) and names the ports."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as held:
        held.bind(("127.0.0.1", 0))
        port = held.getsockname()[1]
        (gcs,) = free_udp_ports(1)
        proc = subprocess.run([sys.executable, "-m", "mesh_sim.cli", "autopilot", "--instance", "0", "--offboard-port",
                               str(port), "--gcs-port", str(gcs), "--duration", "1"],
                              cwd=REPO, capture_output=True, text=True, timeout=60, check=False)
    assert proc.returncode == 2 and proc.stdout == ""
    assert _one_line(proc.stderr) == (f"skymesh autopilot: cannot bind its UDP ports 127.0.0.1:{port}, "
                                      f"127.0.0.1:{gcs}: Address already in use")

