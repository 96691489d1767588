"""3-D geometry of a simulated branch: out-of-plane swing, a tilted branch plane and a pinhole camera.

The physical model (issue #39's shared spec; the ``out_of_plane`` effect fits it, the depth stream measures it):

* The branch's rest pose lies in its *branch plane*. In-plane bend at joint e: ``theta[e, t]`` = rest turn +
  the existing simulator's response (``kappa_e z_t`` with its effects). Out-of-plane bend at joint e, a rotation
  out of the branch plane about the segment's in-plane normal: ``psi[e, t] = kappa_e * z_o(t)`` (degrees), the
  same compliance (a round stem bends alike in both directions), with
  ``z_o(t) = share * (rho * z(t) + sqrt(1 - rho^2) * z'(t))``, ``z'`` an independent draw of the excitation
  process (:func:`~rce_gtsam.sim.simulate.make_excitation`, its own seed stream): the wind's direction wanders.
  ``share`` is the effect's strength (:data:`DEFAULT_SHARE`); ``rho`` = :data:`DEFAULT_RHO`.
* The rest branch plane is tilted by ``tilt_deg`` about the image x axis through the root: with a positive tilt
  the upper part of the branch (smaller image y) leans away from the camera.
* Camera: pinhole with D435i-like colour intrinsics at 640x480 (fx = fy = 615 px, cx = 320, cy = 240), camera
  frame x right, y down, z forward (mm). The root is at depth ``root_depth_mm`` (seeded, 700-900 mm). The
  metric scale is ``mm_per_px = Z_root / fx``: at tilt 0 and without swing the projection reproduces the planar
  simulator's image positions exactly, so the branch fills the image as the 2-D simulator's does (if a tilted
  or swinging branch would leave the image, the scale shrinks until every frame fits).

Kinematics: every node carries a frame (tangent t, out-of-plane normal n). A child edge first turns by theta
about n (in the plane the frame carries), then by psi about its in-plane normal ``n x t``:
``t' = cos(psi) t_theta + sin(psi) n``, ``n' = cos(psi) n - sin(psi) t_theta``. Without swing every tangent
stays in the branch plane and the chain is the planar one. Positive psi turns a segment toward the plane's
normal ``n0 = (0, sin(tilt), cos(tilt))`` (away from the camera).

Truth (:class:`Truth3D`): positions in mm (frames x nodes x 3 in truth.json), theta and psi, the unsigned 3-D
turning angle per joint, the projected 2-D turning angles, ``kappa_true_3d`` (= the simulator's kappa, geometric
mean 1) and ``kappa_true_image`` (the rank-1 kappa of the noise-free projected 2-D turning angles: what a
perfect 2-D tracker would give).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..camera import CameraIntrinsics
from ..errors import InputError
from .kinematics import turning_angles_deg

#: Effects of the 3-D geometry (not laws on the in-plane response): switched on like the others.
GEOMETRIC_EFFECTS: tuple[str, ...] = ("out_of_plane",)
#: Default share of the wind that swings the branch out of its plane (the effect's strength).
DEFAULT_SHARE = 0.5
#: Default correlation of the out-of-plane excitation with the in-plane one.
DEFAULT_RHO = 0.5
#: Default tilt (degrees) of the rest branch plane about the image x axis when the branch swings out of plane.
DEFAULT_TILT_DEG = 30.0
MEANING = ("share: psi_e(t) = kappa_e * share * (rho z(t) + sqrt(1-rho^2) z'(t)), rotation out of the "
           "branch plane (tilted by --tilt-deg, default 30, about the image x axis; rho 0.5)")


#: The pinhole camera of the scene (:class:`rce_gtsam.camera.CameraIntrinsics`, shared with the RealSense
#: reader/writer and the 3-D smoother).
Camera = CameraIntrinsics


@dataclass(frozen=True)
class Scene3D:
    """How the planar simulation is set in 3-D.

    tilt_deg: tilt of the rest branch plane about the image x axis in degrees (None: :data:`DEFAULT_TILT_DEG`
        when the branch swings out of plane, else 0 so a planar recording keeps the 2-D simulator's images).
    rho: correlation of the out-of-plane excitation with the in-plane one (-1..1).
    root_depth_mm: (min, max) of the seeded root depth in mm. background_mm: depth of the background plane (mm).
    camera: the pinhole :class:`Camera`.
    """

    tilt_deg: float | None = None
    rho: float = DEFAULT_RHO
    root_depth_mm: tuple[float, float] = (700.0, 900.0)
    background_mm: float = 1500.0
    camera: CameraIntrinsics = field(default_factory=CameraIntrinsics.d435i_colour)

    def tilt(self, effects) -> float:
        """The tilt in degrees that applies to a simulation with ``effects``."""
        if self.tilt_deg is not None:
            return float(self.tilt_deg)
        return DEFAULT_TILT_DEG if "out_of_plane" in effects else 0.0

    def validate(self, image_size=(640, 480)) -> None:
        src = "simulation config (scene3d)"
        if self.tilt_deg is not None and not (math.isfinite(self.tilt_deg) and abs(self.tilt_deg) <= 75):
            raise InputError(src, f"tilt_deg must be a number in [-75, 75] degrees, got {self.tilt_deg!r}")
        if not (math.isfinite(self.rho) and -1 <= self.rho <= 1):
            raise InputError(src, f"rho must be in [-1, 1], got {self.rho!r}")
        lo, hi = self.root_depth_mm
        if not (300 <= lo <= hi < self.background_mm - 200):
            raise InputError(src, f"root_depth_mm must satisfy 300 <= min <= max < background_mm - 200, got "
                                  f"{self.root_depth_mm} with background {self.background_mm}")
        if (self.camera.width, self.camera.height) != tuple(image_size):
            raise InputError(src, f"camera size {self.camera.width}x{self.camera.height} differs from image_size "
                                  f"{tuple(image_size)}")


@dataclass(frozen=True, eq=False)
class Truth3D:
    """The 3-D truth of a simulated recording (rows of per-node arrays in graph.nodes order, of per-bend arrays
    in graph.bends order).

    positions_mm: (N, F, 3) node positions in the camera frame (mm). tilt_deg, share, rho: the scene.
    root_depth_mm: root depth (mm). mm_per_px: branch-plane scale (mm per px of the planar layout).
    plane_normal: (3,) unit normal of the rest branch plane (camera frame). z_o: (F,) out-of-plane excitation
    (degrees); z_prime: (F,) its independent part. theta_deg, psi_deg: (E, F) in-plane and out-of-plane joint
    angles (theta includes the rest turn; psi has rest 0). turn3d_deg: (E, F) unsigned 3-D turning angle.
    image_turn_deg: (E, F) signed turning angle of the noise-free projected 2-D positions. kappa_3d, kappa_image:
    (E,) compliance of the 3-D bending and of its image projection (both geometric mean 1). segment_mm,
    stem_radius_mm: {(parent, child): mm}.
    """

    camera: Camera
    positions_mm: np.ndarray
    tilt_deg: float
    share: float
    rho: float
    root_depth_mm: float
    mm_per_px: float
    plane_normal: np.ndarray
    z_o: np.ndarray
    z_prime: np.ndarray
    theta_deg: np.ndarray
    psi_deg: np.ndarray
    turn3d_deg: np.ndarray
    image_turn_deg: np.ndarray
    kappa_3d: np.ndarray
    kappa_image: np.ndarray
    segment_mm: dict
    stem_radius_mm: dict

    @property
    def fit_scale(self) -> float:
        """Size of the branch relative to the planar layout (1 = as the planar simulator draws it; below 1 the
        branch was shrunk so that its tilted, swinging image stays in view)."""
        return self.mm_per_px * self.camera.fx / self.root_depth_mm

    def width_factor(self, edge, graph) -> float:
        """The stem's image width at frame 0 over its width in the planar layout for segment ``edge``: the tube
        (radius ``stem_radius_mm``) seen at its mid-point's depth, so the colour and the depth images agree.
        Exactly 1 for a flat scene (tilt 0, no swing)."""
        row = {n: i for i, n in enumerate(graph.nodes)}
        z_mid = 0.5 * (self.positions_mm[row[edge[0]], 0, 2] + self.positions_mm[row[edge[1]], 0, 2])
        k = self.fit_scale * self.root_depth_mm / z_mid
        return 1.0 if abs(k - 1.0) < 1e-9 else float(k)

    def truth_json(self, graph) -> dict:
        """The 3-D entries of truth.json (keys ``kappa_true_3d``, ``kappa_true_image``, ``positions_mm`` and
        ``three_d``: the scene, the camera, the angles), edges keyed "parent->child"."""
        key = lambda e: f"{e[0]}->{e[1]}"  # noqa: E731
        r = lambda a, n=4: np.round(np.asarray(a, float), n).tolist()  # noqa: E731
        bends = graph.bends
        return {
            "kappa_true_3d": {key(b.edge): float(k) for b, k in zip(bends, self.kappa_3d)},
            "kappa_true_image": {key(b.edge): float(k) for b, k in zip(bends, self.kappa_image)},
            "positions_mm": r(self.positions_mm.transpose(1, 0, 2), 3),
            "three_d": {
                "units": {"positions_mm": "mm, camera frame (x right, y down, z forward), frames x nodes x 3 in "
                                          "graph.nodes order", "angles": "degrees", "camera": "px"},
                "node_order": [int(n) for n in graph.nodes],
                "camera": {**self.camera.to_dict(), "model": "pinhole, no distortion", "units": "px"}, "tilt_deg": self.tilt_deg, "share": self.share, "rho": self.rho,
                "root_depth_mm": self.root_depth_mm, "mm_per_px": self.mm_per_px, "fit_scale": self.fit_scale,
                "plane_normal": r(self.plane_normal, 6), "z_o": r(self.z_o, 6), "z_prime": r(self.z_prime, 6),
                "segment_mm": {key(e): float(v) for e, v in self.segment_mm.items()},
                "stem_radius_mm": {key(e): float(v) for e, v in self.stem_radius_mm.items()},
                "theta_deg": {key(b.edge): r(self.theta_deg[i]) for i, b in enumerate(bends)},
                "psi_deg": {key(b.edge): r(self.psi_deg[i]) for i, b in enumerate(bends)},
                "turn3d_deg": {key(b.edge): r(self.turn3d_deg[i]) for i, b in enumerate(bends)},
                "image_turn_deg": {key(b.edge): r(self.image_turn_deg[i]) for i, b in enumerate(bends)},
            },
        }


def _rotate_x(tilt_rad: float) -> np.ndarray:
    c, s = math.cos(tilt_rad), math.sin(tilt_rad)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def chain_3d(graph, planar: np.ndarray, psi_deg: np.ndarray) -> np.ndarray:
    """Node positions (N, F, 3) in branch-plane coordinates (px units; third axis = plane normal).

    ``planar`` (N, F, 2): the planar chain's positions relative to the root (px, rows in graph.nodes order); its
    root headings, in-plane turning angles and segment lengths are kept. ``psi_deg`` (E, F): out-of-plane bend per
    joint (rows in graph.bends order). See the module docstring for the kinematics.
    """
    N, F, _ = planar.shape
    row = {n: i for i, n in enumerate(graph.nodes)}
    theta = np.radians(turning_angles_deg(planar, graph.nodes, graph.bends))
    bend_row = {b.edge: i for i, b in enumerate(graph.bends)}
    pos = np.zeros((N, F, 3))
    pos[..., :2] = planar[row[graph.root]][None]
    tang: dict[int, np.ndarray] = {}
    norm: dict[int, np.ndarray] = {}
    for c in graph.nodes[1:]:
        p = graph.parent[c]
        d = planar[row[c]] - planar[row[p]]
        L = np.linalg.norm(d[0])
        if p == graph.root:
            t = np.concatenate([d / np.linalg.norm(d, axis=-1, keepdims=True), np.zeros((F, 1))], -1)
            n = np.tile([0.0, 0.0, 1.0], (F, 1))
        else:
            i = bend_row[(p, c)]
            t0, n0 = tang[p], norm[p]
            th, ps = theta[i][:, None], np.radians(psi_deg[i])[:, None]
            t1 = np.cos(th) * t0 + np.sin(th) * np.cross(n0, t0)
            t = np.cos(ps) * t1 + np.sin(ps) * n0
            n = np.cos(ps) * n0 - np.sin(ps) * t1
        tang[c], norm[c] = t, n
        pos[row[c]] = pos[row[p]] + L * t
    return pos


def turning_3d_deg(P: np.ndarray, node_ids, bends) -> np.ndarray:
    """Unsigned 3-D turning angle (E, F) in degrees at each bend: the angle between u = p_j - p_g and
    v = p_c - p_j (``P`` (N, F, 3), rows in ``node_ids`` order)."""
    row = {int(n): i for i, n in enumerate(node_ids)}
    g, j, c = (P[[row[getattr(b, a)] for b in bends]] for a in ("grandparent", "joint", "child"))
    u, v = j - g, c - j
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(u, v), axis=-1), (u * v).sum(-1)))


def rank1_kappa(Y: np.ndarray) -> np.ndarray:
    """The rank-1 compliance of a noise-free (E, F) response: the leading left singular vector, signed so
    that most entries are positive, scaled to geometric mean 1 of its magnitudes."""
    U, S, _ = np.linalg.svd(Y, full_matrices=False)
    k = U[:, 0] * (1.0 if np.sum(np.sign(U[:, 0])) >= 0 else -1.0)
    return k / np.exp(np.mean(np.log(np.maximum(np.abs(k), 1e-300))))


def lift(graph, planar_xy: np.ndarray, root_px, psi_deg: np.ndarray, tilt_deg: float, root_depth_mm: float,
         camera: Camera, margin: float = 20.0) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
    """Set the planar simulation in 3-D and project it.

    ``planar_xy`` (N, F, 2): the planar simulator's image positions (px); ``root_px`` its root. Returns
    (positions_mm (N, F, 3), image positions (N, F, 2) px, mm_per_px, plane normal (3,)). The scale starts at
    ``root_depth_mm / fx`` (exact reproduction of ``planar_xy`` at tilt 0 without swing) and shrinks by 5 %
    steps while any projected node would come within ``margin`` px of the image border.
    """
    q = planar_xy - np.asarray(root_px, float)
    local = chain_3d(graph, q, psi_deg)
    R = _rotate_x(-math.radians(tilt_deg))    # (0, 1, 0) -> (0, cos, -sin): upper part (y < 0) leans away
    cam = camera
    root = np.array([(root_px[0] - cam.cx) * root_depth_mm / cam.fx, (root_px[1] - cam.cy) * root_depth_mm / cam.fy,
                     root_depth_mm])
    scale = root_depth_mm / cam.fx
    for _ in range(40):
        P = root + scale * local @ R.T
        xy = cam.project(P)
        inside = (xy[..., 0].min() >= margin and xy[..., 0].max() <= cam.width - margin
                  and xy[..., 1].min() >= margin and xy[..., 1].max() <= cam.height - margin)
        if (inside and P[..., 2].min() > 100) or (tilt_deg == 0 and not np.any(psi_deg)):
            break
        scale *= 0.95
    return P, xy, float(scale), R @ np.array([0.0, 0.0, 1.0])


def out_of_plane_excitation(z: np.ndarray, share: float, rho: float, fps: float, seed: int,
                            rms_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """(z_o, z') in degrees: ``z_o = share * (rho z + sqrt(1 - rho^2) z')``, ``z'`` drawn by
    :func:`~rce_gtsam.sim.simulate.make_excitation` (RMS ``rms_deg``) from its own seed stream."""
    from .bend_laws import make_excitation
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x0B3D]))
    z2 = make_excitation(len(z), fps, rng, rms_deg=rms_deg)
    return share * (rho * z + math.sqrt(max(0.0, 1 - rho ** 2)) * z2), z2


def simulate_3d(graph, planar_xy: np.ndarray, root_px, kappa: np.ndarray, z: np.ndarray, config,
                lengths_px: dict) -> tuple[np.ndarray, Truth3D, dict]:
    """The 3-D scene of a planar simulation: returns (projected image positions (N, F, 2) px, :class:`Truth3D`,
    {edge: projected segment length at frame 0 in px}).

    ``config``: the :class:`~rce_gtsam.sim.simulate.SimulationConfig` (its ``scene3d``, effects, seed, fps,
    z_rms_deg, out_of_plane strength); ``lengths_px``: the planar segment lengths (px; for the tube radius, which
    follows the renderer's stem width).
    """
    stem_width_px = stem_widths_px(graph, lengths_px)
    scene = config.scene3d or Scene3D()
    share = config.strength("out_of_plane") if "out_of_plane" in config.effects else 0.0
    z_o, z2 = out_of_plane_excitation(z, share, scene.rho, config.fps, config.seed, config.z_rms_deg)
    psi = np.outer(kappa, z_o)
    tilt = scene.tilt(config.effects)
    rng = np.random.default_rng(np.random.SeedSequence([int(config.seed), 0xDE97]))
    Z0 = float(rng.uniform(*scene.root_depth_mm))
    P, xy, mm_per_px, normal = lift(graph, planar_xy, root_px, psi, tilt, Z0, scene.camera)
    image_turn = _image_turn(xy, graph)
    dev = (image_turn - image_turn[:, :1] + 180.0) % 360.0 - 180.0
    row = {n: i for i, n in enumerate(graph.nodes)}
    seg_mm = {(p, c): float(np.linalg.norm(P[row[c], 0] - P[row[p], 0])) for p, c in graph.edges}
    truth = Truth3D(camera=scene.camera, positions_mm=P, tilt_deg=tilt, share=share, rho=scene.rho,
                    root_depth_mm=Z0, mm_per_px=mm_per_px, plane_normal=normal, z_o=z_o, z_prime=z2,
                    theta_deg=_image_turn(planar_xy, graph), psi_deg=psi,
                    turn3d_deg=turning_3d_deg(P, graph.nodes, graph.bends), image_turn_deg=image_turn,
                    kappa_3d=np.asarray(kappa, float), kappa_image=rank1_kappa(dev), segment_mm=seg_mm,
                    stem_radius_mm={e: 0.5 * w * mm_per_px for e, w in stem_width_px.items()})
    seg_px = {(p, c): float(np.linalg.norm(xy[row[c], 0] - xy[row[p], 0])) for p, c in graph.edges}
    return xy, truth, seg_px


def _image_turn(xy: np.ndarray, graph) -> np.ndarray:
    return turning_angles_deg(xy, graph.nodes, graph.bends)


def stem_widths_px(graph, lengths: dict) -> dict:
    """{edge: stem width in px} as the renderer draws it: 10 px at the root tapering to 5 px at the tip."""
    dist = {graph.root: 0.0}
    for c in graph.nodes[1:]:
        dist[c] = dist[graph.parent[c]] + lengths[(graph.parent[c], c)]
    dmax = max(dist.values())
    return {(p, c): 10.0 - 5.0 * dist[p] / dmax for p, c in graph.edges}
