"""What the one-node check (rce_gtsam.diagnosis.one_node) withholds and what it keeps.

Two sources, each case with the verdict the decision reached before the check and the check's own numbers:

* ``--cache DIR``: the user's path (``benchmarks/bench_user_path.py``'s case folders, with a ``rediagnosis.json``
  written by ``--rediagnose``): every case where the check ran, effect-free or not;
* ``--own-sim``: the project's simulator through the pipeline (900 frames): delay and dynamics at the default
  strength (``--lag-seeds``), offset at 4x and a second excitation at 3x (``--own-seeds``) (lines cached in
  ``--own-log`` as JSON, re-used where present).

Columns: source, hidden effect, render, seed, the effect the decision named before the check, the carrying node
and its share of the in-sample gain, the effect's fold t and held-out gain without that node's bends, whether it is
still significant there, and whether the check holds (the current rule, :func:`rce_gtsam.diagnosis.one_node.holds`
and, for an effect of per-segment courses, significance). ``--record NAME`` saves docs/validation/NAME.json.

Usage: python benchmarks/bench_one_node.py --cache DIR [--own-sim --own-seeds 8 --lag-seeds 6 --own-log FILE]
       [--record NAME]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

LAG = {"delay", "dynamics"}


def per_segment_courses(effect: str) -> bool:
    """Whether ``effect`` fits each segment a slow course of its own (the check then also asks significance)."""
    from rce_gtsam.effects import CANDIDATES
    return CANDIDATES[effect]().heldout_time_basis(10) is not None


def holds(check: dict) -> bool:
    """The current rule on a recorded check (a check recorded before the per-segment-course field existed takes
    it from the effect)."""
    from rce_gtsam.diagnosis.one_node import OneNodeCheck
    courses = check.get("per_segment_courses", per_segment_courses(check["effect"]))
    return OneNodeCheck.from_dict({**check, "per_segment_courses": courses}).holds


def user_path_rows(cache: Path) -> list[dict]:
    out = []
    for d in sorted(cache.iterdir()):
        f = d / "rediagnosis.json"
        if not f.is_file():
            continue
        diag = json.loads(f.read_text())
        check = (diag.get("settings") or {}).get("one_node")
        if not check:
            continue
        effect, render, _, seed = d.name.rsplit("_", 3)
        out.append({"source": "user's path", "hidden": effect, "render": render, "seed": int(seed[1:]), "check": check,
                    "verdict_now": diag.get("verdict")})
    return out


def own_sim_rows(seeds: int, log: Path, lag_seeds: int = 6) -> list[dict]:
    """The simulator's effect recordings (cached as JSON lines in ``log``)."""
    done = {}
    if log.is_file():
        for line in log.read_text().splitlines():
            r = json.loads(line)
            done[(r["effect"], r["seed"])] = r
    cases = ([(e, 1.0, s) for s in range(lag_seeds) for e in ("delay", "dynamics")]
             + [(e, m, s) for s in range(seeds) for e, m in (("offset", 4.0), ("second_mode", 3.0))])
    todo = [c for c in cases if (c[0], c[2]) not in done]
    if todo:
        from rce_gtsam.diagnosis.diagnose import diagnose
        from rce_gtsam.diagnosis.io import diagnose_inputs
        from rce_gtsam.pipeline import analyze
        from rce_gtsam.sim import simulate as sim
        with log.open("a") as fh:
            for eff, mult, seed in todo:
                cfg = sim.SimulationConfig(seed=seed, n_frames=900, effects=(eff,),
                                           effect_strength={eff: mult * sim.EFFECT_DEFAULTS[eff]})
                simd = sim.simulate(cfg)
                res = analyze(simd.tracks, simd.graph, preset="default", n_boot=0)
                d = diagnose(**diagnose_inputs(res, seed=0))
                r = {"effect": eff, "mult": mult, "seed": seed, "verdict": d.verdict,
                     "withheld": d.settings.get("verdict_withheld"), "one_node": d.settings.get("one_node")}
                fh.write(json.dumps(r, default=str) + "\n")
                done[(eff, seed)] = r
    out = []
    for eff, mult, seed in cases:
        r = done[(eff, seed)]
        out.append({"source": f"simulator x{mult:g}", "hidden": eff, "render": "-", "seed": seed,
                    "check": r["one_node"], "verdict_unchecked": r["verdict"] or (r["withheld"] or {}).get("effect")})
    return out


