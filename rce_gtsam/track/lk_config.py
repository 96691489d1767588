"""Settings of the default tracker (:class:`LKConfig`) and the codes of how each position was found (:data:`HOW`).

The algorithm they steer is described in :mod:`rce_gtsam.track.lk`; each field's docstring says what it does and
what it was measured to do.

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
"""

from __future__ import annotations

from dataclasses import dataclass

from ..errors import InputError


@dataclass(frozen=True)
class LKConfig:
    """Settings of :class:`~rce_gtsam.track.lk.LKTracker` (pixels unless stated; see :mod:`rce_gtsam.track.lk` and this
    module's docstring for the reasons).

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
    recent_template, recent_min_ncc: see :mod:`rce_gtsam.track.lk` (3b). The stored appearance is only as good as its
        anchor: 0.8 (the template explains >= 64 % of the patch variance) keeps a node partly covered by a leaf
        from being stored. Without the narrow-window rule the recent template locked onto the occluding leaf 13-16
        px off in ``tests/test_track_lk.py``'s scene, and at a tip matched with its full patch 7.6 px off
        (simulator seed 0): both are excluded.
    segment_tiebreak: see :mod:`rce_gtsam.track.lk` (3b); re-uses ``min_segment_ncc`` and h/2.
    tip_segment_fallback: a tip (a node with a parent and no child) whose own patch fails is placed where the
        hinged segment search puts it (``min_segment_ncc``), as ``segment_fallback`` does for every node: a tip's
        band is short and thin, and it was marked lost in ~90 % of the texture bed's frames while the positions
        were right to ~0.5 px; with it the tip is visible throughout (bed seed 0: error median 0.96 px, p90 3.0 px,
        sigma median 0.5 px).
    soft_reject: keep a frame-0 match visible, with sigma = sqrt(s_lk^2 + (fb/2)^2 + ``fallback_sigma_px``^2) (px),
        when it passed ``min_ncc`` and the distinctness tests and failed only the forward-backward limit, the
        parent check (re-acquired while the parent is lost) or the segment-length check -- and that sigma is at most
        ``hold_max_sigma_px`` -- instead of marking the node lost (``HOW`` 4). Measured before adopting it
        (``benchmarks/bench_lost_positions.py``): such rejected matches were right to median 0.4-1.1 px, p90
        1.5-2.5 px, over 3 px in 0-7 % (texture bed, tip 150 px, seeds 0-2, against the truth; plant 2 against
        TAPIR, n = 324), with no trend in the forward-backward error (median 0.6-0.9 px for fb < 0.5 px and for
        fb 1-2 px on plant 2); a 2-D Gaussian error of 1 px per axis has median 1.18 px and p90 2.15 px, hence
        the floor. The matches rejected for an indistinct peak (median 1.3-10 px, p90 11-42 px) or a correlation
        below ``min_ncc`` (median 10.5 px) stay lost. A node kept this way counts as re-acquired in the next frame
        (the strict checks apply again).
    bridge: after the refinement pass, re-find each lost node that has a seen ancestor and a seen descendant from the
        similarity that moves those two (:mod:`~rce_gtsam.track.lk_bridge`; ``HOW`` 5), with every re-acquisition
        test. On plant 2's gust windows (frames 120-359) it raised the visible share of TAPIR's rows 89/82/82/96 ->
        91/90/90/99 % at the same p90 distance to TAPIR (1.4-2.1 px); on the simulator's renders (seeds 0/1/3) the
        figures moved within the tracker's own jitter resolution.
    segment_check: compare each node's accepted frame-0 match with where its hinged segment search puts it (when that
        search, at a visible parent, matched at >= ``min_segment_ncc``): two measurements of the node from different
        pixels (its own patch; the whole frame-0 strip of its segment). After the clip, their distances d are checked
        against a bound calibrated on the clip itself (:meth:`~rce_gtsam.track.lk_measure.Measurement._segment_check`:
        the distances taken as the length of a 2-D Gaussian difference, sigma = median / 1.1774, bound = 3.035 sigma,
        i.e. 99 % of such differences; nothing with fewer than 200 distances; ``info["segment_check_px"]``). Beyond it
        the node keeps its match, with sigma^2 + (d - bound)^2 / 2 (``HOW`` 4: either measurement may be the wrong one,
        so each is off by about the unexplained part / sqrt(2); continuous at the bound). No position or visibility
        changes. Off by default (see :mod:`rce_gtsam.track.lk` 3d: it moved no kappa figure clearly on the bed or
        the simulator renders, and on simulator seed 3 Spearman of kappa fell 0.68 -> 0.53). Issue 38: on the
        texture bed most of the squared error in errors > 1 px came from frame-0 matches at
        texture-poor nodes (a pale stem before surroundings that move less than the node) reported with sigma
        0.1-0.3 px at median |error|/sigma 2.6-5.3; the match-to-segment distance correlated 0.74 with the match's
        error. Measured: ``benchmarks/bench_texture_gross.py`` (record ``texture_gross``), the simulator renders and
        plant 2 in :mod:`rce_gtsam.track.lk` (3d). Tried and not kept: a tip beyond the bound taking the segment
        position (bed: tip error median 0.73 -> 0.52 px; but on plant 2 the replaced tip was 2.3 px from TAPIR's
        where its own match was 0.6 px), widening by the whole distance (on clean simulator renders the flagged
        nodes' sigma became 3x their error), and checking online with the bound from the frames so far (the first
        frames, near the rest pose, gave a low bound: a third of a 40-frame render's node-frames flagged).
    threads: 2 = the refinement pass runs in a second thread, node by node right behind the first pass (a node
        is re-matched as soon as the first pass has finished it, its parent and its children, and after its
        parent's re-match: exactly the values a pass after the first reads, so the tracks are bit-identical to
        ``threads=1``, the default, which runs the two passes one after the other). The compiled kernels and
        OpenCV release the GIL, but the per-node Python between them does not, and a re-match is short (a
        2-px search): on the shared 2-core machine (load 4-6) two threads were 0.75-0.98x as fast as one
        (``benchmarks/bench_track.py``, ``current2`` row), so one thread is the default. With less Python per node
        (see the Speed paragraph of :mod:`rce_gtsam.track.lk`) two threads were 1.08x as fast alone and 1.06x from
        the mp4 at load 2.3-2.5, for 1.1x the CPU time.
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
    soft_reject: bool = True
    bridge: bool = True
    segment_check: bool = False

    def __post_init__(self):
        if isinstance(self.threads, bool) or not isinstance(self.threads, int) or self.threads not in (1, 2):
            raise InputError("LKConfig", f"threads must be 1 or 2, got {self.threads!r}", "threads")


#: ``TrackResult.info["how"]`` (P, F) int8 of :class:`~rce_gtsam.track.lk.LKTracker`: how each position was found.
HOW = {-1: "invisible", 0: "anchored to frame 0", 1: "recent template", 2: "held by frame-to-frame LK",
       3: "hinged segment", 4: "frame-0 match, sigma widened",
       5: "frame-0 match, bridged between seen neighbours"}
