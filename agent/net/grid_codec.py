"""Delta-encoded certainty grids on the wire: keyframes, sparse deltas against an acknowledged baseline.

One job: grid layers <-> a msgpack-able payload (it goes into the ``"p"`` field of an
:class:`agent.net.wire.Envelope`). No acknowledgement bookkeeping here: the caller chooses the baseline
(a message every receiver has acknowledged) and keeps the :class:`GridHistory` of what was sent or
reconstructed.

**What travels.** A grid is ``L`` layers of ``rows x cols`` cells: ``L = 1`` for a Bernoulli grid in
log-odds ``l_k`` (Merino (4.2), Alg. 4.3), ``L = 2`` for a Beta grid's ``alpha_k, beta_k`` (Merino
(4.29)-(4.30), Alg. 4.5). Merino sends "all l^i_k" (Alg. 4.3) and finds grids "not very
convenient for transmitting information" (spec 001a §6, "Bandwidth"); sending full beliefs rather than
increments is what makes the exchange robust to lost messages (spec 001a §6, "Dropouts"). A delta
against a baseline the receiver *holds* keeps that property: the receiver applies it to the baseline
and obtains the sender's full belief, never an increment that a lost message could make it miss.

**Quantization.** Values travel as float32 (:data:`WIRE_DTYPE`, chosen here). :func:`quantize` is what a
receiver reconstructs, ``float64(float32(x))``; the sender records what the receivers rebuild as the belief
it sent, so both sides agree bit-for-bit on every message (the channel filters subtract exactly what the
receiver added). float32 keeps 24 bits of mantissa: a relative error below 2^-24 ~ 6e-8 per cell.

**Deadband** (``tolerance = q > 0``; send-on-delta, Miskowicz 2006, "Send-on-delta concept: an event-based
data reporting strategy", Sensors 6(1)). With exact deltas a grid fused by the Chernoff rule on loops
changes in every cell where agents disagree, a little every period (the weighted log-odds converge
geometrically), so nearly every cell's float32 bits change and the delta outgrows the keyframe (measured on
the fire scenario under hybrid on a full mesh, 60 s: 27 of 31 messages were keyframes, 2 400 of 3 600 cells
changed per period, 1 000 by more than 5 %). With a deadband a cell travels only when it left
``|x - b| > s``, ``s = q max(1, |b|)`` (:func:`step_size`; ``b`` the value the receivers hold, an absolute
quantum near 0 and a relative one beyond), and its new value travels as the whole number of quanta
``k = round((x - b) / s)`` (:func:`apply_steps` rebuilds ``float32(b + k s)``, or 0 where rounding alone
crossed zero, so counts stay non-negative): small integers, zlib'd. Every cell the receiver holds is then
within ``s = q max(1, |b|)`` of the sender's value; a cell inside the deadband keeps the baseline's value
and drifts no further, since the test is always against what the receiver holds. The payload carries
``q``, so both sides compute ``s`` with the same IEEE operations and agree bit for bit. Keyframes stay
exact float32.

**Payloads** (short keys: bandwidth is a first-class metric)::

    keyframe: {"mode": "key", "L": L, "shape": [rows, cols],
               "values": zlib(float32 LE bytes of all layers, layer-major, C order)}
    delta:    {"mode": "delta", "base": base_seq, "L": L, "shape": [rows, cols], "n": k,
               "dtype": "u1" | "u2" | "u4", "index": zlib(gap bytes), "values": float32 LE bytes (L, k)}
    step:     {"mode": "step", ...the delta's fields..., "q": q, "vtype": "i1" | "i2" | "i4",
               "values": zlib(the steps k, LE, (L, k))}

A ``step`` delta is a deadband delta; one whose steps need more than 32 bits (a jump of more than 2^31
quanta) or rebuild a value beyond float32's range is sent as a float32 ``delta`` instead.

Without a deadband a delta lists the ``k`` cells whose float32 value differs *bitwise* from ``float32(baseline)`` in any
layer (bitwise, so that even ``-0.0`` vs ``0.0`` is sent and the two sides agree bit-for-bit). Their
flat indices ``i_1 < ... < i_k`` are gap-coded ``g_j = i_j - i_{j-1}`` with ``i_0 = -1`` (every
``g_j >= 1``), stored in the smallest unsigned dtype that holds the largest gap and zlib-compressed;
clustered changes (a camera footprint) give runs of gap 1 that compress to almost nothing.

**Keyframe fallback.** A delta is replaced by a keyframe whenever the keyframe is smaller, with one
exception that keeps sparse deltas cheap: when the delta is at most :data:`KEYFRAME_PROBE_FRACTION`
of the raw keyframe (``4 L rows cols`` bytes), the keyframe is not tried. A smaller keyframe would then
need a grid that compresses more than 16:1 (nearly all cells at one repeated value, the first messages
after take-off), and the bytes lost are below that fraction. Otherwise the keyframe is compressed in
chunks and abandoned as soon as the compressed bytes emitted so far (a lower bound of its final size)
reach the delta's size, so the check costs little when the keyframe is large.

**Measured sizes** (``skymesh bench grid-ops``; msgpack payload bytes; a half-explored grid: a random
half of the cells hold N(0, 2^2) log-odds evidence or Exp(2) Beta counts, the rest the prior 0; a
change adds to a random fraction of the cells; zlib level 6):

=================  ===========  =========  ==========  =============  =============  ===========
grid               raw float32  keyframe   all prior   delta 1 %      delta 10 %     empty delta
=================  ===========  =========  ==========  =============  =============  ===========
256x256, L = 1     262 144      146 737    313         3 708 (2.5 %)  30 869 (21 %)  71
256x256, L = 2     524 288      287 068    567         6 072 (2.1 %)  56 091 (20 %)  71
1024x1024, L = 1   4 194 304    2 338 879  4 122       56 079 (2.4 %) 489 299 (21 %) 71
=================  ===========  =========  ==========  =============  =============  ===========

(percentages: of the keyframe). The 10 % change as a deadband ``step`` delta at q = 0.02 (the bench's
step column; same generator, one draw per grid): 11 430 bytes on 256x256 (7.8 % of the keyframe, 20.7 %
as float32 values), 177 162 on 1024x1024 (7.6 %, vs 21.0 %). A keyframe of a 1024x1024 grid, or of a
512x512 Beta grid, exceeds the wire format's 1 MiB message limit (``agent.net.wire.MAX_MESSAGE_BYTES``).
Time per message on 256x256 (one core of the benchmark machine): keyframe ~ 10.8 ms to encode (zlib),
1.0 ms to decode; delta 1 % ~ 0.1 ms to encode, 0.04 ms to decode; delta 10 % ~ 3 ms to encode (most of it
the keyframe check).

**Decoding** validates everything before a cell is written and raises :class:`agent.net.wire.DecodeError`
with ``reason`` in :data:`GRID_REASONS` (all of them in ``wire.REASONS``):

* ``grid_bad_mode``: payload not a map, unknown mode, fields other than the mode's, malformed ``base``;
* ``grid_bad_shape``: ``L`` or ``shape`` not those the receiver expects for this grid;
* ``grid_bad_index``: ``n`` not in ``[0, rows*cols]``, unknown index dtype, a zero gap (indices not
  increasing), an index beyond the grid;
* ``grid_bad_values``: NaN or inf, or a number of values other than ``L * n``; a step delta's ``q`` not a
  float in ``(0, MAX_TOLERANCE]``, an unknown step dtype, or a rebuilt value beyond float32's range;
* ``grid_missing_baseline``: the receiver does not hold message ``base`` (it waits for a keyframe or a
  delta on a baseline it has);
* ``grid_corrupt``: a field that should be bytes is not, a zlib error, a decompressed or raw byte count
  other than the one the header implies.

Nothing is allocated from a size the message declares: every byte count is derived from the
receiver's own geometry, and decompression stops one byte past the expected length.
"""

