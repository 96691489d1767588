"""Matplotlib figures of an analysis and of a diagnosis (Agg backend, PNG at 150 dpi).

Each ``fig_*`` function returns a :class:`matplotlib.figure.Figure` (tests inspect them);
:func:`write_figures` / :func:`write_diagnosis_figures` save them and close them.

Figures of an analysis (file names):

* ``smoothing.png`` — (a) filtered bending RMS per bend and (b) edge-length CV per edge against root
  distance, raw (the tracker's output, or its moving average when the preset has one, as in ``paper``) vs
  smoothed tracks: what the factor-graph smoother removed;
* ``motion.png`` — (a) root-relative node motion RMS (px) and (b) filtered bending RMS (deg) against root
  distance, with moving-block bootstrap 95 % CIs, coloured by zone;
* ``compliance.png`` — (a) kappa per edge with its bootstrap 95 % CI against root distance, zone colours,
  kappa = 1 (the branch's geometric mean) dashed; (b) U_e = CI width / kappa per edge, root to tip;
* ``excitation.png`` — the shared excitation z_t (deg) against frame;
* ``residuals.png`` — residual heatmap observed - predicted (edges x frames, diverging colours centred
  at 0) with per-frame and per-edge RMS marginals: where and when the rank-1 model fails;
* ``bending_fit.png`` — observed (with +-2 sigma band) vs predicted bending of the worst-fitted edges.

Figures of a diagnosis: ``heldout_error.png`` (held-out RMSE of the baseline and each candidate effect),
``residuals_diagnosis.png`` (the diagnosis' residual heatmap) and ``effect_before_after.png`` when the
diagnosis carries the extended model's prediction.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .style import mpl_style as _style
from .style import fixed_margins, save_png as _save
from .style import (EXCITATION_COLOR, FIG_WIDTH_IN, RAW_COLOR, RC, RESIDUAL_CMAP, SMOOTHED_COLOR,
                    ZONE_COLORS, robust_abs_max)


def _zone_legend(ax, zones, loc="upper left", ncol=1):
    from matplotlib.lines import Line2D
    present = [z for z in ("proximal", "mid", "distal", "root") if z in set(map(str, zones))]
    handles = [Line2D([], [], marker="o", ls="", color=ZONE_COLORS[z], label=z, markersize=4) for z in present]
    if ncol > 1:
        ax.legend(handles=handles, loc=loc, ncol=ncol, handletextpad=0.2, columnspacing=0.8)
    else:
        ax.legend(handles=handles, loc=loc, title="zone", title_fontsize=7)


def _errorbars(ax, x, v, lo, hi, zones, marker="o"):
    """Points ``v`` at ``x`` with their intervals [lo, hi] (no bar where an end is not finite), in zone
    colours: one ``errorbar`` container per zone and kind (with / without an interval), since every call
    costs as much as drawing many points (the figures wait on it)."""
    x, v, lo, hi = (np.asarray(a, dtype=float) for a in (x, v, lo, hi))
    zones = np.array([str(z) for z in zones], dtype=object)
    ok = np.isfinite(v)
    has_ci = np.isfinite(lo) & np.isfinite(hi)
    for zone in dict.fromkeys(zones[ok]):
        for with_ci in (True, False):
            sel = ok & (zones == zone) & (has_ci == with_ci)
            if not sel.any():
                continue
            yerr = np.vstack([np.maximum(v[sel] - lo[sel], 0.0), np.maximum(hi[sel] - v[sel], 0.0)]) if with_ci else None
            ax.errorbar(x[sel], v[sel], yerr=yerr, fmt=marker, color=ZONE_COLORS.get(zone, "#777777"), ms=3.5,
                        elinewidth=0.9, capsize=1.5, zorder=3)


# ------------------------------------------------------------------------------------------- analysis
def fig_smoothing(result):
    """Raw vs smoothed: bending RMS per bend and edge-length CV per edge against root distance."""
    sm, geo, g = result.smoothing, result.geometry, result.graph
    rd_b = np.array([geo.root_distance_px[b.child] for b in result.bending.bends])
    rd_e = np.array([geo.root_distance_px[c] for _, c in g.edges])
    d = sm.as_dict()
    window = int(result.preset.smoother.presmooth_window)
    raw_label = f"raw (moving average of {window})" if window > 1 else "raw (tracker output)"
    with _style() as plt:
        fig, axes = plt.subplots(1, 2, figsize=(FIG_WIDTH_IN, 2.6))
        fixed_margins(fig, left=0.5, top=0.52, bottom=0.4, wspace=0.62, ncols=2)
        for ax, rd, raw, smo, ylabel, title, red in (
                (axes[0], rd_b, sm.bend_rms_raw_deg, sm.bend_rms_smoothed_deg, "filtered bending RMS (deg)",
                 "(a) Bending noise", d["bend_rms_reduction_pct"]),
                (axes[1], rd_e, sm.edge_cv_raw, sm.edge_cv_smoothed, "edge-length CV (std / mean)",
                 "(b) Segment length", d["edge_length_cv_reduction_pct"])):
            o = np.argsort(rd)
            for y, lab, col, ls, mk in ((raw, raw_label, RAW_COLOR, "--", "o"),
                                        (smo, "smoothed (factor graph)", SMOOTHED_COLOR, "-", "s")):
                ok = np.isfinite(y[o])
                ax.plot(rd[o][ok], y[o][ok], ls=ls, marker=mk, color=col, ms=3, label=lab)
            ax.set_xlabel("root distance (px)")
            ax.set_ylabel(ylabel)
            ax.set_title(f"{title}: mean {abs(red):.0f} % {'lower' if red >= 0 else 'higher'}")
            ax.set_ylim(bottom=0)
        h, lab = axes[0].get_legend_handles_labels()
        fig.legend(h, lab, loc="upper center", ncol=2, borderaxespad=0.2)
    return fig


def fig_motion(result, seed: int = 0):
    """Node motion RMS and bending RMS against root distance, with bootstrap CIs, by zone."""
    from .metrics import bend_rms, node_motion
    nm, br = node_motion(result, seed=seed), bend_rms(result, seed=seed)
    with _style() as plt:
        fig, axes = plt.subplots(1, 2, figsize=(FIG_WIDTH_IN, 2.6))
        fixed_margins(fig, left=0.5, top=0.28, bottom=0.4, wspace=0.62, ncols=2)
        _errorbars(axes[0], nm.root_distance_px, nm.value, nm.low, nm.high, nm.zone)
        axes[0].set_ylabel("root-relative motion RMS (px)")
        axes[0].set_title("(a) Node motion")
        _errorbars(axes[1], br.root_distance_px, br.value, br.low, br.high, br.zone, marker="s")
        axes[1].set_ylabel("filtered bending RMS |Δβ| (deg)")
        axes[1].set_title("(b) Bending at each joint")
        for ax in axes:
            ax.set_xlabel("root distance (px)")
            ax.set_ylim(bottom=0)
        _zone_legend(axes[0], nm.zone)
    return fig


def fig_compliance(result):
    """kappa with 95 % CI per edge against root distance (zone colours) and U_e bars root -> tip."""
    resp, fit = result.response, result.fit
    zones = np.array([result.geometry.zone[c] for _, c in resp.edges])
    E = len(resp.edges)
    lo = result.ci.low if result.ci is not None else np.full(E, np.nan)
    hi = result.ci.high if result.ci is not None else np.full(E, np.nan)
    U = result.uncertainty if result.uncertainty is not None else np.full(E, np.nan)
    labels = [f"{j}→{c}" for j, c in resp.edges]
    with _style() as plt:
        fig, axes = plt.subplots(1, 2, figsize=(FIG_WIDTH_IN, 2.8), gridspec_kw={"width_ratios": [1.1, 1]})
        fixed_margins(fig, left=0.5, top=0.28, bottom=0.4 + 0.055 * max(len(s) for s in labels), wspace=0.62,
                      ncols=2)
        ax = axes[0]
        ax.axhline(1.0, color="0.4", ls="--", lw=0.8, zorder=1)
        _errorbars(ax, resp.root_distance_px, fit.kappa, lo, hi, zones)
        ax.set_yscale("log")
        # Axis range: every CI, but at most a factor 10 beyond the kappa values themselves, so one
        # unbounded interval cannot squash the rest (a CI running off the axis reads as "unbounded").
        kpos = fit.kappa[fit.kappa > 0]
        kmin, kmax = (kpos.min(), kpos.max()) if kpos.size else (1.0, 1.0)
        top = min(np.nanmax(np.r_[hi[np.isfinite(hi)], kmax]) * 1.3, kmax * 10)
        bot = max(np.nanmin(np.r_[lo[np.isfinite(lo) & (lo > 0)], kmin]) / 1.3, kmin / 10)
        ax.set_ylim(bot, top * 4.0)  # head-room for the zone legend row
        _log_ticks(ax)
        ax.set_xlabel("root distance of the segment's distal node (px)")
        ax.set_ylabel("relative compliance κ (log scale)")
        ax.set_title("(a) Relative compliance, 95 % CI")
        _zone_legend(ax, zones, loc="upper center", ncol=4)
        ax = axes[1]
        x = np.arange(E)
        ax.bar(x, np.nan_to_num(U), color=[ZONE_COLORS.get(z, "#777") for z in zones], width=0.75)
        if np.isfinite(U).any():
            # clip the axis at 4x the median so one unstable edge does not flatten the others; label it
            cap = 4.0 * float(np.nanmedian(U))
            if np.nanmax(U) > 1.15 * cap:
                ax.set_ylim(0, cap * 1.1)
                for xi, u in zip(x, U):
                    if np.isfinite(u) and u > cap * 1.1:
                        ax.text(xi, cap * 1.08, f"{u:.1f}↑", ha="center", va="top", fontsize=6, rotation=90,
                                color="white", fontweight="bold")
        ax.set_xticks(x, labels, rotation=90, fontsize=6 if E > 15 else 7)
        ax.set_xlim(-0.7, E - 0.3)
        ax.set_xlabel("segment (parent→child), root → tip")
        ax.set_ylabel("U_e = CI width / κ")
        ax.set_title("(b) Relative uncertainty")
        ax.grid(axis="x", visible=False)
        if np.isfinite(U).any():
            ax.axhline(float(np.nanmedian(U)), color="0.3", lw=0.7, ls=":")
            ax.text(E - 0.5, float(np.nanmedian(U)), f" median {np.nanmedian(U):.2f}", ha="right", va="bottom",
                    fontsize=6.5, color="0.2")
    return fig


def _log_ticks(ax):
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullLocator
    lo, hi = ax.get_ylim()
    cands = [t * 10.0 ** k for k in range(-3, 3) for t in (1, 2, 5)]
    ticks = [t for t in cands if lo <= t <= hi]
    ax.yaxis.set_major_locator(FixedLocator(ticks))
    ax.yaxis.set_minor_locator(NullLocator())
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))


def fig_excitation(result, fps: float | None = None):
    """The shared excitation z_t against frame (and seconds when ``fps`` is given)."""
    resp, fit = result.response, result.fit
    with _style() as plt:
        fig, ax = plt.subplots(figsize=(FIG_WIDTH_IN, 2.0))
        fixed_margins(fig, left=0.5, top=0.62 if fps else 0.28, bottom=0.4)
        ax.plot(resp.frames, fit.z, color=EXCITATION_COLOR, lw=0.8)
        ax.axhline(0, color="0.5", lw=0.5)
        ax.set_xlabel("frame")
        ax.set_ylabel("excitation z (deg)")
        rms = float(np.sqrt(np.mean(fit.z ** 2))) if fit.z.size else float("nan")
        kind = "signed" if result.preset.compliance.response == "signed" else "|Δβ|-based, ≥ 0"
        # above the seconds axis when there is one (titles are not moved automatically, style.RC)
        ax.set_title(f"Shared excitation z_t ({kind}); RMS {rms:.2f} deg", pad=26 if fps else None)
        ax.set_xlim(resp.frames.min(), resp.frames.max())
        if fps:
            sec = ax.secondary_xaxis("top", functions=(lambda f: f / fps, lambda s: s * fps))
            sec.set_xlabel("time (s)")
    return fig


def fig_residual_heatmap(R: np.ndarray, frames: np.ndarray, labels: list[str], title: str):
    """Heatmap of residuals R (E, T) in degrees, diverging colours centred at 0 with limits at the 99th
    percentile of |R| (so one outlier does not wash the map out), plus per-frame and per-edge RMS."""
    from matplotlib.colors import Normalize
    from matplotlib.ticker import NullLocator
    E, T = R.shape
    lim = robust_abs_max(R)
    with np.errstate(invalid="ignore"):
        import warnings
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            rms_t = np.sqrt(np.nanmean(R ** 2, axis=0))
            rms_e = np.sqrt(np.nanmean(R ** 2, axis=1))
    with _style() as plt:
        H = 1.2 + 0.16 * E + 0.9
        fig = plt.figure(figsize=(FIG_WIDTH_IN, H))
        # fixed margins (see fixed_margins): y tick labels "parent→child" up to ~9 characters of 6-7 pt
        gs = fig.add_gridspec(2, 3, width_ratios=[12, 1.6, 0.25], height_ratios=[1, max(2.0, 0.16 * E)],
                              left=0.7 / FIG_WIDTH_IN, right=1 - 0.62 / FIG_WIDTH_IN, top=1 - 0.25 / H,
                              bottom=0.42 / H, wspace=0.1, hspace=0.07)
        ax = fig.add_subplot(gs[1, 0])
        axt = fig.add_subplot(gs[0, 0], sharex=ax)
        axe = fig.add_subplot(gs[1, 1])  # the heatmap's rows; not shared, so no second set of row ticks
        cax = fig.add_subplot(gs[1, 2])
        f0, f1 = (frames[0], frames[-1]) if T else (0, 1)
        step = (f1 - f0) / max(T - 1, 1)
        cmap = plt.get_cmap(RESIDUAL_CMAP).with_extremes(bad="0.85")
        im = ax.imshow(np.ma.masked_invalid(R), aspect="auto", cmap=cmap, norm=Normalize(-lim, lim),
                       interpolation="nearest", extent=(f0 - step / 2, f1 + step / 2, E - 0.5, -0.5))
        ax.set_yticks(np.arange(E), labels, fontsize=6 if E > 15 else 7)
        ax.set_xlabel("frame")
        ax.set_ylabel("segment (root → tip)")
        ax.grid(False)
        axt.plot(frames, rms_t, color="0.25", lw=0.6)
        axt.set_ylabel("RMS\n(deg)")
        axt.set_title(title)
        axt.tick_params(labelbottom=False)
        axt.set_ylim(bottom=0)
        axe.barh(np.arange(E), np.nan_to_num(rms_e), color="0.45", height=0.75)
        axe.set_ylim(E - 0.5, -0.5)
        axe.yaxis.set_major_locator(NullLocator())
        axe.set_xlabel("RMS (deg)")
        axe.grid(axis="y", visible=False)
        cb = fig.colorbar(im, cax=cax, extend="both")
        cb.set_label("residual (deg)")
    return fig


def fig_residuals(result):
    """Residual heatmap of the rank-1 fit of ``result``."""
    resp = result.response
    R = resp.Y - result.fit.predict()
    return fig_residual_heatmap(R, resp.frames, [f"{j}→{c}" for j, c in resp.edges],
                                "Residuals of the rank-1 model: observed − κ·z (grey: missing or outlier)")


def fig_bending_fit(result, n: int = 3):
    """Observed bending (with +-2 sigma band) against the rank-1 prediction for the worst-fitted edges."""
    from .scene import worst_edges
    from .scene import AnalysisView
    view = AnalysisView.from_result(result)
    worst = worst_edges(view, n)
    with _style() as plt:
        fig, axes = plt.subplots(len(worst), 1, figsize=(FIG_WIDTH_IN, 1.5 * len(worst) + 0.4), sharex=True,
                                 squeeze=False)
        fixed_margins(fig, left=0.55, top=0.45, bottom=0.4, hspace=0.32, nrows=len(worst))
        for ax, e in zip(axes[:, 0], worst):
            i = view.edges.index(e)
            y, p = view.Y[i], view.pred[i]
            if view.variance is not None:
                s2 = 2 * np.sqrt(view.variance[i])
                ax.fill_between(view.frames, y - s2, y + s2, color=SMOOTHED_COLOR, alpha=0.25, lw=0,
                                label="observed ± 2σ")
            ax.plot(view.frames, y, color=SMOOTHED_COLOR, lw=0.7, label="observed")
            ax.plot(view.frames, p, color="0.1", lw=0.8, label="predicted κ·z")
            r = (y - p)[np.isfinite(y - p)]
            ax.set_title(f"segment {e[0]}→{e[1]} ({view.zone[i]}): κ = {view.kappa[i]:.2f}, "
                         f"residual RMS {np.sqrt(np.mean(r ** 2)):.2f} deg", fontsize=8)
            ax.set_ylabel("bending (deg)")
        h, lab = axes[0, 0].get_legend_handles_labels()
        fig.legend(h, lab, loc="upper right", ncol=3, borderaxespad=0.6)
        axes[-1, 0].set_xlabel("frame")
        axes[-1, 0].set_xlim(view.frames.min(), view.frames.max())
    return fig


#: The analysis figure files :func:`write_figures` writes, and those that need kappa's confidence
#: intervals (the others can be drawn before the bootstrap).
FIGURE_FILES = ("smoothing.png", "motion.png", "compliance.png", "excitation.png", "residuals.png",
                "bending_fit.png")
CI_FIGURES = ("compliance.png",)


def write_figures(result, out_dir: str | Path, diagnosis=None, fps: float | None = None,
                  names=None) -> dict[str, Path]:
    """Write the analysis figures (and the diagnosis figures when ``diagnosis`` is given) into ``out_dir``.

    ``names``: only these analysis figure files (default: all). Usable as an ``extra_writer`` of
    :meth:`AnalysisResult.write`. Returns {file name: path}."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    makers = {"smoothing.png": lambda: fig_smoothing(result), "motion.png": lambda: fig_motion(result, seed=result.preset.compliance.seed),
              "compliance.png": lambda: fig_compliance(result),
              "excitation.png": lambda: fig_excitation(result, fps=fps),
              "residuals.png": lambda: fig_residuals(result), "bending_fit.png": lambda: fig_bending_fit(result)}
    written = {name: _save(make(), out / name) for name, make in makers.items() if names is None or name in names}
    if diagnosis is not None:
        written.update(write_diagnosis_figures(diagnosis, out, result=result))
    return written


