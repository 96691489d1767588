"""Ground-truth simulator of a wind-excited branch with switchable physical effects.

What it produces (all deterministic given ``SimulationConfig.seed``):

* a planar branch (a chain, or a small tree with one side branch) of ``n_nodes`` nodes with node ids
  ``0..n_nodes-1`` (root 0), segment lengths in pixels (10-30 px, like the real plants) and a gently
  curved rest shape (rest turning angles of a few degrees per joint);
* a per-edge compliance ``kappa_true`` (log-normal, geometric mean exactly 1) for every edge that has a bend
  (every edge whose parent is not the root);
* a signed wind excitation ``z_true[t]`` in degrees (calm start, gusts, a periodic sway, coloured noise;
  RMS 1.5 degrees by default, like the real plants' 1.2-1.7 degrees);
* the true bend response ``y[e, t]`` in degrees = deviation of the signed turning angle at the bend's joint
  from its rest value. Baseline (no effect): ``y[e, t] = kappa_e * z_t``. Effects (``EFFECTS``) modify it,
  see :func:`bend_response`;
* planar forward kinematics -> true node positions (pixels, x right, y down) in a 640x480 image;
* tracker-like noisy tracks (see :class:`NoiseConfig`): anisotropic white noise (along the branch >> across),
  slow AR(1) drift, occlusion gaps (absent rows), occasional jumps; optionally, before that noise, tracker
  artifacts that follow the motion (speed-dependent error, lag, occlusion in gusts, slide along the stem,
  coloured along-branch noise, drift; :mod:`rce_gtsam.sim.artifacts`, ``SimulationConfig.artifacts``).

Angle convention (shared with the analysis): the signed turning angle at joint j of bend (g, j, c) is
``atan2(cross(u, v), dot(u, v))`` with ``u = p_j - p_g``, ``v = p_c - p_j`` (image coordinates), in degrees;
0 = straight. See :func:`turning_angles_deg`.

Time unit inside the physics is the video frame (``fps`` frames per second).
"""

from __future__ import annotations

import json
import math
import os
import shutil
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np

from ..errors import InputError
from ..fileio import publish, temp_dir_beside
from ..graph import BranchGraph
from ..jsonutil import jsonable as _jsonable
from ..tracks import Tracks, write_table_atomic
from .artifacts import ArtifactConfig, apply_artifacts, branch_tangents
# the excitation and the effects' laws, the planar kinematics and the tracker noise live in their own modules;
# they are re-exported here, the simulator's one import path
from .bend_laws import (EFFECT_DEFAULTS, EFFECT_FORMS, EFFECT_MEANING, EFFECTS, bend_response,  # noqa: F401
                        default_form, delayed, make_excitation, oscillator_response)
from .kinematics import (build_graph, root_distances, forward_kinematics, place_in_image,  # noqa: F401
                         turning_angles_deg)
from .three_d import GEOMETRIC_EFFECTS, Scene3D, Truth3D
from .tracker_noise import NoiseConfig, add_tracker_noise  # noqa: F401


