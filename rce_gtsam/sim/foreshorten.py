"""Out-of-plane swing made from the 2-D simulator: foreshorten its true tracks (a stand-in for the 3-D simulator).

The physical model of issue #39 (the one ``rce simulate --effect out_of_plane`` follows): the branch's rest pose
lies in its branch plane, and each joint e bends in that plane by theta[e, t] (the existing simulator, its
``response_true``) and out of it by psi[e, t] = kappa_e * z_o(t), the same compliance, about the segment's
in-plane normal. The out-of-plane excitation is

    z_o(t) = share * (rho * z(t) + sqrt(1 - rho^2) * z'(t)),

z' an independent draw of the same excitation process (:func:`~rce_gtsam.sim.simulate.make_excitation`, its own
seed stream; the wind's direction wanders). A segment's elevation out of the plane is the sum of the psi of the
joints between it and the root (chi, degrees); its in-plane heading stays the 2-D simulator's. The branch plane
is then tilted by ``tilt_deg`` about the image x axis through the root, placed ``depth_mm`` in front of a
pinhole camera (fx = fy = ``focal_px``, principal point at the image centre) and projected; the plane's pixels
map to mm at the root's depth, so with ``share = 0`` and ``tilt_deg = 0`` the projection is the 2-D
simulator's positions exactly.

:func:`foreshortened` returns the :class:`~rce_gtsam.sim.simulate.Simulation` of the same seed with the projected
true positions and a tracker's view of them (the simulator's default noise and the configured tracker
artifacts, drawn from the same seed streams), plus the truth of the swing (:class:`SwingTruth`). Units: px, mm,
degrees, frames.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ..tracks import Tracks
from .artifacts import apply_artifacts
from .simulate import NoiseConfig, Simulation, SimulationConfig, add_tracker_noise, make_excitation, simulate, \
    turning_angles_deg


@dataclass(frozen=True)
class SwingTruth:
    """The swing's truth. z_o: (F,) out-of-plane excitation (deg); chi: (N, F) elevation of the segment ending at
    each node out of the branch plane (deg, 0 at the root); kappa_3d: (B,) the compliance in graph.bends order
    (geometric mean 1); kappa_image: (B,) the rank-1 kappa of the noise-free projected turning angles (what a
    perfect 2-D tracker gives); share, rho, tilt_deg, depth_mm, focal_px: the settings."""

    z_o: np.ndarray
    chi: np.ndarray
    kappa_3d: np.ndarray
    kappa_image: np.ndarray
    share: float
    rho: float
    tilt_deg: float
    depth_mm: float
    focal_px: float


def swing_excitation(config: SimulationConfig, z: np.ndarray, share: float, rho: float) -> np.ndarray:
    """z_o (F,) deg: ``share * (rho z + sqrt(1 - rho^2) z')``, z' drawn by ``make_excitation`` from a seed stream
    of its own (spawned after the simulator's seven), so the recording's other draws do not change."""
    ss = np.random.SeedSequence(config.seed)
    r = np.random.default_rng(ss.spawn(9)[8])
    z2 = make_excitation(len(z), config.fps, r, rms_deg=config.z_rms_deg)
    return share * (rho * z + math.sqrt(max(1.0 - rho * rho, 0.0)) * z2)


def project_swing(sim: Simulation, chi_deg: np.ndarray, tilt_deg: float, depth_mm: float = 800.0,
                  focal_px: float = 615.0) -> np.ndarray:
    """(N, F, 2) px: the 2-D simulator's true positions with each segment raised out of the branch plane by its
    elevation ``chi_deg`` (N, F; the segment ending at each node), the plane tilted by ``tilt_deg`` about the image
    x axis through the root, and a pinhole projection with the root ``depth_mm`` in front of the camera."""
    g = sim.graph
    xy = sim.true_xy
    N, F, _ = xy.shape
    w, h = sim.config.image_size
    c = np.array([w / 2.0, h / 2.0])
    mm_per_px = depth_mm / focal_px
    row = {n: i for i, n in enumerate(g.nodes)}
    root = row[g.root]
    P = np.zeros((N, F, 3))  # plane frame (u = image x, v = image y, n = toward the far side), mm, root at 0
    for cnode in g.nodes[1:]:
        i, p = row[cnode], row[g.parent[cnode]]
        d = (xy[i] - xy[p]) * mm_per_px
        ch = np.radians(chi_deg[i])
        P[i, :, :2] = P[p, :, :2] + np.cos(ch)[:, None] * d
        P[i, :, 2] = P[p, :, 2] + np.sin(ch) * np.linalg.norm(d, axis=-1)
    t = math.radians(tilt_deg)
    Y = P[..., 1] * math.cos(t) - P[..., 2] * math.sin(t)
    Z = P[..., 1] * math.sin(t) + P[..., 2] * math.cos(t)
    root_cam = np.concatenate([(xy[root] - c) * mm_per_px, np.full((F, 1), depth_mm)], axis=-1)  # (F, 3)
    X = root_cam[None, :, 0] + P[..., 0]
    Yc = root_cam[None, :, 1] + Y
    Zc = root_cam[None, :, 2] + Z
    return np.stack([c[0] + focal_px * X / Zc, c[1] + focal_px * Yc / Zc], axis=-1)


def rank1_kappa(Y: np.ndarray) -> np.ndarray:
    """The rank-1 kappa (geometric mean 1, positive) of a noise-free response (E, F, deg): its leading singular
    vector, signed so that the geometric mean is real."""
    U, S, Vt = np.linalg.svd(Y, full_matrices=False)
    k = U[:, 0] * np.sign(np.sum(U[:, 0]))
    k = np.abs(k)
    return k / np.exp(np.mean(np.log(np.maximum(k, 1e-12))))


def foreshortened(config: SimulationConfig, share: float = 0.5, tilt_deg: float = 30.0, rho: float = 0.5,
                  depth_mm: float = 800.0, focal_px: float = 615.0) -> tuple[Simulation, SwingTruth]:
    """The recording of ``config`` with out-of-plane swing of strength ``share`` (see the module docstring), seen
    by the tracker ``config.noise`` with ``config.artifacts``. ``share = 0`` and ``tilt_deg = 0`` give the 2-D
    simulator's recording (its tracks drawn again from the same streams on the same true positions)."""
    clean = simulate(dataclasses.replace(config, noise=NoiseConfig(enabled=False),
                                         artifacts=dataclasses.replace(config.artifacts, families=())))
    g = clean.graph
    kappa = np.array([clean.kappa_true[b.edge] for b in g.bends])
    z_o = swing_excitation(config, clean.z_true, share, rho)
    row = {n: i for i, n in enumerate(g.nodes)}
    psi = {b.child: k * z_o for b, k in zip(g.bends, kappa)}
    chi = np.zeros((len(g.nodes), len(z_o)))
    for cnode in g.nodes[1:]:
        p = g.parent[cnode]
        chi[row[cnode]] = chi[row[p]] + psi.get(cnode, 0.0)
    true_xy = project_swing(clean, chi, tilt_deg, depth_mm, focal_px)
    ang = turning_angles_deg(true_xy, g.nodes, g.bends)
    k_img = rank1_kappa(ang - ang[:, :1])
    ss = np.random.SeedSequence(config.seed)
    r_noise = np.random.default_rng(ss.spawn(6)[4])
    dist = {g.root: 0.0}
    for cnode in g.nodes[1:]:
        p = g.parent[cnode]
        dist[cnode] = dist[p] + float(np.linalg.norm(true_xy[row[cnode], 0] - true_xy[row[p], 0]))
    dmax = max(max(dist.values()), 1e-9)
    s_node = np.array([dist[n] / dmax for n in g.nodes])
    tracked, params = true_xy, {}
    if config.artifacts.active:
        art = apply_artifacts(g, true_xy, config.fps, config.artifacts, np.random.default_rng(ss.spawn(7)[6]))
        tracked, params = art.xy, art.params
    noisy, sigma = add_tracker_noise(g, tracked, s_node, config.noise, config.fps, r_noise)
    if config.artifacts.active:
        noisy[~art.visible] = np.nan
    tracks = Tracks(node_ids=np.array(g.nodes), xy=noisy, source=f"foreshortened (seed {config.seed})")
    sim = dataclasses.replace(clean, config=config, tracks=tracks, true_xy=true_xy, artifact_params=params)
    truth = SwingTruth(z_o=z_o, chi=chi, kappa_3d=kappa, kappa_image=k_img, share=float(share), rho=float(rho),
                       tilt_deg=float(tilt_deg), depth_mm=float(depth_mm), focal_px=float(focal_px))
    return sim, truth
