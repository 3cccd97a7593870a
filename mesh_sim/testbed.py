"""``skymesh testbed``: a run across hosts — Linux network namespaces on one machine (issue 17).

One namespace per agent (``uavK``) and one for the world and the observer (``ground``), on one bridge
(:mod:`mesh_sim.netns`). Each host runs its own Zenoh router (``python -m mesh_sim router``, router mode,
listening on its loopback and its bridge address, port :data:`ROUTER_PORT`, connected to the routers of
every host before it: a full mesh) and its processes are clients of that router on ``tcp/127.0.0.1``. So an
agent's message crosses the real (virtual) network once per remote router that has a subscriber for it, over
TCP, as on a fleet of companion computers; the emulated radio (``[radio]``) still acts inside each agent, on
top of the network.

Everything else is :class:`mesh_sim.launcher.Launcher`'s, through two seams: where a child runs
(``ip netns exec`` into its host: an agent's own, the ground for the world and the observer) and which router
the run opens (a router per host, :class:`Routers`; every child connects to ``tcp/127.0.0.1`` of its namespace,
so to its own host's). The run folder is ``skymesh run``'s,
plus ``testbed.json``: each host's address and its veth's kernel counters (:meth:`mesh_sim.netns.Network.counters`),
the link events as they happened (with the host's counters while down), the rate cap, and the bytes comparison
of :func:`bytes_check`.

Impairments are the kernel's: ``--link-down T:uavK[:T_UP]`` sets host K's veth down at simulation time T (and
up at T_UP), ``--tbf-rate BYTES_PER_S`` caps what every UAV host sends with ``tc ... tbf`` (not the ground: the
world's truth and the observer are the simulation's, not radio traffic; ``--tbf-burst BYTES``: the bucket's depth);
with ``--tbf-per-link`` (and ``--router-link udp``) the rate caps each directed link between two UAV hosts
instead, with a bucket of its own (:meth:`mesh_sim.netns.Network.cap_links`), as the emulated radio's ``rate``
does, and what goes to the ground is not capped.
``--router-link udp`` links the routers with Zenoh's datagram links instead of TCP: what the network drops is lost,
as on the emulated radio, instead of retransmitted behind a stalled stream. (This kernel family may
lack ``netem``; delay and loss stay the emulated radio's.)
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from agent.net.zenoh_transport import KEEP_ALIVE, SessionError
from agent.runtime import write_json
from mesh_sim import netns
from mesh_sim.launcher import Launcher, RunOutcome, _sigterm_raises, _Terminated, stop_processes

ROUTER_PORT = 7447  # Zenoh's default, in every namespace: each host has its own port space
ROUTER_READY_S = 60.0  # wall seconds for a host's router to listen (python and zenoh imports on a loaded machine)
LEASE_MS = 3000  # Zenoh lease between routers: a link that is down is noticed within 3 s (default 10 s); chosen
GROUND = "ground"
#: the transport between the hosts' routers -> the headers of one frame on a veth: Ethernet 14, IPv4 20, and TCP with
#: the timestamp option (Linux's default) 32 or UDP 8 bytes
FRAME_HEADERS = {"tcp": 14 + 20 + 32, "udp": 14 + 20 + 8}
TESTBED_FILE = "testbed.json"


@dataclass(frozen=True)
class LinkDown:
    """Host ``host``'s link is down from simulation time ``t_down`` to ``t_up`` (``None``: to the end)."""

    host: str
    t_down: float
    t_up: float | None = None

    @classmethod
    def parse(cls, spec: str) -> LinkDown:
        """``"20:uav1"`` or ``"20:uav1:35"``."""
        parts = spec.split(":")
        try:
            if len(parts) not in (2, 3) or not parts[1]:
                raise ValueError
            event = cls(parts[1], float(parts[0]), float(parts[2]) if len(parts) == 3 else None)
        except ValueError:
            raise ValueError(f"--link-down {spec!r}: expected T:uavK or T:uavK:T_UP, e.g. 20:uav1:35") from None
        if event.t_down < 0 or (event.t_up is not None and event.t_up <= event.t_down):
            raise ValueError(f"--link-down {spec!r}: times must satisfy 0 <= T < T_UP")
        return event


