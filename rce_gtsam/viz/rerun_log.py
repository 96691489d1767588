"""Log an analysis (and a diagnosis) into one Rerun recording.

Entities (timelines ``frame`` = video frame index, and ``time`` = seconds into the video):

* ``image/video`` — the video (``AssetVideo``, static) and a ``VideoFrameReference`` per frame, when given;
* ``image/tracks/raw`` — the input tracker points (orange), ``image/tracks/smoothed`` — the smoothed
  positions (blue), ``image/tracks/uncertainty`` — 2-sigma ellipses of the marginal covariances;
* ``image/skeleton/kappa`` — the measured skeleton, each segment coloured by its kappa (colours fixed,
  blue = stiff, red = compliant); ``image/skeleton/residual`` — the same skeleton coloured by that
  frame's residual (diverging, centred at 0); ``image/skeleton/predicted`` — the skeleton the fitted
  model predicts (forward kinematics, :func:`~rce_gtsam.viz.scene.predicted_skeleton`);
* ``excitation/z`` — z_t in degrees;
* ``bending/<edge>`` — observed and predicted bending (degrees) per edge, with ``bending/<edge>/band``
  the observed value +- 2 sigma of the propagated angle uncertainty (Rerun has no confidence bands);
* ``residuals/<edge>`` — observed minus predicted, degrees;
* ``summary/kappa`` (bar chart) and ``summary/table`` (markdown table of kappa, CI, U_e);
* after a verdict whose model was fitted (``rce run``, ``rce batch``): ``image/skeleton/kappa_to_report``, the
  skeleton coloured by the κ to report (``kappa_<effect>``, on the rank-1 skeleton's colour scale; the default
  layout shows it and hides the rank-1 one), ``summary/kappa_to_report`` (bar chart) and its columns in the table;
* from :func:`log_diagnosis`: ``diagnosis/report`` (markdown), ``diagnosis/heldout`` (bar chart of
  held-out RMSE: baseline then each candidate), ``diagnosis/budget/{total,rank1,noise_floor,unexplained}_deg2``
  (the variance budget per segment, bar charts root -> tip), and ``diagnosis/after/<edge>`` (observed, rank-1 and
  extended-model prediction) when the diagnosis carries the extended model's prediction.

Everything per frame is sent in bulk with ``send_columns`` (one call per entity), not row by row.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
import rerun as rr

from ..fileio import temp_file_beside
from .scene import AnalysisView, covariance_ellipses
from .style import (EXCITATION_COLOR, KAPPA_CMAP, PREDICTED_COLOR, RAW_COLOR, RESIDUAL_CMAP,
                    SMOOTHED_COLOR, cmap_rgb, hex_to_rgb, robust_abs_max)

APP_ID = "rce_gtsam"
DEFAULT_FPS = 30.0  # both real plants were recorded at 30 fps; used only when no video gives timestamps


def _as_view(obj) -> AnalysisView:
    return obj if isinstance(obj, AnalysisView) else AnalysisView.from_result(obj)


def _indexes(frames: np.ndarray, seconds: np.ndarray) -> list:
    return [rr.TimeColumn("frame", sequence=np.asarray(frames, dtype=np.int64)),
            rr.TimeColumn("time", duration=np.asarray(seconds, dtype=np.float64))]


def _frame_seconds(n_frames: int, video_ts_ns: np.ndarray | None, fps: float) -> np.ndarray:
    sec = np.arange(n_frames) / fps
    if video_ts_ns is not None:
        k = min(n_frames, len(video_ts_ns))
        sec[:k] = np.asarray(video_ts_ns[:k], dtype=np.float64) * 1e-9
    return sec


def _segments(view: AnalysisView, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-frame segments of every graph edge: (F, n_edges, 2, 2) and the edge list's kappa (n_edges,)."""
    row = {int(n): i for i, n in enumerate(view.node_ids)}
    a = np.array([row[p] for p, _ in view.graph.edges])
    b = np.array([row[c] for _, c in view.graph.edges])
    seg = np.stack([xy[a], xy[b]], axis=2)  # (n_edges, F, 2, 2)
    return np.transpose(seg, (1, 0, 2, 3))


