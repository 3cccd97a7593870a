"""The MAVLink vehicle's parts without an autopilot: its config keys, the clock mapping, the frame map, the
setpoint guidance, and the errors when there is no autopilot to talk to."""

from __future__ import annotations

import math
import time

import numpy as np
import pymap3d
import pytest

from agent.vehicles import vehicle_from_config
from agent.vehicles.base import Setpoint, orbit_vector_field
from agent.vehicles.geodesy import ned_to_geodetic
from agent.vehicles.mavlink import LinkError
from agent.vehicles.mavlink.clock import BootClock
from agent.vehicles.mavlink.config import MavlinkConfig
from agent.vehicles.mavlink.frames import FrameMap
from agent.vehicles.mavlink.guidance import SETTLE_TIME, Reference
from agent.vehicles.mavlink.vehicle import autopilot_kind
from agent.vehicles.mavlink_protocol import mavlink
from tests.agent.mavlink_peer import ORIGIN, SCENARIO_ORIGIN, free_port


@pytest.mark.parametrize("params, key", [
    ({}, "url"),  # no connection string
    ({"url": "http://example.com"}, "url"),  # not a pymavlink connection string
    ({"url": "udpin:0.0.0.0:14540", "autopilot": "inav"}, "autopilot"),
    ({"url": "udpin:0.0.0.0:14540", "takeoff_altitude": -5.0}, "takeoff_altitude"),
    ({"url": "udpin:0.0.0.0:14540", "heartbeat_timeout": math.nan}, "heartbeat_timeout"),
    ({"url": "udpin:0.0.0.0:14540", "command_attempts": 0}, "command_attempts"),
    ({"url": "/dev/ttyUSB0", "baud": "fast"}, "baud"),
    ({"url": "udpin:0.0.0.0:14540", "battery_reserve": 1.5}, "battery_reserve"),
    ({"url": "udpin:0.0.0.0:14540", "component_id": 300}, "component_id"),
    ({"url": "udpin:0.0.0.0:14540", "speed": 3.0}, "speed"),  # an unknown key
])
def test_bad_config_names_the_key(params, key):
    with pytest.raises(ValueError, match=f"^{key}:"):
        vehicle_from_config({"kind": "mavlink", **params}, [0.0, 0.0, -50.0], 0.0, SCENARIO_ORIGIN)


def test_the_config_takes_every_documented_key():
    config = MavlinkConfig.from_params({"url": "/dev/ttyUSB0", "baud": 921600, "autopilot": "ardupilot",
                                        "takeoff_altitude": 15.0, "command_attempts": 5})
    assert (config.baud, config.autopilot, config.takeoff_altitude, config.command_attempts) == (921600, "ardupilot",
                                                                                               15.0, 5)


def test_the_vehicle_needs_the_scenario_origin():
    with pytest.raises(ValueError, match="^origin:"):
        vehicle_from_config({"kind": "mavlink", "url": "udpin:127.0.0.1:14540"}, [0.0, 0.0, -50.0])


def test_a_link_that_cannot_be_opened_is_a_clear_error():
    # bad input: a UDP address this machine does not have (TEST-NET-1), so the port cannot be bound
    with pytest.raises(LinkError, match="cannot open the MAVLink link 'udpin:192.0.2.1:14540'"):
        vehicle_from_config({"kind": "mavlink", "url": "udpin:192.0.2.1:14540"}, [0.0, 0.0, -50.0], 0.0,
                            SCENARIO_ORIGIN)


def test_no_heartbeat_is_a_clear_error_after_the_connect_timeout():
    start = time.monotonic()
    with pytest.raises(LinkError, match=r"no autopilot HEARTBEAT on 'udpin:127.0.0.1:\d+' within 0.5 s"):
        vehicle_from_config({"kind": "mavlink", "url": f"udpin:127.0.0.1:{free_port()}", "connect_timeout": 0.5},
                            [0.0, 0.0, -50.0], 0.0, SCENARIO_ORIGIN)
    assert time.monotonic() - start < 2.0


def test_an_autopilot_neither_px4_nor_ardupilot_must_be_named():
    with pytest.raises(LinkError, match="^autopilot: the HEARTBEAT says MAV_AUTOPILOT 2,"):
        autopilot_kind(mavlink.MAV_AUTOPILOT_SLUGS)  # bad input: an autopilot whose start-up is not known here
    assert autopilot_kind(mavlink.MAV_AUTOPILOT_PX4) == "px4"


