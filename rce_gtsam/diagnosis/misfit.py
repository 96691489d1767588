"""Where the rank-1 baseline fails: the worst segments and frame windows (:func:`worst_edges_and_frames`) and each
candidate effect's own statistics in its residuals (:func:`residual_statistics`). Descriptions for the report;
no test and no decision.

Units: degrees (residual RMS), frames.
"""

from __future__ import annotations

import math

import numpy as np

from .. import effects as effects_mod
from ..model import ModelFit
from .statistics import ResidualContext


def resolve_effects(effects, n_edges: int) -> list:
    """The candidate :class:`~rce_gtsam.effects.Effect` instances from names or instances (None: every registered
    effect), less those that need more rows than ``n_edges``."""
    if effects is None:
        effects = list(effects_mod.names())
    out = [effects_mod.make(e) if isinstance(e, str) else e for e in effects]
    return [e for e in out if n_edges >= e.min_rows and e.available]  # available: has what it reads


def residual_statistics(fit: ModelFit, effects=None) -> dict[str, dict]:
    """Each candidate effect's own evidence in the residuals of a (baseline) fit: {name: statistics}
    (:meth:`rce_gtsam.effects.Effect.evidence`; default: every registered effect)."""
    ctx = ResidualContext.from_fit(fit)
    effects = resolve_effects(effects, len(fit.kappa))
    return {eff.name: eff.evidence(ctx) for eff in effects}


def worst_edges_and_frames(fit: ModelFit, labels, block_length: int, frames=None, n: int = 3):
    """The n edges and the n non-overlapping ``block_length``-frame windows with the largest residual RMS."""
    R = fit.residuals
    E, T = R.shape
    ok = np.isfinite(R)
    R2 = np.where(ok, R * R, 0.0)
    # mean squares over the observed entries, NaN for an edge or frame with none (a frame every edge lost)
    edge_rms = np.sqrt(np.where(ok.any(axis=1), R2.sum(axis=1) / np.maximum(ok.sum(axis=1), 1), np.nan))
    frame_ms = np.where(ok.any(axis=0), R2.sum(axis=0) / np.maximum(ok.sum(axis=0), 1), np.nan)
    overall = float(np.sqrt(np.nanmean(R * R)))
    order = np.argsort(-np.nan_to_num(edge_rms, nan=-1))
    worst_e = [{"edge": str(labels[i]), "row": int(i), "residual_rms_deg": float(edge_rms[i]),
                "ratio_to_overall": float(edge_rms[i] / max(overall, 1e-300))} for i in order[:n]]
    fm = np.nan_to_num(frame_ms, nan=0.0)
    L = max(1, min(block_length, T))
    win = np.convolve(fm, np.ones(L) / L, mode="valid")  # mean square over each L-frame window
    taken = np.zeros(len(win), bool)
    worst_f = []
    fr = np.arange(T) if frames is None else np.asarray(frames)
    for _ in range(n):
        cand = np.where(taken, -1.0, win)
        j = int(np.argmax(cand))
        if cand[j] < 0:
            break
        worst_f.append({"first_frame": int(fr[j]), "last_frame": int(fr[j + L - 1]),
                        "residual_rms_deg": float(math.sqrt(win[j])),
                        "ratio_to_overall": float(math.sqrt(win[j]) / max(overall, 1e-300))})
        taken[max(0, j - L + 1): j + L] = True
    summary = {"overall_rms_deg": overall, "per_edge_rms_deg": edge_rms,
               "per_frame_rms_deg": np.sqrt(frame_ms)}
    return worst_e, worst_f, summary
