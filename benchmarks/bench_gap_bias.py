"""Kappa's bias from the tracker's lost frames and sigmas, with exact positions (issue #38): mechanism and fix.

Two beds, each with three variants of the default preset in the same run (:data:`MODES`): before (the smoother's
``sigma_mode="per_observation"``, each bend's own median as its rest), the smoother's ``sigma_mode="uniform"``
(:mod:`rce_gtsam.smoothing.uniform_sigma`), and that plus ``bending.rest="common_median"``
(:func:`rce_gtsam.bending.angles.common_frames`):

* texture bed (``bench_texture_bed.py``'s cached videos and truth, the default tracker's cached tracks
  ``tracks_<--tracks-rev>_*.npz``): the TRUE positions with (a) all frames visible and the tracker's sigma (lost
  frames' sigma: the node's median), (b) the tracker's visibility and one sigma (the recording's median), (c) both,
  i.e. the texture record's "none" row; and the tracker's own positions ("truth + E");
* simulator (``rce_gtsam.sim``, tracks with per-node sigma, ``emit_sigma``): exact positions (the true ones on the
  noisy tracks' visibility) and the simulated tracks, with no artifact and with ``gust_occlusion`` (nodes lost when
  fast: missing not at random) at 1x and 2x its measured strength.

Scores per row: kappa log-RMSE against the true kappa (mean and min-max over cases), Spearman, and the share of
segments whose true kappa is inside the 95 % CI (bootstrap: the preset's ``n_boot`` unless ``--n-boot``).
``--record NAME`` saves docs/validation/NAME.json.

``--split SEEDS`` instead splits the simulated gust losses' bias (exact positions) by the pipeline step that causes
it (:func:`split_gust_mechanisms`).

Usage: python benchmarks/bench_gap_bias.py [--seeds 0,1,2,3,4] [--sim-seeds 20] [--tracks-rev cc40a21]
       [--n-boot N] [--record NAME] [--split SEEDS]
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

#: the variants compared: (smoother.sigma_mode, bending.rest) on the default preset
MODES = {"before (per-observation sigma, own median rest)": ("per_observation", "median"),
         "uniform sigma": ("uniform", "median"),
         "uniform sigma + common-median rest": ("uniform", "common_median")}


def scores(tracks, graph, kappa_true: dict, mode: str, n_boot: int | None) -> tuple[float, float, float]:
    """(log-RMSE, Spearman, share of true kappa inside the 95 % CI) of the default preset in variant ``mode``."""
    from scipy.stats import spearmanr

    import rce_gtsam
    from rce_gtsam.presets import get_preset

    sigma_mode, rest = MODES[mode]
    pre = get_preset("default").with_(smoother={"sigma_mode": sigma_mode}, bending={"rest": rest})
    r = rce_gtsam.analyze(tracks, graph, preset=pre, n_boot=n_boot, seed=0)
    est = np.array([r.kappa[e] for e in r.response.edges])
    tru = np.array([kappa_true[e] for e in r.response.edges])
    return (float(np.sqrt(np.mean(np.log(est / tru) ** 2))), float(spearmanr(est, tru)[0]),
            float(np.mean((tru >= r.ci.low) & (tru <= r.ci.high))))


NOTES: list[str] = []  # measured context for the record: the share of points each bed loses


def bed_rows(seeds, cache: Path, rev: str, n_boot) -> dict:
    """{row name: [(log-RMSE, Spearman, inside), ...] per case} on the texture bed."""
    from bench_texture_bed import bed_case
    from rce_gtsam.tracks import Tracks

    out: dict[str, list] = {}
    lost = []
    for cond in ((), ("delay",)):
        for seed in seeds:
            bed, cf, path = bed_case(seed, cond, 300, 60.0, cache)
            npz = cache / f"tracks_{rev}_{path.stem}.npz"
            if not npz.is_file():
                raise SystemExit(f"{npz}: no cached tracks of revision {rev}; run bench_texture_errors.py first")
            d = np.load(npz)
            graph = cf.graph
            nodes = list(graph.nodes)
            vis = d["vis"][nodes]
            sig = np.where(vis, d["sig"][nodes], np.nan)
            node_med = np.nanmedian(sig, axis=1, keepdims=True)
            true = bed.true_xy[nodes]
            cases = {"bed: true positions, all visible, tracker's sigma": (true, np.where(vis, sig, node_med)),
                     "bed: true positions, tracker's visibility, one sigma":
                         (np.where(vis[..., None], true, np.nan), np.where(vis, np.nanmedian(sig), np.nan)),
                     "bed: true positions, tracker's visibility and sigma (texture 'none')":
                         (np.where(vis[..., None], true, np.nan), sig),
                     "bed: our tracks (texture 'truth + E')": (np.where(vis[..., None], d["xy"][nodes], np.nan), sig)}
            for name, (xy, s) in cases.items():
                t = Tracks(node_ids=np.array(nodes), xy=xy, sigma_px=s, source=name)
                for mode in MODES:
                    out.setdefault((name, mode), []).append(scores(t, graph, bed.kappa_true, mode, n_boot))
            lost.append(100 * (1 - vis.mean()))
            print(f"  bed {'-'.join(cond) or 'none'} seed {seed}: lost {lost[-1]:.2f} % of points", flush=True)
    NOTES.append(f"texture bed: the tracker lost {min(lost):.2f}-{max(lost):.2f} % of the points per case")
    return out


def sim_rows(n_seeds: int, frames: int, n_boot) -> dict:
    """{row name: [(log-RMSE, Spearman, inside), ...] per seed} on the simulator."""
    from rce_gtsam.sim.artifacts import ArtifactConfig
    from rce_gtsam.sim.simulate import NoiseConfig, SimulationConfig, simulate
    from rce_gtsam.tracks import Tracks

    out: dict[str, list] = {}
    lost: dict[str, list] = {}
    for label, art in (("no artifact", ArtifactConfig()),
                       ("gust_occlusion 1x", ArtifactConfig(families=("gust_occlusion",), scale=1.0)),
                       ("gust_occlusion 2x", ArtifactConfig(families=("gust_occlusion",), scale=2.0))):
        for seed in range(n_seeds):
            sim = simulate(SimulationConfig(seed=seed, n_frames=frames, artifacts=art,
                                            noise=NoiseConfig(emit_sigma=True)))
            tr = sim.tracks
            obs = tr.observed
            lost.setdefault(label, []).append(1 - obs.mean())
            exact = Tracks(node_ids=tr.node_ids, xy=np.where(obs[..., None], sim.true_xy, np.nan),
                           sigma_px=tr.sigma_px, source="exact")
            for kind, t in ((f"sim {label}: exact positions", exact), (f"sim {label}: simulated tracks", tr)):
                for mode in MODES:
                    out.setdefault((kind, mode), []).append(scores(t, sim.graph, sim.kappa_true, mode, n_boot))
        NOTES.append(f"sim {label}: {100 * np.mean(lost[label]):.1f} % of the points lost ({n_seeds} seeds)")
        print("  " + NOTES[-1], flush=True)
    return out


def split_gust_mechanisms(n_seeds: int, frames: int) -> None:
    """Print kappa's log-RMSE from exact positions under simulated gust losses (1x, 2x) with the pipeline's steps
    that can bias it switched off one at a time: the smoother's prior (acceleration weight 1e-3: the observations
    stand), the per-bend outlier mask (MAD threshold 1e9) and each bend's own rest (the common-frame median with no
    minimum share). All three off must give ~0 (exact rank-1 data); which one's return costs what says where the
    bias comes from."""
    import rce_gtsam.bending.angles as angles
    from rce_gtsam.presets import get_preset
    from rce_gtsam.sim.artifacts import ArtifactConfig
    from rce_gtsam.sim.simulate import NoiseConfig, SimulationConfig, simulate
    from rce_gtsam.tracks import Tracks

    d = get_preset("default")
    flat, nomad, common = {"acceleration_weight": 1e-3}, {"mad_threshold": 1e9}, {"rest": "common_median"}
    variants = {"default": d, "all three off": d.with_(smoother=flat, bending={**nomad, **common}),
                "smoother back": d.with_(bending={**nomad, **common}), "MAD mask back": d.with_(smoother=flat, bending=common),
                "own rest back": d.with_(smoother=flat, bending=nomad)}
    share, angles.MIN_COMMON_SHARE = angles.MIN_COMMON_SHARE, 0.0
    try:
        for scale in (1.0, 2.0):
            res: dict[str, list] = {}
            for seed in range(n_seeds):
                sim = simulate(SimulationConfig(seed=seed, n_frames=frames, noise=NoiseConfig(emit_sigma=True),
                                                artifacts=ArtifactConfig(families=("gust_occlusion",), scale=scale)))
                obs = sim.tracks.observed
                t = Tracks(node_ids=sim.tracks.node_ids, xy=np.where(obs[..., None], sim.true_xy, np.nan),
                           sigma_px=sim.tracks.sigma_px, source="exact")
                for name, p in variants.items():
                    res.setdefault(name, []).append(scores_point(t, sim.graph, sim.kappa_true, p))
            print(f"  gust_occlusion {scale:g}x, exact positions, {n_seeds} seeds, kappa log-RMSE: "
                  + "; ".join(f"{k} {np.mean(v):.3f}" for k, v in res.items()), flush=True)
    finally:
        angles.MIN_COMMON_SHARE = share


def scores_point(tracks, graph, kappa_true: dict, preset) -> float:
    """kappa's log-RMSE against the truth (no bootstrap)."""
    import rce_gtsam

    r = rce_gtsam.analyze(tracks, graph, preset=preset, n_boot=0)
    est = np.array([r.kappa[e] for e in r.response.edges])
    tru = np.array([kappa_true[e] for e in r.response.edges])
    return float(np.sqrt(np.mean(np.log(est / tru) ** 2)))


