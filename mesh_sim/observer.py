"""The ground station: one process that watches a fleet on Zenoh and does all the Rerun logging (DESIGN.md §7).

Agents stay light (no Rerun in them); the observer subscribes to ``telemetry/*``, ``belief/**`` and
``sim/truth`` of one fleet, validates every message exactly as an agent would (``agent.net.wire.decode``
plus payload checks; rejects are counted by reason, logged once per (peer, reason), never raised), and
logs one recording. The same observer works against a real fleet: it only needs a Zenoh endpoint.

What is logged, on the ``sim_time`` timeline (a duration, from each envelope's stamp), in NED
(``world`` carries a static ``RIGHT_HAND_Z_DOWN`` view coordinate: x north, y east, z down)::

    world/truth                    Points3D      truth targets, labelled by id ("car")
    world/uav/<id>                 Points3D      each UAV's position
    world/uav/<id>/path            LineStrips3D  its last PATH_POINTS positions
    world/agents/<id>/tracks       Ellipsoids3D  2-sigma position ellipsoids of the agent's tracks, labelled with the
                                                 true target nearest in Mahalanobis distance within the evaluator's
                                                 gate ("uav1:T1→car"; labels shown on hover, so that they never
                                                 pile up over a target every agent tracks)
    world/agents/<id>/rays         LineStrips3D  bearing rays from the UAV (RAY_LENGTH m or to z=0 ground)
    world/agents/<id>/particles    Points3D      particles of the agent's track candidates (initiation = particles)
    world/links                    LineStrips3D  agent-neighbour links: green if both ends report the link,
                                                 orange if only one does
    maps/<id>                      Image         the agent's fire map (cell probability), north up
    maps/truth                     Image         the true fire: unburnt / burning / burnt cells
    maps/legend                    TextDocument  what the maps' colours mean
    metrics/tracks/<id>            Scalars       number of tracks the agent reports, from its first report of one
    metrics/bytes_rx/<id>          Scalars       the agent's own received-bytes count, if its telemetry has one
    metrics/video_quality/<id>     Scalars       the camera's video-quality measure D(t), if its telemetry has one
    metrics/bytes_seen/<id>        Scalars       bytes the observer has received from the agent (all kinds)

One line per agent in one panel per metric: each ``metrics/<metric>/<id>`` is named after its agent in its colour
(``SeriesLines``). The layout (:func:`mesh_sim.observer_blueprint.fleet_blueprint`) is sent again whenever it
grows: a new agent, a first fire map, a metric first seen. After a run, :mod:`mesh_sim.observer_series` adds the
run's error, NEES and traffic series, compacts the recording and sends the final layout.

Run as a process (the launcher stops it with SIGTERM; it also exits when its parent dies)::

    python -m mesh_sim.observer --fleet F --connect tcp/127.0.0.1:7447 --save run.rrd [--duration S]
    python -m mesh_sim.observer --fleet F --zenoh-config robot.json5 --connect-viewer rerun+http://host:9876/proxy

``--parent-pid PID`` makes it exit when PID is no longer its parent (default: its parent at start).

``--web [PORT]`` serves Rerun's web viewer and the recording to browsers instead of the other sinks, and prints
the URL to open (:mod:`mesh_sim.observer_web`; ``--grpc-port``, ``--web-host``).

``--spawn`` starts this environment's Rerun viewer (``mesh_sim.viewer``: the ``rerun`` beside the Python running
this, else on ``PATH``); no viewer or no display is one line and exit code 2 before anything starts.

Rerun is imported in the ``observer*`` modules and nowhere else in the project.
"""

from __future__ import annotations

import argparse
import logging
import os
import signal
import sys
import threading
import time
from collections import Counter, deque
from collections.abc import Sequence

import numpy as np
import rerun as rr

from agent.net import wire
from agent.net.fleet_key import read_key_file
from agent.net.keys import Incoming, Keys
from agent.net.zenoh_transport import ZenohTransport, load_config
from agent.runtime import usage_error
from mesh_sim.observer_blueprint import LIVE_METRICS, MAPS_LEGEND, PALETTE, fleet_blueprint
from mesh_sim.observer_geometry import RAY_LENGTH, cov_to_ellipsoid, nearest_truth, ray_end
from mesh_sim.observer_grids import LEGEND, GridImages
from mesh_sim.observer_messages import parse_telemetry, parse_truth
from mesh_sim.observer_web import serve_web
from mesh_sim.run_series import pair_states
from mesh_sim.viewer import viewer_to_spawn
from mesh_sim.web_options import Web, add_web_arguments, web_of

