"""Lost agents in the run's metrics: the radio's emulated ``node_loss`` (lockstep here) and a killed agent
process (tests/mesh_sim/test_live_run.py) are reported in one shape, ``metrics["losses"]``, with how long each
survivor took to notice."""

from __future__ import annotations

import json

import pytest

from mesh_sim.launcher import Death
from mesh_sim.lockstep import run_lockstep
from mesh_sim.results import DEATHS_FILE, losses
from mesh_sim.scenario import load


class _Scenario:
    def __init__(self, raw: dict):
        self.raw = raw


def _agent(name: str, heard: dict[str, float]) -> dict:
    return {"id": name, "peers_last_heard": heard, "neighbour_timeout": 3.0}


def test_a_node_loss_is_noticed_one_neighbour_timeout_after_the_last_message(tmp_path):
    """A lockstep run where uav2's radio goes dark at t = 4 s: the survivors heard it last just before and
    drop it from their neighbours 3 s (the neighbour timeout) later."""
    scenario = load("default", agents=3, duration=10.0,
                    radio={"topology": "full", "events": [{"t": 4.0, "kind": "node_loss", "node": "uav2"}]})
    metrics = run_lockstep(scenario, tmp_path)
    (loss,) = metrics["losses"]
    assert (loss["agent"], loss["t"], loss["cause"]) == ("uav2", 4.0, "node_loss")
    assert set(loss["detected_after"]) == {"uav0", "uav1"}
    for seconds in loss["detected_after"].values():
        assert 2.5 <= seconds <= 3.0 + 1e-9, loss
    assert json.loads((tmp_path / "metrics.json").read_text())["losses"] == metrics["losses"]


def test_a_killed_process_and_a_node_loss_have_the_same_shape(tmp_path):
    """The launcher's record of a SIGKILLed agent and an emulated node loss give the same keys (plus the
    process's PID and exit code); a survivor that never heard the lost agent says so with None."""
    death = Death("uav1", "agent", 4242, -9, 12.5)
    observer = Death("observer", "observer", 7, 1, 3.0)  # not an agent: no loss of the fleet
    (tmp_path / DEATHS_FILE).write_text(json.dumps([death.to_dict(), observer.to_dict()]))
    scenario = _Scenario({"radio_plan": {"down_nodes": [{"t": 20.0, "node": "uav2"}]}})
    agents = [_agent("uav0", {"uav1": 12.3, "uav2": 19.9}), _agent("uav3", {"uav2": 19.5}),
              {"id": "uav1", "status": "died: no metrics written"}, _agent("uav2", {"uav0": 19.9})]
    emulated, killed = losses(tmp_path, scenario, agents)
    assert emulated == {"agent": "uav2", "t": 20.0, "cause": "node_loss",
                        "detected_after": {"uav0": pytest.approx(2.9), "uav3": pytest.approx(2.5)}}
    assert killed == {"agent": "uav1", "t": 12.5, "cause": "killed by SIGKILL", "pid": 4242, "exit_code": -9,
                      "restarted_as": None, "detected_after": {"uav0": pytest.approx(2.8), "uav3": None}}
    assert set(killed) - {"pid", "exit_code", "restarted_as"} == set(emulated)


def test_a_restarted_agent_reports_when_each_survivor_heard_its_new_life(tmp_path):
    """``skymesh run --restart``: uav1 died at 12.5 s and came back as incarnation 1; uav0 heard the new life
    at 16 s, uav3 never did (None). It counts as no loss for the other losses' survivors."""
    death = Death("uav1", "agent", 4242, -9, 12.5, restarted_as=1)
    (tmp_path / DEATHS_FILE).write_text(json.dumps([death.to_dict()]))
    agents = [{**_agent("uav0", {"uav1": 30.0}), "peer_restarts": [["uav1", 1, 16.0]]}, _agent("uav3", {}),
              {**_agent("uav1", {"uav0": 30.0}), "incarnation": 1}]
    (loss,) = losses(tmp_path, _Scenario({}), agents)
    assert loss["rejoined_after"] == {"uav0": pytest.approx(3.5), "uav3": None} and "detected_after" not in loss


def test_a_death_names_its_cause():
    assert Death("uav0", "agent", 1, -9, 0.0).cause == "killed by SIGKILL"
    assert Death("uav0", "agent", 1, 3, 0.0).cause == "exit code 3"
    assert Death("uav0", "agent", 1, -200, 0.0).cause == "killed by signal 200"


def test_no_losses_no_entries(tmp_path):
    """A run without deaths or node_loss events (no deaths file at all: a lockstep run) reports none."""
    assert losses(tmp_path, _Scenario({}), [_agent("uav0", {})]) == []


def test_a_lost_agents_target_is_taken_over_by_a_survivor(tmp_path):
    """The running fleet (lockstep, 3 agents, the default scenario's CBBA assignment): uav1 serves the car when
    its radio goes dark at t = 12 s. Each survivor releases uav1's claims ``peer_timeout`` (5 s) after it last
    heard of it, and one of them serves the car within a second after that; no survivor believes uav1 serves
    anything afterwards."""
    scenario = load("default", agents=3, duration=24.0,
                    radio={"topology": "full", "events": [{"t": 12.0, "kind": "node_loss", "node": "uav1"}]})
    agents = {a["id"]: a for a in run_lockstep(scenario, tmp_path)["agents"]}
    before = [served for t, served in agents["uav0"]["assignment"]["timeline"] if t < 12.0][-1]
    assert before.get("car") == "uav1", before  # the setting of the test: uav1 held the car
    for survivor in ("uav0", "uav2"):
        assignment = agents[survivor]["assignment"]
        ((t_expired, who),) = assignment["expired"]
        assert who == "uav1" and 16.0 < t_expired <= 17.5, assignment["expired"]
        after = [(t, served) for t, served in assignment["timeline"] if t > t_expired]
        assert after and all("uav1" not in served.values() for _, served in after)
        assert any(served.get("car") in ("uav0", "uav2") for t, served in after if t <= t_expired + 1.0), after
