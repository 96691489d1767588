"""Rest geometry of the branch: segment rest lengths, root distances and zones.

An edge's or bend's root distance, depth and zone are those of its child (distal) node. Zones split
the normalised root distance s = d / max(d) at 1/3 and 2/3 into proximal, mid and distal.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..graph import BranchGraph

ZONES = ("proximal", "mid", "distal")


@dataclass(frozen=True, eq=False)
class Geometry:
    """rest_length_px: edge -> rest length (pixels); root_distance_px: node -> path length from the root
    along rest lengths (pixels); zone: node -> proximal | mid | distal (or "root" when all distances
    are ~0)."""

    rest_length_px: dict[tuple[int, int], float]
    root_distance_px: dict[int, float]
    zone: dict[int, str]

    def normalised_distance(self, node: int) -> float:
        """Root distance of ``node`` divided by the largest root distance (0..1)."""
        top = max(self.root_distance_px.values())
        return self.root_distance_px[node] / top if top > 0 else 0.0


def edge_lengths(xy: np.ndarray, row: dict[int, int], edge: tuple[int, int]) -> np.ndarray:
    """(F,) length of ``edge`` in pixels per frame, NaN where either end is missing."""
    a, b = edge
    d = xy[row[b]] - xy[row[a]]
    return np.hypot(d[:, 0], d[:, 1])


def zone_of(s: float) -> str:
    """Zone of a normalised root distance ``s`` in [0, 1]."""
    return "proximal" if s <= 1 / 3 else ("mid" if s <= 2 / 3 else "distal")


def compute_geometry(xy: np.ndarray, node_ids, graph: BranchGraph, rest: str = "first") -> Geometry:
    """Rest geometry from positions ``xy`` (N, F, 2), NaN = missing.

    ``rest="first"`` takes each edge's length at its first common frame (paper); ``"median"`` the
    median over common frames.
    """
    row = {int(n): i for i, n in enumerate(node_ids)}
    lengths = {}
    for e in graph.edges:
        L = edge_lengths(xy, row, e)
        finite = L[np.isfinite(L)]
        if finite.size == 0:
            lengths[e] = float("nan")
        else:
            lengths[e] = float(finite[0] if rest == "first" else np.median(finite))
    dist = {graph.root: 0.0}
    for n in graph.nodes[1:]:
        p = graph.parent[n]
        dist[n] = dist[p] + lengths[(p, n)]
    top = max(dist.values())
    if not np.isfinite(top) or top <= 1e-9:
        zone = {n: "root" for n in graph.nodes}
    else:
        zone = {n: zone_of(d / top) for n, d in dist.items()}
    return Geometry(rest_length_px=lengths, root_distance_px=dist, zone=zone)
