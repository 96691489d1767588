"""The diagnosis in words: the verdict's explanation with the numbers behind it (:func:`explain`), the sentence
for significant candidates that were not named, and the text report (:func:`render_diagnosis_report`). A leaf
module: it reads a :class:`~rce_gtsam.diagnosis.result.Diagnosis` (its only import from the diagnosis is
:mod:`rce_gtsam.diagnosis.result`) and computes nothing.

Units: degrees (RMSE), deg^2 (variances), frames.
"""

from __future__ import annotations

import numpy as np

from ..model import render_fit_report
from .result import Diagnosis, complexity, score_is_significant


def calibrated_note(diag) -> str:
    """Which candidates' score tests need only a held-out t > 0 beside them (a test measured calibrated on the
    tracker-artifact test bed and the user's path: ``extra["support_threshold_t"]`` 0), as a clause."""
    names = [c.effect for c in diag.candidates if c.extra.get("support_threshold_t") == 0.0]
    if not names:
        return "the held-out frames must agree"
    return (f"for {', '.join(names)}, whose test is calibrated on the tracker-artifact test bed, t > 0: the held-out "
            f"frames must agree in sign")


def significant_but_not_named(diag: Diagnosis) -> str:
    """A sentence for a diagnosis without a verdict whose candidates include significant ones (fold t or full-
    data score test) that were not supported, each with what it lacked (a held-out error that falls, an AIC that
    falls, or the resolution): the residuals hold structure of their kind that none of the fitted forms earns
    its place with. Empty when there are none."""
    sig = [c for c in diag.candidates if c.extra.get("significant") and not c.supported]
    if not sig:
        return ""

    def why(c) -> str:
        sp = c.extra.get("score_p")
        calibrated = score_is_significant(sp, c.extra.get("score_threshold_p", 0.0))
        test = f"full-data score test p = {sp:.2g}" if calibrated else f"evidence t = {c.evidence:.2f}"
        if c.extra.get("implausible"):
            lacks = "its fit is not plausible physics: " + "; ".join(c.extra["implausible"])
        elif c.heldout_rmse >= diag.baseline_heldout_rmse:
            lacks = f"held-out RMSE {-c.improvement_pct:+.1f}%"
        elif c.delta_aic >= 0 and not calibrated:
            lacks = f"held-out RMSE {-c.improvement_pct:+.1f}% but AIC {c.delta_aic:+.1f} on the effective sample"
        else:
            lacks = (f"held-out RMSE {-c.improvement_pct:+.1f}%, below the resolution of "
                     f"{100 * diag.settings.get('resolution', 0.0):.2g}% of the variance")
        return f"{c.effect} ({test}; {lacks})"

    return (" Significant but not named: " + ", ".join(why(c) for c in sig) + ". The residuals hold structure "
            "of that kind, but the extended model does not earn its place, so that form of the effect is not what "
            "the data show.")


def out_of_plane_text(diag) -> str:
    """What the segment-length test says about out-of-plane swing where the floor is bounded (the segments stretch),
    and what would settle it."""
    # the candidate that read the segment lengths (its length test's p is in its extra), whatever its name
    c = next((c for c in diag.candidates if "length_p" in c.extra), None)
    if c is None:
        return (" Out-of-plane swing is not tested here (no segment lengths); depth (a RealSense recording) or a "
                "second camera view would settle it.")
    p, a = c.extra["length_p"], c.extra.get("alpha", 0.01)
    g, ga = c.extra.get("length_agreement_p"), c.extra.get("agreement_alpha", 0.01)
    if p > a:
        why = ": the lengths share no course beyond tracking noise at that level"
    elif g is not None and g > ga:
        why = (f", but neighbouring segments do not change together as a swing's do (agreement of their loadings "
               f"{c.extra.get('length_agreement', float('nan')):+.2f}, p = {g:.2g} against {ga:g}): a course the "
               f"tracked nodes share, each with a part of its own (compression, lighting, an error that follows the "
               f"motion), gives such lengths too")
    else:
        why = ""
    return (f" The segment lengths' test for out-of-plane swing gives p = {p:.2g} against its level {a:g}{why}; "
            "depth (a RealSense recording) would measure the swing.")


