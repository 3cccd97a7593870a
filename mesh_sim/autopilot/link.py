"""One MAVLink link over UDP: a bound socket, the peer it talks to, decoding that counts bad input.

Like a PX4 SITL MAVLink instance (``mavlink_main.cpp``, ``-u`` local port, ``-o`` remote port) it binds its
local port, sends to the configured remote port until it hears from someone, and then answers whoever last
sent it a valid MAVLink message on that link. (PX4 keeps the first source it learns; following the latest
one lets a client that restarts on another port be found again. A datagram of garbage teaches nothing.)

Each datagram is decoded on its own: a truncated or corrupt packet at the end of one datagram is counted
and dropped, and never swallows the start of the next datagram. Datagrams that a flood made the kernel drop
before they could be read are counted too (Linux ``SO_RXQ_OVFL``: the socket's drop count travels with the
next datagram queued after the drops), so every datagram sent to the simulator, up to the last one that got
through, is either read or counted as dropped. Every datagram goes through a
:class:`~mesh_sim.autopilot.delay_line.DelayLine` in each direction (the configured one-way latency).
"""

from __future__ import annotations

import errno
import socket
import struct

from agent.vehicles.mavlink_protocol import mavlink
from mesh_sim.autopilot.counters import Counters
from mesh_sim.autopilot.delay_line import DelayLine
from mesh_sim.autopilot.streams import StreamSchedule

MAX_DATAGRAM = 65535
READ_BUDGET = 1000  # datagrams read per call, so that a flood cannot starve the streams; chosen here
RECEIVE_BUFFER = 1 << 20  # bytes of socket receive buffer; chosen here
SO_RXQ_OVFL = getattr(socket, "SO_RXQ_OVFL", 40)  # Linux: datagrams the kernel dropped, with each datagram
ANCILLARY_SPACE = socket.CMSG_SPACE(4)


def _reason(bad_data) -> str:
    """Counter name of a pymavlink BAD_DATA."""
    text = str(getattr(bad_data, "reason", "")).lower()
    if "crc" in text:
        return "bad_crc"
    if "prefix" in text:
        return "garbage_bytes"
    if "unknown mavlink message" in text:
        return "unknown_message_id"
    return "bad_packet"


class Link:
    def __init__(self, name: str, bind: tuple[str, int], remote: tuple[str, int], sysid: int, counters: Counters,
                 streams: StreamSchedule, latency: float = 0.0):
        self.name = name
        self.remote = remote
        self.counters = counters
        self.streams = streams
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER)
            self.sock.setsockopt(socket.SOL_SOCKET, SO_RXQ_OVFL, 1)
            self.sock.bind(bind)
        except OSError:
            self.sock.close()
            raise
        self.sock.setblocking(False)
        self.bind = self.sock.getsockname()
        self.mav = mavlink.MAVLink(self, srcSystem=sysid, srcComponent=mavlink.MAV_COMP_ID_AUTOPILOT1)
        self._decoder = mavlink.MAVLink(None)
        self._decoder.robust_parsing = True
        self._inbound = DelayLine(latency)
        self._outbound = DelayLine(latency)
        self._now = 0.0
        self._kernel_drops = 0  # the socket's drop count as last reported

    def fileno(self) -> int:
        return self.sock.fileno()

    def close(self) -> None:
        self.sock.close()

    # -- receiving --------------------------------------------------------------------------------------
    def read(self, now: float) -> None:
        """Read what the socket holds (at most :data:`READ_BUDGET` datagrams) into the inbound delay line."""
        for _ in range(READ_BUDGET):
            try:
                data, ancillary, _, sender = self.sock.recvmsg(MAX_DATAGRAM, ANCILLARY_SPACE)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:  # e.g. ECONNREFUSED reported for an earlier send
                self.counters.send_errors += 1
                continue
            self.counters.datagrams += 1
            self.counters.bytes += len(data)
            self._count_kernel_drops(ancillary)
            self._inbound.push(now, (data, sender))

    def _count_kernel_drops(self, ancillary) -> None:
        for level, kind, value in ancillary:
            if level == socket.SOL_SOCKET and kind == SO_RXQ_OVFL and len(value) >= 4:
                drops = struct.unpack("=I", value[:4])[0]
                self.counters.kernel_drops += (drops - self._kernel_drops) & 0xFFFFFFFF
                self._kernel_drops = drops

    def messages(self, now: float) -> list:
        """The MAVLink messages whose datagrams have come out of the delay line by ``now``."""
        out = []
        for data, sender in self._inbound.pop_due(now):
            decoded = self._decode(data)
            if decoded:
                self.remote = sender
            out.extend(decoded)
        return out

    def _decode(self, data: bytes) -> list:
        decoder = self._decoder
        try:
            parsed = decoder.parse_buffer(data) or []
        except Exception:  # robust parsing should return BAD_DATA; anything else is counted, never raised
            self.counters.reject("undecodable")
            parsed = []
        if decoder.buf_len() > 0:
            self.counters.reject("truncated_packet")
        decoder.buf, decoder.buf_index, decoder.expected_length = bytearray(), 0, mavlink.HEADER_LEN_V1 + 2
        messages = []
        for msg in parsed:
            if msg.get_type() == "BAD_DATA":
                self.counters.reject(_reason(msg))
            else:
                self.counters.messages += 1
                self.counters.received[msg.get_type()] += 1
                messages.append(msg)
        return messages

    # -- sending ----------------------------------------------------------------------------------------
    def send(self, msg, now: float) -> None:
        """Queue ``msg`` (packed with this link's sequence numbers) for sending after the latency."""
        self._now = now
        self.mav.send(msg)

    def write(self, packet: bytes) -> None:
        """pymavlink's ``file.write``: called by :meth:`send` with the packed bytes."""
        self._outbound.push(self._now, packet)

    def flush(self, now: float) -> None:
        """Send what has come out of the outbound delay line."""
        for packet in self._outbound.pop_due(now):
            try:
                self.sock.sendto(packet, self.remote)
                self.counters.sent += 1
            except OSError as error:
                if error.errno not in (errno.ECONNREFUSED, errno.EAGAIN, errno.ENOBUFS, errno.EHOSTUNREACH,
                                       errno.ENETUNREACH):
                    raise
                self.counters.send_errors += 1

    def next_due(self) -> float | None:
        """When the next delayed datagram (either direction) comes out, or ``None``."""
        times = [t for t in (self._inbound.next_due(), self._outbound.next_due()) if t is not None]
        return min(times) if times else None
