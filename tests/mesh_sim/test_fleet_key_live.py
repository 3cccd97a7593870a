"""Secure by default: `skymesh run` makes a fleet key per run and every process signs and checks with it; a
process on the router without the key injects nothing (reliability audit: "a forged uav0 track was adopted by
all 4 agents within 1.2 s and silenced the real uav0"; "a fleet key cannot be used in simulated runs")."""

from __future__ import annotations

import stat
import threading
import time

import pytest
import zenoh

from agent.net import wire
from agent.net.keys import Keys
from agent.net.zenoh_transport import client_config
from mesh_sim.launcher import Launcher, new_run_dir
from mesh_sim.scenario import load
from tests.processes import assert_all_gone

FORGED = 10_000


def _forge(launcher: Launcher, sent: list[int]) -> None:
    """Once the run is on, publish FORGED messages on the fleet's keys from a session of our own: tracks and
    truths that claim to come from uav1 and from the world, half unsigned, half signed with a wrong key, all with the
    fleet's Zenoh encoding (a forger that knows the format: only the MAC stops it)."""
    deadline = time.time() + 60
    while time.time() < deadline and not launcher._epoch_file.exists():
        time.sleep(0.1)
    endpoint = next(a for c in launcher.children for a in c.args if a.startswith("tcp/"))
    keys = Keys(launcher.fleet)
    ghost_truth = {"targets": [{"id": "ghost", "position": [9999.0, 9999.0, 0.0], "velocity": [0.0, 0.0, 0.0]}]}
    with zenoh.open(client_config([endpoint])) as session:
        for n in range(FORGED):
            wrong = b"not the fleet key" if n % 2 else None
            if n % 4 < 2:
                env = wire.Envelope(kind="track", origin="uav1", seq=10**12 + n, stamp=1.0, payload={"tracks": []})
                key = keys.belief("track", "uav1")
            else:
                env = wire.Envelope(kind="truth", origin="world", seq=10**12 + n, stamp=1.0, payload=ghost_truth)
                key = keys.sim("truth")
            session.put(key, wire.encode(env, wrong), encoding=zenoh.Encoding(wire.ZENOH_ENCODING))  # as the fleet's
            sent[0] += 1
            if n % 500 == 499:
                time.sleep(0.2)  # a sustained attack over the run, not one burst the queues would drop


@pytest.mark.slow
def test_a_process_without_the_fleet_key_injects_nothing(tmp_path):
    scenario = load("default", duration=20.0, agents=3)
    launcher = Launcher(scenario, new_run_dir(tmp_path, "forged"), speed=1.0, rerun="save")
    sent = [0]
    forger = threading.Thread(target=_forge, args=(launcher, sent), daemon=True)
    forger.start()
    outcome = launcher.run()
    forger.join(timeout=30)
    assert outcome.status == "completed", outcome.status
    assert_all_gone(outcome.pids.values())
    assert sent[0] == FORGED
    key_file = outcome.run_dir / "fleet.key"
    assert stat.S_IMODE(key_file.stat().st_mode) == 0o600
    secret = key_file.read_text().strip()
    for path in outcome.run_dir.rglob("*"):  # never in the metrics, the logs or the recording
        if path.is_file() and path != key_file:
            assert secret.encode() not in path.read_bytes(), path
    for agent in outcome.metrics["agents"]:
        rejected = agent["rejected_by_reason"]
        assert set(rejected) <= {"bad_mac", "duplicate"}, rejected  # the fleet's own messages all pass
        assert rejected.get("bad_mac", 0) > FORGED // 10, rejected  # the forged ones reach it and are refused
        assert all(t["target"] != "ghost" for t in agent["targets"])
        assert agent["bytes_rx_by_peer"].get("uav1", {}).get("track", 0) < 10**6  # uav1 itself still heard
    assert outcome.metrics["fleet"]["rmse_ratio_to_oracle"] < 2.0  # the real uav1 was not silenced
