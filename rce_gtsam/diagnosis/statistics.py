"""Residual statistics shared by the effects' evidence (:meth:`rce_gtsam.effects.Effect.evidence`).

:class:`ResidualContext` is what an effect sees of the rank-1 baseline: its residuals, kappa, z and the
segments' root distances, plus the AR(1) variance inflation of serially correlated residuals. The helpers
are small NaN-aware regressions with standard errors. The series statistics (autocorrelation, the test of two
loss series) live in :mod:`rce_gtsam.model.series`, where the engine's choice between starts uses them too.
Units: degrees, frames.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def ar1_inflation(R: np.ndarray) -> float:
    """(1 + rho) / (1 - rho) for the pooled lag-1 autocorrelation rho >= 0 (clipped at 0.98) of the residuals."""
    a, b = R[:, :-1], R[:, 1:]
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 3:
        return 1.0
    rho = float(np.sum(a[ok] * b[ok]) / max(np.sqrt(np.sum(a[ok] ** 2) * np.sum(b[ok] ** 2)), 1e-300))
    rho = min(max(rho, 0.0), 0.98)
    return (1 + rho) / (1 - rho)


def per_edge_regression(R: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-row least-squares slope of residual rows R on regressor rows X (NaN-aware): (coef (E,), se (E,))."""
    ok = np.isfinite(R) & np.isfinite(X)
    Xo, Ro = np.where(ok, X, 0.0), np.where(ok, R, 0.0)
    sxx = np.sum(Xo * Xo, axis=1)
    coef = np.sum(Xo * Ro, axis=1) / np.maximum(sxx, 1e-300)
    res = Ro - coef[:, None] * Xo
    n = ok.sum(axis=1)
    s2 = np.sum(np.where(ok, res * res, 0.0), axis=1) / np.maximum(n - 1, 1)
    return coef, np.sqrt(s2 / np.maximum(sxx, 1e-300))


def slope_vs(x: np.ndarray, v: np.ndarray, se: np.ndarray) -> tuple[float, float, float]:
    """Weighted LS slope of v on x (weights 1/se^2), its t statistic (the residual variance at least the
    nominal one) and the Pearson correlation."""
    w = 1.0 / np.maximum(se, 1e-12) ** 2
    ok = np.isfinite(v) & np.isfinite(w)
    x, v, w = x[ok], v[ok], w[ok]
    if len(x) < 3 or np.ptp(x) <= 0:
        return 0.0, 0.0, 0.0
    xm, vm = np.sum(w * x) / w.sum(), np.sum(w * v) / w.sum()
    sxx = np.sum(w * (x - xm) ** 2)
    slope = np.sum(w * (x - xm) * (v - vm)) / sxx
    res = v - vm - slope * (x - xm)
    s2 = max(np.sum(w * res * res) / max(len(x) - 2, 1), 1.0)
    t = slope / math.sqrt(s2 / sxx)
    r = float(np.corrcoef(x, v)[0, 1]) if np.std(v) > 0 else 0.0
    return float(slope), float(t), r


@dataclass(frozen=True, eq=False)
class ResidualContext:
    """What an effect's evidence sees of the rank-1 baseline fit.

    R: (E, T) residuals (deg, NaN = missing); kappa: (E,); z: (T,) deg; s: (E,) root distance 0..1;
    inflation: AR(1) variance inflation of the residuals (multiply naive variances by it)."""

    R: np.ndarray
    kappa: np.ndarray
    z: np.ndarray
    s: np.ndarray
    inflation: float

    @classmethod
    def from_fit(cls, fit) -> "ResidualContext":
        R = fit.residuals
        return cls(R=R, kappa=fit.kappa, z=fit.z, s=fit.root_distance, inflation=ar1_inflation(R))


def difference_covariance(R: np.ndarray) -> np.ndarray:
    """(E, E) covariance between the rows of a residual matrix R (E, T; degrees, NaN = missing) of their
    frame-to-frame differences (deg^2; pairwise over frames where both rows have both frames): the fast
    tracking noise, and how a node's error reaches the bends beside it."""
    D = np.diff(R, axis=1)
    ok = np.isfinite(D)
    D0 = np.where(ok, D, 0.0)
    n = ok.astype(float) @ ok.T.astype(float)
    return (D0 @ D0.T) / np.maximum(n, 1.0)


def noise_correlation(R: np.ndarray, shrink: float = 0.05) -> np.ndarray:
    """(E, E) correlation between edges of the noise in a residual matrix R (E, T), NaN = missing.

    From frame-to-frame differences (:func:`difference_covariance`), shrunk by ``shrink`` toward the identity
    so that it stays well conditioned with few frames."""
    E = R.shape[0]
    C = difference_covariance(R)
    d = np.sqrt(np.clip(np.diag(C), 1e-300, None))
    corr = C / np.outer(d, d)
    corr[~np.isfinite(corr)] = 0.0
    np.fill_diagonal(corr, 1.0)
    corr = (1 - shrink) * corr + shrink * np.eye(E)
    vals, vecs = np.linalg.eigh(0.5 * (corr + corr.T))
    return (vecs * np.clip(vals, 1e-3, None)) @ vecs.T
