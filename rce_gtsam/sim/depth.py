"""Depth images of a simulated branch, aligned to the colour camera, with a D435i-like error model.

Scene: the stem is a tube (a capsule per segment, radius = the renderer's stem half-width at the branch's
scale, ``Truth3D.stem_radius_mm``) along the true 3-D node positions (:mod:`rce_gtsam.sim.three_d`), in front of a
gently tilted, bumpy background plane at ~``Scene3D.background_mm`` (1500 mm). A pixel holds the depth (z, mm) of
the nearest surface along its ray; the tube's front surface is ``radius`` nearer than its axis. Leaves are not
drawn in depth (thin, they would be holes anyway). Depth is in the colour camera's pixels (an aligned stream).

Errors (:class:`DepthNoise`; every random draw from a seed stream of the simulation's seed):

* RMS depth error growing with distance squared, Intel's formula for its stereo cameras (Intel RealSense
  "Tuning depth cameras for best performance", and the D400 datasheet): ``RMS = Z^2 * subpixel / (f * B)``
  with baseline B = 50 mm (D435/D435i), subpixel 0.08 and f = the depth imager's focal length in pixels (674 px:
  the 87-degree horizontal field of view at 1280 px width): 2.4 mm at 1 m, 1.5 mm at 800 mm, 5.3 mm at 1.5 m.
  The noise is spatially correlated over ~1 px (stereo matching windows) and depth is rounded to 1 mm (z16).
* holes (0) on thin structures: a stem pixel is lost with a probability that rises as the stem's image width
  falls toward the matching window's size (logistic in width, half lost at ``thin_half_px``), in blobs;
* holes and flying pixels at depth edges: pixels next to a depth jump are lost (``edge_hole_prob``) or take a
  depth between the stem and the background (``flying_prob``);
* the occlusion shadow of a stereo pair: background pixels left of the stem, over the disparity difference
  ``f * B * (1/Z_stem - 1/Z_background)`` px, see the stem from one imager only and have no depth;
* speckle: small blobs of invalid pixels anywhere (``speckle_fraction`` of the image).

The hole, edge and speckle rates are illustrative (no real D435i depth of a plant is available to the project):
they make the depth reader face every failure a real D435i shows, not its measured rates.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterator

import cv2
import numpy as np
from scipy.special import ndtr


@dataclass(frozen=True)
class DepthNoise:
    """D435i-like depth errors (see the module docstring). Units: mm, px.

    subpixel: stereo subpixel accuracy (px). baseline_mm: stereo baseline. depth_focal_px: focal length of the
    depth imager (px). thin_half_px: stem image width (px) at which half of its pixels are holes;
    thin_spread_px: width of that logistic transition. edge_hole_prob, flying_prob: chance that a pixel at a depth
    edge is a hole / a flying pixel. speckle_fraction: share of the image in speckle holes. shadow: draw the
    stereo occlusion shadow. enabled: False = the exact depth (rounded to 1 mm), no holes.
    """

    subpixel: float = 0.08
    baseline_mm: float = 50.0
    depth_focal_px: float = 674.0
    thin_half_px: float = 4.0
    thin_spread_px: float = 0.8
    edge_hole_prob: float = 0.3
    flying_prob: float = 0.2
    speckle_fraction: float = 0.003
    shadow: bool = True
    enabled: bool = True

    def sigma_mm(self, z_mm):
        """RMS depth error (mm) at depth ``z_mm``: z^2 * subpixel / (f * B)."""
        return np.asarray(z_mm, float) ** 2 * self.subpixel / (self.depth_focal_px * self.baseline_mm)


def background_depth(camera, background_mm: float, rng: np.random.Generator) -> np.ndarray:
    """(H, W) float depth (mm) of the background: a plane tilted by up to ~10 degrees with smooth +-15 mm bumps."""
    H, W = camera.height, camera.width
    v, u = np.mgrid[0:H, 0:W].astype(float)
    gx, gy = rng.uniform(-0.18, 0.18, 2)   # dz per mm of lateral offset (tan of the tilt)
    x = (u - camera.cx) / camera.fx
    y = (v - camera.cy) / camera.fy
    # ray-plane intersection: z = Z0 / (1 - gx x - gy y) for the plane z = Z0 + gx X + gy Y
    z = background_mm / (1 - gx * x - gy * y)
    bumps = cv2.GaussianBlur(rng.standard_normal((H, W)).astype(np.float32), (0, 0), 25)
    bumps /= max(float(bumps.std()), 1e-9)
    return z + 15.0 * bumps


def render_depth(P: np.ndarray, edges: list[tuple[int, int]], row: dict, radius_mm: dict, camera,
                 background: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exact depth (H, W) float mm of one frame and the stem's image width (H, W) px (0 off the stem).

    ``P`` (N, 3): node positions (mm, camera frame); ``edges``: (parent, child) pairs; ``row``: node id -> row of P;
    ``radius_mm``: tube radius per edge; ``background``: (H, W) background depth (mm).
    """
    H, W = background.shape
    depth = background.copy()
    width = np.zeros((H, W))
    f = camera.fx
    for e in edges:
        A, B = P[row[e[0]]], P[row[e[1]]]
        r = radius_mm[e]
        a = np.array([f * A[0] / A[2] + camera.cx, camera.fy * A[1] / A[2] + camera.cy])
        b = np.array([f * B[0] / B[2] + camera.cx, camera.fy * B[1] / B[2] + camera.cy])
        r_px = r * f / min(A[2], B[2]) + 2
        x0, y0 = np.floor(np.minimum(a, b) - r_px).astype(int)
        x1, y1 = np.ceil(np.maximum(a, b) + r_px).astype(int) + 1
        x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, W), min(y1, H)
        if x1 <= x0 or y1 <= y0:
            continue
        yy, xx = np.mgrid[y0:y1, x0:x1].astype(float)
        d = b - a
        L2 = max(float(d @ d), 1e-12)
        t = np.clip(((xx - a[0]) * d[0] + (yy - a[1]) * d[1]) / L2, 0.0, 1.0)
        dist_px = np.hypot(xx - a[0] - t * d[0], yy - a[1] - t * d[1])
        z_axis = A[2] + t * (B[2] - A[2])
        dist_mm = dist_px * z_axis / f
        inside = dist_mm < r
        z_surf = np.where(inside, z_axis - np.sqrt(np.clip(r * r - dist_mm ** 2, 0, None)), np.inf)
        win = depth[y0:y1, x0:x1]
        nearer = z_surf < win
        win[nearer] = z_surf[nearer]
        width[y0:y1, x0:x1][nearer] = (2 * r * f / z_axis)[nearer]
    return depth, width


