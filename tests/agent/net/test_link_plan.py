"""The link plan (agent/net/link_plan.py and its checks, agent/net/plan_checks.py): parameters, presets,
netem commands, per-link overrides, and errors that say where they are."""

import json
import math

import pytest

from agent.net.link_plan import PRESETS, GilbertElliott, LinkParams, LinkPlan, netem_command

AGENTS = ["uav0", "uav1", "uav2", "uav3"]


def plan(default=None, seed=7, **extra):
    return {"agents": AGENTS, "seed": seed, "default": default or {}, **extra}


# ---- parameters ---------------------------------------------------------------------------------------


def test_default_burst():
    assert LinkParams(rate=1e5).bucket_depth == 64 * 1024
    assert LinkParams(rate=1e7).bucket_depth == pytest.approx(1e6)
    assert LinkParams(rate=1e7, burst=3000).bucket_depth == 3000
    assert LinkParams(rate=0).rate is None and LinkParams(rate=0).bucket_depth is None


def test_per_link_overrides():
    p = plan({"loss": 0.0, "delay_ms": 1.0}, links=[{"src": "uav1", "dst": "uav0", "loss": 1.0}])
    lp = LinkPlan.from_dict(p)
    assert lp.params("uav1", "uav0").loss == 1.0 and lp.params("uav1", "uav0").delay_ms == 1.0
    assert lp.params("uav0", "uav1").loss == 0.0  # directed
    p = plan({"ge": {"p": 0.1, "r": 0.5}}, links=[{"src": "uav1", "dst": "uav0", "loss": 0.2}])
    assert LinkPlan.from_dict(p).params("uav1", "uav0") == LinkParams(loss=0.2)


def test_plan_is_plain_json_data():
    p = plan({"ge": {"p": 0.1, "r": 0.5}}, range=50.0, phases=[{"t": 0, "edges": [["uav0", "uav1"]]}])
    assert LinkPlan.from_dict(json.loads(json.dumps(p))).params("uav0", "uav1").ge == GilbertElliott(0.1, 0.5)


# ---- presets and netem commands ---------------------------------------------------------------------


def test_senders_to_is_who_can_ever_reach_an_agent():
    line = [["uav0", "uav1"], ["uav1", "uav2"], ["uav2", "uav3"]]
    names = ["uav0", "uav1", "uav2", "uav3"]
    plan = LinkPlan.from_dict({"agents": names, "seed": 1, "phases": [{"t": 0.0, "edges": line}]})
    assert plan.senders_to("uav0") == ("uav1",) and plan.senders_to("uav2") == ("uav1", "uav3")
    # a later phase's link counts; a link cut one way in every phase does not, that way
    plan = LinkPlan.from_dict({"agents": names, "seed": 1, "phases": [
        {"t": 0.0, "edges": line, "cut": [["uav1", "uav0"]]},
        {"t": 10.0, "edges": [*line, ["uav0", "uav3"]], "cut": [["uav1", "uav0"]]}]})
    assert plan.senders_to("uav0") == ("uav3",) and plan.senders_to("uav1") == ("uav0", "uav2")
    # every pair connected in some phase, or a range known only at run time: everyone may be heard
    assert LinkPlan.from_dict({"agents": names, "seed": 1}).senders_to("uav0") is None
    assert LinkPlan.from_dict({"agents": names, "seed": 1, "range": 100.0,
                               "phases": [{"t": 0.0, "edges": line}]}).senders_to("uav0") is None
    with pytest.raises(ValueError, match="'uav9' is not in the link plan"):  # bad input: a name outside the team
        plan.senders_to("uav9")


def test_presets_parse_and_match_the_anchors():
    assert set(PRESETS) == {"ideal", "wifi", "cellular", "lossy"}
    for params in PRESETS.values():
        assert LinkParams.from_dict(params.to_dict()) == params
        assert LinkParams.from_dict(json.loads(json.dumps(params.to_dict()))) == params
    wifi, cell, lossy = PRESETS["wifi"], PRESETS["cellular"], PRESETS["lossy"]
    assert (wifi.rate * 8, wifi.delay_ms, wifi.loss) == (60e6, 2.0, 0.0014)
    assert (cell.delay_ms, cell.loss) == (100.0, 0.005)
    assert (lossy.loss, lossy.delay_ms) == (0.30, 10.0)
    assert PRESETS["ideal"] == LinkParams()


