"""Figures that compare the recordings of a batch (PNG, the look of :mod:`rce_gtsam.viz.style`).

* ``kappa_by_zone.png`` — one panel per zone (proximal, mid, distal): every segment's kappa to report with its
  95 % CI (the rank-1 kappa, or after a verdict that of the model with the named effect: its recording's label
  ends in ``*``), one column per recording (log scale; kappa = 1, each branch's geometric mean, dashed);
* ``verdicts.png`` — (a) how many recordings got each diagnosis verdict (``none (adequate)``: no effect
  beats the rank-1 model and the rest is at the noise floor; ``none (misses)``: more than noise is left;
  ``none (inconclusive)``; ``failed``: the recording did not run); (b) per recording, the held-out RMSE
  (deg) of the rank-1 baseline and of the model with the verdict's effect;
* ``uncertainty.png`` — U_e = CI width / kappa of every segment's kappa to report per recording, coloured by zone,
  with each recording's median.

Recordings are labelled by id, followed by the first metadata column's value when the manifest has one.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..viz.style import FIG_WIDTH_IN, RC, ZONE_COLORS
from .summary import RecordingSummary

ZONES = ("proximal", "mid", "distal")
VERDICT_COLORS = {"none (adequate)": "#9e9e9e", "none (inconclusive)": "#cfcfcf", "none (misses)": "#5f5f5f",
                  "none": "#9e9e9e", "failed": "#000000", "delay": "#1b9e77", "dynamics": "#d95f02",
                  "second_mode": "#7570b3", "offset": "#e7298a", "nonlinear": "#66a61e"}


def _label(r: RecordingSummary) -> str:
    first = next(iter(r.metadata.values()), "")
    star = " *" if _extended(r) else ""  # the kappa shown is that of the model with the named effect
    return f"{r.id}{star}\n{first}" if first else f"{r.id}{star}"


def _extended(r: RecordingSummary) -> bool:
    """Whether the recording's kappa to report is that of a model with a named effect (not the rank-1 kappa)."""
    return "report" in r.segments and not r.segments.empty and str(r.segments["report"].iloc[0]) != "kappa"


