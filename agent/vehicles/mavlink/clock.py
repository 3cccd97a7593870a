"""The autopilot's clock on this computer's clock: ``time_boot_ms`` -> local (Unix) seconds.

Every autopilot stamps its telemetry with its time since boot (``time_boot_ms``); latency compensation
needs that instant on the local clock (DESIGN §3: every message carries its stamp). Two estimates of the
offset ``local = boot + offset``:

* **TIMESYNC** (MAVLink "Time Synchronization" protocol): this side sends ``TIMESYNC(tc1 = 0, ts1 = t1)``
  with ``t1`` its own time in ns; the autopilot answers ``TIMESYNC(tc1 = its boot time in ns, ts1 = t1)``
  (PX4 ``MavlinkTimesync``, ArduPilot ``GCS_MAVLINK::handle_timesync``). Arriving at ``t4``, the answer was
  made at about the midpoint ``(t1 + t4) / 2`` (symmetric delays), so ``offset = (t1 + t4) / 2 - tc1``. Of
  the last :data:`WINDOW` answers the one with the shortest round trip is used (its midpoint assumption
  errs by at most half that round trip).
* **stamps** (when the autopilot does not answer TIMESYNC): every stamped message gives an upper bound
  ``arrival - boot`` of the offset (the true offset plus that message's delay); the smallest of the last
  :data:`WINDOW` is the estimate, late by the smallest delay seen.

A ``time_boot_ms`` that goes back by more than :data:`REBOOT_JUMP` seconds means the autopilot rebooted:
the estimates start again.
"""

from __future__ import annotations

from collections import deque

WINDOW = 20  # samples kept for each estimate (chosen here: 20 s of 1 Hz TIMESYNC)
REBOOT_JUMP = 1.0  # s: a boot time this much older than the newest one seen is a reboot (chosen here)


class BootClock:
    """``to_local(time_boot_ms)``: the local (Unix) time of an autopilot stamp, from TIMESYNC when the
    autopilot answers it, from the message stamps otherwise (module docstring)."""

    def __init__(self):
        self._syncs: deque[tuple[float, float]] = deque(maxlen=WINDOW)  # (round trip [s], offset [s])
        self._stamps: deque[float] = deque(maxlen=WINDOW)  # arrival - boot [s]
        self._newest_boot = -float("inf")

    def observe_timesync(self, t1_ns: int, tc1_ns: int, t4_ns: int) -> None:
        """An answer to this side's TIMESYNC request sent at ``t1_ns``, received at ``t4_ns`` (local ns)."""
        if tc1_ns <= 0 or t4_ns < t1_ns:
            raise ValueError(f"not an answer to a TIMESYNC request: tc1={tc1_ns}, t1={t1_ns}, t4={t4_ns}")
        self._check_reboot(tc1_ns * 1e-9)
        self._syncs.append(((t4_ns - t1_ns) * 1e-9, ((t1_ns + t4_ns) / 2 - tc1_ns) * 1e-9))

    def observe_stamp(self, time_boot_ms: int, arrival: float) -> None:
        """A message stamped ``time_boot_ms`` that arrived at local time ``arrival`` [s]."""
        boot = time_boot_ms * 1e-3
        self._check_reboot(boot)
        self._stamps.append(arrival - boot)

    def _check_reboot(self, boot: float) -> None:
        if boot < self._newest_boot - REBOOT_JUMP:
            self._syncs.clear()
            self._stamps.clear()
            self._newest_boot = boot
        self._newest_boot = max(self._newest_boot, boot)

    @property
    def source(self) -> str | None:
        """``"timesync"``, ``"stamps"`` or ``None`` (nothing heard yet)."""
        return "timesync" if self._syncs else "stamps" if self._stamps else None

    @property
    def offset(self) -> float | None:
        """``local - boot`` [s] (module docstring), or ``None`` before any sample."""
        if self._syncs:
            return min(self._syncs)[1]
        return min(self._stamps) if self._stamps else None

    @property
    def round_trip(self) -> float | None:
        """The shortest TIMESYNC round trip of the window [s] (``None`` without TIMESYNC)."""
        return min(self._syncs)[0] if self._syncs else None

    def to_local(self, time_boot_ms: int) -> float | None:
        """The local (Unix) time [s] of an autopilot stamp, or ``None`` before any sample."""
        offset = self.offset
        return None if offset is None else time_boot_ms * 1e-3 + offset
