"""What the video's compression costs on the user's path: the same ``outdoor`` scenes at several x264 crf.

``bench_user_path.py`` renders each case (``rce simulate --video --realism outdoor [--crf N]``, render name
``outdoor`` for the preset's crf 28, ``outdoor-crfN`` otherwise) and runs ``rce run`` on it; this script reads those
cached cases and reports, per crf, over the same seeds:

* our tracker's error on the visible points against the truth (``bench_lag_ceiling.error_stats``: median, the
  per-axis RMS of the errors below 2 px, the share beyond);
* a hidden lag (delay or dynamics) found, and effect-free renders named (false verdicts), by the current diagnosis:
  the case's ``rediagnosis.json`` where ``bench_user_path.py --rediagnose`` wrote one, else the diagnosis ``rce run``
  wrote (the same code when the case was rendered after the diagnosis' last change).

Usage: python benchmarks/bench_user_path_crf.py --cache DIR [--cache DIR2 ...] [--seeds 20] [--first-seed 100]
       [--renders outdoor,outdoor-crf23,outdoor-crf18] [--record NAME]
"""

from __future__ import annotations

import argparse
import json
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
LAG = {"delay", "dynamics"}


def find_case(caches: list[Path], effect: str, render: str, seed: int, frames: int) -> Path | None:
    for c in caches:
        d = c / f"{effect}_{render}_f{frames}_s{seed}"
        if (d / "run" / "diagnosis.json").exists():
            return d
    return None


def verdict(case: Path) -> str | None:
    """The current diagnosis' verdict of ``case`` (see the module docstring)."""
    f = case / "rediagnosis.json"
    return json.loads((f if f.exists() else case / "run" / "diagnosis.json").read_text()).get("verdict")


def crf_of(render: str) -> int:
    from bench_user_path import render_parts
    from rce_gtsam.sim.nuisance import REALISM

    realism, crf = render_parts(render)
    return REALISM[realism].crf if crf is None else crf


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache", action="append", required=True, type=Path)
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--first-seed", type=int, default=100)
    ap.add_argument("--frames", type=int, default=450)
    ap.add_argument("--renders", default="outdoor,outdoor-crf23,outdoor-crf18")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--more-none", default=None, metavar="A-B",
                    help="also count false verdicts on the effect-free cases of seeds A..B (inclusive) where cached")
    ap.add_argument("--record", default=None, metavar="NAME")
    a = ap.parse_args()
    from bench_lag_ceiling import error_stats

    seeds = range(a.first_seed, a.first_seed + a.seeds)
    rows, missing = [], []
    for render in a.renders.split(","):
        cases = {(e, s): find_case(a.cache, e, render, s, a.frames)
                 for e in ("delay", "dynamics", "none") for s in seeds}
        missing += [f"{e}_{render}_s{s}" for (e, s), d in cases.items() if d is None]
        have = {k: d for k, d in cases.items() if d is not None}
        ver = {k: verdict(d) for k, d in have.items()}
        lag = [k for k in have if k[0] in LAG]
        found = sum(1 for k in lag if ver[k] in LAG)
        by = {e: sum(1 for k in lag if k[0] == e and ver[k] in LAG) for e in ("delay", "dynamics")}
        n_by = {e: sum(1 for k in lag if k[0] == e) for e in ("delay", "dynamics")}
        none = [k for k in have if k[0] == "none"]
        named = sum(1 for k in none if ver[k])
        with ProcessPoolExecutor(a.workers) as pool:  # the truth is re-simulated per case: one case per job
            parts = list(pool.map(error_stats, [[str(d)] for d in have.values()], [2.0] * len(have)))
        med = float(np.median([p["median_px"] for p in parts]))
        rms = float(np.sqrt(np.mean([p["rms_per_axis_below_px"] ** 2 for p in parts])))
        beyond = float(np.mean([p["share_beyond"] for p in parts]))
        row = [crf_of(render), render, f"{found} of {len(lag)}", f"{by['delay']} of {n_by['delay']}",
               f"{by['dynamics']} of {n_by['dynamics']}", f"{named} of {len(none)}", round(med, 3), round(rms, 3),
               round(100 * beyond, 2)]
        rows.append(row)
        print(f"crf {row[0]:2d} ({render}): lag found {row[2]} (delay {row[3]}, dynamics {row[4]}); effect-free "
              f"named {row[5]}; tracker error median {med:.3f} px (median over cases), per-axis RMS below 2 px "
              f"{rms:.3f} px, beyond 2 px {100 * beyond:.2f} %", flush=True)
    notes = []
    if a.more_none:
        lo, hi = (int(x) for x in a.more_none.split("-"))
        for render in a.renders.split(","):
            more = [d for d in (find_case(a.cache, "none", render, s, a.frames) for s in range(lo, hi + 1)) if d]
            if more:
                named = sum(1 for d in more if verdict(d))
                notes.append(f"effect-free, {render}, seeds {lo}-{hi}: {named} of {len(more)} named")
                print(notes[-1])
    if missing:
        notes.append(f"missing cases: {len(missing)}")
        print(f"missing cases ({len(missing)}): {', '.join(missing[:8])}{' ...' if len(missing) > 8 else ''}")
    if a.record:
        from record import save_record
        save_record(a.record, title="The user's path on outdoor video at several compressions: tracker error, lags "
                                    "found, false verdicts",
                    command=(f"python benchmarks/bench_user_path.py --cache DIR --seeds {a.seeds} --first-seed "
                             f"{a.first_seed} --frames {a.frames} --effects delay,dynamics,none --renders {a.renders}"
                             + (f" (and --effects none over seeds {a.more_none})" if a.more_none else "") + "; "
                             f"python benchmarks/bench_user_path_crf.py --cache DIR --seeds {a.seeds} --first-seed "
                             f"{a.first_seed} --renders {a.renders}"
                             + (f" --more-none {a.more_none}" if a.more_none else "") + f" --record {a.record}"),
                    description=("The same simulated scenes (450 frames, 20 nodes; seeds "
                                 f"{a.first_seed}-{a.first_seed + a.seeds - 1}; a hidden delay, a hidden inertia, or "
                                 "none) rendered as the outdoor preset (motion blur, light drift, shadow, ~1 px shake) "
                                 "at x264 crf 28 (the preset's) and less compressed, tracked by our tracker and "
                                 "diagnosed by rce run. Tracker error: visible points against the true positions (px; "
                                 "median per case, then the median over cases; the RMS per axis of the errors below "
                                 "2 px). A lag counts as found when named delay or dynamics."),
                    columns=["x264 crf", "render", "lag found", "delay found", "dynamics found",
                             "effect-free named", "tracker error median (px)", "RMS per axis below 2 px (px)",
                             "points beyond 2 px (%)"],
                    rows=rows, notes=notes or None)
    return 0


if __name__ == "__main__":
    sys.exit(main())
