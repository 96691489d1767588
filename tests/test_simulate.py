"""Tests of the ground-truth simulator (rce_gtsam.sim.simulate)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from rce_gtsam.errors import InputError
from rce_gtsam.graph import load_graph
from rce_gtsam.sim.simulate import (EFFECTS, NoiseConfig, SimulationConfig, angle_noise_deg, delayed,
                                oscillator_response, rank1_misfit, simulate, turning_angles_deg)
from rce_gtsam.tracks import load_tracks

CLEAN = NoiseConfig(enabled=False)


def _rest(sim):
    return np.array([sim.rest_turn_deg[b.edge] for b in sim.graph.bends])


def test_deterministic_and_seed_dependent():
    a = simulate(SimulationConfig(n_frames=120, seed=3))
    b = simulate(SimulationConfig(n_frames=120, seed=3))
    c = simulate(SimulationConfig(n_frames=120, seed=4))
    np.testing.assert_array_equal(a.tracks.xy, b.tracks.xy)
    np.testing.assert_array_equal(a.z_true, b.z_true)
    assert not np.allclose(a.z_true, c.z_true)


def test_effect_does_not_change_geometry_kappa_or_z():
    base = simulate(SimulationConfig(n_frames=150, seed=1))
    eff = simulate(SimulationConfig(n_frames=150, seed=1, effects=("delay",)))
    assert base.kappa_true == eff.kappa_true
    np.testing.assert_array_equal(base.z_true, eff.z_true)
    assert base.segment_px == eff.segment_px


@pytest.mark.parametrize("layout", ["chain", "tree"])
def test_kinematics_reproduce_response_and_geometry(layout):
    sim = simulate(SimulationConfig(n_frames=200, n_nodes=21, seed=2, branch_layout=layout,
                                    effects=EFFECTS, noise=CLEAN))
    g = sim.graph
    assert len(g.nodes) == 21 and sorted(g.nodes) == list(range(21)) and g.root == 0
    if layout == "tree":
        assert any(len(ch) == 2 for ch in g.children.values())
    ang = turning_angles_deg(sim.true_xy, sim.tracks.node_ids, g.bends)
    np.testing.assert_allclose(ang - _rest(sim)[:, None], sim.response_true, atol=1e-9)
    # segments are rigid and of the stated length
    row = {n: i for i, n in enumerate(sim.tracks.node_ids)}
    for (p, c), L in sim.segment_px.items():
        d = np.linalg.norm(sim.true_xy[row[c]] - sim.true_xy[row[p]], axis=-1)
        np.testing.assert_allclose(d, L, rtol=1e-9)
        assert 8 <= L <= 32
    # the whole motion stays inside the 640x480 image; root fixed
    assert sim.true_xy[..., 0].min() > 0 and sim.true_xy[..., 0].max() < 640
    assert sim.true_xy[..., 1].min() > 0 and sim.true_xy[..., 1].max() < 480
    assert np.ptp(sim.true_xy[row[0]], axis=0).max() == 0


def test_kappa_and_excitation_are_realistic():
    sim = simulate(SimulationConfig(seed=0))
    k = np.array(list(sim.kappa_true.values()))
    assert len(k) == len(sim.graph.bends) == 18
    assert abs(np.exp(np.mean(np.log(k))) - 1) < 1e-12
    assert 0.2 < np.std(np.log(k)) < 1.0
    z = sim.z_true
    assert np.sqrt(np.mean(z ** 2)) == pytest.approx(1.5)
    assert np.all(z[:15] == 0)                      # calm start
    assert z.min() < -0.2 and z.max() > 1.0         # signed, with gusts
    # baseline: the response is exactly rank 1
    np.testing.assert_allclose(sim.response_true, np.outer(k, z), atol=1e-12)


def test_noise_is_anisotropic_gappy_and_realistic():
    sim = simulate(SimulationConfig(seed=0))
    obs = sim.tracks.observed
    assert obs[:, 0].all()                          # frame 0 = the annotation
    frac = 1 - obs.mean()
    assert 0.005 < frac < 0.06
    # distal half misses more than the proximal half
    half = obs.shape[0] // 2
    assert (~obs[half:]).mean() > (~obs[:half]).mean()
    from rce_gtsam.sim.simulate import _tangents
    t = _tangents(sim.graph, sim.true_xy)
    d = sim.tracks.xy - sim.true_xy
    along = np.nanmedian(np.abs((d * t).sum(-1)))
    across = np.nanmedian(np.abs(d[..., 0] * -t[..., 1] + d[..., 1] * t[..., 0]))
    assert 2.0 < along / across < 4.0
    assert 0.1 < across < 0.6
    assert 1.0 < angle_noise_deg(sim) < 5.0         # real TAPIR tracks: ~1.7-3.7 deg high-pass angle noise


def test_clean_noise_config_gives_exact_positions():
    sim = simulate(SimulationConfig(n_frames=100, seed=5, noise=CLEAN))
    np.testing.assert_array_equal(sim.tracks.xy, sim.true_xy)


@pytest.mark.parametrize("effect", EFFECTS)
def test_default_effects_are_modest_but_not_rank1(effect):
    """Each default effect leaves a misfit to the best rank-1 model that is visible (> 3 % of the signal)
    but at most ~1/3 of the bending signal's RMS and below the per-frame angle noise of the raw tracks."""
    for seed in range(4):
        clean = simulate(SimulationConfig(seed=seed, effects=(effect,), noise=CLEAN))
        misfit, rms = rank1_misfit(clean.response_true)
        noise = angle_noise_deg(simulate(SimulationConfig(seed=seed)))
        assert 0.02 * rms < misfit <= rms / 3, (effect, seed, misfit / rms)
        assert misfit < noise, (effect, seed, misfit, noise)


