"""Widen kappa's intervals by how much kappa really varies between disjoint stretches of the recording.

The phase bootstrap resamples the residuals *under the model*: it sees tracking noise, not a model that is
only approximately right (a second excitation that is strong in one minute and absent in the next, a wind
that changes direction, a slow change of the plant). On the two real plants kappa from each third of the
frames scatters about the full-record kappa 1.8-2.3x more than those intervals allow
(``benchmarks/bench_ci_thirds.py``). Batch means measure that directly: fit kappa on ``K`` disjoint
consecutive blocks of frames; if the full record's log-kappa standard error is s_e (from its interval), a
block's deviation from it has variance (K - 1) s_e^2, so

    z_ek = (log kappa_ek - log kappa_e) / (sqrt(K - 1) s_e),    f = max(1, sqrt(mean over e, k of z_ek^2))

and the intervals are widened f-fold about kappa in log space. f is pooled over segments (each has only
K - 1 degrees of freedom); on data the model describes, f stays near 1 (simulated branches: see the README)
and the intervals barely change. Units: kappa dimensionless; frames.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

Z95 = 1.959963984540054  # the normal 97.5 % quantile: s_e = (log high - log low) / (2 Z95)


@dataclass(frozen=True)
class TimeSplitCheck:
    """What the batch-means check found. inflation: f (>= 1); rms_z: sqrt(mean z^2) before the floor at 1;
    n_blocks: K; block_frames: frames per block; n_values: finite z values pooled."""

    inflation: float
    rms_z: float
    n_blocks: int
    block_frames: int
    n_values: int

    def as_dict(self) -> dict:
        return {"inflation": self.inflation, "rms_z": self.rms_z, "n_blocks": self.n_blocks,
                "block_frames": self.block_frames, "n_values": self.n_values}


def time_split_check(Y: np.ndarray, weights, config, kappa: np.ndarray, low: np.ndarray, high: np.ndarray,
                     n_blocks: int) -> TimeSplitCheck:
    """Batch-means check of kappa's intervals (see the module docstring). Y: (E, T) deg; weights: (E, T) or
    None; config: the ComplianceConfig the full fit used; kappa, low, high: (E,) the full fit and its CI."""
    from .response_model import ResponseModel  # the engine (this module is one of its leaves)

    E, T = Y.shape
    cuts = np.linspace(0, T, n_blocks + 1).round().astype(int)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (np.log(high) - np.log(low)) / (2 * Z95)
    zs = []
    for a, b in zip(cuts[:-1], cuts[1:]):
        Yb = Y[:, a:b]
        Wb = None if weights is None else weights[:, a:b]
        if not np.isfinite(Yb).any(axis=1).all():
            continue  # a segment unseen in this block: its kappa is not defined there
        fit = ResponseModel(config=config).fit(Yb, weights=Wb)
        with np.errstate(divide="ignore", invalid="ignore"):
            z = (np.log(np.abs(fit.kappa)) - np.log(np.abs(kappa))) / (math.sqrt(n_blocks - 1) * s)
        zs.append(z[np.isfinite(z)])
    z = np.concatenate(zs) if zs else np.array([])
    rms = float(math.sqrt(np.mean(z ** 2))) if z.size else float("nan")
    return TimeSplitCheck(inflation=max(1.0, rms) if np.isfinite(rms) else 1.0, rms_z=rms, n_blocks=int(n_blocks),
                          block_frames=int(T // max(n_blocks, 1)), n_values=int(z.size))


def widen(ci, kappa: np.ndarray, factor: float):
    """The interval (and its resamples) widened ``factor``-fold about kappa in log space."""
    if factor == 1.0:
        return ci
    lk = np.log(np.abs(kappa))

    def about(x):
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.exp(lk + factor * (np.log(x) - lk))

    samples = ci.samples
    if samples is not None and np.size(samples):
        samples = np.where(samples > 0, about(np.where(samples > 0, samples, 1.0)), samples)
    return replace(ci, low=about(ci.low), high=about(ci.high), samples=samples,
                   width_factor=float(ci.width_factor) * factor)
