"""rce_gtsam: relative compliance of plant branches from monocular video.

Python API in one line: ``result = rce_gtsam.analyze("tracks.csv", "graph.json", preset="default")``.

The names below are imported on first use (PEP 562), so ``import rce_gtsam`` — and with it ``rce --help``
— does not pay for numpy and pandas.
"""

from importlib import import_module

from .version import __version__

#: public name -> module that defines it
_LAZY = {"InputError": "errors", "RceError": "errors", "Bend": "graph", "BranchGraph": "graph",
         "load_graph": "graph", "PRESETS": "presets", "Preset": "presets", "get_preset": "presets",
         "Tracks": "tracks", "load_tracks": "tracks",
         # the real function (its signature and docstring for help()), imported when first named
         "analyze": "pipeline"}


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(import_module(f".{_LAZY[name]}", __name__), name)
        globals()[name] = value
        return value
    if name == "batch":  # rce_gtsam.batch (Dask) is imported on first use, so `import rce_gtsam` stays light
        return import_module(".batch", __name__)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY) | {"batch"})


__all__ = ["InputError", "RceError", "Bend", "BranchGraph", "load_graph", "Tracks", "load_tracks",
           "PRESETS", "Preset", "get_preset", "analyze", "__version__"]
