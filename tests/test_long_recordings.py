"""Long recordings in bounded memory: windowed smoothing equals the whole-recording solve, memory grows
linearly, and the bootstrap streams its resamples."""

from __future__ import annotations

import dataclasses
import tracemalloc

import numpy as np
import pytest

from rce_gtsam.model import uncertainty
from rce_gtsam.model.compliance import fit_rank1
from rce_gtsam.model.uncertainty import (BOOTSTRAP_CHUNK_ELEMENTS, block_bootstrap_indices, bootstrap_chunk,
                                         bootstrap_kappa, iter_block_bootstrap_indices)
from rce_gtsam.errors import InputError
from rce_gtsam.graph import BranchGraph
from rce_gtsam.presets import get_preset
from rce_gtsam.sim.simulate import SimulationConfig, simulate
from rce_gtsam.smoothing.smoother import smooth_tracks
from rce_gtsam.tracks import Tracks
from rce_gtsam.smoothing.windowing import plan_windows


@pytest.fixture(scope="module")
def long_sim():
    """3,000 frames x 6 nodes of tracker-like tracks (gaps, jumps)."""
    return simulate(SimulationConfig(n_nodes=6, n_frames=3000, seed=1))


@pytest.mark.parametrize("preset", ["default", "paper"])
def test_windowed_smoothing_equals_the_whole_recording_solve(long_sim, preset):
    """Six windows of 500 frames (margin 150 observations) against one 3,000-frame solve: positions to
    1e-9 px, covariances to 1e-9 relative (measured: 0 px and 5e-13)."""
    cfg = get_preset(preset).smoother
    full = smooth_tracks(long_sim.tracks, long_sim.graph, dataclasses.replace(cfg, window_frames=0))
    win = smooth_tracks(long_sim.tracks, long_sim.graph, dataclasses.replace(cfg, window_frames=500))
    assert full.report.n_windows == 1 and win.report.n_windows == 6
    assert win.report.converged
    np.testing.assert_allclose(win.tracks.xy, full.tracks.xy, rtol=0, atol=1e-9)
    scale = np.abs(full.cov).max()
    np.testing.assert_allclose(win.cov, full.cov, rtol=0, atol=1e-9 * scale)
    np.testing.assert_allclose(win.frame_cov, full.frame_cov, rtol=0, atol=1e-6 * scale)  # float32 storage


def test_too_small_a_margin_is_visible(long_sim):
    """The test above is not vacuous: with a 10-observation margin the window seams differ."""
    cfg = get_preset("default").smoother
    full = smooth_tracks(long_sim.tracks, long_sim.graph, dataclasses.replace(cfg, window_frames=0))
    win = smooth_tracks(long_sim.tracks, long_sim.graph, dataclasses.replace(cfg, window_frames=500, window_margin=10))
    assert np.abs(win.tracks.xy - full.tracks.xy).max() > 1e-4


def test_windows_tile_the_recording_and_hold_their_margins():
    rng = np.random.default_rng(0)
    obs = rng.random((4, 5000)) < 0.7
    obs[2, 1000:2500] = False  # a long occlusion: that node's margin reaches further
    windows = plan_windows(obs, core=800, margin=100)
    assert windows[0].core_lo == 0 and windows[-1].core_hi == 5000
    assert all(a.core_hi == b.core_lo for a, b in zip(windows, windows[1:]))
    for w in windows:
        assert w.core_hi - w.core_lo <= 800
        assert w.lo <= w.core_lo and w.hi >= w.core_hi and w.hi - w.lo <= 3 * 800
        for i in range(4):
            if w.lo > 0 and w.core_lo - w.lo < 800:   # not capped: the margin holds 100 observations
                assert obs[i, w.lo:w.core_lo].sum() >= 100
            if w.hi < 5000 and w.hi - w.core_hi < 800:
                assert obs[i, w.core_hi:w.hi].sum() >= 100
    assert plan_windows(obs, core=5000, margin=100) == plan_windows(obs, core=0, margin=100)
    assert len(plan_windows(obs, core=5000, margin=100)) == 1


