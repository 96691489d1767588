"""`rce batch` on a real 2-worker Dask LocalCluster: 5 simulated track recordings, one tiny simulated
video and one broken tracks file. The summary matches each recording's folder, the broken one is reported
without stopping the others, a re-run recomputes nothing, a changed row is recomputed alone, and every
recording's files are byte for byte those of `rce analyze` + `rce diagnose` (or `rce run`) run on it alone."""

from __future__ import annotations

import csv
import json
from collections import Counter
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from rce_gtsam import batch
from rce_gtsam.cli import main
from rce_gtsam.sim.simulate import SimulationConfig, simulate

OPTS = ["--effects", "offset", "--bootstrap", "20", "--seed", "3"]
TRACK_IDS = ["p1", "p2", "p3", "p4", "p5"]


def _write_manifest(path: Path, rows: list[dict]) -> Path:
    cols = list(dict.fromkeys(k for r in rows for k in r))
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=cols)
        w.writeheader()
        w.writerows(rows)
    return path


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    root = tmp_path_factory.mktemp("batch_inputs")
    rows = []
    for i, rid in enumerate(TRACK_IDS):
        effects = ("offset",) if i % 2 else ()
        simulate(SimulationConfig(n_nodes=6, n_frames=160, seed=i, effects=effects)).write(root / rid)
        rows.append({"id": rid, "tracks": f"{rid}/tracks.csv", "graph": f"{rid}/graph.json",
                     "plant": f"plant {i}", "treatment": "wind" if i % 2 else "control"})
    simulate(SimulationConfig(n_nodes=5, n_frames=90, seed=7, image_size=(200, 160),
                              segment_px=(16.0, 24.0))).write(root / "v1", video=True)
    rows.append({"id": "v1", "video": "v1/video.mp4", "annotations": "v1/annotations.json",
                 "graph": "v1/graph.json", "plant": "plant v", "treatment": "control"})
    (root / "broken").mkdir()
    (root / "broken" / "tracks.csv").write_text("point_id,frame,x,y\n0,0,1.0,2.0\n0,1,oops,2.0\n")
    rows.append({"id": "broken", "tracks": "broken/tracks.csv", "graph": "p1/graph.json", "plant": "plant b",
                 "treatment": "control"})
    return root, _write_manifest(root / "manifest.csv", rows), rows


@pytest.fixture(scope="module")
def client():
    from distributed import Client, LocalCluster
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster, \
            Client(cluster) as c:
        yield c


@pytest.fixture(scope="module")
def first_run(inputs, client, tmp_path_factory):
    root, manifest, rows = inputs
    out = tmp_path_factory.mktemp("batch_out") / "out"
    code = main(["batch", str(manifest), "--out", str(out), "--scheduler", client.scheduler.address,
                 *OPTS, "--no-figures", "--quiet"])
    return out, code


