"""Widen kappa's intervals by how much kappa really varies between disjoint stretches of the recording.

The phase bootstrap resamples the residuals *under the model*: it sees tracking noise, not a model that is
only approximately right (a second excitation that is strong in one minute and absent in the next, a wind
that changes direction, a slow change of the plant). On the two real plants kappa from each third of the
frames scatters about the full-record kappa 1.8-2.3x more than those intervals allow
(``benchmarks/bench_ci_thirds.py``). Batch means measure that directly: fit kappa on ``K`` disjoint
consecutive blocks of frames (each re-referenced to its own median rest angle, as a recording of that block
alone would be); if the full record's log-kappa standard error is s_e (from its interval), a
block's deviation from it has variance (K - 1) s_e^2, so

    z_ek = (log kappa_ek - log kappa_e) / (sqrt(K - 1) s_e),    rms z = sqrt(mean over e, k of z_ek^2)

pooled over segments (each has only K - 1 degrees of freedom). With the few effective noise samples of a
wind record a block's kappa scatters more than that rule says even when the model is exact, so the same
number is computed on surrogates that obey the model exactly (kappa z plus phase-randomised residuals, the
phase bootstrap's noise model) and the intervals are widened f = max(1, rms z / rms z of the surrogates)
-fold about kappa in log space: only the scatter the model cannot produce widens them. Units: kappa dimensionless; frames.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

Z95 = 1.959963984540054  # the normal 97.5 % quantile: s_e = (log high - log low) / (2 Z95)


@dataclass(frozen=True)
class TimeSplitCheck:
    """What the batch-means check found. inflation: f (>= 1); rms_z: sqrt(mean z^2) of the data;
    rms_z_null: the same where the rank-1 model holds (surrogates); n_blocks: K; block_frames: frames per
    block; n_values: finite z values pooled."""

    inflation: float
    rms_z: float
    n_blocks: int
    block_frames: int
    n_values: int
    rms_z_null: float = 1.0

    def as_dict(self) -> dict:
        return {"inflation": self.inflation, "rms_z": self.rms_z, "rms_z_if_model_holds": self.rms_z_null,
                "n_blocks": self.n_blocks, "block_frames": self.block_frames, "n_values": self.n_values}


def block_z(Y: np.ndarray, weights, config, kappa: np.ndarray, s: np.ndarray, n_blocks: int) -> np.ndarray:
    """The finite z_ek of kappa fitted on ``n_blocks`` disjoint frame blocks (each re-referenced to its own
    median angle) against ``kappa`` with log-SE ``s`` (see the module docstring), blocks in order."""
    from .response_model import ResponseModel  # the engine (this module is one of its leaves)

    E, T = Y.shape
    cuts = np.linspace(0, T, n_blocks + 1).round().astype(int)
    zs = []
    for a, b in zip(cuts[:-1], cuts[1:]):
        Yb = Y[:, a:b]
        if getattr(config, "response", "signed") == "signed":
            # a recording of just this block would take its rest pose from this block: the rest angle's own
            # uncertainty is part of kappa's
            with np.errstate(all="ignore"):
                Yb = Yb - np.nanmedian(Yb, axis=1, keepdims=True)
        Wb = None if weights is None else weights[:, a:b]
        if not np.isfinite(Yb).any(axis=1).all():
            continue  # a segment unseen in this block: its kappa is not defined there
        fit = ResponseModel(config=config).fit(Yb, weights=Wb)
        with np.errstate(divide="ignore", invalid="ignore"):
            z = (np.log(np.abs(fit.kappa)) - np.log(np.abs(kappa))) / (math.sqrt(n_blocks - 1) * s)
        zs.append(z[np.isfinite(z)])
    return np.concatenate(zs) if zs else np.array([])


def block_rms_z(Y: np.ndarray, weights, config, kappa: np.ndarray, s: np.ndarray, n_blocks: int) -> tuple[float, int]:
    """sqrt(mean z_ek^2) of :func:`block_z` and the number of finite z values."""
    z = block_z(Y, weights, config, kappa, s, n_blocks)
    return (float(math.sqrt(np.mean(z ** 2))) if z.size else float("nan")), int(z.size)


def time_split_check(Y: np.ndarray, weights, config, kappa: np.ndarray, low: np.ndarray, high: np.ndarray,
                     n_blocks: int, n_null: int = 12, seed: int = 0) -> TimeSplitCheck:
    """Batch-means check of kappa's intervals (see the module docstring). Y: (E, T) deg; weights: (E, T) or
    None; config: the ComplianceConfig the full fit used; kappa, low, high: (E,) the full fit and its CI.

    The blocks' scatter is compared with what it is when the rank-1 model holds exactly: ``n_null`` surrogates
    kappa z + phase-randomised residuals (the phase bootstrap's noise model), refitted whole and in blocks.
    With a few effective noise samples per record a block's kappa scatters more than the 1 / frames rule says
    even for a perfect model; only the excess is taken as the model's failure:
    f = max(1, rms z(data) / rms z(surrogates))."""
    from .response_model import ResponseModel

    with np.errstate(divide="ignore", invalid="ignore"):
        s = (np.log(high) - np.log(low)) / (2 * Z95)
    rms, n = block_rms_z(Y, weights, config, kappa, s, n_blocks)
    full = ResponseModel(config=config).fit(Y, weights=weights)
    pred = full.predict()
    R = Y - pred
    from .surrogates import phase_randomised_residuals  # the phase bootstrap's own noise model

    null = []
    for Rs in phase_randomised_residuals(R, int(n_null), np.random.default_rng(seed)):
        Ys = np.where(np.isfinite(Y), pred + Rs, np.nan)
        ks = ResponseModel(config=config).fit(Ys, weights=weights).kappa
        null.append(block_rms_z(Ys, weights, config, ks, s, n_blocks)[0])
    rms0 = float(np.sqrt(np.nanmean(np.square(null)))) if null else 1.0
    ratio = rms / rms0 if np.isfinite(rms) and rms0 > 0 else float("nan")
    return TimeSplitCheck(inflation=max(1.0, ratio) if np.isfinite(ratio) else 1.0, rms_z=rms, n_blocks=int(n_blocks),
                          block_frames=int(Y.shape[1] // max(n_blocks, 1)), n_values=n, rms_z_null=rms0)


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
