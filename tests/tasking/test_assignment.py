"""``[tasking] planner = "assignment"``: tasks from the fused picture, the planner that serves the agreed
task, the ``tasks`` exchange between agents (matching, bad messages, the wire schema) and the agreement
measure."""

import math

import numpy as np
import pytest

from agent.beliefs.assignment import (
    BID_TOLERANCE,
    DEAD_RECKONING_TOLERANCE,
    POSITION_TOLERANCE,
    AssignmentExchange,
    agreement,
)
from agent.net import wire
from agent.plugins import Views
from agent.vehicles import vehicle_from_config
from fusion.resync import Edge
from tasking.assignment import AssignmentConfig, AssignmentPlanner, cell_area, fleet_tasks, search_cells, search_tasks
from tasking.base import AssignmentView, TrackView
from tasking.registry import check_tasking
from tasking.tasks import Task

AREA = (-120.0, 120.0, -120.0, 120.0)


class _Picture:
    """A track exchange's view, as the assignment reads it."""

    kind = "track"

    def __init__(self, tracks):
        self.tracks = tracks

    def view(self):
        return TrackView(self.tracks)


def _exchange(me, position, tracks, **config):
    vehicle = vehicle_from_config({"kind": "multirotor", "max_speed": 12.0}, [*position, -80.0])
    return AssignmentExchange(me, AssignmentConfig(**config), AREA, vehicle.state().position,
                              Views({"track": _Picture(tracks)}), vehicle)


def _offer(x, t, neighbours=()):
    """``x``'s message at ``t``, handed back to it as sent, as the agent's host does (``None``: nothing to say)."""
    message = x.outgoing(t, list(neighbours))
    if message is not None:
        x.sent(int(t * 10) + 1, message)
    return message


def _talk(a, b, t):
    """One round: both settle, then each hears the other's message (through the real wire schema)."""
    for x in (a, b):
        x.settle(t)
    for sender, receiver in ((a, b), (b, a)):
        message = _offer(sender, t, [receiver.me])
        if message is not None:
            data = wire.encode(wire.Envelope(kind="tasks", origin=sender.me, seq=int(t * 10) + 1, stamp=t,
                                             payload=message.payload))
            env = wire.decode(data)
            receiver.receive(sender.me, env.seq, env.stamp, env.payload, Edge.TREE, t)


def test_search_cells_tile_the_area():
    cells = search_cells(AREA, 80.0)
    assert len(cells) == 9
    assert cells["search:0:0"].tolist() == [-80.0, -80.0]
    assert cell_area(AREA, "search:2:1", 80.0) == (40.0, 120.0, -40.0, 40.0)


def test_tracks_come_before_search_cells():
    config = AssignmentConfig()
    tasks = fleet_tasks([(7, np.array([1.0, 2.0, 0.0]))], search_tasks(search_cells(AREA, 120.0), config), config)
    assert tasks["track:7"].kind == "track" and tasks["track:7"].value == 10.0
    assert {t.kind for k, t in tasks.items() if k != "track:7"} == {"search"}


def test_two_agents_split_two_targets_and_agree():
    tracks = [(0, np.array([-60.0, -60.0])), (1, np.array([60.0, 60.0]))]
    # the two agents know the targets under different local ids, a few metres apart
    a = _exchange("a", (-70.0, -70.0), tracks)
    b = _exchange("b", (70.0, 70.0), [(5, np.array([58.0, 61.0])), (9, np.array([-61.0, -59.0]))])
    for step in range(10):
        _talk(a, b, 0.2 * step)
    assert a.view().task.key == "track:0" and b.view().task.key == "track:5"  # each takes the nearer one
    assert a.cbba.winners["track:1"] == "b" and b.cbba.winners["track:9"] == "a"
    assert a.peers["b"].tolist() == [70.0, 70.0]


def test_the_nearer_agent_wins_a_lone_target_and_the_other_searches():
    tracks = [(0, np.array([100.0, 0.0]))]
    a, b = _exchange("a", (90.0, 0.0), tracks), _exchange("b", (-90.0, 0.0), tracks)
    for step in range(10):
        _talk(a, b, 0.2 * step)
    assert a.view().task.kind == "track"
    assert b.view().task.kind == "search"


