"""Where a creeping joint's drift goes in the rank-1 fit, per cached beam creep case (``bench_beam.py`` pickles).

Per case: the weak joint (the row where the noise-free response departs most from the effect-free one), its drift
over the record (linear trend of that difference, deg), the rank-1 baseline's kappa of that joint against the
quasi-static truth (both on geometric mean 1 over the bends), the drift left in that row's baseline residual (deg),
and the excitation z's own trend (deg per unit kappa). A drift the fit hands to z (a large kappa for the weak joint,
a trend in z, little left in its residual) is no longer a per-joint course an ``offset`` candidate can find.

Usage: OMP_NUM_THREADS=1 python benchmarks/beam_creep_absorption.py --cache /work/cache/beam4 [--frames 450]
"""

from __future__ import annotations

import argparse
import pickle
import sys
from pathlib import Path

import numpy as np


def trend(v: np.ndarray) -> float:
    """Linear trend of ``v`` (T,) over the record (its slope times T), NaN frames left out."""
    t = np.arange(v.size)
    ok = np.isfinite(v)
    return float(np.polyfit(t[ok], v[ok], 1)[0] * v.size)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cache", required=True)
    ap.add_argument("--frames", type=int, default=450)
    a = ap.parse_args()
    if not Path(a.cache).is_dir():
        print(f"beam_creep_absorption: --cache {a.cache}: no such directory", file=sys.stderr)
        return 2
    from rce_gtsam.model import ResponseModel

    paths = sorted(Path(a.cache).glob(f"creep_*_{a.frames}_bootpreset.pkl"),
                   key=lambda p: (float(p.name.split("_")[1]), int(p.name.split("_")[2])))
    for p in paths:
        with open(p, "rb") as fh:
            c = pickle.load(fh)
        inp, Y, y, yf = c["inputs"], c["Y"], c["truth"], c["truth_effect_free"]
        row = int(np.argmax(np.abs(y - yf).max(axis=1)))
        b = ResponseModel(config=inp["config"]).solve(Y, inp["weights"], inp["root_distance"])
        k, kt = np.abs(np.asarray(b.kappa)), c["kappa_true"]
        kn, ktn = k / np.exp(np.mean(np.log(k))), kt / np.exp(np.mean(np.log(kt)))
        resid = Y - np.asarray(b.kappa)[:, None] * np.asarray(b.z)[None]
        mult, seed = p.name.split("_")[1:3]
        print(f"creep x{mult} seed {seed}: drift {trend(y[row] - yf[row]):6.1f} deg; weak joint kappa fitted / true "
              f"{kn[row]:5.2f} / {ktn[row]:4.2f}; drift left in its residual {trend(resid[row]):5.1f} deg; "
              f"z trend {trend(np.asarray(b.z)):5.2f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
