"""Which preset settings break the diagnosis' calibration? (rce_gtsam.diagnosis.domain)

Effect-free simulated recordings (the simulator's default noise, 900 frames) analysed under ``default`` and
under ``default`` with one setting of the ``paper`` preset each, then under ``paper`` itself. Printed per
variant: how often the second excitation's full-data test (two node-disjoint sets of segments sharing a time
course, :func:`~rce_gtsam.diagnosis.score_test.shared_time_course_test`) gives p <= 0.005 (the diagnosis'
threshold) and p <= 0.05, and whether :func:`~rce_gtsam.diagnosis.domain.settings_outside_domain` flags it.
``--verdicts K``: also the whole diagnosis (all six candidates, as ``rce diagnose`` runs it, but with the
verdict it would name outside the domain) on the first K recordings of each flagged variant.

Usage: python benchmarks/bench_diagnose_domain.py [--seeds 40] [--verdicts 0] [--variants a,b]
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace

import numpy as np


def variants() -> dict:
    """{name: Preset}: default, default with each domain premise of the paper preset broken, and paper."""
    from rce_gtsam.presets import get_preset
    d, p = get_preset("default"), get_preset("paper")
    return {"default": d,
            "smoother.edge_weight": replace(d, smoother=replace(d.smoother, edge_weight=p.smoother.edge_weight)),
            "bending.rest": replace(d, bending=replace(d.bending, rest=p.bending.rest)),
            "compliance.response": replace(d, compliance=replace(d.compliance, response=p.compliance.response)),
            "paper": p}


def analysed(preset, seed: int):
    from rce_gtsam.pipeline import analyze
    from rce_gtsam.sim.simulate import SimulationConfig, simulate
    sim = simulate(SimulationConfig(seed=seed, n_frames=900))
    return analyze(sim.tracks, sim.graph, preset=preset, n_boot=0)


def shared_course_p(result) -> float:
    """p of the shared-time-course test on the diagnosis' baseline and node-disjoint sets of the analysis."""
    from rce_gtsam.diagnosis.io import diagnosis_baseline
    from rce_gtsam.diagnosis.score_test import shared_time_course_test
    return shared_time_course_test(*diagnosis_baseline(result)).p


def would_name(result) -> str | None:
    """The effect the diagnosis would name were the analysis inside the domain."""
    from rce_gtsam.diagnosis.diagnose import diagnose
    from rce_gtsam.diagnosis.io import diagnose_inputs
    return diagnose(**diagnose_inputs(result, respect_domain=False)).verdict


def main() -> int:
    from rce_gtsam.diagnosis.domain import settings_outside_domain
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=40)
    ap.add_argument("--verdicts", type=int, default=0, help="recordings per flagged variant to diagnose whole")
    ap.add_argument("--variants", default=None, help="comma-separated names (default: all)")
    a = ap.parse_args()
    t0 = time.perf_counter()
    chosen = variants() if a.variants is None else {k: v for k, v in variants().items() if k in a.variants.split(",")}
    print(f"effect-free simulated recordings, seeds 0-{a.seeds - 1}, 900 frames")
    for name, preset in chosen.items():
        flagged = bool(settings_outside_domain(preset))
        ps, named = [], []
        for seed in range(a.seeds):
            res = analysed(preset, seed)
            ps.append(shared_course_p(res))
            if flagged and seed < a.verdicts:
                named.append(would_name(res))
        ps = np.array(ps)
        line = (f"  {name:22s} outside the domain: {'yes' if flagged else 'no '}; shared-course test p <= 0.005 on "
                f"{int((ps <= 0.005).sum())} of {len(ps)}, p <= 0.05 on {int((ps <= 0.05).sum())}")
        if named:
            line += (f"; whole diagnosis would name an effect on {sum(v is not None for v in named)} of {len(named)} "
                     f"({', '.join(sorted({v for v in named if v}))})")
        print(line, flush=True)
    print(f"({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
