"""``rce track VIDEO ANNOTATIONS --out TRACKS.csv``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .live_args import add_live_arguments, live_from_args
from .progress import add_quiet_argument, progress_mode


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
    p.add_argument("--corrections", type=Path, default=None, metavar="C.json",
                   help="corrections saved by `rce review` ({\"corrections\": [{\"frame\", \"node\", \"x\", \"y\"}]}, "
                        "pixels): each is an anchor, and the corrected nodes are re-tracked between them, as the "
                        "review page's Re-track does (see rce_gtsam/track/anchors.py)")
    add_quiet_argument(p, "--no-progress")
    add_live_arguments(p)
    p.set_defaults(func=run_track)


def run_track(args: argparse.Namespace) -> int:
    from ..errors import InputError
    from ..graph import load_graph
    from ..track import load_annotations, make_tracker, open_video

    from ..validate import check_output_file

    if args.max_frames is not None and args.max_frames < 1:
        raise InputError("--max-frames", f"must be >= 1, got {args.max_frames}")
    check_output_file(args.out, "--out")
    if args.corrections is not None and Path(args.corrections).resolve() == Path(args.out).resolve():
        raise InputError("--corrections", f"{args.corrections} is also --out: the tracks would overwrite it")
    graph = load_graph(args.graph) if args.graph else None
    tracker = make_tracker(args.model)
    live = live_from_args(args, f"tracking {args.video}")  # a bad address or no display: before any work
    corrections = None
    with open_video(args.video) as src:
        points = load_annotations(args.annotations, image_size=src.size)
        if args.corrections is not None:  # checked before any work: node ids, frames, inside the image
            corrections = load_corrections_for(args.corrections, len(points), src, args.max_frames)
        warn_annotations(args.video, points, graph)
        send_live_video(live, src)
        result = track_with_progress(tracker, src, points, graph, args.max_frames, show=progress_mode(args.quiet),
                                     on_frame=live.frame if live else None)
    from .depth3d import maybe_add_depth
    result, _ = maybe_add_depth(args.video, result)  # a recording with depth: z_mm, z_sigma_mm columns
    if corrections is None:
        result.write_csv(args.out)
    else:
        from ..track.anchors import DenseTracks, FrameStore, retrack
        from ..tracks import write_table_atomic
        if corrections and max(c.frame for c in corrections) >= result.n_frames:
            c = max(corrections, key=lambda c: c.frame)
            raise InputError(args.corrections, f"frame {c.frame} is beyond the video: it has {result.n_frames} "
                                               "frames", f"node {c.node}")
        with FrameStore(args.video, result.n_frames) as store:
            fixed, _ = retrack(store, DenseTracks.from_result(result), corrections, tracker, graph, points, result)
        write_table_atomic(fixed.to_frame(), args.out)
    if live:
        live.close()
    vis = result.visible
    print(f"tracked {result.n_points} points over {result.n_frames} frames with {result.info.get('tracker')}; "
          f"visible {100 * vis.mean():.1f}% of point-frames, median sigma "
          f"{float(_median(result.sigma_px[vis])):.2f} px")
    how = result.info.get("how")
    if how is not None and vis.any():
        from ..track.lk import HOW
        parts = [f"{100 * float((how == k).sum()) / vis.sum():.1f} % {HOW[k]}" for k in (1, 2, 3, 4, 5)
                 if (how == k).any()]
        if parts:
            print("of the visible point-frames, not a plain frame-0 match: " + ", ".join(parts))
    print_visibility(vis)
    if corrections is not None:
        print(f"then re-tracked {len({c.node for c in corrections})} node(s) between {len(corrections)} correction(s) "
              f"from {args.corrections} (the lines above describe the tracks before)")
    print(f"wrote {args.out}")
    return 0


def load_corrections_for(path, n_points: int, src, max_frames: int | None):
    """The corrections of ``path`` checked against the annotation's point ids and the video's frames and size."""
    from ..track.anchors import load_corrections

    n = src.n_frames if max_frames is None else min(max_frames, src.n_frames or max_frames)
    return load_corrections(path, range(n_points), n if n else 10 ** 9, src.size)


def send_live_video(live, src) -> None:
    """Send the video of ``src`` to the live viewer stream (nothing without one; RealSense: points only)."""
    if live is not None and Path(src.path).suffix.lower() not in (".bag", ".db3"):
        live.video(src.path, src.n_frames, src.fps)


def warn_annotations(video, points, graph) -> list[int]:
    """Print (stderr) a warning for each annotated point not on a textured, moving structure; returns the ids
    of those with no image structure at all."""
    from ..track.checks import annotation_warnings, probe_frames

    flagged, notes = annotation_warnings(probe_frames(video), points, root=graph.root if graph else None)
    for line in [*flagged.values(), *notes.values()]:
        print(line, file=sys.stderr)
    return sorted(flagged)


def print_visibility(visible) -> None:
    """The per-node visible share, and a warning (stderr) for each node lost in most frames."""
    from ..track.checks import visibility_lines

    head, *warnings = visibility_lines(visible)
    print(head)
    for line in warnings:
        print(line, file=sys.stderr)


def track_with_progress(tracker, src, points, graph, max_frames: int | None, show: bool | str | None = True,
                        on_frame=None, command: str = "track"):
    """Run ``tracker`` over the frame source ``src`` with a tqdm progress bar on stderr (frames; ``show`` True
    or ``"bar"``), or with a plain flushed line every tenth of the clip (``"lines"``: stderr is a log);
    ``on_frame(index, xy, visible)`` gets each frame's result (live streaming)."""
    bar = None
    total = src.n_frames if max_frames is None else min(max_frames, src.n_frames or max_frames)
    if show and _kernels_to_compile(tracker, graph):
        from .progress import progress_line
        progress_line(command, "compiling the tracker's kernels: once on this machine, tens of seconds")
    if show == "lines":
        bar = _LineProgress(command, total)
    elif show:
        from tqdm import tqdm
        bar = tqdm(total=total, unit="frame", desc="tracking", file=sys.stderr, leave=False)
    try:
        return tracker.track(src, points, graph=graph, max_frames=max_frames,
                             progress=bar.update if bar else None, on_frame=on_frame)
    finally:
        if bar:
            bar.close()


