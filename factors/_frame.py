"""The frame-state layout every smoother factor acts on.

The smoother has one GTSAM variable per video frame t: the **frame state** ``X_t``, a vector of
``2N`` pixels holding every tracked node's position at that frame, node by node:
``X_t = [x_0, y_0, x_1, y_1, ..., x_{N-1}, y_{N-1}]`` (node ``i`` = row ``i`` of the tracks).

Why one vector per frame rather than one ``Point2`` per node and frame: the problem's structure is
a chain in time (temporal factors join frames t-2..t+2) with dense coupling inside a frame (edge
factors), so GTSAM eliminates ~F variables of dimension 2N with dense blocks instead of N·F tiny
ones and ~4 N F factors. On plant 1 (20 nodes x 1104 frames) that is 4.4k factors instead of 87k and
Levenberg-Marquardt is measured ~2x faster, the graph build ~2x faster (benchmarks/bench_analyze.py).
Sorted key order is frame order, and a frame's 2N scalars are node-major (x, y), which is the layout
the marginal computation (:mod:`rce_gtsam.smoothing.marginals`) relies on.

Linear factors live in C++ as ``LinearContainerFactor(JacobianFactor)`` linearised at zero (exact
for a residual linear in the states); genuinely non-linear ones (rest length, robust loss) are one
Python ``CustomFactor`` per frame, so LM makes F callbacks per linearisation, not N·F.
"""

from __future__ import annotations

from functools import lru_cache

import gtsam
import numpy as np

KEY_CHAR = "x"


def frame_key(frame: int) -> int:
    """GTSAM key of the frame state at ``frame`` (sorted keys = frame order)."""
    return gtsam.symbol(KEY_CHAR, int(frame))


def node_columns(node_row: int) -> slice:
    """Columns of node row ``node_row``'s (x, y) inside a frame state."""
    return slice(2 * int(node_row), 2 * int(node_row) + 2)


def zero_values(keys, n_nodes: int) -> gtsam.Values:
    """A Values holding a zero frame state at every key: the linearisation point of the linear
    containers. Build it once and pass it to every ``create`` (a container copies only its own keys)."""
    v = gtsam.Values()
    z = np.zeros(2 * int(n_nodes))
    for k in keys:
        v.insert(int(k), z)
    return v


def linear_container(keys, blocks, b, zeros: gtsam.Values) -> gtsam.LinearContainerFactor:
    """An exact linear factor ``sum_k A_k X_k - b`` (already whitened: unit noise) in C++."""
    unit = unit_noise(int(len(b)))
    if len(keys) == 1:
        jf = gtsam.JacobianFactor(keys[0], blocks[0], b, unit)
    elif len(keys) == 2:
        jf = gtsam.JacobianFactor(keys[0], blocks[0], keys[1], blocks[1], b, unit)
    elif len(keys) == 3:
        jf = gtsam.JacobianFactor(keys[0], blocks[0], keys[1], blocks[1], keys[2], blocks[2], b, unit)
    else:
        raise ValueError(f"a linear container joins 1-3 frame states, got {len(keys)}")
    return gtsam.LinearContainerFactor(jf, zeros)


@lru_cache(maxsize=64)
def unit_noise(dim: int) -> gtsam.noiseModel.Base:
    return gtsam.noiseModel.Unit.Create(int(dim))


@lru_cache(maxsize=16)
def scaled_identity(n_nodes: int, scale: float) -> np.ndarray:
    """``scale * I`` of a frame state's size (2N x 2N); cached, never modify it."""
    out = float(scale) * np.eye(2 * int(n_nodes))
    out.flags.writeable = False
    return out


def check_jacobian_shape(H: np.ndarray, rows: int, n_nodes: int) -> np.ndarray:
    """Guard for ``CustomFactor`` callbacks: GTSAM silently accepts a wrong-shaped block
    (docs/ecosystem-notes §2), so assert the (rows x 2N) shape ourselves."""
    if H.shape != (rows, 2 * n_nodes):
        raise AssertionError(f"Jacobian block has shape {H.shape}, expected ({rows}, {2 * n_nodes})")
    return H
