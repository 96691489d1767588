"""Detection benchmark of ``rce_gtsam.diagnosis.diagnose`` on the FULL pipeline: for each hidden effect x seeds (+ effect-
free seeds), is the verdict right, how much does the effect lower held-out RMSE, does kappa error fall?

Per case: ``simulate(SimulationConfig(effects=(name,), seed=s, n_frames=900))`` -> ``analyze(tracks, graph,
preset="default", n_boot=0)`` -> ``result.response`` -> ``diagnose``.

Columns: correct = verdict names the hidden effect (None for effect-free data); dRMSE% verdict = median held-
out RMSE improvement of the verdict effect over the cases where it is right; dRMSE% hidden = median improvement
of the hidden effect's candidate over all seeds; ceiling% = median improvement an oracle would get: 1 -
RMS(Y - truth) / RMS(Y - best rank-1 approximation of the truth), truth put on the pipeline's rest reference
(per-edge mean of Y - truth removed) — the held-out gain available at all at this tracking-noise level;
truth% = median improvement, over all seeds, of the hidden effect's full-data fit over the rank-1 fit in RMS
distance to the noise-free truth (same rest reference as ceiling%): how much closer to the physics the
extended model gets, which the noisy held-out RMSE can only show through the noise; noise/sig = median
RMS(Y - truth) / RMS(truth), the tracking noise left after smoothing relative to the bending signal (the real
plants: residual of the rank-1 fit / its signal = 1.76 on plant 1, 1.17 on plant 2);
klog = kappa log-RMSE against the truth, baseline -> verdict model (baseline when the verdict is None);
s = median diagnose seconds (pipeline excluded; it is timed separately).

Oracle (:func:`rce_gtsam.diagnosis.oracle.oracle_test`): for every case the same held-out test for the hidden effect's own
candidate with its true shared parameters (fitted to the noise-free truth, then kept fixed; per-edge parameters,
kappa and the held-out excitation estimated from the noisy data as for every candidate): "oracle" counts the
cases where it passes the verdict's threshold, the ceiling the verdict reaches toward with this test. For delay,
dynamics and a second excitation, which the verdict also tests on all frames at once
(:mod:`rce_gtsam.diagnosis.score_test`), the oracle's full-data score test runs along the true signature
(:func:`rce_gtsam.diagnosis.oracle.true_signature`, the noise-free truth less its best rank-1 approximation: of each row set
for the cross-fitted tests, of all rows for the delay's refitted one), with the same split thresholds: fold t or
score p, each at half the level. (Until this was the signature, the truth itself was the direction, and the
oracle fired on effect-free data: 12-14 of 40 recordings at p <= 0.005 along a hypothetical effect's response.) "knows z" counts the same for the noise-free truth itself as the prediction (it knows the
excitation and kappa without estimating them, and fires on effect-free data too: not a ceiling for a diagnosis).

Usage: python benchmarks/bench_diagnose.py [--seeds 10] [--frames 900] [--effects none,delay,...]
       [--strength-mult 0.5,1,1.5,2,3]  (hidden effect strengths, x the simulator's defaults)
       [--noise-free]  (noise-free tracks through the same pipeline)
       [--held-out]  (each effect in its held-out form, rce_gtsam.sim.simulate.EFFECT_FORMS, under HELD_OUT_NOISE:
                      physics and noise the diagnosis was not written for, standing in for another simulator)
       [--shape n_nodes=8,fps=60,branch_layout=tree,root_sway_deg=3]  (recordings of another shape than the
                      simulator's default: 20-node chain, 30 fps; --frames sets their length)
       [--matrices]  (fast: simulator equations + noise instead of the pipeline, for development)
       [--artifacts FAMILY[,FAMILY] --artifact-scale X]  (tracker artifacts, rce_gtsam.sim.artifacts, at X times
                      their measured size on top of the tracker noise; benchmarks/bench_artifacts.py runs the
                      effect-free grid per family)
       [--cache DIR]  (keep each case's pipeline output there: a re-run after a change to the diagnosis only
                       re-diagnoses; the pipeline seconds of a cached case print as 0)
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))


#: The tracker noise of ``--held-out`` runs: another character than the simulator's default at a similar level
#: (less anisotropic, so more of the white noise and the drift lies across the branch; a faster drift; three
#: times the jumps), as a tracker on other footage might give. Smoothed-angle noise / signal 1.13-1.26 on seeds
#: 0-2 (default noise: 0.92-1.02). A harsher setting (sigma_across_px 0.35, along_ratio 1.5, tip_factor 3,
#: drift_px 0.4) reached noise / signal 3.4, twice the real plants', where the rank-1 fit chases the tip's drift
#: (kappa of alternating sign along the tip) and effect-free data got a second-mode verdict on 2 of 10 seeds.
HELD_OUT_NOISE = dict(sigma_across_px=0.25, along_ratio=1.5, tip_factor=2.0, drift_px=0.12, drift_time_s=0.7,
                      jump_prob=0.003)


def held_out_form(effect: str) -> str:
    """The effect's first held-out form in :data:`rce_gtsam.sim.simulate.EFFECT_FORMS` (its second entry)."""
    from rce_gtsam.sim.simulate import EFFECT_FORMS
    return list(EFFECT_FORMS[effect])[1]


