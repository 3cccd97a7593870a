"""``skymesh router --config deploy/router.json5``: Zenoh mutual TLS and access control on loopback (issue 16).

The shipped configs of ``deploy/`` are copied into a folder with certificates made here (``tests.tls_certs``),
changed only as ``deploy/README.md`` tells a user to (the router's port, one client file per certificate), and
every process runs from that folder, as the README says. Real processes: a ``skymesh router`` and two
``python -m agent``; the other sessions (the ground station, intruders) are opened in this process.
Everything started here is stopped by its PID.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
import uuid
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest
import zenoh

from agent.net import wire
from agent.net.fleet_key import new_key_file, read_key_file
from agent.net.zenoh_transport import client_config
from mesh_sim import cli
from mesh_sim.launcher import free_port
from mesh_sim.scenario import load
from tests.processes import assert_all_gone
from tests.tls_certs import write_fleet_certs

REPO = Path(__file__).resolve().parents[2]
DEPLOY = REPO / "deploy"
CLIENTS = ["uav0", "uav1", "ground", "world", "stranger"]  # stranger: a CN router.json5 does not name
AGENTS_TIMEOUT_S = 60.0  # for the agents to start and to hear each other, however loaded the machine
REPORTS = 6  # topology reports heard from each agent: 3-12 s of beacons or refreshes (agent.net.topology)
REPEATS = 5  # puts of one declared publisher
SETTLE_S = 1.0  # for declarations to reach the router and back before a put (chosen here; loopback takes ms)


@dataclass
class Deployment:
    folder: Path  # configs and certs/, the processes' working folder
    port: int

    def session(self, name: str) -> zenoh.Session:
        """A session with ``name``'s certificate, from its copy of ``deploy/agent.json5`` (raises if refused)."""
        with contextlib.chdir(self.folder):  # the config's certificate paths are relative, as shipped
            return zenoh.open(zenoh.Config.from_file(f"{name}.json5"))


def _deploy(folder: Path, port: int) -> None:
    """The user's steps of ``deploy/README.md``: certificates in ``certs/``, the router's port set, and one copy of
    the agent's config per certificate."""
    write_fleet_certs(folder / "certs", CLIENTS)
    address = f"localhost:{port}"
    (folder / "router.json5").write_text((DEPLOY / "router.json5").read_text().replace("localhost:7447", address))
    agent = (DEPLOY / "agent.json5").read_text().replace("localhost:7447", address)
    for name in [*CLIENTS, "rogue"]:
        (folder / f"{name}.json5").write_text(agent.replace("uav0", name))


def _env() -> dict[str, str]:
    """The children import this checkout's code although they run from another folder."""
    return {**os.environ, "PYTHONPATH": str(REPO)}


@pytest.fixture(scope="module")
def deployment(tmp_path_factory):
    folder = tmp_path_factory.mktemp("deploy")
    port = free_port()
    _deploy(folder, port)
    router = subprocess.Popen([sys.executable, "-m", "mesh_sim", "router", "--config", "router.json5"], cwd=folder,
                              env=_env(), stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True)
    try:
        banner = router.stdout.readline()  # printed once the router listens; "" if it exited
        if f"listening on tls/localhost:{port}; mutual TLS on; access control on" not in banner:
            router.kill()
            pytest.fail(f"the router did not start as configured: {banner!r} {router.communicate()[1][-2000:]}")
        yield Deployment(folder, port)
        router.send_signal(signal.SIGTERM)
        assert router.wait(timeout=15) == 0, router.stderr.read()
    finally:
        if router.poll() is None:
            router.kill()
            router.wait()
        assert_all_gone([router.pid])


