"""The implementations timed by ``skymesh bench fusion-ops`` (see :mod:`mesh_sim.bench.fusion_ops`).

Each factory builds one implementation of one operation on a :class:`Scenario` and returns a
:class:`Candidate`: ``step()`` performs the operation once, chaining its own state as a filter would
(so no library can serve a cached result), and ``state()`` returns the current mean and covariance in
skymesh state order for the agreement check.

The *bare-numpy bound* of each operation is the same arithmetic written inline on plain arrays: no
objects, no dispatch, no argument validation. It keeps the numerical tests that decide the result
(the positive-semi-definiteness checks of ``remove`` in the channel filter, the positive-definiteness
test of fast CI; the ``checks=False`` variants drop them, for information) and, for CI, the same
weight computation on plain arrays (:func:`fusion.pair_weights.ci_weight`), so that skymesh / bound
measures the overhead of the skymesh layer, not a different algorithm.

The two-input CI weight itself is timed against :func:`brent_weight_baseline`, a compact copy of the bounded
Brent search (``scipy.optimize.minimize_scalar``) that ``fusion.covariance_intersection.optimal_weights``
used before issue 12: kept here only as that baseline.

Other libraries are optional: :func:`filterpy` and :func:`stonesoup` return ``None`` when missing.
"""

from __future__ import annotations

import datetime
import importlib
import itertools
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
import scipy.optimize

from fusion import information_filter
from fusion.batch import GaussianBatch
from fusion.channel_filter import ChannelFilter
from fusion.covariance_intersection import ci, fast_ci, optimal_weights
from fusion.gaussian import Gaussian
from fusion.measurement import Bearing2D, Bearing3D, PositionMeasurement, wrap_angle
from fusion.motion import ConstantVelocity
from fusion.pair_weights import ci_weight

TRACKS = 100
DT = 0.2  # chosen here: one step of the default 5 Hz agent loop (DESIGN.md §4)
Q_CV = 0.1  # the ConstantVelocity default spectral density
POSITION_SIGMA = 1.0  # m, chosen here
BEARING_SIGMA = 0.01  # rad, chosen here (about 0.6 degrees)
CHECK_STEPS = 3  # steps run by every implementation before the agreement check
SEED = 20240607
_PSD_RTOL = 1e-9  # as fusion.validation.PSD_RTOL
_T0 = datetime.datetime(2024, 1, 1)
_DT = datetime.timedelta(seconds=DT)

@dataclass
class Candidate:
    """One implementation of one operation: ``step()`` performs it once (chaining its own state),
    ``state()`` returns the current ``(mean, cov)`` in skymesh state order, for the agreement check."""

    step: Callable[[], object]
    state: Callable[[], tuple[np.ndarray, np.ndarray]]


# ==================================================================================================
# scenarios
# ==================================================================================================
@dataclass
class Scenario:
    n: int
    d: int
    model: ConstantVelocity
    F: np.ndarray
    Q: np.ndarray
    F_inv: np.ndarray
    position: PositionMeasurement
    bearing: Bearing2D | Bearing3D
    sensor: np.ndarray
    priors: list[Gaussian]  # TRACKS priors; priors[0] is the single-operation prior
    others: list[Gaussian]  # a second belief per track (CI inputs)
    z: np.ndarray  # (TRACKS, d) position measurements
    z_bearing: np.ndarray  # (TRACKS, m) bearing measurements


