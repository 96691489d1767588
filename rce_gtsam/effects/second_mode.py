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
    fitting = ("alternating least squares on the partial residual: mu_e per edge, then w_t per frame "
               "(w is re-estimated, mu frozen, on new frames)")

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
        mu = state["params"]["mu"]
        w = state["latents"]["w"]
        if not frozen:
            den = np.sum(W * w * w, axis=1)
            mu = np.where(den > 1e-12, np.sum(W * w * R, axis=1) / np.maximum(den, 1e-12), 0.0)
        den = np.sum(W * (mu * mu)[:, None], axis=0)
        ok = free & (den > 1e-12)
        w_new = np.where(ok, np.sum(W * mu[:, None] * R, axis=0) / np.where(ok, den, 1.0), w)
        st = {"params": {"mu": mu}, "latents": {"w": w_new}}
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
    return {"params": {"mu": state["params"]["mu"] * rms}, "latents": {"w": w / rms}}
