"""The delay's full-data test against the one it replaced, on every test bed at once: false alarms and power.

The delay's score test (:mod:`rce_gtsam.diagnosis.whitened_score_test`: its lag scan from the full fit's own
excitation, scored by GLS across segments against phase surrogates) and the test of ``--baseline REV`` (default
3d9e6b3: the refitted null, ``refitted_score_test`` of that revision's ``rce_gtsam/diagnosis/score_test.py``,
loaded from ``git show``) run on the same cases in the same process. Per case the p of each; where the truth is
known and the case has a lag, also the ideal oracle's p (:func:`rce_gtsam.diagnosis.ideal_oracle.signature_test`,
the rank-1 residual along the true signature: the ceiling); on an effect-free user-path case, along the signature
of the delay case of the same seed and render (borrowed: how often that statistic fires without a lag).

Test beds (each optional; a folder that is not given is skipped):

* ``--user-path DIR``: ``benchmarks/bench_user_path.py``'s cache (``rce simulate --video`` then ``rce run``: our
  tracker on our rendered video; case folders ``{effect}_{render}_f450_s{seed}``). The analysis is re-run from
  each case's ``run/tracks.csv`` (default preset) and its diagnosis inputs kept beside it
  (``delay_test_inputs.pkl``). Effect-free cases count false alarms; delay and dynamics cases (a lag) power.
* ``--artifacts DIR``: ``benchmarks/bench_artifacts.py``'s cache (the tracker-artifact families at their measured
  size and twice it, effect-free).
* ``--beam DIR`` (repeatable): ``benchmarks/bench_beam.py``'s cache (``*.pkl`` with ``inputs``): effect-free
  branches (false alarms) and gust fronts (a lag, power).

Printed: per test bed and group, the cases and how many reach p <= 0.005 (the verdict's level for a score
test), 0.01 and 0.05 under each test. ``--record NAME`` saves the table as a validation record.

Usage: OMP_NUM_THREADS=1 python benchmarks/bench_delay_test.py [--user-path DIR] [--artifacts DIR] [--beam DIR]
       [--baseline REV] [--workers 2] [--record delay_test]
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import re
import sys
import tempfile
import time
from collections import defaultdict
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
sys.path.insert(0, str(ROOT))

LEVELS = (0.005, 0.01, 0.05)
LAG = ("delay", "dynamics", "gust_front")
_BASELINE: dict = {}


def baseline_module(rev: str):
    """``rce_gtsam/diagnosis/score_test.py`` of revision ``rev`` as the module
    ``rce_gtsam.diagnosis.score_test_baseline`` (its relative imports are this checkout's)."""
    if rev not in _BASELINE:
        from bench_track import _git_show, _load
        src = _git_show(rev, "rce_gtsam/diagnosis/score_test.py")
        if src is None or "def refitted_score_test" not in src:
            raise SystemExit(f"revision {rev} has no refitted_score_test in rce_gtsam/diagnosis/score_test.py")
        path = Path(tempfile.mkdtemp()) / f"score_test_{rev}.py"
        path.write_text(src)
        _BASELINE[rev] = _load("rce_gtsam.diagnosis.score_test_baseline", path)
    return _BASELINE[rev]


def user_path_inputs(case: Path) -> dict:
    """The diagnosis inputs of one user-path case (analysis of its tracks, default preset), kept in the case."""
    keep = case / "delay_test_inputs.pkl"
    if keep.exists():
        return pickle.loads(keep.read_bytes())
    from rce_gtsam.diagnosis.io import diagnose_inputs
    from rce_gtsam.pipeline import analyze
    from rce_gtsam.presets import DEFAULT
    from rce_gtsam.validate import check_analysis_inputs
    graph, _, tracks = check_analysis_inputs(case / "run" / "tracks.csv", case / "sim" / "graph.json", DEFAULT)
    kw = diagnose_inputs(analyze(tracks, graph, preset=DEFAULT, n_boot=0), seed=0)
    keep.write_bytes(pickle.dumps(kw))
    return kw


def true_response(case: Path, labels) -> np.ndarray | None:
    """(E, T) the noise-free bends of a user-path case's simulation (``sim/truth.json``), rows as ``labels``."""
    path = case / "sim" / "truth.json"
    if not path.exists():
        return None
    r = json.loads(path.read_text())["response_true"]
    return np.array([r[str(lab)] for lab in labels], float) if all(str(lab) in r for lab in labels) else None


def p_values(Y, W, s, labels, rev: str, truth=None) -> dict:
    """{"now": p, "baseline": p[, "oracle": p]} of one case's delay tests (seed 0)."""
    from rce_gtsam import effects
    from rce_gtsam.diagnosis.ideal_oracle import signature_test
    from rce_gtsam.diagnosis.oracle import true_signature
    from rce_gtsam.diagnosis.score_dispatch import effect_score_test
    from rce_gtsam.model import ResponseModel, validate_inputs
    from rce_gtsam.model.row_sets import edge_halves, edge_nodes_from_labels, node_disjoint_split, shared_node_matrix
    from rce_gtsam.presets import DEFAULT

    Y, W, s = validate_inputs(Y, W, s)
    delay, model = effects.make("delay"), ResponseModel(config=DEFAULT.compliance)
    fit = model.solve(Y, W, s)
    nodes = edge_nodes_from_labels([str(x) for x in labels])
    split = node_disjoint_split(s, shared_node_matrix(s, nodes), 0, edge_nodes=nodes)
    halves = split if split is not None else edge_halves(s, 0)
    old = baseline_module(rev)
    fits = old.half_fits(model, Y, W, s, halves)
    out = {"now": effect_score_test(delay.score_excitation, model, fit, Y, W, s, fits, halves,
                                    lambda rows, kappa, z, s_: delay.test_directions(kappa, z, s_)).p,
           "baseline": old.refitted_score_test(model, fit, Y, W, s, delay.test_directions, fits, halves).p}
    if truth is not None:
        y = truth + np.nanmean(fit.Y - truth, axis=1, keepdims=True)
        out["oracle"] = signature_test(fit.Y - fit.predict(), true_signature(y), seed=0).p
    return out


def one_case(bed: str, path: str, rev: str) -> dict:
    """One case of a test bed: its group ("effect render" / "family xscale" / "effect xstrength") and p values."""
    p = Path(path)
    if bed == "user path":
        effect, render = p.name.split("_")[0], p.name.split("_")[1]
        kw = user_path_inputs(p)
        # an effect-free case is scored along the lag signature of the delay case of its seed and render (the same
        # wind and branch): how often the oracle's statistic fires without the lag
        source = p if effect in LAG else p.parent / p.name.replace("none_", "delay_", 1)
        truth = true_response(source, kw["edge_labels"]) if source.exists() else None
        ps = p_values(kw["Y"], kw["weights"], kw["root_distance"], kw["edge_labels"], rev, truth)
        return {"bed": bed, "group": f"{effect} {render}", "case": p.name, **ps}
    if bed == "artifacts":
        m = re.match(r"artifact_(.+?)_(\d+(?:\.\d+)?)_(\d+)_", p.name)
        d = np.load(p)
        ps = p_values(d["Y"], d["W"] if d["W"].size else None, d["s"], list(d["labels"]), rev)
        return {"bed": bed, "group": f"{m.group(1)} x{m.group(2)}", "case": p.name, **ps}
    c = pickle.loads(p.read_bytes())
    kw = c["inputs"]
    m = re.match(r"(.+?)_(\d+(?:\.\d+)?)_(\d+)_", p.name)
    truth = c.get("truth") if m.group(1) in LAG else None
    ps = p_values(kw["Y"], kw.get("weights"), kw["root_distance"], kw.get("edge_labels") or range(len(kw["Y"])),
                  rev, truth)
    return {"bed": bed, "group": f"{m.group(1)} x{m.group(2)}", "case": p.name, **ps}


def cases(a) -> list[tuple[str, str]]:
    out = []
    if a.user_path:
        for d in sorted(Path(a.user_path).iterdir()):
            if (re.match(r"(none|delay|dynamics)_(clean|outdoor)_f450_s\d+$", d.name)
                    and (d / "run" / "tracks.csv").exists()):
                out.append(("user path", str(d)))
    if a.artifacts:
        seen = set()
        newest_first = sorted(Path(a.artifacts).glob("artifact_*_450_*.npz"),
                              key=lambda f: (not f.name.endswith("_nf2.npz"), f.name))
        for f in newest_first:
            m = re.match(r"artifact_(.+?)_(\d+(?:\.\d+)?)_(\d+)_450", f.name)
            if m and m.group(1) != "lag" and m.groups() not in seen:
                seen.add(m.groups())
                out.append(("artifacts", str(f)))
    seen = set()
    for folder in a.beam:
        for f in sorted(Path(folder).glob("*.pkl")):
            if re.match(r"(none|gust_front)_\d+_\d+_450", f.name) and f.name not in seen:
                seen.add(f.name)
                out.append(("beam", str(f)))
    return out


def table(rows: list[dict]) -> list[list]:
    groups = defaultdict(list)
    for r in rows:
        groups[(r["bed"], r["group"])].append(r)
    out = []
    for (bed, group), rs in sorted(groups.items()):
        def counts(key):
            have = [r for r in rs if key in r]
            if not have:
                return "-"
            text = " / ".join(str(sum(r[key] <= lv for r in have)) for lv in LEVELS)
            return text if len(have) == len(rs) else f"{text} (of {len(have)})"
        out.append([bed, group, len(rs), counts("baseline"), counts("now"), counts("oracle")])
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--user-path", default=None, metavar="DIR")
    ap.add_argument("--artifacts", default=None, metavar="DIR")
    ap.add_argument("--beam", action="append", default=[], metavar="DIR",
                    help="a beam_curve cache (repeatable: effect-free and gust-front cases may sit in different ones)")
    ap.add_argument("--baseline", default="3d9e6b3", metavar="REV")
    ap.add_argument("--workers", type=int, default=max(1, os.cpu_count() or 2))
    ap.add_argument("--json", default=None, help="write the per-case rows here")
    ap.add_argument("--record", default=None, metavar="NAME")
    ap.add_argument("--rows", default=None, metavar="FILE", help="summarise the per-case rows a --json run wrote "
                                                                "(runs nothing)")
    a = ap.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    t0 = time.perf_counter()
    if a.rows:
        rows = json.loads(Path(a.rows).read_text())
    else:
        jobs = cases(a)
        if not jobs:
            raise SystemExit("no cases: give --user-path, --artifacts and/or --beam with their caches")
        baseline_module(a.baseline)  # fail early on a bad revision
        with ProcessPoolExecutor(a.workers) as pool:
            rows = list(pool.map(one_case, *zip(*[(b, p, a.baseline) for b, p in jobs])))
    cols = ["test bed", "group", "cases", f"baseline ({a.baseline}) p <= 0.005 / 0.01 / 0.05",
            "now p <= 0.005 / 0.01 / 0.05", "ideal oracle p <= 0.005 / 0.01 / 0.05"]
    body = table(rows)
    print("  ".join(cols))
    for r in body:
        print("  ".join(str(x) for x in r))
    print(f"{len(rows)} cases in {time.perf_counter() - t0:.0f} s")
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1))
    if a.record:
        from record import save_record
        save_record(a.record, title="The delay's full-data test: false alarms and power, against the refitted test "
                                    "it replaced",
                    command="python benchmarks/bench_delay_test.py --user-path DIR --artifacts DIR --beam DIR "
                            f"[--beam DIR] --baseline {a.baseline}",
                    description=("Counts of cases whose delay score test reaches p <= 0.005 (the level a score test "
                                 "is read at), 0.01 and 0.05: the test the delay has now (its lag scan from the fit's "
                                 "own excitation, GLS across segments, phase-surrogate null) and the refitted test of "
                                 "the baseline revision, on the same cases. Effect-free groups (none, the artifact "
                                 "families) count false alarms; lag groups (delay, dynamics, gust_front) count "
                                 "detections, beside the ideal oracle that knows the true signature (the ceiling). "
                                 "User path: rce simulate --video then rce run, 450 frames."),
                    columns=cols, rows=body)
    return 0


if __name__ == "__main__":
    sys.exit(main())
