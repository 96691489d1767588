"""Figures and overlays: files exist, are real PNGs, and plot the right numbers."""

from __future__ import annotations

import numpy as np
import pytest

from viz_fixtures import small_analysis


@pytest.fixture(scope="module")
def analysis():
    return small_analysis()


def _png_ok(path, min_bytes=8_000):
    from PIL import Image
    assert path.is_file() and path.stat().st_size > min_bytes, path
    with Image.open(path) as im:
        assert im.format == "PNG"
        w, h = im.size
        assert w > 400 and h > 200, (path, im.size)
        a = np.asarray(im.convert("L"), dtype=float)
        assert a.std() > 5, f"{path.name} looks blank"


def test_write_figures(analysis, tmp_path):
    from rce_gtsam.viz import write_figures
    _, result = analysis
    files = write_figures(result, tmp_path)
    assert set(files) == {"smoothing.png", "motion.png", "compliance.png", "excitation.png", "residuals.png",
                          "bending_fit.png"}
    for p in files.values():
        _png_ok(p)


def test_compliance_figure_plots_every_kappa_with_its_ci(analysis):
    import matplotlib.pyplot as plt
    from matplotlib.container import ErrorbarContainer
    from rce_gtsam.viz.figures import fig_compliance
    _, result = analysis
    fig = fig_compliance(result)
    ax_k, ax_u = fig.axes[:2]
    bars = [c for c in ax_k.containers if isinstance(c, ErrorbarContainer)]  # one per zone
    ys = sorted(float(y) for c in bars for y in c.lines[0].get_ydata())
    np.testing.assert_allclose(ys, np.sort(result.fit.kappa))  # every edge's kappa, once
    spans = sorted(float(np.ptp(seg[:, 1])) for c in bars for seg in c.lines[2][0].get_segments())
    np.testing.assert_allclose(spans, np.sort(result.ci.high - result.ci.low), rtol=1e-9)  # and its CI
    heights = [p.get_height() for p in ax_u.patches]
    np.testing.assert_allclose(heights, np.nan_to_num(result.uncertainty), rtol=1e-9)
    assert ax_k.get_yscale() == "log" and "κ" in ax_k.get_ylabel()
    plt.close(fig)


def test_residual_heatmap_is_centred_at_zero(analysis):
    import matplotlib.pyplot as plt
    from rce_gtsam.viz.figures import fig_residuals
    _, result = analysis
    fig = fig_residuals(result)
    im = next(ax.images[0] for ax in fig.axes if ax.images)
    lo, hi = im.norm.vmin, im.norm.vmax
    assert lo == pytest.approx(-hi) and hi > 0
    assert im.get_array().shape == result.response.Y.shape
    plt.close(fig)


def test_overlays_with_and_without_frame(analysis, tmp_path):
    from rce_gtsam.viz import write_overlays
    _, result = analysis
    frame = np.random.default_rng(0).integers(60, 200, size=(480, 640, 3), dtype=np.uint8)
    for sub, ff in (("bg", None), ("frame", frame)):
        files = write_overlays(result, tmp_path / sub, first_frame=ff)
        assert set(files) == {"kappa_overlay.png", "uncertainty_overlay.png"}
        for p in files.values():
            _png_ok(p, min_bytes=5_000)


def test_after_a_verdict_the_overlays_draw_the_kappa_to_report_on_one_scale(analysis, tmp_path, monkeypatch):
    """With the κ of a model with a named effect (``kappa_choice.fitted``), write_overlays also draws it on the
    frame (kappa_to_report_overlay.png, its own quality's flags), the rank-1 overlay's title says it is not the κ
    to report, and both use one colour scale spanning both κ (here the extended κ reaches 3x further)."""
    import dataclasses

    from rce_gtsam.kappa_report import KappaChoice
    from rce_gtsam.viz import overlays
    _, result = analysis
    k = np.asarray(result.fit.kappa, float)
    ext = k.copy()
    ext[0] = 3.0 * k.max()
    choice = KappaChoice("delay", "rank-1 + delay", "named", tuple(result.response.edges), ext, ext / 1.1, ext * 1.1,
                         np.nan_to_num(result.response.Y))
    drawn = {}
    real = overlays.fig_overlay

    def spy(res, values, label, cmap, first_frame=None, **kw):
        fig = real(res, values, label, cmap, first_frame, **kw)
        coloured = [c for c in fig.axes[0].collections if c.get_array() is not None]  # the κ-coloured segments
        drawn[kw.get("title", "")] = coloured[0].norm if kw.get("log") else None
        return fig
    monkeypatch.setattr(overlays, "fig_overlay", spy)
    files = overlays.write_overlays(dataclasses.replace(result, kappa_choice=choice), tmp_path)
    assert set(files) == {"kappa_overlay.png", "uncertainty_overlay.png", overlays.REPORTED_OVERLAY}
    _png_ok(files[overlays.REPORTED_OVERLAY], min_bytes=5_000)
    rank1_title = next(t for t in drawn if t.startswith("rank-1"))
    reported_title = next(t for t in drawn if t.startswith("κ to report"))
    assert "not the κ to report (kappa_delay is)" in rank1_title and "kappa_delay" in reported_title
    a, b = drawn[rank1_title], drawn[reported_title]
    assert (a.vmin, a.vmax) == pytest.approx((b.vmin, b.vmax)) and a.vmax >= ext[0] * 0.999
    # no verdict: the two overlays, the rank-1 one titled as before
    drawn.clear()
    plain = overlays.write_overlays(dataclasses.replace(result, kappa_choice=KappaChoice(None, "rank-1", "none")),
                                    tmp_path / "plain")
    assert set(plain) == {"kappa_overlay.png", "uncertainty_overlay.png"}
    assert any(t.startswith("κ per segment on the") for t in drawn)


