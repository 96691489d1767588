"""The diagnosis' full-data score test (rce_gtsam.diagnosis.score_test): its projection, every effect's score
directions against the effect's own prediction, and its calibration and power on simulator matrices."""

import types

import numpy as np
import pytest
from _effect_data import synth

from rce_gtsam import effects
from rce_gtsam.diagnosis.diagnose import node_disjoint_split, shared_node_matrix
from rce_gtsam.diagnosis.score_test import (cross_fitted_score_test, effect_directions, half_fits,
                                            remove_rank1_tangent)
from rce_gtsam.model import ResponseModel

# a small amount of each effect that has score directions: its prediction change must lie in their span
NEAR_NULL = {
    "delay": {"tau": 0.3},                                        # frames at the tip
    "dynamics": {"omega_root": 4.0, "omega_tip": 2.0, "zeta": 0.5},  # rad/frame, far above z's band
    "nonlinear": {"c": 1e-4, "z0": 0.7},                          # deg^-2 (a saturation angle of 100 deg), deg
}


def test_projection_leaves_nothing_the_rank1_model_could_absorb():
    rng = np.random.default_rng(0)
    E, T = 7, 120
    kappa, z = np.exp(rng.normal(0, 0.5, E)), rng.standard_normal(T)
    W = rng.uniform(0.5, 2, (E, T))
    W[rng.uniform(size=(E, T)) < 0.1] = 0.0
    X = rng.standard_normal((2, E, T))
    G = X + rng.standard_normal((2, E, 1)) * z[None, None] + kappa[None, :, None] * rng.standard_normal((2, 1, T))
    P = remove_rank1_tangent(G, kappa, z, W)
    assert np.abs(np.einsum("et,jet->je", W * z[None], P)).max() < 1e-8      # no kappa change absorbs it
    assert np.abs(np.einsum("et,jet->jt", W * kappa[:, None], P)).max() < 1e-8  # no z change absorbs it
    # and what is left of a direction the model CAN absorb is nothing
    A = (rng.standard_normal(E)[:, None] * z[None] + kappa[:, None] * rng.standard_normal(T)[None])[None]
    assert np.abs(remove_rank1_tangent(A, kappa, z, W)).max() < 1e-8 * np.abs(A).max()


def _with_directions():
    out = []
    for name in effects.names():
        eff = effects.make(name)
        if eff.score_directions(np.ones(3), np.zeros(10), np.linspace(0, 1, 3)) is not None:
            out.append(name)
    return out


def test_the_effects_with_a_score_test_are_the_calibrated_ones():
    """Delay, dynamics and the saturation have one; an effect added without NEAR_NULL here fails the conformance
    test below."""
    assert set(_with_directions()) == {"delay", "dynamics", "nonlinear"}
    assert set(_with_directions()) <= set(NEAR_NULL)


@pytest.mark.parametrize("name", sorted(NEAR_NULL))
def test_score_directions_span_the_effects_own_first_order_change(name):
    """Conformance: a small amount of the effect, computed with the effect's own operator, moves the rank-1
    prediction within the span of its score directions (after both are projected off what z and kappa absorb)."""
    Y, s, kappa, z, _ = synth(None, seed=1, E=10, T=400)
    eff = effects.make(name)
    view = types.SimpleNamespace(s=s, T=len(z), E=len(s))
    state = {"params": {k: np.array(v) for k, v in NEAR_NULL[name].items()}, "latents": {}}
    X = np.repeat(z[None], len(s), axis=0)
    if eff.kind == "output":  # a map of each joint's deflection kappa_e z_t
        U = kappa[:, None] * X
        change = (eff.output(U, state, kappa)[0] - U)[None]
    else:
        change = (kappa[:, None] * (eff.apply(X, state, view) - X))[None]
    W = np.ones_like(X)
    D = remove_rank1_tangent(np.asarray(eff.score_directions(kappa, z, s), float), kappa, z, W)
    C = remove_rank1_tangent(change, kappa, z, W)[0]
    A = D.reshape(len(D), -1).T
    coef = np.linalg.lstsq(A, C.ravel(), rcond=None)[0]
    r2 = 1 - np.sum((C.ravel() - A @ coef) ** 2) / np.sum(C ** 2)
    assert r2 > 0.95, r2


