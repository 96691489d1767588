"""``rce analyze TRACKS GRAPH --out DIR [--effects a,b]``: the whole analysis on saved tracks."""

from __future__ import annotations

import argparse
from pathlib import Path

from .preset_args import add_preset_arguments, preset_from_args
from .progress import add_quiet_argument


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("analyze", help="smooth saved tracks, measure bending, fit relative compliance",
                       description="Smooth saved tracks with a GTSAM factor graph, measure bending at every "
                                   "joint and fit the rank-1 relative-compliance model with bootstrap CIs.")
    p.add_argument("tracks", type=Path, help="tracks CSV: point_id,frame,x,y[,visible,sigma_px] (pixels)")
    p.add_argument("graph", type=Path, help='branch graph JSON: {"root": id, "edges": [[parent, child], ...]}')
    p.add_argument("--out", type=Path, required=True,
                   help="output folder (created; the files this command writes are replaced, others left alone)")
    add_preset_arguments(p)
    p.add_argument("--seed", type=int, default=None,
                   help="seed of every random step of this command: kappa's bootstrap resamples and the "
                        "motion figure's CIs (default: the preset's, 0)")
    p.add_argument("--bootstrap", type=int, default=None, metavar="N",
                   help="bootstrap resamples (default: the preset's, 250; 0 disables CIs)")
    p.add_argument("--effects", default=None, metavar="A,B",
                   help="add physical effect terms to the rank-1 model and report kappa (with bootstrap CIs) "
                        "from the extended model: comma-separated from delay, dynamics, second_mode, offset, "
                        "nonlinear (see `rce diagnose` for which one your data need)")
    p.add_argument("--rerun", type=Path, default=None, metavar="FILE.rrd", help="also save a Rerun recording")
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    add_quiet_argument(p)
    p.set_defaults(func=run)


def extra_writers(args: argparse.Namespace, video=None, diagnosis=None) -> list:
    """Figure and overlay writers for ``AnalysisResult.write``, drawn in this process (none with
    ``no_figures``): for callers that are already parallel, such as ``rce batch``'s workers."""
    writers = []
    if not getattr(args, "no_figures", False):
        from ..viz.figures import write_figures  # a broken install must fail here, not silently skip figures
        from ..viz.overlays import write_overlays

        def figures(result, tmp):
            out = dict(write_figures(result, tmp / "figures", diagnosis=diagnosis))
            out.update(write_overlays(result, tmp / "figures", first_frame=first_video_frame(video)))
            return out
        writers.append(figures)
    return writers


def first_video_frame(video):
    """The first frame of ``video`` (RGB array) for the overlays, or None without a video."""
    if video is None:
        return None
    from ..track import open_video
    with open_video(video) as src:
        for frame in src:
            return frame.image
    return None


def save_recording(args, result, video=None, diagnosis=None, announce: bool = True) -> None:
    if args.rerun is None:
        return
    from ..viz.rerun_log import save_recording as _save
    path = _save(result, args.rerun, video_path=video, diagnosis=diagnosis)
    if announce:
        from ..viewer import open_command
        print(f"wrote Rerun recording {path} (open it with: {open_command(path)})")


def run(args: argparse.Namespace) -> int:
    from .figure_worker import FigureWorker
    from .progress import Steps, process_seconds, progress_mode

    # the figure worker forks at its first job, once the inputs are checked (see figure_worker)
    worker = None if args.no_figures else FigureWorker()
    figures = None
    try:
        from ..diagnosis.io import parse_effect_names
        from ..pipeline import ANALYSIS_STEPS, analyze

        from ..validate import check_analysis_inputs, check_command_options

        check_command_options(args)
        effects = parse_effect_names(args.effects) or ()  # fail on a bad name before the (slow) analysis
        preset = preset_from_args(args)
        graph, _, tracks = check_analysis_inputs(args.tracks, args.graph, preset)  # the CSV is read once
        print_lost_nodes("analyze", tracks, graph)
        t_start = process_seconds()
        steps = [*ANALYSIS_STEPS, "write"] + (["figures"] if worker else []) + (["recording"] if args.rerun else [])
        with Steps("analyze", steps, enabled=progress_mode(args.quiet)) as bar:
            figures = FiguresInBackground(worker) if worker else None
            result = analyze(tracks, graph, preset=preset, seed=args.seed, n_boot=args.bootstrap,
                             effects=effects, progress=bar.callback,
                             inputs={"graph": str(args.graph), "tracks": str(args.tracks)},
                             before_bootstrap=figures.before_bootstrap if figures else None)
            if figures:
                figures.after_bootstrap(result)
            bar.start("write")
            writers = [figures.writer(bar)] if figures else []
            files = result.write(args.out, extra_writers=writers)
            if args.rerun is not None:
                bar.start("recording")
                save_recording(args, result, announce=False)
    finally:
        if worker:
            worker.close()
        if figures:
            figures.discard()
    record_wall_time(result, t_start)
    print(format_summary(result))
    if args.rerun is not None:
        from ..viewer import open_command
        print(f"wrote Rerun recording {args.rerun} (open it with: {open_command(args.rerun)})")
    print(f"wrote {len(files)} files to {args.out}/: {', '.join(sorted(files))}")
    return quality_exit_code(result, "analyze")


