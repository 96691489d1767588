"""The texture bed's Cramér-Rao bound (benchmarks/texture_bound.py): its Fisher information is the one of the image
moving as the model says, and its noise level is the decoded frame's."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import texture_bound  # noqa: E402

W_PX = 3.0  # the bar's Gaussian half-width (px); a sharper one loses more to the 3x3 derivative


def _bar(p: np.ndarray, c: np.ndarray, shape=(100, 120)) -> np.ndarray:
    """A grey frame with one bright stem from p to c: a Gaussian profile across the segment, smooth ends."""
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]].astype(float)
    d = c - p
    L = float(np.hypot(*d))
    t = ((xx - p[0]) * d[0] + (yy - p[1]) * d[1]) / L
    v = ((xx - p[0]) * -d[1] + (yy - p[1]) * d[0]) / L
    along = 1.0 / (1.0 + np.exp(-(t - 3.0))) / (1.0 + np.exp(t - (L - 3.0)))
    return 50.0 + 120.0 * along * np.exp(-0.5 * (v / W_PX) ** 2)


def test_fisher_is_the_information_of_the_moving_image():
    """Root p fixed, node c free: J equals the sum over the stem's pixels of the squared change of the re-drawn frame
    per px of c's displacement (finite differences), across and along the segment -- to the 3x3 Sobel derivative's
    loss on a 3-px profile (6-8 %; 14-20 % on a 1.5-px one: the bound is then a little too high, never too low)."""
    p, c = np.array([20.0, 50.0]), np.array([80.0, 46.0])
    xy = np.stack([p, c])
    grey = _bar(p, c)
    J, free = texture_bound.fisher(grey, xy, [(0, 1)], inner_px=6.0, blend_px=4.0, root=0)
    assert free == [2, 3]
    # the pixels fisher() keeps: within 6 px of the segment
    yy, xx = np.mgrid[0:grey.shape[0], 0:grey.shape[1]].astype(float)
    d = c - p
    u = np.clip(((xx - p[0]) * d[0] + (yy - p[1]) * d[1]) / float(d @ d), 0, 1)
    keep = np.hypot(xx - p[0] - u * d[0], yy - p[1] - u * d[1]) <= 6.0
    eps = 1e-3
    for k, e in enumerate(np.eye(2)):
        di = (_bar(p, c + eps * e) - _bar(p, c - eps * e)) / (2 * eps)
        j_fd = float(np.sum(di[keep] ** 2))
        assert 0.88 * j_fd <= J[k, k] <= 1.0 * j_fd
    across = np.array([-d[1], d[0]]) / np.hypot(*d)
    var_across = float(across @ np.linalg.inv(J) @ across)
    assert var_across < float(np.diag(np.linalg.inv(J)).max())  # the across direction is the best known


def test_the_bound_scales_with_the_noise_and_the_stems_length():
    p = np.array([20.0, 50.0])
    short, long_ = np.array([50.0, 50.0]), np.array([95.0, 50.0])
    sd = []
    for c in (short, long_):
        J, _ = texture_bound.fisher(_bar(p, c), np.stack([p, c]), [(0, 1)], 6.0, 4.0, 0)
        sd.append(np.sqrt(np.linalg.inv(J)[1, 1]))  # across: y
    assert sd[1] < sd[0]  # more stem, more information


def test_frame_noise_is_the_residual_after_the_flicker():
    rng = np.random.default_rng(3)
    clean = rng.uniform(20, 200, (80, 90))
    decoded = 1.1 * clean + 3.0 + 2.0 * rng.standard_normal(clean.shape)
    xy = np.array([[30.0, 30.0], [60.0, 50.0]])
    assert texture_bound.frame_noise(decoded, clean, xy) == pytest.approx(2.0, rel=0.08)


def test_the_oracle_finds_a_known_displacement_and_its_scatter_under_white_noise_is_the_bound():
    """oracle_offsets: a frame re-drawn with node c moved by 0.2 px (across) and 0.1 px (along) reads that
    displacement; under white noise its offsets scatter as J^-1 s^2 (the bound), after a global gain and offset."""
    p, c = np.array([20.0, 50.0]), np.array([80.0, 46.0])
    xy = np.stack([p, c])
    clean = _bar(p, c)
    shift = np.array([0.1, 0.2])
    moved = 1.05 * _bar(p, c + shift) - 2.0
    off = texture_bound.oracle_offsets(moved, clean, xy, [(0, 1)], 6.0, 4.0, 0)
    np.testing.assert_allclose(off[0], 0.0)  # the root is fixed
    np.testing.assert_allclose(off[1], shift, atol=0.02)
    rng = np.random.default_rng(5)
    s = 2.0
    draws = np.array([texture_bound.oracle_offsets(clean + s * rng.standard_normal(clean.shape), clean, xy,
                                                   [(0, 1)], 6.0, 4.0, 0)[1] for _ in range(300)])
    J, _ = texture_bound.fisher(clean, xy, [(0, 1)], 6.0, 4.0, 0)
    np.testing.assert_allclose(draws.std(0), np.sqrt(np.diag(np.linalg.inv(J))) * s, rtol=0.15)
