"""``skymesh bench fuzz``: the quick run end to end on a tiny budget, and each detector proven to fire on a planted
fault (a receive path that raises, stalls or takes an invalid input in silence), so that the bench cannot
report 0 because it looks nowhere."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest

from agent.net import wire
from mesh_sim.bench import fuzz, fuzz_seeds
from mesh_sim.bench.fuzz_mutate import FAMILIES, Mutator

BUDGET = 2 * len(FAMILIES)  # every family twice


def test_a_tiny_run_covers_every_kind_twice_and_finds_nothing(tmp_path):
    result = fuzz.run(quick=True, inputs=(BUDGET, len(FAMILIES)))
    assert {"benchmark", "settings", "environment", "rows", "goals"} <= set(result)
    rows = result["rows"]
    assert [(r["kind"], r["keyed"]) for r in rows] == [(s.name, k) for s in fuzz_seeds.CASES for k in (False, True)]
    for r in rows:
        assert r["inputs"] == (len(FAMILIES) if r["keyed"] else BUDGET)
        assert set(r["families"]) == set(FAMILIES) and r["invalid_inputs"] > 0
        assert r["decoder"]["crashes"] == r["agent"]["crashes"] == r["accepted_invalid"] == 0, r
        assert r["baseline_us"] > 0 and r["inputs_per_s"] > 0
    goals = {g["name"]: g["pass"] for g in result["goals"]}
    assert goals == {"inputs": False, "crashes": True, "hangs": goals["hangs"], "accepted_invalid": True}
    path = tmp_path / "fuzz.json"
    path.write_text(json.dumps(result))
    assert json.loads(path.read_text())["benchmark"] == "fuzz"


def test_kinds_fuzzes_only_the_kinds_named_and_refuses_unknown_ones():
    result = fuzz.run(quick=True, inputs=(len(FAMILIES), len(FAMILIES)), kinds=("clock",))
    assert [(r["kind"], r["keyed"]) for r in result["rows"]] == [("clock", False), ("clock", True)]
    assert result["settings"]["kinds"] == ["clock"]
    with pytest.raises(ValueError, match="unknown fuzz kinds"):
        fuzz.run(quick=True, kinds=("clock", "nope"))


@pytest.fixture(scope="module")
def track_cases():
    """Four copies of the channel-filter track case (each planted run gets an agent of its own)."""
    return fuzz_seeds.cases([fuzz_seeds.CASES[0]], (None, None, None, None))


class Planted(fuzz.AgentTarget):
    """The real agent, with a fault planted on the inputs of one family."""

    def __init__(self, case, family: str, fault: str):
        super().__init__(case)
        self.family, self.fault, self.planted = family, fault, 0

    def decode(self, inp):
        if self.fault == "decoder" and inp.family == self.family:
            raise KeyError("planted")
        super().decode(inp)

    def receive(self, inp):
        if inp.family != self.family or self.fault == "decoder":
            return super().receive(inp)
        if self.fault == "crash":
            raise RuntimeError("planted")
        if self.fault == "hang":  # busy: hangs are judged on CPU time
            end = time.thread_time() + 1.2 * fuzz.HANG_S
            while time.thread_time() < end:
                pass
            return super().receive(inp)
        self.planted += 1
        self.agent.topology.heard(f"intruder{self.planted}", self.case.now)  # "accepted": a change, uncounted


@pytest.mark.parametrize("i, fault, family", [(0, "crash", "type"), (1, "decoder", "bitflip"), (2, "hang", "kind"),
                                              (3, "accepted", "origin")])
def test_each_detector_fires_on_a_planted_fault(track_cases, i, fault, family):
    case = track_cases[i]
    result = fuzz.fuzz_case(case, BUDGET, np.random.default_rng(0), Planted(case, family, fault))
    planted = result["families"][family]
    assert planted == 2
    if fault == "crash":
        assert result["agent"]["crashes_by_kind"] == {f"RuntimeError ({family})": planted}
        assert len(result["agent"]["examples"]) == planted and result["agent"]["examples"][0]["hex"]
    elif fault == "decoder":
        assert result["decoder"]["crashes_by_kind"] == {f"KeyError ({family})": planted}
        assert result["agent"]["crashes"] == 0
    elif fault == "hang":
        assert result["agent"]["hangs_by_family"][family] == planted
        assert result["agent"]["slowest_ms"] > 1e3 * fuzz.HANG_S
    else:
        assert result["accepted_invalid_by_family"] == {family: planted}
        assert len(result["accepted_invalid_examples"]) == planted


def test_a_wrong_origin_is_never_the_senders_own_name(track_cases):
    """The fuzzer's sender takes other fleet members' names (uav2, ...) once it spent a sequence window: a "wrong
    origin" drawn from uav2 .. uav99 was once its own name, a valid message counted as an accepted invalid one."""
    mutator = Mutator(track_cases[0], np.random.default_rng(0))
    mutator.origin = "uav7"
    origins = {wire.peek_header(mutator.make("origin").data).origin for _ in range(500)}
    assert "uav7" not in origins and len(origins) > 50
