"""A scripted autopilot for the MAVLink vehicle's tests: the autopilot's side of the wire, in real MAVLink 2
bytes over a real socket on loopback: UDP by default, or TCP (``tcp=True``) as ArduPilot SITL serves it.

Like PX4 SITL's offboard link it sends from its own port to the companion computer's (``udpin``) port. It
heartbeats (1 Hz), streams LOCAL_POSITION_NED and ATTITUDE (20 Hz), SYS_STATUS, BATTERY_STATUS and
EXTENDED_SYS_STATE (1 Hz), GLOBAL_POSITION_INT (5 Hz) and GIMBAL_DEVICE_ATTITUDE_STATUS (10 Hz), answers
COMMAND_LONGs with COMMAND_ACKs (scripted refusals and lost acks), REQUEST_MESSAGE with the message, TIMESYNC
requests with its boot time, and "flies": its position moves with the last SET_POSITION_TARGET_LOCAL_NED's
velocity feed-forward plus a position gain (at most 5 m/s), once armed and in the mode that follows them. It
records everything the vehicle sent.
"""

from __future__ import annotations

import math
import socket
import threading
import time
from collections import defaultdict
from contextlib import contextmanager

import numpy as np

from agent.vehicles import vehicle_from_config
from agent.vehicles.geodesy import ned_to_geodetic
from agent.vehicles.mavlink_protocol import PX4_HOLD, mavlink, px4_modes

ORIGIN = (47.397742, 8.545594, 488.0)  # PX4 SITL's default home (Zurich), lat, lon, alt AMSL
POSITION_GAIN = 3.0  # 1/s: the peer's position loop
MAX_SPEED = 5.0  # m/s: the peer's speed limit (PX4's MPC_XY_VEL_MAX is 12 m/s)


#: The scenario's origin, chosen away from the autopilot's: the autopilot's origin lies near (120, -80, -15) in
#: the scenario's NED frame, so a frame mix-up shows
SCENARIO_ORIGIN = ned_to_geodetic([-120.0, 80.0, 15.0], ORIGIN)


def connect(peer: ScriptedAutopilot, **params):
    """The MAVLink vehicle on ``peer``'s port (take-off to 3 m unless ``params`` say otherwise)."""
    url = f"tcp:127.0.0.1:{peer.address[1]}" if peer.tcp else f"udpin:127.0.0.1:{peer.address[1]}"
    config = {"kind": "mavlink", "url": url, "takeoff_altitude": 3.0, **params}
    return vehicle_from_config(config, [0.0, 0.0, -50.0], 0.0, SCENARIO_ORIGIN)


@contextmanager
def flying_vehicle(**params):
    """A scripted autopilot and the MAVLink vehicle on it, taken off; both closed afterwards."""
    peer = ScriptedAutopilot(free_port())
    try:
        vehicle = connect(peer, **params)
        try:
            wait_for(lambda: vehicle.healthy, timeout=15.0)  # the take-off is over
            yield peer, vehicle
        finally:
            vehicle.close()
    finally:
        peer.close()


def wait_for(condition, timeout: float = 5.0) -> float:
    """Poll ``condition`` every 5 ms; the monotonic time it became true (AssertionError after ``timeout``)."""
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, "condition not met in time"
        time.sleep(0.005)
    return time.monotonic()


