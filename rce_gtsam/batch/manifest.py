"""The batch manifest: one recording per CSV row, validated before any work starts.

Columns (header row required, names case-sensitive):

* ``id`` — the recording's name; its outputs go to ``OUT/<id>/``. Letters, digits, ``.``, ``_``, ``-``;
  unique; not starting with a dot.
* ``video`` (with ``annotations``) **or** ``tracks`` — per row exactly one of the two inputs: a video
  (mp4/avi/..., RealSense .bag/.db3) with its first-frame annotations JSON (tracked, then analyzed, like
  ``rce run``), or a tracks CSV (analyzed and diagnosed like ``rce analyze`` + ``rce diagnose``).
* ``graph`` — the branch graph JSON.
* ``preset`` (optional) — ``default`` or ``paper``; empty = the batch's ``--preset``.
* any further column is metadata (plant, species, treatment, ...) carried into the summary.

Relative paths are relative to the manifest's folder. Every problem is an
:class:`~rce_gtsam.errors.InputError` naming the manifest, the row (as a spreadsheet numbers it: the header
is row 1) and the column.
"""

from __future__ import annotations

import csv
import re
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import InputError
from ..presets import PRESETS

#: Columns with a meaning; every other column is metadata.
PIPELINE_COLUMNS = ("id", "video", "annotations", "tracks", "graph", "preset")
#: Column names of ``summary.csv`` that a metadata column may not take.
SUMMARY_NAMES = ("status", "kind", "verdict", "error", "parent", "child", "depth", "zone", "root_distance_px",
                 "rest_length_px", "kappa", "kappa_ci_low", "kappa_ci_high", "uncertainty", "quality", "direction",
                 "relative_stiffness", "n_frames", "fit_rmse_deg", "fit_r2", "bend_rms_deg")
_ID = re.compile(r"[A-Za-z0-9_][A-Za-z0-9._-]*")
_RESERVED_IDS = {"summary.csv", "summary.json", "figures", "batch.rrd"}


@dataclass(frozen=True)
class Recording:
    """One manifest row. Paths are absolute. ``kind`` is ``"video"`` (video + annotations are set) or
    ``"tracks"`` (tracks is set). ``preset``: a preset name, or None for the batch default.
    ``metadata``: the extra columns in manifest order (strings). ``row``: the spreadsheet row number."""

    id: str
    graph: Path
    row: int
    video: Path | None = None
    annotations: Path | None = None
    tracks: Path | None = None
    preset: str | None = None
    metadata: dict[str, str] = field(default_factory=dict)

    @property
    def kind(self) -> str:
        return "video" if self.video is not None else "tracks"

    @property
    def input_files(self) -> dict[str, Path]:
        """The files this recording reads, by column name."""
        names = ("video", "annotations", "graph") if self.kind == "video" else ("tracks", "graph")
        return {n: getattr(self, n) for n in names}


@dataclass(frozen=True)
class Manifest:
    """A validated manifest: its path, the recordings in row order and the metadata column names."""

    path: Path
    recordings: tuple[Recording, ...]
    metadata_columns: tuple[str, ...]


def load_manifest(path: str | Path) -> Manifest:
    """Read and validate a manifest CSV (see the module docstring); raises :class:`InputError`."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "manifest not found" if not path.exists() else "manifest is not a file")
    try:
        with path.open(newline="", encoding="utf-8-sig") as f:
            rows = list(csv.reader(f))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise InputError(path, f"cannot read the manifest as CSV: {exc}") from None
    rows = [r for r in rows if any(c.strip() for c in r)]
    if not rows:
        raise InputError(path, "the manifest is empty; expected a header such as 'id,tracks,graph' and one "
                               "row per recording")
    header = [c.strip() for c in rows[0]]
    dup = sorted({c for c in header if header.count(c) > 1})
    if dup:
        raise InputError(path, f"column {dup[0]!r} appears more than once", "row 1")
    if "" in header:
        raise InputError(path, f"column {header.index('') + 1} of the header has no name", "row 1")
    for need in ("id", "graph"):
        if need not in header:
            raise InputError(path, f"no {need!r} column; the header is {','.join(header)} (need id, video + "
                                   "annotations or tracks, graph)", "row 1")
    if "video" not in header and "tracks" not in header:
        raise InputError(path, "neither a 'video' nor a 'tracks' column; every recording needs one of them",
                         "row 1")
    if "video" in header and "annotations" not in header:
        raise InputError(path, "a 'video' column needs an 'annotations' column (first-frame points JSON)",
                         "row 1")
    if len(rows) == 1:
        raise InputError(path, "the manifest has a header but no recordings")
    meta = tuple(c for c in header if c not in PIPELINE_COLUMNS)
    clash = [c for c in meta if c in SUMMARY_NAMES]
    if clash:
        raise InputError(path, f"metadata column {clash[0]!r} would clash with a column of summary.csv; rename it "
                               f"(taken: {', '.join(SUMMARY_NAMES)})", "row 1")
    base = path.parent
    recordings, seen = [], {}
    for k, raw in enumerate(rows[1:]):
        row_no = k + 2
        if len(raw) > len(header):
            raise InputError(path, f"{len(raw)} fields but the header has {len(header)} columns", f"row {row_no}")
        cells = {c: (raw[i].strip() if i < len(raw) else "") for i, c in enumerate(header)}
        recordings.append(_recording(path, base, row_no, cells, meta, seen))
    return Manifest(path=path, recordings=tuple(recordings), metadata_columns=meta)


def _recording(path: Path, base: Path, row_no: int, cells: dict, meta: tuple, seen: dict) -> Recording:
    def fail(column: str, message: str):
        raise InputError(path, message, f"row {row_no}, column {column!r}")

    rid = cells["id"]
    if not rid:
        fail("id", "empty id; every recording needs a name (its output folder)")
    if not _ID.fullmatch(rid) or rid in _RESERVED_IDS:
        fail("id", f"id {rid!r} cannot name an output folder: use letters, digits, '.', '_' and '-', not "
                   f"starting with '.' or '-', and none of {sorted(_RESERVED_IDS)}")
    if rid in seen:
        fail("id", f"id {rid!r} is already used by row {seen[rid]}")
    seen[rid] = row_no
    video, tracks = cells.get("video", ""), cells.get("tracks", "")
    if video and tracks:
        fail("tracks", "both 'video' and 'tracks' are given; a row needs exactly one of them")
    if not video and not tracks:
        fail("tracks" if "tracks" in cells else "video", "neither 'video' nor 'tracks' is given; a row needs "
                                                         "exactly one of them")

    def existing(column: str) -> Path:
        text = cells.get(column, "")
        if not text:
            fail(column, f"empty {column!r}; this row needs it")
        p = Path(text).expanduser()
        p = p if p.is_absolute() else base / p
        if not p.is_file():
            fail(column, f"{'not a file' if p.exists() else 'file not found'}: {p}")
        return p.resolve()

    preset = cells.get("preset", "") or None
    if preset is not None and preset not in PRESETS:
        fail("preset", f"unknown preset {preset!r}; choose one of {', '.join(sorted(PRESETS))} or leave it empty")
    common = dict(id=rid, graph=existing("graph"), row=row_no, preset=preset,
                  metadata={c: cells[c] for c in meta})
    if video:
        return Recording(video=existing("video"), annotations=existing("annotations"), **common)
    return Recording(tracks=existing("tracks"), **common)