def _blobs(rng: np.random.Generator, shape, sigma: float) -> np.ndarray:
    """Spatially correlated uniform(0, 1) field (a Gaussian field blurred over ``sigma`` px, through its CDF)."""
    n = cv2.GaussianBlur(rng.standard_normal(shape).astype(np.float32), (0, 0), sigma)
    return ndtr(n / max(float(n.std()), 1e-9))


def add_depth_errors(depth: np.ndarray, width: np.ndarray, noise: DepthNoise, rng: np.random.Generator,
                     background_mm: float, focal_px: float) -> np.ndarray:
    """The measured depth (H, W) uint16 mm (0 = no depth) of an exact depth image (see :class:`DepthNoise`);
    ``width``: the stem's image width per pixel (px, 0 off the stem); ``focal_px``: the image's focal length."""
    if not noise.enabled:
        return np.clip(np.round(depth), 0, 65535).astype(np.uint16)
    H, W = depth.shape
    stem = width > 0
    n = cv2.GaussianBlur(rng.standard_normal((H, W)).astype(np.float32), (0, 0), 0.8)
    n /= max(float(n.std()), 1e-9)
    z = depth + noise.sigma_mm(depth) * n
    valid = np.ones((H, W), bool)
    # thin structures
    p_thin = 1.0 / (1.0 + np.exp((width - noise.thin_half_px) / noise.thin_spread_px))
    valid &= ~(stem & (_blobs(rng, (H, W), 1.0) < p_thin))
    # depth edges: a pixel with a neighbour more than 30 mm away
    lo = cv2.erode(depth.astype(np.float32), np.ones((3, 3), np.uint8))
    hi = cv2.dilate(depth.astype(np.float32), np.ones((3, 3), np.uint8))
    edge = (hi - lo) > 30.0
    u = rng.uniform(size=(H, W))
    valid &= ~(edge & (u < noise.edge_hole_prob))
    flying = edge & (u >= noise.edge_hole_prob) & (u < noise.edge_hole_prob + noise.flying_prob)
    lam = rng.uniform(size=(H, W))
    z = np.where(flying, lam * lo + (1 - lam) * hi, z)
    # stereo occlusion shadow left of the stem
    if noise.shadow and stem.any():
        zs = float(np.median(depth[stem]))
        band = int(round(focal_px * noise.baseline_mm * (1 / zs - 1 / background_mm)))  # disparity step, px
        if band > 0:
            kernel = np.zeros((1, 2 * band + 1), np.uint8)
            kernel[0, band:] = 1          # a stem pixel at column j shadows columns j - band .. j
            shadow = cv2.dilate(stem.astype(np.uint8), kernel).astype(bool) & ~stem
            valid &= ~shadow
    # speckle
    valid &= _blobs(rng, (H, W), 0.7) >= noise.speckle_fraction
    out = np.where(valid, np.clip(np.round(z), 0, 65535), 0)
    return out.astype(np.uint16)


def iter_depth_frames(sim, noise: DepthNoise | None = None, n_frames: int | None = None,
                      exact: bool = False) -> Iterator[np.ndarray]:
    """Yield the depth frames (H, W) uint16 mm of a simulation with a 3-D scene (``sim.three_d``), one at a time.

    ``exact``: yield the error-free float depth (mm) instead. Seeded by ``sim.config.seed``.
    """
    truth = sim.three_d
    if truth is None:
        raise ValueError("the simulation has no 3-D scene (make it with scene3d=Scene3D() or out_of_plane)")
    noise = noise or DepthNoise()
    scene = sim.config.scene3d
    bg_mm = scene.background_mm if scene is not None else 1500.0
    rng = np.random.default_rng(np.random.SeedSequence([int(sim.config.seed), 0xDE9F]))
    background = background_depth(truth.camera, bg_mm, rng)
    row = {int(n): i for i, n in enumerate(sim.graph.nodes)}
    F = truth.positions_mm.shape[1] if n_frames is None else min(n_frames, truth.positions_mm.shape[1])
    for f in range(F):
        depth, width = render_depth(truth.positions_mm[:, f], list(sim.graph.edges), row, truth.stem_radius_mm,
                                    truth.camera, background)
        yield depth if exact else add_depth_errors(depth, width, noise, rng, bg_mm, truth.camera.fx)


def depth_preview(depth_mm: np.ndarray, near_mm: float = 500.0, far_mm: float = 1700.0) -> np.ndarray:
    """A BGR uint8 picture of a depth image: turbo colour map from ``near_mm`` (red) to ``far_mm`` (blue),
    holes (0) black."""
    d = depth_mm.astype(float)
    scaled = np.clip(255 * (far_mm - d) / (far_mm - near_mm), 0, 255).astype(np.uint8)
    img = cv2.applyColorMap(scaled, cv2.COLORMAP_TURBO)
    img[depth_mm == 0] = 0
    return img
