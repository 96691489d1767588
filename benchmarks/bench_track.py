"""Default tracker: speed and accuracy against a baseline revision of it, in the same run (prints figures; not a test).

The baseline is the default tracker as it was at ``--baseline`` (git revision, default 7f3b223: before the
speed-up), loaded from ``git show`` into a module of its own (``rce_gtsam/track/lk.py`` with that revision's
``match_kernels.py``, when it has one; from the split of ``lk.py`` on, the revision's whole ``rce_gtsam/track``
package), so both trackers run on the same frames in the same process.

1. Speed, on the simulator's 640x480 render (seed 0, 20 nodes, ``--frames`` frames, H.264 as ``rce simulate
   --video`` writes it): decode time (``open_video``, frames to RGB) on its own; then tracking time alone on the
   decoded frames held in memory, baseline and current alternating ``--repeat`` times, best of each (wall clock,
   and process CPU time, which counts less of what other processes take from a shared machine), next to plain
   frame-to-frame pyramidal LK; and what a user waits for: tracking straight from the mp4 (``open_video``, the
   tracker decoding ahead in its thread), also alternating, best of each. cv2 threads as found
   (``--cv-threads N`` sets them). ``current2`` is the current tracker with ``LKConfig(threads=2)`` (the
   refinement pass in a second thread right behind the first): same tracks, timed to show what the thread adds.
2. Accuracy, on rendered clips (``--clips SEED:FRAMES,...``; default seeds 0-4, 600 frames, seed 1 400, as in the
   README), each tracked by both: median, 99th percentile and largest error of points marked visible (px, against
   the true node positions), visible share of point-frames, and Spearman(kappa, kappa_true) from the full analysis
   (default preset, no bootstrap: kappa does not depend on it), the median and 90th percentile of the reported sigma
   of visible points (sig50, sig90, px: the smoother's measurement weight), plus the largest position difference
   between the two trackers on points both call visible. A third row, ``baseline~``, is the baseline tracker with every
   annotated point moved by ``--jitter-px`` (default 0.001 px) in x and y: how much these figures move under a
   perturbation far below any real annotation error, i.e. the resolution at which two trackers' figures can be
   called different (the tail figures and rho move at the printed precision). Clips are cached in ``--cache``.
3. TAPIR ONNX runner overhead per frame *excluding the network*: a fake model with the real export's I/O
   shapes (R=256, causal state [4, 12, N, 2, 2560], 256/128 query channels) whose graph is nearly free;
   overhead = wall time of track() minus time inside InferenceSession.run.

Usage: .venv/bin/python benchmarks/bench_track.py [--frames 120] [--repeat 5] [--clips 0:600,1:400,...]
       [--no-accuracy] [--no-tapir] [--baseline REV] [--cache DIR] [--cv-threads N] [--jitter-px 0.001]
"""

from __future__ import annotations

import argparse
import importlib.util
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
from scipy.stats import spearmanr

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from rce_gtsam.sim.render import render_video  # noqa: E402
from rce_gtsam.sim.simulate import SimulationConfig, simulate  # noqa: E402
from rce_gtsam.track import ArraySource, LKConfig, LKTracker, open_video  # noqa: E402


def _git_show(rev: str, path: str) -> str | None:
    out = subprocess.run(["git", "-C", str(ROOT), "show", f"{rev}:{path}"], capture_output=True, text=True)
    return out.stdout if out.returncode == 0 else None


def _load(name: str, path: Path):
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # dataclasses look their module up here
    spec.loader.exec_module(mod)
    return mod


