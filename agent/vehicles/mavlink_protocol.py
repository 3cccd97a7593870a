"""What the MAVLink vehicle (:mod:`agent.vehicles.mavlink`) and the autopilot simulator
(``skymesh autopilot``, :mod:`mesh_sim.autopilot`) agree on: the dialect, the autopilots' flight-mode
encodings and their port conventions.

pymavlink chooses MAVLink 1 or 2 for sending from the process-global ``MAVLINK20`` environment variable
when ``mavutil`` is first imported (dependencies.md §5.4); messages above id 255 (the gimbal protocol's
GIMBAL_MANAGER_SET_PITCHYAW is 287, GIMBAL_DEVICE_ATTITUDE_STATUS 285) exist only in MAVLink 2. Import
``mavutil`` from here, never directly, so that every skymesh process speaks MAVLink 2.

PX4 custom modes (PX4-Autopilot ``src/modules/commander/px4_custom_mode.h``): the 32-bit ``custom_mode``
of HEARTBEAT holds the main mode in bits 16-23 and the sub mode in bits 24-31::

    custom_mode = main_mode << 16 | sub_mode << 24

ArduCopter's modes are plain numbers (``GUIDED`` = 4, ArduPilot ``mode.h``).

Ports: PX4 SITL instance ``i`` sends its offboard stream to UDP ``14540 + i`` on the companion computer and
its ground-station stream to ``14550``; its own local ports are ``14580 + i`` (offboard) and
``18570 + i`` (ground station). ArduPilot SITL instance ``i`` serves TCP ``5760 + 10 i``.
"""

from __future__ import annotations

import os

os.environ["MAVLINK20"] = "1"  # before the first import of mavutil (see the module docstring)

from pymavlink import mavutil  # noqa: E402

mavlink = mavutil.mavlink

# PX4 main modes and the AUTO sub modes (px4_custom_mode.h)
PX4_MAIN_MANUAL, PX4_MAIN_ALTCTL, PX4_MAIN_POSCTL, PX4_MAIN_AUTO, PX4_MAIN_ACRO, PX4_MAIN_OFFBOARD = 1, 2, 3, 4, 5, 6
PX4_AUTO_READY, PX4_AUTO_TAKEOFF, PX4_AUTO_LOITER, PX4_AUTO_MISSION, PX4_AUTO_RTL, PX4_AUTO_LAND = 1, 2, 3, 4, 5, 6

ARDUCOPTER_GUIDED = 4

PX4_OFFBOARD_PORT = 14540  # + instance: where a PX4 instance sends its offboard link
PX4_GCS_PORT = 14550  # where every PX4 instance sends its ground-station link
PX4_LOCAL_OFFBOARD_PORT = 14580  # + instance: PX4's own end of the offboard link
PX4_LOCAL_GCS_PORT = 18570  # + instance: PX4's own end of the ground-station link
ARDUPILOT_TCP_PORT = 5760  # + 10 * instance


def px4_custom_mode(main_mode: int, sub_mode: int = 0) -> int:
    """HEARTBEAT ``custom_mode`` of a PX4 (main, sub) mode."""
    if not (0 <= main_mode <= 255 and 0 <= sub_mode <= 255):
        raise ValueError(f"PX4 main and sub modes are bytes, got {main_mode}, {sub_mode}")
    return (main_mode << 16) | (sub_mode << 24)


def px4_modes(custom_mode: int) -> tuple[int, int]:
    """(main mode, sub mode) of a PX4 HEARTBEAT ``custom_mode``."""
    return (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF


PX4_OFFBOARD = px4_custom_mode(PX4_MAIN_OFFBOARD)
PX4_TAKEOFF = px4_custom_mode(PX4_MAIN_AUTO, PX4_AUTO_TAKEOFF)
PX4_HOLD = px4_custom_mode(PX4_MAIN_AUTO, PX4_AUTO_LOITER)
PX4_LAND = px4_custom_mode(PX4_MAIN_AUTO, PX4_AUTO_LAND)
