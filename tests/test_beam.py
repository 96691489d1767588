"""The finite-element beam simulator (rce_gtsam.sim.beam): closed forms, quasi-static truth, each effect's signature,
determinism, and ``rce simulate --simulator beam``."""

from __future__ import annotations

import json

import numpy as np
import pytest

from rce_gtsam.sim.beam import BEAM_EFFECTS, BeamConfig, simulate_beam
from rce_gtsam.sim.beam_fe import Mesh, natural_frequencies_hz
from rce_gtsam.sim.simulate import NoiseConfig

QUIET = NoiseConfig(enabled=False)


def uniform_mesh(n=16, L=0.8, EI=3.0, m=0.4):
    return Mesh(np.linspace(0, L, n + 1), np.full((n, 5), EI), np.full((n, 5), m)), L, EI, m


def test_uniform_cantilever_matches_closed_forms():
    mesh, L, EI, m = uniform_mesh()
    K = mesh.stiffness()
    f = np.zeros(mesh.n_dof)
    f[-2] = 2.5                                     # tip point load P (N)
    u = np.linalg.solve(K, f)
    assert u[-2] == pytest.approx(2.5 * L ** 3 / (3 * EI), rel=1e-9)         # P L^3 / 3 EI
    assert u[-1] == pytest.approx(2.5 * L ** 2 / (2 * EI), rel=1e-9)         # tip slope P L^2 / 2 EI
    q = np.full(mesh.n_el * 5, 1.5)                 # uniform load w (N/m)
    u = np.linalg.solve(K, mesh.load_operator() @ q)
    assert u[-2] == pytest.approx(1.5 * L ** 4 / (8 * EI), rel=1e-9)         # w L^4 / 8 EI
    assert u[-1] == pytest.approx(1.5 * L ** 3 / (6 * EI), rel=1e-9)         # tip slope w L^3 / 6 EI
    f1 = natural_frequencies_hz(K, mesh.mass(), 1)[0]
    assert f1 == pytest.approx(1.8751 ** 2 / (2 * np.pi) * np.sqrt(EI / (m * L ** 4)), rel=1e-4)


def sim(effects=(), frames=300, seed=4, nodes=10, **kw):
    return simulate_beam(BeamConfig(n_nodes=nodes, n_frames=frames, seed=seed, effects=effects, noise=QUIET, **kw))


@pytest.fixture(scope="module")
def free():
    return sim()


def test_effect_free_is_quasi_static_kappa_z_and_the_model_recovers_kappa(free):
    from rce_gtsam.model import ResponseModel
    k = np.array([free.kappa_true[b.edge] for b in free.graph.bends])
    assert np.all(k > 0) and np.exp(np.mean(np.log(k))) == pytest.approx(1.0, abs=1e-12)
    qs = np.outer(k, free.z_true)
    y = free.response_true
    # the turning angles measured on the tracked nodes (project convention) are kappa z, sign included
    assert np.sqrt(np.mean((y - qs) ** 2)) < 0.02 * np.sqrt(np.mean(qs ** 2))
    fit = ResponseModel().solve(y, np.ones_like(y), np.linspace(0, 1, len(k)))
    est = np.abs(fit.kappa)
    err = np.log(est) - np.log(k)
    assert np.sqrt(np.mean((err - err.mean()) ** 2)) < 0.01
    assert np.array_equal(free.response_effect_free, free.response_true)


def dominant_lag(a, b, max_lag=40):
    """Lag (frames) by which ``a`` follows ``b`` (cross-correlation peak)."""
    a, b = a - a.mean(), b - b.mean()
    lags = np.arange(-max_lag, max_lag + 1)
    cc = [np.dot(a[max(0, L):len(a) + min(0, L)], b[max(0, -L):len(b) - max(0, L)]) for L in lags]
    return lags[int(np.argmax(cc))]


