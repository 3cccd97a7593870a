"""The namespace test bed's network (mesh_sim/netns.py): reachability, links down and up, tbf rate caps, clean-up.

Needs root and iproute2: skipped with the reason otherwise. Traffic is Python's TCP inside the namespaces (a
sink that accepts and reads, a client that connects or streams), started by PID and killed by PID."""

from __future__ import annotations

import subprocess
import sys
import time

import pytest

from mesh_sim import netns

pytestmark = pytest.mark.skipif(netns.unavailable() is not None, reason=str(netns.unavailable()))

PORT = 5301  # inside the test's own namespaces: no other process can hold it
CAP = 250_000  # bytes per second: the tbf cap measured (2 Mbit/s)
STREAM_S = 1.5  # seconds of the capped stream
SINK = ("import socket\ns = socket.socket(); s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)\n"
        f"s.bind(('0.0.0.0', {PORT})); s.listen()\nprint('listening', flush=True)\n"
        "while True:\n    c, _ = s.accept()\n    while c.recv(65536): pass\n")


def _ip_state() -> str:
    return subprocess.run(["ip", "netns", "list"], capture_output=True, text=True).stdout + \
        subprocess.run(["ip", "-br", "link"], capture_output=True, text=True).stdout


@pytest.fixture
def sink():
    """``sink(net, host)``: a TCP sink listening on PORT inside ``host``; killed by PID afterwards."""
    started = []

    def start(net: netns.Network, host: str) -> None:
        proc = subprocess.Popen([*net.exec_prefix(host), sys.executable, "-c", SINK], stdout=subprocess.PIPE,
                                stderr=subprocess.DEVNULL, text=True)
        started.append(proc)
        assert proc.stdout.readline() == "listening\n"

    yield start
    for proc in started:
        proc.kill()
        proc.wait()


def _connects(net: netns.Network, client: str, server: str) -> bool:
    """Whether ``client`` opens a TCP connection to ``server``'s sink within 2 s."""
    code = (f"import socket; socket.create_connection(('{net.host(server).address}', {PORT}), timeout=2).close()")
    done = subprocess.run([*net.exec_prefix(client), sys.executable, "-c", code], capture_output=True, timeout=30)
    return done.returncode == 0


def _sent_per_s(net: netns.Network, client: str, code: str) -> float:
    """Bytes per second ``client`` put on its veth (kernel counter) while running the Python ``code`` inside it."""
    before = net.counters(client)["tx_bytes"]
    started = time.time()
    subprocess.run([*net.exec_prefix(client), sys.executable, "-c", code], check=True, timeout=60)
    elapsed = time.time() - started
    return (net.counters(client)["tx_bytes"] - before) / elapsed


def _stream(net: netns.Network, client: str, server: str, seconds: float) -> float:
    """Bytes per second ``client`` sent while streaming over TCP to ``server``'s sink for ``seconds``."""
    return _sent_per_s(net, client, (
        f"import socket, time; s = socket.create_connection(('{net.host(server).address}', {PORT}), timeout=5)\n"
        f"end = time.time() + {seconds}\nwhile time.time() < end: s.sendall(bytes(16384))\n"))


def _datagrams(net: netns.Network, client: str, server: str, seconds: float) -> float:
    """Bytes per second ``client`` sent while sending 1000-byte UDP datagrams to ``server`` as fast as it can for
    ``seconds`` (no sink: what the kernel drops is dropped, as on a radio)."""
    return _sent_per_s(net, client, (
        f"import socket, time; s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)\n"
        f"end = time.time() + {seconds}\nwhile time.time() < end:\n"
        f"    try: s.sendto(bytes(1000), ('{net.host(server).address}', {PORT}))\n"
        f"    except OSError: pass\n"))


def test_hosts_reach_each_other_and_a_link_down_cuts_one_host_off(sink):
    """Two hosts connect over the bridge; with b's link down a cannot reach b (and b's loopback still works);
    up again, a reaches b again. The counters saw the traffic."""
    with netns.network(["a", "b", "c"]) as net:
        sink(net, "b")
        sink(net, "c")
        assert _connects(net, "a", "b")
        net.link_down("b")
        assert not _connects(net, "a", "b")
        assert _connects(net, "a", "c"), "only b's link is down"
        net.link_up("b")
        assert _connects(net, "a", "b")
        assert net.counters("a")["tx_packets"] > 0 and net.counters("b")["rx_bytes"] > 0


def test_tbf_caps_what_a_host_sends(sink):
    """A TCP stream from a capped host runs at the cap (within 35 %: a 1.5 s stream, tbf's burst, TCP's
    ramp), and an uncapped one at many times the cap."""
    with netns.network(["a", "b"]) as net:
        sink(net, "b")
        free = _stream(net, "a", "b", 0.5)
        net.cap_rate("a", CAP)
        capped = _stream(net, "a", "b", STREAM_S)
    assert capped == pytest.approx(CAP, rel=0.35), capped
    assert free > 10 * CAP, free


def test_per_link_caps_cap_each_destination_and_leave_the_others_alone():
    """``cap_links("a", ["b"], CAP)``: UDP datagrams from a to b leave at the cap (within 35 %: a 1.5 s flood,
    the bucket's burst), datagrams from a to c — a destination without a cap — at many times it."""
    with netns.network(["a", "b", "c"]) as net:
        net.cap_links("a", ["b"], CAP)
        to_b, to_c = _datagrams(net, "a", "b", STREAM_S), _datagrams(net, "a", "c", 0.5)
    assert to_b == pytest.approx(CAP, rel=0.35), to_b
    assert to_c > 10 * CAP, to_c


def test_everything_made_is_removed_also_when_the_body_raises():
    before = _ip_state()
    with pytest.raises(RuntimeError, match="the body failed"):
        with netns.network(["a", "b"]) as net:
            assert net.tag in _ip_state()
            raise RuntimeError("the body failed")
    assert net.tag not in _ip_state()
    assert _ip_state() == before


def test_bad_input_is_refused_with_what_was_wrong():
    with pytest.raises(ValueError, match=r"host names must differ, got \['a', 'a'\]"):
        netns.Network(["a", "a"])
    with pytest.raises(ValueError, match="300 hosts do not fit on 10.213.0.0/24"):
        netns.Network([f"h{i}" for i in range(300)])
    with netns.network(["a"]) as net:
        with pytest.raises(ValueError, match=r"no host 'z' in this network \(hosts: a\)"):
            net.link_down("z")
        with pytest.raises(ValueError, match="a rate cap must be positive bytes per second, got 0"):
            net.cap_rate("a", 0)
        with pytest.raises(ValueError, match="a rate cap's burst must be positive bytes, got -1"):
            net.cap_rate("a", 1000, burst=-1)
        with pytest.raises(ValueError, match="a rate cap must be positive bytes per second, got -3"):
            net.cap_links("a", ["a"], -3)
        with pytest.raises(ValueError, match=r"no host 'q' in this network \(hosts: a\)"):
            net.cap_links("a", ["q"], 1000)
        with pytest.raises(netns.NetnsError, match="ip netns add .*: .*exists"):
            netns.run("ip", "netns", "add", net.host("a").netns)
