"""The default Rerun layout: the image (video, tracks, skeletons) beside the time series, documents below.

First screen: left, the image view; right, the excitation z_t, observed vs predicted bending of the
edges the model fits worst, and their residuals; a tab row with the compliance table and (when there is
one) the diagnosis report and held-out error chart.
"""

from __future__ import annotations

import rerun.blueprint as rrb

from .scene import AnalysisView, worst_edges


def build_blueprint(view: AnalysisView, diagnosis=None, video: bool = False, n_edges: int = 3) -> rrb.Blueprint:
    """Blueprint for a recording of ``view`` (and ``diagnosis``). ``n_edges``: how many of the worst-fitted
    edges the bending and residual plots show first (every edge is in the recording)."""
    worst = [view.edge_name(e) for e in worst_edges(view, n_edges)]
    # after a verdict the skeleton coloured by the kappa to report replaces the rank-1 one (both are recorded)
    hide = [] if view.kappa_report is None else ["- $origin/skeleton/kappa"]
    image = rrb.Spatial2DView(origin="image", name="Video, tracks and skeletons" if video else "Tracks and skeletons",
                              contents=["+ $origin/**", *hide])
    series = rrb.Vertical(
        rrb.TimeSeriesView(origin="excitation", name="Excitation z_t (deg)"),
        rrb.TimeSeriesView(origin="bending", contents=[f"$origin/{n}/**" for n in worst],
                           name="Bending: observed vs predicted (worst-fitted edges, deg)"),
        rrb.TimeSeriesView(origin="residuals", contents=[f"$origin/{n}" for n in worst],
                           name="Residuals (deg)"),
    )
    docs = [rrb.TextDocumentView(origin="summary/table", name="Compliance")]
    if diagnosis is not None:
        docs.insert(0, rrb.TextDocumentView(origin="diagnosis/report", name="Diagnosis"))
        docs.append(rrb.BarChartView(origin="diagnosis/heldout", name="Held-out RMSE: baseline, candidates"))
        docs.append(rrb.BarChartView(origin="diagnosis/budget/unexplained_deg2",
                                     name="Unexplained variance per segment (deg², root → tip)"))
        docs.append(rrb.TimeSeriesView(origin="diagnosis/after", name="Before / after adding the effect"))
    if view.kappa_report is not None:
        docs.append(rrb.BarChartView(origin="summary/kappa_to_report",
                                     name=f"{view.report_column}, the κ to report, per edge (root → tip)"))
    docs.append(rrb.BarChartView(origin="summary/kappa", name="κ per edge (root → tip)"
                                 + (", rank-1" if view.kappa_report is not None else "")))
    return rrb.Blueprint(
        rrb.Vertical(rrb.Horizontal(image, series, column_shares=[3, 2]), rrb.Tabs(*docs), row_shares=[3, 1]),
        rrb.TimePanel(state="collapsed"),
        collapse_panels=False,
    )
