"""The Cramér-Rao bound of node positions on a texture-bed video: how well any tracker could place the nodes.

Model (the bed's own, :mod:`rce_gtsam.sim.texture_bed`): every pixel within ``inner_px`` of a segment moves with
the segments' rigid motions blended by Gaussian weights of its distance to each segment (``blend_px``); a segment's
rigid motion is the similarity its two end nodes define. For a small displacement of the nodes a pixel's content
moves by sum_k w_k [(1 - u_k) dp_k + u_k dc_k + v_k R90 (dc_k - dp_k)] (u_k: its fraction along segment k, v_k: its
offset across over the segment's length), so the frame's intensity changes by the image gradient times that. With
white pixel noise of variance s^2 the Fisher information of the node positions is J = G^T G / s^2 (G: one row per
pixel), and no unbiased estimator from that frame has a covariance below J^-1 (root fixed, as in the bed).

* :func:`fisher` — J of one frame from its noise-free render;
* :func:`frame_noise` — s (grey levels): the decoded frame minus the noise-free render after a global gain and
  offset (sensor noise plus what H.264 did to the frame);
* :func:`node_bound` — per node, the bound's RMS per axis (px) over sampled frames;
* :func:`oracle_offsets` / :func:`oracle_tracks` — an estimator that knows every frame's noise-free appearance:
  its error on the decoded video is what the noise *and the compression* displace, which the bound (white noise)
  cannot say.

Gradients are OpenCV's 3x3 Sobel: on a stem profile 3 px wide it keeps 92-94 % of the information a continuous
derivative finds, on a 1.5-px one 80-86 % (``tests/test_texture_bound.py``), so the bound errs a little high.
The noise of a compressed frame is neither white nor independent of the image (H.264 smooths fine texture in
moving regions), so the bound is optimistic where compression is strong: it says what the pixels could support
with the measured noise level, not what a tracker reaches on them. Units: px, grey levels (0-255).
"""

from __future__ import annotations

import math

import cv2
import numpy as np


