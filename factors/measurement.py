"""Measurement factor: the tracked positions of the nodes observed at one frame.

Residual (pixels), for every observation j at frame t (node ``i_j``, measurement ``m_j``)::

    r_j = p_{i_j}(t) - m_j                    (2-vector; m = pre-smoothed measurement)
    cost = 0.5 * sum_j r_j^T Sigma_j^-1 r_j   (GTSAM), = w_m * |r|^2 / 2 for Sigma = I / w_m

Jacobian: dr_j/dp_{i_j} = I_2 (zero for every other node).

Noise per observation: isotropic ``sigma`` (the tracker's ``sigma_px`` if given, else 1/sqrt(w_m)),
or anisotropic with ``sigma_across = sigma`` perpendicular to the branch and ``sigma_along = ratio *
sigma`` along it: ``Sigma = R diag(sigma_along^2, sigma_across^2) R^T``, R's first column the branch
tangent. Rationale: a point tracker slides along a thin branch far more easily than across it. The
factor stores the square-root information ``W_j`` (upper triangular, ``W^T W = Sigma^-1``) and works
with whitened residuals ``e_j = W_j r_j``.

Optional robust loss rho (Huber / Cauchy, threshold k in sigmas), applied **per observation**, so a
tracking glitch of one node cannot drag the others at that frame: the factor returns
``e'_j = sqrt(2 rho(|e_j|)) e_j / |e_j|`` so that GTSAM's ``0.5 |e'|^2`` is exactly
``sum_j rho(|e_j|)``, with the exact Jacobian of that map (Triggs et al. 2000, "Bundle adjustment —
a modern synthesis", §6.8; Ceres' loss "corrector"). For |e_j| below k both losses are quadratic to
first order and the factor equals the non-robust one.

GTSAM: without a robust loss, an exact ``LinearContainerFactor(JacobianFactor)`` on the frame state
(C++); with one, a ``CustomFactor`` on the frame state (one Python callback per frame).
"""

from __future__ import annotations

import gtsam
import numpy as np

from ._frame import check_jacobian_shape, linear_container, unit_noise
from ._noise import ROBUST_LOSSES, oriented_covariance


class MeasurementFactor:
    """``p_i(t) = m_i(t)`` for every node observed at frame t, each with its own 2x2 noise."""

    dim = 2  # rows per observation

    @staticmethod
    def residual(p, measured) -> np.ndarray:
        """r = p - m, pixels; broadcasts over leading axes of (..., 2) arrays."""
        return np.asarray(p, dtype=float) - np.asarray(measured, dtype=float)

    @staticmethod
    def jacobians(p, measured) -> tuple[np.ndarray]:
        """(dr/dp,) = (I_2,)."""
        return (np.eye(2),)

    @staticmethod
    def sqrt_information(sigma: float, tangent=None, along_across_ratio: float = 1.0) -> np.ndarray:
        """Upper-triangular ``W`` (2x2, 1/pixels) with ``W^T W = Sigma^-1`` for one observation.

        sigma: 1-sigma position noise across the branch, pixels (> 0).
        tangent: unit-ish 2-vector along the branch at this node (needed if ``along_across_ratio != 1``).
        along_across_ratio: sigma_along / sigma_across (> 0; 1 = isotropic).
        """
        sigma = float(sigma)
        if not sigma > 0 or not np.isfinite(sigma):
            raise ValueError(f"a measurement sigma must be a finite number > 0, got {sigma!r}")
        if along_across_ratio == 1.0 or tangent is None:
            return np.eye(2) / sigma
        cov = oriented_covariance(along_across_ratio * sigma, sigma, tangent)
        return np.linalg.cholesky(np.linalg.inv(cov)).T

    @staticmethod
    def create(key: int, n_nodes: int, node_rows, measured, sqrt_info, zeros: gtsam.Values,
               robust: str | None = None, robust_k: float = 1.345) -> gtsam.NonlinearFactor:
        """The factor for one frame.

        key: the frame state's key; n_nodes: N; node_rows: (k,) rows of the observed nodes;
        measured: (k, 2) pixels; sqrt_info: (k, 2, 2) per-observation ``W`` (or one (2, 2) for all);
        zeros: zero Values for the linear container; robust, robust_k: optional loss and threshold.
        """
        rows = np.asarray(node_rows, dtype=np.int64)
        m = np.asarray(measured, dtype=float).reshape(len(rows), 2)
        W = np.broadcast_to(np.asarray(sqrt_info, dtype=float), (len(rows), 2, 2))
        A = np.zeros((2 * len(rows), 2 * int(n_nodes)))
        out_rows = np.arange(2 * len(rows)).reshape(-1, 2)           # rows 2j, 2j+1 <- observation j
        state_cols = np.stack([2 * rows, 2 * rows + 1], axis=1)       # columns of node i_j
        A[out_rows[:, :, None], state_cols[:, None, :]] = W
        b = np.einsum("kab,kb->ka", W, m).ravel()
        if robust is None:
            return linear_container([key], [A], b, zeros)
        loss = RobustLoss(robust, robust_k)
        N = int(n_nodes)

        def error(this: gtsam.CustomFactor, values: gtsam.Values, H):
            e = (A @ values.atVector(key) - b).reshape(-1, 2)   # whitened residuals, one row per obs
            out, G = loss.correct(e)                           # G: (k, 2, 2) d out_j / d e_j
            if H is not None:
                J = np.einsum("kab,kbc->kac", G, A.reshape(-1, 2, 2 * N)).reshape(-1, 2 * N)
                H[0] = check_jacobian_shape(J, A.shape[0], N)
            return out.ravel()

        return gtsam.CustomFactor(unit_noise(A.shape[0]), [key], error)


