"""Composable bend-response model: the rank-1 compliance core plus physical effect terms.

Usage (configuration in the constructor, fitted values only in the returned :class:`ModelFit`)::

    from rce_gtsam import effects
    from rce_gtsam.model import ResponseModel
    model = ResponseModel(prior_strength=12.0) + effects.Delay() + effects.Offset()
    fit = model.fit(Y, weights=None, root_distance=s)
    fit.kappa, fit.z, fit.params, fit.predict(), fit.residuals, fit.aic, fit.bic, print(fit.report())

Model (units: degrees, frames)::

    x_e = L_e z                (operator effects; identity for the baseline)
    y_e = g(kappa_e x_e) + a_e (output effect g; additive effects a)

With no effect it is the published rank-1 model y[e, t] = kappa_e z_t, fitted exactly as specified
(docs/reference-pipeline.md §2.8): alternating kappa / z least-squares steps, log-space shrinkage
kappa = kappa_hat ** (n / (n + lambda)) toward 1 and geometric-mean normalisation (prod |kappa| = 1).
With effects the same loop runs as block-coordinate descent: a Gauss-Newton kappa step and z step
through the effects (exact least-squares steps when the model is linear in that block; when an operator
couples frames, z is solved directly from the banded sparse normal matrix for delay, or by conjugate
gradients preconditioned with the operators' frequency responses), then one block update per effect. Each block step
does not increase the weighted squared error, apart from the (small) shrinkage, so the loop converges.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.sparse.linalg import LinearOperator, cg

from .effects.base import Effect
from .errors import InputError

EPS = 1e-6  # numerical floor of the published fit (kappa, z and denominators)


# ----------------------------------------------------------------------------------------------------------
# Data view shared with the effects during a fit
# ----------------------------------------------------------------------------------------------------------

class FitView:
    """Data and current values of a fit, handed to the effects' ``init`` / ``update``.

    Y0: (E, T) data in degrees with missing entries set to 0; W: (E, T) weights (0 = missing);
    s: (E,) normalised root distance of each edge's child (0..1); tt: (T,) time as a fraction t/T;
    free: (T,) frames whose latents may change; kappa (E,), z (T,), states: the current values.
    """

    def __init__(self, model: "ResponseModel", Y0, W, s, free, kappa, z, states):
        self.model = model
        self.effects = model.effects
        self.Y0, self.W, self.s, self.free = Y0, W, s, free
        self.E, self.T = Y0.shape
        self.tt = np.arange(self.T) / max(self.T, 1)
        self.kappa, self.z, self.states = kappa, z, states
        self.z_ridge = 0.0  # precision of a N(0, 1/z_ridge) prior on z (0 = none; see ResponseModel._fit)

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
        for eff, st in reversed(list(zip(self.effects, states))):
            if eff.kind == "operator":
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
                G, dG = eff.output(U, st)
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
        states = list(self.states)
        states[index] = state
        r = (self.Y0 - self.predict(states)) * np.sqrt(self.W)
        return r[self.W > 0]

    def with_state(self, index: int, state: dict) -> list:
        states = list(self.states)
        states[index] = state
        return states


# ----------------------------------------------------------------------------------------------------------
# Fit result
# ----------------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class ParamValue:
    """A fitted parameter: value, standard error (NaN if unknown), unit, description."""

    value: float
    stderr: float
    unit: str
    description: str = ""

    def as_dict(self) -> dict:
        return {"value": _num(self.value), "stderr": _num(self.stderr), "unit": self.unit}


def _num(x):
    x = float(x)
    return x if math.isfinite(x) else None


@dataclass(frozen=True, eq=False)
class ModelFit:
    """A fitted :class:`ResponseModel`.

    kappa: (E,) signed relative compliance (geometric mean of |kappa| = 1); z: (T,) excitation (degrees);
    states: fitted state of each effect; Y, weights: the data fitted (NaN = missing);
    root_distance: (E,); iterations, converged: loop diagnostics; n_obs: observed entries.
    """

    model: "ResponseModel"
    kappa: np.ndarray
    z: np.ndarray
    states: tuple
    Y: np.ndarray
    weights: np.ndarray
    root_distance: np.ndarray
    iterations: int
    converged: bool
    n_obs: int
    _cache: dict = field(default_factory=dict, repr=False)

    # -- core quantities -----------------------------------------------------------------------------
    def _view(self, free=None) -> FitView:
        Y0 = np.where(np.isfinite(self.Y), self.Y, 0.0)
        free = np.ones(self.Y.shape[1], bool) if free is None else free
        return FitView(self.model, Y0, self.weights, self.root_distance, free, self.kappa, self.z,
                       list(self.states))

    def predict(self) -> np.ndarray:
        """(E, T) fitted response in degrees (defined at missing entries too)."""
        if "pred" not in self._cache:
            self._cache["pred"] = self._view().predict()
        return self._cache["pred"]

    def components(self) -> dict[str, np.ndarray]:
        """Each effect's share of the prediction: prediction minus the prediction without that effect."""
        full = self.predict()
        out = {"core": self.model.without_effects()._predict_with(self, ())}
        for i, eff in enumerate(self.model.effects):
            keep = tuple(j for j in range(len(self.model.effects)) if j != i)
            out[eff.name] = full - self.model._predict_with(self, keep)
        return out

    @property
    def residuals(self) -> np.ndarray:
        """(E, T) y - prediction in degrees, NaN where y is missing."""
        return self.Y - self.predict()

    @property
    def wsse(self) -> float:
        r = np.where(np.isfinite(self.Y), self.residuals, 0.0)
        return float(np.sum(self.weights * r * r))

    @property
    def rmse(self) -> float:
        """Unweighted RMS residual over observed entries (degrees)."""
        r = self.residuals
        return float(np.sqrt(np.nanmean(r * r)))

    @property
    def n_params(self) -> int:
        """Fitted degrees of freedom: E-1 kappa (one lost to the normalisation) + observed z frames + effects."""
        E, T = self.Y.shape
        t_obs = int((self.weights > 0).any(axis=0).sum())
        k = (E - 1) + t_obs
        for eff, st in zip(self.model.effects, self.states):
            k += eff.n_free(st, E, t_obs)
        return k

    @property
    def aic(self) -> float:
        """Gaussian AIC with the variance profiled out: n ln(WSSE / n) + 2 k."""
        n = self.n_obs
        return float(n * math.log(max(self.wsse, 1e-300) / n) + 2 * self.n_params)

    @property
    def bic(self) -> float:
        n = self.n_obs
        return float(n * math.log(max(self.wsse, 1e-300) / n) + math.log(n) * self.n_params)

    @property
    def r_squared(self) -> float:
        """1 - SS_res / SS_tot with SS_tot around each edge's own mean (observed entries)."""
        Y = self.Y
        dev = Y - np.nanmean(Y, axis=1, keepdims=True)
        return float(1 - np.nansum(self.residuals ** 2) / max(np.nansum(dev ** 2), 1e-300))

    def residual_autocorrelation(self) -> float:
        """Lag-1 autocorrelation of the residuals (pooled over edges, observed pairs)."""
        r = self.residuals
        a, b = r[:, :-1], r[:, 1:]
        ok = np.isfinite(a) & np.isfinite(b)
        if ok.sum() < 3:
            return 0.0
        a, b = a[ok], b[ok]
        return float(np.clip(np.sum(a * b) / max(np.sqrt(np.sum(a * a) * np.sum(b * b)), 1e-300), -0.99, 0.99))

    # -- parameters with uncertainty -----------------------------------------------------------------
    @property
    def params(self) -> dict[str, ParamValue]:
        """Every static parameter (``kappa[i]`` and ``effect.param[i]``) with a standard error.

        Standard errors are conditional on z and the latent series (linearised least squares with the
        residual variance), inflated by (1 + rho) / (1 - rho) for the residuals' lag-1 autocorrelation
        rho — serially correlated residuals carry fewer independent samples than frames.
        """
        if "params" not in self._cache:
            self._cache["params"] = self._compute_params()
        return self._cache["params"]

    def _compute_params(self) -> dict[str, ParamValue]:
        view = self._view()
        obs = self.weights > 0
        sw = np.sqrt(self.weights[obs])
        r = self.residuals[obs]
        dof = max(self.n_obs - self.n_params, 1)
        sigma2 = float(np.sum(self.weights[obs] * r * r) / dof)
        rho = self.residual_autocorrelation()
        infl = (1 + max(rho, 0.0)) / (1 - max(rho, 0.0))
        out: dict[str, ParamValue] = {}
        # kappa: d pred / d kappa_e = g'(u) x on row e
        _, X, dG = view.parts()
        J = dG * X
        info = np.sum(self.weights * J * J, axis=1)
        se_k = np.sqrt(sigma2 * infl / np.maximum(info, 1e-300))
        for e in range(len(self.kappa)):
            out[f"kappa[{e}]"] = ParamValue(float(self.kappa[e]), float(se_k[e]), "1", "relative compliance")
        base = view.predict()[obs]
        for i, (eff, st) in enumerate(zip(self.model.effects, self.states)):
            for p in eff.parameters(len(self.kappa)):
                val = np.atleast_1d(np.asarray(st["params"][p.name], dtype=float))
                cols = []
                for j in range(val.size):
                    h = 1e-4 * max(abs(val[j]), 1e-2)
                    v2 = val.copy()
                    v2[j] += h
                    st2 = {"params": dict(st["params"]), "latents": st["latents"]}
                    st2["params"][p.name] = v2 if p.per_edge else v2.reshape(np.shape(st["params"][p.name]))
                    pred = view.predict(view.with_state(i, st2))[obs]
                    cols.append(sw * (pred - base) / h)
                Jp = np.stack(cols, axis=1)
                try:
                    cov = np.linalg.pinv(Jp.T @ Jp) * sigma2 * infl
                    se = np.sqrt(np.maximum(np.diag(cov), 0.0))
                except np.linalg.LinAlgError:  # pragma: no cover
                    se = np.full(val.size, np.nan)
                for j in range(val.size):
                    key = f"{eff.name}.{p.name}" + (f"[{j}]" if p.per_edge else "")
                    out[key] = ParamValue(float(val[j]), float(se[j]), p.unit, p.description)
        return out

    def effect_summary(self) -> dict[str, dict]:
        """Per effect: parameters (value, stderr, unit) and derived numbers, JSON-able."""
        prm = self.params
        out = {}
        for eff, st in zip(self.model.effects, self.states):
            d = {k.split(".", 1)[1]: v.as_dict() for k, v in prm.items() if k.startswith(eff.name + ".")}
            d.update({k: (_num(v) if np.isscalar(v) else v) for k, v in eff.describe(st).items()})
            out[eff.name] = d
        return out

    def report(self, edge_labels=None, max_rows: int = 40) -> str:
        """A fit report in the style of lmfit's ``fit_report``."""
        from .diagnose import render_fit_report
        return render_fit_report(self, edge_labels=edge_labels, max_rows=max_rows)


