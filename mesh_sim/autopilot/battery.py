"""The simulated flight battery: a charge that drains linearly over a configurable flight time.

PX4 estimates the state of charge from the voltage and the consumed current (``battery_status``); what an
offboard computer sees is MAVLink's SYS_STATUS (``voltage_battery``, ``current_battery``,
``battery_remaining``) and BATTERY_STATUS. Here the charge itself is the state: it falls by
``1 / flight_time`` per armed second (a hover draw, so a full pack lasts ``flight_time`` seconds of flight)
and not at all while disarmed. The voltage is the linear cell model PX4 uses between its
``BAT1_V_CHARGED`` (4.05 V) and ``BAT1_V_EMPTY`` (3.6 V) per cell, for ``BAT1_N_CELLS`` = 4 cells.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

CELLS = 4  # PX4 BAT1_N_CELLS for a 4S pack; chosen here
CELL_CHARGED_V = 4.05  # PX4 BAT1_V_CHARGED
CELL_EMPTY_V = 3.6  # PX4 BAT1_V_EMPTY
ARMED_CURRENT_A = 15.0  # hover draw of a small quadrotor; chosen here
IDLE_CURRENT_A = 0.5  # avionics only, disarmed; chosen here
CAPACITY_MAH = 5000.0  # chosen here


@dataclass
class Battery:
    """State of charge ``remaining`` (0..1) of a pack that lasts ``flight_time`` armed seconds."""

    flight_time: float = 1200.0  # s of armed flight on a full pack; chosen here (20 min)
    remaining: float = 1.0
    armed: bool = False

    def __post_init__(self):
        if not (math.isfinite(self.flight_time) and self.flight_time > 0):
            raise ValueError(f"battery flight time must be a positive number of seconds, got {self.flight_time!r}")
        if not (math.isfinite(self.remaining) and 0.0 <= self.remaining <= 1.0):
            raise ValueError(f"battery charge must be within [0, 1], got {self.remaining!r}")

    def drain(self, dt: float, armed: bool) -> None:
        """Advance ``dt`` seconds, armed or not."""
        self.armed = armed
        if armed:
            self.remaining = max(0.0, self.remaining - dt / self.flight_time)

    @property
    def voltage(self) -> float:
        """Pack voltage [V] of the linear cell model."""
        return CELLS * (CELL_EMPTY_V + (CELL_CHARGED_V - CELL_EMPTY_V) * self.remaining)

    @property
    def current(self) -> float:
        """Current draw [A]."""
        return ARMED_CURRENT_A if self.armed else IDLE_CURRENT_A

    @property
    def consumed_mah(self) -> float:
        return CAPACITY_MAH * (1.0 - self.remaining)

    @property
    def time_remaining(self) -> float:
        """Seconds of armed flight left."""
        return self.remaining * self.flight_time
