"""The evidence step of the diagnosis: each candidate's fit, held-out error and tests, typed; no decision.

:func:`heldout_setting` fixes what every model is scored on (folds, the node-disjoint row sets, the CV buffer,
the baseline's held-out error); :func:`candidate_evidence` runs one candidate's tests on it (the held-out fold
t, the full-data score test, the information criteria, plausibility); :func:`drift_checks` the tests an
offset/creep needs besides its fold t (held-out null, shared course, drift layout); :func:`maxt_tests` the
family-wise sign-flip test; :func:`form_test` the encompassing test between two forms of one lag. Which of
them run, and at which level each is read, is :mod:`rce_gtsam.diagnosis.decision`'s; every test's result also
comes in the common shape (:class:`~rce_gtsam.diagnosis.result.TestResult`) with its null and its calibration
record. Each test lives in its own module, whose docstring holds its design and measurements.

Units: degrees (errors), deg^2 (MSE), frames.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from ..model import ModelFit
from ..model.series import loss_difference_test
from ..model.starts import alternative_starts, choose_start, solve_from_starts, start_from
from .parallel import map_candidates
from .drift_pattern import drift_pattern_result, drift_pattern_test
from .encompassing import encompassing_result, encompassing_test
from .heldout import fold_t_result, frame_loss, heldout_errors, paired_t
from .heldout_null import heldout_gain_null_test, heldout_null_result
from .information import effective_ic, effective_sample
from .maxt import maxt_result, sign_flip_max_t
from .plausibility import PlausibilityContext, implausibility, implausibility_result
from .score_dispatch import effect_score_test, score_result
from .score_test import ScoreTest, half_fits, shared_time_course_test
from .settings import CV_ITER, FULL_ITER
from .tracker_signature import away_from_gaps, shared_course_away_result


@dataclass
class HeldoutSetting:
    """What every model is scored on: the data Y (E, T, deg), weights W, root distances s; the fold ``blocks``
    ([a, b) frames), the two row sets ``halves`` (node-disjoint where ``node_disjoint``), the CV buffer ``gap``
    (frames); the rank-1 baseline (``base_model``, ``base``) and its held-out error: fold MSE ``b_mse`` (deg^2,
    the folds ``used``), RMSE ``b_rmse`` (deg), per-frame loss ``b_loss``, held-out prediction ``b_pred`` (E, T);
    ``total_var``: the bending variance over the scored entries (deg^2); ``seed``: every surrogate's seed."""

    Y: np.ndarray
    W: np.ndarray
    s: np.ndarray
    blocks: list
    halves: tuple
    node_disjoint: bool
    gap: int
    block_length: int
    base_model: object
    base: ModelFit
    b_mse: np.ndarray
    b_rmse: float
    b_loss: np.ndarray
    b_pred: np.ndarray
    used: np.ndarray
    total_var: float
    seed: int
    hfits: list | None = None
    ess: dict = field(default_factory=dict)
    base_ic: dict = field(default_factory=dict)
    plausibility: PlausibilityContext | None = None
    _shared: list = field(default_factory=list)  # the baseline's shared-course test, once run

    @property
    def n_used(self) -> int:
        return int(self.used.sum())

    def shared_course(self) -> ScoreTest:
        """The baseline's shared-time-course test (:func:`~rce_gtsam.diagnosis.score_test.shared_time_course_test`,
        the second excitation's score test: the same call with the same seed), run once."""
        if not self._shared:
            self._shared.append(shared_time_course_test(self.base, self.halves, seed=self.seed))
        return self._shared[0]