from __future__ import annotations

import zlib
from collections import OrderedDict
from collections.abc import Callable

import msgpack
import numpy as np

from agent.net.wire import DecodeError

WIRE_DTYPE = np.float32  # values travel as float32 (compact); chosen here
_WIRE = np.dtype("<f4")  # the same, with the byte order fixed (wire arrays are little-endian)
_BITS = np.dtype("<u4")  # float32 bit patterns, for the bitwise change test
_FLOAT32_MAX = float(np.finfo(np.float32).max)
ZLIB_LEVEL = 6  # zlib's default level, for index gaps and keyframes (chosen here: bytes over CPU)
KEYFRAME_PROBE_FRACTION = 1 / 16  # deltas up to this fraction of the raw keyframe skip the keyframe check (chosen here)
PROBE_CHUNK = 1 << 16  # bytes fed to zlib between checks of the keyframe's size so far (chosen here)
INDEX_DTYPES: dict[str, np.dtype] = {"u1": np.dtype("u1"), "u2": np.dtype("<u2"), "u4": np.dtype("<u4")}
STEP_DTYPES: dict[str, np.dtype] = {"i1": np.dtype("i1"), "i2": np.dtype("<i2"), "i4": np.dtype("<i4")}
INT32_MAX = (1 << 31) - 1
MAX_CELLS = (1 << 32) - 1  # cells per layer: every gap must fit in uint32
SEQ_LIMIT = 1 << 64  # sequence numbers live in [0, 2**64), as in agent.net.wire
MAX_TOLERANCE = 0.5  # the widest deadband accepted: a cell may lag by half its magnitude (chosen here)