def router_config(host: netns.Host, connect: list[netns.Host], link: str = "tcp") -> dict:
    """A host's Zenoh router: listens on loopback (its own clients, which keep it when the link is down; TCP) and
    on its bridge address (the other routers, over ``link``: ``tcp``, or ``udp``, Zenoh's datagram links, which
    lose what the network drops instead of retransmitting it); connects to the routers ``connect``; no scouting,
    no gossip (every link is configured); no timestamps: a Zenoh router stamps every message it forwards by
    default (a hybrid logical clock and its id: about 25 bytes a message on every hop; nothing here reads them —
    measured, 8 agents over UDP: the kernel's payload 1.14 × the agents' accounting with them, 1.07 × without);
    the lease :data:`LEASE_MS`; and no shared memory: Zenoh (1.x, by default) hands a message of 3 kB or more to
    a peer on the same machine as a reference into ``/dev/shm``, which network namespaces do not separate, so the
    bytes would not cross the veths (measured on the ``partition`` scenario, whose tracks are ~5 kB: a host's
    kernel tx was 0.16 × the expectation of :func:`bytes_check` with it, 1.0 × without)."""
    return {
        "mode": "router",
        "listen": {"endpoints": [f"tcp/127.0.0.1:{ROUTER_PORT}", f"{link}/{host.address}:{ROUTER_PORT}"]},
        "connect": {"endpoints": [f"{link}/{other.address}:{ROUTER_PORT}" for other in connect]},
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
        "timestamping": {"enabled": False},
        "transport": {"link": {"tx": {"lease": LEASE_MS, "keep_alive": KEEP_ALIVE}},
                      "shared_memory": {"enabled": False}},
    }


class Routers:
    """One ``python -m mesh_sim router`` per host, in its namespace; :meth:`close` stops them by PID."""

    def __init__(self, net: netns.Network, folder: Path, env: dict, link: str = "tcp"):
        self.processes: list[subprocess.Popen] = []
        hosts = list(net.hosts.values())
        try:
            for i, host in enumerate(hosts):
                config = folder / f"router-{host.name}.json5"
                write_json(config, router_config(host, hosts[:i], link))
                with open(folder / "logs" / f"router-{host.name}.log", "wb") as log:
                    self.processes.append(subprocess.Popen(
                        [*net.exec_prefix(host.name), sys.executable, "-m", "mesh_sim", "router", "--config",
                         str(config), "--parent-pid", str(os.getpid())],
                        stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, env=env))
            for host in hosts:
                self._wait_listening(folder / "logs" / f"router-{host.name}.log", host.name)
        except BaseException:
            self.close()
            raise

    def _wait_listening(self, log: Path, name: str) -> None:
        deadline = time.time() + ROUTER_READY_S
        while "listening on" not in log.read_text():
            if any(p.poll() is not None for p in self.processes):
                raise SessionError(f"the router of host {name} exited: {log.read_text().strip()[-300:]}")
            if time.time() > deadline:
                raise SessionError(f"the router of host {name} did not listen within {ROUTER_READY_S:.0f} s")
            time.sleep(0.05)

    def close(self) -> None:
        stop_processes(self.processes)


class LinkEvents(threading.Thread):
    """Takes links down and up at their simulation times (wall time = epoch + t / speed); records when it did and
    the host's veth counters while its link is down (just after taking it down, just before bringing it up), so
    that what crossed the link while it was down — nothing — is a difference of two records."""

    def __init__(self, net: netns.Network, events: list[LinkDown], epoch: float, speed: float):
        super().__init__(name="link-events", daemon=True)
        self.net, self.epoch, self.speed = net, epoch, speed
        self.plan = sorted([(e.t_down, "down", e.host) for e in events]
                           + [(e.t_up, "up", e.host) for e in events if e.t_up is not None])
        self.done: list[dict] = []
        self.stop = threading.Event()

    def run(self) -> None:
        for t, what, host in self.plan:
            if self.stop.wait(max(0.0, self.epoch + t / self.speed - time.time())):
                return
            if what == "down":
                self.net.link_down(host)
                counters = self.net.counters(host)
            else:
                counters = self.net.counters(host)
                self.net.link_up(host)
            self.done.append({"t": t, "link": what, "host": host, "counters": counters,
                              "at_sim_s": round((time.time() - self.epoch) * self.speed, 3)})


