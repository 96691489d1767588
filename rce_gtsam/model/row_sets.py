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


def walk_order(s: np.ndarray, shared: np.ndarray, edge_nodes=None) -> np.ndarray:
    """The rows in the order of a walk along the branch: depth first over rows that share a tracked node, at every
    step to the row sharing the most nodes with this one (the next bend along the same stem shares two; a bend
    across a fork shares one), then the nearest to the root, so each side branch comes as one run instead of
    interleaved with the main stem by root distance. ``edge_nodes``: per row, its tracked nodes (without them
    every shared node counts the same). On a chain it is root-distance order."""
    E = len(s)
    nodes = None if edge_nodes is None else [frozenset(n) for n in edge_nodes]
    seen = np.zeros(E, bool)
    out = []
    for start in np.argsort(s, kind="stable"):
        stack = [int(start)]
        while stack:
            r = stack.pop()
            if seen[r]:
                continue
            seen[r] = True
            out.append(r)
            nxt = [int(q) for q in np.flatnonzero(shared[r] & ~seen)]
            overlap = {q: 1 if nodes is None else len(nodes[r] & nodes[q]) for q in nxt}
            # pushed worst first, so the best is popped next
            stack.extend(sorted(nxt, key=lambda q: (overlap[q], -s[q], -q)))
    return np.array(out, int)


def node_disjoint_split(s: np.ndarray, shared: np.ndarray, seed: int, run: int = 3, edge_nodes=None):
    """Two sets of rows (A, B) with no tracked node in common, both spanning root to tip, or None.

    Rows in the order of a walk along the branch (:func:`walk_order`, which ``edge_nodes`` guide: root-distance
    order on a chain, each side branch as one run on a tree) are dealt in the repeating pattern A^m, gap, gap,
    B^m, gap, gap (m = ``run``, reduced to 2 or 1 for short branches; the phase of the pattern drawn with
    ``seed``); B rows that still share a node with an A row are dropped. The two gap rows separate the runs
    because bends up to two joints apart share a node (see :func:`shared_node_matrix`). Held-out latents estimated on A therefore carry none of
    the tracking noise of the B rows they are scored on. Rows that share no node at all (``edge_nodes`` says
    so) get the plain interleaved halves of :func:`edge_halves`.

    On a branched graph (the walk is not root-distance order) one pattern along the walk leaves rows idle at
    every fork, and the one the seed draws can leave too few (a 20-node tree with a 5-node side branch: no split
    at all, so the diagnosis fell back to halves that share nodes and ran none of its full-data tests). There
    every phase of each run length is dealt, the rows that share no node with the other set are added to a set
    (:func:`grow_disjoint`), and the deal whose smaller set is largest and spans most of the branch is kept
    (:func:`best_branched_split`; longer runs, then the seed's order of phases, break ties)."""
    E = len(s)
    if not (shared & ~np.eye(E, dtype=bool)).any():
        return edge_halves(s, seed)  # no two rows share a node: interleaved halves need no gap
    order = walk_order(s, shared, edge_nodes)
    rng = np.random.default_rng(seed)
    if not np.array_equal(order, np.argsort(s, kind="stable")):
        return best_branched_split(s, order, shared, rng, run)
    for m in range(run, 0, -1):
        period = 2 * m + 4
        phase = int(rng.integers(period))
        A, B = deal(order, shared, m, phase)
        if len(A) >= max(1, E // 5) and len(B) >= max(1, E // 5):
            return np.sort(A), np.sort(B)
    return None


def deal(order: np.ndarray, shared: np.ndarray, m: int, phase: int) -> tuple[np.ndarray, np.ndarray]:
    """Rows of ``order`` dealt A^m, gap, gap, B^m, gap, gap from ``phase``; B rows sharing a node with A dropped."""
    pos = (np.arange(len(order)) + phase) % (2 * m + 4)
    A = order[pos < m]
    B = order[(pos >= m + 2) & (pos < 2 * m + 2)]
    return A, np.array([b for b in B if not shared[b, A].any()], int)


def grow_disjoint(A: np.ndarray, B: np.ndarray, order: np.ndarray, shared: np.ndarray):
    """(A, B) with every idle row of ``order`` that shares no node with one set added to it (to the smaller set
    where it shares none with either), in walk order until none is left to add: the sets stay node-disjoint."""
    inA = np.zeros(len(order), bool)
    inB = np.zeros(len(order), bool)
    inA[A], inB[B] = True, True
    changed = True
    while changed:
        changed = False
        for r in order:
            if inA[r] or inB[r]:
                continue
            to_a, to_b = not shared[r, inB].any(), not shared[r, inA].any()
            if to_a and (not to_b or inA.sum() <= inB.sum()):
                inA[r] = changed = True
            elif to_b:
                inB[r] = changed = True
    return np.flatnonzero(inA), np.flatnonzero(inB)


def best_branched_split(s: np.ndarray, order: np.ndarray, shared: np.ndarray, rng: np.random.Generator,
                        run: int):
    """:func:`node_disjoint_split` on a branched graph: every phase of every run length, grown; kept: the deal
    whose smaller set is largest, weighted by the share of the root distances the narrower set spans (growing
    can fill a whole stretch of the stem into one set, and a set that covers only the middle of the branch
    cannot tell where along it an effect lies). None when no deal gives both sets a fifth of the rows."""
    E = len(order)
    full = max(float(np.ptp(s)), 1e-12)
    best, best_key = None, -1.0
    for m in range(run, 0, -1):
        for phase in rng.permutation(2 * m + 4):
            A, B = grow_disjoint(*deal(order, shared, m, int(phase)), order, shared)
            if min(len(A), len(B)) < max(1, E // 5):
                continue
            key = min(len(A), len(B)) * min(np.ptp(s[A]), np.ptp(s[B])) / full
            if key > best_key:
                best, best_key = (np.sort(A), np.sort(B)), key
    return best