GRID_REASONS: frozenset[str] = frozenset(
    {"grid_bad_mode", "grid_bad_shape", "grid_bad_index", "grid_bad_values", "grid_missing_baseline", "grid_corrupt"}
)
_KEY_FIELDS = frozenset({"mode", "L", "shape", "values"})
_DELTA_FIELDS = frozenset({"mode", "base", "L", "shape", "n", "dtype", "index", "values"})
_STEP_FIELDS = _DELTA_FIELDS | {"q", "vtype"}
_FIELDS = {"key": _KEY_FIELDS, "delta": _DELTA_FIELDS, "step": _STEP_FIELDS}


# -- quantization ------------------------------------------------------------------------------------
def quantize(values: np.ndarray) -> np.ndarray:
    """``float64(float32(values))``: what a receiver reconstructs. Raises ``ValueError`` for a
    non-numeric array, NaN/inf, or a value beyond float32's range (it would arrive as inf)."""
    arr = np.asarray(values)
    if arr.dtype.kind not in "fiu":
        raise ValueError(f"grid values must be a real numeric array, got dtype {arr.dtype}")
    if arr.size and not (-_FLOAT32_MAX <= arr.min() and arr.max() <= _FLOAT32_MAX):  # the rule of encode_grid
        raise ValueError("grid values hold NaN, inf or a magnitude beyond float32's range")
    return arr.astype(WIRE_DTYPE).astype(np.float64)


# -- encode ------------------------------------------------------------------------------------------
def encode_grid(layers: np.ndarray, baseline: np.ndarray | None, base_seq: int | None,
                tolerance: float = 0.0) -> dict:
    """A keyframe (``baseline is None``) or a delta against ``baseline``, the quantized layers of message
    ``base_seq`` that the receivers hold (see the module docstring for the format, the deadband of
    ``tolerance`` and the fallback).

    ``layers``: ``(L, rows, cols)`` real array, finite and within float32's range. Raises ``ValueError``
    for bad shapes, non-finite values, a baseline of another shape, a ``base_seq`` missing / given
    without a baseline, or a ``tolerance`` outside ``[0, MAX_TOLERANCE]``."""
    check_tolerance(tolerance, "tolerance")
    cur = _checked_layers(layers, "layers")
    if baseline is None:
        if base_seq is not None:
            raise ValueError(f"base_seq={base_seq!r} given without a baseline")
        return _keyframe(cur.shape, _deflate(cur.astype(_WIRE).tobytes(), None))
    base = np.asarray(baseline)
    if base.shape != cur.shape or base.dtype.kind not in "fiu":
        raise ValueError(f"baseline has shape {base.shape} and dtype {base.dtype}, expected real {cur.shape}")
    if isinstance(base_seq, bool) or not isinstance(base_seq, int | np.integer) or not 0 <= base_seq < SEQ_LIMIT:
        raise ValueError(f"base_seq must be an int in [0, 2**64) with a baseline, got {base_seq!r}")
    L, rows, cols = cur.shape
    cur_flat = cur.reshape(L, rows * cols)
    base_flat = np.ascontiguousarray(base, dtype=np.float64).reshape(L, rows * cols)
    idx = _bit_changes(cur_flat, base_flat) if tolerance == 0.0 else _moved(cur_flat, base_flat, tolerance)
    delta = {"mode": "delta", "base": int(base_seq), "L": L, "shape": [rows, cols], **_index(idx)}
    steps = _steps(cur_flat[:, idx], base_flat[:, idx], tolerance) if tolerance > 0.0 else None
    if steps is None:
        delta["values"] = cur_flat[:, idx].astype(_WIRE).tobytes()
    else:
        delta.update(mode="step", q=float(tolerance), vtype=_int_dtype(steps), values=_packed_steps(steps))
    delta_size = encoded_size(delta)
    if delta_size <= KEYFRAME_PROBE_FRACTION * 4 * cur.size:
        return delta
    compressed = _deflate(cur.astype(_WIRE).tobytes(), stop_at=delta_size)
    if compressed is None:
        return delta
    key = _keyframe(cur.shape, compressed)
    return key if encoded_size(key) < delta_size else delta


