"""Long recordings in bounded memory: `rce analyze` on 1,000 / 10,000 / 50,000 frames x 20 nodes.

Usage: python benchmarks/bench_long.py [--frames 1000,10000,50000] [--nodes 20] [--preset default]

Each recording is simulated here (``rce_gtsam.sim.simulate``, seed 0, tracker-like noise with gaps and jumps),
written as tracks.csv + graph.json into a temporary folder, and analysed by the real CLI as a
subprocess: ``rce analyze TRACKS GRAPH --out DIR --preset PRESET --bootstrap 250 --no-figures``. For each
length it prints the wall time of that subprocess, its peak resident memory (``ru_maxrss`` of exactly
that child, from ``os.wait4``) and both as ratios to the first (1,000-frame) case of the same run.
Goals (issue 14): 50,000 frames in <= 30x the 1,000-frame time and under 1.5 GB peak RSS.
The stage timings (smooth / bending / fit / bootstrap) come from the run's report.json.
The machine this runs on may be shared: read the ratios, which come from one run.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from rce_gtsam.sim.simulate import SimulationConfig, simulate

GOAL_TIME_RATIO = 30.0
GOAL_RSS_GB = 1.5


def run_cli(args: list[str]) -> tuple[float, float, str]:
    """Run ``args`` as a child process; (wall seconds, peak RSS in GB of that child, stdout+stderr)."""
    t = time.perf_counter()
    p = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    out = p.stdout.read()
    _, status, usage = os.wait4(p.pid, 0)
    wall = time.perf_counter() - t
    p.returncode = os.waitstatus_to_exitcode(status)
    if p.returncode != 0:
        raise RuntimeError(f"{' '.join(args)} exited {p.returncode}:\n{out}")
    return wall, usage.ru_maxrss * 1024 / 1e9, out  # ru_maxrss is in KiB on Linux


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", default="1000,10000,50000", help="comma-separated lengths; the first is the baseline")
    ap.add_argument("--nodes", type=int, default=20)
    ap.add_argument("--preset", default="default")
    ap.add_argument("--bootstrap", type=int, default=250)
    ap.add_argument("--keep", type=Path, default=None, help="keep the simulated inputs and outputs here")
    args = ap.parse_args()
    lengths = [int(f) for f in args.frames.split(",")]
    rce = str(Path(sys.executable).with_name("rce"))
    work = Path(tempfile.mkdtemp(prefix="bench_long_")) if args.keep is None else args.keep
    rows = []
    try:
        for F in lengths:
            sim_dir, out_dir = work / f"sim_{F}", work / f"out_{F}"
            shutil.rmtree(out_dir, ignore_errors=True)
            if not (sim_dir / "tracks.csv").is_file():
                simulate(SimulationConfig(n_nodes=args.nodes, n_frames=F, seed=0)).write(sim_dir)
            wall, rss, _ = run_cli([rce, "analyze", str(sim_dir / "tracks.csv"), str(sim_dir / "graph.json"),
                                    "--out", str(out_dir), "--preset", args.preset,
                                    "--bootstrap", str(args.bootstrap), "--no-figures"])
            timings = json.loads((out_dir / "report.json").read_text()).get("timings_s", {})
            rows.append((F, wall, rss, timings))
            print(f"  {F} frames: {wall:.1f} s, {rss:.2f} GB", flush=True)
    finally:
        if args.keep is None:
            shutil.rmtree(work, ignore_errors=True)

    F0, t0, r0, _ = rows[0]
    print(f"\nrce analyze, {args.nodes} nodes, preset {args.preset}, {args.bootstrap} resamples, --no-figures "
          f"(wall and peak RSS of the CLI subprocess)")
    print(f"{'frames':>8} {'wall s':>8} {'x time':>7} {'peak RSS GB':>12} {'x RSS':>6}   stages s (smooth/bending/fit/bootstrap)")
    for F, wall, rss, tm in rows:
        stages = "/".join(f"{tm.get(k, float('nan')):.1f}" for k in ("smooth", "bending", "fit", "bootstrap"))
        print(f"{F:>8} {wall:>8.1f} {wall / t0:>7.1f} {rss:>12.2f} {rss / r0:>6.1f}   {stages}")
    F1, t1, r1, _ = rows[-1]
    print(f"\ngoal: {F1} frames in <= {GOAL_TIME_RATIO:.0f}x the {F0}-frame time -> {t1 / t0:.1f}x "
          f"({'met' if t1 / t0 <= GOAL_TIME_RATIO else 'NOT met'}); peak RSS < {GOAL_RSS_GB} GB -> {r1:.2f} GB "
          f"({'met' if r1 < GOAL_RSS_GB else 'NOT met'})")


if __name__ == "__main__":
    main()
