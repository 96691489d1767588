"""Phase-randomised residual bootstrap and its small-sample widening (the default preset's kappa CIs)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import signal

from rce_gtsam.model.compliance import fit_rank1
from rce_gtsam.model.surrogates import phase_randomised_residuals
from rce_gtsam.model.uncertainty import bootstrap_kappa, excitation_dof, small_sample_factor
from rce_gtsam.presets import DEFAULT
from rce_gtsam.sim.simulate import make_excitation


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 10_000), T=st.integers(16, 301))
def test_surrogates_keep_each_rows_spectrum_and_the_cross_spectra(seed, T):
    rng = np.random.default_rng(seed)
    x = signal.lfilter([1.0], [1.0, -0.9], rng.standard_normal((3, T)), axis=1)
    x[1] = -x[0] + 0.3 * x[1]  # strongly anti-correlated pair, like bends sharing a node
    x += np.array([[1.0], [-2.0], [0.5]])
    S = phase_randomised_residuals(x, 7, np.random.default_rng(seed + 1))
    assert S.shape == (7, 3, T)
    Fx = np.fft.rfft(x - x.mean(axis=1, keepdims=True), axis=1)
    inner = slice(1, Fx.shape[1] - (1 if T % 2 == 0 else 0))  # DC and Nyquist are redrawn
    for s in S:
        Fs = np.fft.rfft(s, axis=1)
        np.testing.assert_allclose(np.abs(Fs[:, inner]), np.abs(Fx[:, inner]), rtol=1e-7, atol=1e-7)
        np.testing.assert_allclose(Fs[0, inner] * np.conj(Fs[1, inner]), Fx[0, inner] * np.conj(Fx[1, inner]),
                                   rtol=1e-6, atol=1e-6)


def test_surrogate_means_are_noise_drawn_from_the_lowest_frequency():
    """A residual row's mean is a noise sample too (slow drift does not average out over a clip): the
    surrogates' means are zero on average with the variance the lowest-frequency power implies."""
    rng = np.random.default_rng(0)
    x = signal.lfilter([1.0], [1.0, -0.98], rng.standard_normal((2, 400)), axis=1)
    S = phase_randomised_residuals(x, 4000, np.random.default_rng(1))
    means = S.mean(axis=2)
    F1 = np.fft.rfft(x - x.mean(axis=1, keepdims=True), axis=1)[:, 1]
    expected_sd = np.abs(F1) / 400
    np.testing.assert_allclose(means.std(axis=0), expected_sd, rtol=0.05)
    assert np.all(np.abs(means.mean(axis=0)) < 0.1 * expected_sd)


def test_missing_residuals_are_left_out_and_the_output_is_finite():
    R = np.random.default_rng(0).normal(size=(2, 50))
    R[0, 10:20] = np.nan
    S = phase_randomised_residuals(R, 3, np.random.default_rng(1))
    assert np.isfinite(S).all()


def test_surrogates_keep_a_gappy_rows_power_on_its_observed_frames():
    """Callers mask the surrogates where the residuals are missing; a row observed on 40 % of its frames must
    still get the variance it has there, and the observed frames' mean is the one removed. Before the
    sqrt(T / n_observed) scale a zero-mean row kept 40 % of it (a null too narrow by 2.5 in variance); before
    the observed mean, this row's offset of 5 left the zero-filled frames a step that came out as 6.5 times
    the variance."""
    rng = np.random.default_rng(3)
    R = 5.0 + rng.normal(size=(2, 1000))
    R[0, rng.random(1000) < 0.6] = np.nan
    S = phase_randomised_residuals(R, 400, np.random.default_rng(4))
    for e in range(2):
        seen = np.isfinite(R[e])
        var_obs = float(np.var(R[e, seen]))
        var_sur = float(np.mean(S[:, e, seen] ** 2))
        assert abs(var_sur / var_obs - 1.0) < 0.1, (e, var_sur / var_obs)


def test_effective_samples_of_narrowband_and_broadband_excitation():
    rng = np.random.default_rng(0)
    T = 600
    R = rng.normal(size=(5, T))
    sine = np.sin(2 * np.pi * 7 * np.arange(T) / T)  # all power in one frequency bin
    assert excitation_dof(R, sine) < 1.5
    assert excitation_dof(R, rng.normal(size=T)) > 50
    assert small_sample_factor(1e6) < 1.001
    assert 1.15 < small_sample_factor(3.5) < 1.25  # Student t with 7 degrees of freedom: 2.36 / 1.96
    assert small_sample_factor(0.5) > small_sample_factor(3.5)


