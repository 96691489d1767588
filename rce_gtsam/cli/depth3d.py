"""The depth steps of ``rce track`` and ``rce run`` on a RealSense recording with depth: sample the depth at the
tracked nodes (tracks.csv gains ``z_mm``, ``z_sigma_mm``), and after the 2-D analysis run the 3-D one
(``kappa_3d.csv``, ``depth3d.json``, ``swing_vs_bending.png``, a 3-D Rerun recording beside ``--rerun``)."""

from __future__ import annotations

from pathlib import Path


def maybe_add_depth(video, tracked):
    """(tracked with depth, intrinsics) when ``video`` is a recording with depth, else (tracked, None)."""
    from ..track.depth import recording_has_depth

    if not recording_has_depth(video):
        return tracked, None
    from ..track.depth_tracks import add_depth

    tracked, depth, cam = add_depth(tracked, video)
    print(f"depth: {100 * depth.coverage:.1f} % of node-frames have a depth (median sigma "
          f"{_median(depth.z_sigma_mm):.1f} mm, window radius {depth.radius_px} px)")
    return tracked, cam


def run_3d(result, tracks_csv: Path, cam, out_dir: Path, figures: bool, rerun: Path | None, video) -> str:
    """The 3-D analysis of ``result`` with the depth columns of ``tracks_csv``; writes its files into ``out_dir``
    and returns the text to print."""
    from ..depth_pipeline import analyze_3d, format_3d, write_3d
    from ..errors import InputError
    from ..track.depth_tracks import read_depth_columns

    depth = read_depth_columns(tracks_csv, result.tracks)
    if depth is None:
        return "3-D: the tracks have no depth columns; 3-D analysis skipped"
    try:
        d3 = analyze_3d(result, *depth, cam)
    except InputError as exc:  # e.g. no node has a depth: the 2-D results stand, written already
        return f"3-D analysis skipped: {exc}"
    files = write_3d(d3, out_dir)
    if figures:
        from ..viz.figures3d import swing_vs_bending_figure
        files.append(swing_vs_bending_figure(d3, out_dir / "swing_vs_bending.png"))
    text = format_3d(d3)
    if rerun is not None:
        from ..viz.rerun3d import save_3d_recording
        path = Path(rerun).with_suffix(".3d.rrd")
        save_3d_recording(d3, path, video)
        text += f"\nwrote 3-D Rerun recording {path}"
    return text + f"\nwrote {', '.join(p.name for p in files)}"


def _median(x):
    import numpy as np
    x = x[np.isfinite(x)]
    return float(np.median(x)) if x.size else float("nan")
