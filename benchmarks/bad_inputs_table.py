"""Bad and degenerate inputs, tried as a new user would: exit code and message of each, no tracebacks.

Usage: python benchmarks/bad_inputs_table.py [--workdir DIR] [--only fast]

Builds a small simulated branch (6 nodes x 200 frames, with video), derives every malformed or degenerate
input of issue 12 and more from it, runs ``rce`` in-process (``rce_gtsam.cli.main``) on each and prints a
Markdown table: case, command, expected exit code, exit code, the one-line message (stderr's last line;
for exit 0 / 3 the quality summary). A case that raises instead of returning is a TRACEBACK row and makes
the script exit 1. Exit codes: 2 = bad input refused before any work; 3 = outputs written but no kappa
passed the quality checks; 0 = fine.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import sys
import tempfile
import traceback
from pathlib import Path

import numpy as np
import pandas as pd

from rce_gtsam.cli import main as rce

FAST = ["--bootstrap", "40", "--no-figures"]


def run_cli(argv: list[str]) -> tuple[int | str, str, str]:
    out, err = io.StringIO(), io.StringIO()
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = rce(argv)
    except SystemExit as exc:  # argparse
        code = exc.code
    except BaseException:  # noqa: BLE001 - this is what the table must show never happens
        return "TRACEBACK", out.getvalue(), traceback.format_exc()
    return code, out.getvalue(), err.getvalue()


def _message(code, out: str, err: str) -> str:
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    if code in (0, 3):
        q = [ln for ln in out.splitlines() if ln.startswith("quality:")]
        tail = (q[-1] if q else "") + (" | " + lines[-1] if code == 3 and lines else "")
        return tail.strip(" |")
    return lines[-1] if lines else ""


def write_tracks(path: Path, df: pd.DataFrame) -> Path:
    df.to_csv(path, index=False)
    return path


def build(work: Path, video: bool = True) -> dict:
    """The base simulation and the derived input files (``video=False``: no rendering, for the cases that
    need no video)."""
    sim = work / "sim"
    if not (sim / "tracks.csv").exists() or (video and not (sim / "video.mp4").exists()):
        code, _, err = run_cli(["simulate", "--seed", "3", "--frames", "200", "--nodes", "6", "--out", str(sim),
                             *(["--video"] if video else [])])
        assert code == 0, err
    t = pd.read_csv(sim / "tracks.csv")
    g = json.loads((sim / "graph.json").read_text())
    f = {"sim": sim, "tracks": sim / "tracks.csv", "graph": sim / "graph.json", "video": sim / "video.mp4",
         "ann": sim / "annotations.json"}
    rng = np.random.default_rng(0)
    first = t[t.frame == 0].set_index("point_id")[["x", "y"]]
    frames = np.arange(200)
    static = pd.DataFrame([(n, fr, first.loc[n, "x"], first.loc[n, "y"]) for n in first.index for fr in frames],
                          columns=["point_id", "frame", "x", "y"])
    f["static"] = write_tracks(work / "static.csv", static)
    noisy = static.copy()
    noisy[["x", "y"]] += rng.normal(0, 0.5, (len(noisy), 2))
    f["static_noise"] = write_tracks(work / "static_noise.csv", noisy)
    f["start50000"] = write_tracks(work / "start50000.csv", t.assign(frame=t.frame + 50000))
    f["start1000"] = write_tracks(work / "start1000.csv", t.assign(frame=t.frame + 1000))
    f["short"] = write_tracks(work / "short.csv", t[t.frame < 10])
    node = int(g["edges"][2][1])
    seen3 = t[(t.point_id != node) | t.frame.isin([0, 50, 100])]
    f["seen3"] = write_tracks(work / "seen3.csv", seen3)
    half = t[(t.point_id != node) | (t.frame < 94)]
    f["lost_half"] = write_tracks(work / "lost_half.csv", half)
    f["nan"] = write_tracks(work / "nan.csv", t.astype({"x": object}).assign(
        x=lambda d: d.x.where(d.index != 7, "nan")))
    (work / "empty.csv").write_text("")
    f["empty"] = work / "empty.csv"
    (work / "header.csv").write_text("point_id,frame,x,y\n")
    f["header"] = work / "header.csv"
    f["invisible"] = write_tracks(work / "invisible.csv", t.assign(visible=(t.point_id != node).astype(int)))
    root = g["root"]
    chain = [root] + [c for _, c in g["edges"]]
    for name, edges in (("g2", [[chain[0], chain[1]]]), ("g3", [[chain[0], chain[1]], [chain[1], chain[2]]]),
                        ("cycle", g["edges"] + [[chain[-1], chain[1]]])):
        (work / f"{name}.json").write_text(json.dumps({"root": root, "edges": edges}))
        f[name] = work / f"{name}.json"
    ann = json.loads(f["ann"].read_text())["points"]
    (work / "half.json").write_text(json.dumps({"points": [[x / 2, y / 2] for x, y in ann]}))
    f["half_ann"] = work / "half.json"
    (work / "outside.json").write_text(json.dumps({"points": [[5000, 10]] + ann[1:]}))
    f["outside_ann"] = work / "outside.json"
    (work / "few_ann.json").write_text(json.dumps({"points": ann[:3]}))
    f["few_ann"] = work / "few_ann.json"
    (work / "trunc.mp4").write_bytes(f["video"].read_bytes()[:20000] if video else b"\0" * 20000)
    f["trunc"] = work / "trunc.mp4"
    (work / "a_file").write_text("not a folder\n")
    f["file"] = work / "a_file"
    ro = work / "readonly"
    ro.mkdir(exist_ok=True)
    f["ro"] = ro
    (work / "existing_dir").mkdir(exist_ok=True)
    f["dir"] = work / "existing_dir"
    return f


def cases(f: dict, work: Path) -> list[tuple[str, list[str], int | set]]:
    """(name, argv, expected exit code or set of codes)."""
    T, G, V, A = str(f["tracks"]), str(f["graph"]), str(f["video"]), str(f["ann"])
    out = str(work / "out")
    an = lambda tracks=T, graph=G, *extra: ["analyze", str(tracks), str(graph), "--out", out, *FAST, *extra]  # noqa: E731
    dg = lambda *extra: ["diagnose", T, G, "--json", str(work / "d.json"), "--candidates", "offset", *extra]  # noqa: E731
    run = lambda *extra, ann=A, video=V: ["run", str(video), str(ann), G, "--out", out, "--no-progress",  # noqa: E731
                                          "--candidates", "offset", *FAST, *extra]
    unwritable = "/proc/rce_out" if Path("/proc").is_dir() else str(f["ro"] / "x")
    return [
        ("--seed -1 (analyze)", an(T, G, "--seed", "-1"), 2),
        ("--seed -1 (diagnose)", dg("--seed", "-1"), 2),
        ("--seed -1 (simulate)", ["simulate", "--seed", "-1", "--out", str(work / "s")], 2),
        ("--seed -1 (run)", run("--seed", "-1"), 2),
        ("--out is an existing file (analyze)", ["analyze", T, G, "--out", str(f["file"]), *FAST], 2),
        ("--out under a file (analyze)", ["analyze", T, G, "--out", str(f["file"] / "sub"), *FAST], 2),
        ("--out unwritable (analyze)", ["analyze", T, G, "--out", unwritable, *FAST], 2),
        ("--out is an existing file (run, before tracking)", run("--out", str(f["file"])), 2),
        ("--out under a file (run)", run("--out", str(f["file"] / "sub")), 2),
        ("--out is an existing file (simulate)", ["simulate", "--out", str(f["file"])], 2),
        ("diagnose --json DIR", ["diagnose", T, G, "--json", str(f["dir"])], 2),
        ("diagnose --json under a file", ["diagnose", T, G, "--json", str(f["file"] / "d.json")], 2),
        ("diagnose --figures is a file", dg("--figures", str(f["file"])), 2),
        ("track --out DIR", ["track", V, A, "--out", str(f["dir"]), "--no-progress"], 2),
        ("track --out unwritable", ["track", V, A, "--out", unwritable + ".csv", "--no-progress"], 2),
        ("analyze --rerun DIR", an(T, G, "--rerun", str(f["dir"])), 2),
        ("view --rrd DIR", ["view", str(f["dir"]), "--rrd", str(f["dir"])], 2),
        ("annotate --out-annotations DIR", ["annotate", "--polyline", "0,0,10,10", "--nodes", "4",
                                            "--out-annotations", str(f["dir"]), "--out-graph", str(work / "g.json")], 2),
        ("annotate --nodes 1", ["annotate", "--polyline", "0,0,10,10", "--nodes", "1", "--out-annotations",
                                str(work / "a.json"), "--out-graph", str(work / "g.json")], 2),
        ("--set smoother.acceleration_weight=-1", an(T, G, "--set", "smoother.acceleration_weight=-1"), 2),
        ("--set smoother.acceleration_weight=nan", an(T, G, "--set", "smoother.acceleration_weight=nan"), 2),
        ("--set smoother.acceleration_weight=1e300", an(T, G, "--set", "smoother.acceleration_weight=1e300"), 2),
        ("--set smoother.measurement_weight=0", an(T, G, "--set", "smoother.measurement_weight=0"), 2),
        ("--set compliance.n_boot=-1", an(T, G, "--set", "compliance.n_boot=-1"), 2),
        ("--set compliance.block_length=0", an(T, G, "--set", "compliance.block_length=0"), 2),
        ("--set bending.mad_threshold=-1", an(T, G, "--set", "bending.mad_threshold=-1"), 2),
        ("--set compliance.tol=inf", an(T, G, "--set", "compliance.tol=inf"), 2),
        ("--set misspelt field", an(T, G, "--set", "smoother.acceleration=1"), 2),
        ("--bootstrap -5", an(T, G, "--bootstrap", "-5"), 2),
        ("diagnose --folds 100", dg("--folds", "100"), 2),
        ("diagnose --folds 12 (200 frames: at most 8)", dg("--folds", "12"), 2),
        ("diagnose --folds 1", dg("--folds", "1"), 2),
        ("simulate --strength delay=10 without --effect", ["simulate", "--strength", "delay=10", "--out",
                                                            str(work / "s")], 2),
        ("simulate --frames 5", ["simulate", "--frames", "5", "--out", str(work / "s")], 2),
        ("simulate --z-rms 0", ["simulate", "--z-rms", "0", "--out", str(work / "s")], 2),
        ("diagnose --candidates ''", ["diagnose", T, G, "--json", str(work / "d.json"), "--candidates", ""], 2),
        ("analyze --effects ''", an(T, G, "--effects", ""), 2),
        ("analyze --effects bogus", an(T, G, "--effects", "bogus"), 2),
        ("run --candidates ''", ["run", V, A, G, "--out", out, "--candidates", ""], 2),
        ("tracks start at frame 50000", an(f["start50000"]), 2),
        ("tracks start at frame 1000", an(f["start1000"]), 2),
        ("10-frame tracks", an(f["short"]), 2),
        ("run --max-frames 10", run("--max-frames", "10"), 2),
        ("track --max-frames 0", ["track", V, A, "--out", str(work / "t.csv"), "--max-frames", "0"], 2),
        ("2-node graph", an(T, f["g2"]), 2),
        ("graph with a cycle", an(T, f["cycle"]), 2),
        ("tracks file missing", an(work / "nope.csv"), 2),
        ("tracks file empty", an(f["empty"]), 2),
        ("tracks header only", an(f["header"]), 2),
        ("NaN coordinate in a row", an(f["nan"]), 2),
        ("a graph node never visible", an(f["invisible"]), 2),
        ("truncated mp4 (track)", ["track", str(f["trunc"]), A, "--out", str(work / "t.csv")], 2),
        ("truncated mp4 (run)", run(video=f["trunc"]), 2),
        ("annotation outside the image", ["track", V, str(f["outside_ann"]), "--out", str(work / "t.csv")], 2),
        ("graph node without annotation (run)", run(ann=f["few_ann"]), 2),
        ("static tracks (exact)", an(f["static"]), 3),
        ("static tracks + 0.5 px noise", an(f["static_noise"]), 3),
        ("every bend an outlier (mad_threshold=0)", an(T, G, "--set", "bending.mad_threshold=0"), 3),
        ("3-node graph (one bend)", an(T, f["g3"]), 3),
        ("annotations off the branch (half scale, run)", run(ann=f["half_ann"]), 3),
        ("node seen in 3 of 200 frames", an(f["seen3"]), {0, 3}),
        ("node lost for half the clip", an(f["lost_half"]), {0, 3}),
        ("clean simulated tracks (control, 200 frames)", an(), {0, 3}),
    ]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workdir", type=Path, default=None)
    args = ap.parse_args(argv)
    work = args.workdir or Path(tempfile.mkdtemp(prefix="rce_bad_inputs_"))
    work.mkdir(parents=True, exist_ok=True)
    rows, bad = run_table(work)
    print("| # | case | expected | exit | message |\n|---|---|---|---|---|")
    for i, (name, expected, code, msg) in enumerate(rows, 1):
        exp = "/".join(map(str, sorted(expected))) if isinstance(expected, set) else str(expected)
        print(f"| {i} | {name} | {exp} | {code} | {msg.replace('|', '/')} |")
    n_tb = sum(code == "TRACEBACK" for _, _, code, _ in rows)
    print(f"\n{len(rows)} cases; {n_tb} tracebacks; {len(bad)} with an unexpected exit code"
          + (": " + ", ".join(bad) if bad else ""))
    return 1 if n_tb or bad else 0


def run_table(work: Path) -> tuple[list, list]:
    """Run every case; returns (rows (name, expected, code, message), names with an unexpected code)."""
    files = build(work)
    os.chmod(files["ro"], 0o555)
    rows, bad = [], []
    try:
        for name, argv, expected in cases(files, work):
            code, out, err = run_cli(argv)
            msg = _message(code, out, err) if code != "TRACEBACK" else err.strip().splitlines()[-1]
            rows.append((name, expected, code, msg))
            ok = code in expected if isinstance(expected, set) else code == expected
            if not ok:
                bad.append(name)
    finally:
        os.chmod(files["ro"], 0o755)
    return rows, bad


if __name__ == "__main__":
    sys.exit(main())
