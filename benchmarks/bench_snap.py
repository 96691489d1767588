"""How well `rce annotate`'s click snapping finds the stem on the simulator's rendered frames.

Usage: python benchmarks/bench_snap.py [--seeds 4] [--nodes 12]

For each seed and layout (chain, tree): simulate a branch, render its first frame (rce_gtsam.sim.render), and
click beside every true node at 2 and 4 px on either side, perpendicular to its segment (a sloppy click
beside the stem). Each click goes through RidgeSnapper (the server's snapping). Printed, for the raw clicks
(the baseline, same clicks) and for the snapped ones: distance to the true node (px), distance to the true
centre line (the polyline of the true nodes, px), the share within 2 px of the node, and the ratio
snapped / raw of the median centre-line distance.
"""

from __future__ import annotations

import argparse

import numpy as np

from rce_gtsam.annotate_web.snap import RidgeSnapper
from rce_gtsam.sim.render import iter_frames
from rce_gtsam.sim.simulate import SimulationConfig, simulate


def line_distance(p: np.ndarray, xy: np.ndarray, edges, row: dict) -> float:
    """Distance (px) from ``p`` to the nearest segment of the branch."""
    best = np.inf
    for a, b in edges:
        A, B = xy[row[a]], xy[row[b]]
        d = B - A
        t = np.clip(np.dot(p - A, d) / np.dot(d, d), 0, 1)
        best = min(best, float(np.linalg.norm(A + t * d - p)))
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--nodes", type=int, default=12)
    args = ap.parse_args()
    raw_node, raw_line, snap_node, snap_line = [], [], [], []
    for layout in ("chain", "tree"):
        for seed in range(args.seeds):
            sim = simulate(SimulationConfig(n_nodes=args.nodes, n_frames=30, seed=seed, branch_layout=layout))
            img = next(iter(iter_frames(sim, n_frames=1)))
            img = img if isinstance(img, np.ndarray) else img.image
            snapper = RidgeSnapper(img)
            ids, xy, g = list(sim.tracks.node_ids), sim.true_xy[:, 0], sim.graph
            row = {n: i for i, n in enumerate(ids)}
            for i, n in enumerate(ids):
                other = g.parent.get(n, g.children[n][0] if g.children.get(n) else None)
                d = xy[row[other]] - xy[i]
                d /= np.linalg.norm(d)
                normal = np.array([-d[1], d[0]])
                for off in (-4.0, -2.0, 2.0, 4.0):
                    click = xy[i] + off * normal
                    r = snapper.snap(*click)
                    s = np.array([r.x, r.y])
                    raw_node.append(np.linalg.norm(click - xy[i]))
                    raw_line.append(line_distance(click, xy, g.edges, row))
                    snap_node.append(np.linalg.norm(s - xy[i]))
                    snap_line.append(line_distance(s, xy, g.edges, row))
    rn, rl, sn, sl = map(np.array, (raw_node, raw_line, snap_node, snap_line))
    print(f"{len(rn)} clicks on {2 * args.seeds} rendered first frames ({args.nodes} nodes, chain and tree)")
    print(f"{'':10s} {'node err median':>16s} {'p90':>6s} {'within 2 px':>12s} {'centre-line median':>19s}")
    for name, a, b in (("raw click", rn, rl), ("snapped", sn, sl)):
        print(f"{name:10s} {np.median(a):16.2f} {np.percentile(a, 90):6.2f} {100 * (a < 2).mean():11.1f}% "
              f"{np.median(b):19.2f}")
    print(f"snapped / raw median centre-line distance: {np.median(sl) / np.median(rl):.2f}")


if __name__ == "__main__":
    main()
