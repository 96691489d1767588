"""Figure of the residual analysis (:mod:`rce_gtsam.diagnosis.sysid`): ``residual_analysis.png``.

Six panels: residual-excitation cross-correlation (segments x lags, in units of its 2-SE band), gain and phase
of the z -> bending frequency response for the root-, mid- and tip-most segments (coherent frequencies drawn
solid), singular values of the residuals' cross-spectral matrix against the model-free noise's, each segment's
residual trend with +/- 2 SE, and gain by excitation-amplitude quartile.
"""

from __future__ import annotations

import numpy as np


def fig_residual_analysis(ra, labels, fps: float | None = None):
    """The six-panel residual-analysis figure of a :class:`~rce_gtsam.diagnosis.sysid.ResidualAnalysis`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    E = ra.xcorr.shape[0]
    scale = fps if fps else 1.0
    unit = "Hz" if fps else "cycles/frame"
    fig, axs = plt.subplots(2, 3, figsize=(15, 8.5), constrained_layout=True)
    ax = axs[0, 0]
    v = ra.xcorr / ra.xcorr_band[:, None]
    lim = max(2.0, float(np.nanmax(np.abs(v))))
    im = ax.imshow(v, aspect="auto", cmap="RdBu_r", vmin=-lim, vmax=lim, interpolation="nearest",
                   extent=[ra.lags[0] - 0.5, ra.lags[-1] + 0.5, E - 0.5, -0.5])
    ax.set_yticks(range(E))
    ax.set_yticklabels(labels, fontsize=6)
    ax.set_xlabel("lag L (frames): corr(r_e(t), z(t - L))")
    ax.set_title("residual vs excitation cross-correlation\n(in units of the 2-SE band; |value| > 1 = significant)")
    fig.colorbar(im, ax=ax, shrink=0.8)
    picks = sorted({0, E // 2, E - 1})
    colors = ["tab:blue", "tab:green", "tab:red"]
    f = ra.freqs * scale
    for k, e in enumerate(picks):
        coh = ra.coherence[e] > ra.coherence_threshold
        for a, y in ((axs[0, 1], ra.gain[e]), (axs[0, 2], ra.phase_deg[e])):
            a.plot(f[1:], y[1:], color=colors[k], lw=0.6, alpha=0.35)
            a.plot(f[1:], np.where(coh, y, np.nan)[1:], color=colors[k], lw=1.6, label=f"{labels[e]}")
    coherent_any = (ra.coherence > ra.coherence_threshold).any(axis=0) & (ra.freqs > 0)
    fmax = 1.5 * float(f[coherent_any].max()) if coherent_any.any() else float(f[-1])
    fmax = min(max(fmax, float(f[min(len(f) - 1, 8)])), float(f[-1]))
    for a in (axs[0, 1], axs[0, 2]):
        a.set_xlim(0, fmax)
    axs[0, 1].axhline(1.0, color="k", lw=0.8, ls="--")
    axs[0, 1].set_yscale("log")
    axs[0, 1].set_xlabel(f"frequency ({unit})")
    axs[0, 1].set_ylabel("gain |H| / kappa (1 = rank-1 model)")
    axs[0, 1].set_title("z -> bending gain (solid: coherent)\nflat = quasi-static; rising = inertia")
    axs[0, 1].legend(fontsize=7)
    axs[0, 2].axhline(0.0, color="k", lw=0.8, ls="--")
    axs[0, 2].set_xlabel(f"frequency ({unit})")
    axs[0, 2].set_ylabel("phase (deg)")
    axs[0, 2].set_title("z -> bending phase\nlinear fall = delay; turn toward -90 = inertia")
    ax = axs[1, 0]
    ax.semilogy(f[1:], ra.sv_residual[1:, 0], color="tab:purple", label="residual s1")
    ax.semilogy(f[1:], np.maximum(ra.sv_residual[1:, 1], 1e-12), color="tab:purple", ls=":", label="residual s2")
    if ra.sv_noise is not None:
        ax.semilogy(f[1:], np.maximum(ra.sv_noise[1:, 0], 1e-12), color="0.4",
                    label="noise floor s1 (segments where it holds)")
    ax.set_xlabel(f"frequency ({unit})")
    ax.set_ylabel("singular value (deg^2 per frequency unit)")
    ax.set_title("cross-spectral singular values of the residuals\ns1 >> noise and >> s2 = a second excitation")
    ax.legend(fontsize=7)
    ax = axs[1, 1]
    se = np.where(ra.trend_t != 0, np.abs(ra.trend_deg / np.where(ra.trend_t == 0, 1, ra.trend_t)), 0.0)
    ax.errorbar(np.arange(E), ra.trend_deg, yerr=2 * se, fmt="o", ms=3, color="tab:orange", ecolor="0.5")
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_xticks(range(E))
    ax.set_xticklabels(labels, rotation=90, fontsize=6)
    ax.set_ylabel("residual trend over the record (deg)")
    ax.set_title("creep / drifting rest pose (+/- 2 SE)")
    ax = axs[1, 2]
    g = ra.gain_by_amplitude
    q = np.nanpercentile(g, [25, 50, 75], axis=0) if np.isfinite(g).any() else np.full((3, 4), np.nan)
    ax.fill_between(ra.amplitude_bins, q[0], q[2], color="tab:cyan", alpha=0.3, label="segments 25-75 %")
    ax.plot(ra.amplitude_bins, q[1], "o-", color="tab:cyan", label="median segment")
    ax.axhline(1.0, color="k", lw=0.8, ls="--")
    ax.set_xlabel("|z| quartile median (deg)")
    ax.set_ylabel("gain y / (kappa z)")
    ax.set_title("gain vs excitation amplitude\nfalling = saturation (nonlinearity)")
    ax.legend(fontsize=7)
    return fig
