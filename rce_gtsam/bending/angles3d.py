"""3-D bending: the turning angle at every joint of a 3-D branch, split into its part in the branch plane and its
part out of it (degrees).

The *branch plane* is the plane through the branch's rest pose (the per-node median position over frames),
fitted by SVD; its normal ``n`` points toward the camera. For a bend (g, j, c) with a = p_j - p_g and
b = p_c - p_j (mm):

* in-plane angle theta: the signed angle from a's to b's projection onto the plane, about ``n``;
* out-of-plane angle psi: the change of elevation over the plane, asin(n.b/|b|) - asin(n.a/|a|) — the rotation
  of the segment out of the plane about its in-plane normal (issue #39's model: theta = kappa z, psi = kappa z_o);
* total: the 3-D turning angle between a and b (unsigned; ~ sqrt(theta^2 + psi^2) for small bends).

Each returned :class:`~rce_gtsam.bending.angles.BendingResult` (``in_plane``, ``out_of_plane``) has the deviation
from rest, the MAD outlier mask and, with the smoother's joint covariance (mm^2), the first-order variance
(numerical gradient), so the 2-D model stage (``pipeline.build_response``) takes them as they are.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..graph import BranchGraph
from ..presets import BendingConfig
from .angles import BendingResult, mad_inliers

_EPS_MM = 1e-3  # step of the numerical gradient (mm)


@dataclass(frozen=True, eq=False)
class Bending3D:
    """in_plane / out_of_plane: per-bend series (degrees) on the same bends and frames; total_deg: (B, F) 3-D
    turning angle; normal: (3,) branch-plane normal (camera frame, toward the camera); tilt_deg: angle between
    the branch plane and the image plane (deg)."""

    in_plane: BendingResult
    out_of_plane: BendingResult
    total_deg: np.ndarray
    normal: np.ndarray
    tilt_deg: float


def branch_plane(xyz_mm: np.ndarray) -> np.ndarray:
    """Unit normal (3,) of the plane through the rest pose (per-node median over frames) of ``xyz_mm`` (N, F, 3),
    oriented toward the camera (negative z)."""
    rest = np.nanmedian(xyz_mm, axis=1)
    rest = rest[np.isfinite(rest).all(axis=1)]
    _, _, vt = np.linalg.svd(rest - rest.mean(axis=0))
    n = vt[-1]
    return -n if n[2] > 0 else n


def _angles(pg, pj, pc, n):
    """(theta, psi, total) in degrees for point arrays (..., 3)."""
    a, b = pj - pg, pc - pj
    na, nb = np.linalg.norm(a, axis=-1), np.linalg.norm(b, axis=-1)
    ap = a - (a @ n)[..., None] * n
    bp = b - (b @ n)[..., None] * n
    theta = np.arctan2(np.cross(ap, bp) @ n, np.sum(ap * bp, axis=-1))
    with np.errstate(invalid="ignore", divide="ignore"):
        psi = np.arcsin(np.clip((b @ n) / nb, -1, 1)) - np.arcsin(np.clip((a @ n) / na, -1, 1))
        total = np.arccos(np.clip(np.sum(a * b, axis=-1) / (na * nb), -1, 1))
    return np.degrees(theta), np.degrees(psi), np.degrees(total)


def _variances(pg, pj, pc, n, cov9):
    """(F,) first-order variances (deg^2) of theta and psi from the (F, 9, 9) joint covariance of (g, j, c)."""
    p = np.concatenate([pg, pj, pc], axis=-1)
    grads = np.zeros((2, p.shape[0], 9))
    for k in range(9):
        d = np.zeros(9)
        d[k] = _EPS_MM
        hi = _angles(*np.split(p + d, 3, axis=-1), n)
        lo = _angles(*np.split(p - d, 3, axis=-1), n)
        for m in range(2):
            grads[m, :, k] = (hi[m] - lo[m]) / (2 * _EPS_MM)
    return [np.einsum("fi,fij,fj->f", g, cov9, g) for g in grads]


def _series(bends, angle, config: BendingConfig, variance) -> BendingResult:
    rest = np.full(len(bends), np.nan)
    for k in range(len(bends)):
        finite = np.flatnonzero(np.isfinite(angle[k]))
        if finite.size:
            rest[k] = angle[k, finite[0]] if config.rest == "first" else np.median(angle[k, finite])
    delta = (angle - rest[:, None] + 180.0) % 360.0 - 180.0
    return BendingResult(bends=tuple(bends), angle_deg=angle, rest_deg=rest, delta_deg=delta,
                         inlier=mad_inliers(delta, config.mad_threshold), variance_deg2=variance, signed=True)


def compute_bending_3d(xyz_mm: np.ndarray, node_ids, graph: BranchGraph, config: BendingConfig = BendingConfig(),
                       frame_cov: np.ndarray | None = None, observed: np.ndarray | None = None) -> Bending3D:
    """Angles of every bend of ``graph`` from 3-D positions ``xyz_mm`` (N, F, 3). ``frame_cov`` (F, 3N, 3N) mm^2
    enables the variances; ``observed`` (N, F) masks frames where a node was not seen (NaN angles there)."""
    xyz = np.asarray(xyz_mm, float)
    if observed is not None:
        xyz = np.where(observed[..., None], xyz, np.nan)
    row = {int(v): i for i, v in enumerate(node_ids)}
    n = branch_plane(xyz)
    bends = graph.bends
    f = xyz.shape[1]
    theta, psi, total = (np.full((len(bends), f), np.nan) for _ in range(3))
    var_t = var_p = None
    if frame_cov is not None:
        var_t, var_p = np.full((len(bends), f), np.nan), np.full((len(bends), f), np.nan)
    for k, bend in enumerate(bends):
        ig, ij, ic = (row[v] for v in bend.nodes)
        theta[k], psi[k], total[k] = _angles(xyz[ig], xyz[ij], xyz[ic], n)
        if frame_cov is not None:
            idx = np.concatenate([np.arange(3 * r, 3 * r + 3) for r in (ig, ij, ic)])
            cov9 = np.asarray(frame_cov[:, idx[:, None], idx[None, :]], float)
            var_t[k], var_p[k] = _variances(xyz[ig], xyz[ij], xyz[ic], n, cov9)
    tilt = float(np.degrees(np.arccos(min(1.0, abs(n[2])))))
    return Bending3D(in_plane=_series(bends, theta, config, var_t), out_of_plane=_series(bends, psi, config, var_p),
                     total_deg=total, normal=n, tilt_deg=tilt)
