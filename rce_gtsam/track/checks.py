"""Checks around tracking that a user should see: are the annotations on a textured, moving structure
(before tracking), and which nodes did the tracker lose (after)?

* :func:`annotation_warnings` — reads the first ``PROBE_FRAMES`` frames and flags an annotated point whose
  neighbourhood (``PATCH`` px square) has no image structure (gradient energy at the level of the sensor
  noise) or does not change over those frames (temporal change at the level of the sensor noise). The
  sensor-noise level is measured on the same frames: the median absolute frame-to-frame difference over
  the whole image (most of an image is still background), so no threshold is tuned to one camera.
* :func:`visibility_lines` — per-node visible share and a warning for every node lost in more than
  :data:`rce_gtsam.quality.LOST_SHARE` of the frames.
"""

from __future__ import annotations

import numpy as np

from ..quality import LOST_SHARE

#: Frames read to judge motion (1 s at 30 fps; the first frames of a clip).
PROBE_FRAMES = 30
#: Side of the square neighbourhood judged around a point, pixels.
PATCH = 9
#: A patch must exceed the sensor-noise level by this factor to count as textured / moving.
NOISE_FACTOR = 3.0


def _gray(image: np.ndarray) -> np.ndarray:
    return image.astype(np.float32).mean(axis=2) if image.ndim == 3 else image.astype(np.float32)


def annotation_warnings(frames: list[np.ndarray], points: np.ndarray,
                        root: int | None = None) -> tuple[dict[int, str], dict[int, str]]:
    """({point id: warning} for points with no image structure, {point id: note} for textured points that
    did not change over the frames) — annotations probably not on a textured, moving structure.

    ``frames``: the first frames (RGB or gray arrays); ``points``: (P, 2) pixels; ``root``: the graph's
    root id, which is exempt from the motion test (the base of a branch barely moves).
    """
    if len(frames) < 2:
        return {}, {}
    stack = np.stack([_gray(f) for f in frames])  # (K, H, W)
    step = np.abs(np.diff(stack, axis=0))
    # sensor noise (+ compression) per pixel and frame in grey levels; at least half an 8-bit step
    noise = max(float(np.median(step)), 0.5)
    gy, gx = np.gradient(stack[0])
    grad = np.hypot(gx, gy)
    grad_noise = float(np.median(grad))
    change = stack.std(axis=0)
    h = PATCH // 2
    H, W = stack.shape[1:]
    out, notes = {}, {}
    for i, (x, y) in enumerate(np.asarray(points, dtype=float)):
        xi, yi = int(round(x)), int(round(y))
        sl = (slice(max(yi - h, 0), min(yi + h + 1, H)), slice(max(xi - h, 0), min(xi + h + 1, W)))
        textured = float(grad[sl].max()) > NOISE_FACTOR * max(grad_noise, noise)
        moving = float(change[sl].max()) > NOISE_FACTOR * noise
        still = not moving and i != root
        if not textured:
            out[i] = (f"warning: point {i} at (x={x:.1f}, y={y:.1f}): no image structure"
                      + (f" and no change over the first {len(frames)} frames" if still else "")
                      + f" within {PATCH} px (sensor noise {noise:.2f} grey levels); is it on the branch? Its "
                        "segments will be flagged off_structure")
        elif still:
            notes[i] = (f"note: point {i} at (x={x:.1f}, y={y:.1f}): no change within {PATCH} px over the first "
                        f"{len(frames)} frames (fine near the base; elsewhere check it is on the branch)")
    return out, notes


def probe_frames(video, n: int = PROBE_FRAMES) -> list[np.ndarray]:
    """The first ``n`` frames of a video path (opened separately from the tracking pass)."""
    from .sources import open_video

    frames = []
    with open_video(video) as src:
        for frame in src:
            frames.append(frame.image)
            if len(frames) >= n:
                break
    return frames


def visibility_lines(visible: np.ndarray, node_ids=None) -> list[str]:
    """A per-node visibility summary (one line) plus one warning per node lost in more than
    ``LOST_SHARE`` of the frames. ``visible``: (P, F) bool."""
    visible = np.asarray(visible, dtype=bool)
    ids = list(range(visible.shape[0])) if node_ids is None else [int(n) for n in node_ids]
    share = visible.mean(axis=1) if visible.shape[1] else np.zeros(visible.shape[0])
    lines = ["visible share per node: " + ", ".join(f"{n} {100 * s:.0f}%" for n, s in zip(ids, share))]
    for n, s, v in zip(ids, share, visible):
        if s < 1 - LOST_SHARE:
            lines.append(f"warning: node {n} is lost in {100 * (1 - s):.0f}% of the frames (seen in {int(v.sum())} "
                         f"of {v.size}; more than {100 * LOST_SHARE:.0f}% lost): the segments at it will be "
                         "flagged tracking_lost")
    return lines