def _p(Y, s, name, seed=0, n=400):
    W = np.where(np.isfinite(Y), 1.0, 0.0)
    halves = node_disjoint_split(s, shared_node_matrix(s), seed)
    fits = half_fits(ResponseModel(), Y, W, s, halves)
    return cross_fitted_score_test(halves, fits, effect_directions(effects.make(name)), n_surrogates=n, seed=seed).p


@pytest.mark.parametrize("name", sorted(NEAR_NULL))
def test_score_test_is_calibrated_on_coloured_noise_and_finds_the_effect(name):
    """Effect-free matrices with white + low-pass (drift-like) noise: p < 0.05 in at most 4 of 20 seeds (expected
    1; P(>= 5) = 0.3 % for a calibrated test). The effect at the simulator's default strength, half that noise:
    p <= 0.01 (measured p = 0.0025, the smallest 400 surrogates give, on seeds 4-5 for both; seed 0 of dynamics is
    0.18: its test is weaker, and the held-out test then decides). The saturation (its default q / y_s = 3): p <=
    0.005 on seeds 0, 1, 2, 3 and 5, 0.13 on seed 4; at a third of that strength on 1 of 6."""
    null = [_p(*synth(None, seed=sd, E=12, T=600)[:2], name) for sd in range(20)]
    assert sum(p < 0.05 for p in null) <= 4, null
    for sd in ((0, 3) if name == "nonlinear" else (4, 5)):
        Y, s, *_ = synth(name, seed=sd, E=12, T=600, noise=0.15)
        assert _p(Y, s, name) <= 0.01


def test_diagnose_runs_the_score_test_where_an_effect_has_one_and_splits_alpha():
    """The diagnosis: delay, dynamics, the saturation and the second excitation carry score_p; the others do not.
    Their fold t threshold is the Bonferroni quantile at alpha / (2 C) and their score threshold alpha / (2 C) (C effects the
    candidates can name: two forms of one effect share its share); significant =
    either test, supported = significant and the held-out error falls. The delay in these matrices is found."""
    from scipy import stats

    from rce_gtsam.diagnosis.diagnose import diagnose
    Y, s, *_ = synth("delay", seed=4, E=12, T=600, noise=0.15)
    d = diagnose(Y, root_distance=s, n_folds=8)
    C = len({effects.finding(c.effect) for c in d.candidates})
    assert C == d.settings["n_findings"] == len(d.candidates) - 1  # resonances is a form of dynamics
    assert d.settings["score_threshold_p"] == pytest.approx(0.05 / (2 * C))
    assert d.settings["evidence_threshold_t_split"] == pytest.approx(stats.t.ppf(1 - 0.05 / (2 * C), 7))
    with_test = set(NEAR_NULL) | {n for n in effects.names() if effects.make(n).score_excitation == "between_rows"}
    assert "second_mode" in with_test
    for c in d.candidates:
        if c.effect in with_test:
            assert 0 < c.extra["score_p"] <= 1 and c.extra["threshold_t"] == d.settings["evidence_threshold_t_split"]
            assert c.extra["score_excitation"] == effects.make(c.effect).score_excitation  # which test ran
            if c.effect == "delay":  # the scan's strongest lag, for the report
                assert c.extra["score_peak"]["tip_lag_frames"] in effects.make("delay").scan_lags()
            assert c.extra["significant"] == bool(c.evidence > c.extra["threshold_t"]
                                                  or c.extra["score_p"] <= c.extra["score_threshold_p"])
        else:
            assert "score_p" not in c.extra
            assert c.extra["significant"] == bool(c.evidence > d.settings["evidence_threshold_t"])
        if c.supported:
            assert c.extra["significant"] and c.heldout_rmse < d.baseline_heldout_rmse
    assert d.candidate("delay").extra["score_p"] <= 0.005
    assert d.verdict == "delay"


