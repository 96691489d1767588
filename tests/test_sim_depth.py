"""Tests of the simulated depth stream (rce_gtsam.sim.depth) and of ``rce simulate --depth``."""

from __future__ import annotations

import json

import numpy as np
import pytest

from rce_gtsam.sim.depth import DepthNoise, iter_depth_frames
from rce_gtsam.sim.simulate import SimulationConfig, simulate
from rce_gtsam.sim.three_d import Scene3D


@pytest.fixture(scope="module")
def sim():
    return simulate(SimulationConfig(n_frames=12, seed=5, effects=("out_of_plane",)))


def _node_pixels(sim, f):
    return np.round(sim.true_xy[:, f]).astype(int)


def test_error_model_is_intels_formula():
    n = DepthNoise()
    assert n.sigma_mm(1000.0) == pytest.approx(1000.0 ** 2 * 0.08 / (674.0 * 50.0))
    assert 2.0 < n.sigma_mm(1000.0) < 2.6            # ~2 mm at 1 m
    assert n.sigma_mm(2000.0) == pytest.approx(4 * n.sigma_mm(1000.0))


def test_exact_depth_is_the_tube_in_front_of_the_background(sim):
    t3 = sim.three_d
    exact = next(iter_depth_frames(sim, exact=True))
    row = {n: i for i, n in enumerate(sim.graph.nodes)}
    for n in sim.graph.nodes:
        x, y = _node_pixels(sim, 0)[row[n]]
        e = (sim.graph.parent.get(n), n) if n != sim.graph.root else sim.graph.edges[0]
        r = t3.stem_radius_mm[e]
        # the front surface is about one radius nearer than the axis through the node
        assert exact[y, x] == pytest.approx(t3.positions_mm[row[n], 0, 2] - r, abs=0.35 * r + 0.5)
    corner = exact[:40, :40]
    assert 1200 < corner.mean() < 1800                      # the background plane at ~1500 mm


def test_measured_depth_has_noise_holes_and_shadow(sim):
    exact = next(iter_depth_frames(sim, exact=True))
    meas = next(iter_depth_frames(sim)).astype(float)
    again = next(iter_depth_frames(sim)).astype(float)
    np.testing.assert_array_equal(meas, again)               # seeded
    bg = (exact > 1200) & (meas > 0)
    resid = (meas - exact)[bg]
    sigma = DepthNoise().sigma_mm(exact[bg])
    robust_sd = 1.4826 * np.median(np.abs(resid - np.median(resid)))   # flying pixels at the stem's edge aside
    assert 0.8 < robust_sd / np.sqrt(np.mean(sigma ** 2)) < 1.2
    assert np.sum(np.abs(resid) > 100) > 10                              # ... which are there
    holes = meas == 0
    assert 0.002 < holes.mean() < 0.2
    stem = exact < 1100
    # thin structures lose more: the distal (thinner in the image) half of the stem has more holes
    row = {n: i for i, n in enumerate(sim.graph.nodes)}
    xy = sim.true_xy[:, 0]
    yy, xx = np.nonzero(stem)
    d_root = np.hypot(xx - xy[row[0], 0], yy - xy[row[0], 1])
    d_tip = np.hypot(xx - xy[-1, 0], yy - xy[-1, 1])
    near_root = holes[yy[d_root < d_tip], xx[d_root < d_tip]].mean()
    near_tip = holes[yy[d_tip < d_root], xx[d_tip < d_root]].mean()
    assert near_tip > near_root
    # the stereo shadow: background pixels just left of the stem have no depth
    left = np.zeros_like(stem)
    left[:, :-3] = stem[:, 3:]
    left &= ~stem
    assert holes[left].mean() > 0.8
    clean = next(iter_depth_frames(sim, noise=DepthNoise(enabled=False))).astype(float)
    assert np.abs(clean - exact).max() <= 0.5


def test_planar_scene_renders_depth_without_swing():
    flat = simulate(SimulationConfig(n_frames=10, seed=1, scene3d=Scene3D()))
    assert flat.three_d.share == 0 and flat.three_d.tilt_deg == 0
    d = next(iter_depth_frames(flat, exact=True))
    x, y = np.round(flat.true_xy[5, 0]).astype(int)
    assert d[y, x] < flat.three_d.root_depth_mm + 1


def test_cli_bad_3d_options_exit_2_before_writing(tmp_path, capsys):
    from rce_gtsam.cli.app import main
    out = tmp_path / "o"
    for argv, option in ((["--oop-share", "0.3"], "--oop-share"),
                         (["--effect", "out_of_plane", "--oop-share", "-1"], "--oop-share"),
                         (["--effect", "out_of_plane", "--tilt-deg", "89"], "--tilt-deg"),
                         (["--simulator", "beam", "--depth"], "--depth")):
        assert main(["simulate", "--out", str(out), "--frames", "20", *argv]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and option in err[0], err
        assert not out.exists() or not any(out.iterdir())


def test_cli_depth_writes_a_recording_that_plays_back(tmp_path):
    pytest.importorskip("pyrealsense2", exc_type=ImportError, reason="pyrealsense2 cannot import (needs libusb-1.0-0)")
    from rce_gtsam.cli.app import main
    from rce_gtsam.sim.recording import depth_frames
    from rce_gtsam.track.depth import RealSenseDepthSource
    out = tmp_path / "rec"
    assert main(["simulate", "--out", str(out), "--frames", "10", "--seed", "3", "--effect", "out_of_plane",
                 "--depth"]) == 0
    names = {p.name for p in out.iterdir()}
    assert {"recording.db3", "video.mp4", "tracks.csv", "truth.json", "graph.json", "annotations.json"} <= names
    truth = json.loads((out / "truth.json").read_text())
    assert np.array(truth["positions_mm"]).shape == (10, 20, 3)
    src = RealSenseDepthSource(out / "recording.db3")
    try:
        frames = list(src)
    finally:
        src.close()
    assert [f.index for f in frames] == list(range(10))
    sim = simulate(SimulationConfig(n_frames=10, seed=3, effects=("out_of_plane",)))
    for f, d in zip(frames, depth_frames(sim)):
        np.testing.assert_array_equal(f.depth_mm, d)
    # a simulation without the flag leaves no stale recording behind
    assert main(["simulate", "--out", str(out), "--frames", "10", "--seed", "3"]) == 0
    assert not (out / "recording.db3").exists()
