"""Detection against strength on the beam simulator (``bench_beam.py --curve``): per case, what the verdict and its
oracle did and, where the diagnosis did not name the effect, which rule refused its candidate; per effect, the pass
rate against strength and the strength at which it reaches 90 %.

A case's outcome (:func:`case_outcome`) is a small JSON object kept beside the case's pipeline pickle
(``<stem>.outcome.json``), so the curve can be summarised from every case run so far without re-running the
diagnosis (:func:`load_outcomes`). Units: strengths as multipliers of
:data:`rce_gtsam.sim.beam.BEAM_EFFECT_DEFAULTS` (and in the effect's own unit, :data:`BEAM_EFFECT_MEANING`); angles
in degrees; the tip excursion in % of the branch's tracked length.
"""

from __future__ import annotations

import json
import math
from collections import Counter
from pathlib import Path

import numpy as np

#: The pass rate the curve's point is read at.
LEVEL = 0.9


def phys_measures(true_xy: np.ndarray, response_true: np.ndarray, length_px: float) -> dict:
    """How far the simulated branch moves: ``max_joint_deg`` the largest |bend from rest| of any joint in any frame
    (deg), ``p99_joint_deg`` its 99th percentile, ``tip_pct`` the largest distance of the tip from its median
    position over the record, in % of the branch's tracked length (``length_px``, the sum of segment lengths)."""
    tip = np.asarray(true_xy)[-1]
    exc = float(np.max(np.linalg.norm(tip - np.median(tip, axis=0), axis=1)))
    a = np.abs(np.asarray(response_true))
    return {"max_joint_deg": round(float(a.max()), 2), "p99_joint_deg": round(float(np.quantile(a, 0.99)), 2),
            "tip_pct": round(100.0 * exc / length_px, 1)}


def _num(v) -> float | None:
    return None if v is None or not math.isfinite(float(v)) else round(float(v), 4)


