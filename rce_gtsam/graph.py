"""The branch graph: a rooted tree of tracked nodes, edges directed root -> tip.

JSON format: ``{"root": id, "edges": [[parent, child], ...]}`` with integer node ids.
A *bend* is a (grandparent, joint, child) triplet; it is attributed to the downstream edge
(joint -> child), so the root edge never has a bend.
"""

from __future__ import annotations

import json
from collections import deque
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

from .errors import InputError


@dataclass(frozen=True)
class Bend:
    """A (grandparent, joint, child) triplet; its angle is measured at ``joint``."""

    grandparent: int
    joint: int
    child: int

    @property
    def edge(self) -> tuple[int, int]:
        """The downstream edge (joint, child) this bend is attributed to."""
        return (self.joint, self.child)

    @property
    def nodes(self) -> tuple[int, int, int]:
        return (self.grandparent, self.joint, self.child)


@dataclass(frozen=True)
class BranchGraph:
    """A validated rooted tree. Build it with :func:`load_graph` or :meth:`from_edges`."""

    root: int
    edges: tuple[tuple[int, int], ...]
    source: str = field(default="<graph>", compare=False)

    @classmethod
    def from_edges(cls, root: int, edges, source: str = "<graph>") -> "BranchGraph":
        """Validate ``edges`` (pairs parent, child) as a tree rooted at ``root``."""
        clean: list[tuple[int, int]] = []
        for i, e in enumerate(edges):
            if not isinstance(e, (list, tuple)) or len(e) != 2:
                raise InputError(source, f"an edge must be a [parent, child] pair, got {e!r}", f"edge {i}")
            p, c = e
            if not all(isinstance(v, int) and not isinstance(v, bool) for v in (p, c)):
                raise InputError(source, f"node ids must be integers, got {e!r}", f"edge {i}")
            if p == c:
                raise InputError(source, f"self-loop on node {p}", f"edge {i} [{p}, {c}]")
            clean.append((int(p), int(c)))
        if not isinstance(root, int) or isinstance(root, bool):
            raise InputError(source, f"'root' must be an integer node id, got {root!r}")
        if not clean:
            raise InputError(source, "the graph has no edges; at least one [parent, child] edge is needed")
        if len(set(clean)) != len(clean):
            dup = next(e for e in clean if clean.count(e) > 1)
            raise InputError(source, "duplicate edge", f"edge {list(dup)}")
        parents: dict[int, int] = {}
        for p, c in clean:
            if c in parents:
                raise InputError(source, f"node {c} has two parents ({parents[c]} and {p}); a branch graph must be a tree",
                                 f"node {c}")
            parents[c] = p
        if root in parents:
            raise InputError(source, f"the root {root} appears as a child of {parents[root]}", f"node {root}")
        nodes = {root} | {p for p, _ in clean} | {c for _, c in clean}
        roots = sorted(n for n in nodes if n not in parents)
        if roots != [root]:
            others = [n for n in roots if n != root]
            if root not in {p for p, _ in clean}:
                raise InputError(source, f"the root {root} is not the parent of any edge", f"node {root}")
            raise InputError(source, f"more than one root: {root} and {others} have no parent; "
                                     "every node but the root needs exactly one parent", f"node {others[0]}")
        graph = cls(root=root, edges=tuple(clean), source=source)
        unreachable = nodes - set(graph.nodes)
        if unreachable:
            raise InputError(source, f"nodes {sorted(unreachable)} are not reachable from the root {root} "
                                     "(the edges contain a cycle)", f"node {min(unreachable)}")
        return graph

    @cached_property
    def parent(self) -> dict[int, int]:
        """child id -> parent id."""
        return {c: p for p, c in self.edges}

    @cached_property
    def children(self) -> dict[int, tuple[int, ...]]:
        """node id -> child ids, in edge order."""
        out: dict[int, list[int]] = {}
        for p, c in self.edges:
            out.setdefault(p, []).append(c)
        return {k: tuple(v) for k, v in out.items()}

    @cached_property
    def nodes(self) -> tuple[int, ...]:
        """All node ids in breadth-first order from the root."""
        order, queue = [], deque([self.root])
        seen = {self.root}
        while queue:
            n = queue.popleft()
            order.append(n)
            for c in self.children.get(n, ()):
                if c not in seen:
                    seen.add(c)
                    queue.append(c)
        return tuple(order)

    @cached_property
    def depth(self) -> dict[int, int]:
        """Hop count from the root (root = 0)."""
        d = {self.root: 0}
        for n in self.nodes[1:]:
            d[n] = d[self.parent[n]] + 1
        return d

    @cached_property
    def bends(self) -> tuple[Bend, ...]:
        """Every (grandparent, joint, child) triplet, in breadth-first order of the joint."""
        out = []
        for j in self.nodes:
            if j == self.root:
                continue
            for c in self.children.get(j, ()):
                out.append(Bend(self.parent[j], j, c))
        return tuple(out)

    def path_to_root(self, node: int) -> list[int]:
        """Nodes from ``node`` up to and including the root."""
        path = [node]
        while path[-1] != self.root:
            path.append(self.parent[path[-1]])
        return path

    def to_json(self) -> dict:
        return {"root": self.root, "edges": [list(e) for e in self.edges]}


def load_graph(path: str | Path) -> BranchGraph:
    """Read and validate a branch-graph JSON file ``{"root": id, "edges": [[parent, child], ...]}``."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "graph file not found")
    text = path.read_text()
    if not text.strip():
        raise InputError(path, "the graph file is empty; expected {\"root\": id, \"edges\": [[parent, child], ...]}")
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(path, f"not valid JSON: {exc.msg}", f"line {exc.lineno}, column {exc.colno}") from None
    if not isinstance(data, dict):
        raise InputError(path, "expected a JSON object {\"root\": id, \"edges\": [[parent, child], ...]}")
    for key in ("root", "edges"):
        if key not in data:
            raise InputError(path, f"missing key '{key}'; expected {{\"root\": id, \"edges\": [[parent, child], ...]}}")
    if not isinstance(data["edges"], list):
        raise InputError(path, "'edges' must be a list of [parent, child] pairs")
    return BranchGraph.from_edges(data["root"], data["edges"], source=str(path))
