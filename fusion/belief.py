"""The belief algebra (DESIGN.md §2), written as code: what a channel filter needs of a belief.

Every belief kind — a Gaussian in information form, a trajectory (delayed-state) belief, a log-odds or
Beta certainty grid — implements the same small algebra, so that one :class:`fusion.channel_filter.ChannelFilter`
serves all of them (Merino (2.26)-(2.28), Alg. 3.4, (3.39)-(3.42)):

* ``fuse(other)`` — independent evidence combined: ``(y_a + y_b, Y_a + Y_b)`` for Gaussians (Merino (3.9)),
  ``e_a + e_b`` for log-odds evidence relative to the prior, ``α_a + α_b`` for Beta counts above the prior;
* ``remove(common)`` — common information taken out: the inverse of ``fuse``;
* ``epoch`` and ``advanced_to(epoch)`` — the time grid a dynamic belief lives on (``None`` and the identity
  for timeless beliefs); two beliefs are advanced to the newer epoch before the algebra is applied;
* an intersection rule ``intersect(a, b) -> belief`` passed to the channel filter — covariance intersection
  for Gaussians (:func:`fusion.covariance_intersection.ci`), the weighted exponential product at the Chernoff
  point or Merino's max rules for grids (:mod:`fusion.grid_intersect`) — which is consistent whatever the
  unknown correlation, and is used where the common information is not known (loops, lost history).

Particle beliefs (:mod:`fusion.particle_fusion`) are the exception the thesis makes them: their product
and division are one re-weighting step (Alg. 5.2) and their common belief is kept as a density per
neighbour, so they carry their own bookkeeping rather than this algebra.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol, Self, TypeVar, runtime_checkable


@runtime_checkable
class Belief(Protocol):
    """A belief a :class:`~fusion.channel_filter.ChannelFilter` can exchange (module docstring)."""

    @property
    def epoch(self) -> int | None:
        """The time-grid index of the newest state (``None``: a timeless belief)."""
        ...

    def fuse(self, other: Self) -> Self:
        """Add independent evidence."""
        ...

    def remove(self, common: Self) -> Self:
        """Take out information already counted (raises ``ValueError`` if that would be invalid)."""
        ...

    def advanced_to(self, epoch: int | None) -> Self:
        """The same belief predicted to ``epoch`` (the identity for timeless beliefs)."""
        ...


B = TypeVar("B", bound=Belief)

#: A conservative combination of two beliefs whose correlation is unknown.
IntersectRule = Callable[[B, B], B]
