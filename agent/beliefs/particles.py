"""The ``"particles"`` belief exchange: particle candidates on the wire, fused with the neighbours' (Merino §5.2).

With ``[tracking] initiation = "particles"`` an agent keeps a particle candidate along the viewing ray of
every detection no track explains (:mod:`agent.beliefs.particle_init`). Alone it resolves the depth only
through its own motion; this plug-in lets the neighbours' rays do it (``[tracking.particle_init] exchange =
true``):

* **outgoing**: every ``exchange_period`` every candidate, compressed to a mixture of at most ``components``
  Gaussians (k-means + moment matching, :meth:`fusion.mixture.GaussianMixture.from_particles`; 80 bytes per
  3-D component), in one message (:func:`agent.net.particle_wire.encode_candidates`) charged whole to the
  link budget;
* **sent**: per candidate, ``bel_ij ← the mixture sent`` (Merino (2.28), what the neighbour now holds of it)
  in the candidate's :class:`fusion.particle_fusion.ParticleChannelFilter`;
* **receive**: decode, match the peer's candidates to ours by position (:mod:`agent.beliefs.particle_match`:
  ids are local), and fuse each match with ``N`` samples of the peer's mixture and the mixture itself as
  ``bel_j``: Bayes, Merino Alg. 5.2 / (5.15)-(5.17), ``bel_i bel_j / bel_ij``, on a tree edge; the linear
  opinion pool, Alg. 5.3 / (5.26)-(5.27), on a loop or where the graph is not known completely (a loop
  would bring old information back, which Bayes would count twice); then ``bel_ij ← bel_j`` (2.27). The
  fused set is jittered with the shrunk kernel of (5.25) (moments kept; Liu & West) so that the resampled
  duplicates spread again. A fused candidate converges sooner and is handed over to the Gaussian track
  layer by the tracker as before; a peer's candidate that matches none of ours is not adopted;
* **evaluate** (simulation only): the first time each target is *resolved* — some belief, a track or a
  unimodal candidate, within 2 m of it (:mod:`agent.beliefs.particle_resolution`) — whether or not the
  exchange is on, so that runs with and without it compare.
"""

from __future__ import annotations

from collections import Counter

import numpy as np

from agent.beliefs.particle_init import ParticleInitConfig
from agent.beliefs.particle_match import match
from agent.beliefs.particle_resolution import ResolutionClock
from agent.net import particle_wire
from agent.net.sending import Every
from agent.plugins import Observations, Outgoing
from agent.sensors.truth import TruthSnapshot
from fusion.mixture import GaussianMixture
from fusion.particle_fusion import ParticleChannelFilter
from fusion.particles import ParticleSet, SIRConfig, sir_update
from fusion.resync import Edge

DIM = 3  # a candidate is a position (north, east, down)
#: an SIR step with a flat likelihood that always resamples: regularises a fused pool (chosen here)
REGULARISE = SIRConfig(resample_threshold=1.0)


