"""Tracker accuracy under camera nuisances: clean render vs each nuisance alone vs all together.

For each seed, the simulator's branch is rendered (H.264) once per condition -- ``clean``; ``blur``
(180-degree shutter, exposure 0.5); ``gain`` (global gain/offset drift, gain_sd 0.12, offset_sd 4 grey
levels); ``shadow`` (a soft penumbra, 30 % darker, drifting over the branch); ``shake`` (1 px RMS camera
translation); ``crf28`` (stronger compression); ``outdoor`` (all of them: the ``REALISM["outdoor"]``
preset) -- and tracked with the default tracker (``LKTracker()``) and, as the same-run baseline, plain
frame-to-frame pyramidal LK (21x21 window, 3 levels; a point counts as visible while OpenCV's status is 1).

Errors are against the node positions in the image (``nuisance.image_xy``: true positions plus the camera
shift). Per condition, pooled over seeds: median, 95th percentile and max error of visible points (px),
visible fraction, and Spearman(kappa, kappa_true) from the full analysis (default preset, no bootstrap;
mean over seeds; ``--no-kappa`` skips it). Videos are cached in ``--cache`` (re-runs only re-track).
``STRESS`` holds harsher conditions (``--conditions gain_fast,blur_full,shadow_sharp,shake_3px,crf34,...``).

Usage: .venv/bin/python benchmarks/bench_track_nuisance.py [--seeds 0,1,2] [--frames 400]
       [--conditions clean,blur,...] [--cache /tmp/rce_nuisance_clips] [--no-kappa] [--no-plain]
       [--lk-highpass 4]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
from scipy.stats import spearmanr

from rce_gtsam.sim.nuisance import REALISM, RenderConfig, image_xy
from rce_gtsam.sim.render import render_video
from rce_gtsam.sim.simulate import SimulationConfig, simulate
from rce_gtsam.track import LKConfig, LKTracker, open_video

_OUT = REALISM["outdoor"]
CONDITIONS: dict[str, RenderConfig] = {
    "clean": RenderConfig(),
    "blur": RenderConfig(exposure=_OUT.exposure),
    "gain": RenderConfig(gain_sd=_OUT.gain_sd, offset_sd=_OUT.offset_sd),
    "shadow": RenderConfig(shadow_depth=_OUT.shadow_depth),
    "shake": RenderConfig(shake_px=_OUT.shake_px),
    "crf28": RenderConfig(crf=_OUT.crf),
    "outdoor": _OUT,
}

#: Harsher than a tripod clip on a breezy day, to find where the tracker breaks (``--conditions`` names them).
STRESS: dict[str, RenderConfig] = {
    "gain_fast": RenderConfig(gain_sd=0.25, offset_sd=8.0, light_time_s=0.2),   # auto-exposure hunting, ~3 %/frame
    "blur_full": RenderConfig(exposure=1.0),                                     # 360-degree shutter
    "shadow_sharp": RenderConfig(shadow_depth=0.5, shadow_width_px=12.0, shadow_speed_px_s=30.0),
    "shake_3px": RenderConfig(shake_px=3.0, shake_time_s=0.1),
    "crf34": RenderConfig(crf=34),
    "outdoor_crf23": replace(_OUT, crf=23),
}


def _video(sim, name: str, cfg: RenderConfig, cache: Path) -> Path:
    key = json.dumps([sim.config.seed, sim.config.n_frames, sorted(vars(cfg).items())])
    path = cache / f"{name}_s{sim.config.seed}_f{sim.config.n_frames}_{hashlib.sha1(key.encode()).hexdigest()[:10]}.mp4"
    if not path.exists():
        render_video(sim, path, config=cfg)
    return path


def _plain_lk(video: Path, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Frame-to-frame pyramidal LK: (P, F, 2) positions and (P, F) OpenCV status (once lost, lost)."""
    p = q.astype(np.float32).reshape(-1, 1, 2)
    xy, vis = [], []
    ok = np.ones(len(q), bool)
    prev = None
    with open_video(video) as src:
        for fr in src:
            g = cv2.cvtColor(fr.image, cv2.COLOR_RGB2GRAY)
            if prev is not None:
                p, st, _ = cv2.calcOpticalFlowPyrLK(prev, g, p, None, winSize=(21, 21), maxLevel=3)
                ok &= st.ravel() == 1
            xy.append(p.reshape(-1, 2).astype(float))
            vis.append(ok.copy())
            prev = g
    return np.stack(xy, axis=1), np.stack(vis, axis=1)


