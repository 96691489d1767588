"""Velocity (first-difference) factor: a node should not move much between consecutive frames.

Residual (pixels per frame)::

    r = p_i(t+1) - p_i(t)                      t = 0 .. F-2
    cost = w_v * |r|^2  (paper)  <->  sigma = 1/sqrt(w_v)

Jacobians: dr/dp(t) = -I_2, dr/dp(t+1) = +I_2.

GTSAM: ``BetweenFactorPoint2(k_t, k_t+1, Point2(0, 0))`` — its error is ``(p1 - p0) - 0`` because
Point2 is a vector space, so the factor is exactly linear and runs in C++.
"""

from __future__ import annotations

import gtsam
import numpy as np

from ._noise import isotropic, sigma_from_weight

_ZERO = np.zeros(2)


class VelocityFactor:
    """``p(t+1) - p(t) = 0`` with isotropic weight ``w_v``."""

    dim = 2

    @staticmethod
    def residual(p0, p1) -> np.ndarray:
        """r = p1 - p0 (pixels/frame); broadcasts over (..., 2)."""
        return np.asarray(p1, dtype=float) - np.asarray(p0, dtype=float)

    @staticmethod
    def jacobians(p0, p1) -> tuple[np.ndarray, np.ndarray]:
        return (-np.eye(2), np.eye(2))

    @staticmethod
    def noise_model(weight: float) -> gtsam.noiseModel.Base:
        return isotropic(2, sigma_from_weight(weight))

    @staticmethod
    def create(key0: int, key1: int, noise: gtsam.noiseModel.Base) -> gtsam.BetweenFactorPoint2:
        """Factor between the positions at frame t (``key0``) and t+1 (``key1``)."""
        return gtsam.BetweenFactorPoint2(key0, key1, _ZERO, noise)
