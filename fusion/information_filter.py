"""The information filter and the extended information filter on :class:`~fusion.gaussian.Gaussian`.

* :func:`predict` — Merino Alg. 3.2 lines 1-3 with a motion model from ``fusion.motion``.
* :func:`update` — Merino (3.17)-(3.18) for a linear model (``PositionMeasurement``).
* :func:`eif_update` — the extended information filter update, Merino (3.49)-(3.52):
  ``Y += H^T R^-1 H`` and ``y += H^T R^-1 [z - h(mu) + H mu]`` with ``H`` the Jacobian at ``mu``.
"""

from __future__ import annotations

import functools

import numpy as np

from fusion import validation
from fusion.gaussian import Gaussian


@functools.lru_cache(maxsize=256)
def discretised(model, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(F, Q, F^-1)`` of a (frozen, hashable) motion model over ``dt``, computed once per pair and
    returned read-only: an agent predicts every track over the same step, every step."""
    matrices = (model.transition(dt), model.noise(dt), model.inverse_transition(dt))
    for m in matrices:
        m.setflags(write=False)
    return matrices


def predict(belief: Gaussian, model, dt: float) -> Gaussian:
    """Predict ``belief`` over ``dt`` seconds with a motion model (Merino Alg. 3.2, (3.11)-(3.13))."""
    F, Q, F_inv = discretised(model, float(dt))
    return belief.predict(F, Q, F_inv)


def update(belief: Gaussian, model, z) -> Gaussian:
    """Linear update (Merino (3.17)-(3.18)); ``model`` must be linear (it has a constant ``H``)."""
    return belief.update(model.jacobian(), model.R_inv, z)


def eif_update(belief: Gaussian, model, z, linearization_point=None) -> Gaussian:
    """Extended information filter update (Merino (3.52)).

    ``linearization_point`` defaults to the belief's mean; pass it explicitly when the belief is not
    yet fully observable (e.g. a bearing-only track initialised from a prior along a ray)."""
    z = validation.shaped(z, "measurement z", (model.dim,))  # finiteness: checked on the update's result
    mu = belief.mean if linearization_point is None else np.asarray(linearization_point, dtype=float)
    z_hat, H = model.linearize(mu)
    innovation = model.residual(z, z_hat)
    return belief.update(H, model.R_inv, innovation + H @ mu)