@pytest.mark.parametrize("name", effects.names())
def test_test_directions_are_shaped_and_combined_as_declared(name):
    """Conformance: every effect's test_directions is None or (G (J, E, T), 'quadratic' | 'max'); a scan
    ('max') over one parameter contains, at its smallest value, the effect's first-order direction (so the
    scan is never blind where the derivative test sees the effect)."""
    Y, s, kappa, z, _ = synth(None, seed=1, E=10, T=400)
    eff = effects.make(name)
    out = eff.test_directions(kappa, z, s)
    if out is None:
        assert eff.score_directions(kappa, z, s) is None
        return
    G, statistic = out
    assert statistic in ("quadratic", "max")
    assert G.ndim == 3 and G.shape[1:] == (len(s), len(z)) and np.all(np.isfinite(G))
    if statistic == "max":
        W = np.ones((len(s), len(z)))
        D = remove_rank1_tangent(np.asarray(eff.score_directions(kappa, z, s), float), kappa, z, W)[0].ravel()
        P = remove_rank1_tangent(G, kappa, z, W).reshape(len(G), -1)
        cos = np.abs(P @ D) / (np.linalg.norm(P, axis=1) * np.linalg.norm(D))
        assert cos.max() > 0.99, cos.max()


def test_the_delay_scan_finds_a_long_lag_the_first_order_direction_misses():
    """A 45-frame tip lag, a quarter of the sway's main period (~200 frames in these matrices): the first-order
    direction -kappa s dz/dt (the delay's Taylor term at tau = 0) is far from the delayed prediction, and the
    test along it is blind (p = 0.62 / 0.96 at noise 0.3 / 0.6 on this seed); the scan over lags finds it
    (p = 1/401, the smallest 400 surrogates give, at a 42-frame lag). Through the pipeline, 20 seeds at 3x
    default: p <= 0.005 in 13/20 with the first-order direction, 17/20 with the scan; effect-free 0/40 both."""
    from rce_gtsam.diagnosis.score_test import excitation_clock

    Y, s, *_ = synth("delay", seed=2, E=12, T=600, noise=0.6, strength=45.0)
    W = np.where(np.isfinite(Y), 1.0, 0.0)
    halves = node_disjoint_split(s, shared_node_matrix(s), 0)
    fits = half_fits(ResponseModel(), Y, W, s, halves)
    delay = effects.make("delay")
    local = cross_fitted_score_test(halves, fits, lambda i, k, z, s_: delay.score_directions(k, z, s_),
                                    n_surrogates=400).p
    scan = cross_fitted_score_test(halves, fits, effect_directions(delay), n_surrogates=400)
    assert scan.statistic == "max" and scan.p <= 0.005 < 0.05 < local, (scan.p, local)
    assert abs(delay.scan_lags()[scan.peak]) >= 15  # the scan peaks at a long lag, not at the derivative's
    assert 0.0 < excitation_clock(fits[0]) < 1.0


def test_shifted_is_the_delay_operator_with_one_lag_per_row():
    """The scan's fast shift (four whole-frame shifts per row) equals the operator's Catmull-Rom taps, ends
    included, for lags of either sign, fractional, and longer than the recording."""
    from rce_gtsam.effects.delay import shifted

    rng = np.random.default_rng(3)
    delay = effects.make("delay")
    for T in (400, 9):
        z = rng.standard_normal(T)
        s = np.array([-0.4, 0.0, 0.1, 0.55, 1.0])
        for tau in (0.3, -7.6, 42.0, -60.0):
            view = types.SimpleNamespace(s=s, T=T, E=len(s))
            state = {"params": {"tau": np.array(tau)}, "latents": {}}
            want = delay.apply(np.repeat(z[None], len(s), axis=0), state, view)
            np.testing.assert_allclose(shifted(z, tau * s), want, atol=1e-12)


@pytest.mark.parametrize("name", effects.names())
def test_an_effect_says_where_its_score_test_gets_z(name):
    """Conformance: score_excitation is "other_rows" (cross-fitted) or "own_whitened" (the fit's own z, GLS), the
    latter only for an effect that has directions; or "between_rows" (do two node-disjoint row sets share a time
    course?), only for an effect without directions whose per-frame latent series is common to the segments."""
    from rce_gtsam.diagnosis.score_dispatch import VERSIONS
    eff = effects.make(name)
    assert eff.score_excitation in VERSIONS
    Y, s, kappa, z, _ = synth(None, seed=1, E=6, T=50)
    if eff.score_excitation == "own_whitened":
        assert eff.test_directions(kappa, z, s) is not None
    if eff.score_excitation == "between_rows":
        assert eff.test_directions(kappa, z, s) is None and eff.latent_names()


def _p_shared(Y, s, seed=0):
    from rce_gtsam.diagnosis.score_test import shared_time_course_test
    W = np.where(np.isfinite(Y), 1.0, 0.0)
    halves = node_disjoint_split(s, shared_node_matrix(s), seed)
    return shared_time_course_test(ResponseModel().solve(Y, W, s), halves, n_surrogates=400, seed=seed).p