def beside_own_text(diag: Diagnosis) -> str:
    """The sentence on a bend candidate weighed beside a supported own-family one
    (:func:`~rce_gtsam.diagnosis.verdict.weigh_beside_own`, the parsimony's ``"beside_own"``): why the verdict is
    the one or the other, with the nested model's fold t. Empty where no such weighing ran."""
    rec = (diag.settings.get("parsimony") or {}).get("beside_own")
    if not rec:
        return ""
    bend, own = diag.candidate(rec["bend"]), rec["own"]
    thr = rec.get("threshold_t", float("nan"))
    if "t" not in rec:
        return (f"{own} is supported too; the model with both {bend.effect} and {own} could not be scored on "
                f"every fold, so {bend.effect}, supported on its own, stays the verdict.")
    adds = rec["t"] > thr and rec["heldout_rmse"] < diag.candidate(own).heldout_rmse
    nested = (f"fold t = {rec['t']:.2f} {'>' if rec['t'] > thr else '<='} {thr:.2f}; held-out RMSE "
              f"{rec['heldout_rmse']:.3f} deg with both terms, {rec['improvement_over_own_pct']:+.1f}% against "
              f"{own}'s alone")
    level = diag.candidate(own).extra.get("alpha", float("nan"))
    course = ("" if "course_p" not in rec else
              f"the swing's courses explain {100 * rec['course_r2']:.0f}% of {bend.effect}'s time course (p = "
              f"{rec['course_p']:.3g} against phase surrogates, level {level:g})")
    if rec["kept"]:
        why = (f"{bend.effect} still lowers the held-out error significantly ({nested})" if adds else
               f"{bend.effect}'s time course is not the swing's ({course}; {nested})")
        return (f"{own} is supported too (its own test on the segments' lengths): the branch also swings out of "
                f"the image plane. Refitted beside the {own} term, {why}, so {bend.effect} is named; both are in "
                f"these data.")
    return (f"The bend angles also support {bend.effect} (held-out RMSE {bend.improvement_pct:.1f}% below the "
            f"rank-1 model's), but refitted beside the {own} term it no longer lowers the held-out error "
            f"significantly ({nested})" + (f", and {course}" if course else "") + ": an out-of-plane swing turns "
            f"the projected bend angles, and what that leaves of rank 1 a {bend.effect} term can take, while the "
            f"segments' lengths show the swing itself. {own} is named; {bend.effect} is not excluded.")


def both_tests_text(c) -> str:
    """Why a candidate of an effect that needs both of its tests (a saturation) was not named though one passed."""
    from ..effects import CANDIDATES

    cls = CANDIDATES.get(c.effect)
    sp, thr = c.extra.get("score_p"), c.extra.get("score_threshold_p")
    if cls is None or not getattr(cls, "needs_both_tests", False) or sp is None or thr is None:
        return ""
    fold_ok = c.evidence > c.extra.get("threshold_t", float("inf"))
    if fold_ok == (sp <= thr):
        return ""
    return (f" ({c.effect} is named only where both its tests pass, the fold t and the score test at p <= "
            f"{thr:.2g}: the excitation absorbs most of a saturation, and one test alone has been a tracker's "
            f"artifact)")


def heldout_null_text(c) -> str:
    """The held-out gain's surrogate test of an effect made of per-segment courses of time
    (:mod:`rce_gtsam.diagnosis.heldout_null`), as a clause starting with "; ", or empty where it did not run."""
    p = c.extra.get("heldout_null_p")
    if p is None:
        return ""
    thr = c.extra.get("heldout_null_threshold_p", float("nan"))
    sp, sthr = c.extra.get("shared_course_p"), c.extra.get("shared_course_threshold_p", float("nan"))
    if p <= thr:
        return f"; its held-out gain beats phase surrogates of the residuals, p = {p:.2g} <= {thr:.2g}"
    if sp is not None and sp <= sthr:
        return (f"; two sets of segments that share no tracked node share a time course (p = {sp:.2g} <= "
                f"{sthr:.2g}), which tracker drift, each node's own, cannot give")
    dp, dthr = c.extra.get("drift_pattern_p"), c.extra.get("drift_pattern_threshold_p", float("nan"))
    if dp is not None and dp <= dthr:
        return (f"; the segments' trends are not laid out as a node's tracking drift turns its bends "
                f"(neighbours in opposite senses; p = {dp:.2g} <= {dthr:.2g}), which assumes that a node's slow and fast "
                f"tracking errors share their layout (so on the simulator, only partly checked on real footage: "
                f"look at the raw tracks for slow drift before trusting it)")
    return (f"; but slow noise of the residuals' own spectrum (tracker drift) gains as much on held-out frames "
            f"(phase surrogates p = {p:.2g} > {thr:.2g})"
            + ("" if dp is None else f", the segments' trends are laid out as a node's drift could lay them out "
               f"(p = {dp:.2g} > {dthr:.2g})")
            + ("" if sp is None else f" and no time course is common to two sets of segments that share no "
               f"tracked node (p = {sp:.2g} > {sthr:.2g})"))


