"""Viewing that works (issue 18, item 1): the viewer of this environment is found without activating it, a machine
without a display or without a viewer is one line and exit code 2 (never a traceback), and a helper process that
fails says why and where its log is. Each test names the bad input it gives."""

from __future__ import annotations

import io
import os
import subprocess
import sys
from pathlib import Path

import pytest
from rich.console import Console

from mesh_sim import cli, viewer
from mesh_sim.child_logs import last_meaningful_line
from mesh_sim.launcher import Child, Launcher
from mesh_sim.observer import main as observer_main
from mesh_sim.scenario import load

REPO = Path(__file__).resolve().parents[2]
RERUN_TRACEBACK = """\x1b[2m2026-11-27T11:01:34Z\x1b[0m INFO re_sdk: Telemetry initialized
Traceback (most recent call last):
  File "/x/mesh_sim/observer.py", line 116, in spawn
    rr.spawn(port=port, connect=False)
RuntimeError: Failed to find Rerun Viewer executable in PATH.

    You can install an appropriate version of the Rerun Viewer via binary releases:
    * Using `pip`: `pip3 install rerun-sdk==0.41.0`
PATH="/usr/bin:/bin"
"""


@pytest.fixture
def no_viewer(tmp_path, monkeypatch):
    """Bad environment: a Python with no ``rerun`` beside it, and a PATH holding none."""
    (tmp_path / "bin").mkdir()
    monkeypatch.setattr(sys, "executable", str(tmp_path / "bin" / "python"))
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    monkeypatch.setenv("DISPLAY", ":0")
    return tmp_path / "bin"


def test_the_viewer_beside_this_python_is_found_without_it_on_path(monkeypatch):
    """Bad input: PATH without this environment's bin folder (a fresh shell, the environment not activated)."""
    monkeypatch.setenv("PATH", "/usr/bin:/bin")
    found = viewer.viewer_executable()
    assert found == str(Path(sys.executable).parent / viewer.VIEWER) and os.access(found, os.X_OK)


def test_no_viewer_anywhere_is_a_viewer_error_naming_where_it_looked(no_viewer):
    with pytest.raises(viewer.ViewerError, match=f"no Rerun viewer: neither {no_viewer / 'rerun'} nor `rerun` on PATH"):
        viewer.viewer_executable()


@pytest.mark.parametrize("env", [{}, {"DISPLAY": ""}])
def test_no_display_on_linux_is_a_viewer_error(env):
    """Bad input: neither DISPLAY nor WAYLAND_DISPLAY set (and DISPLAY set but empty)."""
    with pytest.raises(viewer.ViewerError, match="no display for the Rerun viewer"):
        viewer.require_display(env, platform="linux")
    viewer.require_display(env, platform="darwin")  # macOS and Windows need no X11 / Wayland variable
    viewer.require_display({"WAYLAND_DISPLAY": "wayland-0"}, platform="linux")


def test_children_get_this_environment_first_on_path():
    env = viewer.with_this_environment_on_path({"PATH": "/usr/bin:/bin", "HOME": "/root"})
    assert env["PATH"].split(os.pathsep) == [str(Path(sys.executable).parent), "/usr/bin", "/bin"]
    assert env["HOME"] == "/root"
    assert viewer.with_this_environment_on_path({})["PATH"] == str(Path(sys.executable).parent)


def test_the_launchers_children_get_this_environment_first_on_path(tmp_path, monkeypatch):
    """Bad input: the launcher started from a shell whose PATH lacks the environment (not activated)."""
    monkeypatch.setenv("PATH", "/usr/bin:/bin")
    launcher = Launcher(load("default", agents=1), tmp_path, rerun="off", console=Console(file=io.StringIO()))
    assert launcher.env["PATH"] == os.pathsep.join([str(Path(sys.executable).parent), "/usr/bin", "/bin"])


