"""Point tracks: image positions of every graph node in every video frame.

CSV format (one row per observed (point, frame)): ``point_id,frame,x,y`` in pixels, with optional
``visible`` (0/1; a 0 row counts as not observed) and ``sigma_px`` (per-observation 1-sigma
position noise in pixels). An absent row means the point was not observed in that frame.

In memory, :class:`Tracks` is dense: ``xy[i, f]`` is node ``node_ids[i]`` at frame ``f``
(frames 0..n_frames-1), NaN where not observed.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from .errors import InputError
from .fileio import temp_file_beside
from .graph import BranchGraph

REQUIRED_COLUMNS = ("point_id", "frame", "x", "y")
#: A node observed in fewer frames than this cannot be smoothed (its course between observations is free) and
#: gives no bending series: its bends are dropped (``Tracks.lost_nodes``), the rest of the branch goes on.
MIN_OBSERVED = 2
OPTIONAL_COLUMNS = ("visible", "sigma_px")


@dataclass(frozen=True, eq=False)
class Tracks:
    """Dense tracks of the graph nodes.

    Attributes
    ----------
    node_ids: (N,) int — node ids, in the graph's breadth-first order.
    xy: (N, F, 2) float — pixel positions (x right, y down); NaN where not observed.
    sigma_px: (N, F) float or None — per-observation 1-sigma noise in pixels (NaN where not observed).
    source: where the tracks came from (file path or description), for error messages.
    lost_nodes: nodes observed in fewer than :data:`MIN_OBSERVED` frames (e.g. only in the annotated first
    frame): kept for the geometry (their observed frame gives the rest lengths), but every bend through them
    is dropped from the fit and reported as ``tracking_lost`` (:func:`rce_gtsam.pipeline.analyze`).
    """

    node_ids: np.ndarray
    xy: np.ndarray
    sigma_px: np.ndarray | None = None
    source: str = field(default="<tracks>")
    lost_nodes: tuple[int, ...] = ()

    def __post_init__(self):
        xy = np.asarray(self.xy, dtype=float)
        if xy.ndim != 3 or xy.shape[2] != 2 or xy.shape[0] != len(self.node_ids):
            raise InputError(self.source, f"xy must have shape (n_nodes={len(self.node_ids)}, n_frames, 2), got {xy.shape}")
        object.__setattr__(self, "xy", xy)
        object.__setattr__(self, "node_ids", np.asarray(self.node_ids, dtype=int))

    @property
    def n_nodes(self) -> int:
        return self.xy.shape[0]

    @property
    def n_frames(self) -> int:
        return self.xy.shape[1]

    @property
    def observed(self) -> np.ndarray:
        """(N, F) bool: True where the node was observed."""
        return np.isfinite(self.xy).all(axis=2)

    def index(self, node: int) -> int:
        """Row of ``node`` in the arrays."""
        hits = np.flatnonzero(self.node_ids == node)
        if hits.size == 0:
            raise KeyError(f"node {node} is not in these tracks")
        return int(hits[0])

    def of(self, node: int) -> np.ndarray:
        """(F, 2) positions of one node."""
        return self.xy[self.index(node)]

    def to_frame(self) -> pd.DataFrame:
        """Long table ``point_id, frame, x, y[, sigma_px]`` of the observed entries."""
        n, f = np.nonzero(self.observed)
        df = pd.DataFrame({"point_id": self.node_ids[n], "frame": f,
                           "x": self.xy[n, f, 0], "y": self.xy[n, f, 1]})
        if self.sigma_px is not None:
            df["sigma_px"] = self.sigma_px[n, f]
        return df.sort_values(["point_id", "frame"], kind="stable").reset_index(drop=True)


def _fail(path, msg, row=None):
    # CSV row numbers as a spreadsheet shows them: header is line 1, first data row line 2.
    raise InputError(path, msg, None if row is None else f"line {int(row) + 2}")


#: Leading bytes of files users mistake for a tracks CSV (the video, a figure, an archive), and what they are.
_MAGIC = ((b"\x89PNG", "a PNG image"), (b"\xff\xd8\xff", "a JPEG image"), (b"GIF8", "a GIF image"),
          (b"RIFF", "a RIFF file (AVI video or WAV audio)"), (b"\x1aE\xdf\xa3", "a Matroska/WebM video"),
          (b"PK\x03\x04", "a ZIP archive"), (b"%PDF", "a PDF document"), (b"#ROSBAG", "a ROS bag recording"),
          (b"SQLite format 3", "an SQLite database (ROS 2 .db3 recording?)"), (b"\x1f\x8b", "a gzip archive"))


def _not_text(path: Path) -> str | None:
    """What ``path`` is when it is plainly not a text CSV (an image, a video, an archive, or binary or non-UTF-8
    bytes), else None. Reads the first 4 KiB."""
    with open(path, "rb") as f:
        head = f.read(4096)
    for magic, what in _MAGIC:
        if head.startswith(magic):
            return what
    if head[4:8] == b"ftyp":
        return "an MP4/MOV video"
    if b"\x00" in head:
        return "a binary file"
    try:
        head.decode("utf-8")
    except UnicodeDecodeError as exc:
        if exc.start < len(head) - 4:  # not merely a multi-byte character cut at 4 KiB
            return f"not UTF-8 text (byte {exc.start})"
    return None


def read_tracks_table(path: str | Path) -> pd.DataFrame:
    """Read and validate a tracks CSV into a table (no graph needed). Raises :class:`InputError`."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "tracks file not found" + (" (it is a folder)" if path.is_dir() else ""))
    if path.stat().st_size == 0:
        raise InputError(path, "the tracks file is empty; expected a header 'point_id,frame,x,y' and one row per observation")
    what = _not_text(path)
    if what is not None:
        raise InputError(path, f"this is {what}, not a tracks CSV; expected a text table with the header "
                               "'point_id,frame,x,y' (as `rce track` writes it)")
    try:
        df = pd.read_csv(path, dtype=str, keep_default_na=False, skipinitialspace=True)
    except UnicodeDecodeError as exc:
        raise InputError(path, f"not a UTF-8 text CSV (byte {exc.start}); expected a tracks CSV with the header "
                               "'point_id,frame,x,y'") from None
    except pd.errors.EmptyDataError:
        raise InputError(path, "the tracks file is empty; expected a header 'point_id,frame,x,y'") from None
    except pd.errors.ParserError as exc:
        raise InputError(path, f"not a valid CSV: {exc}") from None
    df.columns = [c.strip() for c in df.columns]
    missing = [c for c in REQUIRED_COLUMNS if c not in df.columns]
    if missing:
        raise InputError(path, f"missing column(s) {missing}; found {list(df.columns)}; "
                               "required: point_id,frame,x,y (optional: visible,sigma_px)")
    if len(df) == 0:
        raise InputError(path, "the tracks file has a header but no rows")
    out = pd.DataFrame(index=df.index)
    for col, kind in (("point_id", "int"), ("frame", "int"), ("x", "float"), ("y", "float"),
                      ("visible", "bool"), ("sigma_px", "float")):
        if col not in df.columns:
            continue
        raw = df[col].str.strip()
        num = pd.to_numeric(raw, errors="coerce")
        bad = num.isna() & ~raw.str.lower().isin(["nan"] if kind == "float" else [])
        if kind == "float":
            bad = bad | (num.isna() & raw.eq(""))
        if bad.any():
            r = int(np.flatnonzero(bad.to_numpy())[0])
            _fail(path, f"column '{col}' has a non-numeric value {df[col].iloc[r]!r}", r)
        values = num.to_numpy(dtype=float)
        if kind == "int" or kind == "bool":
            nonint = ~np.isfinite(values) | (values != np.round(values))
            if nonint.any():
                r = int(np.flatnonzero(nonint)[0])
                _fail(path, f"column '{col}' must hold integers, got {df[col].iloc[r]!r}", r)
            if col == "frame" and (values < 0).any():
                r = int(np.flatnonzero(values < 0)[0])
                _fail(path, f"frame must be >= 0, got {df[col].iloc[r]!r}", r)
            if kind == "bool" and not np.isin(values, (0, 1)).all():
                r = int(np.flatnonzero(~np.isin(values, (0, 1)))[0])
                _fail(path, f"'visible' must be 0 or 1, got {df[col].iloc[r]!r}", r)
            out[col] = values.astype(np.int64)
        else:
            if not np.isfinite(values).all():
                r = int(np.flatnonzero(~np.isfinite(values))[0])
                _fail(path, f"column '{col}' must be finite, got {df[col].iloc[r]!r}", r)
            if col == "sigma_px" and (values <= 0).any():
                r = int(np.flatnonzero(values <= 0)[0])
                _fail(path, f"sigma_px must be > 0 pixels, got {df[col].iloc[r]!r}", r)
            out[col] = values
    first = int(out["frame"].min())
    if first != 0:
        r = int(np.argmin(out["frame"].to_numpy()))
        _fail(path, f"the first frame is {first}, not 0: frame labels are video frame indices counted from the "
                    f"first frame of the clip, and no rows are invented for frames 0..{first - 1}; renumber the "
                    f"frames (frame - {first}) or export the tracks from the start of the video", r)
    dup = out.duplicated(["point_id", "frame"], keep="first")
    if dup.any():
        r = int(np.flatnonzero(dup.to_numpy())[0])
        _fail(path, f"duplicate row for point {out['point_id'].iloc[r]} at frame {out['frame'].iloc[r]}", r)
    return out


