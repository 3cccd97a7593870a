"""``skymesh bench mavlink``: the autopilot simulator under a pymavlink client — setpoint response time against
the bare pymavlink UDP round trip, telemetry rates achieved against requested, CPU per simulator process.

Set-up: ``simulators`` processes of ``python -m mesh_sim.autopilot`` (:class:`mesh_sim.autopilot.process.
AutopilotProcess`, free ports, position valid at once) and one echo process (``python -m mesh_sim.bench.mavlink
--echo PORT``, a hidden mode of this module: pymavlink receives a message on UDP and sends it back). This
process is the offboard computer of every simulator (pymavlink ``udpin`` on each offboard port) and streams
each one a position setpoint at 20 Hz, as MAVSDK does, from a single loop.

1. **Rates**: after arming and climbing to ``HOVER_HEIGHT`` in offboard, the messages of every simulator are
   counted for ``window`` seconds at PX4's ``MAVLINK_MODE_ONBOARD`` default rates
   (:data:`mesh_sim.autopilot.streams.ONBOARD_RATES`); then LOCAL_POSITION_NED is set to
   ``TRIAL_LPN_RATE`` with MAV_CMD_SET_MESSAGE_INTERVAL and its rate is counted again during the trials.
2. **CPU**: ``utime + stime`` of each simulator from ``/proc/PID/stat`` over the rates window (a hovering
   vehicle streaming the default rates), as a share of one core.
3. **Setpoint response**: from rest, a new position setpoint ``STEP`` metres away (north and east in turn, always
   forward, so the decay of the previous step never looks like a response); the time from sending it to the
   first LOCAL_POSITION_NED whose velocity along the step has grown by ``RESPONSE_THRESHOLD`` since the send.
   It includes the physics tick (:data:`mesh_sim.autopilot.simulator.PHYSICS_RATE`) and the LOCAL_POSITION_NED
   interval, which bound it from below: ``response_floor_ms`` says by how much. Beside it, the **bare
   round trip**: a PING sent with pymavlink to the echo and received back with pymavlink, same machine, same
   run; the ratio response / bare is the result.
"""

from __future__ import annotations

import argparse
import math
import os
import select
import subprocess
import sys
import time
from dataclasses import dataclass, field

import numpy as np

from agent.vehicles.mavlink_protocol import PX4_MAIN_OFFBOARD, mavlink, mavutil
from mesh_sim.autopilot.process import REPO, AutopilotProcess, free_udp_ports
from mesh_sim.autopilot.simulator import PHYSICS_RATE
from mesh_sim.autopilot.streams import ONBOARD_RATES
from mesh_sim.bench import common

NAME = "mavlink"
QUICK = {"simulators": 2, "trials": 12, "echoes": 300, "window": 2.0}
FULL = {"simulators": 4, "trials": 40, "echoes": 2000, "window": 5.0}
HOVER_HEIGHT = 2.0  # m
STEP = 0.5  # m per setpoint step
TRIAL_PERIOD = 0.4  # s between steps
TRIAL_LPN_RATE = 100.0  # Hz of LOCAL_POSITION_NED during the trials
RESPONSE_THRESHOLD = 0.02  # m/s of velocity change along the step
SETPOINT_PERIOD = 0.05  # s: 20 Hz, as MAVSDK streams offboard setpoints
RATE_TOLERANCE = 0.1  # goal: achieved rates within 10 % of requested (chosen here)
CPU_GOAL = 0.20  # goal: a simulator at PX4's default onboard rates below 20 % of a core (chosen here: four
#                  vehicles and their agents must fit on a 2-core machine)
IGNORE_ALL_BUT_POSITION = 0b110111111000
CLK_TCK = os.sysconf("SC_CLK_TCK")


