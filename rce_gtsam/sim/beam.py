"""A second simulator built from different physics: a finite-element beam in wind (``rce simulate --simulator beam``).

Where :mod:`rce_gtsam.sim.simulate` writes each bend as ``kappa_e z_t`` and then bends that law into an effect,
here nothing is written per joint: a planar Euler–Bernoulli cantilever (:mod:`.beam_fe`, Hermite cubic elements,
``elements_per_segment`` per tracked segment) with tapering EI and mass per length (radius falling linearly by
``taper`` to the tip: EI ~ r^4 times a log-normal factor per segment, the knots; m ~ r^2), clamped at the root,
carries a distributed wind force (leaf area growing toward the tip) whose leaves sit on petioles (lever arms: the
force also applies a distributed moment), and is integrated in time by Newmark-beta with Rayleigh damping at
``substeps`` steps per video frame. The tracked nodes sit along the beam; their positions integrate the heading
(rest shape + FE rotation) exactly, so the bend of each joint is what :func:`~.simulate.turning_angles_deg`
measures on them, in the project's convention.

Effect-free = the quasi-static regime: first mode at ``f1_hz`` (10 Hz) well above the wind band (< 1.5 Hz), one
load profile, a linear bending law. The effects come from the physics (:data:`BEAM_EFFECTS`, strengths
:data:`BEAM_EFFECT_DEFAULTS`, meaning :data:`BEAM_EFFECT_MEANING`):

* ``modal``: fruit mass at the tip (``tip_mass_ratio`` of the beam's mass) and a softer beam, so the first mode
  falls inside the wind band: inertia, resonance and a phase lag that grows toward the tip.
* ``gust_front``: the wind front travels from root to tip: the force at x arrives ``strength * x / L`` frames
  later.
* ``two_sources``: a second airstream with its own time course hits a band of the branch (a Gaussian load
  profile centred in its lower half): a second excitation with another pattern along the branch.
* ``creep``: a weak joint (a Maxwell dashpot in the two elements either side of one mid-branch node) creeps under
  the moment its rest load (self-weight) and the wind put on it: a slow drift of that joint's bend.
* ``stiffening``: strain stiffening, a cubic moment–curvature law M = EI (k + beta k^3 / k_ref^2) with k_ref the
  99th percentile of the quasi-static curvature over the beam times a per-segment onset factor: the gain falls
  with amplitude (not a corotational update; see :mod:`.beam_fe`). Measured: the rank-1 misfit of the noise-free
  response stays 0.03-0.09 of its RMS for beta 1-9, onset at the 50th or 99th percentile, onset spread 0.7-1.2:
  a cantilever is statically determinate, so each joint's bend is a monotone function of its own moment and all
  the moments follow one load; hardening bends them all along one curve, nearly rank 1 (a bounded saturation,
  the branch simulator's tanh, is not).

Sizes at the default strengths (rank-1 misfit of the noise-free response / its RMS, 450 frames, 5 seeds,
median): modal 0.16, gust_front 0.09, two_sources 0.18, creep 0.11, stiffening 0.04; effect-free 0.0005 (the
10 Hz mode's dynamic part). Most of a gust front's lag is common to all joints (each bend is the moment of every
load beyond it, weighted toward the tip's long lever arms: joint lags 14-19 frames for a 20-frame front), and a
rank-1 model absorbs a common lag in z.

kappa truth is quasi-static: the turning angle of each joint under a static unit load with the wind's (effect-
free) load profile, normalised to geometric mean 1 over the bends (all joints bend the same way under it, so it is
positive), with the load scaled so that the effect-free quasi-static response is exactly ``kappa_e z_t``
(``z_true`` in degrees, made by :func:`~.simulate.make_excitation`). ``truth.json`` also holds the noise-free
response of the same seed with every effect off (``response_effect_free``) for an oracle.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np
from scipy.interpolate import make_interp_spline

from ..errors import InputError
from ..graph import BranchGraph
from ..jsonutil import jsonable as _jsonable
from ..tracks import Tracks
from .beam_fe import Creep, Mesh, Stiffening, hermite, natural_frequencies_hz, newmark, rayleigh
from .simulate import (NoiseConfig, Simulation, place_in_image, add_tracker_noise, make_excitation,
                       turning_angles_deg)

#: Spread (log) of the per-segment curvature at which stiffening sets in, about the beam's 99th-percentile
#: quasi-static curvature: tissue that stiffens at one strain everywhere would saturate every joint in proportion
#: to its own bend, and a cantilever's bends all follow one load, so the response would stay nearly rank 1.
ONSET_SIGMA_LOG = 0.7

BEAM_EFFECTS: tuple[str, ...] = ("modal", "gust_front", "two_sources", "creep", "stiffening")

BEAM_EFFECT_DEFAULTS: dict[str, float] = {
    "modal": 1.0,        # first-mode period in seconds (1 Hz, inside the wind band)
    "gust_front": 20.0,  # travel time of the gust front from root to tip, frames
    "two_sources": 0.3,  # RMS of the second source's quasi-static bend response / RMS of the first's
    "creep": 2.0,        # creep drift of the weak joint's bend at the end of the record / RMS of its wind bend
    "stiffening": 3.0,   # beta: the cubic term is 3x the linear one at the 99th-percentile curvature (median onset)
}

BEAM_EFFECT_MEANING: dict[str, str] = {
    "modal": "first-mode period in seconds (fruit mass at the tip and a softer beam; effect-free: 0.1 s)",
    "gust_front": "frames the gust front takes from root to tip",
    "two_sources": "RMS of the second airstream's quasi-static bend response / RMS of the first's",
    "creep": "drift of the weak joint's bend over the record / RMS of its quasi-static wind bend",
    "stiffening": "beta in M = EI (k + beta k^3 / k_ref^2), k_ref = 99th percentile quasi-static curvature "
                  "times a per-segment log-normal onset factor",
}

#: The diagnosis' name for what each beam effect does to the bends (what a verdict is counted right by).
DIAGNOSIS_NAME: dict[str, tuple[str, ...]] = {
    "modal": ("dynamics", "delay"), "gust_front": ("delay",), "two_sources": ("second_mode",),
    "creep": ("offset",), "stiffening": ("nonlinear",),
}


@dataclass(frozen=True)
class BeamConfig:
    """What to simulate. Geometry in pixels like :class:`~.simulate.SimulationConfig`; physics in SI.

    n_nodes: tracked nodes along the beam (root = node 0); n_frames, fps: the video. effects / effect_strength:
    names of :data:`BEAM_EFFECTS` and overrides of :data:`BEAM_EFFECT_DEFAULTS`. noise: the tracker noise of the
    other simulator (:class:`~.simulate.NoiseConfig`). z_rms_deg: RMS of the effect-free quasi-static
    excitation (degrees per unit kappa). segment_px: (min, max) segment length in pixels. length_m: beam
    length in metres. f1_hz: first natural frequency of the effect-free beam; zeta: Rayleigh damping ratio at the
    first and third modes. taper: the radius falls by this fraction from root to tip. ei_sigma_log: spread of the
    per-segment log EI factor. tip_mass_ratio: fruit mass (``modal``) / beam mass. elements_per_segment: FE
    elements per tracked segment; substeps: Newmark steps per frame.
    """

    n_nodes: int = 20
    n_frames: int = 900
    fps: float = 30.0
    effects: tuple[str, ...] = ()
    effect_strength: dict | None = None
    noise: NoiseConfig = field(default_factory=NoiseConfig)
    seed: int = 0
    image_size: tuple[int, int] = (640, 480)
    z_rms_deg: float = 1.5
    segment_px: tuple[float, float] = (12.0, 28.0)
    length_m: float = 0.6
    f1_hz: float = 10.0
    zeta: float = 0.08
    taper: float = 0.6
    ei_sigma_log: float = 0.35
    tip_mass_ratio: float = 0.5
    elements_per_segment: int = 2
    substeps: int = 6

    def strength(self, effect: str) -> float:
        return float((self.effect_strength or {}).get(effect, BEAM_EFFECT_DEFAULTS[effect]))

    def validate(self) -> None:
        src = "beam simulation config"
        if not isinstance(self.n_nodes, int) or self.n_nodes < 3:
            raise InputError(src, f"n_nodes must be an integer >= 3 (a bend needs 3 nodes), got {self.n_nodes!r}")
        if not isinstance(self.n_frames, int) or self.n_frames < 10:
            raise InputError(src, f"n_frames must be an integer >= 10, got {self.n_frames!r}")
        if not self.fps > 0:
            raise InputError(src, f"fps must be > 0, got {self.fps!r}")
        unknown = [e for e in self.effects if e not in BEAM_EFFECTS]
        if unknown:
            raise InputError(src, f"unknown beam effect(s) {unknown}; known: {', '.join(BEAM_EFFECTS)}")
        for k, v in (self.effect_strength or {}).items():
            if k not in BEAM_EFFECTS:
                raise InputError(src, f"effect_strength names an unknown beam effect {k!r}; known: "
                                      f"{', '.join(BEAM_EFFECTS)}")
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise InputError(src, f"effect_strength[{k!r}] must be a finite number > 0, got {v!r}")
        if "creep" in self.effects and self.n_nodes < 4:
            raise InputError(src, "the creep effect needs n_nodes >= 4 (a weak joint inside the branch)")
        if not self.z_rms_deg > 0:
            raise InputError(src, f"z_rms_deg must be > 0, got {self.z_rms_deg!r}")


@dataclass(frozen=True, eq=False)
class BeamSimulation(Simulation):
    """A :class:`~.simulate.Simulation` made by the beam (``config`` is a :class:`BeamConfig`), plus the noise-
    free response of the same seed with every effect off, ``response_effect_free`` (E, F, degrees)."""

    response_effect_free: np.ndarray | None = None

    def truth_json(self) -> dict:
        key = lambda e: f"{e[0]}->{e[1]}"  # noqa: E731
        cfg = asdict(self.config)
        cfg["effects"] = list(self.config.effects)
        rnd = lambda a: [round(float(v), 6) for v in a]  # noqa: E731
        return {
            "format": "rce_gtsam beam simulation truth v1",
            "simulator": "beam",
            "seed": self.config.seed, "fps": self.config.fps, "n_frames": int(self.z_true.shape[0]),
            "units": {"kappa": "relative (geometric mean 1), quasi-static", "z_true": "degrees",
                      "response": "degrees", "positions": "pixels", "time": "frames"},
            "effects": list(self.config.effects),
            "strengths": {e: self.config.strength(e) for e in self.config.effects},
            "effect_meaning": {e: BEAM_EFFECT_MEANING[e] for e in self.config.effects},
            "diagnosis_names": {e: list(DIAGNOSIS_NAME[e]) for e in self.config.effects},
            "effect_params": _jsonable(self.effect_params),
            "kappa_true": {key(e): float(k) for e, k in self.kappa_true.items()},
            "z_true": rnd(self.z_true),
            "response_true": {key(b.edge): rnd(self.response_true[i]) for i, b in enumerate(self.graph.bends)},
            "response_effect_free": {key(b.edge): rnd(self.response_effect_free[i])
                                     for i, b in enumerate(self.graph.bends)},
            "rest_turn_deg": {key(e): float(v) for e, v in self.rest_turn_deg.items()},
            "segment_px": {key(e): float(v) for e, v in self.segment_px.items()},
            "root_px": [float(v) for v in self.root_px],
            "config": _jsonable(cfg),
        }


class _Kinematics:
    """Node positions (N, F, 2) from FE DOFs: heading = rest heading + FE rotation, integrated along the arc."""

    def __init__(self, mesh: Mesh, node_el: np.ndarray, phi0_seg: tuple[np.ndarray, np.ndarray], sub: int = 8):
        xi = np.arange(sub) / sub
        lengths = mesh.lengths
        s = np.concatenate([mesh.x[:-1, None] + lengths[:, None] * xi[None], ], axis=0).ravel()
        self.s = np.append(s, mesh.x[-1])                          # (G,) arc positions, m
        dN = hermite(xi[None, :], lengths[:, None])[1]              # (n_el, sub, 4)
        G = len(self.s)
        op = np.zeros((G, mesh.n_dof + 2))
        dofs = mesh.dofs() + 2
        for e in range(mesh.n_el):
            for k in range(sub):
                op[e * sub + k, dofs[e]] += dN[e, k]
        op[-1, -1] = 1.0                                            # the tip's rotation DOF
        self.theta = op[:, 2:]                                      # (G, n_dof)
        start, slope = phi0_seg                                     # per element: heading at start, d(heading)/ds
        el = np.minimum(np.arange(G) // sub, mesh.n_el - 1)
        self.phi0 = start[el] + slope[el] * (self.s - mesh.x[el])
        self.node_g = node_el * sub                                 # grid index of each tracked node
        self.ds = np.diff(self.s)

    def positions(self, U: np.ndarray, scale_px: float) -> np.ndarray:
        """(N, F, 2) pixel positions (root at the origin) for DOFs ``U`` (F, n_dof)."""
        phi = self.phi0[:, None] + self.theta @ U.T                 # (G, F)
        c, s = np.cos(phi), np.sin(phi)
        x = np.concatenate([np.zeros((1, phi.shape[1])), np.cumsum(0.5 * (c[1:] + c[:-1]) * self.ds[:, None], 0)])
        y = np.concatenate([np.zeros((1, phi.shape[1])), np.cumsum(0.5 * (s[1:] + s[:-1]) * self.ds[:, None], 0)])
        return scale_px * np.stack([x[self.node_g], y[self.node_g]], axis=-1)


def _fe_beam(cfg: BeamConfig, lengths_px: np.ndarray, r_geom: np.random.Generator):
    """(mesh, kinematics, pixels per metre, segment of each element, rest turn per bend) of the beam."""
    n_seg = len(lengths_px)
    eps = cfg.elements_per_segment
    scale_px = lengths_px.sum() / cfg.length_m
    node_x = np.concatenate([[0.0], np.cumsum(lengths_px)]) / scale_px
    x = np.concatenate([np.linspace(node_x[i], node_x[i + 1], eps + 1)[:-1] for i in range(n_seg)] + [[node_x[-1]]])
    seg_of_el = np.repeat(np.arange(n_seg), eps)
    knots = np.exp(r_geom.normal(0, cfg.ei_sigma_log, n_seg))
    gx = x[:-1, None] + np.diff(x)[:, None] * ((np.polynomial.legendre.leggauss(5)[0] + 1) / 2)[None]
    radius = 1 - cfg.taper * gx / cfg.length_m
    mesh = Mesh(x=x, EI_g=radius ** 4 * knots[seg_of_el][:, None], m_g=0.2 * radius ** 2)
    # rest shape: a bow of 15-45 degrees over the branch plus a few degrees per joint, as a constant curvature
    # per segment (radians per metre)
    bow = np.radians(r_geom.uniform(15, 45) * r_geom.choice([-1, 1]))
    seg_len = np.diff(node_x)
    turn = bow / max(n_seg - 1, 1) + np.radians(r_geom.normal(0, 3.0, n_seg))
    curv_seg = turn / seg_len
    start_seg = np.concatenate([[0.0], np.cumsum(curv_seg * seg_len)[:-1]])
    el_start = start_seg[seg_of_el] + curv_seg[seg_of_el] * (x[:-1] - node_x[seg_of_el])
    kin = _Kinematics(mesh, np.arange(n_seg + 1) * eps, (el_start, curv_seg[seg_of_el]))
    return mesh, kin, scale_px, seg_of_el


def _turns(kin: _Kinematics, U: np.ndarray, scale_px: float, graph: BranchGraph) -> np.ndarray:
    pos = kin.positions(U, scale_px)
    return turning_angles_deg(pos, graph.nodes, graph.bends)


def simulate_beam(config: BeamConfig = BeamConfig()) -> BeamSimulation:
    """Simulate the beam in wind and a tracker's view of it. Deterministic in ``config.seed``; the geometry, EI,
    z and the noise of a seed do not change when an effect is switched on."""
    config.validate()
    ss = np.random.SeedSequence([config.seed, 0xBEA3])
    r_geom, r_load, r_z, r_eff, r_noise, r_place = (np.random.default_rng(s) for s in ss.spawn(6))
    F, fps, n = config.n_frames, config.fps, config.n_nodes
    lo, hi = config.segment_px
    mid, half = (np.log(lo) + np.log(hi)) / 2, (np.log(hi) - np.log(lo)) / 2
    lengths_px = np.exp(np.clip(r_geom.normal(mid, half / 1.5, n - 1), mid - half, mid + half))
    graph = BranchGraph.from_edges(0, [(i, i + 1) for i in range(n - 1)], source="simulated beam")
    mesh, kin, scale_px, seg_of_el = _fe_beam(config, lengths_px, r_geom)
    L = config.length_m
    gx = mesh.gauss_x() / L                                          # (n_el, 5) normalised position
    # wind load profile (leaf area growing toward the tip, patchy) and petiole lever arms (m), per segment
    patch = np.exp(r_load.normal(0, 0.3, n - 1))[seg_of_el][:, None]
    p1 = (0.3 + gx) * patch
    lever = (r_load.uniform(0.0, 0.03, n - 1))[seg_of_el][:, None] * np.ones_like(gx)
    P = mesh.load_operator(lever)
    M0 = mesh.mass()
    K_unit = mesh.stiffness()
    EI_scale = (config.f1_hz / natural_frequencies_hz(K_unit, M0, 1)[0]) ** 2
    effects = tuple(config.effects)
    strength = {e: config.strength(e) for e in effects}
    params: dict[str, dict] = {}
    z = make_excitation(F, fps, r_z, rms_deg=config.z_rms_deg)
    w2 = make_excitation(F, fps, r_eff, rms_deg=1.0)                 # drawn always: seeds stay aligned
    centre2 = r_eff.uniform(0.15, 0.45)
    onset = np.exp(r_eff.normal(0, ONSET_SIGMA_LOG, n - 1))          # per-segment onset of stiffening
    weak = int(r_eff.integers(max(1, (n - 1) // 3), max(2, 2 * (n - 1) // 3)))   # the creeping joint (node)
    rest = turning_angles_deg(kin.positions(np.zeros((1, mesh.n_dof)), scale_px), graph.nodes, graph.bends)[:, 0]

    def static_turn(K, f):
        u = np.linalg.solve(K, f)
        eps = 1e-4 / max(np.abs(u).max(), 1e-300)
        return (_turns(kin, eps * u[None], scale_px, graph)[:, 0] - rest) / eps, u

    mesh = Mesh(x=mesh.x, EI_g=mesh.EI_g * EI_scale, m_g=mesh.m_g)   # the effect-free beam: f1 = f1_hz
    K0 = mesh.stiffness()
    g, u_unit0 = static_turn(K0, P @ p1.ravel())
    sign = float(np.sign(np.median(g)))
    if not np.all(g * sign > 0):
        raise RuntimeError("beam: a joint bends against the load under the static unit load")
    gm = float(np.exp(np.mean(np.log(np.abs(g)))))
    kappa = np.abs(g) / gm
    amp = sign / gm   # load multiplier per degree of z: the effect-free quasi-static response is kappa z

    def run(active: tuple[str, ...]):
        K, M, tip, beam = K0, M0, 0.0, mesh
        if "modal" in active:
            tip = config.tip_mass_ratio * float(np.sum(mesh.m_g * (np.diff(mesh.x)[:, None] * (
                np.polynomial.legendre.leggauss(5)[1] / 2)[None])))
            M = mesh.mass(tip)
            f_tip = natural_frequencies_hz(K0, M, 1)[0]
            beam = Mesh(x=mesh.x, EI_g=mesh.EI_g * (1.0 / strength["modal"] / f_tip) ** 2, m_g=mesh.m_g)
            K = beam.stiffness()
            params["modal"] = {"period_s": strength["modal"], "tip_mass_kg": tip}
        gK, u_unit = static_turn(K, P @ p1.ravel())
        a_scale = amp * float(np.exp(np.mean(np.log(np.abs(g))))) / float(np.exp(np.mean(np.log(np.abs(gK)))))
        freqs = natural_frequencies_hz(K, M, 3)
        C = rayleigh(K, M, freqs[0], freqs[2], config.zeta)
        n_sub = config.substeps
        t_sub = np.arange((F - 1) * n_sub + 1) / n_sub              # frames
        zs = make_interp_spline(np.arange(F, dtype=float), z, k=3)
        lag = strength["gust_front"] * gx.ravel() if "gust_front" in active else np.zeros(gx.size)
        q = a_scale * p1.ravel()[None] * zs(np.clip(t_sub[:, None] - lag[None], 0.0, None))
        if "gust_front" in active:
            params["gust_front"] = {"tip_lag_frames": strength["gust_front"]}
        if "two_sources" in active:
            p2 = np.exp(-0.5 * ((gx - centre2) / 0.12) ** 2)
            g2, _ = static_turn(K, P @ p2.ravel())
            r1 = np.sqrt(np.mean(np.outer(gK * a_scale, z) ** 2))
            r2 = np.sqrt(np.mean(np.outer(g2, w2) ** 2))
            s2 = strength["two_sources"] * r1 / r2
            ws = make_interp_spline(np.arange(F, dtype=float), w2, k=3)
            q = q + s2 * p2.ravel()[None] * ws(t_sub)[:, None]
            params["two_sources"] = {"centre": centre2, "width": 0.12, "w": w2 * s2, "pattern_deg": g2}
        f = q @ P.T                                                # (steps, n_dof)
        stiff = Stiffening()
        if "stiffening" in active:
            B = mesh.curvature_operator()
            k_unit = np.einsum("egi,ei->eg", B, beam.gather(u_unit))
            k_q = float(np.quantile(np.abs(np.multiply.outer(k_unit.ravel(), a_scale * z)), 0.99))
            k_ref = k_q * onset[seg_of_el][:, None]
            stiff = Stiffening(beta=strength["stiffening"], k_ref=k_ref)
            params["stiffening"] = {"beta": stiff.beta, "k_q_per_m": k_q, "onset_factor": onset}
        creep = Creep()
        if "creep" in active:
            j = weak
            els = np.array([j * config.elements_per_segment - 1, j * config.elements_per_segment])
            k_mean = beam.mean_curvature(els) @ u_unit * a_scale    # (2,) per degree of z
            k_qs = np.outer(k_mean, z)
            k_g = np.sign(k_qs.mean()) * np.sqrt(np.mean(k_qs ** 2))
            gc, _ = static_turn(K, beam.eigen_curvature_load(els).sum(axis=1))
            bend = j - 1                                             # the bend whose joint is node j
            drive = abs(float(np.mean(k_g + k_qs)))
            y_rms = float(np.sqrt(np.mean((gK[bend] * a_scale * z) ** 2)))
            tau = (F / fps) * drive * abs(gc[bend]) / (strength["creep"] * y_rms)
            creep = Creep(elements=tuple(int(e) for e in els), tau_s=tau, k_g=float(k_g))
            params["creep"] = {"weak_edge": list(graph.bends[bend].edge), "tau_s": tau, "k_g_per_m": float(k_g)}
        U, kc = newmark(beam, K, M, C, lambda i: f[i], len(t_sub) - 1, 1.0 / (fps * n_sub), stiff, creep,
                        record_every=n_sub)
        if "creep" in active:
            drift = gc[params["creep"]["weak_edge"][0] - 1] * kc.mean(axis=1)
            params["creep"]["drift_deg"] = [round(float(v), 5) for v in drift]   # per frame
        return U, freqs

    U0, freqs0 = run(())
    U = U0 if not effects else run(effects)[0]
    for e in effects:
        params.setdefault(e, {})
    params["_beam"] = {"f_hz_effect_free": freqs0.tolist(), "zeta": config.zeta, "length_m": L,
                       "px_per_m": scale_px, "load_sign": sign}
    pos0 = kin.positions(U, scale_px)
    y0 = turning_angles_deg(kin.positions(U0, scale_px), graph.nodes, graph.bends) - rest[:, None]
    y = turning_angles_deg(pos0, graph.nodes, graph.bends) - rest[:, None]
    true_xy, _, root_px = place_in_image(pos0, config.image_size, r_place)
    seg = {e: float(np.linalg.norm(true_xy[i + 1, 0] - true_xy[i, 0])) for i, e in enumerate(graph.edges)}
    dist = np.concatenate([[0.0], np.cumsum([seg[e] for e in graph.edges])])
    noisy, sigma = add_tracker_noise(graph, true_xy, dist / dist[-1], config.noise, fps, r_noise)
    sigma_px = None
    if config.noise.emit_sigma and config.noise.enabled:
        sigma_px = np.where(np.isfinite(noisy[..., 0]), sigma[:, None], np.nan)
    tracks = Tracks(node_ids=np.array(graph.nodes), xy=noisy, sigma_px=sigma_px,
                    source=f"simulated beam (seed {config.seed})")
    return BeamSimulation(config=config, graph=graph, tracks=tracks, true_xy=true_xy,
                          kappa_true={b.edge: float(k) for b, k in zip(graph.bends, kappa)}, z_true=z,
                          response_true=y, effect_params=params,
                          rest_turn_deg={b.edge: float(r) for b, r in zip(graph.bends, rest)}, segment_px=seg,
                          root_px=(float(root_px[0]), float(root_px[1])), response_effect_free=y0)
