"""Channel filters: per-neighbour common information, so that nothing is counted twice.

Merino (2.26)-(2.28), Alg. 3.4 and (3.39)-(3.42) (after Bourgault & Durrant-Whyte, 2004): when node
``i`` receives neighbour ``j``'s belief it adds ``bel_j - bel_ij``, where ``bel_ij`` is the information
the two already share. This module is generic: it works for any :class:`fusion.belief.Belief` (``fuse``,
``remove``, ``epoch``, ``advanced_to``) with an intersection rule — Gaussians, trajectories and grids.

**Acknowledged common information.** Merino's bookkeeping ("on send, ``bel_ij = bel_i``") assumes the
message arrives. Here a node assumes a neighbour holds only what the neighbour has *acknowledged*: every
message carries the sequence number of the last message its sender received from the receiver. On a
tree the common information splits into two disjoint parts,

* ``B``, the neighbour-side information this node holds — what it took from the neighbour's last fused
  message (it starts as the common prior), and
* ``A``, this node's side information that the neighbour holds — the node-side part of the
  acknowledged message, ``A = sent_a - B_a`` where ``sent_a`` and ``B_a`` are recorded at send time.

Messages are broadcasts: :meth:`ChannelFilter.on_send` records the sent belief once, and each channel
records its ``B`` at that moment. A neighbour first heard after message ``s`` held only the prior at
``s``, so its acknowledgement of an earlier message is still usable.

Receiving ``m`` with acknowledgement ``a``: ``fused = local + m - (B + A)`` and ``B <- m - A``. A lost
message in either direction leaves both parts valid, so loss can never make the result overconfident.

Policies: ``exact`` (channel filters; optimal on trees), ``ci`` (covariance intersection only),
``hybrid`` (exact on edges the caller knows to be tree edges and whose common information is
synchronised, intersection otherwise) and ``naive`` (treat every message as independent evidence —
for comparison only: it double-counts). Whenever the exact result would not be positive semi-definite,
the acknowledged message is no longer in the history, or (``hybrid``) the link may lie on a loop, the
channel falls back to intersection and is *desynchronised*.

**Outages and loops.** A lost link does not desynchronise anything: acknowledgements keep both parts
valid, and when the link comes back exact fusion simply resumes. A desynchronised channel returns to
exact fusion through an explicit agreement of both ends on one baseline (:mod:`fusion.resync`: the
protocol, its equations and its safe condition — a channel desynchronised on a loop is not re-synced);
taking the neighbour's next message as the baseline on each side independently was measured
overconfident (each side's intersection shows up as "new" information in the other's baseline).
Re-synchronisation needs the node's name (``me``): the lower-named end proposes. With a name, every
broadcast goes through :meth:`ChannelFilter.prepare_send` (the belief to send and the per-neighbour
re-sync flags) and then :meth:`ChannelFilter.on_send`. :meth:`ChannelFilter.reset` restarts a channel
whose neighbour restarted.

**New links.** A channel opened to a neighbour heard for the first time (or again after an outage during
which the two ends may have exchanged information by other paths: :meth:`ChannelFilter.forget`) may start
synchronised on the common prior only if the two ends provably share nothing else: the neighbour's message
says it had fused nothing from anyone and sent nothing before (:attr:`Freshness.UNSENT`: whatever it holds
is its own and new here), or this node has fused nothing from anyone and either has sent nothing (nothing
of it can have reached the neighbour by another path) or the neighbour had fused nothing either
(:attr:`Freshness.FRESH`). Any other new channel starts desynchronised (with a name) and returns to exact
fusion through the re-sync agreement; taking the prior as the common information there double-counts
whatever reached both ends before (measured ANEES 3.2-3.5 against a bound of 1.29 in
``tests/fusion/test_resync.py``). The rule cannot tell a neighbour informed only by this node (on a static
tree: the next agent down a line) from one informed by others, so it also desynchronises those, and a
static tree is no longer exactly the centralized filter; ``check_new_links=False`` keeps the old rule (a
new channel trusts the prior), exact on static trees, overconfident where links appear between informed
nodes.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Hashable
from dataclasses import dataclass, field
from enum import IntEnum, StrEnum

from fusion.belief import Belief, IntersectRule
from fusion.covariance_intersection import ci
from fusion.resync import PATIENCE, Edge, agree, as_edge, rebase


class Freshness(IntEnum):
    """What a node's belief holds beyond the prior, as sent with each message (module docstring, "New links")."""

    INFORMED = 0  # something fused from someone
    FRESH = 1  # only its own information, some of it sent before
    UNSENT = 2  # only its own information, none of it sent before


