"""Depth at the nodes, the 3-D smoother, 3-D bending and kappa from 3-D angles, on a simulated 3-D chain with known
compliance (issue #39's model: in-plane bend kappa z, out-of-plane bend kappa z_o, branch plane tilted 30 deg)."""

from __future__ import annotations

import numpy as np
import pytest

from rce_gtsam.bending.angles3d import compute_bending_3d
from rce_gtsam.bending.geometry import compute_geometry
from rce_gtsam.camera import CameraIntrinsics
from rce_gtsam.errors import InputError
from rce_gtsam.model.kappa3d import fit_kappa_3d
from rce_gtsam.presets import get_preset
from rce_gtsam.smoothing.smoother3d import smooth_tracks_3d
from rce_gtsam.track.depth_sample import d435_depth_rms_mm, robust_window_depth, sample_frame

from _chain3d import chain3d, chain_graph

CAM = CameraIntrinsics.d435i_colour()
N, F = 7, 300


def _log_rmse(k, truth):
    d = np.log(k) - np.log(truth)
    return float(np.sqrt(np.mean((d - d.mean()) ** 2)))


@pytest.fixture(scope="module")
def chain():
    pos, kappa, z, z_o, normal = chain3d(N, F, seed=3, rms_deg=2.0)
    rng = np.random.default_rng(7)
    xy = CAM.project(pos) + rng.normal(0, 0.3, (N, F, 2))
    zs = d435_depth_rms_mm(pos[..., 2])
    zm = pos[..., 2] + rng.normal(0, 1, (N, F)) * zs
    zm[rng.uniform(size=(N, F)) < 0.1] = np.nan  # holes
    return pos, kappa, normal, xy, zm, zs


def test_window_depth_keeps_the_stem_not_the_background():
    rng = np.random.default_rng(0)
    stem = 800 + rng.normal(0, 2, 20)
    window = np.concatenate([stem, np.full(25, 1400.0), np.zeros(6)])  # background and holes in the disk
    z, s, n = robust_window_depth(window)
    assert n == 45 and abs(z - 800) < 2.5
    assert d435_depth_rms_mm(800) <= s < 5  # never below the camera's own error model
    assert np.isnan(robust_window_depth(np.array([0.0, 0, 0, 900]))[0])  # too few valid pixels: no depth
    img = np.zeros((40, 40))
    img[:, 18:22] = 700.0
    img[:, :18] = 1500.0
    z, s, c = sample_frame(img, np.array([[20.0, 20.0], [5.0, 5.0], [np.nan, 1.0]]))
    assert z[0] == 700 and z[1] == 1500 and np.isnan(z[2]) and c[2] == 0


def test_smoother3d_beats_the_raw_depth_and_says_how_good_it_is(chain):
    pos, _, _, xy, zm, zs = chain
    sm = smooth_tracks_3d(xy, np.full((N, F), 0.3), zm, zs, np.arange(N), chain_graph(N), CAM)
    err = sm.xyz_mm - pos
    raw = np.sqrt(np.nanmean((zm - pos[..., 2]) ** 2))
    rms = np.sqrt(np.mean(err ** 2, axis=(0, 1)))
    assert rms[2] < 0.6 * raw and rms[0] < 1.0 and rms[1] < 1.0  # mm
    assert np.isfinite(sm.xyz_mm).all()  # holes filled by time and the branch
    zscore = np.abs(err) / sm.sigma_mm
    assert 0.3 < np.median(zscore[..., 2]) < 1.5  # the marginal sigma is the size of the error
    assert sm.report.n_depth == np.isfinite(zm).sum() and sm.report.mm_per_px == pytest.approx(
        np.median(pos[..., 2]) / CAM.fx, rel=0.05)


def test_smoother3d_rejects_inconsistent_input(chain):
    _, _, _, xy, zm, zs = chain
    with pytest.raises(InputError, match="no node has a depth"):
        smooth_tracks_3d(xy, None, np.full((N, F), np.nan), zs, np.arange(N), chain_graph(N), CAM)
    bad = zs.copy()
    bad[2, 5] = -1.0
    zz = zm.copy()
    zz[2, 5] = 800.0
    with pytest.raises(InputError, match="node 2, frame 5"):
        smooth_tracks_3d(xy, None, zz, bad, np.arange(N), chain_graph(N), CAM)