@dataclass(frozen=True)
class SimulationConfig:
    """What to simulate.

    n_nodes: number of tracked nodes (>= 3 so there is a bend); n_frames: video frames; fps: frames/s.
    effects: names from :data:`EFFECTS` to switch on (composable). effect_strength: per-effect overrides of
        :data:`EFFECT_DEFAULTS` (see :data:`EFFECT_MEANING` for units).
    noise: tracker noise model. seed: master seed (every random step derives from it).
    image_size: (width, height) in pixels. branch_layout: ``"chain"`` or ``"tree"`` (a main chain with one
        side branch of about n_nodes/4 nodes).
    z_rms_deg: RMS of the excitation z_true in degrees. kappa_sigma_log: spread of log kappa.
    segment_px: (min, max) segment length in pixels. root_sway_deg: RMS rigid sway of the root edge heading
        (0 = root edge fixed; the sway rotates the whole branch and changes no turning angle).
    """

    n_nodes: int = 20
    n_frames: int = 900
    fps: float = 30.0
    effects: tuple[str, ...] = ()
    effect_strength: dict | None = None
    effect_form: dict | None = None
    noise: NoiseConfig = field(default_factory=NoiseConfig)
    seed: int = 0
    image_size: tuple[int, int] = (640, 480)
    branch_layout: Literal["chain", "tree"] = "chain"
    z_rms_deg: float = 1.5
    kappa_sigma_log: float = 0.5
    segment_px: tuple[float, float] = (12.0, 28.0)
    root_sway_deg: float = 0.0
    artifacts: ArtifactConfig = field(default_factory=ArtifactConfig)
    scene3d: Scene3D | None = None  # the 3-D scene (sim/three_d.py); None: 3-D only with out_of_plane

    def strength(self, effect: str) -> float:
        """The strength of ``effect`` (override or default)."""
        over = self.effect_strength or {}
        return float(over.get(effect, EFFECT_DEFAULTS[effect]))

    def form(self, effect: str) -> str:
        """The form of ``effect`` (override or the first of :data:`EFFECT_FORMS`)."""
        return str((self.effect_form or {}).get(effect, default_form(effect)))

    def validate(self) -> None:
        src = "simulation config"
        if not isinstance(self.n_nodes, int) or self.n_nodes < 3:
            raise InputError(src, f"n_nodes must be an integer >= 3 (a bend needs 3 nodes), got {self.n_nodes!r}")
        if self.branch_layout == "tree" and self.n_nodes < 7:
            raise InputError(src, f"a tree layout needs n_nodes >= 7, got {self.n_nodes}")
        if self.branch_layout not in ("chain", "tree"):
            raise InputError(src, f"branch_layout must be 'chain' or 'tree', got {self.branch_layout!r}")
        if not isinstance(self.n_frames, int) or self.n_frames < 10:
            raise InputError(src, f"n_frames must be an integer >= 10, got {self.n_frames!r}")
        if not self.fps > 0:
            raise InputError(src, f"fps must be > 0, got {self.fps!r}")
        unknown = [e for e in self.effects if e not in EFFECTS + GEOMETRIC_EFFECTS]
        if unknown:
            raise InputError(src, f"unknown effect(s) {unknown}; known: {', '.join(EFFECTS)}")
        for k, v in (self.effect_strength or {}).items():
            if k not in EFFECTS + GEOMETRIC_EFFECTS:
                raise InputError(src, f"effect_strength names an unknown effect {k!r}; known: {', '.join(EFFECTS)}")
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise InputError(src, f"effect_strength[{k!r}] must be a finite number >= 0, got {v!r}")
        for k, v in (self.effect_form or {}).items():
            if k not in EFFECTS:
                raise InputError(src, f"effect_form names an unknown effect {k!r}; known: {', '.join(EFFECTS)}")
            if v not in EFFECT_FORMS[k]:
                raise InputError(src, f"effect_form[{k!r}] must be one of {', '.join(EFFECT_FORMS[k])}, got {v!r}")
        self.artifacts.validate()
        if self.scene3d is not None or "out_of_plane" in self.effects:  # a planar simulation has no camera to check
            (self.scene3d or Scene3D()).validate(self.image_size)
        w, h = self.image_size
        if w < 64 or h < 64:
            raise InputError(src, f"image_size must be at least 64x64, got {self.image_size}")


#: the branch direction at each node (kept under its old name for the tests that use it); the tracker noise is
#: :func:`rce_gtsam.sim.tracker_noise.add_tracker_noise`
_tangents = branch_tangents


