"""`rce run` end to end on a short rendered simulation: diagnosis.json, diagnosis figures, recording."""

from __future__ import annotations

import json
from collections import Counter

import pytest
from rerun.chunk import RrdReader

from rce_gtsam.cli import main


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    out = tmp_path_factory.mktemp("run_sim")
    assert main(["simulate", "--seed", "0", "--frames", "200", "--nodes", "10", "--video", "--out", str(out)]) == 0
    return out


def _args(sim):
    return [str(sim / "video.mp4"), str(sim / "annotations.json"), str(sim / "graph.json")]


def test_run_writes_diagnosis_figures_and_recording(sim, tmp_path, capsys):
    out, rrd = tmp_path / "run", tmp_path / "run" / "rec.rrd"
    assert main(["run", *_args(sim), "--out", str(out), "--effects", "offset,second_mode", "--bootstrap", "20",
                 "--no-progress", "--rerun", str(rrd)]) == 0
    printed = capsys.readouterr().out
    assert "[[Diagnosis]]" in printed and "[[Verdict]]" in printed and "kappa" in printed
    names = {p.name for p in out.iterdir()}
    assert {"tracks.csv", "diagnosis.json", "report.json", "compliance_summary.csv", "figures", "rec.rrd"} <= names
    d = json.loads((out / "diagnosis.json").read_text())
    assert {c["effect"] for c in d["candidates"]} == {"offset", "second_mode"}
    assert isinstance(d["baseline"]["heldout_rmse"], float) and "verdict" in d and d["explanation"]
    assert d["inputs"]["video"].endswith("video.mp4")
    figs = {p.name for p in (out / "figures").iterdir()}
    assert {"heldout_error.png", "residuals_diagnosis.png", "kappa_overlay.png"} <= figs
    paths = Counter(str(ch.entity_path) for ch in RrdReader(str(rrd)).stream())
    assert "/diagnosis/report" in paths


def test_run_bad_effect_fails_before_tracking(sim, tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["run", *_args(sim), "--out", str(out), "--effects", "offsett", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "offsett" in err and "second_mode" in err and "Traceback" not in err
    assert not out.exists()


def test_run_to_a_log_prints_plain_progress_lines_and_times_the_diagnosis(sim, tmp_path, capsys, monkeypatch):
    """stderr captured (not a terminal, as in a log file): one flushed line per stage and per tenth of the
    tracking, no carriage returns; the timing line names the diagnosis as its own stage, apart from write."""
    monkeypatch.delenv("RCE_PROGRESS", raising=False)
    out = tmp_path / "run"
    assert main(["run", *_args(sim), "--out", str(out), "--candidates", "offset", "--bootstrap", "10",
                 "--no-figures"]) == 0
    cap = capsys.readouterr()
    assert "\r" not in cap.err
    lines = cap.err.strip().splitlines()
    assert any(ln.startswith("rce run: tracking ") and "/200 frames" in ln for ln in lines), cap.err
    for stage in ("smooth", "bootstrap", "diagnosis", "write"):
        assert any(ln.startswith("rce run: [") and f"] {stage} (" in ln for ln in lines), cap.err
    together = next(ln for ln in cap.out.splitlines() if ln.startswith("Read together: "))
    assert "segments ok" in together and "informative" in together and "leaves: " in together, together
    timing = next(ln for ln in cap.out.splitlines() if ln.startswith("total "))
    parts = dict(p.rsplit(" ", 1) for p in timing.split("(", 1)[1].rstrip(")").split(", "))
    assert {"track", "diagnosis", "write"} <= set(parts), timing
    assert float(parts["diagnosis"]) > 0 and float(parts["write"]) < float(parts["diagnosis"]) + 5, timing
    quiet = main(["run", *_args(sim), "--out", str(tmp_path / "q"), "--candidates", "offset", "--bootstrap", "0",
                  "--no-figures", "--quiet"])
    assert quiet == 0 and capsys.readouterr().err == ""


def test_run_says_first_when_the_trackers_kernels_must_be_compiled(sim, tmp_path, capsys, monkeypatch):
    """The first run on a machine compiles the tracker's numba kernels before its first frame (17 s of silence in a
    fresh clone's ``make demo``): the run says so first, and only then. The check reads numba's real cache: empty
    (NUMBA_CACHE_DIR pointing at an empty folder, in a fresh process) it reports the kernels missing; after a run
    has tracked, present."""
    import os
    import subprocess
    import sys

    from rce_gtsam.track import match_kernels

    probe = "from rce_gtsam.track.match_kernels import compiled_on_this_machine as c; print(c())"
    cold = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                          env={**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "empty_cache")})
    assert cold.stdout.strip() == "False", cold.stderr
    monkeypatch.delenv("RCE_PROGRESS", raising=False)
    args = [*_args(sim), "--candidates", "offset", "--bootstrap", "0", "--no-figures", "--max-frames", "80"]
    assert main(["run", *args, "--out", str(tmp_path / "warm")]) == 0
    assert match_kernels.compiled_on_this_machine()  # the run above compiled (or loaded) them
    # only kernels every such track calls: a fallback (match_node) no clip has needed yet must not make every
    # later run announce a compilation
    assert match_kernels.match_node not in match_kernels.kernels_called()
    assert "compiling the tracker's kernels" not in capsys.readouterr().err
    monkeypatch.setattr(match_kernels, "compiled_on_this_machine", lambda kernels=None: False)
    assert main(["run", *args, "--out", str(tmp_path / "cold")]) == 0
    err = capsys.readouterr().err.splitlines()
    first_tracking = next(i for i, ln in enumerate(err) if ln.startswith("rce run: tracking "))
    assert "rce run: compiling the tracker's kernels: once on this machine" in err[first_tracking - 1], err
    assert main(["run", *args, "--out", str(tmp_path / "quiet"), "--quiet"]) == 0
    assert capsys.readouterr().err == ""
