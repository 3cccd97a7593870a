"""``python -m agent``: run one agent process (normally started by ``skymesh run``).

Example: ``python -m agent --id uav0 --index 0 --fleet demo --scenario run/scenario.json
--connect tcp/127.0.0.1:7447 --epoch 1700000000.0 --out run/``. With ``--zenoh-config FILE`` the agent
uses a standard Zenoh JSON5 configuration instead (a real deployment across machines: ``deploy/agent.json5``
connects over mutual TLS with the agent's certificate).

``--mavlink URL`` flies a real (or SITL) PX4 or ArduPilot autopilot at a pymavlink connection string
(``udpin:0.0.0.0:14540`` for PX4 SITL, ``tcp:127.0.0.1:5760`` for ArduPilot SITL, ``/dev/ttyUSB0``) instead of the
scenario's vehicle (:mod:`agent.vehicles.mavlink`; a scenario whose vehicle is already ``mavlink`` keeps its other
keys). A link that cannot be opened, an autopilot that never sends a heartbeat or refuses to arm is an error (exit
code 2) before the agent's loop starts.

``--camera SOURCE`` replaces the synthetic camera with an OpenCV video source (a file path, a device
index such as ``0``, a stream URL): one frame is read per agent step, the pose comes from the vehicle as
usual. A source that cannot be opened is an error at start (exit code 2), and so are a Zenoh router that cannot be
reached (or that refuses the agent's certificate: Zenoh does not tell the two apart) and an ``--index`` outside the
scenario's team.

The process imports only what its scenario uses (issue 12): OpenCV comes with a camera (the ``camera``
sensor, ``--camera``, or a ``[grid]``'s thermal camera), never with the geometric bearing sensor; neither
matplotlib nor Rerun is ever imported here (plots and recordings are the launcher's and the observer's).
scipy.optimize is imported at start although it is the largest import left (~0.4 s and ~10 MB of private memory
beyond scipy.linalg and scipy.special): the tracker's association (``linear_sum_assignment``) runs at nearly
every step and covariance intersection at every fallback, so deferring it would only move its cost into the
first steps, as deadline misses.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
import threading
import time
from dataclasses import replace
from pathlib import Path

from agent.agent import Agent
from agent.config import AgentScenario, read_scenario_file
from agent.memory import fix_mmap_threshold
from agent.net.fleet_key import read_key_file
from agent.net.keys import Keys
from agent.net.zenoh_transport import ZenohTransport, load_config
from agent.runtime import (
    LoopStats,
    SimClock,
    install_stop_handlers,
    run_steps,
    staggered_phase,
    usage_error,
    wait_for_epoch,
    write_json,
)
from agent.vehicles.base import VehicleError
from agent.warmup import warm_up

log = logging.getLogger("skymesh.agent")


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m agent", description="Run one skymesh agent process.")
    p.add_argument("--id", required=True, help="agent name, unique in the fleet")
    p.add_argument("--index", type=int, required=True, help="0-based index of the agent in the team")
    p.add_argument("--fleet", required=True, help="fleet name (isolates concurrent runs)")
    p.add_argument("--scenario", required=True, help="scenario TOML (or the launcher's scenario.json)")
    p.add_argument("--connect", action="append", default=[], help="Zenoh router endpoint, e.g. tcp/127.0.0.1:7447")
    p.add_argument("--zenoh-config", help="a Zenoh JSON5 config file (instead of --connect)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--incarnation", type=int, default=0,
                   help="this life of the agent: a restarted agent gets the next one (agent.net.incarnation)")
    p.add_argument("--epoch", type=float, default=None, help="wall time of simulation t=0 (default: now)")
    p.add_argument("--speed", type=float, default=1.0, help="simulation seconds per wall second")
    p.add_argument("--duration", type=float, default=None, help="override the scenario duration [s]")
    p.add_argument("--fleet-key-file", help="file holding the fleet's HMAC key")
    p.add_argument("--out", default=".", help="folder for agent-<id>.json")
    p.add_argument("--parent-pid", type=int, help="exit when this process (the launcher) is gone")
    p.add_argument("--epoch-file", help="wait for the launcher to write the start time here (instead of --epoch)")
    p.add_argument("--ready-file", help="created once this process is ready (with --epoch-file)")
    p.add_argument("--camera", metavar="SOURCE",
                   help="an OpenCV video source (file, device index, stream URL) instead of the synthetic camera")
    p.add_argument("--mavlink", metavar="URL",
                   help="fly the autopilot at this pymavlink connection string (udpin:0.0.0.0:14540, "
                        "tcp:127.0.0.1:5760, /dev/ttyUSB0) instead of the scenario's vehicle")
    return p.parse_args(argv)


def with_mavlink(vehicle: dict, url: str) -> dict:
    """The scenario's ``[vehicle]`` table flying the autopilot at ``url``: ``{"kind": "mavlink", "url": url}``, plus
    the table's own keys if it already is a MAVLink vehicle (its ``autopilot``, timeouts...), or else the simulated
    vehicle's speed (a multirotor's ``max_speed``, a fixed wing's ``airspeed``) as its ``cruise_speed`` and its
    ``max_accel``: the mission is flown as the scenario meant."""
    if vehicle.get("kind") == "mavlink":
        return {**vehicle, "url": url}
    speed = vehicle.get("max_speed", vehicle.get("airspeed"))
    carried = {"cruise_speed": speed, "max_accel": vehicle.get("max_accel")}
    return {"kind": "mavlink", "url": url, **{key: value for key, value in carried.items() if value is not None}}


def _check_index(index: int, agents: int) -> None:
    """``--index`` must name one of the scenario's agents: another index would fly a start position and a
    stagger phase that no agent of the team has (silently, as a duplicate of ``index % agents``)."""
    if not 0 <= index < agents:
        raise ValueError(f"--index {index} is not an agent of this scenario: it has {agents} (0..{agents - 1})")


def _open_camera(source: str):
    """The external video source of ``--camera`` (OpenCV is imported only then)."""
    from agent.sensors.video_source import VideoSource

    return VideoSource(source)


def main(argv=None) -> int:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    fix_mmap_threshold()  # freed frames go back to the system, not to a growing heap (agent.memory)
    args = parse_args(argv)
    try:
        scenario = AgentScenario.from_dict(read_scenario_file(args.scenario))
        if args.mavlink is not None:
            scenario = replace(scenario, vehicle=with_mavlink(scenario.vehicle, args.mavlink))
        _check_index(args.index, scenario.agents)
        key = read_key_file(args.fleet_key_file) if args.fleet_key_file else None
        keys = Keys(args.fleet)
        config = load_config(args.connect, args.zenoh_config)
        camera = _open_camera(args.camera) if args.camera is not None else None
        subscribe = keys.agent_subscriptions(scenario.senders_to(args.id))
        transport = ZenohTransport(args.id, keys, config, subscribe)  # SessionError: no router
    except (OSError, ValueError) as err:
        return usage_error(f"agent {args.id}", err)
    duration = args.duration if args.duration is not None else scenario.duration
    try:
        agent = Agent(args.id, args.index, scenario, transport, keys, seed=args.seed, fleet_key=key, camera=camera,
                      incarnation=args.incarnation)
    except (VehicleError, ValueError) as err:  # a vehicle that cannot fly: nothing has run yet
        transport.close()
        return usage_error(f"agent {args.id}", err)
    warm_up(scenario)  # before reporting ready: the first steps then cost what the next ones do
    stop = threading.Event()
    install_stop_handlers(stop)
    epoch = args.epoch if args.epoch is not None else time.time()
    if args.epoch_file:
        epoch = wait_for_epoch(args.epoch_file, args.ready_file or f"{args.epoch_file}.{args.id}", stop,
                               args.parent_pid)
    try:
        stats = LoopStats() if epoch is None else run_steps(
            agent.step, SimClock(epoch, args.speed), scenario.step, duration, stop, args.parent_pid,
            phase=staggered_phase(args.index, scenario.agents, scenario.step),
        )
    finally:
        transport.close()
        agent.close()
    metrics = {"pid": os.getpid(), "incarnation": args.incarnation, **agent.metrics(), **stats.as_dict(),
               "transport_dropped": transport.dropped}
    try:
        write_json(Path(args.out) / f"agent-{args.id}.json", metrics)
    except OSError as err:
        print(f"agent {args.id}: cannot write its metrics: {err}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
