"""kappa from depth against kappa from the 2-D image, on simulated out-of-plane recordings (issue #39).

Per seed: ``rce simulate --effect out_of_plane --depth`` (default share 0.5, tilt 30 deg), then as a user would
``rce run recording.db3 ...`` (the RealSense recording: tracks the colour stream, reads the depth, reports
kappa_3d and, beside it, the 2-D kappa of the same tracks) and ``rce run video.mp4 ...`` (the 2-D pipeline on the
H.264 video). Scored: kappa log-RMSE (geometric-mean-free) against truth.json's ``kappa_true_3d``, for

* ``2d_video``: compliance_summary.csv of the mp4 run; ``2d_rec``: kappa_2d of the recording run;
* ``3d``: kappa_3d of the recording run (the code's default depth smoothing); ``3d_in``: its in-plane-only fit;
* ``3d@F``: kappa_3d re-fitted from the recording run's tracks.csv with the depth axis' acceleration factor F
  (``smooth_tracks_3d(z_accel_factor=F)``; ``cv`` = chosen by held-out depth);
* ``ceiling``: kappa_true_image (a perfect 2-D tracker) against kappa_true_3d.

Timings: the 3-D smoother's and the 2-D smoother's seconds on the same recording (depth3d.json).

Usage: OMP_NUM_THREADS=1 python benchmarks/bench_depth3d.py --seeds 20 --frames 300 [--factors cv,1,0.5,0.25]
       [--no-video2d] [--out bench_depth3d.json] [--cache DIR [--rerun-3d]] [--oracles | --oracles-only]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from depth3d_oracles import log_rmse  # noqa: E402


def rce(*args, cwd) -> None:
    env = dict(os.environ, PYTHONPATH=str(ROOT), OMP_NUM_THREADS="1")
    r = subprocess.run([sys.executable, "-m", "rce_gtsam.cli", *args], cwd=cwd, env=env, capture_output=True, text=True)
    if r.returncode not in (0, 3):  # 3 = quality flags, outputs written
        raise RuntimeError(f"rce {' '.join(args)} exited {r.returncode}: {r.stderr[-2000:]}")


def refit(d: Path, factors, stretch=()) -> dict:
    """kappa_3d re-fitted from the recording run's tracks.csv (its depths too) with each depth-axis factor in
    ``factors`` (key ``3d@F``) and each inextensibility sigma share in ``stretch`` ("off" = no factor; key
    ``3d+len@S``, the depth factor by cross-validation); also ``smooth_3d_s@...``, the smoother's seconds."""
    from rce_gtsam.camera import CameraIntrinsics
    from rce_gtsam.graph import load_graph
    from rce_gtsam.pipeline import analyze
    from rce_gtsam.presets import get_preset
    from rce_gtsam.smoothing.smoother3d import smooth_tracks_3d
    from rce_gtsam.track.depth_tracks import read_depth_columns
    from rce_gtsam.tracks import load_tracks, lost_nodes
    from depth3d_oracles import kappa_from_xyz, kappa_in_plane_backprojected

    truth = json.loads((d / "truth.json").read_text())
    g = load_graph(d / "graph.json")
    tr = load_tracks(d / "run3d" / "tracks.csv", g)
    pre = get_preset("default").with_(compliance={"n_boot": 0})
    res = analyze(tr, g, pre)
    z, zs = read_depth_columns(d / "run3d" / "tracks.csv", tr)
    cam = CameraIntrinsics.coerce(truth["three_d"]["camera"])
    order = {n: i for i, n in enumerate(truth["three_d"]["node_order"])}
    P = np.asarray(truth["positions_mm"], float).transpose(1, 0, 2)[[order[int(n)] for n in tr.node_ids]]
    z_exact = np.where(np.isfinite(z), np.round(P[..., 2]), np.nan)  # the run's tracks with the true depth
    runs = [(f"3d@{fac}", {"z_accel_factor": fac}) for fac in factors]
    runs += [(f"3d+len@{s}", {"stretch_rel": None if s == "off" else float(s)}) for s in stretch]
    runs += [("3d z-exact", {"z": (z_exact, np.full(z.shape, 1 / np.sqrt(12)))})]
    e = np.linalg.norm(tr.xy - cam.project(P), axis=2)
    e = e[np.isfinite(e)]
    zerr = (z - P[..., 2])[np.isfinite(z)]
    out = {"px_err_median": float(np.median(e)), "px_err_rms": float(np.sqrt(np.mean(e ** 2))),
           "px_gross_pct": float(100 * np.mean(e > 1.0)), "z_err_median": float(np.median(zerr)),
           "z_err_mad": float(1.4826 * np.median(np.abs(zerr - np.median(zerr)))),
           "z_sigma_median": float(np.nanmedian(zs))}
    for key, kw in runs:
        z_, zs_ = kw.pop("z", (z, zs))
        sm = smooth_tracks_3d(tr.xy, tr.sigma_px, z_, zs_, tr.node_ids, g, cam, pre.smoother, **kw)
        k3 = kappa_from_xyz(sm.xyz_mm, tr.node_ids, g, res.geometry, pre, sm.frame_cov, sm.observed,
                            skip_nodes=lost_nodes(tr))
        out[key] = log_rmse(k3, truth["kappa_true_3d"])
        out["smooth_3d_s" + key[2:]] = sm.report.seconds_total
        if kw.get("z_accel_factor") == "cv":
            out["cv_factor"] = sm.report.z_accel_factor
        if key == "3d+len@off":  # the in-plane bends from the pixels on the branch plane
            kb = kappa_in_plane_backprojected(sm.xyz_mm, cam, tr.node_ids, g, res.geometry, pre, sm.observed)
            out["3d bp_in"] = log_rmse(kb, truth["kappa_true_3d"])
    return out


