"""Inspection: Rerun recordings, matplotlib figures and first-frame overlays of an analysis.

Writers the commands call (each returns what it wrote):

* :func:`write_figures` ``(result, out_dir, diagnosis=None) -> dict[str, Path]`` — PNG figures;
* :func:`write_diagnosis_figures` ``(diagnosis, out_dir, result=None) -> dict[str, Path]``;
* :func:`write_overlays` ``(result, out_dir, first_frame=None) -> dict[str, Path]`` — kappa / U_e on the
  first video frame (or a neutral background);
* :func:`save_recording` ``(result, path, video_path=None, diagnosis=None) -> Path`` — one ``.rrd``;
* :func:`log_analysis` ``(result, rec, video_path=None)`` / :func:`log_diagnosis` ``(diagnosis, rec)``.

matplotlib, rerun and the scene are imported lazily (on first use of a name), so importing this package,
or one of its modules such as :mod:`.figures` in the figure worker, stays cheap (rerun alone is ~0.4 s).
"""

_LAZY = {"log_analysis": "rerun_log", "log_diagnosis": "rerun_log", "save_recording": "rerun_log",
         "spawn_viewer": "rerun_log", "AnalysisView": "scene", "predicted_skeleton": "scene"}


def __getattr__(name: str):
    """The Rerun and scene names, imported on first use (PEP 562)."""
    if name not in _LAZY:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    from importlib import import_module
    value = getattr(import_module(f".{_LAZY[name]}", __name__), name)
    globals()[name] = value
    return value


def write_figures(result, out_dir, diagnosis=None):
    """See :func:`rce_gtsam.viz.figures.write_figures`."""
    from .figures import write_figures as _w
    return _w(result, out_dir, diagnosis=diagnosis)


def write_diagnosis_figures(diagnosis, out_dir, result=None):
    """See :func:`rce_gtsam.viz.figures.write_diagnosis_figures`."""
    from .figures import write_diagnosis_figures as _w
    return _w(diagnosis, out_dir, result=result)


def write_overlays(result, out_dir, first_frame=None):
    """See :func:`rce_gtsam.viz.overlays.write_overlays`."""
    from .overlays import write_overlays as _w
    return _w(result, out_dir, first_frame=first_frame)


__all__ = ["AnalysisView", "predicted_skeleton", "log_analysis", "log_diagnosis", "save_recording", "spawn_viewer",
           "write_figures", "write_diagnosis_figures", "write_overlays"]
