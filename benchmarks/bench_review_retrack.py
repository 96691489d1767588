"""What re-tracking from a few corrected frames does on real footage (prints figures; not a test).

Plant 2's footage (``../shared/data/plant_2/annotated_nodes.mp4``, 590 frames, 640x480) is tracked by ``rce track``'s
default tracker from the published 25 annotation points (or ``--tracks`` given). A simulated reviewer then corrects,
in each of ``--frames`` (default four frames in the gusty part, 160,220,280,340), every node the tracker lost there or
placed more than ``--off-px`` (3) px from TAPIR, placing it where TAPIR's track has it, and
:func:`rce_gtsam.track.anchors.retrack` refits the corrected nodes. Printed before and after: visible share (all
frames and frames 120-359, the gusty part), p90 distance to TAPIR over visible point-frames and over all
point-frames, and the re-track's wall time.

Caveat: this video has TAPIR's dots drawn into every frame (see ``../shared/data/README.md``); a template taken at a
TAPIR position contains its dot, so agreement with TAPIR after re-tracking is flattering. It measures how much a few
corrected frames carry through a gust, not accuracy against the plant (tests/test_review.py checks that against a
known motion).

Usage: OMP_NUM_THREADS=1 .venv/bin/python benchmarks/bench_review_retrack.py [--frames 160,220,280,340]
       [--off-px 3] [--tracks T.csv]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "plant_2"


def summary(t, tap, label: str) -> None:
    d = np.hypot(*(t.xy - tap.xy).transpose(2, 0, 1))
    ok = np.isfinite(d)
    w = slice(120, 360)
    v, dw, okw = t.visible[:, w], d[:, w], ok[:, w]
    print(f"{label:>7}: visible {t.visible.mean():.1%} (frames 120-359: {v.mean():.1%}); distance to TAPIR p90 "
          f"{np.percentile(d[ok & t.visible], 90):.2f} px on visible point-frames, {np.percentile(d[ok], 90):.1f} px "
          f"on all (frames 120-359: {np.percentile(dw[okw & v], 90):.2f} / {np.percentile(dw[okw], 90):.1f} px)")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", default="160,220,280,340")
    ap.add_argument("--off-px", type=float, default=3.0)
    ap.add_argument("--tracks", type=Path, default=None)
    a = ap.parse_args()
    if not DATA.is_dir():
        print(f"needs {DATA} (the shared plant-2 footage)")
        return 1
    from rce_gtsam.graph import load_graph
    from rce_gtsam.track import LKTracker
    from rce_gtsam.track.anchors import Correction, DenseTracks, FrameStore, retrack
    from rce_gtsam.tracks import read_tracks_table

    video, graph_path = DATA / "annotated_nodes.mp4", DATA / "branch_graph.json"
    tracks = a.tracks
    if tracks is None:
        tracks = Path(tempfile.mkdtemp()) / "lk.csv"
        subprocess.run([sys.executable, "-m", "rce_gtsam.cli", "track", str(video),
                        str(DATA / "annotation_points.json"), "--graph", str(graph_path), "--out", str(tracks), "--no-progress"], check=True,
                       stdout=subprocess.DEVNULL)
    base = DenseTracks.from_table(read_tracks_table(tracks))
    tap = DenseTracks.from_table(read_tracks_table(DATA / "tapir_tracks.csv"))
    frames = [int(f) for f in a.frames.split(",")]
    corr = []
    for k in frames:
        for n in range(len(base.point_ids)):
            if not np.isfinite(tap.xy[n, k]).all():
                continue
            if not base.visible[n, k] or np.hypot(*(base.xy[n, k] - tap.xy[n, k])) > a.off_px:
                corr.append(Correction(k, n, *map(float, tap.xy[n, k])))
    summary(base, tap, "before")
    t0 = time.perf_counter()
    with FrameStore(video, base.n_frames) as store:
        out, _ = retrack(store, base, corr, LKTracker(), load_graph(graph_path))
    dt = time.perf_counter() - t0
    summary(out, tap, "after")
    print(f"{len(corr)} corrections of {len({c.node for c in corr})} nodes in frames {frames}; re-track {dt:.1f} s "
          "(decoding the clip, the frame-0 run and the runs from each corrected frame)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