def baseline_tracker(rev: str, tmp: Path):
    """``LKTracker`` class of the default tracker at git revision ``rev``, with that revision's compiled kernels
    (their signatures change between revisions; compiled afresh in ``tmp``, which takes a while).

    Up to the split of ``lk.py`` into ``lk_*.py`` modules the tracker was that one file: it is loaded as a module of
    its own (``rce_gtsam.track.lk_baseline``, with ``match_kernels.py`` as ``match_kernels_baseline`` when the
    revision has one). From the split on, every ``rce_gtsam/track/*.py`` of the revision is written to
    ``tmp/track_<rev>/`` and loaded as the package ``rce_gtsam.track_baseline`` (its ``..`` imports are this
    checkout's ``rce_gtsam``), and its ``lk.LKTracker`` returned."""
    src = _git_show(rev, "rce_gtsam/track/lk.py")
    if src is None:
        raise SystemExit(f"no rce_gtsam/track/lk.py at revision {rev}")
    if _git_show(rev, "rce_gtsam/track/lk_node.py") is not None:  # the tracker of several modules
        return _baseline_package(rev, tmp).lk.LKTracker
    kernels = _git_show(rev, "rce_gtsam/track/match_kernels.py")
    if kernels is not None:
        (tmp / "match_kernels_baseline.py").write_text(kernels)
        _load("rce_gtsam.track.match_kernels_baseline", tmp / "match_kernels_baseline.py")
        src = src.replace("from . import match_kernels", "from . import match_kernels_baseline as match_kernels")
    path = tmp / f"lk_{rev}.py"
    path.write_text(src)
    return _load("rce_gtsam.track.lk_baseline", path).LKTracker


def _baseline_package(rev: str, tmp: Path):
    """The package ``rce_gtsam/track`` (and any sub-package of it) of revision ``rev``, loaded as
    ``rce_gtsam.track_baseline`` from ``tmp/track_<rev>/``, with its ``lk`` module imported."""
    files = subprocess.run(["git", "-C", str(ROOT), "ls-tree", "-r", "--name-only", rev, "rce_gtsam/track/"],
                           capture_output=True, text=True, check=True).stdout.split()
    pkg = tmp / f"track_{rev}"
    for name in files:
        if name.endswith(".py"):
            out = pkg / Path(name).relative_to("rce_gtsam/track")
            out.parent.mkdir(parents=True, exist_ok=True)
            out.write_text(_git_show(rev, name))
    spec = importlib.util.spec_from_file_location("rce_gtsam.track_baseline", pkg / "__init__.py",
                                                  submodule_search_locations=[str(pkg)])
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    importlib.import_module("rce_gtsam.track_baseline.lk")
    return mod


def clip(seed: int, n_frames: int, cache: Path):
    """(simulation, mp4 path, (P, F, 2) true positions indexed by node id) of a cached clean render."""
    sim = simulate(SimulationConfig(n_nodes=20, n_frames=n_frames, seed=seed))
    path = cache / f"clean_s{seed}_f{n_frames}.mp4"
    if not path.exists():
        render_video(sim, path)
    truth = np.zeros_like(sim.true_xy)
    truth[list(sim.tracks.node_ids)] = sim.true_xy
    return sim, path, truth


def track_mp4(cls, path: Path, q, graph):
    with open_video(path) as src:
        return cls().track(src, q, graph)


def decode(path: Path) -> np.ndarray:
    with open_video(path) as src:
        return np.stack([fr.image for fr in src])


def plain_lk(frames, q):
    p = q.astype(np.float32).reshape(-1, 1, 2)
    prev = None
    for im in frames:
        g = cv2.cvtColor(im, cv2.COLOR_RGB2GRAY)
        if prev is not None:
            p, _, _ = cv2.calcOpticalFlowPyrLK(prev, g, p, None, winSize=(21, 21), maxLevel=3)
        prev = g


def timed(fn, *args):
    """(result, wall s, process CPU s) of fn(*args)."""
    c, t = time.process_time(), time.perf_counter()
    out = fn(*args)
    return out, time.perf_counter() - t, time.process_time() - c


def spearman_kappa(res, sim) -> float:
    import rce_gtsam
    from rce_gtsam.tracks import load_tracks

    with tempfile.TemporaryDirectory() as tmp:
        tracks = load_tracks(res.write_csv(Path(tmp) / "t.csv"), sim.graph)
    r = rce_gtsam.analyze(tracks, sim.graph, preset="default", n_boot=0)
    est = np.array([r.kappa[e] for e in r.response.edges])
    tru = np.array([sim.kappa_true[e] for e in r.response.edges])
    return float(spearmanr(est, tru)[0])


