"""Correlated (generalised least squares) rank-1 fit and the bend covariance it uses."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rce_gtsam.bending.angles import compute_bending
from rce_gtsam.model.compliance import fit_rank1, frame_precisions
from rce_gtsam.model.uncertainty import bootstrap_kappa
from rce_gtsam.graph import BranchGraph
from rce_gtsam.presets import BendingConfig, ComplianceConfig

COUNT = ComplianceConfig(response="signed", prior_strength=0.0, n_iter=500, tol=1e-11)


def chain_graph(n):
    return BranchGraph.from_edges(0, [(i, i + 1) for i in range(n - 1)])


def node_noise_bends(seed, E=10, T=600, sigma_px=0.5, seg_px=20.0):
    """Signed bend responses of a straight chain whose nodes carry white pixel noise: kappa_e z_t plus the
    angle errors the node noise causes (neighbouring bends share nodes: correlation about -0.65)."""
    rng = np.random.default_rng(seed)
    kappa = np.exp(rng.normal(0, 0.5, E))
    kappa /= np.exp(np.log(kappa).mean())
    z = np.convolve(rng.normal(0, 1, T + 40), np.ones(40) / np.sqrt(40), "valid")[:T] * 2.0
    n = E + 2
    xy = np.zeros((n, T, 2))
    xy[:, :, 0] = np.arange(n)[:, None] * seg_px
    xy += rng.normal(0, sigma_px, xy.shape)
    # angle error of bend k (nodes k, k+1, k+2) of a straight chain to first order, in degrees
    dy = xy[:, :, 1]
    err = np.degrees((dy[2:] - dy[1:-1]) / seg_px - (dy[1:-1] - dy[:-2]) / seg_px)
    Y = kappa[:, None] * z[None, :] + err
    # the exact covariance of those errors: second differences of independent node offsets
    D = np.zeros((E, n))
    for k in range(E):
        D[k, k:k + 3] = np.array([1.0, -2.0, 1.0]) * np.degrees(1.0 / seg_px)
    C = sigma_px**2 * D @ D.T
    return kappa, Y, np.broadcast_to(C, (T, E, E)).copy()


def log_rmse(k, k_true):
    a, b = np.log(k), np.log(k_true)
    return float(np.sqrt(np.mean(((a - a.mean()) - (b - b.mean())) ** 2)))


def test_precision_inverts_the_observed_block_and_zeroes_missing_entries():
    rng = np.random.default_rng(0)
    T, E = 30, 5
    A = rng.normal(size=(T, E, E))
    C = A @ np.transpose(A, (0, 2, 1)) + 0.5 * np.eye(E)
    observed = rng.random((E, T)) > 0.3
    P = frame_precisions(C, observed)
    for t in range(T):
        o = observed[:, t]
        np.testing.assert_allclose(P[t][np.ix_(o, o)] @ C[t][np.ix_(o, o)], np.eye(o.sum()), atol=1e-9)
        assert np.all(P[t][~o] == 0) and np.all(P[t][:, ~o] == 0)


def test_unusable_covariance_falls_back_to_inverse_variances():
    C = np.array([[[1.0, 2.0], [2.0, 1.0]], [[4.0, np.nan], [np.nan, 1.0]]])  # indefinite; NaN entry
    P = frame_precisions(C, np.ones((2, 2), dtype=bool))
    np.testing.assert_allclose(P[0], np.eye(2))
    np.testing.assert_allclose(P[1], np.diag([0.25, 1.0]))


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_diagonal_precision_gives_the_weighted_fit(seed):
    """Without correlations generalised least squares is weighted least squares."""
    rng = np.random.default_rng(seed)
    E, T = 6, 200
    k = np.exp(rng.normal(0, 0.5, E))
    Y = k[:, None] * rng.normal(0, 2, T)[None] + rng.normal(0, 0.5, (E, T))
    Y[rng.random((E, T)) < 0.1] = np.nan
    W = np.where(np.isfinite(Y), rng.uniform(0.2, 2.0, (E, T)), 0.0)
    P = np.zeros((T, E, E))
    P[:, np.arange(E), np.arange(E)] = W.T
    wls = fit_rank1(Y, COUNT, W)
    gls = fit_rank1(Y, COUNT, precision=P)
    np.testing.assert_allclose(gls.kappa, wls.kappa, rtol=1e-6)
    np.testing.assert_allclose(gls.z, wls.z, rtol=1e-5, atol=1e-8)


def test_correlated_fit_beats_the_weighted_fit_under_shared_node_noise():
    """Bend errors from node noise are negatively correlated between neighbours; using that lowers kappa's
    error. Fails if the precision is ignored or mis-assembled (both fits would then agree)."""
    cfg = ComplianceConfig(response="signed", shrinkage="precision", weighted=True, correlated=True)
    gls_err, wls_err = [], []
    for seed in range(8):
        k_true, Y, C = node_noise_bends(seed)
        P = frame_precisions(C, np.isfinite(Y))
        W = 1.0 / np.diagonal(C, axis1=1, axis2=2).T
        gls_err.append(log_rmse(fit_rank1(Y, cfg, precision=P).kappa, k_true))
        wls_err.append(log_rmse(fit_rank1(Y, cfg, W).kappa, k_true))
    assert np.median(gls_err) < 0.8 * np.median(wls_err), (gls_err, wls_err)


@pytest.mark.parametrize("scheme", ["phase", "block"])
def test_correlated_bootstrap_runs_and_brackets_the_estimate(scheme):
    cfg = ComplianceConfig(response="signed", shrinkage="precision", weighted=True, correlated=True,
                           bootstrap=scheme, n_boot=60)
    k_true, Y, C = node_noise_bends(3, T=400)
    P = frame_precisions(C, np.isfinite(Y))
    fit = fit_rank1(Y, cfg, precision=P)
    ci = bootstrap_kappa(Y, cfg, fit=fit, precision=P)
    assert ci is not None and ci.samples.shape == (60, Y.shape[0])
    assert np.all(ci.low <= fit.kappa * 1.05) and np.all(ci.high >= fit.kappa / 1.05)


def test_bend_covariance_matches_monte_carlo_and_its_diagonal_is_the_variance():
    """Propagated (F, B, B) covariance against the empirical covariance of angles under node noise."""
    rng = np.random.default_rng(1)
    n, draws = 5, 20000
    heading = np.radians(np.cumsum([0.0, 30.0, -35.0, 40.0]))  # turns of 30-75 degrees: far from straight,
    steps = 25.0 * np.c_[np.cos(heading), np.sin(heading)]     # where the unsigned angle folds
    base = np.vstack([np.zeros(2), np.cumsum(steps, axis=0)])
    cov_node = np.diag(rng.uniform(0.2, 0.8, 2 * n) ** 2)
    xy = base[:, None, :] + rng.multivariate_normal(np.zeros(2 * n), cov_node, draws).reshape(draws, n, 2).transpose(1, 0, 2)
    graph = chain_graph(n)
    frame_cov = np.broadcast_to(cov_node, (draws, 2 * n, 2 * n))
    for signed in (True, False):
        res = compute_bending(xy, list(range(n)), graph, BendingConfig(signed=signed, mad_threshold=1e9), frame_cov=frame_cov)
        emp = np.cov(res.angle_deg)
        pred = np.mean(res.covariance_deg2, axis=0)
        np.testing.assert_allclose(pred, emp, rtol=0.1, atol=0.03 * np.abs(emp).max())
        np.testing.assert_allclose(np.diagonal(res.covariance_deg2, axis1=1, axis2=2), res.variance_deg2.T, rtol=1e-9)
        if signed:  # neighbouring bends share two nodes: a node's error turns them opposite ways
            assert pred[0, 1] < 0
        else:  # the interior angle flips the sign of the gradient with the turn's sign (+30 then -35 deg)
            assert pred[0, 1] > 0


def test_analyze_with_the_correlated_fit_end_to_end():
    from rce_gtsam.pipeline import analyze
    from rce_gtsam.presets import DEFAULT
    from rce_gtsam.sim.simulate import SimulationConfig, simulate

    sim = simulate(SimulationConfig(seed=2, n_frames=240))
    preset = DEFAULT.with_(compliance={"correlated": True, "n_boot": 30})
    res = analyze(sim.tracks, sim.graph, preset=preset)
    P = res.response.precision
    T, E = res.response.Y.shape[1], res.response.Y.shape[0]
    assert P.shape == (T, E, E) and np.allclose(P, np.transpose(P, (0, 2, 1)))
    k_true = np.array([sim.kappa_true[e] for e in res.response.edges])
    assert np.corrcoef(np.log(res.fit.kappa), np.log(k_true))[0, 1] > 0.8
    assert res.ci is not None and np.all(res.ci.low <= res.ci.high)
    with pytest.raises(ValueError, match="correlated fit has no effect terms"):
        analyze(sim.tracks, sim.graph, preset=preset, effects=("delay",))
