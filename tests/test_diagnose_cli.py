"""`rce diagnose`: printed report, JSON schema (issue 3), atomic writes, --figures / --rerun, bad input."""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import pytest
from rerun.chunk import RrdReader

from rce_gtsam.cli import main
from rce_gtsam.effects import EFFECT_NAMES

SAMPLE = Path(__file__).resolve().parents[1] / "data" / "sample"
FAST = "offset,second_mode"  # the two candidates whose held-out scoring takes < 1 s on the sample


def _check_schema(d: dict, candidates: set[str]) -> None:
    assert isinstance(d["baseline"]["heldout_rmse"], float) and d["baseline"]["heldout_rmse"] > 0
    cands = d["candidates"]
    assert {c["effect"] for c in cands} == candidates
    rmse = [c["heldout_rmse"] for c in cands]
    assert rmse == sorted(rmse), "candidates must be sorted best (lowest held-out RMSE) first"
    for c in cands:
        assert isinstance(c["evidence"], float) and isinstance(c["heldout_rmse"], float)
    assert d["verdict"] is None or d["verdict"] in candidates
    assert isinstance(d["explanation"], str) and len(d["explanation"]) > 40
    edges = set(d["edges"])
    assert d["worst_edges"] and all(w["edge"] in edges and w["residual_rms_deg"] > 0 for w in d["worst_edges"])
    assert d["worst_frames"] and all(w["first_frame"] <= w["last_frame"] for w in d["worst_frames"])


def test_diagnose_sample_json_report_figures_recording(tmp_path, capsys):
    js, figs, rrd = tmp_path / "d" / "diagnosis.json", tmp_path / "figs", tmp_path / "rec.rrd"
    assert main(["diagnose", str(SAMPLE / "tracks.csv"), str(SAMPLE / "graph.json"), "--json", str(js),
                 "--effects", FAST, "--figures", str(figs), "--rerun", str(rrd)]) == 0
    out = capsys.readouterr().out
    for section in ("[[Diagnosis]]", "[[Where the baseline fails]]", "[[Candidates]]", "[[Verdict]]"):
        assert section in out
    d = json.loads(js.read_text())
    _check_schema(d, {"offset", "second_mode"})
    assert d["inputs"]["preset"] == "default" and len(d["frames"]) == 600
    # the sample has no hidden effect
    assert d["verdict"] is None
    assert [p.name for p in js.parent.iterdir()] == ["diagnosis.json"]  # no temp file left behind
    names = {p.name for p in figs.iterdir()}
    assert {"heldout_error.png", "residuals_diagnosis.png", "residuals.png", "compliance.png",
            "variance_budget.png", "residual_analysis.png"} <= names
    assert not [n for n in names if n.startswith(".")]
    paths = Counter(str(ch.entity_path) for ch in RrdReader(str(rrd)).stream())
    assert "/diagnosis/report" in paths and "/diagnosis/heldout" in paths
    assert "/diagnosis/budget/unexplained_deg2" in paths and "/diagnosis/budget/noise_floor_deg2" in paths


def test_diagnose_finds_hidden_offset_and_prints_fit_report(tmp_path, capsys):
    sim = tmp_path / "sim"
    assert main(["simulate", "--clean", "--effect", "offset", "--seed", "0", "--frames", "400", "--nodes", "12",
                 "--out", str(sim)]) == 0
    js = tmp_path / "d.json"
    capsys.readouterr()
    assert main(["diagnose", str(sim / "tracks.csv"), str(sim / "graph.json"), "--json", str(js),
                 "--effects", FAST]) == 0
    out = capsys.readouterr().out
    d = json.loads(js.read_text())
    _check_schema(d, {"offset", "second_mode"})
    assert d["verdict"] == "offset"
    best = d["candidates"][0]
    assert best["effect"] == "offset" and best["heldout_rmse"] < 0.85 * d["baseline"]["heldout_rmse"]
    assert best["params"]["c[0]"]["stderr"] > 0
    # the lmfit-like report of the verdict model: statistics and parameters with standard errors
    for key in ("[[Model]]", "[[Fit Statistics]]", "[[Variables]]", "Akaike info crit", "offset.c[", "+/-"):
        assert key in out


def test_unknown_effect_is_one_line_error_and_writes_nothing(tmp_path, capsys):
    js, figs = tmp_path / "d.json", tmp_path / "figs"
    rc = main(["diagnose", str(SAMPLE / "tracks.csv"), str(SAMPLE / "graph.json"), "--json", str(js),
               "--effects", "offset,wind", "--figures", str(figs)])
    assert rc == 2
    err = capsys.readouterr().err
    assert "wind" in err and all(n in err for n in EFFECT_NAMES) and "Traceback" not in err
    assert not js.exists() and not figs.exists()


def test_bad_tracks_fail_cleanly_and_keep_the_old_json(tmp_path, capsys):
    bad = tmp_path / "tracks.csv"
    bad.write_text("point_id,frame,x\n0,0,1.0\n")  # no y column
    js = tmp_path / "d.json"
    js.write_text('{"old": true}\n')
    rc = main(["diagnose", str(bad), str(SAMPLE / "graph.json"), "--json", str(js), "--effects", "offset",
               "--figures", str(tmp_path / "figs"), "--rerun", str(tmp_path / "r.rrd")])
    assert rc == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "Traceback" not in err
    assert json.loads(js.read_text()) == {"old": True}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.json", "tracks.csv"]


@pytest.mark.parametrize("folds", ["1"])
def test_too_few_folds_rejected(tmp_path, capsys, folds):
    assert main(["diagnose", str(SAMPLE / "tracks.csv"), str(SAMPLE / "graph.json"), "--json",
                 str(tmp_path / "d.json"), "--folds", folds]) == 2
    assert "--folds" in capsys.readouterr().err
