"""The composable response model: the rank-1 compliance core plus physical effect terms.

Model (units: degrees, frames)::

    x_e = L_e z                (operator effects; identity for the baseline)
    y_e = g(kappa_e x_e) + a_e (output effect g; additive effects a)

One engine. With no effect, :meth:`ResponseModel.fit` *is* the rank-1 fit ``rce analyze`` reports: it runs the
rank-1 solver of :mod:`rce_gtsam.model.compliance` (:func:`~rce_gtsam.model.compliance.fit_rank1`) with the model's whole
:class:`~rce_gtsam.presets.ComplianceConfig` — response convention, shrinkage of log kappa (``count`` or
``precision``, with ``prior_strength`` / ``prior_sd_log``), ``n_iter``, ``tol``, and the generalised least
squares of ``correlated`` when per-frame precisions are given — so the diagnosis baseline, the extended
model's starting point and the analysis all have the same kappa. With effects (or a warm start, frozen
parameters, a ridge on z: the diagnosis' held-out refits) the same alternation runs as block-coordinate
descent (:mod:`rce_gtsam.model.steps`): a Gauss-Newton kappa step with the rank-1 solver's shrinkage and
normalisation, a z step through the effects, then one block update per effect. Each block step does not
increase the weighted squared error apart from the (small) shrinkage, so the loop converges.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .compliance import fit_rank1, initial_z
from ..presets import DEFAULT, ComplianceConfig
from .fit import ModelFit
from .inputs import validate_inputs
from .steps import EPS, core_step, kappa_step, z_step
from .view import FitView, PartialView

KINDS = {"operator": 0, "output": 1, "additive": 2}  # effect kinds, in the order the model applies them


class ResponseModel:
    """Rank-1 core ``kappa_e z_t`` plus effect terms; immutable (``+`` returns a new model).

    effects: :class:`~rce_gtsam.effects.Effect` instances (composed operators first, then the output map,
    then additive terms). config: the :class:`~rce_gtsam.presets.ComplianceConfig` of the fit (default: the
    ``default`` preset's). The keyword overrides replace single fields of it: ``prior_strength`` (lambda of
    the count shrinkage), ``response`` (``"signed"`` or ``"abs"``), ``max_iter`` (``n_iter``: loop cap) and
    ``tol`` (stop tolerance on max |log kappa change|; the effects loop also needs the relative error change
    below tol / 100). Checked on construction: a bad config or effect raises ValueError / TypeError.
    """

    def __init__(self, effects=(), config: ComplianceConfig | None = None, *, prior_strength: float | None = None,
                 response: str | None = None, max_iter: int | None = None, tol: float | None = None):
        config = DEFAULT.compliance if config is None else config
        if not isinstance(config, ComplianceConfig):
            raise TypeError(f"config must be a ComplianceConfig, got {type(config).__name__}")
        overrides = {k: v for k, v in (("prior_strength", prior_strength), ("response", response),
                                       ("n_iter", max_iter), ("tol", tol)) if v is not None}
        self.config = replace(config, **overrides) if overrides else config  # replace() re-validates
        effects = tuple(effects)
        for e in effects:
            if getattr(e, "kind", None) not in KINDS or not isinstance(getattr(e, "name", None), str):
                raise TypeError(f"not an Effect: {e!r}")
        if sum(e.kind == "output" for e in effects) > 1:
            raise ValueError("at most one output (nonlinear) effect can be composed")
        names = [e.name for e in effects]
        if len(set(names)) != len(names):
            raise ValueError(f"effect added twice: {names}")
        if effects and self.config.correlated:
            raise ValueError("the correlated (generalised least squares) fit has no effect terms: set "
                             "correlated=False to add " + ", ".join(names))
        self.effects = tuple(sorted(effects, key=lambda e: KINDS[e.kind]))

    @classmethod
    def from_config(cls, config: ComplianceConfig, effects=()) -> "ResponseModel":
        """``ResponseModel(effects, config)``."""
        return cls(effects, config)

    # -- the config's fields under their historical names ----------------------------------------------
    @property
    def prior_strength(self) -> float:
        return float(self.config.prior_strength)

    @property
    def response(self) -> str:
        return self.config.response

    @property
    def max_iter(self) -> int:
        return int(self.config.n_iter)

    @property
    def tol(self) -> float:
        return float(self.config.tol)

    # -- composition ------------------------------------------------------------------------------------
    def with_effects(self, effects) -> "ResponseModel":
        """The same core and config with ``effects`` instead of this model's."""
        return ResponseModel(effects, self.config)

    def add(self, *effects) -> "ResponseModel":
        return self.with_effects(self.effects + tuple(effects))

    def __add__(self, other) -> "ResponseModel":
        if isinstance(other, ResponseModel):
            return self.with_effects(self.effects + other.effects)
        return self.add(other)

    def without_effects(self) -> "ResponseModel":
        return self.with_effects(())

    @property
    def name(self) -> str:
        return "rank1" + "".join(f" + {e.name}" for e in self.effects)

    def __repr__(self) -> str:
        c = self.config
        return (f"ResponseModel({self.name}, response={c.response!r}, shrinkage={c.shrinkage!r}, "
                f"prior_strength={c.prior_strength}, prior_sd_log={c.prior_sd_log})")

    # -- fitting ----------------------------------------------------------------------------------------
    def fit(self, Y, weights=None, root_distance=None, init: ModelFit | None = None, precision=None) -> ModelFit:
        """Fit to ``Y`` (E, T) degrees (NaN = missing). ``weights`` (E, T) >= 0 (e.g. 1 / variance);
        ``root_distance`` (E,) in [0, 1] (default: row order, evenly spaced); ``init``: a previous fit of a
        model with the same core to start from (its kappa, z and the states of effects present in both);
        ``precision`` (T, E, E): per-frame inverse covariances, used (and required) when the config is
        ``correlated`` (:attr:`rce_gtsam.pipeline.Response.precision`)."""
        Y, W, s = validate_inputs(Y, weights, root_distance)
        return self.solve(Y, W, s, start=None if init is None else init.warm_start(), precision=precision)

    def solve(self, Y, W, s, *, start=None, frozen: bool = False, free=None, max_iter: int | None = None,
              refit_shared: bool = True, z_ridge: float | None = None, frame_counts=None,
              precision=None) -> ModelFit:
        """The solver behind :meth:`fit`, with the options that refits and cross-validation need.

        ``Y`` (E, T) degrees with NaN = missing, ``W`` (E, T) weights (0 where missing), ``s`` (E,) root
        distance 0..1: as returned by :func:`~rce_gtsam.model.inputs.validate_inputs`.
        ``start``: (kappa, z, {effect name: state}) to start from (:meth:`ModelFit.warm_start`);
        ``frozen``: only z and latents change, on the ``free`` (T,) frames — the prediction of new frames;
        ``max_iter``: loop cap (default ``config.n_iter``); ``refit_shared=False`` keeps each effect's shared
        (not per-edge) parameters at their starting values; ``z_ridge``: precision of a zero-mean Gaussian
        prior on each z_t in weighted-SSE units (noise variance / z variance: the posterior mean of z), for z
        estimated from few edges; None (default): 0 for models without an operator effect, and for models
        with one (z seen through a lag or a filter) the rank-1 core's own ratio at the start
        (:func:`z_prior_precision`) — without it, frames and frequencies of z that the operators barely pass
        (the last frames behind a lag, high frequencies behind a resonance) are fitted to noise and grow
        without bound (a 30-frame tip lag: z RMS 0.7 -> 41 deg from 3 end frames, its held-out RMSE +8 %);
        ``frame_counts`` (T,): how many times each frame counts in the kappa
        step's sample size (a bootstrap resample applied as multiplicities; W already multiplied by them);
        ``precision``: see :meth:`fit`.

        With no effect and none of these options it is the rank-1 solver itself
        (:func:`rce_gtsam.model.compliance.fit_rank1`; ``max_iter`` replaces ``n_iter``) and the result carries its
        :class:`~rce_gtsam.model.compliance.Rank1Fit` as ``core``.
        """
        cfg = self.config if max_iter is None else replace(self.config, n_iter=int(max_iter))
        plain = start is None and not frozen and free is None and not z_ridge and frame_counts is None
        if not self.effects and plain:
            return self._rank1(Y, W, s, cfg, precision)
        return self._loop(Y, W, s, cfg, start, frozen, free, refit_shared, z_ridge, frame_counts)

    def _rank1(self, Y, W, s, cfg: ComplianceConfig, precision) -> ModelFit:
        if cfg.correlated and precision is None:
            raise ValueError("correlated=True needs the per-frame precisions (Response.precision)")
        obs = W > 0
        core = fit_rank1(Y, cfg, W, precision if cfg.correlated else None)
        return ModelFit(model=self, kappa=core.kappa * core.direction, z=core.z, states=(),
                        Y=np.where(obs, Y, np.nan), weights=W, root_distance=s, iterations=core.iterations,
                        converged=core.converged, n_obs=int(obs.sum()), shrinkage=core.shrinkage, core=core)

    def _loop(self, Y, W, s, cfg, start, frozen, free, refit_shared, z_ridge, frame_counts) -> ModelFit:
        E, T = Y.shape
        obs = W > 0
        Y0 = np.where(obs, Y, 0.0)
        free = np.ones(T, bool) if free is None else np.asarray(free, bool)
        if start is None:
            kappa, z = np.ones(E), initial_z(Y[None], obs[None])[0]
            prev_states = {}
        else:
            kappa, z, prev_states = start
            kappa, z = np.array(kappa, dtype=float), np.array(z, dtype=float)
        view = FitView(self, Y0, W, s, free, kappa, z, [])
        view.frame_counts = None if frame_counts is None else np.asarray(frame_counts, dtype=float)
        if start is None and not frozen:
            for _ in range(5):  # a few baseline iterations so that the effects start from a sensible core
                core_step(view)
        if z_ridge is None:
            z_ridge = z_prior_precision(view) if any(e.kind == "operator" for e in self.effects) else 0.0
        view.z_ridge = float(z_ridge)
        states = []
        for eff in self.effects:
            states.append(prev_states[eff.name] if eff.name in prev_states else eff.init(PartialView(view, states)))
        for st in states:  # an effect's init may hand the core a better start than the linear fit (its state's
            # "core_start": (kappa, z) it found while choosing its own starting parameters)
            _take_core_start(view, st, frozen, only_if_lower=False)
        view.states = states
        has_latent = any(e.latent_names() for e in self.effects)
        converged = False
        it = 0
        err = view.wsse()
        for it in range(1, int(cfg.n_iter) + 1):
            k_prev = view.kappa.copy()
            if not frozen:
                kappa_step(view)
            z_step(view)
            for i, eff in enumerate(self.effects):
                if frozen and not eff.latent_names():
                    continue
                if not refit_shared and not eff.latent_names() and not any(p.per_edge for p in eff.parameters(E)):
                    continue
                view.states[i] = eff.update(view.states[i], view, frozen)
                # an update may also hand the core a better (kappa, z) it found (a per-edge global search that
                # the Gauss-Newton steps cannot make); taken only when it lowers the error
                _take_core_start(view, view.states[i], frozen, only_if_lower=True)
            new_err = view.wsse()
            dk = float(np.max(np.abs(np.log(np.maximum(np.abs(view.kappa), EPS))
                                     - np.log(np.maximum(np.abs(k_prev), EPS))))) if E else 0.0
            rel = abs(err - new_err) / max(err, 1e-300)
            err = new_err
            if dk < cfg.tol and rel < cfg.tol * 1e-2:
                converged = True
                break
            if frozen and not has_latent and not any(e.kind == "output" for e in self.effects):
                converged = True  # the z step is exact (model linear in z): one pass suffices
                break
        return ModelFit(model=self, kappa=view.kappa, z=view.z, states=tuple(view.states), Y=np.where(obs, Y, np.nan),
                        weights=W, root_distance=s, iterations=it, converged=converged, n_obs=int(obs.sum()),
                        shrinkage=view.shrinkage)


