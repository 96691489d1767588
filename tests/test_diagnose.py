import json
import math

import numpy as np
import pytest

from rce_gtsam.diagnose import diagnose, edge_halves, fold_blocks

from _effect_data import synth

FAST = ["offset", "second_mode", "nonlinear"]  # the effects whose candidates fit in well under a second


def test_folds_and_halves():
    blocks = fold_blocks(600, 5, 25)
    assert blocks[0][0] == 0 and blocks[-1][1] == 600 and all(b - a >= 25 for a, b in blocks)
    A, B = edge_halves(np.linspace(0, 1, 9), 0)
    assert len(A) + len(B) == 9 and not set(A) & set(B)


@pytest.mark.parametrize("effect", ["offset", "second_mode"])
def test_verdict_names_hidden_effect(effect):
    Y, s, *_ = synth(effect, seed=0, E=16)
    d = diagnose(Y, root_distance=s, effects=FAST)
    assert d.verdict == effect
    c = d.candidate(effect)
    assert c.improvement_pct >= 15 and c.evidence > d.settings["evidence_threshold_t"]


def test_null_data_gives_no_verdict_and_valid_json():
    Y, s, *_ = synth(None, seed=2)
    d = diagnose(Y, root_distance=s, effects=FAST)
    assert d.verdict is None
    js = json.loads(json.dumps(d.as_dict()))
    assert set(js) >= {"baseline", "candidates", "verdict", "explanation", "worst_edges", "worst_frames"}
    assert js["candidates"][0]["heldout_rmse"] <= js["candidates"][-1]["heldout_rmse"]
    assert math.isfinite(js["baseline"]["heldout_rmse"])
    assert "[[Candidates]]" in d.report()


@pytest.mark.parametrize("effect", ["delay", "dynamics"])
def test_operator_effects_detected_with_large_heldout_gain(effect):
    """Delay / dynamics on simulator-equation data: the verdict names it and held-out RMSE falls >= 15 %
    (a fold whose held-out z was seen only through a long lag used to blow up: -200 %)."""
    Y, s, *_ = synth(effect, seed=0, E=12, T=600)
    d = diagnose(Y, root_distance=s, effects=["delay", "dynamics", "offset"])
    assert d.verdict == effect
    assert d.candidate(effect).improvement_pct >= 15
