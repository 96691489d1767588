"""Synthetic length channels for the out-of-plane tests: a chain of segments and smooth unit-RMS courses."""

from __future__ import annotations

import numpy as np

from rce_gtsam.diagnosis.length_channel import LengthChannel


def smooth_course(rng, T, width=15):
    """(T,) a smooth course (a moving average of white noise over ``width`` frames), unit SD."""
    x = np.convolve(rng.standard_normal(T + 4 * width), np.ones(width) / width, mode="same")[2 * width:-2 * width]
    return x / x.std()


def chain_channel(rel: np.ndarray) -> LengthChannel:
    """The LengthChannel of a chain 0 -> 1 -> ... whose segments' relative length changes are ``rel`` (S, T)."""
    S, T = rel.shape
    return LengthChannel(rel=rel, length_px=np.full(S, 20.0), segments=[(i, i + 1) for i in range(S)],
                         root_distance=np.arange(1, S + 1) / S, frames=np.arange(T))
