"""The ``skymesh`` command line.

* ``skymesh bench NAME [--quick] [--json PATH]`` — run a benchmark of :data:`mesh_sim.bench.BENCHMARKS`
  and print its tables (optionally writing the result as JSON); ``skymesh bench scale [--sensor bearing|camera]
  [--sizes 8,16,32]``, ``skymesh bench fire [--seeds N]``, ``skymesh bench fuzz [--kinds track,grid]`` — the
  options of :data:`BENCH_OPTIONS`, for the benchmarks that take them;
* ``skymesh bench --list`` — list the benchmarks;
* ``skymesh run [--scenario NAME|FILE] [--agents N] [--duration S] [--speed X] [--seed K] [--out DIR]
  [--policy P] [--rerun save|spawn|connect:URL|off] [--camera uavK=SOURCE ...] [--vehicle kinematic|mavlink]``
  — a team of agent processes over Zenoh (``mesh_sim.launcher``); with no arguments, the default scenario.
  ``--vehicle mavlink`` starts a ``skymesh autopilot`` per agent and flies each agent over MAVLink UDP.
  ``--camera uav0=clip.avi`` replaces that agent's synthetic camera with an OpenCV video source (file, device
  index, stream URL); a source that cannot be opened is a usage error before anything starts. A live run prints
  its fleet name and router endpoint first (the ``skymesh view`` line that attaches to it); ``--zenoh-config FILE``
  opens its router from a Zenoh JSON5 file (``mesh_sim.run_router``). A completed run whose agents missed more than
  1 % of their deadlines or whose video source failed ends "completed with warnings" (``mesh_sim.run_health``);
  a bad ``--duration``, ``--loss``, ... names the flag (``mesh_sim.run_overrides``);
* ``skymesh testbed [the options of run] [--link-down T:uavK[:T_UP] ...] [--tbf-rate BYTES_PER_S]
  [--tbf-burst BYTES] [--tbf-per-link] [--router-link tcp|udp]`` — the run
  across hosts on this machine: a Linux network namespace and a Zenoh router per agent (``mesh_sim.testbed``;
  root; not with ``--lockstep``, ``--zenoh-config`` or ``--vehicle mavlink``); a link taken down and up mid-run,
  the kernel's rate cap on every UAV host; ``testbed.json`` in the run folder;
* ``skymesh demo`` — ``skymesh run`` on the default scenario (what ``make demo`` runs);
* ``skymesh view --fleet NAME --connect ENDPOINT`` — the ground station (``mesh_sim.observer``), with this
  environment's Rerun viewer (``mesh_sim.viewer``) unless ``--save``, ``--connect-viewer`` or ``--web`` is given;
  ``--web [PORT] [--grpc-port P] [--web-host HOST]`` serves Rerun's web viewer instead and prints the URL a
  browser opens, until SIGINT / SIGTERM; ``skymesh view --web --recording FILE`` serves an .rrd the same way
  (``mesh_sim.observer_web``);
* ``skymesh compare BEFORE AFTER [--plain] [--limit N]`` — compare two run folders exactly, volatile fields
  (pids, CPU and wall times, ...) aside (``mesh_sim.run_compare``): exit 0 identical, 1 different;
* ``skymesh compare --tree BEFORE_ROOT AFTER_ROOT [--details]`` — pair the run folders of two roots by
  name, one line per pair;
* ``skymesh autopilot --instance I [--vehicle multirotor|fixed_wing] [--north M] [--east M] [--heading DEG]
  [--latency-ms MS] [--offboard-port P] [--gcs-port P] ...`` — a MAVLink autopilot simulator that behaves like
  PX4 SITL instance ``I`` (a subset) around the kinematic vehicle model (``mesh_sim.autopilot``; the same as
  ``python -m mesh_sim.autopilot``): it binds 14580+I and sends to 14540+I (offboard), binds 18570+I and sends
  to 14550 (ground station), until SIGTERM / SIGINT, ``--duration`` or the death of ``--parent-pid``;
* ``skymesh router --config FILE`` — a Zenoh router from a JSON5 file (``mesh_sim.router``), e.g.
  ``deploy/router.json5``: mutual TLS and access control for a deployment across machines, until SIGTERM / SIGINT.

Exit codes: 0 success, 1 a run that failed (a child died) or runs that differ, 2 usage error (unknown
benchmark or scenario, bad settings, not a run folder) or a bad environment (an output folder that cannot be
written, a full disk, a camera that does not open, a port in use, no router): one line on stderr
(:func:`agent.runtime.usage_error`), 130 interrupted.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from agent.beliefs.tracking_config import POLICIES
from agent.runtime import EXIT_USAGE, usage_error
from agent.sensors.registry import SENSORS
from mesh_sim.autopilot.options import add_arguments as add_autopilot_arguments
from mesh_sim.bench import BENCHMARKS
from mesh_sim.bench.common import make_console, write_json
from mesh_sim.web_options import add_web_arguments, web_of

STOPPED_BY = {"interrupted": 130, "terminated": 143}  # a run stopped by SIGINT / SIGTERM: 128 + the signal
#: benchmark options beyond --quick and --json, for the benchmarks naming them
BENCH_OPTIONS = ("sizes", "sensor", "seeds", "kinds")


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text}")
    return value


def _sizes(text: str) -> tuple[int, ...]:
    """``"8,16,32"`` -> ``(8, 16, 32)``: comma-separated positive integers."""
    parts = [part.strip() for part in text.split(",")]
    if not all(part.isdigit() and int(part) >= 1 for part in parts):
        raise argparse.ArgumentTypeError(f"must be positive integers separated by commas, e.g. 8,16,32; got {text!r}")
    return tuple(int(part) for part in parts)


def _names(text: str) -> tuple[str, ...]:
    """``"track,grid"`` -> ``("track", "grid")``: comma-separated names (the benchmark judges them)."""
    return tuple(part.strip() for part in text.split(",") if part.strip())


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="skymesh", description="skymesh: decentralized cooperative perception for teams of UAVs."
    )
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    bench = commands.add_parser("bench", help="run a benchmark and print its table", description="Run a benchmark.")
    bench.add_argument("name", nargs="?", help="the benchmark to run (see --list)")
    bench.add_argument("--list", action="store_true", help="list the available benchmarks and exit")
    bench.add_argument("--quick", action="store_true", help="fewer, shorter repeats: seconds instead of minutes")
    bench.add_argument("--json", metavar="PATH", type=Path, help="also write the result as JSON to PATH")
    bench.add_argument("--repeats", type=_positive_int, metavar="N",
                       help="timed repeats per figure (scale: runs per team size, pooled; testbed: seeds of the "
                            "shaper and per-link rows, pooled; default: the mode's)")
    bench.add_argument("--sizes", type=_sizes, metavar="N,N,...",
                       help="scale: the team sizes to run, e.g. 8,16,32,40,48 (default: each sensor's own)")
    bench.add_argument("--sensor", choices=sorted(SENSORS), help="scale: measure this sensor only (default: each)")
    bench.add_argument("--seeds", type=_positive_int, metavar="N",
                       help="fire: run N seeds (default: 5, or 1 with --quick)")
    bench.add_argument("--kinds", type=_names, metavar="NAME,NAME,...",
                       help="fuzz: fuzz only these message kinds, e.g. track,grid (default: every kind)")

    for name, text in (("run", "run a team of agents on a scenario"), ("demo", "run the default scenario"),
                       ("testbed", "run a team across hosts: one Linux network namespace and Zenoh router per agent")):
        run = commands.add_parser(name, help=text, description=text)
        run.add_argument("--scenario", default="default", help="a shipped scenario name or a TOML file")
        run.add_argument("--agents", type=_positive_int, help="number of agents (overrides the scenario)")
        run.add_argument("--duration", type=float, help="simulation seconds (overrides the scenario)")
        run.add_argument("--speed", type=float, default=1.0, help="simulation seconds per wall second")
        run.add_argument("--seed", type=int, help="random seed (overrides the scenario)")
        run.add_argument("--policy", choices=POLICIES, help="fusion policy")
        run.add_argument("--topology", choices=["full", "ring", "star", "line", "tree", "random", "disk"],
                         help="radio topology (overrides the scenario's [radio])")
        run.add_argument("--loss", type=float, help="Bernoulli loss probability per message, 0..1")
        run.add_argument("--latency", type=float, metavar="MS", help="one-way delay in milliseconds")
        run.add_argument("--bandwidth", type=float, metavar="BYTES_PER_S", help="per-link rate cap")
        run.add_argument("--out", type=Path, default=Path("runs"), help="where run folders go (default: runs)")
        run.add_argument("--rerun", default="save", help="save (default), spawn, connect:URL or off")
        run.add_argument("--lockstep", action="store_true",
                         help="all agents in this process over an in-memory bus, deterministic and fast")
        run.add_argument("--vehicle", choices=["kinematic", "mavlink"], default="kinematic",
                         help="kinematic: each agent flies its own model; mavlink: a skymesh autopilot per agent, "
                              "flown over MAVLink UDP (live runs at --speed 1)")
        run.add_argument("--restart", action="store_true",
                         help="start an agent that dies again, as its next incarnation (live runs)")
        run.add_argument("--zenoh-config", metavar="FILE",
                         help="open the run's Zenoh router from this JSON5 file (a router listing its listen "
                              "endpoints), e.g. to let a ground station on another machine attach")
        run.add_argument("--camera", action="append", default=[], metavar="AGENT=SOURCE",
                         help="replace an agent's synthetic camera with an OpenCV source (file, device index, URL), "
                              "e.g. uav0=clip.avi; repeatable")
    testbed = commands.choices["testbed"]
    testbed.add_argument("--link-down", action="append", default=[], metavar="T:uavK[:T_UP]",
                         help="set host uavK's network link down at simulation time T (and up at T_UP); repeatable")
    testbed.add_argument("--tbf-rate", type=float, metavar="BYTES_PER_S",
                         help="cap what every UAV host sends with the kernel's token bucket (tc tbf)")
    testbed.add_argument("--tbf-burst", type=float, metavar="BYTES",
                         help="the token bucket's depth (default: 1/50 s of --tbf-rate, at least 4096)")
    testbed.add_argument("--tbf-per-link", action="store_true",
                         help="--tbf-rate caps each directed link between two UAV hosts, a bucket per link, as the "
                              "emulated radio's rate does (default: a UAV host's whole egress); with "
                              "--router-link udp")
    testbed.add_argument("--router-link", choices=("tcp", "udp"), default="tcp",
                         help="the transport between the hosts' routers (udp: what the network drops is lost, "
                              "not retransmitted)")

    stress = commands.add_parser("stress", help="bandwidth and topology stress (= skymesh bench stress)",
                                 description="Live runs under topology churn with a shrinking bandwidth cap.")
    stress.add_argument("--quick", action="store_true")
    stress.add_argument("--json", metavar="PATH", type=Path)
    stress.add_argument("--repeats", type=_positive_int, help=argparse.SUPPRESS)

    view = commands.add_parser("view", help="the ground station: log a fleet to Rerun",
                               description="Subscribe to a fleet on Zenoh and log it to Rerun.")
    view.add_argument("--fleet", help="the fleet to watch (required unless --recording is given)")
    view.add_argument("--connect", action="append", default=[], help="Zenoh router endpoint")
    view.add_argument("--zenoh-config", help="a Zenoh JSON5 config file")
    view.add_argument("--save", help="write the recording to this .rrd file")
    view.add_argument("--connect-viewer", help="stream to a Rerun viewer, e.g. rerun+http://127.0.0.1:9876/proxy")
    view.add_argument("--duration", type=float, help="stop after this many seconds")
    add_web_arguments(view)
    view.add_argument("--recording", type=Path, metavar="FILE",
                      help="with --web: serve this .rrd (e.g. RUN/recording.rrd) instead of a live fleet")

    compare = commands.add_parser(
        "compare", help="compare two run folders exactly (volatile fields aside)",
        description="Compare metrics.json, agent-*.json, oracle.json and fire_maps.npz of two run folders exactly, "
                    "ignoring volatile fields (pids, CPU and wall times, memory, speed factor, run and fleet names). "
                    "Exit 0 identical, 1 different, 2 usage error.")
    compare.add_argument("before", type=Path, help="a run folder, or a folder holding exactly one")
    compare.add_argument("after", type=Path, help="a run folder, or a folder holding exactly one")
    compare.add_argument("--tree", action="store_true",
                         help="BEFORE and AFTER are roots whose sub-folders are paired by name: one line per pair")
    compare.add_argument("--details", action="store_true", help="with --tree: also list each pair's differences")
    compare.add_argument("--plain", action="store_true", help="plain lines instead of a table")
    compare.add_argument("--limit", type=_positive_int, default=50, help="list at most N differences (default 50)")
    compare.add_argument("--rtol", type=float, default=0.0,
                         help="floats equal to this relative tolerance, arrays compared by their sums (default 0: "
                              "bit for bit); e.g. 1e-6 across numpy/SciPy/OpenCV releases")

    autopilot = commands.add_parser("autopilot", help="a PX4-SITL-like MAVLink autopilot simulator (one vehicle)",
                                    description="A MAVLink autopilot simulator that behaves like PX4 SITL instance I "
                                                "(a subset) around skymesh's kinematic vehicle models.")
    add_autopilot_arguments(autopilot)

    router = commands.add_parser("router", help="a Zenoh router from a JSON5 file (mutual TLS, access control)",
                                 description="A Zenoh router for a deployment across machines, from a Zenoh JSON5 "
                                             "file (see deploy/README.md). Runs until SIGINT or SIGTERM.")
    router.add_argument("--config", required=True, metavar="FILE",
                        help="a Zenoh JSON5 config file, e.g. deploy/router.json5 (relative paths in it are read "
                             "from the current folder)")
    router.add_argument("--parent-pid", type=int, metavar="PID",
                        help="stop when this process (the one that started the router) is gone")
    return parser


def _known() -> str:
    return ", ".join(sorted(BENCHMARKS))


def _bench(args) -> int:
    console = make_console()
    if args.list:
        for name, bench in sorted(BENCHMARKS.items()):
            console.print(f"[bold]{name}[/bold]  {bench.description}", highlight=False)
        return 0
    if args.name is None:
        print(f"skymesh bench: name a benchmark; known benchmarks: {_known()}", file=sys.stderr)
        return EXIT_USAGE
    if args.name not in BENCHMARKS:
        print(
            f"skymesh bench: unknown benchmark {args.name!r}; known benchmarks: {_known()} "
            "(`skymesh bench --list` describes them)",
            file=sys.stderr,
        )
        return EXIT_USAGE
    bench = BENCHMARKS[args.name]
    options = {name: value for name in BENCH_OPTIONS if (value := getattr(args, name, None)) is not None}
    refused = [f"--{name}" for name in options if name not in bench.options]
    if refused:
        takes = ", ".join(sorted(n for n, b in BENCHMARKS.items() if set(b.options) & set(options)))
        print(f"skymesh bench {args.name}: {' and '.join(refused)} {'is' if len(refused) == 1 else 'are'} not "
              "an option of this benchmark"
              + (f" (only of: {takes})" if takes else ""), file=sys.stderr)
        return EXIT_USAGE
    try:
        result = bench.run(quick=args.quick, repeats=args.repeats, **options)
    except (ValueError, OSError) as err:  # a value the benchmark refuses (--kinds nope), an environment it cannot
        # run in (skymesh bench testbed without namespaces)
        return usage_error(f"skymesh bench {args.name}", err)
    bench.report(result, console)
    if args.json is not None:
        try:
            console.print(f"JSON written to {write_json(args.json, result)}", highlight=False)
        except OSError as err:  # the tables are printed; the file is not half-written (atomic)
            return usage_error(f"skymesh bench {args.name}", err)
    return 0


def _run(args) -> int:
    from mesh_sim.launcher import Launcher, run_folder
    from mesh_sim.lockstep import run_lockstep
    from mesh_sim.results import grid_table, summary_table
    from mesh_sim.run_health import WITH_WARNINGS, judge
    from mesh_sim.run_overrides import given, load_with_flags
    from mesh_sim.sim_progress import sim_progress
    from mesh_sim.testbed import LinkDown, run_testbed

    console = make_console()
    try:
        scenario = load_with_flags(args.scenario, given(args))
        cameras = _cameras(args.camera, scenario.agent.agents)
        with run_folder(args.out, scenario.name) as run_dir:
            if args.lockstep:
                if args.command == "testbed":
                    raise ValueError("--lockstep runs every agent in one process: nothing to spread over hosts")
                if args.rerun not in ("save", "off"):
                    raise ValueError("--lockstep records with --rerun save or off")
                if args.vehicle != "kinematic":
                    raise ValueError("--lockstep flies the kinematic models (the autopilots run on the wall clock)")
                if args.restart:
                    raise ValueError("--restart is for live runs: lockstep agents do not die")
                if args.zenoh_config:
                    raise ValueError("--zenoh-config is for live runs: lockstep agents share an in-memory bus")
                with sim_progress(make_console(stderr=True), f"{scenario.name}: {scenario.agent.agents} agents "
                                  "(lockstep)", scenario.agent.duration) as advance:
                    metrics = run_lockstep(scenario, run_dir, rerun=args.rerun, cameras=cameras, advance=advance)
            else:
                options = dict(speed=args.speed, rerun=args.rerun, console=console, cameras=cameras,
                               vehicle=args.vehicle, restart=args.restart)
                if args.command == "testbed":
                    if args.zenoh_config:
                        raise ValueError("--zenoh-config is for skymesh run: the test bed opens a router per host")
                    outcome = run_testbed(scenario, run_dir, [LinkDown.parse(spec) for spec in args.link_down],
                                          args.tbf_rate, args.tbf_burst, args.router_link, args.tbf_per_link,
                                          **options)
                else:
                    outcome = Launcher(scenario, run_dir, zenoh_config=args.zenoh_config, **options).run()
                metrics = outcome.metrics
            metrics = judge(run_dir, metrics)  # deadlines missed, a failed sensor: "completed with warnings"
    except (ValueError, OSError) as err:
        return usage_error(f"skymesh {args.command}", err)
    console.print(summary_table(metrics))
    if (fire_map := grid_table(metrics)) is not None:
        console.print(fire_map)
    status = metrics["status"]
    for warning in metrics.get("warnings", []):
        console.print(f"warning: {warning}", style="yellow", highlight=False)
    if status.startswith("failed"):
        console.print(status, style="bold red", highlight=False)
    console.print(f"Results: {run_dir}  (metrics.json, plots/"
                  + (", logs/" if not args.lockstep else "")
                  + (f", recording.rrd: open with `{_viewer()} {run_dir / 'recording.rrd'}`" if args.rerun == "save"
                     else "") + ")",
                  highlight=False)
    if status in STOPPED_BY:
        return STOPPED_BY[status]
    return 0 if status in ("completed", WITH_WARNINGS) else 1


def _viewer() -> str:
    """The Rerun viewer to open a recording with: this environment's (``mesh_sim.viewer``), else ``rerun``."""
    from mesh_sim.viewer import ViewerError, viewer_executable

    try:
        return viewer_executable()
    except ViewerError:
        return "rerun"