def _kernels_to_compile(tracker, graph) -> bool:
    """Whether ``tracker`` is the default tracker and the compiled kernels it calls on every clip (with ``graph``
    or without) are not in numba's cache yet (its first frames then wait for the compiler)."""
    from ..track import LKTracker
    if not isinstance(tracker, LKTracker):
        return False
    from ..track import match_kernels
    cfg = tracker.config
    return not match_kernels.compiled_on_this_machine(
        match_kernels.kernels_called(graph is not None and cfg.mask_to_branch, cfg.mask_off_colour))


class _LineProgress:
    """Frame progress as plain lines on stderr: "rce run: tracking 59/590 frames (4.1 s)" at every tenth of
    the clip (every 100 frames when the length is unknown), flushed."""

    def __init__(self, command: str, total: int | None):
        import time
        self.command, self.total, self.n = command, total, 0
        self.every = max(int(total) // 10, 1) if total else 100
        self._clock = time.perf_counter
        self.t0 = self._clock()

    def update(self, k: int = 1) -> None:
        from .progress import progress_line
        before, self.n = self.n, self.n + int(k)
        if self.n // self.every > before // self.every or (self.total and self.n == self.total and before < self.n):
            of = f"/{self.total}" if self.total else ""
            progress_line(self.command, f"tracking {self.n}{of} frames ({self._clock() - self.t0:.1f} s)")

    def close(self) -> None:
        pass


def _median(x):
    import numpy as np
    return np.median(x) if x.size else float("nan")

