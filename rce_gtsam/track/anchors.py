"""Re-track from a user's corrections: each correction is an anchor, and a node's track is refitted between anchors.

A **correction** ``(frame, node, x, y)`` says where node ``node`` really is in frame ``frame`` (pixels, x right,
y down, pixel centres at integers). :func:`retrack` refits the track of every corrected node and leaves every
other node's track as it was:

* the tracker (:class:`~rce_gtsam.track.LKTracker`, through its public ``track`` API) is run **forward** from each
  anchor frame and **backward** (the frames in reverse order) from each anchor frame, its query points being the
  corrections made in that frame and, for the other nodes, the frame-0 run's positions there (the tracker needs
  every node: it predicts a node from its parent and checks segment lengths);
* frame 0 is an implicit anchor of every node (its first-frame annotation): the frame-0 run is the forward run
  from it. It is run afresh from the tracks' frame-0 positions, not read from the tracks file, so re-tracking a
  file that was already re-tracked gives the same result;
* between two anchors ``a < b`` of a node, its position is the blend of the forward run from ``a`` and the
  backward run from ``b``, weighted by distance in frames: ``w_b = (f - a) / (b - a)``, ``w_a = 1 - w_b``; where
  only one of the two runs sees the node, that one is used alone. After the last anchor the forward run from it is
  used alone. So the corrected frame equals the correction, and its neighbours move toward it. Where none of the
  anchored runs sees the node but the frame-0 run does, the frame-0 run's position is kept (a run started at a
  corrected frame -- often mid-gust, with a blurred template -- can lose a node the frame-0 run holds);
* the blend's 1-sigma (px, per axis) is the two-run mixture's: ``sqrt(w_a s_a^2 + w_b s_b^2 + w_a w_b d^2 / 2)``
  with ``d`` the distance between the runs (where the two disagree, the position is uncertain); at an anchor it is
  :data:`CORRECTION_SIGMA_PX`.

The corrections file (JSON, written beside the tracks as ``TRACKS.corrections.json`` by ``rce review``)::

    {"corrections": [{"frame": 120, "node": 4, "x": 312.5, "y": 201.0}, ...]}

``rce track VIDEO ANNOTATIONS --out T.csv --corrections C.json`` applies it after tracking, so a reviewed run
can be reproduced from the video, the annotations and this file.
"""

from __future__ import annotations

import json
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import InputError
from ..fileio import write_text_atomic
from ..graph import BranchGraph
from .sources import ArraySource, open_video

#: 1-sigma (px, per axis) of a correction: a node dragged on the page at 1:1 zoom lands within about half a pixel
#: of where the user means (the page shows whole pixels; zoom in for better).
CORRECTION_SIGMA_PX = 0.5


@dataclass(frozen=True)
class Correction:
    """Node ``node`` is at ``(x, y)`` (px) in frame ``frame`` (0-based video frame index)."""

    frame: int
    node: int
    x: float
    y: float

    def to_json(self) -> dict:
        return {"frame": self.frame, "node": self.node, "x": self.x, "y": self.y}


