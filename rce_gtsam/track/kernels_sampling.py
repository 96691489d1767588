"""Compiled sampling and Lucas-Kanade of the default tracker (numba, compiled once and cached; see
:mod:`rce_gtsam.track.match_kernels`).

* :func:`sample_patch` -- ``cv2.getRectSubPix`` of a float image: bilinear, replicated borders;
* :func:`weighted_lk` -- the weighted, gain/bias-compensated inverse-compositional Lucas-Kanade (template
  gradients by the 3x3 Sobel with reflect-101 borders, scale 1/8, as ``cv2.Sobel``).

Positions in pixels of the array passed in (pixel centres at integers). The other kernel modules call
:func:`bilinear`, :func:`sample_patch` and :func:`weighted_lk`: an edit here must update their ``CALLS_INTO``
digests (``tests/test_track_kernels.py`` says so), or numba would keep their cached code compiled with the old one.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _clamp(i: int, n: int) -> int:
    return 0 if i < 0 else (n - 1 if i > n - 1 else i)


@njit(cache=True, nogil=True)
def bilinear(img, x, y):
    """``img`` at (x, y) px, bilinear, replicated borders."""
    H, W = img.shape
    fx0, fy0 = math.floor(x), math.floor(y)
    ix, iy = int(fx0), int(fy0)
    fx, fy = x - fx0, y - fy0
    c0, c1 = _clamp(ix, W), _clamp(ix + 1, W)
    r0, r1 = _clamp(iy, H), _clamp(iy + 1, H)
    return ((1 - fx) * (1 - fy) * img[r0, c0] + fx * (1 - fy) * img[r0, c1]
            + (1 - fx) * fy * img[r1, c0] + fx * fy * img[r1, c1])


@njit(cache=True, nogil=True)
def sample_patch(img, cx, cy, out):
    """Fill ``out`` (th, tw) with ``img`` sampled bilinearly on the grid centred at (cx, cy) px, replicated
    borders (``cv2.getRectSubPix`` of a float image)."""
    th, tw = out.shape
    H, W = img.shape
    x0 = cx - (tw - 1) * 0.5
    y0 = cy - (th - 1) * 0.5
    ix = math.floor(x0)
    iy = math.floor(y0)
    a = x0 - ix
    b = y0 - iy
    w00 = (1 - a) * (1 - b)
    w01 = a * (1 - b)
    w10 = (1 - a) * b
    w11 = a * b
    if ix >= 0 and iy >= 0 and ix + tw < W and iy + th < H:
        # inside: unsigned flat indices, so no negative-index wraparound per tap (same taps, same arithmetic)
        flat = img.ravel()
        one, uw = np.uint64(1), np.uint64(W)
        for i in range(th):
            o = np.uint64((iy + i) * W + ix)
            for j in range(tw):
                out[i, j] = (w00 * flat[o] + w01 * flat[o + one] + w10 * flat[o + uw] + w11 * flat[o + uw + one])
                o += one
        return
    for i in range(th):
        for j in range(tw):
            r0, r1 = _clamp(iy + i, H), _clamp(iy + i + 1, H)
            c0, c1 = _clamp(ix + j, W), _clamp(ix + j + 1, W)
            out[i, j] = (w00 * img[r0, c0] + w01 * img[r0, c1] + w10 * img[r1, c0] + w11 * img[r1, c1])


@njit(cache=True, nogil=True)
def _reflect101(i: int, n: int) -> int:
    if n == 1:
        return 0
    while i < 0 or i >= n:
        i = -i if i < 0 else 2 * n - 2 - i
    return i


@njit(cache=True, nogil=True)
def _sobel(t, gx, gy):
    """3x3 Sobel derivatives of ``t`` times 1/8 (``cv2.Sobel(t, CV_32F, dx, dy, ksize=3, scale=0.125)``)."""
    th, tw = t.shape
    for i in range(th):
        im, ip = _reflect101(i - 1, th), _reflect101(i + 1, th)
        for j in range(tw):
            jm, jp = _reflect101(j - 1, tw), _reflect101(j + 1, tw)
            gx[i, j] = 0.125 * ((t[im, jp] + 2.0 * t[i, jp] + t[ip, jp]) - (t[im, jm] + 2.0 * t[i, jm] + t[ip, jm]))
            gy[i, j] = 0.125 * ((t[ip, jm] + 2.0 * t[ip, j] + t[ip, jp]) - (t[im, jm] + 2.0 * t[im, j] + t[im, jp]))


@njit(cache=True, nogil=True)
def weighted_lk(tmpl, wts, img, sx0, sy0, iters=20, eps=0.01):
    """Weighted inverse-compositional LK of ``tmpl`` under ``wts`` in ``img`` from (sx0, sy0) px.

    Returns ``(ok, x, y, s_lk)``: ok False when ill-posed (weighted template variance below 1e-3 grey
    levels^2, singular structure tensor) or when the estimate leaves the start by more than the template
    size; ``s_lk`` = sqrt(weighted residual variance / smallest eigenvalue of the structure tensor) px.
    """
    th, tw = tmpl.shape
    t = tmpl.astype(np.float32)
    gx = np.empty((th, tw), np.float32)
    gy = np.empty((th, tw), np.float32)
    _sobel(t, gx, gy)
    wsum = swt = swtt = hxx = hxy = hyy = gsx = gsy = gxt = gyt = 0.0
    for i in range(th):
        for j in range(tw):
            w = float(wts[i, j])
            tv = float(t[i, j])
            ax = float(gx[i, j])
            ay = float(gy[i, j])
            wsum += w
            swt += w * tv
            swtt += w * tv * tv
            hxx += w * ax * ax
            hxy += w * ax * ay
            hyy += w * ay * ay
            gsx += w * ax
            gsy += w * ay
            gxt += w * ax * tv
            gyt += w * ay * tv
    det = hxx * hyy - hxy * hxy
    if det <= 1e-9:
        return False, 0.0, 0.0, 0.0
    mu_t = swt / wsum
    var_t = swtt / wsum - mu_t * mu_t
    if var_t < 1e-3:
        return False, 0.0, 0.0, 0.0
    sd_t = math.sqrt(var_t) + 1e-6
    gt_x = gxt - mu_t * gsx
    gt_y = gyt - mu_t * gsy
    x, y = sx0, sy0
    pf = np.empty((th, tw), np.float32)
    mu_p = 0.0
    gain = 0.0
    for _ in range(iters):
        sample_patch(img, x, y, pf)
        sw = spx = spy = spp = 0.0
        for i in range(th):
            for j in range(tw):
                w = float(wts[i, j])
                p = float(pf[i, j])
                sw += w * p
                spp += w * p * p
                spx += w * float(gx[i, j]) * p
                spy += w * float(gy[i, j]) * p
        mu_p = sw / wsum
        var_p = max(spp / wsum - mu_p * mu_p, 0.0)
        gain = sd_t / (math.sqrt(var_p) + 1e-6)
        bx = gain * (spx - mu_p * gsx) - gt_x
        by = gain * (spy - mu_p * gsy) - gt_y
        dx = (hyy * bx - hxy * by) / det
        dy = (hxx * by - hxy * bx) / det
        x -= dx
        y -= dy
        if not (math.isfinite(x) and math.isfinite(y)) or abs(x - sx0) > tw or abs(y - sy0) > th:
            return False, 0.0, 0.0, 0.0
        if dx * dx + dy * dy < eps * eps:
            break
    res = 0.0
    for i in range(th):
        for j in range(tw):
            e = (float(pf[i, j]) - mu_p) * gain - (float(t[i, j]) - mu_t)
            res += float(wts[i, j]) * e * e
    lam_min = 0.5 * (hxx + hyy - math.sqrt((hxx - hyy) ** 2 + 4 * hxy * hxy))
    s_lk = math.sqrt((res / wsum) / max(lam_min, 1e-9))
    return True, x, y, s_lk