@pytest.mark.slow  # a 2-worker LocalCluster and 7 recordings: about 30 s on an idle 2-core machine
def test_summary_matches_each_recording_and_reports_the_broken_one(inputs, first_run, capsys):
    root, manifest, rows = inputs
    out, code = first_run
    assert code == 1  # one recording failed
    summary = pd.read_csv(out / "summary.csv")
    assert list(summary.columns[:8]) == ["id", "plant", "treatment", "status", "kind", "preset", "verdict",
                                         "diagnosis_status"]
    assert summary.columns[-1] == "error"
    broken = summary[summary.id == "broken"]
    assert len(broken) == 1 and broken.status.iloc[0] == "failed" and broken.kappa.isna().all()
    assert "broken/tracks.csv" in broken.error.iloc[0] and "line 3" in broken.error.iloc[0]
    for r in rows:
        if r["id"] == "broken":
            continue
        mine = summary[summary.id == r["id"]].reset_index(drop=True)
        comp = pd.read_csv(out / r["id"] / "compliance_summary.csv")
        comp = comp[comp.kappa.notna()].reset_index(drop=True)
        assert len(mine) == len(comp) > 0
        assert (mine.status == "ok").all() and (mine.plant == r["plant"]).all()
        assert (mine.treatment == r["treatment"]).all()
        for col in ("parent", "child", "zone", "kappa", "kappa_ci_low", "kappa_ci_high", "uncertainty"):
            assert mine[col].tolist() == comp[col].tolist()
        diag = json.loads((out / r["id"] / "diagnosis.json").read_text())
        assert (mine.verdict == (diag["verdict"] or "none")).all()
        assert (mine.diagnosis_status == diag["status"]).all() and diag["status"] in {
            "effect", "adequate", "misses", "inconclusive"}
        # what limits kappa, per recording: its report.json's floor
        floor = json.loads((out / r["id"] / "report.json").read_text())["kappa_floor"]
        if floor is None:  # too few bends to read the tracker's error from the residuals, and no sigma_px
            assert mine.tracker_error_px.isna().all() and mine.kappa_floor.isna().all()
        else:
            assert np.allclose(mine.tracker_error_px, floor["node_error_px"]) and floor["node_error_px"] > 0
            assert np.allclose(mine.kappa_floor, floor["log_rmse"]) and floor["log_rmse"] > 0
    floors = [json.loads((out / r["id"] / "report.json").read_text())["kappa_floor"] for r in rows
              if r["id"] != "broken"]
    assert sum(f is not None for f in floors) >= 1
    assert set(summary[summary.id == "v1"].kind) == {"video"}
    doc = json.loads((out / "summary.json").read_text())
    assert doc["batch"]["n_recordings"] == 7 and doc["batch"]["n_failed"] == 1 and doc["batch"]["n_computed"] == 6
    by_id = {d["id"]: d for d in doc["recordings"]}
    assert by_id["broken"]["error_kind"] == "input" and by_id["p2"]["metadata"]["treatment"] == "wind"
    assert by_id["p1"]["heldout_rmse_deg"]["baseline"] > 0
    assert by_id["p1"]["budget"]["status"] in {"noise", "misses", "inconclusive"}
    assert by_id["p1"]["diagnosis_status"] == json.loads((out / "p1" / "diagnosis.json").read_text())["status"]
    assert len(by_id["p1"]["segments"]) == len(summary[summary.id == "p1"])
    assert (by_id["p1"]["kappa_floor"] or {}).get("log_rmse", np.nan) == pytest.approx(
        summary[summary.id == "p1"].kappa_floor.iloc[0], nan_ok=True)
    for name in ("kappa_by_zone.png", "verdicts.png", "uncertainty.png"):
        assert (out / "figures" / name).stat().st_size > 10_000
    from rerun.chunk import RrdReader
    paths = Counter(str(ch.entity_path) for ch in RrdReader(str(out / "batch.rrd")).stream())
    assert "/overview/summary" in paths
    # the figures are drawn in a forked process while the plants are logged, and logged last
    assert {f"/overview/figures/{n}" for n in ("kappa_by_zone", "verdicts", "uncertainty")} <= set(paths)
    for r in rows:
        if r["id"] != "broken":
            assert f"/plants/{r['id']}/image/tracks/smoothed" in paths
            assert f"/plants/{r['id']}/diagnosis/report" in paths
    assert not any(p.startswith("/plants/broken") for p in paths)


@pytest.mark.slow
def test_rerun_recomputes_nothing_and_a_changed_row_alone(inputs, first_run, tmp_path):
    root, manifest, rows = inputs
    out, _ = first_run
    options = batch.BatchOptions(effects=("offset",), n_boot=20, seed=3, figures=False)
    stamp = {p: p.stat().st_mtime_ns for p in out.glob("*/compliance_summary.csv")}
    before = pd.read_csv(out / "summary.csv")
    again = batch.run(manifest, out, options=options)  # no client: nothing to do, so no cluster either
    assert again.cluster == {"kind": "none"}
    assert Counter(o.status for o in again.outcomes.values()) == {"skipped": 6, "failed": 1}
    assert again.outcomes["broken"].error_kind == "input"
    assert {p: p.stat().st_mtime_ns for p in out.glob("*/compliance_summary.csv")} == stamp
    pd.testing.assert_frame_equal(pd.read_csv(out / "summary.csv"), before)
    changed = [dict(r, preset="paper") if r["id"] == "p2" else r for r in rows]
    m2 = _write_manifest(root / "manifest_changed.csv", changed)
    third = batch.run(m2, out, options=options, workers=1)  # the default path: a LocalCluster of its own
    assert third.cluster["kind"] == "local" and third.cluster["n_workers"] == 1
    assert {k for k, o in third.outcomes.items() if o.status == "ok"} == {"p2"}
    assert set(third.summary[third.summary.id == "p2"].preset) == {"paper"}
    # the diagnosis is not calibrated under the paper preset's settings: nothing named (diagnosis/domain.py)
    assert set(third.summary[third.summary.id == "p2"].diagnosis_status) == {"uncalibrated"}
    assert set(third.summary[third.summary.id == "p2"].verdict) == {"none"}