def parse_corrections(obj, source: str | Path, nodes, n_frames: int,
                      image_size: tuple[int, int] | None = None) -> list[Correction]:
    """Validate a corrections object (``{"corrections": [...]}`` or the bare list) against the tracks' node ids
    ``nodes``, their frame count ``n_frames`` and the frame size ``(W, H)`` px. Later entries for the same
    (frame, node) replace earlier ones. Raises :class:`InputError` naming the entry."""
    items = obj.get("corrections") if isinstance(obj, dict) else obj
    if not isinstance(items, list):
        raise InputError(source, 'expected {"corrections": [{"frame": F, "node": N, "x": X, "y": Y}, ...]}')
    known = {int(n) for n in nodes}
    out: dict[tuple[int, int], Correction] = {}
    for k, it in enumerate(items):
        where = f"correction {k}"
        if not isinstance(it, dict) or not {"frame", "node", "x", "y"} <= set(it):
            raise InputError(source, 'each correction needs "frame", "node", "x" and "y"', where)
        f, n, x, y = it["frame"], it["node"], it["x"], it["y"]
        if any(isinstance(v, bool) for v in (f, n, x, y)) or not all(isinstance(v, (int, float)) for v in (f, n, x, y)):
            raise InputError(source, f"frame, node, x and y must be numbers, got {it}", where)
        if f != int(f) or n != int(n):
            raise InputError(source, f"frame and node must be integers, got frame={f}, node={n}", where)
        f, n = int(f), int(n)
        if n not in known:
            raise InputError(source, f"node {n} is not in the tracks (nodes {min(known)}..{max(known)})", where)
        if not 0 <= f < n_frames:
            raise InputError(source, f"frame {f} is beyond the video: the tracks have frames 0..{n_frames - 1}", where)
        if not (np.isfinite(x) and np.isfinite(y)):
            raise InputError(source, f"x and y must be finite, got ({x}, {y})", where)
        if image_size is not None:
            w, h = image_size
            if not (-0.5 <= x <= w - 0.5 and -0.5 <= y <= h - 0.5):
                raise InputError(source, f"({x:g}, {y:g}) is outside the {w}x{h} frame", where)
        out[(f, n)] = Correction(f, n, float(x), float(y))
    return sorted(out.values(), key=lambda c: (c.frame, c.node))


def load_corrections(path: str | Path, nodes, n_frames: int,
                     image_size: tuple[int, int] | None = None) -> list[Correction]:
    """Read and validate a corrections JSON file (see :func:`parse_corrections`)."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "corrections file not found")
    try:
        obj = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(path, f"not valid JSON ({exc})") from None
    return parse_corrections(obj, path, nodes, n_frames, image_size)


def write_corrections(path: str | Path, corrections: list[Correction], **meta) -> Path:
    """Write ``{"corrections": [...], **meta}`` atomically (``meta``: where they apply, for the reader)."""
    body = {"corrections": [c.to_json() for c in corrections], **{k: str(v) for k, v in meta.items()}}
    return write_text_atomic(json.dumps(body, indent=1) + "\n", path)


def default_corrections_path(tracks: str | Path) -> Path:
    """``TRACKS.corrections.json`` beside ``TRACKS.csv``."""
    tracks = Path(tracks)
    return tracks.with_name(f"{tracks.stem}.corrections.json")


class FrameStore:
    """The first ``n_frames`` frames of a video decoded once into a temporary file (memory-mapped, uint8 RGB), so
    that tracker runs can start at any frame and run backward. ``close()`` deletes the file."""

    def __init__(self, video: str | Path, n_frames: int):
        self.video = str(video)
        self._dir = Path(tempfile.mkdtemp(prefix="rce-frames-"))
        try:
            with open_video(video) as src:
                self.fps = float(src.fps)
                w, h = src.size
                self.frames = np.lib.format.open_memmap(self._dir / "frames.npy", mode="w+", dtype=np.uint8,
                                                        shape=(int(n_frames), h, w, 3))
                k = 0
                for fr in src:
                    if k >= n_frames:
                        break
                    self.frames[k] = fr.image
                    k += 1
            if k < n_frames:
                raise InputError(video, f"the video has {k} frames but the tracks have {n_frames}")
        except BaseException:
            self.close()
            raise

    @property
    def n_frames(self) -> int:
        return len(self.frames)

    def forward(self, start: int, stop: int) -> ArraySource:
        """Frames ``start .. stop`` (inclusive) in order."""
        return ArraySource(self.frames[start:stop + 1], self.fps, f"{self.video}[{start}:{stop}]")

    def backward(self, start: int, stop: int) -> ArraySource:
        """Frames ``start, start - 1, .., stop`` (``stop <= start``)."""
        return ArraySource(self.frames[stop:start + 1][::-1], self.fps, f"{self.video}[{start}:{stop}:-1]")

    def close(self) -> None:
        self.frames = None
        shutil.rmtree(self._dir, ignore_errors=True)

    def __enter__(self) -> "FrameStore":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


@dataclass(frozen=True, eq=False)
class DenseTracks:
    """Tracks of P nodes over F frames as arrays.

    point_ids: (P,) int. xy: (P, F, 2) px, NaN where the file has no row. visible: (P, F) bool.
    sigma_px: (P, F) px (per axis, 1 sigma) or None when the tracks carry no sigma.
    """

    point_ids: np.ndarray
    xy: np.ndarray
    visible: np.ndarray
    sigma_px: np.ndarray | None = None

    @property
    def n_frames(self) -> int:
        return self.xy.shape[1]

    @classmethod
    def from_table(cls, table: pd.DataFrame) -> "DenseTracks":
        """From a validated long table (:func:`rce_gtsam.tracks.read_tracks_table`); every point's row is kept."""
        ids = np.unique(table["point_id"].to_numpy())
        n_f = int(table["frame"].max()) + 1
        row = {int(p): i for i, p in enumerate(ids)}
        ii = table["point_id"].map(row).to_numpy()
        ff = table["frame"].to_numpy()
        xy = np.full((len(ids), n_f, 2), np.nan)
        xy[ii, ff, 0], xy[ii, ff, 1] = table["x"].to_numpy(), table["y"].to_numpy()
        vis = np.zeros((len(ids), n_f), bool)
        vis[ii, ff] = table["visible"].to_numpy() == 1 if "visible" in table else True
        sig = None
        if "sigma_px" in table:
            sig = np.full((len(ids), n_f), np.nan)
            sig[ii, ff] = table["sigma_px"].to_numpy()
        return cls(ids.astype(int), xy, vis, sig)

    @classmethod
    def from_result(cls, res) -> "DenseTracks":
        """From a tracker's :class:`~rce_gtsam.track.TrackResult`."""
        return cls(np.asarray(res.point_ids, int), res.xy.copy(), res.visible.copy(), res.sigma_px.copy())

    def to_frame(self) -> pd.DataFrame:
        """Long table ``point_id, frame, x, y, visible[, sigma_px]`` (the tracks CSV), rows where xy is known."""
        p, f = np.nonzero(np.isfinite(self.xy).all(axis=2))
        df = pd.DataFrame({"point_id": self.point_ids[p].astype(np.int64), "frame": f.astype(np.int64),
                           "x": self.xy[p, f, 0], "y": self.xy[p, f, 1],
                           "visible": self.visible[p, f].astype(np.int64)})
        if self.sigma_px is not None:
            df["sigma_px"] = self.sigma_px[p, f]
        return df


