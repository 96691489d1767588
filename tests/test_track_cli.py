"""`rce track` and `rce annotate` end to end on files."""

from __future__ import annotations

import json

import numpy as np
import pytest

from rce_gtsam.cli import main
from rce_gtsam.graph import load_graph
from rce_gtsam.tracks import load_tracks

from track_fixtures import blob_video, branch_video, build_fake_tapir, write_mp4


def test_rce_track_default_tracker(tmp_path, capsys):
    bv = branch_video(n_frames=40, size=(200, 200), n_nodes=6, occluder=False, seed=2)
    video = write_mp4(bv.frames, tmp_path / "v.mp4")
    ann, graph = tmp_path / "ann.json", tmp_path / "graph.json"
    ann.write_text(json.dumps({"points": bv.true_xy[:, 0].tolist()}))
    graph.write_text(json.dumps({"root": 0, "edges": bv.edges}))
    out = tmp_path / "tracks.csv"
    assert main(["track", str(video), str(ann), "--graph", str(graph), "--out", str(out), "--max-frames", "30"]) == 0
    assert "wrote" in capsys.readouterr().out
    tracks = load_tracks(out, load_graph(graph))
    assert tracks.n_frames == 30
    err = np.hypot(*(tracks.xy - bv.true_xy[:, :30]).transpose(2, 0, 1))
    assert np.nanmedian(err) < 0.5


def test_rce_track_with_onnx_model(tmp_path):
    frames, centres = blob_video(n_frames=10, size=(160, 120))
    video = write_mp4(frames, tmp_path / "blob.mp4")
    model = build_fake_tapir(tmp_path / "model")
    ann = tmp_path / "ann.json"
    ann.write_text(json.dumps({"points": [centres[0].tolist()]}))
    out = tmp_path / "t.csv"
    assert main(["track", str(video), str(ann), "--out", str(out), "--model", str(model), "--no-progress"]) == 0
    import pandas as pd
    df = pd.read_csv(out)
    assert list(df.columns) == ["point_id", "frame", "x", "y", "visible", "sigma_px"] and len(df) == 10
    np.testing.assert_allclose(df[["x", "y"]].iloc[0], centres[0], atol=0.3)


def test_rce_track_bad_input_is_one_line_error(tmp_path, capsys):
    frames, _ = blob_video(n_frames=3, size=(64, 48))
    video = write_mp4(frames, tmp_path / "v.mp4")
    ann = tmp_path / "ann.json"
    ann.write_text(json.dumps({"points": [[500, 5]]}))
    assert main(["track", str(video), str(ann), "--out", str(tmp_path / "t.csv")]) == 2
    err = capsys.readouterr().err
    assert "ann.json" in err and "outside the 64x48 image" in err and "Traceback" not in err
    assert not (tmp_path / "t.csv").exists()


def test_rce_annotate(tmp_path):
    a, g = tmp_path / "a.json", tmp_path / "g.json"
    assert main(["annotate", "--polyline", "10,100,10,20", "--nodes", "5", "--out-annotations", str(a),
                 "--out-graph", str(g)]) == 0
    pts = np.array(json.loads(a.read_text())["points"])
    np.testing.assert_allclose(pts[:, 1], [100, 80, 60, 40, 20])
    assert load_graph(g).nodes == (0, 1, 2, 3, 4)
    assert main(["annotate", "--nodes", "3"]) == 2  # the polyline mode needs all four options


@pytest.mark.parametrize("argv, message", [
    (["--polyline", "10,100,10,20", "--nodes", "2"], "--nodes: must be >= 3"),
    (["--polyline", "-10,100,10,20", "--nodes", "4"], "--polyline: vertex 0 (x=-10, y=100) is outside the image"),
    (["--polyline", "10,-5.5,10,20", "--nodes", "4"], "--polyline: vertex 0 (x=10, y=-5.5) is outside the image"),
    ([], "give a VIDEO to annotate in the browser"),
])
def test_rce_annotate_bad_input_is_one_line(tmp_path, capsys, argv, message):
    a, g = tmp_path / "a.json", tmp_path / "g.json"
    outs = ["--out-annotations", str(a), "--out-graph", str(g)] if argv else []
    assert main(["annotate", *argv, *outs]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not a.exists() and not g.exists()
