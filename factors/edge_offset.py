"""Edge offset factor (the paper's rigid shape prior, ``edge_prior="offset"``).

Residual (pixels), for an edge a -> b (parent -> child) at every frame t = 0 .. F-1::

    r = (p_b(t) - p_a(t)) - d_ab
    cost = w_e * |r|^2  (paper)  <->  sigma = 1/sqrt(w_e)

``d_ab`` is the pre-smoothed child-minus-parent offset at the pair's first common observed frame
(paper §2.2). Note the bias this prior carries: it pulls every frame toward the first-frame *shape*
(penalising bending and rotation, not only stretch).

Jacobians: dr/dp_a = -I_2, dr/dp_b = +I_2.

GTSAM: one factor per frame state holds every edge's rows: an exact
``LinearContainerFactor(JacobianFactor)`` (2E x 2N, whitened by sqrt(w_e)), in C++.
"""

from __future__ import annotations

from functools import lru_cache

import gtsam
import numpy as np

from ._frame import linear_container, node_columns
from ._noise import sigma_from_weight


class EdgeOffsetFactor:
    """``(p_b - p_a) - d_ab = 0`` for every edge (a, b), isotropic weight ``w_e``."""

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
    def create(key: int, n_nodes: int, edges, offsets, weight: float,
               zeros: gtsam.Values) -> gtsam.LinearContainerFactor:
        """Factor on one frame state. edges: (E, 2) node rows (parent a, child b); offsets: (E, 2) d_ab, px."""
        s = 1.0 / sigma_from_weight(weight)
        edges = np.ascontiguousarray(edges, dtype=np.int64).reshape(-1, 2)
        offsets = np.ascontiguousarray(offsets, dtype=float).reshape(-1, 2)
        A, b = _edge_system(int(n_nodes), edges.tobytes(), offsets.tobytes(), s)
        return linear_container([key], [A], b, zeros)


@lru_cache(maxsize=8)
def _edge_system(n_nodes: int, edge_bytes: bytes, offset_bytes: bytes, s: float) -> tuple[np.ndarray, np.ndarray]:
    """Whitened (A, b) of all edge offsets at one frame: rows 2j, 2j+1 = s (p_b - p_a) - s d_j.
    The same for every frame, so it is built once per (graph, rest offsets, weight)."""
    edges = np.frombuffer(edge_bytes, dtype=np.int64).reshape(-1, 2)
    offsets = np.frombuffer(offset_bytes, dtype=float).reshape(-1, 2)
    E = len(edges)
    A = np.zeros((2 * E, 2 * n_nodes))
    eye = s * np.eye(2)
    for j, (a, b) in enumerate(edges.tolist()):
        A[2 * j:2 * j + 2, node_columns(a)] -= eye
        A[2 * j:2 * j + 2, node_columns(b)] += eye
    return A, s * offsets.ravel()