def case(effect, seed, frames, matrices, mult=1.0, noise_free=False, held_out=False, shape=None, artifacts=None):
    """(Y, weights, root_distance, kappa_true, truth (E, T) or None, pipeline seconds, edge labels). ``shape``:
    :class:`~rce_gtsam.sim.simulate.SimulationConfig` fields other than the simulator's defaults (``--shape``).
    ``artifacts``: an :class:`~rce_gtsam.sim.artifacts.ArtifactConfig` (None: none)."""
    from rce_gtsam.sim.simulate import EFFECT_DEFAULTS
    strength = None if effect is None or mult == 1.0 else EFFECT_DEFAULTS[effect] * mult
    if matrices:
        from _effect_data import synth
        Y, s, k, _, y = synth(effect, seed=seed, E=18, T=frames, strength=strength)
        return Y, None, s, k, y, 0.0, None
    from rce_gtsam.pipeline import analyze
    from rce_gtsam.sim.simulate import NoiseConfig, SimulationConfig, simulate
    kw = {} if strength is None else {"effect_strength": {effect: strength}}
    if noise_free:
        kw["noise"] = NoiseConfig(enabled=False)
    if held_out:
        if not noise_free:
            kw["noise"] = NoiseConfig(**HELD_OUT_NOISE)
        if effect is not None:
            kw["effect_form"] = {effect: held_out_form(effect)}
    kw.update(shape or {})
    if artifacts is not None:
        kw["artifacts"] = artifacts
    sim = simulate(SimulationConfig(effects=() if effect is None else (effect,), seed=seed, n_frames=frames, **kw))
    t = time.perf_counter()
    res = analyze(sim.tracks, sim.graph, preset="default", n_boot=0)
    tp = time.perf_counter() - t
    r = res.response
    k = np.array([sim.kappa_true[e] for e in r.edges])
    row = {b.edge: i for i, b in enumerate(sim.graph.bends)}
    # the response keeps only frames where some bend was measured (gaps at a short branch's ends can empty a
    # frame): the truth on the same frames
    y = sim.response_true[[row[tuple(e)] for e in r.edges]][:, r.frames]
    W = r.weights if res.preset.compliance.weighted else None
    return r.Y, W, r.root_distance, k, y, tp, r.edge_labels


def score_p(p) -> str:
    """' p=...' for a case line: a full-data score test's p, or nothing for an effect without one."""
    return "" if p is None else f" p={p:.4f}"


def form_p(c) -> str:
    """' enc p(simpler)=...' for a case line: the encompassing tests of candidate ``c`` against simpler ones (does its
    model predict what theirs leave; the diagnosis' rule for a richer form of the same finding), or nothing."""
    ps = {**c.extra.get("form_test_p", {}), **c.extra.get("encompassing_p", {})}
    return "".join(f" enc p({k})={v:.4f}" for k, v in ps.items())


def artifact_suffix(artifacts) -> str:
    """The cache file's tag of an :class:`~rce_gtsam.sim.artifacts.ArtifactConfig` (empty for none)."""
    if artifacts is None or not artifacts.active:
        return ""
    import hashlib
    import json

    from rce_gtsam.sim.artifacts import load_preset
    params = load_preset(artifacts.preset)
    # a fingerprint of the families' measured parameters: a re-measured preset is not read from an older cache
    tag = hashlib.sha1(json.dumps([params[f] for f in artifacts.families], sort_keys=True).encode()).hexdigest()[:8]
    return f"_art-{'+'.join(artifacts.families)}-{artifacts.scale:g}-{tag}"


