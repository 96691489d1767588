"""``rce view DIR [--rrd OUT.rrd | --spawn]``: a Rerun recording of an analysis output folder."""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("view", help="open or save a Rerun recording of an analysis output folder",
                       description="Build a Rerun recording (tracks with 2-sigma ellipses, skeleton coloured by "
                                   "kappa and by residual, the model's predicted skeleton, excitation, observed vs "
                                   "predicted bending, diagnosis report) from a folder written by `rce analyze` "
                                   "or `rce run`, and save it or open the Rerun viewer.")
    p.add_argument("dir", type=Path, help="output folder of `rce analyze` / `rce run`")
    out = p.add_mutually_exclusive_group()
    out.add_argument("--rrd", type=Path, default=None, metavar="OUT.rrd",
                     help="write the recording here (default: DIR/recording.rrd unless --spawn)")
    out.add_argument("--spawn", action="store_true", help="open a native Rerun viewer instead of writing a file")
    p.add_argument("--video", type=Path, default=None,
                   help="the video the tracks came from (any codec; non-H.264 is transcoded for the viewer)")
    p.add_argument("--tracks", type=Path, default=None,
                   help="input tracks CSV for the raw points (default: the path in DIR/report.json, if it exists)")
    p.add_argument("--diagnosis", type=Path, default=None,
                   help="diagnosis JSON of `rce diagnose --json` (default: DIR/diagnosis.json, if present)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..errors import InputError
    from ..viz.rerun_log import save_recording, spawn_viewer
    from ..viz.scene import AnalysisView

    from ..validate import check_output_file

    check_output_file(args.rrd, "--rrd")
    if args.spawn:
        from ..viewer import require_display
        require_display()
    view = AnalysisView.from_folder(args.dir, tracks=args.tracks)
    diag_path = args.diagnosis or (args.dir / "diagnosis.json")
    diagnosis = None
    if args.diagnosis is not None or diag_path.is_file():
        try:
            diagnosis = json.loads(Path(diag_path).read_text())
        except (OSError, json.JSONDecodeError) as exc:
            raise InputError(diag_path, f"cannot read the diagnosis JSON: {exc}") from None
    if args.spawn:
        spawn_viewer(view, video_path=args.video, diagnosis=diagnosis)
        print(f"streaming {args.dir} into a Rerun viewer")
        return 0
    path = save_recording(view, args.rrd or (args.dir / "recording.rrd"), video_path=args.video, diagnosis=diagnosis)
    from ..viewer import open_command
    print(f"wrote {path} (open it with: {open_command(path)})")
    return 0