def tracks_from_table(table: pd.DataFrame, graph: BranchGraph, source: str = "<tracks>") -> Tracks:
    """Turn a validated long table into dense :class:`Tracks` for the graph's nodes.

    Points not in the graph are ignored. A graph node without any visible row is an error (the tracks and the
    graph do not belong together); one observed in fewer than :data:`MIN_OBSERVED` frames is kept as a lost
    node (``Tracks.lost_nodes``): its bends are dropped from the fit, not the whole run.
    """
    if "visible" in table.columns:
        table = table[table["visible"] == 1]
    nodes = list(graph.nodes)
    table = table[table["point_id"].isin(nodes)]
    counts = table.groupby("point_id").size()
    for n in nodes:
        c = int(counts.get(n, 0))
        if c == 0:
            raise InputError(source, f"graph node {n} has no tracks (no visible rows with point_id {n}); "
                                     f"graph file: {graph.source}", f"node {n}")
    lost = tuple(int(n) for n in nodes if int(counts.get(n, 0)) < MIN_OBSERVED)
    n_frames = int(table["frame"].max()) + 1
    row = {n: i for i, n in enumerate(nodes)}
    xy = np.full((len(nodes), n_frames, 2), np.nan)
    ii = table["point_id"].map(row).to_numpy()
    ff = table["frame"].to_numpy()
    xy[ii, ff, 0] = table["x"].to_numpy()
    xy[ii, ff, 1] = table["y"].to_numpy()
    sigma = None
    if "sigma_px" in table.columns:
        sigma = np.full((len(nodes), n_frames), np.nan)
        sigma[ii, ff] = table["sigma_px"].to_numpy()
    return Tracks(node_ids=np.array(nodes), xy=xy, sigma_px=sigma, source=source, lost_nodes=lost)


def lost_nodes(tracks: Tracks) -> tuple[int, ...]:
    """Nodes observed in fewer than :data:`~rce_gtsam.tracks.MIN_OBSERVED` frames (``Tracks.lost_nodes``, and
    any such node of tracks made in code): their bends are dropped from the fit."""
    few = {int(n) for n, c in zip(tracks.node_ids, tracks.observed.sum(axis=1)) if c < MIN_OBSERVED}
    return tuple(sorted(set(tracks.lost_nodes) | few))


def dropped_edges(graph: BranchGraph, lost) -> list[tuple[int, int]]:
    """The segments (the downstream edge of each bend) whose bend runs through a lost node."""
    lost = set(lost)
    return [b.edge for b in graph.bends if lost & set(b.nodes)]


def load_tracks(path: str | Path, graph: BranchGraph) -> Tracks:
    """Read, validate and densify a tracks CSV for the nodes of ``graph``."""
    return tracks_from_table(read_tracks_table(path), graph, source=str(path))


def write_table_atomic(df: pd.DataFrame, path: str | Path) -> None:
    """Write a CSV so that a reader never sees a half-written file."""
    path = Path(path)
    tmp = temp_file_beside(path)
    try:
        df.to_csv(tmp, index=False)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
