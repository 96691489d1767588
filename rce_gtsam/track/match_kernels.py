"""Compiled inner loops of the default tracker's measurement against frame 0 (numba, compiled once and cached).

At 20 nodes the tracker's time went to the per-call overhead of small numpy/OpenCV operations (a dozen
array calls per Lucas-Kanade iteration, two per template pixel sum) and to OpenCV's masked
``matchTemplate``, which goes through several DFT correlations for a 19x19 result. These kernels do the
same arithmetic in one compiled call per node, on the crops the tracker cuts with OpenCV:

* :func:`weighted_ncc` -- ``cv2.matchTemplate(img, tmpl, cv2.TM_CCOEFF_NORMED, mask=wts)``: the zero-mean
  normalised correlation with OpenCV's weighting (template mean weighted by ``wts``, products weighted by
  ``wts**2``), summed directly over the template pixels of non-zero weight; -1 where the image window has no
  variance (OpenCV: NaN, which the tracker mapped to -1).
* :func:`weighted_lk` -- the weighted, gain/bias-compensated inverse-compositional Lucas-Kanade of
  ``lk.py`` (template gradients by the 3x3 Sobel with reflect-101 borders, scale 1/8, as ``cv2.Sobel``;
  patches sampled bilinearly with replicated borders, as ``cv2.getRectSubPix``).
* :func:`match_node` -- one node's measurement: correlation peak and the best peak outside h/2 of it,
  parabolic sub-pixel peak, forward LK from it and the forward-backward error (the matched patch searched
  for in the frame-0 crop).
* :func:`segment_search` -- the segment search: :func:`segment_ncc` of the frame-0 strip over the rotations
  around the last one, the best by a parabola, and the child's position there.
* :func:`chromaticity`, :func:`chroma_mask` -- the frame-0 colour mask's per-pixel float32 arithmetic, as numpy
  does it (equal arrays).

All positions are in pixels of the crop passed in (pixel centres at integers). Results equal the
OpenCV/numpy implementation they replace to float rounding (float64 sums instead of OpenCV's float32).
Taps known to lie inside an array (checked once per call) index it through unsigned flat offsets: numba then
emits no negative-index wraparound code per tap (the same taps and arithmetic; 1.1-1.2x).
Every kernel releases the GIL (``nogil``): the tracker's refinement thread matches while the first pass does.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _clamp(i: int, n: int) -> int:
    return 0 if i < 0 else (n - 1 if i > n - 1 else i)


@njit(cache=True, nogil=True)
def _bilinear(img, x, y):
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


@njit(cache=True, nogil=True)
def _segment_sums(src, W, ox0, oy0, x0, y0, ex, ey, uu, vv, strip, round_out, out):
    """:func:`segment_ncc` for strips whose every bilinear tap lies in ``src`` (flat, row length W, pixel (x, y) of
    the image at ``(y - oy0) * W + x - ox0``): no border handling, float64 pixels (no per-tap conversion)."""
    A, V, U = ex.shape[0], vv.shape[0], uu.shape[0]
    n = V * U
    fx0, fy0 = np.float32(x0), np.float32(y0)
    one, uw = np.uint64(1), np.uint64(W)  # unsigned flat indices: no negative-index wraparound code per tap
    cu = np.empty(U, np.float32)
    su = np.empty(U, np.float32)
    for a in range(A):
        s1 = s2 = d = 0.0
        ca, sa = ex[a], ey[a]
        for iu in range(U):  # the same float32 products as in the loop below, computed once per angle
            cu[iu] = ca * uu[iu]
            su[iu] = sa * uu[iu]
        for iv in range(V):
            v = vv[iv]
            sv = sa * v
            cv = ca * v
            for iu in range(U):
                mx = float((cu[iu] - sv) + fx0)
                my = float((su[iu] + cv) + fy0)
                ix, iy = int(mx), int(my)
                fx, fy = mx - ix, my - iy
                o = np.uint64((iy - oy0) * W + (ix - ox0))
                p = ((1 - fx) * (1 - fy) * src[o] + fx * (1 - fy) * src[o + one]
                     + (1 - fx) * fy * src[o + uw] + fx * fy * src[o + uw + one])
                if round_out:
                    p = math.floor(p + 0.5)
                p -= 128.0
                s1 += p
                s2 += p * p
                d += p * strip[iv, iu]
        out[a] = d / (math.sqrt(max(s2 - s1 * s1 / n, 0.0)) + 1e-6)


@njit(cache=True, nogil=True)
def segment_ncc(img, x0, y0, ex, ey, uu, vv, strip, round_out):
    """Zero-mean NCC of the frame-0 ``strip`` (V, U; zero mean, unit norm) with ``img`` sampled along each
    rotation a: point (u, v) of the strip at (x0, y0) + u (ex[a], ey[a]) + v (-ey[a], ex[a]) px.

    Sampling as ``cv2.remap(..., INTER_LINEAR, BORDER_REPLICATE)`` (OpenCV 5) with float32 maps: bilinear at
    the float32 positions, rounded to integers when ``round_out`` (a uint8 image). Returns (A,) NCC.
    """
    H, W = img.shape
    A, V, U = ex.shape[0], vv.shape[0], uu.shape[0]
    n = V * U
    out = np.empty(A)
    reach = 0.0  # farthest sample from (x0, y0): with a 2-px margin inside the image, no border handling
    for iu in range(U):
        for iv in range(V):
            reach = max(reach, math.sqrt(float(uu[iu]) ** 2 + float(vv[iv]) ** 2))
    inside = x0 - reach - 2 >= 0 and y0 - reach - 2 >= 0 and x0 + reach + 2 < W - 1 and y0 + reach + 2 < H - 1
    if inside:
        # the disc the strip sweeps, copied once as float64: the taps then need neither clamping nor conversion
        ox0, oy0 = int(math.floor(x0 - reach - 2)), int(math.floor(y0 - reach - 2))
        ww = int(math.ceil(x0 + reach + 2)) + 2 - ox0
        hh = int(math.ceil(y0 + reach + 2)) + 2 - oy0
        loc = np.empty(hh * ww)
        for y in range(hh):
            for x in range(ww):
                loc[y * ww + x] = img[oy0 + y, ox0 + x]
        _segment_sums(loc, ww, ox0, oy0, x0, y0, ex, ey, uu, vv, strip, round_out, out)
        return out
    fx0, fy0 = np.float32(x0), np.float32(y0)
    cu = np.empty(U, np.float32)
    su = np.empty(U, np.float32)
    for a in range(A):
        s1 = s2 = d = 0.0
        ca, sa = ex[a], ey[a]
        for iu in range(U):
            cu[iu] = ca * uu[iu]
            su[iu] = sa * uu[iu]
        for iv in range(V):
            v = vv[iv]
            sv = sa * v
            cv = ca * v
            for iu in range(U):
                p = _bilinear(img, float((cu[iu] - sv) + fx0), float((su[iu] + cv) + fy0))
                if round_out:
                    p = math.floor(p + 0.5)
                p -= 128.0
                s1 += p
                s2 += p * p
                d += p * strip[iv, iu]
        out[a] = d / (math.sqrt(max(s2 - s1 * s1 / n, 0.0)) + 1e-6)
    return out


@njit(cache=True, nogil=True)
def segment_search(img, xp, yp, phi_prev, offs, a0, step, v0x, v0y, uu, vv, strip, round_out):
    """The segment search of ``LKTracker._segment_search`` in one call: :func:`segment_ncc` over the rotations
    ``phi_prev + offs`` (radians since frame 0; ``a0`` = the segment's frame-0 direction) hinged at (xp, yp), the
    best one refined by a parabola through its neighbours (``step`` apart), and the child there.

    Returns ``(x, y, phi, ncc)``: the child's position (px; frame-0 segment vector (v0x, v0y) rotated by phi from
    the hinge), the rotation and the correlation peak.
    """
    A = offs.shape[0]
    phis = np.empty(A)
    ex = np.empty(A, np.float32)
    ey = np.empty(A, np.float32)
    for a in range(A):
        phis[a] = phi_prev + offs[a]
        ang = a0 + phis[a]
        ex[a] = np.float32(math.cos(ang))
        ey[a] = np.float32(math.sin(ang))
    ncc = segment_ncc(img, xp, yp, ex, ey, uu, vv, strip, round_out)
    k = 0  # numpy's argmax: the first maximum (the first NaN if any)
    for a in range(A):
        if math.isnan(ncc[a]):
            k = a
            break
        if ncc[a] > ncc[k]:
            k = a
    dk = 0.0
    if 0 < k < A - 1:
        a_, b_, c_ = ncc[k - 1], ncc[k], ncc[k + 1]
        den = a_ - 2 * b_ + c_
        if not den >= 0:
            dk = 0.5 * (a_ - c_) / den
            dk = -0.5 if dk < -0.5 else dk  # Python's max(dk, -0.5), min(., 0.5)
            dk = 0.5 if 0.5 < dk else dk
    phi = phis[k] + dk * step
    ct, sn = math.cos(phi), math.sin(phi)
    return xp + (ct * v0x - sn * v0y), yp + (sn * v0x + ct * v0y), phi, ncc[k]


@njit(cache=True, nogil=True)
def articulated_template(gray0, px, py, thetas, bands, bg, min_band, h, margin, round_out):
    """Frame-0 neighbourhood of a node at (px, py), posed per incident segment.

    Segment s's band ``bands[s]`` (centred on the node) and the frame-0 image are rotated about the node by
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
                if band_in:
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
                    g = _bilinear(gray0, gx, gy)  # image: replicated border
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
def match_articulated(gray0, px, py, thetas, bands, bg, min_band, h, margin, round_out, cur, r, qx, qy):
    """:func:`articulated_template` of the node at (px, py) in ``gray0``, then :func:`match_node` of it in
    ``cur`` (the search crop, any dtype, centred on (qx, qy) in the frame) within r px, in one call.

    Returns ``(ok, x, y, ncc, fb, s_lk, second, x2, y2, has_second, wsum)``: :func:`match_node`'s results with the
    match (x, y) and the second peak (x2, y2) in frame pixels, and the template weight sum ``wsum``.
    """
    prev, tmpl, wts, wsum = articulated_template(gray0, px, py, thetas, bands, bg, min_band, h, margin, round_out)
    curf = np.empty(cur.shape, np.float32)
    curf[:] = cur
    m = match_node(curf, tmpl, wts, prev, r, h, float(h + margin))
    c = float(h + r)
    return (m[0] != 0, qx + (m[1] - c), qy + (m[2] - c), m[3], m[4], m[5], m[6], qx + (m[7] - c), qy + (m[8] - c),
            m[9] != 0, wsum)


