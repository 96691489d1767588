"""Default tracker: OpenCV Lucas-Kanade, re-anchored to each node's first-frame appearance.

Plain frame-to-frame LK accumulates drift (each frame's small error is inherited by the next) and
never recovers after an occlusion. This tracker uses frame-to-frame pyramidal LK only as a
*prediction*; every measurement is made against the node's **first-frame template**:

1. **Predict** where node i is in frame f: pyramidal LK from frame f-1 (``cv2.calcOpticalFlowPyrLK``,
   ``pyr_levels`` levels, so swings of tens of pixels per frame are followed) when its forward-backward
   check passes; otherwise, with a graph, from the parent's new position plus the rest-pose segment
   vector rotated by the node's current rotation (the branch is locally rigid); otherwise the last position.
2. **Anchor**: rotate the frame-0 neighbourhood of the node by the node's current rotation (the angle
   change of the branch direction since frame 0, measured over a baseline of >= 2 patch radii along
   the graph so that it is not dominated by pixel noise), and find it in a window around the
   prediction with normalised cross-correlation (``cv2.matchTemplate``, ``TM_CCOEFF_NORMED``; search
   radius = patch radius when the node was visible in the previous frame, twice that to re-acquire a
   lost node). Then refine to sub-pixel with a weighted inverse-compositional LK *from the frame-0
   template* (gain/bias compensated), and run it backwards for a forward-backward error. With a graph,
   template pixels are weighted by a band around the branch (the frame-0 segments, half-width measured
   from the image): a thin stem fills a small part of its patch, and the static background in the rest
   would otherwise pin the match to where the node was in frame 0. Pixels of the band whose frame-0
   chromaticity is not the branch's (measured on the graph's own axis: median and MAD) are dropped too:
   a leaf hanging in front of a node flutters and spoils its template, and background at the band's
   edges pins it (measured on 600-frame simulator clips, seeds 0-4: Spearman of kappa 0.80/0.71/0.71/
   0.25/0.87 -> 0.81/0.85/0.86/0.66/0.94 with the re-acquisition check below). Below 4 (2h + 1) band
   pixels the full patch is used instead -- except at a **tip** (a node with a parent and no child), which
   uses its band down to 16 pixels (``_TIP_MIN_BAND_PX``). A tip's band is small by construction (only one
   segment reaches into its patch, and the stem is thinnest there: 28-55 pixels on the simulator clips),
   whereas an interior node below 4 (2h + 1) has lost its band to a leaf in front of it (the colour mask), and
   its template is spoiled. With the full patch, which is mostly static background, a tip's match was pinned
   toward its frame-0 surroundings: nearly all visible errors > 2 px on the 600-frame clips came from tips,
   and the tip's kappa on seed 3 was 3.2 (true 0.84). Measured (``rce run``, 600-frame simulator clips, seed
   1: 400): Spearman of kappa on seeds 0-4 0.909/0.849/0.903/0.674/0.948 -> 0.899/0.835/0.903/0.765/0.942,
   max visible error 1.6/7.8/14.1/2.7/9.1 -> 1.6/7.8/3.0/2.5/6.3 px, p99 0.70/1.66/1.73/1.10/0.71 ->
   0.69/1.66/1.01/0.83/0.56 px, visible fraction 0.848/0.812/0.955/0.910/0.946 -> 0.857/0.812/0.943/
   0.908/0.944 (the tip is marked invisible more often on seeds 2-4: the band, unlike the background, does
   not match where a leaf covers it). Applying the 16-pixel floor to every node (interior nodes behind a
   leaf included) cuts the tails further (p99 0.42-0.73 px) but gives Spearman 0.893/0.940/0.808/0.383/0.930.
   Not adopted (measured): choosing a tip's template rotation by the image -- a 1-D search over the rotation
   maximising the correlation peak, jointly with the position, instead of the rotation implied by the tip's
   own match (a position -> rotation -> template feedback that amplifies a matching bias). On a controlled
   render (seed 3, branch static, tip segment swinging +-20 degrees, leaves on) it cut the tip's
   across-branch error slope from -0.012 to -0.0015 px/degree; on the 600-frame clips the seed-3 tip's slope
   stayed ~+0.03 px/degree (its bias there is not that feedback), Spearman was 0.878/0.843/0.920/0.773/0.932
   (refinement pass only: 0.899/0.835/0.903/0.773/0.932) at 7 or more extra template matches per tip and pass.
   Because the measurement always compares with frame 0,
   errors do not accumulate: a node that returns to its first pose is measured where it is.
   **Articulated templates** (with a graph): a node is a joint, and its parent segment and child segments
   turn by different angles; one rotation for the whole patch biased every node in proportion to the bend
   at it (measured: bend-angle error correlated -0.99 with the true bend). So each incident segment's band
   of the frame-0 image is rotated about the node by that segment's own rotation and the pieces are
   composited; pixels outside every incident band get weight 0. After all nodes are matched, the segment
   rotations are re-measured from the matches and every visible node is matched again within
   max(2, h // 4) px (the first-pass rotations use frame-to-frame predictions, which lag). A node found
   in the wide window (no frame-to-frame or segment prediction, so its template was posed with the
   rotation borrowed from its parent, not measured) whose re-match fails the first pass's own tests
   (``min_ncc``, forward-backward limit) is marked invisible (``refine_consistency``): its template, posed
   as the match itself implies, does not fit there, so the first-pass score came from a wrongly posed
   template (simulator seed 0, 150 frames, 12 nodes: the
   lost tip, swung ~35 degrees further than its parent segment, was re-acquired with its full-patch
   template rotated by the parent's rotation on a background spot beside the stem, correlation 0.53 and
   distinct, and reported visible 10.6 px off on frames 109-115; posed as that match implies it scored
   0.44-0.46).
   **Segment search** (with a graph, parent visible): the child's prediction comes from a 1-D search over
   the rotation of the segment (parent, child) hinged at the parent (around its last rotation, or, for a
   child lost in the previous frame, around the parent's current rotation plus the child's last bend: the
   whole branch keeps swinging while a node is hidden), matching the whole frame-0 segment
   strip (normalised correlation), so a node cannot slide along a self-similar stem to a neighbouring knot.
   ``segment_fallback`` (off by default) additionally accepts that rigid-segment position as a measurement
   when the node's own patch fails; it raised visibility but lowered kappa rank accuracy on 2 of 3
   simulator seeds, and a wrong visible position is worse than an invisible one.
3. **Decide visibility** -- a node is marked invisible (position = the prediction, ``visible=False``)
   rather than guessed when: the correlation peak is below ``min_ncc``; the node is being re-acquired
   (it was invisible in the previous frame) and a second peak away from the best is within
   ``distinct_sigmas`` correlation standard errors of it (a lost node otherwise locks onto the
   neighbouring knot of a self-similar stem; this cut the p99 error of visible points from 16 to 1.2 px
   on simulator seed 0); the node is being re-acquired while its parent is lost too (no graph check
   would apply to the match: on simulator seed 0 a tip re-found beside a leaf 18 px off was then followed
   to 67 px while marked visible); a search in the wide window (2h: the node had no frame-to-frame or
   segment prediction) counts as re-acquiring for both checks, whatever the previous frame said; a
   followed (not re-acquired) node whose match has such an indistinguishable second peak is marked
   invisible when that second peak is nearer the prediction than the best (``distinct_follow``: the two
   pieces of evidence disagree, and picking one is a guess). With
   these two rules the largest error of a visible point on simulator seeds 0-4 went from
   74/27/14/2.7/50 px to 2.3/9.6/14/2.7/16 px, at 0-4 % fewer visible point-frames; the forward-backward error
   exceeds ``max_fb_fraction`` of the patch radius; or, with a graph, the distance to its parent
   (when the parent is visible) stretches beyond ``(1 + max_stretch) * L0 + length_tol_px`` or
   shrinks below ``min_length_fraction * L0 - length_tol_px`` (L0 = frame-0 segment length; a branch
   segment does not stretch, but it may foreshorten when it turns out of the image plane).
3b. **Hold through fast motion** (issue 38; ``benchmarks/bench_track_plant2.py``, ``bench_texture_bed.py``): before a
   node whose frame-0 match failed is marked invisible, (i) it is matched against its appearance in the last frame
   it was anchored to frame 0 with correlation >= ``recent_min_ncc`` (``recent_template``; only with a trusted
   prediction -- never in the wide window -- and not at a tip), its sigma that anchor's plus this match's;
   (ii) failing that, it is held at its frame-to-frame LK position with a sigma that grows frame by frame
   (``hold``); (iii) a tip is placed by its hinged segment search (``tip_segment_fallback``). A node placed by
   (i) or (ii) is off its frame-0 template, so finding it there again counts as a re-acquisition (strict checks).
   An ambiguous re-acquisition is accepted when the whole segment strip, hinged at the visible parent, matched
   well and points at the best peak and not at the second (``segment_tiebreak``).
   Measured against revision 9adf3ee in one run: on plant 2's footage against TAPIR's tracks, frames 120-359 by
   60-frame window (visible share of TAPIR's rows; p90 distance), 63/52/48/53 % (1.1-1.3 px) -> 85/75/64/90 %
   (1.5-1.7 px), and kappa against the TAPIR run's kappa Spearman 0.50 -> 0.82, log-RMS 0.79 -> 0.51, inside its
   CI 12 -> 15 of 23; on the real-texture bed (``rce_gtsam.sim.texture_bed``) see ``bench_texture_bed.py``. Cost:
   on the simulator's renders (600 frames, seeds 0/2/3/4) Spearman of kappa 0.917/0.903/0.765/0.942 ->
   0.763/0.913/0.711/0.961 and the p99 error of visible points 0.6-1.0 -> 0.65-2.6 px: the recent template
   follows a fluttering leaf now and then (seed 0; without it 0.926). Not kept (measured on plant 2): predicting
   a lost node from where it was last seen moved as its nearest seen ancestor (p90 distance 13-19 px in two
   windows), and requiring the recent template to agree with the segment search (visible 41-67 %).
4. **Uncertainty**: ``sigma_px = sqrt(s_lk^2 + (fb/2)^2 + sigma_floor_px^2)`` with the LK
   least-squares standard error ``s_lk = sqrt(residual_variance / lambda_min(G))`` (G = structure
   tensor of the template, residual = template minus the matched patch, so appearance change counts)
   and fb the forward-backward error. Invisible entries get sigma = the search radius.

Constants and why they are what they are (none is tuned to a video):

* patch radius h: ``clip(0.45 * median segment length, 6, 15)`` px -- large enough to hold texture (LK
  windows below ~13 px are noise-dominated), small enough that the patch covers little more than the
  node's own segment neighbourhood (which moves rigidly with it). Without a graph: 10 px (21x21, a
  common LK window).
* ``min_ncc = 0.5``: the template then explains >= 25 % of the patch variance, while an unrelated
  patch of n pixels correlates at about +-1/sqrt(n) (< 0.08 for n >= 169), so this is far above chance
  at every patch size used, yet tolerant of the lighting/rotation change a swinging branch shows.
* ``max_fb_fraction = 0.1``: a well-posed LK round trip closes to << 0.1 px; a gap of a tenth of the
  patch radius (~1 px for the typical 21 px window, the usual FB threshold in the literature) means the
  match is not a stable minimum.
* ``max_stretch = 0.25``, ``min_length_fraction = 0.4``, ``length_tol_px = 1.5``: relative to L0 so that
  they hold at any zoom; the absolute tolerance covers two nodes' localisation error on short segments.
* ``refine_consistency`` and ``distinct_follow`` add no constant: they re-use ``min_ncc``, the
  forward-backward limit and ``distinct_sigmas``.

Camera nuisances (``benchmarks/bench_track_nuisance.py``, seeds 0-2, 400 frames, ``rce_gtsam.sim.nuisance``):
a drifting global gain/offset (even 3 % per frame), a 180-degree-shutter motion blur, a soft moving shadow
and 1-3 px of camera shake leave the median error of visible points at 0.07-0.09 px (clean 0.07), because
every measurement is a zero-mean normalised correlation and a gain/bias-compensated LK against frame 0.
What hurts is compression: at x264 crf 28 the median is 0.19 px and 83 % of point-frames are visible
(clean crf 16: 0.07 px, 88 %), at crf 34 0.34 px and 52 %; the thin distal stem's texture is quantised
away, and the tracker marks those nodes invisible rather than guess.

Speed (``benchmarks/bench_track.py``, which runs this tracker and the one of revision 7f3b223 on the same
frames in one process): the time went to per-node work on small arrays, not to pixels -- OpenCV's masked
``matchTemplate`` (several DFT correlations for a 19x19 result), a dozen numpy calls per Lucas-Kanade
iteration, two warps per incident segment for each template. The node measurement (weighted correlation
map, peak and second peak, forward LK, forward-backward LK), the articulated template and the segment
search's sampling and correlation are now compiled kernels (:mod:`~rce_gtsam.track.match_kernels`, numba),
each one call per node doing the same arithmetic as the OpenCV/numpy code it replaced (equal to float
rounding; the kernels are tested against OpenCV). What is left in Python is the per-node decision logic;
the two ``calcOpticalFlowPyrLK`` calls (all points at once, forward and backward) are ~1.5 ms of a frame, most
of it building the pyramids (each call builds both images' pyramids again; OpenCV's Python binding cannot take
the pyramids of ``cv2.buildOpticalFlowPyramid``, opencv issue 4777, so they cannot be built once per frame).
Frames are decoded and converted to grey in a thread
(:func:`~rce_gtsam.track.sources.prefetched`). With ``LKConfig.threads=2`` the refinement pass runs in a
second thread, node by node right behind the first pass, and the tracks are bit-identical (tested); it is
off by default because it was slower on the shared machine (the per-node Python holds the GIL, and a re-match
is short). The first pass itself is a chain (each node's segment search hinges at its parent's new match),
so it cannot be split across threads. Against revision 028a0d1 (before the window sums with ``fastmath``,
the one-call articulated match, the grey conversion in the decode thread and the template skipping off-band
samples), on the 120-frame seed-0 render in alternating processes on the shared machine (load 4-7): best
CPU time 1.18x, best wall 1.24x, median CPU 1.09x faster; the tracks of the accuracy clips (seeds 0-4,
below) are bit-identical to that revision's. The compiled kernels against 7f3b223, measured on the shared
2-core machine (120-frame seed-0 render, 20 nodes, best of 3-5, baseline and current
alternating): 3.9x / 3.7x wall, 3.3x / 3.6x CPU time, 3.3x tracking straight from the mp4 (two runs, the
second with the machine's load average at 7-10, so absolute frame rates there mean little: 117 frames/s
tracking alone in the first). The kernels are compiled once per machine (cached next to the module, or in
numba's user cache if that is read-only) and loaded at the first ``track`` of a process. Accuracy: on the
600-frame clips of seeds 0-4 (seed 1: 400) the figures move by as much as the 7f3b223 tracker's own move
when every annotation is shifted by 0.001 px (``baseline~`` in the benchmark): the tracker's output depends
on rounding (the search crop and the frame-0 template are cut as uint8 images at sub-pixel positions), and a
99th percentile or Spearman of kappa at two decimals flips under such a perturbation; medians, largest errors
and visible shares are equal. Tried and not kept (measured on the simulator clips):
re-matching by LK alone without the correlation search in the refinement pass, deferring the first pass's
forward-backward check to the refinement pass (the first moved the largest visible error on seed 0 from 1.6
to 3.9 px, the second that on seed 1 from 7.8 to 8.5 px), and skipping the re-match when the re-measured rotations moved the template
by less than 0.05 px (median error 0.038 -> 0.039 px, largest 4.2 -> 6.9 px on a 150-frame seed-2 clip: the
re-match gains by re-centring the search crop on the match, not only by re-posing the template; with the
compiled kernels the refinement pass is a sixth of the time, and on seed 0 a 0.02-px threshold would skip only
a third of the re-matches). Cutting the search crop at an integer position or as float (no uint8 rounding), or
the frame-0 template without rounding, changed the 99th percentile on 400 frames of seeds 1 / 3 by -0.24 to
+0.06 px, i.e. within the figures' resolution, and was not kept.
Against revision 7cf087e (profiled on the 120-frame seed-0 render: 8.8 ms a frame, of which ~2.3 ms Python and
numpy glue around the kernels, 3 ms the node measurement, 1.8 ms the segment search, 1.5 ms the two pyramidal LK
calls, and 0.3 ms the frame-0 set-up spread over the clip): the segment search is one compiled call (angles,
correlations, the peak and its parabola, the child's position), its taps read a float64 copy of the disc the
strip sweeps with the border branch hoisted out of the loop; the match returns frame-pixel scalars instead of
an array the caller shifts; the per-node constants (incident segments, band stacks, frame-0 directions) are
built once; the in-image taps of the window sums, the segment sums, the articulated template and the LK patch
sampler use unsigned flat indices, so no negative-index wraparound code runs per tap (the window sums' vectorised
reduction is unchanged: the correlation maps were bit-identical on 12,000 captured calls); and the frame-0
chromaticity and colour mask are compiled (numpy's float32 arithmetic, 27 ms of every ``track`` at 640x480).
Every output is bit-identical: the tracks, visibility, sigmas and counters on the accuracy clips (seeds 0-4) and,
on 120 frames of seed 0, with ``threads=2``, without a graph, with ``anchor_highpass_px=4``,
``segment_fallback`` and without rotated or masked templates. Measured in one ``bench_track.py --baseline
7cf087e`` run (best of 5, the machine's load average 2.3-2.5 from another process): tracking alone 144.5 ->
190.1 frames/s wall (6.92 -> 5.26 ms/frame), 117 -> 146 frames/s CPU time; straight from the mp4 136 -> 177
frames/s; with ``threads=2`` 205 frames/s alone and 189 from the mp4 (it now wins on an idle second core, but
costs CPU time, 131 frames/s, and lost under load before; still off by default). In alternating processes under
heavier load (another process taking 1.3 of the 2 cores, load average 3-4; 9 runs each): best 128 -> 176 frames/s
alone (median 123 -> 171), from the mp4 best 113 -> 152 (median 110 -> 143): the decode thread then competes for
the cores. Where a frame goes now (profiled, 6.3 ms): the node measurement 2.2 ms (articulated template 0.7,
correlation map 1.0, forward and backward LK 0.5), the segment search 1.4 ms, the pyramidal LK 1.45 ms, Python
and ``getRectSubPix`` 0.8 ms, the set-up 0.1 ms (13 ms a clip). The first ``track`` of a process loads the
compiled kernels from numba's cache (0.5 s); they are compiled once per machine and change (16 s, measured).
Tried for this and dropped: the segment sums with the angles innermost (numba emitted no gathers: no faster), a
two-pass articulated template (band weights first, then image samples) and taking the background sample only where
no band reaches (no faster), cutting the search crop in a kernel (no formula reproduced OpenCV 5's uint8
``getRectSubPix`` exactly), and the pyramidal LK on a crop around the nodes (not exact near the crop's edge, and
the nodes of a frame span ~200x300 px, so the crop with the level-3 margins is most of the frame).

Limits: the template is rotated, not scaled (a branch that moves a lot toward the camera changes scale);
a node hidden from frame 0 onwards cannot be tracked.
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import cv2
import numpy as np

from ..errors import InputError
from ..graph import BranchGraph
from .result import TrackResult
from .sources import FrameSource, prefetched


@dataclass(frozen=True)
class LKConfig:
    """Settings of :class:`LKTracker` (pixels unless stated; see the module docstring for the reasons).

    patch_radius_px: template half-size h; None = ``clip(0.45 * median segment length, 6, 15)``
        (10 without a graph).
    pyr_levels: pyramid levels of the frame-to-frame prediction (motion up to ~h * 2**levels px/frame).
    min_ncc: minimum normalised cross-correlation of the first-frame template at the match.
    max_fb_fraction: forward-backward error limit as a fraction of h (never below ``min_fb_px``).
    min_fb_px: floor of the forward-backward limit.
    max_stretch, min_length_fraction, length_tol_px: segment-length plausibility (needs a graph).
    sigma_floor_px: smallest reported 1-sigma (interpolation/quantisation limit).
    rotate_templates: rotate the first-frame template by the branch's rotation (needs a graph).
    mask_to_branch: weight template pixels by a band around the branch (the graph's segments in frame 0),
        so the static background inside a patch does not pin the match (needs a graph).
    band_margin_px: the band extends this far beyond the measured branch half-width, so the branch's
        own edges (the strongest across-branch gradients) are inside it.
    refine_pass: re-match visible nodes with segment rotations measured from this frame's matches.
    segment_fallback: accept the hinged-segment position when a node's own patch fails (needs a graph).
    min_segment_ncc: correlation of the whole segment strip required by ``segment_fallback`` (higher
        than ``min_ncc``: the strip has many more pixels, and the position is not refined).
    distinct_reacquire: when re-acquiring a node that was invisible in the previous frame, reject the
        match if another correlation peak (outside h/2 of the best) comes within ``distinct_sigmas``
        correlation standard errors (1/sqrt(weighted template pixels)) of it: on a self-similar stem the
        neighbouring knot is then as good a match, and the node stays invisible rather than guessed.
    distinct_sigmas: peak-separation threshold of ``distinct_reacquire`` in standard errors (2: two
        peaks closer than that are not distinguishable from pixel noise).
    mask_off_colour: drop from the branch bands the frame-0 pixels whose chromaticity is not the branch's
        (leaves in front of the stem, background at the band's edges; see ``_branch_colour_mask``).
    distinct_follow: also for a followed node (not re-acquired), reject a match with a second peak within
        ``distinct_sigmas`` standard errors when that peak is nearer the prediction than the best one.
    refine_consistency: mark a node found in the wide window (template posed by a borrowed rotation)
        invisible when its second-pass re-match (rotations measured from this frame's matches) fails
        ``min_ncc`` or the forward-backward limit, instead of keeping the first-pass match (see
        ``LKTracker._refine``). Applied to every visible node it also dropped a few correct matches and
        lowered Spearman of kappa on simulator seed 1 from 0.83 to 0.80.
    anchor_highpass_px: 0 (default) = measure against frame 0 in the grey image. > 0 = in a locally
        illumination-normalised image instead: log(grey + 8) minus its Gaussian blur of this standard
        deviation (pixels), so a brightness gradient or a shadow edge slower than that scale drops out
        (global gain and offset are already compensated by the normalised correlation and the
        gain/bias-compensated LK). Measured at 4 px (``benchmarks/bench_track_nuisance.py``): a sharp
        moving shadow (12 px penumbra, 50 % darker) no longer puts a visible point 26 px off (seed 1: max
        26.3 -> 9.5 px, visible 0.78 -> 0.84), and on clean 600-frame clips visibility rises (seeds 0-4:
        0.85/0.81/0.96/0.91/0.95 -> 0.93/0.85/0.98/0.97/0.97) but so does the tail (share of visible
        errors > 2 px on seeds 2-4: 0.8/0.2/0.6 % -> 1.1/1.1/0.9 %), and under the soft 60-px shadow one
        visible point was 201 px off (seed 0), so it is not the default.
    hold: when a node's frame-0 match (and the recent template) fails but frame-to-frame pyramidal LK followed it
        from a measured (or held) position -- round trip within the forward-backward limit, the (2h+1)^2 patch
        correlating at least ``hold_min_ncc`` with the previous frame's (a covered node or a blank patch does not),
        its parent visible in this frame (the root excepted), the segment to it within the stretch limits and
        within ``hold_agree_px`` of where the hinged segment search (matched at >= ``min_ncc``) puts the node --
        keep the node visible at the LK position with a sigma that grows as a random walk: sigma^2 =
        max(sigma_prev, ``fallback_sigma_px``)^2 + (fb/2)^2 + ``hold_step_px``^2, until it passes
        ``hold_max_sigma_px`` (None: h/2). A held node that the frame-0 template finds again counts as re-acquired
        (the strict ``distinct_reacquire`` and parent checks apply), so a hold that drifted cannot re-anchor on a
        neighbouring knot. Without the parent and segment conditions a held tip drifted 149 px off on the texture
        bed (150 px excursion), and held points followed fluttering leaves on the simulator clips (p90 7.4 px).
        ``hold_step_px`` (0.3 px a frame) is an assumption, not a calibration.
    fallback_sigma_px: the smallest sigma (px) of a recent-template or held position. Their errors are not what
        the match's own least-squares error says: median 0.5-1.4 px on the texture bed (seeds 0-1) and 1.1-1.8 px
        on simulator seed 0, at err/sigma medians of 1.2-4.3 with the match's sigma alone; 1 px is that scale.
    recent_template, recent_min_ncc: see the module docstring (3b). The stored appearance is only as good as its
        anchor: 0.8 (the template explains >= 64 % of the patch variance) keeps a node partly covered by a leaf
        from being stored. Without the narrow-window rule the recent template locked onto the occluding leaf 13-16
        px off in ``tests/test_track_lk.py``'s scene, and at a tip matched with its full patch 7.6 px off
        (simulator seed 0): both are excluded.
    segment_tiebreak: see the module docstring (3b); re-uses ``min_segment_ncc`` and h/2.
    tip_segment_fallback: a tip (a node with a parent and no child) whose own patch fails is placed where the
        hinged segment search puts it (``min_segment_ncc``), as ``segment_fallback`` does for every node: a tip's
        band is short and thin, and it was marked lost in ~90 % of the texture bed's frames while the positions
        were right to ~0.5 px; with it the tip is visible throughout (bed seed 0: error median 0.96 px, p90 3.0 px,
        sigma median 0.5 px).
    threads: 2 = the refinement pass runs in a second thread, node by node right behind the first pass (a node
        is re-matched as soon as the first pass has finished it, its parent and its children, and after its
        parent's re-match: exactly the values a pass after the first reads, so the tracks are bit-identical to
        ``threads=1``, the default, which runs the two passes one after the other). The compiled kernels and
        OpenCV release the GIL, but the per-node Python between them does not, and a re-match is short (a
        2-px search): on the shared 2-core machine (load 4-6) two threads were 0.75-0.98x as fast as one
        (``benchmarks/bench_track.py``, ``current2`` row), so one thread is the default. With less Python per node
        (see the module docstring's Speed paragraph) two threads were 1.08x as fast alone and 1.06x from the mp4 at
        load 2.3-2.5, for 1.1x the CPU time.
    """

    patch_radius_px: int | None = None
    pyr_levels: int = 3
    min_ncc: float = 0.5
    max_fb_fraction: float = 0.1
    min_fb_px: float = 0.5
    max_stretch: float = 0.25
    min_length_fraction: float = 0.4
    length_tol_px: float = 1.5
    sigma_floor_px: float = 0.05
    rotate_templates: bool = True
    mask_to_branch: bool = True
    band_margin_px: float = 1.5
    refine_pass: bool = True
    segment_fallback: bool = False
    min_segment_ncc: float = 0.7
    distinct_reacquire: bool = True
    mask_off_colour: bool = True
    distinct_sigmas: float = 2.0
    distinct_follow: bool = True
    refine_consistency: bool = True
    anchor_highpass_px: float = 0.0
    threads: int = 1
    tip_segment_fallback: bool = True
    segment_tiebreak: bool = True
    recent_template: bool = True
    recent_min_ncc: float = 0.8
    fallback_sigma_px: float = 1.0
    hold: bool = True
    hold_step_px: float = 0.3
    hold_max_sigma_px: float | None = None
    hold_agree_px: float = 2.0
    hold_min_ncc: float = 0.8

    def __post_init__(self):
        if isinstance(self.threads, bool) or not isinstance(self.threads, int) or self.threads not in (1, 2):
            raise InputError("LKConfig", f"threads must be 1 or 2, got {self.threads!r}", "threads")


#: ``TrackResult.info["how"]`` (P, F) int8 of :class:`LKTracker`: how each position was found.
HOW = {-1: "invisible", 0: "anchored to frame 0", 1: "recent template", 2: "held by frame-to-frame LK",
       3: "hinged segment"}

# A tip's template uses its branch band whenever the band holds at least this many (weighted) pixels: a 4x4
# block, where the correlation of an unrelated patch has a standard error of 1/sqrt(16) = 0.25, so ``min_ncc``
# (0.5) is still two standard errors above chance. See the module docstring ("Below 4 (2h + 1) band pixels").
_TIP_MIN_BAND_PX = 16.0

_LK_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 30, 0.01)


def _with_grey(frames):
    """(frame, its grey image, or None when it is not an RGB image) for each frame of ``frames``."""
    for fr in frames:
        img = fr.image
        ok = img.ndim == 3 and img.shape[2] == 3
        yield fr, (cv2.cvtColor(img, cv2.COLOR_RGB2GRAY) if ok else None)


class _Progress:
    """How many nodes (in ``LKTracker.order``) the first pass has finished in this frame; the refinement thread
    waits on it."""

    def __init__(self):
        self._cond = threading.Condition()
        self._n = 0
        self._aborted = False

    def advance(self) -> None:
        with self._cond:
            self._n += 1
            self._cond.notify()

    def abort(self) -> None:
        with self._cond:
            self._aborted = True
            self._cond.notify_all()

    def wait_for(self, k: int) -> None:
        """Return once the first pass has finished k nodes (RuntimeError if it was abandoned)."""
        if self._n >= k:
            return
        with self._cond:
            self._cond.wait_for(lambda: self._n >= k or self._aborted)
            if self._n < k:
                raise RuntimeError("the first pass was abandoned")


def _f2f_ncc(prev_gray: np.ndarray, gray: np.ndarray, a, b, h: int) -> float:
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


def _turn(a, b, ang0: float) -> float:
    """Rotation (radians, wrapped to (-pi, pi]) of the vector a->b relative to the direction ``ang0`` (radians,
    ``atan2`` of the frame-0 vector: ``LKTracker._ang0``)."""
    d = math.atan2(b[1] - a[1], b[0] - a[0]) - ang0
    return (d + math.pi) % (2 * math.pi) - math.pi


class LKTracker:
    """Drift-free Lucas-Kanade tracker (see module docstring). ``LKTracker(LKConfig()).track(src, pts, graph)``."""

    def __init__(self, config: LKConfig | None = None):
        self.config = config or LKConfig()

    # -- set-up -------------------------------------------------------------------------------
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
        # child: ``_turn``)
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

    # -- measurement against frame 0 ------------------------------------------------------------
    def _node_stack(self, i):
        """Node i's articulated-template inputs for :func:`~rce_gtsam.track.match_kernels.articulated_template`
        but the rotations: ``(bands (S, n, n), background segment, smallest band weight sum)``, S = its incident
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
        return np.stack([self._seg_band[(sp, sc, i)] for sp, sc in keys]), bg, float(min_band)

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

    def _rematch_radius(self) -> int:
        """Radius (px) of the refinement pass's re-match: max(2, h // 4) (the first pass is within a pixel)."""
        return max(2, self.h // 4)

    def _refine_node(self, gray0, gray, q0, i, est, vis, fb_max):
        """Re-match of visible node i with segment rotations from ``est`` (this frame's matches; the nodes before
        i in ``self.order`` already re-matched): ``(xy, sigma px)``, or None when the re-match fails (no match,
        correlation below ``min_ncc`` or forward-backward error above ``fb_max``)."""
        cfg = self.config
        p = self.parent[i]
        ang0 = self._ang0
        tp = _turn(est[p], est[i], ang0[i]) if p >= 0 else 0.0
        thetas = [tp] if p >= 0 else []
        for ch in self.children[i]:
            thetas.append(_turn(est[i], est[ch], ang0[ch]) if vis[ch] else tp)
        m = self._anchor(gray0, gray, i, q0[i], est[i], 0.0, self._margin, thetas)
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

    # -- main loop ------------------------------------------------------------------------------
    def track(self, source: FrameSource, query_points, graph: BranchGraph | None = None,
              max_frames: int | None = None, progress: Callable[[int], object] | None = None,
              on_frame: Callable[[int, np.ndarray, np.ndarray], object] | None = None) -> TrackResult:
        """Track ``query_points`` (P, 2) original pixels on the first frame of ``source``.

        ``graph`` (node id = annotation index) enables rotation-compensated templates, graph-based
        prediction of lost nodes and segment-length checks. ``progress(1)`` is called per frame, and
        ``on_frame(index, xy (P, 2) px, visible (P,))`` with that frame's result (live viewers).
        """
        cfg = self.config
        q0 = np.asarray(query_points, dtype=float)
        src_name = getattr(source, "path", "<video>")
        if q0.ndim != 2 or q0.shape[1] != 2 or len(q0) == 0:
            raise InputError("query points", f"expected a (P, 2) array, got {q0.shape}")
        self._setup(q0, graph, src_name)
        from . import match_kernels  # numba: imported (and compiled, once per machine) only when tracking
        self._kernels = match_kernels
        h, n = self.h, len(q0)
        ang0 = self._ang0
        fb_max = max(cfg.min_fb_px, cfg.max_fb_fraction * h)
        lk_params = dict(winSize=(2 * h + 1, 2 * h + 1), maxLevel=cfg.pyr_levels, criteria=_LK_CRITERIA)
        xs, vis_all, sig_all, how_all = [], [], [], []
        how = np.zeros(n, np.int8)  # per node in this frame: a key of ``HOW`` (how its position was found)
        gray0 = prev_gray = None
        est = q0.copy()
        vis = np.ones(n, bool)
        theta_last = np.zeros(n)
        seg_rot = np.zeros(n)  # rotation (rad) of segment (parent, i) since frame 0, last measured
        bend_rot = np.zeros(n)  # seg_rot[i] - seg_rot[parent] when last measured: the bend at the parent
        counts = {"anchored": 0, "invisible": 0, "rejected_ncc": 0, "rejected_fb": 0, "rejected_length": 0,
                  "lost_match": 0, "predicted_from_graph": 0, "rejected_ambiguous": 0,
                  "predicted_from_segment": 0, "from_segment": 0, "rejected_unanchored": 0,
                  "rejected_refine": 0, "held": 0, "recent_template": 0}
        recent = [None] * n  # per node: (crop of its last frame-0-anchored frame, that position, its sigma)
        held = np.zeros(n, int)  # consecutive frames each node has been held by frame-to-frame LK alone
        sig_prev = np.full(n, cfg.sigma_floor_px)
        hold_max = cfg.hold_max_sigma_px if cfg.hold_max_sigma_px is not None else 0.5 * h
        t0 = time.perf_counter()
        n_done = 0
        pool = ThreadPoolExecutor(1, thread_name_prefix="lk-refine") if cfg.threads == 2 else None
        first = None
        # the next frames decode (and are converted to grey) in a thread (GIL released) while this one is
        # tracked; closed on any exit
        with contextlib.closing(prefetched(_with_grey(source))) as frames, contextlib.ExitStack() as stack:
            if pool is not None:  # on any exit: release a refinement thread still waiting, then join it
                stack.callback(pool.shutdown)
                stack.callback(lambda: first is not None and first.abort())
            for frame, gray in frames:
                if max_frames is not None and n_done >= max_frames:
                    break
                img = frame.image
                if img.ndim != 3 or img.shape[2] != 3:
                    raise InputError(src_name, f"frame {frame.index} is not an RGB image (shape {img.shape})")
                ga = self._anchor_image(gray)
                if gray0 is None:
                    gray0 = ga
                    self.branch_halfwidth_px = None
                    self._band = self._branch_band(img, q0, graph)
                    hh, ww = gray.shape
                    out = (q0[:, 0] < -0.5) | (q0[:, 0] > ww - 0.5) | (q0[:, 1] < -0.5) | (q0[:, 1] > hh - 0.5)
                    if out.any():
                        i = int(np.flatnonzero(out)[0])
                        raise InputError(src_name, f"annotated point {i} {q0[i].tolist()} is outside the {ww}x{hh} frame",
                                         f"point {i}")
                    sig = np.full(n, cfg.sigma_floor_px)
                else:
                    prev_pts = est.astype(np.float32).reshape(-1, 1, 2)
                    f2f, st, _ = cv2.calcOpticalFlowPyrLK(prev_gray, gray, prev_pts, None, **lk_params)
                    back, st_b, _ = cv2.calcOpticalFlowPyrLK(gray, prev_gray, f2f, prev_pts.copy(),
                                                             flags=cv2.OPTFLOW_USE_INITIAL_FLOW, **lk_params)
                    fb_f2f = np.hypot(*(back - prev_pts).reshape(-1, 2).T)
                    f2f_ok = (st.ravel() == 1) & (st_b.ravel() == 1) & (fb_f2f < fb_max) & np.isfinite(f2f.reshape(-1, 2)).all(1)
                    f2f = f2f.reshape(-1, 2).astype(float)
                    prev_est, prev_vis = est.copy(), vis.copy()
                    new_est, new_vis, sig = prev_est.copy(), np.zeros(n, bool), np.zeros(n)
                    done = np.zeros(n, bool)
                    theta_now = np.zeros(n)
                    preds = prev_est.copy()
                    wide = np.zeros(n, bool)  # searched in the wide window: template posed by a borrowed rotation
                    # latest estimates (this frame's where already done): new_est holds prev_est until a node
                    # is done, so only the visibility needs its own merged copy
                    cur_vis = prev_vis.copy()
                    anchored_now = np.zeros(n, bool)
                    how = np.full(n, -1, np.int8)
                    # the refinement pass follows the first one node by node in the second thread (``_refine``)
                    first = _Progress() if pool is not None else None
                    refine = None
                    if self._band is not None and cfg.refine_pass:
                        refine = True if pool is None else pool.submit(self._refine, gray0, ga, q0, new_est,
                                                                       new_vis, fb_max, first.wait_for)
                    for i in self.order:
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
                            tp = _turn(new_est[p], pred, ang0[i]) if p >= 0 else theta
                            thetas = [tp] if p >= 0 else []
                            for ch in self.children[i]:
                                # a child not followed: assume the branch continues straight
                                thetas.append(_turn(pred, f2f[ch], ang0[ch]) if f2f_ok[ch] and prev_vis[ch] else tp)
                        # a wide search (no frame-to-frame or segment prediction to trust) is a re-acquisition
                        # whatever the previous frame said: the same ambiguity and geometry checks apply
                        reacquiring = not prev_vis[i] or r > h or held[i] > 0
                        preds[i], wide[i] = pred, r > h
                        m = self._anchor(gray0, ga, i, q0[i], pred, theta, r, thetas)
                        ok = m is not None
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
                                ok = False
                                counts["rejected_fb"] += 1
                            elif p >= 0 and reacquiring and not new_vis[p]:
                                # re-acquiring while the parent is lost too: nothing checks the match's
                                # geometry (a tip re-found next to a leaf edge 18 px off, then followed
                                # to 67 px, on simulator seed 0); wait until the parent is seen again
                                ok = False
                                counts["rejected_unanchored"] += 1
                            elif p >= 0 and new_vis[p]:
                                d = math.hypot(xy[0] - new_est[p, 0], xy[1] - new_est[p, 1])
                                l0 = self.rest_len[i]
                                if d > (1 + cfg.max_stretch) * l0 + cfg.length_tol_px or d < cfg.min_length_fraction * l0 - cfg.length_tol_px:
                                    ok = False
                                    counts["rejected_length"] += 1
                        if ok:
                            new_est[i], new_vis[i] = xy, True
                            how[i] = 0
                            anchored_now[i] = score >= cfg.recent_min_ncc
                            if p >= 0:
                                seg_rot[i] = _turn(new_est[p], xy, ang0[i])
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
                        elif (cfg.recent_template and recent[i] is not None and r <= h and i not in self._tips
                              and (rm := self._match_recent(gray, recent[i], pred, r, fb_max, i, new_est, new_vis))
                              is not None):
                            # the frame-0 template does not fit, but the node's appearance in the last frame it was
                            # anchored to frame 0 does: measured against that frame, so its error is that anchor's
                            # plus this match's (no accumulation while the node stays off its frame-0 template)
                            new_est[i], new_vis[i] = rm[0], True
                            sig[i] = math.sqrt(recent[i][2] ** 2 + rm[1] ** 2 + cfg.fallback_sigma_px ** 2)
                            if p >= 0:
                                seg_rot[i] = _turn(new_est[p], rm[0], ang0[i])
                            held[i] += 1  # off its frame-0 template: finding it there again is a re-acquisition
                            counts["recent_template"] += 1
                            how[i] = 1
                        elif (cfg.hold and f2f_ok[i] and prev_vis[i] and (p < 0 or new_vis[p])
                              and (s_hold := math.sqrt(max(sig_prev[i], cfg.fallback_sigma_px) ** 2 + (fb_f2f[i] / 2) ** 2
                                                       + cfg.hold_step_px ** 2))
                              <= hold_max and self._length_ok(i, f2f[i], new_est, new_vis)
                              and (p < 0 or (seg is not None and seg[2] >= cfg.min_ncc
                                             and math.hypot(*(f2f[i] - seg[0])) <= cfg.hold_agree_px))
                              and _f2f_ncc(prev_gray, gray, prev_est[i], f2f[i], h) >= cfg.hold_min_ncc):
                            # the frame-0 template does not fit here now (blur, a leaf, a pose far from frame 0),
                            # but frame-to-frame LK followed the node from a measured (or held) position: keep it
                            # visible with a sigma that grows as a random walk (``hold_step_px`` a frame plus the
                            # round trip's own error) until the template fits again or sigma passes ``hold_max``
                            new_est[i], new_vis[i], sig[i] = f2f[i], True, s_hold
                            if p >= 0:
                                seg_rot[i] = _turn(new_est[p], f2f[i], ang0[i])
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
                    if refine is not None:
                        out = refine.result() if pool is not None else self._refine(gray0, ga, q0, new_est,
                                                                                     new_vis, fb_max)
                        self._apply_refine(out, new_est, new_vis, sig, preds, counts, wide)
                    hh, ww = gray.shape
                    new_est[:, 0] = np.clip(new_est[:, 0], -0.5, ww - 0.5)
                    new_est[:, 1] = np.clip(new_est[:, 1], -0.5, hh - 0.5)
                    est, vis = new_est, new_vis
                    if cfg.recent_template:
                        self._keep_recent(ga, est, sig, anchored_now, recent)
                prev_gray = gray
                xs.append(est.copy())
                how_all.append(np.where(vis, how, -1).astype(np.int8))
                vis_all.append(vis.copy())
                sig_all.append(np.maximum(sig, cfg.sigma_floor_px))
                sig_prev = sig_all[-1]
                n_done += 1
                if progress is not None:
                    progress(1)
                if on_frame is not None:
                    on_frame(n_done - 1, est.copy(), vis.copy())
        if n_done == 0:
            raise InputError(src_name, "the video has no frames")
        info = {"how": np.stack(how_all, axis=1), "tracker": "lk-anchored", "patch_radius_px": h, "branch_halfwidth_px": self.branch_halfwidth_px, "frames": n_done,
                "time_total_s": time.perf_counter() - t0, **counts}
        return TrackResult(point_ids=np.arange(n), xy=np.stack(xs, axis=1), visible=np.stack(vis_all, axis=1),
                           sigma_px=np.stack(sig_all, axis=1), fps=source.fps, info=info)
