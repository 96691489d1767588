"""Marginal covariances of the smoother by block-banded selected inversion.

The smoother's variables, in frame-major order, form frames of ``n = 2N`` scalars (N nodes × x, y).
Temporal factors couple a frame only to its neighbours up to ``b`` frames away (b = 2 with the
acceleration factor, 1 with only velocity) and edge/measurement factors act inside one frame, so the
information matrix ``Λ = JᵀJ`` at the solution is block-banded with block bandwidth ``b``.

We take the whitened Jacobian ``J`` of GTSAM's own linearisation at the solution
(``NonlinearFactorGraph.linearize`` → ``GaussianFactorGraph.sparseJacobian_``; noise models and the
robust M-estimator weights are baked in exactly as GTSAM applies them, so this is the same
information matrix ``gtsam.Marginals`` factorises), group every ``b`` consecutive frames into one
super-block (making Λ block-tridiagonal) and compute

* a block Cholesky factor ``Λ = L Lᵀ``, super-block by super-block, and
* the Takahashi / Erisman–Tinney backward recursion for the diagonal blocks of ``Σ = Λ⁻¹``:
  ``Σ_tt = G_tᵀ G_t + H_t Σ_{t+1,t+1} H_tᵀ`` with ``G_t = L_tt⁻¹`` and ``H_t = G_tᵀ L_{t+1,t}ᵀ``.

Cost: O(F · b² · n³) in ~F/b small dense products, versus a Bayes-tree query per key for
``gtsam.Marginals``. The within-frame blocks ``Σ_tt`` are the joint covariances of all nodes at
frame t; their 2×2 diagonal blocks are the per-node marginals.

Caveat for non-linear priors: like ``gtsam.Marginals``, this is the Gauss-Newton (JᵀJ) information,
the Laplace approximation at the solution. For a compressed length prior (segment shorter than its
rest length) the exact Hessian has less transverse curvature than JᵀJ, so there the covariance is
optimistic.
"""

from __future__ import annotations

import gtsam
import numpy as np
import scipy.linalg
import scipy.sparse as sp

from ..errors import RceError


#: Relative pivot threshold below which the information matrix counts as singular (see use).
PIVOT_RTOL = 1e-12


class SingularInformationError(RceError, np.linalg.LinAlgError):
    """The information matrix is not positive definite: some variable is unconstrained."""


def whitened_jacobian(linear: gtsam.GaussianFactorGraph, n_cols: int | None = None) -> tuple[sp.csr_matrix, np.ndarray]:
    """Sparse whitened Jacobian ``A`` and right-hand side ``b`` of a Gaussian factor graph.

    Columns follow the sorted key order of the graph's variables (each key's scalar dimensions in
    turn), as ``GaussianFactorGraph::sparseJacobian`` lays them out.
    """
    ijs = linear.sparseJacobian_()
    rows = ijs[0].astype(np.int64) - 1
    cols = ijs[1].astype(np.int64) - 1
    vals = ijs[2]
    n_rows = int(rows.max()) + 1 if rows.size else 0
    b_col = int(cols.max()) if n_cols is None else n_cols  # sparseJacobian appends b as the last column
    is_b = cols == b_col
    A = sp.csr_matrix((vals[~is_b], (rows[~is_b], cols[~is_b])), shape=(n_rows, b_col))
    b = np.zeros(n_rows)
    np.add.at(b, rows[is_b], vals[is_b])
    return A, b


def information_matrix(linear: gtsam.GaussianFactorGraph, n_cols: int) -> sp.csc_matrix:
    """Λ = JᵀJ of a (whitened) Gaussian factor graph, columns in sorted key order."""
    A, _ = whitened_jacobian(linear, n_cols=n_cols)
    return (A.T @ A).tocsc()


