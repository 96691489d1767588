"""Does a tracker's slow error reach the segments as its fast error does, on REAL footage? (drift_pattern's assumption)

The offset/creep's third drift check (:mod:`rce_gtsam.diagnosis.drift_pattern`) takes trends laid out across the
segments otherwise than the fast noise as evidence of creep. On the simulator that layout is shared by
construction; this asks the real plants (``../shared/data/plant_1``, ``plant_2``), two ways:

* **segment lengths** (:func:`~rce_gtsam.diagnosis.drift_pattern.layout_test` on each edge's length, less its
  median, with the offset's basis 1, t): a branch does not stretch, so a length's variation is tracking error
  along the branch (and out-of-plane tilt, which foreshortens a segment of its own), with no creep to confuse
  it. A small p says the plant's slow length errors are laid out otherwise than its fast ones: the assumption
  fails for that tracker and footage (or the branch tilts slowly out of the image plane). Raw TAPIR tracks and
  the factor-graph-smoothed ones (default preset) are both asked.
* **bend angles** (:func:`~rce_gtsam.diagnosis.drift_pattern.drift_pattern_test` on the rank-1 baseline, default
  and paper presets): the check itself as the diagnosis would run it. A small p is creep *or* a failed
  assumption; the plants' fold t for the offset is not significant, so the diagnosis never asks it there.

``--simulated N`` runs the length test on N effect-free simulated recordings through the same pipeline (the
simulator's drift is a node's, so its layout is shared): what a calibrated p gives (share at p <= 0.05).

Usage: python benchmarks/bench_drift_layout_real.py [--data ../shared/data] [--simulated 0]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ALPHA = 0.05


def length_residuals(tracks, graph) -> np.ndarray:
    """(edges, frames) each edge's length (px) less its median over the frames, NaN where a node is missing."""
    idx = {n: i for i, n in enumerate(tracks.node_ids)}
    L = np.array([np.hypot(*(tracks.xy[idx[c]] - tracks.xy[idx[a]]).T) for a, c in graph.edges])
    return L - np.nanmedian(L, axis=1, keepdims=True)


def offset_basis(n_frames: int) -> np.ndarray:
    """The offset/creep's time basis (1, t), as the diagnosis tests it."""
    from rce_gtsam.effects.offset import Offset
    return Offset().heldout_time_basis(n_frames)


def length_layout_p(tracks, graph, seed: int = 0) -> float:
    """p of :func:`~rce_gtsam.diagnosis.drift_pattern.layout_test` on the segment lengths of ``tracks``."""
    from rce_gtsam.diagnosis.drift_pattern import layout_test
    R = length_residuals(tracks, graph)
    return layout_test(R, np.isfinite(R).astype(float), offset_basis(R.shape[1]), seed=seed).p


def plant(folder: Path) -> dict:
    """{name: p} of the length and bend checks of one real plant."""
    from rce_gtsam.diagnosis.drift_pattern import drift_pattern_test
    from rce_gtsam.graph import load_graph
    from rce_gtsam.diagnosis.io import diagnosis_baseline
    from rce_gtsam.pipeline import analyze
    from rce_gtsam.tracks import load_tracks

    graph = load_graph(folder / "branch_graph.json")
    tracks = load_tracks(folder / "tapir_tracks.csv", graph)
    out = {"lengths raw": length_layout_p(tracks, graph)}
    for preset in ("default", "paper"):
        res = analyze(tracks, graph, preset=preset, n_boot=0, seed=0)
        if preset == "default":
            out["lengths smoothed"] = length_layout_p(res.smoothed.tracks, graph)
        fit, _ = diagnosis_baseline(res)
        out[f"bends {preset}"] = drift_pattern_test(fit, offset_basis(fit.Y.shape[1])).p
    return out


def simulated(seed: int) -> dict:
    """{name: p} of the length test on one effect-free simulated recording (raw and smoothed tracks)."""
    from rce_gtsam.pipeline import analyze
    from rce_gtsam.sim.simulate import SimulationConfig, simulate
    sim = simulate(SimulationConfig(seed=seed, n_frames=900))
    res = analyze(sim.tracks, sim.graph, preset="default", n_boot=0)
    return {"lengths raw": length_layout_p(sim.tracks, sim.graph),
            "lengths smoothed": length_layout_p(res.smoothed.tracks, sim.graph)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=Path(__file__).resolve().parents[2] / "shared" / "data")
    ap.add_argument("--simulated", type=int, default=0, help="effect-free simulated recordings to calibrate on")
    a = ap.parse_args()
    t0 = time.perf_counter()
    print("p of the layout test (small = slow courses laid out otherwise than the fast noise)")
    for name in ("plant_1", "plant_2"):
        ps = plant(a.data / name)
        print(f"  {name}: " + ", ".join(f"{k} p = {v:.3f}" for k, v in ps.items()), flush=True)
    if a.simulated:
        rows = [simulated(s) for s in range(a.simulated)]
        for k in rows[0]:
            hits = sum(r[k] <= ALPHA for r in rows)
            print(f"  simulated effect-free, {k}: p <= {ALPHA} on {hits} of {len(rows)} "
                  f"(smallest p {min(r[k] for r in rows):.3f})")
    print(f"({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
