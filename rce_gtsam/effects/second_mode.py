"""``second_mode``: a second, independent excitation with its own spatial pattern.

Physics: y_e(t) = kappa_e z_t + mu_e w_t. A crosswind, an out-of-plane swing or a side branch hitting the
stem loads the joints in a different proportion mu than the main wind does; w is an unknown per-frame
series like z. Units: w is scaled to RMS 1 over the observed frames, so mu_e is the RMS amplitude of the
second mode at edge e in degrees.

Noise across edges is not independent: a node's tracking error enters the three bends it belongs to with
the pattern +1, -2, +1, so neighbouring bends carry strongly anti-correlated noise (about -0.65 on the
simulator's tracks). The leading singular pair of the residual is then that noise pattern, not a second
excitation (measured: correlation of the fitted mu with the true one 0.01-0.40 over 4 seeds). So the term
is fitted by generalised least squares with the residual noise's correlation between edges, estimated
from frame-to-frame differences of the residual (wind moves slowly; the differences are mostly noise):
the mode is the one that stands out against the noise's own spatial structure (a maximum-noise-fraction
search), not the one with the most variance.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from ..diagnosis.statistics import noise_correlation
from .base import Effect, Parameter


class SecondMode(Effect):
    """Rank-2 response: a second latent excitation w_t with per-edge gains mu_e."""

    name = "second_mode"
    min_rows = 4  # >= 2 rows per node-disjoint half to separate two shared courses
    kind = "additive"
    # no direction to score along (w is unknown), but w is common to all segments: the full-data test asks whether
    # two node-disjoint row sets' residuals move together (score_test.shared_time_course_test; effect-free
    # pipeline seeds 0/40 at p <= 0.005, 3/40 at p <= 0.05; delay at 1x 0/40 at p <= 0.005)
    score_excitation = "between_rows"
    equation = "y_e(t) = kappa_e z_t + mu_e w_t   (w: RMS 1, mu in degrees)"
    fitting = ("alternating generalised least squares on the partial residual with the noise's correlation "
               "between edges (from frame-to-frame residual differences): mu given w, then w_t per frame as "
               "the posterior mean under its N(0, 1) prior; on new frames w is re-estimated with mu frozen")
    physics = ("the joints are driven by a second, independent excitation with its own spatial pattern "
               "(crosswind, out-of-plane swing, a touching leaf or side branch), so one shared excitation cannot "
               "explain every joint. Kappa is then the gain of the dominant mode. Check the footage for "
               "out-of-plane motion; a second camera view would separate it.")

    def parameters(self, n_edges: int):
        return (Parameter("mu", "deg", per_edge=True, description="RMS amplitude of the second mode"),)

    def latent_names(self):
        return ("w",)

    def init(self, view) -> dict:
        i = view.index_of(self)
        R = view.Y0 - view.predict() if i is None else view.partial_target(i)
        W = view.W
        corr = noise_correlation(np.where(W > 0, R, np.nan))
        # start from the leading pair of the noise-whitened residual (weights as per-entry precisions)
        L = np.linalg.cholesky(corr)
        Rw = np.linalg.solve(L, np.where(W > 0, R * np.sqrt(W), 0.0))
        try:
            U, S, Vt = np.linalg.svd(Rw, full_matrices=False)
            mu, w = (L @ U[:, 0]) * S[0], Vt[0].copy()
        except np.linalg.LinAlgError:  # pragma: no cover
            mu, w = np.zeros(view.E), np.zeros(view.T)
        st = {"params": {"mu": mu}, "latents": {"w": w}, "noise_corr": corr}
        st = _normalise(st, W)
        for _ in range(3):
            st = self._als(st, R, W, view.free, frozen=False)
        # the correlation above is of the partial residual, second mode included: re-estimate it from what the
        # mode leaves. Where the mode dominates (noise-free tracks) the first estimate is nearly rank 1 along
        # mu itself, and the GLS weights then discard exactly the direction w is read from: held-out frames'
        # w came out 30x the signal
        resid = np.where(W > 0, R - st["params"]["mu"][:, None] * st["latents"]["w"][None, :], np.nan)
        st = {**st, "noise_corr": noise_correlation(resid)}
        for _ in range(3):
            st = self._als(st, R, W, view.free, frozen=False)
        return st

    def additive(self, state, view):
        return state["params"]["mu"][:, None] * state["latents"]["w"][None, :]

    def update(self, state, view, frozen):
        i = view.index_of(self)
        R = view.partial_target(i)
        return self._als(state, R, view.W, view.free, frozen)

    @staticmethod
    def _als(state, R, W, free, frozen):
        """One mu step (unless frozen) and one w step, both generalised least squares.

        Noise at frame t: covariance s2 * D_t^-1/2 C D_t^-1/2 over the observed edges (C the noise
        correlation between edges, D_t the per-entry weights), precision P_t. w is normalised to RMS 1, so
        its prior is N(0, 1) per frame and the posterior mean of w_t given mu is
        mu' P_t r_t / (mu' P_t mu + s2), s2 the residual variance (kept in the state as ``noise_var``
        from the last fit on all frames). Without the prior a frame seen by few edges with small mu — the
        held-out frames of cross-validation, where w comes from a subset of edges — gets an unbounded w."""
        mu = state["params"]["mu"]
        w = state["latents"]["w"]
        corr = state.get("noise_corr")
        if corr is None:
            corr = np.eye(len(mu))
        P = _frame_precisions(corr, W)  # (T, E, E)
        Rz = np.where(W > 0, R, 0.0)
        PR = np.einsum("tij,jt->ti", P, Rz)  # (T, E)
        if not frozen:
            A = np.einsum("t,tij->ij", w * w, P)
            b = (w[:, None] * PR).sum(axis=0)
            try:
                mu = np.linalg.solve(A + 1e-12 * np.trace(A) * np.eye(len(mu)), b)
            except np.linalg.LinAlgError:  # pragma: no cover
                pass
        obs = W > 0
        if frozen and "noise_var" in state:
            s2 = float(state["noise_var"])
        else:
            r = Rz - mu[:, None] * w[None, :] * obs
            s2 = float(np.einsum("ti,tij,tj->", r.T, P, r.T) / max(int(obs.sum()), 1))
        Pmu = np.einsum("tij,j->ti", P, mu)  # (T, E)
        den = (Pmu * mu).sum(axis=1)
        ok = free & (den > 1e-12)
        num = (Pmu * Rz.T).sum(axis=1)
        w_new = np.where(ok, num / np.where(ok, den + s2, 1.0), w)
        st = {"params": {"mu": mu}, "latents": {"w": w_new}, "noise_var": s2, "noise_corr": corr}
        return st if frozen else _normalise(st, W)

    def describe(self, state):
        mu = state["params"]["mu"]
        return {"rms_amplitude_deg": float(np.sqrt(np.mean(mu ** 2)))}

    def evidence(self, ctx) -> dict:
        """Leading singular value of the residual matrix against the largest one pure noise of the bulk's
        level would give (Marchenko-Pastur edge), and against the second."""
        R = ctx.R
        E, T = R.shape
        sv = np.linalg.svd(np.where(np.isfinite(R), R, 0.0), compute_uv=False)
        if len(sv) < 2:
            return {}
        sigma = float(np.median(sv)) / np.sqrt(T)
        mp_edge = sigma * (np.sqrt(T) + np.sqrt(E))
        return {"s1_over_noise_edge": float(sv[0] / max(mp_edge, 1e-300)),
                "s1_over_s2": float(sv[0] / max(sv[1], 1e-300)),
                "s1_variance_fraction": float(sv[0] ** 2 / max(np.sum(sv ** 2), 1e-300))}

    def explain(self, summary: dict, statistics: dict) -> str:
        return (f"The baseline residual matrix has a leading singular value "
                f"{statistics.get('s1_over_noise_edge', float('nan')):.2f}x the noise edge and "
                f"{statistics.get('s1_over_s2', float('nan')):.2f}x the next one; the second mode's RMS amplitude is "
                f"{summary.get('rms_amplitude_deg', float('nan')):.2f} deg.")


def _frame_precisions(corr: np.ndarray, W: np.ndarray) -> np.ndarray:
    """(T, E, E) noise precision per frame: D^1/2 inv(C_oo) D^1/2 over the edges observed (W > 0), 0 elsewhere.

    The same (corr, W) comes back on every block sweep of a fit, so the result is cached by their bytes
    (read-only: callers only multiply with it)."""
    corr = np.ascontiguousarray(corr, dtype=float)
    W = np.ascontiguousarray(W, dtype=float)
    return _precisions_cached(corr.tobytes(), W.tobytes(), W.shape)


@lru_cache(maxsize=4)
def _precisions_cached(corr_bytes: bytes, w_bytes: bytes, shape: tuple[int, int]) -> np.ndarray:
    """:func:`_frame_precisions` on raw bytes; inv(C_oo) once per distinct pattern of observed edges."""
    E, T = shape
    corr = np.frombuffer(corr_bytes, dtype=float).reshape(E, E)
    W = np.frombuffer(w_bytes, dtype=float).reshape(E, T)
    obs = W > 0
    patterns, which = np.unique(obs.T, axis=0, return_inverse=True)
    invs = np.zeros((len(patterns), E, E))
    for k, o in enumerate(patterns):
        idx = np.flatnonzero(o)
        if idx.size:
            invs[k][np.ix_(idx, idx)] = np.linalg.inv(corr[np.ix_(idx, idx)])
    sw = np.sqrt(np.where(obs, W, 0.0)).T  # (T, E)
    P = invs[np.ravel(which)] * sw[:, :, None] * sw[:, None, :]
    P.flags.writeable = False
    return P


def _normalise(state, W):
    """Scale w to RMS 1 over observed frames, mu accordingly (the product is unchanged)."""
    w = state["latents"]["w"]
    obs = (W > 0).any(axis=0)
    rms = float(np.sqrt(np.mean(w[obs] ** 2))) if obs.any() else 0.0
    if rms <= 1e-12:
        return state
    return {**state, "params": {"mu": state["params"]["mu"] * rms}, "latents": {"w": w / rms}}
