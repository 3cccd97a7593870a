"""Bad MAVLink input never crashes the vehicle, never changes what it believes, and is counted by reason. Each
test says what the bad input is; all of it arrives as real UDP datagrams on the vehicle's port."""

from __future__ import annotations

import math
import socket
import time

import numpy as np
import pytest

from agent.vehicles.mavlink.link import MavlinkLink
from agent.vehicles.mavlink_protocol import mavlink
from tests.agent.mavlink_peer import flying_vehicle, free_port, wait_for


@pytest.fixture
def flying():
    with flying_vehicle() as (peer, vehicle):
        yield peer, vehicle


def encoder(system: int = 1, component: int = 1):
    return mavlink.MAVLink(None, srcSystem=system, srcComponent=component)


def far_position(mav) -> bytes:
    """A LOCAL_POSITION_NED 999 m away: if the vehicle ever took it, its position would show it."""
    return bytes(mav.local_position_ned_encode(1, 999.0, 999.0, -999.0, 0.0, 0.0, 0.0).pack(mav))


def still_fine(peer, vehicle) -> None:
    """The vehicle kept flying: healthy, its position the autopilot's, never the bad input's."""
    time.sleep(0.2)
    assert vehicle.healthy, vehicle.health_reason
    assert np.linalg.norm(vehicle.telemetry.local.position - peer.position) < 1.0
    assert vehicle.link._thread.is_alive()


def test_garbage_bytes_are_counted_and_ignored(flying):
    peer, vehicle = flying
    peer.send_raw(b"\x00\x01 not MAVLink at all \xff" * 20)  # bad input: bytes with no MAVLink start marker
    wait_for(lambda: vehicle.rejected["garbage"] >= 1)
    still_fine(peer, vehicle)


def test_a_frame_with_a_wrong_crc_is_counted_and_not_used(flying):
    peer, vehicle = flying
    frame = bytearray(far_position(encoder()))
    frame[-1] ^= 0xFF  # bad input: a LOCAL_POSITION_NED whose checksum fails (corrupted on the wire)
    for _ in range(5):
        peer.send_raw(bytes(frame))
    wait_for(lambda: vehicle.rejected["crc"] >= 5)
    still_fine(peer, vehicle)


def test_a_message_from_another_system_is_counted_and_not_used(flying):
    peer, vehicle = flying
    other = encoder(system=2)  # bad input: a second vehicle (system 2) on the same link, claiming a position
    peer.send_raw(bytes(other.heartbeat_encode(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4, 0, 0, 0)
                        .pack(other)))
    for _ in range(5):
        peer.send_raw(far_position(other))
    wait_for(lambda: vehicle.rejected["other_system"] >= 6)
    still_fine(peer, vehicle)


def test_a_non_finite_position_is_counted_and_not_used(flying):
    peer, vehicle = flying
    mav = encoder()  # bad input: the autopilot's own system sending a NaN position
    peer.send_raw(bytes(mav.local_position_ned_encode(1, math.nan, 0.0, 0.0, 0.0, 0.0, 0.0).pack(mav)))
    wait_for(lambda: vehicle.rejected["bad_value"] >= 1)
    assert np.all(np.isfinite(vehicle.state().position))
    still_fine(peer, vehicle)


def test_an_unknown_message_id_and_a_truncated_frame_are_counted(flying):
    peer, vehicle = flying
    mav = encoder()
    frame = bytearray(far_position(mav))
    frame[7:10] = (0x3FFF).to_bytes(3, "little")  # bad input: a message id no dialect defines...
    peer.send_raw(bytes(frame))
    wait_for(lambda: vehicle.rejected["unknown_message"] >= 1)
    peer.send_raw(bytes(frame[:12]))  # ...and a frame cut short (the datagram ends mid-payload)
    time.sleep(0.2)
    still_fine(peer, vehicle)


def test_a_flood_is_dropped_unparsed_and_the_setpoint_stream_keeps_its_rate(flying):
    peer, vehicle = flying
    mav = encoder()
    frame = bytes(mav.attitude_encode(1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0).pack(mav))
    flooder = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    start = time.monotonic()
    sent = 0
    # bad input: ~50 000 valid ATTITUDE datagrams a second for 1.5 s, 25 times max_message_rate (on a loaded
    # machine the sender may not reach the rate at first: it goes on, up to 10 s, until the bucket has overflowed)
    try:
        while time.monotonic() - start < 1.5 or (not vehicle.rejected["flood"] and time.monotonic() - start < 10):
            for _ in range(500):
                flooder.sendto(frame, peer.address)
            sent += 500
            time.sleep(0.01)
    finally:
        flooder.close()
    end = time.monotonic()
    assert vehicle.rejected["flood"] > 0
    parsed = vehicle.link.received["ATTITUDE"]
    assert parsed < 2000 * (end - start) + 2000 + 100  # the token bucket: a second's burst, then max_message_rate
    during = [t for t, _ in peer.received["SET_POSITION_TARGET_LOCAL_NED"] if start <= t <= end]
    assert len(during) / (end - start) >= 5.0  # the stream kept its rate through the flood
    still_fine(peer, vehicle)


def test_a_ground_station_heartbeat_is_not_taken_for_the_autopilot():
    port = free_port()
    link = MavlinkLink(f"udpin:127.0.0.1:{port}", lambda msg: None)
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        gcs, autopilot = encoder(system=255, component=190), encoder(system=7)
        # a ground station's heartbeat (MAV_TYPE_GCS, MAV_AUTOPILOT_INVALID) comes first on the link
        sender.sendto(bytes(gcs.heartbeat_encode(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
                            .pack(gcs)), ("127.0.0.1", port))
        time.sleep(0.1)
        assert link.autopilot is None and link.rejected["before_heartbeat"] == 1
        sender.sendto(bytes(autopilot.heartbeat_encode(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4, 0, 0, 0)
                            .pack(autopilot)), ("127.0.0.1", port))
        assert link.wait_for_autopilot(2.0) == (7, 1)
        assert link.connection.mav.srcSystem == 7  # this side speaks as a component of that vehicle
    finally:
        sender.close()
        link.close()


def test_a_tcp_stream_ending_right_behind_its_data_is_counted_as_closed_and_reconnected():
    # bad input: the autopilot sends a HEARTBEAT and closes the TCP connection at once, twice; the stream's end
    # is read in the same pass as the data (the handler is slow), where pymavlink reconnects inside recv
    server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    server.bind(("127.0.0.1", 0))
    server.listen(4)
    server.settimeout(3.0)
    mav = encoder()
    heartbeat = bytes(mav.heartbeat_encode(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 0)
                      .pack(mav))
    link = MavlinkLink(f"tcp:127.0.0.1:{server.getsockname()[1]}", lambda msg: time.sleep(0.1))
    accepted = []
    try:
        for hang_ups in (1, 2):
            client, _ = server.accept()
            accepted.append(client)
            client.sendall(heartbeat)
            client.close()
            wait_for(lambda count=hang_ups: link.rejected["link_closed"] >= count, timeout=3.0)
        accepted.append(server.accept()[0])  # the link opened the connection again after the second hang-up
        assert link.rejected["link_closed"] == 2 and link._thread.is_alive()
    finally:
        link.close()
        for client in accepted:
            client.close()
        server.close()
