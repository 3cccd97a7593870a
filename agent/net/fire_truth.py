"""The true fire as it travels on the wire, and its decoding in the agent.

The world (``mesh_sim.fire.FireWorld``) owns the stochastic fire; the agent never imports the
simulator (DESIGN §1) and sees the fire only as this plain payload inside the world's truth message::

    {"origin": [north, east],     # corner of cell (0, 0): the minimum north and east of the grid [m]
     "cell": c,                   # cell side [m], > 0
     "shape": [rows, cols],       # row i spans north [n0 + i c, n0 + (i + 1) c), column j likewise in east
     "state": <bytes>,            # zlib(int8 raw, C order): 0 unburnt, 1 burning, 2 burnt
     "temperature_K": T}          # optional: flame temperature for the synthetic thermal camera

The state is the binary truth behind Merino's two layers (§6.3, spec 001b §2.6.1): ``F_k = 1`` (fire
in cell k) is "burning", ``Q_k = 1`` (completely burnt) is "burnt". Mostly uniform regions compress
well: a 100 x 100 grid with a fire of a few hundred cells is a few hundred bytes.

Decoding is strict: any defect raises :class:`agent.net.wire.DecodeError` with reason ``"bad_fire"`` and
a detail naming what was wrong (missing or unknown key, wrong type, NaN, non-positive cell, shape out
of range, bytes that are not zlib or that do not hold exactly ``rows * cols`` states, a state value
outside {0, 1, 2}). Decompression is bounded, so a hostile payload cannot expand without limit.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from agent.net.wire import DecodeError
from perception.scene import Fire

__all__ = [
    "UNBURNT",
    "BURNING",
    "BURNT",
    "MAX_FIRE_CELLS",
    "DEFAULT_TEMPERATURE_K",
    "FireTruth",
    "encode_fire",
    "decode_fire",
]

UNBURNT, BURNING, BURNT = 0, 1, 2
MAX_FIRE_CELLS = 1 << 20  # chosen here: the wire's array limit (a 1024 x 1024 grid)
DEFAULT_TEMPERATURE_K = 800.0  # chosen here: a flaming cell in the thermal image
ZLIB_LEVEL = 6  # chosen here: zlib's default speed/size trade-off
_REQUIRED = frozenset({"origin", "cell", "shape", "state"})
_OPTIONAL = frozenset({"temperature_K"})
REASON = "bad_fire"


def _bad(detail: str) -> DecodeError:
    return DecodeError(REASON, detail)


def _number(value: Any, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise _bad(f"{name} must be a number, got {type(value).__name__}")
    if not math.isfinite(value):
        raise _bad(f"{name} must be finite, got {value}")
    return float(value)


def _check_state(state: np.ndarray) -> np.ndarray:
    if state.ndim != 2 or state.shape[0] < 1 or state.shape[1] < 1:
        raise ValueError(f"fire state must be a non-empty (rows, cols) array, got shape {state.shape}")
    if state.size > MAX_FIRE_CELLS:
        raise ValueError(f"fire state has {state.size} cells > {MAX_FIRE_CELLS}")
    if state.dtype.kind not in "iu":
        raise ValueError(f"fire state must hold integers 0/1/2, got dtype {state.dtype}")
    if state.size and (state.min() < UNBURNT or state.max() > BURNT):
        raise ValueError(f"fire state values must be 0 (unburnt), 1 (burning) or 2 (burnt), got {np.unique(state)}")
    out = np.ascontiguousarray(state, dtype=np.int8).copy()
    out.setflags(write=False)
    return out


@dataclass(frozen=True, eq=False)
class FireTruth:
    """The decoded true fire: grid ``origin`` (north, east of the corner of cell (0, 0)), ``cell`` side
    [m], ``state`` (rows, cols) int8 (0 unburnt, 1 burning, 2 burnt, read-only), the flame
    ``temperature_K``, and the ``terrain`` given to :func:`decode_fire` (used for cell heights)."""

    origin: tuple[float, float]
    cell: float
    state: np.ndarray
    temperature_K: float = DEFAULT_TEMPERATURE_K
    terrain: Any = field(default=None, repr=False)

    def __post_init__(self):
        origin = np.asarray(self.origin, dtype=float)
        if origin.shape != (2,) or not np.all(np.isfinite(origin)):
            raise ValueError(f"fire origin must be 2 finite numbers (north, east), got {self.origin!r}")
        if isinstance(self.cell, bool) or not isinstance(self.cell, int | float) or not (
                math.isfinite(self.cell) and self.cell > 0):
            raise ValueError(f"fire cell side must be a positive finite number of metres, got {self.cell!r}")
        temperature = self.temperature_K
        if isinstance(temperature, bool) or not isinstance(temperature, int | float) or not (
                math.isfinite(temperature) and temperature > 0):
            raise ValueError(f"fire temperature_K must be a positive finite number, got {temperature!r}")
        if self.terrain is not None and not callable(getattr(self.terrain, "height", None)):
            raise ValueError("terrain must have a height(north, east) method")
        object.__setattr__(self, "origin", (float(origin[0]), float(origin[1])))
        object.__setattr__(self, "cell", float(self.cell))
        object.__setattr__(self, "temperature_K", float(temperature))
        object.__setattr__(self, "state", _check_state(np.asarray(self.state)))

    @property
    def shape(self) -> tuple[int, int]:
        return int(self.state.shape[0]), int(self.state.shape[1])

    @property
    def burning(self) -> np.ndarray:
        """(rows, cols) bool: cells on fire (Merino's ``F_k = 1``)."""
        return self.state == BURNING

    @property
    def burnt(self) -> np.ndarray:
        """(rows, cols) bool: cells completely burnt (Merino's ``Q_k = 1``)."""
        return self.state == BURNT

    def centres(self) -> np.ndarray:
        """(rows, cols, 2) north/east centres: ``origin + (i + 1/2, j + 1/2) cell``."""
        rows, cols = self.shape
        n = self.origin[0] + (np.arange(rows) + 0.5) * self.cell
        e = self.origin[1] + (np.arange(cols) + 0.5) * self.cell
        nn, ee = np.meshgrid(n, e, indexing="ij")
        return np.stack([nn, ee], axis=-1)

    def scene_fires(self, terrain=None, temperature_K: float | None = None) -> list[Fire]:
        """One :class:`perception.scene.Fire` per burning cell: a square of side ``cell`` centred on the
        cell centre. With a terrain (the argument, else the one given at decoding) the centre is
        ``(n, e, -h(n, e))`` in NED; with none it is ``(n, e)`` and the renderer drapes it on its own
        ground. ``temperature_K`` defaults to the truth's flame temperature."""
        terrain = self.terrain if terrain is None else terrain
        if terrain is not None and not callable(getattr(terrain, "height", None)):
            raise ValueError("terrain must have a height(north, east) method")
        temperature = self.temperature_K if temperature_K is None else float(temperature_K)
        if not (math.isfinite(temperature) and temperature > 0):
            raise ValueError(f"temperature_K must be a positive finite number, got {temperature_K!r}")
        ne = self.centres()[self.burning]
        if terrain is None:
            return [Fire((float(n), float(e)), self.cell, temperature) for n, e in ne]
        z = -np.asarray(terrain.height(ne[:, 0], ne[:, 1]), dtype=float).reshape(-1)
        return [Fire((float(n), float(e), float(d) + 0.0), self.cell, temperature) for (n, e), d in zip(ne, z,
                                                                                                       strict=True)]


def encode_fire(origin, cell: float, state: np.ndarray, temperature_K: float | None = None) -> dict:
    """The wire payload of a fire grid (see the module docstring). Raises ``ValueError`` on a bad grid."""
    truth = FireTruth(origin, cell, state, DEFAULT_TEMPERATURE_K if temperature_K is None else temperature_K)
    rows, cols = truth.shape
    payload = {
        "origin": [truth.origin[0], truth.origin[1]],
        "cell": truth.cell,
        "shape": [rows, cols],
        "state": zlib.compress(truth.state.tobytes(order="C"), ZLIB_LEVEL),
    }
    if temperature_K is not None:
        payload["temperature_K"] = truth.temperature_K
    return payload


def decode_fire(payload: Mapping, terrain=None) -> FireTruth:
    """Validate a fire payload and return the :class:`FireTruth`; raises
    ``DecodeError("bad_fire", detail)`` on any defect of the payload (never anything else). A ``terrain``
    without a ``height(north, east)`` method is the caller's error: plain ``ValueError``, before any check."""
    if terrain is not None and not callable(getattr(terrain, "height", None)):
        raise ValueError("terrain must have a height(north, east) method")
    if not isinstance(payload, Mapping):
        raise _bad(f"payload must be a map, got {type(payload).__name__}")
    keys = set(payload)
    if not keys >= _REQUIRED or not keys <= _REQUIRED | _OPTIONAL:
        raise _bad(f"fields {sorted(map(str, keys))}, expected {sorted(_REQUIRED)} (+ optional {sorted(_OPTIONAL)})")
    origin = payload["origin"]
    if not isinstance(origin, list | tuple) or len(origin) != 2:
        raise _bad(f"origin must be a list [north, east], got {origin!r:.80}")
    n0, e0 = (_number(v, f"origin[{i}]") for i, v in enumerate(origin))
    cell = _number(payload["cell"], "cell")
    if cell <= 0:
        raise _bad(f"cell must be > 0 m, got {cell}")
    shape = payload["shape"]
    if not isinstance(shape, list | tuple) or len(shape) != 2 or any(
            isinstance(v, bool) or not isinstance(v, int) for v in shape):
        raise _bad(f"shape must be a list [rows, cols] of ints, got {shape!r:.80}")
    rows, cols = shape
    if rows < 1 or cols < 1 or rows * cols > MAX_FIRE_CELLS:
        raise _bad(f"shape {rows}x{cols} must be positive with at most {MAX_FIRE_CELLS} cells")
    temperature = DEFAULT_TEMPERATURE_K
    if "temperature_K" in payload:
        temperature = _number(payload["temperature_K"], "temperature_K")
        if temperature <= 0:
            raise _bad(f"temperature_K must be > 0, got {temperature}")
    data = payload["state"]
    if not isinstance(data, bytes | bytearray):
        raise _bad(f"state must be bytes, got {type(data).__name__}")
    count = rows * cols
    inflater = zlib.decompressobj()
    try:
        raw = inflater.decompress(bytes(data), count + 1)  # bounded: never more than one byte too many
    except zlib.error as err:
        raise _bad(f"state is not zlib data ({err})") from None
    if len(raw) != count or not inflater.eof or inflater.unused_data:
        raise _bad(f"state must hold exactly {count} cells for shape {rows}x{cols} in one complete zlib stream")
    state = np.frombuffer(raw, dtype=np.int8).reshape(rows, cols)
    if state.min() < UNBURNT or state.max() > BURNT:
        raise _bad(f"state values must be 0, 1 or 2, got {sorted(set(np.unique(state).tolist()))[:8]}")
    try:
        return FireTruth((n0, e0), cell, state, temperature, terrain)
    except ValueError as err:
        raise _bad(str(err)) from None


def decoy(entry) -> tuple[float, float, float] | None:
    """One decoy ``[north, east, probability of showing in a frame]`` — finite numbers, the probability in
    [0, 1] — as floats, or ``None`` if the entry is not one."""
    ok = isinstance(entry, list | tuple) and len(entry) == 3 and all(
        isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in entry)
    if not ok or not 0.0 <= entry[2] <= 1.0:
        return None
    return float(entry[0]), float(entry[1]), float(entry[2])
