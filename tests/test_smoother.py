"""GTSAM smoother: contract of smooth_tracks, equality with the paper's linear least squares
(direct and LSQR), the non-linear options, and input errors."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import rce_gtsam
from rce_gtsam.errors import InputError
from rce_gtsam.graph import BranchGraph
from rce_gtsam.presets import PAPER, DEFAULT, SmootherConfig
from rce_gtsam.smoothing.presmooth import moving_average
from rce_gtsam.smoothing.smoother import SmoothedTracks, initial_positions, node_tangents, smooth_tracks
from rce_gtsam.smoothing.reference import paper_system, reference_smooth, solve_direct, solve_lsqr
from rce_gtsam.tracks import Tracks


def tree_tracks(n_frames=60, seed=0, gaps=True, noise=0.5):
    """A small branching tree (root 5 -> 1 -> {2, 3}, 3 -> 4) swaying, with occlusion gaps."""
    rng = np.random.default_rng(seed)
    graph = BranchGraph.from_edges(5, [[5, 1], [1, 2], [1, 3], [3, 4]])
    rest = {5: (300, 400), 1: (300, 380), 2: (285, 362), 3: (316, 363), 4: (330, 350)}
    gain = {5: 0, 1: 1, 2: 2, 3: 2, 4: 3}
    t = np.arange(n_frames)
    sway = 2.0 * np.sin(2 * np.pi * t / 25)
    nodes = list(graph.nodes)
    xy = np.stack([np.stack([rest[n][0] + gain[n] * sway, rest[n][1] + 0.2 * gain[n] * sway], 1)
                   for n in nodes]).astype(float)
    xy += rng.normal(0, noise, xy.shape)
    if gaps:
        xy[nodes.index(2), 20:26] = np.nan
        xy[nodes.index(4), 0:3] = np.nan
        xy[nodes.index(4), -4:] = np.nan
    return Tracks(node_ids=np.array(nodes), xy=xy, source="synthetic tree"), graph


@pytest.fixture(scope="module")
def tree():
    return tree_tracks()


def test_contract_paper_config(tree):
    tracks, graph = tree
    res = smooth_tracks(tracks, graph, PAPER.smoother)
    assert isinstance(res, SmoothedTracks)
    N, F = tracks.n_nodes, tracks.n_frames
    assert res.tracks.xy.shape == (N, F, 2) and np.isfinite(res.tracks.xy).all()
    np.testing.assert_array_equal(res.tracks.node_ids, tracks.node_ids)
    np.testing.assert_array_equal(res.observed, tracks.observed)
    np.testing.assert_allclose(res.presmoothed.xy, moving_average(tracks, 5).xy, equal_nan=True)
    assert res.cov.shape == (N, F, 2, 2) and res.frame_cov.shape == (F, 2 * N, 2 * N)
    r = res.report
    assert r.converged and r.iterations == 1 and r.final_error < r.initial_error
    assert r.n_variables == F  # one frame state (2N pixels) per frame
    n_obs_frames = int(tracks.observed.any(axis=0).sum())
    assert r.n_factors == n_obs_frames + (F - 1) + (F - 2) + F  # measurement, velocity, acceleration, edge
    # joint_cov: reordering and consistency with the per-node blocks
    i2, i4 = tracks.index(2), tracks.index(4)
    J = res.joint_cov([4, 2])
    assert J.shape == (F, 4, 4)
    np.testing.assert_allclose(J[:, :2, :2], res.cov[i4])
    np.testing.assert_allclose(J[:, 2:, 2:], res.cov[i2])
    np.testing.assert_allclose(J[:, :2, 2:], res.frame_cov[:, 2 * i4:2 * i4 + 2, 2 * i2:2 * i2 + 2])
    # unobserved frames are less certain than observed ones of the same node
    var = np.trace(res.cov[i2], axis1=1, axis2=2)
    assert var[22] > var[5]


@pytest.mark.parametrize("window", [1, 5])
def test_gtsam_equals_direct_and_lsqr(tree, window):
    tracks, graph = tree
    cfg = dataclasses.replace(PAPER.smoother, presmooth_window=window, marginals=False)
    res = smooth_tracks(tracks, graph, cfg)
    direct = reference_smooth(tracks, graph, cfg, "direct")
    assert np.abs(res.tracks.xy - direct.xy).max() < 1e-6
    lsqr = reference_smooth(tracks, graph, cfg, "lsqr")
    assert np.abs(res.tracks.xy - lsqr.xy).max() < 1e-2  # LSQR stops early at atol=btol=1e-6


def test_reference_system_matches_paper_cost(tree):
    """The assembled rows reproduce the paper's J by direct evaluation at a random point."""
    tracks, graph = tree
    cfg = PAPER.smoother
    pre = moving_average(tracks, 5)
    sysm = paper_system(pre, graph, cfg)
    rng = np.random.default_rng(3)
    P = initial_positions(pre) + rng.normal(0, 1, (tracks.n_nodes, tracks.n_frames, 2))
    p = P.reshape(-1, 2)
    J_rows = np.sum((sysm.A @ p - sysm.b) ** 2)
    obs = pre.observed
    J = cfg.measurement_weight * np.sum((P - np.nan_to_num(pre.xy))[obs] ** 2)
    J += cfg.velocity_weight * np.sum(np.diff(P, axis=1) ** 2)
    J += cfg.acceleration_weight * np.sum((P[:, :-2] - 2 * P[:, 1:-1] + P[:, 2:]) ** 2)
    for a, b in graph.edges:
        ia, ib = pre.index(a), pre.index(b)
        t0 = np.flatnonzero(obs[ia] & obs[ib])[0]
        d = pre.xy[ib, t0] - pre.xy[ia, t0]
        J += cfg.edge_weight * np.sum((P[ib] - P[ia] - d) ** 2)
    assert J_rows == pytest.approx(J, rel=1e-12)


