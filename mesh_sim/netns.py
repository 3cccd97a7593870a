"""Linux network namespaces as the hosts of a test bed on one machine (issue 17).

Each host is a namespace with ``lo`` up and one veth whose other end is a port of a bridge; the bridge lives in
a namespace of its own (the "switch"), never in the root namespace, so the test bed neither sees nor touches
the machine's own interfaces and routes. Hosts get consecutive addresses on a private /24 (``10.213.0.0/24``
unless told otherwise): traffic stays inside the namespaces made here.

Every name carries a per-run tag (``uuid4`` hex), so two test beds never collide: namespaces
``skymesh-TAG-HOST``, interfaces ``smTAGhI`` (a host's veth), ``smTAGpI`` (its bridge port) and ``smTAGbr``
(the bridge), all within Linux's 15 characters. :func:`network` removes every namespace it made — their
interfaces and the bridge go with them — when its body ends, raises or is interrupted (Ctrl-C).

Impairments are the kernel's own: :meth:`Network.link_down` / :meth:`Network.link_up` (``ip link set``) and
:meth:`Network.cap_rate` (a ``tbf`` qdisc on the host's egress), :meth:`Network.cap_links` (a ``tbf`` per
destination host, as the emulated radio caps each directed link). Traffic is read from the kernel's counters of
the host's veth (:meth:`Network.counters`: ``ip -s -j link``, Ethernet frames with their headers).
"""

from __future__ import annotations

import ipaddress
import json
import os
import shutil
import subprocess
import uuid
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass

SUBNET = "10.213.0.0/24"  # private (RFC 1918); only ever configured inside the namespaces made here
TBF_QUEUE_S = 0.2  # cap_rate: the tbf queue holds this many seconds of the rate (tc-tbf(8) limit); chosen here
TBF_MIN_LIMIT = 1600  # bytes: a tbf queue holds at least one full Ethernet frame (1514), or it drops every such frame
UNSHAPED = "10gbit"  # an htb class that only sorts packets: faster than any veth carries here
TBF_MIN_BURST = 4096  # bytes: a burst below a few MTUs stalls tbf at low rates (tc-tbf(8): burst >= rate / HZ)


class NetnsError(RuntimeError):
    """An ``ip``/``tc`` command failed; the message is the command and what it said, on one line."""


@dataclass(frozen=True)
class Host:
    name: str  # "ground", "uav0", ...
    netns: str  # its namespace
    veth: str  # its interface, inside its namespace
    port: str  # the other end of the veth: a port of the bridge, inside the switch namespace
    address: str  # IPv4 address of the veth, on the bridge's subnet


def unavailable() -> str | None:
    """Why namespaces cannot be made here (not root, no ``ip``/``tc``), or ``None`` when they can."""
    if os.geteuid() != 0:
        return "network namespaces need root (ip netns add)"
    missing = [tool for tool in ("ip", "tc") if shutil.which(tool) is None]
    if missing:
        return f"{' and '.join(missing)} not found (iproute2)"
    return None


def run(*command: str) -> str:
    """Run an ``ip``/``tc`` command; its stdout. :class:`NetnsError` if it fails."""
    done = subprocess.run(command, capture_output=True, text=True)
    if done.returncode != 0:
        said = " ".join(done.stderr.split()) or f"exit code {done.returncode}"
        raise NetnsError(f"{' '.join(command)}: {said}")
    return done.stdout


