"""Which κ to report after the diagnosis: the loop closes in one command.

Where the diagnosis names an effect, the rank-1 κ is fitted by a model the data reject: a lag, inertia or a
second excitation leaves part of each segment's response out of kappa_e z_t, and the rank-1 κ absorbs what it
can of it (a tip that lags reads as less compliant than it is). The extended model (rank-1 + the named effect)
then describes the branch, and its κ is the one to report. Without a verdict the rank-1 κ is reported.

:func:`kappa_after_verdict` fits the extended model's κ intervals from the diagnosis' own fit of the named
candidate (the same fit the held-out comparison scored) with the extended bootstrap
(:func:`rce_gtsam.extended_fit.bootstrap_extended`); ``rce run`` and ``rce batch`` put both κ side by side in
``compliance_summary.csv`` (with the extended κ's own quality, :func:`rce_gtsam.quality.assess_reported_quality`)
and say once in ``report.json`` and the printed report which one to read; the figures, overlays and the Rerun
recording draw it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .extended_fit import ExtendedFit, bootstrap_extended


@dataclass(frozen=True)
class KappaChoice:
    """The κ to report and why.

    effect: the named effect's candidate (e.g. ``"delay"``; None: the rank-1 κ is the one to report);
    model: the model that κ comes from ("rank-1" or "rank-1 + delay"); reason: one sentence;
    kappa, ci_low, ci_high: (E,) the extended model's κ and its 95 % interval (relative, geometric mean 1;
    None without an effect); edges: the response rows' (joint, child) edges; prediction: (E, T) the extended
    model's prediction of the bending (deg; its R^2 judges ``poor_fit`` of that κ,
    :func:`rce_gtsam.quality.assess_reported_quality`)."""

    effect: str | None
    model: str
    reason: str
    edges: tuple = ()
    kappa: np.ndarray | None = None
    ci_low: np.ndarray | None = None
    ci_high: np.ndarray | None = None
    prediction: np.ndarray | None = None

    @property
    def column(self) -> str:
        """The compliance_summary.csv column to read: ``kappa`` (rank-1) or ``kappa_<effect>``."""
        return "kappa" if self.effect is None else f"kappa_{self.effect}"

    @property
    def fitted(self) -> bool:
        """Whether an effect is named and its model's κ was fitted (the ``kappa_<effect>`` columns hold it)."""
        return self.effect is not None and self.kappa is not None

    def aligned(self, edges) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(kappa, ci_low, ci_high) of the extended model in the order of ``edges`` ((joint, child) pairs), NaN for an
        edge it has no row for (the root edge, a segment dropped with a lost node) or without intervals."""
        at = {tuple(e): i for i, e in enumerate(self.edges)}
        idx = [at.get((int(p), int(c))) for p, c in edges]

        def pick(a):
            return np.array([np.nan if i is None or a is None else float(a[i]) for i in idx])
        return pick(self.kappa), pick(self.ci_low), pick(self.ci_high)

    def as_dict(self) -> dict:
        out = {"model": self.model, "column": self.column, "reason": self.reason, "effect": self.effect}
        if self.kappa is not None:
            out["kappa"] = {f"{p}->{c}": float(k) for (p, c), k in zip(self.edges, self.kappa)}
        return out

    def line(self) -> str:
        """The printed line: which κ to report, and why."""
        return f"kappa to report: {self.column} ({self.model}). {self.reason}"


def kappa_after_verdict(result, diagnosis) -> KappaChoice:
    """The κ to report after ``diagnosis`` (:class:`~rce_gtsam.diagnosis.result.Diagnosis`) of an analysis
    ``result`` (:class:`~rce_gtsam.pipeline.AnalysisResult`, rank-1). With a verdict, the named candidate's fit
    gets bootstrap intervals under the analysis preset's bootstrap settings (none where the preset runs none)."""
    cand = diagnosis.verdict_candidate
    if cand is None:
        why = ("No effect is named, so the rank-1 model is the description the data support"
               + ("" if diagnosis.status != "misses" else
                  "; the diagnosis found more than noise left over that no effect in the library explains, so "
                  "read kappa as the best one-excitation summary, not a full description") + ".")
        return KappaChoice(effect=None, model="rank-1", reason=why)
    if not cand.heldout_rmse < diagnosis.baseline_heldout_rmse:
        # named from a channel of its own (the segments' lengths), its term predicting the bending no better held
        # out: the extended kappa would be the rank-1 kappa under another name (bend-residual candidates are never
        # named without a lower held-out error)
        why = (f"The diagnosis names {diagnosis.verdict}, but the model with it predicts the bending no better held "
               f"out ({diagnosis.baseline_heldout_rmse:.3g} -> {cand.heldout_rmse:.3g} deg RMSE), so the rank-1 "
               f"kappa is reported; it describes the bending as the camera sees it, and what {diagnosis.verdict} "
               f"adds to it is not measured from these tracks.")
        return KappaChoice(effect=None, model="rank-1", reason=why)
    fit = ExtendedFit(model_fit=cand.fit, baseline_rmse_deg=float(diagnosis.baseline.rmse))
    ci, _ = bootstrap_extended(fit, result.preset.compliance)
    name = cand.effect
    why = (f"The diagnosis names {diagnosis.verdict}: the rank-1 model leaves part of each segment's response out "
           f"of kappa_e z_t and its kappa absorbs it, so report kappa of the model with {name} "
           f"(held-out RMSE {diagnosis.baseline_heldout_rmse:.3g} -> {cand.heldout_rmse:.3g} deg).")
    return KappaChoice(effect=name, model=f"rank-1 + {name}", reason=why, edges=tuple(result.response.edges),
                       kappa=np.asarray(fit.kappa, float),
                       ci_low=None if ci is None else np.asarray(ci.low, float),
                       ci_high=None if ci is None else np.asarray(ci.high, float),
                       prediction=np.asarray(fit.predict(), float))


def add_to_summary(df, choice: KappaChoice, quality: dict | None = None):
    """``compliance_summary`` with the extended model's κ columns (``kappa_<effect>``, ``..._ci_low``,
    ``..._ci_high``, ``..._quality``: :func:`rce_gtsam.quality.assess_reported_quality`) beside the rank-1
    ``kappa`` and a ``report`` column naming the κ column to read. ``quality``: {edge: quality string} of the
    extended κ (None: the quality column is left out)."""
    df = df.copy()
    if choice.kappa is not None:
        col = choice.column
        at = list(df.columns).index("kappa_ci_high") + 1 if "kappa_ci_high" in df.columns else len(df.columns)
        values = choice.aligned(zip(df["parent"], df["child"]))
        for j, (name, v) in enumerate(zip((col, f"{col}_ci_low", f"{col}_ci_high"), values)):
            df.insert(at + j, name, v)
        if quality is not None:
            # a segment without a bend row (the root edge, one dropped with a lost node) keeps its rank-1 word
            df.insert(at + 3, f"{col}_quality", [quality.get((int(p), int(c)), q) for p, c, q in
                                                 zip(df["parent"], df["child"], df["quality"])])
    df["report"] = choice.column
    return df
