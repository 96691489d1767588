"""The README cannot drift: its `rce` commands and its Python snippets run here, on the README's own data, and
the numbers it quotes are compared with what they print or write.

* every ``.venv/bin/rce ...`` line of README.md (backslash continuations joined) runs, in order, in a scratch
  folder that holds the repository's ``data/``; each must exit 0;
* a fenced block without a language holding ``"baseline"`` (a JSON excerpt of ``rce diagnose``), where there is
  one, is read as JSON with ``...`` as "anything": each number in it must equal ``out/diagnosis.json``;
* a command's ``# verdict: NAME, held-out RMSE A -> B deg`` comment must match the JSON that command wrote;
* the ```python blocks run, in order, as one script;
* the README stays a short introduction: at most 200 lines, no development history.
"""

from __future__ import annotations

import json
import math
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
README = (REPO / "README.md").read_text()
FENCED = re.compile(r"^```(\w*)\n(.*?)^```", re.S | re.M)


def rce_commands(text: str = README) -> list[tuple[str, str]]:
    """(command line after ``.venv/bin/rce``, trailing comment) of every README command, in order."""
    body = FENCED.sub("", text)
    out, lines = [], body.splitlines()
    i = 0
    while i < len(lines):
        line = lines[i].strip()
        if line.startswith(".venv/bin/rce "):
            cmd = line
            while cmd.split("#")[0].rstrip().endswith("\\"):
                i += 1
                cmd = cmd.split("#")[0].rstrip()[:-1] + " " + lines[i].strip()
            code, _, comment = cmd.partition("#")
            out.append((code.strip().removeprefix(".venv/bin/rce ").strip(), comment.strip()))
        i += 1
    return out


def fenced(lang: str) -> list[str]:
    return [code for kind, code in FENCED.findall(README) if kind == lang]


class Quoted(float):
    """A number as the README writes it: its value and how many decimals it shows (1.370 -> 3)."""

    def __new__(cls, text: str):
        q = super().__new__(cls, text)
        q.decimals = len(text.split(".")[1]) if "." in text else 0
        return q


def excerpt_as_json(text: str):
    """The README's JSON excerpt as a value: ``...`` entries dropped or read as null; numbers as Quoted."""
    t = re.sub(r",\s*\.\.\.\s*([}\]])", r"\1", text)
    t = t.replace("{...}", "null").replace("[...]", "null")
    t = re.sub(r":\s*\.\.\.", ": null", t)
    return json.loads(t, parse_float=Quoted)


def assert_quoted(quoted, actual, where="") -> int:
    """Every number (and string) in ``quoted`` equals ``actual`` to the quoted decimals; returns how many."""
    n = 0
    if isinstance(quoted, dict):
        for k, v in quoted.items():
            if v is not None:
                assert k in actual, f"{where}.{k} is quoted but not written"
                n += assert_quoted(v, actual[k], f"{where}.{k}")
    elif isinstance(quoted, list):
        for i, v in enumerate(quoted):
            if v is not None:
                n += assert_quoted(v, actual[i], f"{where}[{i}]")
    elif isinstance(quoted, float):  # to the decimals shown, with one unit of slack for rounding
        decimals = getattr(quoted, "decimals", None)
        if decimals is None:
            decimals = len(repr(quoted).split(".")[1]) if "." in repr(quoted) else 0
        assert math.isclose(actual, quoted, abs_tol=10.0 ** -decimals), f"{where}: README {quoted}, now {actual}"
        n += 1
    elif isinstance(quoted, str) and quoted.endswith("..."):  # a quoted beginning
        assert actual.startswith(quoted[:-3].rstrip()), f"{where}: README {quoted!r}, now {actual!r}"
    else:
        assert actual == quoted, f"{where}: README {quoted!r}, now {actual!r}"
        n += 1
    return n


@pytest.fixture(scope="module")
def workspace(tmp_path_factory):
    ws = tmp_path_factory.mktemp("readme")
    (ws / "data").symlink_to(REPO / "data")
    return ws