def check_tolerance(tolerance, name: str) -> float:
    """``tolerance`` as a float in ``[0, MAX_TOLERANCE]``, or a ``ValueError`` naming ``name``."""
    if isinstance(tolerance, bool) or not isinstance(tolerance, int | float | np.floating | np.integer) \
            or not 0.0 <= tolerance <= MAX_TOLERANCE:
        raise ValueError(f"{name} must be a number in [0, {MAX_TOLERANCE}], got {tolerance!r}")
    return float(tolerance)


def _bit_changes(cur: np.ndarray, base: np.ndarray) -> np.ndarray:
    """Flat indices of the cells whose float32 bits differ in any layer (``cur``, ``base``: ``(L, cells)``
    float64). Candidates first: float64 bits differ (equal float64 bits give equal float32 bits); then the
    float32 bits of the candidates only, which avoids two full float32 conversions."""
    cur_bits, base_bits = cur.view(np.uint64), base.view(np.uint64)
    candidate = cur_bits[0] != base_bits[0]
    for layer in range(1, cur.shape[0]):
        candidate |= cur_bits[layer] != base_bits[layer]
    idx = np.flatnonzero(candidate)
    with np.errstate(over="ignore", invalid="ignore"):
        new_bits, old_bits = cur[:, idx].astype(_WIRE).view(_BITS), base[:, idx].astype(_WIRE).view(_BITS)
    return idx[np.any(new_bits != old_bits, axis=0)]


def _moved(cur: np.ndarray, base: np.ndarray, tolerance: float) -> np.ndarray:
    """Flat indices of the cells that left the deadband in any layer: ``|x - b| > q max(1, |b|)``
    (send-on-delta, Miskowicz 2006, with the absolute/relative threshold of the module docstring)."""
    return np.flatnonzero(np.any(np.abs(cur - base) > tolerance * np.maximum(1.0, np.abs(base)), axis=0))


def _index(idx: np.ndarray) -> dict:
    """The ``n``, ``dtype`` and ``index`` fields of sorted flat cell indices ``idx`` (gap-coded, zlib)."""
    gaps = idx.copy()  # i_j - i_{j-1} with i_0 = -1
    gaps[1:] -= idx[:-1]
    gaps[:1] += 1
    name = _index_dtype(int(gaps.max()) if gaps.size else 0)
    return {"n": int(idx.size), "dtype": name,
            "index": zlib.compress(gaps.astype(INDEX_DTYPES[name]).tobytes(), ZLIB_LEVEL)}


def step_size(base: np.ndarray, q: float) -> np.ndarray:
    """The quantum of a cell, ``s = q max(1, |b|)`` (the deadband's width and the step of its values)."""
    return q * np.maximum(1.0, np.abs(base))


def apply_steps(base: np.ndarray, steps: np.ndarray, q: float) -> np.ndarray:
    """What a ``step`` delta rebuilds: ``r = b + k s``, except that a value landing on the other side of zero
    from ``b`` by at most ``s / 2`` becomes 0 (so values that cannot be negative, Beta counts, never are);
    then ``float32`` of it, as float64. The same IEEE operations on both sides: sender and receiver agree
    bit for bit. Non-finite where it overflows float32."""
    step = step_size(base, q)
    with np.errstate(over="ignore", invalid="ignore"):
        rebuilt = base + steps * step
        rebuilt = np.where((rebuilt * base < 0.0) & (np.abs(rebuilt) <= 0.5 * step), 0.0, rebuilt)
        return rebuilt.astype(_WIRE).astype(np.float64)


def _steps(cur: np.ndarray, base: np.ndarray, q: float) -> np.ndarray | None:
    """``k = round((x - b) / s)`` per sent cell and layer, or ``None`` when a ``k`` needs more than 32 bits or
    a rebuilt value overflows float32 (the delta then carries float32 values)."""
    steps = np.rint((cur - base) / step_size(base, q))
    if steps.size and (np.abs(steps).max() > INT32_MAX or not np.all(np.isfinite(apply_steps(base, steps, q)))):
        return None
    return steps.astype(np.int64)