# ----------------------------------------------------------------------------------------------------------
# The model
# ----------------------------------------------------------------------------------------------------------

class ResponseModel:
    """Rank-1 core ``kappa_e z_t`` plus effect terms; immutable (``+`` returns a new model).

    prior_strength: lambda of the log-space shrinkage of kappa toward 1 (§2.8; 12 in the paper).
    response: ``"signed"`` (z and kappa signed) or ``"abs"`` (the paper's |delta| response, z >= 0).
    max_iter, tol: loop cap and stop tolerance (max |log kappa change| and relative error change).
    """

    def __init__(self, effects: tuple[Effect, ...] | list = (), prior_strength: float = 12.0,
                 response: str = "signed", max_iter: int = 300, tol: float = 1e-5):
        effects = tuple(effects)
        for e in effects:
            if not isinstance(e, Effect):
                raise TypeError(f"not an Effect: {e!r}")
        if sum(e.kind == "output" for e in effects) > 1:
            raise ValueError("at most one output (nonlinear) effect can be composed")
        names = [e.name for e in effects]
        if len(set(names)) != len(names):
            raise ValueError(f"effect added twice: {names}")
        if response not in ("signed", "abs"):
            raise ValueError(f"response must be 'signed' or 'abs', got {response!r}")
        # operators first (they act on z), then the output map, then additive terms
        order = {"operator": 0, "output": 1, "additive": 2}
        self.effects = tuple(sorted(effects, key=lambda e: order[e.kind]))
        self.prior_strength = float(prior_strength)
        self.response = response
        self.max_iter = int(max_iter)
        self.tol = float(tol)

    @classmethod
    def from_config(cls, config, effects=()) -> "ResponseModel":
        """From a :class:`~rce_gtsam.presets.ComplianceConfig`."""
        return cls(effects, prior_strength=config.prior_strength, response=config.response)

    def _replace(self, effects) -> "ResponseModel":
        return ResponseModel(effects, self.prior_strength, self.response, self.max_iter, self.tol)

    def add(self, *effects: Effect) -> "ResponseModel":
        return self._replace(self.effects + tuple(effects))

    def __add__(self, other) -> "ResponseModel":
        if isinstance(other, ResponseModel):
            return self._replace(self.effects + other.effects)
        return self.add(other)

    def without_effects(self) -> "ResponseModel":
        return self._replace(())

    @property
    def name(self) -> str:
        return "rank1" + "".join(f" + {e.name}" for e in self.effects)

    def __repr__(self) -> str:
        return f"ResponseModel({self.name}, prior_strength={self.prior_strength}, response={self.response!r})"

    # -- public fit -----------------------------------------------------------------------------------
    def fit(self, Y, weights=None, root_distance=None, init: ModelFit | None = None) -> ModelFit:
        """Fit to ``Y`` (E, T) degrees (NaN = missing). ``weights`` (E, T) >= 0 (e.g. 1 / variance);
        ``root_distance`` (E,) in [0, 1] (default: row order, evenly spaced). ``init``: a previous fit of a
        model with the same core to start from (its kappa, z and the states of effects present in both)."""
        Y, W, s = validate_inputs(Y, weights, root_distance)
        start = None
        if init is not None:
            start = (init.kappa.copy(), init.z.copy(),
                     {eff.name: st for eff, st in zip(init.model.effects, init.states)})
        return self._fit(Y, W, s, start=start)

    # -- engine ---------------------------------------------------------------------------------------
    def _fit(self, Y, W, s, start=None, frozen: bool = False, free=None, max_iter=None,
             refit_shared: bool = True, z_ridge: float = 0.0) -> ModelFit:
        """The fitting loop. ``frozen``: only z and latents change (on ``free`` frames) — prediction of new
        frames. ``refit_shared=False`` keeps each effect's shared (non per-edge) parameters at their
        starting values (used by cross-validation refits, see :mod:`rce_gtsam.diagnose`). ``z_ridge``:
        precision of a zero-mean Gaussian prior on each z_t in weighted-SSE units (noise variance / z
        variance: the posterior mean of z). Used when z is estimated from few edges (held-out frames),
        where a frame seen only weakly — e.g. through a long lag — would otherwise be unbounded."""
        E, T = Y.shape
        obs = W > 0
        Y0 = np.where(obs, Y, 0.0)
        free = np.ones(T, bool) if free is None else np.asarray(free, bool)
        max_iter = self.max_iter if max_iter is None else max_iter
        if start is None:
            kappa, z = np.ones(E), _initial_z(Y, obs)
            prev_states = {}
        else:
            kappa, z, prev_states = start
            kappa, z = kappa.copy(), z.copy()
        view = FitView(self, Y0, W, s, free, kappa, z, [])
        view.z_ridge = float(z_ridge)
        if start is None and not frozen:
            # a few baseline iterations so that the effects start from a sensible core
            for _ in range(5):
                self._core_step(view)
        states = []
        for eff in self.effects:
            if eff.name in prev_states:
                states.append(prev_states[eff.name])
            else:
                st = eff.init(_PartialView(view, states))
                states.append(st)
        view.states = states
        has_latent = any(e.latent_names() for e in self.effects)
        converged = False
        it = 0
        err = view.wsse()
        for it in range(1, max_iter + 1):
            k_prev = view.kappa.copy()
            if not frozen:
                self._kappa_step(view)
            self._z_step(view)
            for i, eff in enumerate(self.effects):
                if frozen and not eff.latent_names():
                    continue
                if not refit_shared and not eff.latent_names() and \
                        not any(p.per_edge for p in eff.parameters(E)):
                    continue
                view.states[i] = eff.update(view.states[i], view, frozen)
            new_err = view.wsse()
            dk = float(np.max(np.abs(np.log(np.maximum(np.abs(view.kappa), EPS))
                                     - np.log(np.maximum(np.abs(k_prev), EPS))))) if E else 0.0
            rel = abs(err - new_err) / max(err, 1e-300)
            err = new_err
            if dk < self.tol and rel < self.tol * 1e-2:
                converged = True
                break
            if frozen and not has_latent and not any(e.kind == "output" for e in self.effects):
                converged = True  # the z step is exact (model linear in z): one pass suffices
                break
        return ModelFit(model=self, kappa=view.kappa, z=view.z, states=tuple(view.states), Y=np.where(obs, Y, np.nan),
                        weights=W, root_distance=s, iterations=it, converged=converged, n_obs=int(obs.sum()))

    def _core_step(self, view: FitView) -> None:
        self._kappa_step(view)
        self._z_step(view)

    def _kappa_step(self, view: FitView) -> None:
        """Gauss-Newton kappa step (exact least squares when g is linear), shrinkage, normalisation."""
        pred, X, dG = view.parts()
        r = view.Y0 - pred
        J = dG * X
        Wm = view.W * (np.abs(X) > EPS)
        num = np.sum(Wm * J * r, axis=1)
        den = np.sum(Wm * J * J, axis=1)
        n = (Wm > 0).sum(axis=1).astype(float)
        k_hat = view.kappa + num / np.maximum(den, EPS)
        if self.response == "abs":
            k_hat = np.maximum(k_hat, EPS)
        sign = np.where(k_hat < 0, -1.0, 1.0)
        mag = np.maximum(np.abs(k_hat), EPS)
        shrink = n / (n + self.prior_strength)
        k_new = np.where(n > 0, sign * np.exp(shrink * np.log(mag)), 1.0)
        big = np.abs(k_new) > EPS
        gm = math.exp(np.log(np.abs(k_new[big])).mean()) if big.any() else 1.0
        k_new = np.where(big, k_new / gm, k_new)
        view.kappa = k_new
        view.z = view.z * gm  # keeps kappa * z (and any operator of z) unchanged

    def _z_step(self, view: FitView) -> None:
        """Gauss-Newton z step on the free frames (exact when the model is linear in z)."""
        pred, X, dG = view.parts()
        r = view.Y0 - pred
        C = dG * view.kappa[:, None]
        WC = view.W * C
        has_op = any(e.kind == "operator" for e in view.effects)
        free = view.free
        lam = view.z_ridge
        if not has_op:
            den = np.sum(WC * C, axis=0) + lam
            ok = free & (den > EPS)
            dz = np.where(ok, (np.sum(WC * r, axis=0) - lam * view.z) / np.where(ok, den, 1.0), 0.0)
        else:
            dz = _operator_z_solve(view, C, r, free)
        new_z = view.z + dz
        if self.response == "abs":
            new_z = np.maximum(new_z, 0.0)
        if any(e.kind == "output" for e in view.effects):
            # Gauss-Newton on a nonlinear g: halve the step until the error does not grow
            old = view.wsse()
            step = 1.0
            for _ in range(6):
                if view.wsse(z=view.z + step * (new_z - view.z)) <= old:
                    break
                step *= 0.5
            new_z = view.z + step * (new_z - view.z)
        view.z = new_z

    def _predict_with(self, fit: ModelFit, keep: tuple[int, ...]) -> np.ndarray:
        """Prediction of ``fit`` using only the effects with indices ``keep`` (for components())."""
        sub = self._replace(tuple(self.effects[i] for i in keep)) if keep or self.effects else self
        Y0 = np.where(np.isfinite(fit.Y), fit.Y, 0.0)
        v = FitView(sub, Y0, fit.weights, fit.root_distance, np.ones(Y0.shape[1], bool), fit.kappa, fit.z,
                    [fit.states[i] for i in keep])
        return v.predict()


