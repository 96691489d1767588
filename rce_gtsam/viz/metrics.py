"""Per-node and per-bend summary numbers the figures plot, with moving-block bootstrap CIs.

Node motion (reference doc §2.4): root-relative displacement q(t) = |(p_i(t) - p_r(t)) - (p_i(t0) - p_r(t0))|
in pixels over the frames the node shares with the root (t0 = the first shared frame); its RMS per node.
Bend filtered RMS: sqrt(mean delta^2) over a bend's inlier frames, degrees.

CIs: percentile (2.5, 97.5) of the statistic over non-circular moving-block resamples of the value series
(block 25 frames, 300 resamples — the published figures' settings, reference doc §2.11), one seeded RNG
per series so a CI does not depend on the order series are processed in.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

BLOCK = 25    # frames; the published per-metric bootstrap's block length (about 1 s at 30 fps)
N_BOOT = 300  # the published per-metric bootstrap's resample count
MIN_VALUES = 8  # fewer values than this: no CI (as the published code)


def rms_ci(values: np.ndarray, seed: int = 0, block: int = BLOCK, n_boot: int = N_BOOT) -> tuple[float, float, float]:
    """(RMS, CI low, CI high) of a series (NaN dropped) with a moving-block bootstrap."""
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return (np.nan, np.nan, np.nan)
    rms = float(np.sqrt(np.mean(v ** 2)))
    if v.size < MIN_VALUES:
        return (rms, np.nan, np.nan)
    rng = np.random.default_rng(seed)
    T = v.size
    L = max(3, min(block, T))
    n_blocks = int(np.ceil(T / L))
    starts = rng.integers(0, T - L + 1, size=(n_boot, n_blocks))
    # sum of v^2 over each resample's blocks (the last one cut to reach T values) from prefix sums
    S = np.concatenate([[0.0], np.cumsum(v ** 2)])
    ends = np.full(n_blocks, L)
    ends[-1] = T - (n_blocks - 1) * L
    boot = np.sqrt((S[starts + ends] - S[starts]).sum(axis=1) / T)
    lo, hi = np.percentile(boot, [2.5, 97.5])
    return (rms, float(lo), float(hi))


@dataclass(frozen=True)
class SeriesStats:
    """Per-entity statistic with CI. ``label``: entity names; ``root_distance_px``; ``zone``; value/low/high."""

    label: list[str]
    root_distance_px: np.ndarray
    zone: np.ndarray
    value: np.ndarray
    low: np.ndarray
    high: np.ndarray


def node_motion(result, seed: int = 0) -> SeriesStats:
    """Root-relative motion RMS (pixels) per node on the smoothed tracks, observed frames only."""
    from ..pipeline import observed_positions
    xy = observed_positions(result.smoothed)
    ids = result.tracks.node_ids
    r = int(np.flatnonzero(ids == result.graph.root)[0])
    rel = xy - xy[r][None]
    out = []
    for i, n in enumerate(ids):
        ok = np.isfinite(rel[i]).all(axis=1)
        if not ok.any():
            out.append((np.nan, np.nan, np.nan))
            continue
        t0 = np.flatnonzero(ok)[0]
        q = np.linalg.norm(rel[i][ok] - rel[i][t0], axis=1)
        out.append(rms_ci(q, seed=seed + int(n)))
    order = np.argsort([result.geometry.root_distance_px[int(n)] for n in ids], kind="stable")
    arr = np.array(out)[order]
    return SeriesStats(label=[str(int(ids[k])) for k in order],
                       root_distance_px=np.array([result.geometry.root_distance_px[int(ids[k])] for k in order]),
                       zone=np.array([result.geometry.zone[int(ids[k])] for k in order]),
                       value=arr[:, 0], low=arr[:, 1], high=arr[:, 2])


def bend_rms(result, bending=None, seed: int = 0) -> SeriesStats:
    """Filtered bending RMS (degrees) per bend, over inlier frames, with CI; ordered by root distance."""
    b = bending if bending is not None else result.bending
    out = []
    for k, bend in enumerate(b.bends):
        d = np.where(b.inlier[k], b.delta_deg[k], np.nan)
        out.append(rms_ci(d, seed=seed + k))
    rd = np.array([result.geometry.root_distance_px[bd.child] for bd in b.bends])
    order = np.argsort(rd, kind="stable")
    arr = np.array(out).reshape(-1, 3)[order]
    return SeriesStats(label=[f"{b.bends[k].joint}→{b.bends[k].child}" for k in order], root_distance_px=rd[order],
                       zone=np.array([result.geometry.zone[b.bends[k].child] for k in order]),
                       value=arr[:, 0], low=arr[:, 1], high=arr[:, 2])