def test_diagnosis_figures(analysis, tmp_path):
    from rce_gtsam.viz import write_diagnosis_figures
    _, result = analysis
    R = result.response.Y - result.fit.predict()
    diag = {"baseline": {"heldout_rmse": 1.0}, "verdict": "delay",
            "candidates": [{"effect": "delay", "heldout_rmse": 0.7}, {"effect": "offset", "heldout_rmse": 0.99}],
            "residuals": R, "after_prediction": result.fit.predict() * 1.05}
    files = write_diagnosis_figures(diag, tmp_path, result=result)
    assert set(files) == {"heldout_error.png", "residuals_diagnosis.png", "effect_before_after.png"}
    for p in files.values():
        _png_ok(p, min_bytes=5_000)


def test_kappa_to_report_figure_only_with_the_named_effects_kappa(analysis, tmp_path):
    """``rce run`` fits the named effect's model and its kappa is the one to report: kappa_to_report.png draws it
    beside the rank-1 kappa, and only when the result carries it (``kappa_choice`` with an effect and a kappa)."""
    import dataclasses

    from rce_gtsam.kappa_report import KappaChoice
    from rce_gtsam.viz import write_diagnosis_figures
    _, result = analysis
    diag = {"baseline": {"heldout_rmse": 1.0}, "verdict": "delay",
            "candidates": [{"effect": "delay", "heldout_rmse": 0.7}]}
    k = np.asarray(result.fit.kappa, float)
    for choice, drawn in ((None, False), (KappaChoice(None, "rank-1", "no verdict"), False),
                          (KappaChoice("delay", "rank-1 + delay", "named", tuple(result.response.edges), k * 1.2,
                                       k * 0.8, k * 1.7), True)):
        r = dataclasses.replace(result, kappa_choice=choice)
        files = write_diagnosis_figures(diag, tmp_path / str(drawn) / str(choice is None), result=r)
        assert ("kappa_to_report.png" in files) == drawn
    _png_ok(files["kappa_to_report.png"], min_bytes=5_000)


def test_variance_budget_figure(tmp_path):
    """variance_budget.png from diagnosis.json's budget: a row worse than no model (R^2 < 0), a row whose floor
    is only a lower bound, a negative unexplained part, and an added effect."""
    from rce_gtsam.viz.budget import fig_variance_budget
    from rce_gtsam.viz.style import save_png
    budget = {"total": 4.0, "rank1": 2.0, "effects": {"delay": 0.4}, "noise_floor": 1.0, "unexplained": 0.6,
              "unexplained_se": 0.2, "status": "inconclusive", "reason": "floor_bounded"}
    rows = [{"segment": "1->2", "total": 3.0, "rank1": -0.6, "effects": {"delay": 0.1}, "noise_floor": 0.05,
             "noise_floor_is_lower_bound": True, "unexplained": 3.45, "unexplained_se": 1.0},
            {"segment": "2->3", "total": 5.0, "rank1": 3.0, "effects": {"delay": 0.5}, "noise_floor": 1.8,
             "noise_floor_is_lower_bound": False, "unexplained": -0.3, "unexplained_se": 0.4}]
    fig = fig_variance_budget(budget, rows)
    ax = fig.axes[0]
    assert "with delay, the rest is inconclusive (floor bounded)" in ax.get_title(loc="left")
    assert [t.get_text() for t in ax.get_yticklabels()] == ["whole branch *", "1->2 *", "2->3"]
    assert ax.get_xlim()[0] < -19  # the R^2 < 0 row is drawn left of zero
    _png_ok(save_png(fig, tmp_path / "variance_budget.png"), min_bytes=5_000)


def test_figures_as_extra_writer(analysis, tmp_path):
    """write_figures plugs into AnalysisResult.write as an extra writer (atomic output folder)."""
    from rce_gtsam.viz import write_figures
    _, result = analysis
    files = result.write(tmp_path / "out", extra_writers=[lambda r, d: write_figures(r, d)])
    assert "compliance.png" in files and (tmp_path / "out" / "compliance_summary.csv").is_file()


