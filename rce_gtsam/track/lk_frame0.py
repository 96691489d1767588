"""The default tracker's frame-0 set-up: the graph's topology as the tracker walks it, the patch radius, the
branch band and its colour mask, the segment strips and each node's articulated-template inputs.

:class:`Frame0Setup` is a part of :class:`~rce_gtsam.track.lk.LKTracker` (a mixin: these methods fill the
attributes the measurement (:mod:`~rce_gtsam.track.lk_measure`) and the first pass
(:mod:`~rce_gtsam.track.lk_node`) read: ``order``, ``parent``, ``children``, ``rest_len``, ``h``, ``partner``,
``_inc``, ``_ang0``, ``_tips``, ``_seg_band``, ``_strip``, ``_stacks``, ``branch_halfwidth_px``). Everything here
runs once per ``track``, on the first frame. Positions in pixels, angles in radians.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from ..errors import InputError
from ..graph import BranchGraph


# A tip's template uses its branch band whenever the band holds at least this many (weighted) pixels: a 4x4
# block, where the correlation of an unrelated patch has a standard error of 1/sqrt(16) = 0.25, so ``min_ncc``
# (0.5) is still two standard errors above chance. See :mod:`rce_gtsam.track.lk` ("Below 4 (2h + 1) band pixels").
_TIP_MIN_BAND_PX = 16.0


class Frame0Setup:
    """Frame-0 set-up of :class:`~rce_gtsam.track.lk.LKTracker` (see the module docstring)."""

    def _setup(self, q: np.ndarray, graph: BranchGraph | None, source: str):
        cfg = self.config
        n = len(q)
        self.order = list(range(n))
        self.parent = [-1] * n
        self.rest_len = np.zeros(n)
        self.children = {i: [] for i in range(n)}
        if graph is not None:
            missing = [v for v in graph.nodes if not 0 <= v < n]
            if missing:
                raise InputError(graph.source, f"graph node {missing[0]} has no annotated point "
                                               f"(annotations list {n} points, ids 0..{n - 1})", f"node {missing[0]}")
            self.order = list(graph.nodes) + [i for i in range(n) if i not in set(graph.nodes)]
            for c, p in graph.parent.items():
                self.parent[c] = p
                self.children[p].append(c)
                self.rest_len[c] = float(np.hypot(*(q[c] - q[p])))
        lengths = self.rest_len[self.rest_len > 0]
        if cfg.patch_radius_px is not None:
            h = int(cfg.patch_radius_px)
        elif lengths.size:
            h = int(np.clip(round(0.45 * float(np.median(lengths))), 6, 15))
        else:
            h = 10
        if h < 2:
            raise InputError(source, f"patch radius must be >= 2 px, got {h}")
        self.h = h
        self._margin = self._rematch_radius()
        # segments incident to each node (the parent's first), and each segment's frame-0 direction (radians, by its
        # child: ``turn``)
        self._inc = [([(self.parent[i], i)] if self.parent[i] >= 0 else []) + [(i, c) for c in self.children[i]]
                     for i in range(n)]
        self._ang0 = [math.atan2(q[c][1] - q[p][1], q[c][0] - q[p][0]) if p >= 0 else 0.0
                      for c, p in enumerate(self.parent)]
        # refinement pass (see ``_refine``): at position k of the order, the nodes read that the pass has not
        # re-matched yet, and how many first-pass nodes must be finished before node order[k] is re-matched
        pos = {i: k for k, i in enumerate(self.order)}
        self._refine_reads, self._refine_needs = [], []
        for k, i in enumerate(self.order):
            near = [j for j in (self.parent[i], i, *self.children[i]) if j >= 0]
            self._refine_reads.append(np.array([j for j in near if pos[j] >= k], int))
            self._refine_needs.append(1 + max(pos[j] for j in near))
        # terminal nodes (a parent, no children): their band is matched down to _TIP_MIN_BAND_PX pixels
        self._tips = {j for j in range(n) if self.parent[j] >= 0 and not self.children[j]}
        # Rotation baseline partner: walk toward the root until >= 2h away, else toward the tip.
        self.partner = [-1] * n
        if graph is not None and cfg.rotate_templates:
            children = graph.children
            for i in graph.nodes:
                j = i
                while self.parent[j] >= 0 and np.hypot(*(q[j] - q[i])) < 2 * h:
                    j = self.parent[j]
                if np.hypot(*(q[j] - q[i])) < 2 * h:
                    k = i
                    while children.get(k) and np.hypot(*(q[k] - q[i])) < 2 * h:
                        k = children[k][0]
                    j = k if np.hypot(*(q[k] - q[i])) > np.hypot(*(q[j] - q[i])) else j
                self.partner[i] = j if j != i else -1

    def _rematch_radius(self) -> int:
        """Radius (px) of the refinement pass's re-match: max(2, h // 4) (the first pass is within a pixel)."""
        return max(2, self.h // 4)

    def _branch_band(self, rgb: np.ndarray, q: np.ndarray, graph: BranchGraph | None) -> np.ndarray | None:
        """Frame-0 weight image: 1 on a band around the graph's segments, 0 elsewhere (None: no graph).

        The branch half-width is measured, not assumed: across the middle of every segment, the colour
        profile is compared with the colour on the axis; the half-width is where the difference first
        exceeds half its maximum (the edge), median over segments, clipped to [1.5 px, h].
        """
        if graph is None or not self.config.mask_to_branch:
            return None
        h = self.h
        img = rgb.astype(np.float32)
        widths = []
        offs = np.arange(-h, h + 1, dtype=np.float32)
        for p, c in graph.edges:
            a, b = q[p], q[c]
            d = b - a
            ln = float(np.hypot(*d))
            if ln < 1e-6:
                continue
            nrm = np.array([-d[1], d[0]]) / ln
            mid = 0.5 * (a + b)
            mx = (mid[0] + offs * nrm[0]).reshape(1, -1).astype(np.float32)
            my = (mid[1] + offs * nrm[1]).reshape(1, -1).astype(np.float32)
            prof = cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)[0]
            centre = prof[h - 1:h + 2].mean(axis=0)
            dist = np.linalg.norm(prof - centre, axis=1)
            if dist.max() < 1e-3:
                continue
            half = 0.5 * dist.max()
            sides = []
            for seq in (dist[h:], dist[h::-1]):
                hit = np.flatnonzero(seq > half)
                sides.append(float(hit[0]) if hit.size else float(h))
            widths.append(float(np.mean(sides)))
        hw = float(np.clip(np.median(widths) if widths else h, 1.5, h)) + self.config.band_margin_px
        self.branch_halfwidth_px = hw
        fg = self._branch_colour_mask(rgb, q, graph) if self.config.mask_off_colour else None
        # one band per segment, cropped around each of its two end nodes (only those crops are used)
        self._seg_band = {}
        self._band_stacks = {}
        size = 2 * (h + 2 * h) + 1
        for p, c in graph.edges:
            for node in (p, c):
                off = q[node] - (size - 1) / 2.0  # crop origin so that q[node] maps to the crop centre
                band = np.zeros((size, size), np.uint8)
                a, b = (np.round((q[p] - off) * 16).astype(int), np.round((q[c] - off) * 16).astype(int))
                cv2.line(band, tuple(map(int, a)), tuple(map(int, b)), 255, int(round(2 * hw)) + 1, cv2.LINE_AA, shift=4)
                band = band.astype(np.float32) / 255.0
                if fg is not None:
                    band *= cv2.getRectSubPix(fg, (size, size), (float(q[node][0]), float(q[node][1])))
                self._seg_band[(p, c, node)] = band
        # frame-0 strip of every segment in its own frame (u along p->c, 1-px steps; v across the band)
        g0 = self._anchor_image(cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)).astype(np.float32)
        self._strip = {}
        vv = np.arange(-math.floor(hw), math.floor(hw) + 1, dtype=np.float32)
        for p, c in graph.edges:
            d = q[c] - q[p]
            ln = float(np.hypot(*d))
            if ln < 2.0:
                continue
            uu = np.arange(0.0, ln + 0.5, 1.0, dtype=np.float32)
            ex = d / ln
            ey = np.array([-ex[1], ex[0]])
            mx = (q[p][0] + uu[None, :] * ex[0] + vv[:, None] * ey[0]).astype(np.float32)
            my = (q[p][1] + uu[None, :] * ex[1] + vv[:, None] * ey[1]).astype(np.float32)
            st = cv2.remap(g0, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
            st = st - st.mean()
            nrm = float(np.sqrt((st * st).sum()))
            if nrm > 1e-3:
                # segment search (``_segment_search``): rotations within atan(2h / L0) of the last one, steps of
                # half a pixel at the child, about the frame-0 direction of the segment (``_ang0``, by its child)
                span, step = math.atan2(2 * h, ln), 0.5 / ln
                self._strip[(p, c)] = (uu, vv, st / nrm, np.arange(-span, span + step / 2, step),
                                       self._ang0[c], step, *map(float, q[c] - q[p]))
        # each node's articulated-template inputs (``_band_stack``)
        self._stacks = [self._node_stack(i) for i in range(len(q))]
        return True

    @staticmethod
    def _branch_colour_mask(rgb: np.ndarray, q: np.ndarray, graph: BranchGraph) -> np.ndarray:
        """Frame-0 image (float32, 1/0): pixels whose chromaticity is that of the branch itself.

        Leaves hanging in front of the stem and the background at the band's edges move independently of
        the node; inside a template they make it fail (a fluttering leaf) or pin it (static background). The
        branch's own colour is measured on its axis (every segment sampled at 1-px steps): median and robust
        spread (1.4826 MAD, floored at 0.01 -- sensor noise on a mid-grey pixel) of the chromaticity
        (r, g) = (R, G) / (R + G + B). Chromaticity, not colour, so that dark bark (knots, shading) counts as
        branch. A pixel is kept when its normalised distance is below 3.41 = sqrt(chi2_2(0.997)), the
        two-dimensional 3-sigma bound: 99.7 % of branch pixels are kept if the spread is Gaussian.
        """
        from . import match_kernels  # the per-pixel float32 arithmetic of numpy, compiled (10x faster, same values)

        chroma = match_kernels.chromaticity(rgb)
        samples = []
        for p, c in graph.edges:
            d = q[c] - q[p]
            ln = float(np.hypot(*d))
            t = np.linspace(0.0, 1.0, max(2, int(ln) + 1), dtype=np.float32)
            mx = (q[p][0] + t * d[0]).reshape(1, -1).astype(np.float32)
            my = (q[p][1] + t * d[1]).reshape(1, -1).astype(np.float32)
            samples.append(cv2.remap(chroma, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)[0])
        smp = np.concatenate(samples, axis=0)
        med = np.median(smp, axis=0)
        spread = np.maximum(1.4826 * np.median(np.abs(smp - med), axis=0), 0.01)
        return match_kernels.chroma_mask(chroma, med, spread, 3.41)

    def _anchor_image(self, gray: np.ndarray) -> np.ndarray:
        """The image every measurement against frame 0 is made in (see ``LKConfig.anchor_highpass_px``)."""
        s = self.config.anchor_highpass_px
        if s <= 0:
            return gray
        lg = np.log(gray.astype(np.float32) + 8.0)
        return (lg - cv2.GaussianBlur(lg, (0, 0), s)) * np.float32(100.0)

    def _node_stack(self, i):
        """Node i's articulated-template inputs for :func:`~rce_gtsam.track.match_kernels.articulated_template`
        but the rotations: ``(bands (S, n, n), their extent per row (``band_rows``), background segment, smallest band
        weight sum)``, S = its incident
        segments, the parent's first (``self._inc[i]``), or None for a node on no segment.

        The template is *articulated*: each incident segment's band of the frame-0 image is rotated about the node
        by that segment's own rotation (a node is a joint: the parent segment and the child segments turn by
        different angles, and one rotation for the whole patch biases the match in proportion to the bend).
        """
        keys = self._inc[i]
        if not keys:
            return None
        bg = max((n for n, (_, sc) in enumerate(keys) if sc == i), default=0)
        # fewer pixels than a 2-px-wide strip: use the full patch -- except at a tip, whose band is short
        # by construction (one segment, the thinnest stem), down to _TIP_MIN_BAND_PX
        min_band = _TIP_MIN_BAND_PX if i in self._tips else 4 * (2 * self.h + 1)
        from .kernels_match import band_rows

        bands = np.stack([self._seg_band[(sp, sc, i)] for sp, sc in keys])
        return bands, band_rows(bands), bg, float(min_band)
