"""The held-out test the user watches: contiguous fold blocks, z estimated on one node-disjoint row set and scored on
the other, and the statistics over folds (paired t) and over frames (Diebold-Mariano with batch means).

* :func:`fold_blocks` — contiguous test blocks;
* :func:`heldout_errors` — a model's held-out squared errors per fold (and per frame), its fit refitted without
  the block and its buffers, z on the block estimated from one row set, the other scored;
* :func:`paired_t` — the fold-paired t of log MSE ratios (the verdict's evidence);
* :func:`frame_loss` — the held-out error per frame, the series the full-series test
  (:func:`rce_gtsam.model.series.loss_difference_test`) compares.

**The scheme** (every model alike, the rank-1 baseline and each candidate):

* Blocked cross-validation: the frames are cut into ``n_folds`` contiguous test blocks (each at least the
  bootstrap block length, 25 frames). A buffer of ``block_length`` frames on each side of the test block is
  also left out of training, because neighbouring frames are dependent (smoothed tracks, delays, ringing):
  this is the hv-block scheme (Racine 2000) with h = the moving-block bootstrap's block length, i.e. the
  same independence horizon the bootstrap CIs assume. The buffer grows to the longest memory any fitted term
  has (:func:`rce_gtsam.diagnosis.evidence.heldout_setting`).
* Held-out z: the excitation (and any other per-frame latent, e.g. the second mode's w) of a test frame is
  unknown, so it is estimated from the test frames' data with every static parameter frozen from the
  training fit — but only from one set of edges (A); another set (B) is scored, then the roles swap. A
  and B share no tracked node: a node's position error enters the three bends it belongs to (pattern
  +1, -2, +1), so neighbouring bends carry anti-correlated noise, and a latent estimated on A would
  otherwise "predict" B's noise (a free second mode w_t did exactly that on effect-free data: 3/10 false
  verdicts). Rows are dealt along the branch as A A A, gap, gap, B B B, gap, gap
  (:func:`rce_gtsam.model.row_sets.node_disjoint_split`), so both sets span root to tip. No number scored was
  used to fit anything that predicts it.
* Per-edge parameters (kappa, offsets, mode shapes) are refitted in every fold. The few *shared* nonlinear
  parameters of an effect (a lag, two frequencies and a damping ratio, a saturation curvature: <= 3 numbers
  against ~10^4 data) are fitted once on all frames and kept in the folds; the optimism this leaves is of
  order p / n ~ 1e-4 of the MSE, far below the fold-to-fold noise, and it saves re-running the slow
  nonlinear searches per fold. Where an effect proposes several starts (dynamics: damping ratios 0.1, 0.3, 1),
  the full fit is run from each and the one that predicts one node-disjoint row set best from the other's
  excitation is kept (:mod:`rce_gtsam.model.starts`: a local search can end in a sharp resonance that fits noise).
* Evidence: per fold, log(MSE_baseline / MSE_candidate); evidence = mean / standard error over folds (a
  paired t statistic, :func:`paired_t`). Its power is set by the number of folds, not by the effect's size: an
  effect's gain is large in gusty blocks and small in calm ones, so the fold log-ratios' spread grows with their
  mean and t stays put as the effect grows (delay at 3x the simulator's default strength: fold log-ratios
  0.0-0.5, t ~3). :data:`~rce_gtsam.diagnosis.settings.N_FOLDS` = 16 folds (t quantile 2.60 at 15 dof instead of
  3.00 at 7, and sqrt(2) more folds) instead of 8 keeps the test blocks >= 2 x the 25-frame buffer on a 900-frame
  clip; measured false verdicts on effect-free pipeline data stay 0/40 (1/40 since the second excitation's
  full-data test, with the AIC hurdle waived for a significant full-data test: p = 0.0045, held-out RMSE 0.4 %
  lower). Its threshold is :mod:`rce_gtsam.diagnosis.decision`'s (a one-sided t quantile, Bonferroni over the
  findings, n_folds - 1 dof).

Units: degrees (errors in deg^2), frames.
"""

from __future__ import annotations

import math

import numpy as np

from ..model import ModelFit, ResponseModel
from .result import TestResult
from .settings import BLOCK_LENGTH


