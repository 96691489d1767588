"""Marginal covariances: the block-banded selected inverse equals a dense inverse and GTSAM's own
``gtsam.Marginals`` (robust weights and the non-linear range prior included)."""

from __future__ import annotations

import dataclasses

import gtsam
import numpy as np
import pytest
import scipy.sparse as sp

from rce_gtsam.graph import BranchGraph
from rce_gtsam.smoothing.marginals import SingularInformationError, banded_selected_inverse, frame_bandwidth
from rce_gtsam.presets import SmootherConfig
from rce_gtsam.factors import frame_key, node_columns
from rce_gtsam.smoothing.smoother import build_problem, smooth_tracks
from rce_gtsam.tracks import Tracks


def random_block_banded_spd(T, n, b, seed):
    rng = np.random.default_rng(seed)
    M = np.zeros((T * n, T * n))
    for t in range(T):
        for k in range(0, b + 1):
            if t + k < T:
                M[t * n:(t + 1) * n, (t + k) * n:(t + k + 1) * n] = rng.normal(size=(n, n))
    # M is block upper-banded; M Mᵀ would widen the band, so use a sum of local SPD terms instead.
    A = np.zeros_like(M)
    for t in range(T):
        s = slice(t * n, min(T, t + b + 1) * n)
        B = rng.normal(size=(s.stop - s.start, s.stop - s.start))
        A[s, s] += B @ B.T / (s.stop - s.start)
    A += 0.1 * np.eye(T * n)
    return A


@pytest.mark.parametrize("T,n,b", [(7, 3, 0), (9, 4, 1), (11, 2, 2), (10, 2, 3), (1, 4, 0), (5, 3, 2)])
def test_selected_inverse_equals_dense_inverse(T, n, b):
    A = random_block_banded_spd(T, n, b, seed=T * 100 + n * 10 + b)
    S = sp.csr_matrix(A)
    assert frame_bandwidth(S, n) == min(b, T - 1)
    blocks = banded_selected_inverse(S, n)
    inv = np.linalg.inv(A)
    for t in range(T):
        np.testing.assert_allclose(blocks[t], inv[t * n:(t + 1) * n, t * n:(t + 1) * n], rtol=1e-9, atol=1e-12)


def test_singular_information_is_reported():
    A = np.eye(6)
    A[2, 2] = A[3, 3] = 0.0
    with pytest.raises(SingularInformationError, match="frame 1"):
        banded_selected_inverse(sp.csr_matrix(A), 2)


def test_rank_deficient_block_is_reported_not_inverted():
    """A direction with no information (here x0 + y0 only ever seen together) must raise, not return
    a rounding-level pivot's 1e20 variances."""
    A = np.eye(6)
    A[:2, :2] = [[1.0, 1.0], [1.0, 1.0]]
    A[2:4, :2] = A[:2, 2:4] = 0.1 * np.eye(2)
    with pytest.raises(SingularInformationError):
        banded_selected_inverse(sp.csr_matrix(A), 2)


def small_tree(n_frames=31, seed=0):
    rng = np.random.default_rng(seed)
    graph = BranchGraph.from_edges(5, [(5, 1), (1, 2), (1, 3)])
    base = {5: (0.0, 0.0), 1: (0.0, -20.0), 2: (-10.0, -35.0), 3: (12.0, -33.0)}
    gain = {5: 0, 1: 1, 2: 2, 3: 2}
    nodes = list(graph.nodes)
    t = np.arange(n_frames)
    xy = np.stack([np.stack([base[n][0] + 3 * gain[n] * np.sin(0.3 * t), base[n][1] + 0 * t], 1) for n in nodes])
    xy = xy + rng.normal(0, 0.5, xy.shape)
    xy[nodes.index(2), 10:14] = np.nan
    xy[nodes.index(3), 0:3] = np.nan
    return Tracks(node_ids=np.array(nodes), xy=xy, source="tree"), graph


@pytest.mark.parametrize("overrides", [
    {},                                                                  # paper: linear, offset prior
    {"edge_prior": "length"},                                            # range factors
    {"robust": "huber", "robust_k": 0.5, "along_across_ratio": 3.0},     # robust + anisotropic
    {"edge_prior": "length", "robust": "cauchy", "along_across_ratio": 2.0},
    {"acceleration_weight": 0.0},                                        # bandwidth 1
])
def test_marginals_equal_gtsam_marginals(overrides):
    tracks, graph = small_tree()
    cfg = SmootherConfig(presmooth_window=1, **overrides)
    res = smooth_tracks(tracks, graph, cfg)
    N, F = tracks.n_nodes, tracks.n_frames
    problem = build_problem(res.presmoothed, graph, cfg)
    solution = gtsam.Values()
    for t in range(F):
        solution.insert(frame_key(t), res.tracks.xy[:, t].ravel())
    marg = gtsam.Marginals(problem.graph, solution)
    for t in (0, 1, 12, 17, F - 1):
        joint = marg.marginalCovariance(frame_key(t))  # the frame state: all nodes at frame t
        # frame_cov is stored in float32 (rounding 6e-8); the per-node blocks in float64
        np.testing.assert_allclose(res.frame_cov[t], joint, rtol=3e-7, atol=3e-7 * np.abs(joint).max())
        for i in range(N):
            c = joint[node_columns(i), node_columns(i)]
            np.testing.assert_allclose(res.cov[i, t], c, rtol=1e-8, atol=1e-8 * np.abs(c).max())


def test_covariance_scales_with_measurement_noise():
    """Doubling every sigma (all weights / 4) multiplies every covariance by 4."""
    tracks, graph = small_tree()
    cfg = SmootherConfig(presmooth_window=1)
    a = smooth_tracks(tracks, graph, cfg)
    quarter = dataclasses.replace(cfg, measurement_weight=0.25, velocity_weight=cfg.velocity_weight / 4,
                                  acceleration_weight=cfg.acceleration_weight / 4, edge_weight=cfg.edge_weight / 4)
    b = smooth_tracks(tracks, graph, quarter)
    np.testing.assert_allclose(b.tracks.xy, a.tracks.xy, atol=1e-8)
    np.testing.assert_allclose(b.cov, 4 * a.cov, rtol=1e-8)
    np.testing.assert_allclose(b.frame_cov, 4 * a.frame_cov, rtol=3e-7)  # float32
