"""The effective sample of serially correlated residuals, and AIC / BIC on it.

Tracking drift and smoothing make the residuals' lag-1 autocorrelation rho ~ 0.9-0.97 on real and simulated
tracks, so the nominal number of observations over-states the information ~20-fold and any extra term "wins" a
nominal AIC. The diagnosis' AIC hurdle (:func:`~rce_gtsam.diagnosis.decision.earns_its_place`) and its likelihood-
ratio test use these instead.

Units: observations, frames; AIC/BIC unitless.
"""

from __future__ import annotations

import math

import numpy as np

from ..model import ModelFit


def effective_sample(fit: ModelFit) -> dict:
    """Effective number of independent observations of serially correlated residuals.

    Per edge, n_eff,e = n_e (1 - rho_e) / (1 + rho_e) with rho_e the lag-1 autocorrelation of the edge's
    residuals (clipped to [0, 0.98]): the variance of a mean of an AR(1) series equals that of n_eff
    independent samples. Tracking drift and smoothing make rho ~ 0.9 on real and simulated tracks, so the
    nominal n over-states the information ~20-fold and any extra term "wins" a nominal AIC. Returns
    {n, n_eff, factor = n_eff / n, t_eff = observed frames x factor, rho (pooled, n-weighted)}."""
    R = fit.residuals
    E, T = R.shape
    n_e = np.isfinite(R).sum(axis=1).astype(float)
    rho_e = np.zeros(E)
    for e in range(E):
        a, b = R[e, :-1], R[e, 1:]
        ok = np.isfinite(a) & np.isfinite(b)
        if ok.sum() >= 3:
            a, b = a[ok] - a[ok].mean(), b[ok] - b[ok].mean()
            rho_e[e] = float(np.sum(a * b) / max(math.sqrt(np.sum(a * a) * np.sum(b * b)), 1e-300))
    rho_e = np.clip(rho_e, 0.0, 0.98)
    n_eff = float(np.sum(n_e * (1 - rho_e) / (1 + rho_e)))
    n = float(n_e.sum())
    factor = n_eff / max(n, 1.0)
    t_obs = int((fit.weights > 0).any(axis=0).sum())
    return {"n": n, "n_eff": n_eff, "factor": factor, "t_eff": t_obs * factor,
            "rho": float(np.sum(n_e * rho_e) / max(n, 1.0)), "rho_per_edge": rho_e}


def effective_ic(fit: ModelFit, ess: dict) -> dict:
    """AIC / BIC on the effective sample: n_eff ln(WSSE / n) + penalty x k_eff.

    k_eff counts static parameters once and per-frame latent series (z, a second mode's w) as t_eff values
    each: a latent series estimated from serially correlated data has as many free values as there are
    independent frames. The same ``ess`` (from the baseline residuals) is used for every model compared."""
    E, T = fit.Y.shape
    t_obs = int((fit.weights > 0).any(axis=0).sum())
    k_static, n_lat = E - 1, 1  # kappa (one lost to the normalisation) and z
    for eff, st in zip(fit.model.effects, fit.states):
        nl = len(eff.latent_names())
        k_static += eff.n_free(st, E, t_obs) - nl * t_obs
        n_lat += nl
    k_eff = k_static + n_lat * ess["t_eff"]
    n_eff, n = max(ess["n_eff"], 1.0), max(ess["n"], 1.0)
    ll = n_eff * math.log(max(fit.wsse, 1e-300) / n)
    return {"aic": ll + 2 * k_eff, "bic": ll + math.log(n_eff) * k_eff, "k_eff": k_eff, "k_static": k_static,
            "free_series": n_lat - 1}
