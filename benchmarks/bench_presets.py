"""Default vs paper preset on simulated ground truth, and what each default choice buys.

Usage: python benchmarks/bench_presets.py [--seeds 20] [--frames 900] [--boot 100]

For each seed: simulate an effect-free branch (rce_gtsam.sim.simulate), analyse it with each variant, and
measure the kappa error against the truth as log-RMSE = sqrt(mean_e (log kappa_e - log kappa_true_e)^2)
(both sides normalised to geometric mean 1), plus bootstrap 95% CI coverage of kappa_true. Variants
start from the paper preset and switch on one default choice at a time, then the full default.
Prints median log-RMSE per variant, its ratio to the paper preset's, and CI coverage.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import rce_gtsam
from rce_gtsam.presets import DEFAULT, PAPER
from rce_gtsam.sim.simulate import SimulationConfig, simulate


def variants():
    """Paper, full default, and the default with one choice reverted or added at a time."""
    d = DEFAULT
    return {
        "paper": PAPER,
        "default": d,
        "default + offset prior (paper's; w_e 0.45)": d.with_(smoother={"edge_prior": "offset", "edge_weight": 0.45}),
        "default + length prior (w_e 0.45)": d.with_(smoother={"edge_prior": "length", "edge_weight": 0.45}),
        "default, paper temporal weights + MA5": d.with_(smoother={"presmooth_window": 5, "velocity_weight": 0.35,
                                                                   "acceleration_weight": 0.2}),
        "default, unsigned |delta| (paper)": d.with_(bending={"signed": False, "rest": "first"},
                                                     compliance={"response": "abs"}),
        "default, count shrinkage (paper's)": d.with_(compliance={"shrinkage": "count"}),
        "default + anisotropic 3:1": d.with_(smoother={"along_across_ratio": 3.0}),
        "default + Huber": d.with_(smoother={"robust": "huber"}),
        "default, unweighted (equal weights)": d.with_(compliance={"weighted": False}),
        "default with moving-block bootstrap (paper)": d.with_(compliance={"bootstrap": "block"}),
        "default + correlated (GLS) fit": d.with_(compliance={"correlated": True}),
    }


def log_rmse(est: dict, truth: dict) -> float:
    keys = [k for k in truth if k in est and np.isfinite(est[k])]
    a = np.log([est[k] for k in keys]); b = np.log([truth[k] for k in keys])
    a -= a.mean(); b -= b.mean()
    return float(np.sqrt(np.mean((a - b) ** 2)))


def coverage(result, truth: dict) -> float:
    if result.ci is None:
        return float("nan")
    # compare on the geometric-mean-1 scale both sides use
    gm = np.exp(np.mean(np.log([truth[e] for e in result.response.edges])))
    hits = [lo <= truth[e] / gm <= hi for e, lo, hi in zip(result.response.edges, result.ci.low, result.ci.high)]
    return float(np.mean(hits))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--frames", type=int, default=900)
    ap.add_argument("--boot", type=int, default=100)
    ap.add_argument("--only", default=None, help="comma list of variant names")
    args = ap.parse_args()
    vs = variants()
    if args.only:
        vs = {k: v for k, v in vs.items() if k in args.only.split(",")}
    errs = {k: [] for k in vs}
    covs = {k: [] for k in vs}
    times = {k: 0.0 for k in vs}
    for seed in range(args.seeds):
        sim = simulate(SimulationConfig(seed=seed, n_frames=args.frames))
        for name, preset in vs.items():
            t = time.perf_counter()
            r = rce_gtsam.analyze(sim.tracks, sim.graph, preset=preset, n_boot=args.boot)
            times[name] += time.perf_counter() - t
            errs[name].append(log_rmse(r.kappa, sim.kappa_true))
            covs[name].append(coverage(r, sim.kappa_true))
        print(f"seed {seed}: " + ", ".join(f"{k} {errs[k][-1]:.3f}" for k in vs), flush=True)
    base = np.median(errs["paper"]) if "paper" in errs else np.nan
    print(f"\n{'variant':28s} {'median log-RMSE':>16s} {'ratio to paper':>15s} {'CI coverage':>12s} {'s/run':>7s}")
    for k in vs:
        m = np.median(errs[k])
        print(f"{k:28s} {m:16.4f} {m / base:15.3f} {np.nanmean(covs[k]):12.1%} {times[k] / args.seeds:7.2f}")


if __name__ == "__main__":
    main()
