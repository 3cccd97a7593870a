"""The flight state machine: arming, PX4 flight modes, offboard, and the kinematic model underneath.

It reproduces, for a subset, what PX4's ``commander`` and navigator do (PX4 user guide, "Flight Modes",
"Offboard Mode", "Arming/Disarming"); no sockets and no clock here — the simulator calls :meth:`step` with
its own time, the command handler calls the other methods, and each command method returns a MAV_RESULT
and says why it refused (PX4 sends that reason as a STATUSTEXT, as :attr:`statustexts` collects it).

* Boot: disarmed, on the ground, mode Hold (``AUTO_LOITER``). The position estimate becomes valid
  ``position_valid_after`` seconds after boot (EKF2 waiting for GPS); until then arming is refused with
  ``MAV_RESULT_TEMPORARILY_REJECTED``. Arming below ``BAT_LOW_THR`` is ``MAV_RESULT_DENIED``. Home is set
  where the vehicle arms. Disarming in the air needs the force magic number 21196.
* Takeoff (``AUTO_TAKEOFF``): climb above the current point to ``MIS_TAKEOFF_ALT`` (or the commanded
  altitude), then Hold there. Land (``AUTO_LAND``): descend where it is; touchdown (land detector:
  below 0.1 m with a setpoint on the ground) disarms after ``COM_DISARM_LAND`` seconds. Return
  (``AUTO_RTL``): climb to ``RTL_RETURN_ALT`` if lower, fly home, land.
* Offboard: switching to it is refused unless setpoints have arrived within ``COM_OF_LOSS_T``; once in it,
  a gap longer than ``COM_OF_LOSS_T`` switches to Hold and says so (PX4's offboard-loss failsafe with no
  RC: ``COM_OBL_RC_ACT``'s Hold).
* Manual modes (Manual, Altitude, Position, Acro, Stabilized) need RC, which a simulator has not:
  ``TEMPORARILY_REJECTED``, like PX4 without a manual control source.

The ground is the plane ``z = 0`` of the NED frame (the origin's altitude): no setpoint goes below it.
The model is stepped only while airborne, so a fixed wing (which cannot hover) waits on the ground.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from agent.vehicles.base import KinematicModel, Setpoint, wrap_angle
from agent.vehicles.mavlink_protocol import (
    PX4_AUTO_LAND,
    PX4_AUTO_LOITER,
    PX4_AUTO_RTL,
    PX4_AUTO_TAKEOFF,
    PX4_MAIN_AUTO,
    PX4_MAIN_OFFBOARD,
    mavlink,
    px4_custom_mode,
)
from mesh_sim.autopilot.battery import Battery
from mesh_sim.autopilot.gimbal import Gimbal
from mesh_sim.autopilot.offboard import OffboardTarget
from mesh_sim.autopilot.params import Params

ACCEPTED = mavlink.MAV_RESULT_ACCEPTED
TEMPORARILY_REJECTED = mavlink.MAV_RESULT_TEMPORARILY_REJECTED
DENIED = mavlink.MAV_RESULT_DENIED

FORCE_DISARM = 21196  # MAV_CMD_COMPONENT_ARM_DISARM param2 that forces (PX4 and ArduPilot)
GROUND_TOLERANCE = 0.1  # m: "on the ground" below this height; chosen here (PX4's land detector is richer)
ALTITUDE_ACCEPTANCE = 0.3  # m: takeoff / climb phase complete within this; chosen here
NAV_ACC_RAD = 2.0  # m: PX4's NAV_ACC_RAD, horizontal acceptance radius of a multirotor
PX4_MANUAL_MAIN_MODES = (1, 2, 3, 5, 7)  # MANUAL, ALTCTL, POSCTL, ACRO, STAB (px4_custom_mode.h)

MAV_SEVERITY_INFO = mavlink.MAV_SEVERITY_INFO
MAV_SEVERITY_WARNING = mavlink.MAV_SEVERITY_WARNING
MAV_SEVERITY_CRITICAL = mavlink.MAV_SEVERITY_CRITICAL


@dataclass(frozen=True)
class Outcome:
    """A command's MAV_RESULT and, for a refusal, the reason."""

    result: int
    reason: str = ""


