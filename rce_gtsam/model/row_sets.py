"""Two sets of a branch's rows (bends) whose tracking noise is independent: they share no tracked node.

A node's position error enters the three bends it belongs to (as child, joint and grandparent, with weights of
the pattern +1, -2, +1), so neighbouring bends carry correlated noise. Everything that estimates a per-frame
series on some rows and scores it on others (the diagnosis' held-out folds and tests, the choice among a fit's
starts in :mod:`rce_gtsam.model.starts`) uses sets from :func:`node_disjoint_split`. Rows are bends labelled
``"joint->child"``; root distances are normalised to 0..1.
"""

from __future__ import annotations

import numpy as np


def edge_halves(s: np.ndarray, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Two interleaved halves of the edges, stratified by root distance (random within each pair)."""
    order = np.argsort(s, kind="stable")
    rng = np.random.default_rng(seed)
    A, B = [], []
    for i in range(0, len(order), 2):
        pair = list(order[i:i + 2])
        if len(pair) == 2 and rng.uniform() < 0.5:
            pair.reverse()
        A.append(pair[0])
        if len(pair) == 2:
            B.append(pair[1])
    return np.array(sorted(A)), np.array(sorted(B))


#: The node that stands for a joint's parent when no row names it (the joint's parent is the root, whose
#: position the labels do not give): every row whose parent it is counts as sharing it.
UNKNOWN_PARENT = "\0root?"


def edge_nodes_from_labels(labels) -> list[frozenset] | None:
    """The tracked nodes whose position errors enter each row, from ``"joint->child"`` labels, or None.

    Row (j, c) is the bend at joint j between the segments (parent(j), j) and (j, c): its angle is computed
    from three tracked nodes, {parent(j), j, c}. parent(j) is the joint of the row whose child is j; when no
    row has child j (j's parent is the root), a shared placeholder (:data:`UNKNOWN_PARENT`) stands for it —
    conservative: every such row is treated as sharing that node."""
    pairs = []
    for lab in labels:
        parts = str(lab).split("->")
        if len(parts) != 2 or not parts[0].strip() or not parts[1].strip():
            return None
        pairs.append((parts[0].strip(), parts[1].strip()))
    parent = {c: j for j, c in pairs}
    return [frozenset({parent.get(j, UNKNOWN_PARENT), j, c}) for j, c in pairs]


def shared_node_matrix(s: np.ndarray, edge_nodes=None) -> np.ndarray:
    """(E, E) bool: rows whose bend angles share a tracked node (diagonal True).

    A node's tracking error enters the three bends it belongs to (as child, joint and grandparent, with
    weights of the pattern +1, -2, +1), so the noise of such rows is correlated — anti-correlated for
    neighbours. Without node information the rows are taken to form a chain in root-distance order
    (rows up to two places apart share a node)."""
    E = len(s)
    if edge_nodes is not None:
        nodes = [frozenset(n) for n in edge_nodes]
        return np.array([[bool(nodes[i] & nodes[j]) for j in range(E)] for i in range(E)])
    rank = np.empty(E, int)
    rank[np.argsort(s, kind="stable")] = np.arange(E)
    return np.abs(rank[:, None] - rank[None, :]) <= 2


def node_disjoint_split(s: np.ndarray, shared: np.ndarray, seed: int, run: int = 3):
    """Two sets of rows (A, B) with no tracked node in common, both spanning root to tip, or None.

    Rows in root-distance order are dealt in the repeating pattern A^m, gap, gap, B^m, gap, gap (m = ``run``,
    reduced to 2 or 1 for short branches; the phase of the pattern drawn with ``seed``); B rows that still
    share a node with an A row (trees, where root-distance order interleaves branches) are dropped. The
    two gap rows separate the runs because bends up to two joints apart share a node (see
    :func:`shared_node_matrix`). Held-out latents estimated on A therefore carry none of the tracking noise
    of the B rows they are scored on. Rows that share no node at all (``edge_nodes`` says so) get the plain
    interleaved halves of :func:`edge_halves`."""
    E = len(s)
    if not (shared & ~np.eye(E, dtype=bool)).any():
        return edge_halves(s, seed)  # no two rows share a node: interleaved halves need no gap
    order = np.argsort(s, kind="stable")
    rng = np.random.default_rng(seed)
    for m in range(run, 0, -1):
        period = 2 * m + 4
        phase = int(rng.integers(period))
        pos = (np.arange(E) + phase) % period
        A = order[pos < m]
        B = order[(pos >= m + 2) & (pos < 2 * m + 2)]
        B = np.array([b for b in B if not shared[b, A].any()], int)
        if len(A) >= max(1, E // 5) and len(B) >= max(1, E // 5):
            return np.sort(A), np.sort(B)
    return None
