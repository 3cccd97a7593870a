"""Certainty grids: Bernoulli log-odds and Beta evidence grids on flat ground (Merino Ch. 4).

Cells are independent binary events (mean-field, Merino (4.6)); cell ``k`` has centre ``r_k``.

**LogOddsGrid** stores the log-odds *evidence relative to the prior*, ``e_k = l_k - l0``:

* update, Alg. 4.2 / (4.2): ``e_k <- e_k + log p(z|x_k) - log p(z|x̄_k)``;
* probability (4.3): ``bel(x_k) = 1 - 1 / (1 + exp(l_k))``, ``l_k = l0 + e_k``;
* ``fuse`` ``e_a + e_b`` (``l_a + l_b - l0``: (4.4), Alg. 4.3 and DESIGN §2); ``remove`` ``e_a - e_c``
  (Alg. 4.3 line 13);
* ``intersect`` ``w e_a + (1-w) e_b``, i.e. ``l = w l_a + (1-w) l_b``: the normalised weighted exponential
  product ``p_a^w p_b^(1-w) / Z`` of the two Bernoulli cells (Hurley 2002; Julier 2006);
* entropy (4.21) ``h = -p log p - (1-p) log(1-p)``; KL (4.25) summed over cells.

*Clamping.* Merino §4.1.2 bounds cell probabilities away from 0 and 1 but gives no values. Here they are
clamped to ``[1 - clamp, clamp]`` only **when read** (``log_odds``, ``probability``, ``entropy``,
``kl_divergence``); the stored evidence is never clamped, so ``fuse``/``remove`` are exact and a channel
filter reproduces centralized fusion to rounding error. Default ``clamp = 0.999`` (chosen here).

**BetaGrid** (Merino §4.4-4.6) keeps, per cell, ``Beta(alpha0 + a, beta0 + b)`` with evidence counts
``a, b >= 0``: update Alg. 4.4 (4.29)-(4.30) ``a += m``, ``b += n``; ``fuse`` (4.34)-(4.35) ``a_a + a_b``
(= ``alpha_a + alpha_b - alpha0``); ``remove`` (4.36) ``a_a - a_c``; mean and variance (4.28). ``intersect``
with weighted counts is exactly the weighted exponential product of two Betas (an exponential family
with natural parameters ``alpha - 1, beta - 1``).

*The fire probability of a Beta cell.* The Beta is a belief over ``X``, the rate at which looks at the
cell see fire (Merino §4.4): near ``P_D`` on a fire, near ``P_F`` off it — with the camera's pixel blur, a
burning cell's looks are only 0.8-0.9 fire (measured: ``tests/agent/beliefs/test_grid_beta_alarms.py``).
The mean (4.28) estimates ``X``, not whether the cell burns; thresholding it at Merino's 0.8 asks for 80 %
fire looks and misses a burning cell whose looks are 0.75 fire, or one that was seen unburnt before it
ignited. Given a ``boundary`` ``x*``, ``probability`` is instead ``P(X > x* | alpha, beta) = 1 -
I_{x*}(alpha, beta)`` (the regularised incomplete Beta function): the posterior mass on the fire side of
``x*`` (without one, the mean). :func:`detection_boundary` gives the ``x*`` at which one look of a
detector ``(P_D, P_F)`` is equally likely under both hypotheses (chosen here).

The intersection rules for loops are in :mod:`fusion.grid_intersect`, the geometry in
:mod:`fusion.grid_geometry`.

Every rule is a per-cell convex combination (or the max) of the inputs, so where all evidence of a cell
has one sign no node can become more confident than the centralized grid. Grids are immutable. Without
``forgetting`` they are static: ``epoch`` is ``None`` and ``advanced_to`` returns the grid itself. With a
:class:`~fusion.grid_forgetting.Forgetting` a grid lives at a tick (``epoch``) of a common clock and
``advanced_to`` multiplies its evidence by the forgetting factor — linear, so fusion stays exact; grids are
combined only at one tick (the channel filter advances both first), and ``kl_divergence`` advances the
older one itself.
"""

from __future__ import annotations

import numpy as np
from scipy.special import betaincc, betaln, digamma, expit, log_expit, logit

from fusion.grid_forgetting import Forgetting
from fusion.grid_geometry import GridGeometry, GridGeometryError, real_number