def full_fits(base_model, base: ModelFit, effects, Y, W, s, halves, workers: int = 1) -> list:
    """Each candidate's fit on all frames, from the converged baseline: [(effect, model, fit, starts)], several
    starts where the effect proposes them, the one that predicts one row set from the other's excitation best
    kept (:func:`rce_gtsam.model.starts.solve_from_starts`: a local search can end in an optimum that fits noise).
    The full fit is the only place an effect's shared parameters are fitted; fold refits start from it.
    ``workers``: processes the fits are spread over (:func:`~rce_gtsam.diagnosis.parallel.map_candidates`): every
    candidate's plain fit, then every alternative start of every candidate, each a task of its own."""
    def start():  # each fit its own copy of the baseline (a fit may change its start in place)
        return base.kappa.copy(), base.z.copy(), {}

    models = [base_model + eff for eff in effects]
    plain = map_candidates(start_from, [(m, Y, W, s, start(), FULL_ITER) for m in models], workers)
    alts = [(i, alt) for i, (m, f) in enumerate(zip(models, plain)) for alt in alternative_starts(m, f, start())]
    refits = map_candidates(start_from, [(models[i], Y, W, s, alt, FULL_ITER) for i, alt in alts], workers)
    out = []
    for i, (eff, model) in enumerate(zip(effects, models)):
        full, starts = choose_start([plain[i]] + [f for (j, _), f in zip(alts, refits) if j == i], halves)
        out.append((eff, model, full, starts))
    return out


def heldout_setting(base_model, base: ModelFit, fulls: list, Y, W, s, blocks, halves, node_disjoint: bool,
                    block_length: int, seed: int) -> HeldoutSetting:
    """The held-out setting of the module's note. The CV buffer is the larger of ``block_length`` and the longest
    memory any fitted term has (a tip lag longer than the buffer would make test frames depend on the training
    frames' data); the same buffer then applies to every model alike."""
    memory = max([0.0] + [e.memory_frames(st) for _, _, f, _ in fulls for e, st in zip(f.model.effects, f.states)])
    gap = max(int(block_length), int(math.ceil(memory)))
    E, T = Y.shape
    b_pred = np.full((E, T), np.nan)
    b_sse, b_cnt, b_sse_t, b_cnt_t = heldout_errors(base_model, base, Y, W, s, blocks, halves, gap, per_frame=True,
                                                    prediction=b_pred)
    used = b_cnt > 0
    scored = np.isfinite(b_pred) & np.isfinite(Y)
    total_var = float(np.mean((Y - np.nanmean(Y, axis=1, keepdims=True))[scored] ** 2)) if scored.any() else 0.0
    ess = effective_sample(base)
    return HeldoutSetting(
        Y=Y, W=W, s=s, blocks=blocks, halves=halves, node_disjoint=node_disjoint, gap=gap, block_length=block_length,
        base_model=base_model, base=base, b_mse=b_sse[used] / b_cnt[used],
        b_rmse=float(math.sqrt(b_sse[used].sum() / max(b_cnt[used].sum(), 1))), b_loss=frame_loss(b_sse_t, b_cnt_t),
        b_pred=b_pred, used=used, total_var=total_var, seed=seed,
        # the score test needs two row sets that share no tracked node (their noise is then independent)
        hfits=half_fits(base_model, Y, W, s, halves) if node_disjoint else None,
        ess=ess, base_ic=effective_ic(base, ess), plausibility=PlausibilityContext.from_fit(base))


@dataclass
class CandidateEvidence:
    """One candidate's evidence (:func:`candidate_evidence`): its ``effect``, full ``fit`` and ``starts`` record;
    held-out RMSE (deg), fold MSE (deg^2), fold-paired t ``evidence``, improvement (%), delta AIC / BIC on the
    effective sample; ``score``: the full-data score test (None where the effect has none or the row sets share
    nodes); ``basis``: the effect's per-segment time courses (K, T) or None; ``implausible``: reasons;
    ``numbers``: the JSON record of the above (the candidate's ``extra``); ``tests``: by name, in the common
    shape."""

    effect: object
    fit: ModelFit
    starts: dict
    heldout_rmse: float
    fold_mse: np.ndarray
    evidence: float
    improvement_pct: float
    delta_aic: float
    delta_bic: float
    score: ScoreTest | None
    basis: np.ndarray | None
    implausible: tuple
    numbers: dict
    tests: dict