def test_modal_puts_a_resonance_in_the_wind_band():
    """The tip bend's gain over its quasi-static response kappa z, around the 1 Hz mode against below it: a
    resonance with fruit mass, flat without; and the tip lags the wind."""
    s, free_long = sim(("modal",), frames=600, seed=4), sim(frames=600, seed=4)
    f = np.fft.rfftfreq(600, 1 / 30.0)
    band = (f > 0.7) & (f < 1.4)     # around the 1 Hz first mode
    low = (f > 0.05) & (f < 0.4)

    def gain(sm):
        qs = sm.z_true * sm.kappa_true[sm.graph.bends[-1].edge]
        H = np.abs(np.fft.rfft(sm.response_true[-1])) / np.maximum(np.abs(np.fft.rfft(qs)), 1e-9)
        return np.median(H[band]) / np.median(H[low])
    assert gain(s) > 1.8 and abs(gain(free_long) - 1) < 0.1
    assert dominant_lag(s.response_true[-1], s.z_true) >= 2
    assert dominant_lag(free_long.response_true[-1], free_long.z_true) == 0


def test_gust_front_makes_the_tip_lag_the_root(free):
    s = sim(("gust_front",), effect_strength={"gust_front": 20.0}, frames=600)
    lag = [dominant_lag(y, s.z_true) for y in s.response_true]
    # each joint's bend is the moment of every load beyond it: the root joint's is weighted toward the tip
    # (the longest lever arms) and lags too; the tip joint's sees only the last loads, the latest
    assert lag[-1] >= 15 and lag[-1] - lag[0] >= 3 and np.all(np.diff(lag) >= 0)
    assert dominant_lag(free.response_true[-1], free.z_true) == 0 == dominant_lag(free.response_true[0], free.z_true)


def test_two_sources_make_the_response_rank_two(free):
    def second_share(y):
        S = np.linalg.svd(y - y.mean(1, keepdims=True), compute_uv=False)
        return S[1] / S[0]
    assert second_share(sim(("two_sources",)).response_true) > 0.15
    assert second_share(free.response_true) < 0.02


def test_creep_drifts_one_joint(free):
    s = sim(("creep",), effect_strength={"creep": 2.0})
    d = s.response_true - s.response_effect_free
    joint = s.effect_params["creep"]["weak_edge"][0]
    i = [b.joint for b in s.graph.bends].index(joint)
    rms = np.sqrt(np.mean(s.response_effect_free[i] ** 2))
    assert abs(d[i, -1]) == pytest.approx(2.0 * rms, rel=0.2)      # strength = end drift / RMS wind bend
    others = np.delete(np.abs(d[:, -1]), i)
    assert others.max() < 0.3 * abs(d[i, -1])                       # one joint (its neighbours a little)
    assert abs(d[i, 20]) < 0.2 * abs(d[i, -1])                       # slow: a drift, not a jump


def test_stiffening_gain_falls_with_amplitude(free):
    s = sim(("stiffening",), frames=240, seed=4)
    def gain_ratio(sm):
        k = np.array([sm.kappa_true[b.edge] for b in sm.graph.bends])
        qs = np.outer(k, sm.z_true)
        big = np.abs(qs) > np.quantile(np.abs(qs), 0.95)
        mid = (np.abs(qs) > np.quantile(np.abs(qs), 0.2)) & (np.abs(qs) < np.quantile(np.abs(qs), 0.5))
        g = sm.response_true / np.where(qs == 0, np.nan, qs)
        return np.nanmedian(g[big]) / np.nanmedian(g[mid])
    assert gain_ratio(s) < 0.85
    assert gain_ratio(sim(frames=240, seed=4)) == pytest.approx(1.0, abs=0.03)


def test_deterministic_by_seed_and_effects_leave_the_seeds_draws_alone():
    a = simulate_beam(BeamConfig(n_nodes=8, n_frames=80, seed=11))
    b = simulate_beam(BeamConfig(n_nodes=8, n_frames=80, seed=11))
    c = simulate_beam(BeamConfig(n_nodes=8, n_frames=80, seed=12))
    e = simulate_beam(BeamConfig(n_nodes=8, n_frames=80, seed=11, effects=("two_sources",)))
    assert np.array_equal(a.tracks.xy, b.tracks.xy, equal_nan=True)
    assert not np.allclose(a.true_xy, c.true_xy)
    assert np.array_equal(a.z_true, e.z_true) and a.kappa_true == e.kappa_true
    assert np.array_equal(a.response_true, e.response_effect_free)


