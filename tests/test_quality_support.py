"""Quality that tells the truth about information and support: an interval that cannot tell stiff from compliant
is ``uninformative``; a kappa resting on the calm frames is ``calm_support``; a fit that explains less than half
of the segment's signal is ``poor_fit``; a node seen in one frame drops its segments, not the run."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from rce_gtsam import analyze
from rce_gtsam.cli import main
from rce_gtsam.model.uncertainty import BootstrapCI
from rce_gtsam.quality import COMPLIANT_ABOVE, STIFF_BELOW, assess_quality, informative_line, quality_report

SAMPLE = Path(__file__).resolve().parents[1] / "data" / "sample"


def _chain_tracks(tmp_path, n_nodes=8, n_frames=600, z=None, bends=None, noise_px=0.1, seed=0, drop=None):
    """A planar chain whose joint k turns by bends[k] (degrees, (J, F)); ``drop``: {node: frames not seen}."""
    rng = np.random.default_rng(seed)
    t = np.arange(n_frames)
    if bends is None:
        kappa = np.exp(np.linspace(-0.6, 0.6, n_nodes - 2))
        bends = kappa[:, None] * z[None, :]
    xy = np.zeros((n_nodes, n_frames, 2))
    xy[0] = (320.0, 440.0)
    heading = np.full(n_frames, -90.0)
    for i in range(1, n_nodes):
        if i >= 2:
            heading = heading + (i % 3 - 1) * 2.0 + bends[i - 2]
        xy[i, :, 0] = xy[i - 1, :, 0] + 30.0 * np.cos(np.radians(heading))
        xy[i, :, 1] = xy[i - 1, :, 1] + 30.0 * np.sin(np.radians(heading))
    xy += rng.normal(0, noise_px, xy.shape)
    n, f = np.meshgrid(np.arange(n_nodes), t, indexing="ij")
    df = pd.DataFrame({"point_id": n.ravel(), "frame": f.ravel(), "x": xy[..., 0].ravel(), "y": xy[..., 1].ravel()})
    for node, frames in (drop or {}).items():
        df = df[~((df.point_id == node) & df.frame.isin(frames))]
    tracks, graph = tmp_path / "tracks.csv", tmp_path / "graph.json"
    df.to_csv(tracks, index=False)
    graph.write_text(json.dumps({"root": 0, "edges": [[i, i + 1] for i in range(n_nodes - 1)]}))
    return tracks, graph


def _sway(n_frames, seed=0):
    t = np.arange(n_frames)
    return 3.0 * np.sin(2 * np.pi * t / 70.0) + 1.5 * np.sin(2 * np.pi * t / 29.0 + 1.0)


def test_an_interval_on_both_sides_of_the_cutoffs_is_uninformative(tmp_path):
    """The rule: 95 % CI reaching below 2^-1/2 AND above 2^1/2. One side only, however wide, is informative."""
    assert STIFF_BELOW == pytest.approx(0.7071, abs=1e-4) and COMPLIANT_ABOVE == pytest.approx(1.4142, abs=1e-4)
    tracks, graph = _chain_tracks(tmp_path, z=_sway(600))
    r = analyze(tracks, graph, n_boot=20)
    E = len(r.response.edges)
    cases = [(0.50, 1.50, False), (0.30, 0.69, True), (1.20, 5.00, True), (0.75, 1.30, True), (0.69, 1.42, False),
             (0.10, 0.80, True)]
    low = np.array([c[0] for c in cases] * E)[:E]
    high = np.array([c[1] for c in cases] * E)[:E]
    ci = dataclasses.replace(r.ci, low=low, high=high)
    q = assess_quality(dataclasses.replace(r, ci=ci))
    for i, e in enumerate(r.response.edges):
        want = cases[i % len(cases)][2]
        assert q[e].informative is want, (e, low[i], high[i])
        assert ("uninformative" in q[e].reasons) is (not want)
    n_inf = sum(c[2] for c in (cases * E)[:E])
    assert informative_line(q).startswith(f"{n_inf} of {E} segments informative")
    rep = quality_report(dataclasses.replace(r, ci=ci), q)
    assert rep["n_informative"] == n_inf and rep["rules"]["uninformative_ci_below_and_above"][0] < 0.71
    assert informative_line(assess_quality(dataclasses.replace(r, ci=None))) is None  # no CI: not judged


def test_a_segment_whose_node_is_lost_in_the_gusts_rests_on_calm_frames(tmp_path):
    """Calm for the first 60 % of the clip, gusty after; node 4 lost in the gusts (seen in 60 % of the frames,
    so not tracking_lost): its bends see a small share of z's variance and are calm_support; the others not."""
    F = 600
    z = _sway(F) * np.where(np.arange(F) < 360, 0.25, 2.0)
    tracks, graph = _chain_tracks(tmp_path, z=z, drop={4: range(360, 600)})
    r = analyze(tracks, graph, n_boot=0)
    q = assess_quality(r)
    for e, v in q.items():
        bend = next(b for b in r.bending.bends if b.edge == e)
        if 4 in bend.nodes:
            assert v.z_var_seen < 0.2 and "calm_support" in v.reasons and "tracking_lost" not in v.reasons, v
        else:
            assert v.z_var_seen > 0.99 and "calm_support" not in v.reasons, v
    df = r.summary().dropna(subset=["kappa"])
    assert {"z_var_seen"} <= set(df.columns) and df["z_var_seen"].between(0, 1).all()
    rep = quality_report(r, q)
    assert all("z_var_seen" in s for s in rep["segments"].values())


