"""The length channel: each tracked segment's projected length over time, and the test that names out-of-plane swing.

A segment that swings out of the branch plane (rotates toward or away from the camera) changes its length in the
image, whereas planar bending in the image plane keeps it. The diagnosis' bend angles never read that channel;
this module does (:class:`LengthChannel`, from the pipeline's pre-smoothed node positions at their observed frames).

**Statistic.** Each segment's relative length change l_e(t) = L_e(t) / median L_e - 1 is first projected off the
columns [1, t, z, z^2, dz/dt] (z the rank-1 fit's excitation, deg): a tilted branch plane foreshortens a segment
as its in-plane heading turns (a function of z: first order in a tilted plane, second order in the image plane),
a tracker that slides along the stem with the node's deflection adds a node-wise multiple of z (slide), slow
drift adds a line, and the smoother's lag a multiple of dz/dt. What is left of an out-of-plane swing is the part
of the out-of-plane excitation that the in-plane one does not carry (the wind's direction wanders): a time course
*common* to the segments (chi_e(t), the elevation, is the sum of kappa_j z_o(t) from the root, so every segment
carries z_o with a loading that grows toward the tip). A tracker's error is a node's own: it changes the two
segments that meet at the node with opposite signs (+1 / -1) and nothing else. So, as the second excitation's
test on the bend residuals (:func:`~rce_gtsam.diagnosis.score_test.shared_time_course_test`): two sets of
segments that share no tracked node (:func:`~rce_gtsam.model.row_sets.node_disjoint_split`), each row scaled to
unit RMS, and the largest singular value of their cross-product X_A X_B'.

**Null and calibration.** X_B held fixed, X_A replaced by multivariate phase surrogates (each row's spectrum and
the set's cross-spectra kept, missing frames missing): a node's error, however coloured and however it follows
the motion, stays within the set it belongs to. p = (1 + #{surrogates >= observed}) / (1 + n). The false-alarm
rate on planar recordings with every tracker-artifact family at 1x and 2x is measured by
``benchmarks/bench_out_of_plane.py``.

The same residual rows give the swing's course w (:func:`swing_course`: their leading right singular vector,
unit RMS), the course the :class:`~rce_gtsam.effects.out_of_plane.OutOfPlane` effect adds to the bending.
Units: px (lengths), 1 (relative changes), deg (z), frames.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.compliance import draw_phases, residual_spectrum, surrogate_slice
from ..model.row_sets import node_disjoint_split, shared_node_matrix
from .one_node import heaviest, rows_without, shares_by_node
from .swing_signature import agreement, rank_growth

#: phase surrogates of the null (p resolution 1/1000)
N_SURROGATES = 999
#: surrogates per batch (memory)
BATCH = 100
#: contiguous time blocks of the held-out length prediction (:func:`heldout_length_gain`)
HELDOUT_FOLDS = 5
#: the length channel's own family-wise level: the diagnosis' other candidates share alpha, this test its own
#: (the nominal family-wise false-alarm rate of a diagnosis is then alpha + ALPHA_OOP)
ALPHA_OOP = 0.01


@dataclass(frozen=True, eq=False)
class LengthChannel:
    """Segment lengths over the frames of the bend response.

    rel: (S, T) relative length change L_e(t) / median_t L_e - 1 (NaN = a node unobserved); length_px: (S,) the
    median lengths (px); segments: [(parent, child)] of the rows; root_distance: (S,) normalised root distance of
    each segment's child (0..1); frames: (T,) the video frame of each column (those of the bend response)."""

    rel: np.ndarray
    length_px: np.ndarray
    segments: list
    root_distance: np.ndarray
    frames: np.ndarray

    @property
    def nodes(self) -> list:
        """The tracked nodes each row's length is measured between."""
        return [frozenset(e) for e in self.segments]