def _to_report(r: RecordingSummary) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(kappa, CI low, CI high) to report of every segment of ``r``: the ``kappa_to_report`` columns where the summary
    has them (:func:`rce_gtsam.batch.summary.with_kappa_to_report`), else the rank-1 columns."""
    s = r.segments
    cols = ("kappa_to_report", "kappa_to_report_ci_low", "kappa_to_report_ci_high") \
        if "kappa_to_report" in s else ("kappa", "kappa_ci_low", "kappa_ci_high")
    return tuple(s[c].to_numpy(float) for c in cols)


def _verdict(r: RecordingSummary) -> str:
    if r.status == "failed":
        return "failed"
    v = r.verdict or "none"
    return f"none ({r.diagnosis_status})" if v == "none" and r.diagnosis_status not in (None, "untested") else v


def _names_no_effect(verdict: str) -> bool:
    """A bar of :func:`_verdict` that names no effect ("none (...)", "failed"): no '+ effect' legend entry."""
    return verdict.startswith("none") or verdict == "failed"


def fig_kappa_by_zone(recordings: list[RecordingSummary]):
    """kappa with 95 % CI per segment, one panel per zone, one column per recording."""
    import matplotlib.pyplot as plt
    n = len(recordings)
    with plt.rc_context(RC):
        fig, axes = plt.subplots(1, 3, figsize=(FIG_WIDTH_IN, 2.4 + 0.1 * max(0, n - 8)), sharey=True,
                                 constrained_layout=True)
        vals = np.concatenate([_to_report(r)[0] for r in recordings if not r.segments.empty]
                              or [np.array([1.0])])
        vals = vals[np.isfinite(vals) & (vals > 0)]
        for ax, zone in zip(axes, ZONES):
            ax.axhline(1.0, color="0.4", ls="--", lw=0.8, zorder=1)
            for i, r in enumerate(recordings):
                if r.segments.empty:
                    ax.text(i, 1.0, "failed", rotation=90, ha="center", va="center", fontsize=6, color="0.3")
                    continue
                here = (r.segments["zone"] == zone).to_numpy()
                k, lo, hi = (a[here] for a in _to_report(r))
                x = i + (np.linspace(-0.25, 0.25, len(k)) if len(k) > 1 else np.zeros(len(k)))
                yerr = np.vstack([np.clip(k - lo, 0, None), np.clip(hi - k, 0, None)])
                ok = np.isfinite(k) & (k > 0)
                yerr = np.where(np.isfinite(yerr), yerr, 0.0)
                ax.errorbar(x[ok], k[ok], yerr=yerr[:, ok], fmt="o", ms=3, color=ZONE_COLORS[zone],
                            elinewidth=0.8, capsize=1.2, zorder=3)
            ax.set_yscale("log")
            ax.set_xticks(range(n), [_label(r) for r in recordings], rotation=90, fontsize=6 if n > 10 else 7)
            ax.set_xlim(-0.7, n - 0.3)
            ax.grid(axis="x", visible=False)
            ax.set_title(f"{zone}", color=ZONE_COLORS[zone])
        if vals.size:
            axes[0].set_ylim(max(vals.min() / 3, 1e-3), min(vals.max() * 3, 1e3))
        from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter
        axes[0].yaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
        axes[0].yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
        axes[0].yaxis.set_minor_formatter(NullFormatter())
        axes[0].set_ylabel("κ (log scale), 95 % CI")
        star = ("; *: after a verdict, κ of the model with the named effect" if any(_extended(r) for r in recordings)
                else "")
        fig.suptitle(f"κ to report by zone across recordings{star}", fontsize=9, fontweight="bold", x=0.01,
                     ha="left")
    return fig


def fig_verdicts(recordings: list[RecordingSummary]):
    """(a) verdict counts, (b) held-out RMSE of the baseline vs the verdict's model per recording."""
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch
    verdicts = [_verdict(r) for r in recordings]
    kinds = list(dict.fromkeys(v for v in [*VERDICT_COLORS, *verdicts] if v in verdicts))
    n = len(recordings)
    with plt.rc_context(RC):
        fig, axes = plt.subplots(1, 2, figsize=(FIG_WIDTH_IN, 2.6), constrained_layout=True,
                                 gridspec_kw={"width_ratios": [1, 2.4]})
        ax = axes[0]
        counts = [verdicts.count(k) for k in kinds]
        ax.bar(range(len(kinds)), counts, color=[VERDICT_COLORS.get(k, "#444444") for k in kinds])
        ax.set_xticks(range(len(kinds)), kinds, rotation=30, ha="right")
        ax.set_ylabel("recordings")
        ax.yaxis.get_major_locator().set_params(integer=True)
        ax.grid(axis="x", visible=False)
        ax.set_title("(a) Diagnosis verdicts")
        ax = axes[1]
        x = np.arange(n)
        base = np.array([_heldout(r, "baseline") for r in recordings])
        after = np.array([_heldout(r, "verdict") for r in recordings])
        ax.bar(x - 0.2, np.nan_to_num(base), width=0.4, color="#bdbdbd", label="rank-1 baseline")
        ax.bar(x + 0.2, np.nan_to_num(after), width=0.4,
               color=[VERDICT_COLORS.get(v, "#444444") for v in verdicts], label="with the verdict's effect")
        for i, v in enumerate(verdicts):
            if _names_no_effect(v):
                ax.text(i + 0.2, (base[i] if np.isfinite(base[i]) else 0) * 0.02, v, rotation=90, ha="center",
                        va="bottom", fontsize=6, color="0.25")
        ax.set_xticks(x, [_label(r) for r in recordings], rotation=90, fontsize=6 if n > 10 else 7)
        ax.set_xlim(-0.7, n - 0.3)
        ax.set_ylabel("held-out RMSE (deg)")
        top = np.nanmax(np.r_[base, after, 0.0])
        if top > 0:
            ax.set_ylim(0, top * 1.45)  # head-room for the legend
        ax.grid(axis="x", visible=False)
        ax.set_title("(b) Held-out error: baseline vs verdict")
        ax.legend(handles=[Patch(color="#bdbdbd", label="rank-1 baseline")]
                  + [Patch(color=VERDICT_COLORS.get(k, "#444444"), label=f"+ {k}") for k in kinds
                     if not _names_no_effect(k)], loc="upper right", fontsize=6)
    return fig