@njit(cache=True, nogil=True)
def chromaticity(rgb):
    """(H, W, 2) float32 chromaticity (r, g) = (R, G) / (R + G + B + 0.001) of an (H, W, 3) image, in float32 as
    numpy computes ``img / (img.sum(axis=2) + 1e-3)`` on ``rgb.astype(np.float32)`` (the three-term sum of integer
    levels is exact in any order)."""
    H, W = rgb.shape[0], rgb.shape[1]
    out = np.empty((H, W, 2), np.float32)
    eps = np.float32(1e-3)
    for y in range(H):
        for x in range(W):
            r = np.float32(rgb[y, x, 0])
            g = np.float32(rgb[y, x, 1])
            s = (r + g + np.float32(rgb[y, x, 2])) + eps
            out[y, x, 0] = r / s
            out[y, x, 1] = g / s
    return out


@njit(cache=True, nogil=True)
def chroma_mask(chroma, med, spread, limit):
    """(H, W) float32: 1 where the normalised chromaticity distance sqrt(sum(((c - med) / spread)^2)) is below
    ``limit``, else 0 -- in float32, as numpy computes it for float32 ``chroma``, ``med`` and ``spread``."""
    H, W = chroma.shape[0], chroma.shape[1]
    out = np.empty((H, W), np.float32)
    m0, m1, s0, s1 = np.float32(med[0]), np.float32(med[1]), np.float32(spread[0]), np.float32(spread[1])
    lim = np.float32(limit)
    for y in range(H):
        for x in range(W):
            d0 = (chroma[y, x, 0] - m0) / s0
            d1 = (chroma[y, x, 1] - m1) / s1
            dist = np.float32(math.sqrt(np.float32(d0 * d0 + d1 * d1)))
            out[y, x] = 1.0 if dist < lim else 0.0
    return out
