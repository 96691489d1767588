"""False verdicts and detection on the user's path: ``rce simulate --video`` -> ``rce run`` (our tracker on our
rendered video), effect-free and with a hidden effect, clean and ``outdoor`` renders, measured together.

Each case runs the two commands as a user would (separate processes, the whole wall time counted) and keeps
the run folder in ``--cache``; a re-run re-uses every case already there, so the summary can be re-printed (or
re-decided after a change to the diagnosis with ``--rediagnose``, which re-runs ``rce diagnose`` on the cached
tracks) without re-rendering and re-tracking.

Columns: cases, verdicts named (any effect; for effect-free cases these are false verdicts), right (the
hidden effect named), the names given, and the median wall seconds of simulate + run.

Usage: python benchmarks/bench_user_path.py --cache DIR [--seeds 20] [--first-seed 100] [--frames 450]
       [--effects none,delay,dynamics] [--renders clean,outdoor] [--workers 2] [--rediagnose [--every]]
       (a render ``R-crfN``, e.g. ``outdoor-crf18``: the preset R compressed at x264 crf N, ``rce simulate --crf``)
       (a rediagnosis already in the cache is kept unless RCE_BENCH_FRESH=1)
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
BIN = Path(sys.executable).parent
#: ``--before NAME``: the file in each case folder that holds the diagnosis to compare with (set by main)
BEFORE: dict = {}


def case_dir(cache: Path, effect: str, render: str, seed: int, frames: int) -> Path:
    return cache / f"{effect}_{render}_f{frames}_s{seed}"


def render_parts(render: str) -> tuple[str, int | None]:
    """(realism preset, x264 crf or None for the preset's) of a render name: ``outdoor``, ``outdoor-crf18``."""
    realism, _, crf = render.partition("-crf")
    return realism, int(crf) if crf else None


def run_case(cache: str, effect: str, render: str, seed: int, frames: int) -> dict:
    """simulate -> run for one case (skipped where its diagnosis.json exists); returns its row."""
    d = case_dir(Path(cache), effect, render, seed, frames)
    diag = d / "run" / "diagnosis.json"
    wall = None
    if not diag.exists():
        t0 = time.perf_counter()
        realism, crf = render_parts(render)
        sim = [str(BIN / "rce"), "simulate", "--seed", str(seed), "--frames", str(frames), "--video",
               "--realism", realism, "--out", str(d / "sim")] + (["--crf", str(crf)] if crf is not None else [])
        if effect != "none":
            sim += ["--effect", effect]
        subprocess.run(sim, check=True, capture_output=True)
        run = [str(BIN / "rce"), "run", str(d / "sim" / "video.mp4"), str(d / "sim" / "annotations.json"),
               str(d / "sim" / "graph.json"), "--out", str(d / "run"), "--seed", "0", "--quiet"]
        p = subprocess.run(run, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        (d / "wall_s.txt").write_text(f"{wall:.2f}\n")
        if p.returncode not in (0, 3):
            (d / "error.txt").write_text(p.stdout + p.stderr)
            return {"effect": effect, "render": render, "seed": seed, "error": p.stderr.strip()[-300:]}
    return row_of(d, effect, render, seed)


def rediagnose(cache: str, effect: str, render: str, seed: int, frames: int, every: bool = False) -> dict:
    """Re-run ``rce diagnose`` on a cached case's tracks (the diagnosis changed, the tracker did not). Unless
    ``every``, only where the decision could change: a case whose first diagnosis named an effect or found a
    candidate significant (the rules since can only take verdicts away from the others)."""
    d = case_dir(Path(cache), effect, render, seed, frames)
    out = d / "rediagnosis.json"
    first = d / "run" / "diagnosis.json"
    if not every and first.exists():
        old = json.loads(first.read_text())
        if old.get("verdict") is None and not any(c.get("significant") for c in old.get("candidates", [])):
            return {**row_of(d, effect, render, seed), "rediagnosed": False}
    if out.exists() and not os.environ.get("RCE_BENCH_FRESH"):  # kept from an earlier --rediagnose
        return {**row_of(d, effect, render, seed, name="rediagnosis.json"), "rediagnosed": True}
    subprocess.run([str(BIN / "rce"), "diagnose", str(d / "run" / "tracks.csv"), str(d / "sim" / "graph.json"),
                    "--json", str(out), "--seed", "0", "--quiet"], capture_output=True, text=True)
    return {**row_of(d, effect, render, seed, name="rediagnosis.json"), "rediagnosed": True}


def row_of(d: Path, effect, render, seed, name=None) -> dict:
    """The case's verdict row from ``d/name`` (default: the diagnosis ``rce run`` wrote, ``run/diagnosis.json``;
    a ``name`` the case lacks falls back to that too where ``name`` is the ``--before`` file)."""
    path = d / name if name else d / "run" / "diagnosis.json"
    if name and name == BEFORE.get("name") and not path.exists():
        path = d / "run" / "diagnosis.json"
    if not path.exists():
        return {"effect": effect, "render": render, "seed": seed, "error": "no diagnosis"}
    diag = json.loads(path.read_text())
    wall = float((d / "wall_s.txt").read_text()) if (d / "wall_s.txt").exists() else float("nan")
    return {"effect": effect, "render": render, "seed": seed, "verdict": diag.get("verdict"),
            "status": diag.get("status"), "wall_s": wall,
            "withheld": (diag.get("settings") or {}).get("verdict_withheld")}


def summarise(rows: list[dict]) -> str:
    import numpy as np
    lines = [f"{'effect':<10} {'render':<8} {'n':>3} {'named':>6} {'right':>6}  names (withheld)  wall s"]
    keys = sorted({(r["effect"], r["render"]) for r in rows})
    for eff, ren in keys:
        rs = [r for r in rows if r["effect"] == eff and r["render"] == ren and "error" not in r]
        named = [r["verdict"] for r in rs if r["verdict"]]
        right = sum(1 for r in rs if r["verdict"] == eff)
        # settings["verdict_withheld"]: {"effect", "rule"} where a verdict was withheld (one_node.py)
        withheld = Counter(r["withheld"]["effect"] for r in rs if isinstance(r.get("withheld"), dict))
        wall = np.nanmedian([r["wall_s"] for r in rs]) if rs else float("nan")
        lines.append(f"{eff:<10} {ren:<8} {len(rs):>3} {len(named):>6} {right if eff != 'none' else '-':>6}  "
                     f"{dict(Counter(named))} ({dict(withheld)})  {wall:.0f}")
    errors = [r for r in rows if "error" in r]
    if errors:
        lines.append(f"{len(errors)} cases failed: " + "; ".join(f"{r['effect']}/{r['render']}/{r['seed']}: "
                                                                 f"{r['error']}" for r in errors[:3]))
    return "\n".join(lines)


def seed_group(seed: int, size: int) -> str:
    """The block of ``size`` seeds ``seed`` belongs to, as "a-b" (size 0: "all")."""
    if size <= 0:
        return "all"
    lo = seed - seed % size
    return f"{lo}-{lo + size - 1}"


def record_rows(first: list[dict], now: list[dict], group: int = 0) -> list[list]:
    """Rows of the validation record: per (hidden effect, render, block of ``group`` seeds) the cases, the verdicts
    of the first diagnosis (the code that ran ``rce run``) and of the current one, and how many name the hidden
    effect. A lag counts as found whether it is named delay or dynamics (two forms of one lag)."""
    lag = {"delay", "dynamics"}
    out = []
    keys = {(r["effect"], r["render"], seed_group(r["seed"], group)) for r in now if "error" not in r}
    for eff, ren, grp in sorted(keys):
        def pick(rows):
            return [r for r in rows if r["effect"] == eff and r["render"] == ren and "error" not in r
                    and seed_group(r["seed"], group) == grp]
        a, b = pick(first), pick(now)
        def named(rs):
            return sum(1 for r in rs if r.get("verdict"))
        def found(rs):
            return sum(1 for r in rs if r.get("verdict") == eff or (eff in lag and r.get("verdict") in lag))
        names = dict(Counter(r["verdict"] for r in b if r.get("verdict")))
        out.append([eff, ren, grp, len(b), f"{named(a)} of {len(a)}", f"{named(b)} of {len(b)}",
                    "-" if eff == "none" else f"{found(a)} / {found(b)}",
                    ", ".join(f"{k} {v}" for k, v in sorted(names.items())) or "-"])
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache", required=True)
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--first-seed", type=int, default=100)
    ap.add_argument("--frames", type=int, default=450)
    ap.add_argument("--effects", default="none,delay,dynamics")
    ap.add_argument("--renders", default="clean,outdoor")
    ap.add_argument("--workers", type=int, default=max(1, (os.cpu_count() or 2)))
    ap.add_argument("--rediagnose", action="store_true")
    ap.add_argument("--every", action="store_true", help="with --rediagnose: every case, not only those whose "
                                                          "decision could change")
    ap.add_argument("--json", default=None, help="write the rows here")
    ap.add_argument("--record", default=None, metavar="NAME",
                    help="save the verdicts as the docs' validation record docs/validation/NAME.json (with "
                         "--rediagnose: the first diagnosis and the current one side by side)")
    ap.add_argument("--note", action="append", default=[], help="a line under the record's table (repeatable)")
    ap.add_argument("--before", default=None, metavar="NAME",
                    help="with --record: the 'first' column from this file in each case folder (e.g. the previous "
                         "rediagnosis kept as rediagnosis_before.json), where present, instead of run/diagnosis.json")
    ap.add_argument("--seed-groups", type=int, default=0, metavar="N",
                    help="with --record: one row per block of N seeds (the seeds a rule was written on apart from "
                         "those it was not)")
    a = ap.parse_args()
    if a.before:
        BEFORE["name"] = a.before
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    jobs = [(a.cache, e, r, s, a.frames) for s in range(a.first_seed, a.first_seed + a.seeds)
            for e in a.effects.split(",") for r in a.renders.split(",")]
    if a.rediagnose:
        jobs = [(*j, a.every) for j in jobs]
    fn = rediagnose if a.rediagnose else run_case
    with ProcessPoolExecutor(a.workers) as pool:
        rows = list(pool.map(fn, *zip(*jobs)))
    print(summarise(rows))
    if a.record:
        from record import save_record
        first = [row_of(case_dir(Path(a.cache), e, r, s_, a.frames), e, r, s_, name=a.before)
                 for _, e, r, s_, _f, *_ in jobs]
        cmd = (f"python benchmarks/bench_user_path.py --cache DIR --seeds {a.seeds} --first-seed {a.first_seed} "
               f"--frames {a.frames} --effects {a.effects} --renders {a.renders}"
               + (" (then the same with --rediagnose)" if a.rediagnose else ""))
        save_record(a.record, title="The user's path: rce simulate --video, then rce run (our tracker on our "
                                    "rendered video): " + ("effect-free" if a.effects == "none" else a.effects.replace(",", ", "))
                                    + (", first and current diagnosis" if a.rediagnose else ""),
                    command=cmd,
                    description=("Each case renders a simulated branch as video (clean: crisp and still; outdoor: "
                                 "motion blur, light drift, shadow, camera shake, crf 28; R-crfN: the preset R "
                                 "compressed at x264 crf N instead), tracks it with the built-in "
                                 "tracker and runs the whole analysis and diagnosis, as a user would (450 frames, "
                                 "20 nodes, default preset). 'first' is the diagnosis rce run wrote, 'now' that of "
                                 "the current diagnosis on the same tracks (the same where there was no "
                                 "--rediagnose). For effect-free cases every name is a false verdict; for a hidden "
                                 "lag 'found' counts delay or dynamics (two forms of one lag)."),
                    columns=["hidden effect", "render", "seeds", "cases", "named (first)", "named (now)",
                             "found (first / now)", "names now"],
                    rows=record_rows(first, rows, a.seed_groups), notes=a.note or None)
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