def _heldout(r: RecordingSummary, which: str) -> float:
    if r.diagnosis is None:
        return np.nan
    d = r.diagnosis
    if which == "baseline":
        v = (d.get("baseline") or {}).get("heldout_rmse")
    else:
        v = next((c.get("heldout_rmse") for c in d.get("candidates", []) if c.get("effect") == d.get("verdict")),
                 None)
    return float(v) if v is not None else np.nan


def fig_uncertainty(recordings: list[RecordingSummary]):
    """U_e of every segment per recording (zone colours) and the recording's median."""
    import matplotlib.pyplot as plt
    n = len(recordings)
    with plt.rc_context(RC):
        fig, ax = plt.subplots(figsize=(FIG_WIDTH_IN, 2.6), constrained_layout=True)
        allu = []
        for i, r in enumerate(recordings):
            if r.segments.empty:
                ax.text(i, 0.0, "failed", rotation=90, ha="center", va="bottom", fontsize=6, color="0.3")
                continue
            k, lo, hi = _to_report(r)
            u = np.where(k > 1e-9, (hi - lo) / np.where(k > 1e-9, k, 1.0), np.nan)
            z = r.segments["zone"].astype(str).to_numpy()
            x = i + np.linspace(-0.25, 0.25, len(u)) if len(u) > 1 else np.full(len(u), float(i))
            ok = np.isfinite(u)
            ax.scatter(x[ok], u[ok], s=9, c=[ZONE_COLORS.get(zz, "#777777") for zz in z[ok]], zorder=3)
            if ok.any():
                med = float(np.median(u[ok]))
                ax.plot([i - 0.35, i + 0.35], [med, med], color="0.2", lw=1.2, zorder=4)
                allu.append(u[ok])
        title = "Relative uncertainty of κ per recording (bar: median)"
        if allu:
            u = np.concatenate(allu)
            cap = 4 * float(np.median(u)) + 1e-9  # one unstable segment must not flatten the rest
            ax.set_ylim(0, min(float(u.max()) * 1.1, cap))
            if u.max() > cap:
                title += f"; {int((u > cap).sum())} segment(s) above {cap:.2g} not shown"
        ax.set_xticks(range(n), [_label(r) for r in recordings], rotation=90, fontsize=6 if n > 10 else 7)
        ax.set_xlim(-0.7, n - 0.3)
        ax.grid(axis="x", visible=False)
        ax.set_ylabel("U_e = CI width / κ")
        ax.set_title(title)
        from matplotlib.lines import Line2D
        ax.legend(handles=[Line2D([], [], marker="o", ls="", color=ZONE_COLORS[z], label=z, markersize=4)
                           for z in ZONES], loc="upper right", ncol=3)
    return fig


#: The comparison figures: (file name, function drawing it from the recordings).
FIGURES = (("kappa_by_zone.png", fig_kappa_by_zone), ("verdicts.png", fig_verdicts),
           ("uncertainty.png", fig_uncertainty))
FIGURE_NAMES = tuple(name for name, _ in FIGURES)


def prepare_matplotlib() -> None:
    """Import matplotlib (Agg) and pyplot and draw one throw-away figure with text into memory (fonts,
    caches), so :func:`write_batch_figures` starts drawing at once (~1 s on a 2-core machine)."""
    import io

    import matplotlib
    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    with plt.rc_context(RC):
        fig, ax = plt.subplots(figsize=(1, 1), constrained_layout=True)
        ax.set_title("κ")
        fig.savefig(io.BytesIO(), format="png", dpi=20)
        plt.close(fig)


def write_batch_figures(recordings: list[RecordingSummary], out_dir: str | Path) -> dict[str, Path]:
    """Write the three comparison figures into ``out_dir``; returns {file name: path}."""
    import matplotlib
    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = {}
    for name, make in FIGURES:
        fig = make(recordings)
        fig.savefig(out / name, dpi=RC["savefig.dpi"], bbox_inches="tight", pad_inches=RC["savefig.pad_inches"])
        plt.close(fig)
        written[name] = out / name
    return written
