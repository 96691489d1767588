"""Is a term's held-out gain more than noise of the residuals' own spectrum gives? (per-segment time courses)

The held-out fold t (:func:`rce_gtsam.diagnosis.heldout.paired_t`) asks whether a candidate lowers the error of
16 test blocks more often and more than chance, taking the blocks as independent. For a term made of slow
per-segment time courses (an offset and a linear creep, c_e + d_e t) they are not: tracker drift, each node's
position wandering over seconds, gives every segment a slow course of its own, and a straight line fitted on
the training frames then predicts the test blocks between them in every fold alike. On the simulator's
effect-free recordings at 60 frames/s (900 frames = 15 s, drift correlation time 2 s) the offset candidate
was named on 3 of 20, with held-out gains of 2.6-3.5 % and fold t of 2.8-5.0; at 30 frames/s (30 s) on none
of 40.

This test asks the question with the noise's colour in it: the statistic is the held-out gain of per-segment
least-squares fits on the same time basis (the term's own columns: 1 and t), fitted on each fold's training
frames (the block and its buffers removed) and scored on the block, summed over the folds and segments, from
the baseline's robust residuals (:func:`~rce_gtsam.diagnosis.score_test.robust_residuals`). Its null: the
same on multivariate phase surrogates of those residuals (every segment's spectrum and cross-spectrum kept,
only *when* the noise happens new, missing entries missing; :func:`~rce_gtsam.model.compliance.draw_phases`).
The p is the share of surrogates whose gain reaches the data's. A creep puts its power into one coherent
ramp, which the surrogates spread over random slow waves.

**A veto, not a calibrated test.** The diagnosis requires it (at alpha), or a time course common to two
node-disjoint row sets (:func:`~rce_gtsam.diagnosis.score_test.shared_time_course_test`, which drift of
different nodes cannot give), *as well as* the fold t (:meth:`~rce_gtsam.effects.Effect.heldout_time_basis`):
they can only take verdicts away. Phase
surrogates are periodic, so they lack the start-to-end change a slow wander has, and on drift alone whose
correlation time nears the record's length the test fires as the fold t does (pure AR(1) drift plus white
noise, 480 frames: p <= 0.05 on 2 of 20 records at a correlation time of 15 frames, 3 of 20 at 30, 15 of 20
at 120). Taking each surrogate as a window of a four times longer series halved that (8 of 20 at 120) but
kept only 7 of 20 creeps at 6x the simulator's default, against 15 with plain surrogates. What separates a
creep from slow tracker drift physically is where it sits, not when: a node's drift turns its three bends in
the pattern +1, -2, +1, a joint's creep only its own bend; this test does not use that, and
:mod:`rce_gtsam.diagnosis.drift_pattern` does.

Measured through the pipeline (default preset, 900 frames): effect-free recordings, smallest p 0.16 of 20 at
30 frames/s and 0.20 of 20 at 60 frames/s (the three named by the fold t at 60 frames/s: 0.36-0.44); offset +
creep at 6x and 4x the simulator's default, p <= 0.05 on 15 of 20 and 6 of 10. The surrogates carry the creep's
own power too (a ramp's spectrum falls as 1/f^2), which is what costs power.

Units: degrees (residuals; gains in weighted deg^2), frames.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from ..model.compliance import draw_phases, residual_spectrum, surrogate_slice
from .result import TestResult
from .score_test import SURROGATE_BATCH, ScoreTest, robust_residuals

N_NULL = 1000  # phase surrogates (p-value resolution 1/1001; the test is used at alpha = 0.05)


def basis_coefficients(X: np.ndarray, M: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """(..., E, K) each row's weighted least-squares coefficients on the time ``basis`` (K, T) for residual sets
    X (..., E, T; 0 where missing) with weights M (E, T; 0 = missing). Units: those of X per unit of each
    basis course."""
    K = basis.shape[0]
    A = np.einsum("et,kt,lt->ekl", M, basis, basis)
    A = A + 1e-9 * np.maximum(np.trace(A, axis1=1, axis2=2), 1e-300)[:, None, None] * np.eye(K)
    rhs = np.einsum("et,...et,kt->...ek", M, X, basis)
    return np.linalg.solve(A, rhs[..., None])[..., 0]


def heldout_gain(X: np.ndarray, M: np.ndarray, blocks, gap: int, basis: np.ndarray) -> np.ndarray:
    """(n,) the held-out gain of per-segment fits on ``basis`` for each residual set of X (n, E, T; 0 where
    missing) with weights M (E, T; 0 = missing): for every fold block [a, b), each segment's weighted least
    squares on the frames outside [a - gap, b + gap), scored on the block as sum M (x^2 - (x - fit)^2), summed
    over blocks and segments (weighted deg^2). ``basis``: (K, T) time courses."""
    n, E, T = X.shape
    gain = np.zeros(n)
    for a, b in blocks:
        train = np.ones(T, bool)
        train[max(0, a - gap):min(T, b + gap)] = False
        coef = basis_coefficients(X, M * train[None], basis)
        fit = np.einsum("nek,kt->net", coef, basis[:, a:b])
        Xb = X[:, :, a:b]
        gain += np.einsum("et,net->n", M[:, a:b], Xb ** 2 - (Xb - fit) ** 2)
    return gain


def heldout_gain_null_test(fit, blocks, gap: int, basis: np.ndarray, n_surrogates: int = N_NULL,
                           seed: int = 0) -> ScoreTest:
    """The test of the module's note for the baseline ``fit`` (a ``ModelFit``: residuals and weights, E x T),
    the diagnosis' fold ``blocks`` and buffer ``gap`` (frames) and a term's time ``basis`` (K, T). Returns a
    :class:`~rce_gtsam.diagnosis.score_test.ScoreTest` with statistic ``"heldout_gain"`` (q: the data's gain,
    weighted deg^2; n_directions: K)."""
    R = robust_residuals(fit.residuals)
    M = np.where(np.isfinite(R), fit.weights, 0.0)
    # each segment's constant over its observed frames is taken out first, as the surrogates have none: the rest
    # pose a bend is measured from is an estimate over the frames the segment was seen in, and where nodes are
    # lost in gusts (missing not at random) it leaves the segment a constant of its own, which a term with a
    # constant column predicts in every fold. That constant is the reference's, not physics; only a course
    # beyond it counts (effect-free videos through our tracker: offset named at p 0.003 with the constants in)
    obs = M > 0
    R = R - (np.sum(np.where(obs, R, 0.0), axis=1) / np.maximum(obs.sum(axis=1), 1))[:, None]
    X = np.where(obs, R, 0.0)
    T = X.shape[1]
    q = float(heldout_gain(X[None], M, blocks, gap, basis)[0])
    spectrum = residual_spectrum(np.where(obs, R, np.nan))
    draws = draw_phases(np.random.default_rng(seed), n_surrogates, T)
    qs = np.concatenate([heldout_gain(surrogate_slice(spectrum, T, draws, slice(i, i + SURROGATE_BATCH)) * obs,
                                      M, blocks, gap, basis)
                         for i in range(0, n_surrogates, SURROGATE_BATCH)])
    p = float((1 + np.sum(qs >= q)) / (n_surrogates + 1))
    return ScoreTest(p=p, q=q, n_directions=int(basis.shape[0]), n_surrogates=n_surrogates,
                     z_equivalent=float(stats.norm.isf(p)), statistic="heldout_gain")


NULL = ("multivariate phase surrogates of the baseline's robust residuals (1000), the same per-segment fits scored "
        "on each; a veto, not a calibrated test: phase surrogates lack a slow wander's start-to-end change")
CALIBRATION = ("benchmarks/bench_diagnose.py: effect-free pipeline recordings, smallest p 0.16 of 20 at 30 frames/s "
               "and 0.20 of 20 at 60 frames/s")


def heldout_null_result(test: ScoreTest, threshold_p: float) -> TestResult:
    """:func:`heldout_gain_null_test`'s result read at ``threshold_p``."""
    return TestResult("heldout_null", float(test.q), float(test.p), float(threshold_p), NULL, CALIBRATION)
