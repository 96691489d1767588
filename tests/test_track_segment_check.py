"""The default tracker's segment check (``LKConfig.segment_check``): a node's frame-0 match against its hinged
segment search, with a bound calibrated on the clip."""

from __future__ import annotations

import numpy as np
import pytest

from rce_gtsam.track import LKConfig, LKTracker

from track_fixtures import rendered_simulation


def _checker(parent):
    t = LKTracker()
    t.parent = np.array(parent)
    t._tips = {i for i in range(len(parent)) if i not in parent}
    return t


def _clip(n_frames, seed=0, sigma_d=0.2):
    """3 nodes (root 0, interior 1, tip 2), every frame anchored (HOW 0); match-to-segment differences a 2-D Gaussian
    of ``sigma_d`` px per axis."""
    rng = np.random.default_rng(seed)
    P, F = 3, n_frames
    xy = rng.normal(100.0, 10.0, (P, F, 2))
    diff = rng.normal(0.0, sigma_d, (P, F, 2))
    seg_xy = xy + diff
    seg_d = np.hypot(*diff.transpose(2, 0, 1))
    seg_d[0] = np.nan  # the root has no segment search
    vis = np.ones((P, F), bool)
    sig = np.full((P, F), 0.06)
    how = np.zeros((P, F), np.int8)
    return xy, vis, sig, how, seg_d, seg_xy


def test_bound_is_the_99th_percentile_of_a_gaussian_difference_and_only_widens_frame0_matches():
    t = _checker([-1, 0, 1])
    xy, vis, sig, how, seg_d, _ = _clip(4000)
    how[1, :10] = 2  # a held position is not a frame-0 match: never touched
    seg_d[1, :10] = 5.0
    vis[2, :10] = False  # nor is an invisible one
    seg_d[2, :10] = 5.0
    s0, h0 = sig.copy(), how.copy()
    counts = {"segment_check": 0}
    t._segment_check(vis, sig, how, seg_d, counts)
    bound = t.segment_check_px
    assert bound == pytest.approx(3.035 * 0.2, rel=0.06)
    flag = (h0 == 0) & vis & (np.nan_to_num(seg_d) > bound)
    assert 0.004 < flag[1:].mean() < 0.02  # ~1 % of a Gaussian difference's lengths exceed the bound
    assert counts["segment_check"] == flag.sum() > 0
    assert np.allclose(sig[flag], np.sqrt(0.06 ** 2 + (seg_d[flag] - bound) ** 2 / 2))
    assert np.all(how[flag] == 4)
    assert np.array_equal(sig[~flag], s0[~flag]) and np.array_equal(how[~flag], h0[~flag])


def test_too_few_distances_change_nothing():
    t = _checker([-1, 0, 1])
    _, vis, sig, how, seg_d, _ = _clip(99)  # 2 x 99 = 198 distances < 200
    seg_d[1:, 0] = 10.0
    before = [a.copy() for a in (sig, how)]
    t._segment_check(vis, sig, how, seg_d, {"segment_check": 0})
    assert all(np.array_equal(a, b) for a, b in zip((sig, how), before))


def test_segment_check_on_a_simulator_render(tmp_path):
    """Simulator seed 0, 150 frames, 12 nodes (clean H.264): the check changes no position and no visibility, only
    widens sigma, and where it does the error is larger than elsewhere; the median sigma of a clean render stays
    where it was (~0.06 px: the sigma is the smoother's weight)."""
    from rce_gtsam.sim.simulate import SimulationConfig
    from rce_gtsam.track import open_video

    sim, video, truth = rendered_simulation(tmp_path, SimulationConfig(n_nodes=12, n_frames=150, seed=0))
    runs = {}
    for on in (False, True):
        with open_video(video) as src:
            runs[on] = LKTracker(LKConfig(segment_check=on)).track(src, truth[:, 0], sim.graph)
    off, res = runs[False], runs[True]
    assert off.info["segment_check"] == 0 and off.info["segment_check_px"] is None
    assert res.info["segment_check"] > 0 and 0 < res.info["segment_check_px"] < 2.0
    assert np.array_equal(res.xy, off.xy) and np.array_equal(res.visible, off.visible)
    assert np.all(res.sigma_px >= off.sigma_px)
    grew = res.sigma_px > off.sigma_px
    assert grew.sum() == res.info["segment_check"] and np.all(res.info["how"][grew] == 4)
    err = np.hypot(*(res.xy - truth).transpose(2, 0, 1))
    assert np.median(err[grew]) > np.median(err[res.visible & ~grew])
    assert np.median(res.sigma_px[res.visible]) < 1.1 * np.median(off.sigma_px[off.visible]) < 0.1
