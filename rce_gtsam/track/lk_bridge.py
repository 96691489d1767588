"""The default tracker's bridge step: re-find a lost node between two seen ones (issue 38; see
:mod:`rce_gtsam.track.lk`, step 3c).

In a gust the distal part of a branch swings far from frame 0, and a node lost there is predicted from its parent
alone (the parent's position plus its frame-0 segment vector, turned by a borrowed rotation): along a chain of
lost nodes that prediction compounds every unmeasured bend, and lands 10-20 px off on plant 2, where the wide
search then finds two indistinguishable peaks or none. But a node further down the branch is often still seen
(re-found by its own match, or kept by ``LKConfig.soft_reject``). Between the nearest seen ancestor a and the
nearest seen descendant d, the branch moved, to first order, by the similarity (rotation, scale, shift) that
takes a's and d's frame-0 positions to their positions now (used only when its scale is within the segment-length
limits, ``min_length_fraction`` to ``1 + max_stretch``: a branch foreshortens but does not stretch, so beyond them a
or d is not where the branch is): the lost node is predicted there, its articulated
template turned by that rotation, and it is searched in the narrow window (the patch radius h) with every test of
a re-acquisition: ``min_ncc`` and distinct peaks; the forward-backward limit and the segment length to a seen
parent as ``LKConfig.soft_reject`` treats them (a failure widens sigma, it does not drop the node). A bridged node
is reported with sigma >= ``fallback_sigma_px`` (it was found from its neighbours' motion, not followed: on plant 2
its distance to TAPIR's position had median 1.7 px, p90 3.8 px, against 0.5 / 3.1 px for those failing only the
forward-backward limit), and finding it in the next frame counts as a re-acquisition. Measured over frames 0-359
of plant 2 (477 bridge attempts): the two-sided prediction was median 3.3 px, p90 7.5 px from TAPIR's position;
the match failed its forward LK in 248, ``min_ncc`` in 140 (distance median 4.1 px), distinct peaks in 77
(median 1.9, p90 15 px): those stay lost.

:class:`Bridge` is a mixin of :class:`~rce_gtsam.track.lk.LKTracker`. Positions in pixels, angles in radians.
"""

from __future__ import annotations

import math

import numpy as np

class Bridge:
    """Bridge step of :class:`~rce_gtsam.track.lk.LKTracker` (see the module docstring)."""

    def _seen_descendant(self, i: int, vis: np.ndarray) -> int:
        """The nearest (fewest edges) visible descendant of node i, or -1."""
        level = list(self.children[i])
        while level:
            for c in level:
                if vis[c]:
                    return c
            level = [g for c in level for g in self.children[c]]
        return -1

    def _bridge(self, gray0, ga, q0, est, vis, sig, how, held, counts, fb_max, hold_max) -> None:
        """Re-find each lost node (in graph order) between a seen ancestor and a seen descendant; writes ``est``,
        ``vis``, ``sig``, ``how`` (5) and ``held`` in place for the nodes found. Limits ``fb_max``, ``hold_max``
        (px) as in the first pass."""
        cfg, h = self.config, self.h
        for i in self.order:
            if vis[i]:
                continue
            a = self.parent[i]
            while a >= 0 and not vis[a]:
                a = self.parent[a]
            d = self._seen_descendant(i, vis) if a >= 0 else -1
            if d < 0:
                continue
            v0, v1 = q0[d] - q0[a], est[d] - est[a]
            n0 = math.hypot(*v0)
            if n0 < 1e-6:
                continue
            scale = math.hypot(*v1) / n0
            if not cfg.min_length_fraction <= scale <= 1 + cfg.max_stretch:
                continue
            phi = math.atan2(v1[1], v1[0]) - math.atan2(v0[1], v0[0])
            c, s = scale * math.cos(phi), scale * math.sin(phi)
            r0 = q0[i] - q0[a]
            pred = est[a] + np.array([c * r0[0] - s * r0[1], s * r0[0] + c * r0[1]])
            thetas = [phi] * len(self._inc[i])
            m = self._anchor(gray0, ga, i, q0[i], pred, phi, h, thetas if self._band is not None else None)
            if m is None:
                continue
            xy, score, fb, s_lk, second, n_eff, xy2 = m
            if score < cfg.min_ncc or second > score - cfg.distinct_sigmas / math.sqrt(n_eff):
                continue
            s = math.sqrt(s_lk ** 2 + (fb / 2) ** 2 + cfg.fallback_sigma_px ** 2)
            if s > hold_max or (not cfg.soft_reject and (fb > fb_max or not self._length_ok(i, xy, est, vis))):
                continue
            est[i], vis[i], sig[i] = xy, True, s
            how[i] = 5
            held[i] += 1  # not re-anchored by its own prediction: finding it next frame is a re-acquisition
            counts["bridged"] += 1
