"""A test bed with real texture and known motion: plant 2's first frame, overlays removed, warped by a known
articulated motion of its branch.

The only real footage (``../shared/data/plant_2/annotated_nodes.mp4``, see its README) has TAPIR's overlays drawn
into every frame. :func:`clean_first_frame` removes them from frame 0 by inpainting (``cv2.inpaint``, Telea) at
their KNOWN positions: a dot of radius ``DOT_RADIUS_PX`` at each node's integer-truncated TAPIR position of frame 0,
the root's ring, 1-px lines between graph neighbours, each node's number beside its dot (only the saturated pixels
of a box beside the dot, so the plant's own texture there is kept) and the frame counter at the top left.

:func:`make_bed` then moves that image: the motion is the project's simulator (:func:`rce_gtsam.sim.simulate`:
kappa, z, the bend response, with or without effects) mapped onto plant 2's 24-edge chain with its real segment
lengths (sim node k = the k-th node from the root), scaled so that the tip's largest excursion is
``tip_excursion_px`` (the real plant's ~60 px). A uniform scale of every bend keeps kappa (relative, geometric
mean 1) unchanged. Rendering (:func:`render_frames`), per frame:

* the stem (pixels within ``inner_px`` of a segment, as it lies in this frame) follows its segments' rigid motions,
  blended at the joints (Gaussian weights of the distance to each segment, ``blend_px``), and is laid over a
  still background: frame 0 with the stem's band (``outer_px`` around the frame-0 chain) inpainted, so the moving
  stem uncovers background, not a copy of itself. Between ``inner_px`` and ``outer_px`` the stem's layer fades
  into the background (an anti-aliased edge; plant 2's stem is 6.5 px in half-width, ``inner_px`` is 8);
* motion blur follows the pixel speed: the frame is the mean of ``n_sub`` sub-frame warps over an exposure of
  ``exposure`` frames centred on the frame's time (more sub-frames where the motion is fast, one where the branch
  is still);
* sensor noise (``noise_grey`` grey levels RMS), a flicker (global gain, ``flicker`` RMS), then H.264
  (``crf``) when written by :func:`write_bed_video`.

Coordinates: original pixels, pixel centres at integers (OpenCV). The root is fixed.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np

from ..graph import BranchGraph, load_graph

#: Radius (px) masked around each drawn dot (the published dots are ~5 px in radius; one more for anti-aliasing).
DOT_RADIUS_PX = 8
#: The root's green ring (px, outer radius masked).
RING_RADIUS_PX = 11
#: The frame counter's box (x0, y0, x1, y1), px.
COUNTER_BOX = (4, 2, 112, 34)
#: Box beside each dot that may hold its number (dx0, dy0, dx1, dy1) px from the dot.
LABEL_BOX = (-4, -20, 26, 14)


@dataclass(frozen=True)
class CleanFrame:
    """Frame 0 without overlays: ``rgb`` (H, W, 3) uint8, ``points`` (P, 2) px (node id = row), ``graph``,
    ``mask`` (H, W) bool: the inpainted pixels."""

    rgb: np.ndarray
    points: np.ndarray
    graph: BranchGraph
    mask: np.ndarray


def overlay_mask(rgb: np.ndarray, points: np.ndarray, graph: BranchGraph) -> np.ndarray:
    """(H, W) bool: where the published code drew over frame 0 (see the module docstring)."""
    h, w = rgb.shape[:2]
    m = np.zeros((h, w), np.uint8)
    ip = np.floor(points).astype(int)  # the dots were drawn at integer-truncated positions
    for p, c in graph.edges:
        cv2.line(m, tuple(map(int, ip[p])), tuple(map(int, ip[c])), 255, 3)
    hsv = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV)
    sat = (hsv[..., 1] > 90) & (hsv[..., 2] > 60)
    for x, y in ip:
        cv2.circle(m, (int(x), int(y)), DOT_RADIUS_PX, 255, -1)
        x0, y0, x1, y1 = (max(0, x + LABEL_BOX[0]), max(0, y + LABEL_BOX[1]), min(w, x + LABEL_BOX[2]),
                          min(h, y + LABEL_BOX[3]))
        box = np.zeros_like(m)
        box[y0:y1, x0:x1] = 255
        m |= np.where(sat & (box > 0), 255, 0).astype(np.uint8)
    cv2.circle(m, tuple(map(int, ip[graph.root])), RING_RADIUS_PX, 255, -1)
    x0, y0, x1, y1 = COUNTER_BOX
    m[y0:y1, x0:x1] = 255
    return cv2.dilate(m, np.ones((3, 3), np.uint8)) > 0


def clean_first_frame(plant_dir: str | Path) -> CleanFrame:
    """Frame 0 of ``plant_dir/annotated_nodes.mp4`` with the overlays inpainted (see the module docstring)."""
    import pandas as pd

    from ..track import open_video

    plant_dir = Path(plant_dir)
    with open_video(plant_dir / "annotated_nodes.mp4") as src:
        rgb = next(iter(src)).image.copy()
    graph = load_graph(plant_dir / "branch_graph.json")
    df = pd.read_csv(plant_dir / "tapir_tracks.csv")
    f0 = df[df.frame == 0].sort_values("point_id")
    points = np.zeros((int(f0.point_id.max()) + 1, 2))
    points[f0.point_id.to_numpy()] = f0[["x", "y"]].to_numpy()
    mask = overlay_mask(rgb, points, graph)
    clean = cv2.inpaint(rgb, mask.astype(np.uint8), 3, cv2.INPAINT_TELEA)
    # the annotation points are the query points (they equal TAPIR's frame-0 positions)
    q = np.array(json.loads((plant_dir / "annotation_points.json").read_text())["points"], float)[:len(points)]
    return CleanFrame(rgb=clean, points=q, graph=graph, mask=mask)


@dataclass(frozen=True)
class Bed:
    """Known articulated motion of the plant-2 chain.

    true_xy: (P, F, 2) px, node id = row. heading: (E, F) rad, the direction of each edge (``edges`` order) in
    every frame. kappa_true: {(joint, child): kappa} (plant node ids). response_deg: (E-1, F) true bend deviations
    (plant bends, ``graph.bends`` order). scale: the factor applied to the simulator's bends. edges: the chain's
    edges root first. seed, effects: of the simulation.
    """

    true_xy: np.ndarray
    heading: np.ndarray
    kappa_true: dict
    response_deg: np.ndarray
    scale: float
    edges: list
    graph: BranchGraph
    seed: int
    effects: tuple


def chain_edges(graph: BranchGraph) -> list[tuple[int, int]]:
    """The edges of a chain graph from the root to the tip (ValueError if it branches)."""
    out, n = [], graph.root
    while graph.children.get(n):
        ch = graph.children[n]
        if len(ch) != 1:
            raise ValueError(f"node {n} has {len(ch)} children: the texture bed needs a chain")
        out.append((n, ch[0]))
        n = ch[0]
    return out


def make_bed(points: np.ndarray, graph: BranchGraph, n_frames: int, seed: int, effects: tuple = (),
             tip_excursion_px: float = 60.0) -> Bed:
    """The simulator's motion (seeded) on plant 2's chain, scaled to ``tip_excursion_px`` (largest tip
    displacement from frame 0, px). See the module docstring."""
    from .simulate import NoiseConfig, SimulationConfig, simulate

    edges = chain_edges(graph)
    sim = simulate(SimulationConfig(n_nodes=len(edges) + 1, n_frames=n_frames, seed=seed, effects=tuple(effects),
                                    noise=NoiseConfig(enabled=False)))
    chain = [edges[0][0]] + [c for _, c in edges]  # plant node ids, root first = sim nodes 0, 1, ...
    # sim bend k: joint k (k = 1..E-1) turns edge (k, k+1): deviation y[k-1] in degrees
    y = np.asarray(sim.response_true)
    sim_bends = [b.edge for b in sim.graph.bends]
    assert sim_bends == [(k, k + 1) for k in range(1, len(edges))]
    vec = np.array([points[c] - points[p] for p, c in edges])
    length = np.hypot(*vec.T)
    h0 = np.arctan2(vec[:, 1], vec[:, 0])

    def heads(s):
        dev = np.vstack([np.zeros((1, n_frames)), np.cumsum(np.radians(s * y), axis=0)])  # (E, F)
        return h0[:, None] + dev

    def positions(hd):
        xy = np.zeros((len(chain), n_frames, 2))
        xy[0] = points[chain[0]]
        steps = length[:, None, None] * np.stack([np.cos(hd), np.sin(hd)], -1)
        xy[1:] = points[chain[0]] + np.cumsum(steps, axis=0)
        return xy

    tip0 = positions(heads(1.0))[-1]
    exc = float(np.max(np.hypot(*(tip0 - tip0[0]).T)))
    scale = tip_excursion_px / exc if exc > 0 else 1.0
    for _ in range(3):  # the excursion is nearly linear in the scale for small angles: refine it
        tip = positions(heads(scale))[-1]
        exc = float(np.max(np.hypot(*(tip - tip[0]).T)))
        scale *= tip_excursion_px / exc
    hd = heads(scale)
    xy_chain = positions(hd)
    true_xy = np.zeros((len(points), n_frames, 2))
    true_xy[chain] = xy_chain
    kappa = {(chain[j], chain[j + 1]): float(sim.kappa_true[(j, j + 1)]) for j in range(1, len(edges))}
    resp = np.array([scale * y[[b.edge for b in sim.graph.bends].index((chain.index(b.joint), chain.index(b.child)))]
                     for b in graph.bends])
    return Bed(true_xy=true_xy, heading=hd, kappa_true=kappa, response_deg=resp, scale=scale, edges=edges,
               graph=graph, seed=seed, effects=tuple(effects))


@dataclass(frozen=True)
class RenderSettings:
    """How :func:`render_frames` turns the motion into images (px, frames, grey levels)."""

    inner_px: float = 8.0
    outer_px: float = 10.0
    blend_px: float = 4.0
    exposure: float = 0.5
    max_sub: int = 6
    noise_grey: float = 2.0
    flicker: float = 0.015
    crf: int = 23

    def perfect(self) -> "RenderSettings":
        """The same bed with nothing between the motion and the pixels: no sensor noise, no flicker, no motion blur
        (one warp at the frame's time) and lossless H.264 (crf 0). What a tracker still gets wrong there is its
        own, deterministic error."""
        return replace(self, noise_grey=0.0, flicker=0.0, exposure=0.0, max_sub=1, crf=0)

    @property
    def is_perfect(self) -> bool:
        return self == self.perfect()


def _seg_dist(px, py, a, b):
    """Distance (px) of points (px, py) to the segment a-b, and the fraction along it (clipped to [0, 1])."""
    d = b - a
    L2 = max(float(d @ d), 1e-12)
    t = np.clip(((px - a[0]) * d[0] + (py - a[1]) * d[1]) / L2, 0.0, 1.0)
    return np.hypot(px - a[0] - t * d[0], py - a[1] - t * d[1])


def _warp_map(bed: Bed, q: np.ndarray, hd: np.ndarray, box, st: RenderSettings):
    """Source coordinates (map_x, map_y) of the pixels of ``box`` for a pose given by edge headings ``hd`` (E,), and
    the stem layer's opacity there (1 within ``inner_px`` of the posed chain, 0 beyond ``outer_px``)."""
    x0, y0, x1, y1 = box
    gx, gy = np.meshgrid(np.arange(x0, x1, dtype=np.float64), np.arange(y0, y1, dtype=np.float64))
    edges = bed.edges
    vec0 = np.array([q[c] - q[p] for p, c in edges])
    length = np.hypot(*vec0.T)
    h0 = np.arctan2(vec0[:, 1], vec0[:, 0])
    # current joint positions
    pos = [q[edges[0][0]]]
    for k in range(len(edges)):
        pos.append(pos[-1] + length[k] * np.array([math.cos(hd[k]), math.sin(hd[k])]))
    wsum = np.zeros_like(gx)
    sx, sy = np.zeros_like(gx), np.zeros_like(gy)
    dmin = np.full_like(gx, np.inf)
    for k, (p, c) in enumerate(edges):
        a, b = pos[k], pos[k + 1]
        dist = _seg_dist(gx, gy, a, b)
        dmin = np.minimum(dmin, dist)
        w = np.exp(-0.5 * (dist / st.blend_px) ** 2)
        # inverse rigid motion of edge k: current -> frame 0 (rotate about the current parent back by -dtheta)
        th = hd[k] - h0[k]
        ct, sn = math.cos(-th), math.sin(-th)
        rx, ry = gx - a[0], gy - a[1]
        ux = q[p][0] + ct * rx - sn * ry
        uy = q[p][1] + sn * rx + ct * ry
        wsum += w
        sx += w * ux
        sy += w * uy
    wsum = np.maximum(wsum, 1e-300)
    mx, my = sx / wsum, sy / wsum
    alpha = np.clip((st.outer_px - dmin) / (st.outer_px - st.inner_px), 0.0, 1.0)
    alpha = alpha * alpha * (3 - 2 * alpha)  # smoothstep: no kink at the band's edges
    return mx.astype(np.float32), my.astype(np.float32), alpha.astype(np.float32)


def still_background(bed: Bed, image: np.ndarray, q: np.ndarray, settings: RenderSettings = None) -> np.ndarray:
    """Frame 0 (H, W, 3) with the stem's band (pixels within ``outer_px`` + 0.5 of the frame-0 chain) inpainted
    (``cv2.inpaint``, Telea): what the moving stem uncovers."""
    st = settings or RenderSettings()
    h, w = image.shape[:2]
    gx, gy = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    dmin = np.full(gx.shape, np.inf)
    for p, c in bed.edges:
        dmin = np.minimum(dmin, _seg_dist(gx, gy, np.asarray(q[p], float), np.asarray(q[c], float)))
    mask = (dmin <= st.outer_px + 0.5).astype(np.uint8)
    return cv2.inpaint(np.ascontiguousarray(image), mask, 3, cv2.INPAINT_TELEA)


def render_frames(bed: Bed, image: np.ndarray, q: np.ndarray, settings: RenderSettings = RenderSettings(),
                  only=None):
    """Yield the bed's frames (H, W, 3) uint8 RGB (before compression); seeded by ``bed.seed``. ``only``: a set of
    frame indices to render (the others yield None; every frame's noise is still drawn, so those rendered are the
    same as in a full run)."""
    st = settings
    rng = np.random.default_rng([bed.seed, 7])
    h, w = image.shape[:2]
    allxy = bed.true_xy[[p for p, _ in bed.edges] + [bed.edges[-1][1]]]
    pad = st.outer_px + 4
    x0, y0 = (max(0, int(np.floor(allxy[..., i].min() - pad))) for i in (0, 1))
    x1, y1 = min(w, int(np.ceil(allxy[..., 0].max() + pad))), min(h, int(np.ceil(allxy[..., 1].max() + pad)))
    box = (x0, y0, x1, y1)
    img = image.astype(np.float32)
    bg = still_background(bed, image, q, st).astype(np.float32)[y0:y1, x0:x1]
    F = bed.heading.shape[1]
    gain = 1 + st.flicker * rng.standard_normal(F)
    speed = np.zeros(F)
    speed[1:] = np.hypot(*np.diff(bed.true_xy, axis=1).transpose(2, 0, 1)).max(axis=0)
    speed[:-1] = np.maximum(speed[:-1], speed[1:])
    for f in range(F):
        if only is not None and f not in only:
            rng.standard_normal((h, w, 3), dtype=np.float32)  # keep the noise stream of a full run
            yield None
            continue
        n_sub = int(np.clip(np.ceil(speed[f] * st.exposure / 0.5), 1, st.max_sub))
        acc = np.zeros((y1 - y0, x1 - x0, 3), np.float32)
        for s in range(n_sub):
            # sub-frame times over an exposure centred on frame f (linear interpolation of the headings), so
            # that the true position of frame f is the middle of its blur
            t = float(np.clip(f + st.exposure * ((s + 0.5) / n_sub - 0.5), 0.0, F - 1.0))
            f0 = min(int(np.floor(t)), F - 1)
            fr = t - f0
            hd = bed.heading[:, f0] * (1 - fr) + bed.heading[:, min(f0 + 1, F - 1)] * fr
            mx, my, alpha = _warp_map(bed, q, hd, box, st)
            stem = cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
            acc += alpha[..., None] * stem + (1 - alpha[..., None]) * bg
        out = img.copy()
        out[y0:y1, x0:x1] = acc / n_sub
        out = out * gain[f] + st.noise_grey * rng.standard_normal(out.shape, dtype=np.float32)
        yield np.clip(out + 0.5, 0, 255).astype(np.uint8)


def write_bed_video(bed: Bed, image: np.ndarray, q: np.ndarray, path: str | Path,
                    settings: RenderSettings = RenderSettings(), fps: float = 30.0) -> Path:
    """Render the bed and write it as H.264 (libx264, yuv420p, ``settings.crf``) to ``path`` (atomic)."""
    from .render import write_h264
    h, w = image.shape[:2]
    return write_h264(render_frames(bed, image, q, settings), path, fps=fps, size=(w, h), crf=settings.crf,
                      preset="veryfast", pixel_format="rgb24")


def angle_floor_deg(err_px: float, length_px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The bend-angle noise (degrees RMS) a tracker error of ``err_px`` (px RMS per axis, independent per node)
    gives at a joint with segments of ``length_px``: from sqrt(2) e/L (one segment's direction, both ends noisy)
    to sqrt(6) e/L (a bend: the joint's error enters both segments). Returns (low, high) per length."""
    L = np.asarray(length_px, float)
    return np.degrees(math.sqrt(2) * err_px / L), np.degrees(math.sqrt(6) * err_px / L)
