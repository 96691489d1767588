"""What limits kappa (rce_gtsam.kappa_floor): the floor a tracker error of e px sets on this branch and this
bending, with e estimated from the recording's residuals, against kappa's measured error where the truth is known.
"""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from rce_gtsam.kappa_floor import KappaFloor, kappa_floor_of
from rce_gtsam.pipeline import analyze
from rce_gtsam.sim.simulate import NoiseConfig, SimulationConfig, simulate


def white(e: float) -> NoiseConfig:
    """Isotropic white node error of e px per axis; no drift, gaps or jumps."""
    return NoiseConfig(sigma_across_px=e, along_ratio=1.0, tip_factor=1.0, drift_px=0.0, gap_rate=0.0, jump_prob=0.0)


def log_rmse(est, tru) -> float:
    d = np.log(est) - np.log(tru)
    d -= d.mean()
    return float(np.sqrt(np.mean(d ** 2)))


@pytest.fixture(scope="module")
def white_runs():
    """(measured log-RMSE, floor, estimated e) on six simulated branches under white node error of 0.6 px."""
    out = []
    for seed in range(6):
        sim = simulate(SimulationConfig(n_frames=450, seed=seed, noise=white(0.6)))
        r = analyze(sim.tracks, sim.graph, n_boot=0)
        tru = np.array([sim.kappa_true[tuple(e)] for e in r.response.edges])
        f = r.kappa_floor
        out.append((log_rmse(r.fit.kappa, tru), f.log_rmse, f.node_error_px, f))
    return out


def test_the_node_error_is_estimated_before_smoothing(white_runs):
    # the node-wise estimate reads the error after the smoother; the floor takes it back through the smoother's
    # gain (without that correction it reads ~0.2 px here)
    est = np.array([r[2] for r in white_runs])
    assert np.all(np.abs(est / 0.6 - 1) < 0.15), est


def test_the_floor_is_the_error_white_node_noise_gives_kappa(white_runs):
    measured = np.sqrt(np.mean([r[0] ** 2 for r in white_runs]))
    floor = np.sqrt(np.mean([r[1] ** 2 for r in white_runs]))
    assert 1 / 1.5 < measured / floor < 1.5, (measured, floor)


def test_half_the_error_lowers_the_floor_and_every_field_is_finite(white_runs):
    f: KappaFloor = white_runs[0][3]
    assert 0 < f.log_rmse_half_error < f.log_rmse
    assert np.isfinite(f.angle_noise_deg).all() and np.isfinite(f.bend_rms_deg).all()
    assert np.isfinite(f.log_rmse_per_segment).all() and f.segment_px.min() > 0
    # the segments' floors make up the whole: their RMS is the log-RMSE (both over the same draws)
    assert np.sqrt(np.mean(f.log_rmse_per_segment ** 2)) == pytest.approx(f.log_rmse, rel=1e-6)
    # the angle noise is e through the bend's geometry: about 2.4 e / L rad on an even chain, less the smoother
    assert 0.2 < np.median(f.angle_noise_deg) < 3.0


def test_the_floor_grows_with_the_node_error():
    sim = simulate(SimulationConfig(n_frames=450, seed=3, noise=white(0.3)))
    r = analyze(sim.tracks, sim.graph, n_boot=0)
    floors = [kappa_floor_of(r, node_error_px=e).log_rmse for e in (0.1, 0.4, 1.6)]
    assert floors[0] < floors[1] < floors[2]


def test_the_viewer_reads_the_floor_from_the_result():
    from rce_gtsam.viz.rerun_log import summary_markdown
    from rce_gtsam.viz.scene import AnalysisView
    sim = simulate(SimulationConfig(n_frames=300, seed=1, noise=white(0.3)))
    r = analyze(sim.tracks, sim.graph, n_boot=0)
    view = AnalysisView.from_result(r)
    assert view.floor_text == r.kappa_floor.line() and "floor (×)" in summary_markdown(view)
    assert np.allclose(view.floor_log_rmse, r.kappa_floor.log_rmse_per_segment)


def test_seeded_and_absent_for_an_extended_model():
    sim = simulate(SimulationConfig(n_frames=300, seed=1, noise=white(0.3)))
    r = analyze(sim.tracks, sim.graph, n_boot=0)
    a, b = kappa_floor_of(r, seed=4), kappa_floor_of(r, seed=4)
    assert a.log_rmse == b.log_rmse
    ext = analyze(sim.tracks, sim.graph, n_boot=0, effects=("delay",))
    assert ext.kappa_floor is None


def test_rce_analyze_prints_it_and_writes_it(tmp_path):
    sim = simulate(SimulationConfig(n_frames=300, seed=2, noise=white(0.5)))
    sim.write(tmp_path / "sim")
    out = tmp_path / "out"
    p = subprocess.run([sys.executable, "-m", "rce_gtsam.cli", "analyze", str(tmp_path / "sim" / "tracks.csv"),
                        str(tmp_path / "sim" / "graph.json"), "--out", str(out), "--quiet"],
                       capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    assert "what limits kappa: a tracker error of" in p.stdout and "median segment x" in p.stdout
    assert "worst " in p.stdout.split("median segment x", 1)[1].split("\n")[0]
    rep = json.loads((out / "report.json").read_text())["kappa_floor"]
    assert rep["node_error_px"] == pytest.approx(0.5, rel=0.25)
    assert rep["log_rmse_half_error"] < rep["log_rmse"]
    assert len(rep["log_rmse_per_segment"]) == len(rep["segment_px"]) == len(rep["edges"])
    import pandas as pd
    table = pd.read_csv(out / "compliance_summary.csv")  # each segment's floor beside its interval
    assert sorted(table.floor_log_rmse.dropna()) == pytest.approx(sorted(rep["log_rmse_per_segment"]))
    # the Rerun viewer's compliance table (rce view DIR reads the folder): a floor column and the same lines
    from rce_gtsam.viz.rerun_log import summary_markdown
    from rce_gtsam.viz.scene import AnalysisView
    view = AnalysisView.from_folder(out)
    md = summary_markdown(view)
    assert "floor (×)" in md and view.floor_text.split("\n")[0] in p.stdout and "what limits kappa" in md
    assert np.isfinite(view.floor_log_rmse).all() and len(view.floor_log_rmse) == len(view.edges)


def test_a_short_branch_falls_back_on_the_tracker_s_own_sigma():
    # three bends on a chain share too few node pairs (3) to read the error from the residuals
    from rce_gtsam.sim.simulate import NoiseConfig
    sim = simulate(SimulationConfig(n_nodes=5, n_frames=300, seed=0,
                                    noise=NoiseConfig(sigma_across_px=0.4, along_ratio=1.0, tip_factor=1.0,
                                                      drift_px=0.0, gap_rate=0.0, jump_prob=0.0, emit_sigma=True)))
    r = analyze(sim.tracks, sim.graph, n_boot=0)
    f = r.kappa_floor
    assert f is not None and f.source == "the tracker's own sigma"
    assert f.node_error_px == pytest.approx(float(np.nanmedian(sim.tracks.sigma_px)))
    bare = analyze(type(sim.tracks)(node_ids=sim.tracks.node_ids, xy=sim.tracks.xy, source="no sigma"), sim.graph,
                   n_boot=0)
    assert bare.kappa_floor is None
