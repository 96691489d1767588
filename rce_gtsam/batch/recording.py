"""One Rerun recording that holds every recording of a batch.

Entities: ``overview/summary`` (markdown table: one line per recording with its metadata, status,
verdict, median kappa per zone and median U_e), ``overview/figures/<name>`` (the comparison PNGs of
:mod:`rce_gtsam.batch.figures`), and per recording, under ``plants/<id>/``, everything
``rce view OUT/<id>`` draws (:func:`rce_gtsam.viz.rerun_log.log_analysis` and ``log_diagnosis``: tracks,
skeletons coloured by kappa and residual, the predicted skeleton, z_t, bending, residuals, the compliance
table, the diagnosis report). Timelines ``frame`` and ``time`` are shared. Videos are not embedded (the
per-recording folders keep the paths); the blueprint has an overview tab and one tab per recording.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from .summary import RecordingSummary

APP_ID = "rce_gtsam_batch"


class PrefixedStream:
    """A :class:`rerun.RecordingStream` stand-in that logs every entity under ``prefix/``, so the
    single-recording loggers (which write ``image/...``, ``excitation/z``, ...) can fill one subtree per
    plant of a shared recording. Forwards ``log`` and ``send_columns``."""

    def __init__(self, rec: rr.RecordingStream, prefix: str):
        self.rec, self.prefix = rec, prefix.strip("/")

    def _path(self, entity: str) -> str:
        tail = str(entity).strip("/")
        return f"{self.prefix}/{tail}" if tail else self.prefix

    def log(self, entity: str, *args, **kwargs):
        return self.rec.log(self._path(entity), *args, **kwargs)

    def send_columns(self, entity: str, *args, **kwargs):
        return self.rec.send_columns(self._path(entity), *args, **kwargs)


def overview_markdown(recordings: list[RecordingSummary]) -> str:
    """Markdown table of every recording: metadata, status, verdict, median kappa per zone, median U_e."""
    meta = list(dict.fromkeys(k for r in recordings for k in r.metadata))
    head = ["id", *meta, "status", "verdict", "κ proximal", "κ mid", "κ distal", "median U_e"]
    lines = ["# Batch overview", "", "Median κ of the segments in each zone (κ is relative: geometric mean 1 "
             "per branch); U_e = CI width / κ.", "", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in recordings:
        cells = [r.id, *[r.metadata.get(m, "") for m in meta], r.status,
                 r.verdict or (r.outcome.error or "")[:80]]
        for zone in ("proximal", "mid", "distal"):
            k = r.segments["kappa"][r.segments["zone"] == zone] if not r.segments.empty else []
            cells.append(f"{np.nanmedian(k):.2f}" if len(k) else "–")
        u = r.segments["uncertainty"].to_numpy(float) if not r.segments.empty else np.array([])
        cells.append(f"{np.nanmedian(u):.2f}" if np.isfinite(u).any() else "–")
        lines.append("| " + " | ".join(str(c).replace("|", "/") for c in cells) + " |")
    return "\n".join(lines) + "\n"


def _blueprint(recordings: list[RecordingSummary], figure_names) -> rrb.Blueprint:
    overview = rrb.Vertical(
        rrb.TextDocumentView(origin="overview/summary", name="Recordings"),
        rrb.Horizontal(*[rrb.Spatial2DView(origin=f"overview/figures/{Path(n).stem}", name=Path(n).stem)
                         for n in figure_names]),
        name="Overview", row_shares=[1, 2])
    tabs = [overview]
    for r in recordings:
        if r.status != "ok":
            continue
        p = f"plants/{r.id}"
        tabs.append(rrb.Horizontal(
            rrb.Spatial2DView(origin=f"{p}/image", name=f"{r.id}: tracks and skeletons"),
            rrb.Vertical(rrb.TimeSeriesView(origin=f"{p}/excitation", name="Excitation z_t (deg)"),
                         rrb.TimeSeriesView(origin=f"{p}/residuals", name="Residuals (deg)"),
                         rrb.Tabs(rrb.TextDocumentView(origin=f"{p}/summary/table", name="Compliance"),
                                  rrb.TextDocumentView(origin=f"{p}/diagnosis/report", name="Diagnosis"),
                                  rrb.BarChartView(origin=f"{p}/summary/kappa", name="κ per edge"))),
            column_shares=[3, 2], name=r.id))
    return rrb.Blueprint(rrb.Tabs(*tabs), rrb.TimePanel(state="collapsed"), collapse_panels=False)


def save_batch_recording(recordings: list[RecordingSummary], path: str | Path,
                         figures: dict[str, Path] | Callable[[], dict[str, Path]] | None = None) -> Path:
    """Write the batch's ``.rrd`` (see the module docstring) atomically; returns its path.

    ``figures``: {file name: PNG path} of the comparison figures, or a function returning them that is
    called only once every recording is logged (so the figures can be drawn meanwhile, in another process;
    the blueprint then names :data:`~rce_gtsam.batch.figures.FIGURE_NAMES`)."""
    import json

    from ..viz.rerun_log import log_analysis, log_diagnosis
    from ..viz.scene import AnalysisView
    from .figures import FIGURE_NAMES

    figures = figures or {}
    figure_names = FIGURE_NAMES if callable(figures) else list(figures)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=".rrd", dir=path.parent)
    os.close(fd)
    try:
        rec = rr.RecordingStream(APP_ID)
        rec.save(tmp, default_blueprint=_blueprint(recordings, figure_names))
        rec.log("overview/summary", rr.TextDocument(overview_markdown(recordings), media_type=rr.MediaType.MARKDOWN),
                static=True)
        for r in recordings:
            if r.status != "ok":
                continue
            tracks = r.folder / "tracks.csv" if (r.folder / "tracks.csv").is_file() else None
            view = AnalysisView.from_folder(r.folder, tracks=tracks)
            stream = PrefixedStream(rec, f"plants/{r.id}")
            log_analysis(view, stream)
            log_diagnosis(json.loads((r.folder / "diagnosis.json").read_text()), stream, view=view)
        for name, fig in (figures() if callable(figures) else figures).items():
            rec.log(f"overview/figures/{Path(name).stem}", rr.EncodedImage(path=fig), static=True)
        rec.flush()
        rec.disconnect()
        del rec
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path