def table(rows: list[dict]) -> list[list]:
    out = []
    for r in rows:
        c = r["check"]
        if not c:
            out.append([r["source"], r["hidden"], r["render"], r["seed"], r.get("verdict_unchecked") or "-",
                        "-", "-", "-", "-", "-", "-"])
            continue
        out.append([r["source"], r["hidden"], r["render"], r["seed"], c["effect"], c["node"], round(c["share"], 2),
                    round(c["fold_t"], 2), round(c["heldout_gain_pct"], 1),
                    "yes" if c.get("significant_without_node") else "no", "holds" if holds(c) else "withheld"])
    return out


def summary(rows: list[dict]) -> list[str]:
    lines = []
    for src in sorted({r["source"] for r in rows}):
        for hidden in sorted({r["hidden"] for r in rows if r["source"] == src}):
            rs = [r for r in rows if r["source"] == src and r["hidden"] == hidden]
            before = [r["check"]["effect"] if r["check"] else r.get("verdict_unchecked") for r in rs]
            # the user's path: the verdict the diagnosis gave (a withheld bend verdict can leave out_of_plane named);
            # the simulator: the current rule on the recorded check
            after = [r["verdict_now"] if "verdict_now" in r else
                     (b if (r["check"] is None or holds(r["check"])) else None) for r, b in zip(rs, before)]

            def right(names):
                if hidden == "none":
                    return sum(1 for n in names if n)
                return sum(1 for n in names if n and (n == hidden or (hidden in LAG and n in LAG)))
            what = "named (false)" if hidden == "none" else "found"
            lines.append(f"{src}, {hidden}: {what} before the check {right(before)}, after {right(after)} "
                         f"(of the {len(rs)} listed)")
    return lines


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache", default=None)
    ap.add_argument("--own-sim", action="store_true")
    ap.add_argument("--own-seeds", type=int, default=8, help="offset and second excitation seeds")
    ap.add_argument("--lag-seeds", type=int, default=6, help="delay and dynamics seeds")
    ap.add_argument("--own-log", default="one_node_own_sim.jsonl")
    ap.add_argument("--record", default=None)
    a = ap.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    rows = user_path_rows(Path(a.cache)) if a.cache else []
    if a.own_sim:
        rows += own_sim_rows(a.own_seeds, Path(a.own_log), a.lag_seeds)
    tab = table(rows)
    cols = ["source", "hidden effect", "render", "seed", "named before the check", "carrying node",
            "share of in-sample gain", "fold t without it", "held-out gain without it (%)",
            "significant without it", "check"]
    print(" | ".join(cols))
    for r in tab:
        print(" | ".join(str(v) for v in r))
    notes = summary(rows)
    print("\n".join(notes))
    print(dict(Counter(r[-1] for r in tab)))
    if a.record:
        from record import save_record
        save_record(a.record, title="The one-node check: the verdicts it withholds and those it keeps",
                    command="python benchmarks/bench_one_node.py --cache DIR --own-sim --own-seeds "
                            f"{a.own_seeds} --lag-seeds {a.lag_seeds} --own-log FILE",
                    description=("Every case in which the diagnosis named an effect before the one-node check ran "
                                 "(rce_gtsam.diagnosis.one_node): on the user's path (the cases of the user_path, "
                                 "user_path_lag and user_path_out_of_plane records; an out_of_plane verdict is "
                                 "checked on its own channel and is not listed) and on the project's simulator "
                                 "through the pipeline (900 frames). The carrying node is the one whose bends hold "
                                 "the largest share of the named effect's in-sample gain; the diagnosis then runs "
                                 "again for that effect without those bends, keeping (where the geometry is known "
                                 "and the effect is not a course per segment) the one combination of them that no "
                                 "displacement of that node moves. 'holds': its held-out gain stays "
                                 "positive there (and an offset, a course per segment, stays significant); "
                                 "'withheld': the report names the node instead of the effect."),
                    columns=cols, rows=tab, notes=notes)
    return 0


if __name__ == "__main__":
    sys.exit(main())