def free_port(kind: int = socket.SOCK_DGRAM) -> int:
    """A free loopback port (UDP by default, TCP with ``socket.SOCK_STREAM``)."""
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class ScriptedAutopilot:
    """The autopilot of the module docstring, sending to ``127.0.0.1:port`` (with ``tcp``: serving TCP on ``port``
    to the one client that connects, like ArduPilot SITL's 5760). ``autopilot``: the HEARTBEAT's
    MAV_AUTOPILOT; ``origin``: its EKF origin; ``start``: its local NED position; ``boot_offset``: seconds it
    has been up when created (its ``time_boot_ms`` starts there)."""

    def __init__(self, port: int, *, system: int = 1, autopilot: int = mavlink.MAV_AUTOPILOT_PX4,
                 origin=ORIGIN, start=(0.0, 0.0, 0.0), boot_offset: float = 100.0, battery: int = 80,
                 answer_timesync: bool = True, tcp: bool = False, home_after: float = 0.0):
        self.tcp = tcp
        self.socket = socket.socket(socket.AF_INET, socket.SOCK_STREAM if tcp else socket.SOCK_DGRAM)
        self.socket.bind(("127.0.0.1", port if tcp else 0))
        if tcp:
            self.socket.listen(1)
        self.socket.setblocking(False)
        self.client: socket.socket | None = None  # the TCP client, once connected
        self.address = ("127.0.0.1", port)
        self.system, self.autopilot, self.origin = system, autopilot, origin
        self.mav = mavlink.MAVLink(self, srcSystem=system, srcComponent=1)
        self.parser = mavlink.MAVLink(None)
        self.parser.robust_parsing = True
        self.position = np.array(start, float)
        self.velocity = np.zeros(3)
        self.home = np.array(start, float)
        self.armed, self.custom_mode = False, PX4_HOLD if autopilot == mavlink.MAV_AUTOPILOT_PX4 else 0
        self.battery, self.fault = battery, 0
        self.answer_timesync = answer_timesync
        self.home_after = home_after  # s after creation before HOME_POSITION requests are answered (no position yet)
        self.gimbal_q = [1.0, 0.0, 0.0, 0.0]
        self.target: tuple[np.ndarray, np.ndarray] | None = None  # last setpoint (position, velocity), local
        self.refuse: dict[int, int] = {}  # command -> MAV_RESULT to answer
        self.drop_acks: dict[int, int] = defaultdict(int)  # command -> acks still to lose
        self.silent = threading.Event()  # set: the autopilot says nothing (a lost link)
        self.received: dict[str, list[tuple[float, object]]] = defaultdict(list)  # type -> [(arrival, msg)]
        self.last_heartbeat_sent = self.last_pose_sent = 0.0
        self._created = time.monotonic() - boot_offset
        self.boot_offset = boot_offset
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="scripted autopilot", daemon=True)
        self._thread.start()

    # -- the pymavlink encoder's file, and raw bytes --------------------------------------------------
    def write(self, data: bytes) -> None:
        if not self.tcp:
            self.socket.sendto(data, self.address)
        elif self.client is not None:
            try:
                self.client.sendall(data)
            except OSError:  # the client went away
                self.hang_up()

    send_raw = write

    def hang_up(self) -> None:
        """Close the TCP connection (the autopilot restarts or the cable is pulled)."""
        client, self.client = self.client, None
        if client is not None:
            client.close()

    def boot_ms(self) -> int:
        return int((time.monotonic() - self._created) * 1e3)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self.hang_up()
        self.socket.close()

    def messages(self, kind: str) -> list:
        return [msg for _, msg in self.received[kind]]

    # -- the loop ---------------------------------------------------------------------------------------
    def _run(self) -> None:
        due: dict[str, float] = defaultdict(float)
        last = time.monotonic()
        while not self._stop.is_set():
            self._receive()
            now = time.monotonic()
            self._fly(now - last)
            last = now
            if not self.silent.is_set():
                for name, period in (("heartbeat", 1.0), ("pose", 0.05), ("status", 1.0), ("global", 0.2),
                                     ("gimbal", 0.1)):
                    if now >= due[name]:
                        due[name] = now + period
                        getattr(self, "_send_" + name)()
            time.sleep(0.005)

    def following(self) -> bool:
        """Armed, and in the mode that follows position targets (PX4 OFFBOARD, ArduCopter GUIDED)."""
        if not self.armed:
            return False
        return px4_modes(self.custom_mode)[0] == 6 if self.autopilot == mavlink.MAV_AUTOPILOT_PX4 \
            else self.custom_mode == 4

    def _fly(self, dt: float) -> None:
        if not self.following() or self.target is None:
            self.velocity = np.zeros(3)
            return
        position, velocity = self.target
        command = velocity + POSITION_GAIN * (position - self.position)
        self.velocity = command * min(1.0, MAX_SPEED / max(float(np.linalg.norm(command)), 1e-9))
        self.position = self.position + self.velocity * dt

    def _send_heartbeat(self) -> None:
        base = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (mavlink.MAV_MODE_FLAG_SAFETY_ARMED if self.armed else 0)
        self.mav.heartbeat_send(mavlink.MAV_TYPE_QUADROTOR, self.autopilot, base, self.custom_mode,
                                mavlink.MAV_STATE_ACTIVE)
        self.last_heartbeat_sent = time.monotonic()

    def _send_pose(self) -> None:
        t = self.boot_ms()
        self.mav.local_position_ned_send(t, *self.position, *self.velocity)
        self.last_pose_sent = time.monotonic()
        self.mav.attitude_send(t, 0.01, -0.02, 0.3, 0.0, 0.0, 0.0)

    def _send_status(self) -> None:
        self.mav.sys_status_send(1, 1, 1, 100, 15000, 1000, self.battery, 0, 0, 0, 0, 0, 0)
        self.mav.battery_status_send(0, 0, 0, 2500, [15000] + [65535] * 9, 1000, 100, 100, self.battery, 600, 1,
                                     [0, 0, 0, 0], 0, self.fault)
        landed = mavlink.MAV_LANDED_STATE_IN_AIR if self.armed else mavlink.MAV_LANDED_STATE_ON_GROUND
        self.mav.extended_sys_state_send(0, landed)

    def _send_global(self) -> None:
        lat, lon, alt = ned_to_geodetic(self.position, self.origin)
        self.mav.global_position_int_send(self.boot_ms(), int(lat * 1e7), int(lon * 1e7), int(alt * 1e3),
                                          int(-(self.position[2] - self.home[2]) * 1e3), 0, 0, 0, 0)

    def _send_gimbal(self) -> None:
        flags = mavlink.GIMBAL_DEVICE_FLAGS_YAW_IN_EARTH_FRAME
        self.mav.gimbal_device_attitude_status_send(0, 0, self.boot_ms(), flags, self.gimbal_q, 0, 0, 0, 0, math.nan,
                                                    math.nan, 1)

    def _send_origin(self) -> None:
        lat, lon, alt = self.origin
        self.mav.gps_global_origin_send(int(lat * 1e7), int(lon * 1e7), int(alt * 1e3), 0)

    def _send_home(self) -> None:
        lat, lon, alt = ned_to_geodetic(self.home, self.origin)
        self.mav.home_position_send(int(lat * 1e7), int(lon * 1e7), int(alt * 1e3), *self.home, [1, 0, 0, 0],
                                    0, 0, 0, 0)

    # -- what the vehicle sends -----------------------------------------------------------------------------
    def _receive(self) -> None:
        if self.tcp and self.client is None:
            try:
                self.client, _ = self.socket.accept()
                self.client.setblocking(False)
            except BlockingIOError:
                return
        source = self.client if self.tcp else self.socket
        while source is not None:
            try:
                data = source.recv(65536)
            except BlockingIOError:
                return
            except OSError:
                data = b""
            if not data:  # the TCP client closed
                return self.hang_up()
            for msg in self.parser.parse_buffer(data) or ():
                self.received[msg.get_type()].append((time.monotonic(), msg))
                handler = getattr(self, "_on_" + msg.get_type().lower(), None)
                if handler is not None and not self.silent.is_set():
                    handler(msg)

    def _on_command_long(self, msg) -> None:
        command = msg.command
        if self.drop_acks[command] > 0:
            self.drop_acks[command] -= 1
            return
        result = self.refuse.get(command, mavlink.MAV_RESULT_ACCEPTED)
        if result == mavlink.MAV_RESULT_ACCEPTED:
            self._execute(msg)
        self.mav.command_ack_send(command, result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent())

    def _execute(self, msg) -> None:
        if msg.command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            self.armed = msg.param1 == 1
        elif msg.command == mavlink.MAV_CMD_DO_SET_MODE:
            if self.autopilot == mavlink.MAV_AUTOPILOT_PX4:
                self.custom_mode = (int(msg.param2) << 16) | (int(msg.param3) << 24)
            else:
                self.custom_mode = int(msg.param2)
        elif msg.command == mavlink.MAV_CMD_NAV_TAKEOFF:
            self.target = (self.home - np.array([0.0, 0.0, msg.param7]), np.zeros(3))
        elif msg.command == mavlink.MAV_CMD_REQUEST_MESSAGE:
            if int(msg.param1) == mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN:
                self._send_origin()
            elif int(msg.param1) == mavlink.MAVLINK_MSG_ID_HOME_POSITION and \
                    time.monotonic() - self._created - self.boot_offset >= self.home_after:
                self._send_home()

    def _on_set_position_target_local_ned(self, msg) -> None:
        self.target = (np.array([msg.x, msg.y, msg.z]), np.array([msg.vx, msg.vy, msg.vz]))

    def _on_timesync(self, msg) -> None:
        if msg.tc1 == 0 and self.answer_timesync:
            self.mav.timesync_send(self.boot_ms() * 1_000_000, msg.ts1)