def print_lost_nodes(command: str, tracks, graph) -> None:
    """One warning line on stderr per lost node (observed in fewer than 2 frames) naming it, the file and the
    segments dropped with it; the analysis goes on without them."""
    import sys

    from ..tracks import dropped_edges, lost_nodes
    for n in lost_nodes(tracks):
        seen = int(tracks.observed[tracks.index(n)].sum())
        segs = ", ".join(f"{j}->{c}" for j, c in dropped_edges(graph, [n]))
        print(f"rce {command}: warning: {tracks.source}: node {n} is observed in {seen} of {tracks.n_frames} frames "
              f"(2 are needed); its segments {segs} are dropped (tracking_lost), the rest go on", file=sys.stderr)


def quality_exit_code(result, command: str) -> int:
    """0, or 3 with one line on stderr when no segment's kappa passes the quality checks."""
    import sys

    from ..quality import assess_quality, verdict_line

    line = verdict_line(assess_quality(result))
    if line is None:
        return 0
    print(f"rce {command}: {line}", file=sys.stderr)
    return 3


def record_wall_time(result, t_start: float, stages: dict[str, float] | None = None) -> None:
    """Put the time before the analysis started (Python start-up and imports) and after it into
    ``result.timings_s``, whose ``total`` becomes the wall time since the process started: what the user
    waited. ``stages``: named stages that ran after the analysis (``{"diagnosis": s}``), each timed on its own;
    the rest of the time after the analysis (writing files, waiting for figures) is ``write``."""
    from .progress import process_seconds
    t = dict(result.timings_s)
    stages = dict(stages or {})
    after = process_seconds() - t_start - t.pop("total", 0.0) - sum(stages.values())
    result.timings_s.clear()
    result.timings_s.update({"imports": t_start, **t, **stages, "write": max(after, 0.0),
                             "total": process_seconds()})


class FiguresInBackground:
    """The analysis figures drawn by a :class:`~.figure_worker.FigureWorker`: matplotlib made ready as
    soon as this is made (before the smoothing), the figures that need no CI while the bootstrap runs,
    the rest right after it, collected into the output's ``figures/``."""

    def __init__(self, worker, first_frame=None):
        import os
        import tempfile

        from .figure_worker import prepare_figures
        self.worker = worker
        self.first_frame = first_frame
        # the worker splits each batch of figures with a second process where there is a second core
        self.processes = 2 if (os.cpu_count() or 1) >= 2 else 1
        self.dir = Path(tempfile.mkdtemp(prefix="rce_figures_"))  # scratch: files are moved out of it
        worker.submit(prepare_figures)

    def discard(self) -> None:
        """Remove the scratch folder (after a failure; :meth:`writer` removes it on success)."""
        import shutil
        shutil.rmtree(self.dir, ignore_errors=True)

    def before_bootstrap(self, partial) -> None:
        from ..viz.figures import CI_FIGURES, FIGURE_FILES
        from ..viz.overlays import CI_OVERLAYS, OVERLAY_FILES
        from .figure_worker import draw_analysis_figures
        self.worker.submit(draw_analysis_figures, partial, self.dir,
                           [n for n in FIGURE_FILES if n not in CI_FIGURES],
                           [n for n in OVERLAY_FILES if n not in CI_OVERLAYS], self.first_frame, self.processes)

    def after_bootstrap(self, result) -> None:
        from ..viz.figures import CI_FIGURES
        from ..viz.overlays import CI_OVERLAYS
        from .figure_worker import draw_analysis_figures
        self.worker.submit(draw_analysis_figures, result, self.dir, list(CI_FIGURES), list(CI_OVERLAYS),
                           self.first_frame, self.processes)

    def diagnosis(self, view, result) -> None:
        """Also draw the diagnosis figures (``view``: :func:`~rce_gtsam.diagnosis.io.diagnosis_for_viz`) and, when
        ``result`` carries the κ of a model with a named effect, its overlay, and the rank-1 overlay again on the
        same colour scale, titled as not the κ to report (this job runs after the first draw and replaces it)."""
        from ..viz.figures import write_diagnosis_figures
        from ..viz.overlays import REPORTED_OVERLAY
        from .figure_worker import draw_analysis_figures
        self.worker.submit(write_diagnosis_figures, view, self.dir, result)
        if getattr(result, "kappa_choice", None) is not None and result.kappa_choice.fitted:
            self.worker.submit(draw_analysis_figures, result, self.dir, [], ["kappa_overlay.png", REPORTED_OVERLAY],
                               self.first_frame, self.processes)

    def writer(self, bar):
        def collect(_result, tmp: Path) -> dict:
            import shutil
            bar.start("figures")
            try:
                drawn = {}
                for out in self.worker.results():
                    drawn.update({str(k): str(v) for k, v in out.items()})
                (tmp / "figures").mkdir(exist_ok=True)
                for name in drawn:
                    shutil.move(str(self.dir / name), tmp / "figures" / name)
            finally:
                shutil.rmtree(self.dir, ignore_errors=True)
            return {f"figures/{n}": tmp / "figures" / n for n in drawn}
        return collect


