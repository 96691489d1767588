"""Tracking throughput on this machine (prints measured figures; not a test).

1. Default tracker (anchored LK) frames/s on a 640x480 video with 20 nodes -- the simulator's render when
   rce_gtsam.render is available, else the synthetic branch of tests/track_fixtures.py -- next to plain
   frame-to-frame pyramidal LK on the same frames (the baseline ratio). Frames are decoded beforehand so
   decode time is not counted.
2. TAPIR ONNX runner overhead per frame *excluding the network*: a fake model with the real export's I/O
   shapes (R=256, causal state [4, 12, N, 2, 2560], 256/128 query channels) whose graph is nearly free;
   overhead = wall time of track() minus time inside InferenceSession.run.

Usage: .venv/bin/python benchmarks/bench_track.py [--frames 120]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from rce_gtsam.track import ArraySource, LKTracker  # noqa: E402


def scene(n_frames: int):
    try:
        from rce_gtsam.render import iter_frames
        from rce_gtsam.simulate import SimulationConfig, simulate

        sim = simulate(SimulationConfig(n_nodes=20, n_frames=n_frames, seed=0))
        frames = np.stack([cv2.cvtColor(f, cv2.COLOR_BGR2RGB) for f in iter_frames(sim)])
        truth = np.zeros_like(sim.true_xy)
        truth[list(sim.tracks.node_ids)] = sim.true_xy
        return "simulator render", frames, truth, sim.graph
    except ImportError:
        from rce_gtsam.graph import BranchGraph
        from track_fixtures import branch_video

        bv = branch_video(n_frames=n_frames, size=(640, 480), n_nodes=20, segment_px=15)
        return "synthetic fixture", bv.frames, bv.true_xy, BranchGraph.from_edges(0, bv.edges)


def plain_lk(frames, q):
    p = q.astype(np.float32).reshape(-1, 1, 2)
    prev = None
    for im in frames:
        g = cv2.cvtColor(im, cv2.COLOR_RGB2GRAY)
        if prev is not None:
            p, _, _ = cv2.calcOpticalFlowPyrLK(prev, g, p, None, winSize=(21, 21), maxLevel=3)
        prev = g


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=120)
    args = ap.parse_args()
    name, frames, truth, graph = scene(args.frames)
    h, w = frames.shape[1:3]
    print(f"scene: {name}, {w}x{h}, {truth.shape[0]} nodes, {len(frames)} frames, cv2 threads {cv2.getNumThreads()}")
    t = time.perf_counter()
    res = LKTracker().track(ArraySource(frames), truth[:, 0], graph)
    t_lk = time.perf_counter() - t
    t = time.perf_counter()
    plain_lk(frames, truth[:, 0])
    t_plain = time.perf_counter() - t
    err = np.hypot(*(res.xy - truth).transpose(2, 0, 1))
    vis = res.visible
    print(f"default tracker: {len(frames) / t_lk:.1f} frames/s ({1000 * t_lk / len(frames):.1f} ms/frame); "
          f"plain frame-to-frame LK: {len(frames) / t_plain:.1f} frames/s; ratio {t_lk / t_plain:.1f}x slower")
    print(f"  accuracy: median {np.median(err[vis]):.3f} px, 90th pct {np.percentile(err[vis], 90):.3f} px, "
          f"visible {100 * vis.mean():.1f}%, last-frame median {np.median(err[:, -1]):.3f} px")

    from rce_gtsam.track.tapir import TapirOnnxTracker
    from track_fixtures import build_fake_tapir

    with tempfile.TemporaryDirectory() as tmp:
        model = build_fake_tapir(Path(tmp) / "m", resolution=256, n_points="N", c1=256, c2=128, state=(4, 12, 2560))
        tracker = TapirOnnxTracker(model)
        nf = min(len(frames), 60)
        r = tracker.track(ArraySource(frames[:nf]), truth[:, 0])
        i = r.info
        print(f"TAPIR ONNX runner (fake network, R=256, N={truth.shape[0]}, state 4x12xNx2x2560): "
              f"total {1000 * i['time_total_s'] / nf:.2f} ms/frame, inside session.run "
              f"{1000 * i['time_network_s'] / nf:.2f} ms/frame, overhead outside the network "
              f"{i['overhead_ms_per_frame']:.2f} ms/frame")


if __name__ == "__main__":
    main()