class FlightController:
    def __init__(self, model: KinematicModel, params: Params, battery: Battery, gimbal: Gimbal,
                 position_valid_after: float = 1.5, airborne: bool = False):
        """``airborne``: the model starts in the air, armed and holding there (home on the ground below) —
        a fleet run's counterpart of the kinematic models' start at altitude; PX4 SITL always boots landed."""
        self.model = model
        self.params = params
        self.battery = battery
        self.gimbal = gimbal
        self.position_valid_after = position_valid_after  # s after boot; chosen here (EKF2 GPS fusion start)
        self.t = 0.0
        self.armed = self.airborne = airborne
        self.main_mode, self.sub_mode = PX4_MAIN_AUTO, PX4_AUTO_LOITER
        self.home = self.position * np.array([1.0, 1.0, 0.0])  # on the ground below the start
        self.offboard: OffboardTarget | None = None
        self.statustexts: list[tuple[int, str]] = []  # (MAV_SEVERITY, text) not yet sent
        self._target = self.position.copy()  # the current mode's reference position
        self._rtl_phase = ""
        self._landed_at: float | None = None
        self.angular_rates = (0.0, 0.0, 0.0)  # roll, pitch, yaw rates [rad/s] over the last step
        # NAV_ACC_RAD for a multirotor; a fixed wing arrives when it loiters around the point
        self.acceptance_radius = max(NAV_ACC_RAD, 1.1 * getattr(model, "loiter_radius", 0.0))

    # -- what telemetry reads -------------------------------------------------------------------------
    @property
    def position(self) -> np.ndarray:
        return self.model.state().position

    @property
    def custom_mode(self) -> int:
        return px4_custom_mode(self.main_mode, self.sub_mode)

    @property
    def position_valid(self) -> bool:
        return self.t >= self.position_valid_after

    @property
    def landed_state(self) -> int:
        if self.armed and self._mode(PX4_MAIN_AUTO, PX4_AUTO_TAKEOFF):
            return mavlink.MAV_LANDED_STATE_TAKEOFF
        if not self.airborne:
            return mavlink.MAV_LANDED_STATE_ON_GROUND
        if self._setpoint().position[2] >= -GROUND_TOLERANCE:  # heading for the ground
            return mavlink.MAV_LANDED_STATE_LANDING
        return mavlink.MAV_LANDED_STATE_IN_AIR

    def _mode(self, main: int, sub: int = 0) -> bool:
        return (self.main_mode, self.sub_mode) == (main, sub)

    def _say(self, severity: int, text: str) -> None:
        self.statustexts.append((severity, text))

    def _refuse(self, result: int, reason: str) -> Outcome:
        self._say(MAV_SEVERITY_CRITICAL, reason)
        return Outcome(result, reason)

    # -- commands ---------------------------------------------------------------------------------------
    def arm(self) -> Outcome:
        if self.armed:
            return Outcome(ACCEPTED)
        if not self.position_valid:
            return self._refuse(TEMPORARILY_REJECTED, "Arming denied: no valid position estimate yet")
        if self.battery.remaining < self.params["BAT_LOW_THR"]:
            return self._refuse(DENIED, f"Arming denied: battery low ({100 * self.battery.remaining:.0f} %)")
        self.armed = True
        self.home = self.position.copy()
        self._landed_at = None
        self._say(MAV_SEVERITY_INFO, "Armed by external command")
        return Outcome(ACCEPTED)

    def disarm(self, force: bool = False) -> Outcome:
        if self.airborne and not force:
            return self._refuse(DENIED, "Disarming denied: vehicle in air")
        self._disarm("Disarmed by external command")
        return Outcome(ACCEPTED)

    def _disarm(self, text: str) -> None:
        if self.armed:
            self._say(MAV_SEVERITY_INFO, text)
        self.armed = False
        self.airborne = False
        self._landed_at = None

    def takeoff(self, height: float | None = None) -> Outcome:
        """Climb to ``height`` above home (``MIS_TAKEOFF_ALT`` if None or not finite), then Hold."""
        if not self.armed:
            return self._refuse(TEMPORARILY_REJECTED, "Takeoff denied: disarmed")
        if height is None or not math.isfinite(height):
            height = self.params["MIS_TAKEOFF_ALT"]
        if height <= 0:
            return self._refuse(DENIED, f"Takeoff denied: altitude {height:.1f} m is not above home")
        self.main_mode, self.sub_mode = PX4_MAIN_AUTO, PX4_AUTO_TAKEOFF
        p = self.position
        self._target = np.array([p[0], p[1], self.home[2] - height])
        return Outcome(ACCEPTED)

    def land(self) -> Outcome:
        self.main_mode, self.sub_mode = PX4_MAIN_AUTO, PX4_AUTO_LAND
        p = self.position
        self._target = np.array([p[0], p[1], 0.0])
        return Outcome(ACCEPTED)

    def return_to_launch(self) -> Outcome:
        if not self.armed:
            return self._refuse(TEMPORARILY_REJECTED, "Return denied: disarmed")
        self.main_mode, self.sub_mode = PX4_MAIN_AUTO, PX4_AUTO_RTL
        p = self.position
        self._rtl_phase = "climb"
        self._target = np.array([p[0], p[1], min(p[2], self.home[2] - self.params["RTL_RETURN_ALT"])])
        return Outcome(ACCEPTED)

    def hold(self) -> Outcome:
        self.main_mode, self.sub_mode = PX4_MAIN_AUTO, PX4_AUTO_LOITER
        self._target = self.position.copy()
        if not self.airborne:
            self._target[2] = 0.0
        return Outcome(ACCEPTED)

    def start_offboard(self) -> Outcome:
        if not self._offboard_fresh():
            return self._refuse(TEMPORARILY_REJECTED, "Switching to Offboard is not possible: no setpoint stream")
        self.main_mode, self.sub_mode = PX4_MAIN_OFFBOARD, 0
        return Outcome(ACCEPTED)

    def set_mode(self, main: int, sub: int) -> Outcome:
        """MAV_CMD_DO_SET_MODE with a PX4 (main, sub) custom mode."""
        switches = {
            (PX4_MAIN_OFFBOARD, 0): self.start_offboard,
            (PX4_MAIN_AUTO, PX4_AUTO_LOITER): self.hold,
            (PX4_MAIN_AUTO, PX4_AUTO_TAKEOFF): self.takeoff,
            (PX4_MAIN_AUTO, PX4_AUTO_LAND): self.land,
            (PX4_MAIN_AUTO, PX4_AUTO_RTL): self.return_to_launch,
        }
        if (main, sub) in switches:
            return switches[main, sub]()
        if main in PX4_MANUAL_MAIN_MODES or main == PX4_MAIN_AUTO:
            return self._refuse(TEMPORARILY_REJECTED, f"Mode {main}.{sub} not available: no manual control / mission")
        return self._refuse(DENIED, f"Unknown PX4 mode {main}.{sub}")

    def set_offboard_target(self, target: OffboardTarget) -> None:
        self.offboard = target

    def _offboard_fresh(self) -> bool:
        return self.offboard is not None and self.t - self.offboard.received_at <= self.params["COM_OF_LOSS_T"]

    # -- time -------------------------------------------------------------------------------------------
    def step(self, t: float) -> None:
        """Advance to simulator time ``t`` (seconds since boot)."""
        dt = t - self.t
        if dt <= 0:
            return
        self.t = t
        if self._mode(PX4_MAIN_OFFBOARD) and not self._offboard_fresh():
            self.hold()
            self._say(MAV_SEVERITY_WARNING, "Offboard setpoints lost: switching to Hold")
        setpoint = self._setpoint()
        if self.armed and not self.airborne and setpoint.position[2] < -GROUND_TOLERANCE:
            self.airborne = True
        if self.airborne:
            before = self.model.state()
            self.model.set_setpoint(setpoint)
            self.model.step(dt)
            after = self.model.state()
            self.angular_rates = tuple(wrap_angle(b - a) / dt for a, b in (
                (before.roll, after.roll), (before.pitch, after.pitch), (before.yaw, after.yaw)))
            self._advance_mission()
        else:
            self.angular_rates = (0.0, 0.0, 0.0)
        self._auto_disarm()
        self.battery.drain(dt, self.armed)
        self.gimbal.step(dt)

    def _setpoint(self) -> Setpoint:
        if self._mode(PX4_MAIN_OFFBOARD):
            setpoint = self.offboard.setpoint(self.position, self.t)
            if setpoint.position[2] > 0.0:  # never below the ground
                setpoint = Setpoint([setpoint.position[0], setpoint.position[1], 0.0], speed=setpoint.speed)
            return setpoint
        return Setpoint(self._target)

    def _advance_mission(self) -> None:
        """Takeoff -> Hold; RTL climb -> home -> land; touchdown."""
        p = self.position
        if self._mode(PX4_MAIN_AUTO, PX4_AUTO_TAKEOFF) and abs(p[2] - self._target[2]) < ALTITUDE_ACCEPTANCE:
            target = self._target
            self.hold()
            self._target = target.copy()
            self._say(MAV_SEVERITY_INFO, "Takeoff complete")
        elif self._mode(PX4_MAIN_AUTO, PX4_AUTO_RTL):
            if self._rtl_phase == "climb" and abs(p[2] - self._target[2]) < ALTITUDE_ACCEPTANCE:
                self._rtl_phase = "return"
                self._target = np.array([self.home[0], self.home[1], self._target[2]])
            elif self._rtl_phase == "return" and np.hypot(*(p[:2] - self.home[:2])) < self.acceptance_radius:
                self._rtl_phase = "land"
                self._target = np.array([self.home[0], self.home[1], 0.0])
        if -p[2] < GROUND_TOLERANCE and self._setpoint().position[2] >= -GROUND_TOLERANCE:
            self.airborne = False
            self._landed_at = self.t
            self._say(MAV_SEVERITY_INFO, "Landing detected")
            self.hold()

    def _auto_disarm(self) -> None:
        delay = self.params["COM_DISARM_LAND"]
        if self.armed and self._landed_at is not None and delay >= 0 and self.t - self._landed_at >= delay:
            self._disarm("Disarmed by landing")
