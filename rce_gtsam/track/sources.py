"""Frame sources: stream RGB frames from a video file or an Intel RealSense recording.

Every source is a context manager and an iterable of :class:`Frame`; frames are decoded one at a
time, so a long video is never held in memory. Images are ``(H, W, 3)`` ``uint8`` **RGB**.

* :class:`VideoFileSource` -- anything OpenCV's FFmpeg backend reads (mp4/H.264, avi, mov, mkv ...).
* :class:`RealSenseSource` -- ``.bag`` (ROS1, librealsense < 2.58) and ``.db3`` (ROS2, written by
  librealsense >= 2.58) recordings, colour stream, played back *not* in real time so no frame is dropped.
* :class:`ArraySource` -- frames already in memory (tests, notebooks).

:func:`open_video` picks the right one from the file suffix; :func:`prefetched` decodes ahead in a thread.
"""

from __future__ import annotations

import contextlib
import os
import queue
import threading
from abc import ABC, abstractmethod
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError, MissingDependencyError

#: File suffixes played back through pyrealsense2.
REALSENSE_SUFFIXES = (".bag", ".db3")

REALSENSE_FIX = ("install the RealSense extra with `pip install 'rce_gtsam[realsense]'` "
                 "(pyrealsense2) and its system library with `apt-get install libusb-1.0-0`")


@dataclass(frozen=True, eq=False)
class Frame:
    """One video frame.

    index: 0-based frame number in the order the source delivers them.
    image: (H, W, 3) uint8 RGB.
    timestamp_s: seconds since the first frame.
    """

    index: int
    image: np.ndarray
    timestamp_s: float


class FrameSource(ABC):
    """A stream of :class:`Frame` objects. Use as ``with open_video(p) as src: for fr in src: ...``.

    Attributes: ``path`` (or a description), ``fps`` (frames per second), ``size`` ``(W, H)`` pixels,
    ``n_frames`` (frame count, ``None`` when the container does not say).
    """

    path: str
    fps: float
    size: tuple[int, int]
    n_frames: int | None

    def __enter__(self) -> "FrameSource":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:  # noqa: B027 - optional hook
        """Release the decoder."""

    @abstractmethod
    def __iter__(self) -> Iterator[Frame]:
        ...


class ArraySource(FrameSource):
    """Frames already in memory: a sequence of (H, W, 3) uint8 RGB arrays (or an (F, H, W, 3) array)."""

    def __init__(self, frames: Sequence[np.ndarray] | np.ndarray, fps: float = 30.0, path: str = "<array>"):
        if len(frames) == 0:
            raise InputError(path, "no frames")
        first = np.asarray(frames[0])
        if first.ndim != 3 or first.shape[2] != 3 or first.dtype != np.uint8:
            raise InputError(path, f"frames must be (H, W, 3) uint8 RGB, got {first.shape} {first.dtype}")
        self._frames = frames
        self.path = path
        self.fps = float(fps)
        self.size = (int(first.shape[1]), int(first.shape[0]))
        self.n_frames = len(frames)

    def __iter__(self) -> Iterator[Frame]:
        for i, im in enumerate(self._frames):
            yield Frame(i, np.asarray(im), i / self.fps)


@contextlib.contextmanager
def quiet_stderr():
    """Silence the process's file descriptor 2 (C libraries such as FFmpeg write there directly) for the
    duration of the block; Python's ``sys.stderr`` object is untouched."""
    try:
        saved = os.dup(2)
    except OSError:  # no fd 2 (embedded interpreter): nothing to silence
        yield
        return
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
            yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def prefetched(frames: Iterable[Frame], depth: int = 8) -> Iterator[Frame]:
    """Iterate ``frames`` while a background thread decodes up to ``depth`` frames ahead.

    Decoding (``cv2.VideoCapture.read``, the colour conversion, PyAV) releases the GIL, so the next frames are
    decoded while the caller works on this one, and at most ``depth`` decoded frames are held (the video stays
    streamed). An exception raised by the source is raised here, after the frames before it; when the caller
    stops early, the thread stops after the frame it is decoding.
    """
    if depth < 1:
        raise ValueError(f"prefetch depth must be >= 1, got {depth}")
    buf: queue.Queue = queue.Queue(maxsize=depth)
    stop = threading.Event()
    end = object()

    def put(item) -> bool:
        while not stop.is_set():
            try:
                buf.put(item, timeout=0.05)
                return True
            except queue.Full:
                continue
        return False

    def decode() -> None:
        try:
            for fr in frames:
                if not put(fr):
                    return
            put(end)
        except BaseException as exc:  # noqa: BLE001 - handed to the consumer, which raises it
            put(exc)

    worker = threading.Thread(target=decode, name="frame-prefetch", daemon=True)
    worker.start()
    try:
        while True:
            item = buf.get()
            if item is end:
                return
            if isinstance(item, BaseException):
                raise item
            yield item
    finally:
        stop.set()
        worker.join()