# ------------------------------------------------------------------------------------------ diagnosis
def _get(obj, name, default=None):
    if isinstance(obj, dict):
        return obj.get(name, default)
    return getattr(obj, name, default)


def fig_heldout(diagnosis):
    """Held-out RMSE of the baseline and of the model extended by each candidate effect (best first), as
    horizontal bars (one row per model, so the names never run into each other however many candidates there
    are), with the relative change; the verdict is highlighted."""
    base = _get(diagnosis, "baseline", {}) or {}
    b = _get(base, "heldout_rmse")
    cands = list(_get(diagnosis, "candidates", []) or [])
    verdict = _get(diagnosis, "verdict")
    import matplotlib.patheffects as pe
    names = ["rank-1 baseline"] + [f"+ {str(_get(c, 'effect')).replace('_', ' ')}" for c in cands]
    vals = np.array([b] + [_get(c, "heldout_rmse") for c in cands], dtype=float)
    colors = ["0.55"] + ["#d95f02" if _get(c, "effect") == verdict else "#7fa7c9" for c in cands]
    with _style() as plt:
        fig, ax = plt.subplots(figsize=(FIG_WIDTH_IN * 0.62, 0.9 + 0.27 * len(vals)), constrained_layout=True)
        y = np.arange(len(vals))
        ax.barh(y, np.nan_to_num(vals), color=colors, height=0.7)
        lo = np.nanmin(vals) if np.isfinite(vals).any() else 0
        hi = np.nanmax(vals) if np.isfinite(vals).any() else 1
        for yi, v in zip(y[1:], vals[1:]):
            if np.isfinite(v) and b:
                # right of the bar, and never on the dashed baseline: a column of labels right of both
                ax.text(max(v, b), yi, f"  {100 * (v / b - 1):+.0f} %", ha="left", va="center", fontsize=6.5,
                        zorder=4, path_effects=[pe.withStroke(linewidth=2.2, foreground="white")])
        if np.isfinite(b):
            ax.axvline(b, color="0.3", lw=0.7, ls="--")
        ax.set_yticks(y, names, fontsize=7)
        ax.invert_yaxis()  # the baseline on top, then the candidates best first
        ax.set_xlabel("held-out RMSE (deg)")
        ax.grid(axis="y", visible=False)
        ax.set_xlim(max(0.0, lo * 0.8), hi * 1.15)
        # over the whole figure (the names on the left take width from the axes)
        fig.suptitle(f"Held-out error per candidate effect — verdict: {verdict or 'none'}",
                     fontsize=ax.title.get_fontsize(), fontweight=ax.title.get_fontweight())
    return fig