def frame_bandwidth(Lam: sp.spmatrix, n: int) -> int:
    """Largest frame distance |t - s| with a nonzero block Λ[t, s] (block size ``n``)."""
    coo = Lam.tocoo()
    if coo.nnz == 0:
        return 0
    return int(np.abs(coo.row // n - coo.col // n).max())


def coordinate_components(Lam: sp.spmatrix, n: int) -> np.ndarray:
    """(n,) component label of each of a frame's n scalars: scalars i and j share a component when Λ
    couples them at any pair of frames (union over the sparsity pattern of (r mod n, c mod n)).

    Without an edge prior or anisotropic noise every pixel coordinate is its own chain in time (2N
    components of one scalar); the offset prior joins all of them into one."""
    from scipy.sparse.csgraph import connected_components

    coo = Lam.tocoo()
    links = sp.coo_matrix((np.ones(coo.nnz), (coo.row % n, coo.col % n)), shape=(n, n))
    return connected_components(links, directed=False)[1]


def banded_selected_inverse(Lam: sp.spmatrix, block: int, first_frame: int = 0) -> np.ndarray:
    """Within-frame blocks ``Σ_tt`` of ``Σ = Λ⁻¹`` for a symmetric positive-definite block-banded Λ.

    Parameters
    ----------
    Lam: (T·n, T·n) sparse symmetric matrix, frame-major, uniform block size ``block`` = n, with
        any frame bandwidth b (found from the sparsity).
    block: n, scalars per frame.
    first_frame: frame number of the first block (only for the error message).

    Returns
    -------
    (T, n, n) array of the diagonal blocks of the inverse.

    Method: the frame's scalars are split into the groups Λ never couples
    (:func:`coordinate_components`; the inverse is zero between groups), groups of equal size are
    batched, and b consecutive frames are grouped into one super-block of size m = b·(group size),
    which makes each group's Λ block-tridiagonal (frames b apart fall in adjacent super-blocks); the
    last super-block is padded with identity rows, which are decoupled and leave the rest of the
    inverse unchanged. Then

    * forward block Cholesky:  L_tt = chol(Λ_tt − C_t C_tᵀ),  G_t = L_tt⁻¹,  C_{t+1} = Λ_{t+1,t} G_tᵀ;
    * backward Takahashi recursion with H_t = G_tᵀ C_{t+1}ᵀ:
      Σ_{T−1,T−1} = G_{T−1}ᵀ G_{T−1},   Σ_tt = G_tᵀ G_t + H_t Σ_{t+1,t+1} H_tᵀ.

    Cost O(F · b² · k³) per group of k scalars: for the default preset's independent coordinates
    (k = 1) a tiny fraction of the dense (2N)³ one. Memory: two (T, m, m) arrays per group batch.

    BLAS runs single-threaded here (if ``threadpoolctl`` is installed): the blocks are small, and
    OpenBLAS worker threads spinning on a shared, busy machine were measured to slow this loop
    twenty-fold.

    Raises :class:`SingularInformationError` if Λ is not positive definite.
    """
    n = int(block)
    N_tot = Lam.shape[0]
    if Lam.shape != (N_tot, N_tot) or N_tot % n:
        raise ValueError(f"information matrix of shape {Lam.shape} is not square in blocks of {n}")
    T_frames = N_tot // n
    b = max(frame_bandwidth(Lam, n), 1)
    T = -(-T_frames // b)
    label = coordinate_components(Lam, n)
    groups: dict[int, list[np.ndarray]] = {}
    for c in range(label.max() + 1):
        idx = np.flatnonzero(label == c)
        groups.setdefault(idx.size, []).append(idx)
    out = np.zeros((T * b, n, n))
    coo = Lam.tocoo()
    with single_threaded_blas():
        for k, members in groups.items():
            members = np.array(members)                        # (C, k) scalars of each group
            diag, sub = _group_blocks(coo, n, b, T, T_frames, members)
            Sig = _block_tridiagonal_selected_inverse(diag, sub, b, first_frame)  # (C, T*b, k, k)
            for c, idx in enumerate(members):
                out[:, idx[:, None], idx[None, :]] = Sig[c]
    out = out[:T_frames]
    return 0.5 * (out + np.swapaxes(out, 1, 2))


def _group_blocks(coo: sp.coo_matrix, n: int, b: int, T: int, T_frames: int,
                  members: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Super-blocks of the groups ``members`` (C, k): ``diag[c, t] = Λ_c[t, t]``, ``sub[c, t] =
    Λ_c[t+1, t]`` (m x m, m = b·k; super-block t holds frames t·b .. t·b+b-1, each frame's k scalars in
    ``members`` order), identity on the padding frames past ``T_frames``."""
    C, k = members.shape
    m = b * k
    group = np.full(n, -1)
    pos = np.zeros(n, dtype=int)
    for c, idx in enumerate(members):
        group[idx] = c
        pos[idx] = np.arange(k)
    r, col, v = coo.row, coo.col, coo.data
    g = group[r % n]
    keep = g >= 0
    r, col, v, g = r[keep], col[keep], v[keep], g[keep]
    tr, tc = (r // n) // b, (col // n) // b                  # super-block of row / column
    i = ((r // n) % b) * k + pos[r % n]
    j = ((col // n) % b) * k + pos[col % n]
    if np.any(np.abs(tr - tc) > 1):
        raise ValueError("matrix is not block-tridiagonal in the given block size")
    diag = np.zeros((C, T, m, m))
    sub = np.zeros((C, max(T - 1, 0), m, m))
    on = tr == tc
    np.add.at(diag, (g[on], tr[on], i[on], j[on]), v[on])
    below = tr == tc + 1
    np.add.at(sub, (g[below], tc[below], i[below], j[below]), v[below])
    pad = np.arange(T_frames * k - (T - 1) * m, m) if T * b > T_frames else np.arange(0)
    diag[:, T - 1, pad, pad] = 1.0
    return diag, sub


def _block_tridiagonal_selected_inverse(diag: np.ndarray, sub: np.ndarray, b: int,
                                        first_frame: int = 0) -> np.ndarray:
    """The recursions of :func:`banded_selected_inverse`, batched over a leading group axis:
    ``diag`` (C, T, m, m), ``sub`` (C, T-1, m, m) -> (C, T·b, k, k) frame blocks, k = m / b.
    Memory: ``diag`` and ``sub`` are overwritten by G_t = L_tt⁻¹ and C_t; Σ_tt is carried one
    super-block at a time and only its b frame blocks are kept."""
    Cn, T, m, _ = diag.shape
    k = m // b
    G, Cb = diag, sub            # G[:, t] = L_tt^-1 and Cb[:, t] = L[t+1, t], in place of Λ's blocks
    for t in range(T):
        S = diag[:, t] - Cb[:, t - 1] @ np.swapaxes(Cb[:, t - 1], 1, 2) if t > 0 else diag[:, t]
        try:
            L = np.linalg.cholesky(S)
        except np.linalg.LinAlgError:
            L = None
        # A pivot at rounding level means a direction with (numerically) no information: the
        # "successful" factor would give variances ~1e20. 1e-12 relative to the block's largest
        # diagonal entry is ~1e4 times double-precision rounding.
        if L is None or np.any(np.min(np.diagonal(L, axis1=1, axis2=2), axis=1) ** 2
                               <= PIVOT_RTOL * np.max(np.diagonal(S, axis1=1, axis2=2), axis=1)):
            raise SingularInformationError(
                f"the smoother's information matrix is singular near frame {first_frame + t * b}: some node "
                "position there is not constrained by any factor")
        G[:, t] = np.linalg.inv(L)
        if t < T - 1:
            Cb[:, t] = sub[:, t] @ np.swapaxes(G[:, t], 1, 2)   # Λ_{t+1,t} L_tt^-T
    out = np.empty((Cn, T * b, k, k))
    frames = np.arange(b)
    Sig = None
    for t in range(T - 1, -1, -1):
        Gt = G[:, t]
        GtT = np.swapaxes(Gt, 1, 2)
        Sig_t = GtT @ Gt                                   # G_tᵀ G_t = (L_tt L_ttᵀ)^-1
        if Sig is not None:
            H = GtT @ np.swapaxes(Cb[:, t], 1, 2)
            Sig_t = Sig_t + H @ Sig @ np.swapaxes(H, 1, 2)
        Sig = Sig_t
        # the super-block's b frame blocks on its diagonal
        out[:, t * b:(t + 1) * b] = Sig.reshape(Cn, b, k, b, k)[:, frames, :, frames, :].swapaxes(0, 1)
    return out


class single_threaded_blas:
    """Context manager limiting BLAS to one thread if threadpoolctl is available (else a no-op).

    Why: on a small shared machine OpenBLAS worker threads busy-wait for cores held by other
    processes. Measured on this project's 2-core box under load: LSQR on plant 1 3.3 s with default
    threads vs 0.086 s single-threaded; the selected inversion 10 s vs 0.4 s. The matrices here are
    small, so one thread loses nothing when the machine is idle."""

    def __enter__(self):
        try:
            from threadpoolctl import threadpool_limits
        except ImportError:  # optional: correctness does not depend on it
            self._ctx = None
            return self
        self._ctx = threadpool_limits(limits=1, user_api="blas")
        self._ctx.__enter__()
        return self

    def __exit__(self, *exc):
        if self._ctx is not None:
            self._ctx.__exit__(*exc)
        return False


def frame_marginals(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, n_nodes: int,
                    n_frames: int, jacobian: sp.spmatrix | None = None, first_frame: int = 0) -> np.ndarray:
    """(F, 2N, 2N) joint covariance of all nodes at each frame (px²), from GTSAM's linearisation of
    ``graph`` at ``values``. Pass ``jacobian`` (the whitened sparse Jacobian of that linearisation,
    from :func:`whitened_jacobian`) if you already have it. Keys must sort frame-major with 2N
    scalars per frame (frame states, as :func:`rce_gtsam.factors.frame_key` keys them). ``first_frame``:
    the frame number of the first state (a window of a long recording), for error messages."""
    n = 2 * int(n_nodes)
    if int(values.dim()) != n * int(n_frames):
        raise ValueError(f"values hold {values.dim()} scalars, expected 2·{n_nodes}·{n_frames}")
    if jacobian is None:
        jacobian, _ = whitened_jacobian(graph.linearize(values), n_cols=n * n_frames)
    if jacobian.shape[1] != n * n_frames:
        raise ValueError(f"Jacobian has {jacobian.shape[1]} columns, expected {n * n_frames}")
    return banded_selected_inverse((jacobian.T @ jacobian).tocsc(), n, first_frame)
