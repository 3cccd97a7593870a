"""The MAVLink vehicle: a real (or SITL) PX4 or ArduPilot autopilot behind the :class:`agent.vehicles.base.Vehicle`
seam.

Built, it is connected and flying: the link is open, the autopilot's HEARTBEAT was heard, the streams are set,
the position known, and the vehicle armed, in OFFBOARD (PX4) or GUIDED (ArduPilot) and taking off
(:mod:`agent.vehicles.mavlink.startup`). Then

* :meth:`state` is the latest LOCAL_POSITION_NED and attitude, mapped into the scenario's NED frame
  (:class:`~agent.vehicles.mavlink.frames.FrameMap`), stamped with the autopilot's time on the local (Unix)
  clock (:class:`~agent.vehicles.mavlink.clock.BootClock`, exposed as :attr:`clock`), and ``fresh = False``
  once the position is older than ``stream_timeout`` or the autopilot's heartbeat older than ``heartbeat_timeout``
  — the agent does not sense with a stale pose;
* :meth:`set_setpoint` replaces the setpoint that the link's thread streams as SET_POSITION_TARGET_LOCAL_NED
  at ``setpoint_rate_hz``: the position and velocity of a reference that flies the setpoint
  (:mod:`agent.vehicles.mavlink.guidance`), which the autopilot tracks (velocity as feed-forward);
* :meth:`step` does not wait: the real vehicle moves on its own clock. It watches the health (below) and
  counts the steps spent with a stale pose;
* :attr:`healthy` is ``False``, with :attr:`health_reason`, when the autopilot's heartbeat is older than
  ``heartbeat_timeout`` or its position stream older than ``stream_timeout`` (a position streamed at tens of Hz that
  stops says the link dropped long before the 1 Hz heartbeat can), the autopilot is disarmed or left the commanded
  mode (a pilot or a failsafe took over), the take-off is not over, or the battery is below ``battery_reserve``. An
  unhealthy vehicle bids for no task (:class:`agent.beliefs.assignment.AssignmentExchange`), so the fleet's
  consensus gives its tasks to others; :attr:`battery` and :attr:`failed` feed the assignment's health model;
* :meth:`point` points the camera with the gimbal protocol v2, :meth:`gimbal_attitude` reads it back.

Closing it stops the stream: the autopilot's own offboard-loss failsafe (PX4 ``COM_OBL_RC_ACT``, ArduPilot
``GUID_TIMEOUT``) then decides what the vehicle does.
"""

from __future__ import annotations

import logging
import math
import time

import numpy as np

from agent.vehicles.base import Setpoint, VehicleState, wrap_angle
from agent.vehicles.mavlink import startup
from agent.vehicles.mavlink.clock import BootClock
from agent.vehicles.mavlink.commands import Commander
from agent.vehicles.mavlink.config import MavlinkConfig
from agent.vehicles.mavlink.errors import LinkError
from agent.vehicles.mavlink.frames import FrameMap
from agent.vehicles.mavlink.guidance import Reference
from agent.vehicles.mavlink.link import MavlinkLink
from agent.vehicles.mavlink.telemetry import GimbalAttitude, Telemetry
from agent.vehicles.mavlink_protocol import mavlink, px4_modes

log = logging.getLogger("skymesh.mavlink")

#: SET_POSITION_TARGET_LOCAL_NED type_mask: position and velocity used; acceleration, yaw and yaw rate ignored
POSITION_AND_VELOCITY = (mavlink.POSITION_TARGET_TYPEMASK_AX_IGNORE | mavlink.POSITION_TARGET_TYPEMASK_AY_IGNORE
                         | mavlink.POSITION_TARGET_TYPEMASK_AZ_IGNORE | mavlink.POSITION_TARGET_TYPEMASK_YAW_IGNORE
                         | mavlink.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE)
TAKEOFF_DONE = 0.95  # the take-off is over at this share of takeoff_altitude (chosen here)
TIMESYNC_PERIOD = 1.0  # s (chosen here)


KINDS = {mavlink.MAV_AUTOPILOT_PX4: "px4", mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA: "ardupilot"}


def autopilot_kind(mav_autopilot: int) -> str:
    """``"px4"`` or ``"ardupilot"`` from a HEARTBEAT's MAV_AUTOPILOT (``autopilot = "auto"``)."""
    if mav_autopilot not in KINDS:
        raise LinkError(f"autopilot: the HEARTBEAT says MAV_AUTOPILOT {mav_autopilot}, neither PX4 nor ArduPilot; "
                        f"set autopilot = \"px4\" or \"ardupilot\" if it behaves like one")
    return KINDS[mav_autopilot]


