"""``rce review VIDEO TRACKS.csv``: scrub the tracks in the browser, drag wrong nodes into place, re-track, save."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    a = sub.add_parser(
        "review", help="review tracks in the browser: scrub, jump to flagged frames, drag nodes to correct, re-track",
        description="rce review VIDEO TRACKS.csv serves a page on 127.0.0.1 (printed, and opened in your browser when "
                    "there is one) showing the video with the tracks, each node's sigma (a circle of radius 2 sigma) "
                    "and the graph's edges drawn over each frame, and the frames the tracker flagged (a node lost, a "
                    "large sigma, a jump). Drag a node to where it is in any frame: each drag is a correction (frame, "
                    "node, x, y). Re-track refits each corrected node's track between its corrections (the tracker run "
                    "forward and backward from each, blended by distance in frames). Save writes the corrections to "
                    "TRACKS.corrections.json (or --corrections) and the re-tracked tracks to TRACKS.csv (the file as "
                    "it was is kept as TRACKS.csv.bak); `rce track VIDEO ANNOTATIONS --out TRACKS.csv --corrections "
                    "C.json` gives the same tracks again.")
    a.add_argument("video", type=Path, help="the video the tracks were made from (mp4/avi/..., or .bag/.db3)")
    a.add_argument("tracks", type=Path, help="tracks CSV (point_id,frame,x,y[,visible,sigma_px]) from `rce track`")
    a.add_argument("--annotations", type=Path, default=None, metavar="A.json",
                   help="the first-frame annotation the tracks started from (default: the tracks' frame 0); "
                        "named in the printed `rce track` command")
    a.add_argument("--graph", type=Path, default=None, metavar="G.json",
                   help="branch graph JSON: its edges are drawn, and the re-track uses it as `rce track --graph` does "
                        "(give the same one the tracks were made with)")
    a.add_argument("--corrections", type=Path, default=None, metavar="C.json",
                   help="corrections file to load (if it exists) and save (default: TRACKS.corrections.json beside "
                        "the tracks)")
    a.add_argument("--port", type=int, default=0, help="local port of the page (default: a free one)")
    a.add_argument("--no-browser", action="store_true", help="only print the page's address")
    a.set_defaults(func=run)


def build_session(args: argparse.Namespace):
    """Validate every input (one-line InputError naming the file) and return the review session."""
    import numpy as np

    from ..annotate_web.review import ReviewSession, check_graph_nodes, reproduce_command
    from ..annotate_web.server import FrameCache
    from ..errors import InputError
    from ..graph import load_graph
    from ..track import LKTracker, load_annotations
    from ..track.anchors import DenseTracks, default_corrections_path, load_corrections
    from ..tracks import read_tracks_table

    if not 0 <= args.port <= 65535:
        raise InputError("--port", f"must be 0..65535, got {args.port}")
    if not args.video.is_file():
        raise InputError(args.video, "video file not found")
    tracks = DenseTracks.from_table(read_tracks_table(args.tracks))
    graph = load_graph(args.graph) if args.graph else None
    check_graph_nodes(graph, tracks.point_ids, args.tracks)
    corr_path = args.corrections or default_corrections_path(args.tracks)
    if corr_path.resolve() == args.tracks.resolve():
        raise InputError("--corrections", "must not be the tracks file itself")
    frames = FrameCache(args.video, max_frames=tracks.n_frames)
    try:
        n_video = frames.n_frames
        if n_video < tracks.n_frames:
            raise InputError(args.tracks, f"the tracks have {tracks.n_frames} frames but the video {args.video} has "
                                          f"{n_video}")
        q0 = None
        if args.annotations:
            q0 = load_annotations(args.annotations, image_size=frames.size)
            if len(q0) != len(tracks.point_ids):
                raise InputError(args.annotations, f"{len(q0)} points, but the tracks have {len(tracks.point_ids)} "
                                                   "nodes: give the annotation the tracks were made from")
        elif not np.isfinite(tracks.xy[:, 0]).all():
            raise InputError(args.tracks, "some node has no row in frame 0, where tracking starts; give "
                                          "--annotations")
        corrections = (load_corrections(corr_path, tracks.point_ids, tracks.n_frames, frames.size)
                       if corr_path.is_file() else [])
        src_frames = _video_frames(args.video)
        command = reproduce_command(args.video, args.annotations, args.graph, args.tracks, corr_path,
                                    tracks.n_frames if src_frames and src_frames > tracks.n_frames else None)
        return ReviewSession(args.video, args.tracks, tracks, frames, graph, q0, corrections, corr_path, LKTracker(),
                             command)
    except BaseException:
        frames.close()
        raise


def _video_frames(video: Path) -> int | None:
    from ..track import open_video
    with open_video(video) as src:
        return src.n_frames


def run(args: argparse.Namespace) -> int:
    from .annotate import serve_until_finished

    session = build_session(args)

    def on_save(res: dict) -> None:
        n = res["n_corrections"]
        print(f"wrote {res['corrections']} ({n} correction{'' if n == 1 else 's'}) and {res['tracks']} "
              f"(the tracks before: {res['backup']})")
        if res["reproducible"]:
            print(f"reproduce: {res['command']}", flush=True)
        else:
            print(f"not reproducible by `{res['command']}`: the uncorrected nodes' rows in {res['tracks']} are not what "
                  "rce track's default tracker gives with these options (other tracker, options or edits); that command "
                  "re-tracks the same corrections over the tracker's own rows",
                  flush=True)

    serve_until_finished(session, args.port, on_save, open_in_browser=not args.no_browser, announce=(
        f"review {args.tracks} over {args.video} in your browser: {{url}}",
        f"(Save writes {session.corrections_path} and {args.tracks}; Finish or Ctrl+C ends the session)"))
    return 0
