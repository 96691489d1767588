"""Bending angles at every joint, their deviation from rest, an outlier mask and their variance.

For a bend (g, j, c) with u = p_g - p_j and v = p_c - p_j (pixels):

* unsigned (paper): theta = arccos(u.v / |u||v|) in [0, 180] degrees, 180 = straight;
* signed: the turning angle phi = atan2(a x b, a . b) with a = p_j - p_g, b = p_c - p_j, in
  (-180, 180] degrees, 0 = straight, positive = counter-clockwise in image coordinates.

delta(t) = angle(t) - rest, where rest is the angle at the bend's first common frame (paper) or the
median over its frames (robust). The outlier mask is the Iglewicz-Hoaglin modified z-score on delta:
inlier <=> 0.6745 |delta - median| / MAD <= threshold.

With the joint covariance of the three nodes (from the smoother's marginals) the per-frame angle
variance follows to first order: var = J Sigma J^T with J the 1x6 gradient of the angle.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..graph import Bend, BranchGraph
from ..presets import BendingConfig

_RAD2DEG = 180.0 / np.pi
_TINY = 1e-12
MAD_SCALE = 0.6745  # 1 / 1.4826: makes the MAD a consistent sigma estimate for Gaussian data


@dataclass(frozen=True, eq=False)
class BendingResult:
    """Per-bend angle series, aligned on frames 0..F-1.

    bends: the (grandparent, joint, child) triplets, rows of every array.
    angle_deg: (B, F) angle in degrees (NaN where any of the three nodes is missing).
    rest_deg: (B,) rest angle in degrees.
    delta_deg: (B, F) angle - rest, degrees.
    inlier: (B, F) bool, finite and within the MAD threshold.
    variance_deg2: (B, F) first-order angle variance in deg^2, or None without covariances.
    covariance_deg2: (F, B, B) first-order covariance between the bends at each frame in deg^2 (bends
        that share a node are correlated: a node's error turns one bend one way and the next the other
        way), or None without covariances; NaN where either angle is missing. Its diagonal is
        ``variance_deg2``.
    signed: whether angles are signed turning angles (True) or unsigned interior angles.
    """

    bends: tuple[Bend, ...]
    angle_deg: np.ndarray
    rest_deg: np.ndarray
    delta_deg: np.ndarray
    inlier: np.ndarray
    variance_deg2: np.ndarray | None
    signed: bool
    covariance_deg2: np.ndarray | None = None

    @property
    def edges(self) -> list[tuple[int, int]]:
        """The downstream edge (joint, child) of every bend."""
        return [b.edge for b in self.bends]

    def nodes_of(self, rows) -> list[tuple[int, int, int]]:
        """The tracked nodes each of the bends ``rows`` (indices into :attr:`bends`, e.g. a response's
        ``bend_rows``) is computed from: rows that share one share its position error."""
        return [self.bends[k].nodes for k in rows]


def bend_angles(pg: np.ndarray, pj: np.ndarray, pc: np.ndarray, signed: bool) -> np.ndarray:
    """Angle in degrees at ``pj`` for arrays of points (..., 2); NaN for degenerate segments."""
    u = pg - pj
    v = pc - pj
    nu = np.hypot(u[..., 0], u[..., 1])
    nv = np.hypot(v[..., 0], v[..., 1])
    bad = (nu < _TINY) | (nv < _TINY)
    with np.errstate(invalid="ignore", divide="ignore"):
        if signed:
            a = -u  # p_j - p_g
            cross = a[..., 0] * v[..., 1] - a[..., 1] * v[..., 0]
            dot = a[..., 0] * v[..., 0] + a[..., 1] * v[..., 1]
            ang = np.arctan2(cross, dot) * _RAD2DEG
        else:
            cosang = (u[..., 0] * v[..., 0] + u[..., 1] * v[..., 1]) / (nu * nv)
            ang = np.degrees(np.arccos(np.clip(cosang, -1.0, 1.0)))
    return np.where(bad, np.nan, ang)


def angle_gradient(pg: np.ndarray, pj: np.ndarray, pc: np.ndarray) -> np.ndarray:
    """(..., 6) gradient of the turning angle (radians) w.r.t. (p_g, p_j, p_c) in pixels.

    The unsigned interior angle is 180 deg - |turning angle|, so it has the same gradient up to a
    sign and the same first-order variance.
    """
    a = pj - pg
    b = pc - pj
    na2 = np.maximum(np.sum(a * a, axis=-1, keepdims=True), _TINY)
    nb2 = np.maximum(np.sum(b * b, axis=-1, keepdims=True), _TINY)
    da = np.stack([-a[..., 1], a[..., 0]], axis=-1) / na2  # d atan2(a) / d a
    db = np.stack([-b[..., 1], b[..., 0]], axis=-1) / nb2
    return np.concatenate([da, -db - da, db], axis=-1)


def mad_inliers(delta: np.ndarray, threshold: float) -> np.ndarray:
    """Modified z-score mask per row of ``delta`` (B, F); non-finite entries are never inliers."""
    finite = np.isfinite(delta)
    out = np.zeros_like(finite)
    for b in range(delta.shape[0]):
        vals = delta[b, finite[b]]
        if vals.size < 3:
            out[b] = finite[b]
            continue
        med = np.median(vals)
        mad = np.median(np.abs(vals - med))
        if mad <= 1e-9:
            out[b] = finite[b]
            continue
        with np.errstate(invalid="ignore"):
            z = MAD_SCALE * np.abs(delta[b] - med) / mad
        out[b] = finite[b] & (z <= threshold)
    return out


#: ``rest="common_median"``: fewest frames, and least share of the frames where any bend is observed, where every
#: bend is observed for their median to be the rest angle (fewer: each bend's own median, as ``"median"``); and
#: fewest frames a bend needs to count toward them (a bend through a node seen only in the annotated frame does not
#: empty the common set; it is dropped downstream). The share: a rest is a median of the recording's pose, so it
#: must rest on most of the recording; a few shared frames between long gust losses are where the smoother pulls
#: the positions most (simulated gust losses of 25-41 % left 15-25 shared frames of 450, and the rest over them
#: raised kappa's log-RMSE 0.37 -> 0.48 and 0.43 -> 0.82)
MIN_COMMON_FRAMES = 10
MIN_COMMON_SHARE = 0.5
MIN_BEND_FRAMES = 3


def common_frames(angle: np.ndarray) -> np.ndarray | None:
    """Frame indices where every bend of ``angle`` (B, F) with at least :data:`MIN_BEND_FRAMES` finite frames is
    finite, or None when there are fewer than :data:`MIN_COMMON_FRAMES` or than :data:`MIN_COMMON_SHARE` of the
    frames where any of them is.

    Why (issue #38): a bend's median over its own frames is its angle at the median excitation of THOSE frames.
    When a tracker loses nodes in gusts (missing not at random), each bend loses different frames, so each rest is
    taken at a different excitation level: delta then carries a per-bend offset that is not kappa_e times one
    constant, and the rank-1 fit (no offsets) turns it into a kappa error (simulated gust losses, exact positions:
    log-RMSE 0.36 at 25 % lost frames, 0.85 at 41 %; over the common frames 0.003). The median over the frames all
    bends share is kappa_e times the same median excitation for every bend (a median is equivariant under scaling,
    also by a negative kappa), which the excitation z absorbs.
    """
    ok = np.isfinite(angle)
    rows = ok.sum(axis=1) >= MIN_BEND_FRAMES
    if not rows.any():
        return None
    frames = np.flatnonzero(ok[rows].all(axis=0))
    enough = max(MIN_COMMON_FRAMES, MIN_COMMON_SHARE * ok[rows].any(axis=0).sum())
    return frames if frames.size >= enough else None


def compute_bending(xy: np.ndarray, node_ids, graph: BranchGraph, config: BendingConfig,
                    frame_cov: np.ndarray | None = None) -> BendingResult:
    """Angles of every bend of ``graph`` from positions ``xy`` (N, F, 2), NaN = not usable.

    ``frame_cov`` (F, 2N, 2N), the joint covariance of all nodes at each frame in px^2 (node order
    = ``node_ids``), enables the propagated angle variance.
    """
    row = {int(n): i for i, n in enumerate(node_ids)}
    bends = graph.bends
    n_frames = xy.shape[1]
    angle = np.full((len(bends), n_frames), np.nan)
    rest = np.full(len(bends), np.nan)
    for k, bend in enumerate(bends):
        ig, ij, ic = (row[n] for n in bend.nodes)
        angle[k] = bend_angles(xy[ig], xy[ij], xy[ic], config.signed)
    common = common_frames(angle) if config.rest == "common_median" else None
    for k in range(len(bends)):
        finite = np.flatnonzero(np.isfinite(angle[k]))
        if finite.size == 0:
            continue
        if config.rest == "first":
            rest[k] = angle[k, finite[0]]
        elif common is not None and np.isfinite(angle[k, common]).all():
            rest[k] = np.median(angle[k, common])
        else:
            rest[k] = np.median(angle[k, finite])
    delta = angle - rest[:, None]
    if config.signed:
        delta = (delta + 180.0) % 360.0 - 180.0  # keep deviations continuous across +-180
    inlier = mad_inliers(delta, config.mad_threshold)
    covariance = variance = None
    if frame_cov is not None:
        covariance = bend_covariance(xy, row, bends, frame_cov, angle, config.signed)
        variance = np.diagonal(covariance, axis1=1, axis2=2).T.copy()  # NaN where the angle is missing
    return BendingResult(bends=bends, angle_deg=angle, rest_deg=rest, delta_deg=delta, inlier=inlier,
                         variance_deg2=variance, signed=config.signed, covariance_deg2=covariance)


#: Frames per batch of :func:`bend_covariance` (bounds its (frames, B, 2N) Jacobian on long recordings).
COVARIANCE_BATCH_FRAMES = 2048


def bend_covariance(xy: np.ndarray, row: dict[int, int], bends, frame_cov: np.ndarray, angle: np.ndarray,
                    signed: bool) -> np.ndarray:
    """(F, B, B) first-order covariance of all bend angles at each frame, deg^2: J Sigma J^T with J the
    (B, 2N) angle Jacobian (3 non-zero 2-blocks per row) and Sigma = ``frame_cov`` (F, 2N, 2N) in px^2
    (any float dtype; computed in float64), in batches of :data:`COVARIANCE_BATCH_FRAMES` frames.

    The unsigned interior angle is 180 - |turning angle|, so its gradient carries the factor
    -sign(turning angle); the variances do not change, the covariances between bends can.
    """
    n_frames = xy.shape[1]
    cov = np.empty((n_frames, len(bends), len(bends)))
    for a in range(0, n_frames, COVARIANCE_BATCH_FRAMES):
        b = min(a + COVARIANCE_BATCH_FRAMES, n_frames)
        J = np.zeros((b - a, len(bends), frame_cov.shape[1]))
        for k, bend in enumerate(bends):
            nodes = [row[n] for n in bend.nodes]
            grad = angle_gradient(*(xy[i, a:b] for i in nodes))  # (frames, 6), radians per pixel
            if not signed:
                turn = bend_angles(*(xy[i, a:b] for i in nodes), True)
                grad = grad * -np.sign(np.nan_to_num(turn))[:, None]
            for j, i in enumerate(nodes):
                J[:, k, 2 * i:2 * i + 2] += grad[:, 2 * j:2 * j + 2]
        J = np.nan_to_num(J)
        Sigma = np.asarray(frame_cov[a:b], dtype=float)
        cov[a:b] = np.matmul(np.matmul(J, Sigma), np.transpose(J, (0, 2, 1))) * _RAD2DEG**2
    missing = ~np.isfinite(angle.T)  # (F, B)
    cov[missing[:, :, None] | missing[:, None, :]] = np.nan
    return cov
