"""How much of a beam effect the diagnosis' forms for it can see, against the noise they must see it through.

Per cached beam case (``bench_beam.py`` pickles in ``--cache``): the rank-1 model and the rank-1 model with each form
(``--forms``; default: the candidate the effect is counted right by, :data:`rce_gtsam.sim.beam.DIAGNOSIS_NAME`, first
name) are fitted to the *noise-free* response (on the pipeline's rest reference, unit weights, the preset's compliance
config, the form started from the rank-1 fit as the oracle's clean fit is:
:func:`rce_gtsam.diagnosis.oracle.oracle_test`).
Printed (degrees, RMS over entries): the rank-1 fit's residual, each form's residual and the share of the rank-1
residual's power it captures, 1 - (rf / r1)^2; the same for the best rank-2 approximation of the (row-centred) response,
a bound for any form that adds one shared time course (a second excitation, a mode); the captured part
sqrt(r1^2 - rf^2) against the angle noise (Y less the truth); per strength the medians. A form that captures little of
the effect (gust front: a smeared lag, not a shift; strain stiffening: a saturation z absorbs), or an effect small
against the noise, bounds what even the oracle can detect.

Usage: OMP_NUM_THREADS=1 python benchmarks/beam_form_capture.py --cache /work/cache/beam4
       [--effects modal,gust_front,two_sources,creep,stiffening] [--frames 450] [--seeds 0,1,2]
       [--forms dynamics,resonances] [--record NAME]
"""

from __future__ import annotations

import argparse
import pickle
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np


def capture(c: dict, forms) -> tuple[float, dict, float, float]:
    """(rank-1 residual RMS, {form: its residual RMS}, rank-2 residual RMS, angle-noise RMS), degrees, of one
    case ``c``."""
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
    rf = {form: float((m + effects_mod.make(form)).solve(y, ones, s, start=(r1.kappa.copy(), r1.z.copy(), {}),
                                                          max_iter=FULL_ITER).rmse) for form in forms}
    yc = y - y.mean(axis=1, keepdims=True)
    sv = np.linalg.svd(yc, compute_uv=False)
    r2 = float(np.sqrt(np.sum(sv[2:] ** 2) / yc.size))
    return float(r1.rmse), rf, r2, float(np.sqrt(np.nanmean((Y - y) ** 2)))


def share(r1: float, rf: float) -> float:
    """The share of the rank-1 residual's power a fit with residual ``rf`` captures (0..1)."""
    return float(max(1 - (rf / r1) ** 2, 0.0)) if r1 > 0 else float("nan")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cache", required=True)
    ap.add_argument("--effects", default="modal,gust_front,two_sources,creep,stiffening")
    ap.add_argument("--frames", type=int, default=450)
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--forms", default=None, help="comma list of candidate forms (default: each effect's first name)")
    ap.add_argument("--record", default=None, metavar="NAME", help="save the table as docs/validation/NAME.json")
    a = ap.parse_args()
    from rce_gtsam import effects as effects_mod
    from rce_gtsam.sim.beam import BEAM_EFFECTS, DIAGNOSIS_NAME

    effects = [e.strip() for e in a.effects.split(",") if e.strip()]
    bad = [e for e in effects if e not in BEAM_EFFECTS]
    if bad:
        print(f"beam_form_capture: --effects: unknown {bad}; choose from {', '.join(BEAM_EFFECTS)}", file=sys.stderr)
        return 2
    forms_arg = [f.strip() for f in a.forms.split(",") if f.strip()] if a.forms else None
    bad = [f for f in forms_arg or [] if f not in effects_mod.names()]
    if bad:
        print(f"beam_form_capture: --forms: unknown {bad}; choose from {', '.join(effects_mod.names())}",
              file=sys.stderr)
        return 2
    if not Path(a.cache).is_dir():
        print(f"beam_form_capture: --cache {a.cache}: no such directory", file=sys.stderr)
        return 2
    seeds = {int(v) for v in a.seeds.split(",")}
    table = []
    for eff in effects:
        forms = forms_arg or [DIAGNOSIS_NAME[eff][0]]
        per = defaultdict(list)
        for p in Path(a.cache).glob(f"{eff}_*_{a.frames}_bootpreset.pkl"):
            mult, seed = p.name[len(eff) + 1:].split("_")[:2]
            if int(seed) in seeds:
                per[float(mult)].append((int(seed), p))
        for mult in sorted(per):
            caps, r2s, ratio, noise_all, r1_all = defaultdict(list), [], defaultdict(list), [], []
            for seed, p in sorted(per[mult]):
                with open(p, "rb") as fh:
                    r1, rf, r2, noise = capture(pickle.load(fh), forms)
                r1_all.append(r1)
                noise_all.append(noise)
                r2s.append(share(r1, r2))
                for form in forms:
                    caps[form].append(share(r1, rf[form]))
                    ratio[form].append(float(np.sqrt(max(r1 ** 2 - rf[form] ** 2, 0.0))) / noise)
                print(f"  {eff} x{mult:g} seed {seed}: rank-1 residual {r1:.3f} deg, noise {noise:.2f} deg; captured "
                      + ", ".join(f"{form} {100 * caps[form][-1]:.0f} %" for form in forms)
                      + f", rank 2 {100 * r2s[-1]:.0f} %", flush=True)
            med = {form: float(np.median(caps[form])) for form in forms}
            print(f"{eff} x{mult:g} ({len(r2s)} seeds): captured (median) "
                  + ", ".join(f"{form} {100 * med[form]:.0f} % (captured / noise {np.median(ratio[form]):.2f})"
                              for form in forms)
                  + f", rank 2 {100 * np.median(r2s):.0f} %", flush=True)
            for form in forms:
                table.append([eff, a.frames, mult, len(r2s), form, round(100 * med[form], 1),
                              f"{100 * min(caps[form]):.0f}-{100 * max(caps[form]):.0f}",
                              round(float(np.median(ratio[form])), 2), round(100 * float(np.median(r2s)), 1),
                              round(float(np.median(r1_all)), 3), round(float(np.median(noise_all)), 2)])
    if a.record:
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        from record import save_record

        save_record(a.record, title="The beam simulator: how much of each effect the diagnosis' forms can see",
                    command=f"python benchmarks/beam_form_capture.py --cache DIR --effects "
                            f"{a.effects} --frames {a.frames} --seeds {a.seeds}"
                            + (f" --forms {a.forms}" if a.forms else "") + f" --record {a.record}",
                    description=("Noise-free beam responses (the cached bench_beam.py cases) fitted by the rank-1 "
                                 "model and by the rank-1 model with each candidate form, started from the rank-1 "
                                 "fit as the oracle's clean fit is. 'captured': the share of the rank-1 residual's "
                                 "power the form "
                                 "removes (median and range over seeds); 'rank 2': the same for the best rank-2 "
                                 "approximation, a bound for any form that adds one shared time course; 'captured / "
                                 "noise': the captured part's RMS against the angle noise the diagnosis sees it "
                                 "through (median)."),
                    columns=["effect", "frames", "x strength", "seeds", "form", "captured (%, median)",
                             "captured (%, range)", "captured / noise (median)", "rank 2 (%, median)",
                             "rank-1 residual (deg, median)", "noise (deg, median)"],
                    rows=table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