def make_scenario(n: int, rng: np.random.Generator) -> Scenario:
    d = n // 2
    model = ConstantVelocity(spatial_dims=d, q=Q_CV)
    sensor = np.array([0.0, 0.0, -50.0])[:d]  # a UAV 50 m up (NED) looking at targets on the ground
    if d == 3:
        bearing = Bearing3D(n, sensor, np.eye(2) * BEARING_SIGMA**2)
    else:
        bearing = Bearing2D(n, sensor, BEARING_SIGMA)
    truths, priors, others = [], [], []
    for _ in range(TRACKS):
        truth = np.concatenate([np.array([40.0, 25.0, 0.0])[:d] + rng.normal(0.0, 10.0, d), rng.normal(0.0, 1.0, d)])
        truths.append(truth)
        for out in (priors, others):
            A = rng.normal(0.0, 0.5, (n, n))
            cov = np.diag([9.0] * d + [1.0] * d) + A @ A.T
            out.append(Gaussian.from_moments(truth + rng.multivariate_normal(np.zeros(n), cov), cov))
    truths = np.array(truths)
    z = truths[:, :d] + rng.normal(0.0, POSITION_SIGMA, (TRACKS, d))
    z_bearing = np.array([bearing.h(t) for t in truths]) + rng.normal(0.0, BEARING_SIGMA, (TRACKS, bearing.dim))
    return Scenario(
        n, d, model, model.transition(DT), model.noise(DT), model.inverse_transition(DT),
        PositionMeasurement(n, np.eye(d) * POSITION_SIGMA**2, spatial_dims=d), bearing, sensor,
        priors, others, z, z_bearing,
    )


