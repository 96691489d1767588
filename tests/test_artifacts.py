"""Tests of the tracker-artifact families (rce_gtsam.sim.artifacts) and their wiring into the simulator and CLI.

Each family is checked on noise-free tracks (the default noise off), so what differs from the truth is the
artifact alone, at a scale large enough to see in a short record.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import signal

from rce_gtsam.errors import InputError
from rce_gtsam.sim.artifacts import (FAMILIES, PARAMETERS, PRESETS_PATH, ArtifactConfig, load_preset,
                                     node_kinematics, parse_families)
from rce_gtsam.sim.simulate import NoiseConfig, SimulationConfig, simulate

CLEAN = NoiseConfig(enabled=False)


def _run(families, scale=1.0, seed=1, frames=300, noise=CLEAN):
    return simulate(SimulationConfig(seed=seed, n_frames=frames, n_nodes=12, noise=noise,
                                     artifacts=ArtifactConfig(families=tuple(families), scale=scale)))


def _split(sim):
    """(along error, across error, velocity along, velocity across, speed, across displacement) per node/frame."""
    tan, nrm, v, sp = node_kinematics(sim.graph, sim.true_xy)
    e = sim.tracks.xy - sim.true_xy
    d = np.sum((sim.true_xy - sim.true_xy[:, :1]) * nrm, -1)
    return (np.sum(e * tan, -1), np.sum(e * nrm, -1), np.sum(v * tan, -1), np.sum(v * nrm, -1), sp, d)


def test_default_is_unchanged_and_no_artifacts_is_the_default():
    """An empty ArtifactConfig gives bit-identical tracks to the default (the artifacts draw from their own
    stream); data/sample*/ being current (test_simulate.test_committed_samples_are_current) pins the default
    itself."""
    a = simulate(SimulationConfig(seed=3, n_frames=120))
    b = simulate(SimulationConfig(seed=3, n_frames=120, artifacts=ArtifactConfig()))
    assert np.array_equal(a.tracks.xy, b.tracks.xy, equal_nan=True)
    c = simulate(SimulationConfig(seed=3, n_frames=120, artifacts=ArtifactConfig(("drift",))))
    # the truth and the default noise's draws are those of the same seed
    assert np.array_equal(a.true_xy, c.true_xy) and np.array_equal(a.z_true, c.z_true)
    assert not np.array_equal(a.tracks.xy, c.tracks.xy, equal_nan=True)


def test_every_family_is_zero_on_frame_0_and_deterministic():
    for fam in FAMILIES:
        s1, s2 = _run([fam], scale=3, seed=5, frames=150), _run([fam], scale=3, seed=5, frames=150)
        assert np.array_equal(s1.tracks.xy, s2.tracks.xy, equal_nan=True), fam
        np.testing.assert_array_equal(s1.tracks.xy[:, 0], s1.true_xy[:, 0])
        assert not np.array_equal(s1.tracks.xy, s1.true_xy, equal_nan=True), fam
    a, b = _run(["coloured_along"], seed=5, frames=150), _run(["coloured_along"], seed=6, frames=150)
    assert not np.allclose(a.tracks.xy - a.true_xy, b.tracks.xy - b.true_xy)


def test_families_draw_independently():
    """Switching drift on does not change the speed error's draws."""
    one = _run(["speed_error"], scale=5)
    both = _run(["speed_error", "drift"], scale=5)
    drift = _run(["drift"], scale=5)
    np.testing.assert_allclose(both.tracks.xy - one.tracks.xy, drift.tracks.xy - drift.true_xy, atol=1e-9)


def test_lag_error_opposes_velocity():
    sim = _run(["lag"], scale=40)
    ea, ec, va, vc, sp, _ = _split(sim)
    e, v = np.r_[ea.ravel(), ec.ravel()], np.r_[va.ravel(), vc.ravel()]
    assert np.corrcoef(e, v)[0, 1] < -0.8
    # the lag in frames: -e / v by least squares, close to the preset's tau at this scale for slow motion
    tau = -np.dot(e, v) / np.dot(v, v)
    q = load_preset()["lag"]
    assert 0.3 * 40 * q["tau_frames"] < tau < 2 * 40 * (q["tau_frames"] + q["tau_per_speed"] * np.percentile(sp, 95))


def test_speed_error_grows_with_speed():
    sim = _run(["speed_error"], scale=3)
    ea, ec, _, _, sp, _ = _split(sim)
    fast, slow = sp > np.percentile(sp, 75), sp < np.percentile(sp, 25)
    assert np.std(ec[fast]) > 4 * np.std(ec[slow]) and np.std(ea[fast]) > 4 * np.std(ea[slow])
    # the error's SD per unit speed is the preset's (x scale)
    q = load_preset()["speed_error"]
    moving = sp > 0.05  # the calm start and frame 0 have no motion and no error
    np.testing.assert_allclose(np.std(ec[moving] / sp[moving]), 3 * q["across_per_speed"], rtol=0.1)


