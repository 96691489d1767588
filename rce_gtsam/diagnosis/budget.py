"""Variance budget: how much of the bending does each part of the model explain, and what is left?

Over the scored segment-frames (finite entries of Y, degrees^2):

    total = mean(Y^2)                                   (Y is the deviation from the rest angle)
    rank1 = total - mean(R0^2) / (1 - p0 / n)           (R0: rank-1 residual; p0 = E - 1 + T fitted values)
    effect = mean(R0^2) / (1 - p0 / n) - mean(R1^2) / (1 - p1 / n)   (R1: residual with the effect added)
    noise_floor = mean over rows of the model-free noise estimate (:mod:`.noise_floor`)
    unexplained = mean(R_final^2) / (1 - p / n) - noise_floor

The (1 - p / n) factor undoes the in-sample shrinkage of a residual by the p values fitted to it, so a model
that fits pure noise leaves ``unexplained`` near 0, not below it. ``unexplained`` is *consistent with zero*
when it is within ``z_crit`` standard errors. The SE combines the sampling error of the residual variance
(effective samples of autocorrelated residuals), the noise floor's own sampling error, and the floor's
*accuracy* (:data:`FLOOR_REL_SD`): without that last term, effect-free simulated branches were told the
model "misses" more than noise on 3 of 30 (their floor was 0.70-0.73 of the true noise variance).

The model is called adequate (status ``"noise"``) only when the data could also have *seen* a miss: at
``z_crit`` SE the unexplained part is at most the noise floor itself (the model leaves at most twice the
noise variance, sqrt(2) x its RMS). A record too short to show that is ``"inconclusive"`` (reason
``"too_uncertain"``) rather than adequate: 120 frames of plant 1 read "adequate" with the unexplained share
62 +/- 43 %. A residual below :data:`~.settings.RESOLUTION` of the total (noise-free tracks) is adequate
whatever its SE. Where the noise floor is only a lower bound (rows where segments stretch with the motion,
see :class:`~.noise_floor.NoiseFloor`), the budget also gives the range the unexplained part lies in, and
is inconclusive (reason ``"floor_bounded"``) where that range straddles zero.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .noise_floor import NoiseFloor, effective_samples
from .settings import RESOLUTION

#: Relative accuracy (1 SD, as a share of its variance) of the model-free noise floor, carried into the budget's
#: SE as a systematic term. Measured by ``benchmarks/bench_noise_floor.py`` on 20 effect-free simulated
#: branches with white noise, drift and along/across ratio varied over seeds: floor / true angle-noise variance
#: median 0.955, RMS relative error 0.094 (0.85 and 0.195 before the node-wise estimate raised it, 0.947 and 0.099
#: before its kappa-step correction); under the tracker-artifact families the floor's RMS reads a median 0.84-1.13 of
#: the truth per family and size (``benchmarks/bench_artifacts.py``), so the
#: term keeps 0.2: this is the accuracy the floor has shown, not a bound.
FLOOR_REL_SD = 0.2


@dataclass(frozen=True)
class VarianceBudget:
    """Variance budget in deg^2 over the scored segment-frames (see module docstring).

    total, rank1, noise_floor, unexplained: deg^2; effects: {effect name: deg^2 explained beyond rank-1};
    unexplained_se: standard error of ``unexplained``; unexplained_range: (low, high) deg^2 — low uses the
    noise ceiling (the inextensibility estimate capped at each row's bending) where the floor is only a lower
    bound, high the floor as used; per_segment: list of dicts with the same keys per row; status: ``"noise"``
    (unexplained consistent with zero, and at most the noise floor at ``z_crit`` SE), ``"misses"``
    (significantly above zero), ``"inconclusive"``; reason: why it is inconclusive — ``"floor_bounded"`` (the
    range straddles zero because the noise floor is only bounded on some rows) or ``"too_uncertain"``
    (consistent with zero, but the record cannot exclude a miss as large as the noise floor); None otherwise;
    floor_is_bound: rows whose floor is a lower bound.
    """

    total: float
    rank1: float
    effects: dict
    noise_floor: float
    unexplained: float
    unexplained_se: float
    unexplained_range: tuple
    status: str
    per_segment: list = field(default_factory=list)
    floor_is_bound: list = field(default_factory=list)
    reason: str | None = None
    z_crit: float = 2.0

    @property
    def upper(self) -> float:
        """The largest unexplained variance the record allows at ``z_crit`` SE (deg^2): the bound the status
        rule compares with the noise floor."""
        return self.unexplained + self.z_crit * self.unexplained_se

    def share(self, part: float) -> float:
        """``part`` as a fraction of the total variance."""
        return float(part / self.total) if self.total > 0 else float("nan")

    def as_dict(self) -> dict:
        return {"total": self.total, "rank1": self.rank1, "effects": dict(self.effects),
                "noise_floor": self.noise_floor, "unexplained": self.unexplained,
                "unexplained_se": self.unexplained_se, "unexplained_range": list(self.unexplained_range),
                "status": self.status, "reason": self.reason, "floor_rel_sd": FLOOR_REL_SD,
                "units": "deg^2 (mean over scored segment-frames)"}


def _corrected_ms(R: np.ndarray, p: float, leverage: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """Per-row and overall mean square of R, divided by (1 - p / n) for p fitted values. With ``leverage``
    (E,) — each row's share of the per-frame latent's fit, e.g. kappa_e^2 / sum kappa^2 — rows are corrected
    by (1 - leverage_e - (E - 1) / n) instead: a row that dominates z's estimate keeps less of its noise."""
    ok = np.isfinite(R)
    n = max(int(ok.sum()), 1)
    c = 1.0 / max(1.0 - p / n, 0.05)
    with np.errstate(invalid="ignore"):
        ms = np.nanmean(np.where(ok, R * R, np.nan), axis=1)
    if leverage is None:
        return ms * c, float(np.sum(R[ok] ** 2) / n * c)
    T = R.shape[1]
    rows = ms / np.maximum(1.0 - np.asarray(leverage) - 1.0 / max(T, 1), 0.05)
    n_e = ok.sum(axis=1)
    return rows, float(np.sum(n_e * np.nan_to_num(rows)) / n)


def variance_budget(Y: np.ndarray, base_residuals: np.ndarray, base_params: int, noise: NoiseFloor,
                    effects: dict | None = None, labels=None, z_crit: float = 2.0,
                    base_kappa: np.ndarray | None = None, floor_rel_sd: float = FLOOR_REL_SD) -> VarianceBudget:
    """Variance budget of a rank-1 fit (and optionally added effects) against a model-free noise floor.

    Y: (E, T) response (deg); base_residuals: (E, T) rank-1 residuals; base_params: the rank-1 fit's number of
    fitted values (E - 1 + frames); noise: the rows' :class:`~.noise_floor.NoiseFloor`; effects: {name:
    (residuals (E, T) of the model with that effect added, its number of fitted values)} — applied in the
    given order as a chain of extensions is not assumed: each is compared with the rank-1 fit, and the final
    residual is that of the last one; labels: row names; z_crit: standard errors for "consistent with zero";
    base_kappa: (E,) the rank-1 kappa, for per-row degrees-of-freedom corrections (leverage kappa_e^2 / sum);
    floor_rel_sd: the noise floor's relative accuracy (1 SD of its variance), a systematic term of the SE.
    """
    effects = effects or {}
    ok = np.isfinite(Y)
    n_e = ok.sum(axis=1)
    with np.errstate(invalid="ignore"):
        tot_rows = np.nanmean(np.where(ok, Y * Y, np.nan), axis=1)
    total = float(np.sum(Y[ok] ** 2) / max(ok.sum(), 1))
    lev = None
    if base_kappa is not None:
        k2 = np.asarray(base_kappa, float) ** 2
        lev = k2 / max(float(k2.sum()), 1e-300)
    base_rows, base_ms = _corrected_ms(base_residuals, base_params, lev)
    eff_out, final_rows, final_ms, final_R = {}, base_rows, base_ms, base_residuals
    eff_rows = {}
    for name, (R, p) in effects.items():
        rows, ms = _corrected_ms(R, p)
        eff_out[name] = base_ms - ms
        eff_rows[name] = base_rows - rows
        final_rows, final_ms, final_R = rows, ms, R
    w = n_e / max(n_e.sum(), 1)  # rows weigh by their scored frames, as the overall means do
    tot_rows = np.where(np.isfinite(tot_rows), tot_rows, 0.0)
    ess_r = np.array([max(effective_samples(final_R[e]), 1.0) for e in range(len(Y))])
    # noise cannot exceed what any unbiased fit leaves: a row whose inextensibility estimate exceeds its
    # (df-corrected) rank-1 residual by more than the two estimates' sampling error allows has segments that
    # stretch by more than tracking noise (out-of-plane swing, a tracker sliding with the motion); there the
    # floor falls back to the white-noise lower bound and the residual is the ceiling
    se_row = np.sqrt(2.0 / ess_r) + np.sqrt(2.0 / np.maximum(noise.n_eff, 1.0))
    inext = np.nan_to_num(noise.inextensible_deg2, nan=np.inf)
    valid = noise.valid & (inext <= base_rows * (1.0 + z_crit * se_row))
    floor_rows = np.where(valid, inext, noise.white_deg2)
    if noise.nodewise_deg2 is not None:  # the tracker's node-wise signature in the residual (noise_floor_nodewise),
        # one node-error size for the branch: on a row it cannot exceed what the rank-1 fit leaves there
        floor_rows = np.fmax(floor_rows, np.minimum(noise.nodewise_deg2, base_rows))
    floor_rows = np.minimum(floor_rows, tot_rows)
    ceil_rows = np.where(valid, floor_rows, np.minimum(np.minimum(inext, base_rows), tot_rows))
    floor = float(np.sum(w * floor_rows))
    ceiling = float(np.sum(w * np.maximum(ceil_rows, floor_rows)))
    unexplained = final_ms - floor
    # standard error: residual mean square from effective samples per row; floor from its own n_eff
    se_res = math.sqrt(float(np.sum((w * final_rows) ** 2 * 2.0 / ess_r)))
    se_floor = math.sqrt(float(np.sum((w * floor_rows) ** 2 * 2.0 / np.maximum(noise.n_eff, 1.0))))
    se = math.hypot(math.hypot(se_res, se_floor), floor_rel_sd * floor)
    low = final_ms - ceiling
    reason = None
    if final_ms <= RESOLUTION * total:  # nothing left worth a word (noise-free tracks)
        status = "noise"
    elif unexplained <= z_crit * se:
        upper = unexplained + z_crit * se  # VarianceBudget.upper
        status, reason = ("noise", None) if upper <= floor else ("inconclusive", "too_uncertain")
    elif low > z_crit * se:
        status = "misses"
    else:
        status, reason = "inconclusive", "floor_bounded"
    per = []
    labels = list(labels) if labels is not None else [str(i) for i in range(len(Y))]
    for e in range(len(Y)):
        se_e = math.sqrt(2.0 * final_rows[e] ** 2 / ess_r[e] + 2.0 * floor_rows[e] ** 2 / max(noise.n_eff[e], 1.0)
                         + (floor_rel_sd * floor_rows[e]) ** 2)
        per.append({"segment": str(labels[e]), "total": _f(tot_rows[e]), "rank1": _f(tot_rows[e] - base_rows[e]),
                    "effects": {k: _f(v[e]) for k, v in eff_rows.items()}, "noise_floor": _f(floor_rows[e]),
                    "noise_floor_is_lower_bound": bool(not valid[e]),
                    "unexplained": _f(final_rows[e] - floor_rows[e]), "unexplained_se": _f(se_e),
                    "r_squared": _f(1.0 - base_rows[e] / tot_rows[e]) if tot_rows[e] > 0 else None})
    return VarianceBudget(total=total, rank1=total - base_ms, effects=eff_out, noise_floor=floor,
                          unexplained=unexplained, unexplained_se=se, unexplained_range=(low, unexplained),
                          status=status, reason=reason, z_crit=z_crit, per_segment=per,
                          floor_is_bound=[str(labels[e]) for e in range(len(Y)) if not valid[e]])


def _f(x):
    x = float(x)
    return x if math.isfinite(x) else None


def budget_of(result, z_crit: float = 2.0) -> VarianceBudget:
    """The rank-1 variance budget of an :class:`~rce_gtsam.pipeline.AnalysisResult` (no effect added): its
    response against its model-free noise floor (:func:`~.noise_floor.noise_floor_of`)."""
    from ..model import ResponseModel  # the engine, imported where used: model imports nothing from here
    from .noise_floor import noise_floor_of

    r, cfg = result.response, result.preset.compliance
    fit = ResponseModel(config=cfg).fit(r.Y, weights=r.weights if cfg.weighted else None,
                                        root_distance=r.root_distance)
    return variance_budget(r.Y, fit.residuals, fit.n_params, noise_floor_of(result),
                           labels=r.edge_labels, z_crit=z_crit, base_kappa=fit.kappa)