def _same_file(a: Path, b: Path):
    assert a.read_bytes() == b.read_bytes(), f"{a} differs from {b}"


@pytest.mark.slow
def test_results_equal_running_each_recording_alone(inputs, first_run, tmp_path):
    root, manifest, rows = inputs
    out, _ = first_run
    for rid in ("p1", "p3"):  # p2 is re-run with the paper preset by the test above
        tracks, graph = str(root / rid / "tracks.csv"), str(root / rid / "graph.json")
        alone = tmp_path / rid
        assert main(["analyze", tracks, graph, "--out", str(alone), "--no-figures", "--bootstrap", "20",
                     "--seed", "3"]) == 0
        assert main(["diagnose", tracks, graph, "--json", str(alone / "diagnosis.json"), "--effects", "offset",
                     "--seed", "3"]) == 0
        for name in ("excitation.csv", "bending.csv", "smoothed_tracks.csv", "diagnosis.json"):
            _same_file(out / rid / name, alone / name)
        # a batch row diagnoses as it analyses, as `rce run` does: its table adds which kappa to report (the
        # rank-1 kappa without a verdict) to what `rce analyze` alone writes
        batch_table = pd.read_csv(out / rid / "compliance_summary.csv")
        assert set(batch_table["report"]) <= {"kappa"} | {c for c in batch_table.columns if c.startswith("kappa_")}
        extra = ["report"] + [c for c in batch_table.columns if c.startswith("kappa_")
                              and c not in ("kappa_ci_low", "kappa_ci_high")]
        pd.testing.assert_frame_equal(batch_table.drop(columns=extra),
                                      pd.read_csv(alone / "compliance_summary.csv"))
    alone = tmp_path / "v1"
    v = root / "v1"
    assert main(["run", str(v / "video.mp4"), str(v / "annotations.json"), str(v / "graph.json"), "--out",
                 str(alone), *OPTS, "--no-figures", "--no-progress"]) == 0
    for name in ("tracks.csv", "compliance_summary.csv", "excitation.csv", "bending.csv"):
        _same_file(out / "v1" / name, alone / name)
    # diagnosis.json names the tracks.csv it analysed, which lives in each run's own output folder
    a, b = (json.loads((d / "diagnosis.json").read_text()) for d in (out / "v1", alone))
    assert a["inputs"].pop("tracks") == str(out / "v1" / "tracks.csv")
    assert b["inputs"].pop("tracks") == str(alone / "tracks.csv")
    assert a == b