def cached_case(cache, effect, seed, frames, matrices, mult=1.0, noise_free=False, held_out=False, shape=None,
                artifacts=None):
    """:func:`case`, its pipeline output kept in (and read back from) the folder ``cache`` when one is given
    (one .npz per effect, strength, seed, length and noise setting; the pipeline seconds of a cached case
    are 0)."""
    if cache is None or matrices:
        return case(effect, seed, frames, matrices, mult, noise_free, held_out, shape, artifacts)
    path = Path(cache) / (f"{effect or 'none'}_{mult:g}_{seed}_{frames}{'_noisefree' if noise_free else ''}"
                          f"{'_heldout' if held_out else ''}{shape_suffix(shape)}{artifact_suffix(artifacts)}.npz")
    if path.exists():
        d = np.load(path)
        return d["Y"], (d["W"] if d["W"].size else None), d["s"], d["k"], d["y"], 0.0, list(d["labels"])
    Y, W, s, k, y, tp, labels = case(effect, seed, frames, matrices, mult, noise_free, held_out, shape, artifacts)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".part.npz")
    np.savez(tmp, Y=Y, W=W if W is not None else np.array([]), s=s, k=k, y=y, labels=np.array(labels))
    tmp.replace(path)
    return Y, W, s, k, y, tp, labels


def parse_shape(text: str) -> dict:
    """``--shape`` text, ``"n_nodes=8,fps=60,branch_layout=tree"``, as SimulationConfig overrides, each value of
    its field's type. One line naming the field on a bad entry (ValueError)."""
    from dataclasses import fields

    from rce_gtsam.sim.simulate import SimulationConfig
    types = {f.name: type(f.default) for f in fields(SimulationConfig)
             if isinstance(f.default, (int, float, str)) and f.name not in ("seed", "n_frames")}
    out = {}
    for item in filter(None, (t.strip() for t in text.split(","))):
        key, _, value = item.partition("=")
        if key not in types or not value:
            raise ValueError(f"--shape {item!r}: expected FIELD=VALUE with FIELD one of {', '.join(sorted(types))}")
        out[key] = types[key](value)
    return out


def shape_suffix(shape) -> str:
    """The cache file's tag of a ``--shape`` (empty for the simulator's defaults)."""
    return "".join(f"_{k}-{v}" for k, v in sorted((shape or {}).items()))


def oracle_pair_test(d, o):
    """The verdict's pair test between the two lags run with the oracle's dynamics model: the encompassing test
    (:mod:`rce_gtsam.diagnosis.encompassing`) of whether the true form, with its true shared parameters (the
    oracle's fit ``o["fit"]``), predicts what the fitted delay candidate leaves. None where it does not apply
    (no delay candidate, no node-disjoint row sets)."""
    from rce_gtsam.diagnosis.encompassing import encompassing_test
    from rce_gtsam.diagnosis.settings import FULL_ITER

    if "fit" not in o or not d.settings.get("node_disjoint_halves"):
        return None
    try:
        delay = d.candidate("delay")
    except KeyError:
        return None
    b = d.baseline
    halves = tuple(np.asarray(h, int) for h in d.settings["edge_halves"])
    return encompassing_test(delay.fit, o["fit"], b.Y, b.weights, b.root_distance, halves,
                             seed=d.settings["seed"], max_iter=FULL_ITER)


def ceiling(Y, y):
    """Held-out improvement (%) an oracle knowing the true response would get over the rank-1 model."""
    y = on_rest_reference(Y, y)
    U, S, Vt = np.linalg.svd(y, full_matrices=False)
    r1 = S[0] * np.outer(U[:, 0], Vt[0])
    return 100 * (1 - np.sqrt(np.nanmean((Y - y) ** 2)) / np.sqrt(np.nanmean((Y - r1) ** 2)))


def on_rest_reference(Y, y):
    """The truth y shifted per edge onto the pipeline's rest reference (mean of Y - y removed)."""
    return y + np.nanmean(Y - y, axis=1, keepdims=True)


def truth_gain(Y, y, base_fit, fit):
    """Improvement (%) of ``fit`` over ``base_fit`` in RMS distance of their predictions to the truth."""
    y = on_rest_reference(Y, y)
    d = lambda f: np.sqrt(np.mean((f.predict() - y) ** 2))  # noqa: E731
    return 100 * (1 - d(fit) / d(base_fit))


def noise_to_signal(Y, y):
    y = on_rest_reference(Y, y)
    return float(np.sqrt(np.nanmean((Y - y) ** 2)) / np.sqrt(np.mean(y ** 2)))


def klog(kappa, k):
    return float(np.sqrt(np.mean(np.log(np.abs(kappa) / k) ** 2)))