def test_the_shared_time_course_test_is_calibrated_and_finds_a_second_excitation():
    """The second excitation's test (do two node-disjoint row sets' residuals move together?). Effect-free
    matrices with white + low-pass noise: p < 0.05 in at most 4 of 20 seeds (measured 1/20, p = 0.015;
    the excitation's own noise, common to every row, is projected out of each set and does not count). A second
    excitation at the simulator's default strength, half that noise: p <= 0.01 on seeds 0-3 (measured 1/401,
    the smallest 400 surrogates give, on seeds 0-7)."""
    null = [_p_shared(*synth(None, seed=sd, E=12, T=600)[:2]) for sd in range(20)]
    assert sum(p < 0.05 for p in null) <= 4, null
    for sd in range(4):
        assert _p_shared(*synth("second_mode", seed=sd, E=12, T=600, noise=0.15)[:2]) <= 0.01


def test_the_shared_time_course_test_does_not_take_a_lag_for_a_second_excitation(monkeypatch):
    """Every segment lagging by its own amount leaves c_e kappa_e dz/dt in its residual: a time course common to
    both row sets that is not a second excitation. Each row's multiple of dz/dt is removed before the sets are
    compared (score_test.remove_row_lag). Delay at the simulator's default strength, white + low-pass noise
    0.15: measured p = 0.55 and 0.29 on seeds 0 and 1, and 1/401 on both without the removal."""
    from rce_gtsam.diagnosis import score_test
    from rce_gtsam.sim.simulate import EFFECT_DEFAULTS

    lagged = [synth("delay", seed=sd, E=12, T=600, noise=0.15, strength=EFFECT_DEFAULTS["delay"])[:2]
              for sd in (0, 1)]
    assert all(_p_shared(Y, s) > 0.05 for Y, s in lagged)
    monkeypatch.setattr(score_test, "remove_row_lag", lambda X, W, z: X)
    assert all(_p_shared(Y, s) <= 0.005 for Y, s in lagged)


def test_the_whitened_test_is_calibrated_and_finds_a_small_delay_the_cross_fitted_one_misses():
    """The delay's test (whitened_score_test: its lag scan from the full fit's own excitation, scored by GLS
    across segments against phase surrogates): on effect-free matrices with white + low-pass noise p < 0.05 in
    at most 2 of 10 seeds (measured 0/20 over seeds 0-19, smallest 0.111; P(>= 3 of 10) = 1.2 % for a
    calibrated test). At a quarter of the default delay it finds what the cross-fitted test, whose directions
    come from the other row set's z, misses: measured on seeds 0-5, p = 1/2001 on all six, cross-fitted
    0.063-0.71 (seed 2: 0.71)."""
    from rce_gtsam.diagnosis.score_dispatch import effect_score_test
    from rce_gtsam.sim.simulate import EFFECT_DEFAULTS

    delay, model = effects.make("delay"), ResponseModel()

    def whitened(Y, s):
        W = np.where(np.isfinite(Y), 1.0, 0.0)
        halves = node_disjoint_split(s, shared_node_matrix(s), 0)
        return effect_score_test(delay.score_excitation, model, model.solve(Y, W, s), Y, W, s,
                                 half_fits(model, Y, W, s, halves), halves,
                                 lambda rows, kappa, z, s_: delay.test_directions(kappa, z, s_))

    null = [whitened(*synth(None, seed=sd, E=12, T=600)[:2]).p for sd in range(10)]
    assert sum(p < 0.05 for p in null) <= 2, null
    Y, s, *_ = synth("delay", seed=2, E=12, T=600, strength=0.25 * EFFECT_DEFAULTS["delay"])
    found = whitened(Y, s)
    assert found.p <= 0.005 < 0.05 < _p(Y, s, "delay"), (found.p, _p(Y, s, "delay"))
    assert found.statistic == "max" and found.n_surrogates == 2000


