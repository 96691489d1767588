"""``rce track VIDEO ANNOTATIONS --out TRACKS.csv`` and ``rce annotate --polyline ...``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .progress import add_quiet_argument, progress_enabled


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("track", help="track the annotated nodes through a video (mp4 or RealSense .bag/.db3)",
                       description="Track first-frame annotated points through a video and write a tracks CSV "
                                   "(point_id,frame,x,y,visible,sigma_px; pixels, pixel centres at integers). "
                                   "Default tracker: OpenCV Lucas-Kanade re-anchored to each node's first-frame "
                                   "appearance (no drift); --model runs a TAPIR ONNX export instead.")
    p.add_argument("video", type=Path, help="video file (mp4/avi/mov/...) or RealSense recording (.bag, .db3)")
    p.add_argument("annotations", type=Path, help='first-frame points JSON: {"points": [[x, y], ...]} (pixels)')
    p.add_argument("--out", type=Path, required=True, help="tracks CSV to write (atomically)")
    p.add_argument("--graph", type=Path, default=None,
                   help='branch graph JSON {"root": id, "edges": [[parent, child], ...]}; lets the default '
                        "tracker use neighbouring nodes to re-find lost points and reject implausible ones")
    p.add_argument("--model", type=Path, default=None, metavar="DIR_OR_ONNX",
                   help="TAPIR ONNX export: folder with tapir.onnx + tapir_pointencoder.onnx "
                        "(see tools/export_tapir_onnx.py); default: the OpenCV tracker")
    p.add_argument("--max-frames", type=int, default=None, metavar="N", help="track only the first N frames")
    add_quiet_argument(p, "--no-progress")
    p.set_defaults(func=run_track)

    a = sub.add_parser("annotate", help="place N evenly spaced nodes along a polyline; write annotations + graph",
                       description="Place N nodes evenly (by arc length) along a polyline from the branch base "
                                   "(first vertex, the graph root) to the tip, and write the annotations JSON "
                                   "and a chain graph JSON for `rce track` / `rce analyze`.")
    a.add_argument("--polyline", required=True, metavar="x1,y1,x2,y2,...",
                   help="vertices in first-frame pixels, base first")
    a.add_argument("--nodes", type=int, required=True, metavar="N", help="number of nodes (>= 2)")
    a.add_argument("--out-annotations", type=Path, required=True, help="annotations JSON to write")
    a.add_argument("--out-graph", type=Path, required=True, help="graph JSON to write")
    a.set_defaults(func=run_annotate)


def run_track(args: argparse.Namespace) -> int:
    from ..errors import InputError
    from ..graph import load_graph
    from ..track import load_annotations, make_tracker, open_video

    if args.max_frames is not None and args.max_frames < 1:
        raise InputError("--max-frames", f"must be >= 1, got {args.max_frames}")
    graph = load_graph(args.graph) if args.graph else None
    tracker = make_tracker(args.model)
    with open_video(args.video) as src:
        points = load_annotations(args.annotations, image_size=src.size)
        result = track_with_progress(tracker, src, points, graph, args.max_frames,
                                     show=progress_enabled(args.quiet))
    result.write_csv(args.out)
    vis = result.visible
    print(f"tracked {result.n_points} points over {result.n_frames} frames with {result.info.get('tracker')}; "
          f"visible {100 * vis.mean():.1f}% of point-frames, median sigma "
          f"{float(_median(result.sigma_px[vis])):.2f} px")
    print(f"wrote {args.out}")
    return 0


def track_with_progress(tracker, src, points, graph, max_frames: int | None, show: bool = True):
    """Run ``tracker`` over the frame source ``src`` with a tqdm progress bar on stderr (frames)."""
    bar = None
    if show:
        from tqdm import tqdm
        total = src.n_frames if max_frames is None else min(max_frames, src.n_frames or max_frames)
        bar = tqdm(total=total, unit="frame", desc="tracking", file=sys.stderr, leave=False)
    try:
        return tracker.track(src, points, graph=graph, max_frames=max_frames,
                             progress=bar.update if bar else None)
    finally:
        if bar:
            bar.close()


def _median(x):
    import numpy as np
    return np.median(x) if x.size else float("nan")


def run_annotate(args: argparse.Namespace) -> int:
    from ..track import parse_polyline, place_nodes_along_polyline, write_annotation_files

    points, graph = place_nodes_along_polyline(parse_polyline(args.polyline), args.nodes)
    write_annotation_files(points, graph, args.out_annotations, args.out_graph)
    print(f"placed {len(points)} nodes; wrote {args.out_annotations} and {args.out_graph}")
    return 0