#: Default read-time probability clamp: cells read within [1 - clamp, clamp] (chosen here).
DEFAULT_CLAMP = 0.999
#: Tolerance below zero that Beta ``remove`` rounds to zero rather than rejecting (chosen here) ...
REMOVE_TOLERANCE = 1e-9
#: ... plus this fraction of the count removed: counts travel as float32 (relative rounding 6e-8 per
#: message), and with forgetting every message re-rounds every count (chosen here: a few roundings' worth).
REMOVE_RELATIVE = 1e-6


# -- shared checks -----------------------------------------------------------------------------------
def _field(value, name: str, shape: tuple[int, int]) -> np.ndarray:
    """A finite float64 array of ``shape``, copied and made read-only."""
    return _frozen(np.array(_operand(value, name, shape)), name)


def _frozen(arr: np.ndarray, name: str) -> np.ndarray:
    # one reduction without a temporary: a NaN or inf anywhere makes the sum non-finite (a sum that
    # overflows although every value is finite is told apart by the exact, slower check)
    with np.errstate(over="ignore"):
        suspicious = not np.isfinite(arr.sum())
    if suspicious and not np.isfinite(arr).all():
        raise ValueError(f"{name} contains non-finite values (NaN or inf) in {int((~np.isfinite(arr)).sum())} cells")
    arr.setflags(write=False)
    return arr


def _operand(value, name: str, shape: tuple[int, int]) -> np.ndarray:
    """A float64 view (no copy when it already is one) of an update operand of ``shape``; its finiteness is
    checked on the result, which is non-finite whenever the operand is."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be numeric, got {type(value).__name__}") from None
    if arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape} (the grid's), got {arr.shape}")
    return arr


def _non_negative(arr: np.ndarray, name: str) -> np.ndarray:
    if arr.size and arr.min() < 0.0:  # NaN never compares below zero: the finiteness check catches it
        raise ValueError(f"{name} has {int((arr < 0.0).sum())} negative cell counts (evidence counts must be >= 0)")
    return arr


def _cells(index, values: list, names: list[str], size: int) -> tuple[np.ndarray, list[np.ndarray]]:
    """Flat row-major cell indices and equally long finite value vectors for a sparse update."""
    idx = np.asarray(index)
    if idx.ndim != 1 or not (np.issubdtype(idx.dtype, np.integer) or idx.size == 0) or idx.dtype == bool:
        raise ValueError(f"cell index must be a 1-D integer array of flat indices, got {idx.dtype} {idx.shape}")
    idx = idx.astype(np.intp)
    if idx.size and (idx.min() < 0 or idx.max() >= size):
        raise ValueError(f"cell index out of range [0, {size}): min {idx.min()}, max {idx.max()}")
    out = []
    for value, name in zip(values, names, strict=True):
        arr = np.asarray(value, dtype=np.float64)
        if arr.shape != idx.shape:
            raise ValueError(f"{name} must have one value per index ({idx.size}), got shape {arr.shape}")
        if not np.isfinite(arr).all():
            raise ValueError(f"{name} contains non-finite values (NaN or inf)")
        out.append(arr)
    return idx, out


def _omega(omega, shape: tuple[int, int]) -> np.ndarray | float:
    if np.ndim(omega) == 0:
        w = real_number(omega if not isinstance(omega, np.ndarray) else float(omega), "omega")
        if not 0.0 <= w <= 1.0:
            raise ValueError(f"omega must lie in [0, 1], got {w}")
        return w
    w = _field(omega, "omega", shape)
    if w.min() < 0.0 or w.max() > 1.0:
        raise ValueError(f"omega must lie in [0, 1] in every cell, got range [{w.min()}, {w.max()}]")
    return w


def _unit(value, name: str) -> float:
    value = real_number(value, name)
    if not 0.0 <= value <= 1.0:
        raise ValueError(f"{name} must lie in [0, 1], got {value}")
    return value


def _open_unit(value, name: str) -> float:
    value = real_number(value, name)
    if not 0.0 < value < 1.0:
        raise ValueError(f"{name} must lie in (0, 1), got {value}")
    return value


def detection_boundary(pd: float, pf: float) -> float:
    """The look rate ``x*`` at which a detector ``(P_D, P_F)`` is no evidence either way: one look with
    detection probability ``x*`` has expected log-likelihood ratio zero (Alg. 4.2),
    ``x* log(P_D / P_F) + (1 - x*) log((1 - P_D) / (1 - P_F)) = 0``, so
    ``x* = log((1 - P_F) / (1 - P_D)) / [log(P_D / P_F) + log((1 - P_F) / (1 - P_D))]``."""
    pd, pf = _open_unit(pd, "pd"), _open_unit(pf, "pf")
    if pd <= pf:
        raise ValueError(f"pd must exceed pf (an informative detector), got pd={pd}, pf={pf}")
    against = np.log((1.0 - pf) / (1.0 - pd))
    return float(against / (np.log(pd / pf) + against))


def _bernoulli_kl(l_p: np.ndarray, l_q: np.ndarray) -> np.ndarray:
    """Per-cell (4.25) between Bernoullis given by their log-odds, stable for any finite log-odds."""
    p = expit(l_p)
    return p * (log_expit(l_p) - log_expit(l_q)) + (1.0 - p) * (log_expit(-l_p) - log_expit(-l_q))


def beta_entropy(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Differential entropy of ``Beta(a, b)`` per cell (nats): ``ln B(a, b) - (a-1) ψ(a) - (b-1) ψ(b)
    + (a+b-2) ψ(a+b)`` (the thesis leaves the formula out, Merino §4.3.1 / §4.7). No checks: the caller
    gives positive counts."""
    return betaln(a, b) - (a - 1.0) * digamma(a) - (b - 1.0) * digamma(b) + (a + b - 2.0) * digamma(a + b)


