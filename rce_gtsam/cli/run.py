"""``rce run VIDEO ANNOTATIONS GRAPH --out DIR``: track -> analyze -> diagnose, every output in DIR."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from .live_args import add_live_arguments
from .preset_args import add_preset_arguments, add_run_options, preset_from_args
from .progress import add_quiet_argument
from .wording import candidates_from_args, cli_wording, cli_wording_json


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="end to end: track a video, analyze the tracks, diagnose the model",
                       description="Track the annotated nodes through VIDEO, smooth and analyze the tracks, "
                                   "fit relative compliance and diagnose the model. Writes tracks.csv, the "
                                   "analysis files and diagnosis.json into DIR.")
    p.add_argument("video", type=Path, help="video file (mp4/avi/...) or RealSense recording (.bag, .db3)")
    p.add_argument("annotations", type=Path, help='first-frame points JSON {"points": [[x, y], ...]} (pixels)')
    p.add_argument("graph", type=Path, help='branch graph JSON {"root": id, "edges": [[parent, child], ...]}')
    p.add_argument("--out", type=Path, required=True,
                   help="output folder (created; the files this command writes are replaced, others left alone)")
    p.add_argument("--model", type=Path, default=None, metavar="DIR_OR_ONNX",
                   help="TAPIR ONNX export (default: the OpenCV tracker)")
    p.add_argument("--max-frames", type=int, default=None, metavar="N", help="use only the first N frames")
    add_preset_arguments(p)
    add_run_options(p, "run")
    p.add_argument("--rerun", type=Path, default=None, metavar="FILE.rrd", help="also save a Rerun recording")
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    add_quiet_argument(p, "--no-progress")
    add_live_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from .figure_worker import FigureWorker
    from .progress import Steps, process_seconds, progress_mode

    worker = None if args.no_figures else FigureWorker()  # forks just before the analysis (FiguresInBackground)
    try:
        return _run(args, worker, Steps, process_seconds, progress_mode(args.quiet))
    finally:
        if worker:
            worker.close()


def _run(args, worker, Steps, process_seconds, show: str | None) -> int:
    import dataclasses
    import shutil
    import tempfile

    from ..diagnosis.io import diagnose_result, diagnosis_for_viz, diagnosis_json, parse_effect_names
    from ..diagnosis.parallel import default_workers
    from ..graph import load_graph
    from ..kappa_report import kappa_after_verdict
    from ..pipeline import ANALYSIS_STEPS, analyze
    from ..track import load_annotations, make_tracker, open_video
    from ..quality import OFF_STRUCTURE_KEY
    from ..tracks import load_tracks
    from ..validate import check_bends_observed, check_clip_length, check_command_options, check_graph_has_bend
    from .analyze import (FiguresInBackground, first_video_frame, format_summary, print_lost_nodes,
                          quality_exit_code, record_wall_time, save_recording)
    from .depth3d import maybe_add_depth, run_3d
    from .live_args import live_from_args
    from .track import print_visibility, send_live_video, track_with_progress, warn_annotations

    check_command_options(args)
    candidates = parse_effect_names(candidates_from_args(args), source="--candidates")  # before tracking
    preset = preset_from_args(args)
    t0 = time.perf_counter()
    graph = load_graph(args.graph)
    check_graph_has_bend(graph)
    tracker = make_tracker(args.model)
    live = live_from_args(args, f"rce run {args.video}")  # a bad address or no display: before any work
    with open_video(args.video) as src:
        points = load_annotations(args.annotations, image_size=src.size)
        _check_graph_matches_points(graph, points, args)
        n_clip = min(x for x in (src.n_frames, args.max_frames) if x is not None) \
            if (src.n_frames, args.max_frames) != (None, None) else None
        check_clip_length(n_clip, args.video, preset.compliance.block_length)
        off_structure = warn_annotations(args.video, points, graph)
        send_live_video(live, src)
        tracked = track_with_progress(tracker, src, points, graph, args.max_frames, show=show, command="run",
                                      on_frame=live.frame if live else None)
    tracked, depth_cam = maybe_add_depth(args.video, tracked)  # a recording with depth: z_mm per node
    t_track = time.perf_counter() - t0
    print_visibility(tracked.visible)
    check_bends_observed(tracked.to_frame(), graph, f"tracks of {args.video}", preset.compliance.block_length)
    scratch = Path(tempfile.mkdtemp(prefix="rce_run_"))
    figures = None
    try:
        # analyse the tracks exactly as `rce track` writes them, so track + analyze + diagnose == run
        tracks_csv = tracked.write_csv(scratch / "tracks.csv")
        tracks = load_tracks(tracks_csv, graph)
        print_lost_nodes("run", tracks, graph)
        t_start = process_seconds()
        steps = [*ANALYSIS_STEPS, "diagnosis", "write"] + (["figures"] if worker else []) \
            + (["recording"] if args.rerun else [])
        with Steps("run", steps, enabled=show) as bar:
            figures = FiguresInBackground(worker, first_frame=first_video_frame(args.video)) if worker else None
            result = analyze(tracks, graph, preset=preset, seed=args.seed, n_boot=args.bootstrap,
                             progress=bar.callback, before_bootstrap=figures.before_bootstrap if figures else None)
            if figures:
                figures.after_bootstrap(result)
            result.inputs.update(video=str(args.video), annotations=str(args.annotations), graph=str(args.graph),
                                 tracks=str(args.out / "tracks.csv"))
            if off_structure:
                result.inputs[OFF_STRUCTURE_KEY] = ",".join(map(str, off_structure))
            if live:
                live.analysis(result)
            bar.start("diagnosis")
            t_diag = time.perf_counter()
            diagnosis = diagnose_result(result, effects=candidates,
                                        seed=args.seed if args.seed is not None else 0, workers=default_workers())
            # the named effect's kappa intervals belong to the diagnosis stage, not to "write"
            result = dataclasses.replace(result, kappa_choice=kappa_after_verdict(result, diagnosis))
            t_diag = time.perf_counter() - t_diag
            written = result.kappa_choice.column if result.kappa_choice.fitted else None  # kappa_<effect>, or None
            view = cli_wording_json(diagnosis_for_viz(diagnosis, result), written)
            if live:
                live.diagnosis(view)
                live.close()
            if figures:
                figures.diagnosis(view, result)

            def write_tracks(_result, tmp: Path) -> dict:
                shutil.copyfile(tracks_csv, tmp / "tracks.csv")
                (tmp / "diagnosis.json").write_text(
                    json.dumps(cli_wording_json(diagnosis_json(diagnosis, result), written), indent=1) + "\n")
                return {}

            bar.start("write")
            files = result.write(args.out,
                                 extra_writers=[write_tracks, *([figures.writer(bar)] if figures else [])])
            if args.rerun is not None:
                bar.start("recording")
                # a RealSense recording is no video file Rerun's AssetVideo can hold: its tracks only
                save_recording(args, result, diagnosis=view, announce=False,
                               video=None if Path(args.video).suffix.lower() in (".bag", ".db3") else args.video)
        text_3d = None if depth_cam is None else run_3d(result, tracks_csv, depth_cam, args.out,
                                                        not args.no_figures, args.rerun, args.video)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
        if figures:
            figures.discard()
    record_wall_time(result, t_start, {"diagnosis": t_diag})
    t = result.timings_s  # the time before the analysis was imports and tracking: split it
    t.update({"imports": t["imports"] - t_track, "track": t_track, **{k: t.pop(k) for k in list(t)[1:]}})
    print(format_summary(result))
    print()
    print(cli_wording(diagnosis.report(), written))
    print("\n" + read_together(result, diagnosis))
    if text_3d:
        print("\n" + text_3d)
    if args.rerun is not None:
        from ..viewer import open_command
        print(f"\nwrote Rerun recording {args.rerun} (open it with: {open_command(args.rerun)})")
    print(f"\nwrote {len(files)} files to {args.out}/")
    return quality_exit_code(result, "run")


def read_together(result, diagnosis) -> str:
    """One paragraph that reads the verdict, the variance budget and the quality flags together, so that
    none of them reads as contradicting another: which kappa to report, and how far to trust it."""
    from ..diagnosis.explain import remainder_text
    from ..quality import assess_quality
    q = assess_quality(result)
    n, n_ok = len(q), sum(v.ok for v in q.values())
    n_inf = sum(v.informative is True for v in q.values())
    counts = f"{n_ok} of {n} rank-1 segments ok, {n_inf} of {n} informative"
    status = diagnosis.status
    if diagnosis.verdict is not None:
        eff = diagnosis.verdict_effect or diagnosis.verdict
        n_poor = sum("poor_fit" in v.reasons for v in q.values())
        poor = (f"; poor_fit marks the {n_poor} it fits worst" if n_poor else
                "; ok there means the rank-1 checks pass, not that the effect is absent")
        choice = getattr(result, "kappa_choice", None)
        column = getattr(choice, "column", None) or f"kappa_{eff}"
        own = ""
        if choice is not None and choice.fitted:
            from ..quality import assess_reported_quality
            qr = assess_reported_quality(result, q)
            own = (f"; of its segments {sum(v.ok for v in qr.values())} of {n} are ok and "
                   f"{sum(v.informative is True for v in qr.values())} informative ({column}_quality)")
        return (f"Read together: the diagnosis names {diagnosis.verdict}, an effect the rank-1 model leaves out, so "
                f"the rank-1 kappa above is not the one to report ({counts}{poor}); report {column} of "
                f"compliance_summary.csv, the model with {eff} with its own intervals, written beside the rank-1 "
                f"kappa by this run (report.json: kappa_to_report{own}). "
                f"{remainder_text(diagnosis.budget, eff).capitalize()}.")
    if status == "adequate":
        advice = "the rank-1 model is adequate: report the kappa above whose quality is ok"
    elif status == "misses":
        advice = ("the rank-1 model leaves more than noise and no candidate effect explains it: report the ok "
                  "kappa with that caveat, and look at the residual figures for what is left")
    elif status == "inconclusive":
        advice = ("no candidate effect is named, and whether the rest is noise cannot be decided here: report "
                  "the ok kappa with that caveat")
    else:
        advice = "no effect is named (see the verdict): report the ok kappa"
    return f"Read together: {advice} ({counts}). {remainder_text(diagnosis.budget).capitalize()}."


def _check_graph_matches_points(graph, points, args) -> None:
    from ..errors import InputError
    bad = [n for n in graph.nodes if not 0 <= n < len(points)]
    if bad:
        raise InputError(args.graph, f"graph node {bad[0]} has no annotated point: {args.annotations} lists "
                                     f"{len(points)} points (ids 0..{len(points) - 1})", f"node {bad[0]}")