def candidate_evidence(h: HeldoutSetting, eff, model, full: ModelFit, starts: dict, levels) -> CandidateEvidence:
    """The tests of one candidate against the baseline on the setting ``h``; ``levels``
    (:class:`~rce_gtsam.diagnosis.decision.Levels`) only labels each test with the level it is read at."""
    Y, W, s = h.Y, h.W, h.s
    sse, cnt, sse_t, cnt_t = heldout_errors(model, full, Y, W, s, h.blocks, h.halves, h.gap, cv_iter=CV_ITER,
                                            per_frame=True)
    mse = sse[h.used] / np.maximum(cnt[h.used], 1)
    rmse = float(math.sqrt(sse[h.used].sum() / max(cnt[h.used].sum(), 1)))
    dm = loss_difference_test(h.b_loss, frame_loss(sse_t, cnt_t), h.block_length)
    ev = paired_t(h.b_mse, mse)
    ic = effective_ic(full, h.ess)
    daic, dbic = ic["aic"] - h.base_ic["aic"], ic["bic"] - h.base_ic["bic"]
    dk = ic["k_eff"] - h.base_ic["k_eff"]
    lr = max(h.ess["n_eff"] * math.log(max(h.base.wsse, 1e-300) / max(full.wsse, 1e-300)), 0.0)
    numbers = {"k_eff": ic["k_eff"], "free_series": ic["free_series"], "delta_k_eff": dk, "lr_statistic": lr,
               "lr_p_value": float(stats.chi2.sf(lr, max(dk, 1e-9))),
               "delta_aic_nominal": full.aic - h.base.aic, "threshold_t": levels.t_crit,
               "full_data_t": dm["t"], "full_data_dof": dm["dof"], "full_data_batch_frames": dm["batch_frames"],
               "heldout_gain_share": (h.b_rmse ** 2 - rmse ** 2) / h.total_var if h.total_var > 0 else 0.0}
    score = (effect_score_test(eff.score_excitation, h.base_model, h.base, Y, W, s, h.hfits, h.halves,
                               lambda rows, kappa, z, s_: eff.test_directions(kappa, z, s_), seed=h.seed)
             if h.hfits is not None else None)
    tests = {}
    if score is not None:
        numbers.update({"score_p": score.p, "score_q": score.q, "score_directions": score.n_directions,
                        "score_threshold_p": levels.p_score, "threshold_t": levels.t_crit_split,
                        "score_z": score.z_equivalent, "score_statistic": score.statistic,
                        "score_excitation": eff.score_excitation})
        if score.peak is not None:
            numbers["score_peak"] = eff.scan_label(score.peak)
        tests["score"] = score_result(score, eff.score_excitation, levels.p_score)
        if eff.score_excitation == "between_rows" and not h._shared:  # the very test the drift checks ask
            h._shared.append(score)
    tests["fold_t"] = fold_t_result(ev, numbers["threshold_t"])
    state = next((st for e, st in zip(full.model.effects, full.states) if e.name == eff.name), {})
    reasons = implausibility(eff, state, len(Y), h.plausibility)
    tests["implausibility"] = implausibility_result(reasons)
    return CandidateEvidence(effect=eff, fit=full, starts=starts, heldout_rmse=rmse, fold_mse=mse, evidence=ev,
                             improvement_pct=100.0 * (1 - rmse / h.b_rmse) if h.b_rmse > 0 else 0.0,
                             delta_aic=daic, delta_bic=dbic, score=score, basis=eff.heldout_time_basis(Y.shape[1]),
                             implausible=reasons, numbers=numbers, tests=tests)


def drift_checks(h: HeldoutSetting, c: CandidateEvidence, levels) -> dict:
    """What an effect of slow per-segment courses (``c.basis``) must show besides its fold t, because tracker drift
    gives every segment such a course too (see :mod:`rce_gtsam.diagnosis.heldout_null`,
    :mod:`rce_gtsam.diagnosis.drift_pattern`, :mod:`rce_gtsam.diagnosis.tracker_signature`): a held-out gain beyond
    phase surrogates of the residuals, a course common to two node-disjoint row sets (each node drifts on its
    own), shown away from the frames where nodes were lost as well, or trends laid out along the branch
    otherwise than a node's error reaches the bends. Adds their results to ``c.tests`` and returns their JSON
    record (in the order the diagnosis' JSON has always had)."""
    null = heldout_gain_null_test(h.base, h.blocks, h.gap, c.basis, seed=h.seed)
    pattern = drift_pattern_test(h.base, c.basis, seed=h.seed)
    shared_p = h.shared_course().p if h.node_disjoint else None
    out = {}
    if shared_p is not None:
        c.tests["shared_course"] = score_result(h.shared_course(), "between_rows", levels.p_score)
        if shared_p <= levels.p_score:
            # a course common to the row sets must show away from the frames where nodes were lost, too (the
            # tracker's errors sit next to its gaps, at the same gusty frames in every set)
            away = shared_time_course_test(away_from_gaps(h.base), h.halves, seed=h.seed)
            out["shared_course_p_away_from_gaps"] = away.p
            c.tests["shared_course_away_from_gaps"] = shared_course_away_result(away, levels.p_score)
    c.tests["heldout_null"] = heldout_null_result(null, levels.alpha)
    if pattern is not None:
        c.tests["drift_pattern"] = drift_pattern_result(pattern, levels.alpha)
    out.update({"heldout_null_p": null.p, "heldout_null_threshold_p": levels.alpha,
                "shared_course_p": shared_p, "shared_course_threshold_p": levels.p_score,
                "drift_pattern_p": None if pattern is None else pattern.p,
                "drift_pattern_threshold_p": levels.alpha})
    return out


