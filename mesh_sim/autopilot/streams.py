"""Telemetry streams of one link: which messages at which rate, and SET_MESSAGE_INTERVAL.

PX4 runs one MAVLink instance per link, each in a mode whose default rates are set in
``mavlink_main.cpp`` ``configure_streams_to_default``: the offboard link (udp 14580+i <-> 14540+i) is in
``MAVLINK_MODE_ONBOARD``, the ground-station link (18570+i <-> 14550) in ``MAVLINK_MODE_NORMAL``. The
rates below are PX4's for the messages simulated here; HEARTBEAT is 1 Hz on every link.
MAV_CMD_SET_MESSAGE_INTERVAL changes a rate on the link it arrives on
(https://mavlink.io/en/messages/common.html#MAV_CMD_SET_MESSAGE_INTERVAL: interval in µs, 0 restores the
default, -1 stops the message).
"""

from __future__ import annotations

import math

from agent.vehicles.mavlink_protocol import mavlink

_M = mavlink
#: MAVLINK_MODE_ONBOARD (Hz). GPS_GLOBAL_ORIGIN and GIMBAL_DEVICE_ATTITUDE_STATUS are not in that PX4 table:
#: their rates are chosen here (like HOME_POSITION, and a camera-pointing rate).
ONBOARD_RATES = {
    _M.MAVLINK_MSG_ID_HEARTBEAT: 1.0,
    _M.MAVLINK_MSG_ID_ATTITUDE: 100.0,
    _M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: 50.0,
    _M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 50.0,
    _M.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 30.0,
    _M.MAVLINK_MSG_ID_SYS_STATUS: 5.0,
    _M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 5.0,
    _M.MAVLINK_MSG_ID_BATTERY_STATUS: 0.5,
    _M.MAVLINK_MSG_ID_HOME_POSITION: 0.5,
    _M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN: 0.5,
    _M.MAVLINK_MSG_ID_GIMBAL_DEVICE_ATTITUDE_STATUS: 10.0,
}
#: MAVLINK_MODE_NORMAL (Hz); the same two additions.
NORMAL_RATES = {
    _M.MAVLINK_MSG_ID_HEARTBEAT: 1.0,
    _M.MAVLINK_MSG_ID_ATTITUDE: 15.0,
    _M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 5.0,
    _M.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 1.0,
    _M.MAVLINK_MSG_ID_SYS_STATUS: 1.0,
    _M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 1.0,
    _M.MAVLINK_MSG_ID_BATTERY_STATUS: 0.5,
    _M.MAVLINK_MSG_ID_HOME_POSITION: 0.5,
    _M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN: 0.5,
    _M.MAVLINK_MSG_ID_GIMBAL_DEVICE_ATTITUDE_STATUS: 5.0,
}
MAX_RATE = 1000.0  # Hz: shorter intervals are refused; chosen here


class StreamSchedule:
    """When each streamed message of one link is next due."""

    def __init__(self, defaults: dict[int, float], can_stream):
        self.defaults = dict(defaults)
        self._can_stream = can_stream  # msg_id -> bool: whether telemetry can encode it
        self.intervals = {msg_id: 1.0 / rate for msg_id, rate in defaults.items()}
        self._next: dict[int, float] = {}

    def set_interval(self, msg_id: int, interval_us: float) -> bool:
        """Apply MAV_CMD_SET_MESSAGE_INTERVAL; ``False`` for a message that cannot be streamed or a bad interval."""
        if not self._can_stream(msg_id) or not math.isfinite(interval_us):
            return False
        if interval_us == -1:
            self.intervals.pop(msg_id, None)
        elif interval_us == 0:
            if msg_id in self.defaults:
                self.intervals[msg_id] = 1.0 / self.defaults[msg_id]
            else:
                self.intervals.pop(msg_id, None)
        elif interval_us >= 1e6 / MAX_RATE:
            self.intervals[msg_id] = interval_us * 1e-6
        else:
            return False
        self._next.pop(msg_id, None)
        return True

    def due(self, now: float) -> list[int]:
        """The messages due at ``now``; each is then next due one interval later (no burst after a stall)."""
        due = []
        for msg_id, interval in self.intervals.items():
            at = self._next.get(msg_id, now)
            if now >= at:
                due.append(msg_id)
                at += interval
                self._next[msg_id] = at if at > now else now + interval
        return due

    def next_due(self, now: float) -> float:
        """The earliest time a message is due (``now`` for a message never sent)."""
        return min((self._next.get(msg_id, now) for msg_id in self.intervals), default=math.inf)
