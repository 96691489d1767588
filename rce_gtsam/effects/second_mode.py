"""``second_mode``: a second, independent excitation with its own spatial pattern.

Physics: y_e(t) = kappa_e z_t + mu_e w_t. A crosswind, an out-of-plane swing or a side branch hitting the
stem loads the joints in a different proportion mu than the main wind does; w is an unknown per-frame
series like z. Units: w is scaled to RMS 1 over the observed frames, so mu_e is the RMS amplitude of the
second mode at edge e in degrees.
"""

from __future__ import annotations

import numpy as np

from .base import Effect, Parameter
from .offset import _index


class SecondMode(Effect):
    """Rank-2 response: a second latent excitation w_t with per-edge gains mu_e."""

    name = "second_mode"
    kind = "additive"
    equation = "y_e(t) = kappa_e z_t + mu_e w_t   (w: RMS 1, mu in degrees)"
    fitting = ("alternating least squares on the partial residual: mu_e per edge, then w_t per frame as the "
               "posterior mean under its N(0, 1) prior (ridge = residual variance); on new frames w is "
               "re-estimated with mu frozen")

    def parameters(self, n_edges: int):
        return (Parameter("mu", "deg", per_edge=True, description="RMS amplitude of the second mode"),)

    def latent_names(self):
        return ("w",)

    def init(self, view) -> dict:
        i = _index(self, view)
        R = view.Y0 - view.predict() if i is None else view.partial_target(i)
        W = view.W
        # start from the leading singular pair of the (weighted, zero-filled) residual
        Rw = np.where(W > 0, R, 0.0)
        try:
            U, S, Vt = np.linalg.svd(Rw, full_matrices=False)
            mu, w = U[:, 0] * S[0], Vt[0].copy()
        except np.linalg.LinAlgError:  # pragma: no cover
            mu, w = np.zeros(view.E), np.zeros(view.T)
        st = {"params": {"mu": mu}, "latents": {"w": w}}
        st = _normalise(st, W)
        for _ in range(3):
            st = self._als(st, R, W, view.free, frozen=False)
        return st

    def additive(self, state, view):
        return state["params"]["mu"][:, None] * state["latents"]["w"][None, :]

    def update(self, state, view, frozen):
        i = _index(self, view)
        R = view.partial_target(i)
        return self._als(state, R, view.W, view.free, frozen)

    @staticmethod
    def _als(state, R, W, free, frozen):
        """One mu step (unless frozen) and one w step.

        w is normalised to RMS 1, so its prior is N(0, 1) per frame and the posterior mean of w_t given mu
        is sum_e W mu_e r_e / (sum_e W mu_e^2 + sigma^2) with sigma^2 the weighted residual variance
        (kept in the state as ``noise_var`` from the last fit on all frames). Without the prior a frame seen
        by few edges with small mu — the held-out frames of cross-validation, where w comes from a subset of
        edges — gets an unbounded w (error amplified by 1 / mu^2) that says nothing about the other edges."""
        mu = state["params"]["mu"]
        w = state["latents"]["w"]
        if not frozen:
            den = np.sum(W * w * w, axis=1)
            mu = np.where(den > 1e-12, np.sum(W * w * R, axis=1) / np.maximum(den, 1e-12), 0.0)
        obs = W > 0
        if frozen and "noise_var" in state:
            s2 = float(state["noise_var"])
        else:
            r = R - mu[:, None] * w[None, :]
            s2 = float(np.sum(W * r * r) / max(int(obs.sum()), 1))
        den = np.sum(W * (mu * mu)[:, None], axis=0)
        ok = free & (den > 1e-12)
        w_new = np.where(ok, np.sum(W * mu[:, None] * R, axis=0) / np.where(ok, den + s2, 1.0), w)
        st = {"params": {"mu": mu}, "latents": {"w": w_new}, "noise_var": s2}
        return st if frozen else _normalise(st, W)

    def describe(self, state):
        mu = state["params"]["mu"]
        return {"rms_amplitude_deg": float(np.sqrt(np.mean(mu ** 2)))}


def _normalise(state, W):
    """Scale w to RMS 1 over observed frames, mu accordingly (the product is unchanged)."""
    w = state["latents"]["w"]
    obs = (W > 0).any(axis=0)
    rms = float(np.sqrt(np.mean(w[obs] ** 2))) if obs.any() else 0.0
    if rms <= 1e-12:
        return state
    return {**state, "params": {"mu": state["params"]["mu"] * rms}, "latents": {"w": w / rms}}
