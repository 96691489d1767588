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
3c. **Sigma instead of dropping** (``LKConfig.soft_reject``): a frame-0 match that passed ``min_ncc`` and the
   distinctness tests but failed only the forward-backward limit, the parent check or the segment length is reported
   with sigma >= ``fallback_sigma_px`` instead of lost (measured with ``benchmarks/bench_lost_positions.py``: such
   matches were right to median 0.4-1.1 px, p90 1.5-2.5 px; see ``LKConfig``). **Bridge**
   (``LKConfig.bridge``, :mod:`~rce_gtsam.track.lk_bridge`): after the refinement pass, a node still lost between a
   seen ancestor and a seen descendant is predicted by the similarity that moved those two and searched in the
   narrow window with every re-acquisition test. Both against revision cec59db in one run
   (``bench_track_plant2.py --kappa --baseline cec59db``): plant 2, frames 120-359 by 60-frame window, visible share
   of TAPIR's rows 85/75/64/90 -> 91/90/90/99 % (240-299: 89.7 %), p90 distance 1.5-1.7 -> 1.4-2.1 px, tip visible
   38 -> 96 %; kappa against the TAPIR run's Spearman 0.82 -> 0.74, log-RMS 0.51 -> 0.49, inside its CI 15 -> 15
   of 23 (kappa moves with which gust frames count, and TAPIR is not the truth); texture bed (seeds 0-4, none /
   delay) visible in the fastest 30 % of frames 99.3 / 99.1 -> 99.9 / 99.8 %, kappa log-RMSE 0.87 / 0.89 -> 0.85
   / 0.86 (limited by the bed's 0.49-degree bending: the true tracks plus white noise of 0.1 px per axis give
   0.28 on seeds 0-1); simulator renders (seeds 0-4) within the tracker's own jitter except seed 3's largest
   visible error 9.8 -> 13.4 px.
