"""The ``tasks`` exchange: the fleet's task assignment by consensus (CBBA) over the mesh.

Built when ``[tasking] planner = "assignment"``. Every step, after the other beliefs settled:

1. **tasks** from this agent's own fused picture (:func:`tasking.assignment.fleet_tasks`): its confirmed
   tracks and the area's search cells;
2. **bundle** (:meth:`tasking.cbba.CBBA.rebuild`): re-bid from the vehicle's current position, scored by
   thesis 000's petal value (4.1) with the range test of the health extension (§2.7.4);
3. **bids** out (kind ``tasks``): per task the winner and bid this agent knows, with its timestamps and its
   own position — when a peer needs them (a winner changed or is disputed, a bid moved by more than
   ``BID_TOLERANCE``, a track task by more than ``POSITION_TOLERANCE`` of ``match_radius``) and every
   ``period``; peers dead-reckon the sender from its position and velocity, and while a peer is within
   ``CROWD`` minimum separations (the planner's separation layer needs where it is) the sender's motion goes
   alone whenever it strays from that reckoning by more than ``DEAD_RECKONING_TOLERANCE`` of the separation;
4. **consensus** on receipt (:meth:`tasking.cbba.CBBA.merge`, Table 1 of Choi et al.).

Task identity across agents: a search cell has the same key everywhere (``search:r:c``); a track is known
to each agent under its own local id, so a peer's track task is sent with its position and matched to this
agent's track tasks one-to-one by nearest neighbour within ``match_radius`` (Hungarian assignment); an
unmatched peer track task is not used (its track reaches this agent through the track exchange).

The **view** (:class:`tasking.base.AssignmentView`) is the first task of this agent's path, and its peers'
positions. **Evaluation** (simulation only) labels each track task with the nearest true target and records
who this agent believes serves each label, so a harness can measure how often, and how fast, the agents
agree (:func:`agreement`).
"""

from __future__ import annotations

import math
from collections import Counter

import numpy as np

from agent.net import wire
from agent.plugins import Outgoing, Views
from agent.sensors.truth import TruthSnapshot
from fusion.resync import Edge
from tasking.assignment import AssignmentConfig, fleet_tasks, search_cells, search_tasks, slot_key, slot_of
from tasking.base import AssignmentView
from tasking.cbba import CBBA, Bids, path_score
from tasking.health import VehicleHealth
from tasking.matching import least_cost_pairs
from tasking.sortie import Sortie
from tasking.tasks import Capability, Task

TRACK = "track"
CROWD = 4.0  # peers closer than this many minimum separations get the motion alone whenever it strays ...
DEAD_RECKONING_TOLERANCE = 0.1  # ... from the last one sent, flown on, by more than this × min_separation
BID_TOLERANCE = 0.05  # a winning bid that moved by less than this share of itself is not news (chosen here)
POSITION_TOLERANCE = 0.2  # a task that moved by less than this share of match_radius is not news (chosen here)