def test_netem_commands():
    assert netem_command("eth0", PRESETS["ideal"]) == "tc qdisc add dev eth0 root netem"
    assert netem_command("eth0", PRESETS["wifi"]) == "tc qdisc add dev eth0 root netem delay 2ms loss 0.14% rate 60mbit"
    assert (
        netem_command("wlan1", LinkParams(delay_ms=100, jitter_ms=10, loss=0.005, rate=1000))
        == "tc qdisc add dev wlan1 root netem delay 100ms 10ms distribution normal loss 0.5% rate 8kbit"
    )
    ge = LinkParams(ge=GilbertElliott(p=0.05, r=0.25, one_minus_h=0.7, one_minus_k=0.001))
    assert netem_command("eth0", ge) == "tc qdisc add dev eth0 root netem loss gemodel 5% 25% 70% 0.1%"
    assert netem_command("veth0", LinkParams(rate=100.5)) == "tc qdisc add dev veth0 root netem rate 804bit"
    with pytest.raises(ValueError, match="dev"):
        netem_command("eth 0", PRESETS["wifi"])


# ---- errors -------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("d", "field"),
    [
        ({"loss": -0.1}, "loss"),
        ({"loss": 1.5}, "loss"),
        ({"loss": True}, "loss"),
        ({"loss": "1%"}, "loss"),
        ({"delay_ms": -1.0}, "delay_ms"),
        ({"delay_ms": math.nan}, "delay_ms"),
        ({"jitter_ms": -0.5}, "jitter_ms"),
        ({"rate": -5}, "rate"),
        ({"rate": math.inf}, "rate"),
        ({"rate": 1e5, "burst": 100}, "burst"),
        ({"rate": 1e5, "queue": -1}, "queue"),
        ({"rate": 1e5, "queue": math.nan}, "queue"),
        ({"ge": {"p": 1.2, "r": 0.1}}, "ge.p"),
        ({"ge": {"p": 0.1, "r": -0.1}}, "ge.r"),
        ({"ge": {"p": 0.1}}, "missing"),
        ({"ge": {"p": 0.1, "r": 0.2, "h": 0.5}}, "'h'"),
        ({"loss": 0.1, "ge": {"p": 0.1, "r": 0.2}}, "one loss model"),
        ({"lost": 0.1}, "lost"),
    ],
)
def test_bad_params_name_the_field(d, field):
    with pytest.raises(ValueError, match=field):
        LinkParams.from_dict(d)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"agents": ["a", "a"]}, "duplicate"),
        ({"seed": 1.5}, "seed"),
        ({"colour": 1}, "colour"),
        ({"range": -3}, "range"),
        ({"phases": [{"t": 0, "edges": [["uav0", "uav9"]]}]}, "uav9"),
        ({"phases": [{"t": 0, "edges": [["uav0", "uav0"]]}]}, r"edges: link \[.*\] joins an agent to itself"),
        ({"phases": [{"t": 0, "edges": [["uav0"]]}]}, r"a link must be a pair \[a, b\], got \['uav0'\]"),
        ({"agents": []}, "non-empty list of names"),
        ({"agents": ["a", ""]}, "'' is not a non-empty string"),
        ({"seed": 1, "agents": ["a", "b", "a"]}, r"duplicate name\(s\) \['a'\]; names must be unique"),
        ({"range": math.nan}, "range: must be finite"),
        ({"phases": [{"t": 0, "edges": "all"}, {"t": 0, "edges": "all"}]}, "not after"),
        ({"phases": [{"t": 0, "edges": "some"}]}, "edges"),
        ({"links": [{"src": "uav0", "dst": "uav1"}, {"src": "uav0", "dst": "uav1"}]}, "twice"),
        ({"links": [{"src": "uav0", "dst": "uav1", "loss": 2}]}, r"links\[0\].*loss"),
        ({"down_nodes": [{"t": 1, "node": "ghost"}]}, r"down_nodes\[0\]: unknown agent 'ghost'; agents: \['uav0'"),
        ({"down_nodes": [{"t": 1, "node": "uav1"}, {"t": 2, "node": "uav1"}]}, r"down_nodes\[1\]: .* lost twice"),
        ({"down_nodes": [{"node": "uav1"}]}, r"down_nodes\[0\]: missing key\(s\) \['t'\]"),
    ],
)
def test_bad_plans_say_where(change, message):
    with pytest.raises(ValueError, match=message):
        LinkPlan.from_dict({**plan(), **change})