def _send_strips(rec, path: str, frames, seconds, strips: np.ndarray, colors: np.ndarray | None,
                 radius: float, labels: list[str] | None = None) -> int:
    """Send per-frame line strips. ``strips`` (F, S, P, 2) with NaN rows dropped; ``colors`` (F, S, 3) or
    (S, 3). Returns the number of rows sent."""
    F, S = strips.shape[:2]
    ok = np.isfinite(strips).all(axis=(2, 3))  # (F, S)
    keep = ok.any(axis=1)
    if not keep.any():
        return 0
    lengths = ok[keep].sum(axis=1)
    flat = strips[keep][ok[keep]]  # (n, P, 2)
    cols = {}
    if colors is not None:
        c = colors if colors.ndim == 3 else np.broadcast_to(colors, (F, S, 3))
        cols["colors"] = c[keep][ok[keep]]
    if labels is not None:
        cols["labels"] = np.broadcast_to(np.array(labels, dtype=object), (F, S))[keep][ok[keep]].tolist()
    # one (n, P, 2) array: Rerun's numpy path converts it in one go (a list converts strip by strip, ~100x slower)
    columns = rr.LineStrips2D.columns(strips=np.ascontiguousarray(flat, dtype=np.float32),
                                      radii=np.full(len(flat), radius, np.float32), **cols).partition(lengths)
    rec.send_columns(path, indexes=_indexes(frames[keep], seconds[keep]), columns=columns)
    return int(keep.sum())


def _send_points(rec, path: str, xy: np.ndarray, seconds, color: str, radius: float, node_ids) -> int:
    """Send (N, F, 2) points per frame (NaN = absent)."""
    N, F, _ = xy.shape
    P = np.transpose(xy, (1, 0, 2))  # (F, N, 2)
    ok = np.isfinite(P).all(axis=2)
    keep = ok.any(axis=1)
    if not keep.any():
        return 0
    lengths = ok[keep].sum(axis=1)
    labels = np.broadcast_to(np.array([str(n) for n in node_ids], dtype=object), (F, N))[keep][ok[keep]]
    columns = rr.Points2D.columns(positions=P[keep][ok[keep]].astype(np.float32),
                                  radii=np.full(int(lengths.sum()), radius, np.float32),
                                  colors=np.broadcast_to(np.array(hex_to_rgb(color), np.uint8),
                                                         (int(lengths.sum()), 3)),
                                  labels=labels.tolist(), show_labels=np.zeros(int(lengths.sum()), bool)
                                  ).partition(lengths)
    frames = np.arange(F)[keep]
    rec.send_columns(path, indexes=_indexes(frames, seconds[keep]), columns=columns)
    return int(keep.sum())


def log_video(rec: rr.RecordingStream, video_path: str | Path, n_frames: int,
              entity: str = "image/video") -> np.ndarray:
    """Log the video (transcoded to H.264 when needed) and one frame reference per frame.

    Returns the video's frame timestamps in nanoseconds (one per decoded frame)."""
    from .video import playable_video
    with tempfile.TemporaryDirectory(prefix="rce_video_") as tmp:
        playable = playable_video(video_path, tmp)
        asset = rr.AssetVideo(contents=Path(playable).read_bytes(), media_type="video/mp4")
    ts = np.asarray(asset.read_frame_timestamps_nanos(), dtype=np.int64)
    rec.log(entity, asset, static=True)
    k = min(len(ts), n_frames) if n_frames else len(ts)
    rec.send_columns(entity, indexes=_indexes(np.arange(k), ts[:k] * 1e-9),
                     columns=rr.VideoFrameReference.columns_nanos(ts[:k]))
    return ts