def speed(trackers, cache: Path, n_frames: int, repeat: int) -> None:
    sim, path, truth = clip(0, n_frames, cache)
    best_dec = min(timed(decode, path)[1] for _ in range(repeat))
    frames = decode(path)
    h, w = frames.shape[1:3]
    print(f"speed: simulator render seed 0, {w}x{h} H.264, {truth.shape[0]} nodes, {len(frames)} frames, "
          f"cv2 threads {cv2.getNumThreads()}, best of {repeat} (machine shared with other processes)")
    print(f"  decode alone: {len(frames) / best_dec:.0f} frames/s ({1000 * best_dec / len(frames):.2f} ms/frame)")
    wall = {k: np.inf for k in trackers}
    cpu, mp4 = dict(wall), dict(wall)
    for _ in range(repeat):
        for name, cls in trackers.items():
            _, t, c = timed(cls().track, ArraySource(frames), truth[:, 0], sim.graph)
            wall[name], cpu[name] = min(wall[name], t), min(cpu[name], c)
            mp4[name] = min(mp4[name], timed(track_mp4, cls, path, truth[:, 0], sim.graph)[1])
    t_plain = min(timed(plain_lk, frames, truth[:, 0])[1] for _ in range(repeat))
    for name in trackers:
        print(f"  {name:8s} tracking alone: {len(frames) / wall[name]:6.1f} frames/s wall "
              f"({1000 * wall[name] / len(frames):5.2f} ms/frame), {len(frames) / cpu[name]:6.1f} frames/s CPU; "
              f"with decode {len(frames) / (wall[name] + best_dec):6.1f} frames/s")
    for name in trackers:
        print(f"  {name:8s} from the mp4 (open_video + track, decoding ahead in a thread): "
              f"{len(frames) / mp4[name]:6.1f} frames/s ({1000 * mp4[name] / len(frames):5.2f} ms/frame)")
    print(f"  plain frame-to-frame LK: {len(frames) / t_plain:.0f} frames/s")
    for name in (k for k in trackers if k != "baseline"):
        print(f"  speed-up {name}/baseline: {wall['baseline'] / wall[name]:.2f}x wall, "
              f"{cpu['baseline'] / cpu[name]:.2f}x CPU, {mp4['baseline'] / mp4[name]:.2f}x from the mp4")


def accuracy(trackers, cache: Path, clips: list[tuple[int, int]], jitter_px: float) -> None:
    print("accuracy on rendered clips (px against the true node positions; rho = Spearman(kappa, kappa_true)):")
    print(f"  {'seed':>4s} {'frames':>6s} {'tracker':9s} {'median':>7s} {'p99':>6s} {'max':>6s} {'visible':>7s} "
          f"{'rho':>6s} {'s':>5s} {'sig50':>6s} {'sig90':>6s}")
    runs = {**{k: (cls, 0.0) for k, cls in trackers.items()}, "baseline~": (trackers["baseline"], jitter_px)}
    rows = {k: [] for k in runs}
    for seed, n in clips:
        sim, path, truth = clip(seed, n, cache)
        res = {}
        for name, (cls, shift) in runs.items():
            r, t, _ = timed(track_mp4, cls, path, truth[:, 0] + shift, sim.graph)
            res[name] = r
            err = np.hypot(*(r.xy - truth).transpose(2, 0, 1))[r.visible]
            rho = spearman_kappa(r, sim)
            rows[name].append((np.median(err), np.percentile(err, 99), err.max(), r.visible.mean(), rho))
            sig = r.sigma_px[r.visible]  # the reported sigma is the smoother's weight: where it sits on a clean render
            print(f"  {seed:4d} {n:6d} {name:9s} {rows[name][-1][0]:7.3f} {rows[name][-1][1]:6.2f} "
                  f"{rows[name][-1][2]:6.1f} {rows[name][-1][3]:7.3f} {rho:6.3f} {t:5.0f} {np.median(sig):6.3f} "
                  f"{np.percentile(sig, 90):6.3f}", flush=True)
        both = res["baseline"].visible & res["current"].visible
        d = np.hypot(*(res["baseline"].xy - res["current"].xy).transpose(2, 0, 1))[both]
        print(f"  {'':11s} both visible: {both.mean():.3f}, |current - baseline| median {np.median(d):.4f} px, "
              f"max {d.max():.2f} px; visible in one only: {(res['baseline'].visible != res['current'].visible).sum()}")
    for name, rs in rows.items():
        a = np.array(rs)
        print(f"  {name:9s} per seed: median {' / '.join(f'{v:.3f}' for v in a[:, 0])}; "
              f"p99 {' / '.join(f'{v:.2f}' for v in a[:, 1])}; max {' / '.join(f'{v:.1f}' for v in a[:, 2])}; "
              f"visible {' / '.join(f'{v:.3f}' for v in a[:, 3])}; rho {' / '.join(f'{v:.2f}' for v in a[:, 4])}")


