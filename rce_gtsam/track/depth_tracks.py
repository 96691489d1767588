"""Depth columns of a tracks CSV: ``z_mm`` (depth along the optical axis, mm; empty = none) and ``z_sigma_mm``
(its 1-sigma, mm), written by ``rce track``/``rce run`` on a RealSense recording with depth. A 2-D tracks file has
neither column and reads as before (:func:`rce_gtsam.tracks.load_tracks` ignores them)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pandas as pd

from ..camera import CameraIntrinsics
from ..errors import InputError
from ..tracks import Tracks
from .depth import RealSenseDepthSource
from .depth_sample import NodeDepth, sample_depth
from .result import TrackResult

DEPTH_COLUMNS = ("z_mm", "z_sigma_mm")


def add_depth(result: TrackResult, recording: str | Path) -> tuple[TrackResult, NodeDepth, CameraIntrinsics]:
    """``result`` with the depth of every visible point sampled from ``recording`` (a second pass over it), the
    sampled :class:`NodeDepth`, and the colour stream's intrinsics."""
    with RealSenseDepthSource(recording) as src:
        depth = sample_depth(src, result.xy, result.visible)
        cam = src.intrinsics
    return dataclasses.replace(result, z_mm=depth.z_mm, z_sigma_mm=depth.z_sigma_mm), depth, cam


def read_depth_columns(path: str | Path, tracks: Tracks) -> tuple[np.ndarray, np.ndarray] | None:
    """(z_mm, z_sigma_mm), each (N, F) in the order of ``tracks`` (NaN = no depth or not observed), from the tracks
    CSV ``path``; None when it has no depth columns. A non-numeric, non-positive or sigma-less depth is an
    :class:`InputError` naming its line."""
    head = pd.read_csv(path, nrows=0)
    cols = [c.strip() for c in head.columns]
    if not set(DEPTH_COLUMNS) <= set(cols):
        return None
    df = pd.read_csv(path, dtype=str, keep_default_na=False, skipinitialspace=True)
    df.columns = cols
    z = pd.to_numeric(df["z_mm"].str.strip().replace("", "nan"), errors="coerce")
    s = pd.to_numeric(df["z_sigma_mm"].str.strip().replace("", "nan"), errors="coerce")
    for name, raw, num in (("z_mm", df["z_mm"], z), ("z_sigma_mm", df["z_sigma_mm"], s)):
        bad = num.isna() & ~raw.str.strip().str.lower().isin(["", "nan"])
        if bad.any():
            r = int(np.flatnonzero(bad.to_numpy())[0])
            raise InputError(path, f"column '{name}' has a non-numeric value {raw.iloc[r]!r}", f"line {r + 2}")
    zv, sv = z.to_numpy(float), s.to_numpy(float)
    has = np.isfinite(zv)
    bad = has & ~((zv > 0) & np.isfinite(sv) & (sv > 0))
    if bad.any():
        r = int(np.flatnonzero(bad)[0])
        raise InputError(path, f"a depth needs z_mm > 0 and z_sigma_mm > 0 (mm), got {df['z_mm'].iloc[r]!r} and "
                               f"{df['z_sigma_mm'].iloc[r]!r}", f"line {r + 2}")
    row = {int(n): i for i, n in enumerate(tracks.node_ids)}
    pid = pd.to_numeric(df["point_id"], errors="coerce").to_numpy()
    frame = pd.to_numeric(df["frame"], errors="coerce").to_numpy()
    keep = has & np.isin(pid, list(row)) & (frame < tracks.n_frames)
    if "visible" in df.columns:
        keep &= pd.to_numeric(df["visible"], errors="coerce").to_numpy() == 1
    out_z = np.full((tracks.n_nodes, tracks.n_frames), np.nan)
    out_s = np.full_like(out_z, np.nan)
    ii = np.array([row[int(p)] for p in pid[keep]], dtype=int)
    ff = frame[keep].astype(int)
    out_z[ii, ff], out_s[ii, ff] = zv[keep], sv[keep]
    out_z[~tracks.observed] = np.nan
    out_s[~tracks.observed] = np.nan
    return out_z, out_s
