"""Is the default tracker's sigma honest? Its reported 1-sigma against its actual error, on real texture and on
the simulator's renders (issue #38, step 2).

Sources: the texture bed (``bench_texture_bed.py``: plant 2's real texture, known motion, H.264; seeds x
effect-free/delay, 300 frames) and the simulator's clean renders (``bench_track.py``'s clips, as ``rce simulate
--video`` writes them). For the matches anchored to frame 0 (``HOW`` 0: the ordinary matches, 90 %+ of all), the
ratio z = |error| / sigma_px (px / px) is summarised by its median, 90th and 99th percentiles; a calibrated
isotropic 2-D Gaussian error gives 1.18 / 2.15 / 3.03 (Rayleigh). Also: the share of the squared error that
lies in errors over 1 px, and the RMS error per axis. ``--baseline REV`` runs that revision's tracker too.

Usage: python benchmarks/bench_texture_sigma.py [--seeds 0,1,2,3,4] [--clips 0:600,1:400,2:600,3:600,4:600]
       [--baseline REV] [--record NAME]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
RAYLEIGH = (1.1774, 2.1460, 3.0349)  # median, p90, p99 of |e| / sigma for a 2-D Gaussian of sigma per axis


def z_stats(err: np.ndarray, sig: np.ndarray) -> dict:
    """Summary of error vectors ``err`` (n, 2) px against sigmas ``sig`` (n,) px."""
    e = np.hypot(err[:, 0], err[:, 1])
    z = e / sig
    return {"n": int(len(z)), "z50": float(np.median(z)), "z90": float(np.percentile(z, 90)),
            "z99": float(np.percentile(z, 99)), "sig50": float(np.median(sig)),
            "rms": float(np.sqrt(np.mean(err ** 2))), "tail": float(np.sum(e[e > 1] ** 2) / max(np.sum(e ** 2), 1e-12))}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0,1,2,3,4")
    ap.add_argument("--conditions", default="none,delay")
    ap.add_argument("--clips", default="0:600,1:400,2:600,3:600,4:600")
    ap.add_argument("--baseline", default=None)
    ap.add_argument("--cache", type=Path, default=None)
    ap.add_argument("--record", default=None, metavar="NAME")
    args = ap.parse_args()
    import cv2

    from bench_texture_bed import PLANT, bed_case, default_cache
    from bench_track import baseline_tracker, clip
    from rce_gtsam.track import LKTracker, open_video

    cv2.setNumThreads(1)
    if not (PLANT / "annotated_nodes.mp4").is_file():
        raise SystemExit(f"plant 2 footage not found at {PLANT}")
    cache = args.cache or default_cache()
    tmp = tempfile.TemporaryDirectory()
    trackers = {"current": LKTracker}
    if args.baseline:
        trackers = {"baseline": baseline_tracker(args.baseline, Path(tmp.name)), **trackers}
    acc = {(name, src): ([], []) for name in trackers for src in ("texture bed", "simulator renders")}

    def add(name, src, res, truth):
        m = res.visible & (np.asarray(res.info["how"]) == 0)
        acc[(name, src)][0].append((res.xy - truth)[m])
        acc[(name, src)][1].append(res.sigma_px[m])

    for c in args.conditions.split(","):
        for seed in (int(s) for s in args.seeds.split(",")):
            bed, cf, path = bed_case(seed, () if c == "none" else (c,), 300, 60.0, cache)
            for name, cls in trackers.items():
                with open_video(path) as s:
                    add(name, "texture bed", cls().track(s, cf.points, cf.graph), bed.true_xy)
    clip_dir = Path(tempfile.gettempdir()) / "rce_track_clips"
    clip_dir.mkdir(exist_ok=True)
    for item in args.clips.split(","):
        seed, n = (int(v) for v in item.split(":"))
        sim, path, truth = clip(seed, n, clip_dir)
        for name, cls in trackers.items():
            with open_video(path) as s:
                add(name, "simulator renders", cls().track(s, truth[:, 0], sim.graph), truth)
    print("anchored matches: z = |error| / sigma (calibrated 2-D Gaussian: median 1.18, p90 2.15, p99 3.03)")
    rows = []
    for (name, src), (errs, sigs) in acc.items():
        s = z_stats(np.concatenate(errs), np.concatenate(sigs))
        print(f"  {name:8s} {src:18s} n {s['n']:6d}: z median {s['z50']:.2f}, p90 {s['z90']:.2f}, p99 {s['z99']:.1f}; "
              f"sigma median {s['sig50']:.3f} px; error RMS {s['rms']:.3f} px/axis, {100 * s['tail']:.0f} % of it "
              f"in errors > 1 px")
        rows.append([name, src, s["n"], round(s["z50"], 2), round(s["z90"], 2), round(s["z99"], 1),
                     round(s["sig50"], 3), round(s["rms"], 3), round(100 * s["tail"], 0)])
    rows.append(["calibrated 2-D Gaussian", "", "", *[round(v, 2) for v in RAYLEIGH], "", "", ""])
    if args.record:
        from record import save_record
        save_record(args.record, title="Default tracker: reported sigma against actual error",
                    command="python benchmarks/bench_texture_sigma.py"
                            + (f" --baseline {args.baseline}" if args.baseline else "") + f" --record {args.record}",
                    description=__doc__.split("\n\n")[1].replace("\n", " "),
                    columns=["tracker", "source", "matches", "z median", "z p90", "z p99", "sigma median (px)",
                             "error RMS (px per axis)", "share of squared error in errors > 1 px (%)"], rows=rows)
    tmp.cleanup()


if __name__ == "__main__":
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    main()