def one_seed(seed: int, frames: int, work: Path, factors, video2d: bool, keep: bool = False,
             rerun: bool = True, stretch=()) -> dict:
    import pandas as pd
    d = work / f"s{seed}"
    if not (d / "truth.json").exists():  # a cached recording (--cache) is rendered once
        rce("simulate", "--out", str(d), "--effect", "out_of_plane", "--depth", "--frames", str(frames),
            "--seed", str(seed), cwd=work)
    truth = json.loads((d / "truth.json").read_text())
    t0 = time.perf_counter()
    if rerun or not (d / "run3d" / "depth3d.json").exists():
        rce("run", "recording.db3", "annotations.json", "graph.json", "--out", "run3d", "--no-figures",
            "--bootstrap", "100", "--no-progress", "--seed", "0", cwd=d)
    row = {"seed": seed, "seconds_run3d": time.perf_counter() - t0}
    k3 = pd.read_csv(d / "run3d" / "kappa_3d.csv")
    rep = json.loads((d / "run3d" / "depth3d.json").read_text())
    kt = truth["kappa_true_3d"]
    row["3d"] = log_rmse(dict(zip(k3.edge, k3.kappa_3d)), kt)
    row["3d_in"] = log_rmse(dict(zip(k3.edge, k3.kappa_in_plane)), kt)
    row["2d_rec"] = log_rmse(dict(zip(k3.edge, k3.kappa_2d)), kt)
    row["ceiling"] = log_rmse(truth["kappa_true_image"], kt)
    row["smooth_3d_s"] = rep["timings_s"]["smooth_3d"]
    row["smooth_2d_s"] = rep["timings_s"]["smooth_2d"]
    row["depth_coverage"] = rep["depth_coverage"]
    if video2d and not (d / "run2d" / "compliance_summary.csv").exists():
        rce("run", "video.mp4", "annotations.json", "graph.json", "--out", "run2d", "--no-figures",
            "--bootstrap", "100", "--no-progress", "--seed", "0", cwd=d)
    if video2d:
        cs = pd.read_csv(d / "run2d" / "compliance_summary.csv")
        row["2d_video"] = log_rmse({f"{p}->{c}": k for p, c, k in zip(cs.parent, cs.child, cs.kappa)}, kt)
    if not keep:
        (d / "recording.db3").unlink(missing_ok=True)  # ~0.7 MB per frame
    if factors or stretch:
        row.update(refit(d, factors, stretch))  # (and 3d z-exact: the run's tracks with the true depth)
    return row