class Network:
    """Hosts on one bridge. Made and removed by :func:`network`."""

    def __init__(self, names: Sequence[str], subnet: str = SUBNET):
        net = ipaddress.ip_network(subnet)
        if len(set(names)) != len(names):
            raise ValueError(f"host names must differ, got {list(names)}")
        if not 0 < len(names) <= net.num_addresses - 2:
            raise ValueError(f"{len(names)} hosts do not fit on {subnet}")
        self.tag = uuid.uuid4().hex[:5]
        self.prefix = net.prefixlen
        self.switch = f"skymesh-{self.tag}-switch"
        self.bridge = f"sm{self.tag}br"
        addresses = net.hosts()
        self.hosts = {name: Host(name, f"skymesh-{self.tag}-{name}", f"sm{self.tag}h{i}", f"sm{self.tag}p{i}",
                                 str(next(addresses))) for i, name in enumerate(names)}
        self._made: list[str] = []  # namespaces created so far: what remove() deletes

    def _namespace(self, name: str) -> None:
        run("ip", "netns", "add", name)
        self._made.append(name)
        run("ip", "-n", name, "link", "set", "lo", "up")

    def create(self) -> None:
        """The switch namespace with its bridge, then each host: namespace, veth into the bridge, address."""
        self._namespace(self.switch)
        run("ip", "-n", self.switch, "link", "add", self.bridge, "type", "bridge")
        run("ip", "-n", self.switch, "link", "set", self.bridge, "up")
        for host in self.hosts.values():
            self._namespace(host.netns)
            run("ip", "-n", host.netns, "link", "add", host.veth, "type", "veth", "peer", "name", host.port,
                "netns", self.switch)
            run("ip", "-n", host.netns, "addr", "add", f"{host.address}/{self.prefix}", "dev", host.veth)
            run("ip", "-n", host.netns, "link", "set", host.veth, "up")
            run("ip", "-n", self.switch, "link", "set", host.port, "master", self.bridge)
            run("ip", "-n", self.switch, "link", "set", host.port, "up")

    def remove(self) -> None:
        """Delete every namespace made (their veths and the bridge go with them); goes on past a failure and
        raises the first one at the end."""
        failures = []
        for name in reversed(self._made):
            try:
                run("ip", "netns", "delete", name)
            except NetnsError as err:
                failures.append(err)
        self._made.clear()
        if failures:
            raise failures[0]

    def host(self, name: str) -> Host:
        try:
            return self.hosts[name]
        except KeyError:
            raise ValueError(f"no host {name!r} in this network (hosts: {', '.join(self.hosts)})") from None

    def exec_prefix(self, name: str) -> list[str]:
        """The command prefix that runs a program inside host ``name``'s namespace (``ip netns exec`` execs it:
        the program keeps the PID of the process spawned, and its parent)."""
        return ["ip", "netns", "exec", self.host(name).netns]

    def link_down(self, name: str) -> None:
        """Host ``name`` loses its link: its veth is set down (nothing leaves or arrives; its loopback stays)."""
        host = self.host(name)
        run("ip", "-n", host.netns, "link", "set", host.veth, "down")

    def link_up(self, name: str) -> None:
        """Host ``name``'s veth up again (the kernel restores the route to the subnet)."""
        host = self.host(name)
        run("ip", "-n", host.netns, "link", "set", host.veth, "up")

    def cap_rate(self, name: str, bytes_per_s: float, burst: float | None = None) -> None:
        """Cap what host ``name`` sends at ``bytes_per_s`` with a token bucket (``tc qdisc replace ... tbf``:
        rate in bit/s, ``burst`` bytes deep — by default 1/50 s of the rate — and at least :data:`TBF_MIN_BURST`;
        packets that find the bucket empty wait in a queue of :data:`TBF_QUEUE_S` seconds of the rate, and what
        does not fit the queue is dropped)."""
        host = self.host(name)
        run("tc", "-n", host.netns, "qdisc", "replace", "dev", host.veth, "root",
            *_tbf(bytes_per_s, burst, bytes_per_s * TBF_QUEUE_S))

    def cap_links(self, name: str, to: Sequence[str], bytes_per_s: float, burst: float | None = None) -> None:
        """Cap each directed link from host ``name`` to a host of ``to`` at ``bytes_per_s``, every link with a
        token bucket of its own — what the emulated radio's ``rate`` does (agent/net/link_emulator.py): an ``htb``
        root whose classes only sort the packets by IPv4 destination (``u32`` filters; each class at
        :data:`UNSHAPED`), each destination's class with a ``tbf`` leaf (``burst`` as :meth:`cap_rate`'s; a queue
        of one frame, :data:`TBF_MIN_LIMIT`: the emulated bucket drops what does not fit it rather than delaying
        it, and the kernel comes as close as it can — one packet waits for tokens, what arrives meanwhile is
        dropped). Packets to any other host (the default class) leave unshaped."""
        host = self.host(name)
        peers = [self.host(other) for other in to]
        leaf = _tbf(bytes_per_s, burst, TBF_MIN_LIMIT)
        tc = ("tc", "-n", host.netns)
        run(*tc, "qdisc", "replace", "dev", host.veth, "root", "handle", "1:", "htb", "default", "1")
        run(*tc, "class", "add", "dev", host.veth, "parent", "1:", "classid", "1:1", "htb", "rate", UNSHAPED)
        for minor, peer in enumerate(peers, start=2):
            run(*tc, "class", "add", "dev", host.veth, "parent", "1:", "classid", f"1:{minor:x}", "htb",
                "rate", UNSHAPED)
            run(*tc, "qdisc", "add", "dev", host.veth, "parent", f"1:{minor:x}", "handle", f"{minor:x}:", *leaf)
            run(*tc, "filter", "add", "dev", host.veth, "parent", "1:", "protocol", "ip", "prio", "1", "u32",
                "match", "ip", "dst", f"{peer.address}/32", "flowid", f"1:{minor:x}")

    def counters(self, name: str) -> dict[str, int]:
        """The kernel's byte and packet counters of host ``name``'s veth since it was made (frames with their
        Ethernet header): ``tx_bytes``, ``rx_bytes``, ``tx_packets``, ``rx_packets``."""
        host = self.host(name)
        (link,) = json.loads(run("ip", "-n", host.netns, "-s", "-j", "link", "show", "dev", host.veth))
        stats = link["stats64"]
        return {f"{way}_{what}": int(stats[way][what]) for way in ("tx", "rx") for what in ("bytes", "packets")}


