"""Where the default tracker's gross errors on the real-texture bed come from, and what each remedy does (issue #38).

On the cases of ``bench_texture_bed.py`` (plant 2's frame 0 warped by known articulated motion, blur, noise,
H.264; ``--seeds`` x ``--conditions``, ``--frames`` frames, tip excursion ``--tip-px``; videos cached there), each
variant of the default tracker (``LKConfig`` fields) and of the smoother (``SmootherConfig.robust``) is scored
against the truth, averaged over the cases:

* error of the points marked visible (px): median, p90, RMS per axis, and the share of the squared error in
  errors > 1 px (gross errors); the median |error| / sigma (a calibrated 2-D Gaussian: 1.18);
* visible share in the fastest 30 % of frames (frames ranked by the fastest node's true speed);
* kappa (``rce_gtsam.analyze``, default preset unless the variant changes the smoother): log-RMSE against the true
  kappa, Spearman, share of true kappa inside the 95 % CI;
* speed: frames/s of the tracker on the decoded frames (one core) and of plain pyramidal LK on the same points
  (``bench_track.plain_lk``), in the same run.

Then, with and without the segment check (``LKConfig.segment_check``, off by default): the squared error in
errors > 1 px split by node (the top four) and by how each position was found (``rce_gtsam.track.lk_config.HOW``),
with each part's median sigma and median |error| / sigma over all its points. ``--record NAME`` saves the table
as docs/validation/NAME.json.

Usage: python benchmarks/bench_texture_gross.py [--seeds 0,1,2,3,4] [--conditions none,delay] [--record NAME]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

#: (label, LKConfig overrides, SmootherConfig overrides or None, tracks of which variant when the tracker is shared)
VARIANTS = [
    ("segment check (LKConfig.segment_check)", {"segment_check": True}, None),
    ("default (the tracker of revision 994f002)", {}, None),
    ("band margin 0 px", {"band_margin_px": 0.0}, None),
    ("smoother Huber k = 1.345", {}, {"robust": "huber", "robust_k": 1.345}),
    ("smoother Cauchy k = 2.385", {}, {"robust": "cauchy", "robust_k": 2.385}),
    ("segment check, smoother Cauchy k = 2.385", {"segment_check": True}, {"robust": "cauchy", "robust_k": 2.385}),
]
BASE = 1  # the variant the segment check is compared with in the breakdown


def kappa_scores(res, graph, bed, preset, n_boot: int) -> tuple[float, float, float]:
    """(log-RMSE, Spearman, share of true kappa inside the 95 % CI) of kappa from a TrackResult."""
    from scipy.stats import spearmanr

    import rce_gtsam
    from rce_gtsam.tracks import load_tracks

    with tempfile.TemporaryDirectory() as tmp:
        tracks = load_tracks(res.write_csv(Path(tmp) / "t.csv"), graph)
    r = rce_gtsam.analyze(tracks, graph, preset=preset, n_boot=n_boot, seed=0)
    est = np.array([r.kappa[e] for e in r.response.edges])
    tru = np.array([bed.kappa_true[e] for e in r.response.edges])
    inside = float(np.mean((tru >= r.ci.low) & (tru <= r.ci.high))) if r.ci is not None else float("nan")
    return float(np.sqrt(np.mean(np.log(est / tru) ** 2))), float(spearmanr(est, tru)[0]), inside


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0,1,2,3,4")
    ap.add_argument("--conditions", default="none,delay", help="comma list: none and/or effect names")
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--tip-px", type=float, default=60.0)
    ap.add_argument("--n-boot", type=int, default=100)
    ap.add_argument("--cache", type=Path, default=None)
    ap.add_argument("--record", default=None, help="save the table as docs/validation/NAME.json")
    args = ap.parse_args()
    import cv2

    cv2.setNumThreads(1)
    from bench_texture_bed import PLANT, bed_case, default_cache
    from bench_track import decode, plain_lk
    from rce_gtsam.presets import get_preset
    from rce_gtsam.track import ArraySource, LKConfig, LKTracker
    from rce_gtsam.track.lk_config import HOW

    if not (PLANT / "annotated_nodes.mp4").is_file():
        raise SystemExit(f"plant 2 footage not found at {PLANT} (set RCE_PLANT2_DIR)")
    cache = args.cache or default_cache()
    seeds = [int(s) for s in args.seeds.split(",")]
    conds = [() if c == "none" else (c,) for c in args.conditions.split(",")]
    default = get_preset("default")
    acc = {v[0]: {k: [] for k in ("err", "sig", "how", "node", "vf", "kappa", "t")} for v in VARIANTS}
    t_plain, n_frames = 0.0, 0
    for c in conds:
        for seed in seeds:
            bed, cf, path = bed_case(seed, c, args.frames, args.tip_px, cache)
            frames = decode(path)
            truth = bed.true_xy
            speed = np.zeros(truth.shape[1])
            speed[1:] = np.hypot(*np.diff(truth, axis=1).transpose(2, 0, 1)).max(axis=0)
            fast = speed >= np.quantile(speed, 0.7)
            t = time.perf_counter()
            plain_lk(frames, cf.points)
            t_plain += time.perf_counter() - t
            n_frames += len(frames)
            runs = {}
            for label, lk_kw, sm_kw in VARIANTS:
                key = tuple(sorted(lk_kw.items()))
                if key not in runs:
                    t = time.perf_counter()
                    res = LKTracker(LKConfig(**lk_kw)).track(ArraySource(frames), cf.points, cf.graph)
                    runs[key] = (res, time.perf_counter() - t)
                res, dt = runs[key]
                a = acc[label]
                vis = res.visible
                err = np.hypot(*(res.xy - truth).transpose(2, 0, 1))
                a["err"].append(err[vis])
                a["sig"].append(res.sigma_px[vis])
                a["how"].append(res.info["how"][vis])
                a["node"].append(np.broadcast_to(np.arange(len(vis))[:, None], vis.shape)[vis])
                a["vf"].append(float(vis[:, fast].mean()))
                a["t"].append(dt)
                preset = default if sm_kw is None else default.with_(smoother=sm_kw)
                a["kappa"].append(kappa_scores(res, cf.graph, bed, preset, args.n_boot))
            print(f"  done {'-'.join(c) or 'none'} seed {seed}", flush=True)
    plain_fps = n_frames / t_plain
    cols = ["variant", "error median (px)", "error p90 (px)", "error RMS (px per axis)", "squared error in > 1 px (%)",
            "median |error| / sigma", "sigma median (px)", "visible, fastest 30 % of frames (%)", "kappa log-RMSE",
            "Spearman", "truth in 95 % CI (%)", "tracker (frames/s)", "plain LK (frames/s)"]
    rows = []
    print(f"texture bed, {len(seeds)} seeds x {len(conds)} conditions, {args.frames} frames, tip {args.tip_px:g} px; "
          f"mean over cases (errors pooled)")
    for label, lk_kw, _ in VARIANTS:
        a = acc[label]
        e, s = np.concatenate(a["err"]), np.concatenate(a["sig"])
        k = np.array(a["kappa"])
        fps = n_frames / sum(a["t"])  # a smoother-only variant shares its tracker run
        gross = float(np.sum(e[e > 1] ** 2) / np.sum(e ** 2))
        row = [label, round(float(np.median(e)), 3), round(float(np.percentile(e, 90)), 3),
               round(float(np.sqrt(np.mean(e ** 2) / 2)), 3), round(100 * gross, 1),
               round(float(np.median(e / s)), 2), round(float(np.median(s)), 3),
               round(100 * float(np.mean(a["vf"])), 2),
               round(float(k[:, 0].mean()), 3), round(float(k[:, 1].mean()), 2), round(100 * float(k[:, 2].mean()), 1),
               round(fps), round(plain_fps)]
        rows.append(row)
        print("  " + "; ".join(f"{c} {v}" for c, v in zip(cols, row)))
    notes = []
    for label in (VARIANTS[0][0], VARIANTS[BASE][0]):
        a = acc[label]
        e, s = np.concatenate(a["err"]), np.concatenate(a["sig"])
        how, node = np.concatenate(a["how"]), np.concatenate(a["node"])
        gross = np.sum(e[e > 1] ** 2)
        parts = []
        for what, keys, sel in (("node", np.unique(node), node), ("how", np.unique(how), how)):
            share = {int(v): float(np.sum(np.where(sel == v, e, 0)[e > 1] ** 2) / gross) for v in keys}
            top = sorted(share, key=share.get, reverse=True)[:4]
            for v in top:
                m = sel == v
                name = f"node {v}" if what == "node" else HOW[v]
                parts.append(f"{name} {100 * share[v]:.0f} % (sigma {np.median(s[m]):.2f} px, |error|/sigma "
                             f"{np.median(e[m] / s[m]):.2f})")
        line = f"squared error in errors > 1 px, {label}: " + "; ".join(parts)
        print("  " + line)
        notes.append(line)
    if args.record:
        from record import save_record

        save_record(args.record, title="Texture bed: the default tracker's gross errors and what each remedy does",
                    command=("python benchmarks/bench_texture_gross.py --seeds " + args.seeds + " --conditions "
                             + args.conditions + f" --record {args.record}"),
                    description=__doc__.split("\n\n")[1].replace("\n", " "), columns=cols, rows=rows, notes=notes)


if __name__ == "__main__":
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    warnings.simplefilter("ignore", RuntimeWarning)
    main()