def fold_blocks(T: int, n_folds: int, block_length: int = BLOCK_LENGTH) -> list[tuple[int, int]]:
    """Contiguous test blocks [a, b) covering the frames; fewer folds if a block would be < block_length."""
    k = max(2, min(int(n_folds), T // max(block_length, 1)))
    edges = np.linspace(0, T, k + 1).round().astype(int)
    return [(int(edges[i]), int(edges[i + 1])) for i in range(k)]


def heldout_errors(model: ResponseModel, full: ModelFit, Y, W, s, blocks, halves, gap: int,
                   cv_iter: int = 60, per_frame: bool = False, prediction: np.ndarray | None = None):
    """Per-fold held-out sum of squared errors and counts (degrees^2, entries) of ``model``; with
    ``per_frame`` also the same two sums per frame (T,) (zero outside the scored test blocks). ``prediction``:
    an (E, T) array that receives each scored entry's held-out prediction (degrees; left as is elsewhere)."""
    E, T = Y.shape
    sse = np.zeros(len(blocks))
    cnt = np.zeros(len(blocks))
    sse_t = np.zeros(T)
    cnt_t = np.zeros(T)
    full_ridge = full.heldout_z_precision()
    for k, (a, b) in enumerate(blocks):
        lo, hi = max(0, a - gap), min(T, b + gap)
        Ytr = Y.copy()
        Ytr[:, lo:hi] = np.nan
        Wtr = W.copy()
        Wtr[:, lo:hi] = 0.0
        if not (Wtr > 0).any(axis=1).all():
            continue  # an edge has no training data in this fold: skip the fold for every model alike
        z0 = full.z.copy()
        z0[lo:hi] = 0.0
        st0 = {eff.name: blank_latents(st, lo, hi) for eff, st in zip(full.model.effects, full.states)}
        # the same zero-mean prior on z as for the held-out estimate below, from the full fit: frames of the
        # left-out window that training data still touch weakly (through a lag) must not blow up
        tr = model.solve(Ytr, Wtr, s, start=(full.kappa.copy(), z0, st0), max_iter=cv_iter, refit_shared=False,
                         z_ridge=full_ridge)
        free = np.zeros(T, bool)
        free[lo:hi] = True
        # prior on the held-out z: zero mean, the training z's variance; precision in weighted-SSE units
        # = (training residual variance) / (z variance) — the posterior mean of z given edges A. It only
        # matters for frames few A observations determine (e.g. seen through a long lag only).
        trained = np.ones(T, bool)
        trained[lo:hi] = False
        z_ridge = tr.heldout_z_precision(trained)
        for A, B in (halves, halves[::-1]):
            if len(A) == 0 or len(B) == 0:
                continue
            # z on the left-out window is estimated from edges A over the whole window (test block and
            # buffers: none of it was used in training, none of it is scored), so that operators with
            # memory (delay, dynamics) see the excitation that drives the block's first frames
            Yte = np.full_like(Y, np.nan)
            Yte[np.ix_(A, np.arange(lo, hi))] = Y[np.ix_(A, np.arange(lo, hi))]
            Wte = np.where(np.isfinite(Yte), W, 0.0)
            st = {eff.name: s_ for eff, s_ in zip(model.effects, tr.states)}
            est = model.solve(Yte, Wte, s, start=(tr.kappa.copy(), tr.z.copy(), st), frozen=True, free=free,
                              max_iter=cv_iter, z_ridge=z_ridge)
            pred = est.predict()[np.ix_(B, np.arange(a, b))]
            if prediction is not None:
                prediction[np.ix_(B, np.arange(a, b))] = pred
            y = Y[np.ix_(B, np.arange(a, b))]
            ok = np.isfinite(y)
            sq = np.where(ok, (y - pred) ** 2, 0.0)
            sse[k] += float(np.sum(sq))
            cnt[k] += int(ok.sum())
            sse_t[a:b] += sq.sum(axis=0)
            cnt_t[a:b] += ok.sum(axis=0)
    return (sse, cnt, sse_t, cnt_t) if per_frame else (sse, cnt)


def blank_latents(state: dict, lo: int, hi: int) -> dict:
    lat = {}
    for k, v in state.get("latents", {}).items():
        v = np.array(v, dtype=float)
        v[lo:hi] = 0.0
        lat[k] = v
    out = dict(state)
    out["latents"] = lat
    return out


def frame_loss(sse_t: np.ndarray, cnt_t: np.ndarray) -> np.ndarray:
    """(T,) held-out mean squared error per frame (deg^2), NaN at frames nothing was scored on."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(cnt_t > 0, sse_t / np.maximum(cnt_t, 1), np.nan)


def paired_t(mse_ref: np.ndarray, mse: np.ndarray) -> float:
    """Paired t statistic over folds of log(mse_ref / mse) (> 0: ``mse`` is lower)."""
    d = np.log(np.maximum(mse_ref, 1e-300)) - np.log(np.maximum(mse, 1e-300))
    if len(d) < 2:
        return float("nan")
    sd = float(np.std(d, ddof=1))
    if sd <= 0:
        return math.inf if np.mean(d) > 0 else 0.0
    return float(np.mean(d) / (sd / math.sqrt(len(d))))


#: how the fold t's null is calibrated, and the record that measured its false-alarm rate
FOLD_T_NULL = ("Student t with (folds - 1) dof for the mean over folds of log(MSE_baseline / MSE_candidate), the "
               "folds made independent by hv-block buffers of at least the bootstrap block length")
FOLD_T_CALIBRATION = ("benchmarks/bench_diagnose.py: effect-free pipeline recordings, 0/40 verdicts (with the AIC "
                      "hurdle; 5/40 without it)")


def fold_t_result(t: float, threshold_t: float) -> TestResult:
    """The fold-paired t (:func:`paired_t`) of a candidate against the baseline, read at ``threshold_t``."""
    return TestResult("fold_t", float(t), None, float(threshold_t), FOLD_T_NULL, FOLD_T_CALIBRATION)
