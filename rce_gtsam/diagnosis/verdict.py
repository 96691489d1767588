"""The decision's helpers between supported candidates (:mod:`rce_gtsam.diagnosis.decision` states the rule):
the leading candidate, the lag's richer form, the encompassing tests the parsimony rule reads and the parsimony
rule itself.

* :func:`leading_candidate`, :func:`richer_form_of` — which supported candidate the verdict starts from;
* :func:`weigh_the_leading` — asks for the encompassing tests of the leading candidate against simpler ones;
* :func:`choose_verdict` — the verdict; :func:`maxt_verdict` — the same rule under the sign-flip max-T test;
* :func:`complexity`, :func:`effect_kind`, :func:`finding_of` — a candidate's parsimony order, kind and finding
  (:mod:`rce_gtsam.diagnosis.result`, re-exported).

The one number computed here is the fold-paired t between two candidates' recorded fold errors
(:func:`~rce_gtsam.diagnosis.heldout.paired_t`). Units: degrees (RMSE), p and t unitless.
"""

from __future__ import annotations

from dataclasses import replace

from .heldout import paired_t
from .result import Diagnosis, candidate_effect, complexity, effect_kind, finding_of  # noqa: F401 (re-exported)


def maxt_verdict(diag: Diagnosis) -> str | None:
    """The verdict the family-wise sign-flip max-T test (:mod:`rce_gtsam.diagnosis.maxt`) gives: the same rule
    as the diagnosis' (lowest held-out RMSE among the supported, parsimony against simpler ones), with
    "supported" from the max-T p-value and the max-T critical t in place of the Bonferroni t."""
    swapped = [replace(c, supported=bool(c.extra.get("supported_maxt", False))) for c in diag.candidates]
    return choose_verdict(swapped, diag.settings["maxt_critical_t"])[0]


def richer_form_of(c, candidates: list, p_pair: float):
    """The supported candidate that is a richer form of ``c``'s finding and predicts what ``c`` leaves in the
    residuals: the same kind (:func:`effect_kind`), more complex (:func:`complexity`), its encompassing test
    against ``c`` (``extra["form_test_p"][c.effect]``, :func:`~rce_gtsam.diagnosis.decision.support_richer_forms`)
    at most ``p_pair``. The lowest in held-out RMSE where several are; None where none is."""
    kind = effect_kind(c)
    forms = [r for r in candidates if r is not c and r.supported and kind is not None and effect_kind(r) == kind
             and complexity(c) < complexity(r) and r.extra.get("form_test_p", {}).get(c.effect, 1.0) <= p_pair]
    return min(forms, key=lambda r: r.heldout_rmse) if forms else None


def leading_candidate(supported: list, t_crit: float, p_pair: float | None = None):
    """The supported candidate the verdict starts from: the one with the lowest held-out RMSE, unless it is another
    form of an effect that is also supported (:func:`finding_of`) and does not beat that effect's own form
    significantly (fold-paired t at most ``t_crit``): then the plain form leads, and the tests that weigh it
    against simpler rivals (the encompassing test between the lags) apply to it. Without this a per-joint
    resonance that was lowest but not significantly lower than the graded dynamics was weighed against the delay
    by the fold t alone, which cannot separate them, and the delay was named (dynamics 1x, seed 7: the graded
    form's encompassing test against the delay p = 0.0005).

    With ``p_pair``: where a richer form of the same finding predicts what the leading one leaves
    (:func:`richer_form_of`), the richer form leads, whichever is lower in held-out RMSE: the two forms' held-out
    errors differ by less than their fold noise (dynamics at 0.75x default, seed 155: delay 3.9 % lower, the
    fitted inertia 3.5 %, fold-paired t 0.5), while the encompassing test uses every frame (p = 0.0005 there)."""
    best = supported[0]
    name = finding_of(best)
    if name != best.effect:
        plain = next((c for c in supported if c.effect == name), None)
        if plain is not None and paired_t(plain.fold_mse, best.fold_mse) <= t_crit:
            best = plain
    if p_pair is not None:
        best = richer_form_of(best, supported, p_pair) or best
    return best


