"""The simulator process: two MAVLink links, the flight controller, telemetry streams, one real-time loop.

Per iteration (one thread, ``selectors``): read both sockets into their delay lines, handle the messages
that came out, step the flight controller at :data:`PHYSICS_RATE`, send the STATUSTEXTs it produced on
every link and the streams that are due, and flush the outbound delay lines; then sleep until the next of
those deadlines or a datagram. Time is ``time.monotonic()`` since boot, the ``time_boot_ms`` of every
message.
"""

from __future__ import annotations

import json
import logging
import math
import os
import selectors
import threading
import time

from agent.runtime import parent_alive, usage_error, write_json
from agent.vehicles import vehicle_from_config
from agent.vehicles.mavlink_protocol import mavlink
from mesh_sim.autopilot.battery import Battery
from mesh_sim.autopilot.counters import Counters
from mesh_sim.autopilot.flight import FlightController
from mesh_sim.autopilot.gimbal import Gimbal
from mesh_sim.autopilot.link import Link
from mesh_sim.autopilot.options import AutopilotOptions
from mesh_sim.autopilot.params import Params
from mesh_sim.autopilot.router import MessageRouter
from mesh_sim.autopilot.streams import NORMAL_RATES, ONBOARD_RATES, StreamSchedule
from mesh_sim.autopilot.telemetry import Telemetry

log = logging.getLogger("skymesh.autopilot")

PHYSICS_RATE = 50.0  # Hz: flight-controller steps; chosen here (the models sub-step at 50 Hz anyway)
PARENT_CHECK_PERIOD = 0.5  # s
MAX_WAIT = 0.05  # s: longest sleep, so that stop and the parent are noticed; chosen here
VEHICLE_TYPES = {"multirotor": mavlink.MAV_TYPE_QUADROTOR, "fixed_wing": mavlink.MAV_TYPE_FIXED_WING}


class Simulator:
    def __init__(self, options: AutopilotOptions):
        self.options = options
        sysid = options.system_id
        model = vehicle_from_config({"kind": options.vehicle, **dict(options.vehicle_params)},
                                    [options.north, options.east, -options.altitude],
                                    math.radians(options.heading_deg))
        self.params = Params(MAV_SYS_ID=sysid, MAV_TYPE=VEHICLE_TYPES[options.vehicle])
        battery = Battery(flight_time=options.flight_time, remaining=options.battery)
        self.controller = FlightController(model, self.params, battery, Gimbal(), options.position_valid_after,
                                           airborne=options.altitude > 0)
        self.telemetry = Telemetry(self.controller, options.origin, sysid, VEHICLE_TYPES[options.vehicle])
        self.counters = Counters()
        self.router = MessageRouter(self.controller, self.telemetry, self.params, self.counters)
        latency = options.latency_ms / 1000.0
        supports = self.telemetry.supports
        self.links: list[Link] = []
        try:
            for name, bind, remote, rates in (
                ("offboard", options.offboard_bind, options.offboard_remote, ONBOARD_RATES),
                ("gcs", options.gcs_bind, options.gcs_remote, NORMAL_RATES),
            ):
                self.links.append(Link(name, bind, remote, sysid, self.counters, StreamSchedule(rates, supports),
                                       latency))
        except OSError:
            self.close()
            raise

    def close(self) -> None:
        for link in self.links:
            link.close()

    def describe(self) -> dict:
        """What a parent needs to talk to this simulator (the ``ready`` line)."""
        return {
            "event": "ready",
            "pid": os.getpid(),
            "sysid": self.options.system_id,
            "vehicle": self.options.vehicle,
            "links": {link.name: {"bind": list(link.bind), "remote": list(link.remote)} for link in self.links},
        }

    def run(self, stop: threading.Event) -> None:
        """Run in real time until ``stop``, the duration, or the parent's death."""
        boot = time.monotonic()
        selector = selectors.DefaultSelector()
        for link in self.links:
            selector.register(link, selectors.EVENT_READ)
        physics_period = 1.0 / PHYSICS_RATE
        next_physics = 0.0
        next_parent_check = PARENT_CHECK_PERIOD
        parent = self.options.parent_pid
        try:
            while not stop.is_set():
                now = time.monotonic() - boot
                if self.options.duration is not None and now >= self.options.duration:
                    break
                if parent is not None and now >= next_parent_check:
                    next_parent_check = now + PARENT_CHECK_PERIOD
                    if not parent_alive(parent):
                        log.error("parent process %d is gone; stopping", parent)
                        break
                for link in self.links:
                    link.read(now)
                    for msg in link.messages(now):
                        for reply in self._handle(msg, link):
                            link.send(reply, now)
                if now >= next_physics:
                    self.controller.step(now)
                    next_physics = max(next_physics + physics_period, now)
                self._send_statustexts(now)
                for link in self.links:
                    for msg_id in link.streams.due(now):
                        msg = self.telemetry.message(msg_id)
                        if msg is not None:
                            link.send(msg, now)
                    link.flush(now)
                wake = min([next_physics, *(link.streams.next_due(now) for link in self.links),
                            *(t for link in self.links if (t := link.next_due()) is not None)])
                timeout = min(max(wake - (time.monotonic() - boot), 0.0), MAX_WAIT)
                if timeout > 0:
                    selector.select(timeout)
        finally:
            selector.close()

    def _handle(self, msg, link: Link) -> list:
        """The router's replies; a message that makes a handler fail is a defect to log and count, never a stop."""
        try:
            return self.router.handle(msg, link.streams)
        except Exception:
            log.exception("handling %s failed", msg.get_type())
            self.counters.reject("handler_error")
            return []

    def _send_statustexts(self, now: float) -> None:
        texts, self.controller.statustexts = self.controller.statustexts, []
        for severity, text in texts:
            log.info("%s", text)
            for link in self.links:
                link.send(self.telemetry.statustext(severity, text), now)

    def report(self) -> dict:
        """The final counters (the ``stopped`` line and the ``--stats`` file)."""
        return {"event": "stopped", "counters": self.counters.as_dict()}


def run(options: AutopilotOptions, stop: threading.Event) -> int:
    """Start, print the ``ready`` line, run until stopped, print (and optionally write) the counters."""
    try:
        simulator = Simulator(options)
    except OSError as error:
        ports = ", ".join(f"{host}:{port}" for host, port in (options.offboard_bind, options.gcs_bind))
        return usage_error("skymesh autopilot", f"cannot bind its UDP ports {ports}: {error.strerror}")
    except ValueError as error:  # a --vehicle-param the model refuses
        return usage_error("skymesh autopilot", error)
    try:
        print(json.dumps(simulator.describe()), flush=True)
        simulator.run(stop)
    finally:
        simulator.close()
        report = simulator.report()
        if options.stats is not None:
            write_json(options.stats, report)
        print(json.dumps(report), flush=True)
    return 0