class AssignmentExchange:
    kind = "tasks"
    needs_edge = False  # CBBA's consensus rules hold on any graph

    def __init__(self, me: str, config: AssignmentConfig, area, base: np.ndarray, views: Views, vehicle,
                 seed: int = 0):
        self.me, self.config, self.views, self.vehicle = me, config, views, vehicle
        model = config.health_model()
        self.sortie = None if model is None else Sortie(
            VehicleHealth(model, np.random.default_rng([seed, 7])), config.cruise_speed, config.reserve,
            config.landing_radius)
        self._video: float | None = None
        self.base = np.asarray(base, float)[:2]
        self.cells = search_cells(area, config.search_cell)
        self.searches = search_tasks(self.cells, config)
        self.slots = {slot_key(TRACK, s) for s in range(config.orbit_slots)}  # track task keys on the wire
        self.cbba = CBBA(me, config.capacity, config.stickiness)
        self.merges = 0
        self.tasks: dict[str, Task] = {}
        self.peers: dict[str, np.ndarray] = {}  # peer -> its position (north, east) now, dead-reckoned at settle
        self._motion: dict[str, tuple[float, np.ndarray, np.ndarray]] = {}  # peer -> (stamp, position, velocity)
        self._told: tuple[float, np.ndarray, np.ndarray] | None = None  # the same of this vehicle, as last sent
        self._peer_heard: dict[str, float] = {}  # peer -> when its last message (bids or motion) arrived
        self.expired: list[tuple[float, str]] = []  # (t, vehicle) each time a silent vehicle's claims were released
        self._sent: dict | None = None  # task key -> (north, east, winner, bid) as last sent
        self._sent_at = -math.inf
        self._disputed = False  # a peer said winners this vehicle disagrees with: it needs our bids
        self.changes = 0  # times this agent's own task changed
        self.timeline: list[tuple[float, dict[str, str]]] = []  # (t, {target label: believed server}) on change
        self.evaluated_until = -math.inf

    # -- the plug-in ---------------------------------------------------------------------------
    def sensors(self) -> list:
        return []

    def planning_hints(self) -> dict:
        return {}

    def absorb(self, t: float, observations) -> None:
        """The camera's video quality D(t), for the health model's camera state."""
        self._video = observations.get("video_quality")

    def settle(self, t: float) -> None:
        """Rebuild the task set from the fused picture, update the sortie, and re-bid the bundle from where the
        vehicle is. A vehicle that is not flying its sortie, or not healthy (a MAVLink vehicle that lost its
        autopilot, or whose autopilot took over), bids for nothing: its tasks go to others. A vehicle that
        reports its battery and failures has them stand in for the health model's fuel and failures."""
        self.tasks = fleet_tasks(self.views["track"].positions, self.searches, self.config)
        self._expire(t)
        self.peers = {peer: _reckoned(motion, t) for peer, motion in self._motion.items()}
        position = self.vehicle.state().position[:2]
        serving = self.cbba.path[0] if self.cbba.path else None
        if self.sortie is None:
            me, bidding = Capability(position, self.config.cruise_speed, self.base), True
        else:
            state = self.sortie.update(t, position, self.base, self._video, battery=self.vehicle.battery,
                                       failed=self.vehicle.failed)
            me, bidding = self.sortie.capability(position, self.base), state == "flying"
        bidding = bidding and self.vehicle.healthy
        self.cbba.rebuild(self.tasks if bidding else {}, path_score(me, self.config.discount))
        if (self.cbba.path[0] if self.cbba.path else None) != serving:
            self.changes += 1

    def _expire(self, t: float) -> None:
        """A vehicle silent for ``peer_timeout`` (crashed, out of reach) loses its claims, and its last position
        stops counting for the separation layer: no ghost holds a target or a patch of sky."""
        self.expired += [(t, k) for k in self.cbba.expire(t, self.config.peer_timeout)]
        for peer in [p for p, heard in self._peer_heard.items() if t - heard > self.config.peer_timeout]:
            del self._peer_heard[peer], self._motion[peer]  # settle reckons the peers from what is left

    def outgoing(self, t: float, neighbours: list[str]) -> Outgoing | None:
        """The bids, when a peer needs them (:meth:`_news`) and every ``period`` otherwise; between those,
        the position and velocity alone while a peer is crowding this vehicle and the position its peers
        dead-reckon from the last ones sent is off by more than ``DEAD_RECKONING_TOLERANCE × min_separation``
        (the separation layer needs where it is; a vehicle on a straight leg needs no message for that)."""
        bids = self.cbba.message(t)
        held = {key: (*map(float, self.tasks[key].position), winner, bid)
                for key, (winner, bid) in sorted(bids.winners.items()) if key in self.tasks}
        state = self.vehicle.state()
        at, v = state.position[:2].astype(float), state.velocity[:2].astype(float)
        motion = {"at": (float(at[0]), float(at[1])), "v": (float(v[0]), float(v[1]))}
        if not self._news(held) and t - self._sent_at < self.config.period:
            if not self._strayed(t, at) or not self._crowded(at):
                return None
            return Outgoing(motion, context=(t, at, v))
        self._sent, self._sent_at, self._disputed = held, t, False
        return Outgoing({**motion, "stamps": dict(bids.stamps),
                         "tasks": [[_wire_key(key), *entry] for key, entry in held.items()]}, context=(t, at, v))

    def _strayed(self, t: float, at: np.ndarray) -> bool:
        """Whether this vehicle is farther than the dead-reckoning tolerance from where its peers reckon it (from
        nothing: it never told them)."""
        if self._told is None:
            return True
        return float(np.hypot(*(at - _reckoned(self._told, t)))) > DEAD_RECKONING_TOLERANCE * self.config.min_separation

    def _news(self, held: dict) -> bool:
        """Whether the bids hold news a peer needs, against what was last sent: a task or winner appeared,
        left or changed; a peer said a winner this vehicle disagrees with (:meth:`receive`); a winning bid
        moved by more than ``BID_TOLERANCE`` of itself; a task moved by more than ``POSITION_TOLERANCE`` of
        ``match_radius``. A bid that drifts as the vehicle flies, or a track task that follows its target by
        a metre, is not news: peers compare bids to decide who wins (Choi et al. Table 1) and match track
        tasks within ``match_radius``, so they decide the same within those tolerances; the ``period``
        refresh bounds how stale they get."""
        sent = self._sent
        if sent is None or self._disputed or sent.keys() != held.keys():
            return True
        reach = POSITION_TOLERANCE * self.config.match_radius
        for key, (north, east, winner, bid) in held.items():
            was_north, was_east, was_winner, was_bid = sent[key]
            if (winner != was_winner or abs(bid - was_bid) > BID_TOLERANCE * abs(was_bid)
                    or math.hypot(north - was_north, east - was_east) > reach):
                return True
        return False

    def _crowded(self, own: np.ndarray) -> bool:
        """A peer within ``CROWD × min_separation`` of ``own`` (north, east): the separation layer needs to know
        where this agent is."""
        if not self.peers or self.config.min_separation <= 0:
            return False
        nearest = min(float(np.hypot(*(p - own))) for p in self.peers.values())
        return nearest < CROWD * self.config.min_separation

    def sent(self, seq: int, message: Outgoing) -> None:
        """The motion the peers now reckon this vehicle from: only a message that left tells them."""
        self._told = message.context

    def thinned(self, message: Outgoing) -> None:
        if "tasks" in message.payload:
            self._sent = None  # not sent: the bids go again next step (a motion alone goes again as itself)

    def receive(self, origin: str, seq: int, stamp: float, payload: dict, edge: Edge | None,
                t: float) -> list[tuple[str, str | None]]:
        """Merge a peer's bids (Table 1), or note where it is when the message is its position alone; the merges
        are counted in :meth:`metrics`, not as fusions. Raises :class:`agent.net.wire.DecodeError` on
        non-finite numbers, a task key this fleet does not have, or timestamps without tasks (or tasks without
        timestamps), and then changes nothing."""
        at, v = payload["at"], payload.get("v", (0.0, 0.0))
        entries, stamps = payload.get("tasks"), payload.get("stamps")
        if (entries is None) != (stamps is None):
            raise wire.DecodeError("bad_field", "stamps without tasks, or tasks without stamps: a tasks message "
                                                "holds both, or neither (the sender's motion alone)")
        entries, stamps = entries or [], stamps or {}
        numbers = [*at, *v, *stamps.values(), *(x for e in entries for x in (e[1], e[2], e[4]))]
        if not np.isfinite(np.array(numbers, float)).all():  # one vectorised test: ~30 numbers per message
            raise wire.DecodeError("non_finite", "NaN or inf in a tasks message")
        slots = self.slots
        unknown = [e[0] for e in entries if e[0] not in slots and e[0] not in self.cells]
        if unknown:
            raise wire.DecodeError("bad_field", f"unknown task keys {unknown[:3]}")
        self.peers[origin] = np.array(at, float)
        self._motion[origin] = (stamp, self.peers[origin], np.array(v, float))
        self._peer_heard[origin] = t
        if "tasks" not in payload:
            self.cbba.heard(origin, t)
            return []
        winners = {e[0]: (e[3], e[4]) for e in entries if e[0] not in slots}
        winners.update(self._match_tracks([e for e in entries if e[0] in slots]))
        self.merges += 1
        self.cbba.merge(origin, Bids(winners, stamps), t)
        held = self.cbba.winners
        self._disputed = self._disputed or any(held.get(key) != winner for key, (winner, _) in winners.items())
        return []  # bids are no belief: nothing to count among the fusions

    def _match_tracks(self, entries: list) -> dict[str, tuple[str, float]]:
        """A peer's track tasks under this agent's keys: its targets (the distinct positions of its entries)
        matched one-to-one to ours, nearest within ``match_radius``; each slot keeps its number."""
        ours = [key for key, task in self.tasks.items() if task.kind == TRACK and slot_of(key)[1] == 0]
        if not ours or not entries:
            return {}
        where = sorted({(e[1], e[2]) for e in entries})
        mine = [self.tasks[key].position for key in ours]
        cost = [[math.hypot(n - m[0], e - m[1]) for m in mine] for n, e in where]
        target = {where[r]: ours[c] for r, c in least_cost_pairs(cost) if cost[r][c] <= self.config.match_radius}
        matched = {}
        for key, north, east, winner, bid in entries:
            if (north, east) in target:
                matched[slot_key(target[north, east], slot_of(key)[1])] = (winner, bid)
        return matched

    @property
    def home(self) -> bool:
        """Going home or refuelling there (never without a health model)."""
        return self.sortie is not None and self.sortie.state in ("home", "refuelling")

    def view(self) -> AssignmentView:
        task = self.tasks.get(self.cbba.path[0]) if self.cbba.path else None
        partners = {}
        if task is not None and task.kind == TRACK:
            target = slot_of(task.key)[0]
            partners = {winner: self.peers[winner] for key, winner in self.cbba.winners.items()
                        if winner != self.me and winner in self.peers and key.startswith(TRACK)
                        and slot_of(key)[0] == target}
        return AssignmentView(task, self.home, self.base, dict(self.peers), partners)

    def telemetry(self) -> dict:
        task = self.view().task
        return {"task": "" if task is None else str(task.key)}

    def evaluate(self, t: float, truth: TruthSnapshot) -> None:
        """Record who this agent believes serves each true target (the nearest within ``match_radius``) and
        each search cell, when that changes."""
        if truth.targets is None:
            return
        labels = {key: key for key in self.cells}
        if truth.targets:
            ids = [target["id"] for target in truth.targets]
            where = np.array([np.asarray(target["position"], float)[:2] for target in truth.targets])
            for key, task in self.tasks.items():
                if task.kind == TRACK:
                    distance = np.hypot(*(where - task.position).T)
                    if distance.min() <= self.config.match_radius:
                        labels[key] = ids[int(distance.argmin())]
        served = {labels[key]: winner for key, winner in self.cbba.winners.items() if key in labels}
        if not self.timeline or self.timeline[-1][1] != served:
            self.timeline.append((t, served))
        self.evaluated_until = t

    def metrics(self) -> dict:
        kinds = Counter(self.tasks[key].kind for key in self.cbba.path if key in self.tasks)
        health = {} if self.sortie is None else {"health": self.sortie.metrics()}
        return {"assignment": {**health, "task_changes": self.changes,
                               "conflicts_resolved": self.cbba.conflicts_resolved,
                               "merges": self.merges,
                               "expired": [[t, k] for t, k in self.expired],
                               "serving": dict(kinds),
                               "timeline": [[t, served] for t, served in self.timeline],
                               "evaluated_until": self.evaluated_until}}


