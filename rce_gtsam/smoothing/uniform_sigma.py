"""One measurement sigma for the whole recording in the smoother's solve, the tracker's own sigmas in its covariances.

Why (issue #38): the smoother is a low-pass filter whose cut-off is set by the ratio of a measurement's sigma to the
acceleration prior's. With each observation's own sigma, a node the tracker is less sure of (or a fast frame, where
its sigma grows with motion blur) is smoothed harder, so its bends lose more of their amplitude than its
neighbours'. The rank-1 fit reads that unequal attenuation as compliance: on the texture bed, the TRUE positions
with the tracker's sigmas gave kappa a log-RMSE of 0.16 (truth inside the 95 % CI on 64 % of segments), the same
positions with one sigma 0.03. One filter applied to every node and frame instead attenuates every bend alike, which
the excitation z absorbs and kappa does not see.

So the positions are solved with the recording's median observed sigma (px) at every observation, and the
marginal covariances are then scaled back to each observation's own sigma: node i's block at frame t by
r_i(t) = sigma_i(t) / sigma_median on each side (D Sigma D with D = diag(r)), which is exact for an observation
that the prior does not inform and keeps the smoother's correlations. Frames where a node was not observed keep
r = 1 (they are not fitted: downstream uses observed frames only).
"""

from __future__ import annotations

import numpy as np

from ..tracks import Tracks


def uniform_sigma(tracks: Tracks) -> tuple[Tracks, np.ndarray | None]:
    """(tracks with every observed sigma set to the median observed sigma, (N, F) ratio own / median sigma, 1 where
    not observed); ``(tracks, None)`` unchanged when the tracks carry no sigma."""
    if tracks.sigma_px is None:
        return tracks, None
    obs = tracks.observed
    s = tracks.sigma_px
    med = float(np.median(s[obs])) if obs.any() else 1.0
    ratio = np.where(obs, s / med, 1.0)
    flat = np.where(obs, med, np.nan)
    return Tracks(node_ids=tracks.node_ids, xy=tracks.xy, sigma_px=flat, source=tracks.source,
                  lost_nodes=tracks.lost_nodes), ratio


def rescale_covariances(cov: np.ndarray, frame_cov: np.ndarray, ratio: np.ndarray) -> None:
    """In place: node i's marginal ``cov`` (N, F, 2, 2) times r_i(t)^2 and the joint ``frame_cov`` (F, 2N, 2N)
    as D Sigma D with D = diag(r(t)) repeated per axis; ``ratio`` (N, F)."""
    cov *= (ratio ** 2)[:, :, None, None]
    d = np.repeat(ratio.T, 2, axis=1).astype(frame_cov.dtype)  # (F, 2N)
    frame_cov *= d[:, :, None]
    frame_cov *= d[:, None, :]