@pytest.mark.parametrize("header, row, where, words", [
    ("id,tracks,graph", "a,missing.csv,g.json", "row 2, column 'tracks'", "file not found"),
    ("id,tracks,graph", "a/b,t.csv,g.json", "row 2, column 'id'", "output folder"),
    ("id,tracks,video,annotations,graph", "a,t.csv,t.csv,g.json,g.json", "row 2, column 'tracks'", "exactly one"),
    ("id,tracks,graph,preset", "a,t.csv,g.json,fast", "row 2, column 'preset'", "unknown preset"),
    ("id,tracks,graph\na,t.csv,g.json", "a,t.csv,g.json", "row 3, column 'id'", "already used by row 2"),
    ("id,graph", "a,g.json", "row 1", "'video' nor a 'tracks'"),
    ("id,tracks,graph,zone", "a,t.csv,g.json,north", "row 1", "'zone' would clash"),
])
def test_bad_manifest_is_one_line_exit_2_before_any_work(tmp_path, capsys, header, row, where, words):
    (tmp_path / "t.csv").write_text("point_id,frame,x,y\n")
    (tmp_path / "g.json").write_text("{}")
    manifest = tmp_path / "m.csv"
    manifest.write_text(f"{header}\n{row}\n")
    out = tmp_path / "out"
    assert main(["batch", str(manifest), "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(manifest) in err and where in err and words in err, err
    assert not out.exists()


def test_bad_option_is_exit_2(tmp_path, capsys):
    (tmp_path / "t.csv").write_text("point_id,frame,x,y\n")
    (tmp_path / "g.json").write_text("{}")
    manifest = tmp_path / "m.csv"
    manifest.write_text("id,tracks,graph\na,t.csv,g.json\n")
    assert main(["batch", str(manifest), "--out", str(tmp_path / "o"), "--set", "smoother.nope=1", "--quiet"]) == 2
    assert "nope" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_local_cluster_workers_run_without_the_statistical_profiler():
    """`rce batch`'s LocalCluster: Dask's profiler (a stack sample of the task every 10 ms) cost ~16 % of each
    recording's CPU time in the worker, so its workers start without it."""
    from distributed import Client

    from rce_gtsam.batch.runner import start_local_cluster
    with start_local_cluster(1) as cluster, Client(cluster) as c:
        profiling = c.run(lambda dask_worker: "profile" in dask_worker.periodic_callbacks)
    assert list(profiling.values()) == [False]


def test_recordings_compare_in_the_kappa_each_one_reports(tmp_path):
    """After a verdict a recording's kappa to report is kappa_<effect>: summary.csv's kappa_to_report columns copy
    the column its ``report`` names, and kappa_by_zone.png plots those (the recording's label starred), not the rank-1
    kappa its own run says not to report."""
    from rce_gtsam.batch import figures
    from types import SimpleNamespace

    from rce_gtsam.batch.summary import TO_REPORT, RecordingSummary, summary_table, with_kappa_to_report
    base = pd.DataFrame({"parent": [0, 1], "child": [1, 2], "zone": ["proximal", "distal"], "kappa": [0.5, 2.0],
                         "kappa_ci_low": [0.4, 1.5], "kappa_ci_high": [0.6, 2.5], "quality": ["ok", "poor_fit"]})

    def rec(i, segs):
        return RecordingSummary(id=f"r{i}", status="ok", kind="tracks", preset="default", metadata={},
                                outcome=SimpleNamespace(error=None), segments=segs, diagnosis={"verdict": None},
                                folder=tmp_path)
    plain = with_kappa_to_report(base.assign(report="kappa"))
    assert plain["kappa_to_report"].tolist() == [0.5, 2.0] and plain["kappa_to_report_quality"].tolist() == ["ok",
                                                                                                            "poor_fit"]
    named = with_kappa_to_report(base.assign(report="kappa_delay", kappa_delay=[0.8, 1.25],
                                             kappa_delay_ci_low=[0.7, 1.1], kappa_delay_ci_high=[0.9, 1.4],
                                             kappa_delay_quality=["ok", "ok"]))
    assert named[list(TO_REPORT)].values.tolist() == [[0.8, 0.7, 0.9, "ok"], [1.25, 1.1, 1.4, "ok"]]
    assert with_kappa_to_report(base) is base  # no report column (an older folder): unchanged
    table = summary_table(SimpleNamespace(metadata_columns=[]), [rec(0, plain), rec(1, named)])
    assert list(table.columns)[-5:] == [*TO_REPORT, "error"]  # last, whichever recording brought them
    plotted = []
    import matplotlib.axes
    orig = matplotlib.axes.Axes.errorbar

    def spy(self, x, y, *a, **kw):
        plotted.extend(np.asarray(y, float).tolist())
        return orig(self, x, y, *a, **kw)
    matplotlib.axes.Axes.errorbar = spy
    try:
        fig = figures.fig_kappa_by_zone([rec(0, plain), rec(1, named)])
    finally:
        matplotlib.axes.Axes.errorbar = orig
    assert sorted(plotted) == [0.5, 0.8, 1.25, 2.0]
    labels = [t.get_text() for t in fig.axes[0].get_xticklabels()]
    assert labels == ["r0", "r1 *"] and "κ of the model with the named effect" in fig._suptitle.get_text()
