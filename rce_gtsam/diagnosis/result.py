"""The diagnosis' typed results: what the tests found (:class:`TestResult`), each candidate's numbers
(:class:`CandidateResult`) and the whole diagnosis (:class:`Diagnosis`), with the few readings of a candidate that
the decision and the report share (:func:`finding_of`, :func:`effect_kind`, :func:`complexity`,
:func:`score_is_significant`).

Everything that needs only these types imports this module, never :mod:`rce_gtsam.diagnosis.diagnose`. It computes
no statistic and decides nothing.

Units: degrees (RMSE), deg^2 (fold MSE), frames; p and t unitless.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

import numpy as np

from ..jsonutil import jsonable
from ..model import ModelFit
from .budget import VarianceBudget
from .noise_floor import NoiseFloor
from .sysid import ResidualAnalysis


@dataclass(frozen=True)
class TestResult:
    """One test of one candidate, in the shape every test of the diagnosis reports.

    name: the test ("fold_t", "score", "heldout_null", "shared_course", "shared_course_away_from_gaps",
    "drift_pattern", "implausibility", "maxt", "encompassing[<simpler>]"); statistic: its value (a t, a score, a
    count of reasons); p: its p-value where its null gives one, else None; threshold: the level p is compared with
    (p <= threshold), or with p None the value the statistic must exceed; null: one sentence naming how the null
    was calibrated; calibration: the benchmark or validation record that measured its false-alarm rate."""

    __test__ = False  # not a pytest class

    name: str
    statistic: float
    p: float | None
    threshold: float
    null: str
    calibration: str

    @property
    def fires(self) -> bool:
        """The test's alternative holds at its threshold: p <= threshold, or (p None) a finite statistic above it."""
        if self.p is not None:
            return bool(self.p <= self.threshold)
        return bool(math.isfinite(self.statistic) and self.statistic > self.threshold)

    def as_dict(self) -> dict:
        return {"name": self.name, "statistic": num(self.statistic), "p": num(self.p),
                "threshold": num(self.threshold), "fires": self.fires, "null": self.null,
                "calibration": self.calibration}


@dataclass(frozen=True, eq=False)
class CandidateResult:
    """One candidate effect: its fit on all frames, held-out error and evidence."""

    effect: str
    fit: ModelFit
    heldout_rmse: float
    fold_mse: np.ndarray
    evidence: float
    improvement_pct: float
    delta_aic: float
    delta_bic: float
    supported: bool
    statistics: dict
    extra: dict = field(default_factory=dict)  # effective-sample IC terms, likelihood-ratio test
    #: the fit of the same model with the lowest in-sample error among its starts (the maximum-likelihood fit;
    #: None: ``fit`` is that one): the encompassing test between two forms of one lag also tries it
    #: (:func:`~rce_gtsam.diagnosis.evidence.form_test`)
    ml_fit: ModelFit | None = None
    #: every test run on this candidate, by :attr:`TestResult.name`, in the common shape
    tests: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        return {**jsonable(self.extra), "effect": self.effect, "heldout_rmse": num(self.heldout_rmse),
                "evidence": num(self.evidence),
                "improvement_pct": num(self.improvement_pct), "delta_aic": num(self.delta_aic),
                "delta_bic": num(self.delta_bic), "supported": bool(self.supported),
                "fit_rmse": num(self.fit.rmse), "n_params": count(self.fit.n_params),
                "fold_mse": [num(v) for v in self.fold_mse], "statistics": jsonable(self.statistics),
                "params": jsonable(self.fit.effect_summary().get(self.effect, {})),
                "kappa": [num(v) for v in self.fit.kappa], "converged": bool(self.fit.converged)}


