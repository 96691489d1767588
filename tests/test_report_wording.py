"""The printed report says what its numbers mean: a rise is "higher", kappa's unit is relative, the
diagnosis is timed as its own stage."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from rce_gtsam.cli.analyze import format_summary, lower_or_higher


@pytest.fixture(scope="module")
def result(tmp_path_factory):
    from conftest import make_chain

    from rce_gtsam import analyze
    tracks, graph, _, _ = make_chain(tmp_path_factory.mktemp("chain"))
    return analyze(tracks, graph, n_boot=0)


def test_a_rise_is_called_higher():
    assert lower_or_higher(45.3) == "45.3% lower"
    assert lower_or_higher(-0.3) == "0.3% higher"


def test_summary_says_higher_when_smoothing_raised_the_bending_rms(result):
    sm = result.smoothing
    raised = dataclasses.replace(sm, bend_rms_raw_deg=np.full_like(sm.bend_rms_raw_deg, 1.83),
                                 bend_rms_smoothed_deg=np.full_like(sm.bend_rms_smoothed_deg, 1.84))
    text = format_summary(dataclasses.replace(result, smoothing=raised))
    assert "bending RMS 1.83 -> 1.84 deg (0.5% higher)" in text, text
    assert "-0." not in text.split("bending RMS")[1].split(")")[0]


def test_kappa_unit_is_relative_in_the_variables_table():
    from rce_gtsam.model import ResponseModel
    rng = np.random.default_rng(0)
    z = np.sin(np.arange(200) / 9.0)
    Y = np.outer([0.5, 1.0, 2.0], z) + rng.normal(0, 0.05, (3, 200))
    rep = ResponseModel().fit(Y).report()
    rows = [r for r in rep.splitlines() if r.strip().startswith("kappa[")]
    assert rows and all("(relative)" in r for r in rows), rep
    assert not any(" 1 (" in r or r.rstrip().endswith(" 1") for r in rows), rep


def test_flagged_segments_are_dashed_and_labelled_on_the_overlay(result):
    from rce_gtsam.viz.overlays import fig_overlay
    edges = list(result.response.edges)
    flags = {edges[0]: "poor_fit+wide_ci", edges[2]: "uninformative"}
    fig = fig_overlay(result, result.kappa, "kappa", "RdYlBu_r", log=True, flags=flags)
    ax = fig.axes[0]
    dashed = [c for c in ax.collections if c.get_gid() == "flagged"]
    assert len(dashed) == 1 and len(dashed[0].get_segments()) == 2
    texts = {t.get_text() for t in ax.texts}
    assert {"poor_fit", "uninformative"} <= texts
    assert "flagged" in ax.get_legend().get_texts()[0].get_text()
    plain = fig_overlay(result, result.kappa, "kappa", "RdYlBu_r", log=True, flags={})
    assert not [c for c in plain.axes[0].collections if c.get_gid() == "flagged"]
    import matplotlib.pyplot as plt
    plt.close("all")


def test_flag_labels_never_print_over_each_other_or_the_node_ids():
    """Every segment of a 30-node branch with 8-12 px segments flagged (as on plant 2's crowded top): each label
    that is drawn has room of its own, every segment is still dashed, and the legend says that labels are drawn
    where there is room."""
    from rce_gtsam import analyze
    from rce_gtsam.sim.simulate import SimulationConfig, simulate
    from rce_gtsam.viz.overlays import fig_overlay
    sim = simulate(SimulationConfig(n_nodes=30, n_frames=120, segment_px=(8.0, 12.0), seed=3))
    crowded = analyze(sim.tracks, sim.graph, n_boot=0)
    edges = list(crowded.response.edges)
    fig = fig_overlay(crowded, crowded.kappa, "kappa", "RdYlBu_r", log=True, flags={e: "poor_fit" for e in edges})
    ax = fig.axes[0]
    fig.draw_without_rendering()
    flag_labels = [t for t in ax.texts if t.get_text() == "poor_fit"]
    flag_boxes = [t.get_window_extent() for t in flag_labels]
    id_boxes = [t.get_window_extent() for t in ax.texts if t.get_text().isdigit()]
    assert len(id_boxes) == 30
    assert not [(a, b) for i, a in enumerate(flag_boxes) for b in flag_boxes[i + 1:] + id_boxes if a.overlaps(b)]
    assert 0 < len(flag_labels) < len(edges)
    assert len([c for c in ax.collections if c.get_gid() == "flagged"][0].get_segments()) == len(edges)
    assert "labelled where there is room" in ax.get_legend().get_texts()[0].get_text()
    import matplotlib.pyplot as plt
    plt.close("all")


@pytest.mark.parametrize("status,reason,words", [
    ("noise", None, "at the noise floor"), ("misses", None, "more than noise"),
    ("inconclusive", "too_uncertain", "too short"), ("inconclusive", "floor_bounded", "only bounded")])
def test_the_budget_status_is_worded_as_what_the_model_leaves(status, reason, words):
    """One vocabulary: the budget's status is about the rest the fitted model leaves; beside a verdict it names
    the model with the verdict's effect, so "delay" and "inconclusive" cannot read as a contradiction."""
    from types import SimpleNamespace

    from rce_gtsam.diagnosis.explain import remainder_text
    b = SimpleNamespace(status=status, reason=reason)
    plain, named = remainder_text(b), remainder_text(b, "delay")
    assert plain.startswith("what the rank-1 model leaves: ") and words in plain
    assert named.startswith("what the model with delay leaves: ") and words in named
    assert "inconclusive" not in named and "delay" not in named.split(": ", 1)[1]
    assert remainder_text(None).endswith("not scored (no noise floor)")