def refusal(d, names: tuple[str, ...]) -> dict:
    """Why the diagnosis ``d`` did not name one of ``names`` (the findings a beam effect is counted right by).

    The candidate looked at is the supported one of those findings if any, else the one with the lowest held-out
    RMSE. ``rule``: ``named`` (the verdict is right), ``other_verdict`` (supported, but the verdict picks another
    candidate: lower held-out RMSE or simpler, :mod:`rce_gtsam.diagnosis.verdict`), ``outside_domain``, ``one_node``
    (supported and leading, withheld by :mod:`rce_gtsam.diagnosis.one_node`), ``drift_checks`` (significant by its
    fold t, refused as tracker drift), ``significance`` (fold t / score p short
    of their thresholds), ``fold_support`` (the score test fires, the fold t is below the support t a full-data test
    needs beside it, :func:`~rce_gtsam.diagnosis.decision.is_significant`), ``plausibility`` (its fit's reasons),
    ``heldout_rmse`` (no lower held-out error), ``aic`` (effective-sample AIC not lower and no significant score
    test), ``resolution`` (less than the resolution's share of the bending variance), ``absent`` (no such candidate
    ran). ``text`` says it with the statistic against its threshold."""
    from rce_gtsam.diagnosis.result import finding_of

    cs = [c for c in d.candidates if finding_of(c) in names]
    base = {"candidate": None, "fold_t": None, "threshold_t": None, "score_p": None, "score_threshold_p": None}
    if not cs:
        return {**base, "rule": "absent", "text": f"no candidate for {'|'.join(names)}"}
    c = next((c for c in cs if c.supported), cs[0])
    x, tests = c.extra, c.tests
    ft = tests["fold_t"]
    sc = tests.get("score")
    out = {"candidate": c.effect, "fold_t": _num(ft.statistic), "threshold_t": _num(ft.threshold),
           "score_p": None if sc is None else _num(sc.p),
           "score_threshold_p": None if sc is None else _num(sc.threshold)}
    score_txt = "" if sc is None else f", score p {sc.p:.4f} vs {sc.threshold:.4f}"
    stat = f"fold t {ft.statistic:.2f} vs {ft.threshold:.2f}{score_txt}"
    if d.verdict in names:
        return {**out, "rule": "named", "text": f"{c.effect}: named ({stat})"}
    if c.supported:
        if d.outside_domain:
            return {**out, "rule": "outside_domain", "text": f"{c.effect}: supported, outside {d.outside_domain}"}
        held = (d.settings or {}).get("one_node") or {}
        if held.get("effect") == c.effect and not held.get("holds", True):
            return {**out, "rule": "one_node",
                    "text": f"{c.effect}: supported, withheld: without node {held.get('node')}'s bends its held-out "
                            f"gain is {held.get('heldout_gain_pct', float('nan')):.1f} % (fold t "
                            f"{held.get('fold_t', float('nan')):.2f})"}
        return {**out, "rule": "other_verdict", "text": f"{c.effect}: supported, verdict {d.verdict} ({stat})"}
    if x.get("significant_by_fold_t") and not x.get("significant"):
        parts = [f"held-out null p {x.get('heldout_null_p', float('nan')):.3f} vs "
                 f"{x.get('heldout_null_threshold_p', 0):.3f}"]
        if x.get("shared_course_p") is not None:
            parts.append(f"shared course p {x['shared_course_p']:.4f} vs {x['shared_course_threshold_p']:.4f}")
        if x.get("drift_pattern_p") is not None:
            parts.append(f"drift pattern p {x['drift_pattern_p']:.3f} vs {x['drift_pattern_threshold_p']:.3f}")
        return {**out, "rule": "drift_checks", "text": f"{c.effect}: {stat}, refused as drift ({'; '.join(parts)})"}
    if not x.get("significant"):
        if sc is not None and sc.fires:
            sup = x.get("support_threshold_t", d.settings.get("support_threshold_t", float("nan")))
            return {**out, "rule": "fold_support", "text": f"{c.effect}: score test fires but the fold t does not "
                                                           f"support it ({stat}; support t {sup:.2f})"}
        return {**out, "rule": "significance", "text": f"{c.effect}: not significant ({stat})"}
    if x.get("implausible"):
        return {**out, "rule": "plausibility", "text": f"{c.effect}: implausible ({'; '.join(x['implausible'])})"}
    if not c.heldout_rmse < d.baseline_heldout_rmse:
        return {**out, "rule": "heldout_rmse", "text": f"{c.effect}: held-out RMSE {c.improvement_pct:+.2f} %"}
    calibrated = sc is not None and sc.fires
    if not (c.delta_aic < 0 or calibrated):
        return {**out, "rule": "aic", "text": f"{c.effect}: delta AIC {c.delta_aic:+.1f} (no significant score test)"}
    res = d.settings.get("resolution", 0.0)
    if x.get("heldout_gain_share", 0.0) < res:
        return {**out, "rule": "resolution",
                "text": f"{c.effect}: gain share {x.get('heldout_gain_share', 0.0):.4f} < resolution {res:.4f}"}
    return {**out, "rule": "other", "text": f"{c.effect}: not supported ({stat})"}


def case_outcome(effect: str, mult: float, strength: float, seed: int, frames: int, d, right: bool,
                 oracle: dict | None, size: float, phys: dict | None) -> dict:
    """The JSON record of one case: the verdict, right or not, the oracle (supported, t, threshold, score p), the
    mapped candidate's refusal (:func:`refusal`), the effect's size (rank-1 misfit / RMS of the noise-free
    response) and how far the branch moved (:func:`phys_measures`)."""
    from rce_gtsam.sim.beam import DIAGNOSIS_NAME

    o = None if oracle is None else {"supported": bool(oracle["supported"]), "t": _num(oracle["t"]),
                                     "threshold_t": _num(oracle["threshold_t"]), "score_p": _num(oracle.get("score_p"))}
    return {"effect": effect, "mult": mult, "strength": strength, "seed": seed, "frames": frames,
            "verdict": d.verdict, "right": bool(right), "oracle": o, "refusal": refusal(d, DIAGNOSIS_NAME[effect]),
            "size": round(float(size), 4), "phys": phys}


