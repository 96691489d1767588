"""``delay``: the load reaches distal segments later.

Physics: y_e(t) = kappa_e z(t - tau_e) with tau_e = tau * s_e, s_e the normalised root distance of the
edge's child (0 at the root, 1 at the farthest tip). A bending wave or the wind front needs time to travel
along the branch, so distal joints lag the proximal ones. Only *differences* in lag are identifiable
(a lag common to all edges is absorbed by z), hence the lag is modelled relative to the root.
Units: tau in frames (fractional; z is interpolated with a Catmull-Rom cubic, clamped at the ends).
"""

from __future__ import annotations

import numpy as np
from scipy import sparse
from scipy.optimize import minimize_scalar

import math

from ..diagnosis.statistics import per_edge_regression, slope_vs
from ..model.steps import profiled_sse, sse_after_z
from .base import Effect, Parameter, scalar


def shifted(z: np.ndarray, lags: np.ndarray) -> np.ndarray:
    """(*lags.shape, T): z (T,) moved later by each lag (frames, any shape): z(t - lag) with the Catmull-Rom taps
    of :meth:`Delay.apply` (frames outside the recording take the nearest end's value). A lag constant in time
    has one fractional part, so each output row is four whole-frame shifts of z, weighted."""
    T = z.size
    lags = np.asarray(lags, float)
    whole = np.floor(-lags)
    f = -lags - whole
    f2, f3 = f * f, f * f * f
    w = np.stack([-0.5 * f3 + f2 - 0.5 * f, 1.5 * f3 - 2.5 * f2 + 1.0,
                  -1.5 * f3 + 2.0 * f2 + 0.5 * f, 0.5 * f3 - 0.5 * f2], axis=-1)   # (..., 4)
    offsets = whole.astype(int)[..., None] + np.arange(-1, 3)                        # (..., 4)
    pad = int(min(max(np.abs(offsets).max(initial=0), 0), T + 2))
    windows = np.lib.stride_tricks.sliding_window_view(np.pad(z, pad, mode="edge"), T)  # (2 pad + 1, T)
    return np.einsum("...k,...kt->...t", w, windows[np.clip(offsets, -pad, pad) + pad])