def log_analysis(result, rec: rr.RecordingStream, video_path: str | Path | None = None,
                 fps: float | None = None) -> AnalysisView:
    """Log an :class:`~rce_gtsam.pipeline.AnalysisResult` (or an :class:`AnalysisView`) into ``rec``.

    ``video_path``: the video the tracks came from (any codec; non-H.264 is transcoded). ``fps``: frame
    rate for the ``time`` timeline when there is no video (default 30). Returns the view that was drawn.
    """
    view = _as_view(result)
    F = view.n_frames
    ts = log_video(rec, video_path, F) if video_path is not None else None
    sec = _frame_seconds(F, ts, fps or DEFAULT_FPS)
    frames_all = np.arange(F)
    rec.log("/", rr.TextDocument(f"rce_gtsam analysis of {view.title}"), static=True)

    # --- image space -------------------------------------------------------------------------
    if view.raw_xy is not None:
        _send_points(rec, "image/tracks/raw", view.raw_xy, sec, RAW_COLOR, 1.5, view.node_ids)
    _send_points(rec, "image/tracks/smoothed", view.xy, sec, SMOOTHED_COLOR, 2.0, view.node_ids)
    if view.cov is not None:
        ell = covariance_ellipses(view.cov, view.xy, n_sigma=2.0)  # (N, F, P, 2)
        _send_strips(rec, "image/tracks/uncertainty", frames_all, sec, np.transpose(ell, (1, 0, 2, 3)),
                     np.array(hex_to_rgb(SMOOTHED_COLOR), np.uint8)[None], radius=0.4)

    seg = _segments(view, view.xy)  # (F, n_edges, 2, 2)
    kappa_of = {e: k for e, k in zip(view.edges, view.kappa)}
    edge_kappa = np.array([kappa_of.get(e, np.nan) for e in view.graph.edges])
    both = np.r_[view.kappa, [] if view.kappa_report is None else view.kappa_report]
    kmax = float(np.nanmax(both)) if np.isfinite(both).any() else 1.0
    # colour scale 0..max(kappa) (at least 0..1; one scale for the rank-1 kappa and the kappa to report): kappa is
    # relative, so the scale is per branch
    kcol = cmap_rgb(edge_kappa, KAPPA_CMAP, 0.0, max(kmax, 1.0))
    klabels = [f"κ={k:.2f}" if np.isfinite(k) else "root edge" for k in edge_kappa]
    _send_strips(rec, "image/skeleton/kappa", frames_all, sec, seg, kcol, radius=1.6, labels=klabels)
    if view.kappa_report is not None:
        report_of = {e: k for e, k in zip(view.edges, view.kappa_report)}
        edge_report = np.array([report_of.get(e, np.nan) for e in view.graph.edges])
        _send_strips(rec, "image/skeleton/kappa_to_report", frames_all, sec, seg,
                     cmap_rgb(edge_report, KAPPA_CMAP, 0.0, max(kmax, 1.0)), radius=1.6,
                     labels=[f"{view.report_column}={k:.2f}" if np.isfinite(k) else "root edge"
                             for k in edge_report])

    res = view.residual
    lim = robust_abs_max(res)
    res_full = np.full((len(view.graph.edges), F), np.nan)
    erow = {e: i for i, e in enumerate(view.graph.edges)}
    for i, e in enumerate(view.edges):
        res_full[erow[e], view.frames] = res[i]
    rcol = cmap_rgb(res_full.T, RESIDUAL_CMAP, -lim, lim)  # (F, n_edges, 3)
    _send_strips(rec, "image/skeleton/residual", frames_all[view.frames], sec[view.frames], seg[view.frames],
                 rcol[view.frames], radius=1.2)
    pseg = _segments(view, view.predicted_xy)
    _send_strips(rec, "image/skeleton/predicted", frames_all[view.frames], sec[view.frames], pseg[view.frames],
                 np.array(hex_to_rgb(PREDICTED_COLOR), np.uint8)[None], radius=0.7)

    # --- time series -------------------------------------------------------------------------
    idx = _indexes(view.frames, sec[view.frames])
    rec.log("excitation/z", rr.SeriesLines(colors=[hex_to_rgb(EXCITATION_COLOR)], names=["z (deg)"]), static=True)
    rec.send_columns("excitation/z", indexes=idx, columns=rr.Scalars.columns(scalars=view.z))
    for i, e in enumerate(view.edges):
        name = view.edge_name(e)
        rec.log(f"bending/{name}", rr.SeriesLines(colors=[hex_to_rgb(SMOOTHED_COLOR), (40, 40, 40)],
                                                  names=[f"observed {e[0]}→{e[1]} (deg)", "predicted κ·z (deg)"],
                                                  widths=[1.5, 1.5]), static=True)
        rec.send_columns(f"bending/{name}", indexes=idx,
                         columns=rr.Scalars.columns(scalars=np.stack([view.Y[i], view.pred[i]], axis=1)))
        if view.variance is not None:
            s2 = 2.0 * np.sqrt(view.variance[i])
            rec.log(f"bending/{name}/band", rr.SeriesLines(colors=[(160, 190, 220)] * 2, widths=[0.5, 0.5],
                                                           names=["observed − 2σ", "observed + 2σ"]), static=True)
            rec.send_columns(f"bending/{name}/band", indexes=idx,
                             columns=rr.Scalars.columns(scalars=np.stack([view.Y[i] - s2, view.Y[i] + s2], axis=1)))
        rec.log(f"residuals/{name}", rr.SeriesLines(colors=[hex_to_rgb("#b2182b")], names=[f"residual {e[0]}→{e[1]} (deg)"]),
                static=True)
        rec.send_columns(f"residuals/{name}", indexes=idx, columns=rr.Scalars.columns(scalars=res[i]))

    # --- summary -------------------------------------------------------------------------------
    rec.log("summary/kappa", rr.BarChart(np.nan_to_num(view.kappa)), static=True)
    if view.kappa_report is not None:
        rec.log("summary/kappa_to_report", rr.BarChart(np.nan_to_num(view.kappa_report)), static=True)
    rec.log("summary/table", rr.TextDocument(summary_markdown(view), media_type=rr.MediaType.MARKDOWN), static=True)
    return view