def test_gust_occlusion_loses_fast_nodes_in_bursts():
    sim = _run(["gust_occlusion"], frames=600)
    *_, sp, _ = _split(sim)
    lost = ~sim.tracks.observed
    fast, slow = sp > np.percentile(sp, 80), sp < np.percentile(sp, 20)
    assert lost[fast].mean() > 3 * lost[slow].mean()
    # bursts: a lost frame is followed by a lost frame far more often than the lost share
    assert np.mean(lost[:, 1:][lost[:, :-1]]) > 3 * lost.mean()
    # positions of the frames kept are exact (occlusion moves nothing)
    ok = sim.tracks.observed
    np.testing.assert_array_equal(sim.tracks.xy[ok], sim.true_xy[ok])


def test_slide_is_along_the_branch_only_and_follows_the_deflection():
    sim = _run(["slide"], scale=20)
    ea, ec, _, _, _, d = _split(sim)
    assert np.max(np.abs(ec)) < 1e-9 and np.max(np.abs(ea)) > 0.05
    slopes = sim.artifact_params["slide"]["slope_per_node"]
    for i in range(len(slopes)):
        if np.std(d[i]) > 0.5:
            np.testing.assert_allclose(ea[i], slopes[i] * d[i], atol=1e-9)


def test_coloured_along_is_along_only_with_the_preset_spectrum():
    sim = _run(["coloured_along"], frames=1024)
    ea, ec, *_ = _split(sim)
    assert np.max(np.abs(ec)) < 1e-9
    f, P = signal.welch(ea, nperseg=256, axis=-1, detrend="linear")
    m = (f >= 1 / 128) & (f <= 1 / 10)
    beta = -np.polyfit(np.log(f[m]), np.log(P.mean(0)[m]), 1)[0]
    assert abs(beta - load_preset()["coloured_along"]["beta"]) < 0.5


def test_drift_is_slow():
    sim = _run(["drift"], frames=600)
    ea, ec, *_ = _split(sim)
    for x in (ea, ec):
        r1 = np.mean([np.corrcoef(row[1:], row[:-1])[0, 1] for row in x])
        assert r1 > 0.9
    assert np.std(ea[:, 1:]) > 0.3 * load_preset()["drift"]["along_px"]


def test_scale_zero_is_no_artifact():
    a = _run(["speed_error", "slide", "coloured_along", "drift", "lag"], scale=0.0)
    np.testing.assert_allclose(a.tracks.xy, a.true_xy, atol=1e-12)


def test_presets_are_data_with_sources():
    doc = json.loads(PRESETS_PATH.read_text())
    measured = doc["presets"]["measured"]
    assert measured["provenance"]["command"].startswith("python benchmarks/measure_artifacts.py")
    for fam in FAMILIES:
        assert set(PARAMETERS[fam]) <= set(measured[fam]) and measured[fam]["source"]
    with pytest.raises(InputError, match="no artifact preset"):
        load_preset("imagined")


def test_bad_config_and_names():
    with pytest.raises(InputError, match="wobble"):
        simulate(SimulationConfig(n_frames=20, artifacts=ArtifactConfig(("wobble",))))
    with pytest.raises(InputError, match="scale"):
        ArtifactConfig(("lag",), scale=-1.0).validate()
    assert parse_families("all") == FAMILIES and parse_families("lag, slide,lag") == ("lag", "slide")
    with pytest.raises(InputError, match="--artifacts"):
        parse_families("lag,blur")


@pytest.mark.parametrize("argv, word", [
    (["--artifacts", "blur"], "blur"),
    (["--artifacts", "lag", "--artifact-scale", "-2"], "--artifact-scale"),
    (["--artifacts", "lag", "--artifact-scale", "inf"], "--artifact-scale"),
    (["--artifact-scale", "2"], "--artifacts"),
    (["--artifacts", ","], "--artifacts"),
])
def test_cli_rejects_bad_artifacts_with_one_line(tmp_path, capsys, argv, word):
    from rce_gtsam.cli import main
    assert main(["simulate", "--out", str(tmp_path / "x"), "--frames", "30", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert word in err and len(err.splitlines()) == 1
    assert not (tmp_path / "x").exists()


def test_cli_writes_the_artifacts_and_records_them(tmp_path, capsys):
    from rce_gtsam.cli import main
    from rce_gtsam.graph import load_graph
    from rce_gtsam.tracks import load_tracks
    out = tmp_path / "run"
    assert main(["simulate", "--out", str(out), "--frames", "80", "--nodes", "8", "--seed", "2",
                 "--artifacts", "slide,gust_occlusion", "--artifact-scale", "2"]) == 0
    assert "tracker artifacts: slide, gust_occlusion at 2x" in capsys.readouterr().out
    sim = simulate(SimulationConfig(n_nodes=8, n_frames=80, seed=2,
                                    artifacts=ArtifactConfig(("slide", "gust_occlusion"), scale=2.0)))
    tr = load_tracks(out / "tracks.csv", load_graph(out / "graph.json"))
    np.testing.assert_allclose(tr.xy, sim.tracks.xy, atol=1e-4)
    truth = json.loads((out / "truth.json").read_text())
    assert truth["artifacts"]["families"] == ["slide", "gust_occlusion"] and truth["artifacts"]["scale"] == 2.0
    assert "slope_per_node" in truth["artifacts"]["params"]["slide"]
    assert truth["artifacts"]["provenance"]["command"]
    assert truth["config"]["artifacts"]["families"] == ["slide", "gust_occlusion"]
