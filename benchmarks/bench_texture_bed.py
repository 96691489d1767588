"""The built-in tracker and kappa on real texture with known motion (``rce_gtsam.sim.texture_bed``).

For each seed and condition (effect-free, and with a delay): plant 2's frame 0, overlays inpainted, warped by the
simulator's motion on plant 2's chain at the real plant's scale (tip excursion ``--tip-px``, default 60 px), with
motion blur, sensor noise, flicker and H.264; videos and truth are cached in ``--cache`` (default
/work/cache/texture, else the temp folder). Scores:

* tracker error against the truth (px): median and p90 of the points marked visible;
* visible share overall and in the fastest 30 % of frames (frames ranked by the fastest node's true speed);
* kappa (``rce_gtsam.analyze``, default preset) against the true kappa: log-RMSE, Spearman, and the share of true
  kappa inside the 95 % CI, for our tracks and for the true tracks through the same pipeline;
* the root's distance from where it is (it is fixed), and the tip's visible share and error where marked lost;
* the physical floor: the bend-angle noise sqrt(2..6) e / L (rad) a tracker error of e px gives on the median
  segment of L px, against the RMS of the bending to measure.

``--baseline REV`` also runs the default tracker (``rce_gtsam/track/lk*.py``) of that revision on the same videos (before/after).
Needs ``../shared/data/plant_2`` beside the repository.

Usage: python benchmarks/bench_texture_bed.py [--seeds 0,1,2,3,4] [--frames 300] [--baseline REV] [--n-boot 100]
"""

from __future__ import annotations

import argparse
import os
import pickle
import sys
import tempfile
import warnings
from pathlib import Path

import cv2
import numpy as np
from scipy.stats import spearmanr

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
#: plant 2's folder: ``../shared/data/plant_2`` beside the repository, or $RCE_PLANT2_DIR (a git worktree elsewhere)
PLANT = Path(os.environ.get("RCE_PLANT2_DIR", ROOT.parent / "shared" / "data" / "plant_2"))


def default_cache() -> Path:
    c = Path("/work/cache/texture")
    try:
        c.mkdir(parents=True, exist_ok=True)
        return c
    except OSError:
        return Path(tempfile.gettempdir()) / "rce_texture_bed"


def bed_case(seed: int, effects: tuple, n_frames: int, tip_px: float, cache: Path, settings=None):
    """(bed, clean frame, mp4 path), rendered once and cached. ``settings``: the bed's ``RenderSettings`` (None:
    the default; others are cached under a tag of their rigid band, ``inner_px``/``outer_px``)."""
    from rce_gtsam.sim.texture_bed import RenderSettings, clean_first_frame, make_bed, write_bed_video

    settings = settings or RenderSettings()
    tag = f"v2_s{seed}_{'-'.join(effects) or 'none'}_f{n_frames}_tip{tip_px:g}"
    if settings != RenderSettings():
        tag += f"_in{settings.inner_px:g}_out{settings.outer_px:g}"
    cache.mkdir(parents=True, exist_ok=True)
    path, meta = cache / f"{tag}.mp4", cache / f"{tag}.pkl"
    cf = clean_first_frame(PLANT)
    if meta.is_file() and path.is_file():
        bed = pickle.loads(meta.read_bytes())
    else:
        bed = make_bed(cf.points, cf.graph, n_frames, seed, effects, tip_excursion_px=tip_px)
        write_bed_video(bed, cf.rgb, cf.points, path, settings=settings)
        meta.write_bytes(pickle.dumps(bed))
    return bed, cf, path


def kappa_scores(tracks, graph, bed, n_boot: int):
    """(log-RMSE, Spearman, share of true kappa inside the CI) of kappa from ``tracks`` (a Tracks object)."""
    import rce_gtsam

    r = rce_gtsam.analyze(tracks, graph, preset="default", n_boot=n_boot, seed=0)
    est = np.array([r.kappa[e] for e in r.response.edges])
    tru = np.array([bed.kappa_true[e] for e in r.response.edges])
    lr = float(np.sqrt(np.mean(np.log(est / tru) ** 2)))
    inside = float(np.mean((tru >= r.ci.low) & (tru <= r.ci.high))) if r.ci is not None else np.nan
    return lr, float(spearmanr(est, tru)[0]), inside