def test_figures_split_between_two_processes(analysis, tmp_path):
    """The figure worker's job draws half of the figures in a forked child: all files, real PNGs, in order;
    a failure is raised in the caller (and the child is reaped, not left behind)."""
    from pathlib import Path

    from rce_gtsam.cli.figure_worker import draw_analysis_figures, split_by_cost
    from rce_gtsam.viz.figures import FIGURE_FILES
    from rce_gtsam.viz.overlays import OVERLAY_FILES
    _, result = analysis
    a, b = split_by_cost([*FIGURE_FILES, *OVERLAY_FILES])
    assert a and b and not set(a) & set(b)
    out = draw_analysis_figures(result, tmp_path, FIGURE_FILES, OVERLAY_FILES, processes=2)
    assert list(out) == [*FIGURE_FILES, *OVERLAY_FILES]
    for p in out.values():
        _png_ok(Path(p), min_bytes=5_000)
    with pytest.raises(Exception):
        draw_analysis_figures(None, tmp_path / "bad", FIGURE_FILES, OVERLAY_FILES, processes=2)


def test_heldout_figure_labels_do_not_overlap_and_stay_inside():
    """With all six candidates the model names ("resonances", "dynamics", ...) must not run into each other,
    and no label or title may be cut at the figure's edge."""
    from rce_gtsam.viz.figures import fig_heldout
    d = {"baseline": {"heldout_rmse": 1.0}, "verdict": "delay",
         "candidates": [{"effect": e, "heldout_rmse": v} for e, v in
                        [("delay", 0.9), ("resonances", 0.93), ("dynamics", 0.95), ("second_mode", 0.97),
                         ("offset", 0.99), ("nonlinear", 1.01)]]}
    fig = fig_heldout(d)
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    r = canvas.get_renderer()
    ax = fig.axes[0]
    boxes = [t.get_window_extent(r) for t in ax.get_yticklabels() + ax.get_xticklabels() if t.get_text()]
    assert len(boxes) >= 7
    for i, a in enumerate(boxes):
        for b in boxes[i + 1:]:
            assert not a.overlaps(b), (a, b)
    page = fig.bbox
    for t in [*ax.get_yticklabels(), *fig.texts, ax.title]:
        if t.get_text():
            bb = t.get_window_extent(r)
            assert bb.x0 >= page.x0 - 1 and bb.x1 <= page.x1 + 1, t.get_text()
    import matplotlib.pyplot as plt
    plt.close(fig)


def test_rce_runs_background_figures_redraw_the_rank1_overlay_after_a_verdict(analysis, tmp_path):
    """``rce run`` draws the overlays in a worker process before the diagnosis; after a verdict whose κ was fitted
    its diagnosis job adds kappa_to_report_overlay.png and draws kappa_overlay.png again (on the shared scale, titled
    as not the κ to report), and the collected figures hold that second draw."""
    import dataclasses

    from PIL import Image

    from rce_gtsam.cli.analyze import FiguresInBackground
    from rce_gtsam.cli.figure_worker import FigureWorker
    from rce_gtsam.kappa_report import KappaChoice
    from rce_gtsam.viz.overlays import REPORTED_OVERLAY, write_overlays
    _, result = analysis
    k = np.asarray(result.fit.kappa, float)
    choice = KappaChoice("delay", "rank-1 + delay", "named", tuple(result.response.edges), k[::-1].copy(), k / 2, k * 2,
                         np.nan_to_num(result.response.Y))
    named = dataclasses.replace(result, kappa_choice=choice)
    view = {"baseline": {"heldout_rmse": 1.0}, "verdict": "delay",
            "candidates": [{"effect": "delay", "heldout_rmse": 0.7}]}
    out = tmp_path / "out"
    out.mkdir()
    with FigureWorker() as worker:
        figs = FiguresInBackground(worker)
        figs.before_bootstrap(result)
        figs.after_bootstrap(result)
        figs.diagnosis(view, named)
        files = figs.writer(type("Bar", (), {"start": lambda self, s: None})())(named, out)
    assert {"figures/kappa_overlay.png", f"figures/{REPORTED_OVERLAY}", "figures/kappa_to_report.png"} <= set(files)
    before = write_overlays(result, tmp_path / "before", names=["kappa_overlay.png"])["kappa_overlay.png"]
    after = write_overlays(named, tmp_path / "after", names=["kappa_overlay.png"])["kappa_overlay.png"]

    def pixels(p):
        with Image.open(p) as im:
            return np.asarray(im.convert("RGB"), dtype=np.int16)
    got = pixels(out / "figures" / "kappa_overlay.png")
    assert got.shape == pixels(after).shape and np.abs(got - pixels(after)).max() == 0
    assert got.shape != pixels(before).shape or np.abs(got - pixels(before)).max() > 0
