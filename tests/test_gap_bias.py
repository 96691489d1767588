"""Kappa from exact positions must not depend on how sure the tracker was of each point (issue #38).

The smoother's ``sigma_mode="uniform"`` (``rce_gtsam.smoothing.uniform_sigma``) solves the positions with one sigma
and scales the covariances back; the bending's ``rest="common_median"`` takes every bend's rest over the frames all
bends share. Each test fails if its mechanism is undone.
"""

from __future__ import annotations

import numpy as np
import pytest

import rce_gtsam
from rce_gtsam.bending.angles import MIN_COMMON_FRAMES, common_frames, compute_bending
from rce_gtsam.model.compliance import fit_rank1
from rce_gtsam.presets import DEFAULT, BendingConfig, SmootherConfig
from rce_gtsam.sim.simulate import NoiseConfig, SimulationConfig, simulate
from rce_gtsam.smoothing.smoother import smooth_tracks
from rce_gtsam.smoothing.uniform_sigma import rescale_covariances, uniform_sigma
from rce_gtsam.tracks import Tracks


@pytest.fixture(scope="module")
def exact():
    """A noise-free simulated branch (300 frames) and a tracker-like sigma: per node 0.15-0.55 px, growing with the
    node's speed in each frame (as motion blur does), px."""
    sim = simulate(SimulationConfig(seed=3, n_frames=300, noise=NoiseConfig(enabled=False)))
    xy = sim.true_xy
    speed = np.zeros(xy.shape[:2])
    speed[:, 1:] = np.hypot(*np.diff(xy, axis=1).transpose(2, 0, 1))
    rng = np.random.default_rng(0)
    node = rng.uniform(0.15, 0.55, xy.shape[0])[:, None]
    sigma = node * (1 + 2 * speed / speed.max())
    return sim, sigma


def log_rmse(r, kappa_true) -> float:
    est = np.array([r.kappa[e] for e in r.response.edges])
    tru = np.array([kappa_true[e] for e in r.response.edges])
    return float(np.sqrt(np.mean(np.log(est / tru) ** 2)))


def test_uniform_sigma_removes_the_bias_of_unequal_smoothing(exact):
    sim, sigma = exact
    t = Tracks(node_ids=sim.tracks.node_ids, xy=sim.true_xy, sigma_px=sigma, source="exact")
    errs = {}
    for mode, preset in (("per_observation", "default"),  # the default preset (the option is off: see presets.py)
                         ("uniform", DEFAULT.with_(smoother={"sigma_mode": "uniform"}))):
        errs[mode] = log_rmse(rce_gtsam.analyze(t, sim.graph, preset=preset, n_boot=0), sim.kappa_true)
    # one sigma for all: one filter for every bend, which z absorbs (measured 1e-5); per observation, the nodes
    # and frames the tracker is less sure of are low-passed harder and kappa reads it (measured 0.027)
    assert errs["uniform"] < 0.002, errs
    assert errs["per_observation"] > 0.015, errs


def test_uniform_sigma_scales_the_covariances_back(exact):
    sim, sigma = exact
    F = 60
    t = Tracks(node_ids=sim.tracks.node_ids, xy=sim.true_xy[:, :F], sigma_px=sigma[:, :F], source="exact")
    flat, ratio = uniform_sigma(t)
    med = float(np.median(sigma[:, :F]))
    assert np.allclose(flat.sigma_px, med) and np.allclose(ratio, sigma[:, :F] / med)
    cfg = DEFAULT.smoother
    a = smooth_tracks(t, sim.graph, SmootherConfig(**{**cfg.__dict__, "sigma_mode": "uniform"}))
    b = smooth_tracks(flat, sim.graph, cfg)  # the same solve with one sigma, per observation
    assert np.allclose(a.tracks.xy, b.tracks.xy, atol=1e-9)
    assert np.allclose(a.cov, b.cov * (ratio ** 2)[:, :, None, None], rtol=1e-6)
    d = np.repeat(ratio.T, 2, axis=1)
    assert np.allclose(a.frame_cov, b.frame_cov * d[:, :, None] * d[:, None, :], rtol=1e-4, atol=1e-9)
    # the tracks without sigma are untouched
    assert uniform_sigma(Tracks(node_ids=t.node_ids, xy=t.xy, source="x")) [1] is None


def test_rescale_covariances_is_d_sigma_d():
    rng = np.random.default_rng(1)
    A = rng.standard_normal((3, 4, 4))
    fc = A @ A.transpose(0, 2, 1)
    cov = np.stack([fc[:, 2 * i:2 * i + 2, 2 * i:2 * i + 2] for i in range(2)])
    ratio = rng.uniform(0.5, 2, (2, 3))
    want = np.stack([np.diag(np.repeat(ratio[:, f], 2)) @ fc[f] @ np.diag(np.repeat(ratio[:, f], 2)) for f in range(3)])
    rescale_covariances(cov, fc, ratio)
    assert np.allclose(fc, want)
    assert np.allclose(cov[1, 2], want[2, 2:4, 2:4])


def test_common_median_rest_keeps_gust_losses_from_biasing_kappa():
    """The tip's nodes lost whenever the excitation is high (missing not at random): each bend's own median is taken
    at a different excitation and the rank-1 fit reads the offsets as kappa; the median over the common frames not."""
    sim = simulate(SimulationConfig(seed=1, n_frames=300, noise=NoiseConfig(enabled=False)))
    xy = sim.true_xy.copy()
    z = sim.z_true
    n = xy.shape[0]
    for k, node in enumerate(range(n // 2, n)):  # farther nodes lost at lower excitation
        xy[node, z > np.quantile(z, 0.9 - 0.3 * k / n)] = np.nan  # up to ~40 %: most frames still shared
    ids = sim.tracks.node_ids
    errs = {}
    for rest in ("median", "common_median"):
        b = compute_bending(xy, ids, sim.graph, BendingConfig(signed=True, rest=rest, mad_threshold=1e9))
        ok = np.isfinite(b.delta_deg).sum(axis=1) >= 3
        fit = fit_rank1(b.delta_deg[ok], DEFAULT.compliance, None, None)
        tru = np.array([sim.kappa_true[e] for e, keep in zip(b.edges, ok) if keep])
        errs[rest] = float(np.sqrt(np.mean(np.log(np.abs(fit.kappa) / tru) ** 2)))
    assert errs["common_median"] < 0.002, errs  # measured 5e-6
    assert errs["median"] > 0.03, errs  # measured 0.054


def test_common_frames_needs_enough_shared_frames():
    a = np.zeros((3, 40))
    a[0, :35] = np.nan  # bend 0 seen in 5 frames, all shared with the others
    assert common_frames(a) is None  # 5 shared frames < MIN_COMMON_FRAMES: each bend its own median
    assert MIN_COMMON_FRAMES > 5
    a[0, :38] = np.nan  # 2 frames: too few to count; the others share all 40
    assert common_frames(a).tolist() == list(range(40))
    with pytest.raises(ValueError, match="bending.rest"):
        BendingConfig(rest="mean")
    with pytest.raises(ValueError, match="sigma_mode"):
        SmootherConfig(sigma_mode="x")