def score(res, bed, graph, n_boot: int) -> dict:
    from rce_gtsam.tracks import load_tracks

    truth = bed.true_xy
    err = np.hypot(*(res.xy - truth).transpose(2, 0, 1))
    vis = res.visible
    speed = np.zeros(truth.shape[1])
    speed[1:] = np.hypot(*np.diff(truth, axis=1).transpose(2, 0, 1)).max(axis=0)
    fast = speed >= np.quantile(speed, 0.7)
    with tempfile.TemporaryDirectory() as tmp:
        tracks = load_tracks(res.write_csv(Path(tmp) / "t.csv"), graph)
    lr, rho, inside = kappa_scores(tracks, graph, bed, n_boot)
    root = graph.root
    tip = bed.edges[-1][1]
    lost_tip = ~vis[tip]
    z = (err / res.sigma_px)[vis]
    return {"median": float(np.median(err[vis])), "p90": float(np.percentile(err[vis], 90)),
            "max": float(err[vis].max()), "visible": float(vis.mean()), "visible_fast": float(vis[:, fast].mean()),
            "kappa_logrmse": lr, "kappa_rho": rho, "kappa_in_ci": inside,
            "root_median_px": float(np.median(err[root])), "tip_visible": float(vis[tip].mean()),
            "tip_err_lost": float(np.median(err[tip][lost_tip])) if lost_tip.any() else np.nan,
            "z_p90": float(np.percentile(z, 90))}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0,1,2,3,4")
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--tip-px", type=float, default=60.0)
    ap.add_argument("--n-boot", type=int, default=100, help="bootstrap resamples of each analysis")
    ap.add_argument("--conditions", default="none,delay", help="comma list: none and/or effect names")
    ap.add_argument("--baseline", default=None, help="git revision of the default tracker (rce_gtsam/track/lk*.py) to run as well")
    ap.add_argument("--cache", type=Path, default=None)
    args = ap.parse_args()
    cv2.setNumThreads(1)
    if not (PLANT / "annotated_nodes.mp4").is_file():
        raise SystemExit(f"plant 2 footage not found at {PLANT}")
    from rce_gtsam.sim.texture_bed import angle_floor_deg
    from rce_gtsam.track import LKTracker, open_video
    from rce_gtsam.tracks import Tracks

    cache = args.cache or default_cache()
    trackers = {"current": LKTracker}
    tmp = tempfile.TemporaryDirectory()
    if args.baseline:
        from bench_track import baseline_tracker
        trackers = {"baseline": baseline_tracker(args.baseline, Path(tmp.name)), **trackers}
    seeds = [int(s) for s in args.seeds.split(",")]
    conds = [() if c == "none" else (c,) for c in args.conditions.split(",")]
    rows = {(name, c): [] for name in trackers for c in conds}
    truth_rows = {c: [] for c in conds}
    floor = []
    print(f"texture bed: plant 2 frame 0 inpainted, {args.frames} frames, tip excursion {args.tip_px:g} px, "
          f"seeds {seeds}, H.264; kappa: default preset, n_boot {args.n_boot}; cache {cache}")
    hdr = (f"  {'tracker':8s} {'cond':6s} {'seed':>4s} {'med':>5s} {'p90':>5s} {'max':>5s} {'vis':>5s} {'visfast':>7s} "
           f"{'logRMSE':>7s} {'rho':>5s} {'inCI':>5s} {'root':>5s} {'tipvis':>6s} {'tiplost':>7s} {'z90':>5s}")
    print(hdr)
    for c in conds:
        for seed in seeds:
            bed, cf, path = bed_case(seed, c, args.frames, args.tip_px, cache)
            graph = cf.graph
            nodes = list(graph.nodes)
            true_tr = Tracks(node_ids=np.array(nodes), xy=bed.true_xy[nodes], source="truth")
            truth_rows[c].append(kappa_scores(true_tr, graph, bed, args.n_boot))
            for name, cls in trackers.items():
                with open_video(path) as src:
                    res = cls().track(src, cf.points, graph)
                s = score(res, bed, graph, args.n_boot)
                rows[(name, c)].append(s)
                print(f"  {name:8s} {'-'.join(c) or 'none':6s} {seed:4d} {s['median']:5.2f} {s['p90']:5.2f} "
                      f"{s['max']:5.1f} {s['visible']:5.3f} {s['visible_fast']:7.3f} {s['kappa_logrmse']:7.2f} "
                      f"{s['kappa_rho']:5.2f} {s['kappa_in_ci']:5.2f} {s['root_median_px']:5.2f} "
                      f"{s['tip_visible']:6.2f} {s['tip_err_lost']:7.2f} {s['z_p90']:5.1f}", flush=True)
            L = np.array([np.hypot(*(cf.points[ch] - cf.points[p])) for p, ch in bed.edges])
            floor.append((np.median(L), float(np.sqrt(np.mean(bed.response_deg ** 2)))))
    print("summary (mean over seeds):")
    for (name, c), rs in rows.items():
        with warnings.catch_warnings():  # a tip never marked lost has no error-where-lost (NaN in every seed)
            warnings.simplefilter("ignore", RuntimeWarning)
            m = {k: np.nanmean([r[k] for r in rs]) for k in rs[0]}
        print(f"  {name:8s} {'-'.join(c) or 'none':6s}: error median {m['median']:.2f} / p90 {m['p90']:.2f} px; "
              f"visible {100 * m['visible']:.1f} %, fastest 30 % {100 * m['visible_fast']:.1f} %; kappa log-RMSE "
              f"{m['kappa_logrmse']:.2f}, Spearman {m['kappa_rho']:.2f}, truth in CI {100 * m['kappa_in_ci']:.0f} %; "
              f"root {m['root_median_px']:.2f} px; tip visible {100 * m['tip_visible']:.0f} %")
    for c, rs in truth_rows.items():
        a = np.array(rs)
        print(f"  true tracks {'-'.join(c) or 'none':6s}: kappa log-RMSE {a[:, 0].mean():.2f}, Spearman "
              f"{a[:, 1].mean():.2f}, truth in CI {100 * a[:, 2].mean():.0f} %")
    L, bend = np.median([f[0] for f in floor]), np.mean([f[1] for f in floor])
    for name in trackers:
        e = float(np.mean([r["median"] for c in conds for r in rows[(name, c)]]))  # median error, px
        lo, hi = angle_floor_deg(e, L)
        print(f"  physical floor ({name}): error e = {e:.2f} px on the median segment L = {L:.1f} px gives "
              f"{lo:.2f}-{hi:.2f} deg of angle noise against a bending RMS of {bend:.2f} deg "
              f"(noise/signal {lo / bend:.2f}-{hi / bend:.2f})")
    tmp.cleanup()


if __name__ == "__main__":
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    main()