3d. **Segment check** (``LKConfig.segment_check``, issue 38; off by default): after the clip, each accepted frame-0
   match is compared with where its hinged segment search put the node (two measurements from different pixels);
   beyond a bound calibrated on the clip's own distances (99 % of a 2-D Gaussian difference), its sigma grows by the
   unexplained part (``HOW`` 4); no position or visibility changes. Where the gross errors came from on the texture
   bed (``benchmarks/bench_texture_gross.py``, record ``texture_gross``): 83 % of the squared error in errors > 1 px
   was at two nodes, a texture-poor interior node (5: its pale stem is invisible against the background, and the
   texture within its band moves less than the node, so the match lags toward the frame-0 position: its across-stem
   error correlates -0.6 with its displacement, node 6's -0.8) and the tip; 59 % came from frame-0 matches (sigma
   median 0.07 px, |error|/sigma 2.6). With the check: median sigma of node 5 0.28 -> 0.37 px, of the tip 0.53 ->
   0.62 px, median |error|/sigma 2.41 -> 2.25 overall; kappa log-RMSE 0.856 -> 0.852, truth in CI 66.5 -> 66.1 %
   (the bed's kappa is limited by its 0.49-degree bending, not by these nodes' weights). Plant 2 against revision
   994f002 in one run: visible share and p90 distance to TAPIR unchanged (91/90/90/99 %, 1.55-2.06 px: positions are
   the same), kappa against the TAPIR run's Spearman 0.74 -> 0.75, log-RMS 0.49 -> 0.46, inside its CI 15 -> 17 of
   23. Simulator renders (``bench_track.py --baseline 994f002``, seeds 0-4, with the check on): positions and
   visibility bit-identical, median sigma 0.062-0.069 px as before, but its 90th percentile 0.13-0.20 -> 0.18-0.38
   px, and Spearman of kappa 0.78/0.90/0.91/0.68/0.96 -> 0.78/0.89/0.94/0.53/0.94 (the 0.001-px jitter row moves
   seed 3 by 0.00): a change of the smoother's weights that helps nowhere clearly and costs seed 3, so it is off
   until the user path (``benchmarks/bench_user_path.py``) has been re-run with it. On the bed as corrected later
   (the whole stem moving over a still background; the numbers above are from the bed before) the check gives
   kappa log-RMSE 0.780 -> 0.731 and truth in CI 86.5 -> 88.7 % (record ``texture_gross``).
   Measured and not kept (``bench_texture_gross.py``): the smoother's robust loss on the bed (Huber 1.345 / Cauchy
   2.385: kappa log-RMSE 0.851 / 0.851 against 0.856; the gross errors are persistent biases, not outliers), a band
   margin of 0 px (bed error RMS 0.360 -> 0.323 px but kappa log-RMSE 0.891; plant 2 visible in the gusts
   91/90/90/99 -> 87/83/82/94 %, kappa Spearman against TAPIR's 0.74 -> 0.63), dropping from the refinement re-match
   the template pixels the static background explains better (error RMS 0.360 -> 0.349 px; plant 2's tip visible 96
   -> 84 %), and a tip beyond the bound taking its segment position (bed tip error median 0.73 -> 0.52 px, but on
   plant 2 those tips were 2.3 px from TAPIR's where the match was 0.6 px).
4. **Uncertainty**: ``sigma_px = sqrt(s_lk^2 + (fb/2)^2 + sigma_floor_px^2)`` with the LK
   least-squares standard error ``s_lk = sqrt(residual_variance / lambda_min(G))`` (G = structure
   tensor of the template, residual = template minus the matched patch, so appearance change counts)
   and fb the forward-backward error. Invisible entries get sigma = the search radius.

Modules: this one holds :class:`LKTracker` and its frame loop (frame-to-frame LK, the refinement thread, the
result); :mod:`~rce_gtsam.track.lk_config` its settings (:class:`LKConfig`, the constants' reasons) and :data:`HOW`;
:mod:`~rce_gtsam.track.lk_frame0` the frame-0 set-up (topology, branch band, colour mask, strips, templates);
:mod:`~rce_gtsam.track.lk_measure` the measurements (frame-0 match, segment search, refinement pass, recent
template); :mod:`~rce_gtsam.track.lk_node` the first pass's decision at one node (steps 1-3b, 3c's soft rejection);
:mod:`~rce_gtsam.track.lk_bridge` the bridge step (3c);
:mod:`~rce_gtsam.track.match_kernels` the compiled kernels.

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
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

import cv2
import numpy as np

from ..errors import InputError
from ..graph import BranchGraph
from .lk_bridge import Bridge
from .lk_config import HOW, LKConfig
from .lk_frame0 import Frame0Setup
from .lk_measure import Measurement
from .lk_node import FirstPassFrame, NodeDecision
from .result import TrackResult
from .sources import FrameSource, prefetched

__all__ = ["LKTracker", "LKConfig", "HOW"]

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


class LKTracker(Bridge, NodeDecision, Measurement, Frame0Setup):
    """Drift-free Lucas-Kanade tracker (see module docstring). ``LKTracker(LKConfig()).track(src, pts, graph)``.

    Its methods live in one module per job: the frame-0 set-up (:class:`~rce_gtsam.track.lk_frame0.Frame0Setup`),
    the measurements (:class:`~rce_gtsam.track.lk_measure.Measurement`) and the first pass's per-node decision
    (:class:`~rce_gtsam.track.lk_node.NodeDecision`); :meth:`track`, the frame loop, is here."""

    def __init__(self, config: LKConfig | None = None):
        self.config = config or LKConfig()

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
                  "rejected_refine": 0, "held": 0, "recent_template": 0, "soft": 0, "bridged": 0, "segment_check": 0}
        recent = [None] * n  # per node: (crop of its last frame-0-anchored frame, that position, its sigma)
        held = np.zeros(n, int)  # consecutive frames each node has been held by frame-to-frame LK alone
        sig_prev = np.full(n, cfg.sigma_floor_px)
        hold_max = cfg.hold_max_sigma_px if cfg.hold_max_sigma_px is not None else 0.5 * h
        t0 = time.perf_counter()
        n_done = 0
        pool = ThreadPoolExecutor(1, thread_name_prefix="lk-refine") if cfg.threads == 2 else None
        first = None
        check = cfg.segment_check and graph is not None and cfg.mask_to_branch
        seg_d_all = []  # per frame after the first: ``FirstPassFrame.seg_d``
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
                    fr = FirstPassFrame(
                        gray0=gray0, ga=ga, gray=gray, prev_gray=prev_gray, q0=q0, f2f=f2f, f2f_ok=f2f_ok,
                        fb_f2f=fb_f2f, prev_est=prev_est, prev_vis=prev_vis, new_est=new_est, new_vis=new_vis, sig=sig,
                        done=done, cur_vis=cur_vis, theta_now=theta_now, preds=preds, wide=wide,
                        anchored_now=anchored_now, how=how, theta_last=theta_last, seg_rot=seg_rot, bend_rot=bend_rot,
                        held=held, recent=recent, counts=counts, sig_prev=sig_prev, fb_max=fb_max, hold_max=hold_max,
                        first=first, seg_d=np.full(n, np.nan) if check else None)
                    for i in self.order:  # in graph order: a node's segment search hinges at its parent's new match
                        self._first_pass_node(fr, i)
                    if refine is not None:
                        out = refine.result() if pool is not None else self._refine(gray0, ga, q0, new_est,
                                                                                     new_vis, fb_max)
                        soft = how == 4
                        sig_soft = sig[soft]
                        self._apply_refine(out, new_est, new_vis, sig, preds, counts, wide)
                        sig[soft] = np.maximum(sig[soft], sig_soft)  # a re-match does not lift the checks it failed
                    if cfg.bridge and self._band is not None:
                        self._bridge(gray0, ga, q0, new_est, new_vis, sig, how, held, counts, fb_max,
                                     hold_max)
                    hh, ww = gray.shape
                    new_est[:, 0] = np.clip(new_est[:, 0], -0.5, ww - 0.5)
                    new_est[:, 1] = np.clip(new_est[:, 1], -0.5, hh - 0.5)
                    est, vis = new_est, new_vis
                    if check:
                        seg_d_all.append(fr.seg_d)
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
        xy_t, vis_t, sig_t, how_t = (np.stack(a, axis=1) for a in (xs, vis_all, sig_all, how_all))
        self.segment_check_px = None
        if check and seg_d_all:  # frame 0 has no segment search: its column is NaN
            self._segment_check(vis_t, sig_t, how_t, np.stack([np.full(n, np.nan)] + seg_d_all, axis=1), counts)
        info = {"how": how_t, "segment_check_px": self.segment_check_px,
                "tracker": "lk-anchored", "patch_radius_px": h, "branch_halfwidth_px": self.branch_halfwidth_px, "frames": n_done,
                "time_total_s": time.perf_counter() - t0, **counts}
        return TrackResult(point_ids=np.arange(n), xy=xy_t, visible=vis_t, sigma_px=sig_t, fps=source.fps, info=info)