def format_summary(result) -> str:
    """A short human-readable summary of an analysis."""
    df = result.summary()
    sm = result.smoothing.as_dict()
    lines = [
        f"preset {result.preset.name}: {result.tracks.n_nodes} nodes, {result.tracks.n_frames} frames, "
        f"{len(result.bending.bends)} bends",
        f"smoother: {result.smoothed.report.iterations} LM iterations, final error "
        f"{result.smoothed.report.final_error:.4g}; bending RMS {sm['mean_bend_rms_raw_deg']:.2f} -> "
        f"{sm['mean_bend_rms_smoothed_deg']:.2f} deg ({lower_or_higher(sm['bend_rms_reduction_pct'])}), edge-length CV "
        f"{sm['mean_edge_length_cv_raw']:.3f} -> {sm['mean_edge_length_cv_smoothed']:.3f}",
        _fit_line(result),
        *_effects_lines(result),
        "",
        f"{'edge':>10} {'zone':>8} {'kappa':>7} {'95% CI':>17} {'U_e':>6} {'R2':>6} {'z seen':>6}  quality",
    ]
    for r in df.itertuples():
        if r.kappa != r.kappa:  # NaN: the root edge, or a segment dropped with a lost node
            what = "(dropped: a node lost)" if r.quality == "tracking_lost" else "(root edge: no bend)"
            lines.append(f"{r.parent:>4}->{r.child:<5} {r.zone:>8} {what:>31}"
                         + (f"{'':>22}{r.quality}" if r.quality else ""))
            continue
        seen = f"{100 * r.z_var_seen:5.0f}%" if r.z_var_seen == r.z_var_seen else f"{'-':>6}"
        lines.append(f"{r.parent:>4}->{r.child:<5} {r.zone:>8} {r.kappa:7.3f} [{r.kappa_ci_low:6.3f}, "
                     f"{r.kappa_ci_high:6.3f}] {r.uncertainty:6.3f} {r.fit_r2:6.2f} {seen}  {r.quality}")
    n_ok = int((df["quality"] == "ok").sum())
    n_dropped = int((df["kappa"].isna() & (df["quality"] == "tracking_lost")).sum())
    dropped = f", {n_dropped} dropped with a lost node" if n_dropped else ""
    lines.append(f"quality: {n_ok} of {int(df['kappa'].notna().sum()) + n_dropped} segments ok{dropped} "
                 "(flags: docs/results.md, "
                 "'The quality flags'; z seen: the share of the excitation's variance in the frames where "
                 "the segment's nodes were all tracked, what its kappa rests on)")
    from ..quality import assess_quality, informative_line
    rank1 = assess_quality(result)
    info = informative_line(rank1)
    if info:
        lines.append(info)
    lines += _reported_table(result, df, rank1)
    floor = getattr(result, "kappa_floor", None)
    if floor is not None and floor.line():
        lines.append(floor.line())
    tot = result.timings_s.get("total", float("nan"))
    waited = " wall, from the command's start" if "imports" in result.timings_s else ""
    lines.append(f"\ntotal {tot:.2f} s{waited} (" + ", ".join(f"{k} {v:.2f}" for k, v in result.timings_s.items()
                                                              if k != "total") + ")")
    return "\n".join(lines)