def _int_dtype(steps: np.ndarray) -> str:
    """The smallest of i1, i2, i4 that holds every step."""
    top = int(np.abs(steps).max()) if steps.size else 0
    return "i1" if top <= 0x7F else "i2" if top <= 0x7FFF else "i4"


def _packed_steps(steps: np.ndarray) -> bytes:
    return zlib.compress(steps.astype(STEP_DTYPES[_int_dtype(steps)]).tobytes(), ZLIB_LEVEL)


def encoded_size(payload: dict) -> int:
    """Bytes of the payload packed alone with msgpack (the envelope adds its own header)."""
    return len(msgpack.packb(payload, use_bin_type=True))


def _checked_layers(layers, name: str) -> np.ndarray:
    """``layers`` as a C-contiguous float64 ``(L, rows, cols)`` array (no copy if it is one already),
    every value finite and within float32's range (a min/max pass: NaN fails the comparisons)."""
    arr = np.asarray(layers)
    if arr.dtype.kind not in "fiu":
        raise ValueError(f"{name} must be a real numeric array, got dtype {arr.dtype}")
    if arr.ndim != 3 or min(arr.shape) < 1:
        raise ValueError(f"{name} must have shape (L, rows, cols) with every size >= 1, got {arr.shape}")
    if arr.shape[1] * arr.shape[2] > MAX_CELLS:
        raise ValueError(f"{name}: {arr.shape[1]}x{arr.shape[2]} cells > {MAX_CELLS}")
    arr = np.ascontiguousarray(arr, dtype=np.float64)
    if not (-_FLOAT32_MAX <= arr.min() and arr.max() <= _FLOAT32_MAX):
        raise ValueError(f"{name} hold NaN, inf or a magnitude beyond float32's range")
    return arr


def _index_dtype(largest_gap: int) -> str:
    """The smallest of u1, u2, u4 that holds ``largest_gap``."""
    return "u1" if largest_gap <= 0xFF else "u2" if largest_gap <= 0xFFFF else "u4"


def _keyframe(shape: tuple[int, int, int], compressed: bytes) -> dict:
    L, rows, cols = shape
    return {"mode": "key", "L": L, "shape": [rows, cols], "values": compressed}


def _deflate(raw: bytes, stop_at: int | None) -> bytes | None:
    """zlib-compress ``raw``; ``None`` as soon as the output emitted so far reaches ``stop_at`` bytes
    (the final stream can only be longer). Output equals ``zlib.compress(raw, ZLIB_LEVEL)`` otherwise."""
    if stop_at is None:
        return zlib.compress(raw, ZLIB_LEVEL)
    packer = zlib.compressobj(ZLIB_LEVEL)
    view, parts, emitted = memoryview(raw), [], 0
    for start in range(0, len(view), PROBE_CHUNK):
        part = packer.compress(view[start : start + PROBE_CHUNK])
        emitted += len(part)
        if emitted >= stop_at:
            return None
        parts.append(part)
    parts.append(packer.flush())
    return b"".join(parts)


