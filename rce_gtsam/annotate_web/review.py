"""The session behind ``rce review VIDEO TRACKS.csv``: scrub tracks, drag nodes to correct them, re-track, save.

Served by the same local server as ``rce annotate`` (:func:`~rce_gtsam.annotate_web.server.make_server`):

* ``GET /`` -- the review page (``static/review.html``); ``GET /frame/N.jpg`` -- frame N;
* ``GET /api/info`` -- video, size (px), frame count, fps, node ids, graph edges, the corrections loaded, the
  flag rules, the files it writes and the ``rce track`` command that reproduces them;
* ``GET /api/tracks`` -- the tracks shown (``xy`` P x F x 2 px, null where unknown; ``visible``; ``sigma`` px or
  null) and the flagged frames (runs of frames where a node is lost, has a large sigma or jumps; :mod:`..track.flags`);
* ``POST /api/retrack`` ``{"corrections": [{"frame", "node", "x", "y"}, ...]}`` -- re-track from these
  corrections (:func:`rce_gtsam.track.anchors.retrack`) and answer the new tracks, without writing anything;
* ``POST /api/save`` (same body) -- re-track if needed, then write the corrections file and the re-tracked tracks
  (atomically; the tracks file as it was when the session started is kept as ``TRACKS.csv.bak``).
"""

from __future__ import annotations

import os
import shlex
import shutil
import threading
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..fileio import temp_file_beside
from ..graph import BranchGraph
from ..track.anchors import Correction, DenseTracks, FrameStore, parse_corrections, retrack, write_corrections
from ..track.flags import FlagRules, flagged_runs, node_flags
from ..tracks import write_table_atomic
from .server import FrameCache


def _tracks_json(t: DenseTracks) -> dict:
    xy = np.round(t.xy, 3)
    return {"xy": [[None if not np.isfinite(p).all() else p.tolist() for p in node] for node in xy],
            "visible": t.visible.astype(int).tolist(),
            "sigma": None if t.sigma_px is None else
            [[None if not np.isfinite(s) else round(float(s), 3) for s in node] for node in t.sigma_px]}