def length_channel(xy: np.ndarray, node_ids, graph, frames) -> LengthChannel:
    """The :class:`LengthChannel` of positions ``xy`` (N, F, 2) px, NaN = unobserved, rows ``node_ids``, for the
    edges of ``graph`` and the video ``frames`` (T,) the bend response keeps."""
    row = {int(n): i for i, n in enumerate(node_ids)}
    frames = np.asarray(frames, int)
    segs = [tuple(map(int, e)) for e in graph.edges if int(e[0]) in row and int(e[1]) in row]
    L = np.array([np.hypot(*(xy[row[c]] - xy[row[p]])[frames].T) for p, c in segs]).reshape(len(segs), len(frames))
    with np.errstate(invalid="ignore"):
        med = np.array([np.nanmedian(r) if np.isfinite(r).any() else np.nan for r in L])
        rel = L / med[:, None] - 1.0
    dist = {graph.root: 0.0}
    for c in graph.nodes[1:]:
        p = graph.parent[c]
        dist[c] = dist[p] + (med[segs.index((p, c))] if (p, c) in segs and np.isfinite(med[segs.index((p, c))])
                             else 0.0)
    dmax = max(max(dist.values()), 1e-9)
    return LengthChannel(rel=rel, length_px=med, segments=segs,
                         root_distance=np.array([dist[c] / dmax for _, c in segs]), frames=frames)


def length_channel_of(result) -> LengthChannel:
    """The length channel of an :class:`~rce_gtsam.pipeline.AnalysisResult`: the moving-average pre-smoothed
    positions (each node on its own) at the frames the tracker observed, at the bend response's frames.

    Not the factor-graph smoother's positions, which the bend angles come from: its edge factors hand part of a
    node's along-stem error to its neighbours, so segments that share no node no longer carry independent errors.
    Measured on planar recordings (20 seeds, 450 frames, p <= 0.01): along-stem coloured noise at 2x its measured
    size fired the test on 4/20 with smoothed positions, 0/20 pre-smoothed; drift 2x 2/20 and 0/20; a swing at the
    default strength was found on 20/20 and 19/20."""
    xy = np.array(result.smoothed.presmoothed.xy, float)
    xy[~result.smoothed.observed] = np.nan
    return length_channel(xy, result.tracks.node_ids, result.graph, result.response.frames)


def excitation_columns(z: np.ndarray) -> np.ndarray:
    """(5, T) the columns projected out of every segment's length change: 1, t, z, z^2, dz/dt (each unit RMS)."""
    T = len(z)
    tt = np.linspace(-1.0, 1.0, T)
    zc = z - z.mean()
    X = np.stack([np.ones(T), tt, zc, zc * zc - np.mean(zc * zc), np.gradient(z)])
    return X / np.maximum(np.sqrt(np.mean(X * X, axis=1, keepdims=True)), 1e-300)


def length_residuals(channel: LengthChannel, z: np.ndarray, min_share: float = 0.25) -> tuple[np.ndarray, np.ndarray]:
    """(rows (S', T) scaled to unit RMS, NaN = missing; the kept row indices): each segment's relative length change
    less its least-squares fit on :func:`excitation_columns` over its observed frames. Segments observed on less
    than ``min_share`` of the frames, or with no spread left, are dropped (a tracker that loses nodes in gusts at
    twice its measured rate leaves a median 36-78 % of a segment's frames on the 3-D simulator's swinging
    recordings; at 0.5 the test lost most tip segments, where the swing is largest)."""
    X = excitation_columns(np.asarray(z, float))
    out, kept = [], []
    for i, r in enumerate(channel.rel):
        ok = np.isfinite(r)
        if ok.sum() < max(min_share * len(r), X.shape[0] + 3):
            continue
        beta = np.linalg.lstsq(X[:, ok].T, r[ok], rcond=None)[0]
        res = np.where(ok, r - beta @ X, np.nan)
        rms = float(np.sqrt(np.nanmean(res * res)))
        if rms <= 1e-12:
            continue
        out.append(res / rms)
        kept.append(i)
    return (np.array(out).reshape(len(out), X.shape[1]), np.array(kept, int))


