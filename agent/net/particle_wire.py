"""Particle beliefs on the wire (Merino §5.3.5, §5.4.1 Fig. 5.13): the full set, or a compressed mixture.

Payloads (msgpack maps with short keys, inside the envelope of :mod:`agent.net.wire`, kind ``KIND``)::

    full set   {"f": "set", "n": N, "d": d, "x": N*d float64 LE bytes (row-major), "w": N float64 LE bytes}
    compressed {"f": "gmm", "k": K, "d": d, "a": K float64, "m": K*d float64,
                "c": K * d(d+1)/2 float64 (upper triangle of each covariance, row by row)}

Raw little-endian bytes (msgpack ``bin``) rather than :mod:`agent.net.wire`'s array extension: the thesis's
message is "N particles x 4 doubles" and nothing else (≈ 6400 bytes for N = 200 with a 3-D state plus
the weight; here 6400 bytes of numbers plus ~20 bytes of payload keys and headers). The compressed form
is :meth:`fusion.mixture.GaussianMixture.from_particles` (k-means + moment matching: it keeps the
set's mean and covariance exactly): ``8 K (1 + d + d(d+1)/2)`` bytes, 640 for K = 8 and d = 3.

A *candidate message* (:mod:`agent.beliefs.particles`, kind ``KIND`` between agents) carries an agent's
particle candidates, each compressed::

    {"candidates": [{"id": local id >= 0, "b": compressed payload}, ...]}   at most MAX_SHARED entries, ids unique

Decoding validates everything before it builds a belief and raises only :class:`agent.net.wire.DecodeError`:
field set and types (``bad_field``/``bad_type``), sizes against the limits (``oversize``), byte counts
against the declared shape (``bad_shape``), finite numbers (``non_finite``), non-negative weights that
sum to one (``bad_field``) and positive-definite covariances (``indefinite``).
"""

from __future__ import annotations

import math

import msgpack
import numpy as np

from agent.net.wire import DecodeError
from fusion.mixture import GaussianMixture
from fusion.particles import WEIGHT_SUM_TOL, ParticleSet

__all__ = [
    "KIND",
    "MAX_DIM",
    "MAX_PARTICLES",
    "MAX_COMPONENTS",
    "encode_particles",
    "encode_mixture",
    "encode_compressed",
    "encode_for_budget",
    "payload_bytes",
    "mixture_bytes",
    "decode_particle_belief",
    "decode_particles",
    "decode_mixture",
    "MAX_SHARED",
    "encode_candidates",
    "decode_candidates",
]

#: Envelope kind of a particle belief (pass ``kinds=wire.KINDS | {KIND}`` to encode/decode).
KIND = "particles"
#: Limits (chosen here) on what a payload may declare, checked before anything is allocated (the envelope
#: itself is bounded by ``agent.net.wire.MAX_MESSAGE_BYTES``).
MAX_DIM = 16
MAX_PARTICLES = 1 << 15
MAX_COMPONENTS = 1024
MAX_SHARED = 64  # candidates in one message (chosen here: twice the initiator's MAX_CANDIDATES)
_F8 = np.dtype("<f8")
_SET_KEYS = frozenset({"f", "n", "d", "x", "w"})
_GMM_KEYS = frozenset({"f", "k", "d", "a", "m", "c"})


# -- encoding -------------------------------------------------------------------------------------------
def _le_bytes(arr: np.ndarray) -> bytes:
    return np.ascontiguousarray(arr, dtype=_F8).tobytes()


def encode_particles(particles: ParticleSet) -> dict:
    """The full set: states and weights as raw little-endian float64 bytes."""
    if not isinstance(particles, ParticleSet):
        raise ValueError(f"expected a ParticleSet, got {type(particles).__name__}")
    if particles.dim > MAX_DIM or particles.n > MAX_PARTICLES:
        raise ValueError(f"{particles.n} particles of dimension {particles.dim} exceed the wire limits")
    return {
        "f": "set",
        "n": particles.n,
        "d": particles.dim,
        "x": _le_bytes(particles.states),
        "w": _le_bytes(particles.weights),
    }