def test_timesync_takes_the_midpoint_of_the_shortest_round_trip():
    clock = BootClock()
    boot_ns = 5_000_000_000  # the autopilot's boot time when it answered [ns]
    # sent at local 1000 s, answered at boot 5 s, received 40 ms later: local = boot + (1000.02 - 5)
    clock.observe_timesync(1_000_000_000_000, boot_ns, 1_000_040_000_000)
    clock.observe_timesync(1_001_000_000_000, boot_ns + 1_000_000_000 + 5_000_000, 1_001_010_000_000)  # 10 ms
    assert clock.source == "timesync" and clock.round_trip == pytest.approx(0.010)
    assert clock.offset == pytest.approx(1001.005 - 6.005)  # the 10 ms sample's midpoint
    assert clock.to_local(6005) == pytest.approx(1001.005)


def test_stamps_give_the_smallest_delay_and_a_reboot_starts_again():
    clock = BootClock()
    clock.observe_stamp(10_000, 110.05)
    clock.observe_stamp(10_100, 110.11)  # 10 ms delay: the least delayed
    assert clock.source == "stamps" and clock.offset == pytest.approx(100.01)
    clock.observe_stamp(500, 200.5)  # time_boot_ms went back: the autopilot rebooted
    assert clock.offset == pytest.approx(200.0)
    with pytest.raises(ValueError, match="TIMESYNC"):
        clock.observe_timesync(10, 0, 20)  # tc1 = 0 is a request, not an answer


def test_the_frame_map_agrees_with_pymap3d_and_inverts():
    frames = FrameMap(SCENARIO_ORIGIN, ORIGIN)
    local = np.array([250.0, -400.0, -60.0])
    lat, lon, alt = pymap3d.ned2geodetic(*local, *ORIGIN)
    np.testing.assert_allclose(frames.position_to_scenario(local), pymap3d.geodetic2ned(lat, lon, alt,
                                                                                        *SCENARIO_ORIGIN), atol=1e-6)
    np.testing.assert_allclose(frames.position_to_local(frames.position_to_scenario(local)), local, atol=1e-6)
    velocity = np.array([3.0, -4.0, 1.0])
    np.testing.assert_allclose(frames.vector_to_local(frames.vector_to_scenario(velocity)), velocity, atol=1e-12)


def test_a_velocity_maps_as_the_difference_of_two_nearby_positions():
    far = ned_to_geodetic([20_000.0, 30_000.0, 0.0], ORIGIN)  # 36 km away: the frames' norths differ visibly
    frames = FrameMap(far, ORIGIN)
    p, v = np.array([10.0, 20.0, -30.0]), np.array([5.0, -2.0, 1.0])
    finite = (frames.position_to_scenario(p + 1e-3 * v) - frames.position_to_scenario(p - 1e-3 * v)) / 2e-3
    np.testing.assert_allclose(frames.vector_to_scenario(v), finite, atol=1e-6)
    assert abs(frames.yaw_offset) > 1e-3  # the meridians' convergence at 36 km


def test_the_origin_derived_from_home_is_the_autopilot_origin():
    home_local = np.array([-700.0, 1200.0, -3.0])
    home = ned_to_geodetic(home_local, ORIGIN)
    frames = FrameMap.from_home(SCENARIO_ORIGIN, home, home_local)
    lat0, lon0, alt0 = frames.autopilot_origin
    assert (lat0, lon0) == pytest.approx(ORIGIN[:2], abs=1e-9)  # 0.1 mm
    assert alt0 == pytest.approx(ORIGIN[2], abs=1e-4)


def test_a_point_reference_moves_at_the_speed_limit_and_settles_on_the_point():
    reference = Reference(cruise_speed=5.0)
    goal = Setpoint([30.0, 40.0, -20.0], speed=3.0)
    position, velocity = reference.advance(goal, np.array([0.0, 0.0, -20.0]), 0.0)  # starts at the vehicle
    np.testing.assert_allclose(position, [0.0, 0.0, -20.0])
    np.testing.assert_allclose(velocity, [1.8, 2.4, 0.0])  # the speed limit, toward the point
    position, _ = reference.advance(goal, position, 0.5)
    np.testing.assert_allclose(position, [0.9, 1.2, -20.0])  # p += v dt
    for _ in range(600):  # 60 s at 10 Hz, the vehicle on the reference
        position, velocity = reference.advance(goal, position, 0.1)
    np.testing.assert_allclose(position, goal.position, atol=1e-3)
    assert np.linalg.norm(velocity) < 1e-3 / SETTLE_TIME * 1.01  # slowing down on arrival: d / SETTLE_TIME


