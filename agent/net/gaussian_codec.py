"""Gaussian beliefs on the wire: a :class:`~fusion.gaussian.Gaussian` or a :class:`~fusion.trajectory.Trajectory`
in information form as the payload of an :class:`agent.net.wire.Envelope` (``"p"``; kind ``"track"``).

One job: beliefs <-> msgpack-able payloads. Arrays travel as :mod:`agent.net.wire` arrays (float64, the
full information matrix or its band). Decoding validates everything before it builds a belief —
shapes, finite values, an information matrix symmetric to :data:`SYMMETRY_RTOL` and positive
semi-definite — and raises only :class:`agent.net.wire.DecodeError` (reasons ``bad_type``,
``bad_field``, ``bad_shape``, ``non_finite``, ``indefinite``).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from agent.net.wire import DecodeError, is_int
from fusion import validation
from fusion.gaussian import Gaussian
from fusion.trajectory import Trajectory, TrajectoryModel

SYMMETRY_RTOL = 1e-9  # |Y - Y^T| <= SYMMETRY_RTOL * max(1, max|Y|) (chosen here)
OVERFLOW_FREE = 1e307  # |a|, |b| below this: a - b and 0.5 (a + b) are finite (float64 max 1.8e308)


def encode_gaussian(g: Gaussian) -> dict:
    """``{"y": (n,), "Y": (n, n)}`` as float64 (the full matrix: the receiver checks its symmetry)."""
    return {"y": np.asarray(g.y, dtype=np.float64), "Y": np.asarray(g.Y, dtype=np.float64)}


def decode_gaussian(d, dim: int | None = None) -> Gaussian:
    """Validate a Gaussian payload: shapes (and ``dim`` if given), finite, Y symmetric PSD."""
    _expect_keys(d, {"y", "Y"})
    y, Y = _float_array(d["y"], "y"), _float_array(d["Y"], "Y")
    if y.ndim != 1 or y.size == 0 or (dim is not None and y.shape != (dim,)):
        raise DecodeError("bad_shape", f"y has shape {y.shape}, expected ({dim if dim is not None else 'n'},)")
    if Y.shape != (y.size, y.size):
        raise DecodeError("bad_shape", f"Y has shape {Y.shape}, expected {(y.size, y.size)}")
    _finite_scale(y)
    return Gaussian(y, _information_matrix(Y))


def encode_trajectory(t: Trajectory) -> dict:
    """Send only the block-tridiagonal part of a trajectory's information matrix.

    The information matrix of a :class:`~fusion.trajectory.Trajectory` is *exactly* block-tridiagonal
    with ``n x n`` blocks (``n = model.state_dim``): the prior chain puts process factors only on
    consecutive states (Merino (3.27)); a measurement update touches one diagonal block (Merino
    (3.29)-(3.30)); fuse/remove/intersect are linear combinations of such matrices; and the Schur
    complement that marginalises the oldest state (Merino (3.31)-(3.32)) changes only the diagonal
    block of the next state, because the oldest state is coupled to nothing else. Entries outside
    the band are therefore exact zeros (``tests/agent/net/test_gaussian_codec.py`` checks it after random
    sequences of operations), and sending ``diag`` and ``off`` loses nothing. Payload::

        {"epoch": int, "n": n, "L": window, "y": (L*n,), "diag": (L, n, n), "off": (L-1, n, n)}

    where ``off[k]`` is the block at (state k+1, state k), below the diagonal. Raises ``ValueError``
    if the matrix is not block-tridiagonal (a defect upstream: it would be silently truncated)."""
    n, L = t.model.state_dim, t.model.window
    Y = np.ascontiguousarray(t.Y, dtype=np.float64).ravel()
    band, outside = _band_positions(L, n)
    stray = float(np.abs(Y[outside]).max(initial=0.0))
    if stray and stray > 1e-12 * max(1.0, float(np.abs(Y).max())):
        raise ValueError("trajectory information matrix is not block-tridiagonal")
    blocks = Y[band[:(2 * L - 1) * n * n]]  # diag, then off: the layout _band_positions documents
    return {
        "epoch": int(t.epoch),
        "n": n,
        "L": L,
        "y": np.asarray(t.y, dtype=np.float64),
        "diag": blocks[:L * n * n].reshape(L, n, n),
        "off": blocks[L * n * n:].reshape(L - 1, n, n),
    }


def decode_trajectory(d, model: TrajectoryModel) -> Trajectory:
    """Validate a trajectory payload against the fleet's ``model`` and rebuild the dense symmetric
    information matrix (see :func:`encode_trajectory` for why the band is all there is)."""
    _expect_keys(d, {"epoch", "n", "L", "y", "diag", "off"})
    if not all(is_int(d[k]) for k in ("epoch", "n", "L")):
        raise DecodeError("bad_type", "epoch, n and L must be ints")
    n, L = model.state_dim, model.window
    if (d["n"], d["L"]) != (n, L):
        raise DecodeError("bad_shape", f"n={d['n']}, L={d['L']} but the model has n={n}, L={L}")
    y, diag, off = (_float_array(d[k], k) for k in ("y", "diag", "off"))
    if y.shape != (L * n,) or diag.shape != (L, n, n) or off.shape != (L - 1, n, n):
        raise DecodeError("bad_shape", f"y {y.shape}, diag {diag.shape}, off {off.shape} for n={n}, L={L}")
    scale = _finite_scale(y, diag, off)
    diag_t = diag.transpose(0, 2, 1)
    if _asymmetry(diag, diag_t, scale) > SYMMETRY_RTOL * scale:  # only the diagonal blocks can be asymmetric:
        raise DecodeError("indefinite", "information matrix is not symmetric")  # the band is mirrored below
    Y = np.zeros(L * n * L * n)
    Y[_band_positions(L, n)[0]] = np.concatenate((0.5 * (diag + diag_t), off, off.transpose(0, 2, 1)), axis=None)
    Y = Y.reshape(L * n, L * n)
    _require_psd(Y)
    return Trajectory(y, Y, d["epoch"], model)


@functools.cache
def _band_positions(L: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Flat positions in the ``(L n) x (L n)`` matrix of ``L x L`` blocks of ``n x n``: first those of the band —
    the entries of ``diag`` ``(L, n, n)``, then of ``off`` ``(L - 1, n, n)`` (block (k+1, k)), then of ``off``
    transposed (block (k, k+1)), each in C order, so that one integer gather or scatter moves them all — and then
    those outside the band."""
    k, i, j = np.meshgrid(np.arange(L), np.arange(n), np.arange(n), indexing="ij")
    rows = np.concatenate((k * n + i, (k[:-1] + 1) * n + i[:-1], k[:-1] * n + i[:-1]), axis=None)
    cols = np.concatenate((k * n + j, k[:-1] * n + j[:-1], (k[:-1] + 1) * n + j[:-1]), axis=None)
    band = rows * L * n + cols
    return band, np.setdiff1d(np.arange((L * n) ** 2), band)