def test_the_whitened_directions_are_the_tangent_free_directions_times_the_inverse_noise_correlation(monkeypatch):
    """D = C^-1 sqrt(W) G~ (G~: the rank-1 tangent removed), 0 where the residual is missing: with C the identity D
    is sqrt(W) G~ itself, and the residual noise's correlation between bends that share a tracked node changes
    it (that is the GLS the test scores with)."""
    from rce_gtsam.diagnosis import whitened_score_test as ws
    from rce_gtsam.sim.simulate import EFFECT_DEFAULTS

    delay, model = effects.make("delay"), ResponseModel()
    Y, s, *_ = synth("delay", seed=2, E=12, T=600, strength=0.25 * EFFECT_DEFAULTS["delay"])
    Y[3, 100:140] = np.nan
    W = np.where(np.isfinite(Y), 1.0, 0.0)
    fit = model.solve(Y, W, s)
    X = ws.whitened_residuals(fit)
    G, _ = delay.test_directions(fit.kappa, fit.z, fit.root_distance - ws.excitation_clock(fit))
    D = ws.whitened_directions(fit, G, X)
    assert D.shape == G.shape and np.all(D[:, 3, 100:140] == 0)
    plain = np.where(np.isfinite(X)[None], remove_rank1_tangent(G, fit.kappa, fit.z, W), 0.0)
    assert not np.allclose(D, plain)
    monkeypatch.setattr(ws, "noise_correlation", lambda R: np.eye(len(R)))
    np.testing.assert_allclose(ws.whitened_directions(fit, G, X), plain, atol=1e-12)


def _glitched(seed, n_pairs=2, amp=25.0, width=3.0):
    """Effect-free matrices with ``n_pairs`` tracking glitches that hit both node-disjoint row sets at nearly the
    same frame: a bump of ``amp`` x the noise's SD, ``width`` frames wide, in one row of each set (a node that
    jumps by 3-8 px against 0.25 px of tracking noise is a 12-32 sigma glitch)."""
    Y, s, kappa, z, y = synth(None, seed=seed, E=12, T=600)
    rng = np.random.default_rng(100 + seed)
    halves = node_disjoint_split(s, shared_node_matrix(s), 0)
    t = np.arange(Y.shape[1])
    sd = np.nanstd(Y - y)
    for _ in range(n_pairs):
        t0 = rng.uniform(20, 580)
        for h in halves:
            Y[rng.choice(h)] += amp * sd * rng.choice([-1, 1]) * np.exp(-0.5 * ((t - t0 - rng.normal(0, 2)) / width) ** 2)
    return Y, s, halves


def test_coincident_tracking_glitches_do_not_make_the_test_significant(monkeypatch):
    """Two coincident glitch pairs in effect-free data: with the raw residuals the dynamics test gave p <= 0.005
    on 4 of 10 seeds (p = 0.001 each: one product of two bumps dominates a score that the Gaussian surrogates
    calibrate); with robust residuals (Huber's psi at 2 robust SDs) on none, and p <= 0.05 on 2 of 10."""
    from rce_gtsam.diagnosis import score_test as st

    def p_values():
        out = []
        for sd in range(10):
            Y, s, halves = _glitched(sd)
            W = np.where(np.isfinite(Y), 1.0, 0.0)
            fits = half_fits(ResponseModel(), Y, W, s, halves)
            out.append(cross_fitted_score_test(halves, fits, effect_directions(effects.make("dynamics")),
                                               n_surrogates=1000).p)
        return np.array(out)

    robust = p_values()
    assert np.sum(robust <= 0.005) == 0 and np.sum(robust <= 0.05) <= 3, robust
    monkeypatch.setattr(st, "HUBER_C", np.inf)
    raw = p_values()
    assert np.sum(raw <= 0.005) >= 3, raw  # the failure the robust residuals remove


def test_robust_residuals_clip_at_two_robust_sds_and_keep_missing():
    from rce_gtsam.diagnosis.score_test import robust_residuals
    rng = np.random.default_rng(0)
    R = rng.standard_normal((3, 2000))
    R[0, 5] = 40.0
    R[1, 7] = np.nan
    P = robust_residuals(R)
    assert np.isnan(P[1, 7]) and np.isfinite(P[0]).all()
    assert P[0, 5] == pytest.approx(2 * 1.4826 * np.nanmedian(np.abs(R[0])))
    assert 0.03 < np.mean(np.abs(R[2]) > np.abs(P[2]).max() - 1e-12) < 0.065  # ~4.6 % of a Gaussian clipped
    np.testing.assert_array_equal(robust_residuals(R, np.inf)[np.isfinite(R)], R[np.isfinite(R)])