def weigh_the_leading(results: list, ask, t_crit: float, p_pair: float | None = None) -> None:
    """For the leading supported candidate (:func:`leading_candidate`) and each simpler supported one
    (:func:`complexity`): the encompassing test of whether the leading one's model predicts what the simpler one
    leaves, ``ask(simpler, leading)`` -> (p, z, {fit: p}) or None where it does not apply
    (:func:`~rce_gtsam.diagnosis.evidence.form_test`), or the one :func:`~rce_gtsam.diagnosis.decision.
    support_richer_forms` already ran. Its p and z go into the leading one's ``extra["encompassing_p"]`` /
    ``["encompassing_z"]`` under the simpler one's name, which :func:`choose_verdict` reads."""
    sup = [c for c in results if c.supported]
    if len(sup) < 2:
        return
    best = leading_candidate(sup, t_crit, p_pair)
    for c in sup:
        if c is best:
            continue
        if complexity(c) < complexity(best):
            if c.effect in best.extra.get("form_test_p", {}):  # already run by support_richer_forms
                p, z = best.extra["form_test_p"][c.effect], best.extra["form_test_z"][c.effect]
            else:
                test = ask(c, best)
                if test is None:
                    continue
                p, z, _ = test
            best.extra.setdefault("encompassing_p", {})[c.effect] = p
            best.extra.setdefault("encompassing_z", {})[c.effect] = z


def choose_verdict(results: list, t_crit: float, same_kind: bool = False,
                   p_pair: float | None = None) -> tuple[str | None, dict]:
    """The verdict among supported candidates, with a parsimony rule.

    Start from the supported candidate with the lowest held-out RMSE (or, where that is another form of a
    supported effect and not significantly better than it, that effect: :func:`leading_candidate`). If a simpler
    supported candidate (fewer free per-frame series, then fewer effective parameters: :func:`complexity`) is not
    significantly worse than it (paired t over folds of the log MSE ratio below the same threshold as the support
    test), the simplest such candidate is the verdict: the data
    cannot tell them apart, and the extra parameters are not earned. Where the lowest candidate carries an
    encompassing test against the simpler one (``extra["encompassing_p"]``, :mod:`rce_gtsam.diagnosis.encompassing`)
    and ``p_pair`` is given, that test decides instead of the fold t: the simpler one is preferred unless its
    residuals hold what the lower one predicts (p <= ``p_pair``). Measured through the pipeline at default
    strength (20 seeds each, 1x): dynamics named 7 -> 15/20, delay 14 -> 15/20 (the fold t alone named half the
    dynamics recordings delay once the delay candidate's z was regularised). This separates a pure delay (1
    parameter: a phase lag linear in frequency, no amplitude change) from second-order dynamics (3
    parameters: the same low-frequency lag, plus amplification near resonance and ringing), which only wins
    when the resonance itself improves the held-out error.

    With ``p_pair``, a richer form of the same finding that predicts what a candidate leaves takes its place,
    whether that candidate leads or is the simpler one preferred (:func:`richer_form_of`; then
    ``"richer_form_of"`` names the form it replaced).

    ``same_kind=True`` also weighs simpler candidates of the best one's kind that are not supported on their
    own but lower the held-out error (see the comment below). Measured on the simulator (bench_diagnose's
    right2 column) it turns delay misnamed as dynamics into delay about as often as it turns strong dynamics
    into delay, so it is not the default."""
    sup = [c for c in results if c.supported]
    if not sup:
        return None, {}
    best = leading_candidate(sup, t_crit, p_pair)
    pair = {}
    simpler = []
    # same_kind: a simpler candidate of the same kind (both operators on z: delay and inertia both put a lag
    # between the excitation and the joint, and at low frequency inertia IS a lag) also counts when it is not
    # supported on its own, as long as it lowers the held-out error: "a lag" is what the data support, and the
    # extra parameters of the complex form must earn their keep against the simple one
    pool = [c for c in sup if c is not best] + ([c for c in results if not c.supported and c.improvement_pct > 0
                       and effect_kind(c) is not None and effect_kind(c) == effect_kind(best)] if same_kind else [])
    # the encompassing tests the leading candidate carries against simpler ones (the form tests are the same test)
    enc = ({**best.extra.get("form_test_p", {}), **best.extra.get("encompassing_p", {})} if p_pair is not None
           else {})
    for c in pool:
        t = paired_t(c.fold_mse, best.fold_mse)  # > 0: best is lower than c
        pair[c.effect] = t
        better = enc[c.effect] <= p_pair if c.effect in enc else t > t_crit
        if complexity(c) < complexity(best) and not better:
            simpler.append(c)
    out = {"lowest_heldout": sup[0].effect, "leading": best.effect, "t_vs_lowest": pair}
    if enc:
        out["encompassing_p"] = dict(enc)
    if not simpler:
        return best.effect, out
    pick = min(simpler, key=lambda c: (complexity(c), c.heldout_rmse))
    # where the simpler effect the data cannot tell from the leading one is a lag, its form is decided by the
    # test between the lag's forms, as where it leads (leading_candidate); the richer form need not be simpler
    # than the leading candidate (dynamics 0.75x seed 139: a saturation led, delay and dynamics both supported)
    form = richer_form_of(pick, sup, p_pair) if p_pair is not None else None
    if form is not None:
        return form.effect, {**out, "preferred_simpler": form.effect, "richer_form_of": pick.effect}
    return pick.effect, {**out, "preferred_simpler": pick.effect}


