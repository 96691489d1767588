"""Are the segments' creeps laid out along the branch as tracker drift lays them out? (creep against drift)

Tracker drift and a creep of the rest pose both give every segment a slow course of its own, and in time they
look alike: the held-out fold t credits either to the ``offset`` effect, and phase surrogates of the residuals
lack a slow wander's start-to-end change (:mod:`rce_gtsam.diagnosis.heldout_null`). Where they sit along the
branch tells them apart. A bend angle is computed from three tracked nodes, so one node's error turns its own
bend and the two beside it in the pattern +1, -2, +1 (times the segments' inverse lengths): every tracking
error, fast or slow, reaches the bends through the same geometry, and neighbouring bends' errors correlate at
about -0.6 (-0.63 on both real plants, -0.58 to -0.65 on the simulator's tracks, fast and slow alike). A
joint's creep (a sag, a relaxation, a turning plant) moves its own bend, or a region's bends together; it has
no such alternation.

The test: each segment's weighted least-squares trend over the record (the effect's time courses that change
with time; its constant is left out, because each segment's constant is set by the reference pose its bending
is measured from, not by drift), from the baseline's robust residuals, is a vector d across segments. Its
agreement with the fast noise's layout is q = d' (C - I) d / d' d, with C the correlation between segments of
the residuals' frame-to-frame differences (:func:`~rce_gtsam.diagnosis.statistics.difference_covariance`;
d scaled by each segment's fast-noise SD): near sum_ij C_ij^2 / E when d is laid out as the noise, near 0 for
a course of each segment's own. Null: d ~ N(0, s^2 C) with s^2 free (how much a tracker drifts is the
tracker's and the footage's, unknown; q does not depend on it), so its distribution is drawn exactly from C,
2000 times; small q is evidence of creep. Both d and C are first projected off kappa: a course along kappa is
the excitation's, which z takes (the baseline's residuals have none).

Its calibration rests on one physical assumption, stated so a user can judge it: a node's slow and fast tracking
errors reach the bends through the same geometry (both are errors of the same node positions), so they share their
layout across the branch up to one overall scale. On real footage it is only partly checked
(``benchmarks/bench_drift_layout_real.py``): the same test on segment lengths, which carry tracking error and no
creep, gives p = 0.47 and 0.047 on the two plants' raw tracks, 0.17 and 0.17 smoothed (3 and 6 of 100 effect-
free simulated recordings at p <= 0.05). Measured on effect-free pipeline recordings (default preset, 900
frames): p <= 0.05 on 5 of 80 at 30 frames/s, 4 of 40 at 60 frames/s, 0 of 20 under the held-out tracker noise of
``benchmarks/bench_diagnose.py``, 1 of 20 trees, 1 of 20 eight-node chains, 0 of 20 with a swaying root (11 of 220,
5.0 %); on synthetic node drift through the bend geometry 4.5 % of 200 records and 6.6 % of 500 others (1.2 % at
0.01), slightly above nominal because the null is drawn from the layout estimated on the same record. With the
segment constants tested too it fired on 18 of 40 (the median reference pose leaves a constant of each segment's
own). Offset + creep at 4x and 6x the simulator's default: 16 of 20 each; delay at 1x 0 of 20, a second excitation
at 2x 2 of 20. With it the diagnosis (all six candidates) names offset + creep on 11 of 20 at 4x and 19 of 20 at 6x
(9 and 18 without it; 12 and 19 before any drift check), effect-free recordings still 40/40 none at 30 frames/s and
39/40 at 60 frames/s (``benchmarks/bench_diagnose.py``).

**A rescue of the fold t, not a test on its own.** The diagnosis names an offset/creep where its fold t is
significant and the data show something drift cannot do (:meth:`rce_gtsam.effects.Effect.heldout_time_basis`):
a held-out gain beyond phase surrogates, a course common to two node-disjoint row sets, or, with this test, a
layout along the branch that a node's drift cannot give.

Units: degrees (residuals), frames; p unitless.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from .heldout_null import basis_coefficients
from .result import TestResult
from .score_test import ScoreTest, robust_residuals
from .statistics import difference_covariance

N_DRAWS = 2000  # null draws (p-value resolution 1/2001)


def agreement(d: np.ndarray, A: np.ndarray) -> np.ndarray:
    """(n,) for n sets of K course vectors ``d`` (n, K, E): the mean over the K of d' A d / d' d, each course on
    its own scale. A (E, E): the fast noise's correlation less the identity (projected off kappa)."""
    num = np.einsum("nke,ef,nkf->nk", d, A, d)
    return np.mean(num / np.maximum(np.einsum("nke,nke->nk", d, d), 1e-300), axis=1)


