"""Compiled segment search of the default tracker (numba, compiled once and cached; see
:mod:`rce_gtsam.track.match_kernels`): :func:`segment_ncc`, the zero-mean normalised correlation of a segment's
frame-0 strip hinged at its parent, over many rotations at once, and :func:`segment_search`, the best rotation
refined by a parabola and the child's position there. Positions in pixels, angles in radians.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _angle_ncc(src, W, ox0, oy0, x0, y0, ca, sa, uu, vv, strip, round_out, cu, su):
    """:func:`segment_ncc` at one rotation (``ca``, ``sa``: its float32 cosine and sine) from the flat float64 disc
    ``src`` of :func:`_disc` (row length W, pixel (x, y) of the image at ``(y - oy0) * W + x - ox0``): every bilinear
    tap lies in it, the image's border replicated there, so no per-tap border handling or conversion. ``cu``, ``su``:
    (U,) float32 scratch."""
    V, U = vv.shape[0], uu.shape[0]
    fx0, fy0 = np.float32(x0), np.float32(y0)
    one, uw = np.uint64(1), np.uint64(W)  # unsigned flat indices: no negative-index wraparound code per tap
    s1 = s2 = d = 0.0
    for iu in range(U):  # the same float32 products as in the loop below, computed once per angle
        cu[iu] = ca * uu[iu]
        su[iu] = sa * uu[iu]
    for iv in range(V):
        v = vv[iv]
        sv = sa * v
        cv = ca * v
        for iu in range(U):
            # in the disc's own pixels, where every tap is >= 0: int() is floor, and the shift by whole pixels is
            # exact, so the weights are those of the image's own coordinates
            mx = float((cu[iu] - sv) + fx0) - ox0
            my = float((su[iu] + cv) + fy0) - oy0
            ix, iy = int(mx), int(my)
            fx, fy = mx - ix, my - iy
            o = np.uint64(iy * W + ix)
            p = ((1 - fx) * (1 - fy) * src[o] + fx * (1 - fy) * src[o + one]
                 + (1 - fx) * fy * src[o + uw] + fx * fy * src[o + uw + one])
            if round_out:
                p = math.floor(p + 0.5)
            p -= 128.0
            s1 += p
            s2 += p * p
            d += p * strip[iv, iu]
    return d / (math.sqrt(max(s2 - s1 * s1 / (V * U), 0.0)) + 1e-6)


@njit(cache=True, nogil=True)
def _disc(img, x0, y0, uu, vv):
    """The square a strip hinged at (x0, y0) sweeps (with a 2-px margin), copied once as float64, the image's border
    replicated where it reaches over the edge (as ``bilinear`` does per tap): ``(flat disc, row length, x0 of the
    disc, y0 of the disc)``."""
    H, W = img.shape
    reach = 0.0  # farthest sample from (x0, y0)
    for iu in range(uu.shape[0]):
        for iv in range(vv.shape[0]):
            reach = max(reach, math.sqrt(float(uu[iu]) ** 2 + float(vv[iv]) ** 2))
    ox0, oy0 = int(math.floor(x0 - reach - 2)), int(math.floor(y0 - reach - 2))
    ww = int(math.ceil(x0 + reach + 2)) + 2 - ox0
    hh = int(math.ceil(y0 + reach + 2)) + 2 - oy0
    loc = np.empty(hh * ww)
    for y in range(hh):
        yy = min(max(oy0 + y, 0), H - 1)
        for x in range(ww):
            loc[y * ww + x] = img[yy, min(max(ox0 + x, 0), W - 1)]
    return loc, ww, ox0, oy0


@njit(cache=True, nogil=True)
def segment_ncc(img, x0, y0, ex, ey, uu, vv, strip, round_out):
    """Zero-mean NCC of the frame-0 ``strip`` (V, U; zero mean, unit norm) with ``img`` sampled along each
    rotation a: point (u, v) of the strip at (x0, y0) + u (ex[a], ey[a]) + v (-ey[a], ex[a]) px.

    Sampling as ``cv2.remap(..., INTER_LINEAR, BORDER_REPLICATE)`` (OpenCV 5) with float32 maps: bilinear at
    the float32 positions, rounded to integers when ``round_out`` (a uint8 image). Returns (A,) NCC.
    """
    A, U = ex.shape[0], uu.shape[0]
    out = np.empty(A)
    loc, ww, ox0, oy0 = _disc(img, x0, y0, uu, vv)
    cu = np.empty(U, np.float32)
    su = np.empty(U, np.float32)
    for a in range(A):
        out[a] = _angle_ncc(loc, ww, ox0, oy0, x0, y0, ex[a], ey[a], uu, vv, strip, round_out, cu, su)
    return out


@njit(cache=True, nogil=True)
def _evaluate(idx, ncc, done, phis, a0, loc, ww, ox0, oy0, xp, yp, uu, vv, strip, round_out, cu, su):
    """``ncc[a]`` for every rotation index a in ``idx`` not ``done`` yet (see :func:`segment_search`)."""
    for a in idx:
        if done[a]:
            continue
        ang = a0 + phis[a]
        ca, sa = np.float32(math.cos(ang)), np.float32(math.sin(ang))
        ncc[a] = _angle_ncc(loc, ww, ox0, oy0, xp, yp, ca, sa, uu, vv, strip, round_out, cu, su)
        done[a] = True


@njit(cache=True, nogil=True)
def segment_search(img, xp, yp, phi_prev, offs, a0, step, v0x, v0y, uu, vv, strip, round_out, stride=3):
    """The segment search of ``LKTracker._segment_search`` in one call: the best of :func:`segment_ncc` over the
    rotations ``phi_prev + offs`` (radians since frame 0; ``a0`` = the segment's frame-0 direction) hinged at
    (xp, yp), refined by a parabola through its neighbours (``step`` apart), and the child there.

    Coarse to fine: the correlation is evaluated at every ``stride``-th rotation (and the last), then from each of
    the two best local maxima of those it climbs on the full grid (all rotations within ``stride`` of the current
    best, until none is better), keeps the better of the two peaks (the first on a tie), and looks once more at twice
    that reach around it (a double peak a few rotations apart), climbing again if something there is better. The
    strip's correlation changes smoothly with its rotation (``step`` moves the child by half a pixel; at ``stride`` 3
    the coarse grid moves it by 1.5 px, under the width of a stem), so this finds the exhaustive search's peak with
    a little over half of its samples. Measured against the exhaustive search (``stride`` 1) on every search the
    tracker made on rendered clip 0 (600 frames, 20 nodes; ``benchmarks/bench_track.py``'s): 1 of 10811 differs,
    between two peaks of correlation 0.38, below ``min_ncc``, which the tracker does not use; on 4000 searches each
    of that clip and plant 2's footage, 1 and 0 differ (the same kind).

    Returns ``(x, y, phi, ncc)``: the child's position (px; frame-0 segment vector (v0x, v0y) rotated by phi from
    the hinge), the rotation and the correlation peak.
    """
    A = offs.shape[0]
    stride = max(int(stride), 1)
    phis = np.empty(A)
    for a in range(A):
        phis[a] = phi_prev + offs[a]
    ncc = np.full(A, -np.inf)
    done = np.zeros(A, np.bool_)
    loc, ww, ox0, oy0 = _disc(img, xp, yp, uu, vv)
    cu = np.empty(uu.shape[0], np.float32)
    su = np.empty(uu.shape[0], np.float32)
    coarse = np.arange(0, A, stride)
    _evaluate(coarse, ncc, done, phis, a0, loc, ww, ox0, oy0, xp, yp, uu, vv, strip, round_out, cu, su)
    _evaluate(np.array([A - 1]), ncc, done, phis, a0, loc, ww, ox0, oy0, xp, yp, uu, vv, strip,
              round_out, cu, su)
    k1 = k2 = -1  # the two best coarse local maxima
    for a in range(A):
        if not done[a]:
            continue
        peak = True
        for b in (a - stride, a + stride):
            b = min(max(b, 0), A - 1)
            if b != a and done[b] and ncc[b] > ncc[a]:
                peak = False
        if peak:
            if k1 < 0 or ncc[a] > ncc[k1]:
                k2, k1 = k1, a
            elif k2 < 0 or ncc[a] > ncc[k2]:
                k2 = a
    k = -1
    for start in (k1, k2):
        if start < 0:
            continue
        c = start
        while True:  # climb on the full grid
            lo, hi = max(c - stride, 0), min(c + stride, A - 1)
            _evaluate(np.arange(lo, hi + 1), ncc, done, phis, a0, loc, ww, ox0, oy0, xp, yp, uu, vv,
                      strip, round_out, cu, su)
            best = lo
            for a in range(lo, hi + 1):
                if ncc[a] > ncc[best]:
                    best = a
            if best == c or ncc[best] == ncc[c]:
                break
            c = best
        if k < 0 or ncc[c] > ncc[k] or (ncc[c] == ncc[k] and c < k):
            k = c
    k = max(k, 0)
    # a peak of nearly the same height a few rotations away (a double peak) that both climbs missed: look at
    # twice the climbing reach around the winner and climb again
    while True:
        lo, hi = max(k - 2 * stride, 0), min(k + 2 * stride, A - 1)
        _evaluate(np.arange(lo, hi + 1), ncc, done, phis, a0, loc, ww, ox0, oy0, xp, yp, uu, vv,
                  strip, round_out, cu, su)
        best = k
        for a in range(lo, hi + 1):
            if ncc[a] > ncc[best] or (ncc[a] == ncc[best] and a < best):
                best = a
        if best == k:
            break
        k = best
    dk = 0.0
    if 0 < k < A - 1:  # both neighbours were evaluated by the climb
        a_, b_, c_ = ncc[k - 1], ncc[k], ncc[k + 1]
        den = a_ - 2 * b_ + c_
        if not den >= 0:
            dk = 0.5 * (a_ - c_) / den
            dk = -0.5 if dk < -0.5 else dk  # Python's max(dk, -0.5), min(., 0.5)
            dk = 0.5 if 0.5 < dk else dk
    phi = phis[k] + dk * step
    ct, sn = math.cos(phi), math.sin(phi)
    return xp + (ct * v0x - sn * v0y), yp + (sn * v0x + ct * v0y), phi, ncc[k]