def fig_before_after(Y, pred_before, pred_after, frames, labels, effect: str, n: int = 3):
    """Observed vs rank-1 vs extended-model prediction on the edges the effect improves most."""
    gain = np.nanmean((Y - pred_before) ** 2, axis=1) - np.nanmean((Y - pred_after) ** 2, axis=1)
    order = np.argsort(-np.nan_to_num(gain, nan=-np.inf))[:n]
    with _style() as plt:
        fig, axes = plt.subplots(len(order), 1, figsize=(FIG_WIDTH_IN, 1.5 * len(order) + 0.4), sharex=True,
                                 constrained_layout=True, squeeze=False)
        for ax, i in zip(axes[:, 0], order):
            ax.plot(frames, Y[i], color=SMOOTHED_COLOR, lw=0.7, label="observed")
            ax.plot(frames, pred_before[i], color="0.35", lw=0.8, ls="--", label="rank-1 κ·z")
            ax.plot(frames, pred_after[i], color="#d95f02", lw=0.9, label=f"with {effect}")
            rb = np.sqrt(np.nanmean((Y[i] - pred_before[i]) ** 2))
            ra = np.sqrt(np.nanmean((Y[i] - pred_after[i]) ** 2))
            ax.set_title(f"segment {labels[i]}: residual RMS {rb:.2f} → {ra:.2f} deg", fontsize=8)
            ax.set_ylabel("bending (deg)")
        h, lab = axes[0, 0].get_legend_handles_labels()
        fig.legend(h, lab, loc="outside upper right", ncol=3)
        axes[-1, 0].set_xlabel("frame")
    return fig


