"""Where does the rank-1 model fail, and which physical effect is missing?

:func:`diagnose` fits the baseline y[e, t] = kappa_e z_t and, for each candidate effect, the baseline extended by
that effect (:mod:`rce_gtsam.effects`), and names the effect the data ask for, in four steps on one screen:

1. **baseline** — the rank-1 fit, the fold blocks and the two row sets that share no tracked node
   (:mod:`rce_gtsam.diagnosis.heldout` explains the held-out scheme);
2. **evidence** — each candidate's fit, held-out error and tests (:mod:`rce_gtsam.diagnosis.evidence`; each test
   in its own module with its null and its calibration: ``heldout`` (fold t), ``score_test``, ``heldout_null``,
   ``drift_pattern``, ``tracker_signature``, ``encompassing``, ``maxt``, ``plausibility``; ``information`` for
   the AIC on the effective sample);
3. **decision** — significant, supported, the verdict: the rule is written down in
   :mod:`rce_gtsam.diagnosis.decision` (its helpers between supported candidates in
   :mod:`rce_gtsam.diagnosis.verdict`);
4. **report** — the explanation and the text report (:mod:`rce_gtsam.diagnosis.explain`), with the residual
   analysis (:mod:`rce_gtsam.diagnosis.sysid`) and the variance budget against the noise floor
   (:mod:`rce_gtsam.diagnosis.budget`).

The results are typed in :mod:`rce_gtsam.diagnosis.result` (:class:`Diagnosis`, :class:`CandidateResult`,
:class:`~rce_gtsam.diagnosis.result.TestResult`). Units: degrees, frames.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..jsonutil import jsonable
from ..model import ResponseModel, validate_inputs
from ..model.row_sets import (edge_halves, edge_nodes_from_labels, node_disjoint_split,  # noqa: F401 (re-exported)
                              shared_node_matrix)
from ..presets import DEFAULT, ComplianceConfig
from . import decision
from .budget import variance_budget
from .evidence import beside_asker, candidate_evidence, drift_checks, form_asker, full_fits, heldout_setting, maxt_tests
from .explain import explain, render_diagnosis_report
from .heldout import fold_blocks
from .information import effective_ic, effective_sample  # noqa: F401 (re-exported)
from .misfit import resolve_effects, residual_statistics, worst_edges_and_frames  # noqa: F401 (re-exported)
from .noise_floor import NoiseFloor
from .one_node import OneNodeCheck, carrying_node, gain_window, node_id, one_node_text, projected_row, rows_without
from .own_family import own_test_significant
from .parallel import map_candidates
from .result import CandidateResult, Diagnosis  # noqa: F401 (re-exported)
from .settings import BLOCK_LENGTH, N_FOLDS, RESOLUTION
from .sysid import residual_analysis
from .tracker_signature import near_gap_share, tracker_text
from .verdict import finding_of, is_own_family


def diagnose(Y, weights=None, root_distance=None, effects=None, n_folds: int | None = None, seed: int = 0,
             block_length: int = BLOCK_LENGTH, prior_strength: float | None = None, response: str | None = None,
             alpha: float = 0.05, edge_labels=None, frames=None, edge_nodes=None,
             config: ComplianceConfig | None = None, noise_floor: NoiseFloor | None = None,
             resolution: float = RESOLUTION, outside_domain: tuple[str, ...] = (),
             check_one_node: bool = True, node_sensitivity: dict | None = None, workers: int = 1) -> Diagnosis:
    """Diagnose which physical effect the rank-1 model misses.

    Y: (E, T) bend response in degrees (NaN = missing/outlier); weights: (E, T) >= 0 or None;
    root_distance: (E,) normalised root distance of each row's child (default: row order);
    effects: candidate names or :class:`~rce_gtsam.effects.Effect` instances (default: every registered effect);
    n_folds: cross-validation blocks (default :data:`N_FOLDS`; reduced so that blocks are >= block_length frames);
    seed: RNG seed of the stratified edge split; block_length: frames, the bootstrap's block length,
    used as the CV buffer and the smallest test block; prior_strength, response: the core model's
    settings (ComplianceConfig); alpha: family-wise significance level of the verdict; edge_nodes: per row,
    the tracked node ids its bend angle is computed from (default: parsed from ``"joint->child"`` edge
    labels, else rows are taken as a chain in root-distance order) — held-out edge sets never share one.
    config: the whole compliance config of the core model (the analysis preset's: the baseline is then the
    fit ``rce analyze`` reports); without it, the default preset's (the fit ``ResponseModel()`` and
    ``rce analyze`` make), with ``prior_strength`` / ``response`` replaced where given.
    resolution: the smallest share of the bending variance an effect must take off the held-out error to be
    named (default :data:`RESOLUTION`, 0.1 %), however significant: on noise-free data the pipeline's own
    small distortions (the smoother, the angle geometry) are "significant" at any size, and a second mode
    worth 1e-5 of the variance is no finding.
    outside_domain: the analysis' settings under which the diagnosis is not calibrated
    (:func:`~rce_gtsam.diagnosis.domain.settings_outside_domain`, which :func:`~rce_gtsam.diagnosis.io.diagnose_result`
    passes): every test still runs, but no effect is named (``settings["verdict_outside_domain"]`` keeps
    the one that would have been) and the status reads ``"uncalibrated"``.
    check_one_node: a named bend effect must hold without the node that carries most of its gain
    (:mod:`rce_gtsam.diagnosis.one_node`; the check's own re-run passes False).
    node_sensitivity: {node id: (E, 2) deg of each row's bend per px of that node's displacement in x and y}
    (:func:`~rce_gtsam.diagnosis.one_node.bend_jacobian`); with it the one-node check keeps, of the carrying node's
    bends, what no displacement of that node can move (:func:`~rce_gtsam.diagnosis.one_node.projected_row`); without
    it, it leaves them out.
    workers: processes the candidates' fits and tests are spread over (:mod:`~rce_gtsam.diagnosis.parallel`; the
    same diagnosis as serially, 1 = serial).
    """
    Y, W, s = validate_inputs(Y, weights, root_distance)
    E, T = Y.shape
    labels = list(edge_labels) if edge_labels is not None else [str(i) for i in range(E)]
    cands = resolve_effects(effects, E)
    if config is None:
        given = {k: v for k, v in (("prior_strength", prior_strength), ("response", response)) if v is not None}
        config = replace(DEFAULT.compliance, **given)
    # 1. baseline: the rank-1 fit, the folds, the two row sets (node-disjoint where the branch allows)
    base_model = ResponseModel(config=config)
    base = base_model.solve(Y, W, s)
    blocks = fold_blocks(T, N_FOLDS if n_folds is None else n_folds, block_length)
    nodes = edge_nodes if edge_nodes is not None else edge_nodes_from_labels(labels)
    shared = shared_node_matrix(s, nodes)
    split = node_disjoint_split(s, shared, seed, edge_nodes=nodes)
    node_disjoint = split is not None
    halves = split if node_disjoint else edge_halves(s, seed)
    # 2. evidence: full fits first (the CV buffer must cover the longest memory any fitted term has)
    fulls = full_fits(base_model, base, cands, Y, W, s, halves, workers)
    h = heldout_setting(base_model, base, fulls, Y, W, s, blocks, halves, node_disjoint, block_length, seed)
    stats_all = residual_statistics(base, cands)
    # an effect read from another channel (own_family: OutOfPlane's lengths) has its own level, outside the family
    lv = decision.levels(alpha, len({e.verdict_name for e in cands if not e.own_family}), h.n_used)
    results = []
    evidence = map_candidates(candidate_evidence, [(h, *f, lv) for f in fulls], workers)
    for (eff, model, full, starts), ev in zip(fulls, evidence):
        # 3. decision, per candidate: significant (with the drift checks where it asks for them), supported
        route = decision.significance_route(ev.tests, lv, both=eff.needs_both_tests, excitation=eff.score_excitation)
        extra, sig = ev.numbers, route is not None
        if "score" in ev.tests:
            extra["support_threshold_t"] = decision.support_t(lv, eff.score_excitation)
        if decision.asks_drift_checks(ev.basis, sig, ev.score is not None):
            extra.update({**drift_checks(h, ev, lv), "significant_by_fold_t": sig})
            sig = decision.drift_rescued(ev.tests)
        if eff.own_family:  # its own test at its own level (own_family.py)
            sig = own_test_significant(eff, base, seed, extra)
            route = "own"
        extra["significant"] = sig
        extra["significant_by"] = route if sig else None
        if starts:
            extra.update({"start_cross_prediction_sse": starts["errors"], "start_chosen": starts["chosen"],
                          "start_lowest_in_sample": starts["lowest_in_sample"]})
        extra["implausible"] = list(ev.implausible)
        results.append(CandidateResult(
            effect=eff.name, fit=full, heldout_rmse=ev.heldout_rmse, fold_mse=ev.fold_mse, evidence=ev.evidence,
            improvement_pct=ev.improvement_pct, delta_aic=ev.delta_aic, delta_bic=ev.delta_bic,
            supported=(decision.own_supported(sig, ev.implausible) if eff.own_family
                       else decision.supported(ev, sig, h.b_rmse, resolution)), statistics=stats_all.get(eff.name, {}),
            extra=extra, tests=ev.tests,
            ml_fit=(starts["lowest_in_sample_fit"] if starts and starts["lowest_in_sample"] != starts["chosen"]
                    else None)))
    results.sort(key=lambda c: c.heldout_rmse)
    mt = maxt_tests(h, results, alpha)
    for c in results:
        c.extra["maxt_p"] = c.tests["maxt"].p
        # the same support with the family-wise max-T test (maxt.py) in place of significance: reported, not used
        c.extra["supported_maxt"] = bool(c.tests["maxt"].fires and decision.earns_its_place(
            c.heldout_rmse, h.b_rmse, c.delta_aic, c.extra["heldout_gain_share"], resolution))
    # 3. decision, between candidates: the lag's richer form, parsimony, the verdict
    results, verdict_effect, parsimony = decision.decide(results, form_asker(h, lv), lv, h.b_rmse, resolution,
                                                         node_disjoint, beside=beside_asker(h))
    named = None if verdict_effect is None else next(c for c in results if c.effect == verdict_effect)
    # 3. decision, last: a named bend effect must not rest on one tracked node (one_node.py)
    one_node = None
    if check_one_node and named is not None and not is_own_family(named):
        one_node = _one_node_check(named, base, Y, W, s, labels, nodes, cands, config, n_folds, seed, block_length,
                                   alpha, resolution, frames, node_sensitivity)
        if one_node is not None:
            named.tests["one_node"] = one_node.as_test()
            named.extra["one_node"] = one_node.as_dict()
            if not one_node.holds:  # not named; an effect read from another channel may still be
                own = [c for c in results if c.supported and is_own_family(c)]
                named = own[0] if own else None
                verdict_effect = None if named is None else named.effect
    verdict = None if named is None else finding_of(named)  # another form of an effect reports that effect
    would_name = verdict
    if outside_domain:  # the tests' calibration does not hold here: nothing is named (domain.py)
        verdict_effect, named, verdict = None, None, None
    # 4. report
    worst_e, worst_f, summary = worst_edges_and_frames(base, labels, block_length, frames)
    settings = {"n_folds": len(blocks), "fold_blocks": blocks, "buffer_frames": h.gap, "block_length": block_length,
                "seed": seed, "alpha": alpha, "evidence_threshold_t": lv.t_crit, "resolution": resolution,
                "support_threshold_t": lv.t_support, "plausibility": jsonable(h.plausibility.__dict__),
                "residual_power_near_gaps": near_gap_share(base),
                "evidence_threshold_t_split": lv.t_crit_split, "score_threshold_p": lv.p_score,
                "heldout_total_variance": h.total_var, "maxt_critical_t": mt.critical_t, "maxt_flips": mt.n_flips,
                "prior_strength": config.prior_strength,
                "response": config.response, "edge_halves": [halves[0].tolist(), halves[1].tolist()],
                "node_disjoint_halves": node_disjoint, "weighted": weights is not None,
                "residual_lag1_autocorrelation": h.ess["rho"], "n_obs": h.ess["n"], "n_eff": h.ess["n_eff"],
                "frames_eff": h.ess["t_eff"], "baseline_k_eff": h.base_ic["k_eff"], "parsimony": parsimony,
                "encompassing_threshold_p": lv.p_score, "n_findings": lv.n_findings,
                "outside_domain": list(outside_domain),
                "verdict_outside_domain": would_name if outside_domain else None,
                "one_node": None if one_node is None else one_node.as_dict(),
                "verdict_withheld": (None if one_node is None or one_node.holds
                                     else {"effect": one_node.effect, "rule": "one_node"})}
    budget = None
    if noise_floor is not None:
        added = {verdict_effect: (named.fit.residuals, named.fit.n_params)} if named is not None else {}
        budget = variance_budget(Y, base.residuals, base.n_params, noise_floor, added, labels, base_kappa=base.kappa)
    analysis = residual_analysis(
        Y, base.kappa, base.z,
        # the noise realisation of the segments where the estimate holds (zero elsewhere)
        np.where(noise_floor.valid[:, None], noise_floor.series_deg, 0.0) if noise_floor is not None else None,
        shared=shared, root_distance=s)
    diag = Diagnosis(baseline=base, baseline_heldout_rmse=h.b_rmse, baseline_fold_mse=h.b_mse, candidates=results,
                     verdict=verdict, verdict_effect=verdict_effect, explanation="", worst_edges=worst_e,
                     worst_frames=worst_f, residual_summary=summary, settings=settings, edge_labels=labels,
                     budget=budget, baseline_frame_loss=h.b_loss, baseline_heldout_prediction=h.b_pred,
                     residual_analysis=analysis, noise_floor=noise_floor, outside_domain=tuple(outside_domain))
    diag = replace(diag, explanation=explain(diag) + tracker_text(settings["residual_power_near_gaps"], labels)
                   + one_node_text(one_node, labels))
    return replace(diag, report_text=render_diagnosis_report(diag))


def _one_node_check(named, base, Y, W, s, labels, nodes, cands, config, n_folds, seed, block_length, alpha,
                    resolution, frames, sensitivity=None):
    """:class:`~rce_gtsam.diagnosis.one_node.OneNodeCheck` of the named candidate: the diagnosis again, for it
    alone, on the other bends plus, where the geometry is known (``sensitivity``), the one row of the carrying
    node's bends that no error of that node reaches (:func:`~rce_gtsam.diagnosis.one_node.projected_row`); None
    where it gains nothing in-sample, too few bends are left, or the rows' nodes are not known."""
    if nodes is None:
        return None
    found = carrying_node(base.residuals, named.fit.residuals, nodes, W)
    if found is None:
        return None
    node, share = found
    keep = rows_without(node, nodes)
    if keep.sum() < 4 or keep.all():
        return None
    Y2, W2, s2 = Y[keep], None if W is None else W[keep], s[keep]
    labels2 = [l for l, k in zip(labels, keep) if k]
    nodes2 = [n for n, k in zip(nodes, keep) if k]
    eff = next(e for e in cands if e.name == named.effect)
    courses = eff.heldout_time_basis(Y.shape[1]) is not None
    # not for an effect of per-segment courses (offset, creep): the drift of the node's neighbours, which the
    # projection keeps, gives that row a course of its own (effect-free user-path renders: 3 offsets named)
    projected = None if courses else projected_row(Y, W, s, node, nodes, sensitivity, np.asarray(base.kappa, float))
    if projected is not None:
        y, w, sp = projected
        Y2, s2 = np.vstack([Y2, y[None]]), np.r_[s2, sp]
        W2 = None if W is None else np.vstack([W2, w[None]])
        labels2 = labels2 + [f"bends of node {node_id(node)}, its error taken out"]
        nodes2 = nodes2 + [tuple(sorted({n for ns, k in zip(nodes, keep) if not k for n in ns} - {node},
                                        key=str))]
    again = diagnose(Y2, W2, s2, effects=[eff], n_folds=n_folds, seed=seed,
                     block_length=block_length, alpha=alpha, edge_labels=labels2,
                     frames=frames, edge_nodes=nodes2, config=config,
                     resolution=resolution, check_one_node=False)
    c = again.candidates[0]
    return OneNodeCheck(effect=named.effect, node=node, share=share,
                        rows=tuple(str(l) for l, k in zip(labels, keep) if not k),
                        fold_t=float(c.evidence), heldout_gain_pct=float(c.improvement_pct),
                        significant=bool(c.extra.get("significant", False)),
                        courses=courses, frames=gain_window(base.residuals, named.fit.residuals, ~keep, W, frames),
                        projected=projected is not None)