def _cameras(specs: list[str], agents: int) -> dict[str, str]:
    """``["uav0=clip.avi", ...]`` -> ``{"uav0": "clip.avi"}``, each source checked to open (then released)."""
    from agent.sensors.video_source import VideoSource

    cameras: dict[str, str] = {}
    names = {f"uav{i}" for i in range(agents)}
    for spec in specs:
        name, sep, source = spec.partition("=")
        if not sep or not source:
            raise ValueError(f"--camera {spec!r}: expected AGENT=SOURCE, e.g. uav0=clip.avi")
        if name not in names:
            raise ValueError(f"--camera {spec!r}: no agent {name!r} in this run (agents are uav0..uav{agents - 1})")
        if name in cameras:
            raise ValueError(f"--camera: {name} is given twice")
        try:
            VideoSource(source).close()
        except ValueError as err:
            raise ValueError(f"--camera {name}: {err}") from None
        cameras[name] = source
    return cameras


def _view(args) -> int:
    if args.recording is not None:
        return _view_recording(args)
    if args.fleet is None:
        return usage_error("skymesh view", "give --fleet NAME (a live fleet) or --web --recording FILE")
    from mesh_sim.observer import main as observer_main

    argv = ["--fleet", args.fleet]
    for endpoint in args.connect:
        argv += ["--connect", endpoint]
    for flag, value in (("--zenoh-config", args.zenoh_config), ("--save", args.save),
                        ("--connect-viewer", args.connect_viewer), ("--duration", args.duration),
                        ("--web", args.web), ("--grpc-port", args.grpc_port), ("--web-host", args.web_host)):
        if value is not None:
            argv += [flag, str(value)]
    if args.save is None and args.connect_viewer is None and args.web is None:
        argv.append("--spawn")
    return observer_main(argv)