def fig_kappa_to_report(result):
    """The κ to report after a verdict (``result.kappa_choice``: the model with the named effect, its 95 % CI, zone
    colours) beside the rank-1 κ and its CI (grey, open), per segment root -> tip, log scale: what
    ``compliance_summary.csv``'s ``kappa_<effect>`` and ``kappa`` columns hold."""
    from matplotlib.lines import Line2D

    choice, resp = result.kappa_choice, result.response
    E = len(resp.edges)
    k_ext, lo_ext, hi_ext = choice.aligned(resp.edges)
    lo1 = result.ci.low if result.ci is not None else np.full(E, np.nan)
    hi1 = result.ci.high if result.ci is not None else np.full(E, np.nan)
    zones = np.array([result.geometry.zone[c] for _, c in resp.edges])
    labels = [f"{j}→{c}" for j, c in resp.edges]
    x = np.arange(E, dtype=float)
    with _style() as plt:
        fig, ax = plt.subplots(figsize=(FIG_WIDTH_IN, 2.9))
        fixed_margins(fig, left=0.55, top=0.3, bottom=0.4 + 0.055 * max(len(s) for s in labels))
        ax.axhline(1.0, color="0.4", ls="--", lw=0.8, zorder=1)
        k1 = np.asarray(result.fit.kappa, float)
        ok = np.isfinite(k1)
        yerr = np.vstack([np.maximum(k1 - lo1, 0.0), np.maximum(hi1 - k1, 0.0)])
        yerr = np.where(np.isfinite(yerr), yerr, 0.0)
        ax.errorbar(x[ok] - 0.17, k1[ok], yerr=yerr[:, ok], fmt="o", mfc="white", color="0.55", ms=3.2,
                    elinewidth=0.8, capsize=1.2, zorder=2)
        _errorbars(ax, x + 0.17, k_ext, lo_ext, hi_ext, zones)
        ax.set_yscale("log")
        # as fig_compliance: every CI, at most a factor 10 beyond the kappa values, head-room for the legend
        kv = np.r_[k1, k_ext]
        kv = kv[np.isfinite(kv) & (kv > 0)]
        kmin, kmax = (kv.min(), kv.max()) if kv.size else (1.0, 1.0)
        his, los = np.r_[hi1, hi_ext], np.r_[lo1, lo_ext]
        top = min(np.nanmax(np.r_[his[np.isfinite(his)], kmax]) * 1.3, kmax * 10)
        bot = max(np.nanmin(np.r_[los[np.isfinite(los) & (los > 0)], kmin]) / 1.3, kmin / 10)
        ax.set_ylim(bot, top * 4.0)
        _log_ticks(ax)
        ax.set_xticks(x, labels, rotation=90, fontsize=6 if E > 15 else 7)
        ax.set_xlim(-0.7, E - 0.3)
        ax.set_xlabel("segment (parent→child), root → tip")
        ax.set_ylabel("relative compliance κ (log scale)")
        ax.set_title(f"κ to report: the model with {choice.effect} ({choice.column}), beside the rank-1 κ; 95 % CI")
        ax.grid(axis="x", visible=False)
        ax.legend(handles=[Line2D([], [], marker="o", ls="", color="#333333", ms=4, label=f"with {choice.effect}"),
                           Line2D([], [], marker="o", ls="", mfc="white", color="0.55", ms=4, label="rank-1")],
                  loc="upper left", ncol=2, handletextpad=0.2, columnspacing=0.8)
    return fig


