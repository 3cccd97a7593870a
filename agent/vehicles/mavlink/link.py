"""The MAVLink link: one connection to one autopilot, read and written by one background thread.

The thread exists because the autopilot needs this side on *its* clock, not on the agent's: PX4 leaves
OFFBOARD when the setpoint stream pauses for ``COM_OF_LOSS_T`` (PX4 parameter reference, default 1 s) and
takes a companion computer for gone without its heartbeat, while the agent's loop may be late (a deadline
miss) or not started yet (waiting for the launcher's epoch). So the thread

* parses everything that arrives (``pymavlink`` ``MAVLink.parse_buffer`` with robust parsing: bytes that are
  no MAVLink come back as BAD_DATA instead of an exception) and hands the autopilot's messages to
  ``on_message(msg)``;
* runs the periodic senders (:meth:`every`): this side's HEARTBEAT at 1 Hz (MAVLink heartbeat protocol:
  MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID, from ``component_id``, under the autopilot's own
  system id since it is a component of the same vehicle), the setpoint stream, TIMESYNC.

**Which system is the autopilot.** The first HEARTBEAT whose ``autopilot`` is not MAV_AUTOPILOT_INVALID and
whose ``type`` is not a ground station, gimbal, ADS-B receiver or onboard controller (pymavlink's
``probably_vehicle_heartbeat`` rule) names it (system and component id). Until then every other message is
dropped (``before_heartbeat``); afterwards messages from other systems are dropped (``other_system``), and the
HEARTBEATs of the vehicle's other components (a camera, a gimbal) are not the autopilot's.

**Bad input never stops the thread**; it is counted in :attr:`rejected` by reason: ``garbage`` (bytes
before a MAVLink start marker), ``crc`` (a frame whose checksum fails: corrupted, or of another dialect),
``unknown_message``, ``malformed`` (a bad length or payload), ``other_system``, ``before_heartbeat``,
``bad_value`` (a message the handler refused: a NaN position, a latitude beyond 90°), ``flood`` (reads dropped
unparsed because more than ``max_message_rate`` messages per second arrived: a token bucket holding one
second of messages; the reads dropped are datagrams on UDP, stretches of the byte stream on TCP and serial).
A flood costs at most the socket reads, so the senders keep their rate. A TCP link the autopilot closes
(``link_closed``) is opened again (pymavlink's ``autoreconnect``) every :data:`RECONNECT_WAIT` seconds; meanwhile
the heartbeat watch reports the vehicle unhealthy. Failures of the link itself are counted too: ``send_error``
(a write the socket refused), ``link_error`` (anything else the thread survived; logged with its traceback once).
"""

from __future__ import annotations

import logging
import select
import threading
import time
from collections import Counter
from collections.abc import Callable

from agent.vehicles.mavlink.errors import LinkError
from agent.vehicles.mavlink_protocol import mavlink, mavutil

log = logging.getLogger("skymesh.mavlink")

READ_SIZE = 4096  # bytes asked of a stream (TCP, serial) per read; a UDP read is one datagram
READS_PER_PASS = 64  # reads before the thread turns to its senders (chosen here: a flood cannot starve them)
IDLE_WAIT = 0.02  # s: the longest the thread sleeps in select() (chosen here)
RECONNECT_WAIT = 0.5  # s between reconnection attempts of a TCP link the autopilot closed (chosen here)
NOT_AUTOPILOTS = frozenset({mavlink.MAV_TYPE_GCS, mavlink.MAV_TYPE_GIMBAL, mavlink.MAV_TYPE_ADSB,
                            mavlink.MAV_TYPE_ONBOARD_CONTROLLER})
BAD_DATA_REASONS = (("Bad prefix", "garbage"), ("CRC", "crc"))


def bad_data_reason(text: str) -> str:
    """The :attr:`MavlinkLink.rejected` reason of a pymavlink BAD_DATA message's ``reason``."""
    return next((reason for marker, reason in BAD_DATA_REASONS if marker in text), "malformed")


def is_autopilot_heartbeat(msg) -> bool:
    return msg.autopilot != mavlink.MAV_AUTOPILOT_INVALID and msg.type not in NOT_AUTOPILOTS


class _Periodic:
    def __init__(self, period: float, send: Callable):
        self.period, self.send, self.due = period, send, time.monotonic()