def test_plant2_paper_gtsam_equals_direct_solve(shared_data):
    d = shared_data / "plant_2"
    graph = rce_gtsam.load_graph(d / "branch_graph.json")
    tracks = rce_gtsam.load_tracks(d / "tapir_tracks.csv", graph)
    cfg = dataclasses.replace(PAPER.smoother, marginals=False)
    res = smooth_tracks(tracks, graph, cfg)
    pre = moving_average(tracks, cfg.presmooth_window)
    system = paper_system(pre, graph, cfg)
    direct = solve_direct(system)
    assert res.report.converged
    assert np.abs(res.tracks.xy - direct.xy).max() < 1e-6
    lsqr = solve_lsqr(system)
    assert np.abs(res.tracks.xy - lsqr.xy)[res.observed].max() < 5e-3


def test_optimality_check_separates_solution_from_start(tree):
    import gtsam

    from rce_gtsam.smoothing.marginals import whitened_jacobian
    from rce_gtsam.smoothing.smoother import LINEAR_OPTIMALITY_TOL, build_problem, normal_equation_residual, optimize

    tracks, graph = tree
    problem = build_problem(moving_average(tracks, 5), graph, PAPER.smoother)
    result, _ = optimize(problem, linear=True)
    for values, small in ((result, True), (problem.initial, False)):
        A, b = whitened_jacobian(problem.graph.linearize(values), n_cols=int(values.dim()))
        r = normal_equation_residual(A, b)
        assert (r < LINEAR_OPTIMALITY_TOL) == small, r
    assert isinstance(result, gtsam.Values)


def test_zero_weights_drop_factor_families(tree):
    tracks, graph = tree
    cfg = SmootherConfig(presmooth_window=1, velocity_weight=0.0, acceleration_weight=0.0, marginals=True)
    res = smooth_tracks(tracks, graph, cfg)
    n_obs_frames = int(tracks.observed.any(axis=0).sum())
    assert res.report.n_factors == n_obs_frames + tracks.n_frames
    direct = reference_smooth(tracks, graph, cfg, "direct")
    np.testing.assert_allclose(res.tracks.xy, direct.xy, atol=1e-6)


def test_sigma_px_sets_the_measurement_weight(tree):
    tracks, graph = tree
    sigma = np.where(tracks.observed, 0.5, np.nan)
    sigma[0, 10] = 5.0  # one uncertain observation
    t2 = Tracks(node_ids=tracks.node_ids, xy=tracks.xy, sigma_px=sigma, source="s")
    cfg = dataclasses.replace(PAPER.smoother, presmooth_window=1, marginals=False)
    res = smooth_tracks(t2, graph, cfg)
    np.testing.assert_allclose(res.tracks.xy, reference_smooth(t2, graph, cfg, "direct").xy, atol=1e-6)


