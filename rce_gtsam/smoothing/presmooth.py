"""Moving-average pre-smoothing of point tracks (reference pipeline §2.1, reproduced exactly).

Per node and per axis (x and y independently) the node's *observed* samples are taken in frame
order and filtered with a centred box kernel. The filter runs over the sample index, not the frame
number, so it averages straight across occlusion gaps (as the published code does). The ends are
handled by repeating the first / last sample ``window // 2`` times ("edge" padding) followed by a
"valid" convolution, so the output has as many samples as the input and, for ``window = 5``, the
first value is ``(3*x0 + x1 + x2) / 5``.

Units: pixels in, pixels out; ``window`` is a number of samples (observed frames).
"""

from __future__ import annotations

import numpy as np

from ..tracks import Tracks


def effective_window(window: int) -> int:
    """The window actually used: an even window is bumped up by one (paper); ``<= 1`` means 1 (off)."""
    if isinstance(window, bool) or not isinstance(window, (int, np.integer)):
        raise TypeError(f"moving-average window must be an integer number of samples, got {window!r}")
    window = int(window)
    if window <= 1:
        return 1
    return window + 1 if window % 2 == 0 else window


def moving_average_1d(x: np.ndarray, window: int) -> np.ndarray:
    """Centred box filter of a 1-D sample sequence with edge padding (same length as ``x``)."""
    w = effective_window(window)
    x = np.asarray(x, dtype=float)
    if w == 1 or x.size == 0:
        return x.copy()
    half = w // 2
    padded = np.pad(x, half, mode="edge")
    return np.convolve(padded, np.full(w, 1.0 / w), mode="valid")


def moving_average(tracks: Tracks, window: int) -> Tracks:
    """Moving-average every node's observed samples, per axis (paper §2.1).

    Parameters
    ----------
    tracks: input tracks; NaN entries are unobserved and are skipped (the kernel runs across gaps).
    window: box width in samples; an even width is bumped to the next odd one; ``<= 1`` returns an
        unchanged copy.

    Returns
    -------
    New :class:`Tracks` with the same node ids, frame count, observation mask and ``sigma_px``
    (passed through unchanged); unobserved entries stay NaN.
    """
    w = effective_window(window)
    xy = tracks.xy.copy()
    if w > 1:
        observed = tracks.observed
        for i in range(tracks.n_nodes):
            frames = np.flatnonzero(observed[i])
            for axis in (0, 1):
                xy[i, frames, axis] = moving_average_1d(tracks.xy[i, frames, axis], w)
    sigma = None if tracks.sigma_px is None else tracks.sigma_px.copy()
    # The source stays the input's, so errors raised downstream name the user's file.
    return Tracks(node_ids=tracks.node_ids.copy(), xy=xy, sigma_px=sigma, source=tracks.source)
