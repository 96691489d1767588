"""Planar geometry of the simulated branch: its graph and rest shape, forward kinematics, the signed turning
angles, and the placement in the image (pixels, x right, y down; angles in degrees)."""

from __future__ import annotations

import math

import numpy as np

from ..graph import BranchGraph


def turning_angles_deg(xy: np.ndarray, node_ids, bends) -> np.ndarray:
    """Signed turning angles (E, F) in degrees at each bend: atan2(cross(u, v), dot(u, v)),
    u = p_j - p_g, v = p_c - p_j; ``xy`` is (N, F, 2) with rows in ``node_ids`` order. NaN propagates."""
    row = {int(n): i for i, n in enumerate(node_ids)}
    g = xy[[row[b.grandparent] for b in bends]]
    j = xy[[row[b.joint] for b in bends]]
    c = xy[[row[b.child] for b in bends]]
    u, v = j - g, c - j
    cross = u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]
    dot = (u * v).sum(-1)
    return np.degrees(np.arctan2(cross, dot))


def build_graph(n: int, layout: str, rng: np.random.Generator) -> tuple[BranchGraph, dict[tuple[int, int], float]]:
    """Topology of ``n`` nodes (``layout`` ``"chain"`` or ``"tree"``: see
    :class:`~rce_gtsam.sim.simulate.SimulationConfig`) and the rest turning angle (degrees) of every non-root edge."""
    if layout == "chain":
        edges = [(i, i + 1) for i in range(n - 1)]
        side: list[tuple[int, int]] = []
    else:
        k = max(2, n // 4)
        m = n - k
        edges = [(i, i + 1) for i in range(m - 1)]
        attach = max(2, int(round(0.4 * m)))
        side = [(attach, m)] + [(m + i, m + i + 1) for i in range(k - 1)]
        edges += side
    graph = BranchGraph.from_edges(0, edges, source="simulated branch")
    bow = rng.uniform(15, 45) * rng.choice([-1, 1])  # total rest curvature of the main axis (degrees)
    n_bends = len(graph.bends)
    rest = {}
    for b in graph.bends:
        rest[b.edge] = bow / n_bends + rng.normal(0, 3.0)
    if side:
        rest[side[0]] = -np.sign(bow) * rng.uniform(25, 45)  # the side branch leaves at an angle
    return graph, rest


def forward_kinematics(graph: BranchGraph, lengths: dict, root_heading_rad: np.ndarray,
                       turn_deg: dict) -> np.ndarray:
    """Node positions (N, F, 2) in graph.nodes order, root at the origin.

    ``root_heading_rad`` (F,): heading of every root edge (atan2 convention in image coordinates);
    ``turn_deg[(j, c)]`` (F,): total turning angle (rest + deviation) of edge (j, c) relative to its
    parent edge; ``lengths[(p, c)]``: segment length in pixels.
    """
    F = len(root_heading_rad)
    row = {nid: i for i, nid in enumerate(graph.nodes)}
    pos = np.zeros((len(graph.nodes), F, 2))
    heading: dict[int, np.ndarray] = {}
    for c in graph.nodes[1:]:
        p = graph.parent[c]
        h = root_heading_rad if p == graph.root else heading[p] + np.radians(turn_deg[(p, c)])
        heading[c] = h
        pos[row[c]] = pos[row[p]] + lengths[(p, c)] * np.stack([np.cos(h), np.sin(h)], axis=-1)
    return pos


def root_distances(graph: BranchGraph, lengths: dict) -> dict[int, float]:
    d = {graph.root: 0.0}
    for c in graph.nodes[1:]:
        d[c] = d[graph.parent[c]] + lengths[(graph.parent[c], c)]
    return d


def place_in_image(pos: np.ndarray, image_size, rng, margin: float = 30.0) -> tuple[np.ndarray, float, np.ndarray]:
    """Rotate (about the root) and translate positions so that every frame fits the image.

    Tries headings in 5-degree steps and keeps the fitting one closest to a seeded preferred direction
    (upward-diagonal, like a branch leaving a stem); if none fits, the shape is scaled down.
    Returns (positions, rotation in radians, root pixel position).
    """
    w, h = image_size
    avail = np.array([w - 2 * margin, h - 2 * margin])
    pref = np.radians(rng.uniform(-150, -30))  # image y is down: negative = upward
    chord = pos[:, 0].mean(axis=0)
    chord_ang = math.atan2(chord[1], chord[0]) if np.linalg.norm(chord) > 0 else 0.0
    best = None
    for rot in np.radians(np.arange(0, 360, 5)):
        cr, sr = math.cos(rot), math.sin(rot)
        p = pos @ np.array([[cr, sr], [-sr, cr]])
        size = p.reshape(-1, 2).max(0) - p.reshape(-1, 2).min(0)
        fit = float(np.min(avail / np.maximum(size, 1e-9)))
        dang = abs((chord_ang + rot - pref + np.pi) % (2 * np.pi) - np.pi)
        key = (min(fit, 1.0), -dang)
        if best is None or key > best[0]:
            best = (key, rot, p, fit)
    _, rot, p, fit = best
    if fit < 1.0:
        p = p * fit
    flat = p.reshape(-1, 2)
    centre = (flat.max(0) + flat.min(0)) / 2
    root_px = np.array([w / 2, h / 2]) - centre
    return p + root_px, float(rot), root_px
