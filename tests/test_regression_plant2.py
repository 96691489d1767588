"""The paper preset reproduces the published plant-2 results (shared/data/README.md: exactly reproducible)."""

from __future__ import annotations

import numpy as np
import pytest

import rce_gtsam
from rce_gtsam.regression import compare_with_reference


@pytest.fixture(scope="module")
def plant2_paper(shared_data):
    d = shared_data / "plant_2"
    return d, rce_gtsam.analyze(d / "tapir_tracks.csv", d / "branch_graph.json", preset="paper")


def test_kappa_and_ci_match_published(plant2_paper):
    d, result = plant2_paper
    report = compare_with_reference(result.summary(), d / "reference" / "compliance_summary.csv")
    assert len(report.table) == 23
    assert report.max_kappa_diff < 1e-3, report.format()
    assert report.max_ci_low_diff < 2e-2 and report.max_ci_high_diff < 2e-2, report.format()
    k87 = report.table.set_index(["parent", "child"]).loc[(8, 7), "kappa"]
    assert k87 == pytest.approx(2.982, abs=1e-3)


def test_smoothing_figures_match_the_supplement(plant2_paper):
    _, result = plant2_paper
    m = result.smoothing.as_dict()
    assert m["n_bends"] == 23 and m["n_edges"] == 24
    assert m["mean_bend_rms_raw_deg"] == pytest.approx(4.42, abs=0.01)
    assert m["mean_bend_rms_smoothed_deg"] == pytest.approx(2.11, abs=0.01)
    assert m["bend_rms_reduction_pct"] == pytest.approx(52.2, abs=0.5)
    assert m["mean_edge_length_cv_raw"] == pytest.approx(0.077, abs=0.001)
    assert m["mean_edge_length_cv_smoothed"] == pytest.approx(0.044, abs=0.001)
    assert m["edge_length_cv_reduction_pct"] == pytest.approx(42.8, abs=0.5)


def test_excitation_matches_published(plant2_paper, shared_data):
    import pandas as pd
    _, result = plant2_paper
    ref = pd.read_csv(shared_data / "plant_2" / "reference" / "relative_compliance_excitation_timeseries.csv")
    assert np.array_equal(ref["frame"].to_numpy(), result.response.frames)
    assert np.max(np.abs(ref["excitation_proxy_deg"].to_numpy() - result.fit.z)) < 1e-3


def test_marginals_are_reported(plant2_paper):
    _, result = plant2_paper
    cov = result.smoothed.cov
    assert cov is not None and np.all(np.isfinite(cov))
    # variances are positive and larger in occlusion gaps than at observed frames
    var = cov[..., 0, 0] + cov[..., 1, 1]
    assert (var > 0).all()
    assert var[~result.smoothed.observed].mean() > var[result.smoothed.observed].mean()
    assert result.bending.variance_deg2 is not None
