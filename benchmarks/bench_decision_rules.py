"""Which of the decision's rules (:mod:`rce_gtsam.diagnosis.decision`) change a verdict, on cached recordings.

The issue that split the diagnosis into evidence -> decision -> report asks to drop the rules the wider test bed
shows do not earn their place. A rule earns it where switching it off alone changes verdicts for the worse. Each
recording is diagnosed once; its recorded evidence is then re-decided with one rule off at a time
(:func:`verdict_without`), and the verdicts that change are counted as right -> wrong (the rule earns its place
there), wrong -> right (it costs) or wrong -> wrong, against the hidden effect. The rules:

* ``aic`` — the AIC hurdle on the effective sample; ``resolution`` — the smallest share of the bending variance;
  ``plausibility`` — no implausible fit is named;
* ``score_rescue`` — the full-data score test as a second route to significance and as the AIC's waiver (off:
  the fold t alone, at the whole share of alpha);
* ``drift_checks`` — what an offset/creep must show besides its fold t (off: its fold t alone);
* ``richer_form`` — support as the richer form of a supported lag; ``encompassing`` — the encompassing test in
  the leading and parsimony rules (off: the fold-paired t decides, as it did before that test).

Switching a rule off re-runs no test, so a test the changed rule would have asked for is missing (see
:func:`verdict_without`): a measurement of what each rule decides on these recordings, not a re-run without it.

Input: the cached pipeline outputs of ``benchmarks/bench_diagnose.py --cache`` / ``bench_artifacts.py --cache``
(npz with Y, W, s, labels). The hidden effect is read from the file name (``none``/``artifact_*``: none).

Measured (2026-11-27; 67 cached recordings: delay and dynamics 1x seeds 0-5, offset 4x and second mode 3x seeds
0-7, nonlinear 3x seeds 0-3, 900 frames; effect-free 450 frames: default noise 15, gust occlusion 2x 15, drift 2x
5): score_rescue right -> wrong 5 (delay 1, dynamics 2, second mode 2), encompassing right -> wrong 3 (dynamics),
aic right -> wrong 2 (effect-free, named dynamics) and wrong -> wrong 1, plausibility wrong -> right 1 (nonlinear
3x seed 0), resolution, drift_checks and richer_form no change. The last three were measured to act on recordings
this bed lacks (60 frames/s effect-free offsets; noise-free data; dynamics at 0.75x), so no rule is dropped on it.

Usage: OMP_NUM_THREADS=1 python benchmarks/bench_decision_rules.py FILE.npz [...] [--json OUT.json]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def hidden_effect(path: Path) -> str | None:
    """The effect hidden in a cached recording, from its file name (None for effect-free ones)."""
    name = path.stem
    if name.startswith(("artifact_", "none_")):
        return None
    return name.rsplit("_", 3)[0]


#: the rules :func:`verdict_without` can switch off, one at a time
RULES = ("aic", "resolution", "plausibility", "score_rescue", "drift_checks", "richer_form", "encompassing")


def verdict_without(d, rule: str | None) -> str | None:
    """The verdict of diagnosis ``d`` re-decided from its recorded evidence with ``rule`` (one of :data:`RULES`,
    None: none) switched off, every other rule kept. Only the decision runs again
    (:mod:`rce_gtsam.diagnosis.decision`): an encompassing test the changed rule would have asked for and that
    did not run is missing, and the parsimony rule then reads the fold-paired t, as it does where that test does
    not apply. ``"encompassing"``: the parsimony and leading rules read the fold t only."""
    from dataclasses import replace

    from rce_gtsam.diagnosis.decision import earns_its_place
    from rce_gtsam.diagnosis.verdict import choose_verdict, finding_of

    b_rmse, res, st = d.baseline_heldout_rmse, d.settings["resolution"], d.settings
    out = []
    for c in d.candidates:
        x, tests = c.extra, c.tests
        score = tests.get("score")
        sig, calibrated = bool(x.get("significant")), score is not None and score.fires
        if rule == "drift_checks" and "significant_by_fold_t" in x:
            sig = bool(x["significant_by_fold_t"])
        if rule == "score_rescue" and score is not None:  # the fold t alone, then at the whole share of alpha
            sig, calibrated = bool(np.isfinite(c.evidence) and c.evidence > st["evidence_threshold_t"]), False
        share = x.get("heldout_gain_share", 0.0)
        sup = bool(sig and (rule == "plausibility" or not x.get("implausible"))
                   and earns_its_place(c.heldout_rmse, b_rmse, c.delta_aic, res if rule == "resolution" else share,
                                       res, calibrated or rule == "aic"))
        if x.get("supported_as_form_of") and rule != "richer_form":
            sup = True
        extra = x
        if rule == "encompassing":
            extra = {k: v for k, v in x.items() if not k.startswith(("form_test", "encompassing"))}
        out.append(replace(c, supported=sup, extra=extra))
    name = choose_verdict(out, st["evidence_threshold_t"], p_pair=st["score_threshold_p"])[0]
    return None if name is None else finding_of(next(c for c in out if c.effect == name))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("files", nargs="+", type=Path)
    ap.add_argument("--json", type=Path, default=None, help="write the per-recording rows here")
    a = ap.parse_args(argv)
    from rce_gtsam.diagnosis.diagnose import diagnose
    from rce_gtsam.presets import get_preset

    config = get_preset("default").compliance
    rows, counts, t0 = [], Counter(), time.perf_counter()
    for path in a.files:
        c = dict(np.load(path))
        W = c["W"] if np.size(c["W"]) else None
        d = diagnose(c["Y"], weights=W, root_distance=c["s"], seed=0, edge_labels=list(c["labels"]), config=config)
        hidden, same = hidden_effect(path), verdict_without(d, None)
        assert same == d.verdict, (path, same, d.verdict)  # re-deciding the recorded evidence gives the verdict
        changed = {r: v for r in RULES if (v := verdict_without(d, r)) != d.verdict}
        for r, v in changed.items():
            counts[r, "right -> wrong" if d.verdict == hidden else
                   "wrong -> right" if v == hidden else "wrong -> wrong"] += 1
        rows.append({"file": path.name, "hidden": hidden, "verdict": d.verdict, "without": changed})
        print(f"{path.name}: hidden {hidden}, verdict {d.verdict}; without a rule: "
              + (", ".join(f"{r} -> {v}" for r, v in changed.items()) or "the same"), flush=True)
    print(f"\n{len(rows)} recordings ({time.perf_counter() - t0:.0f} s); verdicts each rule changes when it is "
          "switched off (right/wrong against the hidden effect; effect-free: right = none):")
    for r in RULES:
        cells = {k[1]: n for k, n in counts.items() if k[0] == r}
        print(f"  {r:<14} " + (", ".join(f"{k} {n}" for k, n in sorted(cells.items())) or "no verdict changes"))
    if a.json is not None:
        a.json.write_text(json.dumps(rows, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