@dataclass(frozen=True)
class LengthTest:
    """The length channel's test. p: phase-surrogate p-value of the shared course; statistic: largest singular
    value of X_A X_B' (unit-RMS rows); null_median: the surrogates' median of it; rows_a, rows_b: segments in each
    node-disjoint set; corr_a, corr_b: correlation of each set's leading course with w (diagnostic);
    loadings: (S,) each segment's regression of its relative length change on w (1 per unit RMS of w, NaN =
    dropped); same_sign_share: share of the kept loadings with the sign of their sum; tip_growth: Spearman
    correlation of |loading| with root distance (a swing's grows toward the tip); agreement, agreement_p: how
    neighbouring segments' loadings on the course the two sets share (:func:`shared_course`) agree, and its
    sign-flip p (the swing's signature: :mod:`~rce_gtsam.diagnosis.swing_signature`); heldout_gain_pct:
    :func:`heldout_length_gain` of the two sets (%)."""

    p: float
    statistic: float
    null_median: float
    rows_a: tuple
    rows_b: tuple
    loadings: np.ndarray
    same_sign_share: float
    tip_growth: float
    agreement: float = 0.0
    agreement_p: float = 1.0
    heldout_gain_pct: float = float("nan")
    carrying_node: int | None = None
    carrying_share: float = float("nan")
    heldout_gain_without_node_pct: float = float("nan")
    p_without_node: float = float("nan")

    def as_dict(self) -> dict:
        return {"length_p": self.p, "length_statistic": self.statistic, "length_null_median": self.null_median,
                "length_heldout_gain_pct": self.heldout_gain_pct,
                "length_carrying_node": self.carrying_node, "length_carrying_share": self.carrying_share,
                "length_heldout_gain_without_node_pct": self.heldout_gain_without_node_pct,
                "length_p_without_node": self.p_without_node,
                "length_rows_a": list(self.rows_a), "length_rows_b": list(self.rows_b),
                "length_loadings": [float(v) for v in self.loadings], "length_same_sign_share": self.same_sign_share,
                "length_tip_growth": self.tip_growth, "length_agreement": self.agreement,
                "length_agreement_p": self.agreement_p}


def swing_course(channel: LengthChannel, z: np.ndarray) -> np.ndarray:
    """(T,) the swing's course w (unit RMS): the leading right singular vector of the segments' length changes
    less their excitation columns (:func:`length_residuals`, missing frames 0), signed so that the loadings'
    sum is positive. Zeros where no segment is usable."""
    R, kept = length_residuals(channel, z)
    T = channel.rel.shape[1]
    if len(kept) == 0:
        return np.zeros(T)
    U, S, Vt = np.linalg.svd(np.nan_to_num(R), full_matrices=False)
    w = Vt[0] * np.sign(np.sum(U[:, 0]) or 1.0)
    return w / max(float(np.sqrt(np.mean(w * w))), 1e-300)


def loadings_on(channel: LengthChannel, w: np.ndarray) -> np.ndarray:
    """(S,) each segment's least-squares coefficient of its relative length change on w (with a constant), NaN
    where fewer than 10 frames are observed."""
    out = np.full(len(channel.rel), np.nan)
    for i, r in enumerate(channel.rel):
        ok = np.isfinite(r)
        if ok.sum() < 10:
            continue
        A = np.stack([np.ones(ok.sum()), w[ok]], axis=1)
        out[i] = np.linalg.lstsq(A, r[ok], rcond=None)[0][1]
    return out


def out_of_plane_test(channel: LengthChannel, z: np.ndarray, seed: int = 0,
                      n_surrogates: int = N_SURROGATES) -> LengthTest | None:
    """The length channel's test of a course common to node-disjoint segments (module docstring), or None where
    the branch has too few segments for two node-disjoint sets."""
    R, kept = length_residuals(channel, z)
    if len(kept) < 4:
        return None
    nodes = [channel.nodes[i] for i in kept]
    s = channel.root_distance[kept]
    halves = node_disjoint_split(s, shared_node_matrix(s, nodes), seed, edge_nodes=nodes)
    if halves is None or len(halves[0]) < 2 or len(halves[1]) < 2:
        return None
    p, q, qs = _shared_course_p(R, halves, seed, n_surrogates)
    w = swing_course(channel, z)
    load = loadings_on(channel, w)
    fin = np.isfinite(load)
    tot = np.sign(np.nansum(load)) or 1.0
    same = float(np.mean(np.sign(load[fin]) == tot)) if fin.any() else 0.0
    growth = rank_growth(channel.root_distance, load)
    agree, agree_p = agreement(channel.segments, loadings_on(channel, shared_course(R, halves)), seed)
    seg = [channel.segments[i] for i in kept]
    gain = heldout_length_gain(channel, z, R, kept, halves)
    node, share, gain_wo, p_wo = gain_without_carrying_node(channel, z, R, kept, load, seed,
                                                            tested=list(halves[0]) + list(halves[1]))
    return LengthTest(heldout_gain_pct=gain, carrying_node=node, carrying_share=share,
                      heldout_gain_without_node_pct=gain_wo, p_without_node=p_wo, p=p, statistic=q,
                      null_median=float(np.median(qs)),
                      rows_a=tuple(f"{a}->{b}" for a, b in (seg[i] for i in halves[0])),
                      rows_b=tuple(f"{a}->{b}" for a, b in (seg[i] for i in halves[1])),
                      loadings=load, same_sign_share=same, tip_growth=growth,
                      agreement=agree, agreement_p=agree_p)


