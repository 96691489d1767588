"""Rank-1 relative compliance: y[e, t] ~ kappa_e * z_t (the fit; its uncertainty is :mod:`.uncertainty`).

kappa_e is the relative compliance of edge e (dimensionless; geometric mean over edges = 1) and z_t the
shared wind excitation (degrees). Fitted by alternating least squares with log-space shrinkage toward
kappa = 1 (kappa = kappa_hat ** (n / (n + lambda)), n = frames with usable excitation) and geometric-mean
normalisation after every kappa step; with per-frame precisions (:func:`frame_precisions`), by generalised
least squares in both steps.

The fit is vectorised over a leading batch axis, so the bootstrap's refits run as one array program.

Two response conventions:
* ``"abs"`` (paper): y = |delta|, z >= 0, kappa > 0;
* ``"signed"``: y = delta, z signed; kappa_e may come out negative (the joint bends against the common
  direction); its magnitude |kappa_e| is the compliance and the sign is reported as ``direction``.

The confidence intervals (moving-block and phase-randomised bootstraps, :class:`BootstrapCI`,
:func:`bootstrap_kappa`) are :mod:`rce_gtsam.model.uncertainty`; the phase surrogates they and the diagnosis
draw (:func:`draw_phases`, :func:`residual_spectrum`, :func:`surrogate_slice`, ...) are
:mod:`rce_gtsam.model.surrogates`. Both were part of this module: their names are still importable from here
(resolved on first use, :func:`__getattr__`), so ``from rce_gtsam.model.compliance import bootstrap_kappa``
keeps working.
"""

from __future__ import annotations

import importlib
import warnings
from dataclasses import dataclass

import numpy as np

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
    k, z, n, it, conv, ch, sh = fit_batch(Y[None], config, None if weights is None else weights[None], precision)
    k, z = k[0], z[0]
    direction = np.where(k < 0, -1.0, 1.0)
    return Rank1Fit(kappa=np.abs(k), direction=direction, z=z, n_used=n[0], shrinkage=sh[0], iterations=int(it[0]),
                    converged=bool(conv[0]), max_log_change=float(ch[0]))


def fit_batch(Yb, config: ComplianceConfig, Wb, precision):
    """One batch of fits: generalised least squares when a precision is given, else (weighted) ALS."""
    if precision is not None:
        return fit_rank1_gls_batch(Yb, config, precision)
    return fit_rank1_batch(Yb, config, Wb)


# Names that moved to :mod:`.uncertainty` and :mod:`.surrogates`, importable from here as before. Resolved on
# first use (PEP 562) rather than imported at the top: :mod:`.uncertainty` imports this module's fit, so an
# eager import would make the two modules' load order matter.
_MOVED = {**{name: "uncertainty" for name in (
    "BootstrapCI", "BOOTSTRAP_CHUNK_ELEMENTS", "block_bootstrap_indices", "iter_block_bootstrap_indices",
    "bootstrap_chunk", "excitation_dof", "small_sample_factor", "bootstrap_kappa", "posterior_widening",
    "interval_about")},
          **{name: "surrogates" for name in (
    "phase_randomised_residuals", "draw_phases", "residual_spectrum", "centred_observed", "surrogate_residuals",
    "surrogate_slice")}}


def __getattr__(name: str):
    """``compliance.<name>`` of a name that moved to :mod:`.uncertainty` or :mod:`.surrogates` (the same object)."""
    module = _MOVED.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__package__}.{module}"), name)


def __dir__() -> list[str]:
    return sorted([*globals(), *_MOVED])
