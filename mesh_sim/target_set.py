"""The target set of a scenario: built from TOML-like tables, and its truth as plain data for the wire.

:func:`targets_from_config` builds the ground-target models of :mod:`mesh_sim.targets` (spec 004 §4) from
a scenario's ``[[targets]]`` tables; :func:`truth_snapshot` evaluates them at one time for the wire.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from numbers import Integral
from typing import Any

from mesh_sim.targets import (
    FLAT_GROUND,
    ConstantVelocityTarget,
    DampedVelocityTarget,
    Figure8Target,
    SingerTarget,
    StaticTarget,
    Target,
    as_real,
)
from perception.terrain import Terrain

__all__ = ["targets_from_config", "truth_snapshot"]

# kind -> (class, required fields, optional fields); each field maps to a parser below.
_KINDS: dict[str, tuple[type, tuple[str, ...], tuple[str, ...]]] = {
    "static": (StaticTarget, ("position",), ()),
    "constant_velocity": (ConstantVelocityTarget, ("position", "velocity"), ()),
    "figure8": (Figure8Target, ("center",), ("d", "omega", "heading_deg")),
    "singer": (
        SingerTarget,
        ("position", "velocity", "alpha", "sigma", "seed"),
        ("dt", "max_speed", "acceleration", "max_horizon"),
    ),
    "damped_velocity": (
        DampedVelocityTarget,
        ("position", "speed_std", "tau", "seed"),
        ("velocity", "dt", "max_horizon"),
    ),
}
_VECTORS = {"position", "velocity", "center", "acceleration"}
_POSITIVE = {"d", "omega", "alpha", "dt", "max_speed", "max_horizon", "speed_std", "tau"}


def _parse_field(name: str, value: Any) -> Any:
    if name in _VECTORS:
        if isinstance(value, (str, bytes)) or not isinstance(value, Sequence):
            raise ValueError(f"must be a list [north, east] of 2 numbers, got {value!r}")
        if len(value) != 2:
            raise ValueError(f"must have 2 entries [north, east], got {len(value)}")
        return tuple(as_real(v, f"entry {i}") for i, v in enumerate(value))
    if name == "seed":
        if isinstance(value, bool) or not isinstance(value, Integral) or value < 0:
            raise ValueError(f"must be a non-negative integer, got {value!r}")
        return int(value)
    if name == "heading_deg":
        return math.radians(as_real(value, "value"))
    return as_real(value, "value", positive=name in _POSITIVE, non_negative=name == "sigma")


def targets_from_config(configs: Sequence[Mapping[str, Any]], terrain: Terrain | None = None) -> list:
    """Build targets from TOML-like tables, all riding on ``terrain`` (flat at 0 m if ``None``):

    - ``{"id": "t0", "kind": "static", "position": [n, e]}``
    - ``{"kind": "constant_velocity", "position": [n, e], "velocity": [vn, ve]}``
    - ``{"kind": "figure8", "center": [n, e], "d": 20, "omega": 0.0285, "heading_deg": 0}``
    - ``{"kind": "singer", "position": [n, e], "velocity": [vn, ve], "alpha": 0.1, "sigma": 0.5,
      "seed": 3, "dt": 0.05, "max_speed": 8.0, "acceleration": [an, ae], "max_horizon": 86400}``
    - ``{"kind": "damped_velocity", "position": [n, e], "speed_std": 1.0, "tau": 10.0, "seed": 3,
      "velocity": [vn, ve] (default: drawn), "dt": 0.05, "max_horizon": 86400}``

    ``id`` defaults to ``"t<index>"`` and must be unique. Angles are degrees in the config and radians
    inside. Unknown kinds or keys, missing keys, wrong lengths and non-finite or out-of-range numbers
    raise :class:`ValueError` naming the target and the field."""
    if isinstance(configs, Mapping) or isinstance(configs, (str, bytes)) or not isinstance(configs, Sequence):
        raise ValueError(f"targets config must be a list of tables, got {type(configs).__name__}")
    terrain = FLAT_GROUND if terrain is None else terrain
    targets = []
    seen: set[str] = set()
    for index, config in enumerate(configs):
        if not isinstance(config, Mapping):
            raise ValueError(f"target #{index}: must be a table, got {type(config).__name__}")
        tid = config.get("id", f"t{index}")
        where = f"target #{index}" if not isinstance(tid, str) else f"target {tid!r} (#{index})"
        if not isinstance(tid, str) or not tid:
            raise ValueError(f"{where}: field 'id' must be a non-empty string, got {tid!r}")
        if tid in seen:
            raise ValueError(f"{where}: field 'id' duplicates an earlier target")
        seen.add(tid)
        kind = config.get("kind")
        if kind not in _KINDS:
            raise ValueError(f"{where}: field 'kind' must be one of {sorted(_KINDS)}, got {kind!r}")
        cls, required, optional = _KINDS[kind]
        for name in required:
            if name not in config:
                raise ValueError(f"{where}: missing field {name!r} (required for kind {kind!r})")
        unknown = sorted(set(config) - {"id", "kind", *required, *optional})
        if unknown:
            raise ValueError(f"{where}: unknown field(s) {unknown} for kind {kind!r}")
        kwargs = {}
        for name in (*required, *optional):
            if name in config:
                try:
                    kwargs[name] = _parse_field(name, config[name])
                except ValueError as err:
                    raise ValueError(f"{where}: field {name!r} {err}") from None
        if "heading_deg" in kwargs:
            kwargs["heading"] = kwargs.pop("heading_deg")
        try:
            targets.append(cls(**kwargs, id=tid, terrain=terrain))
        except ValueError as err:
            raise ValueError(f"{where}: {err}") from None
    return targets


def truth_snapshot(targets: Sequence[Target], t: float) -> list[dict]:
    """Plain data for the wire: ``[{"id", "position": [n, e, d], "velocity": [vn, ve, vd]}]`` at ``t``."""
    out = []
    for target in targets:
        p, v = target.state(t)
        out.append({"id": target.id, "position": [float(x) for x in p], "velocity": [float(x) for x in v]})
    return out
