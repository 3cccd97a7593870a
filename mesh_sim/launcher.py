"""``skymesh run``: start a whole team on this machine and collect the results.

The launcher opens the Zenoh router itself (loopback, multicast scouting off, a free port; or from a Zenoh JSON5
file, ``--zenoh-config``: :mod:`mesh_sim.run_router`) and prints its endpoint and the fleet's name (what
``skymesh view --fleet NAME --connect ENDPOINT`` needs to attach), then starts
the world process, N agent processes and — unless ``--rerun off`` — the observer that writes the Rerun
recording, each as ``python -m ...`` (never by forking this process). The agents are forked by one more child,
``python -m agent.forkserver`` (:mod:`mesh_sim.forked`), which has imported what they import once: they share
those pages, and start in a fraction of the time (a seam: :attr:`Launcher.fork_agents`; the namespace test bed
starts each agent in its namespace instead). It shows progress, and stops everything on completion, on Ctrl-C and
on a fatal death: SIGTERM by PID, then SIGKILL by PID after a grace period. Every child also exits by itself if
the launcher disappears (a forked agent when its fork server does, which ends with the launcher's pipe).

**Losing a member loses only that member.** An agent that dies (a crash, ``kill -9``) is recorded — name,
PID, exit status, simulation time — in ``deaths.json`` and the run goes on with the others; so does a
dead observer (the recording stops) or autopilot (its agent's vehicle turns unhealthy and its tasks go
to the peers). The run fails only when the world dies before the end or every agent has died.

Start-up is measured in the running system: each child's seconds from its spawn to its ready file (created
once it has imported its modules, built its state and opened its Zenoh session) are in
:attr:`RunOutcome.startup_s`, by child name.

The run folder holds ``scenario.json`` (the effective scenario), ``logs/``, each process's own
metrics, the merged ``metrics.json``, ``recording.rrd`` and ``plots/``.
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass, field
from pathlib import Path

import zenoh
from rich.console import Console

from agent.net.fleet_key import new_key_file
from agent.net.zenoh_transport import SessionError, open_session, router_config
from agent.runtime import atomic_file, write_json
from mesh_sim import results
from mesh_sim.child_logs import failure_text
from mesh_sim.forked import ForkServer
from mesh_sim.run_router import router_from_file
from mesh_sim.scenario import Scenario
from mesh_sim.sim_progress import sim_progress
from mesh_sim.viewer import viewer_to_spawn, with_this_environment_on_path

START_DELAY_S = 0.5  # wall seconds between "everyone is ready" and simulation time 0; chosen here
READY_TIMEOUT_S = 120.0  # a process that is not ready by then fails the run
ROUTER_ATTEMPTS = 3  # free ports tried for the router when one is taken before it listens (a race; chosen here)
GRACE_S = 10.0  # wall seconds between SIGTERM and SIGKILL
VEHICLES = ("kinematic", "mavlink")  # each agent's own kinematic model, or an autopilot simulator over MAVLink


@dataclass
class Child:
    name: str
    role: str  # "agent", "world", "observer" or "autopilot"
    process: subprocess.Popen  # or a mesh_sim.forked.ForkedProcess, which answers the same
    log_path: Path
    started: float  # wall time just before the spawn [s since the Unix epoch]
    args: list[str] = field(default_factory=list)  # what it was started with (a restart starts it again so)
    incarnation: int = 0  # agent.net.incarnation: 0, then one more per restart


@dataclass(frozen=True)
class Death:
    """A child that died while the run went on."""

    name: str
    role: str
    pid: int
    exit_code: int  # negative: killed by that signal (subprocess's convention)
    t: float  # simulation seconds when the launcher saw it
    restarted_as: int | None = None  # the incarnation of the agent started in its place (--restart)

    @property
    def cause(self) -> str:
        if self.exit_code < 0:
            try:
                return f"killed by {signal.Signals(-self.exit_code).name}"
            except ValueError:
                return f"killed by signal {-self.exit_code}"
        return f"exit code {self.exit_code}"

    def to_dict(self) -> dict:
        return {"agent" if self.role == "agent" else "process": self.name, "role": self.role, "pid": self.pid,
                "exit_code": self.exit_code, "cause": self.cause, "t": self.t, "restarted_as": self.restarted_as}


@dataclass
class RunOutcome:
    run_dir: Path
    status: str  # "completed", "interrupted" or "failed: <why>"
    metrics: dict = field(default_factory=dict)
    pids: dict = field(default_factory=dict)
    startup_s: dict = field(default_factory=dict)  # child name -> seconds from its spawn to its ready file
    deaths: list[Death] = field(default_factory=list)  # children that died while the run went on


class _Terminated(Exception):
    """SIGTERM arrived: stop the run as Ctrl-C would, and keep its results."""


@contextmanager
def _sigterm_raises() -> Iterator[None]:
    """While inside, SIGTERM raises :class:`_Terminated` in the main thread (a launcher run from another thread
    keeps the default handler: Python delivers signals to the main thread only)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        raise _Terminated

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def free_port() -> int:
    """A TCP port on loopback that was free a moment ago (the OS picks it)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def open_router(attempts: int = ROUTER_ATTEMPTS) -> tuple[zenoh.Session, str]:
    """The run's Zenoh router on a free loopback port, and its endpoint. A port is free when :func:`free_port`
    looks, but another process may take it before the router listens: then another port is tried, and after
    ``attempts`` the last one's :class:`SessionError` (a one-line ``OSError``) is raised."""

    def on_a_free_port() -> tuple[zenoh.Session, str]:
        endpoint = f"tcp/127.0.0.1:{free_port()}"
        return open_session(router_config([endpoint])), endpoint

    for _ in range(attempts - 1):
        with suppress(SessionError):
            return on_a_free_port()
    return on_a_free_port()


