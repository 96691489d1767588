"""``rce diagnose TRACKS GRAPH --json PATH``: which physical effect does the rank-1 model miss?"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

from .preset_args import add_preset_arguments, preset_from_args
from .progress import add_quiet_argument
from .wording import add_candidates_argument, candidates_from_args, cli_wording, cli_wording_json


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("diagnose", help="compare the rank-1 model with the measurements; find the missing effect",
                       description="Run the analysis up to the bend-response matrix, then fit the rank-1 model and "
                                   "each candidate effect, score them on held-out frames (blocked CV) and print a "
                                   "verdict with its physical explanation.")
    p.add_argument("tracks", type=Path, help="tracks CSV: point_id,frame,x,y[,visible,sigma_px] (pixels)")
    p.add_argument("graph", type=Path, help='branch graph JSON: {"root": id, "edges": [[parent, child], ...]}')
    p.add_argument("--json", type=Path, required=True, dest="json_path", help="write the diagnosis JSON here")
    add_preset_arguments(p)
    add_candidates_argument(p, "diagnose")
    p.add_argument("--seed", type=int, default=0,
                   help="seed of every random step of this command: the split of the segments into the two "
                        "node-disjoint halves of the cross-validation (no bootstrap runs here; default 0)")
    p.add_argument("--folds", type=int, default=None,
                   help="cross-validation blocks (default 16, fewer when the clip is too short for 16 blocks of "
                        "at least the bootstrap block length)")
    p.add_argument("--rerun", type=Path, default=None, metavar="FILE.rrd",
                   help="also save a Rerun recording of the analysis with the diagnosis report")
    p.add_argument("--figures", type=Path, default=None, metavar="DIR",
                   help="also write the analysis and diagnosis figures (PNG) into DIR")
    add_quiet_argument(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..diagnosis.io import diagnose_result, diagnosis_for_viz, diagnosis_json, parse_effect_names, \
        write_json_atomic
    from ..diagnosis.parallel import default_workers
    from ..errors import InputError
    from ..pipeline import analyze

    from .progress import Steps, process_seconds, progress_mode

    from ..validate import check_analysis_inputs, check_command_options, check_folds

    check_command_options(args, out_dir_option=None)
    names = parse_effect_names(candidates_from_args(args), source="--candidates")  # before the slow part
    preset = preset_from_args(args)
    if args.folds is not None and args.folds < 2:
        raise InputError("--folds", f"need at least 2 cross-validation blocks, got {args.folds}")
    graph, table, tracks = check_analysis_inputs(args.tracks, args.graph, preset)  # the CSV is read once
    from .analyze import print_lost_nodes
    print_lost_nodes("diagnose", tracks, graph)
    if args.folds is not None:  # an explicit value is checked; the default adapts to a short clip
        check_folds(args.folds, int(table["frame"].max()) + 1, preset.compliance.block_length)
    steps = ["load", "smooth", "bending", "fit", "diagnosis"] + (["figures"] if args.figures else []) \
        + (["recording"] if args.rerun else [])
    with Steps("diagnose", steps, enabled=progress_mode(args.quiet)) as bar:
        result = analyze(tracks, graph, preset=preset, n_boot=0, inputs={"graph": str(args.graph),
                                                                         "tracks": str(args.tracks)},
                         progress=lambda s: s != "bootstrap" and bar.start(s))
        bar.start("diagnosis")
        diag = diagnose_result(result, effects=names, seed=args.seed, n_folds=args.folds,
                               workers=default_workers())
        data = cli_wording_json(diagnosis_json(diag, result))
        view = cli_wording_json(diagnosis_for_viz(diag, result)) if (args.figures or args.rerun) else None
        # write every optional output first, the JSON last: a failure leaves no partial set of new files
        if args.figures is not None:
            bar.start("figures")
            _write_figures_atomic(result, view, args.figures)
        if args.rerun is not None:
            bar.start("recording")
            from ..viz.rerun_log import save_recording
            save_recording(result, args.rerun, diagnosis=view)
        write_json_atomic(data, args.json_path)
    print(cli_wording(diag.report()))
    print(f"\nwrote {args.json_path}")
    if args.figures is not None:
        print(f"wrote figures to {args.figures}/")
    if args.rerun is not None:
        from ..viewer import open_command
        print(f"wrote Rerun recording {args.rerun} (open it with: {open_command(args.rerun)})")
    print(f"total {process_seconds():.2f} s wall, from the command's start")
    return 0


def _write_figures_atomic(result, view, out_dir: Path) -> None:
    """Analysis + diagnosis figures into ``out_dir`` through a temporary sibling folder."""
    from ..fileio import publish, temp_dir_beside
    from ..viz.figures import write_figures

    tmp = temp_dir_beside(out_dir)
    try:
        write_figures(result, tmp, diagnosis=view)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    publish(tmp, out_dir)