def _moments(y: np.ndarray, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return np.linalg.solve(Y, y), np.linalg.inv(Y)


def _box_state(box: list) -> Callable[[], tuple[np.ndarray, np.ndarray]]:
    return lambda: (box[0].mean, box[0].cov)


# ==================================================================================================
# single operations: skymesh and the bare-numpy bound
# ==================================================================================================
def sky_if(sc: Scenario) -> Candidate:
    box, F, Q, F_inv, H, R_inv, z = [sc.priors[0]], sc.F, sc.Q, sc.F_inv, sc.position.H, sc.position.R_inv, sc.z[0]

    def step():
        box[0] = box[0].predict(F, Q, F_inv).update(H, R_inv, z)

    return Candidate(step, _box_state(box))


def sky_if_api(sc: Scenario) -> Candidate:
    box, model, position, z = [sc.priors[0]], sc.model, sc.position, sc.z[0]

    def step():
        box[0] = information_filter.update(information_filter.predict(box[0], model, DT), position, z)

    return Candidate(step, _box_state(box))


def numpy_if(sc: Scenario) -> Candidate:
    st = [sc.priors[0].y.copy(), sc.priors[0].Y.copy()]
    F_inv, F_inv_T, Q, I = sc.F_inv, sc.F_inv.T, sc.Q, np.eye(sc.n)
    H, R_inv, z = sc.position.H, sc.position.R_inv, sc.z[0]

    def step():
        y, Y = st
        psi = F_inv_T @ Y @ F_inv
        sol = np.linalg.solve(I + psi @ Q, np.concatenate([psi, (F_inv_T @ y)[:, None]], axis=1))
        Yp = sol[:, :-1]
        HtRi = H.T @ R_inv
        st[0] = sol[:, -1] + HtRi @ z
        st[1] = 0.5 * (Yp + Yp.T) + HtRi @ H

    return Candidate(step, lambda: _moments(*st))


def sky_bearing(sc: Scenario) -> Candidate:
    box, model, z = [sc.priors[0]], sc.bearing, sc.z_bearing[0]

    def step():
        box[0] = information_filter.eif_update(box[0], model, z)

    return Candidate(step, _box_state(box))


def _bearing_functions(sc: Scenario):
    """Lean ``h(x)`` and Jacobian of the scenario's bearing model (NED conventions of fusion.measurement)."""
    n, s = sc.n, sc.sensor
    if sc.d == 3:
        sx, sy, sz = s.tolist()

        def h_and_H(x):
            dx, dy, dz = x[0] - sx, x[1] - sy, x[2] - sz
            rho2 = dx * dx + dy * dy
            rho = np.sqrt(rho2)
            r2 = rho2 + dz * dz
            H = np.zeros((2, n))
            H[0, 0], H[0, 1] = -dy / rho2, dx / rho2
            H[1, 0], H[1, 1], H[1, 2] = dz * dx / (rho * r2), dz * dy / (rho * r2), -rho / r2
            return np.array([np.arctan2(dy, dx), np.arctan2(-dz, rho)]), H
    else:
        sx, sy = s.tolist()

        def h_and_H(x):
            dx, dy = x[0] - sx, x[1] - sy
            rho2 = dx * dx + dy * dy
            H = np.zeros((1, n))
            H[0, 0], H[0, 1] = -dy / rho2, dx / rho2
            return np.array([np.arctan2(dy, dx)]), H

    return h_and_H


def numpy_bearing(sc: Scenario) -> Candidate:
    st = [sc.priors[0].y.copy(), sc.priors[0].Y.copy()]
    h_and_H, R_inv, z = _bearing_functions(sc), sc.bearing.R_inv, sc.z_bearing[0]

    def step():
        y, Y = st
        mu = np.linalg.solve(Y, y)
        h, H = h_and_H(mu)
        r = z - h
        r[0] = (r[0] + np.pi) % (2.0 * np.pi) - np.pi
        HtRi = H.T @ R_inv
        st[0] = y + HtRi @ (r + H @ mu)
        st[1] = Y + HtRi @ H

    return Candidate(step, lambda: _moments(*st))


def sky_ci(sc: Scenario) -> Candidate:
    a, b, box = sc.priors[0], sc.others[0], [None]

    def step():
        box[0] = ci([a, b], "det")

    return Candidate(step, _box_state(box))


def numpy_ci(sc: Scenario) -> Candidate:
    ya, Ya, yb, Yb, box = sc.priors[0].y, sc.priors[0].Y, sc.others[0].y, sc.others[0].Y, [None]

    def step():
        w = ci_weight(Ya, Yb, "det")
        box[0] = (w * ya + (1.0 - w) * yb, w * Ya + (1.0 - w) * Yb)

    return Candidate(step, lambda: _moments(*box[0]))


def _weight_candidate(sc: Scenario, weight: Callable[[np.ndarray, np.ndarray], float]) -> Candidate:
    """The two-input CI weight of each track's pair ``(priors[i].Y, others[i].Y)`` in turn (so that the figure is
    a mean over 100 pairs, interior optima and end points alike); ``state()`` is ``([w], M(w)^-1)`` of the last."""
    pairs, box = [(a.Y, b.Y) for a, b in zip(sc.priors, sc.others, strict=True)], [0, None]

    def step():
        i = box[0]
        box[0], box[1] = (i + 1) % len(pairs), (weight(*pairs[i]), pairs[i])

    def state():
        w, (Ya, Yb) = box[1]
        return np.array([w]), np.linalg.inv(w * Ya + (1.0 - w) * Yb)

    return Candidate(step, state)


def sky_ci_weight(sc: Scenario, objective: str) -> Candidate:
    return _weight_candidate(sc, lambda Ya, Yb: float(optimal_weights([Ya, Yb], objective)[0]))


def brent_ci_weight(sc: Scenario, objective: str) -> Candidate:
    return _weight_candidate(sc, lambda Ya, Yb: brent_weight_baseline(Ya, Yb, objective))


def brent_weight_baseline(Ya: np.ndarray, Yb: np.ndarray, objective: str) -> float:
    """BASELINE ONLY — not used by skymesh: the two-input weight as ``optimal_weights`` computed it before issue 12,
    SciPy's bounded Brent search on ``f(w)`` (``-log det M(w)`` or ``tr M(w)^-1``, 1e300 where ``M(w)`` is
    singular) with ``xatol = 1e-6``, then the better of its result and the two end points (which it never
    evaluates)."""

    def cost(w: float) -> float:
        M = w * Ya + (1.0 - w) * Yb
        if objective == "det":
            sign, logdet = np.linalg.slogdet(M)
            return -float(logdet) if sign > 0 else 1e300
        try:
            inv = np.linalg.inv(M)
            np.linalg.cholesky(M)
        except np.linalg.LinAlgError:
            return 1e300
        return float(np.trace(inv))

    res = scipy.optimize.minimize_scalar(cost, bounds=(0.0, 1.0), method="bounded", options={"xatol": 1e-6})
    return min((cost(float(res.x)), float(res.x)), (cost(1.0), 1.0), (cost(0.0), 0.0))[1]


def sky_fast_ci(sc: Scenario) -> Candidate:
    a, b, box = sc.priors[0], sc.others[0], [None]

    def step():
        box[0] = fast_ci([a, b])

    return Candidate(step, _box_state(box))


def numpy_fast_ci(sc: Scenario, checks: bool = True) -> Candidate:
    ya, Ya, yb, Yb, box = sc.priors[0].y, sc.priors[0].Y, sc.others[0].y, sc.others[0].Y, [None]

    def step():
        if checks:  # positive definite, else the weight would be 0
            np.linalg.cholesky(Ya)
            np.linalg.cholesky(Yb)
        ia = 1.0 / np.trace(np.linalg.inv(Ya))
        ib = 1.0 / np.trace(np.linalg.inv(Yb))
        wa, wb = ia / (ia + ib), ib / (ia + ib)
        box[0] = (wa * ya + wb * yb, wa * Ya + wb * Yb)

    return Candidate(step, lambda: _moments(*box[0]))


def _cf_messages(sc: Scenario) -> tuple[Gaussian, Gaussian]:
    """The local belief and a neighbour message that contains it (the neighbour fused our last message)."""
    local = sc.priors[0]
    return local, local.fuse(sc.others[0])


def sky_cf(sc: Scenario) -> Candidate:
    local, received = _cf_messages(sc)
    cf, seqs, box = ChannelFilter(Gaussian.zeros(sc.n), policy="exact"), itertools.count(1), [None]

    def step():
        seq = next(seqs)
        cf.on_send(local, seq)
        out = cf.on_receive("peer", local, received, acked_seq=seq, seq=seq)
        if out.method != "exact":
            raise RuntimeError(f"the channel filter fell back to {out.method}: {out.reason}")
        box[0] = out.fused

    return Candidate(step, _box_state(box))


def numpy_cf(sc: Scenario, checks: bool = True, history: int = 64) -> Candidate:
    """The channel-filter bookkeeping of fusion.channel_filter (exact policy, one neighbour), inline:
    the broadcast belief per seq, the neighbour-side information ``B`` per seq, then on receipt
    ``common = B + (sent - B_sent)``, ``B <- m - (sent - B_sent)``, ``fused = local + m - common``."""
    local, received = _cf_messages(sc)
    yl, Yl, ym, Ym = local.y, local.Y, received.y, received.Y
    sent: OrderedDict = OrderedDict()  # seq -> local belief sent
    inbound_at_send: OrderedDict = OrderedDict()  # seq -> B at that time
    st = {"yB": np.zeros(sc.n), "YB": np.zeros((sc.n, sc.n)), "last": None, "fused": None}
    seqs, eigvalsh, cholesky = itertools.count(1), np.linalg.eigvalsh, np.linalg.cholesky

    def psd(M):  # the same decision as fusion.validation.is_psd: Cholesky first, eigenvalues only if it fails
        try:
            cholesky(M)
            return True
        except np.linalg.LinAlgError:
            return eigvalsh(M)[0] >= -_PSD_RTOL * max(1.0, float(np.max(np.abs(M))))

    def step():
        seq = next(seqs)
        sent[seq] = (yl, Yl)  # on_send
        if len(sent) > history:
            sent.popitem(last=False)
        inbound_at_send[seq] = (st["yB"], st["YB"])
        if len(inbound_at_send) > history:
            inbound_at_send.popitem(last=False)
        if st["last"] is not None and seq <= st["last"]:  # on_receive
            raise RuntimeError("stale")
        st["last"] = seq
        ysl, Ysl = sent[seq]
        ysB, YsB = inbound_at_send[seq]
        Yc = st["YB"] + Ysl - YsB  # B + A
        YB = Ym + YsB - Ysl  # m - A
        Yf = Yl + Ym - Yc
        if checks and not (psd(Yc) and psd(YB) and psd(Yf)):
            raise RuntimeError("not positive semi-definite")
        yc = st["yB"] + ysl - ysB
        st["yB"], st["YB"] = ym + ysB - ysl, YB
        st["fused"] = (yl + ym - yc, Yf)

    return Candidate(step, lambda: _moments(*st["fused"]))


# ==================================================================================================
# other libraries (optional: a missing library leaves its columns empty)
# ==================================================================================================
def filterpy():
    try:
        from filterpy.kalman import ExtendedKalmanFilter, KalmanFilter
    except ImportError:
        return None
    return SimpleNamespace(KalmanFilter=KalmanFilter, ExtendedKalmanFilter=ExtendedKalmanFilter)


_STONESOUP_NAMES = {
    "stonesoup.models.measurement.linear": ["LinearGaussian"],
    "stonesoup.models.measurement.nonlinear": ["Cartesian2DToBearing", "CartesianToElevationBearing"],
    "stonesoup.models.transition.linear": ["CombinedLinearGaussianTransitionModel", "ConstantVelocity"],
    "stonesoup.predictor.information": ["InformationKalmanPredictor"],
    "stonesoup.predictor.kalman": ["KalmanPredictor"],
    "stonesoup.types.angle": ["Bearing", "Elevation"],
    "stonesoup.types.detection": ["Detection"],
    "stonesoup.types.hypothesis": ["SingleHypothesis"],
    "stonesoup.types.prediction": ["GaussianStatePrediction"],
    "stonesoup.types.state": ["CovarianceMatrix", "GaussianState", "InformationState", "StateVector"],
    "stonesoup.updater.information": ["InformationKalmanUpdater"],
    "stonesoup.updater.kalman": ["ExtendedKalmanUpdater", "KalmanUpdater"],
}


def stonesoup():
    """The Stone Soup classes used here, as one namespace (``None`` if Stone Soup is not installed)."""
    names = {}
    try:
        for module, attributes in _STONESOUP_NAMES.items():
            mod = importlib.import_module(module)
            names.update({a: getattr(mod, a) for a in attributes})
    except ImportError:
        return None
    return SimpleNamespace(**names)


def _ss_order(d: int) -> np.ndarray:
    """Stone Soup orders a CV state (x, vx, y, vy, ...); skymesh (x, y, ..., vx, vy, ...). ss = sky[perm]."""
    return np.array([k * d + a for a in range(d) for k in range(2)])


def _from_ss(perm: np.ndarray, mean, cov) -> tuple[np.ndarray, np.ndarray]:
    m, P = np.empty(perm.size), np.empty((perm.size, perm.size))
    m[perm] = np.asarray(mean, dtype=float).ravel()
    P[np.ix_(perm, perm)] = np.asarray(cov, dtype=float)
    return m, P


class StoneSoupSetup:
    """Stone Soup models and states equivalent to a scenario (same F, Q, H, R; its state order)."""

    def __init__(self, ss, sc: Scenario):
        self.ss, self.sc, self.perm = ss, sc, _ss_order(sc.d)
        transition = ss.CombinedLinearGaussianTransitionModel([ss.ConstantVelocity(Q_CV) for _ in range(sc.d)])
        self.position = ss.LinearGaussian(ndim_state=sc.n, mapping=tuple(range(0, sc.n, 2)), noise_covar=sc.position.R)
        self.kf = (ss.KalmanPredictor(transition), ss.KalmanUpdater(self.position))
        self.info = (ss.InformationKalmanPredictor(transition), ss.InformationKalmanUpdater(self.position))
        offset = ss.StateVector(sc.sensor)
        if sc.d == 3:  # Stone Soup measures (elevation, bearing) with z up: elevation_ss = -elevation_NED
            R = sc.bearing.R[::-1, ::-1] * np.array([[1.0, -1.0], [-1.0, 1.0]])
            model = ss.CartesianToElevationBearing(
                ndim_state=sc.n, mapping=(0, 2, 4), noise_covar=R, translation_offset=offset
            )
            self.z_bearing = [ss.StateVector([ss.Elevation(-el), ss.Bearing(az)]) for az, el in sc.z_bearing]
        else:
            model = ss.Cartesian2DToBearing(ndim_state=sc.n, mapping=(0, 2), noise_covar=sc.bearing.R,
                                            translation_offset=offset)
            self.z_bearing = [ss.StateVector([ss.Bearing(az)]) for (az,) in sc.z_bearing]
        self.bearing_model, self.ekf = model, ss.ExtendedKalmanUpdater(model)
        self.z = [ss.StateVector(z) for z in sc.z]

    def prior(self, i: int, kind: str = "gaussian"):
        g, p = self.sc.priors[i], self.perm
        if kind == "info":
            return self.ss.InformationState(self.ss.StateVector(g.y[p]), precision=g.Y[np.ix_(p, p)], timestamp=_T0)
        cls = self.ss.GaussianStatePrediction if kind == "prediction" else self.ss.GaussianState
        return cls(self.ss.StateVector(g.mean[p]), self.ss.CovarianceMatrix(g.cov[np.ix_(p, p)]), timestamp=_T0)

    def moments(self, state, info: bool = False) -> tuple[np.ndarray, np.ndarray]:
        if info:
            return _from_ss(self.perm, *_moments(np.asarray(state.state_vector, float).ravel(), state.precision))
        return _from_ss(self.perm, state.state_vector, state.covar)

    def predict_update(self, prior, t, i: int, info: bool = False):
        predictor, updater = self.info if info else self.kf
        prediction = predictor.predict(prior, timestamp=t)
        detection = self.ss.Detection(self.z[i], timestamp=t, measurement_model=self.position)
        return updater.update(self.ss.SingleHypothesis(prediction, detection))

    def bearing_update(self, prediction, i: int):
        detection = self.ss.Detection(self.z_bearing[i], timestamp=_T0, measurement_model=self.bearing_model)
        return self.ekf.update(self.ss.SingleHypothesis(prediction, detection))


def stonesoup_if(S: StoneSoupSetup, info: bool = False) -> Candidate:
    st = [S.prior(0, "info" if info else "gaussian"), _T0]

    def step():
        t = st[1] + _DT
        st[0], st[1] = S.predict_update(st[0], t, 0, info), t

    return Candidate(step, lambda: S.moments(st[0], info))


def stonesoup_bearing(S: StoneSoupSetup) -> Candidate:
    st = [S.prior(0, "prediction")]

    def step():  # an update is a valid prediction for the next update, so the chain needs no copies
        st[0] = S.bearing_update(st[0], 0)

    return Candidate(step, lambda: S.moments(st[0]))


def filterpy_if(fp, sc: Scenario) -> Candidate:
    kf = fp.KalmanFilter(dim_x=sc.n, dim_z=sc.d)
    kf.x, kf.P = sc.priors[0].mean[:, None].copy(), sc.priors[0].cov.copy()
    kf.F, kf.Q, kf.H, kf.R = sc.F, sc.Q, sc.position.H, sc.position.R
    z = sc.z[0]

    def step():
        kf.predict()
        kf.update(z)

    return Candidate(step, lambda: (kf.x.ravel().copy(), kf.P.copy()))


def filterpy_bearing(fp, sc: Scenario) -> Candidate:
    m = sc.bearing.dim
    ekf = fp.ExtendedKalmanFilter(dim_x=sc.n, dim_z=m)
    ekf.x, ekf.P, ekf.R = sc.priors[0].mean[:, None].copy(), sc.priors[0].cov.copy(), sc.bearing.R
    h_and_H, z = _bearing_functions(sc), sc.z_bearing[0][:, None]

    def jacobian(x):
        return h_and_H(x[:, 0])[1]

    def hx(x):
        return h_and_H(x[:, 0])[0][:, None]

    def residual(a, b):
        r = a - b
        r[0] = wrap_angle(r[0])
        return r

    def step():
        ekf.update(z, jacobian, hx, residual=residual)

    return Candidate(step, lambda: (ekf.x.ravel().copy(), ekf.P.copy()))


# ==================================================================================================
# batched
# ==================================================================================================
def _batch_state(box: list) -> Callable[[], tuple[np.ndarray, np.ndarray]]:
    return lambda: (box[0].means(), np.linalg.inv(box[0].Y))


def _list_state(box: list) -> Callable[[], tuple[np.ndarray, np.ndarray]]:
    return lambda: (np.stack([g.mean for g in box[0]]), np.stack([g.cov for g in box[0]]))


def batch_if(sc: Scenario) -> Candidate:
    box, F, Q, F_inv, H, R_inv, z = [GaussianBatch.from_gaussians(sc.priors)], sc.F, sc.Q, sc.F_inv, sc.position.H, \
        sc.position.R_inv, sc.z

    def step():
        box[0] = box[0].predict(F, Q, F_inv).update(H, R_inv, z)

    return Candidate(step, _batch_state(box))


def loop_if(sc: Scenario) -> Candidate:
    box, F, Q, F_inv, H, R_inv, z = [list(sc.priors)], sc.F, sc.Q, sc.F_inv, sc.position.H, sc.position.R_inv, sc.z

    def step():
        box[0] = [g.predict(F, Q, F_inv).update(H, R_inv, zi) for g, zi in zip(box[0], z, strict=True)]

    return Candidate(step, _list_state(box))


def batch_bearing(sc: Scenario) -> Candidate:
    box, sensor, R_inv, z = [GaussianBatch.from_gaussians(sc.priors)], sc.sensor, sc.bearing.R_inv, sc.z_bearing
    update = GaussianBatch.eif_update_bearing3d if sc.d == 3 else GaussianBatch.eif_update_bearing2d

    def step():
        box[0] = update(box[0], sensor, R_inv, z)

    return Candidate(step, _batch_state(box))


def loop_bearing(sc: Scenario) -> Candidate:
    box, model, z = [list(sc.priors)], sc.bearing, sc.z_bearing

    def step():
        box[0] = [information_filter.eif_update(g, model, zi) for g, zi in zip(box[0], z, strict=True)]

    return Candidate(step, _list_state(box))


def batch_fast_ci(sc: Scenario) -> Candidate:
    a, b, box = GaussianBatch.from_gaussians(sc.priors), GaussianBatch.from_gaussians(sc.others), [None]

    def step():
        box[0] = a.fast_ci(b)

    return Candidate(step, _batch_state(box))


def loop_fast_ci(sc: Scenario) -> Candidate:
    pairs, box = list(zip(sc.priors, sc.others, strict=True)), [None]

    def step():
        box[0] = [fast_ci(pair) for pair in pairs]

    return Candidate(step, _list_state(box))


def stonesoup_loop_if(S: StoneSoupSetup) -> Candidate:
    st = [[S.prior(i) for i in range(TRACKS)], _T0]

    def step():
        t = st[1] + _DT
        st[0], st[1] = [S.predict_update(p, t, i) for i, p in enumerate(st[0])], t

    return Candidate(step, lambda: tuple(np.stack(x) for x in zip(*(S.moments(p) for p in st[0]), strict=True)))


def stonesoup_loop_bearing(S: StoneSoupSetup) -> Candidate:
    st = [[S.prior(i, "prediction") for i in range(TRACKS)]]

    def step():
        st[0] = [S.bearing_update(p, i) for i, p in enumerate(st[0])]

    return Candidate(step, lambda: tuple(np.stack(x) for x in zip(*(S.moments(p) for p in st[0]), strict=True)))


def filterpy_loop_if(fp, sc: Scenario) -> Candidate:
    filters = []
    for g, z in zip(sc.priors, sc.z, strict=True):
        kf = fp.KalmanFilter(dim_x=sc.n, dim_z=sc.d)
        kf.x, kf.P = g.mean[:, None].copy(), g.cov.copy()
        kf.F, kf.Q, kf.H, kf.R = sc.F, sc.Q, sc.position.H, sc.position.R
        filters.append((kf, z))

    def step():
        for kf, z in filters:
            kf.predict()
            kf.update(z)

    def state():
        return np.stack([kf.x.ravel() for kf, _ in filters]), np.stack([kf.P for kf, _ in filters])

    return Candidate(step, state)