def summarize(rows: list[dict], frames: int, what: str) -> list[dict]:
    """Print the median and mean of every column over the seeds without an error; returns those rows."""
    ok = [r for r in rows if "error" not in r]
    if ok:
        keys = [k for k in ok[0] if k not in ("seed", "cv_factor")]
        print(f"\n{what}: {len(ok)} of {len(rows)} seeds, {frames} frames; median (and mean) over seeds:")
        for k in keys:
            v = np.array([r[k] for r in ok if k in r], float)
            print(f"  {k:>14}: median {np.median(v):.3f}  mean {np.mean(v):.3f}")
    return ok


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--factors", default="cv,1,0.5,0.25")
    ap.add_argument("--stretch", default="",
                    help="re-fit with these inextensibility sigma shares, e.g. off,0.01 "
                         "(smooth_tracks_3d(stretch_rel)); also the run's tracks with the true depth")
    ap.add_argument("--no-video2d", action="store_true")
    ap.add_argument("--out", type=Path, default=Path("bench_depth3d.json"))
    ap.add_argument("--oracles", action="store_true",
                    help="also the oracle rows (benchmarks/depth3d_oracles.py: true 3-D; true pixels + simulated "
                         "depth noise; tracker-noise pixels + depth noise) per seed, without rendering")
    ap.add_argument("--oracle-rows", type=Path, default=None,
                    help="with --record: take the oracle rows from this file (an earlier --oracles-only run's)")
    ap.add_argument("--reuse-rows", type=Path, nargs="*", default=[],
                    help="take the rows of these seeds from earlier --out files instead of measuring them again")
    ap.add_argument("--oracles-only", action="store_true", help="only the oracle rows (fast: no video)")
    ap.add_argument("--oracle-seeds", type=int, default=None, help="seeds of the oracle rows (default --seeds)")
    ap.add_argument("--record", action="store_true",
                    help="write docs/validation/depth3d.json and benchmarks/results/depth3d_*.json")
    ap.add_argument("--cache", type=Path, default=None,
                    help="keep each seed's recording and runs here (outside git) and reuse them on the next call")
    ap.add_argument("--rerun-3d", action="store_true",
                    help="with --cache: run `rce run recording.db3` again (after a change to the 3-D code)")
    args = ap.parse_args(argv)
    factors = [f if f == "cv" else float(f) for f in args.factors.split(",") if f]
    cache = args.cache
    if cache is not None:
        cache.mkdir(parents=True, exist_ok=True)
    work = cache if cache is not None else Path(tempfile.mkdtemp(prefix="bench_depth3d_"))
    rows, orows = [], []
    if args.oracles or args.oracles_only:
        from depth3d_oracles import oracles
        from rce_gtsam.smoothing.smoother3d import STRETCH_REL
        n_or = args.seeds if args.oracle_seeds is None else args.oracle_seeds
        for s in range(args.first_seed, args.first_seed + n_or):
            orows.append(oracles(s, args.frames, {"": {}, "+len": {"stretch_rel": STRETCH_REL}}))
            print(json.dumps(orows[-1]), flush=True)
        summarize(orows, args.frames, "oracles (no video)")
        args.out.with_name(args.out.stem + "_oracles.json").write_text(json.dumps(orows, indent=1) + "\n")
        if args.oracles_only:
            return 0
    reuse = {r["seed"]: r for f in args.reuse_rows for r in json.loads(f.read_text()) if "error" not in r}
    try:
        for s in range(args.first_seed, args.first_seed + args.seeds):
            if s in reuse:
                rows.append(reuse[s])
                continue
            try:
                rows.append(one_seed(s, args.frames, work, factors, not args.no_video2d, keep=cache is not None,
                                     rerun=cache is None or args.rerun_3d,
                                     stretch=[v for v in args.stretch.split(",") if v]))
            except Exception as exc:  # noqa: BLE001 - a failed seed is reported, the others go on
                rows.append({"seed": s, "error": str(exc)[-500:]})
            print(json.dumps(rows[-1]), flush=True)
            args.out.write_text(json.dumps(rows, indent=1) + "\n")
            if cache is None:
                shutil.rmtree(work / f"s{s}", ignore_errors=True)
    finally:
        if cache is None:
            shutil.rmtree(work, ignore_errors=True)
    ok = summarize(rows, args.frames, "rendered recordings")
    if ok:
        if "2d_video" in ok[0]:
            ratio = np.array([r["3d"] / r["2d_video"] for r in ok])
            print(f"  3d / 2d_video: median {np.median(ratio):.2f}; 3d <= 0.5 x 2d_video in {np.sum(ratio <= 0.5)} of {len(ok)}")
    if args.record:
        from depth3d_record import write
        if args.oracle_rows is not None:
            orows = json.loads(args.oracle_rows.read_text())
            from depth3d_oracles import px0_2d, simulate_seed
            for r in orows:  # rows from before the px0 2-D oracle existed
                if "px0 2d" not in r and "error" not in r:
                    r["px0 2d"] = px0_2d(simulate_seed(r["seed"], args.frames))
        cmd = (f"python benchmarks/bench_depth3d.py --seeds {args.seeds} --frames {args.frames} "
               f"--factors '{args.factors}' --stretch {args.stretch or 'off'} --oracles --cache DIR --record"
               "  (with OMP_NUM_THREADS=1; DIR outside git keeps the rendered recordings; 20 seeds take ~1 h on "
               "2 cores)")
        print("record:", write(ok, [r for r in orows if "error" not in r], args.frames, cmd))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
