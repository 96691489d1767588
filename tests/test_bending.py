"""Bend angles, their gradient, the MAD mask and variance propagation."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rce_gtsam.bending.angles import angle_gradient, bend_angles, compute_bending, mad_inliers
from rce_gtsam.graph import BranchGraph
from rce_gtsam.presets import BendingConfig

P = np.array


def test_known_angles():
    g, j = P([0.0, 0.0]), P([1.0, 0.0])
    straight, left = P([2.0, 0.0]), P([1.0, 1.0])
    assert bend_angles(g, j, straight, signed=False) == pytest.approx(180.0)
    assert bend_angles(g, j, straight, signed=True) == pytest.approx(0.0)
    assert bend_angles(g, j, left, signed=False) == pytest.approx(90.0)
    assert bend_angles(g, j, left, signed=True) == pytest.approx(90.0)
    assert bend_angles(g, j, P([1.0, -1.0]), signed=True) == pytest.approx(-90.0)
    assert np.isnan(bend_angles(g, g, left, signed=True))


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(-50, 50), min_size=6, max_size=6))
def test_gradient_matches_finite_differences(c):
    pts = np.array(c).reshape(3, 2)
    if min(np.linalg.norm(pts[1] - pts[0]), np.linalg.norm(pts[2] - pts[1])) < 1.0:
        return
    f = lambda q: np.radians(bend_angles(q[0], q[1], q[2], signed=True))
    grad = angle_gradient(pts[0], pts[1], pts[2])
    h = 1e-6
    num = np.zeros(6)
    for i in range(6):
        d = np.zeros(6); d[i] = h
        num[i] = (f((pts.ravel() + d).reshape(3, 2)) - f((pts.ravel() - d).reshape(3, 2))) / (2 * h)
    if np.abs(np.abs(f(pts)) - np.pi) < 1e-3:
        return  # atan2 branch cut
    np.testing.assert_allclose(grad, num, atol=1e-6)


def test_mad_mask():
    d = np.zeros((1, 100)); d[0] = np.random.default_rng(0).normal(0, 1, 100); d[0, 10] = 50.0; d[0, 20] = np.nan
    m = mad_inliers(d, 3.5)
    assert not m[0, 10] and not m[0, 20] and m.sum() >= 95
    flat = np.zeros((1, 10))
    assert mad_inliers(flat, 3.5).all()


def test_variance_propagation_matches_monte_carlo():
    graph = BranchGraph.from_edges(0, [[0, 1], [1, 2]])
    base = np.array([[0.0, 0.0], [20.0, 0.0], [38.0, 6.0]])
    cov6 = np.diag([0.5, 1.0, 0.3, 0.2, 1.5, 0.4]); cov6[0, 2] = cov6[2, 0] = 0.1
    rng = np.random.default_rng(0)
    samples = rng.multivariate_normal(base.ravel(), cov6, size=20000).reshape(-1, 3, 2)
    xy = np.transpose(samples, (1, 0, 2))  # (3 nodes, F samples, 2)
    frame_cov = np.broadcast_to(cov6, (xy.shape[1], 6, 6))
    res = compute_bending(xy, [0, 1, 2], graph, BendingConfig(signed=True), frame_cov=frame_cov)
    mc_var = np.var(res.angle_deg[0])
    assert res.variance_deg2[0, 0] == pytest.approx(mc_var, rel=0.05)


def test_rest_first_and_median():
    graph = BranchGraph.from_edges(0, [[0, 1], [1, 2]])
    F = 50
    xy = np.zeros((3, F, 2)); xy[1, :, 0] = 10; xy[2, :, 0] = 20
    xy[2, 0, 1] = 3.0  # deflected first frame
    first = compute_bending(xy, [0, 1, 2], graph, BendingConfig(signed=True, rest="first"))
    med = compute_bending(xy, [0, 1, 2], graph, BendingConfig(signed=True, rest="median"))
    assert med.rest_deg[0] == pytest.approx(0.0)
    assert abs(first.rest_deg[0]) > 10
    assert np.nanmedian(np.abs(first.delta_deg)) > 10 and np.nanmedian(np.abs(med.delta_deg)) == 0
