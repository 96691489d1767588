"""Colour frames with their depth, played back from a RealSense recording (``.bag``/``.db3``).

:class:`RealSenseDepthSource` is the depth-aware sibling of :class:`~rce_gtsam.track.sources.RealSenseSource`:
each :class:`DepthFrame` carries the colour image (H, W, 3 uint8 RGB) and the depth registered to the colour
image (H, W float32 mm, 0 = no depth). No registration is needed when the recording's depth stream already has the
colour stream's geometry (same size and intrinsics, identity extrinsics),
where aligning is the identity and ``rs.align`` would only punch its rounding holes (~2 % of pixels) into it.

Playback is the device route of :class:`RealSenseSource` (``load_device``, ``set_real_time(False)`` before
streaming, callbacks that block on a small bounded queue), for both sensors, pairing colour and depth by frame
number, with playback paused until both sensors are started (``rs.pipeline`` was seen to drop the first or the
last frame of a short recording at random, and sensors started one by one lose the second one's first frames).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..camera import CameraIntrinsics
from ..errors import InputError
from .sources import (REALSENSE_SUFFIXES, FrameSource, drain, import_pyrealsense2, open_playback,
                      put_until_closed, rgb_pixels)


@dataclass(frozen=True, eq=False)
class DepthFrame:
    """One colour frame and its registered depth.

    index: 0-based frame number in delivery order. image: (H, W, 3) uint8 RGB.
    timestamp_s: seconds since the first frame. depth_mm: (H, W) float32 depth along the optical axis in mm,
    registered to ``image`` (0 = hole: no depth measured there).
    """

    index: int
    image: np.ndarray
    timestamp_s: float
    depth_mm: np.ndarray


def recording_has_depth(path: str | Path) -> bool:
    """True if ``path`` is a RealSense recording (``.bag``/``.db3``) with both a depth and a colour stream.

    False for any other file (videos), and for recordings librealsense cannot open (the colour reader then says why).
    """
    p = Path(path)
    if p.suffix.lower() not in REALSENSE_SUFFIXES or not p.is_file():
        return False
    rs = import_pyrealsense2()
    try:
        dev = rs.context().load_device(str(p))
    except RuntimeError:
        return False
    kinds = {sp.stream_type() for s in dev.query_sensors() for sp in s.get_stream_profiles()}
    return rs.stream.depth in kinds and rs.stream.color in kinds


def _intrinsics(profile) -> CameraIntrinsics:
    i = profile.as_video_stream_profile().get_intrinsics()
    return CameraIntrinsics(int(i.width), int(i.height), float(i.fx), float(i.fy), float(i.ppx), float(i.ppy))


def _is_registered(depth_prof, color_prof) -> bool:
    """Depth already in the colour image's geometry: same intrinsics, identity extrinsics (to 1e-6 / 1e-3 mm)."""
    if _intrinsics(depth_prof) != _intrinsics(color_prof):
        return False
    ex = depth_prof.get_extrinsics_to(color_prof)
    return (np.allclose(np.reshape(ex.rotation, (3, 3)), np.eye(3), atol=1e-6)
            and np.allclose(ex.translation, 0.0, atol=1e-6))


def register_depth(depth_mm: np.ndarray, depth_cam: CameraIntrinsics, color_cam: CameraIntrinsics,
                   rotation: np.ndarray, translation_mm: np.ndarray) -> np.ndarray:
    """Depth image (Hd, Wd) mm in the depth camera -> depth (Hc, Wc) mm along the colour camera's axis, registered
    to the colour image; 0 where no depth pixel lands. ``rotation`` (3, 3) and ``translation_mm`` (3,) take a
    depth-frame point to the colour frame (``p_c = R p_d + t``)."""
    v, u = np.nonzero(depth_mm > 0)
    pts = depth_cam.deproject(np.stack([u, v], axis=-1).astype(float), depth_mm[v, u])
    pc = pts @ np.asarray(rotation, float).T + np.asarray(translation_mm, float)
    pc = pc[pc[:, 2] > 0]
    uv = np.rint(color_cam.project(pc)).astype(int)
    inside = (uv[:, 0] >= 0) & (uv[:, 0] < color_cam.width) & (uv[:, 1] >= 0) & (uv[:, 1] < color_cam.height)
    out = np.full((color_cam.height, color_cam.width), np.inf, np.float32)
    np.minimum.at(out, (uv[inside, 1], uv[inside, 0]), pc[inside, 2].astype(np.float32))
    out[~np.isfinite(out)] = 0.0
    return out