def test_effect_equations():
    z = np.sin(np.arange(300) / 10.0)
    np.testing.assert_allclose(delayed(z, 2.5)[10:], np.sin((np.arange(10, 300) - 2.5) / 10.0), atol=1e-5)
    step = np.r_[np.zeros(10), np.ones(600)]
    y = oscillator_response(step, omega=0.2, zeta=0.2)
    assert y[-1] == pytest.approx(1.0, abs=1e-3)   # static gain 1
    assert y.max() > 1.3                            # under-damped overshoot: exp(-pi zeta / sqrt(1-zeta^2)) = 0.53
    sim = simulate(SimulationConfig(n_frames=300, seed=0, effects=("delay",), noise=CLEAN))
    tau = np.array(sim.effect_params["delay"]["tau_frames"])
    assert tau.max() == pytest.approx(15.0, rel=0.05) and np.all(np.diff(tau) > 0)
    sim = simulate(SimulationConfig(n_frames=300, seed=0, effects=("offset",), noise=CLEAN))
    p = sim.effect_params["offset"]
    k = np.array(list(sim.kappa_true.values()))
    t = np.arange(300) / 300
    expect = np.outer(k, sim.z_true) + np.array(p["c_deg"])[:, None] + np.outer(p["d_deg"], t)
    np.testing.assert_allclose(sim.response_true, expect, atol=1e-12)


def test_bad_config_is_an_input_error():
    with pytest.raises(InputError, match="unknown effect"):
        simulate(SimulationConfig(effects=("wobble",)))
    with pytest.raises(InputError, match="n_nodes"):
        simulate(SimulationConfig(n_nodes=2))
    with pytest.raises(InputError, match="effect_strength"):
        simulate(SimulationConfig(effect_strength={"delay": -1.0}))


