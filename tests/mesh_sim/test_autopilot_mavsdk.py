"""MAVSDK (an independent MAVLink client, the C++ library behind mavsdk 4.x's Python binding) flies the simulator:
connect, read the position, arm, take off, offboard to a position setpoint.

mavsdk 4.x is the native binding (libcmavsdk loaded with ctypes, in this process): there is no mavsdk_server
subprocess and no gRPC port any more, so nothing but the simulator is left to clean up, and the test checks
that no child process survives."""

from __future__ import annotations

import asyncio

import pytest

from agent.vehicles.geodesy import ned_to_geodetic
from mesh_sim.autopilot.options import DEFAULT_ORIGIN
from mesh_sim.autopilot.process import AutopilotProcess
from tests.processes import assert_no_children_left

mavsdk = pytest.importorskip("mavsdk", minversion="4.0")
from mavsdk.asyncio import ComponentType, Configuration, Mavsdk  # noqa: E402
from mavsdk.asyncio.plugins.action import ActionAsync  # noqa: E402
from mavsdk.asyncio.plugins.offboard import OffboardAsync, PositionNedYaw  # noqa: E402
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync  # noqa: E402

pytestmark = pytest.mark.slow


async def wait_for(condition, timeout: float, period: float = 0.1):
    """Poll the coroutine function ``condition()`` until it returns something truthy."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    while loop.time() < deadline:
        if value := await condition():
            return value
        await asyncio.sleep(period)
    raise AssertionError(f"condition not met within {timeout} s")


async def fly(port: int) -> dict:
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as sdk:
        await sdk.add_any_connection(f"udpin://127.0.0.1:{port}")
        system = await sdk.first_autopilot(timeout_s=10.0)
        assert system is not None, "MAVSDK found no autopilot"
        telemetry, action, offboard = TelemetryAsync(system), ActionAsync(system), OffboardAsync(system)

        async def ready():
            health = await telemetry.health()
            return health.is_global_position_ok and health.is_home_position_ok and health.is_armable

        await wait_for(ready, timeout=10.0)
        start = await telemetry.position()
        await action.arm()
        await action.takeoff()

        async def climbed():
            return (await telemetry.position_velocity_ned()).position.down_m < -2.2  # MIS_TAKEOFF_ALT 2.5 m

        await wait_for(climbed, timeout=10.0)
        await offboard.set_position_ned(PositionNedYaw(8.0, -4.0, -6.0, 0.0))
        await offboard.start()

        async def arrived():
            p = (await telemetry.position_velocity_ned()).position
            return p if abs(p.north_m - 8.0) < 0.3 and abs(p.east_m + 4.0) < 0.3 and abs(p.down_m + 6.0) < 0.3 else None

        final = await wait_for(arrived, timeout=15.0)
        mode = await telemetry.flight_mode()
        await offboard.stop()
        return {"start": start, "final": final, "mode": mode}


def test_mavsdk_connects_arms_takes_off_and_flies_an_offboard_setpoint():
    with AutopilotProcess.start("--north", "10", "--east", "5") as ap:
        result = asyncio.run(fly(ap.offboard_remote_port))
    lat, lon, _ = ned_to_geodetic([10.0, 5.0, 0.0], DEFAULT_ORIGIN)
    assert result["start"].latitude_deg == pytest.approx(lat, abs=1e-7)
    assert result["start"].longitude_deg == pytest.approx(lon, abs=1e-7)
    assert result["start"].relative_altitude_m == pytest.approx(0.0, abs=0.01)
    assert result["mode"].name == "OFFBOARD"
    assert_no_children_left()
