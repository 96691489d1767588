"""Reference solver: the paper's smoother as one sparse linear least-squares problem (no GTSAM).

Reproduces reference pipeline §2.2: unknowns are every node's position at every frame 0..F-1; x
and y are two independent problems with the same matrix; each row is scaled by sqrt(w):

    J = w_m Σ_(i,t) observed (p_i(t) − m_i(t))²
      + w_v Σ_i Σ_t (p_i(t+1) − p_i(t))²  + w_a Σ_i Σ_t (p_i(t−1) − 2 p_i(t) + p_i(t+1))²
      + w_e Σ_(a→b) Σ_t ((p_b(t) − p_a(t)) − d_ab)²

Weight guards as published: w_m floored at 1e-9 before the square root; any other weight <= 0
drops its rows. If the tracks carry ``sigma_px``, the measurement row weight is 1/sigma² (the same
quadratic the GTSAM smoother then builds); the paper's tracks never do.

Two solvers: :func:`solve_direct` (sparse Cholesky-free LU of the normal equations — exact up to
rounding) and :func:`solve_lsqr` (``scipy.sparse.linalg.lsqr`` with the paper's atol = btol = 1e-6,
iter_lim = 2000, x0 = 0 — what the published results used; its early stop is an approximation).
Use these to validate :func:`rce_gtsam.smoothing.smoother.smooth_tracks` and as the speed floor in benchmarks.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..factors import MEASUREMENT_WEIGHT_FLOOR, EdgeOffsetFactor
from ..graph import BranchGraph
from .marginals import single_threaded_blas
from ..presets import SmootherConfig
from .presmooth import moving_average
from ..tracks import Tracks


@dataclass(frozen=True, eq=False)
class PaperSystem:
    """Row-scaled system ``A p = b`` per axis. Column of node row i, frame t = ``i * F + t``.

    A: (rows, N·F) CSR; b: (rows, 2) right-hand sides for x and y (pixels · sqrt(weight)).
    """

    A: sp.csr_matrix
    b: np.ndarray
    n_nodes: int
    n_frames: int

    def unpack(self, p: np.ndarray) -> np.ndarray:
        """(N·F, 2) solution vector(s) → (N, F, 2) positions."""
        return np.asarray(p).reshape(self.n_nodes, self.n_frames, 2)


@dataclass(frozen=True, eq=False)
class ReferenceSolution:
    """xy: (N, F, 2) solved positions at every frame (pixels); seconds: solve time (excl. assembly);
    iterations / istop: LSQR iteration counts and stop reasons per axis (None for the direct solve)."""

    xy: np.ndarray
    method: str
    seconds: float
    iterations: tuple[int, int] | None = None
    istop: tuple[int, int] | None = None


def paper_system(pre: Tracks, graph: BranchGraph, config: SmootherConfig) -> PaperSystem:
    """Assemble the paper quadratic for already pre-smoothed tracks (moving average NOT applied here).

    Only the linear paper model is representable: ``edge_prior="offset"``, isotropic, no robust loss.
    """
    if config.edge_prior != "offset" or config.robust is not None or config.along_across_ratio != 1.0:
        raise ValueError("the reference solver covers only the linear paper model "
                         "(edge_prior='offset', along_across_ratio=1, robust=None)")
    N, F = pre.n_nodes, pre.n_frames
    col = np.arange(N * F).reshape(N, F)
    rows, cols, vals, rhs = [], [], [], []
    n_rows = 0

    def block(c: np.ndarray, v: np.ndarray, b: np.ndarray) -> None:
        # c, v: (k, m) columns / values of k rows with m entries each; b: (k, 2)
        nonlocal n_rows
        k, m = c.shape
        rows.append(np.repeat(np.arange(n_rows, n_rows + k), m))
        cols.append(c.reshape(-1))
        vals.append(v.reshape(-1))
        rhs.append(b)
        n_rows += k

    obs = pre.observed
    ii, tt = np.nonzero(obs)
    if pre.sigma_px is None:
        sw = np.full(ii.size, np.sqrt(max(float(config.measurement_weight), MEASUREMENT_WEIGHT_FLOOR)))
    else:
        sw = 1.0 / pre.sigma_px[ii, tt]
    block(col[ii, tt][:, None], sw[:, None], sw[:, None] * pre.xy[ii, tt])

    if config.velocity_weight > 0 and F >= 2:
        s = np.sqrt(config.velocity_weight)
        c = np.stack([col[:, :-1].reshape(-1), col[:, 1:].reshape(-1)], axis=1)
        block(c, np.tile([-s, s], (c.shape[0], 1)), np.zeros((c.shape[0], 2)))
    if config.acceleration_weight > 0 and F >= 3:
        s = np.sqrt(config.acceleration_weight)
        c = np.stack([col[:, :-2].reshape(-1), col[:, 1:-1].reshape(-1), col[:, 2:].reshape(-1)], axis=1)
        block(c, np.tile([s, -2 * s, s], (c.shape[0], 1)), np.zeros((c.shape[0], 2)))
    if config.edge_weight > 0:
        s = np.sqrt(config.edge_weight)
        for a, bnode in graph.edges:
            ia, ib = pre.index(a), pre.index(bnode)
            d = EdgeOffsetFactor.rest_offset(pre.xy[ia], pre.xy[ib])
            c = np.stack([col[ia], col[ib]], axis=1)
            block(c, np.tile([-s, s], (F, 1)), np.tile(s * d, (F, 1)))
    A = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(n_rows, N * F))
    return PaperSystem(A=A, b=np.concatenate(rhs, axis=0), n_nodes=N, n_frames=F)


def solve_direct(system: PaperSystem) -> ReferenceSolution:
    """Exact least-squares solution via a sparse LU of the normal equations AᵀA p = Aᵀb (both axes)."""
    t0 = time.perf_counter()
    with single_threaded_blas():
        At = system.A.T.tocsr()
        solve = spla.factorized((At @ system.A).tocsc())
        rhs = At @ system.b
        p = np.stack([solve(rhs[:, 0]), solve(rhs[:, 1])], axis=1)
    return ReferenceSolution(xy=system.unpack(p), method="direct", seconds=time.perf_counter() - t0)


def solve_lsqr(system: PaperSystem, atol: float = 1e-6, btol: float = 1e-6,
               iter_lim: int = 2000) -> ReferenceSolution:
    """LSQR from zero per axis with the paper's stopping rule (the stop flag is reported, not enforced)."""
    t0 = time.perf_counter()
    out, its, stops = [], [], []
    for axis in (0, 1):
        with single_threaded_blas():
            res = spla.lsqr(system.A, system.b[:, axis], atol=atol, btol=btol, iter_lim=iter_lim)
        out.append(res[0])
        stops.append(int(res[1]))
        its.append(int(res[2]))
    return ReferenceSolution(xy=system.unpack(np.stack(out, axis=1)), method="lsqr",
                             seconds=time.perf_counter() - t0, iterations=tuple(its), istop=tuple(stops))


def reference_smooth(tracks: Tracks, graph: BranchGraph, config: SmootherConfig,
                     method: str = "direct") -> ReferenceSolution:
    """Moving average (``config.presmooth_window``) then the paper quadratic, solved ``"direct"`` or
    ``"lsqr"``. Returns positions at all frames (pixels)."""
    pre = moving_average(tracks, config.presmooth_window)
    system = paper_system(pre, graph, config)
    if method == "direct":
        return solve_direct(system)
    if method == "lsqr":
        return solve_lsqr(system)
    raise ValueError(f"method must be 'direct' or 'lsqr', got {method!r}")
