"""Compiled segment search of the default tracker (numba, compiled once and cached; see
:mod:`rce_gtsam.track.match_kernels`): :func:`segment_ncc`, the zero-mean normalised correlation of a segment's
frame-0 strip hinged at its parent, over many rotations at once, and :func:`segment_search`, the best rotation
refined by a parabola and the child's position there. Positions in pixels, angles in radians.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .kernels_sampling import bilinear

#: sha256 (first 16 hex digits) of each kernel file this module's compiled functions call into. numba's cache
#: checks only a function's own file (numba issue 1833), so an edit there must change this file too, or its
#: cached kernels keep the old code; ``tests/test_track_kernels.py`` checks the digests.
CALLS_INTO = {"kernels_sampling.py": "902913666eddb75f"}


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
                p = bilinear(img, float((cu[iu] - sv) + fx0), float((su[iu] + cv) + fy0))
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
