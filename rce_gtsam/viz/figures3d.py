"""``swing_vs_bending.png``: what depth shows that the image cannot.

(a) Each segment's RMS out-of-plane swing (deg, psi) against its RMS in-plane bending (deg, theta), labelled
``joint->child``, with the 1:1 line and the noise floor of the swing (the median propagated 1-sigma of psi, grey
band): points above the band are swing the camera's depth measured, points inside it are not told from noise.
(b) kappa from the 3-D angles with its bootstrap 95 % CI beside the 2-D (image-plane) kappa, per segment root
to tip (log scale).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .style import FIG_WIDTH_IN, fixed_margins
from .style import mpl_style as _style
from .style import save_png as _save


def fig_swing_vs_bending(d3):
    """The figure (a :class:`matplotlib.figure.Figure`) of a :class:`~rce_gtsam.depth_pipeline.Depth3DResult`."""
    k = d3.kappa
    labels = [f"{j}→{c}" for j, c in k.edges]
    var = d3.bending.out_of_plane.variance_deg2
    floor = float(np.sqrt(np.nanmedian(var))) if var is not None and np.isfinite(var).any() else np.nan
    with _style() as plt:
        fig, axes = plt.subplots(1, 2, figsize=(FIG_WIDTH_IN, 3.0))
        fixed_margins(fig, left=0.55, top=0.3, bottom=0.75, wspace=0.7, ncols=2)
        ax = axes[0]
        top = float(np.nanmax(np.r_[k.bend_rms_deg, k.swing_rms_deg, 1e-3])) * 1.15
        ytop = max(top, floor * 1.3) if np.isfinite(floor) else top
        if np.isfinite(floor):
            ax.axhspan(0, floor, color="0.88", zorder=0, label=f"within 1 σ of swing noise ({floor:.2f}°/frame)")
        ax.plot([0, ytop], [0, ytop], color="0.4", ls="--", lw=0.8, label="swing = bending")
        ax.scatter(k.bend_rms_deg, k.swing_rms_deg, s=14, color="tab:purple", zorder=3)
        for x, y, s in zip(k.bend_rms_deg, k.swing_rms_deg, labels):
            ax.annotate(s, (x, y), xytext=(3, 2), textcoords="offset points", fontsize=6)
        ax.set_xlim(0, top)
        ax.set_ylim(0, ytop)
        ax.set_xlabel("in-plane bending RMS θ (deg)")
        ax.set_ylabel("out-of-plane swing RMS ψ (deg)")
        ax.set_title(f"(a) Swing vs bending (plane tilt {k.tilt_deg:.0f}°)")
        ax.legend(loc="upper left", fontsize=6)
        ax = axes[1]
        x = np.arange(len(labels))
        lo = k.kappa - (k.ci_low if k.ci_low is not None else k.kappa)
        hi = (k.ci_high if k.ci_high is not None else k.kappa) - k.kappa
        ax.errorbar(x - 0.12, k.kappa, yerr=[lo, hi], fmt="o", ms=3, color="tab:purple", label="κ from 3-D, 95 % CI")
        ax.plot(x + 0.12, d3.kappa_2d, "s", ms=3, color="tab:orange", label="κ from 2-D image")
        ax.axhline(1.0, color="0.4", ls="--", lw=0.8)
        ax.set_yscale("log")
        from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter
        ax.yaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
        ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _pos: f"{v:g}"))
        ax.yaxis.set_minor_formatter(NullFormatter())
        ax.set_xticks(x)
        ax.set_xticklabels(labels, rotation=60, fontsize=6)
        ax.set_xlabel("segment, root → tip")
        ax.set_ylabel("relative compliance κ")
        ax.set_title("(b) κ from depth and from the image")
        ax.legend(loc="upper left", fontsize=6)
    return fig


def swing_vs_bending_figure(d3, path: str | Path) -> Path:
    """Write :func:`fig_swing_vs_bending` to ``path`` (PNG) and return it."""
    return _save(fig_swing_vs_bending(d3), Path(path))