def remainder_text(budget, effect: str | None = None) -> str:
    """What the variance budget's status says, in words that cannot be read against a verdict: it is always
    about what the fitted model *leaves* (the rank-1 model, or with ``effect`` the model the verdict names),
    never about whether the named effect is there (the held-out test decides that).

    "noise" -> at the noise floor; "misses" -> more than noise; "inconclusive" -> undecided, with its reason."""
    model = "the rank-1 model" if effect is None else f"the model with {effect}"
    if budget is None:
        return f"what {model} leaves: not scored (no noise floor)"
    if budget.status == "noise":
        state = "at the noise floor (nothing more to find at this record's resolution)"
    elif budget.status == "misses":
        state = "more than noise (a further effect, outside the candidates, is missing)"
    elif budget.reason == "too_uncertain":
        state = "not decidable between noise and a further miss (the record is too short to tell)"
    else:
        state = ("not decidable between noise and a further miss (the noise floor is only bounded where "
                 "segments stretch)")
    return f"what {model} leaves: {state}"


def outside_domain_text(diag: Diagnosis) -> str:
    """Why a diagnosis outside its calibrated domain names nothing (:mod:`rce_gtsam.diagnosis.domain`), and what it
    would have named."""
    would = diag.settings.get("verdict_outside_domain")
    return ("No effect is named: this analysis' settings lie outside the domain the diagnosis' tests are calibrated "
            "on (" + "; ".join(diag.outside_domain) + "). Under such settings effect-free simulated recordings get "
            "a verdict, so one here would say nothing about the plant"
            + ("" if would is None else f" (it would have been {would})")
            + ". The candidates' numbers are for inspection only; to diagnose, use the default preset "
            "(rce diagnose --preset default), whose smoothing, rest pose and response the tests were calibrated with.")


