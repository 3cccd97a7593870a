"""The JSON5 files shipped in deploy/: Zenoh reads every one, and the plain routers' settings are the ones
``skymesh testbed`` runs (mesh_sim/testbed.py), so that what the namespace test bed measured is what ships."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import zenoh

from agent.net.zenoh_transport import client_config
from mesh_sim import netns, testbed
from tests.zenoh_probe import first_sample

DEPLOY = Path(__file__).resolve().parents[2] / "deploy"
SHIPPED = sorted(DEPLOY.glob("*.json5"))


def _get(config: zenoh.Config, key: str):
    return json.loads(config.get_json(key))


def test_the_plain_and_tls_configs_are_all_shipped():
    assert {p.name for p in SHIPPED} >= {"router.json5", "agent.json5", "uav-router.json5", "ground-router.json5",
                                         "uav-client.json5", "peers.json5"}


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.name)
def test_zenoh_reads_every_shipped_config(path):
    config = zenoh.Config.from_file(str(path))
    assert _get(config, "mode") in ("router", "client", "peer"), path.name


@pytest.mark.parametrize("name", ["uav-router.json5", "ground-router.json5"])
def test_the_shipped_routers_are_the_testbeds_but_for_the_addresses(name):
    """Mode, scouting, gossip, timestamps, lease, keep-alive and no shared memory as ``skymesh testbed`` runs them;
    listening on loopback (the host's own clients) and on the network."""
    shipped = zenoh.Config.from_file(str(DEPLOY / name))
    host = netns.Host("uav1", "ns", "veth", "port", "10.213.0.3")
    bed = zenoh.Config.from_json5(json.dumps(testbed.router_config(host, [])))
    for key in ("mode", "scouting/multicast/enabled", "scouting/gossip/enabled", "timestamping/enabled",
                "transport/link/tx/lease",
                "transport/link/tx/keep_alive", "transport/shared_memory/enabled"):
        assert _get(shipped, key) == _get(bed, key), key
    assert _get(shipped, "listen/endpoints") == ["tcp/127.0.0.1:7447", "tcp/0.0.0.0:7447"]


def test_the_uav_client_uses_its_hosts_router_and_peers_scout():
    client = zenoh.Config.from_file(str(DEPLOY / "uav-client.json5"))
    assert _get(client, "connect/endpoints") == [f"tcp/127.0.0.1:{testbed.ROUTER_PORT}"]
    peers = zenoh.Config.from_file(str(DEPLOY / "peers.json5"))
    assert _get(peers, "scouting/multicast/enabled") is True and _get(peers, "mode") == "peer"


def _opened(config: dict, listen: list[str], connect: list[str]) -> zenoh.Session:
    config = {**config, "listen": {"endpoints": listen}, "connect": {"endpoints": connect}}
    return zenoh.open(zenoh.Config.from_json5(json.dumps(config)))


def test_a_message_crosses_two_test_bed_routers_without_a_timestamp():
    """A put from a client of one test-bed router, heard by a client of another (the routers linked over TCP on
    loopback): the sample comes without a Zenoh timestamp — no router added its ~25 bytes on the way. With
    Zenoh's default (routers stamp what they forward) it comes stamped: the control run below."""
    from mesh_sim.launcher import free_port

    host = netns.Host("uav1", "ns", "veth", "port", "127.0.0.1")
    for config, stamped in ((testbed.router_config(host, []), False),
                            ({**testbed.router_config(host, []), "timestamping": {"enabled": True}}, True)):
        first, second = (f"tcp/127.0.0.1:{free_port()}" for _ in range(2))
        with _opened(config, [first], []), _opened(config, [second], [first]), \
                zenoh.open(client_config([second])) as listener, zenoh.open(client_config([first])) as talker:
            sample = first_sample(listener, talker, "skymesh/test/stamp")
            assert (sample.timestamp is not None) == stamped, config
