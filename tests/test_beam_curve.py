"""bench_beam --curve (benchmarks/beam_curve.py): the 90 % point by interpolation, the curve's counts, the rule that
refused a candidate read off a real diagnosis, and a missing cache named before any work."""

import sys
from pathlib import Path

import pytest

from _effect_data import synth
from rce_gtsam.diagnosis.diagnose import diagnose

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
import beam_curve  # noqa: E402


def test_the_90_point_is_interpolated_between_the_strengths_around_it():
    assert beam_curve.point_at([1, 2, 4], [0.2, 0.6, 1.0]) == (pytest.approx(3.5), "=")
    assert beam_curve.point_at([1, 2], [0.9, 1.0]) == (1, "<=")          # already there at the weakest
    assert beam_curve.point_at([1, 2, 3], [0.5, 0.8, 0.4]) == (None, "not reached")
    assert beam_curve.fmt_point((None, "not reached")) == "not reached"


def test_a_score_test_without_the_fold_t_beside_it_is_told_apart():
    o = {"refusal": {"rule": "significance", "score_p": 0.0025, "score_threshold_p": 0.005}}
    assert beam_curve.rule_of(o) == "fold_support"
    o["refusal"]["score_p"] = 0.01
    assert beam_curve.rule_of(o) == "significance"


def _outcome(mult, seed, right, oracle, rule):
    return {"effect": "creep", "mult": mult, "strength": 2.0 * mult, "seed": seed, "frames": 450, "verdict": None,
            "right": right, "oracle": {"supported": oracle, "t": 1.0, "threshold_t": 2.6, "score_p": None},
            "refusal": {"rule": "named" if right else rule, "fold_t": 1.0}, "size": 0.1,
            "phys": {"max_joint_deg": 5.0 + mult, "p99_joint_deg": 4.0, "tip_pct": 50.0},
            "effect_rms_deg": 0.1 * mult, "noise_rms_deg": 1.4}


def test_the_curve_counts_passes_and_names_the_refusals_where_the_oracle_passed():
    outs = ([_outcome(1, s, False, s < 5, "drift_checks") for s in range(10)]
            + [_outcome(2, s, s < 5, True, "significance") for s in range(10)]
            + [_outcome(4, s, s < 9, True, "significance") for s in range(10)])
    r = beam_curve.curve(outs)["creep"]
    assert [(x["mult"], x["right"], x["oracle"]) for x in r["rows"]] == [(1, 0, 5), (2, 5, 10), (4, 9, 10)]
    assert r["rows"][0]["gap_rules"] == {"drift_checks": 5} and r["rows"][0]["miss_rules"] == {"drift_checks": 10}
    assert r["rows"][2]["max_joint_deg"] == 9.0 and r["rows"][2]["effect_rms_deg"] == pytest.approx(0.4)
    assert r["oracle_90"] == (pytest.approx(1.8), "=") and r["diagnosis_90"] == (4.0, "=")
    assert r["ratio"] == pytest.approx(4.0 / 1.8) and beam_curve.ratio_text(r) == "2.22"


def test_the_refusal_is_read_off_the_real_diagnosis():
    Y, s, *_ = synth("delay", seed=0, E=10, T=300, strength=6.0)
    d = diagnose(Y, root_distance=s, effects=["delay"], edge_nodes=[{i} for i in range(10)])
    r = beam_curve.refusal(d, ("delay",))
    c = next(c for c in d.candidates if c.effect == "delay")
    assert r["candidate"] == "delay" and r["fold_t"] == pytest.approx(c.tests["fold_t"].statistic, abs=1e-4)
    assert (r["rule"] == "named") == (d.verdict == "delay")
    if r["rule"] == "significance":
        assert not c.extra["significant"] and f"{c.tests['fold_t'].threshold:.2f}" in r["text"]
    assert beam_curve.refusal(d, ("offset",))["rule"] == "absent"


def test_curve_without_outcomes_names_the_cache_and_exits_2(tmp_path, monkeypatch, capsys):
    import bench_beam
    for cache, said in ((tmp_path / "nope", "no such directory"), (tmp_path, "no case outcomes")):
        monkeypatch.setattr(sys, "argv", ["bench_beam.py", "--curve", "--cache", str(cache)])
        assert bench_beam.main() == 2
        err = capsys.readouterr().err
        assert str(cache) in err and said in err and len(err.strip().splitlines()) == 1
    monkeypatch.setattr(sys, "argv", ["bench_beam.py", "--curve", "--effects", "wobble", "--cache", str(tmp_path)])
    assert bench_beam.main() == 2 and "--effects: unknown ['wobble']" in capsys.readouterr().err


def test_curve_writes_a_valid_record_from_the_outcomes_in_the_cache(tmp_path, monkeypatch, capsys):
    import json

    import bench_beam
    from record import load_records
    for i, o in enumerate([_outcome(1, 0, False, True, "significance"), _outcome(2, 0, True, True, "")]):
        (tmp_path / f"creep_{o['mult']}_{o['seed']}_450_bootpreset.outcome.json").write_text(json.dumps(o))
    for seed, verdict in ((0, None), (1, "delay")):  # effect-free outcomes: their false verdicts go in a note
        (tmp_path / f"none_1_{seed}_450_bootpreset.outcome.json").write_text(json.dumps(
            {"effect": "none", "mult": 1, "seed": seed, "frames": 450, "verdict": verdict, "right": verdict is None}))
    out = tmp_path / "records"
    monkeypatch.setenv("RCE_RECORD_DIR", str(out))
    monkeypatch.setattr(sys, "argv", ["bench_beam.py", "--curve", "--effects", "creep", "--cache", str(tmp_path),
                                      "--record", "beam_detection_test"])
    assert bench_beam.main() == 0
    (name, rec), = load_records(out)
    assert name == "beam_detection_test" and [r[:7] for r in rec["rows"]] == [
        ["creep", 450, 1.0, 2.0, 1, "0 of 1", "1 of 1"], ["creep", 450, 2.0, 4.0, 1, "1 of 1", "1 of 1"]]
    assert rec["rows"][0][-2] == "significance 1" and rec["rows"][0][7] == "-"   # no pickle: no effect RMS
    # 0 -> 1 of 1 between x1 and x2 reaches 0.9 at x1.9; the oracle passed at the weakest: the ratio is a bound
    assert rec["notes"][0] == ("creep, 450 frames: 90 % point: diagnosis x1.90, oracle <= x1, ratio >= 1.90; "
                               "highest pass rate: diagnosis 1 of 1 at x2, oracle 1 of 1 at x1; pooled over the "
                               "strengths tried: diagnosis 1 of 2, oracle 2 of 2")
    assert "ratio >= 1.90" in capsys.readouterr().out
    assert ("effect-free beam, 450 frames (the cases in the same cache): 1 false verdicts of 2 ({'delay': 1})"
            in rec["notes"])