def _expect_keys(d, keys: set[str]) -> None:
    if not isinstance(d, dict):
        raise DecodeError("bad_type", f"payload must be a map, got {type(d).__name__}")
    if set(d) != keys:
        raise DecodeError("bad_field", f"payload fields {sorted(map(str, d))}, expected {sorted(keys)}")


def _float_array(value, name: str) -> np.ndarray:
    """A float array as float64 (the wire's decoder built it: no copy when it already is)."""
    if not isinstance(value, np.ndarray) or value.dtype.kind != "f":
        raise DecodeError("bad_type", f"{name} must be a float array")
    return value.astype(np.float64, copy=False)


def _finite_scale(*arrays: np.ndarray) -> float:
    """``max(1, max |a|)`` over the arrays, which must hold only finite values: the maximum of the magnitudes is
    NaN when one is NaN and infinite when one is, so one reduction judges both."""
    peak = float(np.abs(np.concatenate(arrays, axis=None)).max(initial=0.0))
    if not math.isfinite(peak):
        raise DecodeError("non_finite", "NaN or inf in a belief")
    return max(1.0, peak)


def _asymmetry(A: np.ndarray, B: np.ndarray, scale: float) -> float:
    """``max |A - B|`` for finite arrays whose entries are at most ``scale`` in magnitude: the difference cannot
    overflow below ``OVERFLOW_FREE``; above it (a hostile message) it is taken with floating-point errors
    silenced (an overflow is ``inf``, an asymmetry)."""
    if scale < OVERFLOW_FREE:
        return float(np.abs(A - B).max())
    with np.errstate(all="ignore"):
        return float(np.abs(A - B).max())


def _information_matrix(Y: np.ndarray) -> np.ndarray:
    """Finite, symmetric to SYMMETRY_RTOL and PSD; returned exactly symmetric."""
    scale = _finite_scale(Y)
    if _asymmetry(Y, Y.T, scale) > SYMMETRY_RTOL * scale:
        raise DecodeError("indefinite", "information matrix is not symmetric")
    Y = 0.5 * (Y + Y.T)
    _require_psd(Y)
    return Y


def _require_psd(Y: np.ndarray) -> None:
    """PSD to ``validation.PSD_RTOL``: one Cholesky factorisation when it is definite
    (:func:`fusion.validation.is_psd`)."""
    try:
        psd = validation.is_psd(Y)
    except np.linalg.LinAlgError:
        psd = False
    if not psd:
        raise DecodeError("indefinite", "information matrix is not positive semi-definite")
