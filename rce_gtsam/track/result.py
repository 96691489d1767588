"""What a tracker returns: :class:`TrackResult`.

Coordinates are ORIGINAL-image pixels: x right, y down, pixel centres at integer coordinates (the
OpenCV convention; the top-left pixel covers [-0.5, 0.5] x [-0.5, 0.5]).

Invisible entries keep a finite position (the tracker's prediction) and are written to CSV with
``visible=0``; :func:`rce_gtsam.tracks.load_tracks` treats those rows as not observed. ``sigma_px`` is
the 1-sigma position uncertainty in pixels (per axis) of each estimate.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..tracks import write_table_atomic


@dataclass(frozen=True, eq=False)
class TrackResult:
    """Tracks of P points over F frames.

    point_ids: (P,) int -- annotation index of each point.
    xy: (P, F, 2) float -- positions, original pixels; finite everywhere.
    visible: (P, F) bool -- False = occluded or lost (the position is then only a prediction).
    sigma_px: (P, F) float -- 1-sigma position uncertainty per axis, pixels, > 0.
    fps: frames per second of the source video.
    info: free-form diagnostics of the tracker (counts, timings).
    z_mm, z_sigma_mm: (P, F) float or None -- depth of each point (mm, NaN = none) and its 1-sigma (mm), from a
    recording with depth (:mod:`rce_gtsam.track.depth_tracks`); written as CSV columns ``z_mm, z_sigma_mm``.
    """

    point_ids: np.ndarray
    xy: np.ndarray
    visible: np.ndarray
    sigma_px: np.ndarray
    fps: float
    info: dict = field(default_factory=dict)
    z_mm: np.ndarray | None = None
    z_sigma_mm: np.ndarray | None = None

    def __post_init__(self):
        p = len(self.point_ids)
        if self.xy.shape[:1] != (p,) or self.xy.ndim != 3 or self.xy.shape[2] != 2:
            raise ValueError(f"xy must be (P={p}, F, 2), got {self.xy.shape}")
        f = self.xy.shape[1]
        for name in ("visible", "sigma_px"):
            if getattr(self, name).shape != (p, f):
                raise ValueError(f"{name} must be (P={p}, F={f}), got {getattr(self, name).shape}")
        if not np.isfinite(self.xy).all() or not (np.isfinite(self.sigma_px) & (self.sigma_px > 0)).all():
            raise ValueError("TrackResult positions and sigmas must be finite (sigmas > 0)")

    @property
    def n_points(self) -> int:
        return self.xy.shape[0]

    @property
    def n_frames(self) -> int:
        return self.xy.shape[1]

    def to_frame(self) -> pd.DataFrame:
        """Long table ``point_id, frame, x, y, visible (0/1), sigma_px[, z_mm, z_sigma_mm]``; one row per point and
        frame (depth columns only with depth; empty where a point has no depth)."""
        p, f = self.visible.shape
        pid = np.repeat(np.asarray(self.point_ids, dtype=np.int64), f)
        frame = np.tile(np.arange(f, dtype=np.int64), p)
        return pd.DataFrame({"point_id": pid, "frame": frame,
                             "x": self.xy[:, :, 0].ravel(), "y": self.xy[:, :, 1].ravel(),
                             "visible": self.visible.ravel().astype(np.int64),
                             "sigma_px": self.sigma_px.ravel(),
                             **({} if self.z_mm is None else {"z_mm": self.z_mm.ravel(),
                                                               "z_sigma_mm": self.z_sigma_mm.ravel()})})

    def write_csv(self, path: str | Path) -> Path:
        """Write :meth:`to_frame` atomically at full precision (``rce run`` analyses exactly this file, so
        ``rce track`` + ``rce analyze`` give what ``rce run`` gives) and return the path."""
        write_table_atomic(self.to_frame(), path)
        return Path(path)
