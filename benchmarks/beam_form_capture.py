"""How much of a beam effect the diagnosis' form for it can see, against the noise it must see it through.

Per cached beam case (``bench_beam.py`` pickles in ``--cache``): the rank-1 model and the rank-1 model with the
candidate the effect is counted right by (:data:`rce_gtsam.sim.beam.DIAGNOSIS_NAME`, first name) are fitted to the
*noise-free* response (on the pipeline's rest reference, unit weights, the preset's compliance config, the
candidate started from the rank-1 fit as the oracle's clean fit is: :func:`rce_gtsam.diagnosis.oracle.oracle_test`).
Printed (degrees, RMS over entries): the rank-1 fit's residual, the form's residual, the part of the response the
form captures beyond rank 1, sqrt(r1^2 - rf^2), the angle noise (Y less the truth), and per strength the median of
captured / noise. A form that captures little of the effect (gust front: a smeared lag, not a shift; strain
stiffening: a saturation z absorbs), or an effect small against the noise, bounds what even the oracle can detect.

Usage: OMP_NUM_THREADS=1 python benchmarks/beam_form_capture.py --cache /work/cache/beam4
       [--effects modal,gust_front,two_sources,creep,stiffening] [--frames 450] [--seeds 0,1,2]
"""

from __future__ import annotations

import argparse
import pickle
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np


def capture(c: dict, form: str) -> tuple[float, float, float]:
    """(rank-1 residual RMS, the form's residual RMS, angle-noise RMS), degrees, of one case ``c``."""
    from rce_gtsam import effects as effects_mod
    from rce_gtsam.diagnosis.settings import FULL_ITER
    from rce_gtsam.model import ResponseModel
    from rce_gtsam.model.inputs import validate_inputs

    inp = c["inputs"]
    Y = c["Y"]
    y = c["truth"] + np.nanmean(Y - c["truth"], axis=1, keepdims=True)
    _, _, s = validate_inputs(Y, inp["weights"], inp["root_distance"])
    m = ResponseModel(config=inp["config"])
    ones = np.ones_like(y)
    r1 = m.solve(y, ones, s)
    rf = (m + effects_mod.make(form)).solve(y, ones, s, start=(r1.kappa.copy(), r1.z.copy(), {}),
                                             max_iter=FULL_ITER)
    return float(r1.rmse), float(rf.rmse), float(np.sqrt(np.nanmean((Y - y) ** 2)))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cache", required=True)
    ap.add_argument("--effects", default="modal,gust_front,two_sources,creep,stiffening")
    ap.add_argument("--frames", type=int, default=450)
    ap.add_argument("--seeds", default="0,1,2")
    a = ap.parse_args()
    from rce_gtsam.sim.beam import BEAM_EFFECTS, DIAGNOSIS_NAME

    effects = [e.strip() for e in a.effects.split(",") if e.strip()]
    bad = [e for e in effects if e not in BEAM_EFFECTS]
    if bad:
        print(f"beam_form_capture: --effects: unknown {bad}; choose from {', '.join(BEAM_EFFECTS)}", file=sys.stderr)
        return 2
    if not Path(a.cache).is_dir():
        print(f"beam_form_capture: --cache {a.cache}: no such directory", file=sys.stderr)
        return 2
    seeds = {int(v) for v in a.seeds.split(",")}
    for eff in effects:
        form = DIAGNOSIS_NAME[eff][0]
        per = defaultdict(list)
        for p in Path(a.cache).glob(f"{eff}_*_{a.frames}_bootpreset.pkl"):
            mult, seed = p.name[len(eff) + 1:].split("_")[:2]
            if int(seed) in seeds:
                per[float(mult)].append((int(seed), p))
        for mult in sorted(per):
            rows = []
            for seed, p in sorted(per[mult]):
                with open(p, "rb") as fh:
                    r1, rf, noise = capture(pickle.load(fh), form)
                cap = float(np.sqrt(max(r1 ** 2 - rf ** 2, 0.0)))
                rows.append(cap / noise)
                print(f"  {eff} x{mult:g} seed {seed}: rank-1 residual {r1:.3f}, {form} residual {rf:.3f}, captured "
                      f"{cap:.2f} deg ({100 * (1 - (rf / r1) ** 2):.0f} %), noise {noise:.2f} deg", flush=True)
            print(f"{eff} x{mult:g}: captured / noise (median of {len(rows)}) {np.median(rows):.2f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
