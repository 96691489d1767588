"""Are the confidence intervals honest on REAL data? kappa from disjoint thirds of the frames vs the full CI.

For each real plant (``../shared/data/plant_1``, ``plant_2``), preset ``default`` (or ``--preset``): the full
recording gives kappa_full and its 95 % CI; each third of the frames (disjoint) gives kappa_k. If the CI is
calibrated, log kappa's standard error scales as 1 / sqrt(frames), so the third's deviation from the full
estimate (which contains it) has variance 3 s^2 - s^2 = 2 s^2, with s = (log high - log low) / (2 x 1.96) the
full estimate's SE implied by its interval. z = (log kappa_k - log kappa_full) / (sqrt(2) s) over segments x
thirds should then have SD ~ 1 (below 1: intervals too wide; above: too narrow). Also prints each plant's
median U_e. Segments with an unusable third (kappa not finite) are left out and counted.

``--null N`` measures what this check can show at all on each plant (its oracle): N surrogate recordings that
obey the rank-1 model exactly, with the plant's own excitation and noise (fitted kappa z plus phase-randomised
residuals of the plant's fit: the phase bootstrap's noise model, every segment's spectrum and the correlation
between segments kept; the plant's missing frames kept missing). Each is fitted whole with its own phase-
bootstrap interval (coverage of the surrogates' true kappa = the plant's fitted kappa) and in thirds, each third
re-referenced to its own median angle as a recording of that third alone would be (as the check above, which
re-runs the whole pipeline, does). Where the excitation puts kappa's error on few effective samples a third's
kappa scatters more than the 1 / frames rule behind z assumes, so SD(z) exceeds 1 even for exactly calibrated
intervals: the null SD is the figure a calibrated interval gives, and data SD / null SD the honest ratio.

Usage: python benchmarks/bench_ci_thirds.py [--data ../shared/data] [--preset default] [--bootstrap 250]
"""

from __future__ import annotations

import argparse
import dataclasses
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
            "n_eff": full.ci.effective_samples, "full": full}


def log_se(ci) -> np.ndarray:
    """(E,) log-kappa standard error implied by a 95 % interval."""
    from rce_gtsam.model.time_split import Z95
    return (np.log(ci.high) - np.log(ci.low)) / (2 * Z95)


def surrogate_null(full, n_boot: int, n: int, seed: int = 0) -> dict:
    """The thirds check on ``n`` model-exact surrogates of the analysed recording ``full`` (an AnalysisResult
    with intervals; see the module docstring), and on its own data at the same (Y-level) computation."""
    from rce_gtsam.model.surrogates import phase_randomised_residuals
    from rce_gtsam.model.uncertainty import bootstrap_kappa
    from rce_gtsam.model import ResponseModel
    from rce_gtsam.model.time_split import block_z

    config = full.preset.compliance
    Y = full.response.Y
    W = full.response.weights if config.weighted else None
    pred = full.fit.predict()
    kappa = np.abs(full.fit.kappa)
    z_data = block_z(Y, W, config, kappa, log_se(full.ci), 3)
    zs, cover = [], []
    for i, R in enumerate(phase_randomised_residuals(Y - pred, n, np.random.default_rng(seed))):
        Ys = np.where(np.isfinite(Y), pred + R, np.nan)
        fit = ResponseModel(config=config).fit(Ys, weights=W).core
        ci = bootstrap_kappa(Ys, dataclasses.replace(config, seed=1000 + i, n_boot=n_boot), W, fit=fit)
        cover.append((ci.low <= kappa) & (kappa <= ci.high))
        zs.append(block_z(Ys, W, config, np.abs(fit.kappa), log_se(ci), 3))
    z = np.concatenate(zs)
    return {"sd_z": float(np.std(z, ddof=1)), "share_out": float(np.mean(np.abs(z) > 1.96)),
            "coverage": float(np.mean(np.concatenate(cover))), "sd_z_data": float(np.std(z_data, ddof=1))}


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
    ap.add_argument("--null", type=int, default=0, metavar="N",
                    help="also N model-exact surrogates of each plant: the SD(z) a calibrated interval gives there, "
                         "and the surrogates' interval coverage (see the module docstring)")
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
        if a.null:
            n = surrogate_null(r["full"], a.bootstrap, a.null)
            print(f"  {plant} if the rank-1 model held exactly ({a.null} surrogates with its noise and excitation): "
                  f"SD(z) {n['sd_z']:.2f} (Y-level thirds; the data's at the same level {n['sd_z_data']:.2f}, "
                  f"ratio {n['sd_z_data'] / n['sd_z']:.2f}), share |z| > 1.96: {100 * n['share_out']:.0f} %; "
                  f"their 95 % intervals cover the true kappa for {100 * n['coverage']:.1f} % of segments",
                  flush=True)
    if a.simulate:
        from rce_gtsam.sim.simulate import SimulationConfig, simulate
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