def main() -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0,1,2,3,4", help="texture-bed seeds (each with conditions none and delay)")
    ap.add_argument("--sim-seeds", type=int, default=20)
    ap.add_argument("--sim-frames", type=int, default=450)
    ap.add_argument("--tracks-rev", default="cc40a21",
                    help="revision tag of the cached default-tracker tracks (the tracker is unchanged since)")
    ap.add_argument("--n-boot", type=int, default=None, help="bootstrap resamples (default: the preset's)")
    ap.add_argument("--cache", type=Path, default=None)
    ap.add_argument("--no-bed", action="store_true", help="simulator only (no plant 2 footage needed)")
    ap.add_argument("--record", default=None, metavar="NAME")
    ap.add_argument("--split", type=int, default=0, metavar="SEEDS",
                    help="only split the simulated gust losses' bias by pipeline step on this many seeds, and exit")
    args = ap.parse_args()
    if args.split:
        split_gust_mechanisms(args.split, args.sim_frames)
        return {}
    table: dict = {}
    if not args.no_bed:
        from bench_texture_bed import PLANT, default_cache
        if not (PLANT / "annotated_nodes.mp4").is_file():
            raise SystemExit(f"plant 2 footage not found at {PLANT}")
        table.update(bed_rows([int(s) for s in args.seeds.split(",")], args.cache or default_cache(),
                              args.tracks_rev, args.n_boot))
    if args.sim_seeds > 0:
        table.update(sim_rows(args.sim_seeds, args.sim_frames, args.n_boot))
    rows = []
    print(f"  {'case':72s} {'variant':50s} {'logRMSE (min-max)':>19s} {'Spearman':>8s} {'inCI %':>6s}")
    for (name, mode), v in table.items():
        a = np.array(v)
        print(f"  {name:72s} {mode:50s} {a[:, 0].mean():6.3f} ({a[:, 0].min():.2f}-{a[:, 0].max():.2f}) "
              f"{a[:, 1].mean():8.2f} {100 * a[:, 2].mean():6.1f}")
        rows.append([name, mode, len(v), round(a[:, 0].mean(), 3), round(a[:, 0].min(), 3), round(a[:, 0].max(), 3),
                     round(a[:, 1].mean(), 2), round(100 * a[:, 2].mean(), 1)])
    if args.record:
        from record import save_record
        save_record(args.record, title="Kappa's bias from the tracker's lost frames and sigmas, with exact positions "
                                       "(issue #38): before/after",
                    command="python benchmarks/bench_gap_bias.py --seeds " + args.seeds
                            + f" --sim-seeds {args.sim_seeds} --tracks-rev {args.tracks_rev}"
                            + (f" --n-boot {args.n_boot}" if args.n_boot is not None else "")
                            + f" --record {args.record}",
                    description=" ".join(__doc__.split("\n\n")[1:4]).replace("\n", " "), notes=NOTES,
                    columns=["case", "variant", "cases", "kappa log-RMSE (mean)", "min", "max",
                             "Spearman", "truth in 95 % CI (%)"], rows=rows)
    return table


if __name__ == "__main__":
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    main()