def _blend(xa, va, sa, xb, vb, sb, wb):
    """Blend run a (weight 1 - wb) and run b (weight wb) at one node over a frame range; arrays (K, 2)/(K,)."""
    wb = np.where(va & ~vb, 0.0, np.where(vb & ~va, 1.0, wb))
    wa = 1.0 - wb
    xy = wa[:, None] * xa + wb[:, None] * xb
    d2 = ((xa - xb) ** 2).sum(axis=1)
    sig = np.sqrt(wa * sa ** 2 + wb * sb ** 2 + wa * wb * d2 / 2)
    return xy, va | vb, sig


def retrack(store: FrameStore, base: DenseTracks, corrections: list[Correction], tracker,
            graph: BranchGraph | None = None, query0: np.ndarray | None = None, first_run=None):
    """Refit the corrected nodes' tracks between their anchors (see the module docstring).

    ``tracker``: anything with the tracker API ``track(source, points, graph=...) -> TrackResult``; node ids must
    be ``0..P-1`` (annotation indices). ``query0`` (P, 2) px: the frame-0 positions the frame-0 run starts from
    (default: the tracks' frame 0); ``first_run``: that run when already made (a ``TrackResult``; ``rce track`` has
    it). Returns ``(DenseTracks, first_run)``; nodes without corrections keep ``base``'s rows unchanged.
    """
    n_p, n_f = len(base.point_ids), base.n_frames
    if not np.array_equal(base.point_ids, np.arange(n_p)):
        raise InputError("tracks", f"re-tracking needs point ids 0..{n_p - 1} (the annotation's indices), "
                                   f"got {base.point_ids.tolist()[:8]}")
    q0 = (base.xy[:, 0].copy() if query0 is None else np.asarray(query0, float).copy())
    if not np.isfinite(q0).all():
        i = int(np.flatnonzero(~np.isfinite(q0).all(axis=1))[0])
        raise InputError("tracks", f"node {i} has no position in frame 0, where tracking starts", f"node {i}")
    by_frame: dict[int, list[Correction]] = {}
    for c in corrections:
        by_frame.setdefault(c.frame, []).append(c)
    for c in by_frame.get(0, []):
        q0[c.node] = (c.x, c.y)
    if first_run is None or not np.array_equal(first_run.xy[:, 0], q0):
        first_run = tracker.track(store.forward(0, n_f - 1), q0, graph=graph)
    f0 = DenseTracks.from_result(first_run)
    out_xy, out_vis = base.xy.copy(), base.visible.copy()
    out_sig = None if base.sigma_px is None else base.sigma_px.copy()
    anchors = {n: sorted({0} | {c.frame for c in corrections if c.node == n}) for n in {c.node for c in corrections}}
    if not anchors:
        return DenseTracks(base.point_ids, out_xy, out_vis, out_sig), first_run
    # one forward and one backward run per anchor frame, as long as the nodes anchored there need
    fwd: dict[int, DenseTracks] = {0: f0}
    bwd: dict[int, DenseTracks] = {}
    for k, cs in sorted(by_frame.items()):
        q = f0.xy[:, k].copy()
        for c in cs:
            q[c.node] = (c.x, c.y)
        nodes = [c.node for c in cs]
        nxt = [next((a for a in anchors[n] if a > k), n_f - 1) for n in nodes]
        prv = [max(a for a in anchors[n] if a < k) for n in nodes] if k > 0 else [0]
        if k > 0:
            fwd[k] = DenseTracks.from_result(tracker.track(store.forward(k, max(nxt)), q, graph=graph))
            back = tracker.track(store.backward(k, min(prv)), q, graph=graph)
            bwd[k] = DenseTracks.from_result(back)
    for n, ank in anchors.items():
        xy, vis, sig = np.empty((n_f, 2)), np.zeros(n_f, bool), np.empty(n_f)
        for a, b in zip(ank, ank[1:] + [None]):
            if b is None:  # after the last anchor: the forward run from it alone
                run = fwd[a]
                xy[a:], vis[a:], sig[a:] = run.xy[n, :n_f - a], run.visible[n, :n_f - a], run.sigma_px[n, :n_f - a]
                continue
            m = b - a + 1
            ra, rb = fwd[a], bwd[b]
            # backward run: its frame j is video frame b - j
            xb, vb, sb = rb.xy[n, :m][::-1], rb.visible[n, :m][::-1], rb.sigma_px[n, :m][::-1]
            wb = np.arange(m) / (m - 1)
            xy[a:b + 1], vis[a:b + 1], sig[a:b + 1] = _blend(ra.xy[n, :m], ra.visible[n, :m], ra.sigma_px[n, :m],
                                                             xb, vb, sb, wb)
        # where no run from an anchor sees the node but the frame-0 run does, that one is the measurement: a run
        # started at a corrected frame (often mid-gust, its template blurred, its neighbours' query positions
        # guesses) loses nodes the frame-0 run holds, and re-tracking must not drop what was seen
        fb = ~vis & f0.visible[n]
        xy[fb], vis[fb], sig[fb] = f0.xy[n, fb], True, f0.sigma_px[n, fb]
        for a in ank:
            c = next((c for c in by_frame.get(a, []) if c.node == n), None)
            if c is not None:
                xy[a], vis[a], sig[a] = (c.x, c.y), True, CORRECTION_SIGMA_PX
        out_xy[n], out_vis[n] = xy, vis
        if out_sig is not None:
            out_sig[n] = sig
    return DenseTracks(base.point_ids, out_xy, out_vis, out_sig), first_run
