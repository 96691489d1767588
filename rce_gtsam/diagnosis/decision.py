"""THE decision of the diagnosis: which candidate effects are significant, which are supported, and the verdict.

The rule, at a family-wise level alpha (0.05) shared by the n findings the candidates can name (two forms of one
effect share one share), with the folds' t quantiles on (folds - 1) dof (:func:`levels`):

* **significant** = the held-out fold t > t(1 - alpha / n); for an effect with a full-data score test both tests
  run at half that share: fold t > t(1 - alpha / 2n), or score p <= alpha / 2n with fold t > t(1 - alpha), or > 0
  beside a test calibrated on the tracker-artifact bed (:data:`ARTIFACT_CALIBRATED`) (:func:`is_significant`); an
  effect that declares ``needs_both_tests`` (a saturation) needs both at once. An effect of slow per-segment
  courses (offset/creep), which tracker drift mimics, is significant only if, besides its fold t, the data show
  what drift cannot: held-out null p <= alpha, or a course shared by two node-disjoint row sets (p <= alpha / 2n,
  also away from the frames nodes were lost in), or trends laid out otherwise than a node's drift (p <= alpha)
  (:func:`drift_rescued`).
* **supported** = significant AND a plausible fit AND a lower held-out RMSE AND a lower AIC on the effective
  sample (waived when the score test is significant) AND at least ``resolution`` of the bending variance off
  the held-out error (:func:`earns_its_place`). Also supported: the richer form of a supported lag (same kind,
  more complex, earning its place with the AIC waived) whose encompassing test against it has p <= alpha / 2n
  (:func:`support_richer_forms`).
* **verdict** = the supported candidate that leads (lowest held-out RMSE; a richer form of the same lag that
  predicts what it leaves takes its place), unless a simpler supported candidate is not significantly worse
  (encompassing p > alpha / 2n where that test ran, else fold-paired t <= t(1 - alpha / n)): then the simplest
  such (:func:`~rce_gtsam.diagnosis.verdict.choose_verdict`). None when nothing is supported, and nothing is
  named outside the domain the tests are calibrated on (:mod:`rce_gtsam.diagnosis.domain`).
* An effect read from another channel than the bend residuals (``own_family``: out_of_plane, from segment
  lengths) is judged by its own test at its own level, outside the alpha above (family-wise alpha + its level),
  supported when that test holds, its held-out error on that channel falls and its fit is plausible, and the
  verdict where no other candidate is, or where the bend verdict, refitted beside its term, no longer lowers the
  held-out error significantly (fold t <= t(1 - alpha / n)) and its time course, where it has one, is the own
  term's (phase-surrogate p <= the own level: :func:`~rce_gtsam.diagnosis.verdict.weigh_beside_own`)
  (:mod:`rce_gtsam.diagnosis.own_family`, :func:`own_supported`).
* **one node** (last, in :func:`~rce_gtsam.diagnosis.diagnose.diagnose`): the verdict stands only if, without the
  bends of the node that carries most of its in-sample gain (keeping what no error of that node moves), the effect
  still lowers the held-out error (fold t > 0, :mod:`rce_gtsam.diagnosis.one_node`); an own-family effect's test must
  hold without that node's segments (:func:`~rce_gtsam.diagnosis.own_family.own_test_significant`).

Nothing here computes a statistic: the tests' results come in from :mod:`rce_gtsam.diagnosis.evidence`, which
runs an encompassing test where :func:`support_richer_forms` asks for one (``ask``). Why each rule is there,
with its measurements, is in the test modules' docstrings. Units: degrees (RMSE); p and t unitless.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy import stats

from .result import complexity, effect_kind
from .verdict import choose_verdict, choose_with_own_last, weigh_the_leading  # noqa: F401 (re-exported)


@dataclass(frozen=True)
class Levels:
    """The levels every test is read at (see the module's note): ``t_crit`` the fold t's threshold, ``t_crit_split``
    the fold t's where a full-data score test shares the share, ``p_score`` the full-data tests' (score,
    shared course, encompassing), ``t_support`` the fold t a full-data test needs beside it (nominal alpha)."""

    alpha: float
    n_findings: int
    t_crit: float
    t_crit_split: float
    p_score: float
    t_support: float


def levels(alpha: float, n_findings: int, n_folds: int) -> Levels:
    """The :class:`Levels` for ``n_findings`` findings and ``n_folds`` scored folds.

    alpha is shared among the findings, not the candidates: two forms of one effect (dynamics, resonances) test one
    hypothesis with correlated statistics (a sixth share lost borderline lags: dynamics 0.75x seed 1, delay p =
    0.0050). The nominal family-wise bound becomes (n_candidates / n_findings) alpha; measured on effect-free
    pipeline data: 0 of 40 verdicts (bench_diagnose)."""
    n_c, dof = max(n_findings, 1), max(int(n_folds) - 1, 1)
    return Levels(alpha=alpha, n_findings=n_c, t_crit=float(stats.t.ppf(1 - alpha / n_c, dof)),
                  t_crit_split=float(stats.t.ppf(1 - alpha / (2 * n_c), dof)), p_score=alpha / (2 * n_c),
                  t_support=float(stats.t.ppf(1 - alpha, dof)))


def is_significant(t: float, threshold_t: float, score_p: float | None, score_threshold_p: float,
                   support_t: float = -np.inf, both: bool = False) -> bool:
    """The fold t above ``threshold_t``, or (an effect with a score test, ``score_p`` not None) its p at or below
    ``score_threshold_p`` **and** the fold t above ``support_t``. A full-data test alone names nothing: its
    phase-surrogate null assumes stationary noise, which a tracker's is not (``benchmarks/bench_user_path.py``:
    effect-free recordings at score p 0.0005 with a held-out gain of 0.2 %, fold t 0.8); so it fires falsely
    only where both tests do. ``both`` (an effect's :attr:`~rce_gtsam.effects.Effect.needs_both_tests`, with a
    score test): the fold t above ``threshold_t`` **and** the score p at or below its threshold (a saturation,
    which the excitation mostly absorbs: one test alone has only named it on artifacts)."""
    fold = bool(np.isfinite(t) and t > threshold_t)
    if both and score_p is not None:
        return fold and score_p <= score_threshold_p
    full = score_p is not None and score_p <= score_threshold_p and bool(np.isfinite(t) and t > support_t)
    return fold or full


#: Score-test versions measured calibrated on the tracker-artifact bed and the user's path (record ``delay_test``: the
#: delay's, p <= 0.005 on 0 of 440 artifact and 1 of 120 effect-free user-path recordings): fold t > 0 suffices.
ARTIFACT_CALIBRATED = frozenset({"own_whitened"})


def support_t(lv: Levels, excitation: str | None) -> float:
    """The fold t a significant score test of version ``excitation`` needs beside it (:data:`ARTIFACT_CALIBRATED`)."""
    return 0.0 if excitation in ARTIFACT_CALIBRATED else lv.t_support


def significance_route(tests: dict, lv: Levels, both: bool = False, excitation: str | None = None) -> str | None:
    """:func:`is_significant` on a candidate's ``tests`` ("fold_t", and "score" where it has one; ``both``: the
    effect's ``needs_both_tests``; ``excitation``: its score test's version), as the test that made it true, which the
    report quotes: "held-out" (the fold t), "full-data" (the score test beside a fold t above its support),
    "both", or None (not significant)."""
    score, t = tests.get("score"), tests["fold_t"]
    if not is_significant(t.statistic, t.threshold, None if score is None else score.p, lv.p_score,
                          -np.inf if score is None else support_t(lv, excitation), both=both):
        return None
    fold = bool(np.isfinite(t.statistic) and t.statistic > t.threshold)
    return "both" if both and score is not None else "held-out" if fold else "full-data"


def significant(tests: dict, lv: Levels, both: bool = False, excitation: str | None = None) -> bool:
    return significance_route(tests, lv, both, excitation) is not None


def asks_drift_checks(basis, significant_by_fold_t: bool, has_score: bool) -> bool:
    """Per-segment time courses (``basis``) significant by the fold t alone need the drift checks (evidence.py)."""
    return basis is not None and significant_by_fold_t and not has_score


def drift_rescued(tests: dict) -> bool:
    """The drift checks show what tracker drift cannot (see the module's note)."""
    shared, away = tests.get("shared_course"), tests.get("shared_course_away_from_gaps")
    return bool(tests["heldout_null"].fires or (shared is not None and shared.fires and (away is None or away.fires))
                or ("drift_pattern" in tests and tests["drift_pattern"].fires))


def earns_its_place(rmse: float, b_rmse: float, delta_aic: float, gain_share: float, resolution: float,
                     calibrated: bool = False) -> bool:
    """What a significant candidate must also do to be supported: lower the held-out RMSE, lower the effective-
    sample AIC, take at least ``resolution`` of the bending variance off the held-out error. ``calibrated``: its
    full-data score test is significant, and the AIC hurdle is waived. The hurdle guards the fold t (16 numbers;
    without it 5/40 effect-free pipeline seeds got a verdict, all by fold t), whereas the score test's false-alarm
    rate is measured on every frame; and the AIC's penalty, on an AR(1)-corrected sample, charges a free
    per-frame series (a second excitation's w) about 2 per frame that the held-out error has already paid for."""
    return rmse < b_rmse and (delta_aic < 0 or calibrated) and gain_share >= resolution


def supported(c, is_sig: bool, b_rmse: float, resolution: float) -> bool:
    """Candidate evidence ``c`` (:class:`~rce_gtsam.diagnosis.evidence.CandidateEvidence`) is supported."""
    calibrated = "score" in c.tests and c.tests["score"].fires
    return bool(is_sig and not c.implausible and earns_its_place(
        c.heldout_rmse, b_rmse, c.delta_aic, c.numbers["heldout_gain_share"], resolution, calibrated))


def support_richer_forms(results: list, ask, b_rmse: float, resolution: float, p_pair: float) -> list:
    """The results with each supported candidate B's richer forms R (same kind, more complex, plausible, earning
    their place with the AIC waived) weighed by the encompassing test ``ask(B, R)`` -> (p, z, {fit: p}) or None
    (:func:`~rce_gtsam.diagnosis.evidence.form_test`; why, and what it was measured to do: the module docstring of
    :mod:`rce_gtsam.diagnosis.encompassing`). p and z go into R's ``extra["form_test_p"]`` / ``["form_test_z"]``
    under B's name; at p <= ``p_pair`` an R not supported on its own becomes supported, recorded as
    ``extra["supported_as_form_of"] = B``. Returns the (re-built) results in the same order."""
    out = list(results)
    for b in [c for c in results if c.supported]:
        for i, c in enumerate(out):
            if (c is b or effect_kind(c) is None or effect_kind(c) != effect_kind(b)
                    or not complexity(b) < complexity(c) or c.extra.get("implausible")
                    or not earns_its_place(c.heldout_rmse, b_rmse, c.delta_aic,
                                           c.extra.get("heldout_gain_share", 0.0), resolution, calibrated=True)):
                continue
            test = ask(b, c)
            if test is None:
                continue
            p, z, raw = test
            extra = {**c.extra, "form_test_p": {**c.extra.get("form_test_p", {}), b.effect: p},
                     "form_test_z": {**c.extra.get("form_test_z", {}), b.effect: z},
                     "form_test_p_per_fit": {**c.extra.get("form_test_p_per_fit", {}), b.effect: raw}}
            if p <= p_pair and not c.supported:
                extra["supported_as_form_of"] = b.effect
                out[i] = replace(c, supported=True, extra=extra)
            else:
                out[i] = replace(c, extra=extra)
    return out


def decide(results: list, ask, lv: Levels, b_rmse: float, resolution: float, node_disjoint: bool, beside=None):
    """(results, verdict effect or None, the parsimony record) among ``results`` (sorted by held-out RMSE,
    ``supported`` set): the lag's richer forms where the row sets share no node (the encompassing test needs that),
    the encompassing tests the parsimony rule reads, then :func:`~rce_gtsam.diagnosis.verdict.choose_with_own_last`
    (``beside``: the nested test of a bend verdict beside a supported own-family candidate)."""
    if node_disjoint:
        results = support_richer_forms(results, ask, b_rmse, resolution, lv.p_score)
        weigh_the_leading(results, ask, lv.t_crit, lv.p_score)
    # an own-family candidate (read from another channel) is the verdict where no bend candidate is, or where the
    # bend verdict does not earn its place beside it (verdict.weigh_beside_own)
    verdict_effect, parsimony = choose_with_own_last(results, lv.t_crit, p_pair=lv.p_score, beside=beside)
    return results, verdict_effect, parsimony


def own_supported(significant: bool, reasons) -> bool:
    """Support of an own-family candidate: its own test significant and its fit plausible; the held-out change of
    the bend model with its term is reported, not required (why, measured: :mod:`rce_gtsam.diagnosis.own_family`)."""
    return bool(significant and not reasons)
