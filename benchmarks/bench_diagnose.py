"""Detection benchmark of ``rce_gtsam.diagnose``: for each hidden effect x seeds (+ effect-free seeds),
is the verdict right, how much does the verdict effect lower held-out RMSE, does kappa error fall?

Usage: python benchmarks/bench_diagnose.py [--seeds 10] [--pipeline] [--effects a,b] [--frames 900]
Default input: response matrices from the simulator's equations (rce_gtsam.simulate.bend_response) plus
white + smoothed noise and 2 % missing entries ("matrices"); --pipeline runs simulate -> tracks ->
pipeline.analyze (default preset) -> response matrix instead (slow: GTSAM smoothing per seed).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))


def case(effect, seed, frames, pipeline):
    if not pipeline:
        from _effect_data import synth
        Y, s, k, _, _ = synth(effect, seed=seed, E=18, T=frames)
        return Y, None, s, k
    from rce_gtsam.pipeline import analyze
    from rce_gtsam.simulate import SimulationConfig, simulate
    sim = simulate(SimulationConfig(effects=() if effect is None else (effect,), seed=seed, n_frames=frames))
    res = analyze(sim.tracks, sim.graph, preset="default", n_boot=0)
    r = res.response
    k = np.array([sim.kappa_true[e] for e in r.edges])
    return r.Y, r.weights, r.root_distance, k


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--frames", type=int, default=900)
    ap.add_argument("--pipeline", action="store_true")
    ap.add_argument("--effects", default="none,delay,dynamics,second_mode,offset,nonlinear")
    a = ap.parse_args()
    from rce_gtsam.diagnose import diagnose
    print(f"input: {'full pipeline (simulate -> tracks -> analyze)' if a.pipeline else 'matrices (simulator equations + noise)'}; "
          f"{a.seeds} seeds, {a.frames} frames")
    print(f"{'effect':<12} {'correct':>8} {'median dRMSE%':>14} {'klog before':>12} {'klog after':>11} {'median s':>9}")
    for eff in a.effects.split(","):
        hidden = None if eff == "none" else eff
        ok, imps, kb, ka, ts = 0, [], [], [], []
        for sd in range(a.seeds):
            Y, W, s, k = case(hidden, sd, a.frames, a.pipeline)
            t = time.perf_counter()
            d = diagnose(Y, weights=W, root_distance=s, seed=0)
            ts.append(time.perf_counter() - t)
            ok += d.verdict == hidden
            kb.append(np.sqrt(np.mean(np.log(np.abs(d.baseline.kappa) / k) ** 2)))
            if d.verdict is not None:
                c = d.candidate(d.verdict)
                imps.append(c.improvement_pct)
                ka.append(np.sqrt(np.mean(np.log(np.abs(c.fit.kappa) / k) ** 2)))
            print(f"  {eff} seed {sd}: verdict {d.verdict}, " + ", ".join(
                f"{c.effect} {c.improvement_pct:+.1f}% t={c.evidence:.1f}{'*' if c.supported else ''}" for c in d.candidates)
                + f" ({ts[-1]:.1f} s)", flush=True)
        med = lambda v: float(np.median(v)) if v else float("nan")  # noqa: E731
        print(f"{eff:<12} {ok:>5}/{a.seeds} {med(imps):14.1f} {med(kb):12.3f} {med(ka):11.3f} {med(ts):9.1f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
