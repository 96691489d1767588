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

GTSAM: one ``CustomFactor`` per frame state with a row per edge (E x 2N Jacobian), so LM makes one
Python callback per frame and linearisation; isotropic noise sigma = 1/sqrt(w_e).
"""

from __future__ import annotations

import gtsam
import numpy as np

from ._frame import check_jacobian_shape
from ._noise import isotropic, sigma_from_weight


class EdgeLengthFactor:
    """``|p_b - p_a| - L_ab = 0`` for every edge (a, b), weight ``w_e``."""

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
    def create(key: int, n_nodes: int, edges, lengths, weight: float) -> gtsam.CustomFactor:
        """Factor on one frame state. edges: (E, 2) node rows (parent a, child b); lengths: (E,) px."""
        N = int(n_nodes)
        ab = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
        L = np.asarray(lengths, dtype=float).reshape(-1)
        ia, ib = ab[:, 0], ab[:, 1]
        rows = np.arange(len(ab))

        def error(this: gtsam.CustomFactor, values: gtsam.Values, H):
            p = values.atVector(key).reshape(N, 2)
            d = p[ib] - p[ia]
            dist = np.linalg.norm(d, axis=1)
            if H is not None:
                u = d / dist[:, None]
                J = np.zeros((len(ab), N, 2))
                np.add.at(J, (rows, ia), -u)
                np.add.at(J, (rows, ib), u)
                H[0] = check_jacobian_shape(J.reshape(len(ab), 2 * N), len(ab), N)
            return dist - L

        return gtsam.CustomFactor(isotropic(len(ab), sigma_from_weight(weight)), [key], error)