def summary_markdown(view: AnalysisView) -> str:
    """Markdown table of kappa, 95 % CI, U_e and residual RMS per edge, root to tip."""
    res = view.residual
    rep = view.kappa_report
    columns = ["edge", "zone", "κ", "95 % CI", "U_e", "residual RMS (deg)", "floor (×)"]
    lines = [f"# Relative compliance — {view.title}", "",
             f"Response: `{view.response}` bending; {len(view.edges)} edges, {len(view.frames)} frames. "
             "κ is relative (geometric mean 1); U_e = CI width / κ.", ""]
    if rep is not None:
        columns += [f"`{view.report_column}`", "95 % CI"]
        lines += [f"**Report `{view.report_column}`** (the model with the named effect; skeleton "
                  "`image/skeleton/kappa_to_report`), not the rank-1 κ: the diagnosis names an effect the "
                  "rank-1 model leaves out.", ""]
    lines += ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    floor = view.floor_log_rmse
    for i, e in enumerate(view.edges):
        r = res[i][np.isfinite(res[i])]
        rms = float(np.sqrt(np.mean(r ** 2))) if r.size else float("nan")
        u = (view.ci_high[i] - view.ci_low[i]) / view.kappa[i] if view.kappa[i] > 1e-9 else float("nan")
        f = f"{np.exp(floor[i]):.2f}" if floor is not None and np.isfinite(floor[i]) else "–"
        lines.append(f"| {e[0]}→{e[1]} | {view.zone[i]} | {view.kappa[i]:.3f} | "
                     f"[{view.ci_low[i]:.3f}, {view.ci_high[i]:.3f}] | {u:.3f} | {rms:.3f} | {f} |"
                     + ("" if rep is None else
                        f" {rep[i]:.3f} | [{view.ci_low_report[i]:.3f}, {view.ci_high_report[i]:.3f}] |"))
    if view.floor_text:  # what limits kappa: floor (x) is the factor either way the tracker's error alone allows
        lines += ["", "floor (×): the factor either way the tracker's error alone allows κ. " + view.floor_text]
    return "\n".join(lines) + "\n"


def save_recording(result, path: str | Path, video_path: str | Path | None = None, diagnosis=None,
                   fps: float | None = None) -> Path:
    """Write one ``.rrd`` with the analysis (and the diagnosis, if given) and a default blueprint.

    Written to a temporary file beside ``path`` and renamed, so a failure leaves no partial recording.
    """
    from .blueprint import build_blueprint
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    view = _as_view(result)

    def log(rec) -> None:
        log_analysis(view, rec, video_path=video_path, fps=fps)
        if diagnosis is not None:
            log_diagnosis(diagnosis, rec, view=view)

    return write_rrd(path, build_blueprint(view, diagnosis, video=video_path is not None), log)


