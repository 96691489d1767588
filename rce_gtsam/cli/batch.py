"""``rce batch MANIFEST --out DIR``: every recording of a manifest on a Dask cluster, and a summary."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .preset_args import add_preset_arguments, add_run_options
from .wording import candidates_from_args


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("batch", help="run many recordings (a manifest CSV) on a Dask cluster; summarise them",
                       description="Run every recording listed in MANIFEST (columns: id, then video + "
                                   "annotations or tracks, then graph, optional preset, any further columns as "
                                   "metadata; relative paths are relative to the manifest) through the whole "
                                   "pipeline (track a video, analyze, diagnose) into DIR/<id>/, one Dask task "
                                   "per recording, then write DIR/summary.csv, summary.json, figures/ and "
                                   "batch.rrd. A re-run skips recordings whose inputs and options are "
                                   "unchanged. Exit code 1 when a recording failed (see summary.csv).")
    p.add_argument("manifest", type=Path, help="manifest CSV, one recording per row")
    p.add_argument("--out", type=Path, required=True, help="output folder (DIR/<id>/ per recording)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                       help="run on an existing Dask scheduler (default: a LocalCluster on this machine)")
    where.add_argument("--workers", type=int, default=None, metavar="N",
                       help="worker processes of the LocalCluster, one thread each (default: one per core, "
                            "at most one per recording)")
    add_preset_arguments(p)
    add_run_options(p, "batch")
    p.add_argument("--model", type=Path, default=None, metavar="DIR_OR_ONNX",
                   help="TAPIR ONNX export for video rows (default: the OpenCV tracker)")
    p.add_argument("--max-frames", type=int, default=None, metavar="N", help="track only the first N frames")
    p.add_argument("--no-figures", action="store_true", help="skip the per-recording PNG figures")
    p.add_argument("--no-rerun", action="store_true", help="skip the batch Rerun recording (batch.rrd)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..batch import BatchOptions, load_manifest
    from ..batch import run as run_batch

    manifest = load_manifest(args.manifest)
    options = BatchOptions(preset=args.preset, overrides=tuple(args.overrides), seed=args.seed,
                           n_boot=args.bootstrap, effects=candidates_from_args(args), figures=not args.no_figures,
                           max_frames=args.max_frames, model=args.model)
    result = run_batch(manifest, args.out, scheduler=args.scheduler, workers=args.workers, options=options,
                       progress=not args.quiet, recording=not args.no_rerun)
    print(format_outcomes(result))
    print(f"wrote {', '.join(sorted(result.files))} to {args.out}/")
    for o in result.failed:
        print(f"rce batch: {o.id} failed: {o.error}", file=sys.stderr)
    return 1 if result.failed else 0


def format_outcomes(result) -> str:
    """One line per recording (status, verdict, what the diagnosis found, segments, seconds) and the totals."""
    by_id = {rid: g for rid, g in result.summary.groupby("id", sort=False)}
    lines = [f"{'id':<16} {'status':<8} {'verdict':<12} {'diagnosis':<12} {'segments':>8} {'time (s)':>9}"]
    for rid, o in result.outcomes.items():
        g = by_id.get(rid)
        verdict = g["verdict"].iloc[0] if g is not None and isinstance(g["verdict"].iloc[0], str) else "-"
        found = (g["diagnosis_status"].iloc[0] if g is not None and isinstance(g["diagnosis_status"].iloc[0], str)
                 else "-")
        nseg = int(g["kappa"].notna().sum()) if g is not None and "kappa" in g else 0
        status = {"ok": "computed", "skipped": "cached"}.get(o.status, o.status)
        lines.append(f"{rid:<16} {status:<8} {verdict:<12} {found:<12} {nseg:>8} {o.elapsed_s:9.1f}")
    lines.append(f"{len(result.outcomes)} recordings: {result.count('ok')} computed, {result.count('skipped')} "
                 f"unchanged (skipped), {result.count('failed')} failed; {result.wall_s:.1f} s")
    return "\n".join(lines)