def maxt_tests(h: HeldoutSetting, results: list, alpha: float):
    """The family-wise sign-flip max-T test of every candidate's fold MSE against the baseline's
    (:mod:`rce_gtsam.diagnosis.maxt`); adds each candidate's result to its ``tests`` and returns the
    :class:`~rce_gtsam.diagnosis.maxt.MaxTResult`."""
    mt = sign_flip_max_t(h.b_mse, [c.fold_mse for c in results], alpha=alpha, seed=h.seed)
    for c, t, p in zip(results, mt.t, mt.p_adjusted):
        c.tests["maxt"] = maxt_result(float(t), float(p), alpha)
    return mt


def candidate_fits(c) -> dict:
    """The fits of candidate ``c`` an encompassing test weighs, by name: ``"chosen"`` (its fit, the start chosen
    for the held-out score) and, where it is another, ``"maximum_likelihood"`` (the lowest in-sample fit among
    its starts, :attr:`~rce_gtsam.diagnosis.result.CandidateResult.ml_fit`)."""
    ml = getattr(c, "ml_fit", None)
    return {"chosen": c.fit} if ml is None else {"chosen": c.fit, "maximum_likelihood": ml}


def form_test(simple, richer, Y, W, s, halves, seed: int):
    """The encompassing test (:func:`~rce_gtsam.diagnosis.encompassing.encompassing_test`) of whether candidate
    ``richer``'s model predicts what ``simple``'s leaves, run from each of ``richer``'s fits
    (:func:`candidate_fits`) against ``simple``'s fit; the smallest p, Bonferroni-adjusted for the fits tried
    (times their number, at most 1). Returns (p, z of that fit's test, {fit: raw p}) or None where the test
    does not apply."""
    raw = {}
    for name, fit in candidate_fits(richer).items():
        test = encompassing_test(simple.fit, fit, Y, W, s, halves, seed=seed, max_iter=FULL_ITER)
        if test is None:
            return None
        raw[name] = test
    low = min(raw.values(), key=lambda t: t.p)
    return min(1.0, low.p * len(raw)), low.z, {k: t.p for k, t in raw.items()}


def form_asker(h: HeldoutSetting, levels):
    """The ``ask(simple, richer)`` the decision calls where it needs an encompassing test
    (:func:`~rce_gtsam.diagnosis.decision.support_richer_forms`, :func:`~rce_gtsam.diagnosis.verdict.
    weigh_the_leading`): :func:`form_test` on the setting ``h``, its result also added to ``richer.tests`` as
    ``"encompassing[<simple>]"``, read at the full-data tests' level."""
    def ask(simple, richer):
        test = form_test(simple, richer, h.Y, h.W, h.s, h.halves, h.seed)
        if test is not None:
            richer.tests[f"encompassing[{simple.effect}]"] = encompassing_result(simple.effect, test[0], test[1],
                                                                                levels.p_score)
        return test
    return ask


