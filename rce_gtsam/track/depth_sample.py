"""Depth at the tracked nodes: a robust depth (mm) and its 1-sigma (mm) per node and frame, and the 3-D point.

For a node at pixel (u, v) the depth image (registered to the colour image, 0 = hole) is read in a disk of
``radius_px`` around it. Holes are ignored. A thin stem fills only part of the disk and the background behind it
is farther, so the *nearer mode* is kept: the valid pixels within ``tol`` of the disk's 10th-percentile depth,
where ``tol = 3 sigma_D435(z) + NEAR_TOL_MM`` (a speckled pixel in front of the stem, under 10 % of the disk,
does not move the 10th percentile much). The node's depth is their median.

Its sigma combines the D435 stereo error model (RMS depth error growing with distance squared,
``z^2 * subpixel / (focal * baseline)``; not averaged down over the disk, because stereo matching errors are
correlated over the matching window) with the spread of the kept pixels (1.4826 MAD, averaged over
``n / STEREO_PATCH_PX`` independent patches): ``sigma^2 = sigma_D435(z)^2 + (1.4826 MAD)^2 / max(n / 9, 1)``.
A node with fewer than ``MIN_VALID_PX`` valid pixels gets no depth (NaN): the 3-D smoother then holds it by its
pixel measurement and its neighbours in time and along the branch.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..camera import CameraIntrinsics

#: D435/D435i stereo depth error model: baseline (mm), depth focal length at 848x480 (px, HFOV 87 deg), and the
#: subpixel disparity RMS (px) of Intel's depth-quality white paper.
D435_BASELINE_MM = 50.0
D435_DEPTH_FOCAL_PX = 430.0
D435_SUBPIXEL_RMS = 0.08
#: Window radius around a node (px), least valid pixels for a depth, nearer-mode tolerance floor (mm), and the
#: pixels one stereo match spans (so independent depth errors in a window ~ n / 9).
RADIUS_PX = 4
MIN_VALID_PX = 3
NEAR_TOL_MM = 10.0
STEREO_PATCH_PX = 9.0


def d435_depth_rms_mm(z_mm) -> np.ndarray:
    """RMS depth error (mm) of a D435-class stereo camera at depth ``z_mm`` (mm): z^2 * subpixel / (f * B)."""
    z = np.asarray(z_mm, float)
    return z * z * D435_SUBPIXEL_RMS / (D435_DEPTH_FOCAL_PX * D435_BASELINE_MM)


@dataclass(frozen=True, eq=False)
class NodeDepth:
    """Depth sampled at tracked nodes.

    z_mm: (N, F) depth along the optical axis (mm), NaN where no depth (hole, node not visible).
    z_sigma_mm: (N, F) its 1-sigma (mm), NaN where no depth.
    n_valid: (N, F) int, valid depth pixels in the node's window.
    radius_px: the window radius (px).
    """

    z_mm: np.ndarray
    z_sigma_mm: np.ndarray
    n_valid: np.ndarray
    radius_px: int

    @property
    def coverage(self) -> float:
        """Share of node-frames with a depth."""
        return float(np.isfinite(self.z_mm).mean()) if self.z_mm.size else 0.0


def _disk(radius: int) -> tuple[np.ndarray, np.ndarray]:
    dy, dx = np.mgrid[-radius:radius + 1, -radius:radius + 1]
    keep = dx * dx + dy * dy <= radius * radius
    return dy[keep], dx[keep]


def robust_window_depth(values_mm: np.ndarray) -> tuple[float, float, int]:
    """(depth mm, sigma mm, n valid) of the nearer mode of one window's depth values (0 = hole)."""
    v = values_mm[values_mm > 0]
    if v.size < MIN_VALID_PX:
        return float("nan"), float("nan"), int(v.size)
    near = float(np.quantile(v, 0.1))
    tol = 3.0 * float(d435_depth_rms_mm(near)) + NEAR_TOL_MM
    sel = v[np.abs(v - near) <= tol]
    z = float(np.median(sel))
    mad = 1.4826 * float(np.median(np.abs(sel - z)))
    model = float(d435_depth_rms_mm(z))
    sigma = float(np.sqrt(model * model + mad * mad / max(sel.size / STEREO_PATCH_PX, 1.0)))
    return z, sigma, int(v.size)


def sample_frame(depth_mm: np.ndarray, xy_px: np.ndarray, visible: np.ndarray | None = None,
                 radius_px: int = RADIUS_PX) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Depth (mm), sigma (mm) and valid-pixel count at each node ``xy_px`` (N, 2) of one registered depth image."""
    h, w = depth_mm.shape
    dy, dx = _disk(radius_px)
    n = len(xy_px)
    z, s, c = np.full(n, np.nan), np.full(n, np.nan), np.zeros(n, int)
    for i, (x, y) in enumerate(np.asarray(xy_px, float)):
        if (visible is not None and not visible[i]) or not np.isfinite([x, y]).all():
            continue
        yy, xx = int(round(y)) + dy, int(round(x)) + dx
        inside = (yy >= 0) & (yy < h) & (xx >= 0) & (xx < w)
        z[i], s[i], c[i] = robust_window_depth(depth_mm[yy[inside], xx[inside]])
    return z, s, c


def sample_depth(frames, xy_px: np.ndarray, visible: np.ndarray | None = None,
                 radius_px: int = RADIUS_PX) -> NodeDepth:
    """Sample the tracked nodes ``xy_px`` (N, F, 2) in each frame of ``frames`` (an iterable of
    :class:`~rce_gtsam.track.depth.DepthFrame`, e.g. a :class:`RealSenseDepthSource`); frames past F are not read."""
    n, f = xy_px.shape[:2]
    z, s, c = np.full((n, f), np.nan), np.full((n, f), np.nan), np.zeros((n, f), int)
    for fr in frames:
        if fr.index >= f:
            break
        vis = None if visible is None else visible[:, fr.index]
        z[:, fr.index], s[:, fr.index], c[:, fr.index] = sample_frame(fr.depth_mm, xy_px[:, fr.index], vis, radius_px)
    return NodeDepth(z, s, c, radius_px)


def deproject_tracks(xy_px: np.ndarray, z_mm: np.ndarray, intrinsics: CameraIntrinsics) -> np.ndarray:
    """(N, F, 3) camera-frame points (mm) of pixel tracks (N, F, 2) with depths (N, F); NaN where either is."""
    return intrinsics.deproject(xy_px, z_mm)
