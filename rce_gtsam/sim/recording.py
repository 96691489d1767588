"""The media of a simulated recording: ``video.mp4`` and, with depth, a RealSense ``recording.db3``.

The colour frames are rendered once (:func:`rce_gtsam.sim.render.iter_frames`) and go both into the H.264 video
and, as lossless rgb8, into the recording beside the aligned depth (:func:`rce_gtsam.sim.depth.iter_depth_frames`,
shifted with the camera when the render config shakes it), written by
:func:`rce_gtsam.sim.realsense_writer.write_recording` (z16 depth in mm and rgb8 colour, same 640x480
intrinsics, identity extrinsics, frame numbers in step). A recording holds every frame uncompressed, as a real
RealSense recording does: about 1.5 MB per frame (900 frames: 1.4 GB on disk and in memory while written).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

#: Name of the RealSense recording in a simulated recording's folder.
RECORDING_NAME = "recording.db3"


def depth_frames(sim, render=None, noise=None):
    """The simulation's depth frames (H, W) uint16 mm, moved with the camera shake of ``render`` (nearest
    neighbour; pixels shifted in from outside are holes)."""
    import cv2

    from .depth import iter_depth_frames
    from .nuisance import RenderConfig, camera_shift
    shift = camera_shift(sim, render) if render is not None and render != RenderConfig() else None
    for f, d in enumerate(iter_depth_frames(sim, noise=noise)):
        if shift is not None and shift[f].any():
            m = np.array([[1.0, 0.0, shift[f, 0]], [0.0, 1.0, shift[f, 1]]])
            d = cv2.warpAffine(d, m, d.shape[::-1], flags=cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT,
                               borderValue=0)
        yield d


def write_media(sim, folder: str | Path, render=None, depth: bool = False, depth_noise=None) -> dict[str, Path]:
    """Write ``folder``/video.mp4 and, with ``depth``, ``folder``/recording.db3. Returns {name: path}.

    ``render``: the camera nuisances (:class:`~rce_gtsam.sim.nuisance.RenderConfig`); ``depth_noise``: a
    :class:`~rce_gtsam.sim.depth.DepthNoise` (None: the default D435i-like errors). Depth needs the 3-D scene
    (``sim.three_d``) and a whole number of frames per second.
    """
    from .nuisance import RenderConfig
    from .render import iter_frames, write_h264
    folder = Path(folder)
    cfg = render or RenderConfig()
    video = folder / "video.mp4"
    frames = iter_frames(sim, config=cfg)
    common = dict(fps=sim.config.fps, size=sim.config.image_size, crf=cfg.crf, pixel_format="bgr24")
    if not depth:
        write_h264(frames, video, **common)
        return {"video.mp4": video}
    if sim.three_d is None:
        raise ValueError("depth needs the 3-D scene: simulate with scene3d=Scene3D() or the out_of_plane effect")
    fps = sim.config.fps
    if abs(fps - round(fps)) > 1e-9:
        raise ValueError(f"a RealSense recording needs a whole number of frames per second, got {fps}")
    from .realsense_writer import write_recording
    F = sim.true_xy.shape[1]
    w, h = sim.config.image_size
    colour = np.empty((F, h, w, 3), np.uint8)
    depth_mm = np.empty((F, h, w), np.uint16)

    def tee():
        for f, (img, d) in enumerate(zip(frames, depth_frames(sim, cfg, depth_noise))):
            colour[f] = img[..., ::-1]   # BGR -> RGB
            depth_mm[f] = d
            yield img

    write_h264(tee(), video, **common)
    rec = write_recording(folder / RECORDING_NAME, colour, depth_mm, sim.three_d.camera,
                          fps=int(round(fps)))
    return {"video.mp4": video, RECORDING_NAME: Path(rec)}