def cpu_seconds(pid: int) -> float:
    """``utime + stime`` of a process in seconds (``/proc/PID/stat`` fields 14 and 15)."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLK_TCK


@dataclass
class Client:
    """The offboard computer of one simulator: its link, the setpoint it streams, what it has received."""

    process: AutopilotProcess
    link: object = None
    setpoint: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, -HOVER_HEIGHT]))
    next_setpoint: float = 0.0
    counts: dict = field(default_factory=dict)
    last: dict = field(default_factory=dict)
    acks: dict = field(default_factory=dict)

    def connect(self) -> None:
        self.link = mavutil.mavlink_connection(f"udpin:127.0.0.1:{self.process.offboard_remote_port}",
                                               source_system=245, source_component=190)
        if self.link.wait_heartbeat(timeout=10) is None:
            raise RuntimeError(f"no heartbeat from the simulator (pid {self.process.pid})")

    def pump(self) -> list:
        """Stream the setpoint when due and read what has arrived; the new LOCAL_POSITION_NEDs."""
        now = time.monotonic()
        if now >= self.next_setpoint:
            x, y, z = self.setpoint
            self.link.mav.set_position_target_local_ned_send(0, 0, 0, mavlink.MAV_FRAME_LOCAL_NED,
                                                             IGNORE_ALL_BUT_POSITION, x, y, z, 0, 0, 0, 0, 0, 0, 0, 0)
            self.next_setpoint = max(self.next_setpoint + SETPOINT_PERIOD, now)
        positions = []
        while (msg := self.link.recv_msg()) is not None:
            kind = msg.get_type()
            self.counts[kind] = self.counts.get(kind, 0) + 1
            self.last[kind] = msg
            if kind == "COMMAND_ACK":
                self.acks[msg.command] = msg.result
            elif kind == "LOCAL_POSITION_NED":
                positions.append((time.monotonic(), msg))
        return positions

    def command(self, clients, cmd: int, *params: float) -> int:
        params = list(params) + [0.0] * (7 - len(params))
        self.acks.pop(cmd, None)
        self.link.mav.command_long_send(self.process.ready["sysid"], 1, cmd, 0, *params)
        pump_all(clients, 5.0, until=lambda: cmd in self.acks)
        return self.acks.get(cmd, -1)


def pump_all(clients: list[Client], seconds: float, until=None) -> None:
    """Pump every client for ``seconds`` or until ``until()``; waits on the sockets in between."""
    end = time.monotonic() + seconds
    while time.monotonic() < end and not (until is not None and until()):
        for client in clients:
            client.pump()
        select.select([c.link.port for c in clients], [], [], 0.005)


def _take_off(clients: list[Client]) -> None:
    pump_all(clients, 0.3)
    for client in clients:
        arm = client.command(clients, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)
        mode = client.command(clients, mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                              PX4_MAIN_OFFBOARD, 0)
        if (arm, mode) != (mavlink.MAV_RESULT_ACCEPTED, mavlink.MAV_RESULT_ACCEPTED):
            raise RuntimeError(f"simulator {client.process.pid} refused to arm or to go offboard: {arm}, {mode}")

    def hovering():
        return all((lpn := c.last.get("LOCAL_POSITION_NED")) is not None and abs(lpn.z + HOVER_HEIGHT) < 0.05
                   and abs(lpn.vz) < 0.05 for c in clients)

    pump_all(clients, 15.0, until=hovering)


def _measure_rates(clients: list[Client], window: float) -> tuple[list[dict], list[float]]:
    for client in clients:
        client.counts.clear()
    cpu_before = [cpu_seconds(c.process.pid) for c in clients]
    start = time.monotonic()
    pump_all(clients, window)
    elapsed = time.monotonic() - start
    cpu = [(cpu_seconds(c.process.pid) - before) / elapsed for c, before in zip(clients, cpu_before, strict=True)]
    rows = []
    for msg_id, requested in ONBOARD_RATES.items():
        kind = mavlink.mavlink_map[msg_id].msgname
        achieved = [c.counts.get(kind, 0) / elapsed for c in clients]
        rows.append({"message": kind, "requested_hz": requested, "achieved_hz": float(np.mean(achieved)),
                     "achieved_min_hz": min(achieved), "phase": "PX4 onboard defaults"})
    return rows, cpu


def _trials(clients: list[Client], trials: int) -> tuple[list[float], list[float]]:
    """Setpoint response times (s) of every simulator, and the LOCAL_POSITION_NED rate each achieved meanwhile."""
    responses, rates = [], []
    for client in clients:
        result = client.command(clients, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL,
                                mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED, 1e6 / TRIAL_LPN_RATE)
        if result != mavlink.MAV_RESULT_ACCEPTED:
            raise RuntimeError(f"SET_MESSAGE_INTERVAL refused: {result}")
    pump_all(clients, 0.3)
    for client in clients:
        client.counts.pop("LOCAL_POSITION_NED", None)
        start = time.monotonic()
        for k in range(trials):
            axis = k % 2
            velocity_before = getattr(client.last["LOCAL_POSITION_NED"], ("vx", "vy")[axis])
            client.setpoint = client.setpoint.copy()
            client.setpoint[axis] += STEP
            client.next_setpoint = 0.0  # send the new setpoint now
            sent = time.monotonic()
            deadline = sent + TRIAL_PERIOD
            answered = None
            while time.monotonic() < deadline:
                for others in clients:
                    if others is not client:
                        others.pump()
                for at, lpn in client.pump():
                    if answered is None and getattr(lpn, ("vx", "vy")[axis]) - velocity_before > RESPONSE_THRESHOLD:
                        answered = at - sent
                select.select([client.link.port], [], [], 0.002)
            responses.append(math.inf if answered is None else answered)
        rates.append(client.counts.get("LOCAL_POSITION_NED", 0) / (time.monotonic() - start))
    return responses, rates


def _echo_round_trips(count: int) -> list[float]:
    """Round trips (s) of a PING through the pymavlink echo process."""
    (port,) = free_udp_ports(1)
    echo = subprocess.Popen([sys.executable, "-m", "mesh_sim.bench.mavlink", "--echo", str(port), "--parent-pid",
                             str(os.getpid())], cwd=REPO, stdout=subprocess.PIPE, text=True)
    try:
        if echo.stdout.readline().strip() != "ready":
            raise RuntimeError("the echo process did not start")
        link = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=245, source_component=190)
        try:
            rtts = []
            for seq in range(count + 10):  # 10 warm-up round trips
                sent = time.monotonic()
                link.mav.ping_send(int(sent * 1e6), seq, 1, 1)
                msg = link.recv_match(type="PING", blocking=True, timeout=1.0)
                if seq >= 10:
                    rtts.append(time.monotonic() - sent if msg is not None and msg.seq == seq else math.inf)
            return rtts
        finally:
            link.close()
    finally:
        echo.kill()
        echo.wait(timeout=10)


def _echo_main(port: int, parent_pid: int) -> None:
    """The echo process: every MAVLink message received on ``port`` is sent back to its sender, re-encoded."""
    link = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=1, source_component=1)
    print("ready", flush=True)
    while os.getppid() == parent_pid:
        msg = link.recv_match(blocking=True, timeout=0.5)
        if msg is not None and msg.get_type() != "BAD_DATA":
            link.mav.send(msg)


def _stats_ms(values: list[float]) -> dict:
    finite = np.array([v for v in values if math.isfinite(v)]) * 1e3
    return {
        "count": len(values), "lost": len(values) - len(finite),
        "median_ms": float(np.median(finite)) if len(finite) else math.nan,
        "p90_ms": float(np.percentile(finite, 90)) if len(finite) else math.nan,
        "max_ms": float(np.max(finite)) if len(finite) else math.nan,
    }


def run(quick: bool = False, repeats: int | None = None) -> dict:
    """Measure (see the module docstring). ``repeats`` scales the number of trials and echoes (tests: 1-2)."""
    settings = dict(QUICK if quick else FULL)
    if repeats is not None:
        if repeats < 1:
            raise ValueError(f"repeats must be at least 1, got {repeats}")
        settings.update(simulators=1 if repeats < 3 else settings["simulators"], trials=4 * repeats,
                        echoes=50 * repeats, window=1.0 if repeats < 3 else settings["window"])
    load_before = os.getloadavg()
    processes: list[AutopilotProcess] = []
    clients: list[Client] = []
    try:
        for _ in range(settings["simulators"]):
            processes.append(AutopilotProcess.start("--position-valid-after", "0", quiet=True))
        clients = [Client(p) for p in processes]
        for client in clients:
            client.connect()
        _take_off(clients)
        rate_rows, cpu = _measure_rates(clients, settings["window"])
        responses, trial_rates = _trials(clients, settings["trials"])
    finally:
        for client in clients:
            if client.link is not None:
                client.link.close()
        counters = [p.stop() for p in processes]
    echoes = _echo_round_trips(settings["echoes"])
    rate_rows.append({"message": "LOCAL_POSITION_NED", "requested_hz": TRIAL_LPN_RATE,
                      "achieved_hz": float(np.mean(trial_rates)), "achieved_min_hz": min(trial_rates),
                      "phase": "SET_MESSAGE_INTERVAL during the trials"})
    for row in rate_rows:
        row["ratio"] = row["achieved_hz"] / row["requested_hz"]
    response, bare = _stats_ms(responses), _stats_ms(echoes)
    floor_ms = 1e3 * (1.0 / PHYSICS_RATE + 1.0 / TRIAL_LPN_RATE)
    rows = [
        {"measurement": "setpoint -> first LOCAL_POSITION_NED responding", **response},
        {"measurement": "bare pymavlink UDP echo round trip", **bare},
    ]
    ratio = response["median_ms"] / bare["median_ms"]
    return {
        "benchmark": NAME,
        "settings": {"quick": quick, **settings, "step_m": STEP, "trial_period_s": TRIAL_PERIOD,
                     "physics_rate_hz": PHYSICS_RATE, "trial_lpn_rate_hz": TRIAL_LPN_RATE,
                     "load_average_before": list(load_before), "load_average_after": list(os.getloadavg())},
        "environment": common.environment(("numpy", "pymavlink")),
        "rows": rows,
        "rates": rate_rows,
        "cpu_per_simulator": cpu,
        "simulator_counters": counters,
        "response_over_bare": ratio,
        "response_floor_ms": floor_ms,
        "goals": {
            "description": f"achieved telemetry rates within {RATE_TOLERANCE:.0%} of requested; a simulator at PX4's "
                           f"default onboard rates below {CPU_GOAL:.0%} of a core; setpoint response median within "
                           "the physics tick + LOCAL_POSITION_NED interval + 5 ms (chosen here)",
            "rates_pass": all(abs(r["ratio"] - 1.0) <= RATE_TOLERANCE for r in rate_rows if r["requested_hz"] >= 1.0),
            "cpu_pass": max(cpu) < CPU_GOAL,
            "response_pass": response["median_ms"] <= floor_ms + 5.0,
        },
    }


def report(result: dict, console=None) -> None:
    """Print the tables of a :func:`run` result."""
    console = console or common.make_console()
    s, g = result["settings"], result["goals"]
    console.print(
        f"[bold]{NAME}[/bold]  {'quick' if s['quick'] else 'full'} run: {s['simulators']} simulator process(es), "
        f"{s['trials']} setpoint steps each, {s['echoes']} echoes.  "
        f"{common.machine_line(result['environment'], {'pymavlink': 'pymavlink'})}.  Load average before/after: "
        f"{s['load_average_before'][0]:.2f} / {s['load_average_after'][0]:.2f}",
        highlight=False,
    )
    common.print_table(
        console, "Setpoint response vs the bare pymavlink round trip (ms)",
        [("measurement", "left"), "count", "lost", "median", "p90", "max"],
        [[r["measurement"], r["count"], r["lost"], common.fmt_ms(r["median_ms"]), common.fmt_ms(r["p90_ms"]),
          common.fmt_ms(r["max_ms"])] for r in result["rows"]],
        f"response ÷ bare (medians): {common.fmt_ratio(result['response_over_bare'])}.  The response waits for the "
        f"next physics tick ({1e3 / s['physics_rate_hz']:.0f} ms) and the next LOCAL_POSITION_NED "
        f"({1e3 / s['trial_lpn_rate_hz']:.0f} ms at {s['trial_lpn_rate_hz']:g} Hz): a floor of about "
        f"{result['response_floor_ms']:.0f} ms at worst, half that on average.  "
        f"{verdict_text(g['response_pass'])}",
    )
    common.print_table(
        console, "Telemetry rates, achieved vs requested (Hz, mean over simulators)",
        [("message", "left"), "requested", "achieved", "slowest", "ratio", ("phase", "left")],
        [[r["message"], f"{r['requested_hz']:g}", f"{r['achieved_hz']:.2f}", f"{r['achieved_min_hz']:.2f}",
          f"{r['ratio']:.3f}", r["phase"]] for r in result["rates"]],
        f"Rates below 1 Hz are listed but not judged (a window of {s['window']:g} s holds one or none).  "
        f"{verdict_text(g['rates_pass'])}",
    )
    cpu = ", ".join(f"{100 * c:.1f} %" for c in result["cpu_per_simulator"])
    console.print(f"CPU per simulator process (utime + stime from /proc over the rates window, share of one core): "
                  f"{cpu}.  {verdict_text(g['cpu_pass'])}", highlight=False)


def verdict_text(ok: bool) -> str:
    return f"Goal: {common.verdict(ok)}"


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description="the echo process of skymesh bench mavlink (internal)")
    parser.add_argument("--echo", type=int, required=True, metavar="PORT")
    parser.add_argument("--parent-pid", type=int, required=True)
    args = parser.parse_args(argv)
    _echo_main(args.echo, args.parent_pid)


if __name__ == "__main__":
    main()