def test_bids_are_resent_only_when_changed_or_due():
    a = _exchange("a", (0.0, 0.0), [], period=1.0)
    a.settle(0.0)
    assert _offer(a, 0.0) is not None
    assert _offer(a, 0.2) is None  # nothing changed
    assert _offer(a, 1.0) is not None  # the heartbeat


def _bids_sent(a, t):
    """Whether ``a`` sends its bids at ``t`` (not nothing, not its position alone)."""
    message = _offer(a, t)
    return message is not None and "tasks" in message.payload


def test_a_bid_that_drifts_within_its_tolerance_is_not_news_and_one_beyond_it_is():
    a = _exchange("a", (-50.0, 0.0), [(0, np.array([60.0, 0.0]))], period=10.0)
    a.settle(0.0)
    assert a.cbba.winners["track:0"] == "a" and _bids_sent(a, 0.0)
    bid = a.cbba.bids["track:0"]
    a.cbba.bids["track:0"] = bid * (1 + 0.8 * BID_TOLERANCE)  # the vehicle flew a little: a smaller drift
    assert not _bids_sent(a, 0.2)
    a.cbba.bids["track:0"] = bid * (1 + 1.2 * BID_TOLERANCE)
    assert _bids_sent(a, 0.4)


def test_a_track_task_is_news_once_it_moved_beyond_its_share_of_the_match_radius():
    picture = [(0, np.array([60.0, 0.0]))]
    a = _exchange("a", (-50.0, 0.0), picture, period=10.0)
    a.settle(0.0)
    assert _bids_sent(a, 0.0)
    reach = POSITION_TOLERANCE * a.config.match_radius
    for t, north in ((0.2, 60.0 + 0.9 * reach), (0.4, 60.0 + 1.1 * reach)):
        picture[0] = (0, np.array([north, 0.0]))
        a.settle(t)
        a.cbba.bids["track:0"] = a._sent["track:0"][3]  # the bid as sent: only the position moves
        assert _bids_sent(a, t) == (t == 0.4)


def test_a_peer_that_names_another_winner_gets_the_bids_at_once():
    # a holds the lone target; b, farther away, has not heard a and claims it in its first message
    tracks = [(0, np.array([60.0, 0.0]))]
    a, b = _exchange("a", (50.0, 0.0), tracks, period=10.0), _exchange("b", (-60.0, 0.0), tracks, period=10.0)
    for x in (a, b):
        x.settle(0.0)
    assert _bids_sent(a, 0.0) and b.cbba.winners["track:0"] == "b"
    assert not _bids_sent(a, 0.2)  # nothing new
    claim = _offer(b, 0.2).payload
    a.receive("b", 1, 0.2, claim, Edge.TREE, 0.2)
    assert a.cbba.winners["track:0"] == "a"  # a out-bids b: b believes a wrong winner ...
    assert _bids_sent(a, 0.4)  # ... and hears a's bids on the next step, not a period later
    assert not _bids_sent(a, 0.6)


def test_a_crowded_vehicle_sends_its_motion_alone_once_it_strays_from_where_its_peers_reckon_it(monkeypatch):
    a, b = _exchange("a", (0.0, 0.0), [], period=10.0), _exchange("b", (0.0, 15.0), [], period=10.0)
    _talk(a, b, 0.0)  # bids with a at rest
    where = {x: x.vehicle.state().position[:2] for x in (a, b)}
    assert a._crowded(where[a]) and b._crowded(where[b])  # 15 m apart: within CROWD minimum separations
    assert _offer(a, 0.2) is None  # at rest, where b reckons it: nothing to say
    reach = DEAD_RECKONING_TOLERANCE * a.config.min_separation
    monkeypatch.setattr(a.vehicle, "state", lambda: _State([0.9 * reach, 0.0, -80.0], [5.0, 0.0, 0.0]))
    assert _offer(a, 0.4) is None  # it moved, but less than the tolerance
    monkeypatch.setattr(a.vehicle, "state", lambda: _State([1.1 * reach, 0.0, -80.0], [5.0, 0.0, 0.0]))
    message = _offer(a, 0.6)
    assert set(message.payload) == {"at", "v"}
    data = wire.encode(wire.Envelope(kind="tasks", origin="a", seq=2, stamp=0.6, payload=message.payload))
    merges, winners = b.merges, dict(b.cbba.winners)
    b.receive("a", 2, 0.6, wire.decode(data).payload, Edge.TREE, 0.8)
    assert b.merges == merges and b.cbba.winners == winners  # no bids: nothing merged
    assert b.cbba.stamps["a"] == 0.8 and b._peer_heard["a"] == 0.8  # but a was heard
    b.settle(1.0)
    assert b.peers["a"] == pytest.approx([1.1 * reach + 5.0 * 0.4, 0.0])  # and flown on at its velocity
    # flying on at that velocity, a stays where b reckons it: nothing more to say
    monkeypatch.setattr(a.vehicle, "state", lambda: _State([1.1 * reach + 5.0 * 0.4, 0.0, -80.0], [5.0, 0.0, 0.0]))
    assert _offer(a, 1.0) is None


