"""Speed of the GTSAM smoother and its marginal covariances, against baselines measured in the same run.

Usage: python benchmarks/bench_smoother.py [--plant DIR] [--repeat 3] [--skip-gtsam-marginals]

Importable: ``run_benchmark(tracks, graph, repeat=3) -> dict`` (load this file by path, e.g. with
``importlib.util.spec_from_file_location``; benchmarks/ is not a package).

Prints, for the paper preset (linear problem) on the given plant (default: plant 1, 20 nodes x 1104 frames):
1. GTSAM graph build + Levenberg-Marquardt vs a direct scipy sparse solve of the same quadratic
   (assembly + LU of the normal equations) and their ratio (goal <= 10x), with the max |difference|;
   the paper's LSQR (atol = btol = 1e-6) time and its max |difference| from the exact solution;
2. marginal covariances (every node-frame 2x2 and every per-frame joint 2N x 2N) vs the smoother
   time (goal <= 3x);
3. gtsam.Marginals: construction plus marginalCovariance of the first 10 frame states (each the joint
   covariance of all nodes at that frame), extrapolated to every frame (the approach the selected
   inversion replaces);
4. the default preset (whatever presets.DEFAULT holds; non-linear if it uses the length prior or a
   robust loss): build, LM, marginals.
Medians over --repeat runs. The machine is shared and noisy: read the ratios, not the absolute times.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import time
from pathlib import Path

import gtsam
import numpy as np

import rce_gtsam
from rce_gtsam.presets import DEFAULT, PAPER
from rce_gtsam.smoothing.presmooth import moving_average
from rce_gtsam.factors import frame_key
from rce_gtsam.smoothing.smoother import build_problem, smooth_tracks
from rce_gtsam.smoothing.reference import paper_system, solve_direct, solve_lsqr

REPO = Path(__file__).resolve().parents[1]


def _median_time(fn, repeat):
    times, value = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        value = fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times), value


def gtsam_marginals_estimate(tracks, graph, n_query_frames: int = 10) -> dict:
    """Time gtsam.Marginals on the paper problem: construction, then ``marginalCovariance`` of the first
    ``n_query_frames`` frame states in key order, extrapolated linearly to all F frames."""
    cfg = PAPER.smoother
    res = smooth_tracks(tracks, graph, dataclasses.replace(cfg, marginals=False))
    problem = build_problem(res.presmoothed, graph, cfg)
    values = gtsam.Values()
    F = tracks.n_frames
    for t in range(F):
        values.insert(frame_key(t), res.tracks.xy[:, t].ravel())
    t0 = time.perf_counter()
    marg = gtsam.Marginals(problem.graph, values)
    t1 = time.perf_counter()
    n_frames = min(n_query_frames, F)
    for t in range(n_frames):
        marg.marginalCovariance(frame_key(t))   # joint covariance of all nodes at frame t
    per_key = (time.perf_counter() - t1) / n_frames
    return {"construct_s": t1 - t0, "per_key_s": per_key, "all_keys_s": t1 - t0 + per_key * F}


def run_benchmark(tracks, graph, repeat: int = 3, gtsam_marginals: bool = True) -> dict:
    """Measure everything listed in the module docstring; returns a flat dict of seconds/ratios/px."""
    out: dict = {"n_nodes": tracks.n_nodes, "n_frames": tracks.n_frames}
    cfg = PAPER.smoother
    no_marg = dataclasses.replace(cfg, marginals=False)

    t_gtsam, sm = _median_time(lambda: smooth_tracks(tracks, graph, no_marg), repeat)
    pre = moving_average(tracks, cfg.presmooth_window)
    t_direct, ref = _median_time(lambda: solve_direct(paper_system(pre, graph, cfg)), repeat)
    t_lsqr, lsq = _median_time(lambda: solve_lsqr(paper_system(pre, graph, cfg)), 1)
    out.update(paper_gtsam_s=t_gtsam, paper_lm_iterations=sm.report.iterations,
               paper_direct_s=t_direct, paper_ratio_gtsam_to_direct=t_gtsam / t_direct,
               paper_max_diff_gtsam_direct_px=float(np.abs(sm.tracks.xy - ref.xy).max()),
               paper_lsqr_s=t_lsqr, paper_lsqr_iterations=lsq.iterations,
               paper_max_diff_gtsam_lsqr_px=float(np.abs(sm.tracks.xy - lsq.xy).max()),
               paper_max_diff_gtsam_lsqr_observed_px=float(np.abs(sm.tracks.xy - lsq.xy)[sm.observed].max()))

    runs = [smooth_tracks(tracks, graph, cfg) for _ in range(repeat)]
    t_marg = statistics.median(r.report.seconds_marginals for r in runs)
    t_smooth = statistics.median(r.report.seconds_build + r.report.seconds_optimize for r in runs)
    out.update(marginals_s=t_marg, smoother_s=t_smooth, ratio_marginals_to_smoother=t_marg / t_smooth)

    if gtsam_marginals:
        est = gtsam_marginals_estimate(tracks, graph)
        out.update(gtsam_marginals_construct_s=est["construct_s"], gtsam_marginals_per_key_s=est["per_key_s"],
                   gtsam_marginals_all_keys_s=est["all_keys_s"])

    reports, totals = [], []
    for _ in range(max(1, repeat // 2)):
        t = time.perf_counter()
        reports.append(smooth_tracks(tracks, graph, DEFAULT.smoother).report)
        totals.append(time.perf_counter() - t)
    med = lambda field: statistics.median(getattr(rep, field) for rep in reports)  # noqa: E731
    out.update(default_total_s=statistics.median(totals), default_build_s=med("seconds_build"),
               default_optimize_s=med("seconds_optimize"), default_marginals_s=med("seconds_marginals"),
               default_lm_iterations=reports[-1].iterations, default_converged=all(r.converged for r in reports))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--plant", type=Path, default=REPO.parent / "shared" / "data" / "plant_1")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--skip-gtsam-marginals", action="store_true")
    args = ap.parse_args()
    graph = rce_gtsam.load_graph(args.plant / "branch_graph.json")
    tracks = rce_gtsam.load_tracks(args.plant / "tapir_tracks.csv", graph)
    r = run_benchmark(tracks, graph, args.repeat, not args.skip_gtsam_marginals)
    print(f"{args.plant.name}: {r['n_nodes']} nodes x {r['n_frames']} frames (medians of {args.repeat})")
    print(f"1. paper smoother: GTSAM build+LM {r['paper_gtsam_s']:.3f} s ({r['paper_lm_iterations']} LM iteration) vs "
          f"scipy direct sparse solve {r['paper_direct_s']:.3f} s -> ratio {r['paper_ratio_gtsam_to_direct']:.1f}x "
          f"(goal <= 10x); max |GTSAM - direct| {r['paper_max_diff_gtsam_direct_px']:.1e} px")
    print(f"   paper LSQR (atol=btol=1e-6): {r['paper_lsqr_s']:.3f} s, iterations {r['paper_lsqr_iterations']}; "
          f"max |GTSAM - LSQR| {r['paper_max_diff_gtsam_lsqr_px']:.1e} px (observed frames "
          f"{r['paper_max_diff_gtsam_lsqr_observed_px']:.1e} px)")
    print(f"2. marginals (all node-frame 2x2 + per-frame joint): {r['marginals_s']:.3f} s vs smoother "
          f"{r['smoother_s']:.3f} s -> ratio {r['ratio_marginals_to_smoother']:.2f}x (goal <= 3x)")
    if "gtsam_marginals_all_keys_s" in r:
        print(f"3. gtsam.Marginals: construct {r['gtsam_marginals_construct_s']:.2f} s + "
              f"{r['gtsam_marginals_per_key_s'] * 1e3:.2f} ms per frame state -> all {r['n_frames']} frames "
              f"~{r['gtsam_marginals_all_keys_s']:.1f} s (extrapolated) = "
              f"{r['gtsam_marginals_all_keys_s'] / r['marginals_s']:.0f}x the selected inversion")
    c = DEFAULT.smoother
    print(f"4. default preset (edge_prior={c.edge_prior}, w_v={c.velocity_weight}, w_a={c.acceleration_weight}, "
          f"along/across={c.along_across_ratio}, robust={c.robust}): total {r['default_total_s']:.2f} s = build "
          f"{r['default_build_s']:.2f} + LM {r['default_optimize_s']:.2f} ({r['default_lm_iterations']} iterations, "
          f"converged={r['default_converged']}) + marginals {r['default_marginals_s']:.2f}")


if __name__ == "__main__":
    main()