class Policy(StrEnum):
    NAIVE = "naive"
    EXACT = "exact"
    CI = "ci"
    HYBRID = "hybrid"


#: Why a receive was not fused exactly (``Received.cause``).
CAUSES = (
    "policy",  # the policy is ci or naive: nothing is ever fused exactly
    "not_tree_edge",  # hybrid: the link may lie on a loop
    "common_unknown",  # the channel was desynchronised earlier: its common information is unknown
    "ack_not_in_history",  # the acknowledged message is older than the kept history
    "exact_failed",  # the exact result would not be a valid belief (e.g. not positive semi-definite)
    "stale",  # a message not newer than the last one on this channel: ignored
    "resync_wait",  # re-sync in progress: a message built on the old baseline, ignored (fusion.resync)
    "resync_pending",  # a re-sync proposal, kept and adopted in the next message sent
    "resync_refused",  # an accept for a proposal no longer valid: intersected, and proposed again
)


@dataclass
class Received:
    """The outcome of one receive: the fused belief, how it was fused, and — for anything but an exact
    fusion — why: ``cause`` (one of :data:`CAUSES`) and a human-readable ``reason``."""

    fused: Belief
    method: str  # "exact", "ci", "naive", "resync" (the agreed baseline was adopted) or "stale"
    reason: str | None = None
    cause: str | None = None


@dataclass
class _Channel:
    inbound: Belief  # B: neighbour-side information held here (includes the common prior)
    opened_after: int | None  # the last seq sent before this channel existed (B was the prior then)
    inbound_at_send: OrderedDict = field(default_factory=OrderedDict)  # seq -> B when seq was sent
    synchronized: bool = True
    last_seq: int | None = None
    edge: Edge = Edge.TREE  # what the last receive said of the link
    tainted: bool = False  # desynchronised while on a loop: never re-synchronised (fusion.resync)
    pending: tuple | None = None  # acceptor: the newest proposal (seq, belief), adopted at the next send
    accepting: int | None = None  # acceptor: the proposal accepted in the message being sent
    agreed_at: int | None = None  # acceptor: our accept message; messages acknowledging older ones are ignored
    baseline_after: int | None = None  # proposer: our last message before the rebase (it held the old baseline)
    ignored: int = 0  # proposer: the neighbour's messages ignored in a row while proposing


def _intersect_det(a, b):
    return ci([a, b], "det")