def _clock(forgetting, epoch) -> int | None:
    """The epoch of a new grid: ``None`` for a static grid, else a non-negative tick (0 by default)."""
    if forgetting is None:
        if epoch is not None:
            raise ValueError(f"a static grid (no forgetting) has no epoch, got {epoch!r}")
        return None
    if not isinstance(forgetting, Forgetting):
        raise ValueError(f"forgetting must be a Forgetting, got {type(forgetting).__name__}")
    epoch = 0 if epoch is None else epoch
    if isinstance(epoch, bool) or not isinstance(epoch, int | np.integer) or epoch < 0:
        raise ValueError(f"grid epoch must be a non-negative integer tick, got {epoch!r}")
    return int(epoch)


class _Grid:
    """What both grid types share: geometry checks and the time protocol (static, or forgetting)."""

    def _check(self, other) -> None:
        if type(other) is not type(self):
            raise ValueError(f"expected a {type(self).__name__}, got {type(other).__name__}")
        self.geometry.check_same(other.geometry)
        for name in (*self._prior_fields, "forgetting", "epoch"):
            if getattr(self, name) != getattr(other, name):
                raise ValueError(f"{name} mismatch: {getattr(self, name)} vs {getattr(other, name)}")

    def advanced_to(self, epoch):
        """The grid at tick ``epoch``: its evidence times ``forgetting.factor(epoch - self.epoch)``
        (:mod:`fusion.grid_forgetting`). A static grid is the same at every epoch."""
        if self.forgetting is None or epoch is None or epoch == self.epoch:
            return self
        if isinstance(epoch, bool) or not isinstance(epoch, int | np.integer) or epoch < self.epoch:
            raise ValueError(f"a grid at tick {self.epoch} cannot be advanced to {epoch!r} (only forward)")
        out = self.scaled(self.forgetting.factor(int(epoch - self.epoch)))
        out.epoch = int(epoch)
        return out

    def _at_newest(self, other):
        """Both grids advanced to the newer of their ticks (for reading: combining requires one tick)."""
        if self.epoch is None or other.epoch is None:
            return self, other
        epoch = max(self.epoch, other.epoch)
        return self.advanced_to(epoch), other.advanced_to(epoch)

    def _probability_range(self) -> tuple[float, float]:
        p = self.probability()
        return float(p.min()), float(p.max())