class MavlinkLink:
    """The connection to ``url`` (a pymavlink connection string) and its thread (module docstring).
    Raises :class:`LinkError` when the connection cannot be opened."""

    def __init__(self, url: str, on_message: Callable, *, baud: int = 57600,
                 component_id: int = mavlink.MAV_COMP_ID_ONBOARD_COMPUTER, max_message_rate: float = 2000.0):
        try:
            self.connection = mavutil.mavlink_connection(url, baud=baud, source_component=component_id,
                                                         autoreconnect=True, retries=1)
        except Exception as error:  # socket, serial and pymavlink errors alike: nothing to fly
            raise LinkError(f"cannot open the MAVLink link {url!r}: {error}") from None
        self.url, self.on_message, self.component_id = url, on_message, component_id
        self.rejected: Counter = Counter()
        self.received: Counter = Counter()  # message type -> messages handed on
        self.autopilot: tuple[int, int] | None = None  # (system id, component id) once heard
        self.heard = threading.Event()
        self._rate = float(max_message_rate)
        self._tokens = self._rate
        self._refilled = time.monotonic()
        self._periodic: list[_Periodic] = []
        self._send_lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"mavlink {url}", daemon=True)
        self._thread.start()

    # -- sending -----------------------------------------------------------------------------------
    def send(self, write: Callable) -> None:
        """``write(mav)`` with the pymavlink encoder (``mav.command_long_send(...)``...), never two at once
        (the encoder's sequence number is not thread-safe). A socket error is counted, not raised: the
        heartbeat watch tells whether the link still works."""
        with self._send_lock:
            try:
                write(self.connection.mav)
            except OSError:
                self.rejected["send_error"] += 1

    def every(self, period: float, write: Callable) -> None:
        """Send ``write(mav)`` every ``period`` seconds from the link's thread, once the autopilot is known."""
        self._periodic.append(_Periodic(period, write))

    def wait_for_autopilot(self, timeout: float) -> tuple[int, int]:
        """The autopilot's (system id, component id); :class:`LinkError` if no HEARTBEAT came in ``timeout``."""
        if not self.heard.wait(timeout):
            raise LinkError(f"no autopilot HEARTBEAT on {self.url!r} within {timeout:g} s")
        return self.autopilot

    def close(self) -> None:
        self._stop.set()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)
        self.connection.close()

    # -- the thread ----------------------------------------------------------------------------------
    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                self._pass()
            except Exception:  # the thread must outlive anything; say it once per kind of failure
                self.rejected["link_error"] += 1
                if self.rejected["link_error"] == 1:
                    log.exception("MAVLink link %s: unexpected error; it keeps running", self.url)
                self._stop.wait(RECONNECT_WAIT)

    def _pass(self) -> None:
        now = time.monotonic()
        due = min((p.due for p in self._periodic), default=now + IDLE_WAIT) if self.autopilot else now + IDLE_WAIT
        if self._readable(max(0.0, min(due - now, IDLE_WAIT))) and self._read_until_closed():
            self.rejected["link_closed"] += 1
            self._stop.wait(RECONNECT_WAIT)
        if self.autopilot is None:
            return
        now = time.monotonic()
        for periodic in self._periodic:
            if now >= periodic.due:
                periodic.due = max(periodic.due + periodic.period, now - periodic.period)
                self.send(periodic.send)

    def _readable(self, timeout: float) -> bool:
        """Wait up to ``timeout`` for input on the connection's socket or serial port (looked up every time:
        pymavlink's TCP reconnection replaces the socket, and its ``select`` would watch the old one)."""
        port = self.connection.port
        if port is None:  # a TCP link between reconnection attempts: reading tries again
            return True
        readable, _, _ = select.select([port], [], [], timeout)
        return bool(readable)

    def _read_until_closed(self) -> bool:
        """Read what is there (at most :data:`READS_PER_PASS` reads); ``True`` if the link closed meanwhile.

        Closed means: the read raised (reset by the autopilot, or pymavlink's reconnection refused); pymavlink
        replaced the socket (it met a TCP stream's end and reconnected inside ``recv``, which then returns
        nothing, whether or not earlier reads of this pass got data); or the first read of a readable port got
        nothing (a serial device's end)."""
        for reads in range(READS_PER_PASS):
            port = self.connection.port
            try:
                data = self.connection.recv(READ_SIZE)
            except OSError:
                return True
            if port is not None and self.connection.port is not port:
                return True
            if not data:
                return reads == 0
            if not self._admit():
                self.rejected["flood"] += 1
                continue
            for msg in self.connection.mav.parse_buffer(data) or ():
                self._tokens -= 1
                self._accept(msg)
        return False

    def _admit(self) -> bool:
        """Token bucket: ``max_message_rate`` tokens a second, at most one second's worth held."""
        now = time.monotonic()
        self._tokens = min(self._rate, self._tokens + (now - self._refilled) * self._rate)
        self._refilled = now
        return self._tokens >= 1.0

    def _accept(self, msg) -> None:
        kind = msg.get_type()
        if kind == "BAD_DATA":
            self.rejected[bad_data_reason(msg.reason)] += 1
            return
        if kind.startswith("UNKNOWN_"):  # pymavlink's MAVLink_unknown: a message id no dialect defines
            self.rejected["unknown_message"] += 1
            return
        source = (msg.get_srcSystem(), msg.get_srcComponent())
        if self.autopilot is None:
            if kind != "HEARTBEAT" or not is_autopilot_heartbeat(msg):
                self.rejected["before_heartbeat"] += 1
                return
            self.autopilot = source
            self.connection.mav.srcSystem = source[0]  # a component of the autopilot's vehicle
            log.info("MAVLink link %s: autopilot is system %d component %d", self.url, *source)
        if source[0] != self.autopilot[0]:
            self.rejected["other_system"] += 1
            return
        if kind == "HEARTBEAT" and source != self.autopilot:
            return  # another component of the vehicle (camera, gimbal): alive, but not the autopilot
        try:
            self.on_message(msg)
        except (ValueError, TypeError, ArithmeticError):
            self.rejected["bad_value"] += 1
            return
        self.received[kind] += 1
        if not self.heard.is_set():
            self.heard.set()  # after the handler took the first heartbeat: a waiter finds it there

    def heartbeat(self, mav) -> None:
        """This side's HEARTBEAT (a periodic sender, see the module docstring)."""
        mav.heartbeat_send(mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID, 0, 0,
                           mavlink.MAV_STATE_ACTIVE)