def new_run_dir(base: Path, name: str) -> Path:
    """A new, empty folder ``base/NAME-STAMP-XXXX`` (``base`` created if need be). Raises ``OSError`` naming
    ``base`` — the folder the user gave — when it cannot be made (read-only, full, a file in the way)."""
    stamp = time.strftime("%Y%m%d-%H%M%S")
    path = base / f"{name}-{stamp}-{uuid.uuid4().hex[:4]}"
    try:
        path.mkdir(parents=True)
    except OSError as err:
        raise OSError(err.errno, f"cannot create a run folder here: {err.strerror}", str(base)) from None
    return path


@contextmanager
def run_folder(base: Path, name: str) -> Iterator[Path]:
    """A new run folder (:func:`new_run_dir`) that is removed again, with whatever was written to it, when the
    run raises before it could write its metrics (a bad setting found late, a full disk): a failed start leaves
    no half-written folder behind. A run that ends — completed, failed or interrupted — keeps its folder.

    What "nothing half-written" means: every result file (``metrics.json``, the per-process JSON, ``scenario.json``,
    ``fire_maps.npz``, the plots) is written whole or not at all (:func:`agent.runtime.atomic_file`: a temporary
    file, then a rename), and ``metrics.json`` is written last but the plots; so a folder either holds a complete
    ``metrics.json`` or is removed here. (Logs and ``recording.rrd`` are streams: a run that ends keeps what they
    got.) This is simpler than building the folder under a temporary name: the processes of a live run write to
    its final path from the start, and a user may follow its logs there."""
    path = new_run_dir(base, name)
    try:
        yield path
    except BaseException:
        if not (path / "metrics.json").exists():
            shutil.rmtree(path, ignore_errors=True)
        raise


def stop_processes(processes: list[subprocess.Popen]) -> None:
    """SIGTERM every process still running (by PID), wait up to ``GRACE_S`` for all of them, then SIGKILL the
    stragglers (by PID)."""
    for proc in processes:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
    deadline = time.time() + GRACE_S
    for proc in processes:
        try:
            proc.wait(timeout=max(0.1, deadline - time.time()))
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


