"""Figure of the variance budget (:mod:`rce_gtsam.diagnosis.budget`): ``variance_budget.png``.

One horizontal bar per segment (root at the top) and one for the whole branch, each the segment's bending
variance split into shares: explained by the rank-1 model, by each added effect, the model-free noise floor,
and what is left unexplained, with its +/- 2 SE. A hatched noise floor (segment marked ``*``) is only a lower
bound (the segment stretches by more than tracking noise could); the whole branch is starred when any segment
is. A negative rank-1 share (the fit predicts the segment worse than its rest angle does, R^2 < 0) is drawn
left of zero. Shares of each bar's own total variance (%), so a stiff root segment and a swinging tip read
alike; the total (deg^2) is printed at the right.
"""

from __future__ import annotations

from .style import FIG_WIDTH_IN, RC

RANK1_COLOR = "#4393c3"
NOISE_COLOR = "#bdbdbd"
UNEXPLAINED_COLOR = "#d6604d"
EFFECT_COLORS = ("#1b9e77", "#d95f02", "#7570b3", "#e7298a", "#66a61e")
#: the budget's status in the words of the verdict line: always about what the model leaves (the rank-1 model, or
#: the model with the named effect), never about the effect the verdict names
STATUS_WORDS = {"noise": "the rest is at the noise floor", "misses": "the rest is more than noise",
                "inconclusive": "the rest is inconclusive"}


def budget_rows(budget, per_segment=None) -> tuple[dict, list[dict]]:
    """(overall, per-segment rows) of a :class:`~rce_gtsam.diagnosis.budget.VarianceBudget` or of
    diagnosis.json's ``budget`` dict (then ``per_segment`` is its ``budget_per_segment``)."""
    if isinstance(budget, dict):
        return budget, list(per_segment or [])
    return budget.as_dict(), list(budget.per_segment)


def fig_variance_budget(budget, per_segment=None, title: str | None = None):
    """The variance-budget figure (see the module docstring)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    overall, rows = budget_rows(budget, per_segment)
    effects = list((overall.get("effects") or {}).keys())
    se_total = overall.get("unexplained_se") or 0.0
    bars = [{"segment": "whole branch", "total": overall["total"], "rank1": overall["rank1"],
             "effects": overall.get("effects") or {}, "noise_floor": overall["noise_floor"],
             "unexplained": overall["unexplained"], "unexplained_se": se_total}] + rows
    bounded = [bool(r.get("noise_floor_is_lower_bound")) for r in rows]
    labels = ["whole branch" + (" *" if any(bounded) else "")] + [
        str(r["segment"]) + (" *" if bd else "") for r, bd in zip(rows, bounded)]
    n = len(bars)
    with plt.rc_context(RC):
        fig, ax = plt.subplots(figsize=(FIG_WIDTH_IN, 1.0 + 0.2 * n), constrained_layout=True)
        for i, b in enumerate(bars):
            tot = b.get("total") or 0.0
            if tot <= 0:
                continue
            pc = lambda v: 100.0 * float(v or 0.0) / tot  # noqa: E731
            left = 0.0
            parts = [("rank1", pc(b["rank1"]), RANK1_COLOR, None)]
            parts += [(k, pc((b.get("effects") or {}).get(k)), EFFECT_COLORS[j % len(EFFECT_COLORS)], None)
                      for j, k in enumerate(effects)]
            parts.append(("noise_floor", pc(b["noise_floor"]), NOISE_COLOR,
                          "///" if b.get("noise_floor_is_lower_bound") else None))
            for _, w, color, hatch in parts:
                if w < 0:  # worse than no model at all (R^2 < 0): drawn left of zero
                    ax.barh(i, w, left=0.0, color=color, hatch=hatch, edgecolor="white", linewidth=0.3,
                            height=0.72, alpha=0.6)
                    continue
                ax.barh(i, w, left=left, color=color, hatch=hatch, edgecolor="white" if hatch is None else "0.45",
                        linewidth=0.3, height=0.72)
                left += w
            un = pc(b["unexplained"])
            if un > 0:
                ax.barh(i, un, left=left, color=UNEXPLAINED_COLOR, height=0.72, edgecolor="white", linewidth=0.3)
            se = pc(b.get("unexplained_se"))
            if se > 0:
                ax.errorbar(left + un, i, xerr=2 * se, fmt="none", ecolor="0.15", elinewidth=0.8, capsize=2)
            ax.text(1.0, i, f"{tot:.3g}", transform=ax.get_yaxis_transform(), ha="left", va="center", fontsize=6)
        ax.set_yticks(range(n), labels, fontsize=6)
        ax.get_yticklabels()[0].set_fontweight("bold")
        ax.invert_yaxis()
        ax.axhline(0.5, color="0.3", lw=0.6)
        ax.axvline(100.0, color="0.3", lw=0.6, ls="--")
        ax.set_xlabel("share of the segment's bending variance (%); right: total (deg²)")
        lo, hi = ax.get_xlim()
        ax.set_xlim(max(min(lo, 0.0), -100.0), max(130.0, min(250.0, hi)))
        ax.axvline(0.0, color="0.3", lw=0.6)
        from matplotlib.patches import Patch
        handles = [Patch(color=RANK1_COLOR, label="rank-1 κ·z")]
        handles += [Patch(color=EFFECT_COLORS[j % len(EFFECT_COLORS)], label=f"+ {k}")
                    for j, k in enumerate(effects)]
        handles += [Patch(color=NOISE_COLOR, label="noise floor"),
                    Patch(facecolor=NOISE_COLOR, hatch="///", edgecolor="0.45",
                          label="* noise floor only a lower bound"),
                    Patch(color=UNEXPLAINED_COLOR, label="unexplained (±2 SE)")]
        fig.legend(handles=handles, loc="outside lower center", fontsize=6, ncol=len(handles))
        status = STATUS_WORDS.get(overall.get("status"), overall.get("status"))
        if status and effects:  # scored after the verdict's effect: say so, lest it read against the verdict
            status = f"with {' + '.join(effects)}, {status}"
        reason = overall.get("reason")
        ax.set_title(title or ("Variance budget" + (f": {status}" if status else "")
                               + (f" ({str(reason).replace('_', ' ')})" if reason else "")))
    return fig
