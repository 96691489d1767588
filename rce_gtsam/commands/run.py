"""``rce run VIDEO ANNOTATIONS GRAPH --out DIR``: track -> analyze -> diagnose, every output in DIR."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from .live_args import add_live_arguments
from .preset_args import add_preset_arguments, add_run_options, preset_from_args


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="end to end: track a video, analyze the tracks, diagnose the model",
                       description="Track the annotated nodes through VIDEO, smooth and analyze the tracks, "
                                   "fit relative compliance and diagnose the model. Writes tracks.csv, the "
                                   "analysis files and diagnosis.json into DIR.")
    p.add_argument("video", type=Path, help="video file (mp4/avi/...) or RealSense recording (.bag, .db3)")
    p.add_argument("annotations", type=Path, help='first-frame points JSON {"points": [[x, y], ...]} (pixels)')
    p.add_argument("graph", type=Path, help='branch graph JSON {"root": id, "edges": [[parent, child], ...]}')
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--model", type=Path, default=None, metavar="DIR_OR_ONNX",
                   help="TAPIR ONNX export (default: the OpenCV tracker)")
    p.add_argument("--max-frames", type=int, default=None, metavar="N", help="use only the first N frames")
    add_preset_arguments(p)
    add_run_options(p)
    p.add_argument("--rerun", type=Path, default=None, metavar="FILE.rrd", help="also save a Rerun recording")
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_live_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..diagnosis_io import parse_effect_names
    from ..graph import load_graph
    from ..pipeline import analyze
    from ..track import load_annotations, make_tracker, open_video
    from ..tracks import tracks_from_table
    from .track import print_visibility, start_live, track_with_progress, warn_annotations

    from ..quality import OFF_STRUCTURE_KEY
    from ..validate import check_bends_observed, check_clip_length, check_command_options, check_graph_has_bend

    check_command_options(args)
    args.effects = parse_effect_names(args.effects)  # fail on a bad name before tracking
    preset = preset_from_args(args)
    t0 = time.perf_counter()
    graph = load_graph(args.graph)
    check_graph_has_bend(graph)
    tracker = make_tracker(args.model)
    with open_video(args.video) as src:
        points = load_annotations(args.annotations, image_size=src.size)
        _check_graph_matches_points(graph, points, args)
        n_clip = min(x for x in (src.n_frames, args.max_frames) if x is not None) \
            if (src.n_frames, args.max_frames) != (None, None) else None
        check_clip_length(n_clip, args.video, preset.compliance.block_length)
        off_structure = warn_annotations(args.video, points, graph)
        live = start_live(args, src, f"rce run {args.video}")
        tracked = track_with_progress(tracker, src, points, graph, args.max_frames, show=not args.no_progress,
                                      on_frame=live.frame if live else None)
    t_track = time.perf_counter() - t0
    print_visibility(tracked.visible)
    table = tracked.to_frame()
    tracks = tracks_from_table(table, graph, source=f"tracks of {args.video}")
    check_bends_observed(table, graph, f"tracks of {args.video}", preset.compliance.block_length)
    result = analyze(tracks, graph, preset=preset, seed=args.seed, n_boot=args.bootstrap)
    result.timings_s["track"] = t_track
    result.inputs.update(video=str(args.video), annotations=str(args.annotations), graph=str(args.graph))
    if live:
        live.analysis(result)
    if off_structure:
        result.inputs[OFF_STRUCTURE_KEY] = ",".join(map(str, off_structure))

    from ..diagnosis_io import diagnose_result, diagnosis_for_viz, diagnosis_json
    diagnosis = diagnose_result(result, effects=args.effects, seed=args.seed if args.seed is not None else 0)
    view = diagnosis_for_viz(diagnosis, result)
    if live:
        live.diagnosis(view)
        live.close()

    def write_tracks(_result, tmp: Path) -> dict:
        table.to_csv(tmp / "tracks.csv", index=False)
        (tmp / "diagnosis.json").write_text(json.dumps(diagnosis_json(diagnosis, result), indent=1) + "\n")
        return {}

    from .analyze import extra_writers, format_summary, quality_exit_code, save_recording
    files = result.write(args.out, extra_writers=[write_tracks, *extra_writers(args, video=args.video,
                                                                                diagnosis=view)])
    save_recording(args, result, video=args.video, diagnosis=view)
    print(format_summary(result))
    print()
    print(diagnosis.report())
    print(f"\nwrote {len(files)} files to {args.out}/")
    return quality_exit_code(result, "run")


def _check_graph_matches_points(graph, points, args) -> None:
    from ..errors import InputError
    bad = [n for n in graph.nodes if not 0 <= n < len(points)]
    if bad:
        raise InputError(args.graph, f"graph node {bad[0]} has no annotated point: {args.annotations} lists "
                                     f"{len(points)} points (ids 0..{len(points) - 1})", f"node {bad[0]}")

