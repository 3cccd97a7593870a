"""The fleet's key space and what a transport hands the agent (DESIGN.md §5). No Zenoh here.

Key space ``skymesh/<fleet>/...``: ``belief/<kind>/<agent>``, ``topology/<agent>`` (who hears whom, for the
peers), ``telemetry/<agent>`` (for the ground station: agents do not subscribe to it),
``sim/{truth,clock,measurement/<agent>}`` and liveliness tokens ``alive/<agent>``. The fleet name
isolates concurrent runs on one machine.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Incoming:
    key: str
    data: bytes
    received_at: float  # wall clock [s]
    encoding: str | None = None  # the Zenoh encoding it came with (agent.net.wire.ZENOH_ENCODING); None in memory


class Keys:
    """The key expressions of one fleet."""

    def __init__(self, fleet: str):
        if not fleet or any(c in fleet for c in "/*$#? "):
            raise ValueError(f"fleet name {fleet!r} must be a non-empty key chunk (no / * $ # ? or spaces)")
        self.root = f"skymesh/{fleet}"

    def belief(self, kind: str, agent: str) -> str:
        return f"{self.root}/belief/{kind}/{agent}"

    def telemetry(self, agent: str) -> str:
        return f"{self.root}/telemetry/{agent}"

    def topology(self, agent: str) -> str:
        return f"{self.root}/topology/{agent}"

    def agent_subscriptions(self, senders: tuple[str, ...] | None = None) -> list[str]:
        """What an agent listens to: its peers' beliefs and topology reports, and the world's truth (simulation
        only) — not their telemetry, which is for the ground station. ``senders``: the only peers whose beliefs
        can reach it (a sparse emulated radio, :meth:`agent.net.link_plan.LinkPlan.senders_to`; the others'
        would be dropped as ``down`` after decoding), or None for every peer's."""
        if senders is None:
            beliefs = [f"{self.root}/belief/**"]
        else:
            beliefs = [self.belief("*", peer) for peer in senders]
        return [*beliefs, self.topology("*"), self.sim("truth")]

    def sim(self, name: str) -> str:
        return f"{self.root}/sim/{name}"

    def alive(self, agent: str) -> str:
        return f"{self.root}/alive/{agent}"

    def parse(self, key: str) -> tuple[str, ...]:
        """The chunks after the fleet root, e.g. ``("belief", "track", "uav3")``."""
        prefix = self.root + "/"
        if not key.startswith(prefix):
            raise ValueError(f"key {key!r} is not in fleet {self.root!r}")
        return tuple(key[len(prefix):].split("/"))