def test_cli_writes_the_recording_and_rejects_bad_input(tmp_path, capsys):
    from rce_gtsam.cli import main
    out = tmp_path / "b"
    assert main(["simulate", "--simulator", "beam", "--effect", "creep", "--strength", "creep=1.5", "--frames", "60",
                 "--nodes", "6", "--out", str(out)]) == 0
    t = json.loads((out / "truth.json").read_text())
    assert t["simulator"] == "beam" and t["effects"] == ["creep"] and t["strengths"] == {"creep": 1.5}
    assert t["diagnosis_names"] == {"creep": ["offset"]}
    assert np.exp(np.mean(np.log(list(t["kappa_true"].values())))) == pytest.approx(1.0, abs=1e-9)
    assert set(t["response_effect_free"]) == set(t["kappa_true"])
    for bad in (["--effect", "delay"], ["--effect", "modal", "--strength", "modal=0"], ["--form", "delay=quadratic"],
                ["--layout", "tree"], ["--effect", "modal", "--strength", "creep=1"]):
        bad_out = tmp_path / "bad"
        assert main(["simulate", "--simulator", "beam", "--frames", "40", "--out", str(bad_out)] + bad) == 2
        assert not bad_out.exists()
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "Traceback" not in err[0]


def test_every_effect_is_listed():
    assert set(BEAM_EFFECTS) == {"modal", "gust_front", "two_sources", "creep", "stiffening"}


def test_the_renderer_draws_the_beam(tmp_path):
    """``--video`` works for the beam: the renderer reads positions, segment lengths, seed, fps and image size; the
    stem (brown: red above green) is drawn where the true nodes are, on a green background."""
    import cv2
    from rce_gtsam.sim.render import render_video
    s = simulate_beam(BeamConfig(n_nodes=8, n_frames=10, seed=3))
    path = render_video(s, tmp_path / "v.mp4", n_frames=6)
    cap = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, fr = cap.read()
        if not ok:
            break
        frames.append(fr)
    cap.release()
    assert len(frames) == 6 and frames[0].shape == (480, 640, 3)
    mid = 0.5 * (s.true_xy[2:-1, 5] + s.true_xy[3:, 5])        # mid-points of segments in the last frame
    red_minus_green = frames[5][..., 2].astype(float) - frames[5][..., 1]
    on = red_minus_green[mid[:, 1].round().astype(int), mid[:, 0].round().astype(int)]
    off = red_minus_green[(mid[:, 1] + 40).clip(0, 479).round().astype(int), mid[:, 0].round().astype(int)]
    assert np.median(on) > np.median(off) + 20


def test_the_beam_bench_gives_the_one_node_check_its_geometry():
    """bench_beam.with_geometry: a cached case without the one-node check's geometry gets each node's Jacobian at the
    beam's rest pose (the median of its true positions), as ``rce diagnose`` hands it over; one that has it keeps it."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from bench_beam import with_geometry

    from rce_gtsam.diagnosis.one_node import bend_jacobian

    c = {"inputs": {"edge_nodes": [(0, 1, 2), (1, 2, 3), (2, 3, 4)]}}
    out = with_geometry(c, None, seed=0, frames=60, mult=1.0)
    sim = simulate_beam(BeamConfig(n_frames=60, seed=0))
    rest = {int(n): np.median(sim.true_xy[i], axis=0) for i, n in enumerate(sim.tracks.node_ids)}
    want = bend_jacobian([(0, 1, 2), (1, 2, 3), (2, 3, 4)], rest)
    assert set(out["inputs"]["node_sensitivity"]) == set(want) == {0, 1, 2, 3, 4}
    for n, a in want.items():
        np.testing.assert_allclose(out["inputs"]["node_sensitivity"][n], a)
    assert "node_sensitivity" not in c["inputs"]  # the cached case itself is left as it was
    kept = {"inputs": {**c["inputs"], "node_sensitivity": {"x": 1}}}
    assert with_geometry(kept, None, 0, 60, 1.0) is kept