# -- decode ------------------------------------------------------------------------------------------
def decode_grid(
    payload: dict,
    shape: tuple[int, int],
    layers: int,
    baseline_lookup: Callable[[int], np.ndarray | None],
) -> np.ndarray:
    """The ``(layers, rows, cols)`` float64 quantized layers a payload carries.

    ``shape`` and ``layers`` are the receiver's geometry for this grid; ``baseline_lookup(base_seq)``
    returns the layers it reconstructed from message ``base_seq`` (an earlier result of this function)
    or ``None``. Raises :class:`agent.net.wire.DecodeError` for any defect of the payload (reasons in the module
    docstring) and ``ValueError`` for a bad ``shape``/``layers`` or a baseline of the wrong shape (defects
    of the caller, not of the message). The baseline itself is never modified."""
    rows, cols = _check_geometry(shape, layers)
    size = rows * cols
    if not isinstance(payload, dict):
        raise DecodeError("grid_bad_mode", f"payload must be a map, got {type(payload).__name__}")
    mode = payload.get("mode")
    fields = _FIELDS.get(mode) if isinstance(mode, str) else None
    if fields is None:
        raise DecodeError("grid_bad_mode", f"mode {str(mode)[:40]!r} is not 'key', 'delta' or 'step'")
    if set(payload) != fields:
        found = sorted(str(k)[:40] for k in payload)
        raise DecodeError("grid_bad_mode", f"{mode} payload fields {found}, expected {sorted(fields)}")
    declared = payload["shape"]
    if not (isinstance(declared, list | tuple) and len(declared) == 2 and all(map(_is_int, declared))):
        raise DecodeError("grid_bad_shape", "shape must be two ints")
    if not _is_int(payload["L"]) or payload["L"] != layers or tuple(declared) != (rows, cols):
        raise DecodeError(
            "grid_bad_shape", f"L={payload['L']!r}, shape={declared!r}; expected L={layers}, shape=[{rows}, {cols}]"
        )
    if mode == "key":
        values = _values(_inflate(payload["values"], 4 * layers * size, "values"), layers * size)
        return values.astype(np.float64).reshape(layers, rows, cols)

    base = payload["base"]
    if not _is_int(base) or not 0 <= base < SEQ_LIMIT:
        raise DecodeError("grid_bad_mode", f"base {str(base)[:40]!r} is not a seq in [0, 2**64)")
    n, name = payload["n"], payload["dtype"]
    if not _is_int(n) or not 0 <= n <= size:
        raise DecodeError("grid_bad_index", f"n={str(n)[:40]} outside [0, {size}]")
    if not isinstance(name, str) or name not in INDEX_DTYPES:
        raise DecodeError("grid_bad_index", f"index dtype {str(name)[:40]!r} not in {sorted(INDEX_DTYPES)}")
    itemsize = INDEX_DTYPES[name].itemsize
    gaps = np.frombuffer(_inflate(payload["index"], n * itemsize, "index"), dtype=INDEX_DTYPES[name])
    if n and not np.all(gaps):
        raise DecodeError("grid_bad_index", "a zero gap: cell indices are not strictly increasing")
    idx = np.cumsum(gaps, dtype=np.uint64)  # n < 2**32 gaps < 2**32 each: no wrap-around
    if n and int(idx[-1]) > size:
        raise DecodeError("grid_bad_index", f"cell index {int(idx[-1]) - 1} outside a grid of {size} cells")
    if mode == "delta":
        raw = payload["values"]
        if not isinstance(raw, bytes | bytearray) or len(raw) % 4:
            raise DecodeError("grid_corrupt", "delta values must be float32 bytes")
        values = _values(raw, layers * n).reshape(layers, n)
    else:
        q, steps = _step_values(payload, layers * n)
    stored = baseline_lookup(base)
    if stored is None:
        raise DecodeError("grid_missing_baseline", f"baseline message {base} is not held")
    stored = np.asarray(stored)
    if stored.shape != (layers, rows, cols):
        raise ValueError(f"baseline {base} has shape {stored.shape}, expected {(layers, rows, cols)}")
    out = np.array(stored, dtype=np.float64, copy=True)
    cells = idx.astype(np.intp) - 1
    if mode == "step":
        values = apply_steps(out.reshape(layers, size)[:, cells], steps.reshape(layers, n), q)
        if not np.all(np.isfinite(values)):
            raise DecodeError("grid_bad_values", "a rebuilt value overflows float32")
    out.reshape(layers, size)[:, cells] = values
    return out


def _step_values(payload: dict, count: int) -> tuple[float, np.ndarray]:
    """The quantum ``q`` and the ``count`` integer steps of a ``step`` delta (before its baseline is used)."""
    q, vtype = payload["q"], payload["vtype"]
    if not isinstance(q, float) or not 0.0 < q <= MAX_TOLERANCE:  # NaN fails the comparison
        raise DecodeError("grid_bad_values", f"quantum q={str(q)[:40]} is not a float in (0, {MAX_TOLERANCE}]")
    if not isinstance(vtype, str) or vtype not in STEP_DTYPES:
        raise DecodeError("grid_bad_values", f"step dtype {str(vtype)[:40]!r} not in {sorted(STEP_DTYPES)}")
    raw = _inflate(payload["values"], count * STEP_DTYPES[vtype].itemsize, "values")
    return q, np.frombuffer(raw, dtype=STEP_DTYPES[vtype]).astype(np.float64)


