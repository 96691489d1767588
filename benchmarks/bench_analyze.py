"""Speed of the core pipeline on plant 1 (20 nodes x 1104 frames), with baselines measured in the same run.

Usage: python benchmarks/bench_analyze.py [--plant DIR] [--repeat 3]

Prints
1. the GTSAM smoother (graph build + Levenberg-Marquardt, paper weights) against a direct scipy sparse
   solve of the same quadratic (assembly + factorisation), and their ratio (goal <= 10x);
2. the marginal-covariance time (selected inversion of GTSAM's information matrix) against the smoother
   time (goal <= 3x);
3. the whole `rce analyze` wall time for each preset, 250 bootstrap resamples included, as a subprocess
   (goal < 5 s), with the Python start-up + import time measured separately.
Medians over --repeat runs; this machine is noisy, so read the ratios.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import rce_gtsam
from rce_gtsam.presets import PAPER
from rce_gtsam.smoothing.presmooth import moving_average
from rce_gtsam.smoothing.smoother import smooth_tracks
from rce_gtsam.smoothing.reference import paper_system, solve_direct

REPO = Path(__file__).resolve().parents[1]


def median_time(fn, repeat):
    out = []
    for _ in range(repeat):
        t = time.perf_counter()
        value = fn()
        out.append(time.perf_counter() - t)
    return statistics.median(out), value


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--plant", type=Path, default=REPO.parent / "shared" / "data" / "plant_1")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    tracks_csv, graph_json = args.plant / "tapir_tracks.csv", args.plant / "branch_graph.json"
    graph = rce_gtsam.load_graph(graph_json)
    tracks = rce_gtsam.load_tracks(tracks_csv, graph)
    print(f"{args.plant.name}: {tracks.n_nodes} nodes x {tracks.n_frames} frames, "
          f"{int(tracks.observed.sum())} observations")

    cfg = PAPER.smoother
    no_marg = PAPER.with_(smoother={"marginals": False}).smoother
    t_gtsam, sm = median_time(lambda: smooth_tracks(tracks, graph, no_marg), args.repeat)
    pre = moving_average(tracks, cfg.presmooth_window)
    t_direct, ref = median_time(lambda: solve_direct(paper_system(pre, graph, cfg)), args.repeat)
    diff = float(abs(sm.tracks.xy - ref.xy).max())
    print(f"\n1. smoother (paper weights): GTSAM build+LM {t_gtsam:.3f} s ({sm.report.iterations} LM iterations) "
          f"vs scipy direct sparse solve {t_direct:.3f} s -> ratio {t_gtsam / t_direct:.1f}x (goal <= 10x); "
          f"max |difference| {diff:.1e} px")

    runs = [smooth_tracks(tracks, graph, cfg) for _ in range(args.repeat)]
    t_marg = statistics.median(r.report.seconds_marginals for r in runs)
    t_smooth = statistics.median(r.report.seconds_build + r.report.seconds_optimize for r in runs)
    print(f"2. marginals (per node-frame 2x2 and per-frame joint {2 * tracks.n_nodes}x{2 * tracks.n_nodes}): "
          f"{t_marg:.3f} s vs smoother {t_smooth:.3f} s -> ratio {t_marg / t_smooth:.2f}x (goal <= 3x)")

    t_import, _ = median_time(lambda: subprocess.run([sys.executable, "-c", "import rce_gtsam.pipeline"],
                                                     check=True), args.repeat)
    rce = [sys.executable, "-m", "rce_gtsam.cli"]
    for preset in ("paper", "default"):
        with tempfile.TemporaryDirectory() as tmp:
            cmd = [*rce, "analyze", str(tracks_csv), str(graph_json), "--out", f"{tmp}/out", "--preset", preset,
                   "--bootstrap", "250", "--no-figures"]
            t_cli, _ = median_time(lambda: subprocess.run(cmd, check=True, capture_output=True), args.repeat)
        print(f"3. rce analyze --preset {preset} (250 resamples): {t_cli:.2f} s wall (goal < 5 s), of which "
              f"Python start-up + imports {t_import:.2f} s")


if __name__ == "__main__":
    main()
