"""Noise-model helpers shared by the factor classes.

Convention: a weight ``w`` multiplies a squared residual in the paper's cost (``w * r**2``); in GTSAM
this is a Gaussian with sigma = 1/sqrt(w) in the residual's units (pixels here). GTSAM's error is
``0.5 * ||r||^2_Sigma``, i.e. half the paper cost for every factor alike, so the minimiser is the same.
"""

from __future__ import annotations

import math

import gtsam
import numpy as np

#: Paper §2.2: the measurement weight is floored at 1e-9 before the square root (so a zero weight
#: gives a huge but finite sigma instead of a division by zero).
MEASUREMENT_WEIGHT_FLOOR = 1e-9

ROBUST_LOSSES = ("huber", "cauchy")


def sigma_from_weight(weight: float) -> float:
    """sigma = 1/sqrt(w) for a weight ``w > 0`` (cost ``w * r**2``)."""
    weight = float(weight)
    if not weight > 0 or not math.isfinite(weight):
        raise ValueError(f"a factor weight must be a finite number > 0, got {weight!r}")
    return 1.0 / math.sqrt(weight)


def isotropic(dim: int, sigma: float) -> gtsam.noiseModel.Base:
    """Isotropic Gaussian noise model of dimension ``dim`` with standard deviation ``sigma``."""
    return gtsam.noiseModel.Isotropic.Sigma(int(dim), float(sigma))


def oriented_covariance(sigma_along: float, sigma_across: float, tangent) -> np.ndarray:
    """2x2 covariance ``R diag(sigma_along^2, sigma_across^2) R^T`` with R's first column = unit ``tangent``."""
    t = np.asarray(tangent, dtype=float)
    t = t / np.linalg.norm(t)
    R = np.array([[t[0], -t[1]], [t[1], t[0]]])
    return R @ np.diag([sigma_along ** 2, sigma_across ** 2]) @ R.T
