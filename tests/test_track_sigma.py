"""The default tracker's per-match standard error (``weighted_lk``'s sandwich form, ``SE_LAG_PX``) against the
actual spread of its estimates over noise draws: right for independent pixel noise, and still close when the
noise is correlated across pixels (blur, resampling, compression), where the independent-pixel formula is
several times too small."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from rce_gtsam.track.kernels_sampling import SE_LAG_PX, weighted_lk


def _ratio(blur_px: float, lag: int, draws: int = 150) -> float:
    """Median reported s_lk / largest actual SD of the estimate (px / px) over ``draws`` noise draws."""
    rng = np.random.default_rng(1)
    base = cv2.GaussianBlur(rng.uniform(0, 255, (64, 64)).astype(np.float32), (0, 0), 1.5)
    h = 8
    tmpl = base[32 - h:32 + h + 1, 32 - h:32 + h + 1].copy()
    wts = np.ones_like(tmpl)
    est, se = [], []
    for _ in range(draws):
        n = rng.standard_normal((64, 64)).astype(np.float32)
        if blur_px > 0:
            n = cv2.GaussianBlur(n, (0, 0), blur_px)
        n *= np.float32(3.0 / n.std())
        ok, x, y, s = weighted_lk(tmpl, wts, base + n, 32.3, 31.8, 20, 0.01, lag)
        assert ok
        est.append((x, y))
        se.append(s)
    est = np.array(est)
    assert np.abs(est.mean(axis=0) - 32.0).max() < 0.05  # unbiased: the spread is the error
    return float(np.median(se) / est.std(axis=0).max())


@pytest.mark.parametrize("lag", [0, SE_LAG_PX])
def test_standard_error_matches_the_spread_under_white_noise(lag):
    assert 0.8 < _ratio(0.0, lag) < 1.25


def test_standard_error_allows_for_correlated_pixel_noise():
    independent = _ratio(1.0, 0)  # the residuals' correlation ignored
    sandwich = _ratio(1.0, SE_LAG_PX)
    assert independent < 0.55
    assert 0.65 < sandwich < 1.25
