"""Edge length factor (``edge_prior="length"``): inextensible segments, bending left free.

Residual (pixels), for an edge a -> b at every frame t = 0 .. F-1::

    r = |p_b(t) - p_a(t)| - L_ab
    cost = w_e * r^2  <->  sigma = 1/sqrt(w_e)

Jacobians: with u = (p_b - p_a)/|p_b - p_a|,  dr/dp_a = -u^T,  dr/dp_b = +u^T  (1x2 each; undefined
when the two points coincide, which a tracked segment never does).

Rest length ``L_ab`` = the **median** over the pair's common observed frames of the pre-smoothed
length. The median, not the first frame as in the paper, so one deflected or mistracked frame
cannot set the rest length for the whole video; a branch segment's projected length varies only
through foreshortening and tracking noise, whose median is the best single-number summary.

GTSAM: ``RangeFactor2`` — ``RangeFactor<Point2, Point2>`` in C++ (error = distance(p_a, p_b) - L),
so LM never calls into Python.
"""

from __future__ import annotations

import gtsam
import numpy as np

from ._noise import isotropic, sigma_from_weight


class EdgeLengthFactor:
    """``|p_b - p_a| - L_ab = 0`` with weight ``w_e``."""

    dim = 1

    @staticmethod
    def residual(p_a, p_b, length) -> np.ndarray:
        """r = |p_b - p_a| - L (pixels), shape (..., 1)."""
        d = np.asarray(p_b, dtype=float) - np.asarray(p_a, dtype=float)
        return (np.linalg.norm(d, axis=-1) - float(length))[..., None]

    @staticmethod
    def jacobians(p_a, p_b, length) -> tuple[np.ndarray, np.ndarray]:
        d = np.asarray(p_b, dtype=float) - np.asarray(p_a, dtype=float)
        u = (d / np.linalg.norm(d))[None, :]
        return (-u, u)

    @staticmethod
    def rest_length(xy_a: np.ndarray, xy_b: np.ndarray) -> float:
        """Median over common observed frames of |xy_b - xy_a| for two (F, 2) series (pixels).

        Raises ValueError if the two nodes are never observed together.
        """
        common = np.isfinite(xy_a).all(axis=1) & np.isfinite(xy_b).all(axis=1)
        if not common.any():
            raise ValueError("the two nodes are never observed in the same frame")
        return float(np.median(np.linalg.norm(xy_b[common] - xy_a[common], axis=1)))

    @staticmethod
    def noise_model(weight: float) -> gtsam.noiseModel.Base:
        return isotropic(1, sigma_from_weight(weight))

    @staticmethod
    def create(key_a: int, key_b: int, length: float, noise: gtsam.noiseModel.Base) -> gtsam.RangeFactor2:
        return gtsam.RangeFactor2(key_a, key_b, float(length), noise)