class RobustLoss:
    """A robust loss rho(u) of the whitened error norm u, and the residual map that realises it.

    ``correct(e)`` maps whitened residuals e (k, 2) to ``e' = s(u) e/u`` with ``s = sqrt(2 rho(u))``
    and returns their Jacobians ``G = s'(u) n n^T + (s/u)(I - n n^T)`` (n = e/u), so that
    ``0.5 |e'|^2 = rho(u)``. Losses (k = threshold in sigmas, as GTSAM's mEstimator):

    * huber:  rho = u^2/2 for u <= k, k u - k^2/2 beyond;      rho'(u) = min(u, k)
    * cauchy: rho = k^2/2 log(1 + u^2/k^2);                     rho'(u) = u / (1 + u^2/k^2)
    """

    def __init__(self, name: str, k: float):
        if name not in ROBUST_LOSSES:
            raise ValueError(f"robust loss must be None or one of {ROBUST_LOSSES}, got {name!r}")
        k = float(k)
        if not k > 0 or not np.isfinite(k):
            raise ValueError(f"robust threshold k must be a finite number > 0, got {k!r}")
        self.name, self.k = name, k

    def rho(self, u: np.ndarray) -> np.ndarray:
        u, k = np.abs(np.asarray(u, dtype=float)), self.k
        if self.name == "huber":
            return np.where(u <= k, 0.5 * u ** 2, k * u - 0.5 * k ** 2)
        return 0.5 * k ** 2 * np.log1p((u / k) ** 2)

    def rho_prime(self, u: np.ndarray) -> np.ndarray:
        u, k = np.abs(np.asarray(u, dtype=float)), self.k
        if self.name == "huber":
            return np.minimum(u, k)
        return u / (1.0 + (u / k) ** 2)

    def correct(self, e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        e = np.asarray(e, dtype=float)
        u = np.linalg.norm(e, axis=1)
        small = u < 1e-9                       # rho ~ u^2/2 there: the map is the identity
        us = np.where(small, 1.0, u)
        s = np.sqrt(2.0 * self.rho(us))
        ratio = np.where(small, 1.0, s / us)                     # s/u
        slope = np.where(small, 1.0, self.rho_prime(us) / np.where(s > 0, s, 1.0))  # s'(u)
        n = e / us[:, None]
        nnT = n[:, :, None] * n[:, None, :]
        eye = np.eye(2)[None]
        G = np.where(small[:, None, None], eye, slope[:, None, None] * nnT + ratio[:, None, None] * (eye - nnT))
        return e * ratio[:, None], G

