"""The data and current values of one fit, as the solver steps and the effects see them.

A :class:`FitView` is handed to every effect's ``init`` / ``update`` (see :mod:`rce_gtsam.effects.base`) and
to the public solver steps of :mod:`rce_gtsam.model.steps`. Units: degrees (Y, z, predictions), frames.
"""

from __future__ import annotations

import numpy as np


class FitView:
    """Data and current values of a fit.

    model: the :class:`~rce_gtsam.model.ResponseModel` being fitted (its ``effects`` and ``config``);
    Y0: (E, T) data in degrees with missing entries set to 0; W: (E, T) weights (0 = missing);
    s: (E,) normalised root distance of each edge's child (0..1); tt: (T,) time as a fraction t/T;
    free: (T,) frames whose latents may change; kappa (E,), z (T,), states: the current values;
    z_ridge: precision of a N(0, 1 / z_ridge) prior on each z_t in weighted-SSE units (0 = none);
    frame_counts: (T,) how often each frame counts in the kappa step's sample size (a bootstrap resample's
    multiplicities; None = once); shrinkage: (E,) the factor s of the last kappa step
    (log|kappa| = s log|kappa_hat|, 1 = not shrunk).
    """

    def __init__(self, model, Y0, W, s, free, kappa, z, states):
        self.model = model
        self.effects = model.effects
        self.Y0, self.W, self.s, self.free = Y0, W, s, free
        self.E, self.T = Y0.shape
        self.tt = np.arange(self.T) / max(self.T, 1)
        self.kappa, self.z, self.states = kappa, z, states
        self.z_ridge = 0.0
        self.frame_counts: np.ndarray | None = None
        self.shrinkage = np.ones(self.E)

    # prediction -------------------------------------------------------------------------------------
    def transform(self, z: np.ndarray, states=None) -> np.ndarray:
        """x_e = L_e z for every edge, (E, T)."""
        states = self.states if states is None else states
        X = np.broadcast_to(z, (self.E, self.T))
        for eff, st in zip(self.effects, states):
            if eff.kind == "operator":
                X = eff.apply(np.asarray(X, dtype=float), st, self)
        return np.array(X, dtype=float)

    def transform_T(self, R: np.ndarray, states=None) -> np.ndarray:
        """Adjoint of :meth:`transform`: sum over edges of L_e^T r_e, (T,)."""
        states = self.states if states is None else states
        ops = [(eff, st) for eff, st in zip(self.effects, states) if eff.kind == "operator"]
        if len(ops) == 1:  # the usual case: one operator, whose adjoint may sum over edges more cheaply
            return ops[0][0].apply_T_sum(R, ops[0][1], self)
        for eff, st in reversed(ops):
            R = eff.apply_T(R, st, self)
        return R.sum(axis=0)

    def parts(self, states=None, kappa=None, z=None, skip_additive: int | None = None):
        """(prediction, X, g'(U)) with optional overrides; ``skip_additive`` leaves one term out."""
        states = self.states if states is None else states
        kappa = self.kappa if kappa is None else kappa
        z = self.z if z is None else z
        X = self.transform(z, states)
        U = kappa[:, None] * X
        G, dG = U, None
        for eff, st in zip(self.effects, states):
            if eff.kind == "output":
                G, dG = eff.output(U, st, kappa)
        for i, (eff, st) in enumerate(zip(self.effects, states)):
            if eff.kind == "additive" and i != skip_additive:
                a = eff.additive(st, self)
                if a is not None:
                    G = G + a
        return G, X, (np.ones_like(U) if dG is None else dG)

    def predict(self, states=None, kappa=None, z=None) -> np.ndarray:
        return self.parts(states, kappa, z)[0]

    def wsse(self, states=None, kappa=None, z=None) -> float:
        r = self.Y0 - self.predict(states, kappa, z)
        return float(np.sum(self.W * r * r))

    def partial_target(self, index: int) -> np.ndarray:
        """Data minus everything but additive term ``index`` (what that term must explain)."""
        return self.Y0 - self.parts(skip_additive=index)[0]

    def residual_vector(self, index: int, state: dict) -> np.ndarray:
        """sqrt(W) * (Y - prediction) flattened over observed entries, with effect ``index``'s state replaced."""
        r = (self.Y0 - self.predict(self.with_state(index, state))) * np.sqrt(self.W)
        return r[self.W > 0]

    def with_state(self, index: int, state: dict) -> list:
        states = list(self.states)
        states[index] = state
        return states

    def index_of(self, effect) -> int | None:
        """Position of ``effect`` (the instance) among the model's effects, or None (being initialised)."""
        for i, e in enumerate(self.effects):
            if e is effect:
                return i
        return None

    def copy_with(self, model, states) -> "FitView":
        """A view of the same data and current kappa, z (copied) for another ``model`` and its ``states``."""
        v = FitView(model, self.Y0, self.W, self.s, self.free, self.kappa.copy(), self.z.copy(), list(states))
        v.z_ridge, v.frame_counts = self.z_ridge, self.frame_counts
        return v


class PartialView(FitView):
    """A FitView whose states list holds only the effects initialised so far (what an effect's ``init`` sees).

    full_model: the model being fitted; ``model`` / ``effects``: its first ``len(states)`` effects."""

    def __init__(self, view: FitView, states: list):
        n = len(states)
        sub = view.model.with_effects(view.effects[:n])
        super().__init__(sub, view.Y0, view.W, view.s, view.free, view.kappa, view.z, list(states))
        self.z_ridge, self.frame_counts = view.z_ridge, view.frame_counts
        self.full_model = view.model
