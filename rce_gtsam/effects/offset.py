"""``offset``: the rest pose is not the reference frame's pose, and it creeps.

Physics: y_e(t) = (core) + c_e + d_e * t / T. A constant c_e appears when the rest angle was taken from a
frame that was itself deflected (or noisy); d_e is slow creep over the recording (gravity sag, stress
relaxation, a slowly turning plant). Units: c_e and d_e in degrees (d_e = total creep over the record).
"""

from __future__ import annotations

import numpy as np

from .base import Effect, Parameter


class Offset(Effect):
    """Per-edge constant offset and (optionally) linear creep.

    trend: include the creep term d_e t/T (default True).
    """

    name = "offset"
    kind = "additive"
    equation = "y_e(t) = kappa_e z_t + c_e + d_e t/T"
    fitting = "closed form: per-edge weighted least squares of the partial residual on [1, t/T]"
    physics = ("the rest pose is wrong or drifts: the reference angle (first frame or median) was itself "
               "deflected, or the plant sags or relaxes over the recording, leaving a constant and a trend in each "
               "joint's residual. Consider a rest pose from a calm period; the paper's |delta| response turns "
               "offsets into spurious compliance.")

    def __init__(self, trend: bool = True):
        self.trend = bool(trend)

    def __repr__(self) -> str:
        return f"Offset(trend={self.trend})"

    def parameters(self, n_edges: int):
        p = [Parameter("c", "deg", per_edge=True, description="constant offset of the rest angle")]
        if self.trend:
            p.append(Parameter("d", "deg", per_edge=True, description="creep over the whole record"))
        return tuple(p)

    def init(self, view) -> dict:
        st = {"params": {"c": np.zeros(view.E), "d": np.zeros(view.E)}, "latents": {}}
        return self.update(st, view, frozen=False)

    def additive(self, state, view):
        p = state["params"]
        return p["c"][:, None] + p["d"][:, None] * view.tt[None, :]

    def update(self, state, view, frozen):
        if frozen:
            return state
        i = view.index_of(self)
        target = view.partial_target(i) if i is not None else view.Y0 - view.predict()
        W = view.W
        t = view.tt[None, :]
        if not self.trend:
            c = np.sum(W * target, axis=1) / np.maximum(W.sum(axis=1), 1e-12)
            return {"params": {"c": c, "d": np.zeros(view.E)}, "latents": {}}
        s0 = W.sum(axis=1)
        s1 = (W * t).sum(axis=1)
        s2 = (W * t * t).sum(axis=1)
        b0 = (W * target).sum(axis=1)
        b1 = (W * t * target).sum(axis=1)
        det = s0 * s2 - s1 * s1
        ok = det > 1e-12 * np.maximum(s0 * s2, 1e-300)
        c = np.where(ok, (s2 * b0 - s1 * b1) / np.where(ok, det, 1), b0 / np.maximum(s0, 1e-12))
        d = np.where(ok, (s0 * b1 - s1 * b0) / np.where(ok, det, 1), 0.0)
        return {"params": {"c": c, "d": d}, "latents": {}}

    def describe(self, state):
        p = state["params"]
        return {"rms_offset_deg": float(np.sqrt(np.mean(p["c"] ** 2))),
                "rms_creep_deg": float(np.sqrt(np.mean(p["d"] ** 2)))}

    def evidence(self, ctx) -> dict:
        """Per-edge residual mean and linear trend over the record, each with an AR(1)-inflated t statistic."""
        R = ctx.R
        E, T = R.shape
        tt = np.arange(T) / T
        means, tmeans, trends, ttrend = np.zeros(E), np.zeros(E), np.zeros(E), np.zeros(E)
        for e in range(E):
            ok = np.isfinite(R[e])
            if ok.sum() < 3:
                continue
            X = np.stack([np.ones(ok.sum()), tt[ok] - tt[ok].mean()], axis=1)
            beta, *_ = np.linalg.lstsq(X, R[e, ok], rcond=None)
            res = R[e, ok] - X @ beta
            s2 = float(np.sum(res ** 2) / max(ok.sum() - 2, 1)) * ctx.inflation
            cov = s2 * np.linalg.inv(X.T @ X)
            means[e], tmeans[e] = beta[0], beta[0] / np.sqrt(cov[0, 0])
            trends[e], ttrend[e] = beta[1], beta[1] / np.sqrt(cov[1, 1])
        return {"mean_per_edge_deg": means, "trend_per_edge_deg": trends,
                "max_abs_mean_t": float(np.max(np.abs(tmeans))) if E else 0.0,
                "max_abs_trend_t": float(np.max(np.abs(ttrend))) if E else 0.0,
                "rms_mean_deg": float(np.sqrt(np.mean(means ** 2))) if E else 0.0,
                "rms_trend_deg": float(np.sqrt(np.mean(trends ** 2))) if E else 0.0}

    def explain(self, summary: dict, statistics: dict) -> str:
        return (f"Baseline residuals have per-edge means of RMS {statistics.get('rms_mean_deg', 0):.2f} deg "
                f"(max |t| {statistics.get('max_abs_mean_t', 0):.1f}) and trends of RMS "
                f"{statistics.get('rms_trend_deg', 0):.2f} deg over the record (max |t| "
                f"{statistics.get('max_abs_trend_t', 0):.1f}).")