def _tbf(bytes_per_s: float, burst: float | None, queue: float) -> tuple[str, ...]:
    """A ``tbf`` qdisc's kind and parameters: ``bytes_per_s`` as bit/s, ``burst`` bytes (default 1/50 s of the
    rate; at least :data:`TBF_MIN_BURST`), a queue of ``queue`` bytes (at least :data:`TBF_MIN_LIMIT`) for the
    packets waiting for tokens; a packet that does not fit it is dropped. The queue is given as tc-tbf(8)'s
    ``limit``, not its ``latency``: tc turns a latency into ``rate × latency + burst`` bytes, so a 2 s bucket
    made a 20 ms latency a 2 s queue (measured, 8 agents under per-link caps: belief latency 1.24-1.53 s with
    it, 0.70-0.76 s with a queue of one frame; 0.45 s under the emulated radio's). ``ValueError`` for a rate or
    burst that is not positive."""
    if not bytes_per_s > 0:
        raise ValueError(f"a rate cap must be positive bytes per second, got {bytes_per_s}")
    if burst is not None and not burst > 0:
        raise ValueError(f"a rate cap's burst must be positive bytes, got {burst}")
    burst = max(TBF_MIN_BURST, int(bytes_per_s / 50 if burst is None else burst))
    return ("tbf", "rate", f"{int(bytes_per_s * 8)}bit", "burst", str(burst),
            "limit", str(max(TBF_MIN_LIMIT, int(queue))))


@contextmanager
def network(names: Sequence[str], subnet: str = SUBNET) -> Iterator[Network]:
    """Hosts ``names`` on one bridge for the body's duration; everything made is removed afterwards, also when
    the body raises, when it is interrupted, or when making the network failed half-way."""
    net = Network(names, subnet)
    try:
        net.create()
        yield net
    finally:
        net.remove()
