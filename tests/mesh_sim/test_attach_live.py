"""Attaching to a run with what it printed (issue 18, item 4): ``skymesh run`` prints its fleet name and router
endpoint, and ``skymesh view --fleet NAME --connect ENDPOINT`` made of exactly that line records the fleet; with
``--zenoh-config FILE`` the run's router is the file's (here: listening on every interface). A bad file is one line
naming it, exit code 2, no run folder (the bad inputs: a file that is not JSON5, a client's file, a router that lists
no endpoints)."""

from __future__ import annotations

import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from mesh_sim import cli
from mesh_sim.launcher import free_port
from mesh_sim.run_router import local_endpoint

REPO = Path(__file__).resolve().parents[2]
ATTACH = re.compile(r"fleet (\S+) at (\S+); attach a ground station with: skymesh view --fleet (\S+) --connect (\S+)")


def _stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


@pytest.mark.slow  # a live run: router, world, two agents
def test_skymesh_view_attaches_with_the_printed_line_to_a_router_from_a_file(tmp_path):
    port = free_port()
    config = tmp_path / "router.json5"
    config.write_text(f'{{ mode: "router", listen: {{ endpoints: ["tcp/0.0.0.0:{port}"] }},\n'
                      '  scouting: { multicast: { enabled: false } } }\n')
    run = subprocess.Popen([sys.executable, "-m", "mesh_sim", "run", "--agents", "2", "--duration", "30", "--rerun",
                            "off", "--zenoh-config", str(config), "--out", str(tmp_path / "runs")],
                           cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    view = None
    try:
        line = run.stdout.readline()
        found = ATTACH.search(line)
        assert found, line
        fleet, endpoint = found.group(3), found.group(4)
        assert (fleet, endpoint) == found.group(1, 2) and endpoint == f"tcp/127.0.0.1:{port}"
        assert fleet.startswith("default-")
        view = subprocess.Popen([sys.executable, "-m", "mesh_sim", "view", "--fleet", fleet, "--connect", endpoint,
                                 "--save", str(tmp_path / "view.rrd")],
                                cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 240
        while run.poll() is None and time.monotonic() < deadline:
            time.sleep(0.5)
        _stop(view)
        logged = re.search(r"observer: (\d+) messages logged", view.stderr.read())
        assert view.returncode == 0 and logged and int(logged.group(1)) > 100, logged
        assert (tmp_path / "view.rrd").stat().st_size > 10_000
        assert run.wait(timeout=60) == 0
    finally:
        _stop(run)
        if view is not None:
            _stop(view)


@pytest.mark.parametrize(("text", "error"), [
    ("{ mode: ", "cannot read Zenoh config {path}: "),
    ('{ mode: "client", connect: { endpoints: ["tcp/127.0.0.1:7447"] } }',
     "{path}: mode is 'client': skymesh run opens a router (mode: \"router\")"),
    ('{ mode: "router" }', "{path}: listen/endpoints must list where the run's router listens, "
                           'e.g. ["tcp/0.0.0.0:7447"]; got {{"router": ["tcp/[::]:7447"], "peer": ["tcp/[::]:0"]}}'),
])
def test_a_bad_zenoh_config_is_one_line_naming_the_file_and_no_folder(tmp_path, capsys, text, error):
    path = tmp_path / "router.json5"
    path.write_text(text)
    code = cli.main(["run", "--agents", "1", "--duration", "1", "--rerun", "off", "--zenoh-config", str(path),
                     "--out", str(tmp_path / "runs")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and err.startswith("skymesh run: " + error.format(path=path))
    assert not (tmp_path / "runs").exists() or list((tmp_path / "runs").iterdir()) == []


def test_an_unspecified_listen_address_is_dialled_on_loopback():
    assert local_endpoint("tcp/0.0.0.0:7447") == "tcp/127.0.0.1:7447"
    assert local_endpoint("tcp/[::]:7447") == "tcp/[::1]:7447"
    assert local_endpoint("udp/192.168.1.2:7447") == "udp/192.168.1.2:7447"
    with pytest.raises(ValueError, match="listen endpoint 'tcp7447' is not PROTOCOL/HOST:PORT"):
        local_endpoint("tcp7447")
