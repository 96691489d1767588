"""Acceleration (second-difference) factor: trajectories should be smooth.

Residual (pixels per frame^2)::

    r = p_i(t-1) - 2 p_i(t) + p_i(t+1)           t = 1 .. F-2
    cost = w_a * |r|^2  (paper)  <->  sigma = 1/sqrt(w_a)

Jacobians: (+I_2, -2 I_2, +I_2) with respect to (p(t-1), p(t), p(t+1)).

GTSAM has no built-in three-point difference factor, and a Python ``CustomFactor`` makes LM
O(N^2) slow (see docs/ecosystem-notes §2). The residual is exactly linear, so one factor per frame
triple covers every node: a whitened ``JacobianFactor`` (blocks c_k sqrt(w_a) I_2N, b = 0, unit
noise) inside a ``LinearContainerFactor`` linearised at zero: at any values the container evaluates
``A (x - 0) - b``, which is the exact residual, entirely in C++.
"""

from __future__ import annotations

import gtsam
import numpy as np

from ._frame import linear_container, scaled_identity
from ._noise import sigma_from_weight

_COEFFS = (1.0, -2.0, 1.0)


class AccelerationFactor:
    """``p(t-1) - 2 p(t) + p(t+1) = 0`` for every node, isotropic weight ``w_a``."""

    dim = 2  # rows per node

    @staticmethod
    def residual(p_prev, p, p_next) -> np.ndarray:
        """r = p_prev - 2 p + p_next (pixels/frame^2); broadcasts over (..., 2)."""
        return (np.asarray(p_prev, dtype=float) - 2.0 * np.asarray(p, dtype=float)
                + np.asarray(p_next, dtype=float))

    @staticmethod
    def jacobians(p_prev, p, p_next) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return tuple(c * np.eye(2) for c in _COEFFS)

    @staticmethod
    def create(key_prev: int, key: int, key_next: int, n_nodes: int, weight: float,
               zeros: gtsam.Values) -> gtsam.LinearContainerFactor:
        """Exact linear factor on three consecutive frame states, weight ``w_a`` baked into A."""
        s = 1.0 / sigma_from_weight(weight)
        blocks = [scaled_identity(n_nodes, c * s) for c in _COEFFS]
        return linear_container([key_prev, key, key_next], blocks, np.zeros(2 * int(n_nodes)), zeros)
