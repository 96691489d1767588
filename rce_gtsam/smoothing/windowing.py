"""Overlapping frame windows for solving a long recording piece by piece.

The smoother's factor graph is banded in time (temporal factors join frames at most 2 apart), so the
influence of a measurement on the estimate at a frame dies out geometrically with the number of
*observed* frames in between (for the default preset, w_a / w_m = 20, by a factor ~e^-0.33 per frame:
about 1e-14 after 100). A long recording is therefore solved in windows: each window's **core** of
about ``core`` frames is solved together with a **margin** (burn-in) on each side that holds at least
``margin`` observed frames of every node, and only the core's results are kept. The cores tile the
recording exactly. Margins stop at the recording's ends and are capped at ``max_margin`` frames, so a
window never grows without bound (a node unseen for longer than that is an error, see
:func:`plan_windows`).

Units: frames (indices 0..F-1, end-exclusive ranges).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Window:
    """Frames ``lo:hi`` are solved together; the results at ``core_lo:core_hi`` are kept."""

    lo: int
    hi: int
    core_lo: int
    core_hi: int

    @property
    def core(self) -> slice:
        """The core's frames relative to the window's first frame."""
        return slice(self.core_lo - self.lo, self.core_hi - self.lo)


def plan_windows(observed: np.ndarray, core: int, margin: int, max_margin: int | None = None) -> list[Window]:
    """Split frames 0..F-1 into overlapping windows.

    Parameters
    ----------
    observed: (N, F) bool observation mask.
    core: target core length in frames; ``F <= core`` (or ``core <= 0``) gives one window, the whole
        recording (no margins, the exact full solve).
    margin: observed frames of every node that each margin must hold (where the recording allows).
    max_margin: cap on a margin's length in frames (default ``core``).

    Returns windows in frame order; cores are contiguous and cover 0..F-1, each ``<= core`` frames.
    """
    N, F = observed.shape
    if core <= 0 or F <= core:
        return [Window(0, F, 0, F)]
    cap = int(core if max_margin is None else max_margin)
    n_win = -(-F // core)
    cuts = np.round(np.linspace(0, F, n_win + 1)).astype(int)
    # counts[i, f] = observations of node i in frames < f
    counts = np.zeros((N, F + 1), dtype=np.int64)
    np.cumsum(observed, axis=1, out=counts[:, 1:])
    m = max(int(margin), 0)
    out = []
    for a, b in zip(cuts[:-1], cuts[1:]):
        # left: the largest lo with counts[i, a] - counts[i, lo] >= m for every node (0 if none has m)
        need_left = counts[:, a] - m
        lo = 0 if (need_left < 0).any() else int(min(_last_at_most(counts[i], need_left[i], a) for i in range(N)))
        need_right = counts[:, b] + m
        hi = F if (need_right > counts[:, F]).any() else int(max(_first_at_least(counts[i], need_right[i], b) for i in range(N)))
        out.append(Window(max(lo, a - cap), min(hi, b + cap), int(a), int(b)))
    return out


def _last_at_most(c: np.ndarray, value: int, end: int) -> int:
    """Largest f <= end with c[f] <= value (c non-decreasing)."""
    return min(int(np.searchsorted(c[:end + 1], value, side="right")) - 1, end)


def _first_at_least(c: np.ndarray, value: int, start: int) -> int:
    """Smallest f >= start with c[f] >= value (c non-decreasing)."""
    return max(int(np.searchsorted(c, value, side="left")), start)
