"""Edge offset factor (the paper's rigid shape prior, ``edge_prior="offset"``).

Residual (pixels), for an edge a -> b (parent -> child) at every frame t = 0 .. F-1::

    r = (p_b(t) - p_a(t)) - d_ab
    cost = w_e * |r|^2  (paper)  <->  sigma = 1/sqrt(w_e)

``d_ab`` is the pre-smoothed child-minus-parent offset at the pair's first common observed frame
(paper §2.2). Note the bias this prior carries: it pulls every frame toward the first-frame *shape*
(penalising bending and rotation, not only stretch).

Jacobians: dr/dp_a = -I_2, dr/dp_b = +I_2.

GTSAM: ``BetweenFactorPoint2(k_a, k_b, d_ab)`` (exactly linear for Point2, C++).
"""

from __future__ import annotations

import gtsam
import numpy as np

from ._noise import isotropic, sigma_from_weight


class EdgeOffsetFactor:
    """``(p_b - p_a) - d_ab = 0`` with isotropic weight ``w_e``."""

    dim = 2

    @staticmethod
    def residual(p_a, p_b, offset) -> np.ndarray:
        """r = (p_b - p_a) - d (pixels); broadcasts over (..., 2)."""
        return np.asarray(p_b, dtype=float) - np.asarray(p_a, dtype=float) - np.asarray(offset, dtype=float)

    @staticmethod
    def jacobians(p_a, p_b, offset) -> tuple[np.ndarray, np.ndarray]:
        return (-np.eye(2), np.eye(2))

    @staticmethod
    def rest_offset(xy_a: np.ndarray, xy_b: np.ndarray) -> np.ndarray:
        """d_ab = xy_b - xy_a at the first frame where both (F, 2) series are finite (pixels).

        Raises ValueError if the two nodes are never observed together.
        """
        common = np.flatnonzero(np.isfinite(xy_a).all(axis=1) & np.isfinite(xy_b).all(axis=1))
        if common.size == 0:
            raise ValueError("the two nodes are never observed in the same frame")
        t0 = common[0]
        return xy_b[t0] - xy_a[t0]

    @staticmethod
    def noise_model(weight: float) -> gtsam.noiseModel.Base:
        return isotropic(2, sigma_from_weight(weight))

    @staticmethod
    def create(key_a: int, key_b: int, offset, noise: gtsam.noiseModel.Base) -> gtsam.BetweenFactorPoint2:
        return gtsam.BetweenFactorPoint2(key_a, key_b, np.asarray(offset, dtype=float), noise)