def write_diagnosis_figures(diagnosis, out_dir: str | Path, result=None) -> dict[str, Path]:
    """Write ``heldout_error.png`` and, when the diagnosis carries them, ``residuals_diagnosis.png``
    (``residuals`` (E, T) degrees), ``effect_before_after.png`` (``after_prediction`` (E, T), with
    ``result`` for the observed data and the rank-1 prediction), ``variance_budget.png`` (``budget``),
    ``residual_analysis.png`` and, when ``result`` carries the named effect's κ (``kappa_choice``, as ``rce run``
    fits it), ``kappa_to_report.png`` (:func:`fig_kappa_to_report`)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = {"heldout_error.png": _save(fig_heldout(diagnosis), out / "heldout_error.png")}
    R = _get(diagnosis, "residuals")
    frames = _get(diagnosis, "frames")
    edges = _get(diagnosis, "edges")
    if R is not None:
        R = np.asarray(R, dtype=float)
        if frames is None:
            frames = result.response.frames if result is not None and result.response.Y.shape == R.shape \
                else np.arange(R.shape[1])
        if edges is None:
            edges = result.response.edges if result is not None and len(result.response.edges) == R.shape[0] \
                else [(i, i + 1) for i in range(R.shape[0])]
        labels = [f"{e[0]}→{e[1]}" if isinstance(e, (tuple, list)) else str(e) for e in edges]
        written["residuals_diagnosis.png"] = _save(
            fig_residual_heatmap(R, np.asarray(frames), labels, "Residuals of the diagnosed baseline model (deg)"),
            out / "residuals_diagnosis.png")
    after = _get(diagnosis, "after_prediction")
    if after is not None and result is not None and np.shape(after) == result.response.Y.shape:
        resp = result.response
        written["effect_before_after.png"] = _save(
            fig_before_after(resp.Y, result.fit.predict(), np.asarray(after, float), resp.frames,
                             [f"{j}→{c}" for j, c in resp.edges], _get(diagnosis, "verdict") or "effect"),
            out / "effect_before_after.png")
    budget = _get(diagnosis, "budget")
    if budget is not None:
        from .budget import fig_variance_budget
        written["variance_budget.png"] = _save(fig_variance_budget(budget, _get(diagnosis, "budget_per_segment")),
                                               out / "variance_budget.png")
    ra = _get(diagnosis, "residual_analysis_obj")
    if ra is not None:
        from .residual_analysis import fig_residual_analysis
        labels = ([f"{j}→{c}" for j, c in result.response.edges] if result is not None
                  else [str(i) for i in range(ra.xcorr.shape[0])])
        written["residual_analysis.png"] = _save(fig_residual_analysis(ra, labels, fps=30.0),
                                                 out / "residual_analysis.png")
    if result is not None and getattr(result, "kappa_choice", None) is not None and result.kappa_choice.fitted:
        written["kappa_to_report.png"] = _save(fig_kappa_to_report(result), out / "kappa_to_report.png")
    return written