class Delay(Effect):
    """Lag growing linearly with root distance: tau_e = tau * s_e.

    max_lag: bound on |tau| in frames (default 60: 2 s at 30 fps). Only the bound's reach matters: the
    lag is fitted, and :func:`rce_gtsam.diagnosis.diagnose.diagnose` widens its CV buffer to the fitted lag
    (:meth:`memory_frames`), so held-out frames stay independent of training whatever it is. The earlier
    bound of 25 frames (the bootstrap block length) cut off a 1.25-s tip lag: on simulated branches with
    that lag the verdict named delay in 4/10 seeds with it and 7/10 with 60 (held-out RMSE -17 % when
    named), while effect-free data still gave no verdict in 10/10.
    """

    name = "delay"
    kind = "operator"
    equation = "y_e(t) = kappa_e z(t - tau s_e)   (s_e: root distance 0..1; tau in frames)"
    fitting = ("tau by bounded scalar minimisation (scipy.optimize.minimize_scalar) of the error with z "
               "re-solved for each tau (z profiled out), alternating with the kappa step; grid start")
    physics = ("the bending reaches distal joints later than proximal ones: the load (a wind front or a bending "
               "wave) travels along the branch, so one instantaneous excitation cannot describe every joint at once. "
               "Kappa from the delayed model no longer mixes amplitude with phase. Check the camera/tracker timing "
               "only if the lag is implausibly large.")
    # a shift is not what a symmetric smoother does to a signal: the lag scan from the full fit's own z, scored by
    # GLS against phase surrogates, is calibrated (diagnosis.whitened_score_test's record)
    score_excitation = "own_whitened"

    def __init__(self, max_lag: float = 60.0):
        self.max_lag = float(max_lag)

    def __repr__(self) -> str:
        return f"Delay(max_lag={self.max_lag})"

    def parameters(self, n_edges: int):
        return (Parameter("tau", "frames", -self.max_lag, self.max_lag,
                          description="lag of the farthest tip behind the root"),)

    # operator ---------------------------------------------------------------------------------------
    def _taps(self, tau, view):
        # the same (tau, s, T) is asked for many times per solve (every transform, adjoint and error): keep the
        # last few taps, keyed by their exact inputs
        key = (scalar(tau), view.T, view.s.tobytes())
        cache = self.__dict__.setdefault("_tap_cache", {})
        hit = cache.get(key)
        if hit is None:
            if len(cache) >= 8:
                cache.pop(next(iter(cache)))
            hit = cache[key] = self._compute_taps(scalar(tau), view.T, view.s)
        return hit

    @staticmethod
    def _compute_taps(tau: float, T: int, s: np.ndarray):
        """Catmull-Rom interpolation taps of z(t - tau s_e): (E, T, 4) frame indices and weights."""
        lag = tau * s  # (E,)
        src = np.arange(T)[None, :] - lag[:, None]
        i0 = np.floor(src)
        f = src - i0
        i0 = i0.astype(int)
        f2, f3 = f * f, f * f * f
        w = np.stack([-0.5 * f3 + f2 - 0.5 * f, 1.5 * f3 - 2.5 * f2 + 1.0,
                      -1.5 * f3 + 2.0 * f2 + 0.5 * f, 0.5 * f3 - 0.5 * f2], axis=-1)
        idx = np.clip(i0[..., None] + np.arange(-1, 3), 0, T - 1)
        return idx, w

    def apply(self, X, state, view):
        idx, w = self._taps(state["params"]["tau"], view)
        E, T = X.shape
        rows = np.arange(E)[:, None, None]
        return np.sum(X[rows, idx] * w, axis=-1)

    def apply_T(self, R, state, view):
        idx, w = self._taps(state["params"]["tau"], view)
        E, T = R.shape
        flat = (np.arange(E)[:, None, None] * T + idx).ravel()
        return np.bincount(flat, weights=(R[..., None] * w).ravel(), minlength=E * T).reshape(E, T)

    def sparse_operator(self, state, view):
        """The operator as a sparse (E*T, T) matrix: row e*T + t holds edge e's 4 interpolation taps.

        Each row touches 4 consecutive frames, so the z normal matrix sum_e L_e^T D_e L_e is banded
        (half-bandwidth 3) whatever the lags: the model solves the z step exactly and directly with it."""
        idx, w = self._taps(state["params"]["tau"], view)
        E, T = view.E, view.T
        rows = np.repeat(np.arange(E * T), 4)
        return sparse.csr_matrix((w.ravel(), (rows, idx.ravel())), shape=(E * T, T))

    # fitting ----------------------------------------------------------------------------------------
    def init(self, view) -> dict:
        i = len(view.states)
        grid = np.array([0.0, -1.0, 1.0, -2.5, 2.5, -5.0, 5.0, -10.0, 10.0, -20.0, 20.0, -40.0, 40.0])
        grid = grid[np.abs(grid) <= self.max_lag]
        best, best_err = 0.0, np.inf
        for tau in grid:
            st = {"params": {"tau": np.array(tau)}, "latents": {}}
            err = sse_after_z(view, i, st)
            if err < best_err:
                best, best_err = tau, err
        return {"params": {"tau": np.array(best)}, "latents": {}}

    def update(self, state, view, frozen):
        if frozen:
            return state
        i = view.index_of(self)
        t0 = scalar(state["params"]["tau"])
        lo, hi = max(-self.max_lag, t0 - 3.0), min(self.max_lag, t0 + 3.0)

        def prof(tau):  # error with z re-solved: tau and z are strongly coupled, so profile z out
            return profiled_sse(view, i, {"params": {"tau": np.array(tau)}, "latents": {}})

        res = minimize_scalar(prof, bounds=(lo, hi), method="bounded", options={"xatol": 0.02, "maxiter": 12})
        tau = res.x if res.fun <= prof(t0) else t0
        return {"params": {"tau": np.array(tau)}, "latents": {}}

    def memory_frames(self, state):
        return abs(scalar(state["params"]["tau"]))

    def score_directions(self, kappa, z, s):
        """d/dtau of kappa_e z(t - tau s_e) at tau = 0: -kappa_e s_e dz/dt (one direction, degrees per frame)."""
        return (-kappa[:, None] * s[:, None] * np.gradient(np.asarray(z, float))[None, :])[None]

    def scan_lags(self) -> np.ndarray:
        """Tip lags (frames) the score test scans: +-max_lag down by factors of sqrt(2) to about one frame (the
        directions of neighbouring lags correlate strongly, so the scan misses little between them)."""
        n = int(math.floor(2 * math.log2(max(self.max_lag, 1.0)))) + 1
        lags = self.max_lag / np.sqrt(2.0) ** np.arange(n)
        return np.concatenate([lags, -lags])

    def scan_label(self, peak: int) -> dict:
        """The tip lag (frames, from the excitation's clock) whose direction scored highest."""
        return {"tip_lag_frames": float(self.scan_lags()[peak])}

    def test_directions(self, kappa, z, s):
        """A scan over the tip lag: kappa_e z(t - tau s_e) for every tau of :meth:`scan_lags`, combined by the
        largest standardised score. The first-order direction (:meth:`score_directions`) is the Taylor expansion
        of the delay at tau = 0 and holds while omega tau << 1: once the tip lag is a sizeable part of the sway's
        period (45 frames of a ~200-frame sway in tests/test_score_test.py) it points elsewhere. ``s`` is measured
        from the excitation's clock, so that z is moved by the lag relative to where it was estimated (a rank-1
        excitation is a blend of the segments' lagged loads, in phase near their weighted centroid). Measured
        through the pipeline (20 seeds per strength, p <= 0.005, cross-fitted): 13/15/14/13 -> 13/15/16/17 of 20
        at 0.5/1/2/3x default, effect-free 0/40 both; with the full fit's z and a refitted null 18/19/18/15. Its
        test now (``score_excitation`` ``"own_whitened"``) is measured in
        :mod:`rce_gtsam.diagnosis.whitened_score_test`."""
        return kappa[None, :, None] * shifted(np.asarray(z, float), np.outer(self.scan_lags(), s)), "max"

    def align(self, X, state, s):
        """x_e(t + tau s_e): each row moved back by its lag (the same Catmull-Rom taps as the operator, with the
        opposite lag). NaN where the source frame lies outside the recording or a tap of it is missing."""
        tau = scalar(state["params"]["tau"])
        E, T = X.shape
        idx, w = self._compute_taps(-tau, T, np.asarray(s, float))
        ok_in = np.isfinite(X)
        rows = np.arange(E)[:, None, None]
        out = np.sum(np.where(ok_in, X, 0.0)[rows, idx] * w, axis=-1)
        src = np.arange(T)[None, :] + tau * np.asarray(s, float)[:, None]
        ok = ok_in[rows, idx].all(axis=-1) & (src >= 0) & (src <= T - 1)
        return np.where(ok, out, np.nan)

    def describe(self, state):
        return {"tip_lag_frames": scalar(state["params"]["tau"])}

    def evidence(self, ctx) -> dict:
        """Residual ~ -kappa_e tau_e dz/dt: the per-edge lag tau_e (AR-inflated SE) and its trend with root
        distance (t statistic); the pooled residual cross-correlation with kappa_e z(t - L), L = -5..5."""
        R, k, z = ctx.R, ctx.kappa, ctx.z
        dz = np.gradient(z)
        lag, lag_se = per_edge_regression(R, -k[:, None] * dz[None, :])
        lag_se = lag_se * math.sqrt(ctx.inflation)
        slope, t, r = slope_vs(ctx.s, lag, lag_se)
        xc = []
        for L in range(-5, 6):
            zz = np.roll(z, L)
            if L > 0:
                zz[:L] = np.nan
            elif L < 0:
                zz[L:] = np.nan
            X = k[:, None] * zz[None, :]
            ok = np.isfinite(R) & np.isfinite(X)
            xc.append(float(np.corrcoef(R[ok], X[ok])[0, 1]) if ok.sum() > 3 else 0.0)
        return {"lag_per_edge_frames": lag, "lag_slope_frames": slope, "lag_slope_t": t,
                "lag_vs_root_distance_r": r, "residual_xcorr_with_kappa_z_lag_m5_to_p5": xc}

    def implausible(self, state, ctx):
        """A tip lag longer than the excitation's correlation time: the lagged excitation is then another signal,
        not the same one later, and a lag fitted there matches noise. A tip lag shorter than
        ``ctx.shortest_lag_frames`` (one frame interval): a rolling shutter puts that much between root and tip."""
        tau = abs(scalar(state["params"]["tau"]))
        if np.isfinite(ctx.correlation_time_frames) and tau > ctx.correlation_time_frames:
            return [f"its tip lag {tau:.3g} frames is longer than the excitation's correlation time "
                    f"({ctx.correlation_time_frames:.3g} frames)"]
        if tau < getattr(ctx, "shortest_lag_frames", 0.0):
            return [f"its tip lag {tau:.2g} frames is under {ctx.shortest_lag_frames:g} frame: a rolling shutter "
                    f"(image rows read out over up to one frame) or the tracker's timing puts lags that size "
                    f"between root and tip"]
        return []

    def explain(self, summary: dict, statistics: dict) -> str:
        tau = (summary.get("tau") or {}).get("value", float("nan"))
        return (f"Fitted tip lag {tau:.2f} frames relative to the root; in the baseline residuals the per-edge lag "
                f"grows with root distance at {statistics.get('lag_slope_frames', 0):.2f} frames per branch length "
                f"(t = {statistics.get('lag_slope_t', 0):.1f}).")

