"""The local web server behind ``rce annotate VIDEO``.

:class:`AnnotationSession` holds what the page works on (the video's frames, the stem snapper, the output
folder); :func:`make_server` serves it on ``127.0.0.1`` with the standard library's ``http.server``:

* ``GET /`` and ``GET /static/NAME`` -- the page (package data in ``rce_gtsam/annotate_web/static``);
* ``GET /api/info`` -- video name, size (px), frame count, fps, the annotation saved before (if any);
* ``GET /frame/N.jpg`` -- frame N (decoded once, in order, and kept as JPEG);
* ``POST /api/snap`` ``{"x", "y"}`` -- the click moved onto the stem's centre line (frame 0, px);
* ``POST /api/save`` ``{"points": [[x, y], ...], "edges": [[parent, child], ...], "root": 0}`` -- validates
  and writes ``annotations.json`` and ``graph.json``; answers the paths and the ``rce run`` command to run next;
* ``POST /api/quit`` -- ends the session (the CLI returns).

Only requests whose ``Host`` is this server's own loopback address are answered. ``rce review`` serves its own
session (:mod:`.review`: another page, ``get``/``post`` answers) through this same server.
"""

from __future__ import annotations

import json
import shlex
import threading
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from pathlib import Path

import numpy as np

from ..errors import InputError, RceError
from ..graph import BranchGraph, load_graph
from ..track import load_annotations, open_video, validate_points, write_annotation_files
from .snap import RidgeSnapper

#: Fewest nodes a branch needs: a bend is measured at a node with a parent and a child.
MIN_NODES = 3
STATIC_FILES = {"index.html": "text/html; charset=utf-8", "annotate.js": "text/javascript; charset=utf-8",
                "annotate.css": "text/css; charset=utf-8", "review.html": "text/html; charset=utf-8",
                "review.js": "text/javascript; charset=utf-8", "review.css": "text/css; charset=utf-8"}


class FrameCache:
    """Frames of a video as JPEG bytes, decoded in order on first request (at most ``max_frames``)."""

    def __init__(self, video: Path, max_frames: int):
        self._video = video
        self._max = int(max_frames)
        self._jpeg: list[bytes] = []
        self._lock = threading.Lock()
        self._src = None
        self._it = None
        self.first_rgb: np.ndarray | None = None
        self.size: tuple[int, int] = (0, 0)
        self.fps = 30.0
        self.n_frames = 0
        self._open()

    def _open(self) -> None:
        self._src = open_video(self._video)
        self.size, self.fps = self._src.size, float(self._src.fps)
        self._it = iter(self._src)
        first = next(self._it, None)
        if first is None:
            raise InputError(self._video, "the video has no readable frames")
        self.first_rgb = first.image
        self._jpeg.append(self._encode(first.image))
        n = self._src.n_frames
        self.n_frames = min(n, self._max) if n else self._max

    @staticmethod
    def _encode(rgb: np.ndarray) -> bytes:
        import cv2
        ok, buf = cv2.imencode(".jpg", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 92])
        return buf.tobytes()

    def get(self, i: int) -> tuple[int, bytes]:
        """(index actually served, JPEG bytes) of frame ``i``; past the end: the last frame."""
        with self._lock:
            while len(self._jpeg) <= i and self._it is not None and len(self._jpeg) < self._max:
                fr = next(self._it, None)
                if fr is None:
                    self.close()
                    break
                self._jpeg.append(self._encode(fr.image))
            k = max(0, min(i, len(self._jpeg) - 1))
            return k, self._jpeg[k]

    def close(self) -> None:
        if self._src is not None:
            self._src.close()
        self._src, self._it = None, None


