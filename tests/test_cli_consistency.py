"""The command line as a user meets it: quick answers, one meaning per option, ordinary files, progress bars,
CLI words, and `rce track` + `rce analyze` + `rce diagnose` giving exactly what `rce run` gives."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from rce_gtsam.cli import main

RCE = [sys.executable, "-m", "rce_gtsam.cli"]


def _best_of(cmd, n=5) -> float:
    best = float("inf")
    for _ in range(n):
        t = time.perf_counter()
        subprocess.run(cmd, capture_output=True, check=False)
        best = min(best, time.perf_counter() - t)
    return best


def test_help_and_argument_errors_answer_in_half_a_second():
    """`rce --help` and an argument error need no numpy/pandas/scipy: best of 5 subprocesses < 0.5 s (on a
    machine so loaded that a bare interpreter start takes > 0.12 s: within 4x of that start, measured here)."""
    bare = _best_of([sys.executable, "-c", "import argparse, pathlib, dataclasses"])
    for cmd in ([*RCE, "--help"], [*RCE, "analyze"], [*RCE, "simulate", "--frames", "x"]):
        assert _best_of(cmd) < max(0.5, 4 * bare), cmd
    out = subprocess.run([*RCE, "--help"], capture_output=True, text=True).stdout
    assert "analyze" in out and "simulate" in out
    imported = subprocess.run([sys.executable, "-c", "import sys, rce_gtsam.cli as c; c.build_parser(); "
                               "print(' '.join(m for m in ('numpy', 'pandas', 'scipy', 'matplotlib') "
                               "if m in sys.modules))"], capture_output=True, text=True, check=True).stdout
    assert imported.strip() == ""


def test_an_analysis_without_effects_imports_neither_the_effects_nor_scipy_signal():
    """rce analyze fits no effect: the effect library (and scipy.signal and scipy.stats, which dynamics and the
    tests bring in: 0.9 s of a 4 s run on plant 1) is imported only when an analysis asks for an effect."""
    code = ("import sys, rce_gtsam; rce_gtsam.analyze('data/sample/tracks.csv', 'data/sample/graph.json', n_boot=20); "
            "print(' '.join(m for m in ('rce_gtsam.effects', 'scipy.signal', 'scipy.stats') if m in sys.modules))")
    imported = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                              cwd=Path(__file__).resolve().parents[1]).stdout
    assert imported.strip() == ""


def test_simulate_realism_choices_match_the_presets():
    from rce_gtsam.cli import build_parser
    from rce_gtsam.sim.nuisance import REALISM
    sub = next(a for a in build_parser()._actions if a.dest == "command").choices["simulate"]
    realism = next(a for a in sub._actions if a.dest == "realism")
    assert set(realism.choices) == set(REALISM)
    assert "nonlinear (default" in sub.format_help()  # the lazily built epilog
    from rce_gtsam.sim.simulate import EFFECT_FORMS
    helptext = " ".join(sub.format_help().split())
    assert "Forms (--form NAME=FORM)" in helptext
    assert all(f"{k}: {next(iter(forms))} (" in helptext and all(f"{f} (" in helptext for f in forms)
               for k, forms in EFFECT_FORMS.items())  # every form listed, the default first


def test_cli_wording_names_the_command():
    from rce_gtsam.cli.wording import cli_wording
    from rce_gtsam.effects import CANDIDATES
    for name, factory in CANDIDATES.items():  # the two phrasings the diagnosis' explanations use
        for text in (f"so... Fit the model with {factory.__name__}() (lag grows)",
                     f"x. Fit with {factory.__name__}();"):
            out = cli_wording(text)
            assert "()" not in out and f"rce analyze TRACKS GRAPH --effects {name}`" in out


def test_run_wording_says_the_extended_kappa_is_already_written():
    """``rce run`` fits the named effect's model itself and writes its kappa (kappa_<effect>): the verdict's advice to
    fit it and read kappa from the extended fit then says where that kappa is, instead of a second command."""
    from rce_gtsam.cli.wording import cli_wording
    import inspect

    from rce_gtsam.diagnosis import explain
    from rce_gtsam.effects import CANDIDATES
    assert "and read kappa from the extended fit." in inspect.getsource(explain)  # the sentence the run rewrites
    for name, factory in CANDIDATES.items():
        text = (f"What it means: lags. Fit the model with {factory.__name__}() and read kappa from the extended "
                "fit. Next.")
        out = cli_wording(text, written=f"kappa_{name}")
        assert "rce analyze" not in out and "()" not in out
        assert f"This run fitted it: kappa from the extended fit, with its own intervals, is kappa_{name} in " \
               "compliance_summary.csv. Next." in out
        assert f"--effects {name}`" in cli_wording(text)  # rce diagnose writes no extended kappa: the command


@pytest.fixture(scope="module")
def video_sim(tmp_path_factory):
    out = tmp_path_factory.mktemp("consistency_sim")
    assert main(["simulate", "--seed", "2", "--frames", "120", "--nodes", "7", "--effect", "offset",
                 "--strength", "offset=3", "--video", "--out", str(out)]) == 0
    return out


def test_track_analyze_diagnose_equal_run(video_sim, tmp_path, capsys):
    """kappa, its CIs, the verdict and the candidate ranking are identical, and files have ordinary modes."""
    s = video_sim
    common = ["--bootstrap", "10", "--seed", "3", "--quiet"]
    run_out = tmp_path / "run"
    assert main(["run", str(s / "video.mp4"), str(s / "annotations.json"), str(s / "graph.json"), "--out",
                 str(run_out), "--candidates", "offset,second_mode", "--no-figures", *common]) == 0
    tracks = tmp_path / "steps" / "tracks.csv"
    assert main(["track", str(s / "video.mp4"), str(s / "annotations.json"), "--graph", str(s / "graph.json"),
                 "--out", str(tracks), "--quiet"]) == 0
    assert main(["analyze", str(tracks), str(s / "graph.json"), "--out", str(tmp_path / "steps"),
                 "--no-figures", *common]) == 0
    assert main(["diagnose", str(tracks), str(s / "graph.json"), "--json", str(tmp_path / "steps" / "d.json"),
                 "--candidates", "offset,second_mode", "--seed", "3", "--quiet"]) == 0
    assert (run_out / "tracks.csv").read_bytes() == tracks.read_bytes()
    a = pd.read_csv(run_out / "compliance_summary.csv")
    b = pd.read_csv(tmp_path / "steps" / "compliance_summary.csv")
    cols = ["kappa", "kappa_ci_low", "kappa_ci_high"]
    np.testing.assert_array_equal(a[cols].to_numpy(), b[cols].to_numpy())
    da = json.loads((run_out / "diagnosis.json").read_text())
    db = json.loads((tmp_path / "steps" / "d.json").read_text())
    assert da["verdict"] == db["verdict"]
    assert [c["effect"] for c in da["candidates"]] == [c["effect"] for c in db["candidates"]]
    assert [c["heldout_rmse"] for c in da["candidates"]] == [c["heldout_rmse"] for c in db["candidates"]]
    assert "()" not in da["explanation"]
    # ordinary modes everywhere (tempfile's 0700 / 0600 would leak otherwise)
    umask = os.umask(0)
    os.umask(umask)
    for p in [run_out, *run_out.rglob("*"), tracks, tmp_path / "steps" / "d.json"]:
        want = (0o777 if p.is_dir() else 0o666) & ~umask
        assert p.stat().st_mode & 0o777 == want, p


def test_deprecated_effects_option_of_diagnose_still_works_with_a_note(chain, capsys):
    tracks, graph = chain[:2]
    out = Path(graph).parent / "d.json"
    assert main(["diagnose", str(tracks), str(graph), "--json", str(out), "--effects", "offset", "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "--candidates" in err and len(err.strip().splitlines()) == 1
    assert [c["effect"] for c in json.loads(out.read_text())["candidates"]] == ["offset"]


def test_progress_bars_on_stderr_and_quiet_silences_them(chain, tmp_path):
    """A step bar names each step on stderr (forced on with RCE_PROGRESS=1, as on a terminal); --quiet
    draws nothing; stdout carries the summary either way; the printed total is the process's wall time."""
    tracks, graph = chain[:2]
    env = {**os.environ, "RCE_PROGRESS": "1"}
    cmd = [*RCE, "analyze", str(tracks), str(graph), "--out", str(tmp_path / "a"), "--bootstrap", "20"]
    t = time.perf_counter()
    loud = subprocess.run(cmd, capture_output=True, text=True, env=env, check=True)
    wall = time.perf_counter() - t
    for step in ("smooth", "bootstrap", "figures"):
        assert f"analyze: {step}" in loud.stderr
    total = float(loud.stdout.split("\ntotal ")[1].split()[0])
    assert 0.5 * wall < total <= wall
    quiet = subprocess.run([*cmd, "--quiet", "--no-figures"], capture_output=True, text=True, env=env, check=True)
    assert quiet.stderr == "" and "kappa" in quiet.stdout
    assert (tmp_path / "a" / "figures" / "compliance.png").is_file()


def test_the_candidates_help_lists_the_registered_effects():
    """``--candidates``' help writes the default list out (importing the effects would slow ``--help``); it must
    be the registry's, built-in effects in the order the diagnosis tries them."""
    from rce_gtsam import effects
    from rce_gtsam.cli.wording import DEFAULT_CANDIDATES

    assert DEFAULT_CANDIDATES.split(",") == list(effects.names())