log = logging.getLogger("skymesh.observer")

PATH_POINTS = 500  # positions kept per UAV path (chosen here)
LINK_STALE_S = 5.0  # s of sim time: an agent's neighbour report older than this draws no link (chosen here)
BATCH_SECONDS = 1.0  # Rerun's chunk batcher tick: rows of up to this long share a chunk (default 0.2 s; chosen here)
POLL_S = 0.05  # s between queue drains in the process loop
GREEN = (40, 200, 60)
ORANGE = (255, 150, 0)
TRUTH_COLOUR = (230, 40, 40)


# -- the observer ------------------------------------------------------------------------------------
class Observer:
    """Turns validated fleet messages into one Rerun recording. Not thread-safe: call from one thread."""

    def __init__(self, keys: Keys, recording_id: str, application_id: str = "skymesh", *,
                 fleet_key: bytes | None = None, n_sigma: float = 2.0, path_points: int = PATH_POINTS,
                 ray_length: float = RAY_LENGTH, batch_seconds: float = BATCH_SECONDS):
        self.keys = keys
        self.fleet_key = fleet_key
        self.n_sigma = n_sigma
        self.path_points = path_points
        self.ray_length = ray_length
        self.rec = rr.RecordingStream(application_id, recording_id=recording_id,
                                      batcher_config=rr.ChunkBatcherConfig(flush_tick=batch_seconds))
        self.accepted = 0
        self.rejected: Counter = Counter()  # reason -> messages
        self.bytes_seen: Counter = Counter()  # origin -> bytes of accepted messages
        self._logged: set[tuple[str, str]] = set()
        self._sinks: list = []
        self._last_seq: dict[tuple[str, str], int] = {}
        self._colours: dict[str, tuple[int, int, int]] = {}
        self._paths: dict[str, deque] = {}
        self._positions: dict[str, np.ndarray] = {}
        self._reports: dict[str, tuple[float, set[str]]] = {}  # agent -> (stamp, neighbours it reports)
        self._truth: tuple[list[str], np.ndarray] = ([], np.zeros((0, 3)))  # the latest true targets
        self._series: set[str] = set()  # metric entities whose line is named and coloured
        self._live: set[str] = set()  # the LIVE_METRICS with a line, kept as lines are named (not per message)
        self._layout: tuple = ()  # what the last blueprint was made for: (agents, metrics, maps)
        self._maps = False  # whether a fire map was logged
        self.grids = GridImages()
        self.rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_DOWN, static=True)

    # sinks ------------------------------------------------------------------------------------------
    def save(self, path) -> None:
        """Also write the recording to an .rrd file (what was logged before is included)."""
        self._add_sink(rr.FileSink(str(path)))

    def connect(self, url: str = "rerun+http://127.0.0.1:9876/proxy") -> None:
        """Also stream to a Rerun viewer or proxy over gRPC (``rerun+http://host:port/proxy``)."""
        self._add_sink(rr.GrpcSink(url))

    def spawn(self, port: int = 9876) -> None:
        """Start this environment's Rerun viewer (:func:`mesh_sim.viewer.viewer_to_spawn`) and stream to it; a
        :class:`~mesh_sim.viewer.ViewerError` when there is no viewer or no display."""
        rr.spawn(port=port, connect=False, executable_path=viewer_to_spawn(), recording=self.rec)
        self._add_sink(rr.GrpcSink(f"rerun+http://127.0.0.1:{port}/proxy"))

    def serve_web(self, web: Web) -> str:
        """Serve the recording to browsers (:func:`mesh_sim.observer_web.serve_web`: it replaces the other sinks);
        the URL to open."""
        return serve_web(self.rec, web)

    def _add_sink(self, sink) -> None:
        self._sinks.append(sink)
        self.rec.set_sinks(*self._sinks)

    def close(self) -> None:
        """Flush everything to the sinks and close them (an .rrd is complete, with its footer, after this)."""
        try:
            self.rec.flush(timeout_sec=10.0)
        except RuntimeError as err:  # a viewer closed by its user: the other sinks are flushed, say it in one line
            log.warning("observer: the Rerun viewer went away (%s)", " ".join(str(err).split()))
        finally:
            self.rec.disconnect()

    # input ------------------------------------------------------------------------------------------
    def handle(self, incoming: Incoming) -> bool:
        """Validate one sample and log it. Returns False (and counts the reason) if it was rejected."""
        try:
            parts = self.keys.parse(incoming.key)
        except ValueError:
            return self._reject("?", "bad_key")
        if parts == ("sim", "truth"):
            origin, kind = None, "truth"
        elif len(parts) == 2 and parts[0] == "telemetry":
            origin, kind = parts[1], "telemetry"
        elif len(parts) == 3 and parts[0] == "belief":
            origin, kind = parts[2], parts[1]
        else:
            return self._reject("?", "bad_key")
        peer = origin or "world"
        try:
            wire.check_encoding(incoming.encoding)
            env = wire.decode(incoming.data, expected_origin=origin, key=self.fleet_key, kinds=wire.KINDS | {kind})
        except wire.DecodeError as err:
            return self._reject(peer, err.reason)
        if env.kind != kind:
            return self._reject(peer, "kind_mismatch")
        last = self._last_seq.get((env.origin, env.kind))
        if last is not None and env.seq <= last:
            return self._reject(peer, "duplicate", log_it=False)
        try:
            if kind == "truth":
                parsed = parse_truth(env.payload)
            elif kind == "telemetry":
                parsed = parse_telemetry(env.payload)
            elif kind == "grid":
                parsed = self.grids.agent_image(env.origin, env.seq, env.payload)
            else:
                parsed = None  # beliefs: counted as bandwidth (telemetry carries the marginals we draw)
        except wire.DecodeError as err:
            return self._reject(peer, err.reason)
        self._last_seq[(env.origin, env.kind)] = env.seq
        self.accepted += 1
        self.rec.set_time("sim_time", duration=env.stamp)
        try:
            if kind == "truth":
                self._log_truth(*parsed)
                if "fire" in env.payload:
                    self.rec.log("maps/truth", rr.Image(self.grids.truth_image(env.payload["fire"])))
                    self._maps = True
            else:
                self.bytes_seen[env.origin] += len(incoming.data)
                self._scalar("bytes_seen", env.origin, float(self.bytes_seen[env.origin]))
                if kind == "telemetry":
                    self._log_telemetry(env.origin, env.stamp, parsed)
                elif kind == "grid":
                    self.rec.log(f"maps/{env.origin}", rr.Image(parsed))
                    self._maps = True
            self._update_layout()
        except Exception as err:  # a safety net: the observer never dies on input
            log.warning("observer: could not log a %s from %s: %s", kind, peer, err)
            self.rejected["log_error"] += 1
            return False
        return True

    def _reject(self, peer: str, reason: str, log_it: bool = True) -> bool:
        self.rejected[reason] += 1
        if log_it and (peer, reason) not in self._logged:
            self._logged.add((peer, reason))
            log.warning("observer: rejected a message from %s (%s); further ones are only counted", peer, reason)
        return False

    # logging ----------------------------------------------------------------------------------------
    def _colour(self, agent: str) -> tuple[int, int, int]:
        if agent not in self._colours:
            self._colours[agent] = PALETTE[len(self._colours) % len(PALETTE)]
        return self._colours[agent]

    def _scalar(self, metric: str, agent: str, value: float) -> None:
        """One point of ``metrics/<metric>/<agent>``; the first names the line after the agent, in its colour."""
        path = f"metrics/{metric}/{agent}"
        if path not in self._series:
            self._series.add(path)
            self._live.update(m for m in LIVE_METRICS if path.startswith(f"metrics/{m}/"))
            self.rec.log(path, rr.SeriesLines(colors=[self._colour(agent)], names=[agent]), static=True)
        self.rec.log(path, rr.Scalars(value))

    def _update_layout(self) -> None:
        """Send the blueprint again if the fleet, its metrics or its maps grew since the last one."""
        metrics = [m for m in LIVE_METRICS if m in self._live]
        layout = (tuple(self._colours), tuple(metrics), self._maps)
        if layout != self._layout:
            if self._maps and not (self._layout and self._layout[2]):
                self.rec.log(MAPS_LEGEND, rr.TextDocument(LEGEND, media_type=rr.MediaType.MARKDOWN), static=True)
            self._layout = layout
            self.rec.send_blueprint(fleet_blueprint(list(self._colours), metrics, self._maps))

    def _log_truth(self, ids: list[str], positions: np.ndarray) -> None:
        self._truth = (ids, positions)
        self.rec.log("world/truth", rr.Points3D(positions, radii=1.5, colors=[TRUTH_COLOUR] * len(ids), labels=ids))

    def _log_telemetry(self, agent: str, stamp: float, t: dict) -> None:
        rec, colour, pos = self.rec, self._colour(agent), t["position"]
        rec.log(f"world/uav/{agent}", rr.Points3D([pos], radii=2.0, colors=[colour], labels=[agent]))
        path = self._paths.setdefault(agent, deque(maxlen=self.path_points))
        path.append(pos)
        if len(path) >= 2:
            rec.log(f"world/uav/{agent}/path", rr.LineStrips3D([np.asarray(path)], radii=0.3, colors=[colour]))

        centres, halves, quats, labels = [], [], [], []
        for tid, centre, cov in t["tracks"]:
            half, q = cov_to_ellipsoid(cov, self.n_sigma)
            centres.append(centre)
            halves.append(half)
            quats.append(q)
            name = nearest_truth(*self._truth, centre, cov)
            labels.append(f"{agent}:T{tid}" + ("" if name is None else f"→{name}"))
        rec.log(f"world/agents/{agent}/tracks", rr.Ellipsoids3D(
            centers=np.asarray(centres).reshape(-1, 3), half_sizes=np.asarray(halves).reshape(-1, 3),
            quaternions=np.asarray(quats).reshape(-1, 4), colors=[colour] * len(labels), labels=labels,
            show_labels=False, fill_mode=rr.components.FillMode.MajorWireframe))

        if len(t["particles"]):
            rec.log(f"world/agents/{agent}/particles", rr.Points3D(t["particles"], radii=0.4, colors=[colour]))
        rays = [np.array([pos, ray_end(pos, azel, self.ray_length)]) for azel in t["bearings"]]
        rec.log(f"world/agents/{agent}/rays", rr.LineStrips3D(rays, radii=0.15, colors=[colour] * len(rays)))

        if t["tracks"] or f"metrics/tracks/{agent}" in self._series:  # no panel stuck at 0 in a fire run
            self._scalar("tracks", agent, float(len(t["tracks"])))
        if t["bytes_rx"] is not None:
            self._scalar("bytes_rx", agent, t["bytes_rx"])
        if t.get("video_quality") is not None:
            self._scalar("video_quality", agent, t["video_quality"])

        self._positions[agent] = pos
        self._reports[agent] = (stamp, t["neighbours"] - {agent})
        self._log_links(stamp)

    def link_states(self, now: float) -> dict[tuple[str, str], bool]:
        """``{(a, b): both_ends_report}`` for a < b, from neighbour reports at most LINK_STALE_S old."""
        return pair_states({a: nbrs for a, (stamp, nbrs) in self._reports.items() if now - stamp <= LINK_STALE_S})

    def _log_links(self, now: float) -> None:
        strips, colours = [], []
        for (a, b), both in sorted(self.link_states(now).items()):
            if a in self._positions and b in self._positions:
                strips.append(np.array([self._positions[a], self._positions[b]]))
                colours.append(GREEN if both else ORANGE)
        self.rec.log("world/links", rr.LineStrips3D(strips, radii=0.4, colors=colours))


