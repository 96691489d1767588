"""Frames a reviewer should look at: where the tracker lost a node, was unsure, or jumped.

Rules (per node, so a node's own noise level sets its thresholds; all in pixels):

* **lost**: the node is not visible (or has no row) in the frame;
* **σ**: its reported 1-sigma exceeds ``max(sigma_min_px, sigma_factor x`` its median visible sigma``)`` -- three
  times its usual uncertainty, and at least 1 px (below that a position is good enough for bend angles over
  segments of tens of pixels);
* **jump**: its second difference ``|x[f+1] - 2 x[f] + x[f-1]|`` (px) exceeds ``max(jump_min_px, jump_mads x
  1.4826 MAD)`` of its own second differences -- a one-frame spike the smooth sway of a branch does not make
  (6 robust standard deviations: about 1 false flag in 10^8 frames under Gaussian noise).

Flagged frames are merged into runs of consecutive frames for the list on the review page.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class FlagRules:
    sigma_factor: float = 3.0
    sigma_min_px: float = 1.0
    jump_mads: float = 6.0
    jump_min_px: float = 2.0


def node_flags(xy: np.ndarray, visible: np.ndarray, sigma: np.ndarray | None,
               rules: FlagRules = FlagRules()) -> dict[str, np.ndarray]:
    """(P, F) boolean masks ``lost``, ``sigma``, ``jump`` for positions ``xy`` (P, F, 2) px (NaN = no row)."""
    known = np.isfinite(xy).all(axis=2)
    lost = ~(visible & known)
    big = np.zeros_like(lost)
    if sigma is not None:
        for i in range(len(xy)):
            s = sigma[i][~lost[i]]
            if s.size:
                big[i] = ~lost[i] & (sigma[i] > max(rules.sigma_min_px, rules.sigma_factor * float(np.median(s))))
    jump = np.zeros_like(lost)
    if xy.shape[1] >= 3:
        acc = np.hypot(*(xy[:, 2:] - 2 * xy[:, 1:-1] + xy[:, :-2]).transpose(2, 0, 1))  # (P, F-2) at frames 1..F-2
        ok = ~lost[:, 2:] & ~lost[:, 1:-1] & ~lost[:, :-2]
        for i in range(len(xy)):
            a = acc[i][ok[i]]
            if a.size < 3:
                continue
            mad = 1.4826 * float(np.median(np.abs(a - np.median(a))))
            jump[i, 1:-1] = ok[i] & (acc[i] > max(rules.jump_min_px, rules.jump_mads * mad))
    return {"lost": lost, "sigma": big, "jump": jump}


def flagged_runs(flags: dict[str, np.ndarray], node_ids) -> list[dict]:
    """Runs of consecutive flagged frames: ``{"start", "end", "nodes": {"lost": [...], "sigma": [...],
    "jump": [...]}}`` (node ids flagged anywhere in the run, per reason)."""
    any_f = np.zeros(next(iter(flags.values())).shape[1], bool)
    for m in flags.values():
        any_f |= m.any(axis=0)
    runs, f, n_f = [], 0, len(any_f)
    while f < n_f:
        if not any_f[f]:
            f += 1
            continue
        g = f
        while g + 1 < n_f and any_f[g + 1]:
            g += 1
        runs.append({"start": f, "end": g,
                     "nodes": {k: [int(node_ids[i]) for i in np.flatnonzero(m[:, f:g + 1].any(axis=1))]
                               for k, m in flags.items()}})
        f = g + 1
    return runs