def save_outcome(path: Path, outcome: dict) -> None:
    """Write ``outcome`` to ``path`` atomically."""
    tmp = path.with_suffix(".part")
    tmp.write_text(json.dumps(outcome) + "\n")
    tmp.replace(path)


def effect_and_noise_rms(Y: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """(RMS of what no rank-1 model explains of the noise-free response, :func:`~rce_gtsam.diagnosis.oracle.
    true_signature`; RMS of the angle noise, Y less the truth on Y's per-row rest reference), both degrees: the
    part of an effect any rank-1 diagnosis can see against the noise it must see it through."""
    from rce_gtsam.diagnosis.oracle import true_signature

    sig = true_signature(truth)
    n = Y - (truth + np.nanmean(Y - truth, axis=1, keepdims=True))
    return float(np.sqrt(np.mean(sig ** 2))), float(np.sqrt(np.nanmean(n ** 2)))


def load_outcomes(cache: str, effects: list[str], frames: int) -> list[dict]:
    """Every case outcome in ``cache`` for ``effects`` at ``frames`` frames (bootstrap at the preset's count), with
    :func:`effect_and_noise_rms` of its case read from the pickle beside it (``effect_rms_deg``,
    ``noise_rms_deg``; None where the pickle is gone)."""
    import pickle

    out = []
    for p in sorted(Path(cache).glob(f"*_{frames}_bootpreset.outcome.json")):
        o = json.loads(p.read_text())
        if o["effect"] in effects and o["frames"] == frames:
            pkl = p.with_name(p.name.replace(".outcome.json", ".pkl"))
            o["effect_rms_deg"] = o["noise_rms_deg"] = None
            if pkl.exists():
                with open(pkl, "rb") as fh:
                    c = pickle.load(fh)
                o["effect_rms_deg"], o["noise_rms_deg"] = effect_and_noise_rms(c["Y"], c["truth"])
            out.append(o)
    return out


def point_at(mults: list[float], rates: list[float], level: float = LEVEL) -> tuple[float | None, str]:
    """The strength at which the pass rate first reaches ``level``, by linear interpolation between the tested
    strengths (sorted); (None, "not reached") where it never does, (mults[0], "<=") where the weakest tested
    strength already passes (the point lies at or below it), else (value, "=")."""
    for i, (m, r) in enumerate(zip(mults, rates)):
        if r >= level:
            if i == 0:
                return m, "<="
            m0, r0 = mults[i - 1], rates[i - 1]
            return m0 + (level - r0) / (r - r0) * (m - m0), "="
    return None, "not reached"


def rule_of(o: dict) -> str:
    """The refusal rule of outcome ``o``; an outcome kept before ``fold_support`` was told apart from
    ``significance`` is told apart here from its score p and threshold."""
    r = o["refusal"]
    if (r["rule"] == "significance" and r.get("score_p") is not None and r.get("score_threshold_p") is not None
            and r["score_p"] <= r["score_threshold_p"]):
        return "fold_support"
    return r["rule"]


def _median(v: list) -> float:
    v = [x for x in v if x is not None]
    return float(np.median(v)) if v else float("nan")


def curve(outcomes: list[dict]) -> dict:
    """Per effect: rows per strength multiplier (n, right, oracle passes, median size, median and max of the largest
    joint angle and tip excursion, the refusals of the cases the oracle passed and the diagnosis did not, and of all
    the cases the diagnosis missed), and the 90 % points of the diagnosis and the oracle with their ratio."""
    by: dict[str, dict[float, list[dict]]] = {}
    for o in outcomes:
        by.setdefault(o["effect"], {}).setdefault(float(o["mult"]), []).append(o)
    res = {}
    for eff, per in by.items():
        rows = []
        for m in sorted(per):
            cs = per[m]
            phys = [c["phys"] for c in cs if c.get("phys")]
            gap = Counter(rule_of(c) for c in cs
                          if c["oracle"] and c["oracle"]["supported"] and not c["right"])
            miss = Counter(rule_of(c) for c in cs if not c["right"])
            rows.append({"mult": m, "strength": cs[0]["strength"], "n": len(cs), "right": sum(c["right"] for c in cs),
                         "oracle": sum(bool(c["oracle"] and c["oracle"]["supported"]) for c in cs),
                         "size": float(np.median([c["size"] for c in cs])),
                         "effect_rms_deg": _median([c.get("effect_rms_deg") for c in cs]),
                         "noise_rms_deg": _median([c.get("noise_rms_deg") for c in cs]),
                         "max_joint_deg": max((p["max_joint_deg"] for p in phys), default=float("nan")),
                         "tip_pct": float(np.median([p["tip_pct"] for p in phys])) if phys else float("nan"),
                         "oracle_t": float(np.median([c["oracle"]["t"] for c in cs if c["oracle"]])),
                         "cand_t": float(np.median([c["refusal"]["fold_t"] for c in cs
                                                    if c["refusal"]["fold_t"] is not None] or [float("nan")])),
                         "gap_rules": dict(gap), "miss_rules": dict(miss)})
        ms = [r["mult"] for r in rows]
        d90 = point_at(ms, [r["right"] / r["n"] for r in rows])
        o90 = point_at(ms, [r["oracle"] / r["n"] for r in rows])
        ratio = d90[0] / o90[0] if d90[0] is not None and o90[0] is not None else None
        res[eff] = {"rows": rows, "diagnosis_90": d90, "oracle_90": o90, "ratio": ratio}
    return res


def fmt_point(p: tuple[float | None, str]) -> str:
    """A 90 % point as text: 'x3.2', '<= x2', 'not reached'."""
    v, how = p
    return "not reached" if v is None else (f"<= x{v:g}" if how == "<=" else f"x{v:.2f}")


def ratio_text(r: dict) -> str:
    """The diagnosis' 90 % point over the oracle's as text: a bound where either point is only bounded (it lies at
    or below the weakest strength tried), 'undefined' where either is not reached or both are bounds."""
    (d, dh), (o, oh) = r["diagnosis_90"], r["oracle_90"]
    if d is None or o is None or (dh == "<=" and oh == "<="):
        return "undefined"
    return {("=", "="): "", ("=", "<="): ">= ", ("<=", "="): "<= "}[(dh, oh)] + f"{d / o:.2f}"


def print_curve(res: dict, frames: int) -> None:
    """The curve as a table per effect and the 90 % points."""
    print(f"\ndetection against strength, {frames} frames (right / oracle: passes of n; size: rank-1 misfit / RMS "
          "of the noise-free response; effect/noise: RMS of its non-rank-1 part / of the angle noise; joint: "
          "largest |bend| deg; tip: median tip excursion % of length; t: "
          "median fold t of the oracle / of the mapped candidate; gap: why the diagnosis refused where the "
          "oracle passed; miss: why it refused, all misses)")
    for eff, r in res.items():
        for row in r["rows"]:
            print(f"  {eff:<12} x{row['mult']:<5g} ({row['strength']:g}) n {row['n']:>2}: right {row['right']:>2} "
                  f"oracle {row['oracle']:>2}  size {row['size']:.3f} effect/noise {row['effect_rms_deg']:.2f}/"
                  f"{row['noise_rms_deg']:.2f} deg joint {row['max_joint_deg']:.1f} "
                  f"tip {row['tip_pct']:.0f} %  t {row['oracle_t']:+.1f}/{row['cand_t']:+.1f}  "
                  f"gap {row['gap_rules'] or '-'}  miss {row['miss_rules'] or '-'}")
        print(f"  {eff:<12} 90 % point: diagnosis {fmt_point(r['diagnosis_90'])}, oracle {fmt_point(r['oracle_90'])}"
              f", ratio {ratio_text(r)}")
