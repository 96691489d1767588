"""The default tracker's first pass at one node in one frame: predict, match against frame 0, decide visibility,
and the fallbacks (hinged segment, recent template, hold) -- steps 1-3b of :mod:`rce_gtsam.track.lk`.

:class:`FirstPassFrame` carries the frame's arrays between :meth:`~rce_gtsam.track.lk.LKTracker.track` and
:meth:`NodeDecision._first_pass_node`; every array in it is written in place (node by node, in ``order``), never
replaced. Positions in pixels, angles in radians, sigmas in pixels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .lk_measure import f2f_ncc, turn


@dataclass(eq=False)
class FirstPassFrame:
    """One frame of the first pass (P nodes). Images: ``gray0`` frame 0 and ``ga`` this frame in the anchor image
    (``LKConfig.anchor_highpass_px``), ``gray`` / ``prev_gray`` this and the previous frame in grey. ``q0`` (P, 2)
    frame-0 positions. Frame-to-frame LK: ``f2f`` (P, 2) positions, ``f2f_ok`` (P,) round trip passed, ``fb_f2f``
    (P,) its forward-backward error (px). ``prev_est``/``prev_vis`` the previous frame's result; ``new_est``,
    ``new_vis``, ``sig`` this frame's (written); ``done``, ``cur_vis`` (merged visibility), ``theta_now``
    (rotations), ``preds`` (predictions), ``wide`` (searched in the wide window), ``anchored_now`` (anchored well
    enough to store a recent template), ``how`` (a key of ``HOW``). Carried over frames (also written):
    ``theta_last``, ``seg_rot``, ``bend_rot`` (radians), ``held`` (frames held), ``recent`` (recent templates),
    ``counts``. ``sig_prev`` the previous frame's sigmas; ``fb_max``, ``hold_max`` limits (px); ``first`` the
    refinement thread's progress (None without it). ``seg_d`` (P,): where a node's frame-0 match was accepted and its
    hinged segment search matched at >= ``min_segment_ncc``, the distance between the two (px; NaN elsewhere;
    written); None without ``LKConfig.segment_check``."""

    gray0: np.ndarray
    ga: np.ndarray
    gray: np.ndarray
    prev_gray: np.ndarray
    q0: np.ndarray
    f2f: np.ndarray
    f2f_ok: np.ndarray
    fb_f2f: np.ndarray
    prev_est: np.ndarray
    prev_vis: np.ndarray
    new_est: np.ndarray
    new_vis: np.ndarray
    sig: np.ndarray
    done: np.ndarray
    cur_vis: np.ndarray
    theta_now: np.ndarray
    preds: np.ndarray
    wide: np.ndarray
    anchored_now: np.ndarray
    how: np.ndarray
    theta_last: np.ndarray
    seg_rot: np.ndarray
    bend_rot: np.ndarray
    held: np.ndarray
    recent: list
    counts: dict
    sig_prev: np.ndarray
    fb_max: float
    hold_max: float
    first: object = None
    seg_d: np.ndarray | None = None


class NodeDecision:
    """The first pass's per-node step of :class:`~rce_gtsam.track.lk.LKTracker` (see the module docstring)."""

    def _first_pass_node(self, fr: FirstPassFrame, i: int) -> None:
        """Node i in this frame: its prediction, frame-0 match and the checks of ``LKConfig``, else a fallback, else
        invisible at the prediction; writes ``fr``'s arrays at i (see :mod:`rce_gtsam.track.lk`, steps 1-3b)."""
        cfg, h, ang0 = self.config, self.h, self._ang0
        gray0, ga, gray, prev_gray, q0 = fr.gray0, fr.ga, fr.gray, fr.prev_gray, fr.q0
        f2f, f2f_ok, fb_f2f, prev_est, prev_vis = fr.f2f, fr.f2f_ok, fr.fb_f2f, fr.prev_est, fr.prev_vis
        new_est, new_vis, sig, done, cur_vis = fr.new_est, fr.new_vis, fr.sig, fr.done, fr.cur_vis
        theta_now, preds, wide, anchored_now, how = fr.theta_now, fr.preds, fr.wide, fr.anchored_now, fr.how
        theta_last, seg_rot, bend_rot, held, recent = fr.theta_last, fr.seg_rot, fr.bend_rot, fr.held, fr.recent
        counts, sig_prev, fb_max, hold_max, first = fr.counts, fr.sig_prev, fr.fb_max, fr.hold_max, fr.first
        theta = self._rotation(i, new_est, cur_vis, q0, theta_last, theta_now, done)
        theta_now[i] = theta
        p = self.parent[i]
        seg = None
        if p >= 0 and new_vis[p] and self._band is not None:
            # a node lost in the last frame has not been measured while the whole branch kept
            # swinging: its segment turned with the parent's (the bend changes slowly, the
            # sway does not), so search around the parent's rotation plus the last bend
            phi_prev = seg_rot[i] if prev_vis[i] else seg_rot[p] + bend_rot[i]
            seg = self._segment_search(ga, new_est[p], p, i, q0, phi_prev)
        if seg is not None and seg[2] >= cfg.min_ncc:
            pred, r = seg[0], h
            counts["predicted_from_segment"] += 1
        elif f2f_ok[i] and prev_vis[i]:
            pred, r = f2f[i], h
        elif p >= 0:
            ct, sn = math.cos(theta), math.sin(theta)
            v0 = q0[i] - q0[p]
            pred = new_est[p] + np.array([ct * v0[0] - sn * v0[1], sn * v0[0] + ct * v0[1]])
            r = 2 * h
            counts["predicted_from_graph"] += 1
        else:
            pred, r = (f2f[i] if f2f_ok[i] else prev_est[i]), 2 * h
        thetas = None  # rotations of the segments at node i (``self._inc[i]``)
        if self._band is not None:
            tp = turn(new_est[p], pred, ang0[i]) if p >= 0 else theta
            thetas = [tp] if p >= 0 else []
            for ch in self.children[i]:
                # a child not followed: assume the branch continues straight
                thetas.append(turn(pred, f2f[ch], ang0[ch]) if f2f_ok[ch] and prev_vis[ch] else tp)
        # a wide search (no frame-to-frame or segment prediction to trust) is a re-acquisition
        # whatever the previous frame said: the same ambiguity and geometry checks apply
        reacquiring = not prev_vis[i] or r > h or held[i] > 0
        preds[i], wide[i] = pred, r > h
        m = self._anchor(gray0, ga, i, q0[i], pred, theta, r, thetas)
        ok = m is not None
        soft = False  # rejected only by the forward-backward, parent or length check (``LKConfig.soft_reject``)
        if not ok:
            counts["lost_match"] += 1
        else:
            xy, score, fb, s_lk, second, n_eff, xy2 = m
            ambiguous = second > score - cfg.distinct_sigmas / math.sqrt(n_eff)
            if score < cfg.min_ncc:
                ok = False
                counts["rejected_ncc"] += 1
            elif (cfg.distinct_reacquire and reacquiring and ambiguous
                  and not (cfg.segment_tiebreak and seg is not None and seg[2] >= cfg.min_segment_ncc
                           and xy2 is not None
                           and math.hypot(xy[0] - seg[0][0], xy[1] - seg[0][1]) <= h / 2
                           < math.hypot(xy2[0] - seg[0][0], xy2[1] - seg[0][1]))):
                # two indistinguishable peaks, unless the whole segment strip, hinged at the
                # visible parent, matched well (``min_segment_ncc``) and points at the best one
                # (within h/2) and not at the other: the strip's many pixels break the tie
                ok = False
                counts["rejected_ambiguous"] += 1
            elif (cfg.distinct_follow and ambiguous and xy2 is not None
                  and math.hypot(xy2[0] - pred[0], xy2[1] - pred[1])
                  < math.hypot(xy[0] - pred[0], xy[1] - pred[1])):
                # followed (not re-acquired), two indistinguishable peaks, and the prediction
                # points at the other one: which of the two the node is would be a guess
                ok = False
                counts["rejected_ambiguous"] += 1
            elif fb > fb_max:
                ok, soft = False, True
                counts["rejected_fb"] += 1
            elif p >= 0 and reacquiring and not new_vis[p]:
                # re-acquiring while the parent is lost too: nothing checks the match's
                # geometry (a tip re-found next to a leaf edge 18 px off, then followed
                # to 67 px, on simulator seed 0); wait until the parent is seen again
                ok, soft = False, True
                counts["rejected_unanchored"] += 1
            elif p >= 0 and new_vis[p]:
                d = math.hypot(xy[0] - new_est[p, 0], xy[1] - new_est[p, 1])
                l0 = self.rest_len[i]
                if d > (1 + cfg.max_stretch) * l0 + cfg.length_tol_px or d < cfg.min_length_fraction * l0 - cfg.length_tol_px:
                    ok, soft = False, True
                    counts["rejected_length"] += 1
        if ok and fr.seg_d is not None and seg is not None and seg[2] >= cfg.min_segment_ncc:
            # for ``LKConfig.segment_check`` (after the clip, :meth:`_segment_check`): this match against the
            # hinged segment search's position, two measurements of the node from different pixels
            fr.seg_d[i] = math.hypot(xy[0] - seg[0][0], xy[1] - seg[0][1])
        if ok:
            new_est[i], new_vis[i] = xy, True
            how[i] = 0
            anchored_now[i] = score >= cfg.recent_min_ncc
            if p >= 0:
                seg_rot[i] = turn(new_est[p], xy, ang0[i])
                if new_vis[p]:
                    bend_rot[i] = seg_rot[i] - seg_rot[p]
            sig[i] = math.sqrt(s_lk ** 2 + (fb / 2) ** 2 + cfg.sigma_floor_px ** 2)
            counts["anchored"] += 1
            held[i] = 0
        elif ((cfg.segment_fallback or (cfg.tip_segment_fallback and i in self._tips))
              and seg is not None and seg[2] >= cfg.min_segment_ncc
              ):
            # the node's own patch failed (a leaf over the joint, a template spoiled by a leaf in
            # frame 0) but its whole segment matched well, hinged at a measured parent: the node is
            # where the rigid segment puts it. sigma: the half-pixel angular search step at the
            # child on top of the parent's own uncertainty.
            new_est[i], new_vis[i] = seg[0], True
            sig[i] = math.sqrt(sig[p] ** 2 + 0.5 ** 2)
            seg_rot[i] = seg[1]
            counts["from_segment"] += 1
            how[i] = 3
        elif (cfg.soft_reject and soft
              and (s_soft := math.sqrt(s_lk ** 2 + (fb / 2) ** 2 + cfg.fallback_sigma_px ** 2)) <= hold_max):
            # a distinct frame-0 match above ``min_ncc`` that failed only the forward-backward, parent or length
            # check is mostly right (see ``LKConfig.soft_reject``): keep it with a sigma of at least
            # ``fallback_sigma_px``; finding the node next frame counts as a re-acquisition (strict checks)
            new_est[i], new_vis[i], sig[i] = xy, True, s_soft
            if p >= 0:
                seg_rot[i] = turn(new_est[p], xy, ang0[i])
            held[i] += 1
            counts["soft"] += 1
            how[i] = 4
        elif (cfg.recent_template and recent[i] is not None and r <= h and i not in self._tips
              and (rm := self._match_recent(gray, recent[i], pred, r, fb_max, i, new_est, new_vis))
              is not None):
            # the frame-0 template does not fit, but the node's appearance in the last frame it was
            # anchored to frame 0 does: measured against that frame, so its error is that anchor's
            # plus this match's (no accumulation while the node stays off its frame-0 template)
            new_est[i], new_vis[i] = rm[0], True
            sig[i] = math.sqrt(recent[i][2] ** 2 + rm[1] ** 2 + cfg.fallback_sigma_px ** 2)
            if p >= 0:
                seg_rot[i] = turn(new_est[p], rm[0], ang0[i])
            held[i] += 1  # off its frame-0 template: finding it there again is a re-acquisition
            counts["recent_template"] += 1
            how[i] = 1
        elif (cfg.hold and f2f_ok[i] and prev_vis[i] and (p < 0 or new_vis[p])
              and (s_hold := math.sqrt(max(sig_prev[i], cfg.fallback_sigma_px) ** 2 + (fb_f2f[i] / 2) ** 2
                                       + cfg.hold_step_px ** 2))
              <= hold_max and self._length_ok(i, f2f[i], new_est, new_vis)
              and (p < 0 or (seg is not None and seg[2] >= cfg.min_ncc
                             and math.hypot(*(f2f[i] - seg[0])) <= cfg.hold_agree_px))
              and f2f_ncc(prev_gray, gray, prev_est[i], f2f[i], h) >= cfg.hold_min_ncc):
            # the frame-0 template does not fit here now (blur, a leaf, a pose far from frame 0),
            # but frame-to-frame LK followed the node from a measured (or held) position: keep it
            # visible with a sigma that grows as a random walk (``hold_step_px`` a frame plus the
            # round trip's own error) until the template fits again or sigma passes ``hold_max``
            new_est[i], new_vis[i], sig[i] = f2f[i], True, s_hold
            if p >= 0:
                seg_rot[i] = turn(new_est[p], f2f[i], ang0[i])
            held[i] += 1
            counts["held"] += 1
            how[i] = 2
        else:
            new_est[i], new_vis[i], sig[i] = pred, False, float(r)
            counts["invisible"] += 1
        done[i] = True
        cur_vis[i] = new_vis[i]
        if first is not None:
            first.advance()
