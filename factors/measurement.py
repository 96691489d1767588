"""Measurement factor: a prior on one node position at one observed frame.

Residual (pixels)::

    r = p_i(t) - m_i(t)                      (2-vector; m = pre-smoothed measurement)
    cost = 0.5 * r^T Sigma^-1 r               (GTSAM), = w_m * |r|^2 / 2 for Sigma = I / w_m

Jacobian: dr/dp = I_2.

Noise: isotropic ``sigma`` (the tracker's ``sigma_px`` if given, else 1/sqrt(w_m)), or anisotropic
with ``sigma_across = sigma`` perpendicular to the branch and ``sigma_along = ratio * sigma`` along
it: ``Sigma = R diag(sigma_along^2, sigma_across^2) R^T``, R's first column the branch tangent.
Rationale: a point tracker slides along a thin branch far more easily than across it.
Optionally wrapped in a robust M-estimator (Huber / Cauchy) so a tracking glitch cannot drag the
smoothed trajectory.

GTSAM: ``PriorFactorPoint2`` (C++), so the optimiser never calls back into Python.
"""

from __future__ import annotations

import gtsam
import numpy as np

from ._noise import isotropic, oriented_covariance, robustify


class MeasurementFactor:
    """Prior ``p_i(t) = m_i(t)`` with a 2x2 (optionally robust) noise model."""

    dim = 2

    @staticmethod
    def residual(p, measured) -> np.ndarray:
        """r = p - m, pixels; broadcasts over leading axes of (..., 2) arrays."""
        return np.asarray(p, dtype=float) - np.asarray(measured, dtype=float)

    @staticmethod
    def jacobians(p, measured) -> tuple[np.ndarray]:
        """(dr/dp,) = (I_2,)."""
        return (np.eye(2),)

    @staticmethod
    def noise_model(sigma: float, tangent=None, along_across_ratio: float = 1.0,
                    robust: str | None = None, robust_k: float = 1.345) -> gtsam.noiseModel.Base:
        """Noise model for one observation.

        sigma: 1-sigma position noise across the branch, pixels.
        tangent: unit-ish 2-vector along the branch at this node (needed if ``along_across_ratio != 1``).
        along_across_ratio: sigma_along / sigma_across (>= 0; 1 = isotropic).
        robust, robust_k: optional M-estimator name and its threshold in sigmas.
        """
        if along_across_ratio == 1.0 or tangent is None:
            base = isotropic(2, sigma)
        else:
            cov = oriented_covariance(along_across_ratio * sigma, sigma, tangent)
            base = gtsam.noiseModel.Gaussian.Covariance(cov)
        return robustify(base, robust, robust_k)

    @staticmethod
    def create(key: int, measured, noise: gtsam.noiseModel.Base) -> gtsam.PriorFactorPoint2:
        """The GTSAM factor on variable ``key`` (a Point2) with measurement ``measured`` (px)."""
        return gtsam.PriorFactorPoint2(key, np.asarray(measured, dtype=float), noise)