def encode_mixture(mixture: GaussianMixture) -> dict:
    """A mixture: weights, means and the upper triangles of the covariances, raw little-endian float64."""
    if not isinstance(mixture, GaussianMixture):
        raise ValueError(f"expected a GaussianMixture, got {type(mixture).__name__}")
    if mixture.dim > MAX_DIM or mixture.k > MAX_COMPONENTS:
        raise ValueError(f"{mixture.k} components of dimension {mixture.dim} exceed the wire limits")
    iu = np.triu_indices(mixture.dim)
    return {
        "f": "gmm",
        "k": mixture.k,
        "d": mixture.dim,
        "a": _le_bytes(mixture.weights),
        "m": _le_bytes(mixture.means),
        "c": _le_bytes(np.asarray(mixture.covs)[:, iu[0], iu[1]]),
    }


def encode_compressed(particles: ParticleSet, k: int, rng: np.random.Generator) -> dict:
    """At most ``k`` mixture components that keep the set's mean and covariance."""
    return encode_mixture(GaussianMixture.from_particles(particles, k, rng))


def payload_bytes(payload: dict) -> int:
    """Bytes of a payload packed on its own by msgpack (the envelope adds its header to this)."""
    return len(msgpack.packb(payload, use_bin_type=True))


def mixture_bytes(k: int, dim: int) -> int:
    """Bytes of the numbers of a ``k``-component mixture payload: ``8 k (1 + d + d(d+1)/2)``."""
    return 8 * k * (1 + dim + dim * (dim + 1) // 2)


def encode_for_budget(particles: ParticleSet, budget_bytes: int, rng: np.random.Generator) -> dict:
    """The full set if its payload fits in ``budget_bytes``, else the largest mixture that fits (chosen
    here: the byte budget of DESIGN.md §4's sender). Raises ``ValueError`` if not even one component fits."""
    if isinstance(budget_bytes, bool) or not isinstance(budget_bytes, int) or budget_bytes < 1:
        raise ValueError(f"byte budget must be a positive integer, got {budget_bytes!r}")
    full = encode_particles(particles)
    if payload_bytes(full) <= budget_bytes:
        return full
    k = min(particles.n, MAX_COMPONENTS, budget_bytes // mixture_bytes(1, particles.dim))
    while k >= 1:
        payload = encode_compressed(particles, k, rng)
        if payload_bytes(payload) <= budget_bytes:
            return payload
        k -= 1
    raise ValueError(f"a byte budget of {budget_bytes} does not hold even one {particles.dim}-D component")


def encode_candidates(candidates: dict[int, GaussianMixture]) -> dict:
    """A candidate message: every candidate's mixture under its local id."""
    if len(candidates) > MAX_SHARED:
        raise ValueError(f"{len(candidates)} candidates exceed the wire limit of {MAX_SHARED}")
    return {"candidates": [{"id": int(cid), "b": encode_mixture(m)} for cid, m in candidates.items()]}


# -- decoding -------------------------------------------------------------------------------------------
def decode_particle_belief(payload, dim: int | None = None) -> ParticleSet | GaussianMixture:
    """Validate a particle payload of either form; raises only :class:`DecodeError`."""
    try:
        if not isinstance(payload, dict):
            raise DecodeError("bad_type", f"payload must be a map, got {type(payload).__name__}")
        form = payload.get("f")
        if form == "set":
            return decode_particles(payload, dim)
        if form == "gmm":
            return decode_mixture(payload, dim)
        raise DecodeError("bad_field", f"unknown particle payload form {str(form)[:40]!r}")
    except DecodeError:
        raise
    except Exception as exc:  # the agent must never crash on input (DESIGN.md §5)
        raise DecodeError("malformed", f"unexpected {type(exc).__name__} while validating") from None


def decode_particles(payload, dim: int | None = None) -> ParticleSet:
    """Validate a full-set payload (and its dimension ``dim`` if given) and build the set."""
    try:
        n, d = _header(payload, _SET_KEYS, "set", "n", MAX_PARTICLES, dim)
        states = _doubles(payload["x"], n * d, "x").reshape(n, d)
        weights = _doubles(payload["w"], n, "w")
        _weights(weights)
        return ParticleSet(states, weights)
    except DecodeError:
        raise
    except Exception as exc:
        raise DecodeError("malformed", f"unexpected {type(exc).__name__} while validating") from None


def decode_mixture(payload, dim: int | None = None) -> GaussianMixture:
    """Validate a compressed payload (and its dimension ``dim`` if given) and build the mixture."""
    try:
        k, d = _header(payload, _GMM_KEYS, "gmm", "k", MAX_COMPONENTS, dim)
        weights = _doubles(payload["a"], k, "a")
        _weights(weights)
        means = _doubles(payload["m"], k * d, "m").reshape(k, d)
        tri = d * (d + 1) // 2
        upper = _doubles(payload["c"], k * tri, "c").reshape(k, tri)
        covs = np.zeros((k, d, d))
        iu = np.triu_indices(d)
        covs[:, iu[0], iu[1]] = upper
        covs[:, iu[1], iu[0]] = upper
        try:
            np.linalg.cholesky(covs)
        except np.linalg.LinAlgError:
            raise DecodeError("indefinite", "a mixture covariance is not positive definite") from None
        return GaussianMixture(weights, means, covs)
    except DecodeError:
        raise
    except Exception as exc:
        raise DecodeError("malformed", f"unexpected {type(exc).__name__} while validating") from None


def _is_int(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _header(payload, keys: frozenset, form: str, count_key: str, max_count: int, dim: int | None):
    if not isinstance(payload, dict):
        raise DecodeError("bad_type", f"payload must be a map, got {type(payload).__name__}")
    if set(payload) != keys:
        raise DecodeError("bad_field", f"payload fields {sorted(map(str, payload))}, expected {sorted(keys)}")
    if payload["f"] != form:
        raise DecodeError("bad_field", f"payload form {str(payload['f'])[:40]!r}, expected {form!r}")
    count, d = payload[count_key], payload["d"]
    if not (_is_int(count) and _is_int(d)):
        raise DecodeError("bad_type", f"{count_key} and d must be ints")
    if count < 1 or d < 1:
        raise DecodeError("bad_field", f"{count_key}={count} and d={d} must be positive")
    if count > max_count or d > MAX_DIM:
        raise DecodeError("oversize", f"{count_key}={count} (max {max_count}), d={d} (max {MAX_DIM})")
    if dim is not None and d != dim:
        raise DecodeError("bad_shape", f"state dimension {d}, expected {dim}")
    return count, d


def _doubles(raw, count: int, name: str) -> np.ndarray:
    if not isinstance(raw, bytes):
        raise DecodeError("bad_type", f"{name} must be bytes, got {type(raw).__name__}")
    if len(raw) != 8 * count:
        raise DecodeError("bad_shape", f"{name} holds {len(raw)} bytes, expected {8 * count}")
    arr = np.frombuffer(raw, dtype=_F8, count=count).astype(np.float64)  # a native, writable copy
    if not np.all(np.isfinite(arr)):
        raise DecodeError("non_finite", f"NaN or inf in {name}")
    return arr


def _weights(w: np.ndarray) -> None:
    if np.any(w < 0.0):
        raise DecodeError("bad_field", "negative weight")
    total = float(w.sum())
    if not math.isclose(total, 1.0, rel_tol=0.0, abs_tol=WEIGHT_SUM_TOL):
        raise DecodeError("bad_field", f"weights sum to {total!r}, not 1")



def decode_candidates(payload, dim: int) -> dict[int, GaussianMixture]:
    """Validate a candidate message (``dim``-D mixtures, ids unique non-negative ints); only :class:`DecodeError`."""
    if not isinstance(payload, dict) or set(payload) != {"candidates"}:
        raise DecodeError("bad_field", "a candidate message is a map with one field, candidates")
    entries = payload["candidates"]
    if not isinstance(entries, list):
        raise DecodeError("bad_type", f"candidates must be a list, got {type(entries).__name__}")
    if len(entries) > MAX_SHARED:
        raise DecodeError("oversize", f"{len(entries)} candidates (max {MAX_SHARED})")
    out: dict[int, GaussianMixture] = {}
    for entry in entries:
        if not isinstance(entry, dict) or set(entry) != {"id", "b"}:
            raise DecodeError("bad_field", "each candidate needs exactly an id and a belief b")
        cid = entry["id"]
        if not _is_int(cid) or cid < 0:
            raise DecodeError("bad_field", f"candidate id must be a non-negative int, got {str(cid)[:40]!r}")
        if cid in out:
            raise DecodeError("bad_field", f"candidate id {cid} appears twice")
        out[cid] = decode_mixture(entry["b"], dim)
    return out
