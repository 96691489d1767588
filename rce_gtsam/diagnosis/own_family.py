"""Candidates judged by a test of their own (:attr:`~rce_gtsam.effects.Effect.own_family`), outside the Bonferroni
family the bend-residual tests share.

An effect read from another channel than the bend residuals (OutOfPlane: the segments' lengths) brings its own
test at its own level (:meth:`~rce_gtsam.effects.Effect.own_family_test`): it takes no share of the diagnosis'
alpha, so the other candidates' thresholds are what they were without it, and a diagnosis' nominal family-wise
false-alarm rate is alpha + that level. Such a candidate is *significant* when its own test is, *supported* when
besides its fit is plausible (:func:`own_supported`: the held-out change is reported, not required), and it is the
verdict only where no bend-residual candidate is supported (:func:`choose_with_own_last`): it names what the bend
candidates leave, and changes none of their decisions.
"""

from __future__ import annotations

from .verdict import choose_verdict


def own_test_significant(eff, base, seed: int, extra: dict) -> bool:
    """Whether an own-family effect's own test on the baseline fit ``base`` is significant at its own level; its
    statistics go into the candidate's ``extra``. No test (None): not significant."""
    own = eff.own_family_test(base, seed=seed)
    extra.update(own or {})
    return bool(own is not None and own["p"] <= own["alpha"])


def own_supported(significant: bool, reasons) -> bool:
    """Support of an own-family candidate: its own test significant and its fit plausible. The held-out change of
    the bend model with its term is reported, not required: the finding is read from the other channel, and where
    the term does not lower the held-out error the rank-1 kappa stays the one to report
    (:func:`~rce_gtsam.kappa_report.kappa_after_verdict`). Measured on the 3-D simulator at the default swing (20
    seeds, 450 frames): the length test held on 20/20, the term lowered the held-out RMSE by at most 0.3 % and
    raised it by 0.1-0.5 % on 4 (requiring no rise named 15/20)."""
    return bool(significant and not reasons)


def is_own_family(c) -> bool:
    """Whether candidate ``c``'s effect is judged by its own test."""
    return any(e.own_family for e in c.fit.model.effects if e.name == c.effect)


def choose_with_own_last(results: list, t_crit: float, p_pair: float):
    """:func:`~rce_gtsam.diagnosis.verdict.choose_verdict` among the bend-residual candidates; only where it names
    none, among the own-family ones."""
    verdict, parsimony = choose_verdict([c for c in results if not is_own_family(c)], t_crit, p_pair=p_pair)
    if verdict is None:
        verdict, parsimony = choose_verdict([c for c in results if is_own_family(c)], t_crit)
    return verdict, parsimony