# ----------------------------------------------------------------------------------------------------------
# Simulation
# ----------------------------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class Simulation:
    """A simulated recording with its ground truth.

    config: the :class:`SimulationConfig`. graph: the branch (node ids 0..N-1, root 0).
    tracks: noisy tracker-like :class:`~rce_gtsam.tracks.Tracks` (rows in graph.nodes order; NaN = occluded).
    true_xy: (N, F, 2) true node positions in pixels, rows in graph.nodes order (= tracks.node_ids).
    kappa_true: {(parent, child): kappa} for every edge with a bend (geometric mean exactly 1).
    z_true: (F,) excitation in degrees. response_true: (E, F) true bend deviations from rest in degrees, rows
    in graph.bends order. rest_turn_deg: {(joint, child): rest turning angle in degrees}.
    segment_px: {(parent, child): length in pixels}. effect_params: parameters of the active effects.
    artifact_params: {family: parameters used} of the active tracker artifacts (:mod:`rce_gtsam.sim.artifacts`).
    """

    config: SimulationConfig
    graph: BranchGraph
    tracks: Tracks
    true_xy: np.ndarray
    kappa_true: dict
    z_true: np.ndarray
    response_true: np.ndarray
    effect_params: dict
    rest_turn_deg: dict = field(default_factory=dict)
    segment_px: dict = field(default_factory=dict)
    root_px: tuple[float, float] = (0.0, 0.0)
    artifact_params: dict = field(default_factory=dict)
    three_d: Truth3D | None = None  # the 3-D truth (sim/three_d.py) when the scene is 3-D

    def truth_json(self) -> dict:
        """Ground truth as a JSON-ready dict: kappa_true keyed "parent->child", z_true, response_true
        (keyed like kappa), effects and their parameters, seed, config, geometry."""
        key = lambda e: f"{e[0]}->{e[1]}"  # noqa: E731
        cfg = asdict(self.config)
        cfg["effects"] = list(self.config.effects)
        cfg["strengths"] = {e: self.config.strength(e) for e in self.config.effects}
        cfg["artifacts"] = {"families": list(self.config.artifacts.families), "scale": self.config.artifacts.scale,
                            "preset": self.config.artifacts.preset}
        out = {
            "format": "rce_gtsam simulation truth v1",
            "seed": self.config.seed,
            "fps": self.config.fps,
            "n_frames": int(self.z_true.shape[0]),
            "units": {"kappa": "relative (geometric mean 1)", "z_true": "degrees", "response": "degrees",
                      "positions": "pixels", "time": "frames"},
            "effects": list(self.config.effects),
            "effect_params": _jsonable(self.effect_params),
            "kappa_true": {key(e): float(k) for e, k in self.kappa_true.items()},
            "z_true": [round(float(v), 6) for v in self.z_true],
            "response_true": {key(b.edge): [round(float(v), 6) for v in self.response_true[i]]
                              for i, b in enumerate(self.graph.bends)},
            "rest_turn_deg": {key(e): float(v) for e, v in self.rest_turn_deg.items()},
            "segment_px": {key(e): float(v) for e, v in self.segment_px.items()},
            "root_px": [float(v) for v in self.root_px],
            "config": _jsonable(cfg),
        }
        if self.three_d is not None:
            out.update(self.three_d.truth_json(self.graph))
        if self.config.artifacts.active:
            from .artifacts import preset_provenance
            out["artifacts"] = {"families": list(self.config.artifacts.families),
                                "scale": self.config.artifacts.scale, "preset": self.config.artifacts.preset,
                                "units": "px, frames, px/frame, s (rce_gtsam.sim.artifacts.PARAMETERS)",
                                "params": _jsonable(self.artifact_params),
                                "provenance": preset_provenance(self.config.artifacts.preset)}
        return out

    def write(self, out_dir: str | Path, video: bool = False, render=None, depth: bool = False) -> dict[str, Path]:
        """Write tracks.csv, true_tracks.csv, graph.json, truth.json, annotations.json (+ video.mp4; with
        ``depth`` also recording.db3 with colour and aligned depth, :mod:`rce_gtsam.sim.recording`).

        ``render``: camera nuisances of the video (:class:`~rce_gtsam.sim.nuisance.RenderConfig`; None = the
        clean render). With camera shake, true_tracks.csv and tracks.csv hold positions in the image
        (``nuisance.image_xy``: true positions plus the per-frame camera shift, which is zero at frame 0, so
        annotations.json is unchanged); a non-default config is recorded in truth.json under ``"render"``
        (its fields and ``camera_shift_px``, (F, 2) pixels). kappa, z and the bends do not change: a
        translation of the whole image turns no segment.
        Atomic: files are written into a temporary folder next to ``out_dir`` and then moved into it,
        replacing files of the same name and leaving other files alone (the overwrite policy of every
        command, :func:`rce_gtsam.fileio.publish`); a ``video.mp4`` of an earlier run is removed when this one
        renders none, so the folder never pairs new tracks with an old video.
        Returns {name: path}.
        """
        out = Path(out_dir)
        tmp = temp_dir_beside(out)
        try:
            from .nuisance import RenderConfig, camera_shift
            tracks, true_xy, truth = self.tracks, self.true_xy, self.truth_json()
            if render is not None and render != RenderConfig():
                shift = camera_shift(self, render)
                if shift.any():
                    true_xy = true_xy + shift[None]
                    tracks = Tracks(tracks.node_ids, tracks.xy + shift[None], tracks.sigma_px, source=tracks.source)
                truth["render"] = {**asdict(render), "camera_shift_px": [[round(float(v), 4) for v in r] for r in shift]}
            df = tracks.to_frame()
            write_table_atomic(df.round(4), tmp / "tracks.csv")
            tt = Tracks(self.tracks.node_ids, true_xy, source="truth").to_frame()
            write_table_atomic(tt.round(4), tmp / "true_tracks.csv")
            (tmp / "graph.json").write_text(json.dumps(self.graph.to_json()) + "\n")
            (tmp / "truth.json").write_text(json.dumps(truth) + "\n")
            row = {nid: i for i, nid in enumerate(self.tracks.node_ids)}
            pts = [[round(float(v), 4) for v in self.true_xy[row[n], 0]] for n in sorted(row)]
            (tmp / "annotations.json").write_text(json.dumps({"points": pts}) + "\n")
            if video or depth:
                from .recording import write_media
                write_media(self, tmp, render=render, depth=depth)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        publish(tmp, out, stale=WRITTEN_FILES)
        return {p.name: p for p in sorted(out.iterdir()) if p.name in WRITTEN_FILES}