def write_rrd(path: Path, blueprint, log, app_id: str = APP_ID) -> Path:
    """Write one ``.rrd``: a recording stream of ``app_id`` saved to a temporary file beside ``path`` with
    ``blueprint`` as its default, filled by ``log(rec)``, then renamed, so a failure leaves no partial recording.
    Returns ``path``."""
    tmp = temp_file_beside(path, suffix=".rrd")
    try:
        rec = rr.RecordingStream(app_id)
        rec.save(str(tmp), default_blueprint=blueprint)
        log(rec)
        rec.flush()
        rec.disconnect()
        del rec
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def spawn_viewer(result, video_path=None, diagnosis=None, fps=None) -> None:
    """Open a native Rerun viewer and stream the analysis (and diagnosis) into it."""
    from ..viewer import viewer_executable
    from .blueprint import build_blueprint
    view = _as_view(result)
    rec = rr.RecordingStream(APP_ID)
    # the viewer of this environment (.venv/bin/rerun), which need not be on PATH
    rr.spawn(recording=rec, executable_path=viewer_executable(),
             default_blueprint=build_blueprint(view, diagnosis, video=video_path is not None))
    log_analysis(view, rec, video_path=video_path, fps=fps)
    if diagnosis is not None:
        log_diagnosis(diagnosis, rec, view=view)
    rec.flush()


# ---------------------------------------------------------------------------------------- diagnosis
def _get(obj, name, default=None):
    if isinstance(obj, dict):
        return obj.get(name, default)
    return getattr(obj, name, default)


def diagnosis_markdown(diagnosis) -> str:
    """Markdown of a diagnosis: verdict, explanation, held-out error table, worst edges and frames."""
    report = _get(diagnosis, "report_markdown") or _get(diagnosis, "markdown")
    if callable(report):
        report = report()
    if isinstance(report, str) and report:
        return report
    base = _get(diagnosis, "baseline", {}) or {}
    verdict = _get(diagnosis, "verdict")
    lines = ["# Model diagnosis", "", f"**Verdict:** {verdict or 'no missing effect detected'}", "",
             str(_get(diagnosis, "explanation", "") or ""), "",
             "| model | held-out RMSE (deg) | change | evidence |", "|---|---|---|---|",
             f"| rank-1 baseline | {_num(_get(base, 'heldout_rmse'))} | | |"]
    b = _get(base, "heldout_rmse")
    for c in _get(diagnosis, "candidates", []) or []:
        h = _get(c, "heldout_rmse")
        change = f"{100 * (h / b - 1):+.1f} %" if _isnum(h) and _isnum(b) and b else ""
        lines.append(f"| + {_get(c, 'effect')} | {_num(h)} | {change} | {_num(_get(c, 'evidence'))} |")
    we = _get(diagnosis, "worst_edges") or []
    if we:
        lines += ["", "**Worst edges:** " + ", ".join(_fmt_item(x) for x in list(we)[:5])]
    wf = _get(diagnosis, "worst_frames") or []
    if wf:
        lines += ["", "**Worst time windows:** " + ", ".join(_fmt_item(x) for x in list(wf)[:5])]
    text = _get(diagnosis, "text") or _get(diagnosis, "report")
    if isinstance(text, str) and text:
        lines += ["", "```", text.rstrip(), "```"]
    return "\n".join(lines) + "\n"


def _isnum(x) -> bool:
    return isinstance(x, (int, float, np.floating, np.integer)) and np.isfinite(x)


def _num(x) -> str:
    return f"{float(x):.4g}" if _isnum(x) else "–"


def _fmt_item(x) -> str:
    if isinstance(x, dict):
        return "; ".join(f"{k} {_num(v) if _isnum(v) else v}" for k, v in x.items())
    return str(x)