class MavlinkVehicle:
    """The vehicle of the module docstring, for ``config`` in the scenario whose geodetic origin is
    ``scenario_origin`` (lat [deg], lon [deg], alt [m])."""

    def __init__(self, config: MavlinkConfig, scenario_origin):
        self.config = config
        self.scenario_origin = tuple(float(v) for v in scenario_origin)
        self.telemetry = Telemetry()
        self.clock = BootClock()
        self.max_speed = config.cruise_speed  # what the planner may assume
        self.setpoints_sent = self.stale_steps = 0
        self.commander: Commander | None = None
        self.autopilot = config.autopilot  # "px4" or "ardupilot" once the autopilot is heard
        self._frames: tuple[tuple, FrameMap] | None = None
        self._setpoint: Setpoint | None = None
        self.reference = Reference(config.cruise_speed, config.max_accel)  # what the stream sends (scenario frame)
        self._streamed_at: float | None = None  # monotonic time of the last setpoint streamed
        self._takeoff: tuple[float, bool] | None = None  # (local z of the end of the climb, stream during it)
        self._mode: int | None = None  # the custom (main) mode the vehicle must stay in, once commanded
        self._timesyncs: dict[int, None] = {}  # ts1 of the TIMESYNC requests in flight
        self._reason = "starting"
        self.health_changes: list[tuple[float, str]] = []  # (wall time [s], reason; "" when healthy again)
        self._started = time.monotonic()
        self.link = MavlinkLink(config.url, self._on_message, baud=config.baud, component_id=config.component_id,
                                max_message_rate=config.max_message_rate)
        try:
            target = self.link.wait_for_autopilot(config.connect_timeout)
            self.autopilot = config.autopilot if config.autopilot != "auto" else autopilot_kind(
                self.telemetry.heartbeat.autopilot)
            self.commander = Commander(self.link, target, config.command_timeout, config.command_attempts)
            self.link.every(1.0, self.link.heartbeat)
            self.link.every(TIMESYNC_PERIOD, self._timesync)
            self.link.every(1.0 / config.setpoint_rate_hz, self._stream)
            self._mode = startup.start(self)
        except BaseException:
            self.close()
            raise

    # -- the Vehicle seam ------------------------------------------------------------------------------
    def state(self) -> VehicleState:
        local, frames = self.telemetry.local, self.frames()
        roll, pitch, yaw = self.telemetry.attitude or (0.0, 0.0, 0.0)
        stamp = self.clock.to_local(local.time_boot_ms)
        return VehicleState(
            t=time.time() if stamp is None else stamp,
            position=frames.position_to_scenario(local.position),
            velocity=frames.vector_to_scenario(local.velocity),
            yaw=wrap_angle(yaw + frames.yaw_offset), roll=roll, pitch=pitch,
            fresh=self._fresh(),
        )

    def _fresh(self) -> bool:
        """The position stream and the heartbeat are both recent: the pose may be sensed with."""
        return self._alive(self.telemetry.local, self.config.stream_timeout) and self._alive(self.telemetry.heartbeat)

    def _alive(self, record, timeout: float | None = None) -> bool:
        """``record`` (a position, a heartbeat) arrived within ``timeout`` (default ``heartbeat_timeout``)."""
        timeout = self.config.heartbeat_timeout if timeout is None else timeout
        return record is not None and time.monotonic() - record.arrival <= timeout

    def set_setpoint(self, setpoint: Setpoint) -> None:
        if not isinstance(setpoint, Setpoint):
            raise TypeError(f"setpoint must be a Setpoint, got {type(setpoint).__name__}")
        self._setpoint = setpoint

    def step(self, dt: float) -> None:
        """Non-blocking (module docstring): watch the health, count a step with a stale pose."""
        if not self._fresh():
            self.stale_steps += 1
        reason = self.health_reason
        if reason != self._reason:
            (log.info if not reason else log.warning)("MAVLink vehicle %s: %s", self.config.url,
                                                      reason or "healthy")
            self._reason = reason
            self.health_changes.append((time.time(), reason))

    def close(self) -> None:
        """Stop the link and its thread (and with them the setpoint stream)."""
        self.link.close()

    # -- health ------------------------------------------------------------------------------------------
    @property
    def health_reason(self) -> str:
        """Why the vehicle is not flying the agent's setpoints (``""`` when it is; module docstring)."""
        telemetry = self.telemetry
        heartbeat = telemetry.heartbeat
        if not self._alive(heartbeat):
            return f"autopilot heartbeat lost (none for over {self.config.heartbeat_timeout:g} s)"
        if not self._alive(telemetry.local, self.config.stream_timeout):
            return f"position stale (none for over {self.config.stream_timeout:g} s)"
        if not heartbeat.armed:
            return "disarmed"
        if self._mode is not None and self.mode_of(heartbeat.custom_mode) != self._mode:
            return f"autopilot left the commanded mode (custom_mode {heartbeat.custom_mode:#x})"
        if self._takeoff is not None:
            return "taking off"
        battery = telemetry.battery
        if battery is not None and battery < self.config.battery_reserve:
            return f"battery {battery:.0%} below the reserve {self.config.battery_reserve:.0%}"
        return ""

    @property
    def healthy(self) -> bool:
        return not self.health_reason

    @property
    def battery(self) -> float | None:
        """Remaining charge 0-1 (BATTERY_STATUS / SYS_STATUS), ``None`` if the autopilot does not say."""
        return self.telemetry.battery

    @property
    def failed(self) -> bool:
        return self.telemetry.failed

    @property
    def rejected(self):
        """Input the link refused, by reason (:mod:`agent.vehicles.mavlink.link`)."""
        return self.link.rejected

    def mode_of(self, custom_mode: int) -> int:
        """The mode a HEARTBEAT's ``custom_mode`` says: PX4's main mode, ArduPilot's mode number."""
        return px4_modes(custom_mode)[0] if self.autopilot == "px4" else custom_mode

    # -- frames and the take-off ---------------------------------------------------------------------------
    def frames(self) -> FrameMap | None:
        """The map to the scenario's frame from the autopilot's origin (GPS_GLOBAL_ORIGIN, else derived from
        HOME_POSITION), rebuilt when the autopilot moves its origin; ``None`` before either arrived."""
        origin, home = self.telemetry.origin, self.telemetry.home
        key = origin if origin is not None else None if home is None else (home[0], tuple(home[1]))
        if key is None:
            return None
        if self._frames is None or self._frames[0] != key:
            frames = FrameMap(self.scenario_origin, origin) if origin is not None else \
                FrameMap.from_home(self.scenario_origin, *home)
            self._frames = (key, frames)
        return self._frames[1]

    def begin_takeoff(self, stream_during_climb: bool) -> None:
        """Climb to ``takeoff_altitude`` above home over the current position (a vehicle already higher holds its
        altitude), then hold there until the agent sends a setpoint; with ``stream_during_climb`` the climb point is
        streamed (PX4 takes off in OFFBOARD). Before HOME_POSITION has arrived, home is taken to be where the
        vehicle is; the end of the climb is judged against home as known at each check (:meth:`_climbing`), so a
        vehicle restarted in the air is not kept "taking off" when its home arrives a moment later."""
        local, frames = self.telemetry.local, self.frames()
        home_z = self._home_z(local.position[2])
        top = np.array([*local.position[:2], min(local.position[2], home_z - self.config.takeoff_altitude)])
        self._setpoint = Setpoint(frames.position_to_scenario(top))
        self._takeoff = (local.position[2], stream_during_climb)

    def _home_z(self, fallback: float) -> float:
        """Home's local depth (HOME_POSITION), ``fallback`` before it arrived."""
        return self.telemetry.home[1][2] if self.telemetry.home is not None else fallback

    def _climbing(self) -> bool:
        """Whether the take-off is still going on (ends it once the vehicle is high enough above home)."""
        takeoff, local = self._takeoff, self.telemetry.local
        if takeoff is not None and local.position[2] <= self._home_z(takeoff[0]) - TAKEOFF_DONE * \
                self.config.takeoff_altitude:
            self._takeoff = takeoff = None
        return takeoff is not None

    # -- the link's periodic senders (on its thread) -------------------------------------------------------
    def _stream(self, mav) -> None:
        """One SET_POSITION_TARGET_LOCAL_NED: the setpoint's moving reference (:mod:`~agent.vehicles.mavlink.guidance`),
        advanced by the time since the last one."""
        setpoint, local, frames = self._setpoint, self.telemetry.local, self.frames()
        if setpoint is None or local is None or frames is None:
            return
        if self._climbing() and not self._takeoff[1]:
            return
        now = time.monotonic()
        dt = 0.0 if self._streamed_at is None else now - self._streamed_at
        self._streamed_at = now
        position, velocity = self.reference.advance(setpoint, frames.position_to_scenario(local.position), dt)
        x, y, z = frames.position_to_local(position)
        vx, vy, vz = frames.vector_to_local(velocity)
        mav.set_position_target_local_ned_send(self._boot_ms(), *self.commander.target, mavlink.MAV_FRAME_LOCAL_NED,
                                               POSITION_AND_VELOCITY, x, y, z, vx, vy, vz, 0, 0, 0, 0, 0)
        self.setpoints_sent += 1

    def _timesync(self, mav) -> None:
        now = time.time_ns()
        self._timesyncs = {ts: None for ts in [*self._timesyncs, now][-8:]}
        mav.timesync_send(0, now)

    def _boot_ms(self) -> int:
        return int((time.monotonic() - self._started) * 1e3) & 0xFFFFFFFF

    # -- what the link hands over (on its thread) -----------------------------------------------------------
    def _on_message(self, msg) -> None:
        kind = msg.get_type()
        if kind == "COMMAND_ACK":
            if self.commander is not None:
                self.commander.on_ack(msg)
        elif kind == "TIMESYNC":
            self._on_timesync(msg)
        else:
            self.telemetry.handle(msg, time.monotonic())
            if "time_boot_ms" in msg.get_fieldnames():
                self.clock.observe_stamp(msg.time_boot_ms, time.time())

    def _on_timesync(self, msg) -> None:
        """An answer to our request (``ts1`` ours) feeds the clock; a request (``tc1 = 0``) is answered with
        this side's time, as the protocol asks of every component."""
        now = time.time_ns()
        if msg.tc1 == 0:
            self.link.send(lambda mav: mav.timesync_send(now, msg.ts1))
        elif msg.ts1 in self._timesyncs:
            self.clock.observe_timesync(msg.ts1, msg.tc1, now)

    # -- the gimbal (gimbal protocol v2) -----------------------------------------------------------------
    def point(self, look_at) -> None:
        """Point the camera at ``look_at`` (NED point of the scenario, ``None``: leave it) with
        GIMBAL_MANAGER_SET_PITCHYAW (MAVLink 2, id 287) to the autopilot's gimbal manager, all gimbals
        (``gimbal_device_id`` 0): pitch (positive up) and yaw from north (GIMBAL_MANAGER_FLAGS_YAW_IN_EARTH_FRAME)
        of the line of sight from the vehicle, rates NaN (not controlled). The signature of
        :meth:`agent.plugins.Sensor.point`, so a camera sensor can hand its goal's ``look_at`` on."""
        if look_at is None:
            return
        frames = self.frames()
        north, east, down = np.asarray(look_at, float) - frames.position_to_scenario(self.telemetry.local.position)
        if math.hypot(north, east, down) < 1e-6:
            return
        pitch = -math.atan2(down, math.hypot(north, east))
        yaw = wrap_angle(math.atan2(east, north) - frames.yaw_offset)  # from the autopilot's north
        self.link.send(lambda mav: mav.gimbal_manager_set_pitchyaw_send(
            *self.commander.target, mavlink.GIMBAL_MANAGER_FLAGS_YAW_IN_EARTH_FRAME, 0, pitch, yaw, math.nan,
            math.nan))

    def gimbal_attitude(self) -> GimbalAttitude | None:
        """The gimbal's latest GIMBAL_DEVICE_ATTITUDE_STATUS (``None`` before one arrived)."""
        return self.telemetry.gimbal

    def metrics(self) -> dict:
        clock = self.clock
        return {"vehicle": {"kind": "mavlink", "healthy": self.healthy, "health_reason": self.health_reason,
                            "rejected_by_reason": dict(self.link.rejected), "setpoints_sent": self.setpoints_sent,
                            "commands_sent": 0 if self.commander is None else self.commander.sent,
                            "stale_steps": self.stale_steps, "reference_restarts": self.reference.restarts,
                            "health_changes": [[t, reason] for t, reason in self.health_changes],
                            "clock": {"source": clock.source, "offset": clock.offset, "round_trip": clock.round_trip}}}


def from_config(params: dict, initial_position, initial_heading: float = 0.0, origin=None) -> MavlinkVehicle:
    """The MAVLink vehicle of a ``[vehicle] kind = "mavlink"`` table (:mod:`agent.vehicles.mavlink.config`).
    ``initial_position`` and ``initial_heading`` are not used: the autopilot says where the vehicle is."""
    if origin is None:
        raise ValueError("origin: the mavlink vehicle needs the scenario's geodetic origin")
    return MavlinkVehicle(MavlinkConfig.from_params(params), origin)
