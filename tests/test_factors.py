"""Each smoother factor: the GTSAM factor's residual equals the documented numpy residual, and the
Jacobian GTSAM linearises to equals central differences of that residual (whitened, robust-weighted
exactly as GTSAM documents it)."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from rce_gtsam.factors import (AccelerationFactor, EdgeLengthFactor, EdgeOffsetFactor,
                               MeasurementFactor, VelocityFactor, oriented_covariance,
                               sigma_from_weight)

RNG = np.random.default_rng(7)
KEYS = [gtsam.symbol("p", i) for i in range(3)]


def values_of(points) -> gtsam.Values:
    v = gtsam.Values()
    for k, p in zip(KEYS, points):
        v.insert(k, np.asarray(p, dtype=float))
    return v


def numeric_jacobians(error_fn, points, h=1e-6):
    """Central differences of error_fn(list of (2,) points) w.r.t. each point: list of (m, 2)."""
    out = []
    for j in range(len(points)):
        cols = []
        for axis in range(2):
            plus = [np.array(p, dtype=float) for p in points]
            minus = [np.array(p, dtype=float) for p in points]
            plus[j][axis] += h
            minus[j][axis] -= h
            cols.append((error_fn(plus) - error_fn(minus)) / (2 * h))
        out.append(np.stack(cols, axis=1))
    return out


def check_linearisation(factor, points, residual_fn, sqrt_info, robust=None):
    """GTSAM's linearised (A, b) == (sqrt(w) R H, -sqrt(w) R e) with H from central differences of
    the documented residual and w the robust weight at the whitened error norm (1 if not robust)."""
    vals = values_of(points)
    e = residual_fn(points)
    H = numeric_jacobians(residual_fn, points)
    white = sqrt_info @ e
    w = 1.0 if robust is None else robust.weight(float(np.linalg.norm(white)))
    A, b = factor.linearize(vals).jacobian()
    expected_A = np.sqrt(w) * np.hstack([sqrt_info @ Hj for Hj in H])
    np.testing.assert_allclose(A, expected_A, atol=1e-7, rtol=1e-6)
    np.testing.assert_allclose(b, -np.sqrt(w) * white, atol=1e-9, rtol=1e-9)


def test_sigma_from_weight_rejects_non_positive():
    assert sigma_from_weight(4.0) == pytest.approx(0.5)
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError):
            sigma_from_weight(bad)


@pytest.mark.parametrize("sigma", [1.0, 0.4])
def test_measurement_isotropic(sigma):
    p, m = RNG.normal(size=2) * 10, RNG.normal(size=2) * 10
    nm = MeasurementFactor.noise_model(sigma)
    f = MeasurementFactor.create(KEYS[0], m, nm)
    np.testing.assert_allclose(f.unwhitenedError(values_of([p])), MeasurementFactor.residual(p, m))
    check_linearisation(f, [p], lambda P: MeasurementFactor.residual(P[0], m), np.eye(2) / sigma)
    # cost = 0.5 |r|^2 / sigma^2 (paper: w r^2 with w = 1/sigma^2, up to GTSAM's common factor 1/2)
    assert f.error(values_of([p])) == pytest.approx(0.5 * np.sum((p - m) ** 2) / sigma ** 2)


@pytest.mark.parametrize("robust,k", [(None, 1.0), ("huber", 1.345), ("cauchy", 0.8)])
def test_measurement_anisotropic_and_robust(robust, k):
    sigma, ratio = 0.7, 3.0
    tangent = np.array([np.cos(0.4), np.sin(0.4)])
    m = np.array([100.0, 50.0])
    p = m + np.array([2.0, -3.0])  # a large error so the robust weight is well below 1
    nm = MeasurementFactor.noise_model(sigma, tangent, ratio, robust, k)
    base = nm if robust is None else nm.noise()
    cov = base.covariance()
    np.testing.assert_allclose(cov, oriented_covariance(ratio * sigma, sigma, tangent))
    assert tangent @ cov @ tangent == pytest.approx((ratio * sigma) ** 2)  # along the branch
    normal = np.array([-tangent[1], tangent[0]])
    assert normal @ cov @ normal == pytest.approx(sigma ** 2)  # across
    f = MeasurementFactor.create(KEYS[0], m, nm)
    np.testing.assert_allclose(f.unwhitenedError(values_of([p])), MeasurementFactor.residual(p, m))
    est = None if robust is None else nm.robust()
    if est is not None:
        assert est.weight(float(np.linalg.norm(base.R() @ (p - m)))) < 0.9
    check_linearisation(f, [p], lambda P: MeasurementFactor.residual(P[0], m), base.R(), est)


def test_measurement_rejects_unknown_robust_loss():
    with pytest.raises(ValueError, match="robust"):
        MeasurementFactor.noise_model(1.0, robust="tukey-ish")


def test_velocity():
    pts = [RNG.normal(size=2) * 5 for _ in range(2)]
    w = 0.35
    f = VelocityFactor.create(KEYS[0], KEYS[1], VelocityFactor.noise_model(w))
    np.testing.assert_allclose(f.unwhitenedError(values_of(pts)), VelocityFactor.residual(*pts), atol=1e-12)
    check_linearisation(f, pts, lambda P: VelocityFactor.residual(*P), np.sqrt(w) * np.eye(2))
    np.testing.assert_allclose(np.hstack(VelocityFactor.jacobians(*pts)),
                               np.hstack(numeric_jacobians(lambda P: VelocityFactor.residual(*P), pts)), atol=1e-8)


def test_acceleration_linear_container_is_exact():
    pts = [RNG.normal(size=2) * 5 for _ in range(3)]
    w = 0.2
    f = AccelerationFactor.create(*KEYS, w, AccelerationFactor.zero_values(KEYS))
    vals = values_of(pts)
    r = AccelerationFactor.residual(*pts)
    assert f.error(vals) == pytest.approx(0.5 * w * np.sum(r ** 2))
    A, b = f.linearize(vals).jacobian()
    np.testing.assert_allclose(-b / np.sqrt(w), r, atol=1e-12)
    H = numeric_jacobians(lambda P: AccelerationFactor.residual(*P), pts)
    np.testing.assert_allclose(A, np.sqrt(w) * np.hstack(H), atol=1e-8)
    np.testing.assert_allclose(np.hstack(AccelerationFactor.jacobians(*pts)), np.hstack(H), atol=1e-8)
    # far from the zero linearisation point it is still exact (Point2 is a vector space)
    far = [p + 1e4 for p in pts]
    A2, b2 = f.linearize(values_of(far)).jacobian()
    np.testing.assert_allclose(-b2 / np.sqrt(w), AccelerationFactor.residual(*far), atol=1e-8)
    np.testing.assert_allclose(A2, A)


def test_edge_offset():
    pts = [RNG.normal(size=2) * 5 for _ in range(2)]
    d = np.array([3.0, -20.0])
    w = 0.45
    f = EdgeOffsetFactor.create(KEYS[0], KEYS[1], d, EdgeOffsetFactor.noise_model(w))
    np.testing.assert_allclose(f.unwhitenedError(values_of(pts)), EdgeOffsetFactor.residual(*pts, d), atol=1e-12)
    check_linearisation(f, pts, lambda P: EdgeOffsetFactor.residual(*P, d), np.sqrt(w) * np.eye(2))


def test_edge_offset_rest_is_first_common_frame():
    a = np.array([[np.nan, np.nan], [0.0, 0.0], [1.0, 1.0]])
    b = np.array([[5.0, 5.0], [3.0, 4.0], [9.0, 9.0]])
    np.testing.assert_allclose(EdgeOffsetFactor.rest_offset(a, b), [3.0, 4.0])
    with pytest.raises(ValueError):
        EdgeOffsetFactor.rest_offset(a[:1], b[:1])


def test_edge_length_range_factor():
    pts = [np.array([10.0, 20.0]), np.array([13.0, 2.0])]
    L, w = 17.0, 0.45
    f = EdgeLengthFactor.create(KEYS[0], KEYS[1], L, EdgeLengthFactor.noise_model(w))
    assert isinstance(f, gtsam.RangeFactor2)
    np.testing.assert_allclose(f.unwhitenedError(values_of(pts)), EdgeLengthFactor.residual(*pts, L), atol=1e-12)
    check_linearisation(f, pts, lambda P: EdgeLengthFactor.residual(*P, L), np.sqrt(w) * np.eye(1))
    np.testing.assert_allclose(np.hstack(EdgeLengthFactor.jacobians(*pts, L)),
                               np.hstack(numeric_jacobians(lambda P: EdgeLengthFactor.residual(*P, L), pts)),
                               atol=1e-8)


def test_edge_length_rest_is_median_of_common_frames():
    a = np.zeros((5, 2))
    b = np.array([[10, 0], [11, 0], [np.nan, np.nan], [30, 0], [12, 0]], dtype=float)
    assert EdgeLengthFactor.rest_length(a, b) == pytest.approx(11.5)
