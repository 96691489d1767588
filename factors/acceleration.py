"""Acceleration (second-difference) factor: trajectories should be smooth.

Residual (pixels per frame^2)::

    r = p_i(t-1) - 2 p_i(t) + p_i(t+1)           t = 1 .. F-2
    cost = w_a * |r|^2  (paper)  <->  sigma = 1/sqrt(w_a)

Jacobians: (+I_2, -2 I_2, +I_2) with respect to (p(t-1), p(t), p(t+1)).

GTSAM has no built-in three-point difference factor, and a Python ``CustomFactor`` makes LM
O(N^2) slow (see docs/ecosystem-notes §2). Because Point2 is a vector space the residual is exactly
linear, so it is stored as a whitened ``JacobianFactor`` (A_k = c_k sqrt(w_a) I_2, b = 0, unit noise)
inside a ``LinearContainerFactor`` linearised at zero: at any values the container evaluates
``A (x - 0) - b``, which is the exact residual, entirely in C++.
"""

from __future__ import annotations

from functools import lru_cache

import gtsam
import numpy as np

from ._noise import sigma_from_weight

_COEFFS = (1.0, -2.0, 1.0)


class AccelerationFactor:
    """``p(t-1) - 2 p(t) + p(t+1) = 0`` with isotropic weight ``w_a``."""

    dim = 2

    @staticmethod
    def residual(p_prev, p, p_next) -> np.ndarray:
        """r = p_prev - 2 p + p_next (pixels/frame^2); broadcasts over (..., 2)."""
        return (np.asarray(p_prev, dtype=float) - 2.0 * np.asarray(p, dtype=float)
                + np.asarray(p_next, dtype=float))

    @staticmethod
    def jacobians(p_prev, p, p_next) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return tuple(c * np.eye(2) for c in _COEFFS)

    @staticmethod
    def zero_values(keys) -> gtsam.Values:
        """A Values holding Point2(0, 0) at every key: the linearisation point the containers need.
        Build it once for all keys and pass it to :meth:`create` (the container copies only its own
        three entries)."""
        v = gtsam.Values()
        z = np.zeros(2)
        for k in keys:
            v.insert(int(k), z)
        return v

    @staticmethod
    def create(key_prev: int, key: int, key_next: int, weight: float,
               zeros: gtsam.Values) -> gtsam.LinearContainerFactor:
        """Exact linear factor on the three Point2 variables, weight ``w_a`` baked into A."""
        a0, a1, a2, b, unit = _blocks(float(weight))
        return gtsam.LinearContainerFactor(gtsam.JacobianFactor(key_prev, a0, key, a1, key_next, a2, b, unit),
                                           zeros)


@lru_cache(maxsize=8)
def _blocks(weight: float):
    """Whitened Jacobian blocks sqrt(w) * (I, -2I, I), zero rhs and the unit noise model, built once
    per weight (building ~20k factors is measurably faster without re-creating them each time)."""
    s = 1.0 / sigma_from_weight(weight)  # sqrt(w)
    eye = np.eye(2)
    return (*(c * s * eye for c in _COEFFS), np.zeros(2), gtsam.noiseModel.Unit.Create(2))
