"""How densely to place nodes: bend-angle noise, kappa error and no_signal flags against segment length.

Usage: python benchmarks/bench_node_spacing.py [--lengths 10,20,40,80] [--seeds 3] [--frames 600] [--record]

For each typical segment length L (px; the simulator draws each segment's length from 0.8 L to 1.2 L) a
branch of about 360 px is simulated (``rce_gtsam.sim``: default tracker-like noise, no hidden effect, a
1280 x 960 frame so that nothing is scaled down) and analysed with the default preset. Measured per L, over
seeds 0..N-1:

* the bend-angle noise after smoothing: RMS of the analysed bending minus the true bending (each segment's
  mean difference removed: the rest reference is the pipeline's own), median over segments (deg);
* the same noise predicted from three nodes' across-branch errors, sqrt(6) sigma / L (sigma = the
  simulator's across-branch white noise at mid-branch; before smoothing, and without its drift);
* kappa's log-RMSE against the truth, and the share of segments flagged no_signal.

In the simulator the bending of a segment (kappa z) does not grow with its length, while on a real branch a
segment's bending grows with its length (curvature x length): the table gives the noise side of the trade-off,
which holds for both. ``--record`` saves it as ``docs/validation/node_spacing.json`` (``benchmarks/record.py``).
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np

BRANCH_PX = 360.0


def one(length: float, seed: int, frames: int) -> dict:
    from rce_gtsam.pipeline import analyze
    from rce_gtsam.quality import assess_quality
    from rce_gtsam.sim.simulate import NoiseConfig, SimulationConfig, simulate

    n_nodes = max(5, int(round(BRANCH_PX / length)) + 1)
    cfg = SimulationConfig(n_nodes=n_nodes, n_frames=frames, seed=seed, image_size=(1280, 960),
                           segment_px=(0.8 * length, 1.2 * length))
    sim = simulate(cfg)
    res = analyze(sim.tracks, sim.graph, preset="default", n_boot=100)
    r = res.response
    row = {b.edge: i for i, b in enumerate(sim.graph.bends)}
    y = sim.response_true[[row[tuple(e)] for e in r.edges]][:, r.frames]
    d = r.Y - y
    d = d - np.nanmean(d, axis=1, keepdims=True)
    noise = np.sqrt(np.nanmean(d ** 2, axis=1))
    kt = np.array([sim.kappa_true[tuple(e)] for e in r.edges])
    log_err = float(np.sqrt(np.mean(np.log(res.fit.kappa / kt) ** 2)))
    q = assess_quality(res)
    no_signal = [("no_signal" in sq.reasons) for sq in q.values()]
    noise_cfg = NoiseConfig()
    sigma_mid = noise_cfg.sigma_across_px * (1 + (noise_cfg.tip_factor - 1) * 0.5)
    seg = np.array(list(sim.segment_px.values()))
    return {"n_nodes": n_nodes, "segment_px": float(np.median(seg)), "noise_deg": noise.tolist(),
            "predicted_deg": math.degrees(math.sqrt(6) * sigma_mid / float(np.median(seg))),
            "log_err": log_err, "no_signal": no_signal}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lengths", default="10,20,40,80", help="typical segment lengths (px), comma-separated")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--frames", type=int, default=600)
    ap.add_argument("--record", action="store_true", help="save the table as docs/validation/node_spacing.json")
    a = ap.parse_args()
    t0 = time.perf_counter()
    rows = []
    print(f"{'L px':>5} {'nodes':>5} {'median L':>8} {'noise deg':>9} {'predicted':>9} {'kappa logRMSE':>13} "
          f"{'no_signal':>9}")
    for length in (float(x) for x in a.lengths.split(",")):
        runs = [one(length, s, a.frames) for s in range(a.seeds)]
        noise = float(np.median(np.concatenate([r["noise_deg"] for r in runs])))
        pred = float(np.median([r["predicted_deg"] for r in runs]))
        seg = float(np.median([r["segment_px"] for r in runs]))
        err = float(np.median([r["log_err"] for r in runs]))
        flags = [f for r in runs for f in r["no_signal"]]
        rows.append([int(length), runs[0]["n_nodes"], round(seg, 1), round(noise, 2), round(pred, 2), round(err, 2),
                     f"{sum(flags)} of {len(flags)}"])
        print(f"{length:>5.0f} {runs[0]['n_nodes']:>5} {seg:>8.1f} {noise:>9.2f} {pred:>9.2f} {err:>13.2f} "
              f"{sum(flags):>4} of {len(flags)}", flush=True)
    print(f"{time.perf_counter() - t0:.0f} s")
    if a.record:
        from record import save_record  # benchmarks/record.py (this script's folder is on sys.path)
        path = save_record(
            "node_spacing", title="Node spacing: bend-angle noise against segment length",
            command=f"python benchmarks/bench_node_spacing.py --lengths {a.lengths} --seeds {a.seeds} "
                    f"--frames {a.frames} --record",
            description=(f"Simulated branches of about {BRANCH_PX:.0f} px with the simulator's default tracker-like "
                         f"noise (no hidden effect, {a.frames} frames, seeds 0-{a.seeds - 1}), the nodes spaced so "
                         "that segments are about L px long, analysed with the default preset. 'angle noise' is the "
                         "RMS of the analysed bending minus the true bending, median over segments; 'predicted' is "
                         "sqrt(6) sigma / L for the simulator's white across-branch noise sigma at mid-branch (before "
                         "smoothing, without drift). In the simulator a segment's bending does not grow with its "
                         "length; on a real branch it does, so longer segments gain signal as well as losing noise."),
            columns=["L (px)", "nodes", "median segment (px)", "angle noise (deg)", "predicted sqrt(6) sigma/L (deg)",
                     "kappa log-RMSE", "no_signal segments"],
            rows=rows)
        print("wrote", path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