def is_own_family(c) -> bool:
    """Whether candidate ``c``'s effect is judged by its own test."""
    return any(e.own_family for e in c.fit.model.effects if e.name == c.effect)


def weigh_beside_own(bend, own, nested: dict | None, t_crit: float) -> bool:
    """Whether bend candidate ``bend`` keeps the verdict beside a supported own-family candidate ``own``
    (``nested``: :func:`~rce_gtsam.diagnosis.evidence.nested_heldout`). ``own`` takes it only where both hold:

    1. ``bend`` adds nothing beside ``own``'s term: the model with both does not predict the held-out bending
       significantly better than ``own``'s alone (fold-paired t <= ``t_crit``, the bend candidates' threshold, or
       no lower RMSE);
    2. where ``bend`` fits a per-frame course (a second excitation's w), that course is the swing's: the swing's
       courses explain it beyond phase surrogates at ``own``'s own level (``course_p`` <= ``own.extra["alpha"]``).

    Why: a swing out of the image plane is read from the segments' lengths, but it also turns the projected bend
    angles, and what that leaves of rank 1 a second excitation can take. Measured (bench_oop_beside.py): on the
    user's path (23 swing renders through our tracker) second_mode came first on 3; on one its course was the
    swing's (t 2.1, course p 0.009: out_of_plane named 20 -> 21 of 23), on the two others one node's tracking error
    (mode shape -1, +2, -1 on one node's three bends; t 3.4 and 4.8, course p 0.10 and 0.76) kept it. Simulated
    swings: 18 -> 19 of 20 (t 1.9, course p 0.001). A real second excitation beside a swing (3-D simulator, second
    excitation at 2x and 4x its default, 20 seeds each): second_mode came first beside a supported out_of_plane on
    1 and 9 and kept it on all 10 (course p 0.014-0.79); the fold t alone would have renamed 4 (t 1.7-2.6, the
    swings' range), naming out_of_plane wherever supported all 10. Planar recordings did not reach the check
    (out_of_plane supported on none of 20 simulated second excitations, 40 effect-free and 20 lag renders). The
    margins are thin (course p 0.009 renamed, 0.014 kept). Where the nested fit cannot be scored (``nested``
    None), ``bend`` keeps it."""
    if nested is None:
        return True
    adds = nested["t"] > t_crit and nested["heldout_rmse"] < own.heldout_rmse
    is_swing = "course_p" not in nested or nested["course_p"] <= own.extra.get("alpha", 0.01)
    return bool(adds or not is_swing)


def choose_with_own_last(results: list, t_crit: float, p_pair: float, beside=None):
    """:func:`~rce_gtsam.diagnosis.verdict.choose_verdict` among the bend-residual candidates; where it names
    none, among the own-family ones. Where it names one and an own-family candidate is supported too, ``beside``
    (``beside(bend, own)`` -> :func:`~rce_gtsam.diagnosis.evidence.nested_heldout`'s record or None) weighs the
    bend one against the model with the own-family term (:func:`weigh_beside_own`); the record goes into the
    parsimony's ``"beside_own"`` ({"own", "bend", "t", "heldout_rmse", "improvement_over_own_pct", "course_r2",
    "course_p" where the bend candidate has a course, "threshold_t", "kept"})."""
    verdict, parsimony = choose_verdict([c for c in results if not is_own_family(c)], t_crit, p_pair=p_pair)
    own = sorted((c for c in results if is_own_family(c) and c.supported), key=lambda c: c.heldout_rmse)
    if verdict is None:
        return choose_verdict([c for c in results if is_own_family(c)], t_crit)
    if not own or beside is None:
        return verdict, parsimony
    bend = next(c for c in results if c.effect == verdict)
    nested = beside(bend, own[0])
    kept = weigh_beside_own(bend, own[0], nested, t_crit)
    record = {"own": own[0].effect, "bend": bend.effect, **(nested or {}), "threshold_t": t_crit, "kept": kept}
    if kept:
        return verdict, {**parsimony, "beside_own": record}
    return own[0].effect, {**choose_verdict(own, t_crit)[1], "beside_own": record}
