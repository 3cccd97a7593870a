"""``skymesh view --web`` (issue 18, item 1): Rerun's web viewer served for a recording and for a live fleet,
the one URL line a browser opens, serving until SIGINT/SIGTERM, a bad port or recording as one line and exit
code 2, and (where Chromium is installed) the 3D view drawn in a headless browser."""

from __future__ import annotations

import signal
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path
from urllib.parse import parse_qs, urlsplit

import numpy as np
import pytest
import rerun as rr
import rerun.blueprint as rrb

from mesh_sim import cli
from mesh_sim.launcher import free_port
from mesh_sim.observer import TRUTH_COLOUR
from mesh_sim.observer import main as observer_main
from mesh_sim.observer_web import network_host, recording_of
from tests.headless_chromium import Chromium, find_chromium

REPO = Path(__file__).resolve().parents[2]
PREFIX = "web viewer: "
RENDER_TIMEOUT_S = 150.0  # the viewer drew its 3D view 16-20 s after the page opened, on a loaded 2-core machine


def start_view(*args: str) -> tuple[subprocess.Popen, str]:
    """``python -m mesh_sim view ARGS`` in the background; the process and the URL it prints (its first line)."""
    proc = subprocess.Popen([sys.executable, "-m", "mesh_sim", "view", *args], cwd=REPO, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    line = proc.stdout.readline()
    if not line.startswith(PREFIX):
        stop(proc)
        pytest.fail(f"no URL printed: {line!r}; stderr: {proc.stderr.read()}")
    return proc, line[len(PREFIX):].strip()


def stop(proc: subprocess.Popen, signum: int = signal.SIGTERM) -> int:
    """Send ``signum`` to ``proc`` (by its pid) and return its exit code; killed if it lingers."""
    proc.send_signal(signum)
    try:
        return proc.wait(timeout=20)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
        raise
    finally:
        proc.stdout.close()
        proc.stderr.close()


def web_args(web_port: int, grpc_port: int, host: str | None = "127.0.0.1") -> list[str]:
    return ["--web", str(web_port), "--grpc-port", str(grpc_port), *(["--web-host", host] if host else [])]


def fetch(url: str) -> tuple[int, str, bytes]:
    with urllib.request.urlopen(url, timeout=30) as reply:
        return reply.status, reply.headers.get("Content-Type", ""), reply.read()


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    """The recording of a short lockstep run, as a user makes one."""
    out = tmp_path_factory.mktemp("runs")
    subprocess.run([sys.executable, "-m", "mesh_sim", "run", "--lockstep", "--duration", "6", "--rerun", "save",
                    "--out", str(out)], cwd=REPO, check=True, capture_output=True, timeout=240)
    (found,) = out.glob("*/recording.rrd")
    return found


@pytest.fixture(scope="module")
def served(recording):
    """``skymesh view --web --recording`` on free ports; yields (url, web port, gRPC port)."""
    web_port, grpc_port = free_port(), free_port()
    proc, url = start_view(*web_args(web_port, grpc_port), "--recording", str(recording))
    try:
        yield url, web_port, grpc_port
    finally:
        stop(proc)


@pytest.mark.slow
def test_the_printed_url_is_the_page_reading_the_served_data(served):
    url, web_port, grpc_port = served
    parts = urlsplit(url)
    assert (parts.scheme, parts.netloc, parts.path) == ("http", f"127.0.0.1:{web_port}", "/")
    assert parse_qs(parts.query) == {"url": [f"rerun+http://127.0.0.1:{grpc_port}/proxy"]}
    socket.create_connection(("127.0.0.1", grpc_port), timeout=5).close()  # the data's server listens


@pytest.mark.slow
def test_the_page_is_rerun_s_web_viewer_with_its_wasm(served):
    url, web_port, _ = served
    status, kind, page = fetch(url)
    assert status == 200 and kind.startswith("text/html")
    assert b"<title>Rerun Viewer</title>" in page and b"re_viewer_bg.wasm" in page
    status, kind, wasm = fetch(f"http://127.0.0.1:{web_port}/re_viewer_bg.wasm")
    assert status == 200 and kind == "application/wasm" and wasm[:4] == b"\0asm"


def allowed_origin(grpc_port: int, origin: str) -> str | None:
    """The origin the data server allows in its answer to a browser's CORS preflight from ``origin``."""
    ask = urllib.request.Request(f"http://127.0.0.1:{grpc_port}/rerun.sdk_comms.v1alpha1.MessageProxyService/"
                                 "ReadMessages", method="OPTIONS",
                                 headers={"Origin": origin, "Access-Control-Request-Method": "POST",
                                          "Access-Control-Request-Headers": "content-type,x-grpc-web"})
    with urllib.request.urlopen(ask, timeout=10) as reply:
        return reply.headers.get("Access-Control-Allow-Origin")


@pytest.mark.slow
def test_the_data_server_lets_the_printed_page_read_it_across_the_network(recording):
    """Rerun's gRPC server answers only pages of localhost by default: a browser on another machine, on the
    page at the printed (network) address, would get no data (seen in Chromium: the welcome screen)."""
    web_port, grpc_port = free_port(), free_port()
    proc, url = start_view(*web_args(web_port, grpc_port, "groundstation.example"), "--recording", str(recording))
    try:
        assert url.startswith(f"http://groundstation.example:{web_port}/?url=rerun%2Bhttp%3A%2F%2Fgroundstation")
        page = f"http://groundstation.example:{web_port}"
        assert allowed_origin(grpc_port, page) == page
        assert allowed_origin(grpc_port, "http://groundstation.example:1") is None  # another page: refused
    finally:
        stop(proc)


def test_the_network_host_is_an_address_of_this_machine():
    with socket.socket() as s:
        s.bind((network_host(), 0))  # only this machine's own addresses can be bound


@pytest.mark.slow
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_it_serves_until_ctrl_c_or_sigterm_then_exits_0(recording, signum):
    web_port = free_port()
    proc, url = start_view(*web_args(web_port, free_port()), "--recording", str(recording))
    time.sleep(1.0)
    assert proc.poll() is None and fetch(url)[0] == 200  # still serving
    assert stop(proc, signum) == 0
    with pytest.raises(OSError):
        fetch(url)


@pytest.mark.slow
def test_a_live_fleet_is_served_until_sigterm(zenoh_router):
    web_port, grpc_port = free_port(), free_port()
    proc, url = start_view("--fleet", "webtest", "--connect", zenoh_router, *web_args(web_port, grpc_port))
    try:
        assert parse_qs(urlsplit(url).query) == {"url": [f"rerun+http://127.0.0.1:{grpc_port}/proxy"]}
        status, _, page = fetch(url)
        assert status == 200 and b"<title>Rerun Viewer</title>" in page
    finally:
        assert stop(proc) == 0


# -- bad input: one line, exit code 2 ---------------------------------------------------------------------------
@pytest.fixture
def taken_port():
    """Bad input: a port another process listens on."""
    with socket.socket() as s:
        s.bind(("0.0.0.0", 0))
        s.listen()
        yield s.getsockname()[1]


def one_line_exit_2(capsys, argv: list[str], main=cli.main) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    return err


def test_a_web_port_in_use_is_one_line_exit_2(recording_stub, taken_port, capsys):
    err = one_line_exit_2(capsys, ["view", *web_args(taken_port, free_port()), "--recording", str(recording_stub)])
    assert err == f"skymesh view: cannot serve the web viewer on port {taken_port}: Address already in use\n"


def test_a_grpc_port_in_use_is_one_line_exit_2(recording_stub, taken_port, capsys):
    err = one_line_exit_2(capsys, ["view", *web_args(free_port(), taken_port), "--recording", str(recording_stub)])
    assert err == f"skymesh view: cannot serve the web viewer's data (gRPC) on port {taken_port}: " \
                  "Address already in use\n"


def test_a_port_in_use_for_a_live_fleet_is_one_line_exit_2(zenoh_router, taken_port, capsys):
    err = one_line_exit_2(capsys, ["--fleet", "webtest", "--connect", zenoh_router, "--web", str(taken_port)],
                          main=observer_main)
    assert err == f"observer: cannot serve the web viewer on port {taken_port}: Address already in use\n"


@pytest.fixture
def recording_stub(tmp_path) -> Path:
    """A small recording made here: one point."""
    path = tmp_path / "recording.rrd"
    rec = rr.RecordingStream("skymesh", recording_id="stub")
    rec.save(str(path))
    rec.log("world/point", rr.Points3D([[0.0, 0.0, 0.0]]))
    rec.disconnect()
    return path


def test_the_stored_recording_id_is_read_so_the_served_recording_is_the_stored_one(recording_stub):
    stored = recording_of(recording_stub)
    assert (stored.application_id, stored.recording_id) == ("skymesh", "stub")


@pytest.mark.parametrize("name, reason", [
    ("missing.rrd", "No such file or directory"),
    (".", "Is a directory"),
    ("notes.txt", 'not a Rerun recording (expected FourCC header "RRF2", got "hell")'),
    ("layout.rbl", "holds no Rerun recording (only a layout)"),
])
def test_a_missing_or_unreadable_recording_is_one_line_exit_2(tmp_path, capsys, name, reason):
    """Bad input: a recording that does not exist, a folder, a file that is not an .rrd, an .rrd-format file
    holding only a blueprint."""
    (tmp_path / "notes.txt").write_text("hello, these are notes\n" * 10)
    rrb.Blueprint(rrb.Spatial3DView()).save("skymesh", str(tmp_path / "layout.rbl"))
    path = tmp_path / name
    err = one_line_exit_2(capsys, ["view", *web_args(free_port(), free_port()), "--recording", str(path)])
    assert err == f"skymesh view: {path}: {reason}\n"


@pytest.mark.parametrize("argv, says", [
    (["view"], "give --fleet NAME (a live fleet) or --web --recording FILE"),
    (["view", "--recording", "r.rrd"], "--recording is served with --web"),
    (["view", "--web", "--recording", "r.rrd", "--fleet", "f"], "--recording serves a file: give it without"),
])
def test_view_without_what_to_view_is_one_line_exit_2(capsys, argv, says):
    assert says in one_line_exit_2(capsys, argv)


@pytest.mark.parametrize("flag, value", [("--web", "0"), ("--web", "70000"), ("--grpc-port", "x")])
def test_a_port_that_is_no_tcp_port_is_refused_exit_2(capsys, flag, value):
    with pytest.raises(SystemExit) as stopped:
        cli.main(["view", "--web", "9090", "--recording", "r.rrd", flag, value])
    assert stopped.value.code == 2
    assert f"{flag}: must be a TCP port, 1..65535; got {value!r}" in capsys.readouterr().err


@pytest.mark.parametrize("flag", [["--save", "x.rrd"], ["--connect-viewer", "rerun+http://127.0.0.1:1/proxy"],
                                  ["--spawn"]])
def test_web_with_another_sink_is_one_line_exit_2(capsys, flag):
    err = one_line_exit_2(capsys, ["--fleet", "f", "--web", *flag], main=observer_main)
    assert "--web serves the recording itself" in err


# -- in a browser -------------------------------------------------------------------------------------------------
def world(shot: np.ndarray) -> np.ndarray:
    """The 3D world view of a screenshot of the viewer (the blueprint puts it top left, 3/5 wide and high, under
    the 44-pixel top bar), as ints."""
    h, w, _ = shot.shape
    return shot[int(0.06 * h):int(0.6 * h), :int(0.6 * w)].astype(int)


def truth_pixels(shot: np.ndarray) -> int:
    """Pixels of the truth targets' colour in the 3D world view."""
    return int((np.abs(world(shot) - TRUTH_COLOUR).max(axis=2) < 60).sum())


def changed(shot: np.ndarray, blank: np.ndarray) -> float:
    """The share of the 3D world view's pixels that differ from ``blank`` (a screenshot of about:blank)."""
    return float((world(shot) != world(blank)).any(axis=2).mean())


@pytest.fixture(scope="module")
def chromium() -> str:
    """Chromium's executable; the test is skipped (before the recording is made) on a machine without one."""
    executable = find_chromium()
    if executable is None:
        pytest.skip("no Chromium on this machine (Debian: apt-get install chromium)")
    return executable


@pytest.mark.slow
def test_the_3d_view_renders_in_headless_chromium(chromium, recording):
    """The page at the printed URL (this machine's network address, as a browser elsewhere opens it), drawn by a
    real browser, is not blank: its 3D view differs from about:blank (measured: 27 % of its pixels once drawn;
    2.6 % on the viewer's empty light screen) and shows the truth targets in their colour (215 pixels once
    drawn, none on the loading screen, the welcome screen or the empty one)."""
    proc, url = start_view(*web_args(free_port(), free_port(), host=None), "--recording", str(recording))
    try:
        with Chromium(chromium) as browser:
            blank = browser.screenshot(browser.open("about:blank"))
            tab = browser.open(url)
            start = time.monotonic()
            shot = browser.screenshot(tab)
            assert truth_pixels(shot) == 0  # the (dark) loading screen has none of the targets' colour
            while not (truth_pixels(shot) >= 50 and changed(shot, blank) > 0.1) \
                    and time.monotonic() - start < RENDER_TIMEOUT_S:
                time.sleep(2.0)
                shot = browser.screenshot(tab)
            print(f"3D view drawn after {time.monotonic() - start:.1f} s: {truth_pixels(shot)} target pixels, "
                  f"{changed(shot, blank):.0%} of the view changed ({url})")
    finally:
        stop(proc)
    assert shot.shape == blank.shape
    assert changed(shot, blank) > 0.1
    assert truth_pixels(shot) >= 50
