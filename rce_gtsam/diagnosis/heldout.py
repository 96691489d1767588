"""The held-out test the user watches: contiguous fold blocks, z estimated on one node-disjoint row set and scored on
the other, and the statistics over folds (paired t) and over frames (Diebold-Mariano with batch means).

* :func:`fold_blocks` — contiguous test blocks;
* :func:`heldout_errors` — a model's held-out squared errors per fold (and per frame), its fit refitted without
  the block and its buffers, z on the block estimated from one row set, the other scored;
* :func:`paired_t` — the fold-paired t of log MSE ratios (the verdict's evidence);
* :func:`frame_loss` — the held-out error per frame, the series the full-series test
  (:func:`rce_gtsam.model.series.loss_difference_test`) compares.

Units: degrees (errors in deg^2), frames.
"""

from __future__ import annotations

import math

import numpy as np

from ..model import ModelFit, ResponseModel
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