def _smoothing_peak_bytes(n_frames: int) -> int:
    sim = simulate(SimulationConfig(n_nodes=5, n_frames=n_frames, seed=2))
    cfg = dataclasses.replace(get_preset("default").smoother, window_frames=500)
    tracemalloc.start()
    try:
        smooth_tracks(sim.tracks, sim.graph, cfg)
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_smoothing_memory_grows_linearly():
    """tracemalloc peak (numpy arrays; GTSAM's C++ heap is bounded by the window) of the smoothing stage
    at 1,000 and 4,000 frames x 5 nodes: four times the frames cost at most four times the memory, and
    each extra frame at most 4 kB (measured ~1 kB: the float32 (2N)^2 frame covariance is 400 B, the
    per-node float64 results ~500 B; the dense whole-recording selected inversion this replaced held
    ~13 kB per frame at 5 nodes)."""
    small, large = _smoothing_peak_bytes(1000), _smoothing_peak_bytes(4000)
    assert large < 4 * small
    assert (large - small) / 3000 < 4000, (small, large)


def test_tracks_that_start_late_allocate_nothing_for_the_missing_frames():
    """Frames labelled from 50,000: the smoother refuses (no node is seen in the first window) before
    building any factor graph, holding only the dense input (16 B per node-frame)."""
    n_nodes, start, length = 4, 50_000, 300
    t = np.arange(length)
    xy = np.full((n_nodes, start + length, 2), np.nan)
    for i in range(n_nodes):
        xy[i, start:, 0] = 100 + 20 * i + np.sin(t / 20)
        xy[i, start:, 1] = 200 + 0.0 * t
    graph = BranchGraph.from_edges(0, [(i, i + 1) for i in range(n_nodes - 1)])
    tracks = Tracks(node_ids=np.arange(n_nodes), xy=xy, source="late.csv")
    tracemalloc.start()
    try:
        with pytest.raises(InputError, match="frames 0-"):
            smooth_tracks(tracks, graph, get_preset("default").smoother)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 8 * xy.nbytes, peak


def test_block_bootstrap_indices_stream_the_same_draws():
    full = block_bootstrap_indices(500, 25, 37, np.random.default_rng(3))
    pieces = list(iter_block_bootstrap_indices(500, 25, 37, np.random.default_rng(3), chunk=5))
    assert [len(p) for p in pieces] == [5] * 7 + [2]
    np.testing.assert_array_equal(np.concatenate(pieces), full)


def test_bootstrap_batches_shrink_with_the_recording():
    assert bootstrap_chunk(64, 23, 590) == 64                  # plant 2: unchanged batches
    assert bootstrap_chunk(64, 18, 50_000) == 1
    assert bootstrap_chunk(64, 18, 50_000) * 18 * 50_000 <= BOOTSTRAP_CHUNK_ELEMENTS
    assert bootstrap_chunk(64, 20, 10**6) == 1
    assert bootstrap_chunk(64, 23, 590, per_resample_precision=True) < 64


@pytest.mark.parametrize("method", ["phase", "block"])
def test_bootstrap_does_not_depend_on_its_batch_size(monkeypatch, method):
    """The resamples of a long recording are refitted a few at a time; they, and the intervals, are the
    ones the 64-resample batches of a short recording give."""
    rng = np.random.default_rng(4)
    E, T = 5, 301
    z = np.convolve(rng.normal(size=T + 20), np.ones(21) / 21, mode="valid")
    Y = np.exp(rng.normal(0, 0.5, E))[:, None] * z[None] + rng.normal(0, 0.1, (E, T))
    Y[1, 40:60] = np.nan
    cfg = dataclasses.replace(get_preset("default").compliance, n_boot=70, bootstrap=method)
    fit = fit_rank1(Y, cfg)
    ref = bootstrap_kappa(Y, cfg, fit=fit)
    monkeypatch.setattr(uncertainty, "BOOTSTRAP_CHUNK_ELEMENTS", 3 * E * T)  # batches of 3 resamples
    assert bootstrap_chunk(64, E, T) == 3
    small = bootstrap_kappa(Y, cfg, fit=fit)
    np.testing.assert_array_equal(small.samples, ref.samples)
    np.testing.assert_array_equal(small.low, ref.low)
