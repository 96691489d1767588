"""What limits kappa (issue #38): is the floor ``rce analyze`` prints the accuracy that the tracker's error allows?

:mod:`rce_gtsam.kappa_floor` simulates, on the recording's own branch and bending, what white node errors of
e px across the branch cost kappa, with e estimated from the recording's residuals. This benchmark compares that
floor with kappa's actual log-RMSE against the truth (both geometric-mean-free):

* **Simulator, white node error of known size** (``rce simulate``'s branch, 450 frames, isotropic white noise of
  e px per axis, no drift, gaps or jumps): per e, the RMS over seeds of the measured log-RMSE, of the floor with e
  estimated (what ``rce analyze`` prints) and with the true e, the median ratio measured / floor, the share of
  seeds within a factor of 1.5, and the estimated e against the true.
* **Texture bed** (real plant-2 texture warped by known motion, ``bench_texture_bed.py``; its cached videos and
  our tracker's cached tracks, 300 frames, tip 60 px, conditions none and delay): our tracks, and the true tracks
  plus white noise of our error's RMS and of 0.1 px, each with the tracker's visibility and sigma. Here the
  tracker's error is not white: the gap between the floor and the measurement is what its error costs beyond its
  size (it follows the motion).

Columns: data, cases, true e (px per axis; '-' where not white), estimated e (median), measured log-RMSE (RMS over
cases), floor (RMS over cases), median measured / floor, share of cases with measured within [floor / 1.5,
1.5 floor], and the share of segments whose angle noise exceeds their bending RMS (where the floor is optimistic:
kappa there rests mostly on the prior, and the recording cannot show how uneven the branch really is).

Usage: python benchmarks/bench_kappa_floor.py [--seeds 20] [--bed-seeds 0,1,2,3,4] [--record kappa_floor]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))


def log_rmse(est: np.ndarray, tru: np.ndarray) -> float:
    d = np.log(est) - np.log(tru)
    d = d - d.mean()
    return float(np.sqrt(np.mean(d ** 2)))


def simulator_rows(errors, seeds):
    from rce_gtsam.kappa_floor import kappa_floor_of
    from rce_gtsam.pipeline import analyze
    from rce_gtsam.sim.simulate import NoiseConfig, SimulationConfig, simulate

    rows = []
    for e in errors:
        out = []
        for seed in seeds:
            nc = NoiseConfig(sigma_across_px=e, along_ratio=1.0, tip_factor=1.0, drift_px=0.0, gap_rate=0.0,
                             jump_prob=0.0)
            sim = simulate(SimulationConfig(n_frames=450, seed=seed, noise=nc))
            r = analyze(sim.tracks, sim.graph, n_boot=0)
            tru = np.array([sim.kappa_true[tuple(ed)] for ed in r.response.edges])
            est_floor = kappa_floor_of(r)
            true_floor = kappa_floor_of(r, node_error_px=e)
            out.append((log_rmse(r.fit.kappa, tru), est_floor.log_rmse, true_floor.log_rmse,
                        est_floor.node_error_px, buried(est_floor)))
        rows.append(summary_row(f"simulator, white {e:g} px", f"{e:g}", np.array(out)))
        print(rows[-1], flush=True)
    return rows


def buried(floor) -> float:
    """Share of segments whose angle noise exceeds their bending RMS (the floor's low-signal regime)."""
    return float(np.mean(floor.angle_noise_deg > floor.bend_rms_deg))


def summary_row(label, true_e, a: np.ndarray) -> list:
    """a: (cases, 5) measured, floor (estimated e), floor (true e or NaN), estimated e, share buried."""
    ratio = a[:, 0] / a[:, 1]
    within = np.mean((ratio <= 1.5) & (ratio >= 1 / 1.5))
    rms = lambda x: float(np.sqrt(np.nanmean(x ** 2)))  # noqa: E731
    return [label, len(a), true_e, round(float(np.median(a[:, 3])), 3), round(rms(a[:, 0]), 3),
            round(rms(a[:, 1]), 3), "-" if not np.isfinite(a[:, 2]).any() else round(rms(a[:, 2]), 3),
            round(float(np.median(ratio)), 2), round(100 * float(within)), round(100 * float(np.mean(a[:, 4])))]


def bed_rows(seeds, conditions, frames=300, tip_px=60.0):
    import rce_gtsam
    from bench_texture_bed import PLANT, default_cache
    from bench_texture_errors import cached_tracks
    from rce_gtsam.kappa_floor import kappa_floor_of
    from rce_gtsam.track import LKTracker
    from rce_gtsam.tracks import Tracks

    if not (PLANT / "annotated_nodes.mp4").is_file():
        print(f"texture bed skipped: plant 2 footage not found at {PLANT}")
        return []
    rev = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                         text=True).stdout.strip() or "worktree"
    dirty = subprocess.run(["git", "-C", str(ROOT), "status", "--porcelain", "rce_gtsam/track"],
                           capture_output=True, text=True).stdout.strip()
    tag = rev + ("-dirty" if dirty else "")
    cases: dict[str, list] = {"our tracks": [], "truth + white, our error's RMS": [], "truth + white 0.1 px": []}
    for cond in conditions:
        for seed in seeds:
            bed, cf, tr = cached_tracks(seed, cond, frames, tip_px, default_cache(), LKTracker, tag)
            graph = cf.graph
            nodes = list(graph.nodes)
            vis = tr["vis"]
            sig = np.where(vis, tr["sig"], np.nan)[nodes]
            E = np.where(vis[..., None], tr["xy"] - bed.true_xy, np.nan)
            rms = float(np.sqrt(np.nanmean(E ** 2)))
            rng = np.random.default_rng([seed, len(cond)])
            ok = np.isfinite(E)
            variants = {"our tracks": (np.where(vis[..., None], tr["xy"], np.nan), np.nan),
                        "truth + white, our error's RMS": (bed.true_xy + np.where(ok, rng.standard_normal(E.shape)
                                                                                  * rms, np.nan), rms),
                        "truth + white 0.1 px": (bed.true_xy + np.where(ok, rng.standard_normal(E.shape) * 0.1,
                                                                        np.nan), 0.1)}
            for name, (xy, e) in variants.items():
                t = Tracks(node_ids=np.array(nodes), xy=xy[nodes], sigma_px=sig, source=name)
                r = rce_gtsam.analyze(t, graph, preset="default", n_boot=0, seed=0)
                tru = np.array([bed.kappa_true[ed] for ed in r.response.edges])
                est = kappa_floor_of(r)
                given = kappa_floor_of(r, node_error_px=e) if np.isfinite(e) else None
                cases[name].append((log_rmse(r.fit.kappa, tru), est.log_rmse,
                                    np.nan if given is None else given.log_rmse, est.node_error_px, buried(est)))
            print(f"  bed {'-'.join(cond) or 'none'} seed {seed} done", flush=True)
    rows = []
    for name, v in cases.items():
        a = np.array(v)
        true_e = "-" if name == "our tracks" else ("0.1" if "0.1" in name else "our RMS")
        rows.append(summary_row(f"texture bed, {name}", true_e, a))
        print(rows[-1], flush=True)
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--errors", default="0.1,0.3,0.6,1.0")
    ap.add_argument("--bed-seeds", default="0,1,2,3,4")
    ap.add_argument("--record", default=None, metavar="NAME")
    args = ap.parse_args()
    t0 = time.perf_counter()
    rows = simulator_rows([float(x) for x in args.errors.split(",")], range(args.seeds))
    conds = [(), ("delay",)]
    rows += bed_rows([int(s) for s in args.bed_seeds.split(",")] if args.bed_seeds else [], conds)
    columns = ["data", "cases", "true e (px)", "estimated e (px, median)", "measured log-RMSE (RMS)",
               "floor, estimated e (RMS)", "floor, true e (RMS)", "measured / floor (median)",
               "within x1.5 of the floor (%)", "segments whose angle noise exceeds the bending (%)"]
    print(" | ".join(columns))
    for r in rows:
        print(" | ".join(str(x) for x in r))
    print(f"{time.perf_counter() - t0:.0f} s")
    if args.record:
        from record import save_record
        save_record(args.record, title="What limits kappa: the floor a tracker error of e px sets, against kappa's "
                                       "measured error",
                    command=f"python benchmarks/bench_kappa_floor.py --seeds {args.seeds} --errors {args.errors} "
                            f"--bed-seeds {args.bed_seeds} --record {args.record}",
                    description=__doc__.split("\n\n", 1)[1].split("\nUsage:")[0].strip(),
                    columns=columns, rows=rows)


if __name__ == "__main__":
    main()
