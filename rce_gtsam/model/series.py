"""Statistics of time series that the engine and the diagnosis share: autocorrelation, the integrated
autocorrelation time, and the Diebold-Mariano test of whether one loss series is lower than another (the
diagnosis' full-data held-out test; the choice between a fit's starts, :mod:`rce_gtsam.model.starts`).

Units: frames (lags, batch lengths); losses in whatever unit they come in (deg^2 here).
"""

from __future__ import annotations

import math

import numpy as np

MIN_BATCH = 25  # frames: the shortest batch of the batch-means standard error (the diagnosis passes its block length)


def autocorrelation(x: np.ndarray, nlags: int) -> np.ndarray:
    """(nlags + 1,) sample autocorrelation of the series x (mean removed) at lags 0..nlags, by FFT (zeros for a
    constant series)."""
    x = x - x.mean()
    n = len(x)
    f = np.fft.rfft(x, 2 * n)
    ac = np.fft.irfft(f * np.conj(f))[: nlags + 1]
    return ac / ac[0] if ac[0] > 0 else np.zeros(nlags + 1)


def integrated_time(d: np.ndarray) -> float:
    """Integrated autocorrelation time (frames) of a series: 1 + 2 sum of its autocorrelations, summed in
    pairs while positive (Geyer's initial positive sequence); >= 1."""
    n = len(d)
    if n < 8 or not np.any(d - d.mean()):
        return 1.0
    ac = autocorrelation(d, n - 1)
    tau = 1.0
    for k in range(1, n - 1, 2):
        pair = ac[k] + ac[k + 1]
        if pair <= 0:
            break
        tau += 2 * pair
    return float(min(max(tau, 1.0), n / 4))


def loss_difference_test(loss_ref: np.ndarray, loss: np.ndarray, min_batch: int = MIN_BATCH) -> dict:
    """Diebold-Mariano test on the full held-out series: is ``loss`` lower than ``loss_ref`` on average?

    d_t = loss_ref_t - loss_t over frames scored by both (NaN elsewhere). Its mean's standard error comes
    from batch means over consecutive scored frames, with batches ``max(min_batch, 2 x integrated
    autocorrelation time of d)`` long, so that batch means are nearly independent; t has n_batches - 1
    degrees of freedom. Every scored frame counts (thousands of values instead of 8 fold means), and the
    long memory of tracking drift widens the batches rather than faking evidence. Returns {t, dof,
    mean_diff, batch_frames, n_batches}."""
    ok = np.isfinite(loss_ref) & np.isfinite(loss)
    d = (loss_ref - loss)[ok]
    if d.size < 4:
        return {"t": float("nan"), "dof": 0, "mean_diff": float("nan"), "batch_frames": 0, "n_batches": 0}
    L = int(max(min_batch, math.ceil(2 * integrated_time(d))))
    nb = d.size // L
    if nb < 2:
        return {"t": float("nan"), "dof": 0, "mean_diff": float(d.mean()), "batch_frames": L, "n_batches": nb}
    means = d[: nb * L].reshape(nb, L).mean(axis=1)
    sd = float(np.std(means, ddof=1))
    t = (float(np.mean(means)) / (sd / math.sqrt(nb))) if sd > 0 else (math.inf if means.mean() > 0 else 0.0)
    return {"t": t, "dof": nb - 1, "mean_diff": float(d.mean()), "batch_frames": L, "n_batches": nb}