def explain(diag: Diagnosis) -> str:
    """Plain-language explanation of the verdict with the numbers behind it."""
    if diag.outside_domain:
        return outside_domain_text(diag)
    base = diag.baseline_heldout_rmse
    if diag.verdict is None:
        best = diag.candidates[0] if diag.candidates else None
        closest = ""
        if best is not None:
            sp = best.extra.get("score_p")
            closest = (f" The closest candidate, {best.effect}, changes held-out RMSE to {best.heldout_rmse:.3f} deg "
                       f"({-best.improvement_pct:+.1f}%), evidence t = {best.evidence:.2f} against the threshold "
                       f"{best.extra.get('threshold_t', diag.settings['evidence_threshold_t']):.2f}"
                       + ("" if sp is None else f", full-data score test p = {sp:.2g}") + heldout_null_text(best)
                       + both_tests_text(best) + ".")
        closest += significant_but_not_named(diag)
        b = diag.budget
        if b is None:
            return (f"No candidate effect improves the held-out error beyond its sampling noise (rank-1 held-out RMSE "
                    f"{base:.3f} deg).{closest} Without a noise floor (tracks) this cannot say whether the remaining "
                    "misfit is measurement noise or an effect outside the library.")
        share = lambda v: 100.0 * b.share(v)  # noqa: E731
        node_px = diag.noise_floor.nodewise_sigma_px if diag.noise_floor is not None else float("nan")
        tracker = (f" (the residual's node-by-node pattern puts the tracking error at {node_px:.2f} px per node)"
                   if np.isfinite(node_px) and node_px > 0 else "")
        head = (f"The rank-1 model explains {share(b.rank1):.0f}% of the bending variance ({b.total:.3g} deg^2); the "
                f"measured noise floor is {share(b.noise_floor):.0f}%{tracker}, which leaves "
                f"{share(b.unexplained):+.0f}% unexplained (+/- {share(b.unexplained_se):.0f}%).")
        worst = sorted(b.per_segment, key=lambda r: -(r["unexplained"] or 0.0))[:3]
        where = ", ".join(f"{r['segment']} ({r['unexplained']:.2g} deg^2)" for r in worst
                          if (r["unexplained"] or 0) > 0)
        if b.status == "noise":
            return (head + " That is consistent with zero: what the rank-1 model leaves is at the"
                    " tracking-noise level,"
                    f" and the model is adequate for these data: at most {max(share(b.upper), 0):.0f}% of the variance"
                    f" could still be a missed effect ({b.z_crit:g} SE), no more than the noise floor's"
                    f" {share(b.noise_floor):.0f}%; a longer recording narrows that."
                    + closest)
        if b.reason == "too_uncertain":
            return (head + f" That is consistent with zero, but this record cannot show that the model is adequate:"
                    f" the unexplained share could be as large as {share(b.upper):.0f}% ({b.z_crit:g} SE), more than"
                    f" the noise floor's {share(b.noise_floor):.0f}%. Inconclusive; a longer recording narrows that."
                    + closest)
        if b.status == "misses":
            return (head + " That is significantly more than noise, and no candidate effect in the library explains it:"
                    f" the model misses real structure, most in segments {where or 'none singled out'}."
                    + closest + " Look at the residual analysis (cross-correlation with z, frequency response,"
                    " cross-spectrum singular values) for what kind of structure it is.")
        bound = ", ".join(b.floor_is_bound[:6]) + (" ..." if len(b.floor_is_bound) > 6 else "")
        return (head + f" Inconclusive: on {len(b.floor_is_bound)} segments ({bound}) the segments stretch with the "
                "branch's motion by more than tracking noise could (out-of-plane swing, or a tracker sliding along "
                f"the stem), so there the noise floor is only bounded: the unexplained part lies between "
                f"{share(b.unexplained_range[0]):+.0f}% and {share(b.unexplained_range[1]):+.0f}% of the variance."
                + closest + out_of_plane_text(diag))
    c = diag.verdict_candidate
    sp = c.extra.get("score_p")
    score = ("" if sp is None else f"; full-data score test p = {sp:.2g} against {c.extra['score_threshold_p']:.2g}")
    score += heldout_null_text(c)
    named = c.effect if c.effect == diag.verdict else f"{diag.verdict} (in the form {c.effect})"
    lines = [f"Missing effect: {named}. Adding it lowers the held-out RMSE from {base:.3f} to "
             f"{c.heldout_rmse:.3f} deg ({c.improvement_pct:.1f}% lower; evidence t = {c.evidence:.1f} over "
             f"{diag.settings['n_folds']} folds, threshold {c.extra.get('threshold_t', float('nan')):.2f}{score}; "
             f"delta AIC {c.delta_aic:.0f} on the effective sample of "
             f"{diag.settings.get('n_eff', float('nan')):.0f} observations)."]
    eff = next((e for e in c.fit.model.effects if e.name == c.effect), None)
    own = eff is not None and eff.own_family  # named by its own test on another channel (own_family.py)
    if own:
        lines = [f"Missing effect: {named}, named by its own test on a channel besides the bend angles (p = "
                 f"{c.extra.get('p', float('nan')):.2g} against its own level {c.extra.get('alpha', float('nan')):.2g}); "
                 f"the model with it predicts the bending held out at {c.heldout_rmse:.3f} against {base:.3f} deg "
                 f"RMSE ({c.improvement_pct:+.1f}%)."]
    par = diag.settings.get("parsimony") or {}
    enc = par.get("encompassing_p") or {}
    thr = diag.settings.get("encompassing_threshold_p", float("nan"))
    form_of = c.extra.get("supported_as_form_of")
    if form_of:
        o = diag.candidate(form_of)
        osp = o.extra.get("score_p")
        lines.append(f"Its own tests fall short; it is named as the richer form of the lag that {form_of} finds "
                     f"({form_of}: held-out RMSE {abs(o.improvement_pct):.1f}% "
                     f"{'lower' if o.improvement_pct >= 0 else 'higher'}, evidence t = {o.evidence:.1f}"
                     + ("" if osp is None else f", full-data score test p = {osp:.2g}")
                     + f"): {c.effect} predicts what {form_of} leaves in the residuals "
                     f"({form_p_text(c, form_of, thr)}).")
    if eff is not None:
        lines.append(eff.explain(c.fit.effect_summary().get(c.effect, {}), c.statistics))
        lines.append(f"What it means: {eff.physics}" + ("" if own else f" Fit the model with {type(eff).__name__}() "
                                                       "and read kappa from the extended fit."))
    lead = par.get("leading", par.get("lowest_heldout"))
    def leads(cand) -> str:
        return (f"has the lowest held-out RMSE ({cand.heldout_rmse:.3f} deg)"
                if cand.effect == par.get("lowest_heldout")
                else f"leads (held-out RMSE {cand.heldout_rmse:.3f} deg)")
    lowest = par.get("lowest_heldout")
    lead_form_p = diag.candidate(lead).extra.get("form_test_p", {}) if lead is not None else {}
    said = set()  # the simpler candidates whose encompassing test a sentence has quoted
    if lead is not None and lead != lowest and lowest in lead_form_p and lead_form_p[lowest] <= thr:
        said.add(lowest)
        if form_of != lowest:
            low = diag.candidate(lowest)
            lines.append(f"{low.effect} has the lowest held-out RMSE ({low.heldout_rmse:.3f} deg), but {lead}, the "
                         f"richer form of the same lag, predicts what {low.effect} leaves in the residuals "
                         f"({form_p_text(diag.candidate(lead), lowest, thr)}), so {lead} leads.")
    elif lead is not None and lead != lowest:
        low = diag.candidate(par["lowest_heldout"])
        lines.append(f"{low.effect} has the lowest held-out RMSE ({low.heldout_rmse:.3f} deg) but is another form of "
                     f"{lead} and not significantly better than it (paired t = "
                     f"{-par['t_vs_lowest'].get(low.effect, float('nan')):.2f} <= "
                     f"{diag.settings['evidence_threshold_t']:.2f}), so {lead} is the form weighed against the others.")
    if par.get("preferred_simpler") == c.effect and c.effect in enc:
        lo = diag.candidate(lead)
        lines.append(f"Parsimony: {lo.effect} {leads(lo)}, but what it "
                     f"predicts in the residuals {c.effect} leaves is not significant ("
                     + (form_p_text(lo, c.effect, thr) if c.effect in lo.extra.get("form_test_p", {}) else
                        f"encompassing test p = {enc[c.effect]:.3g} > {thr:.3g}")
                     + "): the data do not ask for its extra parameters, so the simpler "
                     f"effect is the verdict ({lo.effect} is not excluded).")
    elif lead == c.effect and set(enc) - said and not form_of:
        lines.append("Against the simpler " + ", ".join(
            f"{k}: the residuals it leaves hold what {c.effect} predicts (encompassing test p = {v:.3g} <= {thr:.3g})"
            for k, v in enc.items() if k not in said) + ".")
    elif par.get("preferred_simpler") == c.effect:
        lo = diag.candidate(lead)
        lines.append(f"Parsimony: {lo.effect} {leads(lo)} but is not "
                     f"significantly better than {c.effect} (paired t = "
                     f"{par['t_vs_lowest'].get(c.effect, float('nan')):.2f}"
                     f" < {diag.settings['evidence_threshold_t']:.2f}) and "
                     + ("fits a free time course of its own, which can imitate the simpler effect's"
                        if complexity(lo)[0] > complexity(c)[0] else
                        f"needs more parameters ({lo.extra.get('k_eff', float('nan')):.0f} vs "
                        f"{c.extra.get('k_eff', float('nan')):.0f} effective)")
                     + "; the simpler effect is the verdict.")
    if par.get("richer_form_of"):
        lag = par["richer_form_of"]
        lines.append(f"{lag} and {c.effect} are two forms of one lag, and {c.effect} predicts what {lag} leaves in "
                     f"the residuals ({form_p_text(c, lag, thr)}): the richer form is named.")
    beside = beside_own_text(diag)
    if beside:
        lines.append(beside)
    weighed = set((diag.settings.get("parsimony") or {}).get("beside_own", {}).values()) if beside else set()
    others = [o.effect for o in diag.candidates if o.supported and o.effect != c.effect and o.effect not in weighed]
    if others:
        lines.append("Also supported (partly mimicking the same misfit, or further effects): " + ", ".join(others)
                     + "; refit with the verdict effect added and diagnose again to separate them.")
    if diag.budget is not None:
        # the route the decision recorded (decision.significance_route); a diagnosis saved before it: the held-out
        by = "own" if own else c.extra.get("significant_by")
        which = {"own": "its own", "full-data": "the full-data", "both": "the held-out and the full-data"}.get(
            by, "the held-out")
        lines.append(f"The variance budget is scored after adding {c.effect}: "
                     f"{remainder_text(diag.budget, c.effect).split(': ', 1)[1]}. That is about the rest, not "
                     f"about {c.effect}, which {which} test above names.")
    return " ".join(lines)