class Heard:
    """What one session receives under a key expression: samples by key, liveliness tokens by key."""

    def __init__(self, session: zenoh.Session, key_expr: str, alive_expr: str | None = None):
        self.samples: Counter[str] = Counter()
        self.payloads: dict[str, bytes] = {}
        self.alive: set[str] = set()
        self._subscribers = [session.declare_subscriber(key_expr, self._on_sample)]
        if alive_expr is not None:
            self._subscribers.append(session.liveliness().declare_subscriber(alive_expr, self._on_token, history=True))

    def _on_sample(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        self.samples[key] += 1
        self.payloads[key] = sample.payload.to_bytes()

    def _on_token(self, sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.PUT:
            self.alive.add(str(sample.key_expr))


def _run_agents(deployment: Deployment, fleet: str, until: Callable[[bytes], bool],
                progress: Callable[[], object]) -> list[dict]:
    """Two agent processes of the default scenario over mTLS, started together and stopped (SIGTERM, as a user's
    Ctrl-C) once ``until(fleet_key)`` holds: a condition on what was heard, not a duration, so that a loaded
    machine that slows the agents down does not fail the test (``progress()`` says how far it got if it never
    holds). Their metrics."""
    folder = deployment.folder / fleet
    folder.mkdir()
    scenario = folder / "scenario.json"
    scenario.write_text(json.dumps(load("default", agents=2, duration=AGENTS_TIMEOUT_S).raw))
    key_file = new_key_file(folder)
    epoch_file = folder / "epoch"
    agents = []
    logs = [folder / f"uav{i}.stderr" for i in range(2)]  # files, not pipes: a full pipe would stall an agent

    def tails() -> list[str]:
        return [log.read_text()[-2000:] for log in logs]

    def wait_for(condition: Callable[[], bool], what: str) -> None:
        deadline = time.time() + AGENTS_TIMEOUT_S
        while not condition():
            assert all(a.poll() is None for a in agents), tails()
            assert time.time() < deadline, f"{what} within {AGENTS_TIMEOUT_S:.0f} s"
            time.sleep(0.05)

    try:
        for i in range(2):
            name = f"uav{i}"
            with open(logs[i], "wb") as err:
                agents.append(subprocess.Popen(
                    [sys.executable, "-m", "agent", "--id", name, "--index", str(i), "--fleet", fleet,
                     "--scenario", str(scenario), "--zenoh-config", f"{name}.json5", "--fleet-key-file", str(key_file),
                     "--out", str(folder), "--epoch-file", str(epoch_file),
                     "--ready-file", str(folder / f"{name}.ready"), "--parent-pid", str(os.getpid())],
                    cwd=deployment.folder, env=_env(), stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=err))
        wait_for(lambda: all((folder / f"uav{i}.ready").exists() for i in range(2)), "the agents were not ready")
        epoch_file.write_text(repr(time.time()))
        fleet_key = read_key_file(key_file)
        wait_for(lambda: until(fleet_key), f"the condition did not hold (heard: {progress()})")
        for agent in agents:
            agent.send_signal(signal.SIGTERM)
        assert [a.wait(timeout=30) for a in agents] == [0, 0], tails()
    finally:
        for agent in agents:
            if agent.poll() is None:
                agent.kill()
                agent.wait()
    assert_all_gone([a.pid for a in agents])
    return [json.loads((folder / f"agent-uav{i}.json").read_text()) for i in range(2)]


def _neighbours(heard: Heard, root: str, name: str, fleet_key: bytes) -> list[str]:
    """The neighbours in ``name``'s last topology report that ``heard`` received (none if it received none)."""
    data = heard.payloads.get(f"{root}/topology/{name}")
    if data is None:
        return []
    return wire.decode(data, expected_origin=name, key=fleet_key).payload["reports"][name][1]


@pytest.mark.slow
def test_two_agents_exchange_beliefs_over_mutual_tls(deployment):
    """The shipped configs work end to end, for as long as the agents run (not just for a key's first message):
    the ground station (its own certificate) hears :data:`REPORTS` topology reports from each agent, the last one
    naming the other agent as its neighbour (they hear each other through the router), and both agents' beliefs
    and liveliness tokens."""
    fleet = f"mtls-{uuid.uuid4().hex[:8]}"
    root = f"skymesh/{fleet}"
    with deployment.session("ground") as ground:
        heard = Heard(ground, f"{root}/**", f"{root}/alive/*")

        def each_hears_the_other(fleet_key: bytes) -> bool:
            return all(heard.samples[f"{root}/topology/uav{i}"] >= REPORTS
                       and _neighbours(heard, root, f"uav{i}", fleet_key) == [f"uav{1 - i}"] for i in range(2))

        metrics = _run_agents(deployment, fleet, until=each_hears_the_other, progress=lambda: dict(heard.samples))
        alive = set(heard.alive)
    for i, agent in enumerate(metrics):
        peer = f"uav{1 - i}"
        assert agent["bytes_rx_by_peer"].get(peer), (f"uav{i} heard nothing from {peer}", agent["bytes_rx_by_peer"])
        assert not agent["rejected_by_reason"], agent["rejected_by_reason"]
    for name in ("uav0", "uav1"):
        assert any(k.startswith(f"{root}/belief/") and k.endswith(f"/{name}") for k in heard.samples), heard.samples
        assert f"{root}/alive/{name}" in alive


@pytest.mark.slow
def test_a_client_without_a_fleet_certificate_cannot_open_a_session(deployment):
    """With mTLS a process without a certificate from the fleet's CA cannot connect at all: neither over TLS
    without a certificate, nor with a certificate (CN uav0) from another CA, nor over plain TCP."""
    with deployment.session("ground") as ground:
        heard = Heard(ground, "skymesh/**")
        time.sleep(SETTLE_S)
        no_certificate = client_config([f"tls/localhost:{deployment.port}"])
        no_certificate.insert_json5("transport/link/tls/root_ca_certificate",
                                    json.dumps(str(deployment.folder / "certs" / "ca.pem")))
        refused = {"no certificate": lambda: zenoh.open(no_certificate),
                   "rogue CA": lambda: deployment.session("rogue"),
                   "plain tcp": lambda: zenoh.open(client_config([f"tcp/localhost:{deployment.port}"]))}
        for what, open_session in refused.items():
            started = time.time()
            with pytest.raises(zenoh.ZError, match="Unable to connect"):
                open_session().put("skymesh/intruder/belief/track/uav0", what.encode())
            assert time.time() - started < 10, what
        time.sleep(SETTLE_S)
    assert not heard.samples, heard.samples


@pytest.mark.slow
def test_an_agent_process_with_a_rogue_certificate_stops_at_start(deployment):
    """``python -m agent`` with a certificate of another CA (its CN uav0) cannot join the fleet: one line on stderr
    and exit code 2 before its loop starts (Zenoh says only that the router could not be reached)."""
    scenario = deployment.folder / "rogue-scenario.json"
    scenario.write_text(json.dumps(load("default", agents=1, duration=1.0).raw))
    done = subprocess.run(
        [sys.executable, "-m", "agent", "--id", "uav0", "--index", "0", "--fleet", "rogue", "--scenario", str(scenario),
         "--zenoh-config", "rogue.json5", "--out", str(deployment.folder), "--parent-pid", str(os.getpid())],
        cwd=deployment.folder, env=_env(), stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE, text=True, timeout=60)  # run kills the process by its PID if it outlives this
    assert done.returncode == 2, done.stderr[-3000:]
    assert done.stderr.startswith("agent uav0: the Zenoh router could not be reached (Unable to connect to any of"), \
        done.stderr
    assert done.stderr.count("\n") == 1, done.stderr
    assert not (deployment.folder / "agent-uav0.json").exists()


@pytest.mark.slow
def test_an_agent_may_publish_only_under_its_own_name(deployment):
    """Access control: uav1's certificate may put on uav1's keys, every time (the router tells its publisher that
    someone listens), and declare uav1's liveliness token (which a ground station joining later still learns),
    and not on another agent's keys or the world's truth; the world
    may put the truth, which agents hear. A certificate of the fleet's CA whose CN the router does not name opens
    a session in which nothing is allowed: it hears nothing and nobody hears it (only its own put, locally)."""
    fleet = f"acl-{uuid.uuid4().hex[:8]}"
    root = f"skymesh/{fleet}"
    forged = {f"{root}/belief/track/uav0", f"{root}/topology/uav0", f"{root}/telemetry/uav0", f"{root}/sim/truth",
              f"{root}/sim/measurement/uav0"}
    own = {f"{root}/belief/track/uav1", f"{root}/topology/uav1", f"{root}/telemetry/uav1"}
    with (deployment.session("ground") as ground, deployment.session("uav0") as uav0,
          deployment.session("stranger") as stranger):
        with deployment.session("uav1") as uav1, deployment.session("world") as world:
            tokens = [uav1.liveliness().declare_token(f"{root}/alive/{name}") for name in ("uav0", "uav1")]
            time.sleep(SETTLE_S)  # the ground station joins later: it learns the tokens from its history
            watch, agent_heard = Heard(ground, f"{root}/**", f"{root}/alive/*"), Heard(uav0, f"{root}/sim/truth")
            stranger_heard = Heard(stranger, f"{root}/**")
            time.sleep(SETTLE_S)
            for key in sorted(forged | own):
                uav1.put(key, b"from uav1")
            publisher = uav1.declare_publisher(f"{root}/belief/track/uav1")  # as an agent publishes, again and again
            time.sleep(SETTLE_S)
            for _ in range(REPEATS):
                publisher.put(b"from uav1")
            world.put(f"{root}/sim/truth", b"from the world")
            stranger.put(f"{root}/belief/track/stranger", b"from a certificate the router does not name")
            time.sleep(SETTLE_S)
            alive = set(watch.alive)
            for token in tokens:
                token.undeclare()
    assert set(watch.samples) == own | {f"{root}/sim/truth"}, watch.samples
    assert watch.samples[f"{root}/belief/track/uav1"] == 1 + REPEATS, watch.samples  # it knew someone listens
    assert watch.payloads[f"{root}/sim/truth"] == b"from the world"
    assert agent_heard.payloads == {f"{root}/sim/truth": b"from the world"}
    assert alive == {f"{root}/alive/uav1"}
    assert stranger_heard.payloads == {f"{root}/belief/track/stranger": b"from a certificate the router does not name"}


def test_a_missing_or_bad_config_is_one_line_and_exit_code_2(tmp_path, capsys):
    """A file that is missing, not JSON5, has a misspelt field or names a key that does not exist."""
    bad = tmp_path / "bad.json5"
    bad.write_text('{ mode: "router", listen: { endpoints: [ }')
    unknown = tmp_path / "unknown.json5"
    unknown.write_text('{ mode: "router", transport: { link: { tls: { enable_mtl: true } } } }')  # a typo
    no_key = tmp_path / "no_key.json5"
    no_key.write_text(json.dumps({"listen": {"endpoints": [f"tls/127.0.0.1:{free_port()}"]},
                                  "transport": {"link": {"tls": {"listen_certificate": "certs/none.pem",
                                                                 "listen_private_key": "certs/none-key.pem"}}}}))

    def refused(path: Path) -> str:
        assert cli.main(["router", "--config", str(path)]) == cli.EXIT_USAGE
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and ".rs:" not in err, err
        return err

    for path, says in ((tmp_path / "missing.json5", "No such file"), (bad, "--> 1:42"),
                       (unknown, "unknown field `enable_mtl`")):
        err = refused(path)
        assert err.startswith(f"skymesh router: cannot read Zenoh config {path}: ") and says in err, err
    err = refused(no_key)
    assert err.startswith("skymesh router: cannot open the Zenoh session (Cannot create a new TLS listener"), err
    assert "Invalid TLS private key file" in err, err