def _spearman(res, sim) -> float:
    import rce_gtsam
    from rce_gtsam.tracks import load_tracks

    with tempfile.TemporaryDirectory() as tmp:
        path = res.write_csv(Path(tmp) / "t.csv")
        tracks = load_tracks(path, sim.graph)
    r = rce_gtsam.analyze(tracks, sim.graph, preset="default", n_boot=0)
    est = np.array([r.kappa[e] for e in r.response.edges])
    tru = np.array([sim.kappa_true[e] for e in r.response.edges])
    return float(spearmanr(est, tru)[0])


def _stats(err: np.ndarray, vis: np.ndarray) -> str:
    e = err[vis]
    return (f"{np.median(e):7.3f} {np.percentile(e, 95):7.2f} {e.max():7.1f} {vis.mean():6.3f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--frames", type=int, default=400)
    ap.add_argument("--conditions", default=",".join(CONDITIONS))
    ap.add_argument("--cache", type=Path, default=Path(tempfile.gettempdir()) / "rce_nuisance_clips")
    ap.add_argument("--no-kappa", action="store_true", help="skip the analysis (Spearman of kappa)")
    ap.add_argument("--no-plain", action="store_true", help="skip the plain frame-to-frame LK baseline")
    ap.add_argument("--lk-highpass", type=float, default=None, metavar="PX",
                    help="LKConfig.anchor_highpass_px of the default tracker (default: the LKConfig default)")
    args = ap.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    names = [c.strip() for c in args.conditions.split(",")]
    known = {**CONDITIONS, **STRESS}
    unknown = [c for c in names if c not in known]
    if unknown:
        raise SystemExit(f"unknown condition(s) {unknown}; choose from {', '.join(known)}")
    args.cache.mkdir(parents=True, exist_ok=True)
    lk_cfg = LKConfig() if args.lk_highpass is None else LKConfig(anchor_highpass_px=args.lk_highpass)
    sims = {s: simulate(SimulationConfig(n_frames=args.frames, seed=s)) for s in seeds}
    print(f"tracker {lk_cfg}")
    print(f"seeds {seeds}, {args.frames} frames, 20 nodes, cv2 threads {cv2.getNumThreads()}; errors in px vs the "
          f"image positions (true + camera shift); kappa rho = mean Spearman over seeds")
    print(f"{'condition':10s} {'tracker':8s} {'median':>7s} {'p95':>7s} {'max':>7s} {'vis':>6s} {'rho':>6s} "
          f"{'per-seed max / rho':s}")
    for name in names:
        cfg = known[name]
        rows: dict[str, list] = {"default": [], "plain": []}
        t0 = time.perf_counter()
        for s, sim in sims.items():
            truth = np.zeros_like(sim.true_xy)
            truth[list(sim.tracks.node_ids)] = image_xy(sim, cfg)
            video = _video(sim, name, cfg, args.cache)
            with open_video(video) as src:
                res = LKTracker(lk_cfg).track(src, truth[:, 0], sim.graph)
            err = np.hypot(*(res.xy - truth).transpose(2, 0, 1))
            rho = np.nan if args.no_kappa else _spearman(res, sim)
            rows["default"].append((err, res.visible, rho))
            if not args.no_plain:
                xy, vis = _plain_lk(video, truth[:, 0])
                rows["plain"].append((np.hypot(*(xy - truth).transpose(2, 0, 1)), vis, np.nan))
        for tracker, rs in rows.items():
            if not rs:
                continue
            err = np.concatenate([r[0] for r in rs], axis=1)
            vis = np.concatenate([r[1] for r in rs], axis=1)
            rho = np.nanmean([r[2] for r in rs]) if tracker == "default" and not args.no_kappa else np.nan
            per = " ".join(f"{r[0][r[1]].max():.1f}/{r[2]:.2f}" if np.isfinite(r[2]) else f"{r[0][r[1]].max():.1f}"
                           for r in rs)
            print(f"{name:10s} {tracker:8s} {_stats(err, vis)} {rho:6.3f}  {per}", flush=True)
        print(f"{'':10s} ({time.perf_counter() - t0:.0f} s)", flush=True)


if __name__ == "__main__":
    main()