class TestbedLauncher(Launcher):
    """:class:`Launcher` with each child in its host's namespace, a client of its host's router."""

    fork_agents = False  # each agent is started in its own host's namespace, not forked from one process

    def __init__(self, net: netns.Network, *args, link_down: list[LinkDown] = (), router_link: str = "tcp",
                 **kwargs):
        super().__init__(*args, **kwargs)
        if self.vehicle != "kinematic":
            raise ValueError("skymesh testbed flies the kinematic models (the autopilots talk MAVLink on loopback)")
        self.net = net
        self.link_down = list(link_down)
        self.router_link = router_link
        self.events: LinkEvents | None = None
        self.at_epoch: dict[str, dict[str, int]] = {}  # each host's counters at simulation time 0

    def _open_router(self) -> tuple[Routers, str]:
        return Routers(self.net, self.run_dir, self.env, self.router_link), f"tcp/127.0.0.1:{ROUTER_PORT}"

    def _command(self, name: str, role: str, args: list[str]) -> list[str]:
        return [*self.net.exec_prefix(name if role == "agent" else GROUND), sys.executable, *args]

    def _release(self) -> float | str:
        epoch = super()._release()
        self.at_epoch = {name: self.net.counters(name) for name in self.net.hosts}
        if isinstance(epoch, float) and self.link_down:
            self.events = LinkEvents(self.net, self.link_down, epoch, self.speed)
            self.events.start()
        return epoch


def bytes_check(agent: dict, sent: dict[str, int], peers: int, observer: bool, link: str = "tcp",
                listeners: int | None = None) -> dict:
    """What host ``uavK`` sent on its veth during the run (``sent``: the counters' growth from simulation time 0
    to the end) against what its agent says it sent, made comparable.

    A router forwards a message once to each remote router with a subscriber for it (over ``link``): a belief crosses
    the veth once per UAV host whose agent subscribes to this one's beliefs (``listeners``, default ``peers``: every
    other UAV host, unless the emulated radio is sparse, :meth:`agent.config.AgentScenario.senders_to`) and once
    more for the ground's observer when it runs; a topology report once per other UAV host (``peers``); telemetry
    and simulation data (the world subscribes) once. So the fair expectation is
    ``E = beliefs × (listeners + observer) + topology × peers + telemetry + simulation`` (the agent's
    own counts: ``bytes_tx_by_kind``, ``sim_bytes_tx_by_kind``), and ``ratio = kernel tx ÷ E``: above 1 by the
    framing (Ethernet 14 + IP 20 + TCP 32 or UDP 8 bytes per frame, Zenoh's batch and message headers), TCP's
    acknowledgements of what the host receives, and Zenoh's own traffic (keep-alives, declarations,
    liveliness). ``payload_ratio`` takes the frame headers out — every frame on the veth is ``link`` over IPv4
    (:data:`FRAME_HEADERS`), and a pure acknowledgement is nothing but headers — so that ``payload_ratio - 1``
    is Zenoh's own share: ``(kernel tx - FRAME_HEADERS[link] × tx packets) ÷ E``."""
    by_kind = agent.get("bytes_tx_by_kind", {})
    telemetry, topology = by_kind.get("telemetry", 0), by_kind.get("topology", 0)
    beliefs = sum(by_kind.values()) - telemetry - topology
    simulation = sum(agent.get("sim_bytes_tx_by_kind", {}).values())
    listeners = peers if listeners is None else listeners
    expected = beliefs * (listeners + observer) + topology * peers + telemetry + simulation
    payload = sent["tx_bytes"] - FRAME_HEADERS[link] * sent["tx_packets"]
    return {"agent_bytes_tx": int(sum(by_kind.values())), "agent_sim_bytes_tx": int(simulation), "peers": peers,
            "listeners": listeners,
            "unfanned_tx": int(telemetry + simulation),  # what only the ground's router receives
            "observer": observer, "expected_tx": int(expected), "kernel_tx": sent["tx_bytes"],
            "kernel_tx_packets": sent["tx_packets"], "ratio": sent["tx_bytes"] / expected if expected else None,
            "payload_ratio": payload / expected if expected else None}