def _reported_table(result, df, rank1) -> list[str]:
    """After a verdict whose model was fitted (``result.kappa_choice.fitted``, ``rce run``): the κ to report, one
    line per segment with its 95 % CI and its own quality (:func:`rce_gtsam.quality.assess_reported_quality`),
    under the rank-1 table; nothing otherwise."""
    choice = getattr(result, "kappa_choice", None)
    if choice is None or not choice.fitted:
        return []
    from ..quality import assess_reported_quality, informative_line
    col = choice.column
    q = assess_reported_quality(result, rank1)
    lines = ["", f"kappa to report: {col}, the model with {choice.effect} (the rank-1 kappa above is not the one "
                 "to report; compliance_summary.csv has both)",
             f"{'edge':>10} {'zone':>8} {'kappa':>7} {'95% CI':>17}  quality"]
    for r in df.itertuples():
        k = getattr(r, col)
        if k != k:
            continue
        lo, hi = getattr(r, f"{col}_ci_low"), getattr(r, f"{col}_ci_high")
        lines.append(f"{r.parent:>4}->{r.child:<5} {r.zone:>8} {k:7.3f} [{lo:6.3f}, {hi:6.3f}]  "
                     f"{q[(int(r.parent), int(r.child))].quality}")
    lines.append(f"quality: {sum(v.ok for v in q.values())} of {len(q)} segments of {col} ok (its own fit and "
                 "interval; the data's flags as above)")
    info = informative_line(q)
    if info:
        lines.append(info)
    return lines


def lower_or_higher(reduction_pct: float) -> str:
    """A reduction in percent as read: "45.3% lower", or "0.3% higher" for a rise (a negative reduction)."""
    if reduction_pct != reduction_pct:
        return "change undefined"
    return f"{abs(reduction_pct):.1f}% {'lower' if reduction_pct >= 0 else 'higher'}"


def _fit_line(result) -> str:
    fit = result.fit
    state = "converged" if fit.converged else "NOT converged"
    if not getattr(result, "effects", ()):
        line = f"rank-1 fit: {fit.iterations} ALS iterations, {state}"
        ci = result.ci
        if ci is not None and ci.method == "phase":
            line += (f"\nCIs: {ci.n_boot} phase-randomised residual resamples; kappa's error rests on ~"
                     f"{ci.effective_samples:.1f} effective independent samples (the excitation's power sits in "
                     f"few frequencies), so intervals are widened x{ci.width_factor:.2f} (Student t)")
        elif ci is not None:
            line += f"\nCIs: {ci.n_boot} moving-block resamples, blocks of {ci.block_length} frames"
        return line
    mf = fit.model_fit
    return (f"model {mf.model.name}: {fit.iterations} iterations, {state}; fit RMSE "
            f"{fit.baseline_rmse_deg:.3f} deg (rank-1) -> {mf.rmse:.3f} deg")


def _effects_lines(result) -> list[str]:
    """One line per shared effect parameter (value +/- standard error, unit); per-edge terms are summarised."""
    if not getattr(result, "effects", ()):
        return []
    lines = []
    for name, summary in result.fit.model_fit.effect_summary().items():
        parts = []
        for key, v in summary.items():
            if "[" in key:
                continue  # per-edge values: in report.json
            if isinstance(v, dict) and v.get("value") is not None:
                se = v.get("stderr")
                parts.append(f"{key} = {v['value']:.4g}" + (f" +/- {se:.2g}" if se is not None else "")
                             + (f" {v['unit']}" if v.get("unit") not in (None, "1") else ""))
            elif isinstance(v, (int, float)):
                parts.append(f"{key} = {v:.4g}")
        lines.append(f"  {name}: " + ("; ".join(parts) if parts else "(per-edge terms only)")
                     + " (all parameters with standard errors in report.json)")
    boot = result.effects_bootstrap
    if boot is not None:
        lines.append(f"  bootstrap: {boot.n_boot} resamples, effect shared parameters {boot.shared_parameters}")
    return lines