class Launcher:
    fork_agents = True  # agents forked by a fork server (mesh_sim.forked) rather than started one by one

    def __init__(self, scenario: Scenario, run_dir: Path, speed: float = 1.0, rerun: str = "save",
                 console: Console | None = None, extra_env: dict | None = None, cameras: dict | None = None,
                 vehicle: str = "kinematic", restart: bool = False, zenoh_config: str | None = None):
        if not speed > 0:
            raise ValueError(f"--speed must be positive, got {speed}")
        if vehicle not in VEHICLES:
            raise ValueError(f"--vehicle must be one of {', '.join(VEHICLES)}, got {vehicle!r}")
        if vehicle == "mavlink" and speed != 1.0:
            raise ValueError("--vehicle mavlink runs at --speed 1: the autopilots fly on the wall clock")
        if rerun not in ("save", "spawn", "off") and not rerun.startswith("connect:"):
            raise ValueError(f"--rerun must be save, spawn, off or connect:URL, got {rerun!r}")
        if rerun == "spawn":
            viewer_to_spawn()  # no viewer or no display: a bad environment (ViewerError), before anything starts
        self.scenario = scenario
        self.run_dir = run_dir
        self.speed = speed
        self.rerun = rerun
        self.console = console or Console(stderr=True)
        # BLAS on one thread per process unless told otherwise: on a shared machine OpenBLAS's worker threads cost
        # 5-10x per collocation solve (tasking.collocation) and the fleet's own matrices are small; this
        # environment first on PATH: the observer's viewer is this environment's `rerun` (mesh_sim.viewer)
        self.env = with_this_environment_on_path({"OPENBLAS_NUM_THREADS": "1", **os.environ, **(extra_env or {})})
        self.fleet = f"{scenario.name}-{uuid.uuid4().hex[:8]}"
        self.cameras = dict(cameras or {})  # agent name -> OpenCV video source replacing its synthetic camera
        self.vehicle = vehicle
        self.restart = restart  # start a dead agent again, as its next incarnation
        self.zenoh_config = zenoh_config  # a Zenoh JSON5 file for the run's router (mesh_sim.run_router), or None
        self.children: list[Child] = []
        self.forkserver: ForkServer | None = None
        self.startup_s: dict[str, float] = {}
        self.deaths: list[Death] = []

    # -- lifecycle --------------------------------------------------------------------------------
    def run(self) -> RunOutcome:
        """Run the team; on completion, on Ctrl-C (status ``interrupted``) and on SIGTERM (``terminated``) the
        children are stopped and the metrics of what ran are written."""
        scenario_file = self.run_dir / "scenario.json"
        write_json(scenario_file, self.scenario.raw)
        (self.run_dir / "logs").mkdir(exist_ok=True)
        router, endpoint = self._open_router()
        self.console.print(f"fleet {self.fleet} at {endpoint}; attach a ground station with: "
                           f"skymesh view --fleet {self.fleet} --connect {endpoint}", highlight=False, soft_wrap=True)
        status = "completed"
        try:
            with _sigterm_raises():
                self._start_all(scenario_file, endpoint)
                epoch = self._release()
                status = self._monitor(epoch) if isinstance(epoch, float) else epoch
        except KeyboardInterrupt:
            status = "interrupted"
        except _Terminated:
            status = "terminated"
        finally:
            self._stop_all()
            router.close()
        write_json(self.run_dir / results.DEATHS_FILE, [d.to_dict() for d in self.deaths])
        metrics = results.collect(self.run_dir, self.scenario, status, self.speed)
        pids = {c.name if c.incarnation == 0 else f"{c.name}.{c.incarnation}": c.process.pid for c in self.children}
        return RunOutcome(self.run_dir, status, metrics, pids,
                          dict(self.startup_s), list(self.deaths))

    def _open_router(self) -> tuple[zenoh.Session, str]:
        """The router every child connects to, and its endpoint: on a free loopback port, or from ``--zenoh-config``
        (a seam: mesh_sim.testbed runs one per host)."""
        return open_router() if self.zenoh_config is None else router_from_file(self.zenoh_config)

    def _command(self, name: str, role: str, args: list[str]) -> list[str]:
        """The command line that starts child ``name`` (a seam: mesh_sim.testbed runs it in a namespace)."""
        return [sys.executable, *args]

    @property
    def _epoch_file(self) -> Path:
        return self.run_dir / "epoch"

    def _ready_file(self, name: str) -> Path:
        return self.run_dir / "logs" / f"{name}.ready"

    def _release(self) -> float | str:
        """Wait until the world and every agent are ready, then publish simulation time 0 (the epoch).
        Returns the epoch, or the failure status if a child died or never got ready."""
        timed = [c for c in self.children if c.role in ("world", "agent")]  # autopilots need no epoch
        deadline = time.time() + READY_TIMEOUT_S
        while not all(self._ready_file(c.name).exists() for c in timed):
            for child in self.children:
                if child.process.poll() is not None:
                    return f"failed: {self._failure(child, f'exited with code {child.process.poll()}')}"
            if time.time() > deadline:
                return f"failed: not every process was ready within {READY_TIMEOUT_S:.0f} s"
            time.sleep(0.05)
        self.startup_s = {c.name: self._ready_file(c.name).stat().st_mtime - c.started for c in timed}
        epoch = time.time() + START_DELAY_S
        with atomic_file(self._epoch_file) as f:
            f.write(repr(epoch))
        return epoch

    def _start_all(self, scenario_file: Path, endpoint: str) -> None:
        sc = self.scenario.agent
        if self.fork_agents:
            self.forkserver = ForkServer(scenario_file, self.env, self.run_dir / "logs" / "forkserver.log",
                                         READY_TIMEOUT_S)
        key_file = new_key_file(self.run_dir)  # every process signs and checks with the run's own fleet key
        common = ["--fleet", self.fleet, "--connect", endpoint, "--parent-pid", str(os.getpid()),
                  "--fleet-key-file", str(key_file)]

        def timing(name: str) -> list[str]:
            return ["--epoch-file", str(self._epoch_file), "--ready-file", str(self._ready_file(name)),
                    "--speed", repr(self.speed)]

        if self.rerun != "off":
            view = {"save": ["--save", str(self.run_dir / "recording.rrd")], "spawn": ["--spawn"]}.get(
                self.rerun, ["--connect-viewer", self.rerun.removeprefix("connect:")]
            )
            self._spawn("observer", "observer", ["-m", "mesh_sim.observer", *common, *view])
        self._spawn("world", "world", ["-m", "mesh_sim.world", *common, *timing("world"),
                                       "--scenario", str(scenario_file),
                                       "--duration", repr(sc.duration), "--out", str(self.run_dir)])
        for i in range(sc.agents):
            mavlink = self._start_autopilot(i) if self.vehicle == "mavlink" else []
            self._spawn(f"uav{i}", "agent", [
                "-m", "agent", "--id", f"uav{i}", "--index", str(i), "--scenario", str(scenario_file),
                "--seed", str(sc.seed * 1000 + i), "--out", str(self.run_dir), *common, *timing(f"uav{i}"),
                *(["--camera", str(self.cameras[f"uav{i}"])] if f"uav{i}" in self.cameras else []), *mavlink,
            ])

    def _start_autopilot(self, index: int) -> list[str]:
        """Start ``skymesh autopilot`` for agent ``index`` (PX4 SITL's conventions on free loopback ports; the
        scenario's vehicle, origin and the agent's start position), and return the agent's ``--mavlink`` options:
        the agent listens where the autopilot sends its offboard link."""
        from mesh_sim.autopilot.process import free_udp_ports

        sc = self.scenario.agent
        offboard, listen, gcs, gcs_remote = free_udp_ports(4)
        vehicle = dict(sc.vehicle)
        north, east, _ = sc.start_position(index)
        self._spawn(f"autopilot{index}", "autopilot", [
            "-m", "mesh_sim.autopilot", "--instance", str(index), "--vehicle", str(vehicle.pop("kind")),
            *(f"--vehicle-param={key}={value}" for key, value in vehicle.items()),
            "--north", repr(float(north)), "--east", repr(float(east)), "--altitude", repr(float(sc.altitude)),
            "--origin", ",".join(map(repr, sc.origin)),
            "--offboard-port", str(offboard), "--offboard-remote-port", str(listen), "--gcs-port", str(gcs),
            "--gcs-remote-port", str(gcs_remote), "--parent-pid", str(os.getpid()),
            "--stats", str(self.run_dir / f"autopilot-uav{index}.json"),
        ])
        return ["--mavlink", f"udpin:127.0.0.1:{listen}"]

    def _spawn(self, name: str, role: str, args: list[str], incarnation: int = 0) -> None:
        log_path = self.run_dir / "logs" / (f"{name}.log" if incarnation == 0 else f"{name}.{incarnation}.log")
        started = time.time()
        if role == "agent" and self.forkserver is not None:
            log_path.touch()  # there from the spawn on, as a spawned child's is
            proc = self.forkserver.spawn(args[2:], log_path)  # args: "-m", "agent", then the agent's own
        else:
            with open(log_path, "wb") as log:
                proc = subprocess.Popen(self._command(name, role, args), stdout=log, stderr=subprocess.STDOUT,
                                        stdin=subprocess.DEVNULL, env=self.env)
        self.children.append(Child(name, role, proc, log_path, started, list(args), incarnation))

    def _monitor(self, epoch: float) -> str:
        """Wait for the agents to finish; return the run's status. A dead agent, observer or autopilot is
        recorded and the run goes on; the world dying before the end, or every agent dying, fails it."""
        duration = self.scenario.agent.duration
        title = f"{self.scenario.name}: {self.scenario.agent.agents} agents"
        with sim_progress(self.console, title, duration) as advance:
            while True:
                time.sleep(0.2)
                sim_t = max(0.0, (time.time() - epoch) * self.speed)
                advance(sim_t)
                for child in list(self.children):  # a restart adds one
                    code = child.process.poll()
                    if code is None or (code == 0 and child.role == "agent") or self._dead(child):
                        continue
                    if child.role == "world":
                        if code == 0 and sim_t >= duration:
                            continue
                        return f"failed: {self._failure(child, f'exited with code {code}')}"
                    self._record_death(child, code, min(sim_t, duration))
                agents = [c for c in self.children if c.role == "agent"]
                if all(c.process.poll() is not None for c in agents):
                    return "completed" if any(c.process.poll() == 0 for c in agents) else "failed: every agent died"

    def _dead(self, child: Child) -> bool:
        return any(d.pid == child.process.pid for d in self.deaths)

    def _record_death(self, child: Child, code: int, t: float) -> None:
        again = self.restart and child.role == "agent" and t < self.scenario.agent.duration
        death = Death(child.name, child.role, child.process.pid, code, round(t, 3),
                      child.incarnation + 1 if again else None)
        self.deaths.append(death)
        if again:  # a new life: peers reset their channels to it (agent.net.incarnation)
            self._spawn(child.name, child.role, [*child.args, "--incarnation", str(death.restarted_as)],
                        death.restarted_as)
        alive = sum(c.process.poll() is None for c in self.children if c.role == "agent")
        then = f"restarted as incarnation {death.restarted_as}" if again else "the run goes on"
        self.console.print(f"{self._failure(child, f'died at t = {t:.1f} s ({death.cause})')}; "
                           f"{then} with {alive} agent{'s' * (alive != 1)}", style="yellow", highlight=False,
                           markup=False)

    @staticmethod
    def _failure(child: Child, what: str) -> str:
        """What happened to ``child``, why (its log's last meaningful line) and where its log is."""
        return failure_text(child.name, child.process.pid, what, child.log_path)

    def _stop_all(self) -> None:
        """SIGTERM every child still running (by PID), wait, then SIGKILL the stragglers (by PID)."""
        stop_processes([child.process for child in self.children])
        if self.forkserver is not None:
            self.forkserver.close(GRACE_S)
