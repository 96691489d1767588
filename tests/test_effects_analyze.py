"""`rce analyze --effects`: the extended model's kappa, its bootstrap CIs and parameters in report.json."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

import rce_gtsam
from rce_gtsam.cli import main
from rce_gtsam.effects import EFFECT_NAMES
from rce_gtsam.errors import InputError

FILES = {"compliance_summary.csv", "excitation.csv", "bending.csv", "smoothed_tracks.csv", "report.json"}


@pytest.fixture(scope="module")
def offset_sim(tmp_path_factory):
    """Noise-free tracks of a branch whose rest pose is off and creeps (the hidden `offset` effect)."""
    out = tmp_path_factory.mktemp("offset_sim")
    assert main(["simulate", "--clean", "--effect", "offset", "--seed", "0", "--frames", "400", "--nodes", "12",
                 "--out", str(out)]) == 0
    return out


def _kappa_log_error(summary: pd.DataFrame, truth: dict) -> float:
    s = summary.dropna(subset=["kappa"])
    kt = np.array([truth["kappa_true"][f"{p}->{c}"] for p, c in zip(s["parent"], s["child"])])
    return float(np.sqrt(np.mean(np.log(s["kappa"].to_numpy() / kt) ** 2)))


def test_offset_effect_lowers_fit_error_and_kappa_error(offset_sim, tmp_path, capsys):
    truth = json.loads((offset_sim / "truth.json").read_text())
    args = [str(offset_sim / "tracks.csv"), str(offset_sim / "graph.json"), "--bootstrap", "40", "--seed", "2"]
    assert main(["analyze", *args, "--out", str(tmp_path / "plain"), "--no-figures"]) == 0
    assert main(["analyze", *args, "--out", str(tmp_path / "ext"), "--effects", "offset"]) == 0
    printed = capsys.readouterr().out
    assert "rank1 + offset" in printed and "(rank-1) ->" in printed
    plain = pd.read_csv(tmp_path / "plain" / "compliance_summary.csv")
    ext = pd.read_csv(tmp_path / "ext" / "compliance_summary.csv")
    rmse_plain, rmse_ext = plain["fit_rmse_deg"].mean(), ext["fit_rmse_deg"].mean()
    assert rmse_ext < 0.5 * rmse_plain, (rmse_plain, rmse_ext)
    assert _kappa_log_error(ext, truth) < _kappa_log_error(plain, truth)
    # complete output folder, figures included
    names = {p.name for p in (tmp_path / "ext").iterdir()}
    assert FILES | {"figures"} <= names
    assert {"compliance.png", "residuals.png"} <= {p.name for p in (tmp_path / "ext" / "figures").iterdir()}
    ok = ext.dropna(subset=["kappa"])
    assert np.isfinite(ok[["kappa_ci_low", "kappa_ci_high"]].to_numpy()).all()
    assert (ok["kappa_ci_low"] <= ok["kappa_ci_high"]).all()
    # the intervals of the extended model contain its estimates (they are placed about them)
    assert ((ok["kappa_ci_low"] <= ok["kappa"]) & (ok["kappa"] <= ok["kappa_ci_high"])).all()
    rep = json.loads((tmp_path / "ext" / "report.json").read_text())
    eff = rep["effects"]
    assert eff["names"] == ["offset"] and eff["model"] == "rank1 + offset"
    assert eff["fit"]["rmse_deg"] < eff["fit"]["baseline_rank1_rmse_deg"]
    c0 = eff["parameters"]["offset"]["c[0]"]
    assert c0["unit"] == "deg" and c0["stderr"] > 0
    assert eff["bootstrap"]["n_boot"] == 40 and "phase-randomised" in eff["bootstrap"]["scheme"]
    assert "effects" not in json.loads((tmp_path / "plain" / "report.json").read_text())


def test_extended_model_starts_from_the_analysis_fit_and_its_cis_contain_the_estimates(offset_sim):
    """One engine: the extended model's starting (rank-1) fit is the plain analysis' fit, under both presets;
    the paper preset's block bootstrap (frame multiplicities) also gives intervals about the estimate."""
    args = (offset_sim / "tracks.csv", offset_sim / "graph.json")
    for preset in ("default", "paper"):
        plain = rce_gtsam.analyze(*args, preset=preset, n_boot=0)
        ext = rce_gtsam.analyze(*args, preset=preset, n_boot=30, effects=("offset",))
        plain_rmse = float(np.sqrt(np.nanmean((plain.response.Y - plain.fit.predict()) ** 2)))
        assert ext.fit.baseline_rmse_deg == pytest.approx(plain_rmse, rel=1e-12)
        k = ext.fit.kappa
        assert ((ext.ci.low <= k) & (k <= ext.ci.high)).all(), (preset, ext.ci.low, k, ext.ci.high)
    assert "multiplicities" in ext.effects_report()["bootstrap"]["scheme"]


