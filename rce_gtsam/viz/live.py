"""Stream a run into a Rerun viewer while it happens (``rce track`` / ``rce run`` with ``--spawn`` or ``--connect``).

Order of what arrives: the video (``image/video``: the asset and one frame reference per frame) as soon as
tracking starts; each frame's tracked points (``image/tracks/raw``, visible points only) as the tracker
finishes that frame; then, from ``rce run``, the whole analysis as soon as it is fitted and the diagnosis
as soon as it is done -- the same entities, written by the same functions
(:func:`~rce_gtsam.viz.rerun_log.log_analysis`, :func:`~rce_gtsam.viz.rerun_log.log_diagnosis`), as the
saved ``.rrd``, with the default layout sent again once the diagnosis is known.

Timelines as in the saved recording: ``frame`` (video frame index) and ``time`` (seconds).
"""

from __future__ import annotations

import re
import socket
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..viewer import viewer_executable, viewer_or_name
from .style import RAW_COLOR, hex_to_rgb


def grpc_url(address: str) -> str:
    """``HOST:PORT``, ``PORT`` or a ``rerun+http://HOST:PORT/proxy`` URL as the URL ``connect_grpc`` takes.

    Checks that something listens there, so a wrong address fails before any work."""
    m = re.fullmatch(r"(?:rerun\+https?://)?(?:([^:/\s]+):)?(\d{1,5})(?:/proxy)?/?", address.strip())
    if not m or not 0 < int(m.group(2)) < 65536:
        raise InputError("--connect", f"expected HOST:PORT or rerun+http://HOST:PORT/proxy, got {address!r}")
    host, port = m.group(1) or "127.0.0.1", int(m.group(2))
    try:
        socket.create_connection((host, port), timeout=3).close()
    except OSError as exc:
        raise InputError("--connect", f"nothing accepts connections at {host}:{port} ({exc.strerror or exc}); "
                                      f"start a viewer first (`{viewer_or_name()} --port {port}`) or use --spawn"
                         ) from None
    scheme = "rerun+https" if address.startswith("rerun+https") else "rerun+http"
    return f"{scheme}://{host}:{port}/proxy"


class LiveStream:
    """One live Rerun recording stream: ``spawn=True`` opens this environment's viewer, ``connect`` is the
    address of a running viewer or gRPC server (see :func:`grpc_url`)."""

    def __init__(self, title: str, spawn: bool = False, connect: str | None = None):
        import rerun as rr

        from .rerun_log import APP_ID
        self._rr = rr
        self.rec = rr.RecordingStream(APP_ID)
        if connect is not None:
            self.rec.connect_grpc(grpc_url(connect))
        elif spawn:
            rr.spawn(recording=self.rec, executable_path=viewer_executable(), hide_welcome_screen=True)
        else:
            raise ValueError("LiveStream needs spawn=True or a connect address")
        self.rec.log("/", rr.TextDocument(f"rce_gtsam live: {title}"), static=True)
        self.fps = 30.0
        self._seconds: np.ndarray | None = None
        self.has_video = False

    def video(self, path: str | Path, n_frames: int | None, fps: float) -> None:
        """Send the video (transcoded to H.264 when needed) and its frame references."""
        from .rerun_log import log_video
        self.fps = float(fps) or 30.0
        ts = log_video(self.rec, path, n_frames or 0)
        self._seconds = np.asarray(ts, dtype=np.float64) * 1e-9
        self.has_video = True

    def frame(self, index: int, xy: np.ndarray, visible: np.ndarray) -> None:
        """Send one frame's tracked points ``xy`` (P, 2) px; ``visible`` (P,) bool; point id = row."""
        rr = self._rr
        sec = (self._seconds[index] if self._seconds is not None and index < len(self._seconds)
               else index / self.fps)
        self.rec.set_time("frame", sequence=int(index))
        self.rec.set_time("time", duration=float(sec))
        ids = np.flatnonzero(visible)
        self.rec.log("image/tracks/raw", rr.Points2D(np.asarray(xy, np.float32)[ids], radii=1.5,
                                                      colors=[hex_to_rgb(RAW_COLOR)],
                                                      labels=[str(i) for i in ids], show_labels=False))

    def analysis(self, result, diagnosis=None) -> None:
        """Send the fitted analysis (an ``AnalysisResult``), and the diagnosis when given, with the layout."""
        from .blueprint import build_blueprint
        from .rerun_log import log_analysis, log_diagnosis
        from .scene import AnalysisView
        self.rec.reset_time()
        view = AnalysisView.from_result(result)
        self.rec.send_blueprint(build_blueprint(view, diagnosis, video=self.has_video))
        log_analysis(view, self.rec, fps=self.fps)
        if diagnosis is not None:
            log_diagnosis(diagnosis, self.rec, view=view)
        self._view = view

    def diagnosis(self, diagnosis) -> None:
        """Send the diagnosis of the analysis sent before, and the layout that shows it."""
        from .blueprint import build_blueprint
        from .rerun_log import log_diagnosis
        self.rec.reset_time()
        self.rec.send_blueprint(build_blueprint(self._view, diagnosis, video=self.has_video))
        log_diagnosis(diagnosis, self.rec, view=self._view)

    def close(self) -> None:
        """Flush everything to the viewer and disconnect (the viewer keeps what it got)."""
        self.rec.flush()
        self.rec.disconnect()
