"""How many kappa are flagged not-ok, and why: effect-free simulations (noisy and noise-free) and the two plants.

Usage: python benchmarks/bench_quality.py [--seeds 5] [--frames 900] [--plants /work/shared/data] [--record]

For each seed, `rce simulate` (no effect; default tracker-like noise, then --clean) is analysed with the
default preset; prints the share of segments whose quality is not `ok` and the count of each reason, and
for the flagged no_signal segments the ground-truth signal / noise (true response variance over the
variance of the smoothed bend's error), which says whether the flag was deserved. Then every flagged
segment of each real plant with its reason, SNR, R^2 and CI.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from collections import Counter
from pathlib import Path

import numpy as np

from rce_gtsam.pipeline import analyze
from rce_gtsam.quality import assess_quality
from rce_gtsam.sim.simulate import NoiseConfig, SimulationConfig, simulate


def sim_share(seeds: int, frames: int, clean: bool) -> list:
    reasons, n_seg, n_bad, deserved = Counter(), 0, 0, []
    for seed in range(seeds):
        sim = simulate(SimulationConfig(seed=seed, n_frames=frames, noise=NoiseConfig(enabled=not clean)))
        with tempfile.TemporaryDirectory() as tmp:
            files = sim.write(tmp)
            truth = json.loads(Path(files["truth.json"]).read_text())
            r = analyze(files["tracks.csv"], files["graph.json"], n_boot=100)
        q = assess_quality(r)
        for i, (e, sq) in enumerate(q.items()):
            n_seg += 1
            if not sq.ok:
                n_bad += 1
                reasons.update(sq.reasons)
            if "no_signal" in sq.reasons:
                yt = np.array(truth["response_true"][f"{e[0]}->{e[1]}"])[r.response.frames]
                y = r.response.Y[list(r.response.edges).index(e)]
                ok = np.isfinite(y)
                err = np.var(y[ok] - yt[ok])
                deserved.append(np.var(yt[ok]) / err if err > 0 else np.inf)
    label = "noise-free (--clean)" if clean else "default tracker-like noise"
    print(f"simulated, {label}, seeds 0-{seeds - 1}, {frames} frames: {n_bad}/{n_seg} segments not ok "
          f"({100 * n_bad / n_seg:.1f} %); reasons {dict(reasons)}")
    if deserved:
        print(f"  no_signal segments: true signal / noise variance median {np.median(deserved):.2f} "
              f"(max {np.max(deserved):.2f})")
    med, top = (round(float(np.median(deserved)), 2), round(float(np.max(deserved)), 2)) if deserved else ("-", "-")
    return [label, n_seg, n_bad, round(100 * n_bad / n_seg, 1), reasons.get("no_signal", 0),
            ", ".join(f"{k} {v}" for k, v in sorted(reasons.items())) or "-", med, top]


def plants(root: Path) -> None:
    for p in sorted(root.glob("plant_*")):
        r = analyze(p / "tapir_tracks.csv", p / "branch_graph.json")
        df = r.summary().dropna(subset=["kappa"])
        bad = df[df.quality != "ok"]
        print(f"{p.name}: {len(bad)}/{len(df)} segments not ok")
        for row in bad.itertuples():
            print(f"  {row.parent}->{row.child}: {row.quality} (snr {row.bend_snr:.2f}, R2 {row.fit_r2:.2f}, "
                  f"kappa {row.kappa:.2f} [{row.kappa_ci_low:.2f}, {row.kappa_ci_high:.2f}])")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--frames", type=int, default=900)
    ap.add_argument("--plants", type=Path, default=Path("/work/shared/data"))
    ap.add_argument("--record", action="store_true", help="save the simulated rows as docs/validation/quality.json")
    args = ap.parse_args()
    rows = [sim_share(args.seeds, args.frames, clean) for clean in (False, True)]
    if args.record:
        from record import save_record  # benchmarks/record.py (this script's folder is on sys.path)
        path = save_record(
            "quality", title="Quality flags on effect-free simulated branches",
            command=f"python benchmarks/bench_quality.py --seeds {args.seeds} --frames {args.frames} --record",
            description=(f"Effect-free branches from rce simulate (20 nodes, {args.frames} frames, seeds 0-"
                         f"{args.seeds - 1}), analysed with the default preset. A segment is not ok when any quality "
                         "flag is raised. For the no_signal segments the last two columns give the ground truth's "
                         "bending variance over the variance of the smoothed angle's error: below 1 the flag was "
                         "deserved (the segment's signal is weaker than its noise)."),
            columns=["tracks", "segments", "not ok", "not ok (%)", "no_signal", "reasons (count)",
                     "true signal/noise of no_signal, median", "max"],
            rows=rows)
        print("wrote", path)
    if args.plants.is_dir():
        plants(args.plants)


if __name__ == "__main__":
    main()
