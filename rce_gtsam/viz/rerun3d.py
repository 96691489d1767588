"""A Rerun recording of the 3-D analysis (``rce run --rerun X.rrd`` on a recording with depth writes it as
``X.3d.rrd``).

Entities (timeline ``frame``):

* ``world/skeleton`` — the smoothed 3-D skeleton (mm, camera frame: x right, y down, z forward), each segment
  coloured by its kappa from the 3-D angles (same colour map as the 2-D skeleton: blue = stiff, red = compliant);
  ``world/nodes`` — the nodes with their marginal 1-sigma as radii; ``world/plane_normal`` — the branch plane's
  normal at the root (static);
* ``depth/image`` — the registered depth image (mm; every ``depth_every``-th frame, to keep the file small) with
  ``depth/nodes`` the tracked nodes on it;
* ``bending3d/<edge>`` — the in-plane bend theta and the out-of-plane swing psi (deviation from rest, deg).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from .rerun_log import write_rrd
from .style import KAPPA_CMAP, cmap_rgb

APP_ID = "rce_gtsam_3d"


def _edge_colors(d3) -> dict:
    k = d3.kappa
    lk = np.log(np.clip(k.kappa, 1e-6, None))
    lim = max(float(np.max(np.abs(lk))), 1e-3)
    rgb = cmap_rgb(lk, KAPPA_CMAP, -lim, lim)
    return {e: rgb[i] for i, e in enumerate(k.edges)}


def log_3d(d3, rec: rr.RecordingStream, video=None, depth_every: int | None = None) -> None:
    """Log a :class:`~rce_gtsam.depth_pipeline.Depth3DResult` into ``rec``; ``video`` (a recording with depth) adds
    the depth images."""
    sm = d3.smoothed
    xyz = sm.xyz_mm
    n, f = xyz.shape[:2]
    row = {int(v): i for i, v in enumerate(sm.node_ids)}
    colors = _edge_colors(d3)
    edges = [e for e in colors if e[0] in row and e[1] in row]
    sig = sm.sigma_mm
    rec.log("world", rr.ViewCoordinates.RDF, static=True)
    root = xyz[0].mean(axis=0)
    rec.log("world/plane_normal", rr.Arrows3D(origins=[root], vectors=[50.0 * d3.bending.normal]), static=True)
    for t in range(f):
        rec.set_time("frame", sequence=t)
        strips = [[xyz[row[p], t], xyz[row[c], t]] for p, c in edges]
        rec.log("world/skeleton", rr.LineStrips3D(strips, colors=[colors[e] for e in edges], radii=1.5))
        radii = 2.0 if sig is None else np.clip(np.linalg.norm(sig[:, t], axis=1), 1.0, 20.0)
        rec.log("world/nodes", rr.Points3D(xyz[:, t], radii=radii, colors=[[30, 30, 30]] * n))
    frames = np.arange(f, dtype=np.int64)
    b3 = d3.bending
    for k, bend in enumerate(b3.in_plane.bends):
        j, c = bend.edge
        path = f"bending3d/{j}-{c}"
        rec.log(path, rr.SeriesLines(names=["in-plane θ", "out-of-plane ψ"], colors=[[31, 119, 180], [148, 103, 189]]),
                static=True)
        vals = np.stack([b3.in_plane.delta_deg[k], b3.out_of_plane.delta_deg[k]], axis=1)
        rec.send_columns(path, indexes=[rr.TimeColumn("frame", sequence=frames)],
                         columns=rr.Scalars.columns(scalars=vals))
    if video is not None:
        from ..track.depth import RealSenseDepthSource
        every = depth_every or max(1, f // 120)
        cam = d3.intrinsics
        rec.log("depth", rr.Pinhole(focal_length=[cam.fx, cam.fy], principal_point=[cam.cx, cam.cy],
                                    width=cam.width, height=cam.height), static=True)
        uv = cam.project(xyz)
        with RealSenseDepthSource(video) as src:
            for fr in src:
                if fr.index >= f:
                    break
                if fr.index % every:
                    continue
                rec.set_time("frame", sequence=fr.index)
                rec.log("depth/image", rr.DepthImage(fr.depth_mm.astype(np.uint16), meter=1000.0))
                rec.log("depth/nodes", rr.Points2D(uv[:, fr.index], radii=2.0, colors=[[255, 255, 255]] * n))


def save_3d_recording(d3, path: str | Path, video=None) -> Path:
    """Write the 3-D recording to ``path`` (atomically) with a blueprint: 3-D view | depth image | bends."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    blueprint = rrb.Blueprint(rrb.Horizontal(
        rrb.Spatial3DView(origin="world", name="3-D skeleton (kappa colours)"),
        rrb.Vertical(rrb.Spatial2DView(origin="depth", name="depth (mm)"),
                     rrb.TimeSeriesView(origin="bending3d", name="in-plane θ / out-of-plane ψ (deg)"))))
    return write_rrd(path, blueprint, lambda rec: log_3d(d3, rec, video=video), app_id=APP_ID)
