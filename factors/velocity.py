"""Velocity (first-difference) factor: a node should not move much between consecutive frames.

Residual (pixels per frame)::

    r = p_i(t+1) - p_i(t)                      t = 0 .. F-2
    cost = w_v * |r|^2  (paper)  <->  sigma = 1/sqrt(w_v)

Jacobians: dr/dp(t) = -I_2, dr/dp(t+1) = +I_2.

GTSAM: one factor per pair of consecutive frame states covers every node: an exact
``LinearContainerFactor(JacobianFactor)`` with blocks ``sqrt(w_v) (-I, +I)`` (2N x 2N), in C++.
"""

from __future__ import annotations

import gtsam
import numpy as np

from ._frame import linear_container, scaled_identity
from ._noise import sigma_from_weight


class VelocityFactor:
    """``p(t+1) - p(t) = 0`` for every node, isotropic weight ``w_v``."""

    dim = 2  # rows per node

    @staticmethod
    def residual(p0, p1) -> np.ndarray:
        """r = p1 - p0 (pixels/frame); broadcasts over (..., 2)."""
        return np.asarray(p1, dtype=float) - np.asarray(p0, dtype=float)

    @staticmethod
    def jacobians(p0, p1) -> tuple[np.ndarray, np.ndarray]:
        return (-np.eye(2), np.eye(2))

    @staticmethod
    def create(key0: int, key1: int, n_nodes: int, weight: float,
               zeros: gtsam.Values) -> gtsam.LinearContainerFactor:
        """Factor between the frame states at t (``key0``) and t+1 (``key1``), weight baked in."""
        s = 1.0 / sigma_from_weight(weight)
        return linear_container([key0, key1], [scaled_identity(n_nodes, -s), scaled_identity(n_nodes, s)],
                                np.zeros(2 * int(n_nodes)), zeros)
