"""Sensor fault detection and isolation by the χ² innovation test.

Lee, Kaminer, Dobrokhodov and Jones (NPS, 2010), spec 003 §2.8, Eqs. 40-44. For an innovation ``ν`` with
covariance ``P^νν = H P H^T + R`` (Eq. 41):

    L{ν} = exp(-½ νᵀ (P^νν)⁻¹ ν)                         (Eq. 40; the printed Eq. 42 drops the ½)
    d² = νᵀ (P^νν)⁻¹ ν                                   (Eq. 43)
    χ² = d² / n_ν                                        (Eq. 44)

and a datum is rejected when ``χ² > χ²_max``. The paper gives no ``χ²_max``; here it is the ``probability``
quantile of the χ² distribution with ``n_ν`` degrees of freedom divided by ``n_ν`` (:func:`chi2_gate`; for
``n_ν = 3`` at 99 %, ``11.34 / 3 = 3.78``), so that a consistent filter rejects a fraction ``1 - probability``
of good data (the false-alarm rate).

Isolation (not in the paper, which only rejects single data): :class:`SensorMonitor` declares a sensor faulty
once ``k`` of its last ``n`` data failed the test (3 of 5, chosen here: a false isolation needs three
1 % events among five data) and excludes it from then on. The isolation time minus the fault onset is the
detection delay.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

from scipy.stats import chi2

from fusion import lapack
from fusion.validation import as_pd, as_vector

#: Default gate probability (chosen here): 1 % of good data rejected.
DEFAULT_GATE_PROBABILITY = 0.99
#: Default isolation rule (chosen here): ``k`` failures among the last ``n`` data.
DEFAULT_K, DEFAULT_N = 3, 5


def chi2_gate(dim: int, probability: float = DEFAULT_GATE_PROBABILITY) -> float:
    """``χ²_max`` of Eq. 44 in its per-dimension form: ``chi2.ppf(probability, dim) / dim``."""
    if isinstance(dim, bool) or int(dim) != dim or dim < 1:
        raise ValueError(f"innovation dimension must be a positive integer, got {dim!r}")
    if not 0.0 < probability < 1.0:
        raise ValueError(f"gate probability must lie in (0, 1), got {probability}")
    return float(chi2.ppf(probability, int(dim))) / int(dim)


@dataclass(frozen=True)
class InnovationTest:
    """One datum's test: ``d²`` (Eq. 43), ``χ² = d²/n_ν`` (Eq. 44) and ``log L = -d²/2`` (Eq. 40)."""

    d2: float
    dim: int

    @property
    def chi2(self) -> float:
        return self.d2 / self.dim  # χ² = d²/n_ν (Eq. 44)

    @property
    def log_likelihood(self) -> float:
        return -0.5 * self.d2  # log L{ν} (Eq. 40)


def innovation_test(innovation, innovation_cov) -> InnovationTest:
    """``d² = νᵀ (P^νν)⁻¹ ν`` (Eq. 43) for an innovation and its (positive-definite) covariance (Eq. 41)."""
    nu = as_vector(innovation, "innovation")
    S = as_pd(innovation_cov, "innovation covariance", nu.shape[0])
    factor = lapack.cholesky(S)
    return InnovationTest(float(nu @ lapack.cholesky_solve(factor, nu)), nu.shape[0])  # d² = νᵀ S⁻¹ ν


class SensorMonitor:
    """The fault state of one sensor: gates its data (Eq. 44) and isolates it after ``k`` of ``n`` failures.

    ``admit(test, t)`` says whether a datum may be used; once isolated, the sensor's data are refused for good
    and ``isolated_at`` holds the time of the datum that tipped it. ``data`` and ``rejections`` count the data
    tested before isolation (their ratio is the measured false-alarm rate on a healthy sensor)."""

    def __init__(
        self,
        name: str,
        dim: int,
        probability: float = DEFAULT_GATE_PROBABILITY,
        k: int = DEFAULT_K,
        n: int = DEFAULT_N,
    ):
        if not (isinstance(k, int) and isinstance(n, int) and 1 <= k <= n):
            raise ValueError(f"isolation rule needs integers 1 <= k <= n, got k={k!r}, n={n!r}")
        self.name = name
        self.dim = int(dim)
        self.threshold = chi2_gate(dim, probability)
        self.k = k
        self._recent: deque[bool] = deque(maxlen=n)
        self.data = 0
        self.rejections = 0
        self.isolated_at: float | None = None

    @property
    def isolated(self) -> bool:
        return self.isolated_at is not None

    @property
    def rejection_rate(self) -> float:
        return self.rejections / self.data if self.data else math.nan

    def admit(self, test: InnovationTest, t: float) -> bool:
        """Record ``test`` (taken at time ``t``) and return whether the datum passes and the sensor is healthy."""
        if test.dim != self.dim:
            raise ValueError(f"sensor {self.name!r} has {self.dim}-D data, got a {test.dim}-D innovation")
        if self.isolated:
            return False
        rejected = not test.chi2 <= self.threshold  # χ² > χ²_max (a NaN is rejected too)
        self.data += 1
        self.rejections += rejected
        self._recent.append(rejected)
        if sum(self._recent) >= self.k:
            self.isolated_at = float(t)
        return not rejected and not self.isolated