@dataclass(frozen=True, eq=False)
class Diagnosis:
    """Result of :func:`~rce_gtsam.diagnosis.diagnose.diagnose`. ``as_dict()`` is the JSON written by
    ``rce diagnose``; ``report()`` the text report."""

    baseline: ModelFit
    baseline_heldout_rmse: float
    baseline_fold_mse: np.ndarray
    candidates: list  # of CandidateResult, best (lowest held-out RMSE) first
    verdict: str | None
    explanation: str
    worst_edges: list
    worst_frames: list
    residual_summary: dict
    settings: dict
    edge_labels: list = field(default_factory=list)
    baseline_frame_loss: np.ndarray | None = None  # (T,) held-out MSE per frame of the rank-1 model (deg^2)
    baseline_heldout_prediction: np.ndarray | None = None  # (E, T) the rank-1 model's held-out prediction (deg)
    residual_analysis: ResidualAnalysis | None = None  # system-identification views of the baseline residuals
    budget: VarianceBudget | None = None  # variance budget against the model-free noise floor
    noise_floor: NoiseFloor | None = None
    #: the candidate the verdict comes from, where it is another form of the effect ``verdict`` names
    #: (:attr:`~rce_gtsam.effects.Effect.finding`: "resonances" for the finding "dynamics"); else ``verdict``
    verdict_effect: str | None = None
    #: the analysis' settings under which the diagnosis is not calibrated (rce_gtsam.diagnosis.domain): no
    #: effect is named where there are any
    outside_domain: tuple = ()
    #: the text report (:func:`~rce_gtsam.diagnosis.explain.render_diagnosis_report`), written by the report step;
    #: a copy changed with ``dataclasses.replace`` keeps it (render it again from the copy)
    report_text: str = ""

    @property
    def status(self) -> str:
        """``"effect"`` (a candidate explains the misfit), ``"adequate"`` (what the rank-1 model leaves is
        consistent with the noise floor), ``"misses"`` (significantly more than noise is left and no candidate
        explains it), ``"inconclusive"`` (the noise floor is only bounded and the bounds straddle the
        residual, or the record is too short to exclude a miss as large as the noise floor:
        ``budget.reason``), ``"untested"`` (no noise floor was given: held-out comparison only), or
        ``"uncalibrated"`` (the analysis' settings lie outside the domain the tests are calibrated on,
        :attr:`outside_domain`: nothing is named)."""
        if self.outside_domain:
            return "uncalibrated"
        if self.verdict is not None:
            return "effect"
        if self.budget is None:
            return "untested"
        return {"noise": "adequate", "misses": "misses", "inconclusive": "inconclusive"}[self.budget.status]

    @property
    def verdict_candidate(self) -> CandidateResult | None:
        """The candidate the verdict comes from (None without a verdict)."""
        return None if self.verdict is None else self.candidate(self.verdict_effect or self.verdict)

    def candidate(self, name: str) -> CandidateResult:
        for c in self.candidates:
            if c.effect == name:
                return c
        raise KeyError(name)

    def as_dict(self) -> dict:
        b = self.baseline
        return {
            "baseline": {"heldout_rmse": num(self.baseline_heldout_rmse), "fit_rmse": num(b.rmse),
                         "aic": num(b.aic), "bic": num(b.bic), "r_squared": num(b.r_squared),
                         "n_params": int(b.n_params), "n_obs": int(b.n_obs),
                         "fold_mse": [num(v) for v in self.baseline_fold_mse],
                         "kappa": [num(v) for v in b.kappa], "converged": bool(b.converged)},
            "candidates": [c.as_dict() for c in self.candidates],
            "verdict": self.verdict,
            "verdict_effect": self.verdict_effect or self.verdict,
            "explanation": self.explanation,
            "worst_edges": jsonable(self.worst_edges),
            "worst_frames": jsonable(self.worst_frames),
            "residuals": jsonable(self.residual_summary),
            "edges": [str(e) for e in self.edge_labels],
            "settings": jsonable(self.settings),
            "status": self.status,
            "budget": jsonable(self.budget.as_dict()) if self.budget is not None else None,
            "budget_per_segment": jsonable(self.budget.per_segment) if self.budget is not None else None,
            "noise_floor": jsonable(self.noise_floor.as_dict()) if self.noise_floor is not None else None,
            "residual_analysis": (jsonable(self.residual_analysis.as_dict())
                                  if self.residual_analysis is not None else None),
        }

    def to_json(self, **kw) -> str:
        return json.dumps(self.as_dict(), **kw)

    def report(self) -> str:
        """The readable text report (made by the diagnosis' report step)."""
        return self.report_text


def count(k):
    """A parameter count for the JSON: an int, or the float effective count of shrunk estimates (the offset's)
    rather than that count truncated."""
    k = float(k)
    return int(k) if k.is_integer() else round(k, 2)


def num(x):
    """A float for the JSON; None for what is not a finite number."""
    try:
        x = float(x)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


# ----------------------------------------------------------------------------------------------------------
# Readings of a candidate the decision and the report share
# ----------------------------------------------------------------------------------------------------------

def candidate_effect(c):
    """The :class:`~rce_gtsam.effects.Effect` instance of candidate ``c`` in its fitted model, or None when it has
    no fit."""
    model = getattr(getattr(c, "fit", None), "model", None)
    return next((e for e in getattr(model, "effects", ()) if e.name == c.effect), None)


def effect_kind(c) -> str | None:
    """The kind of a candidate's effect ("operator", "output", "additive"), or None when it has no fit."""
    return getattr(candidate_effect(c), "kind", None)


def finding_of(c) -> str:
    """What a verdict for candidate ``c`` reports: its effect's :attr:`~rce_gtsam.effects.Effect.finding` where the
    effect is another form of a library effect, else its own name."""
    eff = candidate_effect(c)
    return c.effect if eff is None else eff.verdict_name


def complexity(c) -> tuple[int, float]:
    """The parsimony order of a candidate: (free per-frame series besides z, effective parameters).

    A free per-frame series (the second mode's w_t) comes first: it can take any time course, so it mimics the
    per-frame term of every other effect to first order (w = t is a linear creep, w = z^3 a saturation's
    leading term, w = dz/dt a short lag) and is more flexible than any set of static parameters, whatever
    its effective count (which on smooth, strongly autocorrelated residuals falls to a few values per series:
    a creep's 2 x E offsets then "cost" more than the free series that imitates them; noise-free simulated
    creep: second mode 52.8 against offset 61.9 effective parameters, the second mode named)."""
    return int(c.extra.get("free_series", 0)), float(c.extra.get("k_eff", math.inf))


def score_is_significant(score_p: float | None, score_threshold_p: float) -> bool:
    """A full-data score test's p at or below its threshold (False for an effect without one, ``score_p`` None)."""
    return score_p is not None and score_p <= score_threshold_p