def _reckoned(motion: tuple[float, np.ndarray, np.ndarray], t: float) -> np.ndarray:
    """Dead reckoning: where a vehicle last said it was at ``stamp``, flown on at its velocity until ``t``."""
    stamp, at, v = motion
    return at + v * (t - stamp)


def _wire_key(key: str) -> str:
    """A task's key on the wire: track ids are local, so a track task travels as ``track`` (slot 0) or
    ``track#s`` with its position, and the receiver matches it to its own track (:meth:`_match_tracks`)."""
    return slot_key(TRACK, slot_of(key)[1]) if key.startswith(TRACK) else key


def agreement(timelines: dict[str, list], end: float, window: float) -> dict:
    """How the agents' beliefs of who serves each target agree over time, from each agent's change points
    ``[(t, {label: server})]`` up to ``end``: the share of time during which every agent holds the same map,
    and for every change of any agent's map, whether all agreed again within ``window`` seconds (the issue's
    goal: ≥ 95 % of changes within 3 s under 30 % loss)."""
    times = sorted({t for line in timelines.values() for t, _ in line if t <= end})
    if not times:
        return {"agreed_time_share": None, "changes": 0, "settled_within_window": None}

    def state(line: list, t: float) -> tuple:
        held = [served for when, served in line if when <= t]
        return tuple(sorted(held[-1].items())) if held else ()

    agreed = [len({state(line, t) for line in timelines.values()}) == 1 for t in times]
    spans = np.diff([*times, end])
    settled = [any(agreed[j] for j in range(i, len(times)) if times[j] - t <= window) for i, t in enumerate(times)]
    total = end - times[0]
    return {"agreed_time_share": float(np.dot(spans, agreed) / total) if total > 0 else float(agreed[-1]),
            "changes": len(times), "settled_within_window": float(np.mean(settled))}