def _check_geometry(shape, layers) -> tuple[int, int]:
    if not (isinstance(shape, tuple | list) and len(shape) == 2 and all(map(_is_int, shape))):
        raise ValueError(f"shape must be (rows, cols) ints, got {shape!r}")
    rows, cols = (int(s) for s in shape)
    if rows < 1 or cols < 1 or rows * cols > MAX_CELLS:
        raise ValueError(f"shape {shape!r} must have rows, cols >= 1 and at most {MAX_CELLS} cells")
    if not _is_int(layers) or layers < 1:
        raise ValueError(f"layers must be an int >= 1, got {layers!r}")
    return rows, cols


def _inflate(data, expected: int, name: str) -> bytes:
    """Exactly ``expected`` bytes from one complete zlib stream, or ``grid_corrupt``."""
    if not isinstance(data, bytes | bytearray):
        raise DecodeError("grid_corrupt", f"{name} must be bytes, got {type(data).__name__}")
    unpacker = zlib.decompressobj()
    try:
        out = unpacker.decompress(data, expected + 1)  # never more than one byte past what is expected
    except zlib.error as exc:
        raise DecodeError("grid_corrupt", f"{name}: zlib error ({exc})") from None
    if len(out) != expected or not unpacker.eof or unpacker.unconsumed_tail or unpacker.unused_data:
        raise DecodeError(
            "grid_corrupt", f"{name}: expected {expected} bytes in one complete zlib stream, got {len(out)}+"
        )
    return out


def _values(raw, count: int) -> np.ndarray:
    if len(raw) % 4:
        raise DecodeError("grid_corrupt", f"{len(raw)} value bytes is not a whole number of float32")
    if len(raw) != 4 * count:
        raise DecodeError("grid_bad_values", f"{len(raw) // 4} values, expected {count}")
    values = np.frombuffer(raw, dtype=_WIRE)
    if not np.all(np.isfinite(values)):
        raise DecodeError("grid_bad_values", "NaN or inf among the values")
    return values


def _is_int(value) -> bool:
    return isinstance(value, int | np.integer) and not isinstance(value, bool | np.bool_)


# -- history -----------------------------------------------------------------------------------------
class GridHistory:
    """Quantized layers of recent messages by seq (sender side: what it sent; receiver side: what it
    reconstructed from one origin). Holds at most ``capacity`` messages, all of one shape; ``put``
    stores a read-only copy, so a caller cannot change a baseline after the fact."""

    def __init__(self, capacity: int = 16):
        if not _is_int(capacity) or capacity < 1:
            raise ValueError(f"capacity must be an int >= 1, got {capacity!r}")
        self.capacity = int(capacity)
        self._items: OrderedDict[int, np.ndarray] = OrderedDict()

    def put(self, seq: int, layers: np.ndarray) -> None:
        """Store ``layers`` as message ``seq`` (greater than every stored seq), evicting the oldest when
        full. Raises ``ValueError`` for a seq out of order or range, a shape other than the stored ones'
        or not ``(L, rows, cols)``, or non-finite values."""
        if not _is_int(seq) or not 0 <= seq < SEQ_LIMIT:
            raise ValueError(f"seq must be an int in [0, 2**64), got {seq!r}")
        if self._items and seq <= next(reversed(self._items)):
            raise ValueError(f"seq {seq} does not increase (latest is {next(reversed(self._items))})")
        arr = np.asarray(layers)
        if arr.dtype.kind not in "fiu" or arr.ndim != 3 or min(arr.shape) < 1:
            raise ValueError(f"layers must be a real (L, rows, cols) array, got {arr.dtype} {arr.shape}")
        if self._items and arr.shape != next(iter(self._items.values())).shape:
            raise ValueError(f"layers of shape {arr.shape}, the history holds {next(iter(self._items.values())).shape}")
        stored = np.array(arr, dtype=np.float64, copy=True)
        if not np.all(np.isfinite(stored)):
            raise ValueError("layers hold NaN or inf")
        stored.flags.writeable = False
        self._items[int(seq)] = stored
        while len(self._items) > self.capacity:
            self._items.popitem(last=False)

    def get(self, seq: int) -> np.ndarray | None:
        """The layers of message ``seq`` (read-only), or ``None`` if not held."""
        return self._items.get(seq) if _is_int(seq) else None

    def latest(self) -> tuple[int, np.ndarray] | None:
        """``(seq, layers)`` of the newest message, or ``None`` when empty."""
        if not self._items:
            return None
        seq = next(reversed(self._items))
        return seq, self._items[seq]

    def __len__(self) -> int:
        return len(self._items)