@pytest.fixture(scope="module")
def ran_commands(workspace):
    cmds = rce_commands()
    assert len(cmds) >= 5
    for cmd, _ in cmds:
        p = subprocess.run([sys.executable, "-m", "rce_gtsam.cli", *shlex.split(cmd)], cwd=workspace,
                           capture_output=True, text=True)
        assert p.returncode == 0, f"README command failed: rce {cmd}\n{p.stderr[-2000:]}"
    return cmds


@pytest.mark.slow
def test_readme_commands_run_and_their_quoted_numbers_hold(workspace, ran_commands):
    for excerpt in (b for b in fenced("") if '"baseline"' in b):
        diag = json.loads((workspace / "out" / "diagnosis.json").read_text())
        assert assert_quoted(excerpt_as_json(excerpt), diag, "diagnosis.json") >= 8
    verdicts = [(cmd, c) for cmd, c in ran_commands if c.startswith("verdict:")]
    assert verdicts
    for cmd, comment in verdicts:
        name, before, after = re.match(r"verdict: (\w+), held-out RMSE ([\d.]+) -> ([\d.]+) deg", comment).groups()
        data = json.loads((workspace / cmd.split("--json ")[1].split()[0]).read_text())
        assert data["verdict"] == name
        quoted = {"baseline": {"heldout_rmse": Quoted(before)},
                  "candidates": [{"effect": name, "heldout_rmse": Quoted(after)}]}
        assert_quoted(quoted, data, cmd)
        assert f"--effects {name}" in data["explanation"] and "()" not in data["explanation"]


@pytest.mark.slow
def test_readme_python_snippets_run(workspace, ran_commands):
    code = "\n".join(fenced("python"))
    assert "rce_gtsam.analyze(" in code
    p = subprocess.run([sys.executable, "-c", code], cwd=workspace, capture_output=True, text=True)
    assert p.returncode == 0, p.stderr[-3000:]
    figures = {f.name for f in (workspace / "out" / "sample" / "figures").iterdir()}
    assert {"compliance.png", "kappa_overlay.png"} <= figures


def test_readme_parsers_see_what_the_readme_holds():
    """The parsers themselves: continuation lines are joined and an excerpt is read (fast, no commands run)."""
    cmds = dict(rce_commands())
    diag = next(c for c in cmds if c.startswith("diagnose data/sample"))
    assert "--candidates offset,second_mode" in diag and "--figures out/diagnosis_figures" in diag
    assert any(c.startswith("verdict: ") for c in cmds.values())
    ex = excerpt_as_json('{"baseline": {"heldout_rmse": 1.398, "fit_rmse": ...}, "candidates": [...], ...}')
    assert ex["baseline"]["heldout_rmse"].decimals == 3 and ex["candidates"] is None


#: phrases of a research log that a user cannot place (issue 40)
HISTORY = ("since the", "seed 1", "revision", "an earlier stop", "this stop", "before the dz", "(ours)")


def test_readme_is_a_short_introduction():
    lines = README.splitlines()
    assert len(lines) <= 200, f"README.md has {len(lines)} lines; the details belong in docs/"
    assert "make demo" in README and "make test" in README and "docs/img/kappa_to_report_overlay.png" in README
    assert (REPO / "docs" / "img" / "kappa_to_report_overlay.png").is_file()
    found = [h for h in HISTORY if h in README]
    assert not found, f"development history in README.md: {found}"


def test_the_readme_response_model_with_weights_is_the_command_line_fit():
    """The README's ``ResponseModel().fit(resp.Y, weights=resp.weights, ...)`` gives rce analyze's kappa exactly
    (without ``weights=`` it does not: the default preset's fit is variance-weighted)."""
    import numpy as np

    import rce_gtsam
    from rce_gtsam.model import ResponseModel

    assert "weights=resp.weights" in "\n".join(fenced("python"))
    r = rce_gtsam.analyze(REPO / "data" / "sample" / "tracks.csv", REPO / "data" / "sample" / "graph.json", n_boot=0)
    resp = r.response
    fit = ResponseModel().fit(resp.Y, weights=resp.weights, root_distance=resp.root_distance)
    assert np.array_equal(fit.kappa, r.fit.kappa * r.fit.direction)
