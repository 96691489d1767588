"""How right are the positions of the frames the default tracker marks lost? (issue 38: sigma instead of dropping.)

Runs the default tracker with a trace of its first pass: for every node-frame marked invisible, why (the counter
of ``LKTracker.track``'s ``info`` that the rejection bumped), and each candidate position the tracker had at hand
-- the reported position (its prediction), the rejected frame-0 match with its correlation, its second peak and
forward-backward error, the hinged segment search with its strip correlation, and frame-to-frame pyramidal LK --
with its distance from a reference: the truth on the real-texture bed (``rce_gtsam.sim.texture_bed``), TAPIR's
tracks on plant 2's footage (one tracker against another, not truth).

Usage: python benchmarks/bench_lost_positions.py [--bed-seeds 0,1] [--tip-px 60] [--plant2] [--frames N]
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))


def traced_tracker():
    """An ``LKTracker`` subclass recording, per node-frame marked invisible in the first pass, a dict of the
    reason and candidate positions (``self.trace``)."""
    from rce_gtsam.track import LKTracker

    class Traced(LKTracker):
        def track(self, *a, **k):
            self.trace, self._frame = [], 0
            return super().track(*a, **k)

        def _anchor(self, gray0, gray, i, *a, **k):
            m = super()._anchor(gray0, gray, i, *a, **k)
            if self._tracing:
                self._m[i] = m
            return m

        def _segment_search(self, gray, xp, p, c, *a, **k):
            s = super()._segment_search(gray, xp, p, c, *a, **k)
            if self._tracing:
                self._s[c] = s
            return s

        def _first_pass_node(self, fr, i):
            if i == self.order[0]:
                self._frame += 1
            self._m, self._s, self._tracing = {}, {}, True
            before = dict(fr.counts)
            super()._first_pass_node(fr, i)
            self._tracing = False
            if fr.new_vis[i]:
                return
            why = [k for k in fr.counts if fr.counts[k] != before.get(k) and k.startswith(("rejected", "lost"))]
            m, s = self._m.get(i), self._s.get(i)
            rec = {"frame": self._frame, "node": i, "why": why[0] if why else "?", "pred": fr.new_est[i].copy(),
                   "f2f": fr.f2f[i].copy() if fr.f2f_ok[i] else None}
            if m is not None:
                xy, score, fb, s_lk, second, n_eff, xy2 = m
                rec.update(match=np.array(xy), score=score, fb=fb, margin=(score - second) * math.sqrt(n_eff),
                           match2=None if xy2 is None else np.array(xy2), pred_in=fr.preds[i].copy(), wide=fr.wide[i])
            if s is not None:
                rec.update(seg=np.array(s[0]), seg_ncc=s[2])
            self.trace.append(rec)

    return Traced


#: rejections of a frame-0 match that passed the correlation and distinctness tests
SOFT = ("rejected_fb", "rejected_length", "rejected_unanchored")
MIN_NCC = 0.5


def summarise(trace, ref, res, label: str) -> None:
    """Print, per rejection reason, the distance (px) of each candidate from ``ref`` (P, F, 2), and for the rejected
    frame-0 matches the distance against their correlation."""
    final_lost = ~res.visible
    rows = [r for r in trace if final_lost[r["node"], r["frame"]] and np.isfinite(ref[r["node"], r["frame"]]).all()]
    print(f"{label}: {final_lost.sum()} node-frames lost, {len(rows)} traced with a reference")

    def d(r, key):
        v = r.get(key)
        return np.nan if v is None else float(np.hypot(*(v - ref[r["node"], r["frame"]])))

    def q(a):
        a = np.asarray(a, float)
        a = a[np.isfinite(a)]
        return f"{np.median(a):6.2f} {np.percentile(a, 90):6.2f} (n {a.size:4d})" if a.size else "     -      -  (n    0)"

    nodes, cnt = np.unique([r["node"] for r in rows], return_counts=True)
    print("  lost node-frames by node: " + ", ".join(f"{a}: {b}" for a, b in zip(nodes, cnt)))
    print(f"  {'reason':20s} {'n':>5s}   reported med/p90     frame-0 match       segment           f2f LK")
    for why in sorted({r["why"] for r in rows}):
        rs = [r for r in rows if r["why"] == why]
        print(f"  {why:20s} {len(rs):5d}   {q([d(r, 'pred') for r in rs])}  {q([d(r, 'match') for r in rs])}  "
              f"{q([d(r, 'seg') for r in rs])}  {q([d(r, 'f2f') for r in rs])}")
    ms = [r for r in rows if "match" in r]
    if ms:
        sc = np.array([r["score"] for r in ms])
        de = np.array([d(r, "match") for r in ms])
        fb = np.array([r["fb"] for r in ms])
        mg = np.array([r["margin"] for r in ms])
        print("  rejected frame-0 matches: distance by correlation")
        for lo, hi in [(-1, 0.3), (0.3, 0.4), (0.4, 0.5), (0.5, 0.6), (0.6, 0.7), (0.7, 1.01)]:
            k = (sc >= lo) & (sc < hi)
            if k.any():
                print(f"    ncc {lo:4.1f}-{hi:4.2f}: n {k.sum():4d}, median {np.median(de[k]):6.2f} px, "
                      f"share < 1 px {np.mean(de[k] < 1):.2f}, < 2 px {np.mean(de[k] < 2):.2f}, "
                      f"fb median {np.median(fb[k]):.2f}, peak margin median {np.median(mg[k]):.1f}")
        amb = np.array([r["why"] == "rejected_ambiguous" and r["match2"] is not None for r in ms])
        if amb.any():
            near = np.array([r["match2"] is not None and np.hypot(*(r["match"] - r["pred_in"]))
                             < np.hypot(*(r["match2"] - r["pred_in"])) for r in ms])
            wide = np.array([bool(r["wide"]) for r in ms])
            print("  rejected for an indistinct second peak: distance of the best peak")
            for lab, k in [("best nearer the prediction, narrow search", amb & near & ~wide),
                           ("best nearer the prediction, wide search", amb & near & wide),
                           ("second nearer the prediction", amb & ~near)]:
                if k.any():
                    print(f"    {lab:42s} n {k.sum():4d}, median {np.median(de[k]):6.2f} px, p90 "
                          f"{np.percentile(de[k], 90):6.2f} px, share > 3 px {np.mean(de[k] > 3):.2f}")
        soft = np.array([r["why"] in SOFT for r in ms]) & (sc >= MIN_NCC)
        print(f"  rejected only by {', '.join(SOFT)} (ncc >= {MIN_NCC}, peaks distinct): distance by forward-backward error")
        for lo, hi in [(0, 0.5), (0.5, 1), (1, 2), (2, 4), (4, 1e9)]:
            k = soft & (fb >= lo) & (fb < hi)
            if k.any():
                print(f"    fb {lo:3.1f}-{min(hi, 99):4.1f} px: n {k.sum():4d}, median {np.median(de[k]):6.2f} px, p90 "
                      f"{np.percentile(de[k], 90):6.2f} px, share > 3 px {np.mean(de[k] > 3):.2f}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bed-seeds", default="0,1")
    ap.add_argument("--tip-px", type=float, default=60.0)
    ap.add_argument("--bed-frames", type=int, default=300)
    ap.add_argument("--plant2", action="store_true", help="also plant 2's footage against TAPIR")
    ap.add_argument("--frames", type=int, default=None, help="plant 2: only the first N frames")
    args = ap.parse_args()
    cv2.setNumThreads(1)
    from rce_gtsam.track import ArraySource, open_video

    cls = traced_tracker()
    if args.bed_seeds:
        from bench_texture_bed import bed_case, default_cache

        for seed in [int(s) for s in args.bed_seeds.split(",")]:
            bed, cf, path = bed_case(seed, (), args.bed_frames, args.tip_px, default_cache())
            t = cls()
            with open_video(path) as src:
                res = t.track(src, cf.points, cf.graph)
            summarise(t.trace, bed.true_xy, res, f"texture bed seed {seed}, tip {args.tip_px:g} px")
    if args.plant2:
        from bench_track_plant2 import load_plant

        frames, q, graph, tap = load_plant()
        if args.frames:
            frames, tap = frames[:args.frames], tap[:, :args.frames]
        t = cls()
        res = t.track(ArraySource(frames), q, graph)
        summarise(t.trace, tap, res, "plant 2 against TAPIR")


if __name__ == "__main__":
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    main()