def _shared_course_p(R: np.ndarray, halves, seed: int, n_surrogates: int = N_SURROGATES):
    """(p, statistic, surrogate statistics) of the course common to the node-disjoint row sets ``halves`` of the
    unit-RMS residual rows ``R`` (the module's statistic and null)."""
    XA, XB = R[halves[0]], R[halves[1]]
    obs_a = np.isfinite(XA)
    XA0, XB0 = np.where(obs_a, XA, 0.0), np.nan_to_num(XB)
    q = float(np.linalg.svd(XA0 @ XB0.T, compute_uv=False)[0])
    T = R.shape[1]
    spectrum = residual_spectrum(XA)
    draws = draw_phases(np.random.default_rng(seed), n_surrogates, T)
    qs = np.concatenate([np.linalg.svd((surrogate_slice(spectrum, T, draws, slice(i, i + BATCH)) * obs_a) @ XB0.T,
                                       compute_uv=False)[:, 0] for i in range(0, n_surrogates, BATCH)])
    return float((1 + np.sum(qs >= q)) / (1 + len(qs))), q, qs


def shared_course(R: np.ndarray, halves) -> np.ndarray:
    """(T,) the course the node-disjoint row sets ``halves`` of the unit-RMS residual rows ``R`` share, unit RMS: the
    leading singular pair (u, v) of X_A X_B' (the test's statistic) gives each set's loadings, and the course is
    X_A' u + X_B' v. A node's own error does not enter X_A X_B', so these loadings show where the shared part loads
    (:mod:`~rce_gtsam.diagnosis.swing_signature`), where the leading course of all rows (:func:`swing_course`)
    can be led by the node-wise noise of many rows when the swing is weak: on the simulator's swings in the image
    plane (10 seeds, 450 frames), the agreement on that course failed at p <= 0.01 on 3 of the 9 whose length test
    fired, on this one on none."""
    XA, XB = np.nan_to_num(R[list(halves[0])]), np.nan_to_num(R[list(halves[1])])
    U, _, Vt = np.linalg.svd(XA @ XB.T)
    w = XA.T @ U[:, 0] + XB.T @ Vt[0]
    return w / max(float(np.sqrt(np.mean(w * w))), 1e-300)


def _leading_course(rows: np.ndarray) -> np.ndarray:
    """(T,) the leading right singular vector of unit-RMS residual rows (missing frames 0), unit RMS."""
    w = np.linalg.svd(np.nan_to_num(rows), full_matrices=False)[2][0]
    return w / max(float(np.sqrt(np.mean(w * w))), 1e-300)


