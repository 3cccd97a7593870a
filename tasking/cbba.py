"""The consensus-based bundle algorithm (CBBA): every vehicle reaches the same task assignment by talking
only to its neighbours, under message loss.

Choi, Brunet & How, "Consensus-Based Decentralized Auctions for Robust Task Allocation", IEEE T-RO 25(4),
2009 — the decentralized successor of thesis 000's RHTA from the same laboratory (spec 000 §2.7). Each
vehicle ``i`` keeps

* its *bundle* ``b_i`` (tasks in the order it added them) and *path* ``p_i`` (the same tasks in the order it
  will serve them), at most ``L_t`` tasks;
* per task ``j`` the winning bid ``y_ij`` and winner ``z_ij`` as far as it knows;
* per vehicle ``k`` the time ``s_ik`` of its latest information from ``k`` (directly or relayed).

**Phase 1, bundle construction (Alg. 3).** While ``|b_i| < L_t``: for every task not in the bundle, the
marginal score of inserting it at the best place of the path, ``c_ij = max_n S_i(p_i ⊕_n j) − S_i(p_i)``;
the task is *available* if ``c_ij`` beats the known winning bid, ``h_ij = 𝕀(c_ij > y_ij)`` (ties go to the
smaller vehicle name); add ``J_i = argmax_j c_ij h_ij`` to bundle and path and record ``y_iJ = c_iJ``,
``z_iJ = i``. The path score ``S_i`` is thesis 000's petal value (4.1), ``Σ λ^{T_j} s_j``, and a path that
cannot reach its last task and then the base on the vehicle's fuel is not allowed (the health extension,
§2.7.4): :func:`path_score`.

**Phase 2, consensus (Table 1 of the paper).** On receiving ``(y_k, z_k, s_k)`` from neighbour ``k`` the
receiver updates, resets or leaves its ``(y_ij, z_ij)`` per task by the decision rules of Table 1
(:meth:`CBBA.merge`, one branch per row), then takes the timestamps ``s_ik = τ``, ``s_in = max(s_in, s_kn)``.
If a task of its bundle was lost, the vehicle releases it and every task it added after it (Eq. 7: the bids
of those later tasks are reset, since they were computed on a path that no longer exists).

**Convergence.** With scores of diminishing marginal gain, static tasks and a connected network, CBBA
converges to a conflict-free assignment — the one the centralized *sequential greedy* algorithm finds
(:func:`sequential_greedy`, the test oracle) — in at most ``N_t · D`` rounds, ``D`` the network diameter
(the paper's Theorem 1).

**Moving vehicles.** The paper's scores are static. Here vehicles move, so :meth:`CBBA.rebuild` re-bids the
vehicle's own bundle from its current state every replanning cycle (tasks it wins keep the previous
winner's information until a peer outbids them); ``stickiness`` multiplies the score of the task a vehicle
is serving now, a hysteresis that keeps two vehicles of nearly equal bids from trading a task back and forth.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable, Mapping, Sequence
from dataclasses import dataclass, field

from tasking.tasks import Capability, Task, petal_value, within_reach

#: ``S_i(path)``: the score of serving ``path`` in order; ``-inf`` for a path the vehicle may not fly.
PathScore = Callable[[Sequence[Task]], float]


def path_score(vehicle: Capability, discount: float) -> PathScore:
    """Thesis 000's petal value (4.1) as CBBA's path score, with the health extension's pruning (§2.7.4)."""

    def score(path: Sequence[Task]) -> float:
        if not within_reach(vehicle, path):
            return -math.inf  # L + d(w_last, x_base) > r: the petal is pruned
        return petal_value(vehicle, path, discount)

    return score


@dataclass(frozen=True)
class Bids:
    """What a vehicle tells its neighbours: per task its winner and winning bid, and per vehicle the time of
    its latest information from it."""

    winners: Mapping[Hashable, tuple[str, float]]  # task -> (z_ij, y_ij); tasks with no known winner omitted
    stamps: Mapping[str, float]  # vehicle -> s_ik


def _best_insertion(path: list[Task], task: Task, score: PathScore, base: float) -> tuple[float, int]:
    """``max_n S(p ⊕_n j) − S(p)`` and its ``n`` (Alg. 3, line 6)."""
    best, where = -math.inf, 0
    for n in range(len(path) + 1):
        gain = score(path[:n] + [task] + path[n:]) - base  # S_i(p_i ⊕_n j) − S_i(p_i)
        if gain > best:
            best, where = gain, n
    return best, where


def _beats(bid: float, bidder: str, best: float, holder: str | None) -> bool:
    """``bid`` by ``bidder`` beats ``best`` held by ``holder``: higher, or equal and a smaller name."""
    return bid > best or (bid == best and holder is not None and bidder < holder)