def _listeners(scenario, name: str, names) -> int:
    """How many other UAV hosts' agents subscribe to ``name``'s beliefs
    (:meth:`agent.config.AgentScenario.senders_to`)."""
    return sum(1 for other in names if other != name
               and ((senders := scenario.senders_to(other)) is None or name in senders))


def run_testbed(scenario, run_dir: Path, link_down: list[LinkDown] = (), tbf_rate: float | None = None,
                tbf_burst: float | None = None, router_link: str = "tcp", tbf_per_link: bool = False,
                **launcher) -> RunOutcome:
    """``skymesh testbed``: the hosts made, the run, ``testbed.json`` written, the hosts removed (also on failure,
    Ctrl-C or SIGTERM). ``ValueError`` for bad settings, ``OSError`` when namespaces cannot be made here."""
    if router_link not in FRAME_HEADERS:
        raise ValueError(f"--router-link must be one of {sorted(FRAME_HEADERS)}, got {router_link!r}")
    if tbf_rate is not None and not tbf_rate > 0:
        raise ValueError(f"--tbf-rate must be positive bytes per second, got {tbf_rate:g}")
    if tbf_burst is not None and (tbf_rate is None or not tbf_burst > 0):
        raise ValueError(f"--tbf-burst must be positive bytes, with --tbf-rate; got {tbf_burst:g}")
    if tbf_per_link and tbf_rate is None:
        raise ValueError("--tbf-per-link needs --tbf-rate: the rate of each directed link")
    if tbf_per_link and router_link != "udp":
        raise ValueError("--tbf-per-link needs --router-link udp: its queues of one frame would drop most of a TCP "
                         "stream's segments")
    if (why := netns.unavailable()) is not None:
        raise OSError(f"no namespace test bed here: {why}")
    names = [f"uav{i}" for i in range(scenario.agent.agents)]
    for event in link_down:
        if event.host not in names:
            raise ValueError(f"--link-down: no host {event.host!r} in this run (hosts are uav0..{names[-1]})")
    try:
        with _sigterm_raises(), netns.network([GROUND, *names]) as net:  # SIGTERM while setting up: removed too
            if tbf_rate is not None:  # the UAVs' radios: the ground's traffic is the simulation's, not radio
                for name in names:
                    if tbf_per_link:
                        net.cap_links(name, [other for other in names if other != name], tbf_rate, tbf_burst)
                    else:
                        net.cap_rate(name, tbf_rate, tbf_burst)
            bed = TestbedLauncher(net, scenario, run_dir, link_down=link_down, router_link=router_link, **launcher)
            try:
                outcome = bed.run()
            finally:
                if bed.events is not None:
                    bed.events.stop.set()
                    bed.events.join()  # no link taken up while the namespaces go, nor an event recorded late
            counters = {name: net.counters(name) for name in net.hosts}
    except _Terminated:  # outside the run itself (which reports its own): there are no results
        raise OSError("terminated while the test bed was being set up or torn down; everything made is "
                      "removed") from None
    sent = {name: {k: v - bed.at_epoch.get(name, {}).get(k, 0) for k, v in counters[name].items()}
            for name in names}
    agents = {a["id"]: a for a in outcome.metrics.get("agents", [])}
    write_json(run_dir / TESTBED_FILE, {
        "hosts": {host.name: {"address": host.address, "at_end": counters[host.name],
                              "at_epoch": bed.at_epoch.get(host.name)} for host in net.hosts.values()},
        "tbf_rate": tbf_rate,
        "tbf_burst": tbf_burst,
        "tbf_per_link": tbf_per_link,
        "router_link": router_link,
        "link_events": bed.events.done if bed.events is not None else [],
        "bytes": {name: bytes_check(agents[name], sent[name], len(names) - 1, bed.rerun != "off", router_link,
                                    _listeners(scenario.agent, name, names))
                  for name in names if "bytes_tx_by_kind" in agents.get(name, {})},
    })
    return outcome