class ReviewSession:
    """Review of ``tracks`` (validated :class:`DenseTracks` read from ``tracks_path``) over ``video``.

    ``graph``: the branch graph (edges drawn; the tracker uses it as ``rce track --graph`` does) or None.
    ``query0`` (P, 2) px: the first-frame annotation the tracks started from (default: their frame 0).
    ``corrections``: those loaded from ``corrections_path`` (where Save writes them). ``tracker``: the tracker
    the re-track runs (``LKTracker()``, as ``rce track`` without ``--model``). ``command``: the reproducing
    ``rce track`` command printed after a save.
    """

    page = "review.html"

    def __init__(self, video: str | Path, tracks_path: str | Path, tracks: DenseTracks, frames: FrameCache,
                 graph: BranchGraph | None, query0: np.ndarray | None, corrections: list[Correction],
                 corrections_path: str | Path, tracker, command: str, rules: FlagRules = FlagRules()):
        self.video, self.tracks_path = Path(video), Path(tracks_path)
        self.corrections_path = Path(corrections_path)
        self.backup_path = self.tracks_path.with_name(self.tracks_path.name + ".bak")
        self.frames, self.graph, self.query0 = frames, graph, query0
        self.base = tracks
        self.shown = tracks
        self.corrections = corrections
        self.retracked_for: list[Correction] | None = None
        self.tracker, self.command, self.rules = tracker, command, rules
        self.finished = threading.Event()
        self.saves = 0
        self._lock = threading.Lock()
        self._store: FrameStore | None = None
        self._first_run = None
        self._backed_up = False

    # -- GET
    def info(self) -> dict:
        w, h = self.frames.size
        edges = [list(e) for e in self.graph.edges] if self.graph else []
        return {"video": self.video.name, "width": w, "height": h, "n_frames": self.base.n_frames,
                "fps": self.frames.fps, "nodes": self.base.point_ids.tolist(), "edges": edges,
                "root": self.graph.root if self.graph else None, "has_sigma": self.base.sigma_px is not None,
                "corrections": [c.to_json() for c in self.corrections], "tracks": str(self.tracks_path),
                "corrections_file": str(self.corrections_path), "command": self.command,
                "rules": {"sigma_factor": self.rules.sigma_factor, "sigma_min_px": self.rules.sigma_min_px,
                          "jump_mads": self.rules.jump_mads, "jump_min_px": self.rules.jump_min_px}}

    def tracks(self) -> dict:
        t = self.shown
        flags = node_flags(t.xy, t.visible, t.sigma_px, self.rules)
        return {**_tracks_json(t), "flags": flagged_runs(flags, t.point_ids),
                "retracked": self.retracked_for is not None,
                "n_corrections": len(self.retracked_for or [])}

    def get(self, path: str):
        if path == "/api/info":
            return self.info()
        if path == "/api/tracks":
            return self.tracks()
        return None

    # -- POST
    def _parse(self, payload: dict) -> list[Correction]:
        return parse_corrections(payload, "the page's corrections", self.base.point_ids, self.base.n_frames,
                                 self.frames.size)

    def retrack(self, corrections: list[Correction]) -> dict:
        """Re-track from ``corrections`` (the tracker runs here, in the request's thread) and answer the tracks."""
        with self._lock:
            if self._store is None:
                self._store = FrameStore(self.video, self.base.n_frames)
            before = self.shown
            out, self._first_run = retrack(self._store, self.base, corrections, self.tracker, self.graph,
                                           self.query0, self._first_run)
            self.shown, self.retracked_for, self.corrections = out, corrections, corrections
            moved = np.hypot(*(out.xy - before.xy).transpose(2, 0, 1))
            moved = moved[np.isfinite(moved)]
        return {**self.tracks(), "max_moved_px": float(moved.max()) if moved.size else 0.0}

    def save(self, corrections: list[Correction]) -> dict:
        """Re-track if the corrections changed since the last re-track, then write both files."""
        if corrections != self.retracked_for:
            self.retrack(corrections)
        with self._lock:
            if not self._backed_up and self.tracks_path.is_file():
                tmp = temp_file_beside(self.backup_path)
                try:
                    shutil.copyfile(self.tracks_path, tmp)
                    os.replace(tmp, self.backup_path)
                except BaseException:
                    tmp.unlink(missing_ok=True)
                    raise
                self._backed_up = True
            write_corrections(self.corrections_path, corrections, video=self.video, tracks=self.tracks_path)
            write_table_atomic(self.shown.to_frame(), self.tracks_path)
            self.saves += 1
        return {"corrections": str(self.corrections_path), "tracks": str(self.tracks_path),
                "backup": str(self.backup_path), "n_corrections": len(corrections), "command": self.command,
                "reproducible": self.reproducible()}

    def reproducible(self) -> bool:
        """Whether the printed ``rce track`` command gives the saved file: the uncorrected nodes' rows must be what
        the tracker gives from frame 0 (not so for tracks made by TAPIR or with other options)."""
        run = self._first_run
        if run is None or run.n_frames != self.base.n_frames:
            return False
        keep = np.setdiff1d(np.arange(len(self.base.point_ids)), [c.node for c in self.corrections])
        xy, vis = self.base.xy[keep], self.base.visible[keep]
        return bool(np.isfinite(xy).all() and np.array_equal(xy, run.xy[keep]) and np.array_equal(vis, run.visible[keep]))

    def post(self, path: str, payload: dict):
        if path == "/api/retrack":
            return self.retrack(self._parse(payload))
        if path == "/api/save":
            return self.save(self._parse(payload))
        return None

    def close(self) -> None:
        self.frames.close()
        if self._store is not None:
            self._store.close()


def reproduce_command(video, annotations, graph, tracks, corrections, max_frames: int | None) -> str:
    """The ``rce track`` command that gives the saved tracks from the video, the annotation and the corrections."""
    args = ["rce", "track", video, annotations if annotations else "ANNOTATIONS.json"]
    if graph:
        args += ["--graph", graph]
    if max_frames:
        args += ["--max-frames", max_frames]
    args += ["--out", tracks, "--corrections", corrections]
    return " ".join(shlex.quote(str(a)) for a in args)


def check_graph_nodes(graph: BranchGraph | None, ids, source) -> None:
    """The graph's nodes must be the tracks' point ids (annotation indices) for the tracker to use it."""
    if graph is None:
        return
    missing = sorted(set(graph.nodes) - {int(i) for i in ids})
    if missing:
        raise InputError(graph.source, f"graph node {missing[0]} is not in the tracks {source}", f"node {missing[0]}")