class ChannelFilter:
    """The channel filters of one node, one per neighbour."""

    def __init__(
        self,
        prior: Belief,
        policy: Policy | str = Policy.HYBRID,
        intersect: IntersectRule | None = None,
        history: int = 64,
        me=None,
        check_new_links: bool = True,
    ):
        self.prior = prior
        self.me = me  # this node's name: re-synchronisation is on only with one
        self.check_new_links = check_new_links  # "New links" in the module docstring (with a name only)
        self._latest_prior = prior  # the prior advanced to the newest epoch seen, so advancing stays O(1)
        self.policy = Policy(policy)
        self.intersect = intersect or _intersect_det
        if history < 1:
            raise ValueError(f"history must hold at least one message, got {history}")
        self.history = history
        self._channels: dict[Hashable, _Channel] = {}
        self._sent: OrderedDict = OrderedDict()  # seq -> the local belief broadcast as that message
        self._pruned = False  # has the oldest sent entry ever been dropped?
        self._generation = 0  # counts non-additive changes of the local belief (fusion.resync, step 3)
        self._generation_at: dict = {}  # seq -> the generation when that message was sent
        self._fresh = True  # nothing from anyone fused yet, and no non-additive change

    @property
    def freshness(self) -> Freshness:
        """What the belief holds beyond the prior: sent with every message (taken before :meth:`on_send`), so
        that a new neighbour may trust the prior as the common information."""
        if not self._fresh:
            return Freshness.INFORMED
        return Freshness.FRESH if self._sent else Freshness.UNSENT

    # -- bookkeeping ------------------------------------------------------------------------------
    def neighbours(self) -> list:
        return list(self._channels)

    def is_synchronized(self, neighbour) -> bool:
        return self._channel(neighbour).synchronized

    def reset(self, neighbour) -> None:
        """Start the channel afresh: only the common prior is assumed shared.

        Correct when the neighbour is known to hold nothing of ours (a new neighbour, or one that
        restarted); after a loop or an unknown exchange the channel must stay desynchronised instead."""
        self._channels[neighbour] = _Channel(
            inbound=self._latest_prior, opened_after=next(reversed(self._sent), None)
        )

    def forget(self, neighbour) -> None:
        """The link to ``neighbour`` came up (again): while it was down, what the two ends hold may have
        grown by other paths, so its next message opens the channel as a new link's (module docstring)."""
        self._channels.pop(neighbour, None)

    def desynchronize(self, neighbour) -> None:
        """Mark the common information with ``neighbour`` as unknown: fuse by intersection from now on."""
        self._fall_back(self._channel(neighbour))
        self._generation += 1
        self._fresh = False

    def desynchronize_all(self) -> None:
        """The caller changed the belief by other means than fusion (e.g. merged a duplicate into it, which
        may hold anyone's information): a non-additive change, and no channel's common information is known."""
        for ch in self._channels.values():
            self._fall_back(ch)
        self._generation += 1
        self._fresh = False

    def _fall_back(self, ch: _Channel) -> None:
        ch.synchronized = False
        ch.tainted = ch.tainted or ch.edge is Edge.LOOP
        ch.pending = ch.agreed_at = None

    def _resyncs(self, ch: _Channel) -> bool:
        return (self.me is not None and self.policy in (Policy.EXACT, Policy.HYBRID) and not ch.tainted
                and ch.edge is Edge.TREE)

    def _proposes(self, neighbour) -> bool:
        return self.me < neighbour

    def _channel(self, neighbour, fresh: Freshness = Freshness.INFORMED) -> _Channel:
        """The channel to ``neighbour``, opened if new: synchronised on the prior only where the two ends
        provably share nothing else (module docstring, "New links"; only with a name: re-sync is needed)."""
        if neighbour not in self._channels:
            self.reset(neighbour)
            mine = self.freshness
            trusted = fresh is Freshness.UNSENT or (mine and (fresh or mine is Freshness.UNSENT))
            if self.me is not None and self.check_new_links and not trusted:
                self._channels[neighbour].synchronized = False
        return self._channels[neighbour]

    # -- the protocol -----------------------------------------------------------------------------
    def prepare_send(self, local) -> tuple:
        """The belief to broadcast next and the re-sync flag for each neighbour (:mod:`fusion.resync`).

        Pending proposals are adopted here (step 2: ``F = X_j ⊓ X_i(s)``, in turn for each proposer), so the
        message carries ``F``. Flags: to a higher-named neighbour, "proposal; the newest of your messages
        heard is h" (``h``, 0 if none); to a lower-named one, ``s`` ("accept your proposal ``s``") or ``0``
        ("desynchronised: please propose"). Must be followed by :meth:`on_send` with the same belief."""
        if self.me is None:
            return local, {}
        accepting = [ch for ch in self._channels.values() if ch.pending is not None and self._resyncs(ch)]
        for ch in accepting:
            local = agree(local, ch.pending[1], self.intersect)
        if accepting:
            self._generation += 1
            self._fresh = False
        flags = {}
        for neighbour, ch in self._channels.items():
            if ch in accepting:
                ch.accepting, ch.pending = ch.pending[0], None
                ch.inbound, ch.synchronized = local, True
                flags[neighbour] = ch.accepting
            elif not ch.synchronized and self._resyncs(ch):
                flags[neighbour] = (ch.last_seq or 0) if self._proposes(neighbour) else 0
        return local, flags

    def on_send(self, local, seq: int) -> None:
        """Record the belief broadcast as message ``seq`` (Merino (3.38), deferred to the acknowledgement)."""
        if self.policy in (Policy.CI, Policy.NAIVE):
            return
        if self._sent and seq <= next(reversed(self._sent)):
            raise ValueError(f"sequence numbers must increase: {seq} after {next(reversed(self._sent))}")
        self._sent[seq] = local
        self._generation_at[seq] = self._generation
        if len(self._sent) > self.history:
            del self._generation_at[self._sent.popitem(last=False)[0]]
            self._pruned = True
        for ch in self._channels.values():
            if ch.accepting is not None:
                ch.agreed_at, ch.accepting = seq, None
            ch.inbound_at_send[seq] = ch.inbound
            if len(ch.inbound_at_send) > self.history:
                ch.inbound_at_send.popitem(last=False)

    def _sent_entry(self, ch: _Channel, seq: int):
        """(local, B) as they were when message ``seq`` was sent, or ``None`` if no longer known."""
        if seq not in self._sent:
            return None
        if seq in ch.inbound_at_send:
            return self._sent[seq], ch.inbound_at_send[seq]
        if ch.opened_after is not None and seq <= ch.opened_after:
            return self._sent[seq], self._latest_prior
        return None

    def _predates(self, seq: int) -> bool:
        """Was message ``seq`` sent before this filter sent anything? (Its belief was not in it: e.g. the
        neighbour acknowledges a copy of a track this node deleted before it started this one.)"""
        return not self._pruned and (not self._sent or seq < next(iter(self._sent)))

    def _prior_at(self, epoch):
        """The common prior at ``epoch`` (advanced incrementally: a trajectory prior is the same chain
        at every epoch, and advancing it from its creation on every receive would cost its age)."""
        if epoch is not None and epoch > self._latest_prior.epoch:
            self._latest_prior = self._latest_prior.advanced_to(epoch)
        if epoch is None or epoch == self._latest_prior.epoch:
            return self._latest_prior
        return self.prior.advanced_to(epoch)  # an older epoch than seen before: rare, so the slow path

    def on_receive(
        self,
        neighbour,
        local,
        received,
        acked_seq: int | None,
        seq: int | None = None,
        tree_edge: bool | Edge = True,
        resync: int | None = None,
        fresh: Freshness | int = Freshness.INFORMED,
    ) -> Received:
        """Fuse ``received`` from ``neighbour`` into ``local``.

        ``acked_seq`` is the last of our messages the neighbour had received when it sent this one
        (``None``: none yet); ``seq`` is the message's own sequence number (older or repeated messages
        are ignored); ``tree_edge`` says whether this link is known to be a tree edge (a bridge of the
        communication graph; an :class:`~fusion.resync.Edge` also says whether the graph was known
        completely) — ``hybrid`` uses intersection on any other edge; ``resync`` is the neighbour's
        re-sync flag for us (:meth:`prepare_send`), ``None`` if it sent none; ``fresh`` is the neighbour's
        :attr:`freshness` when it sent the message."""
        out = self._receive(self._channel(neighbour, Freshness(fresh)), local, received, acked_seq, seq, tree_edge,
                            resync, neighbour)
        self._fresh = self._fresh and out.method == "stale"
        return out

    def _receive(self, ch: _Channel, local, received, acked_seq, seq, tree_edge, resync, neighbour) -> Received:
        if seq is not None and ch.last_seq is not None and seq <= ch.last_seq:
            return Received(local, "stale", f"message {seq} is not newer than {ch.last_seq}", "stale")
        if seq is not None:
            ch.last_seq = seq
        ch.edge = as_edge(tree_edge)
        epoch = _newest_epoch(local, received)
        local, received = local.advanced_to(epoch), received.advanced_to(epoch)
        self._prior_at(epoch)

        if self.policy is Policy.NAIVE:
            return Received(local.fuse(received).remove(self._prior_at(epoch)), "naive", cause="policy")
        if self.policy is Policy.CI:
            return Received(self.intersect(local, received), "ci", cause="policy")
        if self.policy is Policy.HYBRID and ch.edge is not Edge.TREE:
            self._fall_back(ch)
            return self._intersect(local, received, f"not a tree edge ({ch.edge})", "not_tree_edge")
        if self.me is not None:
            role = self._as_proposer if self._proposes(neighbour) else self._as_acceptor
            out = role(ch, local, received, acked_seq, resync)
            if out is not None:
                return out
        if not ch.synchronized:
            return self._intersect(local, received, "common information unknown", "common_unknown")
        return self._exact(ch, local, received, acked_seq, epoch)

    def _intersect(self, local, received, reason: str, cause: str) -> Received:
        self._generation += 1
        return Received(self.intersect(local, received), "ci", reason, cause)

    def _as_proposer(self, ch: _Channel, local, received, acked_seq, flag) -> Received | None:
        """Steps 1 and 3 of :mod:`fusion.resync`; ``None``: fuse as usual."""
        if flag == 0 and ch.synchronized:  # the neighbour lost the common information
            self._fall_back(ch)
        if ch.synchronized or not self._resyncs(ch):
            return None
        if not flag:  # not an accept (0 asks for a re-sync): it crossed our proposal, and reaches us inside F
            if ch.ignored >= PATIENCE:
                ch.ignored = 0
                return None
            ch.ignored += 1
            return Received(local, "stale", "waiting for the re-sync accept", "resync_wait")
        ch.ignored = 0
        if self._generation_at.get(flag) != self._generation:
            return self._intersect(local, received, f"accept of a stale proposal {flag}", "resync_refused")
        try:
            rebased = rebase(local, received, self._sent[flag])
        except ValueError as err:
            return self._intersect(local, received, f"re-sync refused: {err}", "resync_refused")
        ch.inbound, ch.synchronized = received, True
        ch.baseline_after = next(reversed(self._sent))
        ch.inbound_at_send.clear()
        self._generation += 1
        return Received(rebased, "resync")

    def _as_acceptor(self, ch: _Channel, local, received, acked_seq, flag) -> Received | None:
        """Step 2 and the start of step 4 of :mod:`fusion.resync`; ``None``: fuse as usual."""
        waiting = ch.synchronized and ch.agreed_at is not None
        if flag is not None:  # a proposal
            if waiting and flag < ch.agreed_at:
                return Received(local, "stale", "a proposal that crossed our accept", "resync_wait")
            self._fall_back(ch)
            if not self._resyncs(ch):
                return None
            ch.pending = (ch.last_seq, received)
            return Received(local, "stale", "re-sync proposal kept for the next message", "resync_pending")
        if waiting and (acked_seq is None or acked_seq < ch.agreed_at):
            return Received(local, "stale", "sent before the neighbour heard our accept", "resync_wait")
        return None

    def _exact(self, ch: _Channel, local, received, acked_seq, epoch) -> Received:
        inbound = ch.inbound.advanced_to(epoch)
        entry = None if acked_seq is None else self._sent_entry(ch, acked_seq)
        before_rebase = ch.baseline_after is not None and acked_seq is not None and acked_seq <= ch.baseline_after
        if acked_seq is None or before_rebase or (entry is None and self._predates(acked_seq)):
            ours_there = None  # the neighbour holds nothing this filter sent (beyond an agreed baseline)
        elif entry is not None:
            ours_there = (entry[0].advanced_to(epoch), entry[1].advanced_to(epoch))
        else:
            self._fall_back(ch)
            return self._intersect(local, received, f"acknowledged message {acked_seq} is not in the history",
                                   "ack_not_in_history")
        try:
            if ours_there is None:
                new_inbound = received
                fused = local.fuse(received).remove(inbound)
            else:
                sent_local, sent_inbound = ours_there
                # Only the fused belief is validated. m - A is a bookkeeping term (Merino's predicted common
                # information, (3.41)-(3.42)) assembled from beliefs marginalised ((3.31)-(3.32)) at different
                # epochs with different information; Schur complements are not linear, so it need not be
                # positive semi-definite even when the fusion itself is (issue 11).
                new_inbound = _difference(received.fuse(sent_inbound), sent_local)  # m - A
                fused = local.fuse(received).fuse(sent_inbound).remove(inbound.fuse(sent_local))  # L + m - (B + A)
        except ValueError as err:
            self._fall_back(ch)
            return self._intersect(local, received, f"exact fusion failed: {err}", "exact_failed")
        ch.inbound = new_inbound
        return Received(fused, "exact")


def _difference(a, b):
    """``a - b`` for a bookkeeping term that is not itself a belief: unchecked where the belief allows it."""
    difference = getattr(a, "difference", None)
    return a.remove(b) if difference is None else difference(b)


def _newest_epoch(a, b):
    if a.epoch is None or b.epoch is None:
        return None
    return max(a.epoch, b.epoch)