def test_a_segment_that_z_explains_less_than_half_of_is_poor_fit(tmp_path):
    """Joint 3 follows z plus a stronger sway of its own (independent of z): kappa z explains some of it
    (0 < R^2, the old rule's ok) but less than half of its signal, so poor_fit; the segments that follow z
    are not."""
    F = 600
    z = _sway(F)
    bends = np.exp(np.linspace(-0.6, 0.6, 10))[:, None] * z[None, :]
    bends[3] += 8.0 * np.sin(2 * np.pi * np.arange(F) / 41.0 + 0.3)
    tracks, graph = _chain_tracks(tmp_path, n_nodes=12, bends=bends)
    r = analyze(tracks, graph, n_boot=0)
    q = assess_quality(r)
    own = next(b.edge for b in r.bending.bends if b.joint == 4)  # joint index 3 turns at node 4
    assert "poor_fit" in q[own].reasons and 0 < q[own].r2 < q[own].r2_needed, q[own]
    assert q[own].snr > 10  # flagged for the fit, not for noise
    followers = [v for e, v in q.items() if e != own and not {4} & set(next(
        b.nodes for b in r.bending.bends if b.edge == e))]
    assert followers and all("poor_fit" not in v.reasons for v in followers), followers


def test_a_node_seen_only_in_frame_0_drops_its_segments_not_the_run(tmp_path, capsys):
    t = pd.read_csv(SAMPLE / "tracks.csv")
    t[(t.point_id != 9) | (t.frame == 0)].to_csv(tmp_path / "lost.csv", index=False)
    out = tmp_path / "out"
    code = main(["analyze", str(tmp_path / "lost.csv"), str(SAMPLE / "graph.json"), "--out", str(out),
                 "--bootstrap", "20", "--no-figures", "--quiet"])
    cap = capsys.readouterr()
    assert code == 0, cap.err
    warn = [ln for ln in cap.err.splitlines() if "warning" in ln]
    assert len(warn) == 1 and "node 9" in warn[0] and "lost.csv" in warn[0] and "8->9" in warn[0], cap.err
    df = pd.read_csv(out / "compliance_summary.csv")
    graph = json.loads((SAMPLE / "graph.json").read_text())
    parent = {c: p for p, c in graph["edges"]}
    at9 = {(8, 9), (9, 10)} | {(c_p, c) for c, c_p in parent.items() if parent.get(c_p) == 9}
    for r in df.itertuples():
        if (r.parent, r.child) in at9:
            assert r.quality == "tracking_lost" and np.isnan(r.kappa), r
        elif r.parent != graph["root"]:
            assert np.isfinite(r.kappa) and "tracking_lost" not in r.quality, r
    kept = df.dropna(subset=["kappa"])
    assert np.exp(np.log(kept.kappa).mean()) == pytest.approx(1.0, abs=1e-6)  # normalised over the kept ones
    rep = json.loads((out / "report.json").read_text())["quality"]
    assert rep["lost_nodes"] == [9] and set(rep["dropped_segments"]) == {f"{p}->{c}" for p, c in at9}
    assert "dropped with a lost node" in cap.out and "(dropped: a node lost)" in cap.out


