"""One model engine on the real plants: ``rce analyze`` reports the diagnosis baseline's kappa, and the
extended model's intervals contain its estimates."""

from __future__ import annotations

import numpy as np
import pytest

import rce_gtsam
from rce_gtsam.diagnosis.io import diagnose_result

pytestmark = pytest.mark.slow  # ~20 s alone: five analyses and four (one-candidate) diagnoses of real plants


@pytest.mark.parametrize("plant", ["plant_1", "plant_2"])
def test_analysis_kappa_is_the_diagnosis_baseline_kappa(shared_data, plant):
    d = shared_data / plant
    for preset in ("default", "paper"):
        result = rce_gtsam.analyze(d / "tapir_tracks.csv", d / "branch_graph.json", preset=preset, n_boot=0)
        diagnosis = diagnose_result(result, effects=("offset",), n_folds=2)
        assert np.max(np.abs(np.abs(diagnosis.baseline.kappa) - result.fit.kappa)) <= 1e-10, (plant, preset)
        np.testing.assert_allclose(np.abs(diagnosis.baseline.z), np.abs(result.fit.z), rtol=0, atol=1e-10)


def test_extended_intervals_on_a_real_plant_contain_the_estimates(shared_data):
    """(The paper preset's block scheme is checked on simulated tracks in test_effects_analyze.py.)"""
    d = shared_data / "plant_2"
    ext = rce_gtsam.analyze(d / "tapir_tracks.csv", d / "branch_graph.json", n_boot=12, effects=("offset",))
    k = ext.fit.kappa
    assert ((ext.ci.low <= k) & (k <= ext.ci.high)).all()
