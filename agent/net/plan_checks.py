"""Checks of the link plan's plain data, with one set of error messages (DESIGN.md §6).

:class:`agent.net.link_plan.LinkPlan` checks a plan with these, and ``mesh_sim.radio`` checks a scenario's
``[radio]`` section with the same ones before it compiles it into a plan, so a rule (what a number may be,
which keys a table takes, what names an agent, that a node is lost once) is written once. Every check
raises ValueError with a message that starts with where the problem is.
"""

from __future__ import annotations

import math

import numpy as np


def check_number(name: str, value, *, lo: float | None = None, hi: float | None = None) -> float:
    """A finite real number (not a bool) within [lo, hi], or ValueError naming the field."""
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise ValueError(f"{name}: must be a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{name}: must be finite, got {value!r}")
    if lo is not None and value < lo:
        raise ValueError(f"{name}: must be >= {lo:g}, got {value:g}")
    if hi is not None and value > hi:
        raise ValueError(f"{name}: must be <= {hi:g}, got {value:g}")
    return value


def check_keys(where: str, d, allowed: set[str] | frozenset[str], required: tuple[str, ...] = ()) -> None:
    """``d`` is a table (dict) with only ``allowed`` keys and every ``required`` one, or ValueError saying where."""
    if not isinstance(d, dict):
        raise ValueError(f"{where}: must be a table/dict, got {type(d).__name__}")
    unknown = sorted(set(d) - set(allowed))
    if unknown:
        raise ValueError(f"{where}: unknown key(s) {unknown}; known: {sorted(allowed)}")
    missing = [k for k in required if k not in d]
    if missing:
        raise ValueError(f"{where}: missing key(s) {missing}")


class AgentNames:
    """A plan's agents (a non-empty list of unique non-empty names), to check every name that refers to one."""

    def __init__(self, where: str, agents):
        if not isinstance(agents, list | tuple) or not agents:
            raise ValueError(f"{where}: agents must be a non-empty list of names, got {agents!r}")
        for a in agents:
            if not isinstance(a, str) or not a:
                raise ValueError(f"{where}: agents: {a!r} is not a non-empty string")
        dup = sorted({a for a in agents if list(agents).count(a) > 1})
        if dup:
            raise ValueError(f"{where}: agents: duplicate name(s) {dup}; names must be unique")
        self.names: tuple[str, ...] = tuple(agents)
        self._known = set(agents)

    def agent(self, name, where: str) -> str:
        if not isinstance(name, str) or name not in self._known:
            raise ValueError(f"{where}: unknown agent {name!r}; agents: {list(self.names)}")
        return name

    def pair(self, x, where: str) -> tuple[str, str]:
        """A link ``[a, b]`` between two different agents."""
        if not isinstance(x, list | tuple) or len(x) != 2:
            raise ValueError(f"{where}: a link must be a pair [a, b], got {x!r}")
        a, b = self.agent(x[0], where), self.agent(x[1], where)
        if a == b:
            raise ValueError(f"{where}: link [{a!r}, {b!r}] joins an agent to itself")
        return a, b


def lose_node(down: dict[str, float], node: str, t: float, where: str) -> None:
    """Record in ``down`` (node -> time lost) that ``node`` is lost from ``t`` on, for good: a node is lost once."""
    if node in down:
        raise ValueError(f"{where}: node {node!r} is lost twice")
    down[node] = t