def test_write_round_trips_and_is_safe(tmp_path):
    sim = simulate(SimulationConfig(n_frames=90, seed=7, effects=("delay", "offset")))
    out = tmp_path / "sim"
    files = sim.write(out)
    assert set(files) == {"tracks.csv", "true_tracks.csv", "graph.json", "truth.json", "annotations.json"}
    g = load_graph(out / "graph.json")
    assert g == sim.graph
    tr = load_tracks(out / "tracks.csv", g)
    np.testing.assert_allclose(tr.xy, sim.tracks.xy, atol=1e-4)
    truth = json.loads((out / "truth.json").read_text())
    assert truth["effects"] == ["delay", "offset"] and truth["seed"] == 7
    assert set(truth["kappa_true"]) == {f"{b.joint}->{b.child}" for b in g.bends}
    assert len(truth["z_true"]) == 90
    ann = json.loads((out / "annotations.json").read_text())["points"]
    np.testing.assert_allclose(ann, sim.true_xy[:, 0], atol=1e-4)
    # the overwrite policy of every command: our files are replaced, other files are left alone, and a
    # video of an earlier run is removed when this run renders none (never new tracks beside an old video)
    (out / "notes.txt").write_text("mine")
    (out / "video.mp4").write_bytes(b"old")
    (out / "tracks.csv").write_text("stale")
    files = sim.write(out)
    assert set(files) == {"tracks.csv", "true_tracks.csv", "graph.json", "truth.json", "annotations.json"}
    assert (out / "notes.txt").read_text() == "mine" and not (out / "video.mp4").exists()
    np.testing.assert_allclose(load_tracks(out / "tracks.csv", g).xy, sim.tracks.xy, atol=1e-4)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temp leftovers
    # ordinary modes (umask), not tempfile's private 0700 / 0600
    import os
    umask = os.umask(0)
    os.umask(umask)
    assert (out.stat().st_mode & 0o777) == 0o777 & ~umask
    assert {p.stat().st_mode & 0o777 for p in out.iterdir() if p.name != "notes.txt"} == {0o666 & ~umask}


def test_cli_writes_what_simulate_gives(tmp_path, capsys):
    from rce_gtsam.cli import main
    out = tmp_path / "run"
    rc = main(["simulate", "--out", str(out), "--effect", "delay", "--effect", "offset,nonlinear",
               "--frames", "60", "--nodes", "8", "--seed", "4", "--sigma", "--strength", "delay=5"])
    assert rc == 0
    printed = capsys.readouterr().out
    assert "tracks.csv" in printed and "delay (strength 5)" in printed
    sim = simulate(SimulationConfig(n_nodes=8, n_frames=60, seed=4, effects=("delay", "offset", "nonlinear"),
                                    effect_strength={"delay": 5.0}, noise=NoiseConfig(emit_sigma=True)))
    g = load_graph(out / "graph.json")
    tr = load_tracks(out / "tracks.csv", g)
    np.testing.assert_allclose(tr.xy, sim.tracks.xy, atol=1e-4)
    assert tr.sigma_px is not None and np.nanmin(tr.sigma_px) > 0
    truth = json.loads((out / "truth.json").read_text())
    assert truth["effect_params"]["delay"]["tau_tip_frames"] == 5.0


def test_cli_rejects_bad_effect_names(tmp_path, capsys):
    from rce_gtsam.cli import main
    assert main(["simulate", "--out", str(tmp_path / "x"), "--effect", "wobble"]) == 2
    assert "wobble" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_committed_samples_are_current():
    """data/sample*/ are what write_sample() makes now (regenerate: python -m rce_gtsam.sim.simulate data)."""
    from pathlib import Path

    from rce_gtsam.sim.simulate import SAMPLES
    root = Path(__file__).resolve().parents[1] / "data"
    for name, effects in SAMPLES.items():
        folder = root / name
        sim = simulate(SimulationConfig(n_nodes=20, n_frames=600, effects=effects, seed=0))
        g = load_graph(folder / "graph.json")
        assert g == sim.graph
        np.testing.assert_allclose(load_tracks(folder / "tracks.csv", g).xy, sim.tracks.xy, atol=1e-3)
        truth = json.loads((folder / "truth.json").read_text())
        assert truth["effects"] == list(effects)
        np.testing.assert_allclose(truth["z_true"], sim.z_true, atol=1e-5)


