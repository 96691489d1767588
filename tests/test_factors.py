"""Each smoother factor: the GTSAM factor's error equals the documented residual (whitened, summed
over the nodes / edges / observations of its frame state), and the Jacobian GTSAM linearises to equals
central differences of that whitened residual with respect to the frame states."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from rce_gtsam.factors import (AccelerationFactor, EdgeLengthFactor, EdgeOffsetFactor,
                               MeasurementFactor, RobustLoss, VelocityFactor, frame_key, node_columns,
                               oriented_covariance, sigma_from_weight, zero_values)

RNG = np.random.default_rng(7)
N = 3                                     # nodes per frame state
KEYS = [frame_key(t) for t in range(3)]
ZEROS = zero_values(KEYS, N)


def states(n: int = 3, scale: float = 10.0) -> list[np.ndarray]:
    """``n`` random frame states (2N pixels each)."""
    return [RNG.normal(size=2 * N) * scale for _ in range(n)]


def values_of(xs) -> gtsam.Values:
    v = gtsam.Values()
    for k, x in zip(KEYS, xs):
        v.insert(k, np.asarray(x, dtype=float))
    return v


def numeric_jacobian(fn, xs, h=1e-6) -> np.ndarray:
    """Central differences of fn(list of frame states) -> (m,), stacked over all states: (m, 2N len(xs))."""
    cols = []
    for j in range(len(xs)):
        for c in range(2 * N):
            plus = [np.array(x, dtype=float) for x in xs]
            minus = [np.array(x, dtype=float) for x in xs]
            plus[j][c] += h
            minus[j][c] -= h
            cols.append((fn(plus) - fn(minus)) / (2 * h))
    return np.stack(cols, axis=1)


def check_factor(factor, xs, whitened_fn, cost=None):
    """error == cost (default 0.5 |e|^2) and GTSAM's linearisation (A, b) == (de/dX numerically, -e)."""
    vals = values_of(xs)
    e = whitened_fn(xs)
    assert factor.error(vals) == pytest.approx(0.5 * e @ e if cost is None else cost, rel=1e-9, abs=1e-12)
    A, b = factor.linearize(vals).jacobian()
    np.testing.assert_allclose(A, numeric_jacobian(whitened_fn, xs), atol=1e-6, rtol=1e-6)
    np.testing.assert_allclose(b, -e, atol=1e-9, rtol=1e-9)


def node(x, i):
    return x[node_columns(i)]


def test_sigma_from_weight_rejects_non_positive():
    assert sigma_from_weight(4.0) == pytest.approx(0.5)
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError):
            sigma_from_weight(bad)


@pytest.mark.parametrize("sigma", [1.0, 0.4])
def test_measurement_isotropic(sigma):
    x = states(1)
    rows = np.array([0, 2])                       # node 1 unobserved at this frame
    m = RNG.normal(size=(2, 2)) * 10
    W = MeasurementFactor.sqrt_information(sigma)
    np.testing.assert_allclose(W, np.eye(2) / sigma)
    f = MeasurementFactor.create(KEYS[0], N, rows, m, W, ZEROS)
    white = lambda X: np.concatenate([W @ MeasurementFactor.residual(node(X[0], i), mj) for i, mj in zip(rows, m)])  # noqa: E731
    check_factor(f, x, white)
    # cost = 0.5 |r|^2 / sigma^2 (paper: w r^2 with w = 1/sigma^2, up to GTSAM's common factor 1/2)
    r = np.concatenate([node(x[0], i) - mj for i, mj in zip(rows, m)])
    assert f.error(values_of(x)) == pytest.approx(0.5 * r @ r / sigma ** 2)
    A, _ = f.linearize(values_of(x)).jacobian()
    assert not A[:, 2:4].any()                    # the unobserved node is untouched


def test_measurement_anisotropic_per_observation_sigma():
    sigma, ratio = 0.7, 3.0
    tangent = np.array([np.cos(0.4), np.sin(0.4)])
    W1 = MeasurementFactor.sqrt_information(sigma, tangent, ratio)
    cov = np.linalg.inv(W1.T @ W1)
    np.testing.assert_allclose(cov, oriented_covariance(ratio * sigma, sigma, tangent))
    assert tangent @ cov @ tangent == pytest.approx((ratio * sigma) ** 2)  # along the branch
    normal = np.array([-tangent[1], tangent[0]])
    assert normal @ cov @ normal == pytest.approx(sigma ** 2)  # across
    W = np.stack([W1, MeasurementFactor.sqrt_information(2.0), W1 / 4])
    rows, m = np.arange(3), RNG.normal(size=(3, 2)) * 10
    f = MeasurementFactor.create(KEYS[0], N, rows, m, W, ZEROS)
    white = lambda X: np.concatenate([W[i] @ (node(X[0], i) - m[i]) for i in rows])  # noqa: E731
    check_factor(f, states(1), white)