def form_p_text(c, simpler: str, thr: float) -> str:
    """"encompassing test p = P <= THR" (or "> THR") for candidate ``c``'s test against ``simpler``
    (:func:`~rce_gtsam.diagnosis.evidence.form_test`), saying where P is the smaller of two fits' p times 2."""
    p = c.extra['form_test_p'][simpler]
    text = f"encompassing test p = {p:.3g} {'<=' if p <= thr else '>'} {thr:.3g}"
    raw = c.extra.get("form_test_p_per_fit", {}).get(simpler, {})
    if len(raw) > 1:
        text += (f": the smaller p of its {len(raw)} fits, {' and '.join(f'{v:.3g}' for v in raw.values())}, "
                 f"times {len(raw)}")
    return text


def _support_label(c) -> str:
    """The report's "supported" cell: yes / no, or the lag it is the richer form of
    (:func:`~rce_gtsam.diagnosis.decision.support_richer_forms`)."""
    form_of = c.extra.get("supported_as_form_of")
    if form_of:
        return f"yes, as the richer form of {form_of}"
    if c.supported:
        return "yes"
    return "no (implausible fit)" if c.extra.get("significant") and c.extra.get("implausible") else "no"


def render_diagnosis_report(diag: Diagnosis) -> str:
    """Readable text report of a diagnosis."""
    b = diag.baseline
    st = diag.settings
    n_effects = st.get("n_findings", len(diag.candidates))
    out = ["[[Diagnosis]]",
           f"    baseline: rank-1 (kappa_e z_t), {b.Y.shape[0]} edges x {b.Y.shape[1]} frames, "
           f"{b.n_obs} observations; response {st['response']}; weighted {st['weighted']}",
           f"    held-out scheme: {st['n_folds']} contiguous test blocks, buffer {st['buffer_frames']} frames "
           "each side, "
           f"z estimated on half the edges and scored on the other half; evidence threshold t > "
           f"{st['evidence_threshold_t']:.2f} (alpha {st['alpha']} / {n_effects} effects"
           f"{'' if n_effects == len(diag.candidates) else ', forms of one effect sharing its share'}) and AIC lower",
           f"    z on held-out frames estimated from {len(st['edge_halves'][0])} edges, scored on "
           f"{len(st['edge_halves'][1])} (and swapped); the two sets share no tracked node: "
           f"{'yes' if st.get('node_disjoint_halves') else 'no (too few edges)'}",
           f"    residual lag-1 autocorrelation {st.get('residual_lag1_autocorrelation', float('nan')):.2f}: "
           f"effective sample {st.get('n_eff', float('nan')):.0f} of {st.get('n_obs', float('nan')):.0f} observations "
           f"({st.get('frames_eff', float('nan')):.0f} effective frames); AIC/BIC use it",
           "[[Where the baseline fails]]",
           f"    overall residual RMS {diag.residual_summary['overall_rms_deg']:.3f} deg; fit RMSE {b.rmse:.3f}, "
           f"held-out RMSE {diag.baseline_heldout_rmse:.3f} deg"]
    for w in diag.worst_edges:
        out.append(f"    worst edge {w['edge']:<10} residual RMS {w['residual_rms_deg']:.3f} deg "
                   f"({w['ratio_to_overall']:.2f}x overall)")
    for w in diag.worst_frames:
        out.append(f"    worst frames {w['first_frame']}-{w['last_frame']}: residual RMS "
                   f"{w['residual_rms_deg']:.3f} deg "
                   f"({w['ratio_to_overall']:.2f}x overall)")
    if diag.budget is not None:
        bd = diag.budget
        pc = lambda v: 100.0 * bd.share(v)  # noqa: E731
        named = diag.verdict_effect or diag.verdict
        out.append("[[Variance budget]]  (deg^2 over scored segment-frames; share of total"
                   + (f"; scored for the model with {named}, the verdict" if named and bd.effects else "") + ")")
        out.append(f"    total {bd.total:.4g}   rank-1 {bd.rank1:.4g} ({pc(bd.rank1):.0f}%)   "
                   + "".join(f"{k} {v:.3g} ({pc(v):.0f}%)   " for k, v in bd.effects.items())
                   + f"noise floor {bd.noise_floor:.4g} ({pc(bd.noise_floor):.0f}%)   unexplained {bd.unexplained:.3g} "
                   f"+/- {bd.unexplained_se:.2g} ({pc(bd.unexplained):+.0f}%)")
        out.append(f"    status {bd.status}" + (f" ({bd.reason.replace('_', ' ')})" if bd.reason else "") + ": "
                   + remainder_text(bd, named if named and bd.effects else None))
        nf = diag.noise_floor
        out.append("    noise floor from segment stretch (inextensibility) x across/along ratio "
                   f"{nf.across_over_along:.2f}; "
                   f"{int(nf.valid.sum())}/{len(nf.valid)} segments consistent, others use the white-noise lower bound")
    out.append("[[Candidates]]  (held-out RMSE before -> after, deg)")
    out.append(f"    {'effect':<12} {'held-out RMSE':>22} {'change':>8} {'evidence t':>11} {'score p':>9} {'dAIC':>10} "
               f"{'dBIC':>10}  supported")
    for c in diag.candidates:
        sp = c.extra.get("score_p")
        out.append(f"    {c.effect:<12} {diag.baseline_heldout_rmse:9.4f} -> {c.heldout_rmse:9.4f} "
                   f"{-c.improvement_pct:+7.1f}% {c.evidence:11.2f} {'-' if sp is None else f'{sp:.4f}':>9} "
                   f"{c.delta_aic:10.1f} {c.delta_bic:10.1f}  {_support_label(c)}")
    if any(c.extra.get("score_p") is not None for c in diag.candidates):
        how = {"own_whitened": "its directions from the fit's own excitation, scored across segments by GLS",
               "other_rows": "its directions from the other node-disjoint segments' excitation",
               "between_rows": "do two node-disjoint sets of segments' residuals move together"}
        methods = "; ".join(f"{c.effect}: {how.get(c.extra.get('score_excitation'), 'phase-randomised null')}"
                            for c in diag.candidates if c.extra.get("score_p") is not None)
        out.append(f"    score p: full-data score test where an effect has one ({methods}); "
                   f"such an effect is significant when t > {st['evidence_threshold_t_split']:.2f}, or p <= "
                   f"{st['score_threshold_p']:.3g} with t > {st.get('support_threshold_t', float('-inf')):.2f} "
                   f"(a full-data test alone names nothing; {calibrated_note(diag)}), and supported only if the "
                   f"held-out RMSE also falls and the fit is plausible physics")
    enc = (st.get("parsimony") or {}).get("encompassing_p") or {}
    if enc:
        lo = st["parsimony"].get("leading", st["parsimony"]["lowest_heldout"])
        out.append(f"    encompassing test (does {lo} predict what a simpler supported candidate leaves?): "
                   + ", ".join(f"vs {k} p = {v:.4f}" for k, v in enc.items())
                   + f"; the simpler one is named unless p <= {st['encompassing_threshold_p']:.3g}")
    out.append("[[Verdict]]")
    none_text = {"adequate": "none (the rank-1 model is adequate: the residual is at the noise floor)",
                 "misses": "none of the candidates, but the rank-1 model misses more than noise",
                 "inconclusive": "none of the candidates; whether the rest is noise is inconclusive",
                 "untested": "none (no candidate beats the rank-1 model on held-out frames)",
                 "uncalibrated": "none named (the diagnosis is not calibrated for this analysis' settings)"}
    form = (f" (in the form {diag.verdict_effect})"
            if diag.verdict_effect not in (None, diag.verdict) else "")
    out.append(f"    {diag.verdict or none_text.get(diag.status, 'none')}{form}")
    out.append("    " + diag.explanation)
    if diag.verdict is not None:
        out.append("")
        out.append(render_fit_report(diag.verdict_candidate.fit, diag.edge_labels, max_rows=12))
    return "\n".join(out)
