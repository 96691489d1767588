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

from .errors import RceError


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


def _tridiagonal_blocks(Lam: sp.spmatrix, m: int, T: int) -> tuple[np.ndarray, np.ndarray]:
    """Dense blocks of a block-tridiagonal matrix: ``diag[t] = Λ[t, t]``, ``sub[t] = Λ[t+1, t]`` (m×m)."""
    coo = Lam.tocoo()
    r, c, v = coo.row, coo.col, coo.data
    tr, tc = r // m, c // m
    diag = np.zeros((T, m, m))
    sub = np.zeros((max(T - 1, 0), m, m))
    on = tr == tc
    np.add.at(diag, (tr[on], r[on] % m, c[on] % m), v[on])
    below = tr == tc + 1
    np.add.at(sub, (tc[below], r[below] % m, c[below] % m), v[below])
    if np.any(np.abs(tr - tc) > 1):
        raise ValueError("matrix is not block-tridiagonal in the given block size")
    return diag, sub


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

    Method: b consecutive frames are grouped into one super-block of size m = b·n, which makes Λ
    block-tridiagonal (frames b apart fall in adjacent super-blocks); the last group is padded with
    identity rows, which are decoupled and leave the rest of the inverse unchanged. Then

    * forward block Cholesky:  L_tt = chol(Λ_tt − C_t C_tᵀ),  C_{t+1} = Λ_{t+1,t} L_tt⁻ᵀ;
    * backward Takahashi recursion with G_t = L_tt⁻¹ and H_t = G_tᵀ C_{t+1}ᵀ:
      Σ_{T−1,T−1} = G_{T−1}ᵀ G_{T−1},   Σ_tt = G_tᵀ G_t + H_t Σ_{t+1,t+1} H_tᵀ.

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
    m = b * n
    T = -(-T_frames // b)
    pad = T * m - N_tot
    if pad:
        Lam = sp.block_diag([Lam, sp.identity(pad)], format="csr")
    with single_threaded_blas():
        return _block_tridiagonal_selected_inverse(*_tridiagonal_blocks(Lam, m, T), n, T_frames, b, first_frame)


def _block_tridiagonal_selected_inverse(diag: np.ndarray, sub: np.ndarray, n: int, T_frames: int,
                                        b: int, first_frame: int = 0) -> np.ndarray:
    """The recursions of :func:`banded_selected_inverse`. Memory: ``diag`` and ``sub`` are overwritten
    by L_tt and C_t (no other (T, m, m) array is made); Σ_tt is carried one super-block at a time and
    only its b frame blocks (n x n) are kept."""
    T, m, _ = diag.shape
    L, C = diag, sub             # L[t] = L[t, t] and C[t] = L[t+1, t], in place of Λ's blocks
    for t in range(T):
        S = diag[t] - C[t - 1] @ C[t - 1].T if t > 0 else diag[t]
        try:
            L[t] = np.linalg.cholesky(S)
            # A pivot at rounding level means a direction with (numerically) no information: the
            # "successful" factor would give variances ~1e20. 1e-12 relative to the block's largest
            # diagonal entry is ~1e4 times double-precision rounding.
            if np.min(np.diag(L[t])) ** 2 <= PIVOT_RTOL * np.max(np.diag(S)):
                raise np.linalg.LinAlgError
        except np.linalg.LinAlgError:
            f0 = first_frame + t * b
            raise SingularInformationError(
                f"the smoother's information matrix is singular near frame {f0}: some node position "
                "there is not constrained by any factor") from None
        if t < T - 1:
            # C[t] = sub[t] · L[t]^-T  ⇔  L[t] · C[t]ᵀ = sub[t]ᵀ
            C[t] = scipy.linalg.solve_triangular(L[t], sub[t].T, lower=True, check_finite=False).T
    out = np.empty((T * b, n, n))
    frames = np.arange(b)
    Sig = None
    for t in range(T - 1, -1, -1):
        G = np.linalg.inv(L[t])                           # L_tt^-1 (triangular)
        Sig_t = G.T @ G                                   # G_tᵀ G_t = (L_tt L_ttᵀ)^-1
        if Sig is not None:
            H = G.T @ C[t].T
            Sig_t = Sig_t + H @ Sig @ H.T
        Sig = Sig_t
        # the super-block's b frame blocks on its diagonal
        out[t * b:(t + 1) * b] = Sig.reshape(b, n, b, n)[frames, :, frames, :]
    out = out[:T_frames]
    return 0.5 * (out + np.swapaxes(out, 1, 2))


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