class AnnotationSession:
    """One annotation of ``video``, written to ``out_dir`` (annotations.json, graph.json).

    ``snap_radius_px``: how far a click may move onto a stem. ``max_frames``: frames the slider can show.
    """

    #: the page ``GET /`` serves (a session behind another page, such as ``rce review``'s, names its own)
    page = "index.html"

    def __init__(self, video: str | Path, out_dir: str | Path, snap_radius_px: float = 6.0, max_frames: int = 900):
        self.video = Path(video)
        self.out_dir = Path(out_dir)
        self.frames = FrameCache(self.video, max_frames)
        self.snapper = RidgeSnapper(self.frames.first_rgb, radius_px=snap_radius_px)
        self.annotations_path = self.out_dir / "annotations.json"
        self.graph_path = self.out_dir / "graph.json"
        self.finished = threading.Event()
        self.saves = 0

    def info(self) -> dict:
        w, h = self.frames.size
        return {"video": self.video.name, "width": w, "height": h, "n_frames": self.frames.n_frames,
                "fps": self.frames.fps, "snap_radius_px": self.snapper.radius_px, "out_dir": str(self.out_dir),
                "min_nodes": MIN_NODES, "previous": self._previous()}

    def _previous(self) -> dict | None:
        """The annotation already in the output folder, so a session can go on where one stopped."""
        if not (self.annotations_path.is_file() and self.graph_path.is_file()):
            return None
        try:
            pts = load_annotations(self.annotations_path, image_size=self.frames.size)
            g = load_graph(self.graph_path)
        except RceError:
            return None
        if g.root != 0 or set(g.nodes) != set(range(len(pts))):
            return None
        return {"points": pts.tolist(), "edges": [list(e) for e in g.edges]}

    def snap(self, x: float, y: float) -> dict:
        r = self.snapper.snap(float(x), float(y))
        return {"x": r.x, "y": r.y, "snapped": r.snapped, "moved_px": r.moved_px}

    def save(self, payload: dict) -> dict:
        """Validate the page's points and edges and write both files (atomically). Raises InputError."""
        src = "the annotation"
        pts = payload.get("points")
        edges = payload.get("edges")
        if not isinstance(pts, list) or not isinstance(edges, list):
            raise InputError(src, "expected {'points': [[x, y], ...], 'edges': [[parent, child], ...]}")
        if len(pts) < MIN_NODES:
            raise InputError(src, f"place at least {MIN_NODES} nodes (a bend needs a node with a parent and a "
                                  f"child); there are {len(pts)}")
        points = validate_points(pts, src, image_size=self.frames.size)
        graph = BranchGraph.from_edges(int(payload.get("root", 0)), [list(map(int, e)) for e in edges], source=src)
        if set(graph.nodes) != set(range(len(points))):
            loose = sorted(set(range(len(points))) - set(graph.nodes))
            raise InputError(src, f"node {loose[0]} is not connected to the branch", f"node {loose[0]}")
        write_annotation_files(points, graph, self.annotations_path, self.graph_path)
        self.saves += 1
        run_dir = self.out_dir / "run"
        from ..cli.wording import rce_invocation  # "rce", or its path where rce is not on PATH
        nxt = " ".join(shlex.quote(str(a)) for a in (
            *rce_invocation(), "run", self.video, self.annotations_path, self.graph_path, "--out", run_dir,
            "--rerun", run_dir / "recording.rrd"))
        return {"annotations": str(self.annotations_path), "graph": str(self.graph_path), "n_nodes": len(points),
                "n_edges": len(graph.edges), "n_bends": len(graph.bends), "next": nxt}

    def get(self, path: str):
        """The JSON answer to ``GET path`` (besides the page, static files and frames), or None (not found)."""
        return self.info() if path == "/api/info" else None

    def post(self, path: str, payload: dict):
        """The JSON answer to ``POST path``, or None (not found). Raises RceError/KeyError/... on a bad request."""
        if path == "/api/snap":
            return self.snap(payload["x"], payload["y"])
        if path == "/api/save":
            return self.save(payload)
        return None

    def close(self) -> None:
        self.frames.close()


def _static(name: str) -> bytes:
    return resources.files(__package__).joinpath("static", name).read_bytes()


