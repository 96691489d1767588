"""Rank-1 relative compliance: y[e, t] ~ kappa_e * z_t.

kappa_e is the relative compliance of edge e (dimensionless; geometric mean over edges = 1) and z_t the
shared wind excitation (degrees). Fitted by alternating least squares with log-space shrinkage toward
kappa = 1 (kappa = kappa_hat ** (n / (n + lambda)), n = frames with usable excitation) and geometric-mean
normalisation after every kappa step. Confidence intervals come from a moving-block bootstrap over
frames that refits everything (all edges at once, so the cross-edge structure is kept).

The fit is vectorised over a leading batch axis, so the bootstrap's refits run as one array program.

Two response conventions:
* ``"abs"`` (paper): y = |delta|, z >= 0, kappa > 0;
* ``"signed"``: y = delta, z signed; kappa_e may come out negative (the joint bends against the common
  direction); its magnitude |kappa_e| is the compliance and the sign is reported as ``direction``.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
from scipy import special  # t and normal quantiles; scipy.stats would add ~0.8 s of import to every run

from ..presets import ComplianceConfig

EPS = 1e-6  # numerical floor of the published fit (kappa, z and denominators)


@dataclass(frozen=True, eq=False)
class Rank1Fit:
    """Result of one rank-1 fit.

    kappa: (E,) relative compliance magnitude (geometric mean 1 over edges with kappa > EPS).
    direction: (E,) +1 / -1, the sign of the fitted gain (always +1 for the ``abs`` response).
    z: (T,) excitation in degrees (>= 0 for ``abs``).
    n_used: (E,) frames with data and |z| > EPS in the final kappa step (the shrinkage's n).
    shrinkage: (E,) the factor s of the final kappa step, log kappa = s log kappa_hat (1 = not shrunk).
    iterations: ALS iterations run; converged: whether the tolerance was met before ``n_iter``.
    max_log_change: the last iteration's max |log kappa change|.
    """

    kappa: np.ndarray
    direction: np.ndarray
    z: np.ndarray
    n_used: np.ndarray
    shrinkage: np.ndarray
    iterations: int
    converged: bool
    max_log_change: float

    def predict(self) -> np.ndarray:
        """(E, T) model prediction kappa_e * direction_e * z_t in degrees."""
        return (self.kappa * self.direction)[:, None] * self.z[None, :]


@dataclass(frozen=True, eq=False)
class BootstrapCI:
    """Percentile bootstrap intervals of kappa.

    low, high: (E,) 2.5th / 97.5th percentiles; samples: (n_boot, E) the resampled kappa (for the
    ``"phase"`` bootstrap already widened about kappa_hat by ``width_factor``, so that their percentiles
    are the interval); block_length: frames per block (0: no blocks); seed: the RNG seed; n_boot: resamples.
    method: ``"block"`` or ``"phase"``. effective_samples: for ``"phase"``, the effective number of
    independent noise samples kappa's error rests on (:func:`excitation_dof`); width_factor: how much the
    resampled log-kappa deviations were widened for it (1 = not at all).
    """

    low: np.ndarray
    high: np.ndarray
    samples: np.ndarray
    block_length: int
    seed: int
    method: str = "block"
    effective_samples: float | None = None
    width_factor: float = 1.0

    @property
    def n_boot(self) -> int:
        return self.samples.shape[0]


def initial_z(Y: np.ndarray, W: np.ndarray) -> np.ndarray:
    """Starting excitation of every fit: the per-frame median over observed edges (mean as fallback; 1 for
    data without any excitation), batched: Y, W (B, E, T) -> (B, T) degrees."""
    masked = np.where(W, Y, np.nan)
    with warnings.catch_warnings():  # frames with no observed edge give NaN ("all-NaN slice"), set to 0 below
        warnings.simplefilter("ignore", RuntimeWarning)
        z = nanmedian_axis1(masked)
        for b in range(z.shape[0]):
            zb = z[b]
            if not np.isfinite(zb).any() or np.nanmax(zb) <= 1e-9:
                z[b] = np.nanmean(masked[b], axis=0)
    z = np.nan_to_num(z, nan=0.0)
    flat = np.abs(z).max(axis=1) <= 1e-9
    z[flat] = 1.0
    return z


def nanmedian_axis1(X: np.ndarray) -> np.ndarray:
    """``np.nanmedian(X, axis=1)`` of a (B, E, T) array, the same numbers (the mean of the two middle
    values for an even count, NaN where a column has none) from one sort: numpy's masked-array path for a
    short axis was a fifth of the bootstrap's time."""
    S = np.sort(X, axis=1)  # NaN last
    n = (~np.isnan(X)).sum(axis=1, keepdims=True)
    h = n // 2
    lo = np.take_along_axis(S, np.where(n % 2 == 1, h, np.maximum(h - 1, 0)), axis=1)[:, 0]
    hi = np.take_along_axis(S, np.minimum(h, X.shape[1] - 1), axis=1)[:, 0]
    return np.where(n[:, 0] > 0, (lo + hi) / 2.0, np.nan)


def _matvec(M: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(B, E, T) @ (B, T) -> (B, E)."""
    return np.matmul(M, v[:, :, None])[:, :, 0]


def _matvec_t(M: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(B, E, T)^T @ (B, E) -> (B, T)."""
    return np.matmul(v[:, None, :], M)[:, 0, :]


class _PrecisionTerms:
    """Products of the data that the precision shrinkage needs, computed once per batch (B, E, T); those
    of the mask alone are (1, E, T) when every resample shares it (``W`` given as (1, E, T))."""

    def __init__(self, Y0: np.ndarray, W: np.ndarray, Wf: np.ndarray):
        Wc = W.astype(float)
        pair = Wc[:, :, 1:] * Wc[:, :, :-1]  # both neighbouring frames observed
        self.WfYY = Wf * Y0 * Y0  # weighted, for the residual variance
        self.WYY, self.WY, self.Wc = Wc * Y0 * Y0, Wc * Y0, Wc  # unweighted, for the autocorrelation
        self.YY1 = Y0[:, :, 1:] * Y0[:, :, :-1] * pair
        self.Ylead, self.Ylag = Y0[:, :, 1:] * pair, Y0[:, :, :-1] * pair
        self.pair = pair

    def take(self, a: np.ndarray) -> "_PrecisionTerms":
        """The rows ``a`` of every per-resample product (shared (1, E, T) ones are kept as they are)."""
        out = object.__new__(_PrecisionTerms)
        shared = self.WY.shape[0] > 1 and self.Wc.shape[0] == 1
        for k, v in vars(self).items():
            setattr(out, k, v if shared and v.shape[0] == 1 else v[a])
        return out


def _precision_shrinkage(terms: _PrecisionTerms, zm, k_hat, num, den, n, tau):
    """(B, E) shrinkage factors tau^2 / (tau^2 + se^2(log kappa_hat)) of a log-normal prior on kappa.

    se^2(kappa_hat) = sigma^2 / sum(w z^2) * (1 + rho) / (1 - rho): the residual variance of the
    per-edge regression y ~ kappa_hat z over the frames used, inflated by the lag-1 autocorrelation rho
    of those residuals (an AR(1) effective sample size: neighbouring frames are not independent); the
    delta method gives se(log kappa_hat) = se(kappa_hat) / |kappa_hat|. ``zm``: (B, T) excitation, 0 on
    frames not used. Every sum of residual products is expanded into mat-vecs of precomputed data
    products, r = y - k z: sum r^2 = sum y^2 - 2k sum yz + k^2 sum z^2, likewise for lag-1 products.
    """
    m = (zm != 0).astype(float)
    k, k2 = k_hat, k_hat * k_hat
    rss_w = _matvec(terms.WfYY, m) - 2 * k * num + k2 * den
    sigma2 = np.maximum(rss_w, 0.0) / np.maximum(n - 1, 1)
    sumsq = _matvec(terms.WYY, m) - 2 * k * _matvec(terms.WY, zm) + k2 * _matvec(terms.Wc, zm * zm)
    mm = m[:, 1:] * m[:, :-1]
    lag = (_matvec(terms.YY1, mm) - k * (_matvec(terms.Ylead, zm[:, :-1] * mm) + _matvec(terms.Ylag, zm[:, 1:] * mm))
           + k2 * _matvec(terms.pair, zm[:, 1:] * zm[:, :-1] * mm))
    rho = np.clip(lag / np.maximum(sumsq, 1e-300), 0.0, 0.99)
    return log_normal_shrinkage(sigma2 / np.maximum(den, EPS), rho, k_hat, tau)


def log_normal_shrinkage(var_k_white, rho, k_hat, tau):
    """tau^2 / (tau^2 + se^2(log kappa_hat)): se^2(kappa_hat) = ``var_k_white`` (its variance for
    independent frames) * (1 + rho) / (1 - rho) (AR(1) effective sample size), and the delta method
    se(log kappa_hat) = se(kappa_hat) / |kappa_hat|."""
    var_k = var_k_white * (1 + rho) / (1 - rho)
    se2_log = var_k / np.maximum(k_hat * k_hat, 1e-300)
    return tau * tau / (tau * tau + se2_log)


def shrink_and_normalise(k_hat, shrink, n, signed: bool):
    """The kappa step's end, shared by every fit (the two rank-1 solvers here and the extended model's
    block-coordinate loop, :func:`rce_gtsam.model.steps.kappa_step`): log|kappa| = shrink * log|kappa_hat|
    (kappa = 1 for an edge without usable frames), then geometric-mean normalisation over edges with
    |kappa| > EPS. All arrays (B, E). Returns (kappa (B, E), big: the edges with |kappa| > EPS, gm (B,):
    the geometric mean divided out)."""
    sign = np.where(k_hat < 0, -1.0, 1.0) if signed else np.ones_like(k_hat)
    mag = np.maximum(np.abs(k_hat) if signed else k_hat, EPS)
    k_new = np.where(n > 0, sign * np.exp(shrink * np.log(mag)), 1.0)
    big = np.abs(k_new) > EPS
    logs = np.where(big, np.log(np.maximum(np.abs(k_new), EPS)), 0.0)
    gm = np.exp(logs.sum(axis=1) / np.maximum(big.sum(axis=1), 1))
    return np.where(big, k_new / gm[:, None], k_new), big, gm


def _log_change(k_new, k_old):
    """(B,) max over edges of |log|k_new| - log|k_old||: the convergence measure of both fits."""
    return np.max(np.abs(np.log(np.maximum(np.abs(k_new), EPS)) - np.log(np.maximum(np.abs(k_old), EPS))), axis=1)


def fit_rank1_batch(Y: np.ndarray, config: ComplianceConfig, weights: np.ndarray | None = None):
    """Fit (B, E, T) data (NaN = missing) as B independent rank-1 problems.

    Returns (kappa_signed (B, E), z (B, T), n_used (B, E), iterations (B,), converged (B,), change (B,),
    shrinkage (B, E): the factor s of the last kappa step, log|kappa| = s log|kappa_hat| (1 = none)).
    """
    signed = config.response == "signed"
    W = np.isfinite(Y)
    Y0 = np.where(W, Y, 0.0)
    B, E, T = Y.shape
    lam = float(config.prior_strength)
    z = initial_z(Y, W)
    # Resamples that share the missing-data mask and the weights (the phase bootstrap's) share the arrays
    # made of them: (1, E, T), broadcast by every mat-vec below (each resample's product is computed
    # exactly as before; one copy instead of B is less memory to stream through)
    shared = B > 1 and not (W != W[:1]).any() and (weights is None or not (
        np.where(W, weights, 0.0) != np.where(W[:1], weights[:1], 0.0)).any())
    if shared:
        W = W[:1]
    Wf = W.astype(float) if weights is None else np.where(W, weights[:1] if shared else weights, 0.0)
    kappa = np.ones((B, E))
    active = np.ones(B, dtype=bool)
    iterations = np.zeros(B, dtype=int)
    converged = np.zeros(B, dtype=bool)
    change = np.full(B, np.inf)
    n_used = np.zeros((B, E))
    shrink_used = np.ones((B, E))
    WY = Wf * Y0  # constant over iterations: every step below is a batched mat-vec (BLAS)
    Wc = W.astype(float)
    precision = config.shrinkage == "precision"
    terms = _PrecisionTerms(Y0, W, Wf) if precision else None
    rows = np.arange(B)  # the resamples the working arrays below hold
    WYa, Wfa, Wca, terms_a = WY, Wf, Wc, terms
    for _ in range(config.n_iter):
        if not active.any():
            break
        a = np.flatnonzero(active)
        # Compute on the working arrays and keep only the active rows' results; copy the active rows
        # out once half of the held ones have converged (each row's fit is independent of the others).
        if 2 * a.size <= rows.size:
            keep = np.searchsorted(rows, a)
            WYa = WYa[keep]
            if not shared:
                Wfa, Wca = Wfa[keep], Wca[keep]
            terms_a = terms_a.take(keep) if precision else None
            rows = a
        full = a.size == rows.size
        keep = np.searchsorted(rows, a)
        za, prev = z[rows], kappa[rows]
        # kappa step over frames with data and usable excitation (|z| > EPS)
        m = (np.abs(za) > EPS).astype(float)
        n = _matvec(Wca, m)
        num = _matvec(WYa, za * m)
        den = np.maximum(_matvec(Wfa, za * za * m), EPS)
        k_hat = num / den
        if precision:
            shrink = _precision_shrinkage(terms_a, za * m, k_hat, num, den, n, float(config.prior_sd_log))
        else:
            shrink = n / (n + lam)
        k_new, big, _ = shrink_and_normalise(k_hat, shrink, n, signed)
        # z step over edges observed at t with |kappa| > EPS
        mk = big.astype(float)
        znum = _matvec_t(WYa, k_new * mk)
        zden = np.maximum(_matvec_t(Wfa, k_new * k_new * mk), EPS)
        z_new = znum / zden
        if not signed:
            z_new = np.maximum(z_new, 0.0)
        z_new = np.where(_matvec_t(Wca, mk) > 0, z_new, 0.0)
        ch = _log_change(k_new, prev)
        if not full:  # results of rows that had already converged are discarded
            shrink = np.broadcast_to(shrink, k_new.shape)[keep]
            k_new, z_new, n, ch = k_new[keep], z_new[keep], n[keep], ch[keep]
        kappa[a], z[a], n_used[a], change[a] = k_new, z_new, n, ch
        shrink_used[a] = np.where(n > 0, shrink, 1.0)
        iterations[a] += 1
        done = ch < config.tol
        converged[a[done]] = True
        active[a[done]] = False
    return kappa, z, n_used, iterations, converged, change, shrink_used


def frame_precisions(covariance: np.ndarray, observed: np.ndarray) -> np.ndarray:
    """(T, E, E) per-frame precision matrices from covariances (T, E, E) and the observed mask (E, T).

    At each frame the covariance of the observed entries is inverted; rows and columns of missing
    entries are zero. Frames are grouped by their observed pattern so each group is one batched
    inverse. A frame whose covariance block is not finite or not positive definite falls back to the
    inverse of its diagonal (plain inverse-variance weights), or to zero where even that is unusable.
    """
    T, E, _ = covariance.shape
    P = np.zeros((T, E, E))
    obs = observed.T  # (T, E)
    patterns, which = np.unique(obs, axis=0, return_inverse=True)
    for g, pattern in enumerate(patterns):
        idx = np.flatnonzero(pattern)
        frames = np.flatnonzero(which.reshape(-1) == g)
        if idx.size == 0:
            continue
        C = covariance[np.ix_(frames, idx, idx)]
        ok = np.isfinite(C).all(axis=(1, 2))
        good = np.zeros(frames.size, dtype=bool)
        if ok.any():
            eig_min = np.linalg.eigvalsh(np.where(ok[:, None, None], C, np.eye(idx.size)))[:, 0]
            good = ok & (eig_min > 0)
        block = np.zeros_like(C)
        if good.any():
            block[good] = np.linalg.inv(C[good])
        bad = ~good
        if bad.any():
            d = np.diagonal(C[bad], axis1=1, axis2=2)
            with np.errstate(divide="ignore", invalid="ignore"):
                inv = np.where(np.isfinite(d) & (d > 0), 1.0 / d, 0.0)
            block[bad] = inv[:, :, None] * np.eye(idx.size)
        P[np.ix_(frames, idx, idx)] = block
    return P


def _apply_precision(P: np.ndarray, V: np.ndarray) -> np.ndarray:
    """(B, T, E) -> (B, T, E): P_t v_bt. A shared (T, E, E) precision is applied as T matmuls of
    (E, E) @ (E, B), which BLAS does far faster than B*T tiny mat-vecs; a per-resample (B, T, E, E) one
    as mat-vecs."""
    if P.ndim == 3:
        return np.transpose(np.matmul(P, np.transpose(V, (1, 2, 0))), (2, 0, 1))
    return np.matmul(P, V[..., None])[..., 0]


def _gls_shrinkage(P, Y0, W, z, k_hat, A_inv_diag, tau):
    """(B, E) precision-shrinkage factors for the correlated fit: se^2(kappa_hat_e) = [A^-1]_ee
    * sigma^2 * (1 + rho_e) / (1 - rho_e), A = sum_t z_t^2 P_t, sigma^2 the reduced chi-square
    sum_t r_t' P_t r_t / (observations - E - frames), rho_e the lag-1 autocorrelation of edge e's
    residuals (as in :func:`_precision_shrinkage`)."""
    R = (Y0 - k_hat[:, :, None] * z[:, None, :]) * W  # (B, E, T)
    Rt = np.transpose(R, (0, 2, 1))  # (B, T, E)
    chi2 = np.sum(Rt * _apply_precision(P, Rt), axis=(1, 2))
    used = np.abs(z) > EPS
    dof = np.maximum(np.sum(W * used[:, None, :], axis=(1, 2)) - k_hat.shape[1] - used.sum(axis=1), 1)
    sigma2 = np.maximum(chi2, 0.0) / dof
    lag = np.sum(R[:, :, 1:] * R[:, :, :-1], axis=2)
    rho = np.clip(lag / np.maximum(np.sum(R * R, axis=2), 1e-300), 0.0, 0.99)
    return log_normal_shrinkage(A_inv_diag * sigma2[:, None], rho, k_hat, tau)


def fit_rank1_gls_batch(Y: np.ndarray, config: ComplianceConfig, precision: np.ndarray):
    """:func:`fit_rank1_batch` with correlated errors: generalised least squares in both steps.

    ``precision``: (T, E, E) shared by the batch or (B, T, E, E), the per-frame inverse covariance of the
    observed entries (zero for missing ones; see :func:`frame_precisions`). The kappa step minimises
    sum_t (y_t - kappa z_t)' P_t (y_t - kappa z_t) over all edges jointly: A kappa = b with
    A = sum_t z_t^2 P_t, b = sum_t z_t P_t y_t. The z step is z_t = kappa' P_t y_t / kappa' P_t kappa.
    Shrinkage and normalisation as in the uncorrelated fit. Same return values.
    """
    B, E, T = Y.shape
    if config.response != "signed":
        raise ValueError("the correlated fit needs the signed response (the covariance of |delta| between "
                         "bends depends on signs the fit does not know)")
    P = np.asarray(precision, dtype=float)
    if P.shape[-3:] != (T, E, E) or P.ndim not in (3, 4):
        raise ValueError(f"precision has shape {P.shape}; expected (T, E, E) = ({T}, {E}, {E})")
    W = np.isfinite(Y)
    Y0 = np.where(W, Y, 0.0)
    Wc = W.astype(float)
    Pflat = P.reshape(P.shape[:-2] + (E * E,))  # (..., T, E*E)
    PY = _apply_precision(P, np.transpose(Y0, (0, 2, 1)))  # (B, T, E): P_t y_t, fixed over iterations
    lam, tau = float(config.prior_strength), float(config.prior_sd_log)
    z = initial_z(Y, W)
    kappa = np.ones((B, E))
    n_used = np.zeros((B, E))
    shrink = np.ones((B, E))
    iterations = np.zeros(B, dtype=int)
    converged = np.zeros(B, dtype=bool)
    change = np.full(B, np.inf)
    eye = np.eye(E)
    for _ in range(config.n_iter):
        a = np.flatnonzero(~converged)
        if a.size == 0:
            break
        Pa, Pfa = (P, Pflat) if P.ndim == 3 else (P[a], Pflat[a])
        Y0a, Wa, PYa = Y0[a], W[a], PY[a]
        zm = np.where(np.abs(z[a]) > EPS, z[a], 0.0)
        n = _matvec(Wc[a], (zm != 0).astype(float))
        A = np.matmul((zm * zm)[:, None, :], Pfa)[:, 0].reshape(a.size, E, E)
        b = np.einsum("bt,bte->be", zm, PYa)
        A = A + (1e-9 * np.maximum(np.trace(A, axis1=1, axis2=2) / E, EPS))[:, None, None] * eye
        k_hat = np.linalg.solve(A, b[..., None])[..., 0]
        if config.shrinkage == "precision":
            A_inv_diag = np.diagonal(np.linalg.inv(A), axis1=1, axis2=2)
            s = _gls_shrinkage(Pa, Y0a, Wa, zm, k_hat, A_inv_diag, tau)
        else:
            s = n / (n + lam)
        k_new, big, _ = shrink_and_normalise(k_hat, s, n, signed=True)
        km = k_new * big
        kPk = np.matmul(Pfa, (km[:, :, None] * km[:, None, :]).reshape(a.size, E * E, 1))[..., 0]  # (b, T)
        kPy = np.einsum("be,bte->bt", km, PYa)
        z_new = np.where(kPk > EPS, kPy / np.maximum(kPk, EPS), 0.0)
        ch = _log_change(k_new, kappa[a])
        kappa[a], z[a], n_used[a], change[a] = k_new, z_new, n, ch
        shrink[a] = np.where(n > 0, s, 1.0)
        iterations[a] += 1
        converged[a] = ch < config.tol
    return kappa, z, n_used, iterations, converged, change, shrink


def fit_rank1(Y: np.ndarray, config: ComplianceConfig, weights: np.ndarray | None = None,
              precision: np.ndarray | None = None) -> Rank1Fit:
    """Fit y[e, t] ~ kappa_e z_t to ``Y`` (E, T) in degrees, NaN = missing.

    ``weights`` (E, T) >= 0 turns the least-squares steps into weighted ones (e.g. 1 / angle variance);
    ``precision`` (T, E, E), per-frame inverse covariances (:func:`frame_precisions`), into generalised
    least squares that also uses the correlation between rows (it takes precedence over ``weights``).
    """
    Y = np.asarray(Y, dtype=float)
    k, z, n, it, conv, ch, sh = _fit_batch(Y[None], config, None if weights is None else weights[None], precision)
    k, z = k[0], z[0]
    direction = np.where(k < 0, -1.0, 1.0)
    return Rank1Fit(kappa=np.abs(k), direction=direction, z=z, n_used=n[0], shrinkage=sh[0], iterations=int(it[0]),
                    converged=bool(conv[0]), max_log_change=float(ch[0]))


def _fit_batch(Yb, config: ComplianceConfig, Wb, precision):
    """One batch of fits: generalised least squares when a precision is given, else (weighted) ALS."""
    if precision is not None:
        return fit_rank1_gls_batch(Yb, config, precision)
    return fit_rank1_batch(Yb, config, Wb)


def block_bootstrap_indices(n_columns: int, block_length: int, n_boot: int,
                            rng: np.random.Generator) -> np.ndarray:
    """(n_boot, T) column indices of non-circular moving-block resamples.

    Block starts are drawn uniformly from 0..T-L; blocks of L consecutive columns are concatenated
    until at least T indices, then truncated to T.
    """
    parts = list(iter_block_bootstrap_indices(n_columns, block_length, n_boot, rng, max(n_boot, 1)))
    return parts[0] if parts else np.empty((0, n_columns), dtype=int)


def iter_block_bootstrap_indices(n_columns: int, block_length: int, n_boot: int, rng: np.random.Generator,
                                 chunk: int):
    """:func:`block_bootstrap_indices` streamed: yields (<= chunk, T) pieces of the same array (the same
    random draws in the same order), so a long recording never holds all (n_boot, T) indices."""
    T = n_columns
    L = max(3, min(block_length, T))
    n_blocks = int(np.ceil(T / L))
    for s in range(0, n_boot, chunk):
        out = np.empty((min(chunk, n_boot - s), T), dtype=int)
        for b in range(out.shape[0]):
            starts = rng.integers(0, T - L + 1, size=n_blocks)
            out[b] = (starts[:, None] + np.arange(L)[None, :]).ravel()[:T]
        yield out


#: Largest resampled batch the bootstrap refits at once, in array elements per (B, E, T) array
#: (float64: 8 MB; the fit holds about fifteen such arrays). Fewer resamples are batched on long
#: recordings: 64 up to E x T = 16,384 (e.g. 20 segments x 800 frames), 1 at 18 x 50,000. The resamples
#: and their random draws do not depend on the batch size.
BOOTSTRAP_CHUNK_ELEMENTS = 2 ** 20


def bootstrap_chunk(chunk: int, n_edges: int, n_frames: int, per_resample_precision: bool = False) -> int:
    """Resamples per batch: ``chunk``, fewer where a batch would exceed :data:`BOOTSTRAP_CHUNK_ELEMENTS`
    (a per-resample (T, E, E) precision counts too), at least 1."""
    per = n_edges * n_frames * (1 + (n_edges if per_resample_precision else 0))
    return max(1, min(int(chunk), BOOTSTRAP_CHUNK_ELEMENTS // max(per, 1)))


def phase_randomised_residuals(R: np.ndarray, n_boot: int, rng: np.random.Generator) -> np.ndarray:
    """(n_boot, E, T) resampled zero-mean residual series of an (E, T) residual matrix R (NaN = 0).

    Multivariate Fourier surrogates (Prichard & Theiler 1994): the rows (means removed) are Fourier
    transformed, every frequency's phase is shifted by one random angle shared by all rows, and the
    result is transformed back. Each row keeps its periodogram, so its (circular) autocovariance at every
    lag, and every pair of rows keeps its cross-spectrum, so the anti-correlated noise of bends that share
    a tracked node stays; only the phases, i.e. *when* the noise happens, are new. That is the structure
    a drifting tracker leaves: correlated over seconds, longer than any usable frame block.

    The mean of a residual row is a noise sample too (slow drift does not average out over a clip, and it
    enters kappa through the excitation's mean): the surrogate's mean is drawn with the spectrum at the
    lowest non-zero frequency as its variance, sqrt(2) Re(F_1 exp(i phi_0)), jointly across rows.
    """
    return surrogate_residuals(residual_spectrum(R), R.shape[1], *draw_phases(rng, n_boot, R.shape[1]))


def draw_phases(rng: np.random.Generator, n_boot: int, n_frames: int) -> tuple[np.ndarray, np.ndarray | None]:
    """The random draws of :func:`phase_randomised_residuals` for ``n_boot`` surrogates of ``n_frames``:
    (n_boot, K) phases of the K = T // 2 + 1 frequencies, then (n_boot, 1) phases of the mean (radians)."""
    K = n_frames // 2 + 1
    phase = rng.uniform(0.0, 2 * np.pi, size=(n_boot, K))
    dc_phase = rng.uniform(0.0, 2 * np.pi, size=(n_boot, 1)) if K > 1 else None
    return phase, dc_phase


def residual_spectrum(R: np.ndarray) -> np.ndarray:
    """(E, K) Fourier transform of the rows of R (E, T; NaN = missing): each row's mean over its observed
    frames removed, missing frames set to 0, and the row scaled by sqrt(T / n_observed).

    Why the scale: every caller masks its surrogates again where R is missing. A zero-filled row's power is
    spread by the phase randomisation over all T frames, so the n_observed frames that stay would carry only
    n_observed / T of the row's power per frame, a null narrower than the noise it stands for (and a mean taken
    over the zeros too left the filled frames a step of their own). The pipeline leaves a median 6.4 % of the
    simulator's segment-frames missing (default preset, 900 frames); the second excitation's test between
    node-disjoint sets gave p <= 0.05 on 6 of 80 effect-free recordings (1 at 0.005) before, 4 (0) with the
    scale. A recording without missing frames gets the same surrogates as before."""
    R = np.asarray(R, float)
    n_obs = np.isfinite(R).sum(axis=1, keepdims=True)
    return np.fft.rfft(centred_observed(R) * np.sqrt(R.shape[1] / np.maximum(n_obs, 1)), axis=1)


def centred_observed(R: np.ndarray) -> np.ndarray:
    """(E, T) rows of R (NaN = missing) less each row's mean over its observed frames, 0 where missing: the
    zero-filled series a Fourier transform of residuals with gaps starts from (a mean taken over the filled
    zeros too would leave the observed frames an offset and the gaps a step of their own). Units: those of R."""
    R = np.asarray(R, float)
    observed = np.isfinite(R)
    n_obs = np.maximum(observed.sum(axis=1, keepdims=True), 1)
    mean = np.where(observed, R, 0.0).sum(axis=1, keepdims=True) / n_obs
    return np.where(observed, R - mean, 0.0)


def surrogate_residuals(F: np.ndarray, n_frames: int, phase: np.ndarray, dc_phase: np.ndarray | None) -> np.ndarray:
    """(len(phase), E, T) surrogates from a :func:`residual_spectrum` and :func:`draw_phases` draws
    (any subset of their rows)."""
    T, K = n_frames, F.shape[1]
    Fs = F[None] * np.exp(1j * phase)[:, None, :]
    if K > 1:
        Fs[:, :, 0] = math.sqrt(2.0) * np.real(F[None, :, 1] * np.exp(1j * dc_phase))
    if T % 2 == 0 and K > 1:
        Fs[:, :, -1] = np.real(Fs[:, :, -1]) * math.sqrt(2.0)  # the Nyquist term must stay real
    return np.fft.irfft(Fs, n=T, axis=2)


def surrogate_slice(F: np.ndarray, n_frames: int, draws: tuple, sl: slice) -> np.ndarray:
    """:func:`surrogate_residuals` for the surrogates ``sl`` of one :func:`draw_phases` result ``draws`` (its
    phases and mean phases, the latter None for a single frame): how the batched callers take a slice."""
    phase, dc_phase = draws
    return surrogate_residuals(F, n_frames, phase[sl], None if dc_phase is None else dc_phase[sl])


def excitation_dof(R: np.ndarray, z: np.ndarray) -> float:
    """Effective number of independent noise samples that kappa's error rests on (>= 1).

    kappa_hat_e - kappa_e = sum_t n_e(t) z_t / sum_t z_t^2 weighs the noise n_e at each frequency f by the
    excitation's power |Z(f)|^2 there, so its variance is a sum over frequencies of w(f) = S_n(f) |Z(f)|^2.
    When a few frequencies carry that sum (wind excitation is concentrated at the lowest frequencies, and
    so is tracker drift), it is an average of few independent terms: n_eff = (sum w)^2 / sum w^2 (a
    Satterthwaite count; w from the residual periodograms summed over edges, the mean excluded: those of
    :func:`residual_spectrum`, the spectrum the surrogates are drawn from).
    Measured (default preset): 2.1 on plant 2, 4.0 on plant 1.
    """
    S = (np.abs(residual_spectrum(R)) ** 2).sum(axis=0)
    if len(S) > 1:
        S[0] = S[1]  # the residual mean's noise power: the spectrum at the lowest frequency (as resampled)
    w = S * np.abs(np.fft.rfft(np.asarray(z, float))) ** 2
    tot = float(w.sum())
    if not np.isfinite(tot) or tot <= 0:
        return float(len(w)) if len(w) else 1.0
    return max(1.0, tot * tot / float((w * w).sum()))


def small_sample_factor(n_eff: float, level: float = 0.95) -> float:
    """Widening of bootstrap log-kappa deviations for an error that rests on ``n_eff`` noise samples.

    The resampled spread is an estimate from the residuals' periodogram; where n_eff frequencies carry
    kappa's error it has about nu = 2 n_eff degrees of freedom (each frequency's periodogram ordinate is
    a chi-square with 2), so an interval from it needs Student-t quantiles instead of normal ones:
    t_nu(q) / z(q), q = (1 + level) / 2, nu floored at 1. It tends to 1 for broadband excitation.
    """
    nu = max(2.0 * float(n_eff), 1.0)
    q = 0.5 * (1.0 + level)
    return float(special.stdtrit(nu, q)) / float(special.ndtri(q))


def bootstrap_kappa(Y: np.ndarray, config: ComplianceConfig, weights: np.ndarray | None = None,
                    chunk: int = 64, fit: Rank1Fit | None = None,
                    precision: np.ndarray | None = None) -> BootstrapCI | None:
    """Bootstrap of the whole rank-1 fit; None when n_boot = 0 or T < 8 frames.

    ``config.bootstrap == "block"``: moving blocks of frames of the data, refitted. ``"phase"``: the
    fitted model (``fit``; computed here when not given) plus phase-randomised residuals
    (:func:`phase_randomised_residuals`), refitted; each edge's resampled log-kappa deviations (from their
    median) are widened by :func:`small_sample_factor` of :func:`excitation_dof` and by 1 / sqrt(s_e)
    for an edge shrunk by s_e, then put around kappa_hat.

    Calibration with a known truth. Spread of log kappa over 30 noise draws / mean resampled spread
    before widening (12 edges, AR(1) noise of correlation time tau, the simulator's excitation): tau = 60
    frames (2-s drift): block 2.05, phase 1.02-1.06; white: block 1.04, phase 1.13. Through the whole
    pipeline on simulated tracks (20 seeds, 900 frames, 250 resamples), share of edges whose 95 %
    interval covers kappa_true: block 82.8 %, phase 91.1 % (seeds 0-19); block 75.6 %, phase 86.4 %
    (seeds 100-119).
    """
    E, T = Y.shape
    if config.n_boot <= 0 or T < 8:
        return None
    if config.bootstrap == "phase":
        if fit is None:
            fit = fit_rank1(Y, config, weights, precision)
        return _phase_bootstrap(Y, config, weights, chunk, fit, precision)
    return _block_bootstrap(Y, config, weights, chunk, precision)


def _block_bootstrap(Y, config: ComplianceConfig, weights, chunk: int, precision=None) -> BootstrapCI:
    """Moving blocks of ``config.block_length`` frames of the data, every resample refitted; the
    resamples are drawn and refitted in batches of :func:`bootstrap_chunk` (memory bounded in T)."""
    E, T = Y.shape
    rng = np.random.default_rng(config.seed)
    chunk = bootstrap_chunk(chunk, E, T, per_resample_precision=precision is not None)
    samples = np.empty((config.n_boot, E))
    s = 0
    for cols in iter_block_bootstrap_indices(T, config.block_length, config.n_boot, rng, chunk):
        Yb = np.transpose(Y[:, cols], (1, 0, 2))
        Wb = None if weights is None else np.transpose(weights[:, cols], (1, 0, 2))
        Pb = None if precision is None else precision[cols]
        samples[s:s + len(cols)] = np.abs(_fit_batch(Yb, config, Wb, Pb)[0])
        s += len(cols)
    low, high = np.percentile(samples, [2.5, 97.5], axis=0)
    return BootstrapCI(low=low, high=high, samples=samples,
                       block_length=max(3, min(config.block_length, T)), seed=config.seed)


def _phase_bootstrap(Y, config: ComplianceConfig, weights, chunk: int, fit: Rank1Fit, precision=None) -> BootstrapCI:
    """The fit plus phase-randomised residuals, refitted; deviations widened (see :func:`bootstrap_kappa`)."""
    if config.response != "signed":
        raise ValueError("the phase-randomised bootstrap needs the signed response (|delta| residuals "
                         "are not a zero-mean series)")
    E, T = Y.shape
    rng = np.random.default_rng(config.seed)
    batch = bootstrap_chunk(chunk, E, T)
    mask = np.isfinite(Y)
    pred = fit.predict()
    R = np.where(mask, Y - pred, np.nan)
    samples = np.empty((config.n_boot, E))
    spectrum = residual_spectrum(R)
    # phases are drawn ``chunk`` resamples at a time (so the random stream, and the result, do not depend
    # on the recording's length); the surrogates are made and refitted ``batch`` at a time
    for s in range(0, config.n_boot, chunk):
        draws = draw_phases(rng, min(chunk, config.n_boot - s), T)
        for b in range(0, len(draws[0]), batch):
            Yb = pred[None] + surrogate_slice(spectrum, T, draws, slice(b, b + batch))
            Yb[:, ~mask] = np.nan
            Wb = None if weights is None else np.broadcast_to(weights, Yb.shape)
            samples[s + b:s + b + len(Yb)] = np.abs(_fit_batch(Yb, config, Wb, precision)[0])
    n_eff = excitation_dof(R, fit.z)
    factor = small_sample_factor(n_eff)
    # deviations from the resamples' own median: data made from an already shrunk kappa_hat and shrunk
    # again sit further toward 1; that offset is the estimator's, not kappa's, uncertainty
    low, high, samples = interval_about(fit.kappa, samples, factor * posterior_widening(fit.shrinkage))
    return BootstrapCI(low=low, high=high, samples=samples, block_length=0, seed=config.seed,
                       method="phase", effective_samples=n_eff, width_factor=factor)


def posterior_widening(shrinkage: np.ndarray) -> np.ndarray:
    """(E,) 1 / sqrt(s_e) for edges shrunk by s_e: a shrunk estimate s log kappa_hat varies s times as much as
    log kappa_hat, while the posterior of the log-normal prior it comes from has sqrt(s) times its spread
    (1 for well-measured edges; a stiff edge buried in noise is pulled toward 1 and gets the prior's width)."""
    return 1.0 / np.sqrt(np.clip(shrinkage, 1e-6, 1.0))


def interval_about(kappa_hat: np.ndarray, samples: np.ndarray, scale) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """95 % interval of kappa from resampled estimates, placed about the estimate ``kappa_hat`` (E,).

    Each edge's resampled log-kappa deviations from the resamples' own median (data made from an already
    shrunk kappa_hat and shrunk again sit further toward 1: that offset is the estimator's, not kappa's,
    uncertainty) are multiplied by ``scale`` (scalar or (E,)) and put around kappa_hat. The median deviation
    is 0, so the interval always contains kappa_hat. Returns (low (E,), high (E,), the placed samples
    (n_boot, E))."""
    dev = np.log(np.maximum(samples, EPS))
    dev -= np.median(dev, axis=0)
    placed = np.maximum(kappa_hat, EPS) * np.exp(scale * dev)
    low, high = np.percentile(placed, [2.5, 97.5], axis=0)
    return low, high, placed

