"""Render a :class:`~rce_gtsam.sim.simulate.Simulation` as a video a point tracker can follow.

Scene (all seeded by the simulation's seed, so a rendering is reproducible):

* a static, non-uniform background: blurred multi-scale colour noise and out-of-focus foliage blobs;
* the stem: one textured sprite per segment (bark colour, cylinder shading, fine isotropic blotches and
  along-stem streaks so Lucas-Kanade has gradients in both directions, and a subtle darker knot at each
  node), tapering from 10 px at the root to 5 px at the tip, with round caps so joints stay closed;
* leaves: a few leaf sprites attached to distal segments; each moves with its segment and flutters about its
  petiole (angle +-10-25 degrees at 0.4-1.2 Hz), so some of them sweep over nodes now and then;
* mild sensor noise (1 grey level RMS) per frame, then H.264 encoding;
* optional camera nuisances (a :class:`~rce_gtsam.sim.nuisance.RenderConfig`: motion blur, illumination drift,
  a moving soft shadow, camera shake, stronger compression); the default config is the clean render above.

Geometry uses the TRUE positions (``sim.true_xy``) and the OpenCV pixel convention: pixel (row i, column j)
has its centre at (x=j, y=i). Each sprite is placed by an exact affine warp (bilinear interpolation), so
node positions are reproduced with sub-pixel accuracy.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Iterator

import cv2
import numpy as np

from ..errors import MissingDependencyError
from .nuisance import RenderConfig, ShadowField, camera_shift, illumination

BARK_BGR = np.array([45.0, 75.0, 115.0])   # brown
LEAF_BGR = np.array([40.0, 140.0, 70.0])   # green


@dataclass(frozen=True)
class _Sprite:
    """A textured patch in the local frame of segment (parent, child).

    ``bgra``: (H, W, 4) float32, colour premultiplied by alpha in channels 0-2, alpha in channel 3.
    Sprite pixel (col, row) sits at local coordinates (u, v) = (col - u0, row - v0) in the sprite's own frame;
    that frame is rotated by ``angle`` (radians, possibly time-varying) about the point at fraction ``at``
    along the segment.
    """

    edge: tuple[int, int]
    bgra: np.ndarray
    u0: float
    v0: float
    at: float = 0.0
    angle0: float = 0.0
    flutter_amp: float = 0.0
    flutter_hz: float = 0.0
    flutter_phase: float = 0.0
    length: float = 0.0   # stem sprites: the drawn length (px); a segment that projects longer or shorter
    #                       (out-of-plane swing, sim/three_d.py) stretches the sprite along it. 0 = never stretch


def _smooth_noise(rng, shape, sigma) -> np.ndarray:
    n = rng.standard_normal(shape).astype(np.float32)
    if isinstance(sigma, tuple):
        n = cv2.GaussianBlur(n, (0, 0), sigmaX=sigma[0], sigmaY=sigma[1])
    else:
        n = cv2.GaussianBlur(n, (0, 0), sigma)
    return n / max(float(n.std()), 1e-6)


def make_background(width: int, height: int, rng: np.random.Generator) -> np.ndarray:
    """A static BGR float32 background: multi-scale coloured noise plus blurred foliage blobs."""
    base = np.empty((height, width, 3), np.float32)
    # foliage-like greens and greys, out of focus (a real background is usually behind the focal plane)
    c1, c2 = np.array([60, 90, 70], np.float32), np.array([125, 145, 135], np.float32)
    mix = 0.5 + 0.25 * _smooth_noise(rng, (height, width), 60)
    base[:] = c1 + (c2 - c1) * np.clip(mix, 0, 1)[..., None]
    for sigma, amp in ((14, 16.0), (5, 7.0), (2, 2.5)):
        lum = _smooth_noise(rng, (height, width), sigma)[..., None]
        tint = _smooth_noise(rng, (height, width), sigma)[..., None] * np.array([0.3, -0.3, 0.3], np.float32)
        base += amp * (lum + 0.4 * tint)
    blobs = np.zeros((height, width, 3), np.float32)
    for _ in range(25):
        centre = (int(rng.uniform(0, width)), int(rng.uniform(0, height)))
        axes = (int(rng.uniform(15, 60)), int(rng.uniform(8, 30)))
        k = float(rng.uniform(-30, 25))
        colour = (0.6 * k, k, 0.5 * k)
        cv2.ellipse(blobs, centre, axes, float(rng.uniform(0, 180)), 0, 360, colour, -1, cv2.LINE_AA)
    base += cv2.GaussianBlur(blobs, (0, 0), 6)
    return np.clip(base, 0, 255)


def _stem_sprite(rng, length: float, width: float, knot: bool) -> tuple[np.ndarray, float, float]:
    """Bark sprite of a capsule of the given length and width (pixels); returns (bgra, u0, v0)."""
    cap = width / 2 + 1.5
    W = int(math.ceil(length + 2 * cap)) + 2
    H = int(math.ceil(width + 3)) + 2
    u0, v0 = cap + 1.0, (H - 1) / 2
    uu, vv = np.meshgrid(np.arange(W, dtype=np.float32) - u0, np.arange(H, dtype=np.float32) - v0)
    # capsule distance from the axis segment [0, length] x {0}
    du = np.clip(uu, 0, length) - uu
    dist = np.hypot(du, vv)
    alpha = np.clip(width / 2 - dist + 0.5, 0, 1)
    shade = 0.75 + 0.35 * np.sqrt(np.clip(1 - (vv / (width / 2 + 1e-6)) ** 2, 0, 1))
    tex = (1.0 + 0.22 * _smooth_noise(rng, (H, W), 0.9) + 0.12 * _smooth_noise(rng, (H, W), (3.0, 0.6))
           + 0.08 * np.sin(2 * np.pi * uu / rng.uniform(5, 9) + rng.uniform(0, 6.3)))
    if knot:  # subtle darker band at the node (u = 0)
        tex *= 1 - 0.18 * np.exp(-0.5 * (uu / 1.5) ** 2)
    lum = (shade * tex)[..., None]
    bgr = np.clip(BARK_BGR * rng.uniform(0.85, 1.15) * lum, 0, 255)
    bgra = np.dstack([bgr * alpha[..., None], alpha]).astype(np.float32)
    return bgra, float(u0), float(v0)


def _leaf_sprite(rng, length: float, width: float) -> tuple[np.ndarray, float, float]:
    """Leaf sprite: pointed blade along +u from the petiole at u = 0, with a midrib and side veins."""
    W = int(math.ceil(length)) + 4
    H = int(math.ceil(width)) + 4
    u0, v0 = 2.0, (H - 1) / 2
    uu, vv = np.meshgrid(np.arange(W, dtype=np.float32) - u0, np.arange(H, dtype=np.float32) - v0)
    x = np.clip(uu / length, 0, 1)
    half = 0.5 * width * np.clip(np.sin(np.pi * x), 0, None) ** 0.8
    alpha = np.clip(half - np.abs(vv) + 0.5, 0, 1) * ((uu >= 0) & (uu <= length))
    vein = 0.25 * np.exp(-0.5 * (vv / 0.6) ** 2)
    side = 0.1 * (np.cos(2 * np.pi * (uu - 0.8 * np.abs(vv)) / 4.0) > 0.6)
    lum = (0.8 + vein + side + 0.08 * _smooth_noise(rng, (H, W), 1.0))[..., None]
    bgr = np.clip(LEAF_BGR * rng.uniform(0.8, 1.2, 3) * lum, 0, 255)
    bgra = np.dstack([bgr * alpha[..., None], alpha]).astype(np.float32)
    return bgra, float(u0), float(v0)


def build_scene(sim, n_leaves: int | None = None) -> tuple[np.ndarray, list[_Sprite]]:
    """The static background (H, W, 3) float32 and the sprites (stem segments first, then leaves)."""
    width, height = sim.config.image_size
    rng = np.random.default_rng(np.random.SeedSequence([sim.config.seed, 0x5EED]))
    background = make_background(width, height, rng)
    g = sim.graph
    dist = {g.root: 0.0}
    for c in g.nodes[1:]:
        dist[c] = dist[g.parent[c]] + sim.segment_px[(g.parent[c], c)]
    dmax = max(dist.values())
    sprites: list[_Sprite] = []
    for p, c in sorted(g.edges, key=lambda e: dist[e[0]]):
        s = dist[p] / dmax
        w = 10.0 - 5.0 * s
        if getattr(sim, "three_d", None) is not None:   # a 3-D scene: the stem's width follows its depth
            w *= sim.three_d.width_factor((p, c), g)
        bgra, u0, v0 = _stem_sprite(rng, sim.segment_px[(p, c)], w, knot=True)
        sprites.append(_Sprite((p, c), bgra, u0, v0, length=float(sim.segment_px[(p, c)])))
    distal = [e for e in g.edges if dist[e[1]] / dmax > 0.45]
    if n_leaves is None:
        n_leaves = max(2, len(g.nodes) // 4)
    for k in range(min(n_leaves, len(distal))):
        e = distal[int(rng.integers(len(distal)))]
        bgra, u0, v0 = _leaf_sprite(rng, rng.uniform(18, 32), rng.uniform(8, 13))
        side = rng.choice([-1.0, 1.0])
        sprites.append(_Sprite(e, bgra, u0, v0, at=float(rng.uniform(0.2, 0.8)),
                               angle0=float(side * np.radians(rng.uniform(25, 60))),
                               flutter_amp=float(np.radians(rng.uniform(10, 25))),
                               flutter_hz=float(rng.uniform(0.4, 1.2)),
                               flutter_phase=float(rng.uniform(0, 2 * np.pi))))
    return background, sprites


def _blit(canvas: np.ndarray, sp: _Sprite, P: np.ndarray, C: np.ndarray, t_s: float) -> None:
    """Composite one sprite onto ``canvas`` (float32 BGR) for segment endpoints P -> C (pixels)."""
    d = C - P
    L = float(np.hypot(*d))
    if L < 1e-9:
        return
    d = d / L
    ang = sp.angle0 + sp.flutter_amp * math.sin(2 * math.pi * sp.flutter_hz * t_s + sp.flutter_phase)
    ca, sa = math.cos(ang), math.sin(ang)
    ex = np.array([d[0] * ca - d[1] * sa, d[1] * ca + d[0] * sa])   # sprite u axis in the image
    ey = np.array([-ex[1], ex[0]])                                   # sprite v axis
    origin = P + sp.at * L * d
    H, W = sp.bgra.shape[:2]
    if sp.length > 0 and abs(L - sp.length) > 1e-9 * sp.length:
        ex = ex * (L / sp.length)   # the segment's image length changed: the bark stretches with it
    t = origin - sp.u0 * ex - sp.v0 * ey
    M = np.array([[ex[0], ey[0], t[0]], [ex[1], ey[1], t[1]]])
    corners = np.array([[0, 0, 1], [W - 1, 0, 1], [0, H - 1, 1], [W - 1, H - 1, 1]], float) @ M.T
    x0, y0 = np.floor(corners.min(0)).astype(int) - 1
    x1, y1 = np.ceil(corners.max(0)).astype(int) + 2
    ih, iw = canvas.shape[:2]
    x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, iw), min(y1, ih)
    if x1 <= x0 or y1 <= y0:
        return
    M2 = M.copy()
    M2[:, 2] -= (x0, y0)
    warped = cv2.warpAffine(sp.bgra, M2, (x1 - x0, y1 - y0), flags=cv2.INTER_LINEAR,
                            borderMode=cv2.BORDER_CONSTANT, borderValue=(0, 0, 0, 0))
    roi = canvas[y0:y1, x0:x1]
    roi *= 1 - warped[..., 3:4]
    roi += warped[..., :3]


def _subframe_positions(xy: np.ndarray, f: int, offsets: np.ndarray) -> np.ndarray:
    """(K, N, 2) node positions at ``f + offsets`` (frames), linear between neighbouring frames (pixels).

    Beyond the clip's ends the nearest frame-to-frame velocity is extended.
    """
    F = xy.shape[1]
    fwd = xy[:, f + 1] - xy[:, f] if f + 1 < F else (xy[:, f] - xy[:, f - 1] if F > 1 else 0 * xy[:, f])
    bwd = xy[:, f] - xy[:, f - 1] if f > 0 else fwd
    o = offsets[:, None, None]
    return xy[None, :, f] + np.where(o >= 0, o * fwd[None], o * bwd[None])


def _composite(background: np.ndarray, sprites: list[_Sprite], row: dict[int, int], xy: np.ndarray,
               t_s: float) -> np.ndarray:
    """Background plus every sprite for node positions ``xy`` (N, 2) pixels at time ``t_s`` seconds."""
    canvas = background.copy()
    for sp in sprites:
        p, c = sp.edge
        _blit(canvas, sp, xy[row[p]], xy[row[c]], t_s)
    return canvas


def iter_frames(sim, *, n_frames: int | None = None, sensor_noise: float | None = None,
                config: RenderConfig | None = None) -> Iterator[np.ndarray]:
    """Yield the rendered frames as (H, W, 3) uint8 BGR arrays (OpenCV order), one at a time.

    ``config``: camera nuisances (:class:`~rce_gtsam.sim.nuisance.RenderConfig`; default = the clean render).
    ``sensor_noise`` (grey levels RMS) overrides ``config.sensor_noise`` when given. With camera shake the
    nodes appear at :func:`~rce_gtsam.sim.nuisance.image_xy`, not at ``sim.true_xy``.
    """
    cfg = config or RenderConfig()
    noise_rms = cfg.sensor_noise if sensor_noise is None else float(sensor_noise)
    background, sprites = build_scene(sim)
    row = {int(n): i for i, n in enumerate(sim.tracks.node_ids)}
    F = sim.true_xy.shape[1] if n_frames is None else min(n_frames, sim.true_xy.shape[1])
    rng = np.random.default_rng(np.random.SeedSequence([sim.config.seed, 0xF4A3E]))
    fps = sim.config.fps
    shift = camera_shift(sim, cfg)
    gain, offset = illumination(sim, cfg)
    shadow = ShadowField(sim, cfg) if cfg.shadow_depth > 0 else None
    speed = np.zeros(sim.true_xy.shape[1])
    if sim.true_xy.shape[1] > 1:  # fastest node displacement around each frame (pixels per frame)
        v = np.hypot(*np.diff(sim.true_xy, axis=1).transpose(2, 0, 1)).max(axis=0)
        speed = np.maximum(np.r_[v[:1], v], np.r_[v, v[-1:]])
    for f in range(F):
        bg = background
        if shift[f].any():
            m = np.array([[1.0, 0.0, shift[f, 0]], [0.0, 1.0, shift[f, 1]]])
            bg = cv2.warpAffine(background, m, background.shape[1::-1], flags=cv2.INTER_LANCZOS4,
                                borderMode=cv2.BORDER_REFLECT)
        if cfg.exposure > 0:
            # leaves flutter up to ~4 px/frame at their tips on top of the node motion
            k = int(np.clip(math.ceil(cfg.exposure * (speed[f] + 4.0) / cfg.blur_step_px), 2, cfg.max_subframes))
            offs = cfg.exposure * ((np.arange(k) + 0.5) / k - 0.5)
            subs = _subframe_positions(sim.true_xy, f, offs) + shift[f]
            canvas = _composite(bg, sprites, row, subs[0], (f + offs[0]) / fps)
            for j in range(1, k):
                canvas += _composite(bg, sprites, row, subs[j], (f + offs[j]) / fps)
            canvas *= np.float32(1.0 / k)
        else:
            xy = sim.true_xy[:, f] + shift[f] if shift[f].any() else sim.true_xy[:, f]
            canvas = _composite(bg, sprites, row, xy, f / fps)
        if cfg.lighting:
            light = np.float32(gain[f]) * (shadow(f) if shadow is not None else np.float32(1.0))
            canvas *= np.asarray(light, np.float32)[..., None] if np.ndim(light) else light
            canvas += np.float32(offset[f])
        if noise_rms > 0:
            canvas += noise_rms * rng.standard_normal(canvas.shape, dtype=np.float32)
        yield np.clip(canvas + 0.5, 0, 255).astype(np.uint8)


def render_video(sim, path: str | Path, *, crf: int | None = None, preset: str = "veryfast",
                 n_frames: int | None = None, config: RenderConfig | None = None) -> Path:
    """Write ``sim`` as an H.264 (libx264, yuv420p) mp4 at the simulation's fps; frames are streamed.

    ``config``: camera nuisances (:class:`~rce_gtsam.sim.nuisance.RenderConfig`; default = the clean render).
    ``crf``: x264 constant rate factor (lower = better quality; 16 keeps the bark texture crisp); overrides
    ``config.crf`` when given.
    The file is written next to ``path`` under a temporary name and renamed when complete.
    """
    cfg = config or RenderConfig()
    return write_h264(iter_frames(sim, n_frames=n_frames, config=cfg), path, fps=sim.config.fps,
                      size=sim.config.image_size, crf=cfg.crf if crf is None else crf, preset=preset,
                      pixel_format="bgr24")


def write_h264(frames, path: str | Path, *, fps: float, size: tuple[int, int], crf: int, preset: str = "veryfast",
               pixel_format: str = "bgr24") -> Path:
    """Stream ``frames`` (uint8 images of ``size`` = (width, height) px, channels in ``pixel_format`` order) into
    an H.264 (libx264, yuv420p) mp4 at ``fps`` frames/s with x264's ``crf`` and ``preset``. The file is written
    next to ``path`` under a temporary name and renamed when complete (nothing half-written is left)."""
    try:
        import av
    except ImportError as exc:  # pragma: no cover - av is a dependency
        raise MissingDependencyError("rendering a video needs PyAV: pip install av") from exc
    from ..fileio import temp_file_beside
    path = Path(path)
    width, height = size
    tmp = temp_file_beside(path, suffix=".mp4")
    try:
        with av.open(str(tmp), mode="w", format="mp4") as container:
            stream = container.add_stream("libx264", rate=Fraction(fps).limit_denominator(1001))
            stream.width, stream.height, stream.pix_fmt = width, height, "yuv420p"
            stream.options = {"crf": str(crf), "preset": preset}
            for img in frames:
                for packet in stream.encode(av.VideoFrame.from_ndarray(img, format=pixel_format)):
                    container.mux(packet)
            for packet in stream.encode():
                container.mux(packet)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path