def design(grey: np.ndarray, xy: np.ndarray, edges, inner_px: float, blend_px: float, root: int):
    """(G, free, rows, cols): the change of the noise-free grey frame ``grey`` (float) per px of each free node
    coordinate (parameters 2 i, 2 i + 1 = node i's x, y; the root's left out), one row per stem pixel (within
    ``inner_px`` of a segment of the pose ``xy`` (P, 2) px), and those pixels' row and column indices."""
    P = xy.shape[0]
    lo = np.floor(xy.min(0) - inner_px - 2).astype(int)
    hi = np.ceil(xy.max(0) + inner_px + 2).astype(int)
    lo = np.maximum(lo, 0)
    hi = np.minimum(hi, [grey.shape[1] - 1, grey.shape[0] - 1])
    gx, gy = np.meshgrid(np.arange(lo[0], hi[0] + 1, dtype=float), np.arange(lo[1], hi[1] + 1, dtype=float))
    gx, gy = gx.ravel(), gy.ravel()
    K = len(edges)
    D, U, V = (np.empty((gx.size, K)) for _ in range(3))
    for k, (p, c) in enumerate(edges):
        a, d = xy[p], xy[c] - xy[p]
        L2 = float(d @ d)
        u = ((gx - a[0]) * d[0] + (gy - a[1]) * d[1]) / L2
        uc = np.clip(u, 0.0, 1.0)
        D[:, k] = np.hypot(gx - a[0] - uc * d[0], gy - a[1] - uc * d[1])
        U[:, k] = u
        V[:, k] = ((gx - a[0]) * -d[1] + (gy - a[1]) * d[0]) / L2
    keep = D.min(1) <= inner_px
    gx, gy, D, U, V = gx[keep], gy[keep], D[keep], U[keep], V[keep]
    w = np.exp(-0.5 * (D / blend_px) ** 2)
    w /= w.sum(1, keepdims=True)
    rows, cols = gy.astype(int), gx.astype(int)
    ix = (cv2.Sobel(grey, cv2.CV_64F, 1, 0, ksize=3) / 8)[rows, cols]
    iy = (cv2.Sobel(grey, cv2.CV_64F, 0, 1, ksize=3) / 8)[rows, cols]
    rx, ry = iy, -ix  # R90^T g: the gradient's component along a rotation of the offset
    G = np.zeros((gx.size, 2 * P))
    for k, (p, c) in enumerate(edges):
        wk, u, v = w[:, k], U[:, k], V[:, k]
        G[:, 2 * p] += wk * ((1 - u) * ix - v * rx)
        G[:, 2 * p + 1] += wk * ((1 - u) * iy - v * ry)
        G[:, 2 * c] += wk * (u * ix + v * rx)
        G[:, 2 * c + 1] += wk * (u * iy + v * ry)
    free = [j for j in range(2 * P) if j // 2 != root]
    return G[:, free], free, rows, cols


def fisher(grey: np.ndarray, xy: np.ndarray, edges, inner_px: float, blend_px: float, root: int):
    """(J / 1 (unit noise), free parameter indices) of the node positions ``xy`` (P, 2) px in the noise-free grey
    frame ``grey`` (float); parameters 2 i, 2 i + 1 = node i's x, y; the root's are left out."""
    G, free, _, _ = design(grey, xy, edges, inner_px, blend_px, root)
    return G.T @ G, free


def oracle_offsets(decoded: np.ndarray, clean: np.ndarray, xy: np.ndarray, edges, inner_px: float,
                   blend_px: float, root: int) -> np.ndarray:
    """(P, 2) px: where an estimator that knows the frame's noise-free appearance ``clean`` at the true pose ``xy``
    puts each node in the ``decoded`` frame, minus the truth (0 at the root). It fits the decoded stem pixels with
    the clean ones moved by the bed's articulated model (one Gauss-Newton step from the truth, least squares over
    every stem pixel, after a global gain and offset): what the noise and the compression of that frame displace.
    Under white noise its covariance is the Cramér-Rao bound's."""
    G, free, rows, cols = design(clean, xy, edges, inner_px, blend_px, root)
    r = after_flicker(decoded, clean)[rows, cols]
    # content moved by delta reads I(x - delta) ~ I(x) - grad I . delta: G's rows are +grad I, so delta = -G^+ r
    d = -np.linalg.lstsq(G, r, rcond=None)[0]
    out = np.zeros(xy.shape)
    for j, col in enumerate(free):
        out[col // 2, col % 2] = d[j]
    return out


def after_flicker(decoded: np.ndarray, clean: np.ndarray) -> np.ndarray:
    """``decoded`` - (a ``clean`` + b) (grey levels), a and b fitted over the whole frame (the flicker's gain and an
    offset): what the sensor noise and the compression left."""
    A = np.stack([clean.ravel(), np.ones(clean.size)], 1)
    a, b = np.linalg.lstsq(A, decoded.ravel(), rcond=None)[0]
    return decoded - a * clean - b


def frame_noise(decoded: np.ndarray, clean: np.ndarray, xy: np.ndarray, margin_px: float = 9.0) -> float:
    """RMS (grey levels) of :func:`after_flicker` over the branch's bounding box (grown by ``margin_px``)."""
    r = after_flicker(decoded, clean)
    lo = np.maximum(np.floor(xy.min(0) - margin_px).astype(int), 0)
    hi = np.ceil(xy.max(0) + margin_px).astype(int)
    return float(np.std(r[lo[1]:hi[1], lo[0]:hi[0]]))


def clean_and_decoded(bed, image_rgb: np.ndarray, q: np.ndarray, video, settings, only=None):
    """Yield (frame, noise-free render, decoded frame), both grey float (grey levels), of the bed ``bed`` whose
    video is the file ``video``; ``only``: a set of frame indices (default: every frame)."""
    from dataclasses import replace

    from rce_gtsam.sim.texture_bed import render_frames
    from rce_gtsam.track import open_video

    clean = render_frames(bed, image_rgb, q, replace(settings, noise_grey=0.0, flicker=0.0), only=only)
    with open_video(video) as src:
        for f, (img, fr) in enumerate(zip(clean, src)):
            if only is None or f in only:
                yield (f, cv2.cvtColor(img, cv2.COLOR_RGB2GRAY).astype(np.float64),
                       cv2.cvtColor(fr.image, cv2.COLOR_RGB2GRAY).astype(np.float64))


def node_bound(bed, image_rgb: np.ndarray, q: np.ndarray, video, settings, every: int = 15):
    """(P,) per node the Cramér-Rao bound's RMS per axis (px; median over every ``every``-th frame; 0 at the
    fixed root) and the median noise level (grey levels) of the bed ``bed`` whose video is the file ``video``."""
    want = set(range(every, bed.true_xy.shape[1], every))
    P, root = bed.true_xy.shape[0], bed.graph.root
    per, noise = [], []
    for f, clean, dec in clean_and_decoded(bed, image_rgb, q, video, settings, only=want):
        xy = bed.true_xy[:, f]
        s = frame_noise(dec, clean, xy)
        J, free = fisher(clean, xy, bed.edges, settings.inner_px, settings.blend_px, root)
        C = np.linalg.inv(J) * s ** 2
        row = np.zeros(P)
        for i in range(P):
            if i != root:
                j = free.index(2 * i)
                row[i] = math.sqrt(0.5 * (C[j, j] + C[j + 1, j + 1]))
        per.append(row)
        noise.append(s)
    return np.median(np.array(per), axis=0), float(np.median(noise))


def oracle_tracks(bed, image_rgb: np.ndarray, q: np.ndarray, video, settings) -> np.ndarray:
    """(P, F, 2) px: :func:`oracle_offsets` in every frame of the bed ``bed`` whose video is the file ``video``
    (the truth plus these is the oracle's tracks)."""
    out = np.zeros(bed.true_xy.shape)
    for f, clean, dec in clean_and_decoded(bed, image_rgb, q, video, settings):
        out[:, f] = oracle_offsets(dec, clean, bed.true_xy[:, f], bed.edges, settings.inner_px, settings.blend_px,
                                   bed.graph.root)
    return out