@pytest.mark.parametrize("robust,k", [("huber", 1.345), ("cauchy", 0.8)])
def test_measurement_robust_loss_per_observation(robust, k):
    """error = sum_j rho(|W r_j|) with GTSAM's own mEstimator rho; the Jacobian is that of the
    corrected residual; an inlier (|e| << k) contributes as without a robust loss."""
    sigma = 0.5
    W = MeasurementFactor.sqrt_information(sigma)
    m = np.array([[10.0, 20.0], [30.0, 40.0], [50.0, 60.0]])
    x = [m.ravel() + np.array([0.05, -0.02, 3.0, -4.0, 0.8, 0.6])]   # inlier, outlier, near threshold
    f = MeasurementFactor.create(KEYS[0], N, np.arange(3), m, W, ZEROS, robust, k)
    est = (gtsam.noiseModel.mEstimator.Huber if robust == "huber" else gtsam.noiseModel.mEstimator.Cauchy).Create(k)
    loss = RobustLoss(robust, k)
    u = np.linalg.norm((x[0].reshape(3, 2) - m) / sigma, axis=1)
    np.testing.assert_allclose(loss.rho(u), [est.loss(float(v)) for v in u], rtol=1e-12)
    np.testing.assert_allclose(loss.rho_prime(u), [est.weight(float(v)) * v for v in u], rtol=1e-12)
    assert est.weight(float(u[1])) < 0.5                                 # the outlier is down-weighted

    def corrected(X):
        e = (X[0].reshape(3, 2) - m) / sigma
        return loss.correct(e)[0].ravel()

    check_factor(f, x, corrected, cost=float(loss.rho(u).sum()))
    A, _ = f.linearize(values_of(x)).jacobian()
    # inlier row: plain whitening (Huber is exactly quadratic below k; Cauchy nearly so at u << k)
    np.testing.assert_allclose(A[:2, :2], W, rtol=1e-9 if robust == "huber" else 0.03, atol=0.01)


def test_robust_loss_rejects_unknown_names_and_thresholds():
    with pytest.raises(ValueError, match="robust"):
        RobustLoss("tukey-ish", 1.0)
    with pytest.raises(ValueError, match="threshold"):
        RobustLoss("huber", 0.0)
    with pytest.raises(ValueError, match="sigma"):
        MeasurementFactor.sqrt_information(0.0)


def test_velocity():
    xs = states(2)
    w = 0.35
    f = VelocityFactor.create(KEYS[0], KEYS[1], N, w, ZEROS)
    white = lambda X: np.sqrt(w) * np.concatenate([VelocityFactor.residual(node(X[0], i), node(X[1], i))  # noqa: E731
                                                   for i in range(N)])
    check_factor(f, xs, white)
    p0, p1 = node(xs[0], 0), node(xs[1], 0)
    H = numeric_jacobian(lambda X: VelocityFactor.residual(node(X[0], 0), node(X[1], 0)), xs)
    np.testing.assert_allclose(np.hstack(VelocityFactor.jacobians(p0, p1)), H[:, [0, 1, 6, 7]], atol=1e-8)


def test_acceleration_linear_container_is_exact():
    xs = states(3)
    w = 0.2
    f = AccelerationFactor.create(*KEYS, N, w, ZEROS)
    white = lambda X: np.sqrt(w) * np.concatenate([AccelerationFactor.residual(*(node(x, i) for x in X))  # noqa: E731
                                                   for i in range(N)])
    check_factor(f, xs, white)
    H = numeric_jacobian(lambda X: AccelerationFactor.residual(*(node(x, 1) for x in X)), xs)
    np.testing.assert_allclose(np.hstack(AccelerationFactor.jacobians(*(node(x, 1) for x in xs))),
                               H[:, [2, 3, 8, 9, 14, 15]], atol=1e-8)
    # far from the zero linearisation point it is still exact (the states form a vector space)
    check_factor(f, [x + 1e4 for x in xs], white)


def test_edge_offset():
    x = states(1)
    edges = np.array([[0, 1], [1, 2]])
    d = np.array([[3.0, -20.0], [1.0, 2.0]])
    w = 0.45
    f = EdgeOffsetFactor.create(KEYS[0], N, edges, d, w, ZEROS)
    white = lambda X: np.sqrt(w) * np.concatenate([EdgeOffsetFactor.residual(node(X[0], a), node(X[0], b), dj)  # noqa: E731
                                                   for (a, b), dj in zip(edges, d)])
    check_factor(f, x, white)


def test_edge_offset_rest_is_first_common_frame():
    a = np.array([[np.nan, np.nan], [0.0, 0.0], [1.0, 1.0]])
    b = np.array([[5.0, 5.0], [3.0, 4.0], [9.0, 9.0]])
    np.testing.assert_allclose(EdgeOffsetFactor.rest_offset(a, b), [3.0, 4.0])
    with pytest.raises(ValueError):
        EdgeOffsetFactor.rest_offset(a[:1], b[:1])


def test_edge_length():
    x = [np.array([10.0, 20.0, 13.0, 2.0, 30.0, -5.0])]
    edges = np.array([[0, 1], [1, 2]])
    L, w = np.array([17.0, 20.0]), 0.45
    f = EdgeLengthFactor.create(KEYS[0], N, edges, L, w)
    white = lambda X: np.sqrt(w) * np.concatenate([EdgeLengthFactor.residual(node(X[0], a), node(X[0], b), Lj)  # noqa: E731
                                                   for (a, b), Lj in zip(edges, L)])
    check_factor(f, x, white)
    pa, pb = node(x[0], 0), node(x[0], 1)
    H = numeric_jacobian(lambda X: EdgeLengthFactor.residual(node(X[0], 0), node(X[0], 1), L[0]), x)
    np.testing.assert_allclose(np.hstack(EdgeLengthFactor.jacobians(pa, pb, L[0])), H[:, :4], atol=1e-8)


def test_edge_length_rest_is_median_of_common_frames():
    a = np.zeros((5, 2))
    b = np.array([[10, 0], [11, 0], [np.nan, np.nan], [30, 0], [12, 0]], dtype=float)
    assert EdgeLengthFactor.rest_length(a, b) == pytest.approx(11.5)
