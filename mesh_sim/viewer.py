"""The Rerun viewer of this Python environment, and whether it can open a window here.

``pip install rerun-sdk`` puts the viewer executable ``rerun`` beside the environment's Python (``.venv/bin/``),
which is not on ``PATH`` unless the environment is activated; rerun-sdk itself looks only on ``PATH``
(``Failed to find Rerun Viewer executable in PATH``). So the viewer is looked for beside :data:`sys.executable`
first, then on ``PATH``, and every child ``skymesh run`` starts gets this environment's folder first on its
``PATH`` (:func:`with_this_environment_on_path`). On Linux the viewer needs an X11 or Wayland display: without one
it dies at start and the gRPC sink streaming to it fails later with a traceback that hides why, so that is checked
before the viewer is started.

No Rerun import here (the observer is the one module that imports it).
"""

from __future__ import annotations

import os
import shutil
import sys
from collections.abc import Mapping
from pathlib import Path

VIEWER = "rerun.exe" if sys.platform == "win32" else "rerun"


class ViewerError(OSError):
    """The Rerun viewer cannot be started here (not installed, or no display): a bad environment, one line."""


def environment_bin() -> Path:
    """The folder of this environment's executables: the one holding :data:`sys.executable`."""
    return Path(sys.executable).parent


def viewer_executable(env: Mapping[str, str] = os.environ) -> str:
    """The ``rerun`` beside this Python, else the one on ``env``'s ``PATH``; :class:`ViewerError` if neither."""
    beside = environment_bin() / VIEWER
    if beside.is_file() and os.access(beside, os.X_OK):
        return str(beside)
    found = shutil.which(VIEWER, path=env.get("PATH", ""))
    if found is None:
        raise ViewerError(f"no Rerun viewer: neither {beside} nor `{VIEWER}` on PATH "
                          "(install rerun-sdk into this environment)")
    return found


def require_display(env: Mapping[str, str] = os.environ, platform: str = sys.platform) -> None:
    """:class:`ViewerError` on Linux when neither X11 (``DISPLAY``) nor Wayland (``WAYLAND_DISPLAY``,
    ``WAYLAND_SOCKET``) is available: the viewer's window could not open."""
    if platform.startswith("linux") and not any(env.get(k) for k in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET")):
        raise ViewerError("no display for the Rerun viewer (DISPLAY and WAYLAND_DISPLAY are unset): save the "
                          "recording instead (skymesh run --rerun save, skymesh view --save FILE) and open it where "
                          "there is a display, or stream it to a viewer elsewhere (--connect-viewer URL)")


def viewer_to_spawn(env: Mapping[str, str] = os.environ) -> str:
    """The viewer executable to start, once it is known that it can open its window (:class:`ViewerError`
    otherwise: the display is checked first, as it is what a headless machine lacks)."""
    require_display(env)
    return viewer_executable(env)


def with_this_environment_on_path(env: Mapping[str, str]) -> dict[str, str]:
    """``env`` with this environment's executables (:func:`environment_bin`) first on ``PATH``: a child finds
    this environment's ``rerun`` (and any other tool it installed) without activating it."""
    rest = env.get("PATH", "")
    return {**env, "PATH": os.pathsep.join([str(environment_bin()), *([rest] if rest else [])])}