def test_a_motion_the_link_budget_refused_is_offered_again_until_it_leaves(monkeypatch):
    """Bad luck on the radio: the link budget thins a crowded vehicle's motion message. Its peers still reckon
    it from the last motion that left, so it must not take the refused one as told, and what it offers again is
    that motion, not its whole bids (which a budget that just refused the motion would refuse the more)."""
    a, b = _exchange("a", (0.0, 0.0), [], period=10.0), _exchange("b", (0.0, 15.0), [], period=10.0)
    _talk(a, b, 0.0)
    reach = DEAD_RECKONING_TOLERANCE * a.config.min_separation
    monkeypatch.setattr(a.vehicle, "state", lambda: _State([2 * reach, 0.0, -80.0], [0.0, 0.0, 0.0]))
    refused = a.outgoing(0.2, [])
    assert set(refused.payload) == {"at", "v"}
    a.thinned(refused)  # the host could not admit it
    again = _offer(a, 0.4)
    assert set(again.payload) == {"at", "v"} and again.payload["at"] == refused.payload["at"]  # not all the bids
    assert _offer(a, 0.6) is None  # once it left, the peers reckon it right


@pytest.mark.parametrize("payload, reason", [
    ({"at": (0.0, math.nan), "stamps": {}, "tasks": []}, "non_finite"),  # a NaN position
    ({"at": (0.0, 0.0), "stamps": {"b": math.inf}, "tasks": []}, "non_finite"),  # an infinite timestamp
    ({"at": (0.0, 0.0), "stamps": {}, "tasks": [["search:9:9", 0.0, 0.0, "b", 1.0]]}, "bad_field"),  # no such cell
    ({"at": (0.0, 0.0), "stamps": {"b": 0.0}}, "bad_field"),  # timestamps without the bids they stamp
    ({"at": (0.0, 0.0), "tasks": [["search:0:0", -80.0, -80.0, "b", 1.0]]}, "bad_field"),  # bids, no timestamps
    ({"at": (math.inf, 0.0)}, "non_finite"),  # a position alone, but not a finite one
    ({"at": (0.0, 0.0), "v": (0.0, math.nan)}, "non_finite"),  # a velocity to dead-reckon from that is NaN
])
def test_a_bad_tasks_message_is_refused_and_changes_nothing(payload, reason):
    a = _exchange("a", (0.0, 0.0), [])
    a.settle(0.0)
    before = dict(a.cbba.winners)
    with pytest.raises(wire.DecodeError) as err:
        a.receive("b", 1, 0.0, payload, Edge.TREE, 0.0)
    assert err.value.reason == reason
    assert a.cbba.winners == before and "b" not in a.peers


@pytest.mark.parametrize("payload, reason", [
    ({"at": [0.0], "stamps": {}, "tasks": []}, "bad_type"),  # a position with one coordinate
    ({"at": [0.0, 0.0], "stamps": {}, "tasks": [["track", 0.0, 0.0, "", 1.0]]}, "bad_field"),  # an empty winner
    ({"at": [0.0, 0.0], "stamps": {}, "tasks": [["track", "north", 0.0, "b", 1.0]]}, "bad_type"),
])
def test_the_wire_schema_rejects_malformed_bids(payload, reason):
    data = wire.encode(wire.Envelope(kind="tasks", origin="b", seq=1, stamp=0.0, payload=payload))
    with pytest.raises(wire.DecodeError) as err:
        wire.decode(data)
    assert err.value.reason == reason


