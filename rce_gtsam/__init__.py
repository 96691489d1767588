"""rce_gtsam: relative compliance of plant branches from monocular video.

Python API in one line: ``result = rce_gtsam.analyze("tracks.csv", "graph.json", preset="default")``.
"""

from .errors import InputError, RceError
from .graph import Bend, BranchGraph, load_graph
from .presets import PRESETS, Preset, get_preset
from .tracks import Tracks, load_tracks
from .version import __version__


def analyze(*args, **kwargs):
    """See :func:`rce_gtsam.pipeline.analyze`."""
    from .pipeline import analyze as _analyze
    return _analyze(*args, **kwargs)


def __getattr__(name):
    # rce_gtsam.batch (Dask) is imported on first use, so `import rce_gtsam` stays light
    if name == "batch":
        import importlib
        return importlib.import_module(".batch", __name__)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["InputError", "RceError", "Bend", "BranchGraph", "load_graph", "Tracks", "load_tracks",
           "PRESETS", "Preset", "get_preset", "analyze", "__version__"]
