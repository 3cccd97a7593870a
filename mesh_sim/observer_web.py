"""Rerun's web viewer served from the ground station (``skymesh view --web [PORT]``), for a browser on its network.

Two servers make it: the recording's own gRPC server (``RecordingStream.serve_grpc``: it keeps everything logged,
so a browser that opens late still gets the whole run) and an HTTP server of the viewer's page and wasm
(``rr.serve_web_viewer``). The page is told where the data is by its ``?url=`` query, so the one line printed
is the address to open. Both servers listen on every interface, and the address printed is this machine's on
its network (:func:`network_host`), not loopback, as the browser is usually on another machine; the gRPC server
only answers pages of localhost and of that printed origin (CORS), so it is allowed explicitly.

A recording (``--recording RUN/recording.rrd``) is served the same way: the file is loaded into a recording
stream of the file's own application and recording id (so the viewer lists one recording, not the file's and an
empty one) whose gRPC server the page reads; a live fleet and a finished run look and behave alike.

Ports are checked before serving: rerun-sdk only logs a gRPC port in use and goes on serving nothing, so a
port in use is a :class:`~mesh_sim.viewer.ViewerError` here (one line, exit code 2), as is a recording that is
missing, unreadable or not an .rrd.
"""

from __future__ import annotations

import signal
import socket
import threading
from pathlib import Path
from urllib.parse import quote

import rerun as rr
from rerun.chunk import RrdReader, StoreEntry

from mesh_sim.viewer import ViewerError
from mesh_sim.web_options import Web

PROBE_ADDRESS = ("192.0.2.1", 9)  # TEST-NET-1: a UDP "connect" to it only picks the outgoing interface; nothing is sent


def network_host() -> str:
    """This machine's address on its network (the interface of its default route), else ``127.0.0.1``."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.connect(PROBE_ADDRESS)
            return s.getsockname()[0]
        except OSError:  # no route at all: only this machine can open the page
            return "127.0.0.1"


def require_free_port(port: int, what: str) -> None:
    """:class:`ViewerError` unless a TCP server could listen on ``port`` on every interface (as rerun's do)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as rerun's servers: a TIME_WAIT port is free
        try:
            s.bind(("0.0.0.0", port))
        except OSError as err:
            raise ViewerError(f"cannot serve the {what} on port {port}: {err.strerror}") from None


def recording_of(path: Path) -> StoreEntry:
    """The (first) recording stored in the .rrd at ``path``: its application and recording id. A
    :class:`ViewerError` if the file cannot be read or holds no Rerun recording."""
    try:
        open(path, "rb").close()  # the OS's own words for a missing or unreadable file
    except OSError as err:
        raise ViewerError(f"{path}: {err.strerror}") from None
    try:
        stores = RrdReader(str(path)).recordings()
    except RuntimeError as err:  # "Not an RRD file: expected FourCC header ..."
        raise ViewerError(f"{path}: not a Rerun recording ({str(err).rsplit(': ', 1)[-1]})") from None
    if not stores:
        raise ViewerError(f"{path}: holds no Rerun recording (only a layout)")
    return stores[0]


def serve_web(rec: rr.RecordingStream, web: Web) -> str:
    """Serve ``rec`` over gRPC and the web viewer over HTTP, on ``web``'s ports; the URL a browser opens.

    Replaces ``rec``'s sinks (it streams to its own server from now on). Both servers live as long as this
    process and ``rec``."""
    host = web.host or network_host()
    require_free_port(web.port, "web viewer")
    require_free_port(web.grpc_port, "web viewer's data (gRPC)")
    origin = f"http://{host}:{web.port}"
    data = rec.serve_grpc(grpc_port=web.grpc_port, cors_allow_origin=[origin]).replace("127.0.0.1", host, 1)
    try:
        rr.serve_web_viewer(web_port=web.port, open_browser=False, connect_to=data)
    except RuntimeError as err:  # taken between the check and now
        raise ViewerError(f"cannot serve the web viewer on port {web.port}: {' '.join(str(err).split())}") from None
    return f"{origin}/?url={quote(data, safe='')}"


def serve_recording(path: Path, web: Web) -> tuple[rr.RecordingStream, str]:
    """Serve the .rrd at ``path`` to browsers (:func:`serve_web`); the recording holding the servers, and the URL."""
    stored = recording_of(path)
    rec = rr.RecordingStream(stored.application_id, recording_id=stored.recording_id)
    url = serve_web(rec, web)
    rec.log_file_from_path(path)
    return rec, url


def wait_for_stop() -> None:
    """Block until SIGINT (Ctrl-C) or SIGTERM; the previous handlers are restored after."""
    stopped = threading.Event()
    previous = {s: signal.signal(s, lambda signum, frame: stopped.set()) for s in (signal.SIGTERM, signal.SIGINT)}
    try:
        while not stopped.wait(0.2):
            pass
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


def serve_recording_until_stopped(path: Path, web: Web) -> None:
    """``skymesh view --web --recording FILE``: serve it, print the URL to open (one line), serve until stopped."""
    rec, url = serve_recording(path, web)
    print(f"web viewer: {url}", flush=True)
    wait_for_stop()
    rec.disconnect()