def z_prior_precision(view) -> float:
    """The precision of the zero-mean Gaussian prior on each z_t that makes the z step a posterior mean, in
    weighted-SSE units: (the rank-1 core's mean weighted squared residual) / (mean z^2), both from the
    view's current kappa and z with no effect applied (0 when z is all zero). Relative to a typical frame's
    information (sum_e W kappa_e^2) it is ~1 / (E x signal-to-noise): it shrinks well-observed frames by
    about that fraction and keeps frames the data barely determine near zero."""
    obs = view.W > 0
    z2 = float(np.mean(view.z ** 2))
    if z2 <= 0 or not obs.any():
        return 0.0
    r = np.where(obs, view.Y0 - view.kappa[:, None] * view.z[None, :], 0.0)
    return float(np.sum(view.W * r * r) / obs.sum()) / z2


def _take_core_start(view, state, frozen: bool, only_if_lower: bool) -> None:
    """Pop an effect state's ``"core_start": (kappa, z)`` and, unless ``frozen``, move the core there (with
    ``only_if_lower``, only when that lowers the weighted SSE)."""
    core_start = state.pop("core_start", None) if isinstance(state, dict) else None
    if core_start is None or frozen:
        return
    k_new, z_new = np.array(core_start[0], dtype=float), np.array(core_start[1], dtype=float)
    if not only_if_lower or view.wsse(kappa=k_new, z=z_new) < view.wsse():
        view.kappa, view.z = k_new, z_new
