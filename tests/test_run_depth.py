"""`rce run` and `rce track` end to end on a simulated RealSense recording with depth (rce simulate --effect
out_of_plane --depth): tracks gain z_mm, the 3-D analysis writes kappa_3d.csv beside the 2-D kappa, the swing
figure and a 3-D Rerun recording; a 2-D reader still reads the tracks."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

pytest.importorskip("pyrealsense2", exc_type=ImportError,
                    reason="pyrealsense2 cannot import (needs apt libusb-1.0-0; `make test` installs it as root)")

from rce_gtsam.cli import main  # noqa: E402
from rce_gtsam.errors import InputError  # noqa: E402
from rce_gtsam.graph import load_graph  # noqa: E402
from rce_gtsam.track.depth_tracks import read_depth_columns  # noqa: E402
from rce_gtsam.tracks import load_tracks  # noqa: E402


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    out = tmp_path_factory.mktemp("oop_depth")
    assert main(["simulate", "--out", str(out), "--effect", "out_of_plane", "--depth", "--frames", "60",
                 "--nodes", "6", "--seed", "3"]) == 0
    return out


@pytest.mark.slow
def test_run_on_a_recording_with_depth(sim, tmp_path, capsys):
    out = tmp_path / "run"
    rc = main(["run", str(sim / "recording.db3"), str(sim / "annotations.json"), str(sim / "graph.json"),
               "--out", str(out), "--bootstrap", "30", "--no-progress", "--rerun", str(out / "r.rrd")])
    assert rc in (0, 3)
    printed = capsys.readouterr().out
    assert "3-D from depth" in printed and "kappa_3d" in printed
    truth = json.loads((sim / "truth.json").read_text())
    k3 = pd.read_csv(out / "kappa_3d.csv")
    assert list(k3.edge) == list(truth["kappa_true_3d"])  # every bend of the chain, root to tip
    assert np.isfinite(k3[["kappa_3d", "kappa_2d", "kappa_in_plane", "swing_rms_deg"]].to_numpy()).all()
    assert (k3.kappa_3d_ci_low <= k3.kappa_3d).all() and (k3.kappa_3d <= k3.kappa_3d_ci_high).all()
    assert np.exp(np.mean(np.log(k3.kappa_3d))) == pytest.approx(1.0, rel=0.05)  # geometric mean 1, as in 2-D
    # the depth of every visible node is the stem's near surface: within a stem radius + noise of the truth
    tracks = pd.read_csv(out / "tracks.csv")
    pos = np.array(truth["positions_mm"])  # frames x nodes x 3
    vis = tracks[(tracks.visible == 1) & tracks.z_mm.notna()]
    err = vis.z_mm.to_numpy() - pos[vis.frame.to_numpy(), vis.point_id.to_numpy(), 2]
    assert len(vis) > 0.9 * (tracks.visible == 1).sum() and np.median(np.abs(err)) < 10.0
    rep = json.loads((out / "depth3d.json").read_text())
    assert rep["smoother_3d"]["seconds"] > 0 and rep["timings_s"]["smooth_2d"] > 0
    assert abs(rep["branch_plane_tilt_deg"] - truth["three_d"]["tilt_deg"]) < 10
    assert (out / "swing_vs_bending.png").stat().st_size > 10_000
    from rerun.chunk import RrdReader
    paths = {str(ch.entity_path) for ch in RrdReader(str(out / "r.3d.rrd")).stream()}
    assert {"/world/skeleton", "/world/nodes", "/depth/image"} <= paths
    assert (out / "r.rrd").is_file()  # the 2-D recording too (no video asset for a .db3)


def test_track_writes_depth_columns_a_2d_reader_ignores(sim, tmp_path):
    out = tmp_path / "t.csv"
    assert main(["track", str(sim / "recording.db3"), str(sim / "annotations.json"), "--out", str(out),
                 "--graph", str(sim / "graph.json"), "--no-progress"]) == 0
    table = pd.read_csv(out)
    assert {"z_mm", "z_sigma_mm"} <= set(table.columns)
    graph = load_graph(sim / "graph.json")
    tracks = load_tracks(out, graph)  # the 2-D reader, unchanged
    z, zs = read_depth_columns(out, tracks)
    assert z.shape == (tracks.n_nodes, tracks.n_frames) and np.isfinite(z[tracks.observed]).mean() > 0.9
    assert (zs[np.isfinite(z)] > 0).all()
    bad = tmp_path / "bad.csv"
    table.loc[3, "z_sigma_mm"] = -1.0
    table.to_csv(bad, index=False)
    with pytest.raises(InputError, match="line 5"):
        read_depth_columns(bad, tracks)
