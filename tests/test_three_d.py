"""Tests of the 3-D simulation: out-of-plane swing, tilted branch plane, projection (rce_gtsam.sim.three_d)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rce_gtsam.errors import InputError
from rce_gtsam.sim.simulate import NoiseConfig, SimulationConfig, simulate, turning_angles_deg
from rce_gtsam.sim.three_d import Scene3D, rank1_kappa

CLEAN = NoiseConfig(enabled=False)
F = 240


def _sim(**kw):
    kw.setdefault("n_frames", F)
    kw.setdefault("noise", CLEAN)
    return simulate(SimulationConfig(**kw))


def _lengths(sim):
    row = {n: i for i, n in enumerate(sim.graph.nodes)}
    return np.stack([np.linalg.norm(sim.true_xy[row[c]] - sim.true_xy[row[p]], axis=-1) for p, c in sim.graph.edges])


@pytest.mark.parametrize("layout", ["chain", "tree"])
def test_flat_scene_reproduces_the_planar_simulator(layout):
    """Tilt 0 without swing: the 3-D scene projects onto the planar simulator's positions, tracks unchanged,
    and the image kappa is the 3-D kappa."""
    planar = _sim(seed=4, branch_layout=layout, n_nodes=16, noise=NoiseConfig())
    flat = _sim(seed=4, branch_layout=layout, n_nodes=16, noise=NoiseConfig(), scene3d=Scene3D())
    assert planar.three_d is None and flat.three_d.tilt_deg == 0 and flat.three_d.share == 0
    np.testing.assert_allclose(flat.true_xy, planar.true_xy, atol=1e-9)
    np.testing.assert_allclose(flat.tracks.xy, planar.tracks.xy, atol=1e-9)
    np.testing.assert_allclose(flat.three_d.kappa_image, flat.three_d.kappa_3d, rtol=1e-9)
    assert 700 <= flat.three_d.root_depth_mm <= 900
    np.testing.assert_allclose(flat.three_d.positions_mm[..., 2].min(), flat.three_d.root_depth_mm, rtol=1e-9)


@pytest.mark.parametrize("layout", ["chain", "tree"])
def test_swing_kinematics(layout):
    """psi = kappa z_o with z_o = share (rho z + sqrt(1 - rho^2) z'); rigid segments in mm; fixed root; the 3-D
    turning angle composes theta and psi (cos turn = cos theta cos psi); the chain stays in the image."""
    sim = _sim(seed=2, branch_layout=layout, n_nodes=16, effects=("out_of_plane",))
    t3 = sim.three_d
    assert t3.tilt_deg == 30 and t3.share == 0.5 and t3.rho == 0.5
    np.testing.assert_allclose(t3.z_o, 0.5 * (0.5 * sim.z_true + math.sqrt(0.75) * t3.z_prime), atol=1e-12)
    k = np.array([sim.kappa_true[b.edge] for b in sim.graph.bends])
    np.testing.assert_allclose(t3.psi_deg, np.outer(k, t3.z_o), atol=1e-12)
    assert np.corrcoef(t3.z_prime, sim.z_true)[0, 1] < 0.6          # its own draw, not a copy of z
    P = t3.positions_mm
    row = {n: i for i, n in enumerate(sim.graph.nodes)}
    for (p, c), L in t3.segment_mm.items():
        np.testing.assert_allclose(np.linalg.norm(P[row[c]] - P[row[p]], axis=-1), L, rtol=1e-9)
    assert np.ptp(P[row[0]], axis=0).max() == 0
    th, ps = np.radians(t3.theta_deg), np.radians(t3.psi_deg)
    np.testing.assert_allclose(np.cos(np.radians(t3.turn3d_deg)), np.cos(th) * np.cos(ps), atol=1e-9)
    # in-plane angles are the planar simulator's: rest + response
    rest = np.array([sim.rest_turn_deg[b.edge] for b in sim.graph.bends])
    np.testing.assert_allclose(t3.theta_deg - rest[:, None], sim.response_true, atol=1e-9)
    xy = sim.true_xy
    assert xy[..., 0].min() >= 20 and xy[..., 0].max() <= 620 and xy[..., 1].min() >= 20 and xy[..., 1].max() <= 460
    np.testing.assert_allclose(sim.tracks.xy, xy)                   # clean tracks = the projection
    np.testing.assert_allclose(turning_angles_deg(xy, sim.graph.nodes, sim.graph.bends), t3.image_turn_deg)


def test_swing_does_not_change_geometry_kappa_or_z():
    base = _sim(seed=1)
    oop = _sim(seed=1, effects=("out_of_plane", "delay"))
    assert base.kappa_true == oop.kappa_true
    np.testing.assert_array_equal(base.z_true, oop.z_true)
    delayed = _sim(seed=1, effects=("delay",))
    np.testing.assert_allclose(oop.response_true, delayed.response_true)   # in-plane effects act as before
    assert not np.allclose(oop.true_xy, base.true_xy)


def test_segment_lengths_follow_the_swing():
    """Projected segment lengths: constant for a flat planar branch; with swing at tilt 30 they move with z_o to
    first order (a linear fit on z_o explains most of their change) and more toward the tip."""
    flat = _lengths(_sim(seed=0, n_frames=600, scene3d=Scene3D()))
    np.testing.assert_allclose(flat - flat[:, :1], 0, atol=1e-9)
    sim = _sim(seed=0, n_frames=600, effects=("out_of_plane",))
    L = _lengths(sim)
    dL = L - L[:, :1]
    X = np.c_[np.ones(600), sim.three_d.z_o]
    res = dL.T - X @ np.linalg.lstsq(X, dL.T, rcond=None)[0]
    r2 = 1 - (res ** 2).sum() / ((dL.T - dL.T.mean(0)) ** 2).sum()
    assert r2 > 0.5, r2
    rms = np.sqrt(np.mean(dL ** 2, axis=1))
    assert rms[-5:].mean() > 2 * rms[:5].mean() and rms.max() > 0.5


def test_image_kappa_differs_from_3d_kappa_when_tilted_and_swinging():
    k = _sim(seed=0, n_frames=600, effects=("out_of_plane",)).three_d
    assert np.sqrt(np.mean(np.log(np.abs(k.kappa_image) / k.kappa_3d) ** 2)) > 0.02
    assert abs(np.exp(np.mean(np.log(np.abs(k.kappa_image)))) - 1) < 1e-9


def test_rank1_kappa_recovers_a_rank1_matrix():
    kappa = np.exp(np.random.default_rng(0).normal(0, 0.5, 6))
    kappa /= np.exp(np.log(kappa).mean())
    z = np.sin(np.arange(50) / 5.0)
    np.testing.assert_allclose(rank1_kappa(np.outer(kappa, z)), kappa, rtol=1e-9)
    np.testing.assert_allclose(rank1_kappa(-np.outer(kappa, z)), kappa, rtol=1e-9)


def test_truth_json_carries_the_3d_truth():
    sim = _sim(seed=3, n_frames=30, effects=("out_of_plane",))
    t = sim.truth_json()
    assert np.array(t["positions_mm"]).shape == (30, 20, 3)
    assert set(t["kappa_true_3d"]) == set(t["kappa_true_image"]) == set(t["kappa_true"])
    assert t["kappa_true_3d"] == t["kappa_true"]
    assert t["three_d"]["camera"]["fx"] == 615.0 and t["three_d"]["tilt_deg"] == 30.0
    assert _sim(seed=3, n_frames=30).truth_json().get("positions_mm") is None


def test_bad_scene_is_an_input_error():
    with pytest.raises(InputError, match="tilt_deg"):
        simulate(SimulationConfig(n_frames=30, scene3d=Scene3D(tilt_deg=80.0)))
    with pytest.raises(InputError, match="rho"):
        simulate(SimulationConfig(n_frames=30, scene3d=Scene3D(rho=1.5)))
    with pytest.raises(InputError, match="effect_strength"):
        simulate(SimulationConfig(n_frames=30, effects=("out_of_plane",), effect_strength={"out_of_plane": -1.0}))


def _r2(y, x):
    X = np.c_[np.ones_like(x), x]
    res = y.T - X @ np.linalg.lstsq(X, y.T, rcond=None)[0]
    return 1 - (res ** 2).sum() / ((y.T - y.T.mean(0)) ** 2).sum()


def test_at_tilt_0_the_swing_shortens_segments_to_second_order_but_for_perspective():
    """Tilt 0: seen orthographically the swing shortens segments by L (1 - cos a), second order in z_o; the
    pinhole adds a first-order term (a point nearer the camera moves away from the principal point)."""
    sim = _sim(seed=0, n_frames=600, effects=("out_of_plane",), scene3d=Scene3D(tilt_deg=0))
    t3 = sim.three_d
    row = {n: i for i, n in enumerate(sim.graph.nodes)}

    def dlen(xy):
        L = np.stack([np.linalg.norm(xy[row[c]] - xy[row[p]], axis=-1) for p, c in sim.graph.edges])
        return L - L[:, :1]
    ortho = dlen(t3.positions_mm[..., :2])
    assert np.all(ortho <= 1e-9)                      # only ever shorter
    assert _r2(ortho, t3.z_o ** 2) > 0.9 and _r2(ortho, t3.z_o) < 0.3
    assert _r2(dlen(sim.true_xy), t3.z_o) > 0.8


def test_stem_width_in_colour_matches_the_depth_tube():
    """The renderer's bark width (planar width x width_factor) is the tube's image width 2 r f / z at frame 0."""
    from rce_gtsam.sim.three_d import stem_widths_px
    flat = _sim(seed=2, n_frames=20, scene3d=Scene3D())
    assert all(flat.three_d.width_factor(e, flat.graph) == 1.0 for e in flat.graph.edges)
    sim = _sim(seed=2, n_frames=20, effects=("out_of_plane",))
    t3, g = sim.three_d, sim.graph
    planar = simulate(SimulationConfig(n_frames=20, seed=2, noise=CLEAN))
    w0 = stem_widths_px(g, planar.segment_px)
    row = {n: i for i, n in enumerate(g.nodes)}
    factors = []
    for e in g.edges:
        z_mid = t3.positions_mm[[row[e[0]], row[e[1]]], 0, 2].mean()
        expect = 2 * t3.stem_radius_mm[e] * t3.camera.fx / z_mid
        assert w0[e] * t3.width_factor(e, g) == pytest.approx(expect, rel=1e-9)
        factors.append(t3.width_factor(e, g))
    assert min(factors) < 0.95                     # the upper branch leans away: thinner in the image
