"""Where did the tracker lose nodes, and does a finding survive without those frames?

A tracker that loses nodes in gusts (missing not at random) leaves its errors next to the gaps: the frames
before a node is lost and after it is found again carry its worst positions (a template sliding off, a re-found
node a pixel away), and they come with the strongest motion, at the same frames in every segment near the tip.
Two row sets that share no tracked node then share a time course, which is what a second excitation or a slow
per-segment course shows too. Measured on the user's path (``benchmarks/bench_user_path.py``: our tracker on
rendered effect-free video), the course common to the two sets (p 0.0005) was named an offset where the tip's
residuals burst around its gaps.

:func:`away_from_gaps` gives the baseline fit with every segment-frame within :data:`GAP_MARGIN_FRAMES` of a
frame the segment was not observed in left out; a finding whose evidence is a course common to the row sets
must show it there too (the diagnosis re-runs the shared-course test on it and takes the larger p).
Units: frames.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy import ndimage

from .result import TestResult

#: Frames on each side of a missing segment-frame that count as the tracker's: a few frames of a template
#: sliding off before a node is declared lost, and of a re-found node settling.
GAP_MARGIN_FRAMES = 5


def near_gaps(Y: np.ndarray, margin: int = GAP_MARGIN_FRAMES) -> np.ndarray:
    """(E, T) bool: observed entries of ``Y`` (NaN = missing) within ``margin`` frames of a missing entry in the
    same row. Rows with no missing entry have none."""
    missing = ~np.isfinite(np.asarray(Y, float))
    if margin <= 0 or not missing.any():
        return np.zeros_like(missing)
    grown = ndimage.binary_dilation(missing, structure=np.ones((1, 2 * margin + 1), bool))
    return grown & ~missing


def away_from_gaps(fit, margin: int = GAP_MARGIN_FRAMES):
    """A copy of ``fit`` (a ``ModelFit``) with the entries :func:`near_gaps` marks made missing (Y NaN, weight 0);
    kappa, z and the states are kept (residuals are recomputed from them)."""
    near = near_gaps(fit.Y, margin)
    if not near.any():
        return fit
    Y = np.where(near, np.nan, fit.Y)
    W = np.where(near, 0.0, fit.weights)
    return replace(fit, Y=Y, weights=W, _cache={})


def near_gap_share(fit, margin: int = GAP_MARGIN_FRAMES) -> dict:
    """How much of the baseline's residual power sits next to the gaps: {"entries": share of observed entries
    near a gap, "power": share of the residuals' squared sum there}. A power share well above the entry share
    says the misfit concentrates where the tracker lost nodes."""
    R = np.asarray(fit.residuals, float)
    ok = np.isfinite(R)
    near = near_gaps(fit.Y, margin) & ok
    P = np.where(near, R * R, 0.0)
    total = float(np.sum(np.where(ok, R * R, 0.0)))
    rows = [int(i) for i in np.argsort(-P.sum(axis=1))[:3] if P[i].sum() > 0]
    return {"entries": float(near.sum() / max(ok.sum(), 1)),
            "power": float(P.sum() / total) if total > 0 else 0.0, "rows": rows}


#: The misfit "concentrates where the tracker lost nodes" when the share of residual power next to the gaps is at
#: least this multiple of the share of segment-frames there (a stated rule: white noise gives about 1).
CONCENTRATION = 2.0


def tracker_text(share: dict | None, labels) -> str:
    """A sentence naming the tracker where the baseline's misfit concentrates next to the gaps (:func:`near_gap_share`
    at least :data:`CONCENTRATION` times the entries' share), with the segments it is worst in; else empty."""
    if not share or share["entries"] <= 0 or share["power"] < CONCENTRATION * share["entries"]:
        return ""
    where = ", ".join(str(labels[i]) for i in share.get("rows", []) if i < len(labels))
    return (f" The tracker: {100 * share['power']:.0f}% of what the rank-1 model leaves sits in the "
            f"{100 * share['entries']:.0f}% of segment-frames within {GAP_MARGIN_FRAMES} frames of a frame where a "
            f"node was lost (worst in {where}); look at the tracks there (rce review) before reading it as "
            f"physics.")


AWAY_NULL = ("multivariate phase surrogates of one node-disjoint row set's residuals against the other's (2000), "
             f"the segment-frames within {GAP_MARGIN_FRAMES} frames of a lost node left out")
AWAY_CALIBRATION = "benchmarks/bench_user_path.py (our tracker on rendered effect-free video)"


def shared_course_away_result(test, threshold_p: float) -> TestResult:
    """The shared-course test on :func:`away_from_gaps` of the baseline (a
    :class:`~rce_gtsam.diagnosis.score_test.ScoreTest`) read at ``threshold_p``."""
    return TestResult("shared_course_away_from_gaps", float(test.q), float(test.p), float(threshold_p), AWAY_NULL,
                      AWAY_CALIBRATION)
