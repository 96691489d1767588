"""Coverage of kappa_true by the 95 % intervals of the rank-1 model and of the extended model (``--effects``).

For every seed the simulator (``rce_gtsam.sim.simulate``, 20 nodes, tracker-like noise with drift) makes a branch
with known kappa, once effect-free and once with a hidden ``offset`` (rest-pose offset and creep). Each is
analysed with the default preset as ``rce analyze`` does, plain and with ``--effects offset``. Printed per
model and data set: the share of edges whose interval covers kappa_true (both on the geometric-mean-1
scale), the share whose interval contains the model's own estimate, the median U_e and the median kappa
log-RMSE, and the seconds per analysis; plus the extended model's coverage and U_e as ratios to the plain
model's on the same data (same process, same seeds).

    python benchmarks/bench_effects_ci.py --seeds 20 --boot 100

The machine the figures in the README were measured on was shared with other jobs: compare the ratios.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import rce_gtsam
from rce_gtsam.sim.simulate import SimulationConfig, simulate


def scores(result, truth: dict) -> dict:
    """Per-edge coverage of kappa_true, containment of the estimate, U_e, and kappa log-RMSE."""
    edges = result.response.edges
    k = result.fit.kappa
    gm = np.exp(np.mean(np.log([truth[e] for e in edges])))
    kt = np.array([truth[e] / gm for e in edges])
    lo, hi = result.ci.low, result.ci.high
    a, b = np.log(k), np.log(kt)
    return {"cover": (lo <= kt) & (kt <= hi), "contain": (lo <= k) & (k <= hi), "u": (hi - lo) / k,
            "log_rmse": float(np.sqrt(np.mean((a - a.mean() - (b - b.mean())) ** 2)))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--frames", type=int, default=900)
    ap.add_argument("--boot", type=int, default=100)
    ap.add_argument("--preset", default="default")
    args = ap.parse_args()
    data = {"effect-free": (), "hidden offset": ("offset",)}
    models = {"rank-1": (), "--effects offset": ("offset",)}
    acc = {(d, m): {"cover": [], "contain": [], "u": [], "log_rmse": [], "s": 0.0} for d in data for m in models}
    for seed in range(args.first_seed, args.first_seed + args.seeds):
        line = [f"seed {seed}:"]
        for dname, hidden in data.items():
            sim = simulate(SimulationConfig(seed=seed, n_frames=args.frames, effects=hidden))
            for mname, eff in models.items():
                t = time.perf_counter()
                r = rce_gtsam.analyze(sim.tracks, sim.graph, preset=args.preset, n_boot=args.boot, effects=eff)
                a = acc[(dname, mname)]
                a["s"] += time.perf_counter() - t
                sc = scores(r, sim.kappa_true)
                for key in ("cover", "contain", "u"):
                    a[key].append(sc[key])
                a["log_rmse"].append(sc["log_rmse"])
                line.append(f"{dname}/{mname} cover {sc['cover'].mean():.0%}")
        print(" ".join(line), flush=True)
    n = args.seeds
    print(f"\n{args.preset} preset, {n} seeds x {args.frames} frames, {args.boot} resamples")
    print(f"{'data':14s} {'model':17s} {'covers kappa_true':>18s} {'contains estimate':>18s} "
          f"{'median U_e':>11s} {'log-RMSE':>9s} {'s/run':>6s}")
    for (d, m), a in acc.items():
        print(f"{d:14s} {m:17s} {np.mean(np.concatenate(a['cover'])):18.1%} "
              f"{np.mean(np.concatenate(a['contain'])):18.1%} {np.median(np.concatenate(a['u'])):11.3f} "
              f"{np.median(a['log_rmse']):9.3f} {a['s'] / n:6.2f}")
    for d in data:
        p, e = acc[(d, "rank-1")], acc[(d, "--effects offset")]
        print(f"{d}: --effects offset / rank-1: coverage ratio "
              f"{np.mean(np.concatenate(e['cover'])) / np.mean(np.concatenate(p['cover'])):.3f}, median U_e ratio "
              f"{np.median(np.concatenate(e['u'])) / np.median(np.concatenate(p['u'])):.3f}, time ratio "
              f"{e['s'] / p['s']:.2f}")


if __name__ == "__main__":
    main()
