"""Compiled node measurement of the default tracker (numba, compiled once and cached; see
:mod:`rce_gtsam.track.match_kernels`).

* :func:`weighted_ncc` -- ``cv2.matchTemplate(img, tmpl, cv2.TM_CCOEFF_NORMED, mask=wts)``;
* :func:`match_node` -- one node's measurement: correlation peak and the best peak outside h/2 of it, parabolic
  sub-pixel peak, forward LK from it and the forward-backward error;
* :func:`articulated_template` -- a node's frame-0 neighbourhood posed per incident segment (:func:`band_rows`: the
  band's extent per row, computed once per node);
  :func:`match_articulated` -- that template and :func:`match_node` in one call.

Positions in pixels of the crop passed in (pixel centres at integers); correlations dimensionless.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .kernels_sampling import bilinear, sample_patch, weighted_lk

#: sha256 (first 16 hex digits) of each kernel file this module's compiled functions call into. numba's cache
#: checks only a function's own file (numba issue 1833), so an edit there must change this file too, or its
#: cached kernels keep the old code; ``tests/test_track_kernels.py`` checks the digests.
CALLS_INTO = {"kernels_sampling.py": "902913666eddb75f"}


@njit(cache=True, nogil=True)
def weighted_ncc(img, tmpl, wts):
    """(H - th + 1, W - tw + 1) float32 map: OpenCV's masked ``TM_CCOEFF_NORMED`` of ``tmpl`` under ``wts``.

    With w = ``wts``, mu_t = sum(w t) / sum(w) and mu_I the same weighted mean of the image window:
    sum(w^2 (t - mu_t)(I - mu_I)) / sqrt(sum(w^2 (t - mu_t)^2) sum(w^2 (I - mu_I)^2)); -1 where the window
    has no weighted variance. The four window sums run over the template pixels of non-zero weight only (a
    thin branch band is a third to a half of its patch).
    """
    th, tw = tmpl.shape
    H, W = img.shape
    rh, rw = H - th + 1, W - tw + 1
    out = np.empty((rh, rw), np.float32)
    n = 0
    msum = mt = 0.0
    for i in range(th):
        for j in range(tw):
            w = float(wts[i, j])
            if w != 0:
                n += 1
                msum += w
                mt += w * float(tmpl[i, j])
    if n == 0 or msum <= 0:
        out[:] = -1.0
        return out
    mu_t = mt / msum
    # per template pixel: m = w, m2 = w^2, a = w^2 (t - mu_t)
    a = np.zeros((th, tw))
    m = np.zeros((th, tw))
    m2 = np.zeros((th, tw))
    asum = m2sum = tnorm = 0.0
    for i in range(th):
        for j in range(tw):
            w = float(wts[i, j])
            d = float(tmpl[i, j]) - mu_t
            m[i, j] = w
            m2[i, j] = w * w
            a[i, j] = w * w * d
            asum += a[i, j]
            m2sum += m2[i, j]
            tnorm += w * w * d * d
    tnorm = math.sqrt(tnorm)
    sums = _window_sums(img, a, m, m2, n)
    for v in range(rh):
        for u in range(rw):
            mu_i = sums[0, v, u] / msum
            num = sums[1, v, u] - mu_i * asum
            den2 = sums[3, v, u] - 2.0 * mu_i * sums[2, v, u] + mu_i * mu_i * m2sum
            if den2 <= 0.0 or tnorm <= 0.0:
                out[v, u] = -1.0
            else:
                out[v, u] = num / (math.sqrt(den2) * tnorm)
    return out


@njit(cache=True, nogil=True, fastmath=True)
def _window_sums(img, a, m, m2, n):
    """(4, rh, rw): sum(m I), sum(a I), sum(m2 I), sum(m2 I^2) over each window, from the n pixels with m != 0.

    ``fastmath``: the compiler may reorder each window's float64 sum over the template pixels (and so
    vectorise it): 1.9x faster, and the sums then differ from the in-order ones by ~1e-15 relative, far below
    the float32 precision of the correlation map they feed.
    """
    th, tw = a.shape
    H, W = img.shape
    rh, rw = H - th + 1, W - tw + 1
    off = np.empty(n, np.uint64)  # flat offset of each weighted pixel in a window (unsigned: no wraparound code)
    fa = np.empty(n)
    fm = np.empty(n)
    fm2 = np.empty(n)
    k = 0
    for i in range(th):
        for j in range(tw):
            if m[i, j] != 0:
                off[k], fa[k], fm[k], fm2[k] = i * W + j, a[i, j], m[i, j], m2[i, j]
                k += 1
    flat = img.ravel()
    out = np.empty((4, rh, rw))
    for v in range(rh):
        for u in range(rw):
            base = np.uint64(v * W + u)
            s_a = s_m = s_m2 = s_i2 = 0.0
            for k in range(n):
                p = float(flat[base + off[k]])
                s_a += fa[k] * p
                s_m += fm[k] * p
                mp = fm2[k] * p
                s_m2 += mp
                s_i2 += mp * p
            out[0, v, u], out[1, v, u], out[2, v, u], out[3, v, u] = s_m, s_a, s_m2, s_i2
    return out


@njit(cache=True, nogil=True)
def _parabola(a, b, c):
    den = a - 2 * b + c
    if den >= 0:
        return 0.0
    return min(max(0.5 * (a - c) / den, -0.5), 0.5)


@njit(cache=True, nogil=True)
def match_node(cur, tmpl, wts, prev, r, h, c_prev):
    """Measure one node: ``tmpl`` (2h + 1 square, weights ``wts``) searched in ``cur`` ((2 (h + r) + 1) square
    crop centred on the prediction) within r px, then checked back in the frame-0 crop ``prev`` (template
    centred at (c_prev, c_prev)).

    Returns a float64 array ``[ok, x, y, ncc, fb, s_lk, second, x2, y2, has_second]``: (x, y) the match in
    ``cur`` (px), ncc its correlation peak, fb the forward-backward error (px, inf if the backward LK fails),
    s_lk the LK standard error (px), second the best correlation outside h/2 of the peak at (x2, y2) (crop px)
    when ``has_second``. ok = 0 when the forward LK is ill-posed or moves more than 2 px from the peak.
    """
    out = np.zeros(10)
    res = weighted_ncc(cur, tmpl, wts)
    rh, rw = res.shape
    bu = bv = 0
    best = res[0, 0]
    for v in range(rh):
        for u in range(rw):
            if res[v, u] > best:
                best, bu, bv = res[v, u], u, v
    rad2 = (h / 2.0) ** 2
    second = -2.0
    su = sv = -1
    for v in range(rh):
        for u in range(rw):
            if (u - bu) ** 2 + (v - bv) ** 2 > rad2 and res[v, u] > second:
                second, su, sv = res[v, u], u, v
    if su >= 0:
        out[6] = second
        out[7] = su + h
        out[8] = sv + h
        out[9] = 1.0
    else:
        out[6] = -1.0
    du = _parabola(float(res[bv, bu - 1]), float(best), float(res[bv, bu + 1])) if 0 < bu < rw - 1 else 0.0
    dv = _parabola(float(res[bv - 1, bu]), float(best), float(res[bv + 1, bu])) if 0 < bv < rh - 1 else 0.0
    gx0 = h + bu + du
    gy0 = h + bv + dv
    out[3] = best
    ok, x, y, s_lk = weighted_lk(tmpl, wts, cur, gx0, gy0)
    if not ok or math.hypot(x - gx0, y - gy0) > 2.0:
        return out
    back = np.empty(tmpl.shape, np.float32)
    sample_patch(cur, x, y, back)
    okb, bx, by, _ = weighted_lk(back, wts, prev, c_prev, c_prev)
    out[0] = 1.0
    out[1] = x
    out[2] = y
    out[4] = math.hypot(bx - c_prev, by - c_prev) if okb else math.inf
    out[5] = s_lk
    return out


def band_rows(bands: np.ndarray) -> np.ndarray:
    """(S, n, 2) int64: for each band of ``bands`` (S, n, n) and each row, the first and last column of non-zero
    weight (n + 5 and -5 for a row with none): :func:`articulated_template` skips a bilinear tap block that lies
    off them, since its weight would be exactly 0 (a third less time on a thin branch's band)."""
    nz = bands != 0
    any_ = nz.any(axis=2)
    n = bands.shape[2]
    first = np.where(any_, nz.argmax(axis=2), n + 5)
    last = np.where(any_, n - 1 - nz[:, :, ::-1].argmax(axis=2), -5)
    return np.stack([first, last], axis=2).astype(np.int64)


@njit(cache=True, nogil=True)
def articulated_template(gray0, px, py, thetas, bands, rows, bg, min_band, h, margin, round_out):
    """Frame-0 neighbourhood of a node at (px, py), posed per incident segment.

    Segment s's band ``bands[s]`` (centred on the node; ``rows`` = :func:`band_rows` of it) and the frame-0 image are
    rotated about the node by
    ``thetas[s]`` (radians) -- ``cv2.warpAffine`` with bilinear sampling, replicated borders for the image
    (rounded to integers when ``round_out``: a uint8 image) and zeros outside the band -- and composited by
    weight; where no band reaches, segment ``bg``'s rotated image. Returns ``(crop, tmpl, wts, wsum)``: the
    (k, k) float32 crop (k = 2 (h + margin) + 1, node at its centre), its central (2h + 1) square, that
    square's weights (band weight clipped at 1; all ones when they sum to less than ``min_band``) and their sum.
    """
    S = thetas.shape[0]
    bs = bands.shape[1]
    k = 2 * (h + margin) + 1
    c = (k - 1) * 0.5
    cs = (bs - 1) * 0.5
    crop = np.empty((k, k), np.float32)
    wacc_all = np.empty((k, k), np.float32)
    cos_t = np.cos(thetas)
    sin_t = np.sin(thetas)
    # every sample lies within ``reach`` of the node (the crop's corner, rotated, plus the bilinear tap): when the
    # band crops and the image hold that disc, the taps need no bounds checks (unsigned flat indices, no clamping;
    # the same taps and arithmetic)
    H, W = gray0.shape
    reach = c * math.sqrt(2.0) + 2.0
    band_in = reach < cs - 1.0
    img_in = px - reach >= 0 and py - reach >= 0 and px + reach < W - 1 and py + reach < H - 1
    fb = bands.ravel()
    fg = gray0.ravel()
    one, ubs, uw = np.uint64(1), np.uint64(bs), np.uint64(W)
    for y in range(k):
        for x in range(k):
            dx, dy = x - c, y - c
            acc = np.float32(0.0)
            wacc = np.float32(0.0)
            back = np.float32(0.0)
            for s in range(S):
                ox = cos_t[s] * dx + sin_t[s] * dy
                oy = -sin_t[s] * dx + cos_t[s] * dy
                # band: zero outside
                bx, by = cs + ox, cs + oy
                fbx, fby = math.floor(bx), math.floor(by)
                jx, jy = int(fbx), int(fby)
                ax, ay = bx - fbx, by - fby
                w = 0.0
                if band_in and ((rows[s, jy, 1] < jx or rows[s, jy, 0] > jx + 1)
                                and (rows[s, jy + 1, 1] < jx or rows[s, jy + 1, 0] > jx + 1)):
                    pass  # the four taps are off the band (``rows``): w is exactly 0 without reading them
                elif band_in:
                    o = np.uint64((s * bs + jy) * bs + jx)
                    w += (1 - ax) * (1 - ay) * fb[o]
                    w += ax * (1 - ay) * fb[o + one]
                    w += (1 - ax) * ay * fb[o + ubs]
                    w += ax * ay * fb[o + ubs + one]
                else:
                    if jy >= 0 and jy < bs:
                        if jx >= 0 and jx < bs:
                            w += (1 - ax) * (1 - ay) * bands[s, jy, jx]
                        if jx + 1 >= 0 and jx + 1 < bs:
                            w += ax * (1 - ay) * bands[s, jy, jx + 1]
                    if jy + 1 >= 0 and jy + 1 < bs:
                        if jx >= 0 and jx < bs:
                            w += (1 - ax) * ay * bands[s, jy + 1, jx]
                        if jx + 1 >= 0 and jx + 1 < bs:
                            w += ax * ay * bands[s, jy + 1, jx + 1]
                wf = np.float32(w)
                if wf == 0 and s != bg:
                    continue  # adds exactly nothing: skip the image sample (most of a patch is off every band)
                gx, gy = px + ox, py + oy
                if img_in:
                    fgx, fgy = math.floor(gx), math.floor(gy)
                    ix, iy = int(fgx), int(fgy)
                    fx, fy = gx - fgx, gy - fgy
                    o = np.uint64(iy * W + ix)
                    g = ((1 - fx) * (1 - fy) * fg[o] + fx * (1 - fy) * fg[o + one]
                         + (1 - fx) * fy * fg[o + uw] + fx * fy * fg[o + uw + one])
                else:
                    g = bilinear(gray0, gx, gy)  # image: replicated border
                if round_out:
                    g = math.floor(g + 0.5)
                gf = np.float32(g)
                if s == bg:
                    back = gf
                acc += wf * gf
                wacc += wf
            wacc_all[y, x] = wacc
            crop[y, x] = acc / max(wacc, np.float32(1e-3)) if wacc > 1e-3 else back
    n = 2 * h + 1
    tmpl = np.empty((n, n), np.float32)
    wts = np.empty((n, n), np.float32)
    wsum = 0.0
    for y in range(n):
        for x in range(n):
            tmpl[y, x] = crop[y + margin, x + margin]
            wts[y, x] = min(wacc_all[y + margin, x + margin], np.float32(1.0))
            wsum += wts[y, x]
    if wsum < min_band:
        wts[:] = 1.0
        wsum = float(n * n)
    return crop, tmpl, wts, wsum


@njit(cache=True, nogil=True)
def match_articulated(gray0, px, py, thetas, bands, rows, bg, min_band, h, margin, round_out, cur, r, qx, qy):
    """:func:`articulated_template` of the node at (px, py) in ``gray0``, then :func:`match_node` of it in
    ``cur`` (the search crop, any dtype, centred on (qx, qy) in the frame) within r px, in one call.

    Returns ``(ok, x, y, ncc, fb, s_lk, second, x2, y2, has_second, wsum)``: :func:`match_node`'s results with the
    match (x, y) and the second peak (x2, y2) in frame pixels, and the template weight sum ``wsum``.
    """
    prev, tmpl, wts, wsum = articulated_template(gray0, px, py, thetas, bands, rows, bg, min_band, h, margin,
                                                 round_out)
    curf = np.empty(cur.shape, np.float32)
    curf[:] = cur
    m = match_node(curf, tmpl, wts, prev, r, h, float(h + margin))
    c = float(h + r)
    return (m[0] != 0, qx + (m[1] - c), qy + (m[2] - c), m[3], m[4], m[5], m[6], qx + (m[7] - c), qy + (m[8] - c),
            m[9] != 0, wsum)
