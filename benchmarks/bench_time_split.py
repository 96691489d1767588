"""Does the time-split widening keep the intervals calibrated where the model is right? Coverage of kappa_true.

For seeds of the project's simulator (effect-free and with a hidden offset, 900 frames, tracker-like noise with
drift): analyze with the default preset (phase bootstrap) and with the opt-in time-split check on (4 blocks,
``--set compliance.time_split_blocks=4``), in the same process. Printed: the share of segments whose 95 % interval covers kappa_true, the median
U_e, and the median inflation the check applied. The real-data side is ``benchmarks/bench_ci_thirds.py``.

    python benchmarks/bench_time_split.py --seeds 20 --boot 100
"""

from __future__ import annotations

import argparse

import numpy as np

from rce_gtsam.pipeline import analyze
from rce_gtsam.presets import get_preset
from rce_gtsam.sim.simulate import SimulationConfig, simulate


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--boot", type=int, default=100)
    ap.add_argument("--effects", default="none,offset")
    a = ap.parse_args()
    off = get_preset("default")
    on = off.with_(compliance={"time_split_blocks": 4})
    for eff in a.effects.split(","):
        cov = {"on": [], "off": []}
        ue = {"on": [], "off": []}
        infl = []
        for sd in range(a.first_seed, a.first_seed + a.seeds):
            sim = simulate(SimulationConfig(seed=sd, n_frames=900, effects=() if eff == "none" else (eff,)))
            for name, preset in (("on", on), ("off", off)):
                r = analyze(sim.tracks, sim.graph, preset=preset, n_boot=a.boot, seed=0)
                kt = np.array([sim.kappa_true[e] for e in r.response.edges])
                kt = kt / np.exp(np.mean(np.log(kt)))
                cov[name] += list((r.ci.low <= kt) & (kt <= r.ci.high))
                ue[name].append(float(np.median((r.ci.high - r.ci.low) / r.fit.kappa)))
                if name == "on" and r.time_split is not None:
                    infl.append(r.time_split.inflation)
            print(f"  {eff} seed {sd}: inflation {infl[-1]:.2f}", flush=True)
        print(f"{eff}: coverage with the check {100 * np.mean(cov['on']):.1f} % (median U_e {np.median(ue['on']):.2f}), "
              f"without {100 * np.mean(cov['off']):.1f} % (U_e {np.median(ue['off']):.2f}); "
              f"median inflation {np.median(infl):.2f} (max {np.max(infl):.2f})", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
