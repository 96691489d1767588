"""How well does the model-free noise floor (:mod:`rce_gtsam.diagnosis.noise_floor`) match the true angle noise?

Per simulated branch (the project's simulator: anisotropic white noise, AR(1) drift, jumps, occlusion gaps,
with the white-noise level, the drift and the along/across ratio varied over seeds so that one setting is not
what is measured): simulate -> analyze (default preset, no bootstrap) -> noise floor. The true angle noise of
each row is RMS(Y - truth) with the truth on the pipeline's rest reference (per-row mean of Y - truth
removed). Printed per seed: true and estimated overall RMS (deg), their ratio, the share of rows whose own
estimate is within 25 %, and the across/along ratio q found vs set.

Usage: python benchmarks/bench_noise_floor.py [--seeds 20] [--first-seed 0] [--frames 900] [--record]

``--record`` saves the per-branch table as the validation record ``docs/validation/noise_floor.json``
(``benchmarks/record.py``), which the documentation's Validation page shows.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np


def one(seed: int, frames: int) -> dict:
    from dataclasses import replace

    from rce_gtsam.diagnosis.budget import budget_of
    from rce_gtsam.diagnosis.noise_floor import noise_floor_of
    from rce_gtsam.pipeline import analyze
    from rce_gtsam.sim.simulate import NoiseConfig, SimulationConfig, simulate

    sig = (0.5, 1.0, 2.0)[seed % 3]
    drift = (1.0, 2.0, 0.5, 1.0)[seed % 4]
    ratio = (3.0, 2.0, 1.5, 3.0, 1.0)[seed % 5]
    base = NoiseConfig()
    noise = replace(base, sigma_across_px=base.sigma_across_px * sig, drift_px=base.drift_px * drift,
                    along_ratio=ratio)
    sim = simulate(SimulationConfig(seed=seed, n_frames=frames, noise=noise))
    res = analyze(sim.tracks, sim.graph, preset="default", n_boot=0)
    r = res.response
    row = {b.edge: i for i, b in enumerate(sim.graph.bends)}
    y = sim.response_true[[row[tuple(e)] for e in r.edges]][:, r.frames]
    Y = r.Y
    yref = y + np.nanmean(Y - y, axis=1, keepdims=True)
    true_rows = np.nanmean((Y - yref) ** 2, axis=1)
    nf = noise_floor_of(res)
    b = budget_of(res)
    ok = np.isfinite(Y)
    true_var = float(np.mean((Y - yref)[ok] ** 2))
    return {"seed": seed, "sigma_mult": sig, "drift_mult": drift, "along_ratio": ratio,
            "budget_status": b.status, "budget_floor_over_true": b.noise_floor / true_var,
            "unexplained_z": b.unexplained / b.unexplained_se if b.unexplained_se > 0 else float("nan"),
            "true_rms": float(np.sqrt(true_rows.mean())), "est_rms": nf.rms_deg,
            "rows_within_25": float(np.mean(np.abs(np.sqrt(nf.variance_deg2 / true_rows) - 1) <= 0.25)),
            "q": nf.across_over_along, "q_true": 1.0 / ratio ** 2, "valid": float(nf.valid.mean()),
            "signal_rms": float(np.sqrt(np.mean(yref ** 2)))}


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--frames", type=int, default=900)
    ap.add_argument("--record", action="store_true", help="save the table as docs/validation/noise_floor.json")
    a = ap.parse_args()
    t0 = time.perf_counter()
    rows = []
    print(f"{'seed':>4} {'sigma x':>7} {'drift x':>7} {'along':>5} {'true deg':>8} {'est deg':>8} {'ratio':>6} "
          f"{'rows<=25%':>9} {'q':>6} {'q set':>6} {'consistent':>10} {'floor/true var':>14} {'unexpl z':>8} "
          f"{'budget':>12}")
    for s in range(a.first_seed, a.first_seed + a.seeds):
        r = one(s, a.frames)
        rows.append(r)
        print(f"{s:>4} {r['sigma_mult']:>7.1f} {r['drift_mult']:>7.1f} {r['along_ratio']:>5.1f} {r['true_rms']:>8.3f} "
              f"{r['est_rms']:>8.3f} {r['est_rms'] / r['true_rms']:>6.2f} {100 * r['rows_within_25']:>8.0f}% "
              f"{r['q']:>6.3f} {r['q_true']:>6.3f} {100 * r['valid']:>9.0f}% "
              f"{r['budget_floor_over_true']:>14.2f} {r['unexplained_z']:>8.2f} {r['budget_status']:>12}", flush=True)
    ratio = np.array([r["est_rms"] / r["true_rms"] for r in rows])
    print(f"\nestimated / true angle-noise RMS over {len(rows)} branches: median {np.median(ratio):.3f}, "
          f"range {ratio.min():.3f}-{ratio.max():.3f}; within 25 %: {int(np.sum(np.abs(ratio - 1) <= 0.25))}/{len(rows)}; "
          f"rows within 25 % (median over branches) {100 * np.median([r['rows_within_25'] for r in rows]):.0f}%; "
          f"{time.perf_counter() - t0:.0f} s")
    fv = np.array([r["budget_floor_over_true"] for r in rows])
    status = [r["budget_status"] for r in rows]
    print(f"variance budget on these effect-free branches: floor / true noise variance median {np.median(fv):.3f}, "
          f"RMS relative error {np.sqrt(np.mean((fv - 1) ** 2)):.3f}; status noise {status.count('noise')}, "
          f"misses {status.count('misses')} (false), inconclusive {status.count('inconclusive')}")
    if a.record:
        from record import save_record  # benchmarks/record.py (this script's folder is on sys.path)
        last = a.first_seed + a.seeds - 1
        path = save_record(
            "noise_floor", title="Noise floor against the true angle noise",
            command=f"python benchmarks/bench_noise_floor.py --seeds {a.seeds} --first-seed {a.first_seed} "
                    f"--frames {a.frames} --record",
            description=(f"Effect-free simulated branches (seeds {a.first_seed}-{last}, {a.frames} frames) with white "
                         "noise, drift and along/across noise ratio varied per seed (multiples of the simulator's "
                         "default), analysed with the default preset. The diagnosis' noise floor is estimated without "
                         "the model and compared with the true angle noise (RMS of the smoothed angles minus the "
                         "truth). A ratio near 1 is right; the budget status of an effect-free branch should not be "
                         "misses."),
            columns=["seed", "white noise (x default)", "drift (x default)", "along/across", "true noise (deg)",
                     "estimated (deg)", "estimated / true", "segments within 25 % (%)", "budget status"],
            rows=[[s, round(r["sigma_mult"], 1), round(r["drift_mult"], 1), round(r["along_ratio"], 1),
                   round(r["true_rms"], 3), round(r["est_rms"], 3), round(r["est_rms"] / r["true_rms"], 2),
                   round(100 * r["rows_within_25"]), {"noise": "adequate"}.get(r["budget_status"], r["budget_status"])]
                  for s, r in zip(range(a.first_seed, last + 1), rows)],
            notes=[f"estimated / true over {len(rows)} branches: median {np.median(ratio):.2f}, range "
                   f"{ratio.min():.2f}-{ratio.max():.2f}; within 25 %: {int(np.sum(np.abs(ratio - 1) <= 0.25))} of "
                   f"{len(rows)}",
                   f"budget status: adequate {status.count('noise')}, misses {status.count('misses')}, "
                   f"inconclusive {status.count('inconclusive')}"])
        print("wrote", path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