class ParticleExchange:
    """The candidates of one agent's tracker (``tracker.initiator``), shared and fused with its peers."""

    kind = particle_wire.KIND
    needs_edge = True  # Bayes (Alg. 5.2) on tree edges, LOP (Alg. 5.3) on loops

    def __init__(self, config: ParticleInitConfig, tracker, seed: int):
        self.config = config
        self.tracker = tracker  # agent.beliefs.tracking.Tracker: its initiator holds the candidates
        self.rng = np.random.default_rng(seed)
        self.channels: dict[int, ParticleChannelFilter] = {}  # local candidate id -> its common beliefs
        self.labels: dict[str, dict[int, int]] = {}  # peer -> (its candidate id -> ours)
        self.resolution = ResolutionClock()
        self._timer = Every(config.exchange_period)
        self.fusions: Counter = Counter()  # "bayes"/"lop" -> candidates fused
        self.unmatched = 0  # peers' candidates that matched none of ours
        self.degenerate = 0  # fusions left out: no particle of either set was plausible under the other
        self.message_bytes: list[int] = []
        self.thinned_messages = 0

    def sensors(self) -> list:
        return []

    def planning_hints(self) -> dict:
        return {}

    def _candidates(self) -> dict:
        initiator = self.tracker.initiator
        return {} if initiator is None else {c.id: c for c in initiator.candidates}

    def absorb(self, t: float, observations: Observations) -> None:
        """Nothing: the track exchange's tracker feeds the bearings to the candidates; channels of candidates
        that are gone (handed over, expired) are closed."""
        live = self._candidates()
        self.channels = {cid: cf for cid, cf in self.channels.items() if cid in live}

    def settle(self, t: float) -> None:
        """Nothing held back: candidates are fused as they arrive."""

    # -- sending ----------------------------------------------------------------------------------
    def outgoing(self, t: float, neighbours: list[str]) -> Outgoing | None:
        candidates = self._candidates()
        if not (self.config.exchange and candidates and neighbours and self._timer.due(t)):
            return None
        chosen = sorted(candidates.values(), key=lambda c: -c.hits)[:particle_wire.MAX_SHARED]
        mixtures = {c.id: GaussianMixture.from_particles(c.particles, self.config.components, self.rng)
                    for c in chosen}
        context = ([(c, mixtures[c.id]) for c in chosen], list(neighbours))
        return Outgoing(particle_wire.encode_candidates(mixtures), context=context)

    def sent(self, seq: int, message: Outgoing) -> None:
        entries, neighbours = message.context
        for candidate, mixture in entries:
            self._channel(candidate.id).on_send(candidate.particles, neighbours, sent=mixture)
        self.message_bytes.append(particle_wire.payload_bytes(message.payload))

    def thinned(self, message: Outgoing) -> None:
        self.thinned_messages += 1

    def _channel(self, cid: int) -> ParticleChannelFilter:
        # flat initial bel_ij: a candidate holds only its own bearings (its uniform depth prior is flat); the
        # density estimate of our set shrunk (Liu & West, moments kept: the unshrunk (5.25) widens by 1 + h²)
        return self.channels.setdefault(cid, ParticleChannelFilter(method="bayes", shrink=True))

    # -- receiving --------------------------------------------------------------------------------
    def receive(self, origin: str, seq: int, stamp: float, payload: dict, edge: Edge,
                t: float) -> list[tuple[str, str | None]]:
        """Decode a peer's candidates and fuse each one that matches one of ours. Raises
        :class:`agent.net.wire.DecodeError` on a bad message (nothing is changed then)."""
        remote = particle_wire.decode_candidates(payload, DIM)
        candidates = self._candidates()
        labels = match({cid: c.particles for cid, c in candidates.items()}, remote, self.labels.get(origin, {}))
        self.labels[origin] = labels
        self.unmatched += len(remote) - len(labels)
        method, cause = ("bayes", None) if edge == Edge.TREE else ("lop", "not_tree_edge")
        out = []
        for rid, cid in labels.items():
            candidate, mixture = candidates[cid], remote[rid]
            fused = self._fuse(origin, cid, candidate.particles, mixture, method)
            if fused is None:
                self.degenerate += 1
                continue
            candidate.particles = fused
            self.fusions[method] += 1
            out.append((f"particles_{method}", cause))
        return out

    def peer_restarted(self, peer: str) -> None:
        """A restarted peer (:mod:`agent.net.incarnation`): its candidate ids mean nothing any more and it holds
        none of our candidates, so its labels go and every channel to it is back to the initial common belief."""
        self.labels.pop(peer, None)
        for channel in self.channels.values():
            if peer in channel.neighbours():
                channel.reset(peer)

    def _fuse(self, origin: str, cid: int, local: ParticleSet, mixture: GaussianMixture,
              method: str) -> ParticleSet | None:
        """``local`` fused with a peer's ``mixture`` (``N`` samples of it) through the candidate's channel, as a
        regularised set of ``N`` particles: the weighted pool is resampled and jittered with the kernel of its
        weighted moments (the SIR step's regularisation, §5.3.3). ``None`` if the result is degenerate (no
        particle plausible under the other belief, or too few distinct particles left for a covariance):
        the candidate is then left as it was."""
        received = mixture.sample(self.rng, local.n)
        try:
            pool = self._channel(cid).on_receive(origin, local, received, self.rng, method,
                                                      received_belief=mixture, resample=False)
            fused = sir_update(pool, np.zeros(pool.n), self.rng, REGULARISE).particles.resampled(self.rng, local.n)
            fused.to_gaussian()  # ValueError if its covariance is singular
        except ValueError:  # incl. fusion.resampling.DegenerateWeightsError
            return None
        return fused

    # -- views and results ------------------------------------------------------------------------
    def view(self) -> list:
        """The candidates' mean positions (no planner reads them yet)."""
        return [c.particles.mean() for c in self._candidates().values()]

    def telemetry(self) -> dict:
        return {}

    def evaluate(self, t: float, truth: TruthSnapshot) -> None:
        """Record which targets a unimodal belief of this agent (a track or a candidate) is within 2 m of."""
        if truth.targets is None:
            return
        means = [est.mean[:3] for _, est in self.tracker.estimates(confirmed_only=False)]
        means += [c.particles.mean() for c in self._candidates().values() if c.particles.is_unimodal()]
        self.resolution.record(t, truth.targets, means)

    def metrics(self) -> dict:
        sizes = np.asarray(self.message_bytes, float)
        return {"particles": {
            "exchange": self.config.exchange,
            "resolved_s": self.resolution.summary(),
            "messages": int(sizes.size),
            "payload_bytes": int(sizes.sum()),
            "payload_bytes_max": int(sizes.max()) if sizes.size else None,
            "fusions": dict(self.fusions),
            "unmatched": self.unmatched,
            "degenerate": self.degenerate,
            "thinned": self.thinned_messages,
        }}