class RealSenseDepthSource(FrameSource):
    """Colour + registered depth frames of a RealSense recording; iterate for :class:`DepthFrame` objects.

    Attributes: ``path``; ``fps`` (Hz); ``size`` ``(W, H)`` px of the colour stream; ``n_frames`` (``None``);
    ``intrinsics`` (:class:`CameraIntrinsics` of the colour stream, px); ``depth_unit_mm`` (mm per depth count);
    ``aligned_by`` (``"registered"``: the streams share geometry, or ``"reprojected"``).
    """

    timeout_ms = 5000
    queue_size = 6

    def __init__(self, path: str | Path):
        import queue
        import threading

        rs = import_pyrealsense2()
        self._rs = rs
        self.path = str(path)
        self._ctx, dev, self._playback = open_playback(rs, path)
        found = {}
        for s in dev.query_sensors():
            for sp in s.get_stream_profiles():
                if sp.stream_type() in (rs.stream.depth, rs.stream.color) and sp.stream_type() not in found:
                    found[sp.stream_type()] = (s, sp)
        if rs.stream.color not in found:
            raise InputError(path, "the recording has no colour stream")
        if rs.stream.depth not in found:
            raise InputError(path, "the recording has no depth stream")
        (self._dsensor, dprof), (self._csensor, cprof) = found[rs.stream.depth], found[rs.stream.color]
        self._dprof, self._cprof = dprof, cprof
        self.intrinsics = _intrinsics(cprof)
        self._depth_cam = _intrinsics(dprof)
        self.size = (self.intrinsics.width, self.intrinsics.height)
        self.fps = float(cprof.fps()) or 30.0
        self.n_frames = None
        try:
            unit_m = float(self._dsensor.as_depth_sensor().get_depth_scale())
        except RuntimeError:
            unit_m = 0.001
        self.depth_unit_mm = 1000.0 * unit_m
        ex = dprof.get_extrinsics_to(cprof)
        self._rotation = np.reshape(np.asarray(ex.rotation, float), (3, 3)).T  # librealsense stores column-major
        self._translation_mm = 1000.0 * np.asarray(ex.translation, float)
        self.aligned_by = "registered" if _is_registered(dprof, cprof) else "reprojected"
        self._color_format = cprof.format()
        self._queue: queue.Queue = queue.Queue(maxsize=self.queue_size)
        self._closed = threading.Event()
        self._started = False

    def _on_frame(self, frame) -> None:
        try:
            is_depth = frame.get_profile().stream_type() == self._rs.stream.depth
            data = (np.asanyarray(frame.get_data()).astype(np.float32) * np.float32(self.depth_unit_mm) if is_depth
                    else rgb_pixels(self._rs, frame.as_video_frame(), self._color_format, self.size, self.path))
            item = ("depth" if is_depth else "color", frame.get_frame_number(), frame.get_timestamp() / 1000.0, data)
        except Exception as exc:  # report in the reader thread, not librealsense's
            item = exc
        put_until_closed(self._queue, item, self._closed)

    def _registered(self, depth_mm: np.ndarray) -> np.ndarray:
        if self.aligned_by == "registered":
            return depth_mm
        return register_depth(depth_mm, self._depth_cam, self.intrinsics, self._rotation, self._translation_mm)

    def __iter__(self) -> Iterator[DepthFrame]:
        import queue

        rs = self._rs
        if self._started:
            raise RuntimeError(f"{self.path}: a RealSenseDepthSource can be iterated once; open the recording again")
        self._started = True
        self._dsensor.open(self._dprof)
        self._csensor.open(self._cprof)
        # playback starts with the first sensor started: hold it until both callbacks are attached, or the
        # first frames of the stream started second are lost
        self._playback.pause()
        self._dsensor.start(self._on_frame)
        self._csensor.start(self._on_frame)
        self._playback.resume()
        pending: dict[str, dict[int, tuple[float, np.ndarray]]] = {"depth": {}, "color": {}}
        i, t0, last, waited = 0, None, -1, 0
        while not self._closed.is_set():
            try:
                item = self._queue.get(timeout=0.05)
            except queue.Empty:
                waited += 50
                if (self._playback.current_status() == rs.playback_status.stopped and self._queue.empty()) \
                        or waited >= self.timeout_ms:
                    break
                continue
            waited = 0
            if isinstance(item, Exception):
                raise item
            kind, number, t, data = item
            if number <= last:  # delivered twice, or its partner never came
                continue
            pending[kind][number] = (t, data)
            other = pending["color" if kind == "depth" else "depth"]
            if number not in other:
                continue
            (tc, image), (_, depth) = (pending["color"].pop(number), pending["depth"].pop(number))
            for stale in [k for k in pending["color"] if k < number] + [k for k in pending["depth"] if k < number]:
                pending["color"].pop(stale, None)
                pending["depth"].pop(stale, None)
            last = number
            t0 = tc if t0 is None else t0
            yield DepthFrame(i, image, tc - t0, self._registered(depth))
            i += 1

    def close(self) -> None:
        if self._closed.is_set():
            return
        self._closed.set()
        if self._started:
            drain(self._queue)  # unblock the callbacks, then stop the sensors
            for step in (self._dsensor.stop, self._csensor.stop, self._dsensor.close, self._csensor.close):
                try:
                    step()
                except RuntimeError:
                    pass
