"""Tracker-like noise on simulated node positions (what TAPIR gives on real footage): anisotropic white noise,
slow AR(1) drift, jumps and occlusion gaps. The model's parameters: :class:`NoiseConfig`."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal

from ..graph import BranchGraph
from .artifacts import branch_tangents as _tangents


@dataclass(frozen=True)
class NoiseConfig:
    """Tracker-like noise on node positions (what TAPIR gives on real footage). Units: pixels, frames.

    sigma_across_px: white-noise 1-sigma perpendicular to the branch at the root; it grows linearly to
        ``sigma_across_px * tip_factor`` at the tip (real TAPIR residuals on the two plants: 0.15-1.0 px,
        growing toward the tip).
    along_ratio: white-noise sigma along the branch / sigma across it (trackers slide along a featureless
        stem; brief: ~3; the two real plants show 1.4-2.3 in high-pass residuals).
    tip_factor: noise multiplier at the tip relative to the root (linear in normalised root distance).
    drift_px: stationary 1-sigma of the slow AR(1) drift along the branch (across: drift_px / along_ratio).
    drift_time_s: correlation time of the drift in seconds.
    gap_rate: expected number of occlusion gaps per node per 30 s at mid-branch; the rate grows
        linearly from 0.2x at the root to 1.8x at the tip (distal nodes pass behind leaves more often).
    gap_median_frames, gap_max_frames: gap lengths are log-normal (sigma_log 1.1) with this median,
        clipped to [1, gap_max_frames] — many 1-3 frame dropouts and a few of tens of frames, as in the
        real tracks (about 2 % of rows missing).
    jump_prob: probability per observation that a jump (outlier) starts there.
    jump_px: (min, max) jump magnitude in pixels; a jump lasts 1-3 frames.
    emit_sigma: if True, tracks carry a per-observation ``sigma_px`` (the isotropic-equivalent white-noise
        sigma of that node) and ``tracks.csv`` gets a ``sigma_px`` column.
    enabled: False = noise-free tracks (positions exactly true_xy, no gaps).
    """

    sigma_across_px: float = 0.25
    along_ratio: float = 3.0
    tip_factor: float = 1.8
    drift_px: float = 0.2
    drift_time_s: float = 2.0
    gap_rate: float = 5.0
    gap_median_frames: float = 2.0
    gap_max_frames: int = 50
    jump_prob: float = 0.001
    jump_px: tuple[float, float] = (3.0, 8.0)
    emit_sigma: bool = False
    enabled: bool = True


def add_tracker_noise(graph: BranchGraph, true_xy: np.ndarray, s_node: np.ndarray, noise: NoiseConfig,
                      fps: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Noisy positions (N, F, 2) with NaN at occlusion gaps, and the nominal white-noise sigma (N,) in px.

    Per node i with normalised root distance s_i: white noise with sigma_across = sigma_across_px *
    (1 + (tip_factor - 1) s_i) across the branch and along_ratio times that along it; plus an AR(1) drift
    (correlation time drift_time_s, stationary sigma drift_px along / drift_px/along_ratio across, also
    growing toward the tip); plus jumps; then occlusion gaps (see :class:`NoiseConfig`).
    """
    N, F, _ = true_xy.shape
    if not noise.enabled:
        return true_xy.copy(), np.full(N, np.nan)
    grow = 1 + (noise.tip_factor - 1) * s_node  # (N,)
    s_across = noise.sigma_across_px * grow
    s_along = s_across * noise.along_ratio
    tan = _tangents(graph, true_xy)
    nrm = np.stack([-tan[..., 1], tan[..., 0]], axis=-1)
    along = rng.standard_normal((N, F)) * s_along[:, None]
    across = rng.standard_normal((N, F)) * s_across[:, None]
    rho = math.exp(-1.0 / (noise.drift_time_s * fps))
    innov = math.sqrt(1 - rho ** 2)
    e = rng.standard_normal((N, F, 2))
    # stationary AR(1): x[0] = e[0], x[t] = rho x[t-1] + sqrt(1 - rho^2) e[t]
    drift = signal.lfilter([innov], [1.0, -rho], e, axis=1, zi=e[:, :1] * (1 - innov))[0]
    drift_along = drift[..., 0] * noise.drift_px * grow[:, None]
    drift_across = drift[..., 1] * noise.drift_px / noise.along_ratio * grow[:, None]
    xy = true_xy + (along + drift_along)[..., None] * tan + (across + drift_across)[..., None] * nrm
    # jumps
    starts = rng.uniform(size=(N, F)) < noise.jump_prob
    for i, f in zip(*np.nonzero(starts)):
        L = int(rng.integers(1, 4))
        ang = rng.uniform(0, 2 * np.pi)
        mag = rng.uniform(*noise.jump_px)
        xy[i, f:f + L] += mag * np.array([math.cos(ang), math.sin(ang)])
    # occlusion gaps
    for i in range(N):
        rate = noise.gap_rate * (0.2 + 1.6 * s_node[i]) * F / (30.0 * fps)
        for _ in range(rng.poisson(rate)):
            L = int(np.clip(round(noise.gap_median_frames * math.exp(1.1 * rng.standard_normal())), 1,
                            noise.gap_max_frames))
            f0 = int(rng.integers(0, F))
            xy[i, f0:f0 + L] = np.nan
    # frame 0 is the user's annotation: the tracker returns the query point there exactly (as TAPIR does
    # on the real plant 2), so every node is observed, noise-free, in frame 0.
    xy[:, 0] = true_xy[:, 0]
    sigma = np.sqrt((s_along ** 2 + s_across ** 2) / 2)
    return xy, sigma
