"""Inspection: Rerun recordings, matplotlib figures and first-frame overlays of an analysis.

Writers the commands call (each returns what it wrote):

* :func:`write_figures` ``(result, out_dir, diagnosis=None) -> dict[str, Path]`` — PNG figures;
* :func:`write_diagnosis_figures` ``(diagnosis, out_dir, result=None) -> dict[str, Path]``;
* :func:`write_overlays` ``(result, out_dir, first_frame=None) -> dict[str, Path]`` — kappa / U_e on the
  first video frame (or a neutral background);
* :func:`save_recording` ``(result, path, video_path=None, diagnosis=None) -> Path`` — one ``.rrd``;
* :func:`log_analysis` ``(result, rec, video_path=None)`` / :func:`log_diagnosis` ``(diagnosis, rec)``.

matplotlib is imported lazily (Agg backend), so importing this package stays cheap.
"""

from .rerun_log import log_analysis, log_diagnosis, save_recording, spawn_viewer
from .scene import AnalysisView, predicted_skeleton


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