#: Files :meth:`Simulation.write` may write.
WRITTEN_FILES = ("tracks.csv", "true_tracks.csv", "graph.json", "truth.json", "annotations.json", "video.mp4",
                 "recording.db3")


def simulate(config: SimulationConfig = SimulationConfig()) -> Simulation:
    """Simulate a wind-excited branch and a tracker's view of it. Deterministic in ``config.seed``.

    Independent random streams (spawned from the seed) drive geometry, kappa, the excitation, the effects
    and the noise, so switching an effect on does not change the geometry, kappa or z of the same seed.
    """
    config.validate()
    ss = np.random.SeedSequence(config.seed)
    r_geom, r_kappa, r_z, r_eff, r_noise, r_place = (np.random.default_rng(s) for s in ss.spawn(6))
    F = config.n_frames
    graph, rest = build_graph(config.n_nodes, config.branch_layout, r_geom)
    lo, hi = config.segment_px
    mid, half = (np.log(lo) + np.log(hi)) / 2, (np.log(hi) - np.log(lo)) / 2
    lengths = {e: float(np.exp(np.clip(r_geom.normal(mid, half / 1.5), mid - half, mid + half))) for e in graph.edges}
    dist = root_distances(graph, lengths)
    dmax = max(dist.values())
    bends = graph.bends
    s_edge = np.array([dist[b.child] / dmax for b in bends])
    logk = r_kappa.normal(0, config.kappa_sigma_log, len(bends))
    kappa = np.exp(logk - logk.mean())
    z = make_excitation(F, config.fps, r_z, rms_deg=config.z_rms_deg)
    strength = {e: config.strength(e) for e in EFFECTS}
    y, params = bend_response(kappa, s_edge, z, tuple(config.effects), strength, config.fps, r_eff,
                              {e: config.form(e) for e in EFFECTS})
    turn = {b.edge: rest[b.edge] + y[i] for i, b in enumerate(bends)}
    sway = config.root_sway_deg * z / max(np.sqrt(np.mean(z ** 2)), 1e-12)
    pos0 = forward_kinematics(graph, lengths, np.radians(sway), turn)
    true_xy, rot, root_px = place_in_image(pos0, config.image_size, r_place)
    if not np.isclose(np.linalg.norm(true_xy[1, 0] - true_xy[0, 0]), lengths[graph.edges[0]]):
        scale = np.linalg.norm(true_xy[1, 0] - true_xy[0, 0]) / lengths[graph.edges[0]]
        lengths = {e: L * scale for e, L in lengths.items()}
    three = None
    if config.scene3d is not None or "out_of_plane" in config.effects:  # 3-D scene, projected (sim/three_d.py)
        from .three_d import simulate_3d
        true_xy, three, lengths = simulate_3d(graph, true_xy, root_px, kappa, z, config, lengths)
    s_node = np.array([dist[n] / dmax for n in graph.nodes])
    tracked, artifact_params = true_xy, {}
    if config.artifacts.active:
        # its own stream, spawned after the six above: the default recording's draws stay as they were
        art = apply_artifacts(graph, true_xy, config.fps, config.artifacts, np.random.default_rng(ss.spawn(1)[0]))
        tracked, artifact_params = art.xy, art.params
    noisy, sigma = add_tracker_noise(graph, tracked, s_node, config.noise, config.fps, r_noise)
    if config.artifacts.active:
        noisy[~art.visible] = np.nan
    sigma_px = None
    if config.noise.emit_sigma and config.noise.enabled:
        sigma_px = np.where(np.isfinite(noisy[..., 0]), sigma[:, None], np.nan)
    tracks = Tracks(node_ids=np.array(graph.nodes), xy=noisy, sigma_px=sigma_px,
                    source=f"simulated (seed {config.seed})")
    return Simulation(config=config, graph=graph, tracks=tracks, true_xy=true_xy,
                      kappa_true={b.edge: float(k) for b, k in zip(bends, kappa)}, z_true=z,
                      response_true=y, effect_params=params, rest_turn_deg=rest, segment_px=lengths,
                      root_px=(float(root_px[0]), float(root_px[1])), artifact_params=artifact_params, three_d=three)


