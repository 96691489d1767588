"""lmfit-style text report of one fitted response model."""

from __future__ import annotations

import numpy as np


def render_fit_report(fit: "ModelFit", edge_labels=None, max_rows: int = 40) -> str:
    """lmfit-style report of one fit: model, statistics, variables with standard errors."""
    E = len(fit.kappa)
    labels = list(edge_labels) if edge_labels is not None else [str(i) for i in range(E)]
    out = ["[[Model]]", f"    {fit.model.name}"]
    for eff in fit.model.effects:
        out.append(f"    {eff.name}: {eff.equation}")
    out += ["[[Fit Statistics]]",
            f"    # iterations       = {fit.iterations} ({'converged' if fit.converged else 'NOT converged'})",
            f"    # data points      = {fit.n_obs}",
            f"    # variables        = {_count(fit.n_params)}",
            f"    weighted SSE       = {fit.wsse:.6g}",
            f"    RMSE               = {fit.rmse:.4f} deg",
            f"    R-squared          = {fit.r_squared:.4f}",
            f"    Akaike info crit   = {fit.aic:.2f}",
            f"    Bayesian info crit = {fit.bic:.2f}",
            f"    residual lag-1 autocorrelation = {fit.residual_autocorrelation():.3f}",
            "[[Variables]]  (standard errors conditional on z, inflated for residual autocorrelation)"]
    rows = []
    for key, pv in fit.params.items():
        name = key
        if key.startswith("kappa["):
            i = int(key[6:-1])
            name = f"kappa[{labels[i]}]"
        elif key.endswith("]"):
            base, idx = key[:-1].split("[")
            name = f"{base}[{labels[int(idx)]}]"
        pct = f" ({100 * pv.stderr / abs(pv.value):.1f}%)" if pv.value and np.isfinite(pv.stderr) else ""
        rows.append(f"    {name:<28} {pv.value: .5g} +/- {pv.stderr:.2g} {unit_text(key, pv.unit)}{pct}")
    eff_rows = [r for r in rows if not r.strip().startswith("kappa")]
    k_rows = [r for r in rows if r.strip().startswith("kappa")]
    shown = eff_rows[:max_rows] + k_rows[:max_rows]
    out += shown
    if len(eff_rows) + len(k_rows) > len(shown):
        out.append(f"    ... ({len(eff_rows) + len(k_rows) - len(shown)} more)")
    for eff, st in zip(fit.model.effects, fit.states):
        for k_, v in eff.describe(st).items():
            out.append(f"    {eff.name}.{k_:<20} = {v:.4g}")
    return "\n".join(out)


def unit_text(key: str, unit: str) -> str:
    """A parameter's unit as the report shows it: kappa is "(relative)" (a ratio to the branch's geometric mean,
    which is 1), another unit-free number "(dimensionless)"; a physical unit as it is (frames, deg, ...)."""
    if unit in ("1", "", None):
        return "(relative)" if key.startswith("kappa[") else "(dimensionless)"
    return unit


def _count(k) -> str:
    """A parameter count as read: an integer as such, a fractional effective count (shrunk estimates, e.g. the
    offset's) to one decimal, marked effective."""
    k = float(k)
    return f"{k:.0f}" if k.is_integer() else f"{k:.1f} (effective: shrunk estimates count by their shrinkage)"
