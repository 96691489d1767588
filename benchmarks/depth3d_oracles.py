"""Oracles for kappa from depth (issue #39): how much of the 3-D kappa error is depth noise, how much the
tracker's pixel error, how much the fit itself. No video is rendered: each oracle starts from the simulator's
truth (``simulate(out_of_plane)``, the same seed and defaults as ``rce simulate --effect out_of_plane --depth``).

Rows (kappa log-RMSE against ``kappa_true_3d``, the geometric-mean-free error of bench_depth3d.py):

* ``true3d``: the true 3-D node positions (mm) -> angles3d -> kappa3d (the fit's own floor: rank-1 model, the
  branch-plane estimate, the rest geometry);
* ``px0+z``: the true pixel positions plus white noise of :data:`PX0_SIGMA` (the sigma given to the smoother)
  and, per node and frame, the true depth plus the simulator's D435i depth-noise draw (``DepthNoise.sigma_mm(z)``
  of :mod:`rce_gtsam.sim.depth`, independent per node and frame) -> ``smooth_tracks_3d`` -> angles3d -> kappa3d;
  the depth sigma given to the smoother is the reader's (:func:`rce_gtsam.track.depth_sample.d435_depth_rms_mm`),
  as in ``rce run``;
* ``pxN+z``: as ``px0+z`` with the default tracker-noise model's pixel tracks (``sim.tracks``; sigma_px emitted);
* ``pxN+z0``: those pixel tracks with the exact depth (rounded to mm): what the tracker's pixels allow;
* ``px0+z bp_in``, ``pxN+z bp_in``: kappa of the in-plane bends only, each smoothed node moved along its pixel
  ray onto the branch plane (:func:`kappa_in_plane_backprojected`): the depth noise kept out of those angles;
* ``px0 2d``: the 2-D pipeline on the 0.1 px pixels of ``px0+z``;
* ``pxN 2d``: the 2-D pipeline on those same noisy tracks (what the 2-D analysis loses to the same pixel error);
* ``image``: kappa_true_image (a perfect 2-D tracker, the 2-D ceiling).

Each oracle with depth is run with the 3-D smoother's default and, where given, other keyword arguments
(``variants``: {name: kwargs for smooth_tracks_3d}), so a change to the smoother is measured here first.
"""

from __future__ import annotations

import numpy as np


#: The ``px0`` rows' pixel error (px, white, isotropic; also the sigma given to the smoother): a tracker good to
#: 0.1 px, about the rendered runs' median error (0.1-0.15 px) without their gross failures.
PX0_SIGMA = 0.1


def log_rmse(kappa: dict, truth: dict) -> float:
    keys = [k for k in truth if k in kappa and np.isfinite(kappa[k]) and kappa[k] > 0]
    d = np.log([kappa[k] for k in keys]) - np.log([truth[k] for k in keys])
    d -= d.mean()
    return float(np.sqrt(np.mean(d ** 2)))


def simulate_seed(seed: int, frames: int):
    """The simulation behind ``rce simulate --effect out_of_plane --depth --seed S --frames F`` (tracks with
    their sigma_px; the noise draws do not depend on emitting it)."""
    from rce_gtsam.sim.simulate import NoiseConfig, SimulationConfig, simulate

    return simulate(SimulationConfig(n_frames=frames, effects=("out_of_plane",), seed=seed,
                                     noise=NoiseConfig(emit_sigma=True)))


def kappa_from_xyz(xyz_mm, node_ids, graph, geometry, preset, frame_cov=None, observed=None,
                   skip_nodes=()) -> dict:
    """{"p->c": kappa} from 3-D positions (N, F, 3) mm through angles3d and kappa3d."""
    from rce_gtsam.bending.angles3d import compute_bending_3d
    from rce_gtsam.model.kappa3d import fit_kappa_3d

    b3 = compute_bending_3d(xyz_mm, node_ids, graph, preset.bending, frame_cov, observed=observed)
    k3 = fit_kappa_3d(b3, geometry, preset, skip_nodes=skip_nodes)
    return {f"{j}->{c}": float(v) for (j, c), v in zip(k3.edges, k3.kappa)}


def kappa_in_plane_backprojected(xyz_mm, cam, node_ids, graph, geometry, preset, observed=None) -> dict:
    """{"p->c": kappa} of the in-plane bends only, with each node's 3-D point replaced by its pixel ray's
    intersection with the branch plane (normal and rest centroid of ``xyz_mm``): the depth then enters only
    through the plane, fitted to every node and frame, not through each node's own depth."""
    from rce_gtsam.bending.angles3d import branch_plane, compute_bending_3d
    from rce_gtsam.model.kappa3d import fit_kappa_3d

    n = branch_plane(xyz_mm)
    c = np.nanmedian(xyz_mm, axis=1).mean(axis=0)
    uv = cam.project(xyz_mm)
    ray = np.stack([(uv[..., 0] - cam.cx) / cam.fx, (uv[..., 1] - cam.cy) / cam.fy, np.ones(uv.shape[:2])], -1)
    on_plane = ray * ((n @ c) / (ray @ n))[..., None]
    k = fit_kappa_3d(compute_bending_3d(on_plane, node_ids, graph, preset.bending, observed=observed), geometry,
                     preset)
    return {f"{j}->{c_}": float(v) for (j, c_), v in zip(k.edges, k.kappa_in_plane)}