def test_phase_intervals_cover_kappa_under_slow_drift_where_blocks_do_not():
    """Noise correlated over 2 s (tracker drift) and the simulator's excitation: the moving-block intervals
    are far too narrow; the widened phase intervals cover the truth at about the nominal rate."""
    E, T, tau = 12, 600, 60.0
    rng = np.random.default_rng(5)
    kappa = np.exp(rng.normal(0, 0.5, E))
    kappa /= np.exp(np.log(kappa).mean())
    z = make_excitation(T, 30.0, np.random.default_rng(6), rms_deg=1.3)
    rho = np.exp(-1 / tau)
    cfg = replace(DEFAULT.compliance, n_boot=80, weighted=False)
    cover = {"phase": [], "block": []}
    for k in range(12):
        e = np.random.default_rng(100 + k).standard_normal((E, T + 300))
        noise = signal.lfilter([np.sqrt(1 - rho ** 2)], [1.0, -rho], e, axis=1)[:, 300:]
        Y = kappa[:, None] * z[None] + 0.6 * noise
        fit = fit_rank1(Y, cfg)
        for method in cover:
            c = replace(cfg, bootstrap=method)
            ci = bootstrap_kappa(Y, c, fit=fit)
            cover[method].append(np.mean((kappa >= ci.low) & (kappa <= ci.high)))
    assert np.mean(cover["phase"]) >= 0.85, cover
    assert np.mean(cover["block"]) < 0.75, cover


def test_phase_bootstrap_is_deterministic_and_reports_its_widening():
    rng = np.random.default_rng(2)
    Y = np.outer(np.exp(rng.normal(0, 0.4, 6)), make_excitation(300, 30.0, rng)) + rng.normal(0, 0.3, (6, 300))
    cfg = replace(DEFAULT.compliance, n_boot=40, weighted=False)
    a, b = bootstrap_kappa(Y, cfg), bootstrap_kappa(Y, cfg)
    np.testing.assert_array_equal(a.samples, b.samples)
    assert a.method == "phase" and a.effective_samples >= 1 and a.width_factor >= 1
    fit = fit_rank1(Y, cfg)
    assert (a.low <= fit.kappa).all() and (fit.kappa <= a.high).all()


def test_intervals_at_a_low_signal_to_noise_ratio_keep_the_posterior_width():
    """Bending buried in slow node noise (per-segment SNR ~0.2, as on real texture with a 0.3 px tracker whose
    error lasts ~half a second; a node's error turns its bends with opposite signs): the resampled intervals
    alone are too narrow (kappa_hat
    z_hat already holds noise, so the resamples show less of it than the data have); with the posterior floor
    (each side >= 1.96 tau sqrt(1 - s) in log, s the shrinkage) they cover the truth at about the nominal rate.
    Where the data determine kappa (s ~ 1) nothing changes."""
    from rce_gtsam.diagnosis.noise_floor_nodewise import angle_sensitivity
    from rce_gtsam.model.uncertainty import posterior_floor
    N, T = 16, 300
    rng = np.random.default_rng(11)
    steps = rng.uniform(12.0, 25.0, N - 1)
    rest = {i: np.array([0.0, -float(np.sum(steps[:i]))]) for i in range(N)}
    A = angle_sensitivity([(i - 1, i, i + 1) for i in range(1, N - 1)], rest)  # deg per px
    E = A.shape[0]
    kappa = np.exp(rng.normal(0, 0.6, E))
    kappa /= np.exp(np.log(kappa).mean())
    z = make_excitation(T, 30.0, np.random.default_rng(12), rms_deg=0.5)
    W = np.broadcast_to(1.0 / (0.3 ** 2 * np.sum(A * A, axis=1))[:, None], (E, T))
    cfg = DEFAULT.compliance
    cfg = replace(cfg, n_boot=60)
    cover = {True: [], False: []}
    for k in range(8):
        e = np.random.default_rng(200 + k).standard_normal((N, T + 60))
        e = np.array([np.convolve(r, np.ones(15), "same") for r in e])[:, 30:-30]  # node errors over ~15 frames
        Y = kappa[:, None] * z[None] + A @ (0.3 * e / e.std())
        fit = fit_rank1(Y, cfg, W)
        for floor in cover:
            ci = bootstrap_kappa(Y, replace(cfg, posterior_floor=floor), W, fit=fit)
            cover[floor].append(np.mean((kappa >= ci.low) & (kappa <= ci.high)))
    # measured: 91 % with the floor, 76 % without
    assert np.mean(cover[True]) >= 0.85 > np.mean(cover[False]) + 0.05, cover
    # s = 1: the floor is zero and the interval is the resamples'
    placed = np.exp(np.random.default_rng(3).normal(0, 0.1, (200, 3)))
    lo, hi, out = posterior_floor(np.ones(3), placed, np.ones(3), 1.0)
    np.testing.assert_allclose(out, placed)
    np.testing.assert_allclose([lo, hi], np.percentile(placed, [2.5, 97.5], axis=0))
    # s = 0.25: each side at least 1.96 sqrt(0.75) = 1.70 in log
    lo, hi, out = posterior_floor(np.ones(3), placed, np.full(3, 0.25), 1.0)
    assert np.all(np.log(hi) >= 1.69) and np.all(np.log(lo) <= -1.69)
    np.testing.assert_allclose([lo, hi], np.percentile(out, [2.5, 97.5], axis=0), rtol=1e-3)  # the resamples say so