def test_nothing_usable_left_is_still_refused(tmp_path, capsys):
    tracks, graph = _chain_tracks(tmp_path, n_nodes=4, z=_sway(300), n_frames=300, drop={1: range(1, 300)})
    code = main(["analyze", str(tracks), str(graph), "--out", str(tmp_path / "o"), "--no-figures", "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and "tracks.csv" in err, err
    assert not (tmp_path / "o").exists()


def test_the_kappa_to_report_is_judged_on_its_own_model(tmp_path):
    """After a verdict the κ to report is the model with the effect's: its quality keeps the rank-1 verdict's flags
    about the data (tracking_lost here, from a node lost in most frames) and judges the model's again, poor_fit from
    that model's prediction and uninformative from its own interval. A segment the rank-1 model fits poorly but
    the extended model explains is not poor_fit; one the extended model explains worse is."""
    from rce_gtsam.kappa_report import KappaChoice
    from rce_gtsam.quality import DATA_REASONS, assess_reported_quality
    F = 600
    z = _sway(F)
    bends = np.exp(np.linspace(-0.6, 0.6, 10))[:, None] * z[None, :]
    bends[3] += 8.0 * np.sin(2 * np.pi * np.arange(F) / 41.0 + 0.3)  # joint 3 (node 4): its own sway
    tracks, graph = _chain_tracks(tmp_path, n_nodes=12, bends=bends)
    r = analyze(tracks, graph, n_boot=20)
    rank1 = assess_quality(r)
    edges = list(r.response.edges)
    own = next(b.edge for b in r.bending.bends if b.joint == 4)
    assert "poor_fit" in rank1[own].reasons
    calm = [edges[-1]]  # as if its tip node had been lost in most frames (a flag about the data)
    rank1[calm[0]] = dataclasses.replace(rank1[calm[0]], reasons=("tracking_lost", "poor_fit"))
    E = len(edges)
    prediction = np.nan_to_num(r.response.Y).copy()  # the extended model explains every bend...
    worse = next(e for e in edges if e != own and not rank1[e].reasons)
    prediction[edges.index(worse)] = 0.0  # ...but one, which it does not explain at all (R^2 = 0)
    low, high = np.full(E, 0.9), np.full(E, 1.1)
    wide = next(e for e in edges if e not in (own, worse) and e not in calm)
    low[edges.index(wide)], high[edges.index(wide)] = 0.5, 1.5
    choice = KappaChoice("delay", "rank-1 + delay", "named", tuple(edges), np.asarray(r.fit.kappa, float), low, high,
                         prediction)
    q = assess_reported_quality(dataclasses.replace(r, kappa_choice=choice), rank1)
    for e in edges:
        assert {x for x in rank1[e].reasons if x in DATA_REASONS} <= set(q[e].reasons), e
    assert all("tracking_lost" in q[e].reasons for e in calm)
    assert "poor_fit" not in q[own].reasons and "poor_fit" in q[worse].reasons
    assert "uninformative" in q[wide].reasons and q[wide].informative is False
    assert sum(v.informative is True for v in q.values()) == E - 1
    # a choice without the model's prediction cannot judge its fit: the rank-1 poor_fit stays
    blind = dataclasses.replace(choice, prediction=None)
    assert "poor_fit" in assess_reported_quality(dataclasses.replace(r, kappa_choice=blind), rank1)[own].reasons
    # without a fitted effect the κ to report is the rank-1 κ, and so is its quality
    none = dataclasses.replace(r, kappa_choice=KappaChoice(None, "rank-1", "no verdict"))
    assert assess_reported_quality(none, rank1) is rank1
    # compliance_summary.csv carries it beside the rank-1 quality, report.json counts it
    with_choice = dataclasses.replace(r, kappa_choice=choice)
    q = assess_reported_quality(with_choice)
    df = with_choice.summary().dropna(subset=["kappa"])
    by_edge = {(int(p), int(c)): s for p, c, s in zip(df.parent, df.child, df.kappa_delay_quality)}
    assert by_edge[own] == q[own].quality == "ok" and "poor_fit" in by_edge[worse]
    from rce_gtsam.results import report_dict
    rep = report_dict(with_choice)["kappa_to_report"]
    assert rep["n_informative"] == E - 1 and rep["quality"][f"{own[0]}->{own[1]}"] == "ok"
    assert rep["n_ok"] == sum(v.ok for v in q.values())
    # the printed summary lists it under the rank-1 table, each segment with its own quality
    from rce_gtsam.cli.analyze import format_summary
    text = format_summary(with_choice)
    assert "kappa to report: kappa_delay, the model with delay" in text
    table = text.split("kappa to report: kappa_delay", 1)[1]
    row = next(ln for ln in table.splitlines() if ln.strip().startswith(f"{worse[0]}->{worse[1]} "))
    assert row.endswith(q[worse].quality) and "poor_fit" in row
    assert f"quality: {rep['n_ok']} of {E} segments of kappa_delay ok" in table
    assert "kappa to report:" not in format_summary(r)  # no verdict, no second table
