"""Relative compliance from 3-D bending: one kappa per segment from its in-plane and out-of-plane bends together.

Issue #39's model bends joint e by theta[e, t] = kappa_e z(t) in the branch plane and psi[e, t] = kappa_e z_o(t)
out of it (a round stem is as compliant both ways). Both are rank-1 with the same kappa, so the two series are
set side by side in time, Y = [theta | psi] (E x 2T), and fitted by the project's rank-1 fit
(:func:`~rce_gtsam.model.compliance.fit_rank1`, the preset's response and shrinkage) with inverse-variance
weights from the smoother's covariances (the out-of-plane half rests on depth and is noisier), and its bootstrap
(:func:`~rce_gtsam.model.compliance.bootstrap_kappa`; its moving blocks may straddle the seam between the
halves, 1 block in T / block_length). The in-plane half alone gives ``kappa_in_plane``, beside it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..bending.angles3d import Bending3D
from ..bending.geometry import Geometry
from ..presets import Preset
from .compliance import bootstrap_kappa, fit_rank1


@dataclass(frozen=True, eq=False)
class Kappa3D:
    """kappa from 3-D angles, per segment (rows ordered as the 2-D response: by root distance).

    edges: (joint, child) per row. kappa: (E,) from [theta | psi]; ci_low / ci_high: (E,) 95 % bootstrap
    interval (None without a bootstrap). kappa_in_plane: (E,) from theta alone. bend_rms_deg / swing_rms_deg:
    (E,) RMS of the in-plane and out-of-plane deviations (deg). tilt_deg: branch plane vs image plane (deg).
    """

    edges: list[tuple[int, int]]
    kappa: np.ndarray
    ci_low: np.ndarray | None
    ci_high: np.ndarray | None
    kappa_in_plane: np.ndarray
    bend_rms_deg: np.ndarray
    swing_rms_deg: np.ndarray
    tilt_deg: float

    def as_dict(self) -> dict:
        rows = []
        for k, (j, c) in enumerate(self.edges):
            rows.append({"edge": f"{j}->{c}", "kappa_3d": float(self.kappa[k]),
                         "ci_low": None if self.ci_low is None else float(self.ci_low[k]),
                         "ci_high": None if self.ci_high is None else float(self.ci_high[k]),
                         "kappa_in_plane": float(self.kappa_in_plane[k]),
                         "bend_rms_deg": float(self.bend_rms_deg[k]), "swing_rms_deg": float(self.swing_rms_deg[k])})
        return {"tilt_deg": self.tilt_deg, "segments": rows}


def _weights(*variances) -> np.ndarray | None:
    if any(v is None for v in variances):
        return None
    var = np.concatenate(variances, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        w = np.where(np.isfinite(var) & (var > 0), 1.0 / var, 0.0)
    pos = w > 0
    return w / w[pos].mean() if pos.any() else None


def _rms(Y: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore"):
        return np.sqrt(np.nanmean(Y * Y, axis=1))


def fit_kappa_3d(bending: Bending3D, geometry: Geometry, preset: Preset, skip_nodes=()) -> Kappa3D:
    """Fit kappa to the 3-D bends of ``bending`` (rows ordered by ``geometry``'s root distances)."""
    from ..pipeline import build_response

    r_in = build_response(bending.in_plane, geometry, preset, skip_nodes)
    r_out = build_response(bending.out_of_plane, geometry, preset, skip_nodes)
    Y = np.concatenate([r_in.Y, r_out.Y], axis=1)
    w = _weights(r_in.variance, r_out.variance)
    cfg = preset.compliance
    fit = fit_rank1(Y, cfg, w)
    ci = bootstrap_kappa(Y, cfg, w, fit=fit)
    w_in = None if w is None else w[:, :r_in.Y.shape[1]]
    fit_in = fit_rank1(r_in.Y, cfg, w_in)
    delta_in = bending.in_plane.delta_deg[r_in.bend_rows]
    delta_out = bending.out_of_plane.delta_deg[r_out.bend_rows]
    return Kappa3D(edges=list(r_in.edges), kappa=np.asarray(fit.kappa, float),
                   ci_low=None if ci is None else ci.low, ci_high=None if ci is None else ci.high,
                   kappa_in_plane=np.asarray(fit_in.kappa, float), bend_rms_deg=_rms(delta_in),
                   swing_rms_deg=_rms(delta_out), tilt_deg=bending.tilt_deg)
