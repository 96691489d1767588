"""rce_gtsam: relative compliance of plant branches from monocular video."""

from .errors import InputError, RceError
from .graph import Bend, BranchGraph, load_graph
from .tracks import Tracks, load_tracks

__all__ = ["InputError", "RceError", "Bend", "BranchGraph", "load_graph", "Tracks", "load_tracks"]
__version__ = "0.1.0"
