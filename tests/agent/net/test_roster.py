"""Names inside a message checked against the fleet's roster (agent.net.roster, agent.net.wire.decode)."""

from __future__ import annotations

import numpy as np
import pytest

from agent.net import roster, wire

FLEET = frozenset({"uav0", "uav1", "uav2"})


def _decode(kind: str, payload: dict, acks: dict | None = None, fleet=FLEET) -> wire.Envelope:
    data = wire.encode(wire.Envelope(kind=kind, origin="uav1", seq=1, stamp=0.0, acks=acks or {}, payload=payload))
    return wire.decode(data, expected_origin="uav1", fleet=fleet)


VALID = {
    "topology": {"reports": {"uav1": [0.0, ["uav0", "uav2"]], "uav2": [0.0, ["uav1"]]}},
    "tasks": {"at": [0.0, 0.0], "stamps": {"uav0": 0.0, "uav1": 0.0}, "tasks": [["c0", 1.0, 2.0, "uav2", 3.0]]},
    "track": {"increments": [["uav2", 1, np.zeros((1, 9))]], "acks": {"uav0": [3, 7]}},
    "grid": {"acks": {"uav2": 4}},
}
#: each place a name can hide, with a name outside the fleet put there (the bad input)
STRANGERS = [
    ("topology", {"reports": {"uav1": [0.0, ["uav0", "uav7"]]}}),  # a neighbour
    ("topology", {"reports": {"ghost": [0.0, ["uav1"]]}}),  # a reporting agent
    ("tasks", {"at": [0.0, 0.0], "stamps": {"uav9": 0.0}, "tasks": []}),  # a CBBA timestamp
    ("tasks", {"at": [0.0, 0.0], "stamps": {}, "tasks": [["c0", 1.0, 2.0, "intruder", 3.0]]}),  # a winner
    ("track", {"increments": [["uav3", 1, np.zeros((1, 9))]]}),  # a flooded increment's origin
    ("track", {"acks": {"uav4": [0, 1]}}),  # the flood's acks
    ("grid", {"acks": {"uav5": 1}}),  # a grid's acks
]


@pytest.mark.parametrize("kind", sorted(VALID))
def test_a_message_naming_only_members_decodes(kind):
    assert _decode(kind, VALID[kind]).payload.keys() == VALID[kind].keys()


@pytest.mark.parametrize(("kind", "payload"), STRANGERS)
def test_a_name_outside_the_fleet_anywhere_in_a_typed_payload_is_unknown_name(kind, payload):
    with pytest.raises(wire.DecodeError) as err:
        _decode(kind, payload)
    assert err.value.reason == "unknown_name"
    assert _decode(kind, payload, fleet=None).kind == kind  # without a roster the wire does not judge names


def test_a_stranger_in_the_envelope_acks_is_unknown_name_and_the_error_names_it():
    with pytest.raises(wire.DecodeError, match="names outside the fleet: uav8") as err:
        _decode("grid", {}, acks={"uav0": 1, "uav8": 2})
    assert err.value.reason == "unknown_name"


def test_strangers_lists_every_outside_name_once_sorted():
    payload = {"reports": {"uav1": [0.0, ["zed", "uav0", "abe"]], "zed": [0.0, ["uav1"]]}}
    assert roster.strangers("topology", {}, payload, FLEET) == ["abe", "zed"]
    assert roster.strangers("telemetry", {}, {"anything": ["uav9"]}, FLEET) == []  # kinds that name no agent