class _Handler(BaseHTTPRequestHandler):
    server: "AnnotationServer"

    def log_message(self, fmt, *args) -> None:  # quiet: the CLI prints what matters
        pass

    def _host_ok(self) -> bool:
        host = self.headers.get("Host", "")
        port = self.server.server_address[1]
        return host in (f"127.0.0.1:{port}", f"localhost:{port}")

    def _send(self, status: int, body: bytes, ctype: str) -> None:
        self.send_response(status)
        self.send_header("Content-Type", ctype)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.end_headers()
        self.wfile.write(body)

    def _json(self, obj, status: int = 200) -> None:
        self._send(status, json.dumps(obj).encode(), "application/json")

    def do_GET(self) -> None:  # noqa: N802 (http.server's naming)
        if not self._host_ok():
            return self._send(HTTPStatus.FORBIDDEN, b"forbidden", "text/plain")
        s = self.server.session
        path = self.path.split("?", 1)[0]
        if path in ("/", "/index.html"):
            return self._send(200, _static(s.page), STATIC_FILES[s.page])
        if path.startswith("/static/") and path[8:] in STATIC_FILES:
            return self._send(200, _static(path[8:]), STATIC_FILES[path[8:]])
        if path.startswith("/api/"):
            out = s.get(path)
            if out is not None:
                return self._json(out)
        if path.startswith("/frame/") and path.endswith(".jpg") and path[7:-4].isdigit():
            k, data = s.frames.get(int(path[7:-4]))
            self.send_response(200)
            self.send_header("Content-Type", "image/jpeg")
            self.send_header("Content-Length", str(len(data)))
            self.send_header("X-Frame-Index", str(k))
            self.end_headers()
            self.wfile.write(data)
            return None
        return self._send(HTTPStatus.NOT_FOUND, b"not found", "text/plain")

    def do_POST(self) -> None:  # noqa: N802
        if not self._host_ok():
            return self._send(HTTPStatus.FORBIDDEN, b"forbidden", "text/plain")
        s = self.server.session
        try:
            n = int(self.headers.get("Content-Length", "0"))
            payload = json.loads(self.rfile.read(n) or b"{}")
        except (ValueError, json.JSONDecodeError):
            return self._json({"error": "the request is not JSON"}, HTTPStatus.BAD_REQUEST)
        try:
            if self.path == "/api/quit":
                self._json({"ok": True})
                s.finished.set()
                return None
            out = s.post(self.path, payload)
            if out is not None:
                if self.path == "/api/save":
                    self.server.on_save(out)
                return self._json(out)
        except (RceError, KeyError, TypeError, ValueError) as exc:
            return self._json({"error": str(exc)}, HTTPStatus.BAD_REQUEST)
        return self._send(HTTPStatus.NOT_FOUND, b"not found", "text/plain")


class AnnotationServer(ThreadingHTTPServer):
    """``ThreadingHTTPServer`` on 127.0.0.1 carrying a session: an :class:`AnnotationSession` or any object with its
    ``page``, ``frames`` (a :class:`FrameCache`), ``get(path)``, ``post(path, payload)`` and ``finished``
    (``rce review``'s :class:`~rce_gtsam.annotate_web.review.ReviewSession`)."""

    daemon_threads = True

    def __init__(self, session: AnnotationSession, port: int = 0, on_save=None):
        super().__init__(("127.0.0.1", int(port)), _Handler)
        self.session = session
        self.on_save = on_save or (lambda _out: None)

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.server_address[1]}/"


def make_server(session: AnnotationSession, port: int = 0, on_save=None) -> AnnotationServer:
    """Bind the page's server to 127.0.0.1:``port`` (0: a free port); call ``serve_forever`` to run it."""
    try:
        return AnnotationServer(session, port, on_save)
    except OSError as exc:
        raise InputError("--port", f"cannot listen on 127.0.0.1:{port} ({exc.strerror or exc})") from None
