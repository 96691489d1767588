"""Residual analysis as system identification does it: what kind of structure does the rank-1 model miss?

The rank-1 model says each segment's bending is a pure, instantaneous gain on one shared excitation:
y_e(t) = kappa_e z(t). Five views test that, each with a null band from the data's own noise:

* **Residual-excitation cross-correlation** (MATLAB ``resid``): corr(r_e(t), z(t - L)) over lags L, with the
  band +/- 2 SE from Bartlett's formula for two independent autocorrelated series
  (var = (1/n) sum_k rho_r(k) rho_z(k)). A peak at L != 0 means the segment responds to z late (delay) or
  with memory (inertia); at L = 0 a gain error.
* **Frequency response** z -> y_e: gain |H_e(f)| and phase with coherence (Welch cross-spectra). Quasi-static:
  flat gain, zero phase. A **delay** tau: flat gain, phase falling linearly (-2 pi f tau). **Inertia** (a
  second-order segment below resonance): the same phase lag at the lowest frequencies, but a gain that
  *rises* with frequency toward resonance (|H| ~ 1 + (1 - 2 zeta^2) (f / f_n)^2) and a phase lag growing faster
  than linearly. The two are told apart by the gain's curvature with frequency (its t statistic from the
  coherence-based variance of Welch estimates, Bendat & Piersol), not by a threshold tuned to a simulator.
  Frequencies count only where coherence is significant: above 1 - (alpha / n_f)^(1 / (K - 1)) for K
  averaged segments and n_f frequencies (the null distribution of Welch coherence of independent series,
  Bonferroni over frequencies).
* **Cross-spectral singular values** of the residuals across segments (operational modal analysis'
  frequency-domain decomposition): one dominant singular value over a band where the noise's own (from the
  model-free noise series, :mod:`.noise_floor`) is lower means a second excitation with its own shape.
* **Trend** of each segment's residual over the record (creep, a drifting rest pose), with an
  autocorrelation-inflated standard error.
* **Gain against amplitude**: each segment's gain y / (kappa z) in quartiles of |z|; a gain falling with
  amplitude means the response saturates (nonlinearity).

Units: degrees, frames, cycles/frame (x fps for Hz).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import signal

from ..model.series import autocorrelation


@dataclass(frozen=True, eq=False)
class ResidualAnalysis:
    """Residual analysis of a rank-1 fit (see module docstring). Arrays are per segment (rows) first.

    lags: (L,) frames; xcorr: (E, L) corr(r_e(t), z(t - lag)); xcorr_band: (E,) 2-SE half-width.
    freqs: (K,) cycles/frame; gain: (E, K) |H_e| / kappa_e (1 = the rank-1 model); phase_deg: (E, K);
    coherence: (E, K); coherence_threshold: significance level of coherence (alpha 0.05).
    delay_frames: (E,) -slope of phase vs 2 pi f over coherent frequencies; delay_se: (E,);
    gain_curvature: (E,) slope of log gain against f^2 (per (cycles/frame)^2); gain_curvature_t: (E,).
    sv_residual: (K, 2) the two largest singular values of the residuals' cross-spectral matrix;
    sv_noise: (K, 2) the same of the model-free noise series (None without a noise floor).
    trend_deg: (E,) residual change over the record (deg); trend_t: (E,).
    amplitude_bins: (4,) median |z| of each quartile (deg); gain_by_amplitude: (E, 4) y / (kappa z) per quartile.
    summary: branch-level numbers (slope of the delay with root distance and its SE; Stouffer-pooled gain
    curvature t — descriptive: the Welch gain is biased where the input is noisy, so it is not calibrated;
    max |trend t|; log-log slope of gain against amplitude and its SE; peak s1 / noise s1).
    """

    lags: np.ndarray
    xcorr: np.ndarray
    xcorr_band: np.ndarray
    freqs: np.ndarray
    gain: np.ndarray
    phase_deg: np.ndarray
    coherence: np.ndarray
    coherence_threshold: float
    delay_frames: np.ndarray
    delay_se: np.ndarray
    gain_curvature: np.ndarray
    gain_curvature_t: np.ndarray
    sv_residual: np.ndarray
    sv_noise: np.ndarray | None
    trend_deg: np.ndarray
    trend_t: np.ndarray
    amplitude_bins: np.ndarray
    gain_by_amplitude: np.ndarray
    summary: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        return {"summary": self.summary, "delay_frames": self.delay_frames.tolist(),
                "delay_se": self.delay_se.tolist(), "gain_curvature_t": self.gain_curvature_t.tolist(),
                "trend_deg": self.trend_deg.tolist(), "trend_t": self.trend_t.tolist(),
                "coherence_threshold": self.coherence_threshold}


def cross_correlation(R: np.ndarray, z: np.ndarray, max_lag: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(lags, (E, L) corr(r_e(t), z(t - lag)), (E,) 2-SE band from Bartlett's formula)."""
    E, T = R.shape
    lags = np.arange(-max_lag, max_lag + 1)
    out = np.zeros((E, len(lags)))
    band = np.zeros(E)
    zc = z - z.mean()
    rho_z = autocorrelation(zc, min(T - 1, 4 * max_lag))
    for e in range(E):
        r = np.where(np.isfinite(R[e]), R[e], 0.0)
        r = r - r.mean()
        den = math.sqrt(float(np.sum(r * r) * np.sum(zc * zc))) or 1.0
        full = np.correlate(r, zc, mode="full") / den  # index T - 1 is lag 0; lag L pairs r(t) with z(t - L)
        out[e] = full[T - 1 + lags]
        rho_r = autocorrelation(r, len(rho_z) - 1)
        var = (1.0 + 2.0 * float(np.sum(rho_r[1:] * rho_z[1:]))) / T
        band[e] = 2.0 * math.sqrt(max(var, 1.0 / T))
    return lags, out, band


