"""Re-synchronising a channel filter: two ends agree on one common baseline (issue 11, item 2).

A channel that fell back to intersection (:mod:`fusion.channel_filter`) no longer knows what it shares with
its neighbour. It returns to exact fusion through an explicit agreement: afterwards both ends hold the
*same* belief ``F`` and record it as their common information. Roles follow the names: the lower-named end
``i`` proposes, the higher-named end ``j`` accepts.

1. **Propose.** Every message ``s`` that ``i`` broadcasts while the channel is desynchronised (and the link
   is a tree edge on its side) is a proposal: its belief ``X_i(s)`` is kept in the send history together
   with the *generation* of ``i``'s belief (a counter of non-additive changes: intersections, rebases,
   adoptions, merges).
2. **Accept.** ``j`` (tree edge on its side too) keeps the newest proposal and, when it next broadcasts,
   adopts ``F = X_j ⊓ X_i(s)`` (the channel filter's intersection rule, covariance intersection for
   Gaussians — consistent whatever the correlation, Merino (3.43)-(3.44)). ``F`` is the belief of that
   message ``a``, which is tagged "accept ``s``"; ``j`` sets its common information to ``F``.
3. **Rebase.** ``i`` receives ``a``. If its belief has changed only additively since ``s`` (own measurements,
   exact fusions: same generation) it adopts :func:`rebase`, ``X_i <- F + (X_i - X_i(s))`` — the agreed
   baseline plus its own information gained since the proposal — and sets its common information to
   ``F``. Otherwise it intersects ``F`` like any message and proposes again.
4. **Exact again.** From then on ``fused = local + received - (B + A)`` as usual (``B = F`` at the
   agreement, ``A`` from acknowledgements of messages sent after it). ``j`` ignores ``i``'s messages sent
   before ``i`` heard ``a`` (acknowledgement older than ``a``): they were built on the old baseline, and
   everything in them reaches ``j`` in ``i``'s next message anyway.

**Loss, crossing and idempotence.** Proposals repeat with every message, so a lost proposal is replaced by
the next. The proposal's flag carries the newest of ``j``'s sequence numbers that ``i`` has heard: a
waiting ``j`` that sees a proposal having heard ``a`` or later knows ``a`` was lost or refused and accepts
again; one that has not is a proposal that crossed ``a`` in flight and is ignored. ``i`` uses an accept only
once (messages are de-duplicated by sequence number) and only for a proposal still in its history; while
proposing it ignores ``j``'s other messages (at most :data:`PATIENCE` in a row — they cross the
proposal in flight, and their content reaches ``i`` inside ``F``), so that intersecting them does not
make every proposal stale. Either end that loses the common information asks for an agreement: the
higher-named end sends the flag ``0`` ("desynchronised") and the lower-named end starts proposing.

**Trajectory windows.** ``F`` is formed at the newer of the two epochs; ``i`` advances ``F``, ``X_i(s)``
and its belief to its newest epoch before :func:`rebase`. Marginalising the oldest state does not commute
with the difference (the Schur complement is not linear), the same approximation the channel filter's
bookkeeping makes; the rebased belief is validated and the accept refused if it is not a valid belief.

**Safe condition (the rumour problem).** The agreement is exact only if everything ``i`` gained since
``s`` is new to ``j``. On a tree, information from ``i``'s side reaches ``j`` only through ``i``, so this
holds. After a *loop* it does not: old information spread to both sides before the loop broke, and
each side's later intersections and agreements raise its weight again, so two exact channels could
deliver the same old information to one node twice. A channel that fell back while its link was known
to lie on a loop (:attr:`Edge.LOOP`) is therefore never re-synchronised (it stays on intersection, which
is consistent); channels that fell back for other reasons — a duplicate-track merge, an exact fusion
that was not a valid belief, an acknowledgement older than the history, incomplete knowledge of the
graph (:attr:`Edge.UNKNOWN`) — are. The Monte Carlo tests in ``tests/fusion/test_resync.py`` show
that re-synchronising loop channels as well, or each end taking the other's next message as its
baseline on its own (the naive re-sync), is overconfident.
"""

from __future__ import annotations

from enum import StrEnum

#: Messages from a neighbour ignored in a row while proposing to it, before one is intersected anyway
#: (the neighbour may never accept, e.g. if it does not see the link as a tree edge). Chosen here:
#: a proposal and its accept take one round trip, about two messages each way.
PATIENCE = 4


class Edge(StrEnum):
    """What a node knows of one of its links."""

    TREE = "tree"  # a bridge of the communication graph, known completely
    LOOP = "loop"  # on a loop of the graph, known completely
    UNKNOWN = "unknown"  # the graph is not completely known: the link may lie on a loop


def as_edge(tree_edge) -> Edge:
    """``True`` means a tree edge and ``False`` a loop (the conservative reading of a plain boolean)."""
    if isinstance(tree_edge, Edge):
        return tree_edge
    return Edge.TREE if tree_edge else Edge.LOOP


def agree(local, proposal, intersect):
    """The agreed baseline ``F = local ⊓ proposal`` at the newer epoch of the two."""
    epoch = _newest(local.epoch, proposal.epoch)
    return intersect(local.advanced_to(epoch), proposal.advanced_to(epoch))


def rebase(local, agreed, proposed):
    """``F + (X_i - X_i(s))`` at ``X_i``'s epoch (step 3), as ``(X_i + F) - X_i(s)`` so that the result is
    validated by ``remove`` (``ValueError`` if it is not a valid belief)."""
    epoch = _newest(local.epoch, agreed.epoch)
    local = local.advanced_to(epoch)
    return local.fuse(agreed.advanced_to(epoch)).remove(proposed.advanced_to(epoch))


def _newest(a, b):
    return None if a is None or b is None else max(a, b)
