"""The built-in tracker on plant 2's real footage against the published TAPIR tracks, per 60-frame window.

Tracks ``../shared/data/plant_2/annotated_nodes.mp4`` from the published 25 annotation points (with the branch
graph) and compares, per 60-frame window, with ``tapir_tracks.csv``: the share of the (point, frame) rows TAPIR has
that our tracker marks visible, and the 90th percentile of the distance to TAPIR on those (px). TAPIR is not the
truth (its dots are drawn into the video, too; nothing here is tuned to them): this is one tracker against another.
Also: the root node's distance from its annotated position (the root is fixed), the tip node's visible share, and
with ``--kappa`` kappa of both runs through ``rce_gtsam.analyze`` (default preset): Spearman, log-RMS of the ratio,
and how many of ours lie inside the TAPIR run's CI. ``--baseline REV`` runs the default tracker (``track/lk*.py``) of that revision on the
same frames in the same process (before/after). Speed: the tracker on the decoded frames against plain OpenCV
pyramidal LK (``cv2.calcOpticalFlowPyrLK``, 21x21, 3 levels, frame to frame) on the same points, one core.

Usage: python benchmarks/bench_track_plant2.py [--baseline REV] [--kappa [--sigma-modes per_observation,uniform]] [--frames N]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
from scipy.stats import spearmanr

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
#: plant 2's folder: ``../shared/data/plant_2`` beside the repository, or $RCE_PLANT2_DIR (a git worktree elsewhere)
PLANT = Path(os.environ.get("RCE_PLANT2_DIR", ROOT.parent / "shared" / "data" / "plant_2"))


def load_plant(plant: Path = PLANT):
    """(frames (F, H, W, 3) uint8 RGB, annotation points (P, 2), graph, TAPIR xy (P, F, 2) NaN = no row)."""
    from rce_gtsam.graph import load_graph
    from rce_gtsam.track import open_video

    with open_video(plant / "annotated_nodes.mp4") as src:
        frames = np.stack([fr.image for fr in src])
    q = np.array(json.loads((plant / "annotation_points.json").read_text())["points"], float)
    graph = load_graph(plant / "branch_graph.json")
    df = pd.read_csv(plant / "tapir_tracks.csv")
    tap = np.full((len(q), len(frames), 2), np.nan)
    tap[df.point_id.to_numpy(), df.frame.to_numpy()] = df[["x", "y"]].to_numpy()
    return frames, q, graph, tap


def window_table(xy, visible, tap, width: int = 60):
    """Per window of ``width`` frames: (first, last, visible share of TAPIR's rows, p90 distance to TAPIR px)."""
    has = np.isfinite(tap[..., 0])
    d = np.hypot(*(xy - tap).transpose(2, 0, 1))
    rows = []
    for a in range(0, xy.shape[1], width):
        b = min(a + width, xy.shape[1])
        m = has[:, a:b]
        v = visible[:, a:b] & m
        dd = d[:, a:b][v]
        rows.append((a, b - 1, v.sum() / max(m.sum(), 1), float(np.percentile(dd, 90)) if dd.size else np.nan))
    return rows


def kappa_vs_tapir(res, tap, graph, n_boot: int = 250, sigma_mode: str | None = None):
    """(Spearman, log-RMS of the ratio, n inside the TAPIR run's CI, n segments) of kappa from ``res``; ``sigma_mode``
    overrides the default preset's ``smoother.sigma_mode`` (TAPIR's tracks carry no sigma: only ours change)."""
    import rce_gtsam
    from rce_gtsam.presets import get_preset
    from rce_gtsam.tracks import Tracks, load_tracks

    preset = get_preset("default")
    if sigma_mode:
        preset = preset.with_(smoother={"sigma_mode": sigma_mode})

    with tempfile.TemporaryDirectory() as tmp:
        ours = load_tracks(res.write_csv(Path(tmp) / "t.csv"), graph)
    ids = np.arange(tap.shape[0])
    ref = Tracks(node_ids=ids[list(graph.nodes)], xy=tap[list(graph.nodes)], source="tapir")
    a = rce_gtsam.analyze(ours, graph, preset=preset, n_boot=n_boot)
    b = rce_gtsam.analyze(ref, graph, preset=preset, n_boot=n_boot)
    ka = np.array([a.kappa[e] for e in b.response.edges])
    kb = np.array([b.kappa[e] for e in b.response.edges])
    inside = int(((ka >= b.ci.low) & (ka <= b.ci.high)).sum())
    return float(spearmanr(ka, kb)[0]), float(np.sqrt(np.mean(np.log(ka / kb) ** 2))), inside, len(kb)


def plain_lk_time(frames, q) -> float:
    """Seconds plain frame-to-frame pyramidal LK (``bench_track.plain_lk``) takes over ``frames`` (grey conversion
    included)."""
    from bench_track import plain_lk

    t = time.perf_counter()
    plain_lk(frames, q)
    return time.perf_counter() - t


def report(name, res, q, graph, tap, kappa: bool, sigma_modes=(None,)):
    rows = window_table(res.xy, res.visible, tap)
    print(f"{name}: visible {100 * res.visible.mean():.1f} % of point-frames; "
          f"{res.n_frames / res.info['time_total_s']:.0f} frames/s")
    print("  window     visible(TAPIR rows)  p90 to TAPIR (px)")
    for a, b, v, p in rows:
        print(f"  {a:3d}-{b:3d}   {100 * v:6.1f} %            {p:5.2f}")
    root, tips = graph.root, [n for n in graph.nodes if not graph.children.get(n)]
    drift = np.hypot(*(res.xy[root] - q[root]).T)
    print(f"  root {root}: distance from its annotation median {np.median(drift):.2f} px, max {drift.max():.2f} px; "
          f"visible {100 * res.visible[root].mean():.1f} %")
    for t in tips:
        d = np.hypot(*(res.xy[t] - tap[t]).T)
        inv = ~res.visible[t] & np.isfinite(d)
        print(f"  tip {t}: visible {100 * res.visible[t].mean():.1f} %; distance to TAPIR where marked lost: "
              f"median {np.median(d[inv]) if inv.any() else np.nan:.2f} px")
    worst = min(r[2] for r in rows[2:6])
    print(f"  frames 120-359: visible {' / '.join(f'{100 * r[2]:.0f}' for r in rows[2:6])} % "
          f"(worst {100 * worst:.0f}); p90 {' / '.join(f'{r[3]:.2f}' for r in rows[2:6])} px")
    for mode in sigma_modes if kappa else ():
        rho, lr, inside, n = kappa_vs_tapir(res, tap, graph, sigma_mode=mode)
        print(f"  kappa vs the TAPIR run's{f' (smoother sigma_mode {mode})' if mode else ''}: Spearman {rho:.2f}, "
              f"log-RMS {lr:.2f}, inside its CI {inside}/{n}")
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", default=None, help="git revision of the default tracker (rce_gtsam/track/lk*.py) to run as well")
    ap.add_argument("--kappa", action="store_true", help="also compare kappa with the TAPIR run's (bootstrap)")
    ap.add_argument("--frames", type=int, default=None, help="only the first N frames")
    ap.add_argument("--sigma-modes", default=None,
                    help="with --kappa: smoother sigma_mode values to compare, e.g. per_observation,uniform")
    args = ap.parse_args()
    modes = tuple(args.sigma_modes.split(",")) if args.sigma_modes else (None,)
    cv2.setNumThreads(1)
    if not (PLANT / "annotated_nodes.mp4").is_file():
        raise SystemExit(f"plant 2 footage not found at {PLANT}")
    from rce_gtsam.track import ArraySource, LKTracker

    frames, q, graph, tap = load_plant()
    if args.frames:
        frames, tap = frames[:args.frames], tap[:, :args.frames]
    trackers = {"current": LKTracker}
    tmp = tempfile.TemporaryDirectory()
    if args.baseline:
        from bench_track import baseline_tracker
        trackers = {"baseline": baseline_tracker(args.baseline, Path(tmp.name)), **trackers}
    for name, cls in trackers.items():
        cls().track(ArraySource(frames[:3]), q, graph)  # load the compiled kernels outside the timing
        res = cls().track(ArraySource(frames), q, graph)
        report(name, res, q, graph, tap, args.kappa, modes)
    t = plain_lk_time(frames, q)
    print(f"plain pyramidal LK on the same {len(q)} points: {len(frames) / t:.0f} frames/s")
    tmp.cleanup()


if __name__ == "__main__":
    main()