def test_length_prior_config_runs_and_keeps_lengths(tree):
    tracks, graph = tree
    cfg = dataclasses.replace(DEFAULT.smoother, edge_prior="length", edge_weight=0.45)
    res = smooth_tracks(tracks, graph, cfg)
    assert res.report.converged and res.report.iterations >= 2
    assert np.isfinite(res.cov).all()
    for a, b in graph.edges:
        ia, ib = tracks.index(a), tracks.index(b)
        raw = np.linalg.norm(tracks.xy[ib] - tracks.xy[ia], axis=1)
        sm = np.linalg.norm(res.tracks.xy[ib] - res.tracks.xy[ia], axis=1)
        assert np.nanstd(sm) < np.nanstd(raw)


def test_robust_loss_rejects_a_glitch():
    tracks, graph = tree_tracks(gaps=False, noise=0.2)
    xy = tracks.xy.copy()
    i = tracks.index(4)
    truth = xy[i, 30].copy()
    xy[i, 30] += (15.0, -10.0)  # a tracker glitch
    glitchy = Tracks(node_ids=tracks.node_ids, xy=xy, source="glitch")
    base = SmootherConfig(presmooth_window=1, edge_prior="length", marginals=False)
    err = {}
    for robust in (None, "huber", "cauchy"):
        res = smooth_tracks(glitchy, graph, dataclasses.replace(base, robust=robust))
        err[robust] = np.linalg.norm(res.tracks.xy[i, 30] - truth)
    assert err["huber"] < 0.6 * err[None]
    assert err["cauchy"] < 0.6 * err[None]


def test_tangents_follow_the_branch(tree):
    tracks, graph = tree
    tan = node_tangents(moving_average(tracks, 5), graph)
    np.testing.assert_allclose(np.linalg.norm(tan, axis=1), 1.0)
    # tip 2's only edge is 1 -> 2: direction (-15, -18) roughly
    u = np.array([-15.0, -18.0]) / np.hypot(15, 18)
    assert tan[tracks.index(2)] @ u > 0.95


def test_initial_positions_interpolate_gaps():
    xy = np.full((1, 6, 2), np.nan)
    xy[0, 1] = (0, 0)
    xy[0, 4] = (3, 6)
    init = initial_positions(Tracks(node_ids=np.array([0]), xy=xy))
    np.testing.assert_allclose(init[0, :, 0], [0, 0, 1, 2, 3, 3])
    np.testing.assert_allclose(init[0, :, 1], [0, 0, 2, 4, 6, 6])


def test_input_errors(tree):
    tracks, graph = tree
    other = BranchGraph.from_edges(5, [[5, 1], [1, 2], [1, 3], [3, 7]], source="g.json")
    with pytest.raises(InputError, match="disagree"):
        smooth_tracks(tracks, other, PAPER.smoother)
    xy = tracks.xy.copy()
    i2, i1 = tracks.index(2), tracks.index(1)
    xy[i2, :30] = np.nan
    xy[i1, 30:] = np.nan
    bad = Tracks(node_ids=tracks.node_ids, xy=xy, source="t.csv")
    with pytest.raises(InputError, match=r"never observed in the same frame") as e:
        smooth_tracks(bad, graph, PAPER.smoother)
    assert e.value.where == "edge [1, 2]"
    full, _ = tree_tracks(gaps=False)
    gap = full.xy.copy()
    gap[full.index(4), 7] = np.nan
    no_time = SmootherConfig(presmooth_window=1, velocity_weight=0.0, acceleration_weight=0.0, edge_prior="length")
    with pytest.raises(InputError, match="not determined") as e:
        smooth_tracks(Tracks(node_ids=tracks.node_ids, xy=gap, source="t.csv"), graph, no_time)
    assert e.value.where == "node 4, frame 7" and e.value.source == "t.csv"
    one = full.xy.copy()
    one[full.index(4), 1:] = np.nan
    accel_only = SmootherConfig(presmooth_window=1, velocity_weight=0.0, acceleration_weight=20.0)
    with pytest.raises(InputError, match="fewer than 2 frames") as e:
        smooth_tracks(Tracks(node_ids=full.node_ids, xy=one, source="t.csv"), graph, accel_only)
    assert e.value.where == "node 4"
    with pytest.raises(ValueError, match="edge_prior"):
        smooth_tracks(tracks, graph, SmootherConfig(edge_prior="rigid"))


def test_default_config_is_linear_and_solved_in_one_step(tree):
    tracks, graph = tree
    res = smooth_tracks(tracks, graph, DEFAULT.smoother)
    assert res.report.converged and res.report.iterations == 1
    assert np.isfinite(res.cov).all()