def finding_of(name):
    """The finding a verdict for candidate ``name`` reports (a form of a library effect reports that effect)."""
    from rce_gtsam import effects

    return None if name is None else effects.finding(name)


def full_data_verdict(d, alpha=0.05):
    """The verdict the full-data (Diebold-Mariano, batch means) test would give: the supported candidate with
    the lowest held-out RMSE, supported = its full-data t above the Bonferroni t quantile at its dof."""
    from scipy import stats
    n_c = max(len(d.candidates), 1)
    sup = [c for c in d.candidates if np.isfinite(c.extra.get("full_data_t", np.nan))
           and c.extra["full_data_t"] > stats.t.ppf(1 - alpha / n_c, max(c.extra.get("full_data_dof", 1), 1))
           and c.heldout_rmse < d.baseline_heldout_rmse]
    return min(sup, key=lambda c: c.heldout_rmse).effect if sup else None


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--frames", type=int, default=900)
    ap.add_argument("--cache", default=None,
                    help="folder that keeps each case's pipeline output, so a re-run only re-diagnoses")
    ap.add_argument("--matrices", action="store_true")
    ap.add_argument("--noise-free", action="store_true", help="noise-free tracks (the pipeline still runs)")
    ap.add_argument("--held-out", action="store_true",
                    help="each effect in its held-out form (rce_gtsam.sim.simulate.EFFECT_FORMS) under other tracker "
                         "noise (HELD_OUT_NOISE): data the diagnosis was not written for")
    ap.add_argument("--strength-mult", default="1",
                    help="comma-separated multipliers of rce_gtsam.sim.simulate.EFFECT_DEFAULTS (default 1), "
                         "e.g. 0.5,1,1.5,2,3 for a detection-vs-strength table")
    ap.add_argument("--effects", default="none,delay,dynamics,second_mode,offset,nonlinear")
    ap.add_argument("--folds", type=int, default=None,
                    help="cross-validation blocks of diagnose (default: diagnose's own, N_FOLDS = 16)")
    ap.add_argument("--artifacts", default=None, metavar="FAMILY[,FAMILY]",
                    help="tracker artifacts (rce_gtsam.sim.artifacts; 'all' for every family) on every recording")
    ap.add_argument("--artifact-scale", type=float, default=1.0, metavar="X",
                    help="their strength, x the measured size (default 1)")
    ap.add_argument("--shape", default="",
                    help="simulated recordings of another shape: SimulationConfig fields, e.g. "
                         "n_nodes=8,fps=60,branch_layout=tree,root_sway_deg=3 (frames: --frames)")
    a = ap.parse_args()
    try:
        shape = parse_shape(a.shape)
    except ValueError as err:
        ap.error(str(err))
    artifacts = None
    if a.artifacts:
        from rce_gtsam.errors import InputError
        from rce_gtsam.sim.artifacts import ArtifactConfig, parse_families
        try:
            artifacts = ArtifactConfig(parse_families(a.artifacts), scale=a.artifact_scale)
            artifacts.validate()
        except InputError as err:
            ap.error(str(err))
    from scipy import stats

    from rce_gtsam.diagnosis.diagnose import diagnose
    from rce_gtsam.diagnosis.heldout import paired_t
    from rce_gtsam.diagnosis.oracle import oracle_test
    from rce_gtsam.diagnosis.verdict import choose_verdict, maxt_verdict
    from rce_gtsam.presets import get_preset
    mults = [float(m) for m in a.strength_mult.split(",")]
    print(f"input: {'matrices (simulator equations + noise)' if a.matrices else 'full pipeline (simulate -> analyze default preset)'}; "
          f"{a.seeds} seeds from {a.first_seed}, {a.frames} frames, effect strength {a.strength_mult} x default; "
          f"{'HELD-OUT forms and noise; ' if a.held_out else ''}{f'shape {a.shape}; ' if shape else ''}"
          f"{f'tracker artifacts {a.artifacts} x{a.artifact_scale:g}; ' if artifacts else ''}"
          "oracle = the hidden effect's candidate with its true shared parameters, through the same folds", flush=True)
    # the core model's config: the default preset's, as `rce diagnose` runs it (rce_gtsam.diagnosis.io);
    # the matrices mode keeps diagnose's own default
    config = None if a.matrices else get_preset("default").compliance
    rows, table = [], []
    for eff in a.effects.split(","):
        hidden = None if eff == "none" else eff
        for mult in (mults if hidden is not None else [1.0]):
            okz, ok2, conf2, ok3, orc3, conf3, n_sep, conf_sep = 0, 0, 0, 0, 0, 0, 0, 0
            n_sep_e, conf_sep_e = 0, 0
            okf, orcf, ok, orc, conf, imp_v, imp_h, ceil, kb, ka, ts, tps, tru, nsr = 0, 0, 0, 0, 0, [], [], [], [], [], [], [], [], []
            for sd in range(a.first_seed, a.first_seed + a.seeds):
                Y, W, s, k, y, tp, labels = cached_case(a.cache, hidden, sd, a.frames, a.matrices, mult,
                                                        a.noise_free, a.held_out, shape, artifacts)
                t = time.perf_counter()
                d = diagnose(Y, weights=W, root_distance=s, seed=0, edge_labels=labels, n_folds=a.folds,
                             config=config)
                ts.append(time.perf_counter() - t)
                tps.append(tp)
                ok += d.verdict == hidden
                fv = finding_of(full_data_verdict(d))
                okf += fv == hidden
                conf += {d.verdict, hidden} == {"delay", "dynamics"}
                v2 = finding_of(choose_verdict(d.candidates, d.settings["evidence_threshold_t"], same_kind=True)[0])
                ok2 += v2 == hidden
                conf2 += {v2, hidden} == {"delay", "dynamics"}
                v3 = finding_of(maxt_verdict(d))
                ok3 += v3 == hidden
                conf3 += {v3, hidden} == {"delay", "dynamics"}
                o = oracle_test(d, Y, y, hidden)
                orc += bool(o["supported"])
                o3 = bool(o["t"] > d.settings["maxt_critical_t"] and o["improvement_pct"] > 0
                          and (hidden is not None))
                orc3 += o3
                okz += bool(o["knows_z"]["supported"])
                # does even the true form (the oracle) beat the rival lag candidate by the verdict's own test?
                # Where it does not, no method can tell delay from dynamics on this recording
                rival = {"delay": "dynamics", "dynamics": "delay"}.get(hidden)
                sep = False
                if rival is not None and "fold_mse" in o:
                    t_sep = paired_t(d.candidate(rival).fold_mse, o["fold_mse"][: len(d.candidate(rival).fold_mse)])
                    sep = bool(np.isfinite(t_sep) and t_sep > d.settings["evidence_threshold_t"])
                n_sep += sep
                conf_sep += sep and {d.verdict, hidden} == {"delay", "dynamics"}
                # the verdict decides between the two lags by the encompassing test, not the fold t: does the true
                # form (oracle) predict what the fitted delay leaves, at the verdict's threshold? Where it does not,
                # that test cannot separate them on this recording whatever the dynamics fit
                enc_o = oracle_pair_test(d, o) if hidden == "dynamics" else None
                if enc_o is not None:
                    sep_e = enc_o.p <= d.settings["encompassing_threshold_p"]
                    n_sep_e += sep_e
                    conf_sep_e += sep_e and d.verdict == "delay"
                dm_crit = stats.t.ppf(1 - 0.05 / max(len(d.candidates), 1), max(o.get("full_data_dof", 1), 1))
                orcf += bool(o["full_data_t"] > dm_crit and o["improvement_pct"] > 0)
                kb.append(klog(d.baseline.kappa, k))
                ka.append(klog(d.verdict_candidate.fit.kappa, k) if d.verdict else kb[-1])
                if d.verdict is not None and d.verdict == hidden:
                    imp_v.append(d.verdict_candidate.improvement_pct)
                if hidden is not None:
                    imp_h.append(d.candidate(hidden).improvement_pct)
                    ceil.append(ceiling(Y, y))
                    tru.append(truth_gain(Y, y, d.baseline, d.candidate(hidden).fit))
                nsr.append(noise_to_signal(Y, y))
                print(f"  {eff} x{mult:g} seed {sd}: verdict {d.verdict}{'' if d.verdict_effect in (None, d.verdict) else ' [' + d.verdict_effect + ']'} (same-kind parsimony: {v2}; max-T: {v3}{'' if not o3 else ', oracle max-T*'}; full-data test: {fv}), oracle t={o['t']:.1f}"
                      f"{'*' if o['supported'] else ''}{'' if enc_o is None else f' enc p(delay)={enc_o.p:.4f}'}"
                      f" (knows z t={o['knows_z']['t']:.1f}"
                      f"{'*' if o['knows_z']['supported'] else ''}) ft={o.get('full_data_t', float('nan')):.1f}"
                      f"{score_p(o.get('score_p'))}; " + ", ".join(
                    f"{c.effect} {c.improvement_pct:+.1f}% t={c.evidence:.1f}{'*' if c.supported else ''} "
                    f"ft={c.extra.get('full_data_t', float('nan')):.1f}{score_p(c.extra.get('score_p'))} "
                    f"dAIC={c.delta_aic:.1f}{form_p(c)}"
                    for c in d.candidates)
                    + f" (diagnose {ts[-1]:.1f} s, pipeline {tp:.1f} s)", flush=True)
            med = lambda v: float(np.median(v)) if v else float("nan")  # noqa: E731
            n = a.seeds
            rows.append(f"{eff:<12} {mult:>5g} {ok:>5}/{n} {orc:>5}/{n} {okz:>5}/{n} {okf:>5}/{n} "
                        f"{orcf:>5}/{n} {conf:>5} {conf_sep:>4}/{n_sep:<4} {conf_sep_e:>4}/{n_sep_e:<4} {ok2:>5}/{n} {conf2:>5} {ok3:>5}/{n} {orc3:>5}/{n} {conf3:>5} {med(imp_v):14.1f} "
                        f"{med(imp_h):13.1f} {med(ceil):9.1f} {med(tru):7.1f} {med(nsr):9.2f} {med(kb):8.3f} -> "
                        f"{med(ka):.3f} {med(ts):7.1f} {med(tps):6.1f}")
            table.append({"effect": eff, "mult": mult, "right": ok, "oracle": orc, "knows_z": okz, "n": n, "right_full": okf, "right2": ok2,
                          "oracle_full": orcf, "separated": n_sep, "confused_where_separated": conf_sep,
                          "separated_by_pair_test": n_sep_e, "confused_where_pair_test_separates": conf_sep_e})
            print(rows[-1], flush=True)
    print(f"\n{'effect':<12} {'x':>5} {'right':>8} {'oracle':>8} {'knows z':>8} {'right*':>8} {'oracle*':>8} {'d<->d':>5} {'d<->d|sep':>9} {'d<->d|enc':>9} {'right2':>8} {'d<->d2':>6} {'right3':>8} {'oracle3':>8} {'d<->d3':>6} {'dRMSE% verdict':>14} {'dRMSE% hidden':>13} "
          f"{'ceiling%':>9} {'truth%':>7} {'noise/sig':>9} {'klog before -> after':>20} {'s':>7} {'pipe s':>6}")
    print("\n".join(rows))
    print("(right/oracle/knows z: the verdict's fold-paired t rule; right*/oracle*: the full-data Diebold-Mariano rule;"
          " for effect-free rows 'right' counts no verdict and 'oracle'/'knows z' count false firings;"
          " d<->d|sep: delay<->dynamics confusions / cases where the oracle (true form and shared parameters) beats"
          " the rival lag candidate by the verdict's fold t (where it does not, the recording cannot tell them apart);"
          " d<->d|enc (dynamics rows): dynamics named delay / cases where the oracle's dynamics model predicts what the"
          " fitted delay leaves by the verdict's own pair test, the encompassing test at its threshold;"
          " right2 / d<->d2: the verdict with same-kind parsimony, choose_verdict(same_kind=True);"
          " right3 / oracle3 / d<->d3: the family-wise sign-flip max-T test, maxt_verdict)")
    # the strength at which each is right >= 90 %: project vs oracle
    for eff in sorted({r["effect"] for r in table if r["effect"] != "none"}):
        pr = [r for r in table if r["effect"] == eff]
        p90 = next((r["mult"] for r in pr if r["right"] >= 0.9 * r["n"]), None)
        o90 = next((r["mult"] for r in pr if r["oracle"] >= 0.9 * r["n"]), None)
        p90f = next((r["mult"] for r in pr if r["right_full"] >= 0.9 * r["n"]), None)
        p902 = next((r["mult"] for r in pr if r["right2"] >= 0.9 * r["n"]), None)
        o90f = next((r["mult"] for r in pr if r["oracle_full"] >= 0.9 * r["n"]), None)
        print(f"{eff:<12} right >= 90 % from strength x{p90 if p90 is not None else '>max'}; "
              f"oracle from x{o90 if o90 is not None else '>max'}; full-data rule x{p90f if p90f is not None else '>max'}, "
              f"its oracle x{o90f if o90f is not None else '>max'}; same-kind parsimony x{p902 if p902 is not None else '>max'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