def excitation_without(Y: np.ndarray, kappa: np.ndarray, shared: np.ndarray) -> np.ndarray:
    """(E, T) for each row e, the excitation estimated from the rows that share no tracked node with e:
    z_(-e)(t) = sum_k kappa_k y_k(t) / sum_k kappa_k^2 over those rows observed at t (0 where none).

    The fitted z is a weighted mean of every row, so it carries row e's own noise and makes that noise look
    coherent with z; an input built without row e's nodes cannot."""
    E, T = Y.shape
    ok = np.isfinite(Y)
    Yf = np.where(ok, Y, 0.0)
    out = np.zeros((E, T))
    for e in range(E):
        far = ~shared[e]
        if not far.any():
            far = np.arange(E) != e
        num = (kappa[far, None] * Yf[far]).sum(axis=0)
        den = ((kappa[far, None] ** 2) * ok[far]).sum(axis=0)
        out[e] = np.where(den > 0, num / np.maximum(den, 1e-300), 0.0)
    return out


def frequency_response(Y: np.ndarray, Z: np.ndarray, kappa: np.ndarray, nperseg: int):
    """Welch estimates of H_e = S_(z_e y_e) / S_(z_e z_e) with each row's own input Z[e] (E, T): (freqs,
    gain / kappa, phase deg, coherence, K segments averaged)."""
    E, T = Y.shape
    Yf = np.where(np.isfinite(Y), Y, 0.0)
    n = nperson(nperseg, T)
    f, Pzz = signal.welch(Z, nperseg=n, axis=1)
    _, Pzy = signal.csd(Z, Yf, nperseg=n, axis=1)
    _, Pyy = signal.welch(Yf, nperseg=n, axis=1)
    H = Pzy / np.maximum(Pzz, 1e-300)
    coh = np.abs(Pzy) ** 2 / np.maximum(Pzz * Pyy, 1e-300)
    k = np.where(np.abs(kappa) > 0, kappa, 1.0)[:, None]
    n = nperson(nperseg, T)
    K = max(1, 2 * T // n - 1)  # 50 % overlap
    return f, np.abs(H) / np.abs(k), np.degrees(np.angle(H * np.sign(k))), np.clip(coh, 0, 1), K


def nperson(nperseg: int, T: int) -> int:
    """Welch segment length used for T frames: ``nperseg`` but at most T // 4 (>= 16)."""
    return int(max(16, min(nperseg, T // 4)))


def _wls(x, y, w):
    """Weighted LS slope (through a free intercept) and its SE from the weights (1 / variance)."""
    W = w.sum()
    if W <= 0 or len(x) < 3:
        return float("nan"), float("nan")
    xm, ym = np.sum(w * x) / W, np.sum(w * y) / W
    sxx = np.sum(w * (x - xm) ** 2)
    if sxx <= 0:
        return float("nan"), float("nan")
    b = np.sum(w * (x - xm) * (y - ym)) / sxx
    res = y - ym - b * (x - xm)
    chi = max(float(np.sum(w * res * res)) / max(len(x) - 2, 1), 1.0)  # over-dispersion, never below nominal
    return float(b), float(math.sqrt(chi / sxx))


def cross_spectral_svs(X: np.ndarray, nperseg: int) -> tuple[np.ndarray, np.ndarray]:
    """(freqs, (K, 2)) the two largest singular values of the (E, E) Welch cross-spectral matrix of rows X."""
    E, T = X.shape
    Xf = np.where(np.isfinite(X), X, 0.0)
    Xf = Xf - Xf.mean(axis=1, keepdims=True)
    n = nperson(nperseg, T)
    f, S = signal.csd(Xf[:, None, :], Xf[None, :, :], nperseg=n, axis=-1)  # (E, E, K)
    sv = np.linalg.svd(np.moveaxis(S, -1, 0), compute_uv=False)  # (K, E)
    out = np.zeros((len(f), 2))
    out[:, : min(2, E)] = sv[:, : min(2, E)]
    return f, out


def residual_analysis(Y: np.ndarray, kappa: np.ndarray, z: np.ndarray, noise_series: np.ndarray | None = None,
                      shared: np.ndarray | None = None, root_distance: np.ndarray | None = None,
                      nperseg: int = 128, alpha: float = 0.05) -> ResidualAnalysis:
    """Residual analysis of the rank-1 fit y = kappa z of Y (E, T) degrees (NaN = missing).

    noise_series: (E, T) a realisation of the model-free angle noise (:attr:`NoiseFloor.series_deg`), for the
    cross-spectral singular values' null band; shared: (E, E) bool, rows whose bends share a tracked node
    (default: rows up to two apart) — the frequency response of row e uses the excitation estimated without
    them (:func:`excitation_without`); nperseg: Welch segment length (frames); alpha: level of the coherence
    threshold; root_distance: (E,) 0..1, for the trend of the delay along the branch (default: row order)."""
    E, T = Y.shape
    s_rd = np.linspace(0, 1, E) if root_distance is None else np.asarray(root_distance, float)
    if shared is None:
        idx = np.arange(E)
        shared = np.abs(idx[:, None] - idx[None, :]) <= 2
    R = Y - kappa[:, None] * z[None, :]
    lags, xc, band = cross_correlation(R, z, max_lag=int(min(60, max(5, T // 10))))
    f, gain, phase, coh, K = frequency_response(Y, excitation_without(Y, kappa, shared), kappa, nperseg)
    # Welch coherence of independent series exceeds 1 - a^(1 / (K - 1)) with probability a; a = alpha over the
    # number of frequencies (Bonferroni), so that a few coherent-looking bins are not noise by chance
    n_freq = max(int(np.sum(f > 0)), 1)
    thr = 1.0 - (alpha / n_freq) ** (1.0 / max(K - 1, 1))
    delay = np.full(E, np.nan)
    delay_se = np.full(E, np.nan)
    curv = np.full(E, np.nan)
    curv_t = np.full(E, np.nan)
    for e in range(E):
        use = (coh[e] > thr) & (f > 0)
        if use.sum() < 3:
            continue
        g2 = coh[e, use]
        var_rel = (1 - g2) / (2 * g2 * K)  # var(log|H|) ~ var(phase, rad^2) (Bendat & Piersol)
        w = 1.0 / np.maximum(var_rel, 1e-12)
        ph = np.unwrap(np.radians(phase[e, use]))
        b, se = _wls(2 * np.pi * f[use], ph, w)
        delay[e], delay_se[e] = -b, se
        c, cse = _wls(f[use] ** 2, np.log(np.maximum(gain[e, use], 1e-12)), w)
        curv[e], curv_t[e] = c, c / cse if cse and np.isfinite(cse) and cse > 0 else np.nan
    _, sv_r = cross_spectral_svs(R, nperseg)
    sv_n = cross_spectral_svs(noise_series, nperseg)[1] if noise_series is not None else None
    # trend per segment with an AR(1)-inflated SE
    tt = (np.arange(T) - (T - 1) / 2) / T
    trend = np.zeros(E)
    trend_t = np.zeros(E)
    for e in range(E):
        ok = np.isfinite(R[e])
        if ok.sum() < 10:
            continue
        X = np.stack([np.ones(ok.sum()), tt[ok]], axis=1)
        beta, *_ = np.linalg.lstsq(X, R[e, ok], rcond=None)
        res = R[e, ok] - X @ beta
        rho = float(np.clip(autocorrelation(res, 1)[1], 0.0, 0.99))
        s2 = float(np.sum(res ** 2) / max(ok.sum() - 2, 1)) * (1 + rho) / (1 - rho)
        se = math.sqrt(s2 * np.linalg.inv(X.T @ X)[1, 1])
        trend[e], trend_t[e] = beta[1], beta[1] / se if se > 0 else 0.0
    # gain against amplitude: quartiles of |z|
    az = np.abs(z)
    edges_q = np.quantile(az, [0, 0.25, 0.5, 0.75, 1.0])
    bins = np.clip(np.searchsorted(edges_q, az, side="right") - 1, 0, 3)
    med = np.array([np.median(az[bins == b]) if np.any(bins == b) else np.nan for b in range(4)])
    gba = np.full((E, 4), np.nan)
    for e in range(E):
        for b in range(4):
            m = (bins == b) & np.isfinite(Y[e])
            den = float(np.sum((kappa[e] * z[m]) ** 2))
            if m.sum() > 5 and den > 0:
                gba[e, b] = float(np.sum(Y[e, m] * kappa[e] * z[m])) / den
    # branch-level summary
    okd = np.isfinite(delay) & np.isfinite(delay_se) & (delay_se > 0)
    # a load travelling along the branch: the delay relative to z grows with root distance
    dslope, dse = _wls(s_rd[okd], delay[okd], 1.0 / delay_se[okd] ** 2) if okd.sum() >= 3 else (np.nan, np.nan)
    ct = curv_t[np.isfinite(curv_t)]
    pooled_curv_t = float(np.sum(ct) / math.sqrt(len(ct))) if len(ct) else float("nan")  # Stouffer
    x_amp = np.tile(np.log(np.maximum(med, 1e-12)), (E, 1))
    ok = np.isfinite(gba) & (gba > 0)
    slope_amp, se_amp = _wls(x_amp[ok], np.log(gba[ok]), np.ones(ok.sum())) if ok.sum() > 3 else (np.nan, np.nan)
    band_f = f > 0
    ratio = (sv_r[band_f, 0] / np.maximum(sv_n[band_f, 0], 1e-300)) if sv_n is not None else np.array([np.nan])
    summary = {"delay_slope_frames_per_branch": float(dslope), "delay_slope_se": float(dse),
               "pooled_gain_curvature_t": pooled_curv_t,
               "max_abs_trend_t": float(np.max(np.abs(trend_t))) if E else float("nan"),
               "gain_vs_amplitude_log_slope": float(slope_amp), "gain_vs_amplitude_se": float(se_amp),
               "peak_s1_over_noise_s1": float(np.nanmax(ratio)) if np.isfinite(ratio).any() else float("nan"),
               "max_abs_xcorr_over_band": float(np.max(np.abs(xc) / band[:, None])) if E else float("nan"),
               "coherent_segments": int(np.sum(np.isfinite(delay)))}
    return ResidualAnalysis(lags=lags, xcorr=xc, xcorr_band=band, freqs=f, gain=gain, phase_deg=phase,
                            coherence=coh, coherence_threshold=float(thr), delay_frames=delay, delay_se=delay_se,
                            gain_curvature=curv, gain_curvature_t=curv_t, sv_residual=sv_r, sv_noise=sv_n,
                            trend_deg=trend, trend_t=trend_t, amplitude_bins=med, gain_by_amplitude=gba,
                            summary=summary)