class LogOddsGrid(_Grid):
    """Bernoulli certainty grid stored as log-odds *evidence* relative to the prior: ``e = l - l0``.
    ``fuse`` is ``e_a + e_b`` and ``remove`` ``e_a - e_c``, i.e. ``l_a + l_b - l0`` as in DESIGN §2 and
    Merino (4.4), Alg. 4.3."""

    __slots__ = ("geometry", "evidence", "prior", "clamp", "_l0", "_lmax", "forgetting", "epoch")
    _prior_fields = ("prior",)

    def __init__(self, geometry: GridGeometry, evidence: np.ndarray | None = None, prior: float = 0.5,
                 clamp: float = DEFAULT_CLAMP, forgetting: Forgetting | None = None, epoch: int | None = None):
        if not isinstance(geometry, GridGeometry):
            raise GridGeometryError(f"geometry must be a GridGeometry, got {type(geometry).__name__}")
        prior, clamp = real_number(prior, "prior"), real_number(clamp, "clamp")
        if not 0.0 < prior < 1.0:
            raise ValueError(f"prior must lie in (0, 1), got {prior}")
        if not 0.5 < clamp < 1.0:
            raise ValueError(f"clamp must lie in (0.5, 1), got {clamp}")
        if not 1.0 - clamp <= prior <= clamp:
            raise ValueError(f"prior {prior} lies outside the clamp range [{1.0 - clamp}, {clamp}]")
        self.geometry, self.prior, self.clamp = geometry, prior, clamp
        self.forgetting, self.epoch = forgetting, _clock(forgetting, epoch)
        self._l0, self._lmax = float(logit(prior)), float(logit(clamp))
        self.evidence = _field(np.zeros(geometry.shape) if evidence is None else evidence, "evidence", geometry.shape)

    @classmethod
    def uniform(cls, geometry: GridGeometry, prior: float = 0.5, clamp: float = DEFAULT_CLAMP,
                forgetting: Forgetting | None = None, epoch: int | None = None) -> LogOddsGrid:
        """Every cell at the prior (Merino Alg. 4.3, line 1)."""
        return cls(geometry, None, prior, clamp, forgetting, epoch)

    def _like(self, evidence: np.ndarray, operand: str = "the operand") -> LogOddsGrid:
        """A grid with ``evidence`` (the result of an operation on ``operand``, named in errors)."""
        new = object.__new__(LogOddsGrid)
        new.geometry, new.prior, new.clamp, new._l0, new._lmax, new.forgetting, new.epoch = (
            self.geometry, self.prior, self.clamp, self._l0, self._lmax, self.forgetting, self.epoch)
        new.evidence = _frozen(evidence, f"evidence after adding {operand}")
        return new

    # -- reading --------------------------------------------------------------------------------------
    def log_odds(self) -> np.ndarray:
        """``l = l0 + e``, clamped to ``±logit(clamp)``."""
        return np.clip(self._l0 + self.evidence, -self._lmax, self._lmax)

    def probability(self) -> np.ndarray:
        """(4.3) ``bel = 1 - 1/(1 + exp(l))``, within ``[1 - clamp, clamp]``."""
        return expit(self.log_odds())

    def entropy(self) -> np.ndarray:
        """(4.21) per cell, nats."""
        l = self.log_odds()
        p = expit(l)
        return -(p * log_expit(l) + (1.0 - p) * log_expit(-l))

    def kl_divergence(self, other: LogOddsGrid) -> float:
        """(4.25) ``D(self || other)`` summed over cells (clamped probabilities), at the newer tick."""
        a, b = self._at_newest(other)
        a._check(b)
        return float(_bernoulli_kl(a.log_odds(), b.log_odds()).sum())

    def allclose(self, other: LogOddsGrid, atol: float = 1e-9) -> bool:
        self._check(other)
        return bool(np.allclose(self.evidence, other.evidence, rtol=0.0, atol=atol))

    # -- updates and the algebra ------------------------------------------------------------------------
    def update(self, llr: np.ndarray) -> LogOddsGrid:
        """Alg. 4.2: ``e + log p(z|x) - log p(z|x̄)`` for every cell."""
        llr = _operand(llr, "llr", self.geometry.shape)
        return self._like(self.evidence + llr, "llr")

    def update_cells(self, index: np.ndarray, llr: np.ndarray) -> LogOddsGrid:
        """Alg. 4.2 on some cells: flat row-major ``index``; repeated indices accumulate."""
        idx, (values,) = _cells(index, [llr], ["llr"], self.geometry.size)
        evidence = self.evidence.ravel().copy()
        np.add.at(evidence, idx, values)
        return self._like(evidence.reshape(self.geometry.shape))

    def fuse(self, other: LogOddsGrid) -> LogOddsGrid:
        self._check(other)
        return self._like(self.evidence + other.evidence)

    def remove(self, common: LogOddsGrid) -> LogOddsGrid:
        self._check(common)
        return self._like(self.evidence - common.evidence)

    def intersect(self, other: LogOddsGrid, omega: float | np.ndarray) -> LogOddsGrid:
        """Weighted log-odds ``omega e_a + (1 - omega) e_b``; ``omega`` scalar or per cell, in [0, 1]."""
        self._check(other)
        w = _omega(omega, self.geometry.shape)
        return self._like(w * self.evidence + (1.0 - w) * other.evidence)

    def scaled(self, w: float) -> LogOddsGrid:
        """``w e`` (the belief to the power ``w``), ``w >= 0``."""
        w = real_number(w, "scale weight")
        if w < 0.0:
            raise ValueError(f"scale weight must be non-negative, got {w}")
        return self._like(w * self.evidence)

    def decayed(self, factor: float) -> LogOddsGrid:
        """Forgetting, ``factor * e`` with ``factor`` in [0, 1]: linear, so it commutes with fuse/remove."""
        return self._like(_unit(factor, "decay factor") * self.evidence)

    def __repr__(self) -> str:
        lo, hi = self._probability_range()
        return f"LogOddsGrid(shape={self.geometry.shape}, prior={self.prior}, p in [{lo:.3g}, {hi:.3g}])"


