"""An implausible fit is never named, and a full-data test alone names nothing (rce_gtsam.diagnosis.plausibility,
score_test.is_significant); after a verdict the extended model's kappa is reported beside the rank-1 kappa
(rce_gtsam.kappa_report)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from rce_gtsam import effects
from rce_gtsam.diagnosis.plausibility import PlausibilityContext, at_bound, correlation_time, implausibility
from rce_gtsam.diagnosis.decision import is_significant

CTX = PlausibilityContext(q99_deflection_deg=6.0, correlation_time_frames=40.0, n_frames=450)


def test_at_bound_measures_closeness_on_the_ranges_scale():
    assert at_bound(0.031, 0.03, 2.0) == "lower"  # log range: 0.03..2
    assert at_bound(1.99, 0.03, 2.0) == "upper"
    assert at_bound(0.3, 0.03, 2.0) is None
    # a range open on one side has no scale: only the bound itself counts
    assert at_bound(0.0, 0.0, np.inf) == "lower"
    assert at_bound(0.0017, 0.0, np.inf) is None
    assert at_bound(float("nan"), 0.0, 1.0) is None


def test_correlation_time_is_where_the_excitation_forgets_itself():
    t = np.arange(3000)
    assert correlation_time(np.sin(2 * np.pi * t / 200)) == pytest.approx(50, abs=1)  # a quarter period
    rng = np.random.default_rng(0)
    box = correlation_time(np.convolve(rng.standard_normal(5000), np.ones(40) / 40, "same"))
    assert 35 <= box <= 80  # a box of width 40: zero from 40 frames on, where sampling noise wanders about 0


def _state(effect, n_edges=6, **params):
    return {"params": {k: np.asarray(v, float) if np.ndim(v) else float(v) for k, v in params.items()},
            "latents": {}}


def test_a_saturation_beyond_twice_the_deflections_seen_is_implausible():
    nl = effects.make("nonlinear")
    far = _state(nl, c=1 / 24.0 ** 2, z0=1.0)  # saturation 24 deg, deflections up to 6 deg
    near = _state(nl, c=1 / 5.0 ** 2, z0=1.0)
    assert any("saturation angle" in r for r in implausibility(nl, far, 6, CTX))
    assert implausibility(nl, near, 6, CTX) == ()


def test_an_oscillator_at_the_frame_rate_is_implausible_a_quasi_static_root_is_not():
    dyn = effects.make("dynamics")
    jitter = _state(dyn, omega_root=2 * np.pi, omega_tip=2 * np.pi * 0.95, zeta=0.03)
    reasons = implausibility(dyn, jitter, 6, CTX)
    assert any("natural period" in r for r in reasons) and any("zeta" in r for r in reasons)
    # root at the top bound (quasi-static: a physical limit), tip period 30 frames, damping inside its range
    real = _state(dyn, omega_root=2 * np.pi, omega_tip=2 * np.pi / 30, zeta=0.2)
    assert implausibility(dyn, real, 6, CTX) == ()


def test_a_lag_longer_than_the_excitations_memory_is_implausible():
    d = effects.make("delay")
    assert implausibility(d, _state(d, tau=15.0), 6, CTX) == ()
    assert any("correlation time" in r for r in implausibility(d, _state(d, tau=45.0), 6, CTX))
    assert any("bound" in r for r in implausibility(d, _state(d, tau=60.0), 6, CTX))


def test_a_lag_under_one_frame_is_implausible():
    """A tip lag under one frame interval is what a rolling shutter (rows read out over up to a frame) puts between
    root and tip; the one effect-free user-path render named delay had -0.96 frames, the lags found 8-17."""
    d = effects.make("delay")
    for tau in (-0.96, 0.5):
        assert any("rolling shutter" in r for r in implausibility(d, _state(d, tau=tau), 6, CTX)), tau
    assert implausibility(d, _state(d, tau=1.5), 6, CTX) == ()
    assert implausibility(d, _state(d, tau=-8.0), 6, CTX) == ()


def test_a_full_data_test_alone_names_nothing():
    # the case measured on the user's path: score p 0.0005, fold t 0.8 (a 0.2 % held-out gain)
    assert not is_significant(0.8, 2.95, 0.0005, 0.005, support_t=1.75)
    assert is_significant(2.0, 2.95, 0.0005, 0.005, support_t=1.75)  # the held-out frames agree
    assert is_significant(3.1, 2.95, None, 0.005, support_t=1.75)  # the fold t alone, as before
    assert not is_significant(2.0, 2.95, 0.2, 0.005, support_t=1.75)


def test_a_saturation_needs_both_of_its_tests():
    """The effect-free user-path recordings named nonlinear by one test alone (the fold t or the score test)
    are not named; both together are; effects without the flag keep either route."""
    assert effects.make("nonlinear").needs_both_tests and not effects.make("delay").needs_both_tests
    for t, p in [(4.5, 0.20), (3.2, 0.44), (3.1, 0.043), (2.0, 0.002)]:  # the measured cases
        assert not is_significant(t, 2.95, p, 0.005, support_t=1.75, both=True)
    assert is_significant(3.1, 2.95, 0.004, 0.005, support_t=1.75, both=True)
    assert is_significant(3.1, 2.95, None, 0.005, both=True)  # no score test: the fold t, as for any effect


def test_the_report_says_why_a_saturation_with_one_test_was_not_named():
    from types import SimpleNamespace

    from rce_gtsam.diagnosis.explain import both_tests_text

    one = SimpleNamespace(effect="nonlinear", evidence=3.08, extra={"score_p": 0.043, "score_threshold_p": 0.005,
                                                                    "threshold_t": 2.98})
    assert "named only where both its tests pass" in both_tests_text(one)
    assert both_tests_text(SimpleNamespace(effect="delay", evidence=3.08, extra=one.extra)) == ""
    neither = SimpleNamespace(effect="nonlinear", evidence=1.0, extra=one.extra)
    assert both_tests_text(neither) == ""


def test_the_diagnosis_asks_a_saturation_for_both_tests(monkeypatch):
    """diagnose hands each candidate's flag to the decision's significance route (a nonlinear fit on a branch is
    asked for both tests, the others for either)."""
    from rce_gtsam.diagnosis import decision
    from rce_gtsam.diagnosis.diagnose import diagnose
    from rce_gtsam.sim.simulate import SimulationConfig, simulate

    seen = []
    real = decision.significance_route

    def spy(tests, lv, both=False, excitation=None):
        seen.append(both)
        return real(tests, lv, both=both, excitation=excitation)

    monkeypatch.setattr(decision, "significance_route", spy)
    sim = simulate(SimulationConfig(seed=1, n_frames=200, n_nodes=10))
    Y = sim.response_true + np.random.default_rng(0).normal(0, 0.3, sim.response_true.shape)
    s = np.linspace(0.05, 1, Y.shape[0])
    d = diagnose(Y, root_distance=s, effects=["delay", "nonlinear"],
                 edge_nodes=[{i, i + 1, i + 2} for i in range(Y.shape[0])])
    assert d is not None
    assert sorted(set(seen)) == [False, True]  # delay: either test; nonlinear: both


@pytest.mark.slow
def test_run_reports_the_extended_kappa_beside_the_rank1_kappa(tmp_path):
    from rce_gtsam import analyze, load_graph, load_tracks
    from rce_gtsam.diagnosis.io import diagnose_result
    from rce_gtsam.kappa_report import kappa_after_verdict
    from pathlib import Path

    sample = Path(__file__).resolve().parents[1] / "data" / "sample_delay"  # a hidden delay, default strength
    graph = load_graph(sample / "graph.json")
    result = analyze(load_tracks(sample / "tracks.csv", graph), graph, seed=0, n_boot=40)
    diag = diagnose_result(result, effects=("delay",))
    assert diag.verdict == "delay"
    choice = kappa_after_verdict(result, diag)
    assert choice.column == "kappa_delay" and "delay" in choice.reason
    with_choice = dataclasses.replace(result, kappa_choice=choice)
    with_choice.write(tmp_path / "out")
    import pandas as pd
    df = pd.read_csv(tmp_path / "out" / "compliance_summary.csv")
    assert {"kappa", "kappa_delay", "kappa_delay_ci_low", "kappa_delay_ci_high", "report"} <= set(df.columns)
    ok = df["kappa_delay"].notna()
    assert ok.sum() >= 8 and (df.loc[ok, "kappa_delay_ci_low"] <= df.loc[ok, "kappa_delay"]).all()
    assert set(df["report"]) == {"kappa_delay"}
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["kappa_to_report"]["column"] == "kappa_delay"
    # the extended kappa is closer to the truth than the rank-1 kappa the lag biases
    truth = json.loads((sample / "truth.json").read_text())["kappa_true"]
    k_true = np.array([truth[f"{int(p)}->{int(c)}"] for p, c in zip(df.loc[ok, "parent"], df.loc[ok, "child"])])
    err = lambda k: float(np.sqrt(np.mean(np.log(np.abs(k) / k_true) ** 2)))  # noqa: E731
    assert err(df.loc[ok, "kappa_delay"].to_numpy()) <= err(df.loc[ok, "kappa"].to_numpy()) + 0.02


def test_the_tracker_is_named_where_the_misfit_sits_next_to_its_gaps():
    from types import SimpleNamespace

    from rce_gtsam.diagnosis.tracker_signature import near_gap_share, near_gaps, tracker_text
    rng = np.random.default_rng(0)
    E, T = 6, 300
    Y = rng.standard_normal((E, T))
    Y[4, 100:110] = np.nan
    Y[5, 200:220] = np.nan
    near = near_gaps(Y, 5)
    assert near[4, 95:100].all() and near[4, 110:115].all() and not near[4, 94] and not near[4, 105]
    R = 0.5 * rng.standard_normal((E, T))
    white = SimpleNamespace(residuals=np.where(np.isfinite(Y), R, np.nan), Y=Y)
    assert tracker_text(near_gap_share(white), [f"s{i}" for i in range(E)]) == ""
    R[near] *= 6.0  # the tracker's errors around the frames it lost the nodes in
    burst = SimpleNamespace(residuals=np.where(np.isfinite(Y), R, np.nan), Y=Y)
    text = tracker_text(near_gap_share(burst), [f"s{i}" for i in range(E)])
    assert "The tracker" in text and "s5" in text
