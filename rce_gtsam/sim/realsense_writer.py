"""Write colour + depth frames as an Intel RealSense recording (``.db3``, ROS2 rosbag2, librealsense >= 2.58).

The layout is the one a D435i recording played back by ``rs.config.enable_device_from_file`` presents:
one ``rs.software_device`` with two sensors,

* ``"Stereo Module"``: a ``z16`` depth stream (read-only option ``depth_units`` = 0.001 m, so a pixel value is mm;
  0 = no depth),
* ``"RGB Camera"``: an ``rgb8`` colour stream,

both at the same size, intrinsics and frame rate, the depth stream registered to the colour stream with identity
extrinsics (``register_extrinsics_to``), frame numbers ``0..T-1`` and timestamps ``i * 1000 / fps`` ms in step.
``rs.align(rs.stream.color)`` therefore works on the playback (and leaves the depth where it was, up to the
align filter's 1-mm rounding).

The file is written under a temporary name in the target folder and renamed into place when complete, so a
crash never leaves a half-written ``path``.
"""

from __future__ import annotations

import os
import time
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from ..camera import CameraIntrinsics
from ..errors import InputError
from ..track.sources import import_pyrealsense2

#: Seconds to pause after handing each frame pair to the recorder, which writes on its own thread; without a
#: pause a fast producer outruns it and frames go missing from the file.
PACE_S = 0.004


def _rs_intrinsics(rs, cam: CameraIntrinsics):
    intr = rs.intrinsics()
    intr.width, intr.height = cam.width, cam.height
    intr.fx, intr.fy, intr.ppx, intr.ppy = cam.fx, cam.fy, cam.cx, cam.cy
    intr.model, intr.coeffs = rs.distortion.brown_conrady, [0.0] * 5
    return intr


def _stream(rs, kind, uid: int, fmt, bpp: int, cam: CameraIntrinsics, fps: int):
    vs = rs.video_stream()
    vs.type, vs.index, vs.uid = kind, 0, uid
    vs.width, vs.height, vs.fps, vs.bpp, vs.fmt = cam.width, cam.height, fps, bpp, fmt
    vs.intrinsics = _rs_intrinsics(rs, cam)
    return vs


def _check(path: Path, color: np.ndarray, depth: np.ndarray, cam: CameraIntrinsics, fps) -> None:
    if path.suffix.lower() != ".db3":
        raise InputError(path, "librealsense >= 2.58 records only ROS2 .db3 files; give the path a .db3 suffix")
    if color.ndim != 4 or color.shape[3] != 3 or color.dtype != np.uint8:
        raise InputError(path, f"color_frames must be (T, H, W, 3) uint8 RGB, got {color.shape} {color.dtype}")
    if depth.ndim != 3 or depth.dtype != np.uint16:
        raise InputError(path, f"depth_mm must be (T, H, W) uint16 millimetres, got {depth.shape} {depth.dtype}")
    if depth.shape != color.shape[:3]:
        raise InputError(path, f"depth_mm {depth.shape} and color_frames {color.shape[:3]} differ in frames or size")
    if len(color) == 0:
        raise InputError(path, "no frames to write")
    if (cam.height, cam.width) != color.shape[1:3]:
        raise InputError(path, f"intrinsics are for {cam.width}x{cam.height} px but the frames are "
                               f"{color.shape[2]}x{color.shape[1]} px")
    if not (isinstance(fps, int | np.integer) and 1 <= int(fps) <= 1000):
        raise InputError(path, f"fps must be a whole number of frames per second in 1..1000, got {fps!r}")


def write_recording(path: str | Path, color_frames: np.ndarray, depth_mm: np.ndarray,
                    intrinsics: CameraIntrinsics | Mapping, fps: int = 30) -> Path:
    """Record ``color_frames`` (T, H, W, 3) uint8 RGB and aligned ``depth_mm`` (T, H, W) uint16 mm (0 = hole)
    to the RealSense recording ``path`` (``.db3``), both streams with ``intrinsics`` (px) at ``fps`` Hz.

    Returns ``path``. Raises :class:`InputError` on inconsistent input (before anything is written) and
    :class:`~rce_gtsam.errors.MissingDependencyError` when pyrealsense2 cannot be imported.
    """
    path = Path(path)
    color = np.asarray(color_frames)
    depth = np.asarray(depth_mm)
    cam = CameraIntrinsics.coerce(intrinsics)
    _check(path, color, depth, cam, fps)
    fps = int(fps)
    rs = import_pyrealsense2()
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.partial.db3")
    tmp.unlink(missing_ok=True)
    try:
        _record(rs, tmp, color, depth, cam, fps)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def _record(rs, path: Path, color: np.ndarray, depth: np.ndarray, cam: CameraIntrinsics, fps: int) -> None:
    sd = rs.software_device()
    depth_sensor = sd.add_sensor("Stereo Module")
    color_sensor = sd.add_sensor("RGB Camera")
    depth_prof = depth_sensor.add_video_stream(_stream(rs, rs.stream.depth, 0, rs.format.z16, 2, cam, fps))
    color_prof = color_sensor.add_video_stream(_stream(rs, rs.stream.color, 1, rs.format.rgb8, 3, cam, fps))
    depth_sensor.add_read_only_option(rs.option.depth_units, 0.001)
    identity = rs.extrinsics()
    identity.rotation = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    identity.translation = [0.0, 0.0, 0.0]
    depth_prof.register_extrinsics_to(color_prof, identity)
    sd.create_matcher(rs.matchers.dlr_c)
    rec = rs.recorder(str(path), sd)
    depth_sensor.open(depth_prof)
    color_sensor.open(color_prof)
    queues = (rs.frame_queue(2), rs.frame_queue(2))  # the recorder taps frames before these queues
    depth_sensor.start(queues[0])
    color_sensor.start(queues[1])
    w = cam.width
    try:
        for i in range(len(color)):
            for sensor, prof, pixels, bpp in ((depth_sensor, depth_prof, depth[i], 2),
                                              (color_sensor, color_prof, color[i], 3)):
                fr = rs.software_video_frame()
                fr.pixels = np.ascontiguousarray(pixels)
                fr.bpp, fr.stride = bpp, w * bpp
                fr.timestamp = i * 1000.0 / fps
                fr.domain = rs.timestamp_domain.hardware_clock
                fr.frame_number = i
                fr.profile = prof.as_video_stream_profile()
                sensor.on_video_frame(fr)
            time.sleep(PACE_S)
        time.sleep(0.2)
    finally:
        for step in (depth_sensor.stop, color_sensor.stop, depth_sensor.close, color_sensor.close):
            try:
                step()
            except RuntimeError:
                pass
        rec.pause()
        del rec