# Relative Tikhonov ridge of the iterative z solve (fraction of a typical frame's information). Operators
# with memory (dynamics) attenuate high frequencies of z, whose components are then barely determined by
# the data; 1e-3 keeps them bounded while biasing well-determined components by ~0.1 %.
Z_RIDGE = 1e-3


def _operator_z_solve(view: FitView, C: np.ndarray, r: np.ndarray, free: np.ndarray) -> np.ndarray:
    """Gauss-Newton step dz of  min sum_e,t W (r - C L_e dz)^2  over the free frames, operators present.

    Frames whose z no observation touches (through the operators) are not free: nothing determines them.
    Direct path: a single operator that exposes ``sparse_operator`` (delay) gives a sparse, banded normal
    matrix, solved exactly with a sparse LU. Otherwise preconditioned conjugate gradients, with the
    circulant approximation of the normal matrix (sum_e mean(D_e) |H_e(f)|^2, from the operators'
    ``transfer``) as the preconditioner when every operator provides its frequency response — it is
    exact for full, evenly weighted data, so CG needs few iterations; Jacobi otherwise.
    """
    from scipy import sparse
    from scipy.sparse.linalg import spsolve

    T = view.T
    D = view.W * C * C
    ops = [(e, st) for e, st in zip(view.effects, view.states) if e.kind == "operator"]
    dz = np.zeros(T)
    lam = view.z_ridge
    rhs = view.transform_T(view.W * C * r) - lam * view.z
    if len(ops) == 1 and hasattr(ops[0][0], "sparse_operator"):
        L = ops[0][0].sparse_operator(ops[0][1], view)
        A = (L.T @ sparse.diags(D.ravel()) @ L).tocsc()
        diag = A.diagonal()
        med = max(float(np.median(diag[diag > 0])) if (diag > 0).any() else 1.0, EPS)
        idx = np.flatnonzero(free & (diag > 1e-9 * med))
        if idx.size == 0:
            return dz
        Aff = A[idx][:, idx] + sparse.identity(idx.size, format="csc") * (1e-9 * med + lam)
        dz[idx] = spsolve(Aff.tocsc(), rhs[idx])
        return dz
    support = np.abs(view.transform_T(D))
    med = max(float(np.median(support[support > 0])) if (support > 0).any() else 1.0, EPS)
    idx = np.flatnonzero(free & (support > 1e-9 * med))
    if idx.size == 0:
        return dz
    ridge = Z_RIDGE * med + lam
    transfers = [e.transfer(st, view, 2 * T) if hasattr(e, "transfer") else None for e, st in ops]
    if all(h is not None for h in transfers):
        H2 = np.ones((view.E, T + 1))
        for h in transfers:
            H2 = H2 * np.abs(h) ** 2
        P = np.sum(D[:, idx].mean(axis=1)[:, None] * H2, axis=0) + ridge  # data density where z is free

        def precond(v):
            full = np.zeros(T)
            full[idx] = v
            return np.fft.irfft(np.fft.rfft(full, 2 * T) / P, 2 * T)[:T][idx]
    else:
        dj = support[idx] + ridge

        def precond(v):
            return v / dj

    def matvec(v):
        full = np.zeros(T)
        full[idx] = v
        return (view.transform_T(D * view.transform(full)) + ridge * full)[idx]

    n = idx.size
    A = LinearOperator((n, n), matvec=matvec, dtype=float)
    M = LinearOperator((n, n), matvec=precond, dtype=float)
    sol, _ = cg(A, rhs[idx], rtol=1e-3, maxiter=25, M=M)
    dz[idx] = sol
    return dz