def _view_recording(args) -> int:
    """``skymesh view --web --recording FILE``: a finished run's recording served to browsers until stopped."""
    if args.web is None:
        return usage_error("skymesh view", "--recording is served with --web (open it natively with "
                           f"`{_viewer()} {args.recording}`)")
    if args.fleet or args.connect or args.zenoh_config or args.save or args.connect_viewer or args.duration:
        return usage_error("skymesh view", "--recording serves a file: give it without --fleet, --connect, "
                           "--zenoh-config, --save, --connect-viewer and --duration")
    from mesh_sim.observer_web import serve_recording_until_stopped
    from mesh_sim.viewer import ViewerError

    try:
        serve_recording_until_stopped(args.recording, web_of(args))
    except ViewerError as err:
        return usage_error("skymesh view", err)
    return 0


def _compare(args) -> int:
    from mesh_sim.run_compare import RunFolderError, compare, compare_tree, difference_lines, difference_table

    try:
        found = (compare_tree(args.before, args.after, args.rtol) if args.tree
                 else compare(args.before, args.after, args.rtol))
    except (RunFolderError, OSError, ValueError) as err:
        return usage_error("skymesh compare", err)
    console = make_console()

    def show(differences, title: str, indent: str = "") -> None:
        if args.plain:
            for line in difference_lines(differences, args.limit):
                print(indent + line)
        else:
            console.print(difference_table(differences, title, args.limit))

    if not args.tree:
        if not found:
            within = f", floats within {args.rtol:g}" if args.rtol else ""
            print(f"identical: {args.before} and {args.after} (volatile fields aside{within})")
            return 0
        show(found, f"{len(found)} difference(s): {args.before} -> {args.after}")
        return 1
    for pair in found:
        print(pair.summary())
        if args.details and pair.differences:
            show(pair.differences, pair.name, indent="  ")
    same = sum(pair.identical for pair in found)
    print(f"{same} of {len(found)} pairs identical")
    return 0 if same == len(found) else 1


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``skymesh`` console script; returns the exit code."""
    args = build_parser().parse_args(argv)
    if args.command == "bench":
        return _bench(args)
    if args.command == "view":
        return _view(args)
    if args.command == "compare":
        return _compare(args)
    if args.command == "autopilot":
        from mesh_sim.autopilot.cli import run_from_args

        return run_from_args(args)
    if args.command == "router":
        from mesh_sim.router import run_from_args as run_router

        return run_router(args)
    if args.command == "stress":
        args.name, args.list = "stress", False
        return _bench(args)
    return _run(args)


if __name__ == "__main__":
    sys.exit(main())
