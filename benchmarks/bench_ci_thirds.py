"""Are the confidence intervals honest on REAL data? kappa from disjoint thirds of the frames vs the full CI.

For each real plant (``../shared/data/plant_1``, ``plant_2``), preset ``default`` (or ``--preset``): the full
recording gives kappa_full and its 95 % CI; each third of the frames (disjoint) gives kappa_k. If the CI is
calibrated, log kappa's standard error scales as 1 / sqrt(frames), so the third's deviation from the full
estimate (which contains it) has variance 3 s^2 - s^2 = 2 s^2, with s = (log high - log low) / (2 x 1.96) the
full estimate's SE implied by its interval. z = (log kappa_k - log kappa_full) / (sqrt(2) s) over segments x
thirds should then have SD ~ 1 (below 1: intervals too wide; above: too narrow). Also prints each plant's
median U_e. Segments with an unusable third (kappa not finite) are left out and counted.

Usage: python benchmarks/bench_ci_thirds.py [--data ../shared/data] [--preset default] [--bootstrap 250]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np


def thirds(tracks_path, graph_path, preset: str, n_boot: int) -> dict:
    """The thirds check of one recording: file paths, or (Tracks, BranchGraph) objects."""
    from rce_gtsam.graph import load_graph
    from rce_gtsam.pipeline import analyze
    from rce_gtsam.tracks import Tracks, load_tracks

    graph = load_graph(graph_path) if isinstance(graph_path, (str, Path)) else graph_path
    tr = load_tracks(tracks_path, graph) if isinstance(tracks_path, (str, Path)) else tracks_path
    full = analyze(tr, graph, preset=preset, n_boot=n_boot, seed=0)
    k_full = dict(zip(full.response.edges, full.fit.kappa))
    lo = dict(zip(full.response.edges, full.ci.low))
    hi = dict(zip(full.response.edges, full.ci.high))
    F = tr.n_frames
    cuts = np.linspace(0, F, 4).round().astype(int)
    zs, dropped = [], 0
    for a, b in zip(cuts[:-1], cuts[1:]):
        part = Tracks(node_ids=tr.node_ids, xy=tr.xy[:, a:b], sigma_px=None if tr.sigma_px is None else tr.sigma_px[:, a:b],
                      source=f"{tracks_path} frames {a}-{b - 1}")
        res = analyze(part, graph, preset=preset, n_boot=0, seed=0)
        for e, k in zip(res.response.edges, res.fit.kappa):
            s = (np.log(hi[e]) - np.log(lo[e])) / (2 * 1.96)
            if not (np.isfinite(k) and k > 0 and s > 0 and k_full[e] > 0):
                dropped += 1
                continue
            zs.append((np.log(k) - np.log(k_full[e])) / (np.sqrt(2) * s))
    u = (full.ci.high - full.ci.low) / full.fit.kappa
    return {"z": np.array(zs), "dropped": dropped, "median_U": float(np.median(u)),
            "n_eff": full.ci.effective_samples}


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", default=str(Path(__file__).resolve().parents[2] / "shared" / "data"))
    ap.add_argument("--preset", default="default")
    ap.add_argument("--bootstrap", type=int, default=250)
    ap.add_argument("--time-split", type=int, default=0, metavar="K",
                    help="switch on the time-split widening with K blocks (compliance.time_split_blocks)")
    ap.add_argument("--simulate", type=int, default=0, metavar="N",
                    help="also run the same check on N simulated effect-free branches (900 frames), where the "
                         "model is right and the intervals cover kappa_true ~90 %% of the time: what SD(z) the "
                         "check gives for calibrated intervals")
    a = ap.parse_args()
    if a.time_split:
        from rce_gtsam.presets import get_preset
        a.preset = get_preset(a.preset).with_(compliance={"time_split_blocks": a.time_split})
    t0 = time.perf_counter()
    print(f"preset {getattr(a.preset, 'name', a.preset)} (time-split blocks {a.time_split}), {a.bootstrap} resamples; z = (log kappa_third - log kappa_full) / (sqrt(2) SE_full)")
    for plant in ("plant_1", "plant_2"):
        d = Path(a.data) / plant
        r = thirds(d / "tapir_tracks.csv", d / "branch_graph.json", a.preset, a.bootstrap)
        z = r["z"]
        print(f"{plant}: {len(z)} segment-thirds, SD(z) {np.std(z, ddof=1):.2f}, median |z| {np.median(np.abs(z)):.2f}, "
              f"share |z| > 1.96: {100 * np.mean(np.abs(z) > 1.96):.0f} %, dropped {r['dropped']}; "
              f"median U_e {r['median_U']:.2f}; effective samples {r['n_eff']}", flush=True)
    if a.simulate:
        from rce_gtsam.simulate import SimulationConfig, simulate
        allz = []
        for sd in range(a.simulate):
            sim = simulate(SimulationConfig(seed=sd, n_frames=900))
            r = thirds(sim.tracks, sim.graph, a.preset, a.bootstrap)
            allz.append(r["z"])
            print(f"  simulated seed {sd}: SD(z) {np.std(r['z'], ddof=1):.2f}, median U_e {r['median_U']:.2f}", flush=True)
        z = np.concatenate(allz)
        print(f"simulated, {a.simulate} branches: SD(z) {np.std(z, ddof=1):.2f}, share |z| > 1.96: "
              f"{100 * np.mean(np.abs(z) > 1.96):.0f} %", flush=True)
    print(f"({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