class _PartialView(FitView):
    """A FitView whose states list holds only the effects initialised so far (used by ``init``)."""

    def __init__(self, view: FitView, states: list):
        n = len(states)
        sub = view.model._replace(view.effects[:n]) if n else view.model.without_effects()
        super().__init__(sub, view.Y0, view.W, view.s, view.free, view.kappa, view.z, list(states))
        self.full_model = view.model
        self.effects = tuple(view.effects[:n])


def _initial_z(Y: np.ndarray, obs: np.ndarray) -> np.ndarray:
    """Per-frame median over observed edges (§2.8 initialisation); 0 where nothing is observed."""
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        z = np.nanmedian(np.where(obs, Y, np.nan), axis=0)
    z = np.nan_to_num(z, nan=0.0)
    if np.abs(z).max(initial=0.0) <= 1e-9:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            z = np.nan_to_num(np.nanmean(np.where(obs, Y, np.nan), axis=0), nan=0.0)
    if np.abs(z).max(initial=0.0) <= 1e-9:
        z = np.ones_like(z)
    return z


def validate_inputs(Y, weights=None, root_distance=None, source: str = "response matrix"):
    """Check and normalise inputs: returns Y (E, T) float, W (E, T) >= 0 (0 where Y is NaN), s (E,)."""
    try:
        Y = np.array(Y, dtype=float)
    except (TypeError, ValueError):
        raise InputError(source, "Y must be a numeric (edges x frames) array") from None
    if Y.ndim != 2:
        raise InputError(source, f"Y must be 2-D (edges x frames), got shape {Y.shape}")
    E, T = Y.shape
    if E < 2 or T < 3:
        raise InputError(source, f"need at least 2 edges and 3 frames, got {E} x {T}")
    if np.isinf(Y).any():
        e, t = np.argwhere(np.isinf(Y))[0]
        raise InputError(source, "Y contains an infinite value", where=f"row {e}, column {t}")
    obs = np.isfinite(Y)
    if weights is None:
        W = obs.astype(float)
    else:
        W = np.array(weights, dtype=float)
        if W.shape != Y.shape:
            raise InputError(source, f"weights shape {W.shape} differs from Y shape {Y.shape}")
        bad = obs & ~(np.isfinite(W) & (W >= 0))
        if bad.any():
            e, t = np.argwhere(bad)[0]
            raise InputError(source, "weights must be finite and >= 0 where Y is observed",
                             where=f"row {e}, column {t}")
        W = np.where(obs, W, 0.0)
    empty = ~(W > 0).any(axis=1)
    if empty.any():
        raise InputError(source, "an edge has no observed (positively weighted) frame",
                         where=f"row {int(np.flatnonzero(empty)[0])}")
    if root_distance is None:
        s = np.linspace(0.0, 1.0, E) if E > 1 else np.zeros(1)
    else:
        s = np.array(root_distance, dtype=float).reshape(-1)
        if s.shape != (E,) or not np.isfinite(s).all():
            raise InputError(source, f"root_distance must be {E} finite numbers (one per row), got shape {s.shape}")
        top = s.max()
        s = s / top if top > 1.0 + 1e-9 else s
    return Y, W, s