def heldout_length_gain(channel: LengthChannel, z: np.ndarray, R: np.ndarray, kept: np.ndarray, halves,
                        n_folds: int = HELDOUT_FOLDS) -> float:
    """The out-of-plane term's held-out error on the observable it models, the segments' lengths (%).

    ``R``, ``kept``: :func:`length_residuals` of ``channel`` and ``z``; ``halves``: two node-disjoint sets of row
    positions in ``R``. For each set in turn: the swing course w is taken from the *other* set's length
    residuals (all frames: that set is measured there), and each segment of this set is predicted on held-out
    frames (``n_folds`` contiguous blocks) from its fit on the remaining frames, once on the baseline columns
    (:func:`excitation_columns`: what the rank-1 model's bending alone moves a length with) and once on those
    columns plus w. Returned: 100 (1 - mean over segments of SSE_with_w / SSE_baseline), each segment's held-out
    frames summed (relative length changes). No segment's own data set its course, and no frame its own
    prediction, so a tracker's node-wise error cannot make it positive; about 0 or below without a swing. NaN where
    a set has no usable row.

    Each segment is scored in units of its own baseline error, as the test scales each row to unit RMS: summed in
    relative length, a few segments where the tracker failed grossly (relative changes of order 1 on short
    segments) outweighed the rest. Measured on the user's path (rendered swings, seeds 160-169, clean and
    outdoor): two swings whose length test and signature held at p 0.001 had a summed gain of -3.0 and -0.2 %,
    three of their 10 and 9 segments carrying 87 and 69 % of the baseline's held-out squared error, and 42.9 and
    45.1 % with each segment in its own units; on 20 effect-free renders (seeds 170-179) the gain went from
    -13.1..+3.4 % to -3.3..+4.6 %, and none of them passed the length test and the signature together, so none is
    named either way (record ``user_path_swing_naming``)."""
    X = excitation_columns(np.asarray(z, float))
    T = X.shape[1]
    blocks = np.array_split(np.arange(T), n_folds)
    ratios = []  # per segment: held-out SSE with w / without
    for own, other in ((halves[0], halves[1]), (halves[1], halves[0])):
        if len(other) == 0:
            return float("nan")
        Xw = np.vstack([X, _leading_course(R[list(other)])])
        for i in own:
            r = channel.rel[int(kept[i])]
            sse = np.zeros(2)
            for blk in blocks:
                test = np.zeros(T, bool)
                test[blk] = True
                ok_tr, ok_te = np.isfinite(r) & ~test, np.isfinite(r) & test
                if ok_tr.sum() < Xw.shape[0] + 3 or not ok_te.any():
                    continue
                for j, A in enumerate((X, Xw)):
                    beta = np.linalg.lstsq(A[:, ok_tr].T, r[ok_tr], rcond=None)[0]
                    sse[j] += float(np.sum((r[ok_te] - beta @ A[:, ok_te]) ** 2))
            if sse[0] > 0:
                ratios.append(sse[1] / sse[0])
    return float(100.0 * (1.0 - np.mean(ratios))) if ratios else float("nan")


def gain_without_carrying_node(channel: LengthChannel, z: np.ndarray, R: np.ndarray, kept: np.ndarray,
                               loadings: np.ndarray, seed: int = 0,
                               tested=None) -> tuple[int | None, float, float, float]:
    """The one-node check on the length channel (:mod:`rce_gtsam.diagnosis.one_node`): (the node whose segments
    carry the largest share of the swing course's squared loadings, that share, :func:`heldout_length_gain` of the
    other segments in two new node-disjoint sets (%), and the shared-course test's p on those sets). A swing is in
    every segment; a node the tracker lost and re-found off its place, or slid along the stem, changes only its two
    segments' lengths. Measured on 120 effect-free user-path renders (seeds 100-159): 5 passed the length test
    with a positive held-out gain, and without their carrying node's segments the test failed on 4 of them
    (p 0.026-0.63); on 60 rendered swings it failed on 1 (record ``user_path_out_of_plane``). ``tested``:
    positions in ``kept`` of the segments the test reads (its two node-disjoint sets; None = all): the carrying
    node is sought among them, since a node whose segments the split left out changes neither the test nor its
    gain. (None, NaN, NaN, NaN) where nothing loads;
    the gain and p NaN where fewer than 4 segments are left."""
    nodes = [tuple(channel.nodes[int(i)]) for i in kept]
    load = np.asarray(loadings, float)[kept]
    l2 = np.where(np.isfinite(load), load * load, 0.0)
    if tested is not None:
        l2 = np.where(np.isin(np.arange(len(kept)), np.asarray(list(tested), int)), l2, 0.0)
    found = heaviest(shares_by_node(l2, nodes)) if nodes else None
    if found is None:
        return None, float("nan"), float("nan"), float("nan")
    node, share = found
    keep = rows_without(node, nodes)
    if keep.sum() < 4:
        return node, share, float("nan"), float("nan")
    kept2 = np.asarray(kept)[keep]
    nodes2 = [nodes[j] for j in np.flatnonzero(keep)]
    s2 = channel.root_distance[kept2]
    halves2 = node_disjoint_split(s2, shared_node_matrix(s2, nodes2), seed, edge_nodes=nodes2)
    if halves2 is None or len(halves2[0]) < 2 or len(halves2[1]) < 2:
        return node, share, float("nan"), float("nan")
    return (node, share, heldout_length_gain(channel, z, R[keep], kept2, halves2),
            _shared_course_p(R[keep], halves2, seed)[0])