def nested_heldout(h: HeldoutSetting, bend, own) -> dict | None:
    """The held-out test of bend candidate ``bend`` beside an own-family candidate ``own``: the model with both
    terms (``own``'s fitted state and ``bend``'s as starts, refitted on all frames from ``bend``'s kappa and z,
    several starts as for every candidate: :func:`~rce_gtsam.model.starts.solve_from_starts`), scored on the same
    folds and row sets as every candidate. Returns {"t": fold-paired t of ``own``'s fold MSE against the nested
    model's (> 0: the bend term lowers the error beyond ``own``'s term), "heldout_rmse": the nested model's (deg),
    "improvement_over_own_pct"; where ``bend`` has a per-frame course (a second excitation's w) and ``own`` a swing
    course: "course_r2", "course_p" (:func:`course_explained` on the swing's courses w, w (z - mean z), w^2, the
    baseline's z)} or None where a fold of ``own`` has no counterpart. Units: deg, t unitless."""
    effs = list(own.fit.model.effects) + [e for e in bend.fit.model.effects if e.name != own.effect]
    states = {e.name: st for e, st in zip(own.fit.model.effects, own.fit.states)}
    states.update({e.name: st for e, st in zip(bend.fit.model.effects, bend.fit.states)})
    model = h.base_model.with_effects(effs)
    full, _ = solve_from_starts(model, h.Y, h.W, h.s, h.halves,
                                start=(bend.fit.kappa.copy(), bend.fit.z.copy(), states), max_iter=FULL_ITER)
    sse, cnt = heldout_errors(model, full, h.Y, h.W, h.s, h.blocks, h.halves, h.gap, cv_iter=CV_ITER)
    mse = sse[h.used] / np.maximum(cnt[h.used], 1)
    if len(mse) != len(own.fold_mse) or not (cnt[h.used] > 0).all():
        return None
    rmse = float(math.sqrt(sse[h.used].sum() / max(cnt[h.used].sum(), 1)))
    out = {"t": paired_t(own.fold_mse, mse), "heldout_rmse": rmse,
           "improvement_over_own_pct": 100.0 * (1.0 - rmse / own.heldout_rmse) if own.heldout_rmse > 0 else 0.0}
    eff = next(e for e in own.fit.model.effects if e.name == own.effect)
    course = next((np.asarray(v, float) for st in bend.fit.states for v in st.get("latents", {}).values()
                   if np.ndim(v) == 1 and len(v) == h.Y.shape[1]), None)
    if course is not None and hasattr(eff, "course"):
        w, zc = eff.course(h.Y.shape[1]), h.base.z - np.mean(h.base.z)
        if np.any(w):
            out.update(course_explained(course, np.stack([w, w * zc, w * w]), seed=h.seed))
    return out


def course_explained(course: np.ndarray, C: np.ndarray, seed: int = 0, n_surrogates: int = 999) -> dict:
    """How much of a bend candidate's per-frame ``course`` (T,) the own-family term's courses ``C`` (K, T) explain:
    R^2 of its least-squares fit on them (with a constant), and the p-value against phase surrogates of the course
    (its spectrum kept, so its autocorrelation is the null's: an independent course of the same colour),
    p = (1 + #{surrogates >= observed}) / (1 + n). {"course_r2", "course_p"}; unitless."""
    T = len(course)
    A = np.column_stack([np.ones(T), (C - C.mean(axis=1, keepdims=True)).T])
    Q = np.linalg.qr(A)[0][:, 1:]  # orthonormal columns of the centred courses
    def r2(x):  # rows of x: courses
        xc = x - x.mean(axis=-1, keepdims=True)
        return np.sum((xc @ Q) ** 2, axis=-1) / np.maximum(np.sum(xc * xc, axis=-1), 1e-300)
    X = np.fft.rfft(course - course.mean())
    ph = np.random.default_rng(seed).uniform(0.0, 2 * np.pi, (n_surrogates, len(X)))
    ph[:, 0] = 0.0
    if T % 2 == 0:
        ph[:, -1] = 0.0
    null = r2(np.fft.irfft(X[None] * np.exp(1j * ph), n=T, axis=1))
    obs = float(r2(course[None])[0])
    return {"course_r2": obs, "course_p": float((1 + np.sum(null >= obs)) / (1 + n_surrogates))}


def beside_asker(h: HeldoutSetting):
    """The ``beside(bend, own)`` the decision calls where a bend candidate and an own-family one are both
    supported (:func:`~rce_gtsam.diagnosis.verdict.weigh_beside_own`): :func:`nested_heldout` on the setting
    ``h``."""
    return lambda bend, own: nested_heldout(h, bend, own)
