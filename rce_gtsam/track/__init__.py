"""From video to tracks: frame sources, first-frame annotations, the default OpenCV tracker and TAPIR via ONNX.

>>> from rce_gtsam.track import open_video, load_annotations, LKTracker, LKConfig
>>> with open_video("plant.mp4") as src:
...     result = LKTracker(LKConfig()).track(src, load_annotations("annotations.json"), graph)
>>> result.write_csv("tracks.csv")
"""

from .annotations import (load_annotations, parse_polyline, place_nodes_along_polyline, validate_points,
                          write_annotation_files)
from .lk import LKConfig, LKTracker
from .result import TrackResult
from .sources import ArraySource, Frame, FrameSource, RealSenseSource, VideoFileSource, open_video

__all__ = ["ArraySource", "Frame", "FrameSource", "LKConfig", "LKTracker", "RealSenseSource", "TapirOnnxTracker",
           "TrackResult", "VideoFileSource", "load_annotations", "make_tracker", "open_video", "parse_polyline",
           "place_nodes_along_polyline", "validate_points", "write_annotation_files"]


def __getattr__(name):
    # TapirOnnxTracker imports onnxruntime lazily: only when asked for.
    if name == "TapirOnnxTracker":
        from .tapir import TapirOnnxTracker
        return TapirOnnxTracker
    raise AttributeError(name)


def make_tracker(model=None, lk_config: LKConfig | None = None):
    """The TAPIR ONNX tracker if ``model`` (folder or tapir.onnx) is given, else :class:`LKTracker`."""
    if model:
        from .tapir import TapirOnnxTracker
        return TapirOnnxTracker(model)
    return LKTracker(lk_config)
