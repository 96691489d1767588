"""What out-of-plane swing does to the 2-D view of a simulated branch (:mod:`rce_gtsam.sim.three_d`).

Per seed and scene (noise-free: the numbers are properties of the geometry, not of a tracker):

* ``unexpl``: share of the projected 2-D bending variance (turning-angle deviations from frame 0, the rest pose)
  that the best rank-1 model leaves unexplained, ``misfit^2 / RMS^2`` (:func:`rce_gtsam.sim.simulate.rank1_misfit`);
* ``ceil``: log-RMSE of ``kappa_true_image`` (the rank-1 kappa of the noise-free projected angles: the best any
  2-D method can do with perfect tracks) against ``kappa_true_3d``;
* ``dL``: segment-length change in px: RMS over time of each segment's projected length less its frame-0 length,
  median over segments, and the same for the distal third (``dL_tip``); ``p2p``: its median peak-to-peak;
* ``R2(z_o)``: share of the length changes' variance that a per-segment linear fit on ``z_o`` explains (first
  order in the swing) and ``R2(z_o^2)`` on ``z_o^2`` (second order);
* ``R2(z)``: the same on the in-plane excitation ``z`` (a tilted plane also changes lengths under in-plane bending).

With ``--pipeline``: also the kappa of ``analyze(preset="default")`` (what ``rce run`` fits) on the noise-free
projected tracks (``pipe_clean``) and on the default tracker-noise tracks (``pipe_noisy``), log-RMSE against
``kappa_true_3d`` (both normalised to geometric mean 1 over the fitted bends).

Scenes: planar (tilt 0, share 0), tilted planar (tilt 30, share 0), swing without tilt (tilt 0, share 0.5),
the default out-of-plane scene (tilt 30, share 0.5).

Usage: OMP_NUM_THREADS=1 python benchmarks/bench_oop_sim.py [--seeds 20] [--frames 900] [--pipeline]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

SCENES = {"planar": (0.0, 0.0), "tilted planar": (30.0, 0.0), "swing, tilt 0": (0.0, 0.5),
          "out_of_plane default": (30.0, 0.5)}


def _r2(y: np.ndarray, x: np.ndarray) -> float:
    """Share of the variance of the rows of ``y`` (E, F) explained by a per-row linear fit on ``x`` (F,)."""
    X = np.c_[np.ones_like(x), x]
    beta, *_ = np.linalg.lstsq(X, y.T, rcond=None)
    res = y.T - X @ beta
    tot = ((y.T - y.T.mean(0)) ** 2).sum()
    return float(1 - (res ** 2).sum() / tot) if tot > 0 else float("nan")


def _pipeline_error(sim, kappa_3d: dict) -> float:
    """log-RMSE of the default pipeline's kappa on ``sim``'s tracks against ``kappa_3d`` ({edge: kappa})."""
    from rce_gtsam.pipeline import analyze
    res = analyze(sim.tracks, sim.graph, preset="default", n_boot=0)
    edges = [e for e in res.kappa if e in kappa_3d]
    est = np.log(np.maximum(np.abs([res.kappa[e] for e in edges]), 1e-6))
    tru = np.log([kappa_3d[e] for e in edges])
    return float(np.sqrt(np.mean(((est - est.mean()) - (tru - tru.mean())) ** 2)))


def measure(seed: int, frames: int, tilt: float, share: float, pipeline: bool = False) -> dict:
    from rce_gtsam.sim.simulate import NoiseConfig, SimulationConfig, rank1_misfit, simulate
    from rce_gtsam.sim.three_d import Scene3D
    effects = ("out_of_plane",) if share > 0 else ()
    cfg = SimulationConfig(seed=seed, n_frames=frames, noise=NoiseConfig(enabled=False), effects=effects,
                           effect_strength={"out_of_plane": share} if share > 0 else None,
                           scene3d=Scene3D(tilt_deg=tilt))
    sim = simulate(cfg)
    t3 = sim.three_d
    ang = t3.image_turn_deg
    dev = (ang - ang[:, :1] + 180) % 360 - 180
    misfit, rms = rank1_misfit(dev)
    lr = np.log(np.abs(t3.kappa_image)) - np.log(t3.kappa_3d)
    row = {n: i for i, n in enumerate(sim.graph.nodes)}
    edges = list(sim.graph.edges)
    L = np.stack([np.linalg.norm(sim.true_xy[row[c]] - sim.true_xy[row[p]], axis=-1) for p, c in edges])
    dL = L - L[:, :1]
    rms_dL = np.sqrt(np.mean(dL ** 2, axis=1))
    tip = rms_dL[int(len(edges) * 2 / 3):]
    out = {}
    if pipeline:
        out["pipe_clean"] = _pipeline_error(sim, sim.kappa_true)
        from dataclasses import replace
        out["pipe_noisy"] = _pipeline_error(simulate(replace(cfg, noise=NoiseConfig())), sim.kappa_true)
    return out | {"unexpl": misfit ** 2 / rms ** 2, "ceil": float(np.sqrt(np.mean(lr ** 2))),
            "neg": int(np.sum(t3.kappa_image <= 0)), "dL": float(np.median(rms_dL)),
            "dL_tip": float(np.median(tip)), "p2p": float(np.median(np.ptp(dL, axis=1))),
            "R2(z_o)": _r2(dL, t3.z_o) if share > 0 else float("nan"),
            "R2(z_o^2)": _r2(dL, t3.z_o ** 2) if share > 0 else float("nan"),
            "R2(z)": _r2(dL, sim.z_true)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--frames", type=int, default=900)
    ap.add_argument("--pipeline", action="store_true", help="also run analyze() on clean and noisy tracks")
    a = ap.parse_args(argv)
    keys = ("unexpl", "ceil", "pipe_clean", "pipe_noisy", "dL", "dL_tip", "p2p", "R2(z_o)", "R2(z_o^2)", "R2(z)")
    print(f"{a.seeds} seeds x {a.frames} frames, noise-free; median [min, max] over seeds")
    for name, (tilt, share) in SCENES.items():
        rows = [measure(s, a.frames, tilt, share, a.pipeline) for s in range(a.seeds)]
        print(f"{name} (tilt {tilt:g} deg, share {share:g}); kappa_image <= 0 on {sum(r['neg'] for r in rows)} "
              f"bends in all")
        for k in keys:
            v = np.array([r.get(k, np.nan) for r in rows])
            if np.all(np.isnan(v)):
                continue
            print(f"  {k:10s} {np.median(v):8.4f}  [{v.min():.4f}, {v.max():.4f}]")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