class BetaGrid(_Grid):
    """Beta evidence grid (Merino §4.4-4.6): per cell ``B(alpha0 + a, beta0 + b)``, with evidence counts
    ``a, b >= 0`` (the ``alpha``/``beta`` attributes) and prior ``alpha0, beta0 > 0``."""

    __slots__ = ("geometry", "alpha", "beta", "alpha0", "beta0", "forgetting", "epoch", "boundary")
    _prior_fields = ("alpha0", "beta0")

    def __init__(self, geometry: GridGeometry, alpha: np.ndarray | None = None, beta: np.ndarray | None = None,
                 alpha0: float = 1.0, beta0: float = 1.0, forgetting: Forgetting | None = None,
                 epoch: int | None = None, boundary: float | None = None):
        if not isinstance(geometry, GridGeometry):
            raise GridGeometryError(f"geometry must be a GridGeometry, got {type(geometry).__name__}")
        alpha0, beta0 = real_number(alpha0, "alpha0"), real_number(beta0, "beta0")
        if alpha0 <= 0.0 or beta0 <= 0.0:
            raise ValueError(f"the Beta prior must be positive, got alpha0={alpha0}, beta0={beta0}")
        self.geometry, self.alpha0, self.beta0 = geometry, alpha0, beta0
        self.forgetting, self.epoch = forgetting, _clock(forgetting, epoch)
        self.boundary = None if boundary is None else _open_unit(boundary, "boundary")
        zeros = np.zeros(geometry.shape)
        self.alpha = _non_negative(_field(zeros if alpha is None else alpha, "alpha", geometry.shape), "alpha")
        self.beta = _non_negative(_field(zeros if beta is None else beta, "beta", geometry.shape), "beta")

    @classmethod
    def uniform(cls, geometry: GridGeometry, alpha0: float = 1.0, beta0: float = 1.0,
                forgetting: Forgetting | None = None, epoch: int | None = None,
                boundary: float | None = None) -> BetaGrid:
        """No evidence yet; ``alpha0 = beta0 = 1`` is Merino's uninformed prior (Alg. 4.5, line 1)."""
        return cls(geometry, None, None, alpha0, beta0, forgetting, epoch, boundary)

    def _like(self, alpha: np.ndarray, beta: np.ndarray, operand: str = "the operand") -> BetaGrid:
        """A grid with these counts (the result of an operation on ``operand``, named in errors)."""
        new = object.__new__(BetaGrid)
        new.geometry, new.alpha0, new.beta0 = self.geometry, self.alpha0, self.beta0
        new.forgetting, new.epoch, new.boundary = self.forgetting, self.epoch, self.boundary
        new.alpha = _frozen(alpha, f"alpha after adding {operand}")
        new.beta = _frozen(beta, f"beta after adding {operand}")
        return new

    def shape_parameters(self) -> tuple[np.ndarray, np.ndarray]:
        """The Beta parameters ``(alpha0 + a, beta0 + b)`` per cell."""
        return self.alpha0 + self.alpha, self.beta0 + self.beta

    # -- reading --------------------------------------------------------------------------------------
    def mean(self) -> np.ndarray:
        """(4.28) ``alpha / (alpha + beta)``."""
        a, b = self.shape_parameters()
        return a / (a + b)

    def variance(self) -> np.ndarray:
        """(4.28) ``alpha beta / ((alpha + beta)^2 (alpha + beta + 1))``."""
        a, b = self.shape_parameters()
        return a * b / ((a + b) ** 2 * (a + b + 1.0))

    def probability(self) -> np.ndarray:
        """The cell's fire probability: ``P(X > boundary) = 1 - I_boundary(alpha, beta)`` (module docstring),
        or the mean (4.28) without a boundary."""
        if self.boundary is None:
            return self.mean()
        return betaincc(*self.shape_parameters(), self.boundary)

    def entropy(self) -> np.ndarray:
        """Differential entropy of each cell's Beta (nats): ``ln B(a, b) - (a-1) digamma(a) - (b-1) digamma(b)
        + (a+b-2) digamma(a+b)`` (the thesis leaves the formula out, §4.3.1)."""
        return beta_entropy(*self.shape_parameters())

    def kl_divergence(self, other: BetaGrid) -> float:
        """(4.25) between the mean cell probabilities, summed over cells: ``D(self || other)``, at the newer
        tick."""
        mine, theirs = self._at_newest(other)
        mine._check(theirs)
        (a, b), (c, d) = mine.shape_parameters(), theirs.shape_parameters()
        return float(_bernoulli_kl(np.log(a) - np.log(b), np.log(c) - np.log(d)).sum())

    def allclose(self, other: BetaGrid, atol: float = 1e-9) -> bool:
        self._check(other)
        return bool(np.allclose(self.alpha, other.alpha, rtol=0.0, atol=atol)
                    and np.allclose(self.beta, other.beta, rtol=0.0, atol=atol))

    # -- updates and the algebra ------------------------------------------------------------------------
    def update(self, m: np.ndarray, n: np.ndarray) -> BetaGrid:
        """Alg. 4.4 (4.29)-(4.30): ``a += m`` detections, ``b += n`` non-detections (fractional allowed)."""
        shape = self.geometry.shape
        m, n = _non_negative(_operand(m, "m", shape), "m"), _non_negative(_operand(n, "n", shape), "n")
        return self._like(self.alpha + m, self.beta + n, "m or n")

    def update_cells(self, index: np.ndarray, m: np.ndarray, n: np.ndarray) -> BetaGrid:
        """Alg. 4.4 on some cells: flat row-major ``index``; repeated indices accumulate."""
        idx, (m, n) = _cells(index, [m, n], ["m", "n"], self.geometry.size)
        _non_negative(m, "m"), _non_negative(n, "n")
        alpha, beta = self.alpha.ravel().copy(), self.beta.ravel().copy()
        np.add.at(alpha, idx, m)
        np.add.at(beta, idx, n)
        return self._like(alpha.reshape(self.geometry.shape), beta.reshape(self.geometry.shape))

    def fuse(self, other: BetaGrid) -> BetaGrid:
        """(4.34)-(4.35): ``B(alpha_a + alpha_b - alpha0, beta_a + beta_b - beta0)``."""
        self._check(other)
        return self._like(self.alpha + other.alpha, self.beta + other.beta)

    def remove(self, common: BetaGrid) -> BetaGrid:
        """(4.36): subtract the common counts. Raises ``ValueError`` if a count would fall below
        ``-(REMOVE_TOLERANCE + REMOVE_RELATIVE * common)`` (``common`` holds evidence this grid does not);
        tinier negatives (rounding) become 0."""
        self._check(common)
        out = []
        for name, mine, theirs in (("alpha", self.alpha, common.alpha), ("beta", self.beta, common.beta)):
            diff = mine - theirs
            bad = int((diff < -(REMOVE_TOLERANCE + REMOVE_RELATIVE * theirs)).sum())
            if bad:
                raise ValueError(f"removing more {name} evidence than the grid holds in {bad} cells")
            out.append(np.maximum(diff, 0.0))
        return self._like(*out)

    def intersect(self, other: BetaGrid, omega: float | np.ndarray) -> BetaGrid:
        """Weighted counts ``omega a_a + (1 - omega) a_b`` (the weighted exponential product of the Betas)."""
        self._check(other)
        w = _omega(omega, self.geometry.shape)
        return self._like(w * self.alpha + (1.0 - w) * other.alpha, w * self.beta + (1.0 - w) * other.beta)

    def scaled(self, w: float) -> BetaGrid:
        w = real_number(w, "scale weight")
        if w < 0.0:
            raise ValueError(f"scale weight must be non-negative, got {w}")
        return self._like(w * self.alpha, w * self.beta)

    def decayed(self, factor: float) -> BetaGrid:
        """Forgetting: counts times ``factor`` in [0, 1]; linear, so it commutes with fuse/remove."""
        factor = _unit(factor, "decay factor")
        return self._like(factor * self.alpha, factor * self.beta)

    def __repr__(self) -> str:
        lo, hi = self._probability_range()
        prior = f"({self.alpha0}, {self.beta0})"
        return f"BetaGrid(shape={self.geometry.shape}, prior={prior}, mean in [{lo:.3g}, {hi:.3g}])"
