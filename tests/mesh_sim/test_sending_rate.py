"""``[sending] rate``: the link budget of a network the agents cannot see (a real radio, the test bed's ``tbf``),
kept by every agent of a run with no emulated rate cap."""

from __future__ import annotations

from mesh_sim.lockstep import run_lockstep
from mesh_sim.scenario import load

DURATION_S = 20.0
RATE, BURST = 600.0, 4000.0  # bytes/s, bytes: well below what an agent sends unbounded (~2-3 kB/s with bearings)


def _sent(tmp_path, **sending) -> dict[str, int]:
    scenario = load("default", agents=3, duration=DURATION_S, sensor={"kind": "bearing"}, sending=sending,
                    radio={"topology": "full", "preset": "ideal"})
    tmp_path.mkdir()
    metrics = run_lockstep(scenario, tmp_path)
    return {a["id"]: sum(a["bytes_tx_by_kind"].values()) for a in metrics["agents"]}


def test_a_run_without_a_rate_cap_keeps_the_told_rate(tmp_path):
    told = _sent(tmp_path / "told", rate=RATE, burst=BURST)
    unbounded = _sent(tmp_path / "unbounded")
    for agent, sent in told.items():
        assert sent <= RATE * DURATION_S + BURST, (agent, sent)  # the token bucket's bound: rate T + depth
        assert sent >= 0.8 * RATE * DURATION_S, (agent, sent)  # and the budget was used, not left idle
        assert unbounded[agent] > 2 * (RATE * DURATION_S + BURST), (agent, unbounded[agent])  # it bound