@dataclass
class CBBA:
    """One vehicle's side of CBBA. ``capacity`` is ``L_t``; ``stickiness`` ≥ 1 the hysteresis factor."""

    me: str
    capacity: int = 1
    stickiness: float = 1.0
    bids: dict[Hashable, float] = field(default_factory=dict)  # y_ij
    winners: dict[Hashable, str] = field(default_factory=dict)  # z_ij (absent: no winner known)
    stamps: dict[str, float] = field(default_factory=dict)  # s_ik
    bundle: list[Hashable] = field(default_factory=list)  # b_i, in the order added
    path: list[Hashable] = field(default_factory=list)  # p_i, in the order served
    conflicts_resolved: int = 0  # times merging took a task this vehicle believed it had won

    def __post_init__(self):
        if isinstance(self.capacity, bool) or int(self.capacity) != self.capacity or self.capacity < 1:
            raise ValueError(f"bundle capacity L_t must be a positive integer, got {self.capacity}")
        if not (math.isfinite(self.stickiness) and self.stickiness >= 1.0):
            raise ValueError(f"stickiness must be ≥ 1, got {self.stickiness}")

    # -- phase 1 ---------------------------------------------------------------------------------
    def build(self, tasks: Mapping[Hashable, Task], score: PathScore) -> None:
        """Grow the bundle greedily with the tasks this vehicle out-bids everyone it knows of (Alg. 3)."""
        self._forget(tasks)
        self._grow(tasks, score, self.path[0] if self.path else None)

    def _grow(self, tasks: Mapping[Hashable, Task], score: PathScore, serving: Hashable | None) -> None:
        path = [tasks[key] for key in self.path]
        while len(self.bundle) < self.capacity:
            base = score(path)
            best: tuple[float, str, Hashable, int] | None = None
            for key in sorted(set(tasks) - set(self.bundle), key=str):
                gain, where = _best_insertion(path, tasks[key], score, base)
                if key == serving:
                    gain *= self.stickiness
                if gain <= 0 or not math.isfinite(gain):
                    continue
                if not _beats(gain, self.me, self.bids.get(key, 0.0), self.winners.get(key)):
                    continue  # h_ij = 0: somebody bids more
                if best is None or gain > best[0]:
                    best = (gain, str(key), key, where)
            if best is None:
                break
            gain, _, key, where = best
            self.bundle.append(key)
            path.insert(where, tasks[key])
            self.path.insert(where, key)
            self.bids[key], self.winners[key] = gain, self.me  # y_iJ = c_iJ, z_iJ = i

    def rebuild(self, tasks: Mapping[Hashable, Task], score: PathScore) -> None:
        """Re-bid the own bundle from the vehicle's current state: drop its own claims, then grow it again
        (the task served now, ``path[0]``, bid up by :attr:`stickiness`)."""
        serving = self.path[0] if self.path else None
        for key in self.bundle:
            if self.winners.get(key) == self.me:
                self.bids.pop(key, None)
                self.winners.pop(key, None)
        self.bundle.clear()
        self.path.clear()
        self._forget(tasks)
        self._grow(tasks, score, serving if serving in tasks else None)

    def _forget(self, tasks: Mapping[Hashable, Task]) -> None:
        """Tasks that no longer exist leave the bids and the bundle."""
        for key in [k for k in self.bids if k not in tasks]:
            del self.bids[key]
            self.winners.pop(key, None)
        self._release(next((n for n, key in enumerate(self.bundle) if key not in tasks), None))

    def expire(self, now: float, timeout: float) -> list[str]:
        """Vehicles nobody has heard of for more than ``timeout`` seconds are gone (a crash, a lost link):
        their claims are released so that the survivors bid for those tasks. "Heard of" is ``s_ik``, the
        newest time this vehicle or a neighbour heard from ``k`` (kept by :meth:`merge`), so a vehicle that is
        alive somewhere in a connected fleet is never expired. CBBA itself (Choi et al. 2009) assumes a fixed
        fleet; the rule is chosen here. A claim relayed again later by a neighbour that still holds it carries
        the same stale stamp and is expired again. Returns the vehicles expired."""
        if not timeout > 0:
            raise ValueError(f"timeout must be positive, got {timeout!r}")
        gone = sorted(k for k, stamp in self.stamps.items() if k != self.me and now - stamp > timeout)
        for k in gone:
            del self.stamps[k]
        for key in [key for key, winner in self.winners.items() if winner in gone]:
            self._set(key, None, 0.0)
        return gone

    # -- phase 2 ---------------------------------------------------------------------------------
    def message(self, now: float) -> Bids:
        """``(z_i, y_i, s_i)`` to broadcast; the vehicle's own stamp is ``now``."""
        self.stamps[self.me] = now
        return Bids({key: (winner, self.bids[key]) for key, winner in self.winners.items()}, dict(self.stamps))

    def heard(self, sender: str, received: float) -> None:
        """``s_ik = τ_r``: this vehicle heard from ``sender`` at ``received`` (a message of its bids, or one that
        says only that it is there)."""
        self.stamps[sender] = received

    def merge(self, sender: str, message: Bids, received: float) -> None:
        """Apply a neighbour's ``(z_k, y_k, s_k)`` by the decision rules of Table 1, then the timestamps and the
        bundle release of Eq. (7)."""
        if sender == self.me:
            raise ValueError(f"vehicle {self.me!r} cannot merge its own bids")
        theirs = message.stamps
        for key in set(message.winners) | set(self.winners):
            their_winner, their_bid = message.winners.get(key, (None, 0.0))
            self._decide(key, sender, their_winner, their_bid, theirs)
        self.heard(sender, received)
        for vehicle, stamp in theirs.items():
            if vehicle not in (self.me, sender):
                self.stamps[vehicle] = max(self.stamps.get(vehicle, -math.inf), stamp)  # s_in = max(s_in, s_kn)
        lost = next((n for n, key in enumerate(self.bundle) if self.winners.get(key) != self.me), None)
        if lost is not None:
            self.conflicts_resolved += 1
        self._release(lost)

    def _decide(self, key: Hashable, k: str, zk: str | None, yk: float, sk: Mapping[str, float]) -> None:
        """One row of Table 1 for task ``key``: receiver ``i`` = :attr:`me`, sender ``k``."""
        i, zi, yi = self.me, self.winners.get(key), self.bids.get(key, 0.0)

        def newer(m: str) -> bool:  # s_km > s_im: the sender heard from m more recently
            return sk.get(m, -math.inf) > self.stamps.get(m, -math.inf)

        update, reset = (lambda: self._set(key, zk, yk)), (lambda: self._set(key, None, 0.0))
        if zk == k:
            if zi == i:
                if _beats(yk, k, yi, i):
                    update()
            elif zi == k or zi is None:
                update()
            elif newer(zi) or yk > yi:
                update()
        elif zk == i:
            if zi == k:
                reset()
            elif zi is not None and zi != i and newer(zi):
                reset()
        elif zk is not None:  # the sender believes a third vehicle m wins
            m = zk
            if zi == i:
                if newer(m) and _beats(yk, m, yi, i):
                    update()
            elif zi == k:
                if newer(m):
                    update()
                else:
                    reset()
            elif zi == m:
                if newer(m):
                    update()
            elif zi is not None:  # a fourth vehicle n
                if newer(m) and (newer(zi) or yk > yi):
                    update()
                elif newer(zi) and self.stamps.get(m, -math.inf) > sk.get(m, -math.inf):
                    reset()
            elif newer(m):
                update()
        elif zi == k:  # the sender knows no winner
            update()
        elif zi is not None and zi != i and newer(zi):
            update()

    def _set(self, key: Hashable, winner: str | None, bid: float) -> None:
        if winner is None:
            self.winners.pop(key, None)
            self.bids.pop(key, None)
        else:
            self.winners[key], self.bids[key] = winner, bid

    def _release(self, first: int | None) -> None:
        """Drop ``bundle[first:]``; the bids of the tasks added after ``first`` are reset (Eq. 7)."""
        if first is None:
            return
        for key in self.bundle[first + 1:]:
            if self.winners.get(key) == self.me:
                self._set(key, None, 0.0)
        if self.winners.get(self.bundle[first]) == self.me:
            self._set(self.bundle[first], None, 0.0)  # a task that vanished
        dropped = set(self.bundle[first:])
        del self.bundle[first:]
        self.path[:] = [key for key in self.path if key not in dropped]


def sequential_greedy(tasks: Mapping[Hashable, Task], scores: Mapping[str, PathScore],
                      capacity: int) -> dict[str, list[Hashable]]:
    """The centralized sequential greedy assignment CBBA converges to (the test oracle): repeatedly give the
    (vehicle, task) pair of the largest marginal score its task, until no positive marginal score is left."""
    paths: dict[str, list[Task]] = {v: [] for v in scores}
    order: dict[str, list[Hashable]] = {v: [] for v in scores}
    free = set(tasks)
    while free:
        best: tuple[float, str, str, Hashable, int] | None = None
        for vehicle in sorted(scores):
            if len(order[vehicle]) >= capacity:
                continue
            base = scores[vehicle](paths[vehicle])
            for key in sorted(free, key=str):
                gain, where = _best_insertion(paths[vehicle], tasks[key], scores[vehicle], base)
                if gain > 0 and math.isfinite(gain) and (best is None or gain > best[0]):
                    best = (gain, vehicle, str(key), key, where)
        if best is None:
            break
        _, vehicle, _, key, where = best
        paths[vehicle].insert(where, tasks[key])
        order[vehicle].insert(where, key)
        free.discard(key)
    return order
