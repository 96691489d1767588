"""Candidates judged by a test of their own (:attr:`~rce_gtsam.effects.Effect.own_family`), outside the Bonferroni
family the bend-residual tests share.

An effect read from another channel than the bend residuals (OutOfPlane: the segments' lengths) brings its own
test at its own level (:meth:`~rce_gtsam.effects.Effect.own_family_test`): it takes no share of the diagnosis'
alpha, so the other candidates' thresholds are what they were without it, and a diagnosis' nominal family-wise
false-alarm rate is alpha + that level. Such a candidate is *significant* when its own test is, *supported* when
besides its fit is plausible (the held-out change is reported, not required), and it is the
verdict only where no bend-residual candidate is supported
(:func:`~rce_gtsam.diagnosis.verdict.choose_with_own_last`): it names what the bend candidates leave, and changes
none of their decisions. This module runs the test (evidence); :func:`~rce_gtsam.diagnosis.decision.own_supported`
and the verdict's order are the decision's.
"""

from __future__ import annotations



def own_test_significant(eff, base, seed: int, extra: dict) -> bool:
    """Whether an own-family effect's own test on the baseline fit ``base`` is significant at its own level; its
    statistics go into the candidate's ``extra``. No test (None): not significant."""
    own = eff.own_family_test(base, seed=seed)
    extra.update(own or {})
    return bool(own is not None and own["p"] <= own["alpha"])
