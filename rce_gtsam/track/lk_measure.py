"""The default tracker's measurements: a node against its frame-0 appearance (articulated template or rotated
patch; the compiled kernels of :mod:`~rce_gtsam.track.match_kernels`), the hinged segment search, the refinement
pass, and the recent-template match; plus the small geometry they share.

:class:`Measurement` is a part of :class:`~rce_gtsam.track.lk.LKTracker` (a mixin reading what
:class:`~rce_gtsam.track.lk_frame0.Frame0Setup` set up and ``self._kernels``). Positions in pixels (pixel centres
at integers), angles in radians, correlations dimensionless, sigmas in pixels.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

#: distances between frame-0 matches and hinged segment searches needed for ``LKConfig.segment_check`` (a median of
#: 200 values is within ~9 % of the population's: its relative standard error is ~1.25 / sqrt(n)).
_SEG_CHECK_MIN = 200


def f2f_ncc(prev_gray: np.ndarray, gray: np.ndarray, a, b, h: int) -> float:
    """Normalised correlation of the (2h+1)^2 patch of ``prev_gray`` at ``a`` with that of ``gray`` at ``b``
    (px; sub-pixel crops): whether frame-to-frame LK followed the same appearance (a node covered by a leaf or a
    blank patch correlates poorly). 0 for a flat patch."""
    size = (2 * h + 1, 2 * h + 1)
    pa = cv2.getRectSubPix(prev_gray, size, (float(a[0]), float(a[1])), patchType=cv2.CV_32F).ravel()
    pb = cv2.getRectSubPix(gray, size, (float(b[0]), float(b[1])), patchType=cv2.CV_32F).ravel()
    pa, pb = pa - pa.mean(), pb - pb.mean()
    den = math.sqrt(float(pa @ pa) * float(pb @ pb))
    return float(pa @ pb) / den if den > 1e-6 else 0.0


def _rotation_about(cx: float, cy: float, theta: float, dx: float, dy: float) -> np.ndarray:
    """2x3 affine matrix: rotation by ``theta`` (radians, image frame) about (cx, cy), then a shift (dx, dy) px.

    ``cv2.getRotationMatrix2D((cx, cy), -degrees(theta), 1)`` with (dx, dy) added to its last column.
    """
    a, b = math.cos(theta), -math.sin(theta)
    return np.array([[a, b, (1 - a) * cx - b * cy + dx], [-b, a, b * cx + (1 - a) * cy + dy]])


def turn(a, b, ang0: float) -> float:
    """Rotation (radians, wrapped to (-pi, pi]) of the vector a->b relative to the direction ``ang0`` (radians,
    ``atan2`` of the frame-0 vector: ``LKTracker._ang0``)."""
    d = math.atan2(b[1] - a[1], b[0] - a[0]) - ang0
    return (d + math.pi) % (2 * math.pi) - math.pi


class Measurement:
    """Measurement methods of :class:`~rce_gtsam.track.lk.LKTracker` (see the module docstring)."""

    def _segment_search(self, gray, xp, p, c, q0, phi_prev):
        """Rotation of segment (p, c) found by matching its frame-0 strip around the parent at ``xp``.

        The segment is a rigid body hinged at its parent: the child can only be on a circle of radius L0
        around the parent, so a 1-D search over the segment's rotation (within atan(2h / L0) of its previous
        rotation: the child moves at most ~2 patch radii relative to the parent per frame, the same bound as
        the re-acquisition window; steps of half a pixel at the child) finds it with the whole segment's
        texture, and cannot slide along a self-similar stem the way a 2-D search around the node can.
        Returns (predicted child position, rotation, zero-mean NCC) or None.
        """
        item = self._strip.get((p, c))
        if item is None:
            return None
        uu, vv, st0, offs, a0, step, v0x, v0y = item
        x, y, phi, ncc = self._kernels.segment_search(gray, float(xp[0]), float(xp[1]), phi_prev, offs, a0, step,
                                                      v0x, v0y, uu, vv, st0, gray.dtype == np.uint8)
        return (x, y), phi, ncc

    def _rotation(self, i: int, est: np.ndarray, vis: np.ndarray, q0: np.ndarray, last: np.ndarray,
                  now: np.ndarray, done: np.ndarray) -> float:
        """Rotation (radians, image frame) of node i's neighbourhood since frame 0.

        Measured from node i and its baseline partner when both are visible; otherwise borrowed from the
        parent's rotation in this frame (a lost node turns with the branch it hangs on), else the last value.
        """
        j = self.partner[i]
        if j < 0:
            return 0.0
        if vis[i] and vis[j]:
            a = est[j] - est[i]
            b = q0[j] - q0[i]
            last[i] = math.atan2(a[1], a[0]) - math.atan2(b[1], b[0])
            return float(last[i])
        p = self.parent[i]
        if p >= 0 and done[p]:
            return float(now[p])
        return float(last[i])

    def _anchor(self, gray0, gray, i, p0, q, theta, r, thetas=None):
        """Locate node i (frame-0 position p0) near q in ``gray`` within r px, with its frame-0 appearance posed
        for this frame: articulated (see ``_node_stack``; ``thetas``: the rotations of its incident segments since
        frame 0, radians, in ``self._inc[i]``'s order) with branch bands, else the whole frame-0 patch rotated by
        ``theta``.

        Returns (xy, ncc, fb, sigma, second-peak ncc, template weight sum, second-peak xy) or None.
        """
        h = self.h
        k = 2 * (h + r) + 1
        # the frame-0 crop is only searched by the backward LK, which starts at its centre: a margin of
        # ``_rematch_radius`` px around the template suffices, whatever the search radius r in this frame
        margin = self._margin
        px, py = float(p0[0]), float(p0[1])
        qx, qy = float(q[0]), float(q[1])
        cur = cv2.getRectSubPix(gray, (k, k), (qx, qy))
        stack = self._stacks[i] if self._band is not None and thetas else None
        if stack is not None:
            ok, x, y, score, fb, s_lk, second, x2, y2, has2, wsum = self._kernels.match_articulated(
                gray0, px, py, np.array(thetas), *stack, h, margin, gray0.dtype == np.uint8, cur, r, qx, qy)
            if not ok:
                return None
            return (x, y), score, fb, s_lk, second, wsum, ((x2, y2) if has2 else None)
        c = float(h + r)
        cp = float(h + margin)
        kp = 2 * (h + margin) + 1
        prev = cv2.warpAffine(gray0, _rotation_about(px, py, theta, cp - px, cp - py), (kp, kp),
                              flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).astype(np.float32)
        tmpl = np.ascontiguousarray(prev[margin:margin + 2 * h + 1, margin:margin + 2 * h + 1])
        wsum = float(tmpl.size)
        m = self._kernels.match_node(cur.astype(np.float32), tmpl, np.ones_like(tmpl), prev, r, h, cp)
        if not m[0]:
            return None
        return ((qx + (m[1] - c), qy + (m[2] - c)), m[3], m[4], m[5], m[6], wsum,
                ((qx + (m[7] - c), qy + (m[8] - c)) if m[9] else None))

    def _refine_thetas(self, i, est, vis) -> list:
        """The rotations since frame 0 (radians) of node i's incident segments, in ``self._inc[i]``'s order, from
        the positions ``est`` (P, 2) px: the parent segment's, then each child's (a child not visible in ``vis``
        is taken to continue its parent segment)."""
        p, ang0 = self.parent[i], self._ang0
        tp = turn(est[p], est[i], ang0[i]) if p >= 0 else 0.0
        thetas = [tp] if p >= 0 else []
        for ch in self.children[i]:
            thetas.append(turn(est[i], est[ch], ang0[ch]) if vis[ch] else tp)
        return thetas

    def _refine_node(self, gray0, gray, q0, i, est, vis, fb_max):
        """Re-match of visible node i with segment rotations from ``est`` (this frame's matches; the nodes before
        i in ``self.order`` already re-matched): ``(xy, sigma px)``, or None when the re-match fails (no match,
        correlation below ``min_ncc`` or forward-backward error above ``fb_max``)."""
        cfg = self.config
        m = self._anchor(gray0, gray, i, q0[i], est[i], 0.0, self._margin, self._refine_thetas(i, est, vis))
        if m is not None and m[1] >= cfg.min_ncc and m[2] <= fb_max:
            xy, _, fb, s_lk = m[:4]
            return xy, math.sqrt(s_lk ** 2 + (fb / 2) ** 2 + cfg.sigma_floor_px ** 2)
        return None

    def _keep_recent(self, gray, est, sig, anchored, recent) -> None:
        """Store, for every node anchored to its frame-0 template in this frame, the (2(h + margin) + 1)^2 crop of
        ``gray`` centred on its position, the position and its sigma (``recent``, in place)."""
        kp = 2 * (self.h + self._margin) + 1
        for i in np.flatnonzero(anchored):
            x, y = float(est[i, 0]), float(est[i, 1])
            recent[i] = (cv2.getRectSubPix(gray, (kp, kp), (x, y)).astype(np.float32), (x, y), float(sig[i]))

    def _match_recent(self, gray, rec, pred, r, fb_max, i, est, vis):
        """Match node i's last frame-0-anchored appearance ``rec`` (see ``_keep_recent``) within r px of ``pred``
        in ``gray``: the same correlation search, Lucas-Kanade refinement and forward-backward check as a frame-0
        match, on the whole patch. Returns (xy, sigma px) when it passes ``min_ncc``, the forward-backward limit,
        the distinctness test of a re-acquisition (``distinct_sigmas``) and the segment-length check, else None."""
        cfg, h, margin = self.config, self.h, self._margin
        prev = rec[0]
        tmpl = np.ascontiguousarray(prev[margin:margin + 2 * h + 1, margin:margin + 2 * h + 1])
        k = 2 * (h + r) + 1
        qx, qy = float(pred[0]), float(pred[1])
        cur = cv2.getRectSubPix(gray, (k, k), (qx, qy)).astype(np.float32)
        m = self._kernels.match_node(cur, tmpl, np.ones_like(tmpl), prev, r, h, float(h + margin))
        if not m[0] or m[3] < cfg.min_ncc or m[4] > fb_max:
            return None
        if m[9] and m[6] > m[3] - cfg.distinct_sigmas / math.sqrt(tmpl.size):
            return None
        c = float(h + r)
        xy = np.array([qx + (m[1] - c), qy + (m[2] - c)])
        if not self._length_ok(i, xy, est, vis):
            return None
        return xy, math.sqrt(m[5] ** 2 + (m[4] / 2) ** 2)

    def _segment_check(self, vis, sig, how, seg_d, counts) -> None:
        """``LKConfig.segment_check`` on the whole clip, in place: (P, F) ``vis``, ``sig`` (px) and ``how`` of the
        tracker's result; ``seg_d`` (P, F) the distance (px) between each accepted frame-0 match and its hinged segment
        search's position (NaN where there is none).

        The bound is calibrated on the clip: the distances taken as the length of a 2-D Gaussian difference
        (Rayleigh: sigma = median / 1.1774), the bound is the distance 99 % of such differences stay below,
        ``3.035 sigma`` (sqrt of chi2_2's 99th percentile). Nothing happens with fewer than ``_SEG_CHECK_MIN``
        distances. Beyond the bound, at a position still found by its frame-0 match (``HOW`` 0), the node keeps its
        match with sigma^2 + (d - bound)^2 / 2 (``HOW`` 4): which of the two is wrong is not known (see
        ``LKConfig.segment_check``).
        """
        ok = np.isfinite(seg_d)
        if ok.sum() < _SEG_CHECK_MIN:
            return
        bound = 3.035 * float(np.median(seg_d[ok])) / 1.1774
        self.segment_check_px = bound
        flag = ok & vis & (how == 0) & (np.where(ok, seg_d, 0.0) > bound)
        counts["segment_check"] += int(flag.sum())
        sig[flag] = np.sqrt(sig[flag] ** 2 + (seg_d[flag] - bound) ** 2 / 2)
        how[flag] = 4

    def _length_ok(self, i: int, xy, est, vis) -> bool:
        """Whether ``xy`` for node i keeps the segment to its parent (when the parent is visible) within the
        stretch limits of ``LKConfig`` (``max_stretch``, ``min_length_fraction``, ``length_tol_px``)."""
        p, cfg = self.parent[i], self.config
        if p < 0 or not vis[p]:
            return True
        d = math.hypot(xy[0] - est[p, 0], xy[1] - est[p, 1])
        l0 = self.rest_len[i]
        return (cfg.min_length_fraction * l0 - cfg.length_tol_px <= d
                <= (1 + cfg.max_stretch) * l0 + cfg.length_tol_px)

    def _refine(self, gray0, gray, q0, est, vis, fb_max, first_done=None):
        """Second pass: re-match every visible node with segment rotations from this frame's matches.

        In the first pass a node's articulated template is rotated with angles measured partly from
        frame-to-frame predictions, which lag the true motion (the pyramidal LK window contains static
        background). Matches are far more accurate, so the rotations are recomputed from them and each node
        is matched again within a small radius (max(2, h // 4) px: the first pass is already within a pixel).

        ``est``/``vis``: the first pass's (P, 2) positions and (P,) visibility, only read. ``first_done(k)``
        (threaded, the first pass still running) returns once the first pass has finished the first k nodes of
        ``self.order``. Node i is re-matched once the first pass has finished it, its parent and its children;
        it reads the re-matched position of the nodes before it in ``self.order`` and the first pass's of the
        others: what a pass run after the whole first pass reads. Returns ``{node: (xy, sigma px) or None}``
        for the visible nodes (None: the re-match failed; see ``_apply_refine``).
        """
        cur = est.copy()
        out = {}
        for k, i in enumerate(self.order):
            reads = self._refine_reads[k]  # nodes the re-match of i reads that this pass has not reached yet
            if first_done is not None:
                first_done(self._refine_needs[k])
                cur[reads] = est[reads]
            if not vis[i]:
                continue
            r = out[i] = self._refine_node(gray0, gray, q0, i, cur, vis, fb_max)
            if r is not None:
                cur[i] = r[0]
        return out

    def _apply_refine(self, out, est, vis, sig, pred, counts, borrowed) -> None:
        """Write the refinement pass's results ``out`` (see ``_refine``) into ``est``, ``vis`` and ``sig``.

        With ``LKConfig.refine_consistency``, a node found in the wide window in this frame (``borrowed``: no
        frame-to-frame or segment prediction, so its first-pass template was posed with the rotation borrowed
        from its parent, not measured) whose re-match failed (the template posed as the match itself implies
        does not fit there) is marked invisible at ``pred`` (its first-pass prediction).
        """
        rejected = []
        for i in self.order:
            r = out.get(i, False)
            if r is False:
                continue
            if r is not None:
                est[i], sig[i] = r
            elif self.config.refine_consistency and borrowed[i]:
                rejected.append(i)
        for i in rejected:  # after the pass: a child's re-match is posed from its parent's match, not moved
            vis[i] = False
            est[i] = pred[i]
            sig[i] = float(self.h)
            counts["rejected_refine"] += 1
