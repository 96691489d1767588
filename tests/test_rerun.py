"""Rerun recordings: entity paths and row counts read back with rerun.chunk.RrdReader, `rerun rrd verify`."""

from __future__ import annotations

import subprocess
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from rerun.chunk import RrdReader

from viz_fixtures import small_analysis, write_mp4v_video

RERUN_CLI = Path(sys.executable).with_name("rerun")


@pytest.fixture(scope="module")
def analysis():
    return small_analysis()


def _rows(path) -> tuple[Counter, Counter]:
    """(temporal rows, static rows) per entity path."""
    temporal, static = Counter(), Counter()
    for ch in RrdReader(str(path)).stream():
        (static if ch.is_static else temporal)[str(ch.entity_path)] += ch.num_rows
    return temporal, static


def _verify(path):
    if not RERUN_CLI.exists():
        pytest.skip("rerun CLI not installed next to the interpreter")
    out = subprocess.run([str(RERUN_CLI), "rrd", "verify", str(path)], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr


def test_recording_entities_and_rows(analysis, tmp_path, monkeypatch):
    monkeypatch.setenv("RERUN_STRICT", "1")
    from rce_gtsam.viz import save_recording
    sim, result = analysis
    path = save_recording(result, tmp_path / "a.rrd")
    assert path.is_file() and path.stat().st_size > 10_000
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")], "temporary file left behind"
    temporal, static = _rows(path)
    F = result.tracks.n_frames
    T = len(result.response.frames)
    E = len(result.response.edges)
    # image space: one row per frame
    for ent in ("image/tracks/raw", "image/tracks/smoothed", "image/tracks/uncertainty", "image/skeleton/kappa"):
        assert temporal[f"/{ent}"] == F, ent
    for ent in ("image/skeleton/residual", "image/skeleton/predicted"):
        assert temporal[f"/{ent}"] == T, ent
    # time series: one row per response frame for every edge
    assert temporal["/excitation/z"] == T
    bend = sorted(k for k in temporal if k.startswith("/bending/") and not k.endswith("/band"))
    assert len(bend) == E and all(temporal[k] == T for k in bend)
    assert sum(k.startswith("/residuals/") for k in temporal) == E
    assert static["/summary/table"] == 1 and static["/summary/kappa"] == 1
    reader = RrdReader(str(path))
    assert len(reader.blueprints()) >= 1, "no default blueprint"
    _verify(path)


def test_recording_values_round_trip(analysis, tmp_path):
    """The bulk-logged series hold exactly the observed / predicted numbers."""
    from rce_gtsam.viz import save_recording
    _, result = analysis
    path = save_recording(result, tmp_path / "a.rrd")
    e = result.response.edges[-1]
    i = len(result.response.edges) - 1
    got = None
    for ch in RrdReader(str(path)).stream():
        if str(ch.entity_path) == f"/bending/edge_{e[0]}_{e[1]}" and not ch.is_static:
            rb = ch.to_record_batch()
            got = np.array(rb.column("Scalars:scalars").to_pylist(), dtype=float)
            frames = np.array(rb.column("frame").to_pylist())
    assert got is not None
    order = np.argsort(frames)
    np.testing.assert_allclose(frames[order], result.response.frames)
    np.testing.assert_allclose(got[order, 1], result.fit.predict()[i], rtol=1e-6, atol=1e-9)
    obs = result.response.Y[i]
    ok = np.isfinite(obs)
    np.testing.assert_allclose(got[order, 0][ok], obs[ok], rtol=1e-6, atol=1e-9)


def test_predicted_skeleton_follows_the_model(analysis):
    """Forward kinematics of the *observed* bending reproduces the measured skeleton; the model's
    prediction departs from it by about the residual, growing toward the tip."""
    from rce_gtsam.viz.scene import AnalysisView, predicted_skeleton
    _, r = analysis
    v = AnalysisView.from_result(r)
    b, resp = r.bending, r.response
    dobs = b.delta_deg[resp.bend_rows][:, resp.frames]
    p_obs = predicted_skeleton(r.graph, r.tracks.node_ids, v.xy, v.frames, v.edges, np.nan_to_num(dobs),
                               b.rest_deg[resp.bend_rows], r.geometry.rest_length_px, b.signed, dobs)
    d_obs = np.linalg.norm(p_obs[:, v.frames] - v.xy[:, v.frames], axis=-1)
    d_pred = np.linalg.norm(v.predicted_xy[:, v.frames] - v.xy[:, v.frames], axis=-1)
    root = int(np.flatnonzero(r.tracks.node_ids == r.graph.root)[0])
    assert np.nanmax(d_obs[root]) < 1e-9 and np.nanmax(d_pred[root]) < 1e-9
    assert np.nanmedian(d_obs) < 0.5  # only segment-length changes remain
    assert np.nanmedian(d_pred[-1]) > np.nanmedian(d_obs[-1])
    assert np.isnan(v.predicted_xy[:, np.setdiff1d(np.arange(v.n_frames), v.frames)]).all()


def test_video_is_transcoded_and_referenced(analysis, tmp_path):
    from rce_gtsam.viz import save_recording
    from rce_gtsam.viz.video import video_codec
    _, result = analysis
    video = tmp_path / "mp4v.mp4"
    write_mp4v_video(video, result.tracks.n_frames)
    assert video_codec(video) == "mpeg4"
    path = save_recording(result, tmp_path / "v.rrd", video_path=video)
    temporal, static = _rows(path)
    assert static["/image/video"] == 1
    assert temporal["/image/video"] == result.tracks.n_frames
    _verify(path)


def test_diagnosis_and_view_command(analysis, tmp_path):
    """`rce view DIR` rebuilds the same recording from an output folder, with a diagnosis JSON."""
    import json
    from rce_gtsam.cli import main
    from rce_gtsam.viz.scene import AnalysisView
    _, result = analysis
    out = tmp_path / "out"
    result.write(out)
    v1, v2 = AnalysisView.from_result(result), AnalysisView.from_folder(out)
    assert v1.edges == v2.edges
    np.testing.assert_allclose(v2.kappa, v1.kappa, rtol=1e-6)
    np.testing.assert_allclose(v2.pred, v1.pred, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(np.nan_to_num(v2.Y), np.nan_to_num(v1.Y), atol=1e-6)
    np.testing.assert_allclose(v2.predicted_xy, v1.predicted_xy, atol=1e-3, equal_nan=True)
    E, T = result.response.Y.shape
    diag = {"baseline": {"heldout_rmse": 1.0}, "verdict": "delay", "explanation": "Distal segments lag.",
            "candidates": [{"effect": "delay", "heldout_rmse": 0.7, "evidence": 12.0},
                           {"effect": "offset", "heldout_rmse": 0.98, "evidence": 0.5}],
            "worst_edges": [{"edge": "5->6", "rms": 1.2}], "worst_frames": [{"start": 10, "end": 30}],
            "after_prediction": (result.fit.predict() * 0.9).tolist(),
            "budget": {"total": 2.0, "rank1": 1.0, "effects": {}, "noise_floor": 0.8, "unexplained": 0.2,
                       "unexplained_se": 0.1, "status": "noise"},
            "budget_per_segment": [{"segment": str(i), "total": 2.0, "rank1": 1.0, "noise_floor": 0.8,
                                    "unexplained": 0.2, "unexplained_se": 0.3} for i in range(E)]}
    (out / "diagnosis.json").write_text(json.dumps(diag))
    assert main(["view", str(out), "--rrd", str(tmp_path / "v.rrd")]) == 0
    temporal, static = _rows(tmp_path / "v.rrd")
    assert static["/diagnosis/report"] == 1 and static["/diagnosis/heldout"] == 1
    assert all(static[f"/diagnosis/budget/{p}_deg2"] == 1 for p in ("total", "rank1", "noise_floor", "unexplained"))
    assert sum(k.startswith("/diagnosis/after/") for k in temporal) == E
    assert temporal["/image/tracks/raw"] == 0  # the simulation's tracks were never a file
    _verify(tmp_path / "v.rrd")
    assert main(["view", str(tmp_path / "nope")]) == 2


def test_after_a_verdict_the_recording_shows_the_kappa_to_report(analysis, tmp_path, monkeypatch):
    """With the κ of a model with a named effect (``kappa_choice.fitted``), the recording adds the skeleton coloured by
    it (every frame), its bar chart and its columns in the table, and the default layout hides the rank-1 skeleton;
    ``rce view`` on the written folder rebuilds the same κ from compliance_summary.csv's ``report`` column."""
    import dataclasses

    from rce_gtsam.kappa_report import KappaChoice
    from rce_gtsam.viz import save_recording
    from rce_gtsam.viz.blueprint import build_blueprint
    from rce_gtsam.viz.rerun_log import summary_markdown
    from rce_gtsam.viz.scene import AnalysisView
    monkeypatch.setenv("RERUN_STRICT", "1")
    _, result = analysis
    k = np.asarray(result.fit.kappa, float)
    choice = KappaChoice("delay", "rank-1 + delay", "named", tuple(result.response.edges), k[::-1].copy(), k / 2, k * 2,
                         np.nan_to_num(result.response.Y))
    named = dataclasses.replace(result, kappa_choice=choice)
    path = save_recording(named, tmp_path / "a.rrd")
    temporal, static = _rows(path)
    assert temporal["/image/skeleton/kappa_to_report"] == temporal["/image/skeleton/kappa"] == result.tracks.n_frames
    assert static["/summary/kappa_to_report"] == 1
    view = AnalysisView.from_result(named)
    assert view.report_column == "kappa_delay" and np.allclose(view.kappa_report, k[::-1])
    table = summary_markdown(view)
    first = next(ln for ln in table.splitlines() if ln.startswith(f"| {view.edges[0][0]}→{view.edges[0][1]} |"))
    assert "**Report `kappa_delay`**" in table and "`kappa_delay` | 95 % CI |" in table
    rows = [ln for ln in table.splitlines() if ln.startswith("|")]
    assert len({ln.count("|") for ln in rows}) == 1, rows[:3]  # header, rule and rows have the same cells
    assert first.endswith(f" {k[-1]:.3f} | [{k[0] / 2:.3f}, {k[0] * 2:.3f}] |"), first  # its κ and CI, last columns
    seen = {}
    import rerun.blueprint as rrb
    real = rrb.Spatial2DView

    def spy(*a, **kw):
        seen.update(kw)
        return real(*a, **kw)
    monkeypatch.setattr(rrb, "Spatial2DView", spy)
    build_blueprint(view)
    assert "- $origin/skeleton/kappa" in seen["contents"]
    build_blueprint(AnalysisView.from_result(result))
    assert "- $origin/skeleton/kappa" not in seen["contents"]
    plain = AnalysisView.from_result(result)
    assert plain.kappa_report is None and "Report" not in summary_markdown(plain)
    _verify(path)
    # the output folder: compliance_summary.csv's report column names kappa_delay, and the view reads it back
    named.write(tmp_path / "out")
    back = AnalysisView.from_folder(tmp_path / "out")
    assert back.report_column == "kappa_delay" and np.allclose(back.kappa_report, view.kappa_report)
    assert np.allclose(back.ci_high_report, view.ci_high_report)