def test_an_orbit_reference_flies_the_orbit_field_onto_the_circle():
    reference = Reference(cruise_speed=4.0)
    setpoint = Setpoint([0.0, 0.0, -30.0], orbit=(np.array([10.0, 10.0]), 20.0, -1))
    position, velocity = reference.advance(setpoint, np.array([10.0, 50.0, -25.0]), 0.0)  # 40 m east of the centre
    np.testing.assert_allclose(velocity[:2], orbit_vector_field(np.array([0.0, 40.0]), 20.0, -1, 4.0))
    assert velocity[2] == pytest.approx(-4.0)  # toward the orbit's depth, 5 m up: 5 m / SETTLE_TIME, at most 4 m/s
    for _ in range(1200):
        position, velocity = reference.advance(setpoint, position, 0.1)
    assert np.hypot(*(position[:2] - [10.0, 10.0])) == pytest.approx(20.0, abs=0.05)
    assert position[2] == pytest.approx(-30.0, abs=1e-3) and np.linalg.norm(velocity[:2]) == pytest.approx(4.0)
    radial = (position[:2] - [10.0, 10.0]) / 20.0
    assert radial[0] * velocity[1] - radial[1] * velocity[0] < 0  # anticlockwise seen from above (direction -1)


def test_the_reference_restarts_at_a_vehicle_that_could_not_follow():
    reference = Reference(cruise_speed=5.0)
    goal = Setpoint([100.0, 0.0, -20.0])
    position, _ = reference.advance(goal, np.zeros(3), 0.0)
    for _ in range(30):  # 3 s: the reference is 15 m ahead of a vehicle held at the start
        position, _ = reference.advance(goal, np.zeros(3), 0.1)
    assert reference.restarts == 1 and np.linalg.norm(position) < 10.1  # restarted at the vehicle, then 2 s on


def test_a_feed_forward_carries_the_reference_with_a_moving_point():
    """A point moving east at 3 m/s, given with its velocity: the reference keeps on it (no lag), as the
    kinematic multirotor does, within one tick's motion; without the feed-forward it trails by the distance at which
    d / SETTLE_TIME = 3."""
    def trail(feed_forward):
        reference = Reference(cruise_speed=10.0)
        position = np.array([0.0, 0.0, -20.0])
        for k in range(300):
            point = np.array([0.0, 3.0 * 0.1 * k, -20.0])
            setpoint = Setpoint(point, velocity=(0.0, 3.0) if feed_forward else None)
            position, velocity = reference.advance(setpoint, position, 0.1)
        return np.linalg.norm(point + [0.0, 0.3, 0.0] - position)  # where the point is at the end of the tick

    assert trail(True) < 0.3  # within the point's motion over one tick (the point is held through the tick)
    assert trail(False) == pytest.approx(3.0 * SETTLE_TIME, abs=0.35)


def test_mavlink_replaces_the_scenarios_vehicle_at_the_speed_it_flew():
    from agent.__main__ import with_mavlink

    url = "udpin:0.0.0.0:14540"
    assert with_mavlink({"kind": "multirotor", "max_speed": 12.0}, url) == {
        "kind": "mavlink", "url": url, "cruise_speed": 12.0}
    assert with_mavlink({"kind": "multirotor", "max_accel": 4.0}, url)["max_accel"] == 4.0
    assert with_mavlink({"kind": "fixed_wing", "airspeed": 18.0}, url)["cruise_speed"] == 18.0
    assert with_mavlink({"kind": "multirotor"}, url) == {"kind": "mavlink", "url": url}  # the vehicle's default
    kept = with_mavlink({"kind": "mavlink", "url": "tcp:a:1", "autopilot": "ardupilot"}, url)
    assert kept == {"kind": "mavlink", "url": url, "autopilot": "ardupilot"}  # a MAVLink table keeps its keys


def test_an_orbit_is_flown_no_faster_than_its_radius_allows():
    """12 m/s asked on a 15 m circle: the reference flies sqrt(0.8 a r) = 6 m/s at a = 3 m/s², as the kinematic
    multirotor would (144/15 = 9.6 m/s² of centripetal acceleration is beyond the vehicle)."""
    reference = Reference(cruise_speed=12.0, max_accel=3.0)
    setpoint = Setpoint([0.0, 0.0, -30.0], orbit=(np.array([0.0, 0.0]), 15.0, 1))
    position, velocity = reference.advance(setpoint, np.array([15.0, 0.0, -30.0]), 0.0)
    assert np.linalg.norm(velocity[:2]) == pytest.approx(6.0)