def noisy_depth(xyz_mm: np.ndarray, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(z measured, z sigma claimed) (N, F) mm: the true depth plus the simulator's D435i noise (seeded)."""
    from rce_gtsam.sim.depth import DepthNoise
    from rce_gtsam.track.depth_sample import d435_depth_rms_mm

    z = xyz_mm[..., 2]
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x0AC1E]))
    zm = np.round(z + DepthNoise().sigma_mm(z) * rng.standard_normal(z.shape))  # z16: whole mm
    return zm, d435_depth_rms_mm(zm)


def px0_pixels(sim) -> np.ndarray:
    """(N, F, 2) the true pixels plus white noise of :data:`PX0_SIGMA` (seeded by the simulation's seed)."""
    rng = np.random.default_rng(np.random.SeedSequence([int(sim.config.seed), 0x0AC1F]))
    P = np.asarray(sim.three_d.positions_mm, float)
    return sim.three_d.camera.project(P) + rng.normal(0.0, PX0_SIGMA, P.shape[:2] + (2,))


def px0_2d(sim, uv=None, preset=None) -> float:
    """kappa log-RMSE (vs kappa_true_3d) of the 2-D pipeline on the 0.1 px pixels (:func:`px0_pixels`)."""
    from rce_gtsam.pipeline import analyze
    from rce_gtsam.presets import get_preset
    from rce_gtsam.tracks import Tracks

    g = sim.graph
    uv = px0_pixels(sim) if uv is None else uv
    pre = preset or get_preset("default").with_(compliance={"n_boot": 0})
    res = analyze(Tracks(node_ids=np.array(g.nodes), xy=uv, sigma_px=np.full(uv.shape[:2], PX0_SIGMA),
                         source="oracle"), g, pre)
    truth = {f"{b.edge[0]}->{b.edge[1]}": float(k) for b, k in zip(g.bends, sim.three_d.kappa_3d)}
    return log_rmse({f"{p}->{c}": float(k) for (p, c), k in zip(res.response.edges, res.fit.kappa)}, truth)


def oracles(seed: int, frames: int, variants: dict | None = None, tracks_xy=None, tracks_sigma=None) -> dict:
    """The oracle rows of one seed (see the module docstring). ``tracks_xy``/``tracks_sigma`` (N, F, 2)/(N, F):
    other pixel tracks for the ``pxN`` rows (e.g. a rendered run's), rows in graph.nodes order."""
    from rce_gtsam.bending.geometry import compute_geometry
    from rce_gtsam.pipeline import analyze
    from rce_gtsam.presets import get_preset
    from rce_gtsam.smoothing.smoother3d import smooth_tracks_3d
    from rce_gtsam.tracks import Tracks

    variants = {"": {}} if variants is None else variants
    sim = simulate_seed(seed, frames)
    t3 = sim.three_d
    g = sim.graph
    ids = np.array(g.nodes)
    truth = {f"{b.edge[0]}->{b.edge[1]}": float(k) for b, k in zip(g.bends, t3.kappa_3d)}
    pre = get_preset("default").with_(compliance={"n_boot": 0})
    P = np.asarray(t3.positions_mm, float)  # (N, F, 3)
    geo = compute_geometry(sim.true_xy, ids, g, rest=pre.bending.rest)
    out = {"seed": seed, "true3d": log_rmse(kappa_from_xyz(P, ids, g, geo, pre), truth),
           "image": log_rmse({f"{b.edge[0]}->{b.edge[1]}": float(k) for b, k in zip(g.bends, t3.kappa_image)},
                             truth)}
    zm, zs = noisy_depth(P, seed)
    uv_true = px0_pixels(sim)  # a 0.1 px tracker
    xy_n = sim.tracks.xy if tracks_xy is None else tracks_xy
    sig_n = sim.tracks.sigma_px if tracks_sigma is None else tracks_sigma
    sig0 = np.where(np.isfinite(sig_n), sig_n, np.nanmedian(sig_n))
    out["px0 2d"] = px0_2d(sim, uv_true, pre)
    res = analyze(Tracks(node_ids=ids, xy=xy_n, sigma_px=sig_n, source="oracle"), g, pre)
    out["pxN 2d"] = log_rmse({f"{p}->{c}": float(k) for (p, c), k in zip(res.response.edges, res.fit.kappa)},
                             truth)
    z_exact = np.round(P[..., 2])
    zs_exact = np.full(z_exact.shape, 1 / np.sqrt(12))  # z16 rounding, mm
    for name, kw in variants.items():
        for label, xy, sig, z_, zs_ in (("px0+z", uv_true, np.full(sig0.shape, PX0_SIGMA), zm, zs),
                                        ("pxN+z", xy_n, sig_n, zm, zs), ("pxN+z0", xy_n, sig_n, z_exact, zs_exact)):
            zz = np.where(np.isfinite(xy).all(axis=2), z_, np.nan)
            sm = smooth_tracks_3d(xy, sig, zz, zs_, ids, g, t3.camera, pre.smoother, source="oracle", **kw)
            k = kappa_from_xyz(sm.xyz_mm, ids, g, res.geometry if label == "pxN+z" else geo, pre,
                               sm.frame_cov, sm.observed)
            key = label + (f" {name}" if name else "")
            out[key] = log_rmse(k, truth)
            out[key + " s"] = sm.report.seconds_total
            if not name and label != "pxN+z0":  # the in-plane bends from the pixels on the branch plane
                kb = kappa_in_plane_backprojected(sm.xyz_mm, t3.camera, ids, g,
                                                  res.geometry if label == "pxN+z" else geo, pre, sm.observed)
                out[label + " bp_in"] = log_rmse(kb, truth)
    return out
