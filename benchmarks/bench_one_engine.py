"""One model engine on the real plants (the figures quoted in the README).

For plants 1 and 2 under the ``default`` and ``paper`` presets: the largest |kappa| difference between
``rce analyze`` and the diagnosis baseline (``rce diagnose``), and for ``rce analyze --effects offset`` the
share of edges whose 95 % interval contains the estimate, the median U_e against the plain analysis' and
the seconds each took (same process; the machine may be shared, compare the ratios).

    python benchmarks/bench_one_engine.py [--data /work/shared/data] [--boot 250]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import rce_gtsam
from rce_gtsam.diagnosis.io import diagnose_result


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", type=Path, default=Path("/work/shared/data"))
    ap.add_argument("--boot", type=int, default=250)
    args = ap.parse_args()
    print(f"{'plant':8s} {'preset':8s} {'max|dk| analyze-diagnose':>25s} {'CI contains (ext)':>18s} "
          f"{'median U_e plain':>17s} {'ext':>6s} {'s plain':>8s} {'s ext':>6s}")
    for plant in ("plant_1", "plant_2"):
        d = args.data / plant
        for preset in ("default", "paper"):
            t = time.perf_counter()
            plain = rce_gtsam.analyze(d / "tapir_tracks.csv", d / "branch_graph.json", preset=preset,
                                      n_boot=args.boot)
            t_plain = time.perf_counter() - t
            diag = diagnose_result(plain, effects=("offset",), n_folds=2)
            dk = float(np.max(np.abs(np.abs(diag.baseline.kappa) - plain.fit.kappa)))
            t = time.perf_counter()
            ext = rce_gtsam.analyze(d / "tapir_tracks.csv", d / "branch_graph.json", preset=preset,
                                    n_boot=args.boot, effects=("offset",))
            t_ext = time.perf_counter() - t
            k = ext.fit.kappa
            contain = float(np.mean((ext.ci.low <= k) & (k <= ext.ci.high)))
            print(f"{plant:8s} {preset:8s} {dk:25.3g} {contain:18.0%} {np.nanmedian(plain.uncertainty):17.3f} "
                  f"{np.nanmedian(ext.uncertainty):6.3f} {t_plain:8.1f} {t_ext:6.1f}", flush=True)


if __name__ == "__main__":
    main()