def test_skymesh_view_without_a_display_is_one_line_exit_2_before_zenoh(capsys, monkeypatch):
    """Bad input: ``skymesh view`` (a live viewer) with DISPLAY and WAYLAND_DISPLAY unset; the router endpoint is
    dead too, but the display is what is said (checked first, and no gRPC flush traceback hides it)."""
    for name in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setattr(sys, "platform", "linux")
    code = cli.main(["view", "--fleet", "f", "--connect", "tcp/127.0.0.1:9"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith("observer: no display for the Rerun viewer")


def test_skymesh_view_without_a_viewer_is_one_line_exit_2(no_viewer, capsys):
    """Bad input: ``skymesh view`` with no ``rerun`` beside the Python nor on PATH."""
    code = observer_main(["--fleet", "f", "--connect", "tcp/127.0.0.1:9", "--spawn"])
    err = capsys.readouterr().err
    assert code == 2 and err == f"observer: no Rerun viewer: neither {no_viewer / 'rerun'} nor `rerun` on PATH " \
                                "(install rerun-sdk into this environment)\n"


def test_skymesh_run_rerun_spawn_without_a_display_is_one_line_exit_2_and_no_folder(tmp_path, capsys, monkeypatch):
    """Bad input: ``skymesh run --rerun spawn`` with DISPLAY and WAYLAND_DISPLAY unset: refused before any process
    starts, no run folder left."""
    for name in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setattr(sys, "platform", "linux")
    code = cli.main(["run", "--rerun", "spawn", "--agents", "1", "--duration", "1", "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("skymesh run: no display for the Rerun viewer") and err.count("\n") == 1
    assert list(tmp_path.iterdir()) == []


def test_the_meaningful_line_of_a_traceback_is_its_exception(tmp_path):
    log = tmp_path / "observer.log"
    log.write_text(RERUN_TRACEBACK)
    assert last_meaningful_line(log) == "RuntimeError: Failed to find Rerun Viewer executable in PATH."
    log.write_text("INFO starting\nagent uav0: the Zenoh router could not be reached (Unable to connect)\n\n")
    assert last_meaningful_line(log) == "agent uav0: the Zenoh router could not be reached (Unable to connect)"
    log.write_text("")
    assert last_meaningful_line(log) is None
    assert last_meaningful_line(tmp_path / "missing.log") is None


def _failed_child(tmp_path: Path, name: str, role: str) -> Child:
    """A real process that fails with a traceback, its output in its log, as the launcher starts children."""
    log_path = tmp_path / f"{name}.log"
    with open(log_path, "wb") as log:
        proc = subprocess.Popen([sys.executable, "-c", "raise RuntimeError('Failed to find Rerun Viewer executable')"],
                                stdout=log, stderr=subprocess.STDOUT)
    proc.wait(timeout=60)
    return Child(name, role, proc, log_path, 0.0)


def test_a_helper_that_dies_is_printed_with_its_cause_and_log(tmp_path):
    """Bad input: an observer process that exits with a traceback while the run goes on."""
    out = io.StringIO()
    launcher = Launcher(load("default", agents=1), tmp_path, rerun="off", console=Console(file=out, width=400))
    child = _failed_child(tmp_path, "observer", "observer")
    launcher._record_death(child, child.process.returncode, 3.0)
    printed = " ".join(out.getvalue().split())
    assert (f"observer (pid {child.process.pid}) died at t = 3.0 s (exit code 1): RuntimeError: Failed to find Rerun "
            f"Viewer executable (log: {child.log_path}); the run goes on") in printed


def test_a_helper_that_fails_at_start_fails_the_run_with_its_cause_and_log(tmp_path):
    """Bad input: a world process that exits with a traceback before it is ready."""
    launcher = Launcher(load("default", agents=1), tmp_path, rerun="off", console=Console(file=io.StringIO()))
    child = _failed_child(tmp_path, "world", "world")
    launcher.children.append(child)
    assert launcher._release() == (f"failed: world (pid {child.process.pid}) exited with code 1: RuntimeError: "
                                   f"Failed to find Rerun Viewer executable (log: {child.log_path})")
