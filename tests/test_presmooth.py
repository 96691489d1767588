"""Moving-average pre-smoothing reproduces the paper's §2.1 exactly."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rce_gtsam.smoothing.presmooth import effective_window, moving_average, moving_average_1d
from rce_gtsam.tracks import Tracks


def tracks_of(xy, sigma=None):
    xy = np.asarray(xy, dtype=float)
    return Tracks(node_ids=np.arange(xy.shape[0]), xy=xy, sigma_px=sigma, source="test")


def test_edge_padding_matches_paper_formula():
    x = np.array([1.0, 4.0, 9.0, 16.0, 25.0, 36.0, 49.0])
    y = moving_average_1d(x, 5)
    assert y[0] == pytest.approx((3 * x[0] + x[1] + x[2]) / 5)
    assert y[1] == pytest.approx((2 * x[0] + x[1] + x[2] + x[3]) / 5)
    assert y[3] == pytest.approx(x[1:6].mean())
    assert y[-1] == pytest.approx((3 * x[-1] + x[-2] + x[-3]) / 5)
    assert y.shape == x.shape


def test_even_window_bumped_and_small_window_is_identity():
    assert effective_window(4) == 5
    assert effective_window(5) == 5
    assert effective_window(1) == effective_window(0) == effective_window(-3) == 1
    x = np.random.default_rng(0).normal(size=20)
    np.testing.assert_array_equal(moving_average_1d(x, 4), moving_average_1d(x, 5))
    np.testing.assert_array_equal(moving_average_1d(x, 1), x)
    with pytest.raises(TypeError):
        effective_window(2.5)


def test_runs_across_gaps_by_sample_index_and_keeps_nan():
    rng = np.random.default_rng(1)
    xy = rng.normal(size=(2, 30, 2)) * 3
    xy[0, 10:14] = np.nan
    xy[1, 0:2] = np.nan
    sigma = np.where(np.isfinite(xy[..., 0]), 0.5, np.nan)
    out = moving_average(tracks_of(xy, sigma), 5)
    np.testing.assert_array_equal(np.isnan(out.xy), np.isnan(xy))
    np.testing.assert_array_equal(out.sigma_px, sigma)
    for i in range(2):
        f = np.flatnonzero(np.isfinite(xy[i, :, 0]))
        for axis in range(2):
            np.testing.assert_allclose(out.xy[i, f, axis], moving_average_1d(xy[i, f, axis], 5))
    # frame 14 (first after the gap) averages samples at frames 8, 9, 14, 15, 16
    np.testing.assert_allclose(out.xy[0, 14], xy[0, [8, 9, 14, 15, 16]].mean(axis=0))
    # input untouched
    assert np.isnan(xy[0, 10, 0])


def test_window_one_returns_copy():
    xy = np.arange(24, dtype=float).reshape(2, 6, 2)
    t = tracks_of(xy)
    out = moving_average(t, 1)
    np.testing.assert_array_equal(out.xy, xy)
    assert out.xy is not t.xy


@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 40), window=st.integers(2, 11), a=st.floats(-100, 100), b=st.floats(-5, 5))
def test_preserves_constants_and_interior_ramps(n, window, a, b):
    x = a + b * np.arange(n)
    y = moving_average_1d(x, window)
    half = effective_window(window) // 2
    np.testing.assert_allclose(moving_average_1d(np.full(n, a), window), a, atol=1e-9)
    if n > 2 * half:
        np.testing.assert_allclose(y[half:n - half], x[half:n - half], atol=1e-9)