# ----------------------------------------------------------------------------------------------------------
# Measurements used by the tests and the report
# ----------------------------------------------------------------------------------------------------------

def rank1_misfit(Y: np.ndarray) -> tuple[float, float]:
    """(RMS of Y - best rank-1 approximation (truncated SVD), RMS of Y), both in Y's units."""
    U, S, Vt = np.linalg.svd(Y, full_matrices=False)
    R = Y - S[0] * np.outer(U[:, 0], Vt[0])
    return float(np.sqrt(np.mean(R ** 2))), float(np.sqrt(np.mean(Y ** 2)))


def angle_noise_deg(sim: Simulation) -> float:
    """RMS over bends and observed frames of (turning angle from noisy tracks - from true positions), degrees."""
    a = turning_angles_deg(sim.tracks.xy, sim.tracks.node_ids, sim.graph.bends)
    b = turning_angles_deg(sim.true_xy, sim.tracks.node_ids, sim.graph.bends)
    d = (a - b + 180) % 360 - 180
    return float(np.sqrt(np.nanmean(d ** 2)))


#: The committed sample recordings (folder name under data/ -> effects). Regenerate with
#: ``python -m rce_gtsam.sim.simulate`` (calls :func:`write_sample`).
SAMPLES: dict[str, tuple[str, ...]] = {"sample": (), "sample_delay": ("delay",)}


def write_sample(data_dir: str | Path = "data", seed: int = 0, n_frames: int = 600,
                 n_nodes: int = 20) -> dict[str, Path]:
    """Write the small committed sample recordings (no video) into ``data_dir``/<name>/ with a README.md
    saying how they were made. Returns {name: folder}."""
    out = {}
    for name, effects in SAMPLES.items():
        cfg = SimulationConfig(n_nodes=n_nodes, n_frames=n_frames, effects=effects, seed=seed)
        folder = Path(data_dir) / name
        simulate(cfg).write(folder)
        eff = ", ".join(effects) or "none"
        note = (f"# Simulated sample recording `{name}`\n\n"
                f"Made by `rce_gtsam.sim.simulate.write_sample()` (run `python -m rce_gtsam.sim.simulate [DATA_DIR]`), i.e.\n"
                f"`rce simulate --seed {seed} --frames {n_frames} --nodes {n_nodes}"
                f"{' --effect ' + ','.join(effects) if effects else ''} --out {folder}`.\n\n"
                f"- hidden effect: {eff}\n"
                f"- `tracks.csv`: noisy tracker-like tracks (point_id,frame,x,y; absent rows = occluded)\n"
                f"- `true_tracks.csv`: noise-free node positions; `graph.json`: branch graph (root 0)\n"
                f"- `truth.json`: kappa_true, z_true, response_true (degrees), effect parameters, config\n"
                f"- `annotations.json`: first-frame node positions (index = point id)\n")
        tmp = folder / ".README.md.tmp"
        tmp.write_text(note)
        os.replace(tmp, folder / "README.md")
        out[name] = folder
    return out


if __name__ == "__main__":  # pragma: no cover
    import sys
    for n, f in write_sample(sys.argv[1] if len(sys.argv) > 1 else "data").items():
        print(f"wrote {f}")
