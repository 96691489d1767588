"""Candidates judged by a test of their own (:attr:`~rce_gtsam.effects.Effect.own_family`), outside the Bonferroni
family the bend-residual tests share.

An effect read from another channel than the bend residuals (OutOfPlane: the segments' lengths) brings its own
test at its own level (:meth:`~rce_gtsam.effects.Effect.own_family_test`): it takes no share of the diagnosis'
alpha, so the other candidates' thresholds are what they were without it, and a diagnosis' nominal family-wise
false-alarm rate is alpha + that level. Such a candidate is *significant* when its own test is, its held-out
error on its own channel falls and, where it has one, its signature holds (a swing's neighbouring segments change
together: :func:`signature_holds`), *supported* when besides its fit is plausible (the held-out change is
reported, not required), and it is the
verdict where no bend-residual candidate is supported, or where the bend verdict, refitted beside its term, no
longer lowers the held-out error significantly and its time course is this term's
(:func:`~rce_gtsam.diagnosis.verdict.choose_with_own_last`,
:func:`~rce_gtsam.diagnosis.verdict.weigh_beside_own`): it changes none of the bend candidates' tests, only which
of two supported findings is named. Why the held-out change is not required: the finding is read from the other
channel, and where the term does not lower the held-out error the rank-1 kappa stays the one to report
(:func:`~rce_gtsam.kappa_report.kappa_after_verdict`); measured on the 3-D simulator at the default swing (20
seeds, 450 frames), the length test held on 20/20, the term lowered the held-out RMSE by at most 0.3 % and raised
it by 0.1-0.5 % on 4 (requiring no rise named 15/20). This module runs the test (evidence);
:func:`~rce_gtsam.diagnosis.decision.own_supported`
and the verdict's order are the decision's.
"""

from __future__ import annotations

from .swing_signature import ALPHA_AGREE


def own_test_significant(eff, base, seed: int, extra: dict) -> bool:
    """Whether an own-family effect's own test on the baseline fit ``base`` is significant at its own level and its
    held-out error on the channel it models falls (``heldout_gain_pct`` > 0 where the test reports one: a full-data
    test alone names nothing); its statistics go into the candidate's ``extra``. No test (None): not significant.

    Measured (OutOfPlane, whose held-out error is the segments' lengths predicted from the course of the segments
    they share no node with): on 40 effect-free user-path recordings the gain was -25 to +2.9 %, and the one planar
    recording whose length test held (p 0.007, a tracker re-finding tip nodes) had -1.9 %; on rendered swings
    +82 %, on the simulator's swinging tracks a median +5 % (one of 19 named had -0.3 %). Those were summed in
    relative length; each segment is now scored in its own units (:func:`~rce_gtsam.diagnosis.length_channel.
    heldout_length_gain`): on the simulator's swings (20 seeds, 450 frames) those passing the other tests and the
    gain went 18 -> 18 of 20 with the plane tilted 30 deg and 5 -> 3 of 20 in the image plane (gains within
    +-0.5 % there), on the user path's rendered swings see record ``user_path_swing_naming``."""
    own = eff.own_family_test(base, seed=seed)
    extra.update(own or {})
    # the one-node check (one_node.py) on its channel: without the segments of the node that carries most of the
    # course, its test must still hold at its level (NaN: it could not run, and holds). Its sign is the test's, not
    # the held-out length gain's: a swing's length change grows toward the tip, so without the tip node's segments
    # the gain left is small and noisy (3-D simulator: 7 of 20 swings <= 0 there, their test still at p 0.001),
    # whereas one node's artifact loses the test itself (4 of 5 effect-free user-path renders)
    own = own or {}
    p_wo = own.get("length_p_without_node", float("nan"))
    holds = not (p_wo == p_wo) or p_wo <= own.get("alpha", 1.0)
    return bool(own and own["p"] <= own["alpha"] and own.get("heldout_gain_pct", 1.0) > 0.0 and holds
                and signature_holds(own))


def signature_holds(own: dict) -> bool:
    """Whether an own-family test's record shows the effect's signature where it reports one: for OutOfPlane,
    neighbouring segments' loadings on the shared length course agree (:mod:`~rce_gtsam.diagnosis.swing_signature`:
    a course the tracked nodes share, each with a part of its own, gives node-disjoint segments a course too, but
    neighbouring loadings that disagree). True where the record has no such test."""
    p = own.get("length_agreement_p")
    return p is None or p <= own.get("agreement_alpha", ALPHA_AGREE)