class VideoFileSource(FrameSource):
    """A video file decoded with OpenCV (``cv2.VideoCapture``), converted BGR -> RGB."""

    def __init__(self, path: str | Path):
        import cv2

        self.path = str(path)
        self._cv2 = cv2
        with quiet_stderr():  # FFmpeg prints its own raw complaint ("moov atom not found") to fd 2
            self._cap = cv2.VideoCapture(self.path)
            opened = self._cap.isOpened()
            ok, first = self._cap.read() if opened else (False, None)
        if not opened:
            self._cap.release()
            raise InputError(path, "OpenCV cannot open this file as a video (unknown container or codec, "
                                   "or a truncated or corrupt file)")
        if not ok or first is None:
            self._cap.release()
            raise InputError(path, "the video has no readable frames")
        self._first = first
        fps = float(self._cap.get(cv2.CAP_PROP_FPS) or 0.0)
        # Some containers report 0 or absurd rates; fall back to 30 fps and say so in `fps_reported`.
        self.fps_reported = fps
        self.fps = fps if 0.0 < fps < 1000.0 else 30.0
        self.size = (int(first.shape[1]), int(first.shape[0]))
        n = int(self._cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
        self.n_frames = n if n > 0 else None
        self._used = False

    def __iter__(self) -> Iterator[Frame]:
        if self._used:
            raise RuntimeError(f"{self.path}: a VideoFileSource can be iterated once; open the video again")
        self._used = True
        cv2 = self._cv2
        image, i = self._first, 0
        self._first = None
        while image is not None:
            yield Frame(i, cv2.cvtColor(image, cv2.COLOR_BGR2RGB), i / self.fps)
            ok, image = self._cap.read()
            if not ok:
                image = None
            i += 1

    def close(self) -> None:
        self._cap.release()


def import_pyrealsense2():
    """Import pyrealsense2 or raise :class:`MissingDependencyError` that says how to install it."""
    try:
        import pyrealsense2 as rs
    except ImportError as exc:
        what = "its system library libusb-1.0 is missing" if "libusb" in str(exc) else "pyrealsense2 is not installed"
        raise MissingDependencyError(f"reading RealSense recordings needs pyrealsense2, but {what} ({exc}); "
                                     f"{REALSENSE_FIX}") from None
    return rs


def open_playback(rs, path: str | Path):
    """(context, device, playback) of a RealSense recording, played back not in real time (set before streaming
    starts, so no frame is dropped). :class:`InputError` naming ``path`` where librealsense cannot play it."""
    try:
        ctx = rs.context()
        dev = ctx.load_device(str(path))
    except RuntimeError as exc:
        raise InputError(path, f"librealsense cannot play this recording ({exc}); note: librealsense >= 2.58 "
                               "reads .bag and .db3, older versions only .bag") from None
    playback = dev.as_playback()
    playback.set_real_time(False)
    return ctx, dev, playback


def rgb_pixels(rs, frame, fmt, size: tuple[int, int], path) -> np.ndarray:
    """(H, W, 3) uint8 RGB copy of a RealSense colour ``frame`` in format ``fmt`` (rgb8, bgr8, rgba8, bgra8 or
    yuyv; ``size`` (W, H) px); :class:`InputError` naming ``path`` for any other format."""
    import cv2

    data = np.asanyarray(frame.get_data())
    if fmt == rs.format.rgb8:
        return np.array(data, copy=True)  # own the pixels: librealsense reuses its frame buffers
    conv = {rs.format.bgr8: cv2.COLOR_BGR2RGB, rs.format.rgba8: cv2.COLOR_RGBA2RGB,
            rs.format.bgra8: cv2.COLOR_BGRA2RGB}.get(fmt)
    if conv is not None:
        return cv2.cvtColor(data, conv)
    if fmt == rs.format.yuyv:
        return cv2.cvtColor(data.reshape(size[1], size[0], 2), cv2.COLOR_YUV2RGB_YUYV)
    raise InputError(path, f"unsupported colour format {fmt}; expected rgb8, bgr8, rgba8, bgra8 or yuyv")


def put_until_closed(q, item, closed) -> None:
    """Put ``item`` into the bounded queue ``q`` from a librealsense callback, waiting while it is full (so the
    non-real-time playback waits for the reader) until the ``closed`` event is set."""
    import queue

    while not closed.is_set():
        try:
            q.put(item, timeout=0.1)
            return
        except queue.Full:
            continue


def drain(q) -> None:
    """Empty the queue ``q`` (unblocks a callback waiting in :func:`put_until_closed`)."""
    import queue

    while True:
        try:
            q.get_nowait()
        except queue.Empty:
            return


class RealSenseSource(FrameSource):
    """The colour stream of a RealSense ``.bag``/``.db3`` recording, played back frame by frame.

    The recording is opened as a playback device (``rs.context().load_device``) with
    ``set_real_time(False)`` set *before* streaming starts, and the colour sensor delivers frames to a
    callback that copies each one into a small bounded queue. The playback thread waits while the queue
    is full, so no frame is dropped however slowly the frames are consumed, and memory stays bounded.
    (The ``rs.pipeline`` route starts in real time and was seen to drop the first frame.)
    ``timestamp_s`` comes from the device timestamps (relative to the first frame); ``n_frames`` is
    ``None`` (recordings carry a duration, not a frame count).
    """

    #: Give up waiting for a next frame after this long (milliseconds) -- only if playback never reports
    #: the end; non-real-time playback delivers as fast as we read.
    timeout_ms = 5000
    #: Frames buffered between the playback thread and the reader.
    queue_size = 4

    def __init__(self, path: str | Path):
        import queue
        import threading

        rs = import_pyrealsense2()
        self._rs = rs
        self.path = str(path)
        self._ctx, dev, self._playback = open_playback(rs, path)
        found = [(s, sp) for s in dev.query_sensors() for sp in s.get_stream_profiles()
                 if sp.stream_type() == rs.stream.color]
        if not found:
            raise InputError(path, "the recording has no colour stream")
        self._sensor, prof = found[0]
        vsp = prof.as_video_stream_profile()
        self.fps = float(vsp.fps()) or 30.0
        self.size = (int(vsp.width()), int(vsp.height()))
        self.n_frames = None
        self._queue: queue.Queue = queue.Queue(maxsize=self.queue_size)
        self._closed = threading.Event()
        self._prof = prof
        self._started = False

    def _on_frame(self, frame) -> None:
        try:
            vf = frame.as_video_frame()
            item = (frame.get_timestamp() / 1000.0,
                    rgb_pixels(self._rs, vf, vf.get_profile().format(), self.size, self.path))
        except Exception as exc:  # report in the reader thread, not librealsense's
            item = exc
        put_until_closed(self._queue, item, self._closed)

    def __iter__(self) -> Iterator[Frame]:
        import queue

        rs = self._rs
        if self._started:
            raise RuntimeError(f"{self.path}: a RealSenseSource can be iterated once; open the recording again")
        self._started = True
        self._sensor.open(self._prof)
        self._sensor.start(self._on_frame)
        i, t0, last_t, waited = 0, None, None, 0.0
        while not self._closed.is_set():
            try:
                item = self._queue.get(timeout=0.05)
            except queue.Empty:
                waited += 50
                if self._playback.current_status() == rs.playback_status.stopped and self._queue.empty():
                    break
                if waited >= self.timeout_ms:
                    break
                continue
            waited = 0.0
            if isinstance(item, Exception):
                raise item
            t, image = item
            if last_t is not None and t <= last_t:  # a frame delivered twice
                continue
            last_t = t
            t0 = t if t0 is None else t0
            yield Frame(i, image, t - t0)
            i += 1

    def close(self) -> None:
        if self._closed.is_set():
            return
        self._closed.set()
        if self._started:
            drain(self._queue)  # unblock the callback, then stop the sensor
            for step in (self._sensor.stop, self._sensor.close):
                try:
                    step()
                except RuntimeError:
                    pass


def open_video(path: str | Path) -> FrameSource:
    """Open a video file or RealSense recording as a :class:`FrameSource` (use it in a ``with`` block).

    Raises :class:`InputError` if the file is missing or unreadable and
    :class:`~rce_gtsam.errors.MissingDependencyError` if a RealSense file needs pyrealsense2/libusb.
    """
    p = Path(path)
    if not p.is_file():
        raise InputError(p, "video file not found")
    if p.stat().st_size == 0:
        raise InputError(p, "the video file is empty")
    if p.suffix.lower() in REALSENSE_SUFFIXES:
        return RealSenseSource(p)
    return VideoFileSource(p)
