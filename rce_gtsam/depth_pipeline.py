"""The 3-D analysis beside the 2-D one, for recordings with depth: tracks + depth -> 3-D smoother -> 3-D bends
(in and out of the branch plane) -> kappa from both, with the 2-D kappa beside it.

:func:`analyze_3d` takes a finished 2-D :class:`~rce_gtsam.pipeline.AnalysisResult` (its tracks, preset, rest
geometry and kappa) and the tracks' depths; :func:`write_3d` writes ``kappa_3d.csv`` and ``depth3d.json``.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from .bending.angles3d import Bending3D, compute_bending_3d
from .camera import CameraIntrinsics
from .fileio import write_text_atomic
from .model.kappa3d import Kappa3D, fit_kappa_3d
from .smoothing.smoother3d import Smoothed3D, smooth_tracks_3d
from .tracks import lost_nodes, write_table_atomic

KAPPA_3D_CSV = "kappa_3d.csv"
DEPTH_JSON = "depth3d.json"


@dataclass(frozen=True, eq=False)
class Depth3DResult:
    """smoothed: 3-D positions (mm); bending: 3-D bends; kappa: kappa from 3-D angles; kappa_2d: (E,) the 2-D
    kappa of the same rows; intrinsics: colour stream (px); depth_coverage: share of observed node-frames with a
    depth; timings_s: seconds (``smooth_3d``, and the 2-D ``smooth`` of the same recording for comparison)."""

    smoothed: Smoothed3D
    bending: Bending3D
    kappa: Kappa3D
    kappa_2d: np.ndarray
    intrinsics: CameraIntrinsics
    depth_coverage: float
    timings_s: dict = field(default_factory=dict)

    def table(self) -> pd.DataFrame:
        """One row per segment: kappa from 3-D angles with its 95 % CI, from the in-plane bends only, the 2-D
        kappa, and the RMS in-plane bending and out-of-plane swing (deg)."""
        k = self.kappa
        return pd.DataFrame({
            "edge": [f"{j}->{c}" for j, c in k.edges],
            "kappa_3d": k.kappa,
            "kappa_3d_ci_low": np.full(len(k.edges), np.nan) if k.ci_low is None else k.ci_low,
            "kappa_3d_ci_high": np.full(len(k.edges), np.nan) if k.ci_high is None else k.ci_high,
            "kappa_in_plane": k.kappa_in_plane,
            "kappa_2d": self.kappa_2d,
            "bend_rms_deg": k.bend_rms_deg,
            "swing_rms_deg": k.swing_rms_deg,
        })

    def report(self) -> dict:
        r = self.smoothed.report
        return {"intrinsics": self.intrinsics.to_dict(), "depth_coverage": self.depth_coverage,
                "branch_plane_tilt_deg": self.kappa.tilt_deg, "branch_plane_normal": self.bending.normal.tolist(),
                "smoother_3d": {"iterations": r.iterations, "n_depth": r.n_depth, "n_depth_dropped": r.n_depth_dropped,
                                "mm_per_px": r.mm_per_px, "seconds": r.seconds_total},
                "timings_s": self.timings_s, "segments": self.kappa.as_dict()["segments"],
                "kappa_2d": [float(v) for v in self.kappa_2d]}


def analyze_3d(result, z_mm: np.ndarray, z_sigma_mm: np.ndarray, intrinsics: CameraIntrinsics) -> Depth3DResult:
    """The 3-D analysis of ``result``'s tracks with their depths ``z_mm``/``z_sigma_mm`` (N, F, mm; NaN = none)."""
    tracks, preset = result.tracks, result.preset
    t0 = time.perf_counter()
    sm = smooth_tracks_3d(tracks.xy, tracks.sigma_px, z_mm, z_sigma_mm, tracks.node_ids, result.graph, intrinsics,
                          preset.smoother, source=tracks.source)
    t_smooth = time.perf_counter() - t0
    t1 = time.perf_counter()
    b3 = compute_bending_3d(sm.xyz_mm, tracks.node_ids, result.graph, preset.bending, sm.frame_cov,
                            observed=sm.observed)
    k3 = fit_kappa_3d(b3, result.geometry, preset, skip_nodes=lost_nodes(tracks))
    k2 = dict(zip(result.response.edges, np.asarray(result.fit.kappa, float)))
    kappa_2d = np.array([k2.get(e, np.nan) for e in k3.edges])
    obs = tracks.observed
    coverage = float(np.isfinite(z_mm)[obs].mean()) if obs.any() else 0.0
    timings = {"smooth_3d": t_smooth, "smooth_2d": float(result.timings_s.get("smooth", np.nan)),
               "bending_fit_3d": time.perf_counter() - t1}
    return Depth3DResult(smoothed=sm, bending=b3, kappa=k3, kappa_2d=kappa_2d, intrinsics=intrinsics,
                         depth_coverage=coverage, timings_s=timings)


def write_3d(d3: Depth3DResult, out_dir: str | Path) -> list[Path]:
    """Write ``kappa_3d.csv`` and ``depth3d.json`` into ``out_dir`` (each atomically); returns their paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_table_atomic(d3.table(), out / KAPPA_3D_CSV)
    write_text_atomic(json.dumps(d3.report(), indent=1, allow_nan=True) + "\n", out / DEPTH_JSON)
    return [out / KAPPA_3D_CSV, out / DEPTH_JSON]


def format_3d(d3: Depth3DResult) -> str:
    """The two kappa tables side by side, as text."""
    k = d3.kappa
    lines = [f"3-D from depth ({100 * d3.depth_coverage:.0f} % of node-frames with a depth; branch plane tilted "
             f"{k.tilt_deg:.0f} deg to the image; 3-D smoother {d3.timings_s['smooth_3d']:.2f} s, "
             f"2-D {d3.timings_s['smooth_2d']:.2f} s):",
             f"  {'segment':>8} {'kappa_3d':>9} {'95% CI':>15} {'in-plane':>9} {'kappa_2d':>9} "
             f"{'bend rms':>9} {'swing rms':>10}"]
    for i, (j, c) in enumerate(k.edges):
        ci = "" if k.ci_low is None else f"[{k.ci_low[i]:.2f}, {k.ci_high[i]:.2f}]"
        lines.append(f"  {f'{j}->{c}':>8} {k.kappa[i]:9.3f} {ci:>15} {k.kappa_in_plane[i]:9.3f} "
                     f"{d3.kappa_2d[i]:9.3f} {k.bend_rms_deg[i]:8.2f}° {k.swing_rms_deg[i]:9.2f}°")
    lines.append("  kappa_3d fits the in-plane bends and the out-of-plane swing together (same compliance both "
                 "ways); kappa_2d is the image-plane fit above, which reads swing as bending.")
    return "\n".join(lines)