def tapir(cache: Path, n_frames: int) -> None:
    from rce_gtsam.track.tapir import TapirOnnxTracker
    from track_fixtures import build_fake_tapir

    _, path, truth = clip(0, n_frames, cache)
    frames = decode(path)
    with tempfile.TemporaryDirectory() as tmp:
        model = build_fake_tapir(Path(tmp) / "m", resolution=256, n_points="N", c1=256, c2=128, state=(4, 12, 2560))
        nf = min(len(frames), 60)
        i = TapirOnnxTracker(model).track(ArraySource(frames[:nf]), truth[:, 0]).info
        print(f"TAPIR ONNX runner (fake network, R=256, N={truth.shape[0]}, state 4x12xNx2x2560): "
              f"total {1000 * i['time_total_s'] / nf:.2f} ms/frame, inside session.run "
              f"{1000 * i['time_network_s'] / nf:.2f} ms/frame, overhead outside the network "
              f"{i['overhead_ms_per_frame']:.2f} ms/frame")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=120, help="frames of the speed clip")
    ap.add_argument("--repeat", type=int, default=5, help="timings per tracker (best is reported)")
    ap.add_argument("--clips", default="0:600,1:400,2:600,3:600,4:600", help="accuracy clips SEED:FRAMES,...")
    ap.add_argument("--baseline", default="7f3b223", help="git revision of rce_gtsam/track/lk.py to compare with")
    ap.add_argument("--cache", type=Path, default=Path(tempfile.gettempdir()) / "rce_track_clips")
    ap.add_argument("--cv-threads", type=int, default=None, help="cv2.setNumThreads before timing")
    ap.add_argument("--jitter-px", type=float, default=0.001,
                    help="annotation shift (px) of the baseline~ accuracy row: the figures' own resolution")
    ap.add_argument("--no-accuracy", action="store_true")
    ap.add_argument("--no-tapir", action="store_true")
    args = ap.parse_args()
    if args.cv_threads is not None:
        cv2.setNumThreads(args.cv_threads)
    clips = [tuple(int(v) for v in c.split(":")) for c in args.clips.split(",") if c]
    args.cache.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        trackers = {"baseline": baseline_tracker(args.baseline, Path(tmp)), "current": LKTracker}
        print(f"baseline: rce_gtsam/track/lk.py at {args.baseline}; current: the working tree (default "
              f"LKConfig, threads={LKConfig().threads}); current2: the same with LKConfig(threads=2)")
        speed({**trackers, "current2": lambda: LKTracker(LKConfig(threads=2))}, args.cache, args.frames,
              args.repeat)
        if not args.no_accuracy:
            accuracy(trackers, args.cache, clips, args.jitter_px)
    if not args.no_tapir:
        tapir(args.cache, args.frames)


if __name__ == "__main__":
    main()
