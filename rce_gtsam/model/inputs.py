"""Checking and normalising the data a response model is fitted to."""

from __future__ import annotations

import numpy as np

from ..errors import InputError


def validate_inputs(Y, weights=None, root_distance=None, source: str = "response matrix"):
    """Check and normalise inputs: returns Y (E, T) float, W (E, T) >= 0 (0 where Y is NaN), s (E,)."""
    try:
        Y = np.array(Y, dtype=float)
    except (TypeError, ValueError):
        raise InputError(source, "Y must be a numeric (edges x frames) array") from None
    if Y.ndim != 2:
        raise InputError(source, f"Y must be 2-D (edges x frames), got shape {Y.shape}")
    E, T = Y.shape
    if E < 2 or T < 3:
        raise InputError(source, f"need at least 2 edges and 3 frames, got {E} x {T}")
    if np.isinf(Y).any():
        e, t = np.argwhere(np.isinf(Y))[0]
        raise InputError(source, "Y contains an infinite value", where=f"row {e}, column {t}")
    obs = np.isfinite(Y)
    if weights is None:
        W = obs.astype(float)
    else:
        W = np.array(weights, dtype=float)
        if W.shape != Y.shape:
            raise InputError(source, f"weights shape {W.shape} differs from Y shape {Y.shape}")
        bad = obs & ~(np.isfinite(W) & (W >= 0))
        if bad.any():
            e, t = np.argwhere(bad)[0]
            raise InputError(source, "weights must be finite and >= 0 where Y is observed",
                             where=f"row {e}, column {t}")
        W = np.where(obs, W, 0.0)
    empty = ~(W > 0).any(axis=1)
    if empty.any():
        raise InputError(source, "an edge has no observed (positively weighted) frame",
                         where=f"row {int(np.flatnonzero(empty)[0])}")
    if root_distance is None:
        s = np.linspace(0.0, 1.0, E) if E > 1 else np.zeros(1)
    else:
        s = np.array(root_distance, dtype=float).reshape(-1)
        if s.shape != (E,) or not np.isfinite(s).all():
            raise InputError(source, f"root_distance must be {E} finite numbers (one per row), got shape {s.shape}")
        top = s.max()
        s = s / top if top > 1.0 + 1e-9 else s
    return Y, W, s
