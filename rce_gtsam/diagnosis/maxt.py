"""Family-wise test of several candidates' held-out gains by sign flips of the folds (Westfall-Young max-T).

Each candidate c has, per cross-validation fold k, the log ratio d_ck = log(MSE_baseline,k / MSE_c,k) (> 0: the
candidate predicts the fold's held-out frames better). Without an effect the folds' d_ck are symmetric about a
value <= 0 (an extra term only costs on new frames), whatever their spread, and folds are independent (the
buffers of the hv-block scheme see to that). Flipping the sign of whole folds — the same flip for every
candidate, so their correlation (delay and dynamics fit the same lag) is kept — gives the null distribution of
the largest paired t over candidates; a candidate is significant when its own t exceeds the (1 - alpha)
quantile of that maximum. The family-wise false-alarm rate is then <= alpha exactly (up to the flips'
granularity, 1 / 2^K), where a Bonferroni t quantile is both approximate (normal folds) and conservative for
correlated candidates. Units: none (t statistics, probabilities).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from .result import TestResult


@dataclass(frozen=True)
class MaxTResult:
    """t: (C,) each candidate's paired t over folds; p_adjusted: (C,) family-wise p-values (share of flips whose
    largest t reaches the candidate's); critical_t: the (1 - alpha) quantile of the largest t over flips;
    n_flips: sign patterns used (all 2^K up to ``max_flips``, else a seeded sample)."""

    t: np.ndarray
    p_adjusted: np.ndarray
    critical_t: float
    n_flips: int


def fold_t(D: np.ndarray) -> np.ndarray:
    """Paired t of each row of D (C, K) against zero (inf where the row is constant and positive)."""
    K = D.shape[1]
    mean = D.mean(axis=1)
    sd = D.std(axis=1, ddof=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = mean / (sd / math.sqrt(K))
    return np.where(sd > 0, t, np.where(mean > 0, np.inf, 0.0))


def sign_flip_max_t(ref_mse: np.ndarray, cand_mse: list, alpha: float = 0.05, max_flips: int = 4096,
                    seed: int = 0) -> MaxTResult:
    """The max-T sign-flip test of candidates' fold MSEs (each (K,), degrees^2) against the baseline's (K,)."""
    ref = np.log(np.maximum(np.asarray(ref_mse, dtype=float), 1e-300))
    D = np.array([ref - np.log(np.maximum(np.asarray(m, dtype=float), 1e-300)) for m in cand_mse])
    C, K = D.shape if D.ndim == 2 else (0, len(ref))
    if C == 0 or K < 2:
        return MaxTResult(np.full(C, np.nan), np.ones(C), math.inf, 0)
    if 2 ** K <= max_flips:
        S = np.array(list(itertools.product((1.0, -1.0), repeat=K)))
    else:
        rng = np.random.default_rng(seed)
        S = np.vstack([np.ones(K), rng.choice((1.0, -1.0), size=(max_flips - 1, K))])
    # (flips, C, K) -> largest t over candidates per flip
    flipped = S[:, None, :] * D[None, :, :]
    mean = flipped.mean(axis=2)
    sd = flipped.std(axis=2, ddof=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        tt = np.where(sd > 0, mean / (sd / math.sqrt(K)), np.where(mean > 0, np.inf, 0.0))
    mx = tt.max(axis=1)
    t = fold_t(D)
    p = np.array([(np.sum(mx >= tc - 1e-12)) / len(mx) for tc in t])
    crit = float(np.quantile(mx, 1 - alpha, method="higher"))
    return MaxTResult(t=t, p_adjusted=p, critical_t=crit, n_flips=len(mx))


NULL = ("sign flips of whole folds, the same flip for every candidate (all 2^K, or a seeded sample of 4096): the "
        "family-wise rate is alpha up to the flips' granularity")
CALIBRATION = "exact by construction; benchmarks/bench_diagnose.py reports its verdicts beside the diagnosis'"


def maxt_result(t: float, p_adjusted: float, alpha: float) -> TestResult:
    """A candidate's max-T result (its fold t, the family-wise p) read at ``alpha``."""
    return TestResult("maxt", float(t), float(p_adjusted), float(alpha), NULL, CALIBRATION)
