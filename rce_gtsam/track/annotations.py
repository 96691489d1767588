"""First-frame annotations: the pixel positions of the nodes to track.

JSON format: ``{"points": [[x, y], ...]}``, pixels in the first frame (x right, y down, pixel centres
at integer coordinates as OpenCV uses); the point id is the list index.

:func:`place_nodes_along_polyline` places N nodes evenly (by arc length) along a polyline the user
clicked, and :func:`write_annotation_files` writes the annotation and chain-graph JSON files.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..fileio import write_text_atomic
from ..graph import BranchGraph


def validate_points(points, source: str | Path = "<points>", image_size: tuple[int, int] | None = None) -> np.ndarray:
    """Check and return ``points`` as a float (P, 2) array; ``image_size`` is ``(W, H)`` pixels.

    A point must be finite and, if ``image_size`` is given, inside the image
    (``-0.5 <= x <= W - 0.5``, the outer edges of the border pixels).
    """
    try:
        arr = np.asarray(points, dtype=float)
    except (TypeError, ValueError):
        raise InputError(source, "'points' must be a list of [x, y] number pairs") from None
    if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] == 0:
        raise InputError(source, f"'points' must be a non-empty list of [x, y] pairs, got shape {arr.shape}")
    bad = ~np.isfinite(arr).all(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise InputError(source, f"point {i} is not finite: {arr[i].tolist()}", f"point {i}")
    if image_size is not None:
        w, h = image_size
        out = (arr[:, 0] < -0.5) | (arr[:, 0] > w - 0.5) | (arr[:, 1] < -0.5) | (arr[:, 1] > h - 0.5)
        if out.any():
            i = int(np.flatnonzero(out)[0])
            raise InputError(source, f"point {i} at (x={arr[i, 0]:g}, y={arr[i, 1]:g}) is outside the "
                                     f"{w}x{h} image", f"point {i}")
    return arr


def load_annotations(path: str | Path, image_size: tuple[int, int] | None = None) -> np.ndarray:
    """Read ``{"points": [[x, y], ...]}`` into a (P, 2) float array (row = point id).

    ``image_size`` ``(W, H)``: also check every point lies inside the image.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "annotations file not found")
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise InputError(path, f"not valid JSON: {exc.msg}", f"line {exc.lineno}, column {exc.colno}") from None
    if not isinstance(data, dict) or "points" not in data:
        raise InputError(path, 'expected a JSON object {"points": [[x, y], ...]}')
    pts = data["points"]
    if not isinstance(pts, list) or not all(isinstance(p, list) and len(p) == 2 for p in pts):
        raise InputError(path, "'points' must be a list of [x, y] pairs")
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for p in pts for v in p):
        raise InputError(path, "every coordinate must be a number")
    return validate_points(pts, path, image_size)


def parse_polyline(text: str) -> np.ndarray:
    """Parse ``"x1,y1,x2,y2,..."`` into a (K, 2) array (K >= 2)."""
    try:
        vals = [float(v) for v in text.replace(";", ",").split(",") if v.strip()]
    except ValueError:
        raise InputError("--polyline", f"expected comma-separated numbers x1,y1,x2,y2,..., got {text!r}") from None
    if len(vals) < 4 or len(vals) % 2:
        raise InputError("--polyline", f"need an even number (>= 4) of coordinates, got {len(vals)}")
    return np.asarray(vals).reshape(-1, 2)


def place_nodes_along_polyline(polyline, n_nodes: int) -> tuple[np.ndarray, BranchGraph]:
    """Place ``n_nodes`` evenly spaced (by arc length) nodes along ``polyline`` (K, 2) pixels.

    The first node sits on the polyline's first vertex (the base, which becomes the graph root), the
    last on its final vertex. Returns ``(points (n_nodes, 2), chain graph 0 -> 1 -> ... -> n-1)``.
    """
    poly = validate_points(polyline, "polyline")
    if poly.shape[0] < 2:
        raise InputError("polyline", "a polyline needs at least 2 vertices")
    if not isinstance(n_nodes, (int, np.integer)) or n_nodes < 2:
        raise InputError("polyline", f"the number of nodes must be an integer >= 2, got {n_nodes!r}")
    seg = np.hypot(*np.diff(poly, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    if s[-1] <= 0:
        raise InputError("polyline", "the polyline has zero length")
    # Remove zero-length segments so arc length is strictly increasing for interpolation.
    keep = np.concatenate([[True], seg > 0])
    s, poly = s[keep], poly[keep]
    t = np.linspace(0.0, s[-1], int(n_nodes))
    pts = np.column_stack([np.interp(t, s, poly[:, 0]), np.interp(t, s, poly[:, 1])])
    graph = BranchGraph.from_edges(0, [[i, i + 1] for i in range(int(n_nodes) - 1)], source="polyline")
    return pts, graph


def write_annotation_files(points, graph: BranchGraph, annotations_path: str | Path, graph_path: str | Path) -> None:
    """Write ``{"points": ...}`` and ``{"root": ..., "edges": ...}`` JSON files, each atomically."""
    pts = validate_points(points)
    rows = ",\n".join(f"  [{round(float(x), 3)}, {round(float(y), 3)}]" for x, y in pts)
    write_text_atomic('{"points": [\n' + rows + "\n]}\n", Path(annotations_path))
    write_text_atomic(json.dumps(graph.to_json()) + "\n", Path(graph_path))