def test_held_out_forms_are_other_physics_at_a_like_strength():
    """Each effect's held-out form (EFFECT_FORMS, for checking the diagnosis on data it was not written for)
    changes the response, leaves a rank-1 misfit of the same order as the default form's, and naming an effect's
    first form changes nothing. A form that is not listed is refused naming the option."""
    from rce_gtsam.sim.simulate import EFFECT_FORMS, rank1_misfit
    for effect, forms in EFFECT_FORMS.items():
        default, held_out = list(forms)[:2]
        cfg = dict(effects=(effect,), seed=1, n_frames=300)
        plain = simulate(SimulationConfig(**cfg)).response_true
        named = simulate(SimulationConfig(**cfg, effect_form={effect: default})).response_true
        other = simulate(SimulationConfig(**cfg, effect_form={effect: held_out}))
        assert np.array_equal(plain, named)
        assert not np.allclose(plain, other.response_true)
        assert other.effect_params[effect]["form"] == held_out
        m0, r0 = rank1_misfit(plain)
        m1, r1 = rank1_misfit(other.response_true)
        assert 0.5 < (m1 / r1) / (m0 / r0) < 2.0, (effect, m0 / r0, m1 / r1)
    with pytest.raises(InputError, match=r"effect_form\['delay'\]"):
        simulate(SimulationConfig(effects=("delay",), effect_form={"delay": "cubic"}))
    from rce_gtsam.sim.simulate import EFFECT_DEFAULTS, bend_response
    with pytest.raises(ValueError, match="form 'cubic' of delay"):
        bend_response(np.ones(3), np.linspace(0, 1, 3), np.zeros(50), ("delay",), EFFECT_DEFAULTS, 30.0,
                      np.random.default_rng(0), {"delay": "cubic"})


def test_cli_form_picks_a_held_out_form_and_names_a_bad_one(tmp_path, capsys):
    from rce_gtsam.cli import main
    out = tmp_path / "run"
    assert main(["simulate", "--out", str(out), "--effect", "delay", "--form", "delay=quadratic",
                 "--frames", "60", "--nodes", "8"]) == 0
    assert "delay (strength 15, held-out form quadratic)" in capsys.readouterr().out
    truth = json.loads((out / "truth.json").read_text())
    assert truth["effect_params"]["delay"]["form"] == "quadratic"
    tau = np.array(truth["effect_params"]["delay"]["tau_frames"])
    assert tau.max() == pytest.approx(15.0) and np.all(tau <= 15.0 * np.linspace(0, 1, len(tau)).max())
    for bad, says in ((["--effect", "delay", "--form", "delay=cubic"], "--form: expected NAME=FORM"),
                      (["--form", "offset=relaxation"], "offset's form is set but the effect is not switched on")):
        assert main(["simulate", "--out", str(tmp_path / "bad"), "--frames", "60", *bad]) == 2
        assert says in capsys.readouterr().err
        assert not (tmp_path / "bad").exists()


def test_cli_output_cut_short_by_its_reader_ends_quietly(tmp_path):
    """``rce simulate ... | head -c0``: the reader goes away before the first line (it closes the pipe while the
    command is still importing, so its first print meets a closed pipe); no traceback, exit 141 as Unix tools."""
    import os
    import subprocess
    import sys
    cmd = [sys.executable, "-c", "import sys; from rce_gtsam.cli import main; sys.exit(main())", "simulate",
           "--out", str(tmp_path / "run"), "--frames", "30", "--nodes", "5"]
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         env={**os.environ, "PYTHONUNBUFFERED": "1"})
    p.stdout.close()
    err = p.stderr.read().decode()
    assert p.wait(timeout=120) == 141, err
    assert "Traceback" not in err and "BrokenPipe" not in err


def test_cli_crf_sets_the_videos_compression_and_names_a_bad_one(tmp_path, capsys):
    """--crf overrides the realism preset's compression: a lossless render is many times the crf-28 file (the same
    frames), and a crf outside x264's range, or without a video, is refused in one line before any work."""
    from rce_gtsam.cli import main
    sizes = {}
    for crf in ("0", "28"):
        out = tmp_path / f"crf{crf}"
        assert main(["simulate", "--out", str(out), "--frames", "20", "--nodes", "6", "--video", "--crf", crf]) == 0
        sizes[crf] = (out / "video.mp4").stat().st_size
    assert sizes["0"] > 5 * sizes["28"]
    capsys.readouterr()
    for bad in (["--video", "--crf", "52"], ["--crf", "18"]):
        assert main(["simulate", "--out", str(tmp_path / "bad"), "--frames", "20", *bad]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "--crf" in err[0]
        assert not (tmp_path / "bad").exists()