# -- the process -------------------------------------------------------------------------------------
def run_observer(fleet: str, connect: list[str] | None, zenoh_config: str | None, save: str | None,
                 connect_viewer: str | None, spawn: bool, duration: float | None, *, web: Web | None = None,
                 recording_id: str | None = None, application_id: str = "skymesh",
                 fleet_key: bytes | None = None, parent_pid: int | None = None) -> Observer:
    """Watch ``fleet`` until ``duration`` s (wall clock) pass, SIGTERM/SIGINT arrives or the parent dies.

    The parent is ``parent_pid`` if given (a launcher passes its own pid, so that even a parent that
    died while this process was starting is noticed), else the parent at the time of the call; it is
    taken as dead when ``os.getppid()`` no longer returns it. Returns the (closed) observer, whose
    counters tell what was accepted and rejected."""
    keys = Keys(fleet)
    # the session first: a router that cannot be reached (SessionError) leaves no recording file behind
    transport = ZenohTransport(
        "observer", keys, load_config(connect, zenoh_config),
        subscribe=[keys.telemetry("*"), f"{keys.root}/belief/**", keys.sim("truth")], liveliness=False,
    )
    observer = Observer(keys, recording_id or fleet, application_id, fleet_key=fleet_key)
    stop = False

    def _stop(signum, frame):
        nonlocal stop
        stop = True

    in_main = threading.current_thread() is threading.main_thread()  # signals can only be caught there
    previous = {s: signal.signal(s, _stop) for s in (signal.SIGTERM, signal.SIGINT)} if in_main else {}
    parent = os.getppid() if parent_pid is None else parent_pid
    try:
        if save:
            observer.save(save)
        if connect_viewer:
            observer.connect(connect_viewer)
        if spawn:
            observer.spawn()
        if web:
            print(f"web viewer: {observer.serve_web(web)}", flush=True)
        deadline = None if duration is None else time.monotonic() + duration
        while not stop:
            for item in transport.drain():
                observer.handle(item)
            if deadline is not None and time.monotonic() >= deadline:
                break
            if os.getppid() != parent:
                log.warning("observer: parent process %d is gone; stopping", parent)
                break
            time.sleep(POLL_S)
        for item in transport.drain():
            observer.handle(item)
    finally:
        transport.close()
        observer.close()
        for s, handler in previous.items():
            signal.signal(s, handler)
    return observer


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m mesh_sim.observer",
        description="Ground station: log a skymesh fleet's telemetry, beliefs and truth to Rerun.",
    )
    p.add_argument("--fleet", required=True, help="fleet name (the key space skymesh/<fleet>/...)")
    p.add_argument("--connect", action="append", metavar="ENDPOINT",
                   help="Zenoh router endpoint, e.g. tcp/127.0.0.1:7447 (repeatable)")
    p.add_argument("--zenoh-config", metavar="FILE", help="a Zenoh JSON5 config file (instead of --connect)")
    p.add_argument("--save", metavar="PATH", help="write the recording to this .rrd file")
    p.add_argument("--connect-viewer", metavar="URL", help="stream to a Rerun viewer, e.g. rerun+http://127.0.0.1:9876/proxy")
    p.add_argument("--spawn", action="store_true", help="start a live Rerun viewer (needs a display)")
    add_web_arguments(p)
    p.add_argument("--duration", type=float, metavar="S", help="stop after S seconds of wall clock")
    p.add_argument("--recording-id", help="Rerun recording id (default: the fleet name)")
    p.add_argument("--application-id", default="skymesh", help="Rerun application id (default: skymesh)")
    p.add_argument("--fleet-key-file", help="file holding the fleet's HMAC key: unsigned messages are rejected")
    p.add_argument("--parent-pid", type=int, help="exit when this process is no longer our parent (default: the "
                   "parent at start)")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    if not (args.save or args.connect_viewer or args.spawn or args.web is not None):
        print("observer: nothing to do: give --save, --connect-viewer, --spawn or --web", file=sys.stderr)
        return 2
    if args.web is not None and (args.save or args.connect_viewer or args.spawn):
        print("observer: --web serves the recording itself: give it without --save, --connect-viewer and --spawn",
              file=sys.stderr)
        return 2
    try:
        if args.spawn:  # before the Zenoh session: no viewer or no display is said first, in one line
            viewer_to_spawn()
        obs = run_observer(args.fleet, args.connect, args.zenoh_config, args.save, args.connect_viewer, args.spawn,
                           args.duration, web=web_of(args), recording_id=args.recording_id,
                           application_id=args.application_id, parent_pid=args.parent_pid,
                           fleet_key=read_key_file(args.fleet_key_file) if args.fleet_key_file else None)
    except (OSError, ValueError) as err:  # OSError: no router (SessionError), an unwritable --save, no viewer
        return usage_error("observer", err)
    rejected = ", ".join(f"{r}={n}" for r, n in sorted(obs.rejected.items())) or "none"
    log.info("observer: %d messages logged; rejected: %s%s", obs.accepted, rejected,
             f"; saved {args.save}" if args.save else "")
    return 0


if __name__ == "__main__":
    sys.exit(main())