def layout_test(R: np.ndarray, weights: np.ndarray, basis: np.ndarray, along: np.ndarray | None = None,
                n_draws: int = N_DRAWS, seed: int = 0) -> ScoreTest | None:
    """Are the slow courses of the rows of a residual matrix laid out across the rows as their fast noise is?

    R: (E, T) residuals (NaN = missing); weights: (E, T) >= 0; basis: (K, T) time courses, of which those that
    change over time are fitted to each row (weighted least squares); along: (E,) a direction across the rows
    that both the courses and the layout are projected off (the baseline's kappa, whose courses z takes), or
    None. The statistic and its null are the module's note's (q = :func:`agreement`, small q = laid out
    otherwise than the fast noise); :func:`drift_pattern_test` is this on a baseline fit's robust residuals
    along its kappa. Any rows whose errors are one set of tracked positions seen through fixed geometry fit
    the same assumption: the segment lengths, whose variation is tracking error along the branch
    (``benchmarks/bench_drift_layout_real.py`` asks it of the real plants). Returns None where the basis has
    only a constant."""
    basis = np.asarray(basis, float)
    M = np.where(np.isfinite(R), weights, 0.0)
    coef = basis_coefficients(np.where(M > 0, R, 0.0), M, basis)[:, np.ptp(basis, axis=1) > 0]   # (E, K)
    if coef.shape[1] == 0:
        return None
    C = difference_covariance(np.where(M > 0, R, np.nan))
    sd = np.sqrt(np.maximum(np.diag(C), 1e-300))
    corr = C / np.outer(sd, sd)
    P = np.eye(sd.size)
    if along is not None:
        k = np.asarray(along, float) / sd
        P = P - np.outer(k, k) / max(float(k @ k), 1e-300)
    A = P @ (corr - np.eye(sd.size)) @ P
    q = float(agreement((P @ (coef / sd[:, None])).T[None], A)[0])
    lam, V = np.linalg.eigh(P @ corr @ P)
    rng = np.random.default_rng(seed)
    draws = (rng.standard_normal((n_draws, coef.shape[1], lam.size)) * np.sqrt(np.clip(lam, 0.0, None))) @ V.T
    p = float((1 + np.sum(agreement(draws, A) <= q)) / (n_draws + 1))
    return ScoreTest(p=p, q=q, n_directions=int(coef.shape[1]), n_surrogates=n_draws,
                     z_equivalent=float(stats.norm.isf(p)), statistic="drift_pattern")


def drift_pattern_test(fit, basis: np.ndarray, n_draws: int = N_DRAWS, seed: int = 0) -> ScoreTest | None:
    """The test of the module's note for the baseline ``fit`` (a ``ModelFit``: residuals, weights, kappa) and a
    term's time ``basis`` (K, T), of which the courses that change over time are tested: :func:`layout_test` of
    the fit's robust residuals, projected off its kappa. Returns a
    :class:`~rce_gtsam.diagnosis.score_test.ScoreTest` with statistic ``"drift_pattern"`` (q: :func:`agreement`
    of the data; n_directions: the courses tested; p: the share of null draws whose agreement is at most
    the data's), or None where the basis has only a constant."""
    return layout_test(robust_residuals(fit.residuals), fit.weights, basis, along=fit.kappa, n_draws=n_draws,
                       seed=seed)


NULL = ("trends drawn as N(0, s^2 C) from the fast noise's correlation C between segments (2000 draws), assuming a "
        "node's slow and fast tracking errors share their layout along the branch")
CALIBRATION = ("benchmarks/bench_diagnose.py (11 of 220 effect-free pipeline recordings at p <= 0.05) and "
               "benchmarks/bench_drift_layout_real.py (the real plants' segment lengths)")


def drift_pattern_result(test: ScoreTest, threshold_p: float) -> TestResult:
    """:func:`drift_pattern_test`'s result read at ``threshold_p``."""
    return TestResult("drift_pattern", float(test.q), float(test.p), float(threshold_p), NULL, CALIBRATION)
