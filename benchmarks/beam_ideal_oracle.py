"""Is the second excitation's held-out test too weak? Detection against strength on the beam simulator for the
diagnosis, its oracle, the ideal oracle and alternative held-out schemes (issue #37).

Per cached beam case (``benchmarks/bench_beam.py``'s pickles; a missing one is simulated and cached by
:func:`bench_beam.cached_case`):

* **diagnosis**: :func:`rce_gtsam.diagnosis.diagnose.diagnose` names the mapped effect
  (:data:`rce_gtsam.sim.beam.DIAGNOSIS_NAME`);
* **oracle**: :func:`rce_gtsam.diagnosis.oracle.oracle_test`, the verdict's own tests with the true form and
  shared parameters (for ``second_mode`` there is nothing shared to know: the candidate itself);
* **ideal oracle**: :func:`rce_gtsam.diagnosis.ideal_oracle.signature_test`, whether the rank-1 residual
  contains the known extra signature (the true one, :func:`rce_gtsam.diagnosis.oracle.true_signature`), at the
  verdict's full-data level (the case's ``score_threshold_p``, 0.005): the ceiling;
* **held-out schemes** (``second_mode`` only, :mod:`heldout_schemes`): the fold t of the diagnosis' own
  prediction, of a joint GLS posterior on the same rows, of node-respecting bi-cross-validation and of a
  predictor that knows the signature; passing = fold t above the split threshold (the fold-t route alone) /
  above the support t (the t a full-data test needs beside it).

The null (``--null-cache``): effect-free beam cases, each residual tested along a signature borrowed from an
effect case of the same length (seed k % seeds at ``--null-mult``); and the alternative held-out schemes of a
second-mode fit on each, against the same thresholds: what each would give with nothing to find.

Usage: OMP_NUM_THREADS=1 python benchmarks/beam_ideal_oracle.py [--effect two_sources] [--mults 1,2,3,5]
       [--seeds 5] [--frames 450] [--cache /work/cache/beam4] [--null-cache /work/cache/beam6] [--null-seeds 40]
       [--null-mult 3] [--no-heldout] [--own-sim-seeds 10 --own-sim-null 20 [--own-sim-mult 1]
       [--own-sim-frames 900] [--own-sim-cache /work/cache/bd]] [--record beam_ideal_oracle]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))


def rate(flags) -> str:
    return f"{int(sum(flags))} of {len(flags)}"


def case_nodes(c: dict):
    """The tracked nodes of each row (the diagnosis' own rule: given, else parsed from the edge labels)."""
    from rce_gtsam.model.row_sets import edge_nodes_from_labels
    nodes = c["inputs"].get("edge_nodes")
    labels = c["inputs"].get("edge_labels")
    return nodes if nodes is not None or labels is None else edge_nodes_from_labels(labels)


def effect_case(c: dict, names: tuple[str, ...], heldout: bool) -> dict:
    """One effect case whose verdict is right when it is one of ``names`` (the first is the oracle's candidate):
    the diagnosis, its oracle, the ideal oracle and (``heldout``) the held-out schemes."""
    from heldout_schemes import scheme_fold_t
    from rce_gtsam.diagnosis.diagnose import diagnose
    from rce_gtsam.diagnosis.ideal_oracle import signature_test
    from rce_gtsam.diagnosis.oracle import oracle_test, true_signature
    d = diagnose(**c["inputs"])
    st, base = d.settings, d.baseline
    name = names[0]
    o = oracle_test(d, c["Y"], c["truth"], name)
    y = c["truth"] + np.nanmean(base.Y - c["truth"], axis=1, keepdims=True)
    sig = true_signature(y)
    ideal = signature_test(base.Y - base.predict(), sig, seed=st["seed"])
    out = {"right": d.verdict in names, "oracle": bool(o["supported"]), "oracle_t": o["t"],
           "ideal_p": ideal.p, "ideal_z": ideal.z, "level_p": st["score_threshold_p"],
           "t_split": st["evidence_threshold_t_split"], "t_support": st["support_threshold_t"],
           "effect_rms": float(np.sqrt(np.mean(sig ** 2))),
           "noise_rms": float(np.sqrt(np.nanmean((base.Y - y) ** 2)))}
    if heldout and name == "second_mode":
        from heldout_schemes import bcv_sets
        halves = [np.asarray(h, int) for h in st["edge_halves"]]
        bcv = bcv_sets(base.root_distance, case_nodes(c))
        out["rows"] = {"E": len(base.Y), "halves": sorted(len(h) for h in halves),
                       "halves_unused": len(base.Y) - sum(len(h) for h in halves),
                       "bcv_estimate": float(np.median([len(A) for A, _ in bcv])),
                       "bcv_scored": max(len(B) for _, B in bcv)}
        cand = next(x for x in d.candidates if x.effect == "second_mode")
        out["schemes"] = scheme_fold_t(base.model, base, cand.fit.model, cand.fit, base.Y, base.weights,
                                       base.root_distance, [tuple(b) for b in st["fold_blocks"]],
                                       int(st["buffer_frames"]),
                                       tuple(np.asarray(h, int) for h in st["edge_halves"]),
                                       case_nodes(c), sig)
    return out


def null_case(c: dict, sig: np.ndarray, heldout: bool, seed: int) -> dict:
    """One effect-free case: the ideal oracle along a borrowed signature, and the held-out schemes of a
    second-mode fit (the diagnosis' own full fit, :func:`rce_gtsam.diagnosis.evidence.full_fits`)."""
    from heldout_schemes import scheme_fold_t
    from rce_gtsam.diagnosis.diagnose import diagnose
    from rce_gtsam.diagnosis.ideal_oracle import signature_test

    d = diagnose(**c["inputs"])
    st, base = d.settings, d.baseline
    ideal = signature_test(base.Y - base.predict(), sig, seed=seed)
    out = {"verdict": d.verdict, "ideal_p": ideal.p, "level_p": st["score_threshold_p"],
           "t_split": st["evidence_threshold_t_split"], "t_support": st["support_threshold_t"]}
    if heldout:
        cand = next(x for x in d.candidates if x.effect == "second_mode")
        out["schemes"] = scheme_fold_t(base.model, base, cand.fit.model, cand.fit, base.Y, base.weights,
                                       base.root_distance, [tuple(b) for b in st["fold_blocks"]],
                                       int(st["buffer_frames"]),
                                       tuple(np.asarray(h, int) for h in st["edge_halves"]),
                                       case_nodes(c))
    return out


def scheme_cells(cases: list[dict], name: str) -> tuple[str, str, float | str]:
    """(passes at the split t, passes at the support t, median t) of held-out scheme ``name`` over ``cases``."""
    ts = [c["schemes"][name]["t"] for c in cases if name in c.get("schemes", {})]
    if not ts:
        return "-", "-", "-"
    split = [t > c["t_split"] for t, c in zip(ts, cases)]
    sup = [t > c["t_support"] for t, c in zip(ts, cases)]
    return rate(split), rate(sup), round(float(np.median(ts)), 2)


def curve_notes(per_mult: dict) -> list[str]:
    """One line per test: its 90 % point (:func:`beam_curve.point_at`, linear interpolation between the strengths),
    and per held-out scheme the median held-out RMSE change (%) of the second-mode fit per strength."""
    from beam_curve import fmt_point, point_at
    from heldout_schemes import SCHEMES

    mults = sorted(per_mult)
    tests = {"diagnosis": lambda c: c["right"], "oracle": lambda c: c["oracle"],
             "ideal oracle": lambda c: c["ideal_p"] <= c["level_p"]}
    ran = {s for cs in per_mult.values() for c in cs for s in c.get("schemes", {})}
    for s in [s for s in SCHEMES if s in ran]:
        tests[f"{s} (fold t > split t)"] = (lambda c, s=s: s in c.get("schemes", {})
                                             and c["schemes"][s]["t"] > c["t_split"])
    notes = []
    for name, ok in tests.items():
        rates = [float(np.mean([ok(c) for c in per_mult[m]])) for m in mults]
        notes.append(f"{name}: 90 % point {fmt_point(point_at(mults, rates))}; pass rate by strength "
                     + ", ".join(f"x{m:g} {r:.0%}" for m, r in zip(mults, rates)))
    for s in SCHEMES:
        gains = [[c["schemes"][s]["gain_pct"] for c in per_mult[m] if s in c.get("schemes", {})] for m in mults]
        if any(gains):
            notes.append(f"{s}: median held-out RMSE gain over the rank-1 baseline by strength "
                         + ", ".join(f"x{m:g} {np.median(g):+.1f} %" for m, g in zip(mults, gains) if g))
    rows = [c["rows"] for cs in per_mult.values() for c in cs if "rows" in c]
    if rows:
        notes.append(f"rows per split (medians over cases): the diagnosis' node-disjoint halves estimate z and w "
                     f"from {np.median([r['halves'][1] for r in rows]):g} rows and score "
                     f"{np.median([r['halves'][0] for r in rows]):g} (then the roles swap; "
                     f"{np.median([r['halves_unused'] for r in rows]):g} of {np.median([r['E'] for r in rows]):g} "
                     f"rows neither estimate nor are scored); bi-cross-validation estimates from "
                     f"{np.median([r['bcv_estimate'] for r in rows]):g} rows for each run of "
                     f"{np.median([r['bcv_scored'] for r in rows]):g} scored, every row scored once")
    return notes


def effect_row(label: str, cases: list[dict]) -> list:
    """A table row of effect cases: counts of the diagnosis, oracle, ideal oracle; medians; the schemes' cells."""
    from heldout_schemes import SCHEMES
    row = [label, len(cases), rate([c["right"] for c in cases]), rate([c["oracle"] for c in cases]),
           rate([c["ideal_p"] <= c["level_p"] for c in cases]),
           round(float(np.median([c["ideal_z"] for c in cases])), 1),
           round(float(np.median([c["effect_rms"] for c in cases])), 2),
           round(float(np.median([c["noise_rms"] for c in cases])), 2)]
    return row + [x for s in SCHEMES for x in scheme_cells(cases, s)]


def null_row(label: str, null: list[dict]) -> list:
    """A table row of effect-free cases: any verdict, the ideal oracle along a borrowed signature, the schemes."""
    from heldout_schemes import SCHEMES
    row = [label, len(null), rate([c["verdict"] is not None for c in null]), "-",
           rate([c["ideal_p"] <= c["level_p"] for c in null]), "-", "-", "-"]
    return row + [x for s in SCHEMES for x in scheme_cells(null, s)]


def own_sim(a, heldout: bool, t0: float) -> tuple[list[dict], list[dict]]:
    """``--own-sim-seeds``: the project's own simulator (benchmarks/bench_diagnose.py's cases, its cache), its
    ``second_mode`` at ``--own-sim-mult`` and effect-free seeds with a signature borrowed from those cases."""
    from bench_diagnose import cached_case
    from rce_gtsam.diagnosis.oracle import true_signature

    def inputs(Y, W, s, labels):
        return {"inputs": {"Y": Y, "weights": W, "root_distance": s, "seed": 0, "edge_labels": labels}, "Y": Y}

    eff, sigs = [], []
    for sd in range(a.own_sim_seeds):
        Y, W, s, _, y, _, labels = cached_case(a.own_sim_cache, "second_mode", sd, a.own_sim_frames, False,
                                               a.own_sim_mult)
        r = effect_case({**inputs(Y, W, s, labels), "truth": y}, ("second_mode",), heldout)
        eff.append(r)
        sigs.append(true_signature(y + np.nanmean(Y - y, axis=1, keepdims=True)))
        print(f"  own second_mode x{a.own_sim_mult:g} seed {sd}: right {r['right']} oracle {r['oracle']} ideal p "
              f"{r['ideal_p']:.4f}; " + " ".join(f"{k} t={v['t']:.2f} ({v['gain_pct']:+.1f}%)"
                                                 for k, v in r.get("schemes", {}).items())
              + f" [{time.perf_counter() - t0:.0f} s]", flush=True)
    null = []
    for sd in range(a.own_sim_null if sigs else 0):
        Y, W, s, _, _, _, labels = cached_case(a.own_sim_cache, None, sd, a.own_sim_frames, False)
        sig = sigs[sd % len(sigs)]
        if sig.shape != Y.shape:
            continue
        r = null_case(inputs(Y, W, s, labels), sig, heldout, seed=sd)
        null.append(r)
        print(f"  own none seed {sd}: verdict {r['verdict']} ideal p {r['ideal_p']:.4f}; "
              + " ".join(f"{k} t={v['t']:.2f}" for k, v in r.get("schemes", {}).items())
              + f" [{time.perf_counter() - t0:.0f} s]", flush=True)
    return eff, null


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--effect", default="two_sources")
    ap.add_argument("--mults", default="1,2,3,5")
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--frames", type=int, default=450)
    ap.add_argument("--cache", default="/work/cache/beam4")
    ap.add_argument("--null-cache", default="/work/cache/beam6")
    ap.add_argument("--null-seeds", type=int, default=40)
    ap.add_argument("--null-mult", type=float, default=3.0)
    ap.add_argument("--no-heldout", action="store_true", help="skip the held-out schemes (the slow part)")
    ap.add_argument("--own-sim-seeds", type=int, default=0,
                    help="also the project's own simulator: second_mode seeds (0: skip)")
    ap.add_argument("--own-sim-null", type=int, default=0, help="own simulator effect-free seeds")
    ap.add_argument("--own-sim-mult", type=float, default=1.0)
    ap.add_argument("--own-sim-frames", type=int, default=900)
    ap.add_argument("--own-sim-cache", default="/work/cache/bd")
    ap.add_argument("--record", default=None, metavar="NAME")
    a = ap.parse_args()
    from rce_gtsam.sim.beam import BEAM_EFFECTS, DIAGNOSIS_NAME
    if a.effect not in BEAM_EFFECTS:
        print(f"beam_ideal_oracle: --effect {a.effect}: unknown; choose from {', '.join(BEAM_EFFECTS)}",
              file=sys.stderr)
        return 2
    try:
        mults = [float(m) for m in a.mults.split(",")]
    except ValueError:
        print(f"beam_ideal_oracle: --mults {a.mults!r}: not a comma-separated list of numbers", file=sys.stderr)
        return 2
    if a.null_cache and a.null_seeds > 0 and a.null_mult not in mults:
        print(f"beam_ideal_oracle: --null-mult {a.null_mult:g} is not among --mults {a.mults}: no signature to "
              "borrow", file=sys.stderr)
        return 2
    for opt, path in (("--cache", a.cache), ("--null-cache", a.null_cache)):
        if path and not Path(path).is_dir():
            print(f"beam_ideal_oracle: {opt} {path}: no such directory", file=sys.stderr)
            return 2
    from bench_beam import cached_case, case_path
    from rce_gtsam.diagnosis.oracle import true_signature
    heldout = not a.no_heldout
    t0 = time.perf_counter()
    per_mult, sigs = {}, {}
    for m in mults:
        cases = []
        for sd in range(a.seeds):
            c = cached_case(a.cache, a.effect, sd, a.frames, m, None)
            r = effect_case(c, DIAGNOSIS_NAME[a.effect], heldout)
            cases.append(r)
            if m == a.null_mult:
                y = c["truth"] + np.nanmean(c["Y"] - c["truth"], axis=1, keepdims=True)
                sigs[sd] = true_signature(y)
            sch = " ".join(f"{k} t={v['t']:.2f} ({v['gain_pct']:+.1f}%)" for k, v in r.get("schemes", {}).items())
            print(f"  {a.effect} x{m:g} seed {sd}: right {r['right']} oracle {r['oracle']} (t {r['oracle_t']:.2f}) "
                  f"ideal p {r['ideal_p']:.4f} z {r['ideal_z']:.1f}; effect {r['effect_rms']:.2f} noise "
                  f"{r['noise_rms']:.2f} deg; {sch} [{time.perf_counter() - t0:.0f} s]", flush=True)
        per_mult[m] = cases
    null = []
    if a.null_cache and a.null_seeds > 0:
        for sd in range(a.null_seeds):
            path = case_path(a.null_cache, None, sd, a.frames, 1.0, None)
            if not path.exists():
                continue
            c = cached_case(a.null_cache, None, sd, a.frames, 1.0, None)
            sig = sigs[sd % len(sigs)]
            if sig.shape != c["Y"].shape:
                continue
            r = null_case(c, sig, heldout and a.effect == "two_sources", seed=sd)
            null.append(r)
            sch = " ".join(f"{k} t={v['t']:.2f}" for k, v in r.get("schemes", {}).items())
            print(f"  none seed {sd}: verdict {r['verdict']} ideal p {r['ideal_p']:.4f}; {sch} "
                  f"[{time.perf_counter() - t0:.0f} s]", flush=True)
    own_eff, own_null = own_sim(a, heldout, t0) if a.own_sim_seeds > 0 else ([], [])
    from heldout_schemes import SCHEMES as schemes
    cols = ["strength", "seeds", "diagnosis", "oracle", "ideal oracle", "ideal z (median)", "effect RMS (deg)",
            "noise RMS (deg)"] + [f"{s} {k}" for s in schemes for k in ("t>split", "t>support", "t median")]
    rows = [effect_row(f"x{m:g}", cases) for m, cases in per_mult.items()]
    if null:
        rows.append(null_row("none", null))
    if own_eff:
        rows.append(effect_row(f"own simulator second_mode x{a.own_sim_mult:g} ({a.own_sim_frames} frames)", own_eff))
    if own_null:
        rows.append(null_row(f"own simulator none ({a.own_sim_frames} frames)", own_null))
    if not any("schemes" in c for cs in [*per_mult.values(), null, own_eff, own_null] for c in cs):
        cols, rows = cols[:8], [r[:8] for r in rows]  # no held-out scheme ran (--no-heldout, or not a second mode)
    print("\n" + " | ".join(cols))
    for r in rows:
        print(" | ".join(str(x) for x in r))
    nulls05 = rate([c["ideal_p"] <= 0.05 for c in null]) if null else "-"
    notes = curve_notes(per_mult) + [f"ideal oracle on the effect-free cases at p <= 0.05: {nulls05} (at the "
                                     "verdict's 0.005: the 'none' row)"]
    if null:
        ps = np.array([c["ideal_p"] for c in null])
        tail = (": conservative if anything, so its pass rates are a floor of the ceiling"
                if ps.min() > 0.05 and 1 - 0.95 ** len(ps) > 0.8 else "")
        notes.append(f"ideal oracle's p on the effect-free cases: median {np.median(ps):.2f}, smallest {ps.min():.3f} "
                     f"(uniform would give a smallest below 0.05 with probability {1 - 0.95 ** len(ps):.2f}){tail}")
    for n in notes:
        print(n)
    print(f"[{time.perf_counter() - t0:.0f} s]")
    if a.record:
        from record import save_record
        save_record(a.record, title=f"Beam {a.effect}: the diagnosis, its oracle, the ideal oracle and held-out "
                                    "schemes against strength",
                    command=(f"python benchmarks/beam_ideal_oracle.py --effect {a.effect} --mults "
                             f"{a.mults} --seeds {a.seeds} --frames {a.frames} --cache {a.cache} --null-cache "
                             f"{a.null_cache} --null-seeds {a.null_seeds} --null-mult {a.null_mult:g}"
                             + (" --no-heldout" if a.no_heldout else "")
                             + (f" --own-sim-seeds {a.own_sim_seeds} --own-sim-null {a.own_sim_null} --own-sim-mult "
                                f"{a.own_sim_mult:g} --own-sim-frames {a.own_sim_frames} --own-sim-cache "
                                f"{a.own_sim_cache}" if a.own_sim_seeds > 0 else "") + f" --record {a.record}"),
                    description=(
                        "Per strength (multiple of the beam default), the share of seeds on which the diagnosis names "
                        "the effect, its oracle (the verdict's own tests, true form and shared parameters) passes, and "
                        "the ideal oracle (GLS projection of the rank-1 residual on the known true signature, "
                        "phase-surrogate null, rce_gtsam.diagnosis.ideal_oracle) has p <= the verdict's full-data "
                        "level 0.005; its median z (null SDs). "
                        + ("Held-out schemes (benchmarks/heldout_schemes.py): the second-mode fit's fold t against "
                           "the rank-1 baseline scored alike: halves_code = the diagnosis' own prediction (node-"
                           "disjoint halves, alternating z/w), halves_gls = same rows with a joint GLS posterior of z "
                           "and w (against a GLS rank-1 baseline), halves_signature = the diagnosis' rank-1 "
                           "prediction plus the true signature (its held-out test's ceiling), bcv_gls = "
                           "bi-cross-validation over runs of 3 rows, latents from every row sharing no node with the "
                           "run, bcv_signature = the same ceiling on those rows; counts of t above the split "
                           "threshold (fold t alone names it) and above the support t (what a passing full-data test "
                           "needs beside it). " if len(cols) > 8 else "")
                        + "'none': effect-free beam cases, each tested along a signature borrowed from an effect "
                        "case." + (" 'own simulator' rows: the same on the project's own simulator (bench_diagnose.py "
                                   "cases)." if own_eff else "")),
                    columns=cols, rows=rows, notes=notes)
    return 0


if __name__ == "__main__":
    sys.exit(main())