def log_diagnosis(diagnosis, rec: rr.RecordingStream, view: AnalysisView | None = None) -> None:
    """Log a diagnosis (the ``rce diagnose`` JSON dict or a ``Diagnosis`` object) into ``rec``.

    ``diagnosis/report`` (markdown), ``diagnosis/heldout`` (bar chart: baseline, then each candidate),
    and, when the diagnosis carries an extended-model prediction (``after_prediction`` / ``Y_after``:
    (E, T) degrees in the response's edge and frame order) and ``view`` is given, before/after curves
    ``diagnosis/after/<edge>`` = observed, rank-1 prediction, extended-model prediction.
    """
    rec.log("diagnosis/report", rr.TextDocument(diagnosis_markdown(diagnosis), media_type=rr.MediaType.MARKDOWN),
            static=True)
    base = _get(diagnosis, "baseline", {}) or {}
    vals = [_get(base, "heldout_rmse")] + [_get(c, "heldout_rmse") for c in (_get(diagnosis, "candidates", []) or [])]
    vals = [float(v) if _isnum(v) else 0.0 for v in vals]
    if vals:
        rec.log("diagnosis/heldout", rr.BarChart(np.array(vals)), static=True)
    log_budget(diagnosis, rec)
    ra = _get(diagnosis, "residual_analysis_obj") or _get(diagnosis, "residual_analysis")
    if ra is not None and hasattr(ra, "freqs"):
        log_residual_analysis(ra, rec, [view.edge_name(e) for e in view.edges] if view is not None else None)
    after = _get(diagnosis, "after_prediction")
    if after is None:
        after = _get(diagnosis, "Y_after")
    if view is None or after is None:
        return
    after = np.asarray(after, dtype=float)
    if after.shape != view.Y.shape:
        return
    sec = view.frames / DEFAULT_FPS
    idx = _indexes(view.frames, sec)
    name = _get(diagnosis, "verdict") or "extended"
    for i, e in enumerate(view.edges):
        p = f"diagnosis/after/{view.edge_name(e)}"
        rec.log(p, rr.SeriesLines(colors=[hex_to_rgb(SMOOTHED_COLOR), (40, 40, 40), hex_to_rgb("#d95f02")],
                                  names=["observed (deg)", "rank-1 κ·z (deg)", f"with {name} (deg)"]), static=True)
        rec.send_columns(p, indexes=idx, columns=rr.Scalars.columns(
            scalars=np.stack([view.Y[i], view.pred[i], after[i]], axis=1)))


#: the variance-budget parts logged per segment under ``diagnosis/budget/<part>_deg2`` (root -> tip)
BUDGET_PARTS = ("total", "rank1", "noise_floor", "unexplained")


def log_budget(diagnosis, rec: rr.RecordingStream) -> None:
    """The variance budget per segment (deg^2, in the response's edge order): one bar chart per part of
    :data:`BUDGET_PARTS` under ``diagnosis/budget/``. Nothing when the diagnosis has no budget."""
    from .budget import budget_rows

    budget = _get(diagnosis, "budget")
    if budget is None:
        return
    _, rows = budget_rows(budget, _get(diagnosis, "budget_per_segment"))
    if not rows:
        return
    for part in BUDGET_PARTS:
        vals = np.array([r.get(part) if _isnum(r.get(part)) else np.nan for r in rows], dtype=float)
        rec.log(f"diagnosis/budget/{part}_deg2", rr.BarChart(np.nan_to_num(vals)), static=True)


def log_residual_analysis(ra, rec: rr.RecordingStream, names=None) -> None:
    """Log a :class:`~rce_gtsam.diagnosis.sysid.ResidualAnalysis` under ``diagnosis/sysid/``: per segment the
    z -> bending gain and phase against log10 frequency (2-D line strips, coherent frequencies only), the
    residual-z cross-correlation in units of its band against lag, and bar charts of each segment's delay
    (frames) and residual trend (deg)."""
    E = ra.gain.shape[0]
    names = names or [str(i) for i in range(E)]
    f = ra.freqs
    pos = f > 0
    for e in range(E):
        coh = pos & (ra.coherence[e] > ra.coherence_threshold)
        if coh.sum() >= 2:
            lf = np.log10(f[coh])
            rec.log(f"diagnosis/sysid/gain/{names[e]}", rr.LineStrips2D([np.stack([lf, np.log10(ra.gain[e, coh])], 1)]),
                    static=True)
            rec.log(f"diagnosis/sysid/phase/{names[e]}", rr.LineStrips2D([np.stack([lf, ra.phase_deg[e, coh] / 90.0], 1)]),
                    static=True)
        rec.log(f"diagnosis/sysid/xcorr/{names[e]}",
                rr.LineStrips2D([np.stack([ra.lags.astype(float), ra.xcorr[e] / ra.xcorr_band[e]], 1)]), static=True)
    rec.log("diagnosis/sysid/delay_frames", rr.BarChart(np.nan_to_num(ra.delay_frames)), static=True)
    rec.log("diagnosis/sysid/trend_deg", rr.BarChart(np.nan_to_num(ra.trend_deg)), static=True)