class _State:
    def __init__(self, position, velocity=(0.0, 0.0, 0.0)):
        self.position = np.asarray(position, float)
        self.velocity = np.asarray(velocity, float)


def test_the_planner_serves_the_agreed_task():
    planner = AssignmentPlanner(AssignmentConfig(), AREA, 80.0)
    base = np.array([-120.0, 0.0])
    track = Task("track:3", [10.0, 20.0], 10.0)
    goal = planner.plan(_State([0.0, 0.0, -80.0]), {"tasks": AssignmentView(track, False, base, {})})
    assert goal.is_orbit and goal.orbit_center.tolist() == [10.0, 20.0] and planner.mode == "track"
    cell = Task("search:2:2", [80.0, 80.0], 1.0, "search")
    goal = planner.plan(_State([0.0, 0.0, -80.0]), {"tasks": AssignmentView(cell, False, base, {})})
    n0, n1, e0, e1 = cell_area(AREA, "search:2:2", 80.0)
    assert not goal.is_orbit and n0 <= goal.position[0] <= n1 and e0 <= goal.position[1] <= e1
    goal = planner.plan(_State([0.0, 0.0, -80.0]), {"tasks": AssignmentView(None, True, base, {})})
    assert goal.position[:2].tolist() == base.tolist() and planner.mode == "home"
    goal = planner.plan(_State([5.0, 6.0, -80.0]), {"tasks": AssignmentView(None, False, base, {})})
    assert goal.is_orbit and goal.orbit_center.tolist() == [5.0, 6.0] and planner.mode == "idle"


def test_agreement_weighs_time_and_times_how_fast_changes_settle():
    timelines = {"a": [(0.0, {"car": "a"}), (1.0, {"car": "b"})],
                 "b": [(0.0, {"car": "a"}), (2.0, {"car": "b"})]}
    out = agreement(timelines, end=4.0, window=1.0)
    # agreed on [0, 1) and [2, 4): 3 of 4 s; the changes at 0, 1 and 2 s each settle within 1 s
    assert out == {"agreed_time_share": 0.75, "changes": 3, "settled_within_window": 1.0}
    assert agreement(timelines, end=4.0, window=0.5)["settled_within_window"] == 2 / 3  # 1 s -> 2 s is too slow
    assert agreement({}, end=1.0, window=1.0)["changes"] == 0


@pytest.mark.parametrize("section, match", [
    ({"planner": "assignment", "discount": 1.5}, "discount"),  # λ above 1 rewards waiting
    ({"planner": "assignment", "search_value": 20.0}, "search_value"),  # searching worth more than a target
    ({"planner": "assignment", "orbit_radius": -1.0}, "orbit_radius"),
    ({"planner": "assignment", "capacity": 1.5}, "wrong type"),
    ({"planner": "assignment", "peer_timeout": 0.0}, "peer_timeout"),  # every peer would be expired at once
])
def test_bad_tasking_sections_are_refused_when_the_scenario_is_read(section, match):
    with pytest.raises(ValueError, match=match):
        check_tasking(section, frozenset({"track", "tasks"}))


def test_a_vehicle_sent_home_hands_its_target_to_its_peer():
    tracks = [(0, np.array([60.0, 0.0]))]
    # a starts next to the target with 12 s of fuel and its base 120 m away: it must go home at once
    a = _exchange("a", (55.0, 0.0), tracks, flight_time=12.0, reserve=2.0)
    b = _exchange("b", (-60.0, 0.0), tracks)
    a.base = np.array([-65.0, 0.0])
    for step in range(8):
        _talk(a, b, 0.2 * step)
    assert a.view().home and a.view().task is None and a.cbba.bundle == []
    assert b.view().task.kind == "track" and b.cbba.winners["track:0"] == "b"
    assert a.metrics()["assignment"]["health"]["state"] == "home"


def test_health_settings_are_checked():
    with pytest.raises(ValueError, match="failure_burn"):
        AssignmentConfig(flight_time=60.0, failure_burn=0.5)  # a failure that makes the engine thriftier
    assert AssignmentConfig().health_model() is None
    assert AssignmentConfig(flight_time=60.0).health_model().burn == pytest.approx(1 / 60)
