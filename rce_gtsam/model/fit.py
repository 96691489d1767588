"""The result of fitting a :class:`~rce_gtsam.model.ResponseModel`: values, parameters with standard errors,
information criteria and a report. Units: degrees, frames."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .compliance import Rank1Fit
from .report import render_fit_report
from .view import FitView


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
    root_distance: (E,); iterations, converged: loop diagnostics; n_obs: observed entries;
    shrinkage: (E,) the factor s of the last kappa step, log|kappa| = s log|kappa_hat| (1 = not shrunk);
    core: the rank-1 solver's own result (:class:`~rce_gtsam.model.compliance.Rank1Fit`: frames used, shrinkage,
    convergence) when the model has no effects and was fitted on all frames from scratch — the fit
    ``rce analyze`` reports; None otherwise.
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
    shrinkage: np.ndarray | None = None
    core: Rank1Fit | None = None
    _cache: dict = field(default_factory=dict, repr=False)

    # -- core quantities -----------------------------------------------------------------------------
    def view(self, model=None, states=None) -> FitView:
        """A :class:`FitView` of the fitted data and values (of ``model`` with ``states`` when given)."""
        Y0 = np.where(np.isfinite(self.Y), self.Y, 0.0)
        return FitView(self.model if model is None else model, Y0, self.weights, self.root_distance,
                       np.ones(self.Y.shape[1], bool), self.kappa, self.z,
                       list(self.states if states is None else states))

    def heldout_z_precision(self, frames=None) -> float:
        """The precision of a zero-mean Gaussian prior on z for estimating it on new frames, in weighted-SSE units:
        (this fit's mean weighted squared residual) / (mean z^2 over ``frames``, a (T,) bool mask; default all),
        0 when that z is all zero. With it the z step is a posterior mean: frames few observations determine
        (seen through a long lag, or by few rows) stay near zero instead of following noise."""
        z = self.z if frames is None else self.z[np.asarray(frames, bool)]
        z_var = float(np.mean(z ** 2)) if z.size else 0.0
        return (self.wsse / max(self.n_obs, 1)) / z_var if z_var > 0 else 0.0

    def warm_start(self) -> tuple:
        """(kappa, z, {effect name: state}) copies: the ``start`` of a refit from this fit
        (:meth:`rce_gtsam.model.ResponseModel.solve`)."""
        return (self.kappa.copy(), self.z.copy(),
                {eff.name: st for eff, st in zip(self.model.effects, self.states)})

    def predict(self) -> np.ndarray:
        """(E, T) fitted response in degrees (defined at missing entries too)."""
        if "pred" not in self._cache:
            self._cache["pred"] = self.view().predict()
        return self._cache["pred"]

    def components(self) -> dict[str, np.ndarray]:
        """Each effect's share of the prediction: prediction minus the prediction without that effect."""
        full = self.predict()
        out = {"core": self.predict_with(())}
        for i, eff in enumerate(self.model.effects):
            out[eff.name] = full - self.predict_with(tuple(j for j in range(len(self.model.effects)) if j != i))
        return out

    def predict_with(self, keep: tuple[int, ...]) -> np.ndarray:
        """(E, T) prediction in degrees using only the effects with indices ``keep`` (fitted kappa, z)."""
        sub = self.model.with_effects(tuple(self.model.effects[i] for i in keep))
        return self.view(sub, [self.states[i] for i in keep]).predict()

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
        view = self.view()
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
        return render_fit_report(self, edge_labels=edge_labels, max_rows=max_rows)
