"""A small 3-D branch for the depth tests: a chain whose joints bend in the branch plane by kappa z(t) and out of
it by kappa z_o(t) (issue #39's model), its plane tilted about the camera's x axis, seen by a 640x480-like
pinhole camera; plus a renderer of colour + registered depth images (a textured stem over a far, textured
background, D435-like depth noise and holes) for end-to-end runs through a RealSense recording."""

from __future__ import annotations

import cv2
import numpy as np

from rce_gtsam.camera import CameraIntrinsics
from rce_gtsam.graph import BranchGraph


def chain3d(n_nodes=6, n_frames=120, seg_mm=45.0, share=0.8, tilt_deg=30.0, rms_deg=4.0, seed=0,
            root_mm=(0.0, 150.0, 800.0)):
    """Return (positions_mm (N, F, 3), kappa (N-2,), z (F,), z_o (F,), plane normal (3,)).

    Joint k (node k, k = 1..N-2) turns the next segment by rest + kappa z in the plane and kappa z_o out of it."""
    rng = np.random.default_rng(seed)
    kappa = np.exp(rng.uniform(-0.6, 0.6, n_nodes - 2))
    kappa /= np.exp(np.mean(np.log(kappa)))
    t = np.arange(n_frames)

    def wind(r):
        x = sum(r.uniform(0.5, 1.0) * np.sin(2 * np.pi * t / r.uniform(60, 200) + r.uniform(0, 6.3)) for _ in range(3))
        return x / x.std()

    z = rms_deg * wind(rng)
    z_o = share * (0.5 * z + np.sqrt(0.75) * rms_deg * wind(np.random.default_rng(seed + 1000)))
    tilt = np.radians(tilt_deg)
    e1 = np.array([1.0, 0.0, 0.0])                         # in-plane, image right
    e2 = np.array([0.0, -np.cos(tilt), np.sin(tilt)])      # in-plane, up the image and away from the camera
    normal = np.cross(e1, e2)
    heading = np.full(n_frames, np.radians(80.0))
    elev = np.zeros(n_frames)
    pos = np.zeros((n_nodes, n_frames, 3))
    pos[0] = np.asarray(root_mm, float)
    rest = np.radians(rng.uniform(-8, 8, n_nodes))
    for i in range(1, n_nodes):
        if i >= 2:
            heading = heading + rest[i] + np.radians(kappa[i - 2] * z)
            elev = elev + np.radians(kappa[i - 2] * z_o)
        d = (np.cos(elev)[:, None] * (np.cos(heading)[:, None] * e1 + np.sin(heading)[:, None] * e2)
             + np.sin(elev)[:, None] * normal)
        pos[i] = pos[i - 1] + seg_mm * d
    return pos, kappa, z, z_o, normal


def chain_graph(n_nodes: int) -> BranchGraph:
    return BranchGraph.from_edges(0, [(i, i + 1) for i in range(n_nodes - 1)], source="<chain3d>")


def render(pos_mm: np.ndarray, cam: CameraIntrinsics, seed: int = 0, stem_px: int = 9, bg_mm: float = 1400.0,
           hole_frac: float = 0.03):
    """(colour (F, H, W, 3) uint8 RGB, depth (F, H, W) uint16 mm) of the chain: a bark-textured stem drawn
    between the projected nodes over a textured background; depth = the stem's z along each segment, the
    background at ``bg_mm``, D435-like noise (sigma ~ z^2), holes at a ``hole_frac`` of pixels and at stem edges."""
    from rce_gtsam.track.depth_sample import d435_depth_rms_mm

    rng = np.random.default_rng(seed)
    n, f = pos_mm.shape[:2]
    h, w = cam.height, cam.width
    uv = cam.project(pos_mm)
    noise = cv2.GaussianBlur(rng.normal(0, 1, (h, w)).astype(np.float32), (0, 0), 5)
    bg = np.clip(np.dstack([95 + 45 * noise, 125 + 45 * noise, 90 + 35 * noise]), 0, 255)
    bark = cv2.GaussianBlur(rng.normal(0, 1, (h, w)).astype(np.float32), (0, 0), 1.5)
    bark = np.dstack([120 * (1 + 0.8 * bark), 80 * (1 + 0.8 * bark), 50 * (1 + 0.8 * bark)]).clip(0, 255)
    color = np.empty((f, h, w, 3), np.uint8)
    depth = np.empty((f, h, w), np.uint16)
    for t in range(f):
        mask = np.zeros((h, w), np.float32)
        zimg = np.full((h, w), np.inf, np.float32)
        for i in range(n - 1):
            a, b = uv[i, t], uv[i + 1, t]
            seg = np.zeros((h, w), np.uint8)
            cv2.line(seg, tuple(int(round(v * 16)) for v in a), tuple(int(round(v * 16)) for v in b), 255, stem_px,
                     cv2.LINE_AA, shift=4)
            cv2.line(mask, tuple(int(round(v * 16)) for v in a), tuple(int(round(v * 16)) for v in b), 1.0, stem_px,
                     cv2.LINE_AA, shift=4)
            ys, xs = np.nonzero(seg > 128)
            ab = b - a
            s = np.clip(((xs - a[0]) * ab[0] + (ys - a[1]) * ab[1]) / max(ab @ ab, 1e-9), 0, 1)
            zs = pos_mm[i, t, 2] + s * (pos_mm[i + 1, t, 2] - pos_mm[i, t, 2])
            zimg[ys, xs] = np.minimum(zimg[ys, xs], zs)
        m = mask[..., None]
        color[t] = np.clip(m * bark + (1 - m) * bg, 0, 255).astype(np.uint8)
        stem = np.isfinite(zimg)
        d = np.where(stem, zimg, bg_mm).astype(np.float64)
        d += rng.normal(0, 1, (h, w)) * d435_depth_rms_mm(d)
        edge = stem & ~cv2.erode(stem.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
        holes = (rng.uniform(size=(h, w)) < hole_frac) | (edge & (rng.uniform(size=(h, w)) < 0.5))
        d[holes] = 0
        depth[t] = np.clip(np.rint(d), 0, 65535).astype(np.uint16)
    return color, depth