def test_extended_fit_splits_the_rows_by_the_tracked_nodes_the_diagnosis_uses(offset_sim, monkeypatch):
    """The extended fit keeps the start that predicts one node-disjoint row set from the other best, as the
    diagnosis does: both take each row's tracked nodes from the bending (not parsed from "joint->child" labels,
    which stand a placeholder in for the root)."""
    import rce_gtsam.pipeline as pipeline
    seen = {}
    real = pipeline.fit_extended

    def spy(*a, **kw):
        seen.update(kw)
        return real(*a, **kw)

    monkeypatch.setattr(pipeline, "fit_extended", spy)
    res = rce_gtsam.analyze(offset_sim / "tracks.csv", offset_sim / "graph.json", n_boot=0, effects=("offset",))
    assert seen["edge_nodes"] == [res.bending.bends[k].nodes for k in res.response.bend_rows]


def test_reports_label_the_rows_as_the_response_does(offset_sim):
    """One source for the "joint->child" row labels: the response's, in order (the variance budget and the
    labels the diagnosis would parse tracked nodes from read them there)."""
    from rce_gtsam.diagnosis.budget import budget_of
    from rce_gtsam.model.row_sets import UNKNOWN_PARENT, edge_nodes_from_labels

    res = rce_gtsam.analyze(offset_sim / "tracks.csv", offset_sim / "graph.json", n_boot=0)
    labels = res.response.edge_labels
    assert labels == [f"{j}->{c}" for j, c in res.response.edges]
    assert [row["segment"] for row in budget_of(res).per_segment] == labels
    nodes = edge_nodes_from_labels(labels)
    bends = [res.bending.bends[k] for k in res.response.bend_rows]
    assert all(n - {UNKNOWN_PARENT} <= set(map(str, b.nodes)) for n, b in zip(nodes, bends)), (nodes, bends)


def test_extended_fit_keeps_the_rank1_interface(chain):
    tracks, graph, _, _ = chain
    res = rce_gtsam.analyze(tracks, graph, n_boot=12, effects=("delay",))
    E, T = res.response.Y.shape
    fit = res.fit
    assert fit.kappa.shape == (E,) and (fit.kappa > 0).all()
    assert set(np.unique(fit.direction)) <= {-1.0, 1.0}
    assert fit.z.shape == (T,) and fit.predict().shape == (E, T)
    assert fit.iterations >= 1 and isinstance(fit.converged, bool)
    assert np.isclose(np.exp(np.log(fit.kappa).mean()), 1.0)
    assert res.ci.samples.shape == (12, E)
    # an operator effect's shared parameters (the lag) are held at the full fit in the resamples, and said so
    assert res.effects_report()["bootstrap"]["shared_parameters"].startswith("fixed at the full-data fit")
    assert "tau" in res.effects_report()["parameters"]["delay"]
    assert len(res.summary()) == len(res.graph.edges)


def test_unknown_effect_lists_the_valid_names(chain, tmp_path, capsys):
    tracks, graph, _, _ = chain
    with pytest.raises(InputError) as exc:
        rce_gtsam.analyze(tracks, graph, n_boot=0, effects=("offset", "gravity"))
    assert "gravity" in str(exc.value) and all(n in str(exc.value) for n in EFFECT_NAMES)
    out = tmp_path / "o"
    assert main(["analyze", str(tracks), str(graph), "--out", str(out), "--effects", "delays"]) == 2
    err = capsys.readouterr().err
    assert "delays" in err and "nonlinear" in err and not out.exists()