def test_3d_angles_recover_the_model_and_kappa(chain):
    pos, kappa, normal, xy, zm, zs = chain
    g = chain_graph(N)
    preset = get_preset("default").with_(compliance={"n_boot": 40})
    truth = compute_bending_3d(pos, np.arange(N), g, preset.bending)
    assert abs(truth.tilt_deg - 30.0) < 3.0 and abs(abs(truth.normal @ normal) - 1) < 2e-3
    geo = compute_geometry(CAM.project(pos), np.arange(N), g)
    assert _log_rmse(fit_kappa_3d(truth, geo, preset.with_(compliance={"n_boot": 0})).kappa, kappa) < 1e-3
    sm = smooth_tracks_3d(xy, np.full((N, F), 0.3), zm, zs, np.arange(N), g, CAM)
    b3 = compute_bending_3d(sm.xyz_mm, np.arange(N), g, preset.bending, sm.frame_cov)
    assert b3.in_plane.variance_deg2 is not None and np.nanmedian(b3.out_of_plane.variance_deg2) > \
        np.nanmedian(b3.in_plane.variance_deg2)  # the out-of-plane bend rests on depth: noisier
    k3 = fit_kappa_3d(b3, geo, preset)
    assert _log_rmse(k3.kappa, kappa) < 0.1
    assert np.all(k3.ci_low <= k3.kappa) and np.all(k3.kappa <= k3.ci_high)
    assert (k3.swing_rms_deg > 0.3).all() and len(k3.as_dict()["segments"]) == N - 2


def test_analyze_3d_writes_tables_figure_and_recording(chain, tmp_path):
    import json

    import pandas as pd
    from rerun.chunk import RrdReader

    from rce_gtsam.depth_pipeline import analyze_3d, format_3d, write_3d
    from rce_gtsam.pipeline import analyze
    from rce_gtsam.tracks import Tracks
    from rce_gtsam.viz.figures3d import swing_vs_bending_figure
    from rce_gtsam.viz.rerun3d import save_3d_recording

    pos, kappa, _, xy, zm, zs = chain
    res = analyze(Tracks(node_ids=np.arange(N), xy=xy, sigma_px=np.full((N, F), 0.3)), chain_graph(N), "default",
                  n_boot=30)
    d3 = analyze_3d(res, zm, zs, CAM)
    assert d3.depth_coverage == pytest.approx(np.isfinite(zm).mean())
    files = write_3d(d3, tmp_path)
    table = pd.read_csv(files[0])
    assert list(table.edge) == [f"{j}->{c}" for j, c in res.response.edges]
    assert np.allclose(table.kappa_2d, res.fit.kappa)  # the 2-D kappa beside the 3-D one, row for row
    rep = json.loads(files[1].read_text())
    assert rep["smoother_3d"]["n_depth"] == int(np.isfinite(zm).sum()) and len(rep["segments"]) == N - 2
    assert "kappa_3d" in format_3d(d3)
    assert swing_vs_bending_figure(d3, tmp_path / "s.png").stat().st_size > 10_000
    rrd = save_3d_recording(d3, tmp_path / "x.3d.rrd")
    paths = {str(ch.entity_path) for ch in RrdReader(str(rrd)).stream()}
    assert {"/world/skeleton", "/world/nodes", "/world/plane_normal", "/bending3d/1-2"} <= paths


def test_run_3d_says_why_it_skips_a_recording_without_depth_at_the_nodes(chain, tmp_path):
    import pandas as pd

    from rce_gtsam.cli.depth3d import run_3d
    from rce_gtsam.pipeline import analyze
    from rce_gtsam.tracks import Tracks

    _, _, _, xy, _, _ = chain
    tracks = Tracks(node_ids=np.arange(N), xy=xy, sigma_px=np.full((N, F), 0.3))
    res = analyze(tracks, chain_graph(N), "default", n_boot=0)
    table = tracks.to_frame().assign(visible=1, z_mm=np.nan, z_sigma_mm=np.nan)
    table.to_csv(tmp_path / "tracks.csv", index=False)
    text = run_3d(res, tmp_path / "tracks.csv", CAM, tmp_path / "out", figures=False, rerun=None, video=None)
    assert text.startswith("3-D analysis skipped") and "no node has a depth" in text
    pd.DataFrame(table.drop(columns=["z_mm", "z_sigma_mm"])).to_csv(tmp_path / "t2.csv", index=False)
    assert "no depth columns" in run_3d(res, tmp_path / "t2.csv", CAM, tmp_path / "out", False, None, None)
